//! Soft shadows three ways on one scene: Bevy's hard shadows, Bevy's PCSS and Screen Space Soft
//! Shadows (keys 1 / 2 / 3, or `technique` in the panel, which also shows the live GPU cost:
//! `render/ssss/elapsed_gpu` for the SSSS passes, `render/main_opaque_pass_3d/elapsed_gpu` where
//! PCSS filters).
//!
//! ```text
//! cargo run --release --example soft_shadows                 # windowed, egui panel
//! cargo run --example soft_shadows -- --headless --frames 30 --stats ssss.json
//! cargo run --example soft_shadows -- --bench [--frames N]   # the issue-6 table, JSON
//! cargo run --example soft_shadows -- --bench --spot          # the same under a lamp
//! ```
//!
//! Key 4 (or `spot` in the panel) switches from the sun to a lamp (a spot light) above the scene.
//!
//! `--bench` measures, in one process, for small / medium / large light sizes at two
//! resolutions: the GPU time of soft shadowing over hard shadows (timestamp queries: PCSS = its
//! main opaque pass minus the hard-shadow one; SSSS = its own passes plus its main pass minus the
//! hard-shadow one; SSSS as by default, then with its direct and its O(1)-per-texel segment
//! min filter forced) and each image's RMSE against an area-light reference (48 hard-shadowed
//! suns jittered over the light's disk, averaged in linear light — or with `--spot`, 48 spot
//! lights spread over the lamp's disk) rendered in the same run.

use bevy::prelude::*;
use bevy_nature::shadow_scene::{
    DemoLamp, DemoSun, LAMP_AIM, LAMP_POSITION, ShadowDemo, ShadowTechnique, add_shadow_demo,
    lamp_diameter, lamp_transform, spawn_shadow_scene, sun_direction,
};
use bevy_nature::soft_shadows::ScreenSpaceSoftShadows;
use bevy_nature::soft_shadows::reference::{
    LinearAverage, jittered_directions, jittered_positions, srgb_to_linear,
};
use bevy_nature::soft_shadows::ssss::render::SsssDilationFilter;
use bevy_nature_harness::headless::HarnessConfig;
use bevy_nature_harness::{ExampleArgs, ExampleRunner, RenderHarness, require_adapter};

fn main() -> AppExit {
    let mut rest: Vec<String> = std::env::args().skip(1).collect();
    let bench = rest.iter().any(|a| a == "--bench");
    let spot = rest.iter().any(|a| a == "--spot");
    rest.retain(|a| a != "--bench" && a != "--spot");
    let args = ExampleArgs::parse_from(rest).unwrap_or_else(|e| {
        eprintln!("{e} [--bench] [--spot]");
        std::process::exit(2)
    });
    if bench {
        return run_bench(&args, spot);
    }
    ExampleRunner::with_args("soft_shadows", args)
        .inspect_resource::<ShadowDemo>()
        .inspect_component::<ScreenSpaceSoftShadows>()
        .run(|app| {
            app.add_plugins(bevy_nature::soft_shadows::SoftShadowsPlugin)
                .add_systems(Startup, spawn_shadow_scene);
            add_shadow_demo(app);
            app.world_mut().resource_mut::<ShadowDemo>().spot = spot;
        })
}

fn linear(image: &[u8]) -> Vec<f32> {
    image.iter().map(|&v| srgb_to_linear(v)).collect()
}

/// RMSE over the colour channels, in linear light.
fn rmse(a: &[f32], b: &[f32]) -> f64 {
    let mut sum = 0.0f64;
    let mut n = 0usize;
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        if i % 4 != 3 {
            sum += ((x - y) as f64).powi(2);
            n += 1;
        }
    }
    (sum / n as f64).sqrt()
}

