//! The grass benchmark (Boulanger 2008, thesis §4.4), headless, one process: a field of grass to
//! the horizon drawn by our levels (blade geometry near, volume slices, the horizontal slice and
//! macro-cells far) and by what the Bevy grass crates draw — plain instanced blade geometry to the
//! same distance — each swept over its settings, every image compared with an all-geometry
//! reference rendered in the same run.
//!
//! Rows (`mode`):
//! - `reference`: every blade as geometry to `distance`, full segments (rendered once, untimed);
//! - `geometry`: the baseline — the base patch mesh instanced per cell (mirrored as ours) with
//!   Bevy's `StandardMaterial`, opaque, no discard, no dither, nothing of ours switched on; swept
//!   over blade segments, how far it reaches (beyond: bare ground) and whether the blades cast
//!   into the sun's shadow maps;
//! - `ours`: a `GrassField`, swept over the transition distances, the vertical slices per axis,
//!   the silhouette slices and whether the blades cast into the shadow maps
//!   (`GrassSettings::cast_shadow_maps`; off, the blade shadow mask alone shades them). The
//!   reference's blades cast.
//!
//! Both draw the same blades in the same colours (the species' root-to-tip gradient as vertex
//! colours for the baseline, with no ambient occlusion on either side), so the reference is the
//! baseline at its best and the error of ours is what its levels change.
//!
//! Frame time is GPU-synchronised: each frame is `App::update` (the renderer runs inside it,
//! unpipelined) followed by a blocking wait until the GPU has finished everything submitted
//! (`timing: "gpu-synchronised"`). `virtual_blades` counts the blades of every cell in view within
//! `distance` (the field's content); `geometry_blades` those drawn as geometry. `rmse` is per
//! pixel; `rmse_4x4` compares 4×4 block means — the grass's colour and coverage rather than which
//! blade lands on which pixel: two renders of equally good grass differ per pixel almost as much
//! as a poor one (the baseline with two segments a blade instead of four, the same blades
//! otherwise, is 0.07 per pixel from the reference). The headline, `speedup_at_matched_rmse`, is
//! ours over the baseline's lower envelope interpolated at our `rmse_4x4`, our worst case over the
//! matched range (`bevy_nature::bench_curves`).
//!
//! ```text
//! cargo run --release --example grass_bench -- [--preset gpu|quick] [--distance M]
//!     [--strata N] [--frames N] [--size WxH] [--transitions G0,G1,V0,V1]...
//!     [--ours-only] [--only-level geometry|slices] [--no-shadow-maps] [--gpu-passes] [--screenshot DIR] [--stats FILE]
//! ```
//! `--preset gpu` (default): 400 m of the default species (576 blades per 0.5 m patch); the
//! all-geometry reference is some 10^9 triangles, for a GPU. `--preset quick`: 40 m of a sparser
//! species at 160×90, what a software rasteriser can finish. `--transitions` (repeatable)
//! replaces the preset's sweep of ours' transitions (`min_geom,max_geom,min_btf,max_btf`, m).
//! `--ours-only` skips the baseline and the reference (no RMSE): the count of virtual blades
//! ours draws in view. `--only-level geometry|slices` draws one of ours' levels alone (to time
//! them apart; its RMSE then counts what the other level would have drawn). `--no-shadow-maps`:
//! the sun casts no shadow map on either side (ours keeps its blade shadow mask). Both sides
//! draw in still air; each measurement follows a few unmeasured frames. `--gpu-passes` records
//! GPU timestamps and prints each configuration's whole-frame GPU time and its passes' times.

use bevy::camera::primitives::Frustum;
use bevy::light::NotShadowCaster;
use bevy::prelude::*;
use bevy_nature::bench_curves::{matched_speedups, speedups_at_baseline_points};
use bevy_nature::foliage::grass::bake::GrassSliceBakeCamera;
use bevy_nature::foliage::grass::lighting::{BLADE_PERCEPTUAL_ROUGHNESS, BLADE_REFLECTANCE};
use bevy_nature::foliage::grass::mesh::patch_mesh;
use bevy_nature::foliage::grass::patch::{BasePatch, Mirror, PatchSettings};
use bevy_nature::foliage::grass::quadtree::{
    CellGrid, CellNode, CellView, GroundBounds, select_cells,
};
use bevy_nature::foliage::grass::systems::{
    GEOMETRY_BLADES, cell_transform, field_grid, grass_ready,
};
use bevy_nature::foliage::grass::transition::TransitionDistances;
use bevy_nature::foliage::grass::{GrassField, GrassSettings, GrassSpecies};
use bevy_nature_harness::compare::{Comparison, RgbaImage};
use bevy_nature_harness::headless::HarnessConfig;
use bevy_nature_harness::{RenderHarness, require_adapter};
use std::path::PathBuf;

