//! Settings of the per-frame pruning (Gumbau 2011, §3.4).

use crate::distance::LodDistances;
use bevy::prelude::*;

/// How the three stored viewpoints nearest the current view direction are weighted when the
/// view-dependent LoD of a cell is interpolated (eq. 3.3). The thesis does not specify it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Reflect)]
#[reflect(Default, Debug, PartialEq)]
pub enum ViewWeighting {
    /// Weight of view k ∝ 1 / (angle between the view direction and viewpoint k + ε),
    /// normalised to sum to 1. Smooth, and exact when the view coincides with a viewpoint.
    #[default]
    InverseAngle,
    /// Only the nearest stored viewpoint (weight 1): cheapest, pops between viewpoints.
    Nearest,
}

/// Global settings of view-dependent stochastic pruning.
///
/// `distances` are those of eq. 3.4: nearer than `near` a tree keeps every visible leaf,
/// farther than `far` it keeps none, linear in between — by default measured by the crown's size
/// on screen, so trees of any size and unit prune alike ([`LodDistances`]).
#[derive(Resource, Clone, Debug, PartialEq, Reflect)]
#[reflect(Resource, Default, Debug, PartialEq)]
pub struct FoliagePruningSettings {
    /// Prune at all. Off draws every leaf of every tree (full detail), e.g. to compare.
    pub enabled: bool,
    /// `near` and `far` of eq. 3.4 (and of the forest manager's eq. 4.2).
    pub distances: LodDistances,
    /// Shadow views draw the shadow light's own selection of leaves, so pruning for the camera
    /// does not thin the shadows ([`crate::pruning::selection`]). Off: shadows draw the camera's
    /// selection (one extraction per tree instead of two).
    pub shadow_selection: bool,
    /// Interpolation of the baked per-view visibility between viewpoints.
    pub view_weighting: ViewWeighting,
    /// Enlarge kept leaves so the total leaf area is preserved (eq. 3.7–3.9).
    pub area_compensation: bool,
    /// Fade leaves at or below pixel size to a solid colour so distant crowns keep their density
    /// (§3.4): as a leaf's projected size falls from `fade_start_pixels` to `fade_end_pixels`,
    /// its texture coordinates converge on the leaf's centre texel (so its alpha mask stops
    /// averaging away in the coarse mips and it is drawn in one colour) and it shrinks to the
    /// opaque area of its texture (see [`crate::pruning::appearance`]).
    pub subpixel_fade: bool,
    /// Projected leaf diameter (pixels) at which the fade starts. A mip-mapped alpha mask starts
    /// losing the leaf when the leaf's narrow side is about 4 texels of the mip level sampled,
    /// i.e. a diameter near 9 px for a leaf half as wide as long: the fade must be well under way
    /// by then, hence 16 px.
    pub fade_start_pixels: f32,
    /// Projected leaf diameter (pixels) at which a leaf is fully solid. Below `fade_start_pixels`.
    pub fade_end_pixels: f32,
    /// Largest linear enlargement of a kept leaf by area compensation. A cell keeping 1 leaf of
    /// 30 would otherwise draw it √30 ≈ 5.5 times larger, a visible spike.
    pub max_leaf_scale: f32,
}

impl Default for FoliagePruningSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            distances: LodDistances::default(),
            shadow_selection: true,
            view_weighting: ViewWeighting::InverseAngle,
            area_compensation: true,
            subpixel_fade: true,
            fade_start_pixels: 16.0,
            fade_end_pixels: 1.0,
            max_leaf_scale: 4.0,
        }
    }
}

impl FoliagePruningSettings {
    /// Returns valid settings and the list of corrections made: non-finite or negative `near`
    /// becomes the default (or 0), a `far` not beyond `near` is moved just beyond it.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let default = Self::default();
        let mut out = self.clone();
        let mut fixes = Vec::new();
        let (distances, fix) = out.distances.sanitized();
        if let Some(fix) = fix {
            fixes.push(fix);
            out.distances = distances;
        }
        if !(out.max_leaf_scale.is_finite() && out.max_leaf_scale >= 1.0) {
            fixes.push(format!(
                "max_leaf_scale = {} must be finite and at least 1: using {}",
                out.max_leaf_scale, default.max_leaf_scale
            ));
            out.max_leaf_scale = default.max_leaf_scale;
        }
        let fade_ok = |v: f32| v.is_finite() && v >= 0.0;
        if !(fade_ok(out.fade_start_pixels)
            && fade_ok(out.fade_end_pixels)
            && out.fade_start_pixels > out.fade_end_pixels)
        {
            fixes.push(format!(
                "fade_start_pixels = {} must be finite and above fade_end_pixels = {} >= 0: using {} and {}",
                out.fade_start_pixels,
                out.fade_end_pixels,
                default.fade_start_pixels,
                default.fade_end_pixels
            ));
            out.fade_start_pixels = default.fade_start_pixels;
            out.fade_end_pixels = default.fade_end_pixels;
        }
        (out, fixes)
    }
}

/// Replaces invalid settings with corrected ones, logging each correction once.
pub(crate) fn sanitize_pruning_settings(mut settings: ResMut<FoliagePruningSettings>) {
    let (fixed, fixes) = settings.sanitized();
    if !fixes.is_empty() {
        for fix in &fixes {
            warn!("FoliagePruningSettings: {fix}");
        }
        *settings = fixed;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_settings_are_corrected() {
        let bad = FoliagePruningSettings {
            distances: LodDistances::World {
                near: f32::NAN,
                far: -5.0,
            },
            ..default()
        };
        let (fixed, fixes) = bad.sanitized();
        assert_eq!(fixes.len(), 1, "{fixes:?}");
        let (near, far) = fixed.distances.range();
        assert!(near >= 0.0 && far > near);

        let inverted = FoliagePruningSettings {
            distances: LodDistances::ScreenSize {
                near: 0.01,
                far: 0.5,
            },
            ..default()
        };
        let (fixed, fixes) = inverted.sanitized();
        assert_eq!(fixes.len(), 1);
        assert_eq!(fixed.distances, LodDistances::default());

        let bad_leaf = FoliagePruningSettings {
            max_leaf_scale: 0.5,
            fade_start_pixels: 1.0,
            fade_end_pixels: 3.0,
            ..default()
        };
        let (fixed, fixes) = bad_leaf.sanitized();
        assert_eq!(fixes.len(), 2, "{fixes:?}");
        assert_eq!(fixed.max_leaf_scale, 4.0);
        assert!(fixed.fade_start_pixels > fixed.fade_end_pixels);

        let (same, none) = FoliagePruningSettings::default().sanitized();
        assert!(none.is_empty());
        assert_eq!(same, FoliagePruningSettings::default());
    }

    #[test]
    fn plugin_corrects_settings_at_runtime() {
        let mut app = App::new();
        app.add_plugins(crate::FoliagePlugin);
        app.world_mut()
            .resource_mut::<FoliagePruningSettings>()
            .distances = LodDistances::World {
            near: 10.0,
            far: f32::INFINITY,
        };
        app.update();
        let s = app.world().resource::<FoliagePruningSettings>();
        let (near, far) = s.distances.range();
        assert!(far.is_finite() && far > near, "{s:?}");
    }
}