fn run_bench(args: &ExampleArgs, spot: bool) -> AppExit {
    if require_adapter("soft_shadows").is_none() {
        return AppExit::error();
    }
    let frames = args.frames.unwrap_or(12);
    let mut rows = Vec::new();
    for size in [UVec2::new(320, 180), UVec2::new(640, 360)] {
        let mut harness =
            RenderHarness::new(HarnessConfig::sized(size.x, size.y)).expect("harness");
        harness
            .app_mut()
            .add_plugins(bevy_nature::soft_shadows::SoftShadowsPlugin)
            .add_systems(Startup, spawn_shadow_scene);
        add_shadow_demo(harness.app_mut());
        harness.world_mut().resource_mut::<ShadowDemo>().spot = spot;
        harness.wait_until_ready().expect("scene ready");
        for (label, light_size) in [("small", 0.03f32), ("medium", 0.1), ("large", 0.25)] {
            let set = |harness: &mut RenderHarness, technique: ShadowTechnique| {
                let mut demo = harness.world_mut().resource_mut::<ShadowDemo>();
                demo.technique = ShadowTechnique::ALL
                    .iter()
                    .position(|t| *t == technique)
                    .unwrap() as u32;
                demo.light_size = light_size;
            };
            // The reference: hard shadows from suns jittered over the light's disk, or lamps
            // spread over the lamp's disk.
            set(&mut harness, ShadowTechnique::Hard);
            harness.run_frames(3).unwrap();
            let (sun, lamp) = {
                let world = harness.world_mut();
                let sun = world
                    .query_filtered::<Entity, With<DemoSun>>()
                    .single(world)
                    .unwrap();
                let lamp = world
                    .query_filtered::<Entity, With<DemoLamp>>()
                    .single(world)
                    .unwrap();
                (sun, lamp)
            };
            let mut average = LinearAverage::default();
            let poses: Vec<(Entity, Transform)> = if spot {
                let diameter = lamp_diameter(light_size);
                jittered_positions(LAMP_POSITION, LAMP_AIM - LAMP_POSITION, diameter, 48)
                    .into_iter()
                    .map(|p| (lamp, lamp_transform(p)))
                    .collect()
            } else {
                jittered_directions(sun_direction(), light_size, 48)
                    .into_iter()
                    .map(|d| (sun, Transform::default().looking_to(-d, Vec3::Y)))
                    .collect()
            };
            for (light, pose) in poses {
                *harness.world_mut().get_mut::<Transform>(light).unwrap() = pose;
                average.add(&harness.render().unwrap().data);
            }
            *harness.world_mut().get_mut::<Transform>(sun).unwrap() =
                Transform::default().looking_to(-sun_direction(), Vec3::Y);
            *harness.world_mut().get_mut::<Transform>(lamp).unwrap() =
                lamp_transform(LAMP_POSITION);
            let reference = average.linear();
            let mut measured = Vec::new();
            // SSSS as it runs by default (the min filter picked by radius), then with each min
            // filter forced, timed side by side (same maps, so the same image).
            let runs = [
                (ShadowTechnique::Hard, SsssDilationFilter::Auto, "hard"),
                (ShadowTechnique::Pcss, SsssDilationFilter::Auto, "pcss"),
                (ShadowTechnique::Ssss, SsssDilationFilter::Auto, "ssss"),
                (
                    ShadowTechnique::Ssss,
                    SsssDilationFilter::Direct,
                    "ssss_direct_filter",
                ),
                (
                    ShadowTechnique::Ssss,
                    SsssDilationFilter::Segments,
                    "ssss_segment_filter",
                ),
            ];
            for (technique, filter, name) in runs {
                set(&mut harness, technique);
                harness.world_mut().insert_resource(filter);
                // Let pipelines compile and the receivers switch, then time.
                harness.run_frames(8).unwrap();
                harness.reset_timing();
                harness.run_frames(frames).unwrap();
                let main = harness
                    .pass_time_ms("main_opaque_pass_3d")
                    .unwrap_or(f64::NAN);
                let ssss = harness.pass_time_ms("ssss").unwrap_or(0.0);
                let breakdown: Vec<String> = ["reduce", "dilate", "distance", "blur_h", "blur_v"]
                    .iter()
                    .filter_map(|p| {
                        let ms = harness.pass_time_ms(&format!("ssss/ssss_{p}"))?;
                        Some(format!("\"{p}\": {ms:.3}"))
                    })
                    .collect();
                let image = linear(&harness.render().unwrap().data);
                let error = rmse(&image, &reference);
                let breakdown = if technique == ShadowTechnique::Ssss {
                    breakdown.join(", ")
                } else {
                    String::new()
                };
                measured.push((technique, name, main, ssss, error, breakdown));
            }
            harness
                .world_mut()
                .insert_resource(SsssDilationFilter::Auto);
            let hard_main = measured[0].2;
            for (technique, name, main, ssss, error, breakdown) in &measured {
                let passes = if *technique == ShadowTechnique::Ssss {
                    *ssss
                } else {
                    0.0
                };
                let cost = main + passes - hard_main;
                rows.push(format!(
                    "{{\"size\": [{}, {}], \"light\": \"{}{label}\", \"light_size_rad\": {light_size}, \"technique\": \"{}\", \"main_pass_ms\": {main:.3}, \"ssss_passes_ms\": {passes:.3}, \"cost_over_hard_ms\": {cost:.3}, \"rmse_vs_reference\": {error:.5}, \"ssss_pass_ms\": {{{breakdown}}}}}",
                    size.x,
                    size.y,
                    if spot { "spot " } else { "" },
                    name
                ));
                eprintln!("{}", rows.last().unwrap());
            }
        }
    }
    println!(
        "{{\"frames\": {frames}, \"rows\": [\n  {}\n]}}",
        rows.join(",\n  ")
    );
    AppExit::Success
}