struct Args {
    distance: f32,
    strata: u32,
    frames: u32,
    size: UVec2,
    ours_only: bool,
    /// Ours draws one level only (`geometry` or `slices`), to time the levels apart.
    only_level: Option<&'static str>,
    /// The sun casts no shadow maps (either side).
    no_shadow_maps: bool,
    /// Record GPU timestamps and print each configuration's GPU frame time and pass times.
    gpu_passes: bool,
    screenshots: Option<PathBuf>,
    stats: Option<PathBuf>,
    ours_sweep: Vec<TransitionDistances>,
}

fn distances(min_geom: f32, max_geom: f32, min_btf: f32, max_btf: f32) -> TransitionDistances {
    TransitionDistances {
        min_geom,
        max_geom,
        min_btf,
        max_btf,
        max_silhouettes: max_btf * 4.0,
        ..default()
    }
}

/// Unmeasured GPU-synchronised frames before each measurement: the software rasteriser compiles
/// a pipeline's shaders at its first draws, and a new configuration's first frames run up to
/// twice as long as its steady ones.
const WARM_UP_FRAMES: u32 = 5;

fn parse_args() -> Args {
    let mut args = Args {
        distance: 400.0,
        strata: 24,
        frames: 10,
        size: UVec2::new(640, 360),
        ours_only: false,
        only_level: None,
        no_shadow_maps: false,
        gpu_passes: false,
        screenshots: None,
        stats: None,
        ours_sweep: Vec::new(),
    };
    let mut preset = "gpu".to_string();
    let (mut distance, mut strata, mut size) = (None, None, None);
    let mut transitions: Vec<TransitionDistances> = Vec::new();
    let mut it = std::env::args().skip(1);
    let usage = "flags: [--preset gpu|quick] [--distance M] [--strata N] [--frames N] [--size WxH] [--transitions G0,G1,V0,V1]... [--ours-only] [--only-level geometry|slices] [--no-shadow-maps] [--gpu-passes] [--screenshot DIR] [--stats FILE]";
    let fail = |m: String| -> ! {
        eprintln!("{m}; {usage}");
        std::process::exit(2)
    };
    while let Some(flag) = it.next() {
        let mut value = || {
            it.next()
                .unwrap_or_else(|| fail(format!("{flag} needs a value")))
        };
        match flag.as_str() {
            "--preset" => preset = value(),
            "--distance" => {
                distance = Some(
                    value()
                        .parse::<f32>()
                        .ok()
                        .filter(|d| *d > 1.0 && d.is_finite())
                        .unwrap_or_else(|| fail("--distance takes metres > 1".into())),
                )
            }
            "--strata" => {
                strata = Some(
                    value()
                        .parse::<u32>()
                        .ok()
                        .filter(|s| (1..=64).contains(s))
                        .unwrap_or_else(|| fail("--strata takes 1..=64".into())),
                )
            }
            "--frames" => {
                args.frames = value()
                    .parse::<u32>()
                    .ok()
                    .filter(|f| *f > 0)
                    .unwrap_or_else(|| fail("--frames takes a whole number > 0".into()))
            }
            "--size" => {
                size = Some(
                    bevy_nature_harness::runner::parse_size(&value()).unwrap_or_else(|e| fail(e)),
                )
            }
            "--transitions" => {
                let v: Vec<f32> = value()
                    .split(',')
                    .filter_map(|x| x.trim().parse::<f32>().ok())
                    .collect();
                let t = match v[..] {
                    [a, b, c, d] => distances(a, b, c, d),
                    _ => fail("--transitions takes min_geom,max_geom,min_btf,max_btf".into()),
                };
                if let Err(e) = t.validate() {
                    fail(format!("--transitions: {e}"));
                }
                transitions.push(t);
            }
            "--ours-only" => args.ours_only = true,
            "--only-level" => {
                args.only_level = Some(match value().as_str() {
                    "geometry" => "geometry",
                    "slices" => "slices",
                    other => fail(format!(
                        "--only-level takes geometry or slices, not {other}"
                    )),
                })
            }
            "--no-shadow-maps" => args.no_shadow_maps = true,
            "--gpu-passes" => args.gpu_passes = true,
            "--screenshot" => args.screenshots = Some(value().into()),
            "--stats" => args.stats = Some(value().into()),
            other => fail(format!("unknown flag {other}")),
        }
    }
    match preset.as_str() {
        "gpu" => {
            args.ours_sweep = vec![
                distances(8.0, 16.0, 40.0, 80.0),
                distances(4.0, 8.0, 20.0, 40.0),
                distances(16.0, 32.0, 60.0, 120.0),
            ];
        }
        "quick" => {
            args.distance = 40.0;
            args.strata = 8;
            args.size = UVec2::new(160, 90);
            args.frames = 10;
            args.ours_sweep = vec![
                distances(2.0, 4.0, 8.0, 16.0),
                distances(1.0, 2.0, 4.0, 8.0),
                distances(4.0, 8.0, 12.0, 24.0),
            ];
        }
        other => fail(format!("unknown preset {other}")),
    }
    if !transitions.is_empty() {
        args.ours_sweep = transitions;
    }
    args.distance = distance.unwrap_or(args.distance);
    args.strata = strata.unwrap_or(args.strata);
    args.size = size.unwrap_or(args.size);
    args
}

