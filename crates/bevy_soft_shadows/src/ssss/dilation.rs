//! The dilation's coarse radius for the SSSS light, worked out in the main world each frame:
//! the render world's extraction reads it (the spot light's radius in the uniform, the choice of
//! min filter), Bevy diagnostics publish it (`ssss/dilation_radius`, `ssss/segment_filter`), and
//! a window the cap cuts short gets a warning.

use super::min_filter::{
    DILATION_BLOCK, MAX_COARSE_RADIUS, MAX_DILATION_TEXELS, coarse_radius, coarse_radius_of,
    dilation_block, fine_reach, spot_fine_reach,
};
use crate::settings::ScreenSpaceSoftShadows;
use bevy::diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy::light::{
    Cascades, DirectionalLightShadowMap, PointLightShadowMap, SimulationLightSystems,
};
use bevy::prelude::*;
use bevy::render::extract_resource::ExtractResource;

/// How the separable min filter of the dilation runs. All give the same map bit for bit.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq, Reflect, ExtractResource)]
#[reflect(Resource, Default)]
pub enum SsssDilationFilter {
    /// The direct filter below a coarse radius of
    /// [`SEGMENT_FILTER_FROM_RADIUS`](super::min_filter::SEGMENT_FILTER_FROM_RADIUS), the
    /// segments from it on (the largest radius of the light's cascades decides).
    #[default]
    Auto,
    /// Van Herk / Gil-Werman segments: O(1) work per texel whatever the radius.
    Segments,
    /// The direct filter, 2R + 1 reads per texel and pass.
    Direct,
}

impl SsssDilationFilter {
    /// Whether the segment filter runs for a largest coarse radius of `max_radius`.
    pub fn uses_segments(self, max_radius: usize) -> bool {
        match self {
            Self::Auto => max_radius >= super::min_filter::SEGMENT_FILTER_FROM_RADIUS,
            Self::Segments => true,
            Self::Direct => false,
        }
    }
}

/// The largest coarse dilation radius `R` over the SSSS light's shadow maps (coarse texels).
pub const DILATION_RADIUS: DiagnosticPath = DiagnosticPath::const_new("ssss/dilation_radius");
/// 1 while the segment min filter runs, 0 for the direct one.
pub const SEGMENT_FILTER: DiagnosticPath = DiagnosticPath::const_new("ssss/segment_filter");

/// The SSSS light's dilation, as this frame's settings and shadow maps give it.
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq)]
pub struct SsssDilationRadius {
    /// The largest coarse radius over the light's shadow maps (its cascades, the spot's map, or
    /// the point light's cube faces).
    pub radius: usize,
    /// Shadow-map texels a side per coarse texel ([`dilation_block`]: the finest that holds the
    /// widest reach within [`MAX_COARSE_RADIUS`]).
    pub block: usize,
    /// Whether `max_occluder_distance` asked for more than [`MAX_DILATION_TEXELS`] fine texels
    /// somewhere, so the window stops short of the farthest blockers asked for.
    pub capped: bool,
}

impl Default for SsssDilationRadius {
    fn default() -> Self {
        Self {
            radius: 0,
            block: DILATION_BLOCK,
            capped: false,
        }
    }
}

/// The radius for the light the render world shades: the first directional light with SSSS
/// (over its cascades; the widest until it has any), else the first spot light with it, else the
/// first point light with it (`point_map_size`: `PointLightShadowMap::size`; its cube faces are
/// 90° perspective maps, a spot's of half angle π/4).
pub fn dilation_radius(
    directional: Option<(&ScreenSpaceSoftShadows, Option<&Cascades>)>,
    spot: Option<(&ScreenSpaceSoftShadows, &SpotLight)>,
    point: Option<&ScreenSpaceSoftShadows>,
    shadow_map_size: f32,
    point_map_size: f32,
) -> SsssDilationRadius {
    let capped = |reach: f32| reach > MAX_DILATION_TEXELS as f32;
    if let Some((settings, cascades)) = directional {
        let s = settings.sanitized().0;
        let texels: Vec<f32> = cascades
            .into_iter()
            .flat_map(|c| c.cascades.values().flatten())
            .map(|c| c.texel_size)
            .collect();
        if texels.is_empty() {
            return SsssDilationRadius {
                radius: MAX_COARSE_RADIUS,
                block: DILATION_BLOCK,
                capped: false,
            };
        }
        let reach = texels
            .iter()
            .map(|&t| fine_reach(s.max_occluder_distance, s.light_size, t))
            .fold(0.0f32, f32::max);
        let block = dilation_block(reach);
        return SsssDilationRadius {
            radius: texels
                .iter()
                .map(|&t| coarse_radius(s.max_occluder_distance, s.light_size, t, block))
                .max()
                .unwrap_or(0),
            block,
            capped: capped(reach),
        };
    }
    // Bevy clamps a spot's outer angle just below π/2 for the shadow projection.
    let local = spot
        .map(|(settings, spot)| {
            (
                settings,
                spot.outer_angle
                    .min(std::f32::consts::FRAC_PI_2 - 1e-4)
                    .tan(),
                shadow_map_size,
            )
        })
        .or(point.map(|settings| (settings, 1.0, point_map_size)));
    if let Some((settings, tan_half_angle, map_size)) = local {
        let s = settings.sanitized().0;
        let reach = spot_fine_reach(
            s.light_size,
            s.max_occluder_distance,
            tan_half_angle,
            map_size,
        );
        let block = dilation_block(reach);
        return SsssDilationRadius {
            radius: coarse_radius_of(reach, block),
            block,
            capped: capped(reach),
        };
    }
    SsssDilationRadius::default()
}

