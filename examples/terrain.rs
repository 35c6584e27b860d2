//! A flight at 250 m/s over a 262 km × 262 km terrain with relief, textured from a clip stack:
//! a virtual texture of 20 levels (2^19 texels of 0.5 m), procedural aerial imagery and heights
//! generated tile by tile on the IO task pool — or tile pyramids on disk (`--pyramid DIR` for
//! imagery, `--heights DIR` for an elevation pyramid: `height16`, terrarium or Mapbox tiles,
//! built with `cargo run -p bevy_terrain_clip --bin pyramid_build`). The ground is seamless
//! patches (`TerrainGeometry`) displaced by a height clip stack; the flight keeps 150 m above
//! the resident heights ahead. It starts over the data wherever the pyramid lies (its manifest's
//! origin), lower and slower over small pyramids; beyond the data the ground shows
//! `ClipmapSettings::no_data_color`. `--flat` draws the flat ground instead (the default with
//! `--pyramid` and no `--heights`); `--no-culling` turns the patches' frustum culling off.
//!
//! ```text
//! cargo run --release --example terrain            # windowed: the panel shows terrain/* counters
//! cargo run --example terrain -- --headless --frames 60 --stats terrain.json
//! cargo run --example terrain -- --pyramid path/to/imagery --heights path/to/dem
//! cargo run --example terrain -- --headless --budget-ms 1 --stats t.json  # time budget
//! ```

use bevy::math::DVec2;
use bevy::prelude::*;
use bevy_nature::terrain_clip::dem::DiskHeightSource;
use bevy_nature::terrain_clip::material::{ClipmapMaterial, flat_patch_mesh};
use bevy_nature::terrain_clip::source::{
    DiskTileSource, ProceduralTileSource, TileSource, imagery_texel, relief_texel,
};
use bevy_nature::terrain_clip::stack_gpu::{ClipStackTexture, TextureMapping};
use bevy_nature::terrain_clip::terrain::{TerrainGeometry, TerrainPrecision};
use bevy_nature::terrain_clip::{ClipmapSettings, UpdateBudget};
use bevy_nature_harness::{ExampleArgs, ExampleRunner};
use std::sync::Arc;

/// Side of the terrain patch drawn around the camera (m), rebuilt as the camera moves on.
const PATCH_M: f64 = 24_000.0;

/// An elevation source and where it lies.
type Relief = (Arc<dyn TileSource>, TextureMapping);

#[derive(Resource, Clone)]
struct Terrain {
    source: Arc<dyn TileSource>,
    mapping: TextureMapping,
    /// Heights and where they lie, for relief; `None`: flat ground.
    heights: Option<Relief>,
}

/// The height stack's entity, which the flight reads the ground from.
#[derive(Component)]
struct Heights;

/// Whether the patch selection culls by the view frustum (`--no-culling`: not).
#[derive(Resource)]
struct Culling(bool);

/// The flight's smoothed altitude (m).
#[derive(Resource, Default)]
struct Altitude(Option<f64>);

#[derive(Component)]
struct Patch {
    center: DVec2,
}

