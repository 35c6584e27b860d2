//! The cost of the tree lighting (Boulanger 2008, ch. 5) on the GPU, headless, one process: the
//! same pruned forest drawn with Bevy's PBR leaf shading (the baseline: nothing of the tree
//! lighting switched on), with the tree lighting without its bounce, and with the whole tree
//! lighting (sky, sun, one bounce of sunlight), in turns, several rounds.
//!
//! Each configuration's frames: GPU frame time and main-pass time from GPU timestamps (`timing:
//! "gpu-timestamps"`; the bench refuses to run on an adapter without them — there is no other
//! clock to fall back on), and GPU-synchronised frame time beside. The headline,
//! `tree_lighting_over_bevy_gpu_frame`, is the tree lighting's GPU frame time over Bevy's
//! shading's (< 1: cheaper); `bounce_share_of_frame` is what the bounce adds over the frame
//! without it, as a share of the whole tree-lit frame (the thesis' budget for the indirect part:
//! under 7 %).
//!
//! ```text
//! cargo run --release --example tree_lighting_bench -- [--trees N] [--leaves N] [--rounds N]
//!     [--frames N] [--size WxH] [--stats FILE]
//! ```

use bevy::prelude::*;
use bevy_nature::foliage::TreeLightingSettings;
use bevy_nature::foliage::pruning::bake::{BakeSettings, BakedFoliage, CellCount, bake};
use bevy_nature::foliage::pruning::components::PrunedFoliage;
use bevy_nature::foliage::pruning::material::{LeafMaterial, leaf_material};
use bevy_nature::foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_nature::foliage::pruning::spawn::default_leaf_material;
use bevy_nature::foliage::pruning::systems::TRIANGLES_DRAWN;
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::headless::HarnessConfig;
use std::path::PathBuf;

struct Args {
    trees: u32,
    leaves: usize,
    rounds: u32,
    frames: u32,
    size: UVec2,
    stats: Option<PathBuf>,
}

fn parse_args() -> Args {
    let mut args = Args {
        trees: 64,
        leaves: 20_000,
        rounds: 3,
        frames: 20,
        size: UVec2::new(640, 360),
        stats: None,
    };
    let usage =
        "flags: [--trees N] [--leaves N] [--rounds N] [--frames N] [--size WxH] [--stats FILE]";
    let fail = |m: String| -> ! {
        eprintln!("{m}; {usage}");
        std::process::exit(2)
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || {
            it.next()
                .unwrap_or_else(|| fail(format!("{flag} needs a value")))
        };
        let mut whole = |name: &str, min: u64, max: u64| -> u64 {
            value()
                .parse::<u64>()
                .ok()
                .filter(|v| (min..=max).contains(v))
                .unwrap_or_else(|| fail(format!("{name} takes a whole number in {min}..={max}")))
        };
        match flag.as_str() {
            "--trees" => args.trees = whole("--trees", 1, 4096) as u32,
            "--leaves" => args.leaves = whole("--leaves", 100, 500_000) as usize,
            "--rounds" => args.rounds = whole("--rounds", 1, 20) as u32,
            "--frames" => args.frames = whole("--frames", 1, 10_000) as u32,
            "--size" => {
                args.size =
                    bevy_nature_harness::runner::parse_size(&value()).unwrap_or_else(|e| fail(e))
            }
            "--stats" => args.stats = Some(value().into()),
            other => fail(format!("unknown flag {other}")),
        }
    }
    args
}

/// The configurations, in the order each round runs them.
const CONFIGS: [(&str, bool, bool); 3] = [
    ("bevy_pbr", false, false),
    ("tree_lighting_no_bounce", true, false),
    ("tree_lighting", true, true),
];

