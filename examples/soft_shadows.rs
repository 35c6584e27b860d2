//! Soft shadows three ways on one scene: Bevy's hard shadows, Bevy's PCSS and Screen Space Soft
//! Shadows (keys 1 / 2 / 3, or `technique` in the panel, which also shows the live GPU cost:
//! `render/ssss/elapsed_gpu` for the SSSS passes, `render/main_opaque_pass_3d/elapsed_gpu` where
//! PCSS filters).
//!
//! ```text
//! cargo run --release --example soft_shadows                 # windowed, egui panel
//! cargo run --example soft_shadows -- --headless --frames 30 --stats ssss.json
//! cargo run --example soft_shadows -- --bench [--frames N] [--stats FILE] [--scenes poles,palm]
//! cargo run --example soft_shadows -- --bench --spot          # the same under a lamp
//! cargo run --example soft_shadows -- --bench --filtered      # the filterable shadow maps
//! cargo run --example soft_shadows -- --bench --filtered --spot  # ... on the lamp
//! ```
//!
//! Key 6 (technique 3) shadows the sun (or the lamp) with a filterable shadow map, key 7 (or
//! `filtered` in the panel) cycles its method: the thesis' Gaussian and power CDFs, VSM, ESM,
//! four moments.
//! Key 4 (or `spot` in the panel) switches from the sun to a lamp (a spot light) above the scene,
//! key 5 (`scene`) cycles from the posts to a canopy of three trees and to a palm on a beach (a
//! thin trunk and fronds high over the sand: large penumbrae over thin blockers).
//!
//! `--bench` measures, in one process and for small / medium / large light sizes, on the pole,
//! canopy and palm scenes (640×360 unless `--size`), each technique's GPU cost over hard
//! shadows and its image's RMSE against an area-light reference rendered in the same run (48
//! hard-shadowed suns jittered over the light's disk, averaged in linear light — or with
//! `--spot`, 48 lamps spread over the lamp's disk), all rendered without tonemapping so the
//! average is one of radiance (a tonemapper's curve would bend it). GPU time is the whole frame from timestamp
//! queries written before and after everything the frame submits (shadow maps, prepasses, main
//! pass, TAA, the SSSS passes: `bevy_nature_harness::frame_timer`), so a technique's cost
//! includes everything it turns on; the GPU is warmed up before anything is timed; without timestamp queries the bench says so
//! and exits with an error. Rows: hard; Bevy's PCSS at the best of a sweep of its size per light;
//! Bevy's PCSS as Bevy intends it (`ShadowFilteringMethod::Temporal` under TAA, compared once TAA
//! has converged); SSSS on the classified tiles (with the active-tile fraction and the blur's cost
//! per active tile) and on every tile. Every scene's baseline rows run before SSSS first runs.
//! `--stats FILE` writes the rows as JSON (`"timing": "timestamps"`).
//!
//! `--bench --filtered [--spot]` measures the filterable shadow maps instead, each scene in a
//! harness of its own (their receivers replace the standard materials): per light size, hard
//! shadows and each
//! method with its pre-filter's σ swept (best RMSE against the same area-light reference timed);
//! then the cost of each method over hard shadows at σ = 2 texels with 1024² and 2048² maps.

use bevy::anti_alias::taa::TemporalAntiAliasing;
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::light::{DirectionalLightShadowMap, ShadowFilteringMethod};
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy_nature::shadow_scene::{
    DemoLamp, DemoSun, FILTERED_METHODS, LAMP_AIM, LAMP_POSITION, PCSS_SIZE_PER_RADIAN,
    SCENE_NAMES, ShadowDemo, ShadowTechnique, add_shadow_demo, lamp_diameter, lamp_transform,
    spawn_shadow_scene, sun_direction,
};
use bevy_nature::soft_shadows::ScreenSpaceSoftShadows;
use bevy_nature::soft_shadows::filterable::FilteredShadowMap;
use bevy_nature::soft_shadows::filterable::filter::FilterableMethod;
use bevy_nature::soft_shadows::reference::{
    LinearAverage, jittered_directions, jittered_positions, srgb_to_linear,
};
use bevy_nature::soft_shadows::ssss::render::SsssTileReadback;
use bevy_nature_harness::headless::HarnessConfig;
use bevy_nature_harness::{ExampleArgs, ExampleRunner, RenderHarness, require_adapter};