/// The species: default blades, `strata²` a patch, no ambient occlusion (the baseline's
/// `StandardMaterial` has none per vertex, so neither side gets it).
fn species(strata: u32) -> GrassSpecies {
    GrassSpecies {
        patch: PatchSettings {
            strata,
            ..default()
        },
        root_ao: 1.0,
        ..default()
    }
}

/// Flat ground.
struct Flat;
impl GroundBounds for Flat {
    fn height_range(&self, _: &CellGrid, _: CellNode) -> (f32, f32) {
        (0.0, 0.0)
    }
    fn is_flat(&self, _: &CellGrid, _: CellNode) -> bool {
        true
    }
}

/// Marks the baseline's cells.
#[derive(Component)]
struct BaselineCell;

fn camera_transform(distance: f32) -> Transform {
    Transform::from_xyz(0.0, 1.7, -1.05 * distance).looking_to(Vec3::new(0.0, -0.1, 1.0), Vec3::Y)
}

/// The cells in view within `reach` (single cells), from the camera's frustum.
fn cells_in_view(
    harness: &mut RenderHarness,
    grid: &CellGrid,
    reach: f32,
    height: f32,
) -> Vec<CellNode> {
    let world = harness.world_mut();
    let (transform, frustum) = world
        .query_filtered::<(&GlobalTransform, &Frustum), (With<Camera3d>, Without<GrassSliceBakeCamera>)>()
        .single(world)
        .expect("one camera");
    let view = CellView {
        eye: transform.translation(),
        frustum: Some(frustum.half_spaces.map(|h| h.normal_d())),
        max_distance: reach,
        macro_from: f32::INFINITY,
        split_factor: 2.0,
        grass_height: height,
    };
    select_cells(grid, &Flat, &view)
        .drawn
        .into_iter()
        .map(|(node, _)| node)
        .collect()
}

/// The patch mesh with each vertex coloured by the species' root-to-tip gradient.
fn coloured_patch_mesh(patch: &BasePatch, species: &GrassSpecies, segments: u32) -> Mesh {
    let mut mesh = patch_mesh(patch, species.patch.width, segments);
    let Some(bevy::mesh::VertexAttributeValues::Float32x2(uv1)) =
        mesh.attribute(Mesh::ATTRIBUTE_UV_1)
    else {
        unreachable!()
    };
    let (r, t) = (species.root_color, species.tip_color);
    let colours: Vec<[f32; 4]> = uv1
        .iter()
        .map(|uv| {
            let h = uv[1].clamp(0.0, 1.0);
            [
                r.red + (t.red - r.red) * h,
                r.green + (t.green - r.green) * h,
                r.blue + (t.blue - r.blue) * h,
                1.0,
            ]
        })
        .collect();
    mesh.insert_attribute(Mesh::ATTRIBUTE_COLOR, colours);
    mesh
}

