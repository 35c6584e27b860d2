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
    /// Fade leaves at or below pixel size to a solid colour so distant crowns keep their density.
    pub subpixel_fade: bool,
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