fn main() -> AppExit {
    let mut rest: Vec<String> = std::env::args().skip(1).collect();
    let bench = rest.iter().any(|a| a == "--bench");
    let spot = rest.iter().any(|a| a == "--spot");
    let filtered = rest.iter().any(|a| a == "--filtered");
    rest.retain(|a| a != "--bench" && a != "--spot" && a != "--filtered");
    // `--scenes poles,palm`: the bench's scenes (all by default).
    let mut scenes: Vec<String> = SCENE_NAMES.iter().map(|s| s.to_string()).collect();
    if let Some(i) = rest.iter().position(|a| a == "--scenes") {
        let Some(list) = rest.get(i + 1).cloned() else {
            eprintln!("--scenes needs a list, e.g. --scenes poles,palm");
            std::process::exit(2)
        };
        scenes = list.split(',').map(str::to_string).collect();
        if let Some(bad) = scenes.iter().find(|s| !SCENE_NAMES.contains(&s.as_str())) {
            eprintln!(
                "--scenes: unknown scene '{bad}' (scenes: {})",
                SCENE_NAMES.join(", ")
            );
            std::process::exit(2)
        }
        rest.drain(i..=i + 1);
    }
    let args = ExampleArgs::parse_from(rest).unwrap_or_else(|e| {
        eprintln!("{e} [--bench] [--spot] [--filtered] [--scenes poles,canopy,palm]");
        std::process::exit(2)
    });
    if bench {
        return run_bench(&args, spot, filtered, &scenes);
    }
    ExampleRunner::with_args("soft_shadows", args)
        .inspect_resource::<ShadowDemo>()
        .inspect_component::<ScreenSpaceSoftShadows>()
        .inspect_component::<FilteredShadowMap>()
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

/// One measured row of the bench.
struct Row {
    scene: &'static str,
    light: String,
    light_size: f32,
    technique: &'static str,
    params: String,
    frame_gpu_ms: f64,
    rmse: f64,
    /// SSSS rows: active tiles / all tiles, and the blur passes' GPU time.
    tiles: Option<(f64, usize, f64)>,
}

/// The GPU time of the whole frame (timestamps bracketing everything it submits, median over
/// `frames` after `settle` frames) and the image's RMSE against `reference`.
fn measure(
    harness: &mut RenderHarness,
    frames: u32,
    settle: u32,
    reference: &[f32],
) -> Result<(f64, f64), String> {
    harness
        .run_frames(settle.max(4))
        .map_err(|e| e.to_string())?;
    harness.reset_timing();
    // Whole-frame timestamps are read back a frame or two late: two more frames of the same
    // configuration bring the last ones in.
    harness.run_frames(frames + 2).map_err(|e| e.to_string())?;
    let frame = harness.gpu_frame_time_ms()?;
    let image = linear(&harness.render().map_err(|e| e.to_string())?.data);
    Ok((frame, rmse(&image, reference)))
}

/// The SSSS classification's active tiles of the last frame, and all tiles.
fn active_tiles(harness: &mut RenderHarness) -> Result<(usize, usize), String> {
    let mut grid = UVec2::ZERO;
    let bytes = harness
        .read_render_buffer(|world| {
            let r = world.get_resource::<SsssTileReadback>()?;
            grid = r.grid;
            r.args.clone()
        })
        .map_err(|e| e.to_string())?;
    let active = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]) as usize;
    Ok((active, (grid.x * grid.y) as usize))
}

fn set_technique(harness: &mut RenderHarness, technique: ShadowTechnique, light_size: f32) {
    let mut demo = harness.world_mut().resource_mut::<ShadowDemo>();
    demo.technique = ShadowTechnique::ALL
        .iter()
        .position(|t| *t == technique)
        .unwrap() as u32;
    demo.light_size = light_size;
    settle(harness);
}

