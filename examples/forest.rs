//! A walk through the thesis' dense forest (6,450 trees of the four test species) or its sparse
//! one (210), drawn by the forest LoD manager: trees ranked by urgency, served under a per-frame
//! budget from per-type LoD caches.
//!
//! ```text
//! cargo run --release --example forest                 # windowed: the panel shows forest/* counters
//! cargo run --release --example forest -- --forest sparse --leaf-scale 1
//! cargo run --example forest -- --headless --frames 30 --stats forest.json
//! ```
//! `--leaf-scale F` scales the thesis' leaf counts (default 0.25). In the panel, switch
//! `ForestSettings::enabled` off for full detail, `feedback` on to let the frame-rate exponent
//! steer detail, or change the slots and the budget.

use bevy::prelude::*;
use bevy_nature::foliage::{FoliagePruningSettings, ForestSettings};
use bevy_nature::forest_scene::{ForestArgs, ForestScene, camera_transform, spawn_forest};
use bevy_nature_harness::{ExampleArgs, ExampleRunner};

fn main() -> AppExit {
    let ForestArgs {
        kind,
        leaf_scale,
        rest,
    } = ForestArgs::parse(std::env::args().skip(1), 0.25).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let args = ExampleArgs::parse_from(rest).unwrap_or_else(|e| {
        eprintln!("{e} [--forest dense|sparse] [--leaf-scale F]");
        std::process::exit(2)
    });
    ExampleRunner::with_args("forest", args)
        .inspect_resource::<ForestSettings>()
        .inspect_resource::<FoliagePruningSettings>()
        .run(move |app| {
            app.add_plugins(bevy_nature::NaturePlugins)
                .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)))
                .insert_resource(ForestScene {
                    kind,
                    leaf_scale,
                    with_hlod: false,
                })
                .add_systems(Startup, (spawn_forest, spawn_camera))
                .add_systems(Update, walk);
        })
}

fn spawn_camera(mut commands: Commands) {
    commands.spawn((Camera3d::default(), camera_transform()));
}

/// Walks a 60 m circle through the forest, looking ahead.
fn walk(time: Res<Time>, mut cameras: Query<&mut Transform, With<Camera3d>>) {
    let t = time.elapsed_secs() * 0.08;
    let position = Vec3::new(60.0 * t.cos() - 60.0, 3.0, 60.0 * t.sin());
    let ahead = Vec3::new(-t.sin(), -0.05, t.cos());
    for mut transform in &mut cameras {
        *transform = Transform::from_translation(position).looking_to(ahead, Vec3::Y);
    }
}