fn main() -> AppExit {
    let mut pyramid = None;
    let mut dem = None;
    let mut flat = false;
    let mut culling = true;
    let mut budget = UpdateBudget::Subtiles(16);
    let mut rest = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--pyramid" {
            pyramid = Some(args.next().unwrap_or_default());
        } else if arg == "--heights" {
            dem = Some(args.next().unwrap_or_default());
        } else if arg == "--flat" {
            flat = true;
        } else if arg == "--no-culling" {
            culling = false;
        } else if arg == "--budget-ms" || arg == "--budget-subtiles" {
            let value = args.next().unwrap_or_default();
            budget = match (arg.as_str(), value.parse::<f32>()) {
                ("--budget-ms", Ok(ms)) => UpdateBudget::Millis(ms),
                (_, Ok(n)) => UpdateBudget::Subtiles(n as u32),
                _ => {
                    eprintln!("{arg} takes a number, not '{value}'");
                    std::process::exit(2)
                }
            };
        } else {
            rest.push(arg);
        }
    }
    let heights = match &dem {
        Some(dir) => match DiskHeightSource::open(dir) {
            Ok(source) => Some((
                TextureMapping::from_manifest(&source.manifest),
                Arc::new(source) as Arc<dyn TileSource>,
            )),
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1)
            }
        },
        None => None,
    };
    let mut terrain = match pyramid {
        Some(dir) => match DiskTileSource::open(&dir) {
            Ok(source) => Terrain {
                mapping: TextureMapping::from_manifest(&source.manifest),
                source: Arc::new(source),
                heights: None,
            },
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1)
            }
        },
        None => {
            // 12 pyramid levels of 256² tiles: virtual levels 0..20, the finest 2^19 texels.
            let size_m = 0.5 * 2f64.powi(19);
            let mapping = TextureMapping {
                origin_m: DVec2::ZERO,
                size_m,
            };
            Terrain {
                source: Arc::new(ProceduralTileSource::new(256, 12, move |l, x, y| {
                    imagery_texel(l, x, y, size_m)
                })),
                mapping,
                heights: Some((
                    Arc::new(ProceduralTileSource::heights(256, 12, move |l, x, y| {
                        relief_texel(l, x, y, size_m)
                    })),
                    mapping,
                )),
            }
        }
    };
    if let Some((mapping, source)) = heights {
        terrain.heights = Some((source, mapping));
    }
    if flat {
        terrain.heights = None;
    }
    let args = ExampleArgs::parse_from(rest).unwrap_or_else(|e| {
        eprintln!(
            "{e} [--pyramid DIR] [--heights DIR] [--flat] [--no-culling] \
             [--budget-ms F | --budget-subtiles N]"
        );
        std::process::exit(2)
    });
    ExampleRunner::with_args("terrain", args)
        .inspect_resource::<ClipmapSettings>()
        .run(move |app| {
            app.add_plugins(bevy_nature::NaturePlugins)
                .insert_resource(ClearColor(Color::srgb(0.62, 0.74, 0.9)))
                .insert_resource(ClipmapSettings {
                    budget,
                    ..default()
                })
                .insert_resource(terrain)
                .init_resource::<Altitude>()
                .insert_resource(Culling(culling))
                .add_systems(Startup, setup)
                .add_systems(Update, (fly, follow_patch));
        })
}

/// Where the flight starts: a quarter into the data, wherever the pyramid lies in the world.
fn start(mapping: &TextureMapping) -> DVec2 {
    mapping.origin_m + DVec2::new(0.25, 0.3) * mapping.size_m
}

/// Height (m) and speed (m/s) of the flight: 300 m at 250 m/s over the large textures, lower
/// and slower over small pyramids so the data fills the view.
fn altitude_and_speed(mapping: &TextureMapping) -> (f64, f64) {
    let altitude = (mapping.size_m * 0.02).clamp(20.0, 300.0);
    (altitude, altitude * 250.0 / 300.0)
}

#[allow(clippy::too_many_arguments)]
fn setup(
    mut commands: Commands,
    terrain: Res<Terrain>,
    culling: Res<Culling>,
    settings: Res<ClipmapSettings>,
    mut images: ResMut<Assets<Image>>,
    mut materials: ResMut<Assets<ClipmapMaterial>>,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    let center = start(&terrain.mapping);
    let (altitude, _) = altitude_and_speed(&terrain.mapping);
    let uv = terrain.mapping.uv_of(center);
    let mut clip = ClipStackTexture::from_settings(
        terrain.source.clone(),
        &settings,
        [uv.x, uv.y],
        &mut images,
    );
    clip.mapping = Some(terrain.mapping);
    let material = clip.material(
        StandardMaterial {
            perceptual_roughness: 1.0,
            ..default()
        },
        &mut materials,
    );
    commands.spawn((Name::new("clip stack"), clip));
    let mapping = terrain.mapping;
    if let Some((source, height_mapping)) = &terrain.heights {
        let uv = height_mapping.uv_of(center);
        let mut heights =
            ClipStackTexture::heights(source.clone(), &settings, [uv.x, uv.y], &mut images);
        heights.mapping = Some(*height_mapping);
        let heights = commands
            .spawn((Name::new("height stack"), Heights, heights))
            .id();
        commands.spawn((
            Name::new("terrain"),
            TerrainGeometry {
                culling: culling.0,
                // Vertices 3 px apart on screen: 60 km of ground stays interactive on a software
                // rasteriser too. (The default, 1.1 px, keeps the silhouette within a pixel of the
                // full mesh, at up to (3 / 1.1)² ≈ 7× the triangles.)
                precision: TerrainPrecision::VertexPixels(3.0),
                ..TerrainGeometry::new(heights, material)
            },
        ));
    } else {
        spawn_flat_ground(&mut commands, &mut meshes, material, center, mapping);
    }
    commands.spawn((
        DirectionalLight {
            illuminance: 9000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.5, -0.35, -0.3), Vec3::Y),
    ));
    commands.insert_resource(GlobalAmbientLight {
        brightness: 600.0,
        ..default()
    });
    commands.spawn((
        Camera3d::default(),
        // Bevy culls at the projection's far plane, and so does the patch selection: the ground
        // to 60 km.
        Projection::Perspective(PerspectiveProjection {
            far: 60_000.0,
            ..default()
        }),
        Transform::from_xyz(center.x as f32, altitude as f32, center.y as f32),
    ));
}