/// Lets a change take effect and every pipeline it needs compile before anything is rendered:
/// a technique switch (or a camera losing its prepasses) specialises new pipelines, which a
/// real GPU's driver compiles over many of its fast frames — meanwhile Bevy skips the draws
/// that need them, and a render would miss meshes.
fn settle(harness: &mut RenderHarness) {
    if harness.run_frames(2).is_ok() {
        harness.wait_until_ready().ok();
    }
}

/// The area-light reference: hard shadows from suns jittered over the light's disk (or lamps
/// spread over the lamp's disk), averaged in linear light.
fn reference(harness: &mut RenderHarness, light_size: f32, spot: bool) -> Result<Vec<f32>, String> {
    set_technique(harness, ShadowTechnique::Hard, light_size);
    harness.run_frames(3).map_err(|e| e.to_string())?;
    let world = harness.world_mut();
    let sun = world
        .query_filtered::<Entity, With<DemoSun>>()
        .single(world)
        .unwrap();
    let lamp = world
        .query_filtered::<Entity, With<DemoLamp>>()
        .single(world)
        .unwrap();
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
        average.add(&harness.render().map_err(|e| e.to_string())?.data);
    }
    *harness.world_mut().get_mut::<Transform>(sun).unwrap() =
        Transform::default().looking_to(-sun_direction(), Vec3::Y);
    *harness.world_mut().get_mut::<Transform>(lamp).unwrap() = lamp_transform(LAMP_POSITION);
    Ok(average.linear())
}

/// The scene's camera (not an offscreen one of a plugin).
fn scene_camera(harness: &mut RenderHarness) -> Entity {
    let world = harness.world_mut();
    world
        .query_filtered::<Entity, (With<Camera3d>, With<ShadowFilteringMethod>)>()
        .single(world)
        .unwrap()
}

const LIGHTS: [(&str, f32); 3] = [("small", 0.03), ("medium", 0.1), ("large", 0.25)];
/// PCSS sizes swept, as factors of the demo's default size per radian.
const PCSS_FACTORS: [f32; 7] = [0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0];
/// Frames TAA gets to converge before the temporal PCSS row is timed and compared.
const TAA_FRAMES: u32 = 48;

/// A harness showing `scene`, ready.
fn scene_harness(scene: u32, size: UVec2, spot: bool) -> Result<RenderHarness, String> {
    let mut harness =
        RenderHarness::new(HarnessConfig::sized(size.x, size.y)).map_err(|e| e.to_string())?;
    harness
        .app_mut()
        .add_plugins(bevy_nature::soft_shadows::SoftShadowsPlugin)
        .add_systems(Startup, spawn_shadow_scene);
    add_shadow_demo(harness.app_mut());
    {
        let mut demo = harness.world_mut().resource_mut::<ShadowDemo>();
        demo.spot = spot;
        demo.scene = scene;
    }
    harness.wait_until_ready().map_err(|e| e.to_string())?;
    // Linear output for every row: the reference averages radiance, and each technique's image
    // is compared with it as rendered (the interactive example keeps Bevy's tonemapping).
    let camera = scene_camera(&mut harness);
    harness
        .world_mut()
        .entity_mut(camera)
        .insert((Tonemapping::None, DebandDither::Disabled));
    harness.wait_until_ready().map_err(|e| e.to_string())?;
    // A real GPU raises its clocks under load: warm it up (60 frames and at least 2 s — a fast
    // GPU's 60 frames take a tenth of that) before anything is timed.
    let start = std::time::Instant::now();
    let mut frames = 0;
    while frames < 60 || start.elapsed().as_secs_f32() < 2.0 {
        harness.run_frames(10).map_err(|e| e.to_string())?;
        frames += 10;
    }
    Ok(harness)
}

