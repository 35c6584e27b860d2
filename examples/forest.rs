//! A walk through the thesis' dense forest (6,450 trees of the four test species), its sparse
//! one (210) or a huge one (100,000), drawn by the forest LoD manager: trees ranked by urgency,
//! served under a per-frame budget from per-type LoD caches, and beyond `far` by their billboard
//! clouds (baked on the GPU at the first run, then loaded from `assets/impostors/`).
//!
//! ```text
//! cargo run --release --example forest                 # windowed: the panel shows forest/* counters
//! cargo run --release --example forest -- --forest sparse --leaf-scale 1
//! cargo run --example forest -- --headless --frames 30 --stats forest.json
//! cargo run --release --example forest -- --forest huge --headless --frames 20 --stats huge.json
//! cargo run --release --example forest -- --mixed 400000   # the time-critical mixed LoD
//! ```
//! `--leaf-scale F` scales the thesis' leaf counts (default 0.25). Press `R` (or tick
//! `ImpostorSettings::show_representation` in the panel, or start with `--show-representation`)
//! to colour-code what draws each tree:
//! billboard clouds orange, leaf geometry blue at full detail, then cyan, green and magenta as
//! pruning keeps fewer leaves. In the panel, switch `ForestSettings::enabled` off for full detail,
//! `feedback` on to let the frame-rate exponent steer detail, or change the slots and the budget.

use bevy::prelude::*;
use bevy_nature::foliage::forest::components::MixedLodSettings;
use bevy_nature::foliage::impostor::bake::ImpostorBakeCamera;
use bevy_nature::foliage::impostor::systems::ImpostorSettings;
use bevy_nature::foliage::{FoliagePruningSettings, ForestSettings};
use bevy_nature::forest_scene::{
    ForestArgs, ForestDraw, ForestScene, ForestScenePlugin, camera_transform,
};
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
    // `--mixed BUDGET`: the time-critical mixed LoD under a budget of leaf triangles.
    let (mut mixed, mut runner_flags, mut rest) = (None, Vec::new(), rest.into_iter());
    let mut show_representation = false;
    while let Some(arg) = rest.next() {
        if arg == "--show-representation" {
            show_representation = true;
        } else if arg == "--mixed" {
            let v = rest.next().unwrap_or_default();
            mixed = Some(
                v.parse::<f32>()
                    .ok()
                    .filter(|b| *b >= 0.0)
                    .unwrap_or_else(|| {
                        eprintln!("--mixed takes a budget of triangles, not '{v}'");
                        std::process::exit(2)
                    }),
            );
        } else {
            runner_flags.push(arg);
        }
    }
    let args = ExampleArgs::parse_from(runner_flags).unwrap_or_else(|e| {
        eprintln!(
            "{e} [--forest dense|sparse|huge] [--leaf-scale F] [--mixed BUDGET] [--show-representation]"
        );
        std::process::exit(2)
    });
    ExampleRunner::with_args("forest", args)
        .inspect_resource::<ForestSettings>()
        .inspect_resource::<FoliagePruningSettings>()
        .inspect_resource::<ImpostorSettings>()
        .run(move |app| {
            app.add_plugins((bevy_nature::NaturePlugins, ForestScenePlugin))
                .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)))
                .insert_resource(ForestScene {
                    kind,
                    leaf_scale,
                    draw: ForestDraw::Managed,
                    impostors: true,
                })
                .insert_resource(ForestSettings {
                    mixed: MixedLodSettings {
                        enabled: mixed.is_some(),
                        budget_triangles: mixed
                            .unwrap_or(MixedLodSettings::default().budget_triangles),
                        ..default()
                    },
                    ..default()
                })
                .insert_resource(ImpostorSettings {
                    show_representation,
                    ..default()
                })
                .add_systems(Startup, spawn_camera)
                .add_systems(Update, (walk, toggle_representation));
        })
}

fn spawn_camera(mut commands: Commands) {
    commands.spawn((Camera3d::default(), camera_transform()));
}

/// `R` colour-codes what draws each tree.
fn toggle_representation(
    keys: Option<Res<ButtonInput<KeyCode>>>,
    mut settings: ResMut<ImpostorSettings>,
) {
    if keys.is_some_and(|k| k.just_pressed(KeyCode::KeyR)) {
        settings.show_representation = !settings.show_representation;
    }
}

/// Walks a 60 m circle through the forest, looking ahead.
fn walk(
    time: Res<Time>,
    mut cameras: Query<&mut Transform, (With<Camera3d>, Without<ImpostorBakeCamera>)>,
) {
    let t = time.elapsed_secs() * 0.08;
    let position = Vec3::new(60.0 * t.cos() - 60.0, 3.0, 60.0 * t.sin());
    let ahead = Vec3::new(-t.sin(), -0.05, t.cos());
    for mut transform in &mut cameras {
        *transform = Transform::from_translation(position).looking_to(ahead, Vec3::Y);
    }
}