/// The baseline's sweep: (segments a blade, reach as a share of the distance, casts into the
/// shadow maps).
fn baseline_sweep(full_segments: u32) -> Vec<(u32, f32, bool)> {
    let mut sweep = Vec::new();
    for casts in [true, false] {
        for segments in [full_segments, 2, 1] {
            for reach in [1.0, 0.5, 0.25] {
                sweep.push((segments, reach, casts));
            }
        }
    }
    sweep
}

/// Replaces the baseline's cells: `segments` per blade, cells within `reach`, casting into the
/// sun's shadow maps or not.
#[allow(clippy::too_many_arguments)]
fn spawn_baseline(
    harness: &mut RenderHarness,
    cells: &[CellNode],
    grid: &CellGrid,
    patch: &BasePatch,
    species: &GrassSpecies,
    segments: u32,
    reach: f32,
    casts: bool,
) -> u64 {
    let world = harness.world_mut();
    let old: Vec<Entity> = world
        .query_filtered::<Entity, With<BaselineCell>>()
        .iter(world)
        .collect();
    for e in old {
        world.despawn(e);
    }
    let mesh = world
        .resource_mut::<Assets<Mesh>>()
        .add(coloured_patch_mesh(patch, species, segments));
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::WHITE,
            perceptual_roughness: BLADE_PERCEPTUAL_ROUGHNESS,
            reflectance: BLADE_REFLECTANCE,
            diffuse_transmission: species.transmission,
            double_sided: true,
            cull_mode: None,
            ..default()
        });
    let camera = world
        .query_filtered::<&GlobalTransform, (With<Camera3d>, Without<GrassSliceBakeCamera>)>()
        .single(world)
        .expect("camera")
        .translation();
    let mut drawn = 0u64;
    for node in cells {
        let (corner, side) = grid.rect(*node);
        let nearest = Vec2::new(
            camera.x.clamp(corner.x, corner.x + side),
            camera.z.clamp(corner.y, corner.y + side),
        );
        if (nearest - camera.xz()).length() > reach {
            continue;
        }
        let mirror = Mirror::of_cell(node.x as i64, node.z as i64, species.patch.seed);
        let mut cell = world.spawn((
            BaselineCell,
            Mesh3d(mesh.clone()),
            MeshMaterial3d(material.clone()),
            cell_transform(corner, side, mirror),
        ));
        if !casts {
            cell.insert(NotShadowCaster);
        }
        drawn += patch.blades.len() as u64;
    }
    drawn
}

struct Row {
    mode: &'static str,
    params: String,
    virtual_blades: u64,
    geometry_blades: u64,
    frame_ms: f64,
    frame_ms_p95: f64,
    /// Median GPU frame time from timestamps (`--gpu-passes`).
    gpu_frame_ms: Option<f64>,
    rmse: Option<f64>,
    rmse_4x4: Option<f64>,
}

fn measure(
    harness: &mut RenderHarness,
    frames: u32,
    reference: Option<&RgbaImage>,
    name: &str,
    shots: Option<&PathBuf>,
) -> Measured {
    harness.wait_until(grass_ready).expect("ready");
    for _ in 0..2 {
        harness.step();
    }
    harness
        .run_frames_gpu_synchronised(WARM_UP_FRAMES)
        .expect("warm-up frames");
    harness.reset_timing();
    harness
        .run_frames_gpu_synchronised(frames)
        .expect("measured frames");
    let stats = harness.frame_stats();
    let mut gpu_frame_ms = None;
    if harness.has_gpu_timestamps() {
        // Timestamp results arrive a frame or two late.
        harness
            .run_frames_gpu_synchronised(3)
            .expect("frames for late timestamps");
        let passes = harness.run_stats(name).gpu_pass_ms;
        let mut passes: Vec<_> = passes.into_iter().filter(|(_, ms)| *ms >= 0.05).collect();
        passes.sort_by(|a, b| b.1.total_cmp(&a.1));
        let list: Vec<String> = passes
            .iter()
            .map(|(pass, ms)| format!("{pass} {ms:.2}"))
            .collect();
        let gpu = harness.gpu_frame_time_ms();
        eprintln!(
            "grass_bench: {name}: GPU frame {} ms (timestamps); passes (ms): {}",
            gpu.as_ref()
                .map_or_else(|e| e.clone(), |ms| format!("{ms:.2}")),
            list.join(", ")
        );
        gpu_frame_ms = gpu.ok();
    }
    let image = harness.render().expect("render");
    if let Some(dir) = shots {
        std::fs::create_dir_all(dir).ok();
        image.save_png(dir.join(format!("{name}.png"))).ok();
    }
    let rmse = reference.map(|r| {
        (
            Comparison::new(format!("grass_bench/{name}"), &image, r).rmse,
            Comparison::new(
                format!("grass_bench/{name}_4x4"),
                &image.box_downsample(4),
                &r.box_downsample(4),
            )
            .rmse,
        )
    });
    Measured {
        ms: stats.median_ms,
        p95: stats.p95_ms,
        gpu_frame_ms,
        rmse,
    }
}