/// A harness for `scene` (under the lamp with `spot`) and its area-light reference for each of
/// [`LIGHTS`], with progress on stderr (`mode`: the bench's flags).
fn scene_and_references(
    scene: u32,
    size: UVec2,
    spot: bool,
    mode: &str,
) -> Result<(RenderHarness, Vec<Vec<f32>>), String> {
    let scene_name = SCENE_NAMES[scene.min(2) as usize];
    let mut harness = scene_harness(scene, size, spot)?;
    let mut references = Vec::new();
    for (label, light_size) in LIGHTS {
        eprintln!(
            "soft_shadows {mode}: {scene_name}, {label} light: area-light reference (48 renders)"
        );
        references.push(reference(&mut harness, light_size, spot)?);
    }
    Ok((harness, references))
}

/// One scene: references first, then every baseline row (before SSSS ever runs: receivers and
/// camera untouched), then the SSSS rows.
fn bench_scene(
    scene: u32,
    size: UVec2,
    frames: u32,
    spot: bool,
    rows: &mut Vec<Row>,
) -> Result<(), String> {
    let scene_name = SCENE_NAMES[scene.min(2) as usize];
    let (mut harness, references) = scene_and_references(scene, size, spot, "--bench")?;
    let light_name = |label: &str| format!("{}{label}", if spot { "spot " } else { "" });
    let push = |rows: &mut Vec<Row>, row: Row| {
        eprintln!(
            "  {:<7} {:<8} {:<20} {:<26} GPU frame {:>8.2} ms  RMSE {:.5}{}",
            row.scene,
            row.light,
            row.technique,
            row.params,
            row.frame_gpu_ms,
            row.rmse,
            row.tiles
                .map(|(f, n, _)| format!("  active tiles {:.1} % ({n})", 100.0 * f))
                .unwrap_or_default()
        );
        rows.push(row);
    };
    let row = |technique, light: (&str, f32), params: String, (frame, rmse): (f64, f64)| Row {
        scene: scene_name,
        light: light_name(light.0),
        light_size: light.1,
        technique,
        params,
        frame_gpu_ms: frame,
        rmse,
        tiles: None,
    };
    // Hard shadows.
    for (light, reference) in LIGHTS.iter().zip(&references) {
        set_technique(&mut harness, ShadowTechnique::Hard, light.1);
        let m = measure(&mut harness, frames, 8, reference)?;
        push(rows, row("hard", *light, String::new(), m));
    }
    // Bevy's PCSS, its size swept per light (best RMSE timed), then as Bevy intends it: the
    // temporal filter under TAA, at the best size, once TAA has converged.
    let mut best_pcss = Vec::new();
    for (light, reference) in LIGHTS.iter().zip(&references) {
        set_technique(&mut harness, ShadowTechnique::Pcss, light.1);
        let mut best = (f64::INFINITY, 1.0f32);
        let mut sweep = Vec::new();
        for factor in PCSS_FACTORS {
            harness
                .world_mut()
                .resource_mut::<ShadowDemo>()
                .pcss_size_per_radian = factor * PCSS_SIZE_PER_RADIAN;
            harness.render().map_err(|e| e.to_string())?;
            let image = linear(&harness.render().map_err(|e| e.to_string())?.data);
            let e = rmse(&image, reference);
            sweep.push(format!(
                "{:.2}:{e:.5}",
                factor * PCSS_SIZE_PER_RADIAN * light.1
            ));
            if e < best.0 {
                best = (e, factor);
            }
        }
        let pcss_size = best.1 * PCSS_SIZE_PER_RADIAN * light.1;
        harness
            .world_mut()
            .resource_mut::<ShadowDemo>()
            .pcss_size_per_radian = best.1 * PCSS_SIZE_PER_RADIAN;
        let m = measure(&mut harness, frames, 4, reference)?;
        eprintln!("    PCSS sweep (soft_shadow_size:RMSE) {}", sweep.join(" "));
        push(
            rows,
            row(
                "pcss",
                *light,
                format!("soft_shadow_size {pcss_size:.2}"),
                m,
            ),
        );
        best_pcss.push(best.1);
    }
    // PCSS as Bevy intends it, in a harness of its own (taking TAA off a camera again trips
    // Bevy 0.19's motion-vector prepass), at each light's best size.
    {
        let mut taa = scene_harness(scene, size, spot)?;
        let camera = scene_camera(&mut taa);
        taa.world_mut().entity_mut(camera).insert((
            TemporalAntiAliasing::default(),
            ShadowFilteringMethod::Temporal,
        ));
        settle(&mut taa);
        for ((light, reference), factor) in LIGHTS.iter().zip(&references).zip(&best_pcss) {
            set_technique(&mut taa, ShadowTechnique::Pcss, light.1);
            taa.world_mut()
                .resource_mut::<ShadowDemo>()
                .pcss_size_per_radian = factor * PCSS_SIZE_PER_RADIAN;
            let m = measure(&mut taa, frames, TAA_FRAMES, reference)?;
            let pcss_size = factor * PCSS_SIZE_PER_RADIAN * light.1;
            push(
                rows,
                row(
                    "pcss_temporal_taa",
                    *light,
                    format!("soft_shadow_size {pcss_size:.2}, TAA"),
                    m,
                ),
            );
        }
    }
    harness
        .world_mut()
        .resource_mut::<ShadowDemo>()
        .pcss_size_per_radian = PCSS_SIZE_PER_RADIAN;
    // Where SSSS's cost goes: hard shadows with the depth and normal prepasses SSSS turns on
    // (its receivers need them before the main pass), nothing else of SSSS. The SSSS rows below
    // run with the same prepasses.
    {
        let camera = scene_camera(&mut harness);
        harness.world_mut().entity_mut(camera).insert((
            bevy::core_pipeline::prepass::DepthPrepass,
            bevy::core_pipeline::prepass::NormalPrepass,
        ));
        settle(&mut harness);
        for (light, reference) in LIGHTS.iter().zip(&references) {
            set_technique(&mut harness, ShadowTechnique::Hard, light.1);
            let m = measure(&mut harness, frames, 8, reference)?;
            push(
                rows,
                row(
                    "hard_with_prepasses",
                    *light,
                    "depth + normal prepass".into(),
                    m,
                ),
            );
        }
    }
    // SSSS: classified tiles (the default), then every tile blurred (the same image).
    harness
        .app_mut()
        .get_sub_app_mut(RenderApp)
        .unwrap()
        .world_mut()
        .init_resource::<SsssTileReadback>();
    for (light, reference) in LIGHTS.iter().zip(&references) {
        for all_tiles in [false, true] {
            set_technique(&mut harness, ShadowTechnique::Ssss, light.1);
            harness
                .world_mut()
                .resource_mut::<ShadowDemo>()
                .ssss_all_tiles = all_tiles;
            settle(&mut harness);
            let m = measure(&mut harness, frames, 8, reference)?;
            let blur = harness.gpu_pass_time_ms("ssss/ssss_blur_h")?
                + harness.gpu_pass_time_ms("ssss/ssss_blur_v")?;
            let (active, total) = active_tiles(&mut harness)?;
            let mut r = row(
                if all_tiles { "ssss_all_tiles" } else { "ssss" },
                *light,
                "taps_per_side 11, max_kernel_px 96".into(),
                m,
            );
            r.tiles = Some((active as f64 / total as f64, active, blur));
            push(rows, r);
        }
    }
    harness
        .world_mut()
        .resource_mut::<ShadowDemo>()
        .ssss_all_tiles = false;
    Ok(())
}