#[derive(Default, Clone)]
struct Sample {
    gpu_frame_ms: Vec<f64>,
    main_pass_ms: Vec<f64>,
    sync_frame_ms: Vec<f64>,
    leaf_triangles: Vec<f64>,
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

fn main() {
    let args = parse_args();
    let mut harness = RenderHarness::new(HarnessConfig {
        gpu_timing: true,
        synchronous_pipeline_compilation: true,
        ..HarnessConfig::sized(args.size.x, args.size.y)
    })
    .expect("harness");
    if !harness.has_gpu_timestamps() {
        eprintln!("tree_lighting_bench: this adapter records no GPU timestamps; nothing measured");
        std::process::exit(1);
    }
    harness
        .app_mut()
        .add_plugins(bevy_nature::NaturePlugins)
        .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)))
        .insert_resource(GlobalAmbientLight {
            brightness: 400.0,
            ..default()
        });

    // Two of the thesis' species, baked once (the bake includes the lighting's envelope).
    let species = [TreeSpecies::olea(), TreeSpecies::quercus()];
    let started = std::time::Instant::now();
    let mut baked_handles = Vec::new();
    let mut spacing: f32 = 0.0;
    for s in &species {
        let s = s.clone().with_leaf_count(args.leaves);
        spacing = spacing.max(2.6 * s.crown_radius);
        let tree = generate(&s);
        let (baked, _) = bake(
            &tree.leaves,
            &BakeSettings {
                cells: CellCount::Depth(8),
                ..default()
            },
            &|_| {},
        )
        .expect("bake");
        baked_handles.push(
            harness
                .world_mut()
                .resource_mut::<Assets<BakedFoliage>>()
                .add(baked),
        );
    }
    eprintln!(
        "tree_lighting_bench: baked {} species of {} leaves in {:.1} s",
        species.len(),
        args.leaves,
        started.elapsed().as_secs_f64()
    );
    let material = harness
        .world_mut()
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(default_leaf_material()));
    let side = (args.trees as f32).sqrt().ceil() as u32;
    for i in 0..args.trees {
        let (x, z) = ((i % side) as f32, (i / side) as f32);
        let jitter = Vec3::new(
            ((i * 37) % 11) as f32 / 11.0 - 0.5,
            0.0,
            ((i * 53) % 7) as f32 / 7.0 - 0.5,
        );
        harness.world_mut().spawn((
            PrunedFoliage {
                baked: baked_handles[i as usize % baked_handles.len()].clone(),
                material: material.clone(),
            },
            Transform::from_translation(Vec3::new(x, 0.0, -z) * spacing + jitter * spacing * 0.4)
                .with_rotation(Quat::from_rotation_y(i as f32 * 2.39996)),
        ));
    }
    let extent = side as f32 * spacing;
    let ground = {
        let world = harness.world_mut();
        let mesh = world
            .resource_mut::<Assets<Mesh>>()
            .add(Plane3d::default().mesh().size(extent * 3.0, extent * 3.0));
        let material = world
            .resource_mut::<Assets<StandardMaterial>>()
            .add(StandardMaterial {
                base_color: Color::srgb(0.45, 0.5, 0.35),
                perceptual_roughness: 1.0,
                ..default()
            });
        (Mesh3d(mesh), MeshMaterial3d(material))
    };
    harness.world_mut().spawn(ground);
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: 10_000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.4, -1.0, -0.3), Vec3::Y),
    ));
    let centre = Vec3::new(extent * 0.5, 4.0, -extent * 0.5);
    harness.world_mut().spawn((
        Camera3d::default(),
        Msaa::Off,
        Transform::from_xyz(extent * 0.5, 9.0, 12.0).looking_at(centre, Vec3::Y),
    ));
    harness.wait_until_ready().expect("scene ready");

    let mut samples = vec![Sample::default(); CONFIGS.len()];
    for round in 0..args.rounds {
        for (c, (name, enabled, bounce)) in CONFIGS.iter().enumerate() {
            {
                let mut lighting = harness.world_mut().resource_mut::<TreeLightingSettings>();
                lighting.enabled = *enabled;
                lighting.bounce = *bounce;
            }
            harness
                .run_frames_gpu_synchronised(10)
                .expect("warm-up frames");
            harness.reset_timing();
            harness
                .run_frames_gpu_synchronised(args.frames)
                .expect("measured frames");
            let sync = harness.frame_stats().median_ms;
            // Timestamp results arrive a frame or two late.
            harness
                .run_frames_gpu_synchronised(3)
                .expect("frames for late timestamps");
            let gpu = harness.gpu_frame_time_ms().unwrap_or(f64::NAN);
            let main = harness
                .gpu_pass_time_ms("main_opaque_pass_3d")
                .unwrap_or(f64::NAN);
            let triangles = harness.diagnostic(&TRIANGLES_DRAWN).unwrap_or(f64::NAN);
            eprintln!(
                "tree_lighting_bench: round {round} {name}: GPU frame {gpu:.3} ms, main pass {main:.3} ms (timestamps); frame {sync:.2} ms (GPU-synchronised); {triangles:.0} leaf triangles"
            );
            let s = &mut samples[c];
            s.gpu_frame_ms.push(gpu);
            s.main_pass_ms.push(main);
            s.sync_frame_ms.push(sync);
            s.leaf_triangles.push(triangles);
        }
    }
    let gpu: Vec<f64> = samples.iter().map(|s| median(&s.gpu_frame_ms)).collect();
    let ratio = gpu[2] / gpu[0];
    let bounce_share = (gpu[2] - gpu[1]) / gpu[2];
    let rows: Vec<String> = CONFIGS
        .iter()
        .zip(&samples)
        .map(|((name, _, _), s)| {
            format!(
                "{{\"mode\": \"{name}\", \"gpu_frame_ms\": {:.4}, \"main_pass_ms\": {:.4}, \"frame_ms\": {:.3}, \"leaf_triangles\": {:.0}, \"gpu_frame_ms_rounds\": {:?}}}",
                median(&s.gpu_frame_ms),
                median(&s.main_pass_ms),
                median(&s.sync_frame_ms),
                median(&s.leaf_triangles),
                s.gpu_frame_ms
            )
        })
        .collect();
    let adapter = harness
        .adapter()
        .map(|a| a.name.clone())
        .unwrap_or_default();
    let json = format!(
        "{{\"bench\": \"tree_lighting\", \"headline\": \"tree_lighting_over_bevy_gpu_frame (the tree lighting's GPU frame time over Bevy's PBR leaf shading's, same forest and view; < 1: cheaper)\", \"timing\": \"gpu-timestamps\", \"adapter\": \"{adapter}\", \"trees\": {}, \"leaves_per_tree\": {}, \"size\": [{}, {}], \"frames\": {}, \"rounds\": {}, \"tree_lighting_over_bevy_gpu_frame\": {ratio:.4}, \"bounce_share_of_frame\": {bounce_share:.4}, \"rows\": [\n  {}\n]}}",
        args.trees,
        args.leaves,
        args.size.x,
        args.size.y,
        args.frames,
        args.rounds,
        rows.join(",\n  ")
    );
    println!("{json}");
    eprintln!(
        "tree_lighting_bench: tree_lighting_over_bevy_gpu_frame = {ratio:.3}; bounce_share_of_frame = {:.1} % (medians over {} rounds, GPU timestamps)",
        bounce_share * 100.0,
        args.rounds
    );
    if let Some(path) = args.stats {
        std::fs::write(&path, json).expect("write stats");
    }
}
