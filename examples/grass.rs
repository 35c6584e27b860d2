//! A meadow to the horizon (Boulanger 2008, thesis ch. 4): one base patch of blades repeated
//! over a 400 m field of rolling hills in four mirrored versions, drawn near as blade geometry,
//! at middle distance as baked volume slices and far as the horizontal slice, thinned by a
//! procedural density map with clearings, lifted onto the hills from a height map and swayed by
//! the wind; the camera glides low over it so the transitions sweep past.
//!
//! ```text
//! cargo run --example grass                     # windowed: the panel edits GrassSettings and
//!                                               # shows the grass/* counters
//! cargo run --example grass -- --headless --frames 30 --screenshot grass.png --stats grass.json
//! ```
//! In the panel, turn `geometry` or `slices` off to see what each level draws, or change the
//! `wind`.

use bevy::prelude::*;
use bevy_nature::foliage::grass::density::{DensityMap, meadow};
use bevy_nature::foliage::grass::ground::ambient_occlusion_map;
use bevy_nature::foliage::grass::material::density_map_image;
use bevy_nature::foliage::grass::systems::grass_ready;
use bevy_nature::foliage::grass::{GrassField, GrassSettings, GrassSpecies, height_map_image};
use bevy_nature_harness::ExampleRunner;

/// Side of the meadow (m).
const FIELD: f32 = 400.0;

/// The hills (m) at world (x, z): gentle swells a few metres high, 150–300 m across.
fn hills(x: f32, z: f32) -> f32 {
    5.0 * (x / 45.0).sin() * (z / 38.0).cos() + 2.5 * ((x + 0.5 * z) / 27.0).sin()
}

fn main() -> AppExit {
    ExampleRunner::new("grass")
        .inspect_resource::<GrassSettings>()
        .ready_when(grass_ready)
        .run(|app| {
            app.add_plugins(bevy_nature::NaturePlugins)
                .insert_resource(ClearColor(Color::srgb(0.62, 0.74, 0.9)))
                .insert_resource(GrassSettings {
                    slice_cache: Some("assets/grass".into()),
                    ..default()
                })
                .add_systems(Startup, setup)
                .add_systems(Update, glide);
        })
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut images: ResMut<Assets<Image>>,
) {
    // The ground: a plane of 2 m squares bent onto the hills.
    let mut ground = Plane3d::default()
        .mesh()
        .size(FIELD * 1.5, FIELD * 1.5)
        .subdivisions(299)
        .build();
    if let Some(bevy::mesh::VertexAttributeValues::Float32x3(positions)) =
        ground.attribute_mut(Mesh::ATTRIBUTE_POSITION)
    {
        for p in positions.iter_mut() {
            p[1] = hills(p[0], p[2]);
        }
    }
    ground.compute_smooth_normals();
    commands.spawn((
        Name::new("ground"),
        Mesh3d(meshes.add(ground)),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.2, 0.17, 0.09),
            perceptual_roughness: 1.0,
            ..default()
        })),
    ));
    // Two rocks in clearings.
    let rock = materials.add(StandardMaterial {
        base_color: Color::srgb(0.45, 0.44, 0.42),
        perceptual_roughness: 0.9,
        ..default()
    });
    let clearings = [([-6.0, 30.0], 3.5), ([14.0, 70.0], 5.0)];
    for ([x, z], r) in clearings {
        commands.spawn((
            Mesh3d(meshes.add(Sphere::new(r * 0.55).mesh().ico(3).unwrap())),
            MeshMaterial3d(rock.clone()),
            Transform::from_xyz(x, hills(x, z), z).with_scale(Vec3::new(1.0, 0.6, 1.0)),
        ));
    }
    let density = match meadow(256, [0.0, 0.0], [FIELD, FIELD], &clearings, 11) {
        Ok(map) => Some(images.add(density_map_image(&map))),
        Err(e) => {
            error!("meadow density: {e}");
            None
        }
    };
    commands.spawn((
        Name::new("meadow"),
        GrassField {
            size: Vec2::splat(FIELD),
            species: GrassSpecies::default(),
            density,
            // The same hills, one height every 1.5 m (the grass samples it at its cell corners).
            ground: Some(images.add(height_map_image(
                Vec2::splat(FIELD),
                UVec2::splat(267),
                |p| hills(p.x, p.y),
            ))),
            // The hills' own ambient occlusion, computed once (§4.2.6): hollows darker.
            ambient_occlusion: {
                let half = Vec2::splat(FIELD / 2.0);
                let texels = UVec2::splat(200);
                let ao =
                    ambient_occlusion_map(|p| hills(p.x, p.y), -half, 2.0 * half, texels, 20.0);
                DensityMap::new(texels.x, texels.y, ao, (-half).to_array(), [FIELD; 2])
                    .ok()
                    .map(|map| images.add(density_map_image(&map)))
            },
        },
    ));
    commands.spawn((
        DirectionalLight {
            illuminance: 10_000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.5, -0.7, 0.6), Vec3::Y),
    ));
    commands.insert_resource(GlobalAmbientLight {
        brightness: 500.0,
        ..default()
    });
    commands.spawn((
        FlyCamera,
        Camera3d::default(),
        Transform::from_xyz(0.0, hills(0.0, -10.0) + 1.6, -10.0),
    ));
}

/// The camera that glides.
#[derive(Component)]
struct FlyCamera;

/// Glides forward along z at 1.5 m/s, 1.6 m above the ground, looking slightly down.
fn glide(time: Res<Time>, mut cameras: Query<&mut Transform, With<FlyCamera>>) {
    let z = -10.0 + (time.elapsed_secs() * 1.5) % 120.0;
    for mut transform in &mut cameras {
        *transform = Transform::from_xyz(0.0, hills(0.0, z) + 1.6, z)
            .looking_to(Vec3::new(0.15, -0.18, 1.0), Vec3::Y);
    }
}
