//! The forest benchmark (Gumbau 2011, table 3.5), headless, one process: the same forest drawn
//! three ways, each measured over N frames after it settled —
//!
//! - `full`: every tree in view (frustum, nearer than `far`) with every leaf (the reference);
//! - `manager`: the urgency-ranked manager with LoD caches;
//! - `visibility_range`: what a Bevy user would build — three decimated leaf meshes per type
//!   switched by `VisibilityRange` (full / 40 % / 12 %, leaves enlarged to keep the area).
//!
//! A `no_trees` row (the forest hidden) gives the cost every mode pays regardless (ground, sky,
//! frame overhead), so `tree_ms` is what the trees themselves cost.
//!
//! Reports frame time (median, p95), leaf triangles, the manager's CPU time and counters, and
//! image error of each against `full` rendered in the same run: per-pixel RMSE and RMSE of 8×8
//! block means (leaves are a pixel or two far away, so per-pixel error mostly counts which
//! leaves were dropped; block means compare the forest's density). Prints one JSON object.
//!
//! ```text
//! cargo run --release --example forest_bench -- [--forest dense|sparse] [--leaf-scale F]
//!     [--no-borrowing] [--exponent N] [--frames N] [--size WxH] [--screenshot DIR]
//! ```
//! `--leaf-scale` scales the thesis' leaf counts (default 0.1: the full counts give a software
//! rasteriser frames of tens of seconds at full detail).

use bevy::camera::visibility::VisibilityRange;
use bevy::prelude::*;
use bevy_nature::foliage::ForestSettings;
use bevy_nature::foliage::forest::systems::{ForestState, LEAF_TRIANGLES, MANAGER_MS};
use bevy_nature::forest_scene::{
    ForestArgs, ForestScene, HlodForestRoot, ManagedForestRoot, camera_transform, spawn_forest,
};
use bevy_nature_harness::compare::{Comparison, RgbaImage};
use bevy_nature_harness::headless::HarnessConfig;
use bevy_nature_harness::{ExampleArgs, RenderHarness, require_adapter};

struct Measured {
    name: &'static str,
    median_ms: f64,
    p95_ms: f64,
    leaf_triangles: f64,
    manager_ms: f64,
    image: RgbaImage,
}