#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn measure_dilation(
    directional: Query<(&ScreenSpaceSoftShadows, Option<&Cascades>), With<DirectionalLight>>,
    spots: Query<(&ScreenSpaceSoftShadows, &SpotLight)>,
    points: Query<&ScreenSpaceSoftShadows, With<PointLight>>,
    shadow_map: Res<DirectionalLightShadowMap>,
    point_map: Res<PointLightShadowMap>,
    filter: Res<SsssDilationFilter>,
    mut dilation: ResMut<SsssDilationRadius>,
    mut diagnostics: Diagnostics,
    mut warned: Local<bool>,
) {
    let now = dilation_radius(
        directional.iter().next(),
        spots.iter().next(),
        points.iter().next(),
        shadow_map.size as f32,
        point_map.size as f32,
    );
    if now.capped && !*warned {
        warn!(
            "ScreenSpaceSoftShadows: max_occluder_distance needs a dilation wider than \
             {MAX_DILATION_TEXELS} shadow-map texels; it is capped there, so penumbrae of the \
             farthest blockers are cut short (lower max_occluder_distance or light_size, or \
             use a coarser shadow map)"
        );
    }
    *warned = now.capped;
    if *dilation != now {
        *dilation = now;
    }
    diagnostics.add_measurement(&DILATION_RADIUS, || now.radius as f64);
    diagnostics.add_measurement(&SEGMENT_FILTER, || {
        filter.uses_segments(now.radius) as u32 as f64
    });
}

pub(crate) fn build(app: &mut App) {
    app.init_resource::<SsssDilationRadius>()
        .register_diagnostic(Diagnostic::new(DILATION_RADIUS))
        .register_diagnostic(Diagnostic::new(SEGMENT_FILTER))
        .add_systems(
            PostUpdate,
            measure_dilation.after(SimulationLightSystems::UpdateDirectionalLightCascades),
        );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_radius_follows_the_light_and_reports_the_cap() {
        let settings = ScreenSpaceSoftShadows {
            light_size: 0.7,
            max_occluder_distance: 3.5,
            ..default()
        };
        let lamp = SpotLight {
            outer_angle: 0.75,
            ..default()
        };
        let r = dilation_radius(None, Some((&settings, &lamp)), None, 2048.0, 1024.0);
        assert_eq!(
            r,
            SsssDilationRadius {
                radius: 14,
                block: 4,
                capped: false
            }
        );
        // A 1.76 m lamp asks for ~139 texels: blocks of 16, R = 9, not capped.
        let wide = ScreenSpaceSoftShadows {
            light_size: 1.76,
            ..settings.clone()
        };
        let r = dilation_radius(None, Some((&wide, &lamp)), None, 2048.0, 1024.0);
        assert_eq!(
            r,
            SsssDilationRadius {
                radius: 9,
                block: 16,
                capped: false
            }
        );
        // Past the coarsest block's 1024 texels the window is capped, and said so.
        let absurd = ScreenSpaceSoftShadows {
            light_size: 10.0,
            max_occluder_distance: 0.5,
            ..settings.clone()
        };
        let r = dilation_radius(None, Some((&absurd, &lamp)), None, 4096.0, 1024.0);
        assert!(r.capped);
        assert_eq!(r.radius, MAX_COARSE_RADIUS);
        // A directional light wins; before its cascades exist it assumes the widest window.
        let sun = ScreenSpaceSoftShadows {
            light_size: 0.1,
            max_occluder_distance: 5.0,
            ..default()
        };
        let r = dilation_radius(
            Some((&sun, None)),
            Some((&settings, &lamp)),
            None,
            2048.0,
            1024.0,
        );
        assert_eq!(r.radius, MAX_COARSE_RADIUS);
        assert_eq!(
            dilation_radius(None, None, None, 2048.0, 1024.0),
            SsssDilationRadius::default()
        );
        // A point light's faces: a 90° map of the point-light shadow map's size; a spot light
        // wins over it.
        let bulb = ScreenSpaceSoftShadows {
            light_size: 0.6,
            max_occluder_distance: 4.0,
            ..default()
        };
        let reach = spot_fine_reach(0.6, 4.0, 1.0, 1024.0);
        let block = dilation_block(reach);
        assert_eq!(
            dilation_radius(None, None, Some(&bulb), 2048.0, 1024.0),
            SsssDilationRadius {
                radius: coarse_radius_of(reach, block),
                block,
                capped: false
            }
        );
        assert_ne!(
            dilation_radius(None, None, Some(&bulb), 2048.0, 1024.0),
            dilation_radius(None, None, Some(&bulb), 2048.0, 4096.0),
            "the point map's size counts"
        );
        assert_eq!(
            dilation_radius(None, Some((&settings, &lamp)), Some(&bulb), 2048.0, 1024.0),
            dilation_radius(None, Some((&settings, &lamp)), None, 2048.0, 1024.0)
        );
    }
}
