//! A **spot light's** filterable shadow map on the GPU against its CPU reference: the pole scene
//! under a lamp 6 m up, beside a directional light and two point lights that cast shadows but
//! give no light (their maps move the spot's layer in Bevy's shadow texture to 4 and its index
//! among the clustered lights to 2). For a method of each texel format:
//!
//! - per ground pixel, the visibility the receiver applied (its linear green over the render
//!   with the pole hidden) equals what the CPU reads from the GPU's own map — Bevy's spot
//!   projection and biases (`ssss::distance::SpotProjection`) give the texel, the distance
//!   along the spot's axis over its range the receiver's depth (`filter::DepthSource::Spot`),
//!   the pixel's footprint in the map the mip (`filter::sample`);
//! - away from the shadow's edges it agrees with Bevy's hard shadow (lit stays lit, the core
//!   stays dark: the resolve linearised the right layer's depths as the receiver's depth is
//!   measured), and across the penumbra it is softer.
//!
//! Tolerances: every ground pixel within 0.03 of the CPU and 99 % within 0.02 (measured on
//! llvmpipe: worst 0.017–0.019, the 8-bit output's rounding in the penumbra — the directional
//! map's unexplained penumbra residual, `filtered_receiver.rs`, does not show here); 97 % of the
//! ground away from the edges within 0.1 of Bevy's hard shadow (measured: all but 4 of 16,665).
//! Resolving the spot's depths as a cascade's fails the second (12,507 of 16,665 agree, no
//! penumbra).

mod common;

use bevy::light::DirectionalLightShadowMap;
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy_nature_harness::RenderHarness;
use bevy_soft_shadows::SoftShadowsPlugin;
use bevy_soft_shadows::filterable::FilteredShadowMap;
use bevy_soft_shadows::filterable::filter::{FilterableMethod, MomentMap, sample};
use bevy_soft_shadows::filterable::render::FilteredShadowViewMaps;
use bevy_soft_shadows::ssss::distance::SpotProjection;
use common::*;

const LAMP: Vec3 = Vec3::new(3.0, 6.0, 0.0);
const AIM: Vec3 = Vec3::new(-1.5, 0.0, 0.0);

/// The GPU's spot map (every mip) and the layer of Bevy's shadow texture it was resolved from,
/// or `None` before it was made.
fn read_spot_map(harness: &RenderHarness) -> Option<(Vec<MomentMap>, u32)> {
    let render_world = harness.app().get_sub_app(RenderApp).unwrap().world();
    let device = render_world.resource::<RenderDevice>();
    let queue = render_world.resource::<RenderQueue>();
    let mut maps = render_world.try_query::<&FilteredShadowViewMaps>()?;
    let maps = maps.iter(render_world).next()?;
    assert!(maps.directional.is_none(), "no directional light asked");
    let textures = maps.spot.as_ref()?;
    let chain = (0..textures.moments.mip_level_count())
        .map(|level| read_level(device, queue, &textures.moments, level))
        .collect();
    Some((chain, textures.base_layer))
}

/// The CPU's visibility at every ground pixel (NaN on the pole and its margin) from the GPU's
/// map `chain`, as `filtered_receiver.wgsl` computes it.
fn cpu_visibility(
    lamp: &SpotLight,
    forward: Vec3,
    method: FilterableMethod,
    chain: &[MomentMap],
) -> Vec<f32> {
    let projection = SpotProjection {
        position: LAMP,
        forward,
        tan_outer: lamp.outer_angle.tan(),
        near: lamp.shadow_map_near_z,
    };
    let size = chain[0].width as f32;
    let m_per_px = VIEW_M / SIZE as f32;
    let mut out = vec![f32::NAN; (SIZE * SIZE) as usize];
    for (i, p) in ground_pixels() {
        // Bevy's spot biases (`fetch_spot_shadow`): towards the light, and along the normal
        // in proportion to the distance along the spot's axis — the normal bias in texels of
        // a unit distance, times √2 (`extract_lights`).
        let to_light = LAMP - p;
        let along = (-forward).dot(to_light);
        let normal_bias =
            lamp.shadow_normal_bias * 2.0 * projection.tan_outer / size * std::f32::consts::SQRT_2;
        let biased =
            p + lamp.shadow_depth_bias * to_light.normalize() + Vec3::Y * normal_bias * along;
        let Some((uv, distance)) = projection.project(biased) else {
            continue;
        };
        let texels = |d: Vec3| (projection.project(biased + d).unwrap().0 - uv) * size;
        let footprint = texels(Vec3::X * m_per_px)
            .length()
            .max(texels(Vec3::Z * m_per_px).length());
        let texel = sample(chain, [uv.x, uv.y], footprint);
        out[i] = method.visibility(texel, distance / lamp.range);
    }
    out
}