/// The flat ground: a patch around the camera, rebuilt as it moves on ([`follow_patch`]).
fn spawn_flat_ground(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    material: Handle<ClipmapMaterial>,
    center: DVec2,
    mapping: TextureMapping,
) {
    commands.spawn((
        Name::new("terrain patch"),
        Patch { center },
        Mesh3d(meshes.add(flat_patch_mesh(
            center - DVec2::splat(PATCH_M / 2.0),
            PATCH_M,
            64,
            center,
            move |p| mapping.uv_of(p),
        ))),
        MeshMaterial3d(material),
        Transform::from_xyz(center.x as f32, 0.0, center.y as f32),
    ));
}

/// Along the diagonal (250 m/s, 300 m up over large textures), looking ahead and down. Over
/// relief the altitude is 150 m above the highest resident ground under the camera and up to
/// 2 km ahead of it, eased so the camera climbs before a ridge and sinks slowly after.
fn fly(
    time: Res<Time>,
    terrain: Res<Terrain>,
    mut altitude: ResMut<Altitude>,
    mut heights: Query<&mut ClipStackTexture, With<Heights>>,
    mut cameras: Query<&mut Transform, With<Camera3d>>,
) {
    let (base_altitude, speed) = altitude_and_speed(&terrain.mapping);
    let direction = DVec2::new(1.0, 1.0).normalize();
    let along = direction * speed * time.elapsed_secs_f64();
    let p = start(&terrain.mapping) + along;
    let mut target = base_altitude;
    if let Ok(mut stack) = heights.single_mut() {
        let ground = (0..=8)
            .filter_map(|k| stack.resident_height(p + direction * (250.0 * k as f64)))
            .map(|(h, _)| h as f64)
            .fold(f64::NEG_INFINITY, f64::max);
        if ground.is_finite() {
            target = ground + 150.0;
        }
    }
    let dt = time.delta_secs_f64().min(0.1);
    let eased = match altitude.0 {
        // Up quickly, down slowly.
        Some(a) if target > a => a + (target - a) * (dt * 3.0).min(1.0),
        Some(a) => a + (target - a) * (dt * 0.5).min(1.0),
        None => target,
    };
    altitude.0 = Some(eased);
    for mut t in &mut cameras {
        *t = Transform::from_xyz(p.x as f32, eased as f32, p.y as f32)
            .looking_to(Vec3::new(0.7, -0.35, 0.7), Vec3::Y);
    }
}

/// Rebuilds the patch around the camera once it is a kilometre off centre.
fn follow_patch(
    terrain: Res<Terrain>,
    cameras: Query<&Transform, With<Camera3d>>,
    mut patches: Query<(&mut Patch, &mut Mesh3d, &mut Transform), Without<Camera3d>>,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    let Some(camera) = cameras.iter().next() else {
        return;
    };
    let here = DVec2::new(camera.translation.x as f64, camera.translation.z as f64);
    for (mut patch, mut mesh, mut transform) in &mut patches {
        if patch.center.distance(here) < 1000.0 {
            continue;
        }
        let mapping = terrain.mapping;
        patch.center = here;
        mesh.0 = meshes.add(flat_patch_mesh(
            here - DVec2::splat(PATCH_M / 2.0),
            PATCH_M,
            64,
            here,
            move |p| mapping.uv_of(p),
        ));
        *transform = Transform::from_xyz(here.x as f32, 0.0, here.y as f32);
    }
}
