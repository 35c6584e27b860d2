//! The component that gives a directional light a filterable shadow map.

use super::filter::FilterableMethod;
use bevy::prelude::*;

/// Put on a shadow-casting `DirectionalLight` or `SpotLight`: its shadow maps (a directional
/// light's cascades, a spot light's one map) are resolved into a filterable shadow map of
/// `method`'s statistics, blurred by a Gaussian of `blur_sigma` shadow-map texels and
/// mip-mapped, every frame after the shadow passes, for the scene's camera; meshes'
/// `StandardMaterial`s become [`SoftShadowMaterial`](crate::SoftShadowMaterial)s that read it
/// as this light's shadow term (where Screen Space Soft Shadows do not shadow the same light).
/// The first such directional light and the first such spot light are served, each with its own
/// method; point lights are not.
///
/// A spot light's map holds the distance along its axis over its `range` (Bevy's perspective
/// depth would crowd every distance beyond a few near planes into the last percent of the
/// range): keep the range close to the scene it lights.
///
/// It costs memory: three textures of the light's maps at Bevy's directional shadow-map size
/// (the resolved texels, the blur's scratch and the mip-mapped map), 32-bit floats in as many
/// channels as the method needs: with the default 2048² maps and four cascades, about 0.22 GB
/// for ESM, 0.45 GB for VSM and the Gaussian CDF, 0.9 GB for the power CDF and four moments
/// (a spot light's a quarter of that; 16-bit storage is to come).
///
/// Diagnostics: [`FILTERED_MAPS`](super::receiver::FILTERED_MAPS) (maps made) and
/// [`FILTERED_MAP_MIB`](super::receiver::FILTERED_MAP_MIB) (their GPU memory); with Bevy's
/// `RenderDiagnosticsPlugin`, the passes' GPU time as `render/filtered_shadow/elapsed_gpu`.
#[derive(Component, Clone, Copy, Debug, PartialEq, Reflect)]
#[reflect(Component, Debug, PartialEq, Default)]
pub struct FilteredShadowMap {
    /// Which statistics the map holds, and so which visibility reads them.
    pub method: FilterableMethod,
    /// The pre-filter's standard deviation in shadow-map texels (0.05..=12).
    pub blur_sigma: f32,
}

impl Default for FilteredShadowMap {
    fn default() -> Self {
        Self {
            method: FilterableMethod::GaussianCdf,
            blur_sigma: 1.5,
        }
    }
}

impl FilteredShadowMap {
    /// The largest `blur_sigma`: its Gaussian's radius (⌈2.5σ⌉) fills the passes' 31 texels.
    pub const MAX_BLUR_SIGMA: f32 = 12.0;
    /// The smallest `blur_sigma`.
    pub const MIN_BLUR_SIGMA: f32 = 0.05;

    /// Valid settings and what was corrected: a non-finite σ becomes the default, an
    /// out-of-range one is clamped; an exponential scale that is not finite and positive
    /// becomes 80.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let mut out = *self;
        let mut fixes = Vec::new();
        if !out.blur_sigma.is_finite() {
            fixes.push(format!(
                "blur_sigma = {} is not finite: using 1.5",
                out.blur_sigma
            ));
            out.blur_sigma = 1.5;
        } else if !(Self::MIN_BLUR_SIGMA..=Self::MAX_BLUR_SIGMA).contains(&out.blur_sigma) {
            let clamped = out
                .blur_sigma
                .clamp(Self::MIN_BLUR_SIGMA, Self::MAX_BLUR_SIGMA);
            fixes.push(format!(
                "blur_sigma = {} is outside {}..={}: clamped to {clamped}",
                out.blur_sigma,
                Self::MIN_BLUR_SIGMA,
                Self::MAX_BLUR_SIGMA
            ));
            out.blur_sigma = clamped;
        }
        if let FilterableMethod::Exponential { c } = out.method
            && !(c.is_finite() && c > 0.0)
        {
            fixes.push(format!(
                "the exponential's scale c = {c} must be positive: using 80"
            ));
            out.method = FilterableMethod::Exponential { c: 80.0 };
        }
        (out, fixes)
    }
}

/// Replaces unusable [`FilteredShadowMap`] settings in place, with a warning naming each fix.
pub(crate) fn sanitize_filtered_shadow_settings(
    mut lights: Query<(Entity, &mut FilteredShadowMap), Changed<FilteredShadowMap>>,
) {
    for (entity, mut settings) in &mut lights {
        let (fixed, fixes) = settings.sanitized();
        if !fixes.is_empty() {
            warn!("FilteredShadowMap on {entity}: {}", fixes.join("; "));
            *settings = fixed;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_settings_are_corrected() {
        let (fixed, fixes) = FilteredShadowMap {
            method: FilterableMethod::Exponential { c: f32::NAN },
            blur_sigma: 100.0,
        }
        .sanitized();
        assert_eq!(fixed.blur_sigma, FilteredShadowMap::MAX_BLUR_SIGMA);
        assert_eq!(fixed.method, FilterableMethod::Exponential { c: 80.0 });
        assert_eq!(fixes.len(), 2, "{fixes:?}");
        let good = FilteredShadowMap::default();
        assert_eq!(good.sanitized(), (good, vec![]));
        assert_eq!(
            FilteredShadowMap {
                blur_sigma: f32::INFINITY,
                ..good
            }
            .sanitized()
            .0,
            good
        );
    }

    #[test]
    fn the_plugin_clamps_the_component_on_a_light() {
        let mut app = App::new();
        app.add_plugins(crate::SoftShadowsPlugin);
        let light = app
            .world_mut()
            .spawn(FilteredShadowMap {
                blur_sigma: -3.0,
                ..default()
            })
            .id();
        app.update();
        let fixed = app.world().get::<FilteredShadowMap>(light).unwrap();
        assert_eq!(fixed.blur_sigma, FilteredShadowMap::MIN_BLUR_SIGMA);
    }
}