/// The pre-filter's σ (shadow-map texels) swept per light for the filterable methods.
const FILTER_SIGMAS: [f32; 5] = [0.5, 1.0, 2.0, 4.0, 8.0];

/// A short name for a filterable method.
fn method_name(method: FilterableMethod) -> &'static str {
    match method {
        FilterableMethod::GaussianCdf => "gaussian_cdf",
        FilterableMethod::PowerCdf => "power_cdf",
        FilterableMethod::Variance => "vsm",
        FilterableMethod::Exponential { .. } => "esm",
        FilterableMethod::Moments4 => "msm4",
    }
}

/// One scene's filterable shadow maps (on the sun, or with `spot` the lamp): references, hard
/// shadows, each method swept over its σ per light (the best timed), then each method's cost at
/// 1024² and 2048² maps.
fn bench_filtered(
    scene: u32,
    size: UVec2,
    frames: u32,
    spot: bool,
    rows: &mut Vec<Row>,
) -> Result<(), String> {
    let scene_name = SCENE_NAMES[scene.min(2) as usize];
    let (mut harness, references) = scene_and_references(scene, size, spot, "--bench --filtered")?;
    let mut push = |row: Row| {
        eprintln!(
            "  {:<7} {:<8} {:<20} {:<26} GPU frame {:>8.2} ms  RMSE {:.5}",
            row.scene, row.light, row.technique, row.params, row.frame_gpu_ms, row.rmse
        );
        rows.push(row);
    };
    let row = |technique, light: (&str, f32), params: String, (frame, rmse): (f64, f64)| Row {
        scene: scene_name,
        light: format!("{}{}", if spot { "spot " } else { "" }, light.0),
        light_size: light.1,
        technique,
        params,
        frame_gpu_ms: frame,
        rmse,
        tiles: None,
    };
    let set_map = |harness: &mut RenderHarness, side: usize| {
        harness
            .world_mut()
            .insert_resource(DirectionalLightShadowMap { size: side });
        settle(harness);
    };
    set_map(&mut harness, 2048);
    for (light, reference) in LIGHTS.iter().zip(&references) {
        set_technique(&mut harness, ShadowTechnique::Hard, light.1);
        let m = measure(&mut harness, frames, 8, reference)?;
        push(row("hard", *light, "map 2048²".into(), m));
    }
    for method in FILTERED_METHODS {
        for (light, reference) in LIGHTS.iter().zip(&references) {
            set_technique(&mut harness, ShadowTechnique::Filtered, light.1);
            let mut best = (f64::INFINITY, FILTER_SIGMAS[0]);
            let mut sweep = Vec::new();
            for sigma in FILTER_SIGMAS {
                harness.world_mut().resource_mut::<ShadowDemo>().filtered = FilteredShadowMap {
                    method,
                    blur_sigma: sigma,
                };
                settle(&mut harness);
                let image = linear(&harness.render().map_err(|e| e.to_string())?.data);
                let e = rmse(&image, reference);
                sweep.push(format!("{sigma}:{e:.5}"));
                if e < best.0 {
                    best = (e, sigma);
                }
            }
            harness.world_mut().resource_mut::<ShadowDemo>().filtered = FilteredShadowMap {
                method,
                blur_sigma: best.1,
            };
            settle(&mut harness);
            let m = measure(&mut harness, frames, 8, reference)?;
            eprintln!(
                "    {} sweep (σ:RMSE) {}",
                method_name(method),
                sweep.join(" ")
            );
            push(row(
                method_name(method),
                *light,
                format!("map 2048², σ {}", best.1),
                m,
            ));
        }
    }
    // Cost: every method at one σ, over hard shadows of the same map size (medium light).
    let (light, reference) = (LIGHTS[1], &references[1]);
    for side in [1024usize, 2048] {
        set_map(&mut harness, side);
        set_technique(&mut harness, ShadowTechnique::Hard, light.1);
        let m = measure(&mut harness, frames, 8, reference)?;
        // The cost rows compare with the hard row of their own map size.
        let mut r = row("hard", light, format!("map {side}²"), m);
        r.light = format!("{} {side}", r.light);
        push(r);
        for method in FILTERED_METHODS {
            set_technique(&mut harness, ShadowTechnique::Filtered, light.1);
            harness.world_mut().resource_mut::<ShadowDemo>().filtered = FilteredShadowMap {
                method,
                blur_sigma: 2.0,
            };
            settle(&mut harness);
            let m = measure(&mut harness, frames, 8, reference)?;
            let technique = match method {
                FilterableMethod::GaussianCdf => "cost_gaussian_cdf",
                FilterableMethod::PowerCdf => "cost_power_cdf",
                FilterableMethod::Variance => "cost_vsm",
                FilterableMethod::Exponential { .. } => "cost_esm",
                FilterableMethod::Moments4 => "cost_msm4",
            };
            let mut r = row(technique, light, format!("map {side}², σ 2"), m);
            r.light = format!("{} {side}", r.light);
            push(r);
        }
    }
    set_map(&mut harness, 2048);
    Ok(())
}

