//! The four test trees of Gumbau 2011 (table 3.1) with view-dependent stochastic pruning, and a
//! camera that circles them while moving in and out, so the kept-leaf counts change live.
//!
//! ```text
//! cargo run --example foliage                      # windowed: the panel shows foliage/* counters
//! cargo run --example foliage -- --headless --frames 60 --stats foliage.json
//! ```
//! Toggle `enabled` in the panel's FoliagePruningSettings to compare with full detail.

use bevy::prelude::*;
use bevy_nature::foliage::pruning::procedural::TreeSpecies;
use bevy_nature::foliage::pruning::spawn::TreeAssets;
use bevy_nature::foliage::{FoliagePruningSettings, LodDistances};
use bevy_nature_harness::ExampleRunner;

fn main() -> AppExit {
    ExampleRunner::new("foliage")
        .inspect_resource::<FoliagePruningSettings>()
        .run(|app| {
            app.add_plugins(bevy_nature::NaturePlugins)
                .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)))
                .insert_resource(FoliagePruningSettings {
                    distances: LodDistances::World {
                        near: 15.0,
                        far: 160.0,
                    },
                    ..default()
                })
                .add_systems(Startup, setup)
                .add_systems(Update, fly);
        })
}

fn setup(mut commands: Commands, mut trees: TreeAssets) {
    commands.spawn((
        Mesh3d(
            trees
                .meshes
                .add(Plane3d::default().mesh().size(400.0, 400.0)),
        ),
        MeshMaterial3d(trees.materials.add(StandardMaterial {
            base_color: Color::srgb(0.45, 0.5, 0.35),
            perceptual_roughness: 1.0,
            ..default()
        })),
    ));
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
    commands.insert_resource(GlobalAmbientLight {
        brightness: 400.0,
        ..default()
    });
    commands.spawn((Camera3d::default(), Transform::from_xyz(0.0, 12.0, 60.0)));
}

/// Circles the trees; the distance swings between 25 m and 140 m every 20 s.
fn fly(time: Res<Time>, mut cameras: Query<&mut Transform, With<Camera3d>>) {
    let t = time.elapsed_secs();
    let distance = 82.5 - 57.5 * (t * std::f32::consts::TAU / 20.0).cos();
    let angle = t * 0.15;
    for mut transform in &mut cameras {
        *transform = Transform::from_xyz(
            angle.sin() * distance,
            8.0 + distance * 0.1,
            angle.cos() * distance,
        )
        .looking_at(Vec3::new(0.0, 6.0, 0.0), Vec3::Y);
    }
}
