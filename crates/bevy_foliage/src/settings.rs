//! Settings of the per-frame pruning (Gumbau 2011, §3.4).

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
/// `near`/`far` are the distances of eq. 3.4: closer than `near` a tree keeps every visible leaf,
/// farther than `far` it keeps none (its impostor or nothing takes over), linear in between.
#[derive(Resource, Clone, Debug, PartialEq, Reflect)]
#[reflect(Resource, Default, Debug, PartialEq)]
pub struct FoliagePruningSettings {
    /// Prune at all. Off draws every leaf of every tree (full detail), e.g. to compare.
    pub enabled: bool,
    /// Distance (m) under which the distance factor is 1.
    pub near: f32,
    /// Distance (m) over which the distance factor is 0. Must exceed `near`.
    pub far: f32,
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
            near: 10.0,
            far: 250.0,
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
        if !out.near.is_finite() {
            fixes.push(format!(
                "near = {} is not finite: using {}",
                out.near, default.near
            ));
            out.near = default.near;
        }
        if out.near < 0.0 {
            fixes.push(format!("near = {} is negative: using 0", out.near));
            out.near = 0.0;
        }
        if !out.far.is_finite() || out.far <= out.near {
            let far = if default.far > out.near {
                default.far
            } else {
                out.near * 2.0 + 1.0
            };
            fixes.push(format!(
                "far = {} must be finite and beyond near = {}: using {far}",
                out.far, out.near
            ));
            out.far = far;
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

    /// The distance factor of eq. 3.4 for a tree at distance `d`: 1 under `near`, 0 over `far`,
    /// `1 − (d − near)/(far − near)` between.
    pub fn distance_factor(&self, d: f32) -> f32 {
        if d <= self.near {
            1.0
        } else if d >= self.far {
            0.0
        } else {
            1.0 - (d - self.near) / (self.far - self.near)
        }
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
    fn distance_factor_follows_eq_3_4() {
        let s = FoliagePruningSettings {
            near: 10.0,
            far: 110.0,
            ..default()
        };
        assert_eq!(s.distance_factor(0.0), 1.0);
        assert_eq!(s.distance_factor(10.0), 1.0);
        assert!((s.distance_factor(35.0) - 0.75).abs() < 1e-6);
        assert!((s.distance_factor(60.0) - 0.5).abs() < 1e-6);
        assert_eq!(s.distance_factor(110.0), 0.0);
        assert_eq!(s.distance_factor(1e9), 0.0);
    }

    #[test]
    fn absurd_settings_are_corrected() {
        let bad = FoliagePruningSettings {
            near: f32::NAN,
            far: -5.0,
            ..default()
        };
        let (fixed, fixes) = bad.sanitized();
        assert_eq!(fixes.len(), 2, "{fixes:?}");
        assert_eq!(fixed.near, 10.0);
        assert!(fixed.far > fixed.near);

        let inverted = FoliagePruningSettings {
            near: 500.0,
            far: 100.0,
            ..default()
        };
        let (fixed, fixes) = inverted.sanitized();
        assert_eq!(fixes.len(), 1);
        assert!(fixed.far > 500.0);

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
        app.world_mut().resource_mut::<FoliagePruningSettings>().far = f32::INFINITY;
        app.update();
        let s = app.world().resource::<FoliagePruningSettings>();
        assert!(s.far.is_finite() && s.far > s.near, "{s:?}");
    }
}