fn main() {
    // Our own flags first; the rest are the runner's.
    let ForestArgs {
        kind,
        leaf_scale,
        rest,
    } = ForestArgs::parse(std::env::args().skip(1), 0.1).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let mut borrowing = true;
    let mut exponent = 1.0f32;
    let mut runner_flags = Vec::new();
    let mut rest = rest.into_iter();
    while let Some(arg) = rest.next() {
        match arg.as_str() {
            "--no-borrowing" => borrowing = false,
            "--exponent" => {
                let v = rest.next().unwrap_or_default();
                exponent = v
                    .parse()
                    .ok()
                    .filter(|n: &f32| *n > 0.0)
                    .unwrap_or_else(|| {
                        eprintln!("--exponent takes a positive number, not '{v}'");
                        std::process::exit(2)
                    });
            }
            _ => runner_flags.push(arg),
        }
    }
    let rest = runner_flags;
    let args = ExampleArgs::parse_from(rest).unwrap_or_else(|e| {
        eprintln!("{e} [--forest dense|sparse] [--leaf-scale F] [--no-borrowing] [--exponent N]");
        std::process::exit(2)
    });
    let size = args.size.unwrap_or(UVec2::new(480, 270));
    let frames = args.frames.unwrap_or(8);
    if require_adapter("forest_bench").is_none() {
        std::process::exit(1);
    }
    let mut harness = RenderHarness::new(HarnessConfig::sized(size.x, size.y)).expect("harness");
    harness
        .app_mut()
        .add_plugins(bevy_nature::NaturePlugins)
        .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)))
        .insert_resource(ForestScene {
            kind,
            leaf_scale,
            with_hlod: true,
        })
        .insert_resource(ForestSettings {
            budget: bevy_nature::foliage::ForestBudget::Extractions(64),
            borrowing,
            exponent,
            ..default()
        })
        .add_systems(Startup, spawn_forest);
    harness
        .world_mut()
        .spawn((Camera3d::default(), Msaa::Off, camera_transform()));
    harness.wait_until_ready().expect("scene ready");

    let show = |harness: &mut RenderHarness, managed: bool, manager_on: bool| {
        let world = harness.world_mut();
        world.resource_mut::<ForestSettings>().enabled = manager_on;
        let mut roots =
            world.query::<(&mut Visibility, Has<ManagedForestRoot>, Has<HlodForestRoot>)>();
        for (mut v, is_managed, is_hlod) in roots.iter_mut(world) {
            if is_managed {
                *v = if managed {
                    Visibility::Inherited
                } else {
                    Visibility::Hidden
                };
            } else if is_hlod {
                *v = if managed {
                    Visibility::Hidden
                } else {
                    Visibility::Inherited
                };
            }
        }
        // Settle: the manager serves its backlog, new pipelines compile.
        for _ in 0..400 {
            harness.step();
            if harness
                .world_mut()
                .resource::<ForestState>()
                .last
                .candidates
                == 0
            {
                break;
            }
        }
        harness.wait_until_ready().expect("ready");
    };
    let measure = |harness: &mut RenderHarness, name: &'static str| {
        harness.reset_timing();
        harness.run_frames(frames).unwrap();
        let stats = harness.frame_stats();
        let leaf_triangles = harness.diagnostic(&LEAF_TRIANGLES).unwrap_or(0.0);
        let manager_ms = harness.diagnostic(&MANAGER_MS).unwrap_or(0.0);
        let image = harness.render().unwrap();
        Measured {
            name,
            median_ms: stats.median_ms,
            p95_ms: stats.p95_ms,
            leaf_triangles,
            manager_ms,
            image,
        }
    };
    // The frame without any tree leaves or bark: what every mode pays regardless.
    {
        let world = harness.world_mut();
        let mut roots = world
            .query_filtered::<&mut Visibility, Or<(With<ManagedForestRoot>, With<HlodForestRoot>)>>(
            );
        for mut v in roots.iter_mut(world) {
            *v = Visibility::Hidden;
        }
    }
    for _ in 0..3 {
        harness.step();
    }
    let mut empty = measure(&mut harness, "no_trees");
    empty.leaf_triangles = 0.0;
    show(&mut harness, true, false);
    let full = measure(&mut harness, "full");
    let visible = harness.world_mut().resource::<ForestState>().last.visible;
    show(&mut harness, true, true);
    let managed = measure(&mut harness, "manager");
    let report = harness.world_mut().resource::<ForestState>().last;
    show(&mut harness, false, true);
    let mut hlod = measure(&mut harness, "visibility_range");
    // The baseline's leaves are ordinary meshes: count the triangles of the levels drawn.
    hlod.leaf_triangles = {
        let world = harness.world_mut();
        let mut levels =
            world.query_filtered::<(&Mesh3d, &ViewVisibility), With<VisibilityRange>>();
        let drawn: Vec<Handle<Mesh>> = levels
            .iter(world)
            .filter(|(_, v)| v.get())
            .map(|(m, _)| m.0.clone())
            .collect();
        let meshes = world.resource::<Assets<Mesh>>();
        drawn
            .iter()
            .filter_map(|h| meshes.get(h))
            .map(|m| m.indices().map_or(0, |i| i.len()) as f64 / 3.0)
            .sum()
    };

    if let Some(dir) = &args.screenshot {
        std::fs::create_dir_all(dir).ok();
        for m in [&full, &managed, &hlod] {
            m.image.save_png(dir.join(format!("{}.png", m.name))).ok();
        }
    }
    let rows: Vec<String> = [&empty, &full, &managed, &hlod]
        .iter()
        .map(|m| {
            let cmp = Comparison::new(format!("forest_bench/{}", m.name), &m.image, &full.image);
            let blocks = Comparison::new(
                format!("forest_bench/{}_8x8", m.name),
                &m.image.box_downsample(8),
                &full.image.box_downsample(8),
            );
            format!(
                "{{\"mode\": \"{}\", \"frame_ms_median\": {:.1}, \"frame_ms_p95\": {:.1}, \"speedup_vs_full\": {:.2}, \"tree_ms\": {:.1}, \"tree_speedup_vs_full\": {:.2}, \"leaf_triangles\": {}, \"manager_cpu_ms\": {:.3}, \"rmse\": {:.4}, \"rmse_8x8\": {:.4}, \"ssim\": {:.3}}}",
                m.name,
                m.median_ms,
                m.p95_ms,
                full.median_ms / m.median_ms.max(1e-9),
                m.median_ms - empty.median_ms,
                (full.median_ms - empty.median_ms) / (m.median_ms - empty.median_ms).max(1e-9),
                m.leaf_triangles,
                m.manager_ms,
                cmp.rmse,
                blocks.rmse,
                cmp.ssim,
            )
        })
        .collect();
    println!(
        "{{\"bench\": \"forest\", \"forest\": \"{kind:?}\", \"trees\": {}, \"in_view\": {visible}, \"leaf_scale\": {leaf_scale}, \"borrowing\": {borrowing}, \"exponent\": {exponent}, \"size\": [{}, {}], \"frames\": {frames}, \"adapter\": {:?}, \"manager_last_frame\": {{\"visible\": {}, \"extractions\": {}, \"borrows\": {}}}, \"rows\": [\n  {}\n]}}",
        kind.tree_count(),
        size.x,
        size.y,
        harness
            .adapter()
            .map(|a| a.name.clone())
            .unwrap_or_default(),
        report.visible,
        report.extractions,
        report.borrows,
        rows.join(",\n  ")
    );
}