#[test]
fn a_spot_lights_filtered_map_is_resolved_and_received_as_the_cpu_does() {
    let Some(mut harness) = RenderHarness::for_test("filtered_spot", SIZE, SIZE) else {
        return;
    };
    harness.app_mut().add_plugins(SoftShadowsPlugin);
    spawn_ground_blocker_and_camera(
        &mut harness,
        Cuboid::new(0.2, 4.0, 1.0),
        Vec3::new(0.0, 2.0, 0.0),
        CENTRE,
    );
    let spot = SpotLight {
        intensity: 1.2e6,
        range: 30.0,
        shadow_maps_enabled: true,
        outer_angle: 0.6,
        inner_angle: 0.5,
        ..default()
    };
    let world = harness.world_mut();
    let lamp = world
        .spawn((
            spot,
            Transform::from_translation(LAMP).looking_to(AIM - LAMP, Vec3::Y),
        ))
        .id();
    spawn_dark_sun(world);
    for x in [-2.0, 2.0] {
        spawn_dark_bulb(world, Vec3::new(x, 3.0, 2.0));
    }
    // A small map, so that the pre-filter's penumbra spans pixels.
    world.insert_resource(DirectionalLightShadowMap { size: 256 });
    harness.wait_until_ready().expect("pipelines");
    // The lamp's forward as Bevy extracts it: along z it is ±0 up to rounding, and the sign
    // decides the basis `orthonormalize` builds (the map's orientation about the axis).
    let forward = harness
        .world_mut()
        .get::<GlobalTransform>(lamp)
        .unwrap()
        .forward()
        .as_vec3();
    let unshadowed = render_without_blocker(&mut harness);
    let hard = visibility(&to_linear(&harness.render().expect("hard")), &unshadowed);
    for method in [
        FilterableMethod::GaussianCdf,
        FilterableMethod::Exponential { c: 80.0 },
        FilterableMethod::PowerCdf,
    ] {
        harness
            .world_mut()
            .entity_mut(lamp)
            .insert(FilteredShadowMap {
                method,
                blur_sigma: 4.0,
            });
        let mut last = String::new();
        let mut matched = false;
        for _ in 0..60 {
            let Ok(image) = harness.render() else {
                continue;
            };
            let gpu = visibility(&to_linear(&image), &unshadowed);
            let Some((chain, layer)) = read_spot_map(&harness) else {
                continue;
            };
            // Four cascades of the directional light, then the spot's map.
            assert_eq!(layer, 4, "the spot's layer in Bevy's shadow texture");
            let cpu = cpu_visibility(&spot, forward, method, &chain);
            let (mut compared, mut within, mut close, mut worst) = (0usize, 0usize, 0usize, 0.0f32);
            let (mut settled, mut agree, mut penumbra, mut softened) = (0usize, 0, 0, 0);
            for (i, &v) in cpu.iter().enumerate() {
                if v.is_nan() {
                    continue;
                }
                let g = gpu[i * 4 + 1];
                let bevy = hard[i * 4 + 1];
                let d = (g - v).abs();
                compared += 1;
                within += (d <= 0.03) as usize;
                close += (d <= 0.02) as usize;
                worst = worst.max(d);
                // Bevy's hard shadow, far from its edge (beyond the pre-filter's reach, 2.5 σ
                // ≈ 0.37 m here, 12 pixels: a 25-pixel neighbourhood alike).
                let (c, r) = ((i as u32 % SIZE) as i32, (i as u32 / SIZE) as i32);
                let alike = (-12..=12).all(|dr: i32| {
                    (-12..=12).all(|dc: i32| {
                        let (cc, rr) = (c + dc, r + dr);
                        if cc < 0 || rr < 0 || cc >= SIZE as i32 || rr >= SIZE as i32 {
                            return true;
                        }
                        let other = hard[((rr as u32 * SIZE + cc as u32) * 4 + 1) as usize];
                        (other > 0.5) == (bevy > 0.5)
                    })
                });
                if alike {
                    settled += 1;
                    agree += ((g - bevy).abs() < 0.1) as usize;
                }
                if v > 0.05 && v < 0.95 {
                    penumbra += 1;
                    softened += ((g - bevy).abs() > 0.1) as usize;
                }
            }
            last = format!(
                "{method:?}: {within} of {compared} ground pixels within 0.03 of the CPU, {close} \
                 within 0.02 (worst {worst:.3}); {agree} of {settled} away from the edges agree with Bevy's hard \
                 shadow; {penumbra} penumbra pixels, {softened} softer than Bevy's"
            );
            if compared > 0 && within == compared && close as f32 >= 0.99 * compared as f32 {
                matched = true;
                assert!(
                    agree as f32 >= 0.97 * settled as f32 && settled > 10_000,
                    "{last}"
                );
                assert!(penumbra > 200 && softened >= 100, "{last}");
                break;
            }
        }
        eprintln!("{last}");
        assert!(matched, "the receivers never matched the CPU: {last}");
    }
}
