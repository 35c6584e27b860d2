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
//! cargo run --release --example terrain -- --bench [--frames N] [--size WxH] [--stats FILE]
//! ```
//!
//! `--bench` measures the GPU's triangle rate over the relief and what the patches' frustum
//! culling saves (paper 4, table 1): at five stations along the flight, once the stacks have
//! streamed, for vertices 3 px and 1.1 px apart (the default), with culling on and off, the
//! whole frame's GPU time (timestamps around everything it submits: shadow map, prepass, main
//! pass; median of N frames), the triangles and patches drawn, and the CPU time of the
//! selection. Without GPU timestamp queries it says so and exits non-zero. `--stats FILE` writes
//! `{"rows": [{"station", "vertex_px", "culling", "triangles", "patches", "culled",
//! "gpu_frame_ms", "mtris_per_s", "selection_us"}], "timing": "timestamps"}`.

use bevy::math::{DVec2, DVec3};
use bevy::prelude::*;
use bevy_nature::terrain_clip::dem::DiskHeightSource;
use bevy_nature::terrain_clip::material::{ClipmapMaterial, flat_patch_mesh};
use bevy_nature::terrain_clip::source::{
    DiskTileSource, ProceduralTileSource, TileSource, imagery_texel, relief_texel,
};
use bevy_nature::terrain_clip::stack_gpu::{ClipStackTexture, TextureMapping};
use bevy_nature::terrain_clip::terrain::{TerrainGeometry, TerrainPrecision};
use bevy_nature::terrain_clip::{ClipmapSettings, RenderOrigin, UpdateBudget};
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
    let mut bench = false;
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
        } else if arg == "--bench" {
            bench = true;
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
             [--budget-ms F | --budget-subtiles N] [--bench]"
        );
        std::process::exit(2)
    });
    if bench {
        return run_bench(&args, terrain, budget);
    }
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

/// Render space follows the camera in steps of this many metres (a floating origin,
/// [`RenderOrigin`]): pyramids placed in real-world coordinates (UTM, 10^6 m and more from the
/// origin) draw as sharply as ones at the origin.
const ORIGIN_STEP_M: f64 = 4096.0;

/// The render origin for a camera at world `p`.
fn floating_origin(p: DVec2) -> RenderOrigin {
    let snapped = (p / ORIGIN_STEP_M).round() * ORIGIN_STEP_M;
    RenderOrigin(DVec3::new(snapped.x, 0.0, snapped.y))
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
    let origin = floating_origin(center);
    commands.insert_resource(origin);
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
        spawn_flat_ground(
            &mut commands,
            &mut meshes,
            material,
            center,
            mapping,
            &origin,
        );
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
        Transform::from_translation(origin.render_of(DVec3::new(center.x, altitude, center.y))),
    ));
}

/// The flat ground: a patch around the camera, rebuilt as it moves on ([`follow_patch`]).
fn spawn_flat_ground(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    material: Handle<ClipmapMaterial>,
    center: DVec2,
    mapping: TextureMapping,
    origin: &RenderOrigin,
) {
    let at = origin.render_xz(center);
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
        Transform::from_xyz(at.x, 0.0, at.y),
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
    mut origin: ResMut<RenderOrigin>,
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
    origin.set_if_neq(floating_origin(p));
    for mut t in &mut cameras {
        *t = Transform::from_translation(origin.render_of(DVec3::new(p.x, eased, p.y)))
            .looking_to(Vec3::new(0.7, -0.35, 0.7), Vec3::Y);
    }
}

/// Rebuilds the patch around the camera once it is a kilometre off centre.
fn follow_patch(
    terrain: Res<Terrain>,
    origin: Res<RenderOrigin>,
    cameras: Query<&Transform, With<Camera3d>>,
    mut patches: Query<(&mut Patch, &mut Mesh3d, &mut Transform), Without<Camera3d>>,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    let Some(camera) = cameras.iter().next() else {
        return;
    };
    let here = origin.world_xz(camera.translation);
    for (mut patch, mut mesh, mut transform) in &mut patches {
        // Placed under the render origin, which moves with the camera.
        let at = origin.render_xz(patch.center);
        transform.set_if_neq(Transform::from_xyz(at.x, 0.0, at.y));
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
        let at = origin.render_xz(here);
        *transform = Transform::from_xyz(at.x, 0.0, at.y);
    }
}

