//! Settings of Screen Space Soft Shadows (Gumbau 2011, ch. 6).

use bevy::prelude::*;

/// Turns Screen Space Soft Shadows on for the light it is put on.
///
/// The penumbra width in screen space follows eq. 6.2,
/// `w = (d_receiver − d_blocker) · light_size / (d_blocker · d_observer)`; the blur kernel's reach
/// (2.5 σ, σ = w/4) is clamped to `[min_kernel_px, max_kernel_px]`.
#[derive(Component, Clone, Debug, PartialEq, Reflect)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct ScreenSpaceSoftShadows {
    /// Size of the light source: for a directional light its angular diameter (radians; the Sun
    /// is 0.0093), for a spot or point light its diameter (m). Larger lights give wider
    /// penumbrae. Must be positive.
    pub light_size: f32,
    /// Largest blocker–receiver distance (m) the min filter of the shadow map searches for
    /// blockers: it bounds the widest outer penumbra. For a spot or point light the filter's
    /// window covers every blocker at least this far from the light and at most this far in
    /// front of its receiver (`ssss::min_filter::spot_fine_reach`).
    pub max_occluder_distance: f32,
    /// Smallest blur kernel radius in pixels (0 keeps hard contact shadows).
    pub min_kernel_px: f32,
    /// Largest blur kernel radius in pixels.
    pub max_kernel_px: f32,
    /// Samples whose view depth differs from the centre pixel's by more than this fraction are
    /// rejected, so penumbrae do not bleed across depth discontinuities.
    pub depth_rejection: f32,
    /// Taps a side of each blur pass at most: 2 / 5 / 11 are the thesis' 5×5 / 11×11 / 23×23
    /// kernels. Wider penumbrae spread the same taps further apart.
    pub taps_per_side: u32,
    /// Lazy shadowing (§6.3.2): a rejected sample is re-tested against the shadow map at the
    /// point it would be on the centre pixel's tangent plane, instead of being dropped — this
    /// removes light leaks around blockers that hide their own shadow from the camera.
    pub lazy_shadowing: bool,
    /// Blur only the 8×8 screen tiles where the blur can change a pixel (`ssss::tiles`): near
    /// shadow edges, within the kernels' reach. The result is the same as blurring every pixel
    /// (off: every tile is blurred, to compare or measure).
    pub tile_classification: bool,
}

impl Default for ScreenSpaceSoftShadows {
    fn default() -> Self {
        Self {
            light_size: 0.05,
            max_occluder_distance: 10.0,
            min_kernel_px: 0.0,
            max_kernel_px: 23.0,
            depth_rejection: 0.05,
            taps_per_side: 5,
            lazy_shadowing: true,
            tile_classification: true,
        }
    }
}

impl ScreenSpaceSoftShadows {
    /// The smallest light size accepted; zero or negative sizes are clamped to it.
    pub const MIN_LIGHT_SIZE: f32 = 1e-4;
    /// The most taps a side a blur pass takes.
    pub const MAX_TAPS_PER_SIDE: u32 = 32;