/// One configuration's measurement: GPU-synchronised frame time (median, p95), the GPU frame
/// time from timestamps where recorded, and (per pixel, 4×4 blocks) RMSE against the reference.
struct Measured {
    ms: f64,
    p95: f64,
    gpu_frame_ms: Option<f64>,
    rmse: Option<(f64, f64)>,
}

fn main() {
    let args = parse_args();
    if require_adapter("grass_bench").is_none() {
        eprintln!("grass_bench: no GPU adapter");
        std::process::exit(1);
    }
    let species = species(args.strata);
    let patch = BasePatch::generate(&species.patch);
    let field_size = Vec2::splat(2.2 * args.distance);
    let grid = field_grid(Vec2::ZERO, field_size, species.patch.size);
    let mut harness = RenderHarness::new(HarnessConfig {
        gpu_timing: args.gpu_passes,
        ..HarnessConfig::sized(args.size.x, args.size.y)
    })
    .expect("harness");
    harness
        .app_mut()
        .add_plugins(bevy_nature::NaturePlugins)
        .insert_resource(ClearColor(Color::srgb(0.62, 0.74, 0.9)))
        .insert_resource(GrassSettings {
            max_distance: args.distance,
            geometry: false,
            slices: false,
            // As the reference draws it: still air.
            wind: bevy_nature::foliage::grass::GrassWind {
                strength: 0.0,
                ..default()
            },
            ..default()
        });
    {
        let world = harness.world_mut();
        let ground = world.resource_mut::<Assets<Mesh>>().add(
            Plane3d::default()
                .mesh()
                .size(field_size.x * 1.5, field_size.y * 1.5),
        );
        let ground_material =
            world
                .resource_mut::<Assets<StandardMaterial>>()
                .add(StandardMaterial {
                    base_color: Color::srgb(0.2, 0.17, 0.09),
                    perceptual_roughness: 1.0,
                    ..default()
                });
        world.spawn((Mesh3d(ground), MeshMaterial3d(ground_material)));
        world.spawn((
            DirectionalLight {
                illuminance: 10_000.0,
                shadow_maps_enabled: !args.no_shadow_maps,
                ..default()
            },
            Transform::default().looking_to(Vec3::new(-0.5, -0.7, 0.6), Vec3::Y),
        ));
        world.insert_resource(GlobalAmbientLight {
            brightness: 500.0,
            ..default()
        });
        world.spawn((
            Camera3d::default(),
            Msaa::Off,
            camera_transform(args.distance),
        ));
    }
    harness.wait_until_ready().expect("ready");
    let cells = cells_in_view(&mut harness, &grid, args.distance, species.patch.height.1);
    let virtual_blades = cells.len() as u64 * patch.blades.len() as u64;
    eprintln!(
        "grass_bench: {} cells in view within {} m: {virtual_blades} virtual blades ({:.2e})",
        cells.len(),
        args.distance,
        virtual_blades as f64
    );
    let shots = args.screenshots.as_ref();
    let mut rows = Vec::new();
    let reference = if args.ours_only {
        None
    } else {
        // The reference: every blade, full segments, to the full distance.
        spawn_baseline(
            &mut harness,
            &cells,
            &grid,
            &patch,
            &species,
            species.patch.segments,
            args.distance,
            true,
        );
        harness.wait_until_ready().expect("reference ready");
        let image = harness.render().expect("reference");
        if let Some(dir) = shots {
            std::fs::create_dir_all(dir).ok();
            image.save_png(dir.join("reference.png")).ok();
        }
        // Swept over segments, reach and whether the blades cast into the shadow maps (the
        // reference's blades do: without, the blades lose their shadows on one another and on
        // the ground, and every shadow pass skips them).
        for (segments, reach, casts) in baseline_sweep(species.patch.segments) {
            let reach = args.distance * reach;
            {
                let drawn = spawn_baseline(
                    &mut harness,
                    &cells,
                    &grid,
                    &patch,
                    &species,
                    segments,
                    reach,
                    casts,
                );
                let cast_tag = if casts { "" } else { "_nocast" };
                let name = format!("geometry_s{segments}_r{reach:.0}{cast_tag}");
                let Measured {
                    ms,
                    p95,
                    gpu_frame_ms,
                    rmse,
                } = measure(&mut harness, args.frames, Some(&image), &name, shots);
                let (rmse, rmse_4x4) = rmse.expect("a reference");
                eprintln!(
                    "grass_bench: {name}: {ms:.1} ms, rmse {rmse:.4}, 4×4 blocks {rmse_4x4:.4}"
                );
                rows.push(Row {
                    mode: "geometry",
                    params: format!(
                        "segments {segments}, reach {reach:.0} m, {}",
                        if casts {
                            "casts shadow maps"
                        } else {
                            "casts no shadow map"
                        }
                    ),
                    virtual_blades,
                    geometry_blades: drawn,
                    frame_ms: ms,
                    frame_ms_p95: p95,
                    gpu_frame_ms,
                    rmse: Some(rmse),
                    rmse_4x4: Some(rmse_4x4),
                });
            }
        }
        spawn_baseline(&mut harness, &[], &grid, &patch, &species, 1, 0.0, true);
        Some(image)
    };
    // Ours, swept over its transitions, the slices per axis (K: fewer slices, fewer fragments
    // where they overlap) and the silhouette slices of eq. 4.14 (at a grazing view even flat
    // ground has them out to `max_silhouettes`; off: the horizontal slice alone beyond
    // `max_btf`). The blade shadow mask stays on: the reference's blades shade each other
    // through Bevy's shadow map, which ours beyond the blades' reach cannot (slices cast none).
    for per_axis in [2, 4] {
        harness
            .world_mut()
            .resource_mut::<GrassSettings>()
            .slice_per_axis = per_axis;
        let field = harness
            .world_mut()
            .spawn(GrassField {
                size: field_size,
                species: species.clone(),
                density: None,
                ground: None,
                ambient_occlusion: None,
            })
            .id();
        for t in &args.ours_sweep {
            for (silhouettes, casts) in [(true, true), (false, true), (true, false), (false, false)]
            {
                let t = TransitionDistances {
                    max_silhouettes: if silhouettes {
                        t.max_silhouettes
                    } else {
                        t.max_btf
                    },
                    ..*t
                };
                {
                    let mut settings = harness.world_mut().resource_mut::<GrassSettings>();
                    settings.transitions = t;
                    settings.geometry = args.only_level != Some("slices");
                    settings.slices = args.only_level != Some("geometry");
                    settings.shadow_mask = true;
                    settings.cast_shadow_maps = casts;
                }
                let name = format!(
                    "ours_g{}-{}_v{}-{}_k{per_axis}{}{}",
                    t.min_geom,
                    t.max_geom,
                    t.min_btf,
                    t.max_btf,
                    if silhouettes { "_sil" } else { "" },
                    if casts { "" } else { "_nocast" }
                );
                let Measured {
                    ms,
                    p95,
                    gpu_frame_ms,
                    rmse,
                } = measure(&mut harness, args.frames, reference.as_ref(), &name, shots);
                let geometry_blades = harness.diagnostic(&GEOMETRY_BLADES).unwrap_or(0.0) as u64;
                eprintln!(
                    "grass_bench: {name}: {ms:.1} ms, {geometry_blades} geometry blades, rmse {rmse:?}"
                );
                rows.push(Row {
                    // One level alone is not ours as a whole: kept out of the headline.
                    mode: match args.only_level {
                        Some("geometry") => "ours_geometry_only",
                        Some(_) => "ours_slices_only",
                        None => "ours",
                    },
                    params: format!(
                        "geometry {}–{} m, vertical slices to {}–{} m, K = {per_axis}, silhouettes {}, {}",
                        t.min_geom,
                        t.max_geom,
                        t.min_btf,
                        t.max_btf,
                        if silhouettes {
                            format!("to {} m", t.max_silhouettes)
                        } else {
                            "off".to_string()
                        },
                        if casts {
                            "blades cast shadow maps"
                        } else {
                            "blades cast no shadow map"
                        }
                    ),
                    virtual_blades,
                    geometry_blades,
                    frame_ms: ms,
                    frame_ms_p95: p95,
                    gpu_frame_ms,
                    rmse: rmse.map(|r| r.0),
                    rmse_4x4: rmse.map(|r| r.1),
                });
            }
        }
        harness.world_mut().despawn(field);
    }
    let points = |mode: &str| -> Vec<(f64, f64)> {
        rows.iter()
            .filter(|r| r.mode == mode)
            .filter_map(|r| r.rmse_4x4.map(|e| (e, r.frame_ms)))
            .collect()
    };
    let matched = matched_speedups(&points("ours"), &points("geometry"));
    let headline = matched.iter().map(|m| m.1).min_by(f64::total_cmp);
    // The same on GPU timestamps (with `--gpu-passes`, every row timed): the GPU's share alone,
    // what a pipelined game overlapping CPU and GPU would see of the GPU side.
    let gpu_points = |mode: &str| -> Option<Vec<(f64, f64)>> {
        rows.iter()
            .filter(|r| r.mode == mode)
            .filter(|r| r.rmse_4x4.is_some())
            .map(|r| Some((r.rmse_4x4?, r.gpu_frame_ms?)))
            .collect()
    };
    let matched_gpu = match (gpu_points("ours"), gpu_points("geometry")) {
        (Some(ours), Some(geometry)) => matched_speedups(&ours, &geometry),
        _ => Vec::new(),
    };
    let headline_gpu = matched_gpu.iter().map(|m| m.1).min_by(f64::total_cmp);
    let at_baseline = speedups_at_baseline_points(&points("ours"), &points("geometry"));
    let json_f = |v: Option<f64>| v.map_or("null".to_string(), |v| format!("{v:.5}"));
    let rows_json: Vec<String> = rows
        .iter()
        .map(|r| {
            format!(
                "{{\"mode\": \"{}\", \"params\": \"{}\", \"virtual_blades\": {}, \"geometry_blades\": {}, \"frame_ms\": {:.3}, \"frame_ms_p95\": {:.3}, \"gpu_frame_ms\": {}, \"rmse\": {}, \"rmse_4x4\": {}}}",
                r.mode, r.params, r.virtual_blades, r.geometry_blades, r.frame_ms, r.frame_ms_p95, json_f(r.gpu_frame_ms), json_f(r.rmse), json_f(r.rmse_4x4)
            )
        })
        .collect();
    let matched_json: Vec<String> = matched
        .iter()
        .map(|(e, s)| format!("{{\"rmse\": {e:.5}, \"speedup\": {s:.3}}}"))
        .collect();
    let at_baseline_json: Vec<String> = at_baseline
        .iter()
        .map(|(e, s)| format!("{{\"baseline_rmse\": {e:.5}, \"speedup\": {}}}", json_f(*s)))
        .collect();
    let json = format!(
        "{{\"bench\": \"grass\", \"headline\": \"speedup_at_matched_rmse (ours over plain instanced blade geometry at equal rmse_4x4 against the all-geometry reference; our worst case; > 1: ours faster)\", \"timing\": \"gpu-synchronised\", \"distance_m\": {}, \"blades_per_patch\": {}, \"size\": [{}, {}], \"frames\": {}, \"virtual_blades_in_view\": {virtual_blades}, \"speedup_at_matched_rmse\": {}, \"matched_points\": [{}], \"speedup_at_matched_rmse_gpu_timestamps\": {}, \"matched_points_gpu_timestamps\": [{}], \"speedup_at_baseline_points\": [{}], \"rows\": [\n  {}\n]}}",
        args.distance,
        patch.blades.len(),
        args.size.x,
        args.size.y,
        args.frames,
        json_f(headline),
        matched_json.join(", "),
        json_f(headline_gpu),
        matched_gpu
            .iter()
            .map(|(e, s)| format!("{{\"rmse\": {e:.5}, \"speedup\": {s:.3}}}"))
            .collect::<Vec<_>>()
            .join(", "),
        at_baseline_json.join(", "),
        rows_json.join(",\n  ")
    );
    println!("{json}");
    if let Some(path) = &args.stats
        && let Err(e) = bevy_nature_harness::stats::write_atomically(path, &json)
    {
        eprintln!("grass_bench: {e}");
        std::process::exit(1);
    }
}
