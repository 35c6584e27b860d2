//! The four test trees of Gumbau 2011 (table 3.1) with view-dependent stochastic pruning, and a
//! camera that circles them while moving in and out, so the kept-leaf counts change live.
//!
//! ```text
//! cargo run --example foliage                      # windowed: the panel shows foliage/* counters
//! cargo run --example foliage -- --headless --frames 60 --stats foliage.json
//! cargo run --example foliage -- --opacity-shadows  # the trees' opacity shadow map from the start
//! cargo run --example foliage -- --tree-lighting    # leaves lit as volumes from the start
//! cargo run --example foliage -- --still            # a fixed close view of two trees
//! ```
//! Toggle `enabled` in the panel's FoliagePruningSettings to compare with full detail. Key `O`
//! switches the trees' ground shadows between Bevy's shadow map and the world-space opacity
//! shadow map (`TreeOpacityShadows`, editable in the panel): dark where leaves pile up, light
//! where they are sparse, soft away from the crowns. Key `L` switches the leaves between Bevy's
//! lighting and the tree lighting (`TreeLightingSettings`, editable in the panel): sky, sun and
//! one bounce of sunlight through each crown, from the light its leaves' neighbours let through.

use bevy::prelude::*;
use bevy_nature::foliage::pruning::procedural::TreeSpecies;
use bevy_nature::foliage::pruning::spawn::TreeAssets;
use bevy_nature::foliage::{FoliagePruningSettings, LodDistances, TreeLightingSettings};
use bevy_nature::soft_shadows::foliage::TreeOpacityShadows;
use bevy_nature_harness::{ExampleArgs, ExampleRunner};

/// Whether the sun starts with the trees' opacity shadow map.
#[derive(Resource)]
struct StartWithOpacityShadows(bool);

fn main() -> AppExit {
    let mut rest: Vec<String> = std::env::args().skip(1).collect();
    let opacity = rest.iter().any(|a| a == "--opacity-shadows");
    let tree_lighting = rest.iter().any(|a| a == "--tree-lighting");
    let still = rest.iter().any(|a| a == "--still");
    rest.retain(|a| a != "--opacity-shadows" && a != "--tree-lighting" && a != "--still");
    let args = ExampleArgs::parse_from(rest).unwrap_or_else(|e| {
        eprintln!("{e} [--opacity-shadows] [--tree-lighting] [--still]");
        std::process::exit(2)
    });
    ExampleRunner::with_args("foliage", args)
        .inspect_resource::<FoliagePruningSettings>()
        .inspect_component::<TreeOpacityShadows>()
        .inspect_resource::<TreeLightingSettings>()
        .run(move |app| {
            app.add_plugins(bevy_nature::NaturePlugins)
                .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)))
                .insert_resource(FoliagePruningSettings {
                    distances: LodDistances::World {
                        near: 15.0,
                        far: 160.0,
                    },
                    ..default()
                })
                .insert_resource(TreeLightingSettings {
                    enabled: tree_lighting,
                    ..default()
                })
                .insert_resource(StartWithOpacityShadows(opacity))
                .add_systems(Startup, setup)
                .add_systems(
                    Update,
                    (
                        fly.run_if(move || !still),
                        toggle_opacity_shadows,
                        toggle_tree_lighting,
                    ),
                );
        })
}

/// The sun's opacity shadow map over the four trees: 100 × 40 m at 2048², 5 cm texels.
fn opacity_shadows() -> TreeOpacityShadows {
    TreeOpacityShadows {
        resolution: 2048,
        bounds_min: Vec3::new(-50.0, 0.0, -20.0),
        bounds_max: Vec3::new(50.0, 30.0, 20.0),
        plane_y: 0.0,
        ..default()
    }
}

/// `O`: the trees' shadows from the opacity shadow map, or from Bevy's shadow map.
fn toggle_opacity_shadows(
    mut commands: Commands,
    keys: Option<Res<ButtonInput<KeyCode>>>,
    suns: Query<(Entity, Has<TreeOpacityShadows>), With<DirectionalLight>>,
) {
    if !keys.is_some_and(|k| k.just_pressed(KeyCode::KeyO)) {
        return;
    }
    for (sun, on) in &suns {
        if on {
            commands.entity(sun).remove::<TreeOpacityShadows>();
            info!("tree shadows: Bevy's shadow map");
        } else {
            commands.entity(sun).insert(opacity_shadows());
            info!("tree shadows: the opacity shadow map");
        }
    }
}

/// `L`: leaves lit as volumes, or by Bevy's lighting.
fn toggle_tree_lighting(
    keys: Option<Res<ButtonInput<KeyCode>>>,
    mut lighting: ResMut<TreeLightingSettings>,
) {
    if keys.is_some_and(|k| k.just_pressed(KeyCode::KeyL)) {
        lighting.enabled = !lighting.enabled;
        info!(
            "leaves lit by {}",
            if lighting.enabled {
                "the tree lighting"
            } else {
                "Bevy's lighting"
            }
        );
    }
}

fn setup(mut commands: Commands, mut trees: TreeAssets, start: Res<StartWithOpacityShadows>) {
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
    let mut sun = commands.spawn((
        DirectionalLight {
            illuminance: 10_000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.4, -1.0, -0.3), Vec3::Y),
    ));
    if start.0 {
        sun.insert(opacity_shadows());
    }
    commands.insert_resource(GlobalAmbientLight {
        brightness: 400.0,
        ..default()
    });
    // The still view (`--still`): the two middle trees from 30 m; `fly` moves it otherwise.
    commands.spawn((
        Camera3d::default(),
        Transform::from_xyz(-2.0, 7.0, 30.0).looking_at(Vec3::new(0.0, 6.0, 0.0), Vec3::Y),
    ));
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