fn run_bench(args: &ExampleArgs, spot: bool, filtered: bool, scenes: &[String]) -> AppExit {
    let Some(adapter) = require_adapter("soft_shadows") else {
        return AppExit::error();
    };
    if !adapter.timestamp_queries {
        eprintln!(
            "soft_shadows --bench: the adapter '{}' has no GPU timestamp queries, so GPU costs \
             cannot be measured; no figures are reported",
            adapter.name
        );
        return AppExit::error();
    }
    let frames = args.frames.unwrap_or(12);
    let size = args.size.unwrap_or(UVec2::new(640, 360));
    let mut rows = Vec::new();
    for scene in 0..SCENE_NAMES.len() as u32 {
        if !scenes.iter().any(|s| s == SCENE_NAMES[scene as usize]) {
            continue;
        }
        let result = if filtered {
            bench_filtered(scene, size, frames, spot, &mut rows)
        } else {
            bench_scene(scene, size, frames, spot, &mut rows)
        };
        if let Err(e) = result {
            eprintln!("soft_shadows --bench: {e}");
            return AppExit::error();
        }
    }
    // Cost over hard shadows: the whole GPU frame against the hard row of the same scene and
    // light (prepasses, TAA and the SSSS passes included).
    let hard: Vec<(&str, String, f64)> = rows
        .iter()
        .filter(|r| r.technique == "hard")
        .map(|r| (r.scene, r.light.clone(), r.frame_gpu_ms))
        .collect();
    let json_rows: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            let hard_ms = hard
                .iter()
                .find(|(s, l, _)| *s == r.scene && *l == r.light)
                .map(|h| h.2)
                .unwrap_or(f64::NAN);
            let cost = r.frame_gpu_ms - hard_ms;
            let mut row = serde_json::json!({
                "scene": r.scene,
                "size": [size.x, size.y],
                "light": r.light,
                "light_size_rad": r.light_size,
                "technique": r.technique,
                "params": r.params,
                "frame_gpu_ms": r.frame_gpu_ms,
                "cost_over_hard_ms": cost,
                "rmse": r.rmse,
                "active_tile_fraction": r.tiles.map(|t| t.0),
            });
            if let Some((_, active, blur)) = r.tiles {
                row["active_tiles"] = active.into();
                row["blur_passes_ms"] = blur.into();
                row["blur_us_per_active_tile"] = (1000.0 * blur / active.max(1) as f64).into();
            }
            row
        })
        .collect();
    let headline_technique = if filtered {
        "cost_gaussian_cdf"
    } else {
        "ssss"
    };
    let headline: serde_json::Map<String, serde_json::Value> = json_rows
        .iter()
        .filter(|r| r["scene"] == "poles" && r["technique"] == headline_technique)
        .map(|r| {
            (
                r["light"].as_str().unwrap_or_default().to_string(),
                r["cost_over_hard_ms"].clone(),
            )
        })
        .collect();
    let out = serde_json::json!({
        "timing": "timestamps",
        "adapter": adapter.name,
        "frames": frames,
        "headline": {format!("{headline_technique}_cost_over_hard_ms_on_poles"): headline},
        "rows": json_rows,
    });
    let text = serde_json::to_string_pretty(&out).unwrap();
    eprintln!(
        "HEADLINE {headline_technique}_cost_over_hard_ms_on_poles ({}x{}, GPU timestamps): {}",
        size.x,
        size.y,
        serde_json::to_string(&headline).unwrap()
    );
    if let Some(path) = &args.stats
        && let Err(e) = bevy_nature_harness::stats::write_atomically(path, &text)
    {
        eprintln!("soft_shadows --bench: {e}");
        return AppExit::error();
    }
    println!("{text}");
    AppExit::Success
}
