//! The filterable shadow map's receivers on the GPU against their CPU reference: the pole scene
//! (no ambient light, a white Lambertian ground, one cascade) with a [`FilteredShadowMap`] on
//! the sun, for each method. Per ground pixel the visibility the receiver applied (its linear
//! green over the lit ground's) equals what the CPU reads from the GPU's own map — Bevy's biases
//! and the cascade's projection give the texel and the receiver's depth, the pixel's footprint
//! in the map the mip (`filter::sample`), the method the visibility — and differs from Bevy's
//! hard shadow across the penumbra.
//!
//! Tolerance: every ground pixel within 0.02 (measured on llvmpipe: worst 0.0085–0.011, the
//! 8-bit output's rounding). A receiver reading the wrong map, level or light, or Bevy's hard
//! shadow, misses by far more; so does a CPU reference that leaves out the √2 Bevy puts on the
//! normal bias (up to 0.125 across the penumbra: the receiver sits 0.4 texel higher).

mod common;

use bevy::light::Cascades;
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy_nature_harness::RenderHarness;
use bevy_soft_shadows::filterable::filter::{FilterableMethod, MomentMap, sample};
use bevy_soft_shadows::filterable::render::FilteredShadowViewMaps;
use common::*;

/// The GPU's map (layer 0, every mip), or `None` before it was made.
fn read_map(harness: &RenderHarness) -> Option<Vec<MomentMap>> {
    let render_world = harness.app().get_sub_app(RenderApp).unwrap().world();
    let device = render_world.resource::<RenderDevice>();
    let queue = render_world.resource::<RenderQueue>();
    let mut maps = render_world.try_query::<&FilteredShadowViewMaps>()?;
    let textures = maps.iter(render_world).next()?.directional.as_ref()?;
    let levels = textures.moments.mip_level_count();
    Some(
        (0..levels)
            .map(|level| read_level(device, queue, &textures.moments, level))
            .collect(),
    )
}

/// The CPU's visibility at every pixel of the ground (NaN on the pole and its margin), from the
/// GPU's map `chain` and the sun's cascade as Bevy computed it.
fn cpu_visibility(
    harness: &mut RenderHarness,
    method: FilterableMethod,
    chain: &[MomentMap],
) -> Vec<f32> {
    let world = harness.world_mut();
    let camera = world
        .query_filtered::<Entity, With<Camera3d>>()
        .single(world)
        .unwrap();
    let (light, cascades) = world
        .query_filtered::<(&DirectionalLight, &Cascades), With<Sun>>()
        .single(world)
        .unwrap();
    let cascade = &cascades.cascades[&camera][0];
    let to_light = sun_direction();
    let size = chain[0].width as f32;
    let m_per_px = VIEW_M / SIZE as f32;
    // Bevy's normal bias (scaled to the cascade's texel, and by √2 for a texel's diagonal as
    // `extract_lights` does) and depth bias, along the ground's normal and towards the light.
    let offset = light.shadow_normal_bias * std::f32::consts::SQRT_2 * cascade.texel_size * Vec3::Y
        + light.shadow_depth_bias * to_light;
    let texels = |d: Vec3| {
        let c = cascade.clip_from_world * d.extend(0.0);
        Vec2::new(c.x * 0.5, -c.y * 0.5) * size
    };
    let footprint = texels(Vec3::X * m_per_px)
        .length()
        .max(texels(Vec3::Z * m_per_px).length());
    let mut out = vec![f32::NAN; (SIZE * SIZE) as usize];
    for (i, ground) in ground_pixels() {
        let clip = cascade.clip_from_world * (ground + offset).extend(1.0);
        let ndc = clip.truncate() / clip.w;
        let uv = [ndc.x * 0.5 + 0.5, -ndc.y * 0.5 + 0.5];
        let texel = sample(chain, uv, footprint);
        out[i] = method.visibility(texel, 1.0 - ndc.z);
    }
    out
}

#[test]
fn receivers_apply_the_filtered_visibility_the_cpu_reads_from_the_map() {
    let Some(mut harness) = pole_harness("filtered_receiver") else {
        return;
    };
    harness.wait_until_ready().expect("pipelines");
    let hard = to_linear(&harness.render().expect("hard"));
    let lit_green = lit(&hard);
    let sun = sun_entity(&mut harness);
    for method in FILTERED_METHODS {
        use_filtered_map(&mut harness, sun, method);
        // Until the receivers read this method's map: the CPU's visibility from the map read
        // back after the frame matches the frame.
        let mut last = (0usize, 0usize, 0.0f32, 0usize, 0usize);
        let mut matched = false;
        let mut bad = Vec::new();
        for _ in 0..60 {
            let Ok(image) = harness.render() else {
                continue;
            };
            let image = to_linear(&image);
            let Some(chain) = read_map(&harness) else {
                continue;
            };
            let cpu = cpu_visibility(&mut harness, method, &chain);
            let (mut compared, mut within, mut worst, mut penumbra, mut softened) =
                (0usize, 0usize, 0.0f32, 0usize, 0usize);
            bad.clear();
            for (i, &v) in cpu.iter().enumerate() {
                if v.is_nan() {
                    continue;
                }
                let gpu = image[i * 4 + 1] / lit_green;
                let bevy = hard[i * 4 + 1] / lit_green;
                let d = (gpu - v).abs();
                if d > 0.02 {
                    bad.push((i as u32 % SIZE, i as u32 / SIZE, gpu, v, bevy));
                }
                compared += 1;
                within += (d <= 0.02) as usize;
                worst = worst.max(d);
                if v > 0.02 && v < 0.98 {
                    penumbra += 1;
                    softened += ((gpu - bevy).abs() > 0.1) as usize;
                }
            }
            last = (compared, within, worst, penumbra, softened);
            if compared > 0 && within == compared {
                matched = true;
                break;
            }
        }
        let (compared, within, worst, penumbra, softened) = last;
        // The pixels furthest from the CPU, to see where a failure lies.
        bad.sort_by(|a, b| (b.2 - b.3).abs().total_cmp(&(a.2 - a.3).abs()));
        for b in bad.iter().take(5) {
            eprintln!(
                "  pixel {:?}: GPU {:.3}, CPU {:.3}, Bevy's hard {:.3}",
                (b.0, b.1),
                b.2,
                b.3,
                b.4
            );
        }
        eprintln!(
            "{method:?}: {within} of {compared} ground pixels within 0.02 of the CPU (worst \
             {worst:.4}); {penumbra} penumbra pixels, {softened} of them > 0.1 from Bevy's hard shadow"
        );
        assert!(
            matched,
            "{method:?}: the receivers never matched the CPU: {within}/{compared}, worst {worst}"
        );
        // The filtered shadow is soft: a band of penumbra where Bevy's shadow is hard.
        assert!(
            penumbra > 300,
            "{method:?}: only {penumbra} penumbra pixels"
        );
        // Bevy's hard shadow as the receivers' output would leave ~0 here (measured: 348 for
        // ESM, whose penumbra hugs the lit side, to 596 for the Gaussian CDF).
        assert!(
            softened >= 150,
            "{method:?}: {softened} of {penumbra} penumbra pixels differ from Bevy's"
        );
    }
}
