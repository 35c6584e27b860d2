//! The filterable shadow map's passes on the GPU against their CPU reference
//! (`filterable::filter`): the pole scene's sun (one cascade, a 256² map) resolved into texels
//! of statistics, blurred by a Gaussian and mip-mapped; the GPU's blurred map and every mip equal
//! what `blur` and `mip_chain` make of the GPU's own resolved texels, for a method of each
//! texel format (one, two and four channels).

mod common;

use bevy::light::DirectionalLightShadowMap;
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::render_resource::TextureFormat;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy_nature_harness::RenderHarness;
use bevy_soft_shadows::SoftShadowsPlugin;
use bevy_soft_shadows::filterable::FilteredShadowMap;
use bevy_soft_shadows::filterable::filter::{FilterableMethod, blur, mip_chain};
use bevy_soft_shadows::filterable::render::{FilteredShadowViewMaps, texel_format};
use common::*;

/// The texel format of the sun's filtered map as the render world holds it, where a view has
/// one.
fn directional_format(harness: &RenderHarness) -> Option<TextureFormat> {
    let render_world = harness.app().get_sub_app(RenderApp)?.world();
    let mut maps = render_world.try_query::<&FilteredShadowViewMaps>()?;
    maps.iter(render_world)
        .find_map(|maps| maps.directional.as_ref())
        .map(|textures| textures.format)
}

/// One harness (one render device) for every method: the sun's method is changed in place, as
/// a user switching methods does, and the passes must follow it to the new texel format.
#[test]
fn the_gpu_blurs_and_mips_the_statistics_as_the_cpu_does() {
    let Some(mut harness) = RenderHarness::for_test("filtered_shadow_map", 32, 32) else {
        return;
    };
    harness.app_mut().add_plugins(SoftShadowsPlugin);
    setup(&mut harness);
    harness
        .world_mut()
        .insert_resource(DirectionalLightShadowMap { size: 256 });
    let sigma = 1.5;
    let sun = sun_entity(&mut harness);
    for method in [
        FilterableMethod::Moments4,
        FilterableMethod::PowerCdf,
        FilterableMethod::GaussianCdf,
        FilterableMethod::Exponential { c: 20.0 },
    ] {
        harness
            .world_mut()
            .entity_mut(sun)
            .insert(FilteredShadowMap {
                method,
                blur_sigma: sigma,
            });
        harness.wait_until_ready().expect("pipelines");
        // The maps are made again in the new method's format within a few frames.
        let mut frames = 0;
        while directional_format(&harness) != Some(texel_format(method)) {
            frames += 1;
            assert!(frames <= 10, "{method:?}: the maps never took its format");
            harness.step();
        }
        harness.reset_timing();
        for _ in 0..3 {
            harness.step();
        }
        // The passes' GPU time is recorded, where the adapter has timestamps.
        if harness.has_gpu_timestamps() {
            let ms = harness
                .gpu_pass_time_ms("filtered_shadow")
                .expect("a timed span");
            assert!(ms >= 0.0, "{ms}");
        }
        let render_world = harness.app().get_sub_app(RenderApp).unwrap().world();
        let device = render_world.resource::<RenderDevice>();
        let queue = render_world.resource::<RenderQueue>();
        let mut maps = render_world
            .try_query::<&FilteredShadowViewMaps>()
            .expect("the component is registered");
        let textures = maps
            .iter(render_world)
            .find_map(|maps| maps.directional.as_ref())
            .expect("a view with the map");
        assert_eq!(textures.format, texel_format(method));
        let raw = read_level(device, queue, &textures.raw.texture, 0);
        assert_eq!((raw.width, raw.height), (256, 256));
        // The resolve: the pole nearer the sun than the ground, each texel its encoding.
        let depths: Vec<f32> = raw
            .texels
            .iter()
            .map(|t| match method {
                FilterableMethod::Exponential { c } => t[0].ln() / c,
                _ => t[0],
            })
            .collect();
        for (t, &z) in raw.texels.iter().zip(&depths) {
            let want = method.encode(z);
            for c in 0..4 {
                assert!(
                    (t[c] - want[c]).abs() <= 1e-5 * want[c].abs().max(1.0),
                    "{method:?}: {t:?}"
                );
            }
        }
        let (lo, hi) = depths
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &z| {
                (a.min(z), b.max(z))
            });
        assert!(hi - lo > 0.05, "{method:?}: one depth only ({lo}..{hi})");
        // The blur and every mip against the CPU's, from the GPU's own resolved texels.
        let chain = mip_chain(&blur(&raw, method, sigma), method);
        let levels = textures.mip_views.len() as u32;
        assert_eq!(levels as usize, chain.len());
        let mut worst = 0.0f32;
        for level in 0..levels {
            let gpu = read_level(device, queue, &textures.moments, level);
            let cpu = &chain[level as usize];
            assert_eq!((gpu.width, gpu.height), (cpu.width, cpu.height));
            for (g, c) in gpu.texels.iter().zip(&cpu.texels) {
                for k in 0..4 {
                    let d = (g[k] - c[k]).abs() / c[k].abs().max(1.0);
                    worst = worst.max(d);
                }
            }
        }
        eprintln!("{method:?}: {levels} levels, worst relative difference {worst:e}");
        assert!(worst < 1e-4, "{method:?}: {worst}");
    }
}