    /// Returns valid settings and the corrections made (non-finite values become defaults,
    /// non-positive sizes are clamped, an inverted kernel range is reordered).
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let d = Self::default();
        let mut out = self.clone();
        let mut fixes = Vec::new();
        let mut positive = |name: &str, v: &mut f32, min: f32, default: f32| {
            if !v.is_finite() {
                fixes.push(format!("{name} = {v} is not finite: using {default}"));
                *v = default;
            } else if *v < min {
                fixes.push(format!("{name} = {v} is below {min}: clamped to {min}"));
                *v = min;
            }
        };
        positive(
            "light_size",
            &mut out.light_size,
            Self::MIN_LIGHT_SIZE,
            d.light_size,
        );
        positive(
            "max_occluder_distance",
            &mut out.max_occluder_distance,
            1e-3,
            d.max_occluder_distance,
        );
        positive(
            "min_kernel_px",
            &mut out.min_kernel_px,
            0.0,
            d.min_kernel_px,
        );
        positive(
            "max_kernel_px",
            &mut out.max_kernel_px,
            1.0,
            d.max_kernel_px,
        );
        positive(
            "depth_rejection",
            &mut out.depth_rejection,
            1e-4,
            d.depth_rejection,
        );
        if !(1..=Self::MAX_TAPS_PER_SIDE).contains(&out.taps_per_side) {
            let clamped = out.taps_per_side.clamp(1, Self::MAX_TAPS_PER_SIDE);
            fixes.push(format!(
                "taps_per_side = {} is outside 1..={}: clamped to {clamped}",
                out.taps_per_side,
                Self::MAX_TAPS_PER_SIDE
            ));
            out.taps_per_side = clamped;
        }
        if out.min_kernel_px > out.max_kernel_px {
            fixes.push(format!(
                "min_kernel_px {} > max_kernel_px {}: swapped",
                out.min_kernel_px, out.max_kernel_px
            ));
            std::mem::swap(&mut out.min_kernel_px, &mut out.max_kernel_px);
        }
        (out, fixes)
    }
}

/// Clamps invalid settings on changed lights, with one warning per correction.
pub(crate) fn sanitize_soft_shadow_settings(
    mut lights: Query<(Entity, &mut ScreenSpaceSoftShadows), Changed<ScreenSpaceSoftShadows>>,
) {
    for (entity, mut settings) in &mut lights {
        let (fixed, fixes) = settings.sanitized();
        if !fixes.is_empty() {
            for fix in &fixes {
                warn!("ScreenSpaceSoftShadows on {entity}: {fix}");
            }
            *settings = fixed;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_or_negative_light_size_is_clamped() {
        for bad in [0.0, -2.0] {
            let (s, fixes) = ScreenSpaceSoftShadows {
                light_size: bad,
                ..default()
            }
            .sanitized();
            assert_eq!(s.light_size, ScreenSpaceSoftShadows::MIN_LIGHT_SIZE);
            assert_eq!(fixes.len(), 1);
        }
        let (s, fixes) = ScreenSpaceSoftShadows {
            light_size: f32::NAN,
            ..default()
        }
        .sanitized();
        assert_eq!(s.light_size, ScreenSpaceSoftShadows::default().light_size);
        assert_eq!(fixes.len(), 1);
    }

    #[test]
    fn inverted_or_negative_kernel_is_fixed() {
        let (s, fixes) = ScreenSpaceSoftShadows {
            min_kernel_px: 30.0,
            max_kernel_px: -1.0,
            ..default()
        }
        .sanitized();
        assert_eq!(fixes.len(), 2, "{fixes:?}");
        assert!(s.min_kernel_px <= s.max_kernel_px);
        assert_eq!((s.min_kernel_px, s.max_kernel_px), (1.0, 30.0));
        assert!(ScreenSpaceSoftShadows::default().sanitized().1.is_empty());
        for (taps, fixed) in [(0, 1), (1000, ScreenSpaceSoftShadows::MAX_TAPS_PER_SIDE)] {
            let (s, fixes) = ScreenSpaceSoftShadows {
                taps_per_side: taps,
                ..default()
            }
            .sanitized();
            assert_eq!((s.taps_per_side, fixes.len()), (fixed, 1));
        }
    }

    #[test]
    fn plugin_clamps_component_on_a_light() {
        let mut app = App::new();
        app.add_plugins(crate::SoftShadowsPlugin);
        let light = app
            .world_mut()
            .spawn(ScreenSpaceSoftShadows {
                light_size: -1.0,
                ..default()
            })
            .id();
        app.update();
        let s = app.world().get::<ScreenSpaceSoftShadows>(light).unwrap();
        assert_eq!(s.light_size, ScreenSpaceSoftShadows::MIN_LIGHT_SIZE);
    }
}
