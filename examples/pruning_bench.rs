//! Pruning on vs off, measured side by side in one process (headless): the four thesis trees seen
//! from several distances; for each, frame time (median of N frames), GPU time of the main opaque
//! pass where timestamp queries exist, leaf triangles drawn, and image error of the pruned frame
//! against full detail rendered in the same run. Prints one JSON object.
//!
//! ```text
//! cargo run --example pruning_bench -- [--frames N] [--size WxH]
//! ```

use bevy::prelude::*;
use bevy_nature::foliage::pruning::procedural::TreeSpecies;
use bevy_nature::foliage::pruning::spawn::TreeAssets;
use bevy_nature::foliage::pruning::systems::{TRIANGLES_DRAWN, TRIANGLES_FULL};
use bevy_nature::foliage::{FoliagePruningSettings, LodDistances};
use bevy_nature_harness::compare::{Comparison, coverage_against_background};
use bevy_nature_harness::headless::HarnessConfig;
use bevy_nature_harness::{ExampleArgs, RenderHarness, require_adapter};

const SKY: [u8; 4] = [140, 179, 230, 255];

fn main() {
    let args = ExampleArgs::from_env();
    let size = args.size.unwrap_or(UVec2::new(480, 270));
    let frames = args.frames.unwrap_or(10);
    if require_adapter("pruning_bench").is_none() {
        std::process::exit(1);
    }
    let mut harness = RenderHarness::new(HarnessConfig::sized(size.x, size.y)).expect("harness");
    harness
        .app_mut()
        .add_plugins(bevy_nature::NaturePlugins)
        .insert_resource(ClearColor(Color::srgb_u8(SKY[0], SKY[1], SKY[2])))
        .insert_resource(FoliagePruningSettings {
            distances: LodDistances::World {
                near: 15.0,
                far: 160.0,
            },
            ..default()
        })
        .add_systems(Startup, setup);
    harness.wait_until_ready().expect("scene ready");
    let camera = {
        let world = harness.world_mut();
        world
            .query_filtered::<Entity, With<Camera3d>>()
            .single(world)
            .unwrap()
    };
    let mut rows = Vec::new();
    for distance in [30.0f32, 60.0, 100.0] {
        *harness.world_mut().get_mut::<Transform>(camera).unwrap() =
            Transform::from_xyz(0.0, 6.0 + distance * 0.15, distance)
                .looking_at(Vec3::new(0.0, 6.0, 0.0), Vec3::Y);
        let mut measure = |enabled: bool| {
            harness
                .world_mut()
                .resource_mut::<FoliagePruningSettings>()
                .enabled = enabled;
            for _ in 0..3 {
                harness.step();
            }
            harness.reset_timing();
            harness.run_frames(frames).unwrap();
            let stats = harness.frame_stats();
            let opaque = harness.pass_time_ms("main_opaque_pass_3d");
            let drawn = harness.diagnostic(&TRIANGLES_DRAWN).unwrap_or(0.0);
            let full = harness.diagnostic(&TRIANGLES_FULL).unwrap_or(0.0);
            let image = harness.render().unwrap();
            (stats, opaque, drawn, full, image)
        };
        let (off, off_pass, off_tris, full_tris, full_image) = measure(false);
        let (on, on_pass, on_tris, _, pruned_image) = measure(true);
        let cmp = Comparison::new(
            format!("pruning_bench/{distance}"),
            &pruned_image,
            &full_image,
        );
        let cov_full = coverage_against_background(&full_image, SKY, 8);
        let cov_pruned = coverage_against_background(&pruned_image, SKY, 8);
        rows.push(format!(
            "{{\"distance_m\": {distance}, \"triangles_full\": {full_tris}, \"triangles_off\": {off_tris}, \"triangles_on\": {on_tris}, \"frame_ms_off\": {:.1}, \"frame_ms_on\": {:.1}, \"frame_ratio\": {:.2}, \"opaque_pass_ms_off\": {}, \"opaque_pass_ms_on\": {}, \"rmse\": {:.4}, \"psnr_db\": {:.1}, \"coverage_full\": {:.4}, \"coverage_pruned\": {:.4}}}",
            off.median_ms,
            on.median_ms,
            off.median_ms / on.median_ms.max(1e-9),
            off_pass.map_or("null".into(), |v| format!("{v:.2}")),
            on_pass.map_or("null".into(), |v| format!("{v:.2}")),
            cmp.rmse,
            cmp.psnr,
            cov_full,
            cov_pruned,
        ));
    }
    println!(
        "{{\"bench\": \"pruning\", \"size\": [{}, {}], \"frames\": {frames}, \"adapter\": {:?}, \"rows\": [\n  {}\n]}}",
        size.x,
        size.y,
        harness
            .adapter()
            .map(|a| a.name.clone())
            .unwrap_or_default(),
        rows.join(",\n  ")
    );
}

fn setup(mut commands: Commands, mut trees: TreeAssets) {
    for (i, species) in TreeSpecies::thesis_trees().iter().enumerate() {
        let x = (i as f32 - 1.5) * 22.0;
        if let Err(e) =
            trees.spawn_procedural(&mut commands, species, Transform::from_xyz(x, 0.0, 0.0))
        {
            error!("{}: {e}", species.name);
        }
    }
    commands.spawn((
        DirectionalLight {
            illuminance: 10_000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.4, -1.0, -0.3), Vec3::Y),
    ));
    commands.spawn((
        Camera3d::default(),
        Msaa::Off,
        Transform::from_xyz(0.0, 12.0, 60.0),
    ));
}