/// One measured configuration of `--bench`.
struct BenchRow {
    station: usize,
    vertex_px: f32,
    culling: bool,
    triangles: f64,
    patches: f64,
    culled: f64,
    gpu_frame_ms: f64,
    selection_us: f64,
}

/// `--bench`: see the module docs.
fn run_bench(args: &ExampleArgs, terrain: Terrain, budget: UpdateBudget) -> AppExit {
    use bevy_nature::terrain_clip::terrain::{DEFAULT_VERTEX_PIXELS, TRIANGLES, TerrainPatches};
    use bevy_nature_harness::headless::HarnessConfig;
    use bevy_nature_harness::{RenderHarness, require_adapter};
    let Some(adapter) = require_adapter("terrain --bench") else {
        return AppExit::error();
    };
    if !adapter.timestamp_queries {
        eprintln!(
            "terrain --bench: the adapter '{}' has no GPU timestamp queries, so GPU times cannot \
             be measured; no figures are reported",
            adapter.name
        );
        return AppExit::error();
    }
    if terrain.heights.is_none() {
        eprintln!("terrain --bench measures the relief: drop --flat, or give --heights DIR");
        return AppExit::error();
    }
    let frames = args.frames.unwrap_or(8);
    let size = args.size.unwrap_or(UVec2::new(640, 360));
    let run = || -> Result<Vec<BenchRow>, String> {
        let mut harness =
            RenderHarness::new(HarnessConfig::sized(size.x, size.y)).map_err(|e| e.to_string())?;
        let mapping = terrain.mapping;
        harness
            .app_mut()
            .add_plugins(bevy_nature::NaturePlugins)
            .insert_resource(ClearColor(Color::srgb(0.62, 0.74, 0.9)))
            .insert_resource(ClipmapSettings {
                budget,
                ..default()
            })
            .insert_resource(terrain.clone())
            .init_resource::<Altitude>()
            .insert_resource(Culling(true))
            .add_systems(Startup, setup);
        harness.wait_until_ready().map_err(|e| e.to_string())?;
        let (altitude, _) = altitude_and_speed(&mapping);
        let direction = DVec2::new(1.0, 1.0).normalize();
        let mut rows = Vec::new();
        for station in 0..5 {
            // 20 s of flight apart.
            let p =
                start(&mapping) + direction * (altitude * 250.0 / 300.0) * 20.0 * station as f64;
            let world = harness.world_mut();
            let origin = floating_origin(p);
            world.insert_resource(origin);
            let mut cameras = world.query_filtered::<&mut Transform, With<Camera3d>>();
            let mut place = |world: &mut World, altitude: f64| {
                for mut t in cameras.iter_mut(world) {
                    *t = Transform::from_translation(
                        origin.render_of(DVec3::new(p.x, altitude, p.y)),
                    )
                    .looking_to(Vec3::new(0.7, -0.35, 0.7), Vec3::Y);
                }
            };
            place(world, altitude);
            // Stream around the station, then keep 150 m above the ground there.
            let settle = |harness: &mut RenderHarness| -> Result<(), String> {
                for _ in 0..400 {
                    harness.run_frames(1).map_err(|e| e.to_string())?;
                    let world = harness.world_mut();
                    let mut stacks = world.query::<&ClipStackTexture>();
                    if stacks.iter(world).all(|c| {
                        c.base_ready()
                            && c.writes().is_empty()
                            && c.stack.layers.iter().all(|l| l.complete())
                    }) {
                        return Ok(());
                    }
                }
                Err("the stacks did not settle in 400 frames".into())
            };
            settle(&mut harness)?;
            let world = harness.world_mut();
            let mut heights = world.query_filtered::<&mut ClipStackTexture, With<Heights>>();
            let ground = heights
                .single_mut(world)
                .ok()
                .and_then(|mut h| h.resident_height(p))
                .map_or(0.0, |(h, _)| h as f64);
            place(world, ground + 150.0);
            settle(&mut harness)?;
            for vertex_px in [3.0, DEFAULT_VERTEX_PIXELS] {
                for culling in [true, false] {
                    let world = harness.world_mut();
                    let mut geometry = world.query::<&mut TerrainGeometry>();
                    for mut g in geometry.iter_mut(world) {
                        g.precision = TerrainPrecision::VertexPixels(vertex_px);
                        g.culling = culling;
                    }
                    harness.run_frames(4).map_err(|e| e.to_string())?;
                    harness.reset_timing();
                    // Whole-frame timestamps are read back a frame or two late.
                    harness.run_frames(frames + 2).map_err(|e| e.to_string())?;
                    let gpu_frame_ms = harness.gpu_frame_time_ms()?;
                    let triangles = harness.diagnostic(&TRIANGLES).unwrap_or(0.0);
                    let world = harness.world_mut();
                    let mut patches = world.query::<&TerrainPatches>();
                    let p = patches
                        .single(world)
                        .map_err(|e| format!("terrain patches: {e}"))?;
                    let row = BenchRow {
                        station,
                        vertex_px,
                        culling,
                        triangles,
                        patches: p.selection.patches.len() as f64,
                        culled: p.selection.stats.culled as f64,
                        gpu_frame_ms,
                        selection_us: p.selection_us,
                    };
                    eprintln!(
                        "terrain --bench: station {station}, vertices {vertex_px} px apart, culling \
                         {}: {:.0} triangles, {:.0} patches ({:.0} culled), GPU frame {:.2} ms \
                         ({:.1} M triangles/s), selection {:.0} µs",
                        if culling { "on" } else { "off" },
                        row.triangles,
                        row.patches,
                        row.culled,
                        row.gpu_frame_ms,
                        row.triangles / row.gpu_frame_ms / 1000.0,
                        row.selection_us
                    );
                    rows.push(row);
                }
            }
        }
        Ok(rows)
    };
    let rows = match run() {
        Ok(rows) => rows,
        Err(e) => {
            eprintln!("terrain --bench: {e}");
            return AppExit::error();
        }
    };
    // The headline: the triangle rate at the default precision with culling, and culling's
    // frame-time ratio per precision (paper: culling doubles to triples the frame rate).
    for vertex_px in [3.0, DEFAULT_VERTEX_PIXELS] {
        let sum = |culling: bool, f: fn(&BenchRow) -> f64| -> f64 {
            rows.iter()
                .filter(|r| r.vertex_px == vertex_px && r.culling == culling)
                .map(f)
                .sum()
        };
        let (on, off) = (
            sum(true, |r| r.gpu_frame_ms),
            sum(false, |r| r.gpu_frame_ms),
        );
        let rate = sum(true, |r| r.triangles) / on / 1000.0;
        println!(
            "terrain --bench ({}, {}x{}, GPU timestamps): vertices {vertex_px} px apart: \
             {rate:.1} M triangles/s with culling; culling speeds the frame up {:.2}x \
             ({:.2} ms vs {:.2} ms a frame over {} stations)",
            adapter.name,
            size.x,
            size.y,
            off / on,
            on / 5.0,
            off / 5.0,
            5
        );
    }
    if let Some(path) = &args.stats {
        let json = serde_json::json!({
            "rows": rows.iter().map(|r| serde_json::json!({
                "station": r.station,
                "vertex_px": r.vertex_px,
                "culling": r.culling,
                "triangles": r.triangles,
                "patches": r.patches,
                "culled": r.culled,
                "gpu_frame_ms": r.gpu_frame_ms,
                "mtris_per_s": r.triangles / r.gpu_frame_ms / 1000.0,
                "selection_us": r.selection_us,
            })).collect::<Vec<_>>(),
            "timing": "timestamps",
            "adapter": adapter.name,
        });
        if let Err(e) = std::fs::write(path, serde_json::to_string_pretty(&json).unwrap()) {
            eprintln!("terrain --bench: cannot write {path:?}: {e}");
            return AppExit::error();
        }
    }
    AppExit::Success
}
