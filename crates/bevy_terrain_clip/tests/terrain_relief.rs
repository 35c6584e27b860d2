//! Terrain with relief on the GPU: seamless patches displaced by a streamed height clip stack
//! (`TerrainGeometry`), against the CPU references of the patch selection, the patch meshes and
//! the vertex stage's height lookup, on the adapter at hand (software Vulkan in CI).
//!
//! - **Vertex positions**: seen from the side through an orthographic camera, the terrain's
//!   silhouette in every pixel column — the highest point of any drawn triangle there — is where
//!   the CPU puts it: the selection the plugin made (`TerrainPatches`), each patch's lattice mesh
//!   (`geometry::tile`), each vertex raised to `geometry::relief::height_at` on the stack's
//!   coverage, back faces culled; within a pixel.
//! - **No cracks**: from a low eye over rough relief at a grazing angle, no pixel below the
//!   terrain's top in its column shows the background colour. (Tiles whose half-diagonals keep
//!   their own spacing instead of the shared one leave T-junctions that show it through 4
//!   pixels; the level boundaries' edge rule is proven on the CPU, `tests/patch_cracks.rs`.)

use bevy::camera::{OrthographicProjection, Projection, ScalingMode};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::math::{DVec2, DVec3, Vec2};
use bevy::prelude::*;
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::compare::RgbaImage;
use bevy_terrain_clip::geometry::relief::height_at;
use bevy_terrain_clip::geometry::tile::patch_mesh;
use bevy_terrain_clip::material::ClipmapMaterial;
use bevy_terrain_clip::source::ProceduralTileSource;
use bevy_terrain_clip::stack_gpu::{ClipStackTexture, TextureMapping};
use bevy_terrain_clip::terrain::{
    DEFAULT_VERTEX_PIXELS, TerrainGeometry, TerrainPatches, TerrainPrecision, TerrainTile,
};
use bevy_terrain_clip::{ClipmapSettings, RenderOrigin, TerrainClipPlugin, UpdateBudget};
use std::sync::Arc;

/// World side of the terrain (m); 64-texel tiles, 6 pyramid levels: level 11 (2048 texels) is
/// the finest, 1 m texels.
const TERRAIN_M: f64 = 2048.0;
const BACKGROUND: Color = Color::srgb(1.0, 0.0, 1.0);

/// Heights (m) at a level texel: rolling ridges and 40 m bumps (a mesh crack shows as a gap tall
/// enough to see), one continuous function of the texture coordinates sampled at each level's
/// texel centres.
fn terrain_height(level: u32, x: u64, y: u64) -> f32 {
    let n = (1u64 << level) as f64;
    let (u, v) = ((x as f64 + 0.5) / n, (y as f64 + 0.5) / n);
    let tau = std::f64::consts::TAU;
    (45.0 * (tau * 3.0 * u).sin() * (tau * 2.0 * v).cos()
        + 25.0 * (tau * 7.0 * v + 1.0).sin()
        + 12.0 * (tau * 13.0 * (u + v)).sin()
        + 6.0 * (tau * 50.0 * u).sin() * (tau * 47.0 * v).sin()) as f32
}

/// Rougher ground for the crack test: `terrain_height` with 30 m bumps 20 m across, where a gap
/// between neighbouring tiles' edges would be metres tall.
fn rough_height(level: u32, x: u64, y: u64) -> f32 {
    let n = (1u64 << level) as f64;
    let (u, v) = ((x as f64 + 0.5) / n, (y as f64 + 0.5) / n);
    let tau = std::f64::consts::TAU;
    terrain_height(level, x, y) + (30.0 * (tau * 97.0 * u).sin() * (tau * 101.0 * v).cos()) as f32
}

/// The ground a test draws: heights and colours (level texels) of pyramids of `levels` levels of
/// 64² tiles over a square `terrain_m` wide whose corner is at world `texture_origin`, with render
/// space under `render_origin`.
struct Ground {
    height: fn(u32, u64, u64) -> f32,
    colour: fn(u32, u64, u64) -> [u8; 4],
    terrain_m: f64,
    levels: u32,
    texture_origin: DVec2,
    render_origin: RenderOrigin,
}

impl Ground {
    /// White ground of `height` over [`TERRAIN_M`], at the origin.
    fn white(height: fn(u32, u64, u64) -> f32) -> Self {
        Self {
            height,
            colour: |_, _, _| [255; 4],
            terrain_m: TERRAIN_M,
            levels: 6,
            texture_origin: DVec2::ZERO,
            render_origin: RenderOrigin::default(),
        }
    }
}

/// The harness with `ground` (unlit) and `camera`; returns the terrain entity once the height
/// stack has settled.
fn relief_harness(
    test: &str,
    w: u32,
    h: u32,
    ground: Ground,
    camera: impl Bundle,
) -> Option<(RenderHarness, Entity)> {
    let Ground {
        height,
        colour,
        terrain_m,
        levels,
        texture_origin,
        render_origin,
    } = ground;
    let mut harness = RenderHarness::for_test(test, w, h)?;
    harness.app_mut().add_plugins(TerrainClipPlugin);
    harness.world_mut().insert_resource(render_origin);
    let settings = ClipmapSettings {
        clip_size: 128,
        subtile_size: 32,
        cache_tiles: 256,
        budget: UpdateBudget::Subtiles(64),
        ..default()
    };
    let mapping = TextureMapping {
        origin_m: texture_origin,
        size_m: terrain_m,
    };
    let terrain = {
        let world = harness.world_mut();
        world.insert_resource(ClearColor(BACKGROUND));
        let (heights, colour) = {
            let mut images = world.resource_mut::<Assets<Image>>();
            let mut heights = ClipStackTexture::heights(
                Arc::new(ProceduralTileSource::heights(64, levels, height)),
                &settings,
                [0.5, 0.5],
                &mut images,
            );
            heights.mapping = Some(mapping);
            let mut colour = ClipStackTexture::from_settings(
                Arc::new(ProceduralTileSource::new(64, levels, colour)),
                &settings,
                [0.5, 0.5],
                &mut images,
            );
            colour.mapping = Some(mapping);
            (heights, colour)
        };
        let mut colour = colour;
        let material = colour.material(
            StandardMaterial {
                unlit: true,
                ..default()
            },
            &mut world.resource_mut::<Assets<ClipmapMaterial>>(),
        );
        let heights = world.spawn(heights).id();
        world.spawn(colour);
        world.spawn(camera);
        world
            // The height range: what has streamed (`ClipStackTexture::height_range`).
            .spawn(TerrainGeometry::new(heights, material))
            .id()
    };
    harness.wait_until_ready().unwrap();
    // Let both stacks stream around the camera.
    for _ in 0..300 {
        harness.step();
        let settled = {
            let world = harness.world_mut();
            let mut q = world.query::<&ClipStackTexture>();
            q.iter(world).all(|c| {
                c.base_ready()
                    && c.writes().is_empty()
                    && c.stack.layers.iter().all(|l| l.complete())
            })
        };
        if settled {
            break;
        }
    }
    harness.run_frames(3).unwrap();
    Some((harness, terrain))
}

/// Renders a frame, saves it under the artifacts as `file` (when given), and returns it with the
/// patches the terrain drew.
fn render_patches(
    harness: &mut RenderHarness,
    terrain: Entity,
    file: Option<&str>,
) -> (RgbaImage, TerrainPatches) {
    let image = harness.render().unwrap();
    if let Some(file) = file {
        image
            .save_png(bevy_nature_harness::artifacts_dir().join(file))
            .ok();
    }
    let patches = harness
        .world_mut()
        .get::<TerrainPatches>(terrain)
        .unwrap()
        .clone();
    (image, patches)
}

fn is_background(image: &RgbaImage, x: u32, y: u32) -> bool {
    let i = ((y * image.width + x) * 4) as usize;
    let p = &image.data[i..i + 3];
    p[0] > 200 && p[1] < 80 && p[2] > 200
}

/// The topmost terrain row of each column (`None`: all background).
fn silhouette(image: &RgbaImage) -> Vec<Option<u32>> {
    (0..image.width)
        .map(|x| (0..image.height).find(|&y| !is_background(image, x, y)))
        .collect()
}

#[test]
fn the_silhouette_of_the_relief_is_where_the_cpu_puts_its_vertices() {
    const W: u32 = 128;
    const H: u32 = 64;
    // Looking along +z from beyond the terrain's near edge, 512 m wide, 256 m tall.
    let (view_w, view_h) = (512.0f32, 256.0f32);
    let eye = Vec3::new(900.0, 20.0, -200.0);
    let camera = (
        Camera3d::default(),
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
        Projection::Orthographic(OrthographicProjection {
            scaling_mode: ScalingMode::Fixed {
                width: view_w,
                height: view_h,
            },
            far: 5000.0,
            ..OrthographicProjection::default_3d()
        }),
        Transform::from_translation(eye).looking_to(Vec3::Z, Vec3::Y),
    );
    let Some((mut harness, terrain)) = relief_harness(
        "terrain_relief_silhouette",
        W,
        H,
        Ground::white(terrain_height),
        camera,
    ) else {
        return;
    };
    let (image, patches) =
        render_patches(&mut harness, terrain, Some("terrain_relief_silhouette.png"));
    let material = {
        let world = harness.world_mut();
        let handle = world
            .get::<TerrainGeometry>(terrain)
            .unwrap()
            .material
            .clone();
        world
            .resource::<Assets<ClipmapMaterial>>()
            .get(&handle)
            .unwrap()
            .extension
            .relief
    };
    let grid = patches.grid.unwrap();
    let layers = material.height_layers();
    let texel = |l: u32, x: i64, y: i64| terrain_height(l, x as u64, y as u64);
    // The CPU silhouette: per pixel column, the topmost pixel centre inside a front-facing
    // displaced triangle (looking along +z with y up, image right is world −x) — rasterised
    // as the GPU samples it: near the terrain's near edge the ground is seen almost edge on,
    // and its thin slivers cover some pixel centres and miss others.
    let px = view_w / W as f32;
    let right = eye.x + view_w / 2.0;
    let top = eye.y + view_h / 2.0;
    let mut first_row = vec![u32::MAX; W as usize];
    for patch in &patches.selection.patches {
        let mesh = patch_mesh(&grid, patch);
        let points: Vec<Vec3> = mesh
            .vertices
            .iter()
            .map(|&p| {
                let xz = grid.world(p);
                let lattice = Vec2::new(p[0] as f32, p[1] as f32);
                Vec3::new(xz.x, height_at(&layers, texel, lattice), xz.y)
            })
            .collect();
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| points[i as usize]);
            // Back faces are culled: the camera (looking along +z) sees a triangle whose normal
            // has a negative z — a slope rising away from it. (At the terrain's near edge,
            // ground falling away shows its underside to a camera level with it.)
            if (b - a).cross(c - a).z >= 0.0 {
                continue;
            }
            let [a, b, c] = [a, b, c].map(|p| Vec2::new(p.x, p.y));
            for (col, first) in first_row.iter_mut().enumerate() {
                let x = right - (col as f32 + 0.5) * px;
                // The triangle's extent on the vertical line x.
                let (mut low, mut high) = (f32::INFINITY, f32::NEG_INFINITY);
                for (p, q) in [(a, b), (b, c), (c, a)] {
                    if (p.x - x) * (q.x - x) <= 0.0 && p.x != q.x {
                        let y = p.y + (q.y - p.y) * (x - p.x) / (q.x - p.x);
                        low = low.min(y);
                        high = high.max(y);
                    }
                }
                if high < low {
                    continue;
                }
                let row = ((top - high) / px - 0.5).ceil().max(0.0);
                if top - (row + 0.5) * px >= low {
                    *first = (*first).min(row as u32);
                }
            }
        }
    }
    let gpu = silhouette(&image);
    let (mut worst, mut differing) = (0u32, 0u32);
    let mut rows = Vec::new();
    for col in 0..W as usize {
        let row = gpu[col].expect("terrain in every column");
        worst = worst.max(row.abs_diff(first_row[col]));
        differing += (row != first_row[col]) as u32;
        rows.push(row as f32);
    }
    let relief = rows.iter().cloned().fold(f32::NEG_INFINITY, f32::max)
        - rows.iter().cloned().fold(f32::INFINITY, f32::min);
    println!(
        "{} patches, {} triangles; silhouette rows span {relief} px; {differing} of {W} columns \
         differ from the CPU's, by at most {worst} px",
        patches.selection.patches.len(),
        patches.triangles
    );
    assert!(
        relief >= 10.0,
        "the relief shows: the silhouette spans {relief} rows"
    );
    // Pixel centres on a triangle's edge are a coin toss between the two: a few columns may be a
    // row off. (Sampling the base level everywhere instead of the finest layer puts 30 columns
    // off, by up to 3 rows.)
    assert!(worst <= 1, "the silhouette is {worst} px from the CPU's");
    assert!(
        differing <= W / 64,
        "{differing} columns differ from the CPU's"
    );
    // The tiles are the terrain's children: despawning it leaves none behind.
    let world = harness.world_mut();
    let tiles = world
        .query_filtered::<(), With<TerrainTile>>()
        .iter(world)
        .count();
    assert_eq!(tiles, 4 * patches.selection.patches.len());
    world.despawn(terrain);
    harness.run_frames(1).unwrap();
    let world = harness.world_mut();
    assert_eq!(
        world
            .query_filtered::<(), With<TerrainTile>>()
            .iter(world)
            .count(),
        0
    );
}

#[test]
fn a_grazing_view_over_the_relief_shows_no_cracks() {
    const W: u32 = 320;
    const H: u32 = 192;
    let camera = (
        Camera3d::default(),
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
        Transform::from_xyz(700.0, 110.0, 500.0)
            .looking_at(Vec3::new(1100.0, 40.0, 1300.0), Vec3::Y),
    );
    let Some((mut harness, terrain)) = relief_harness(
        "terrain_relief_cracks",
        W,
        H,
        Ground::white(rough_height),
        camera,
    ) else {
        return;
    };
    let (image, patches) =
        render_patches(&mut harness, terrain, Some("terrain_relief_grazing.png"));
    let levels: std::collections::BTreeSet<u8> = patches
        .selection
        .patches
        .iter()
        .map(|p| p.id.level)
        .collect();
    let mut holes = 0;
    let mut terrain_pixels = 0;
    for (x, top) in silhouette(&image).iter().enumerate() {
        let Some(top) = *top else {
            continue;
        };
        for y in top..H {
            if is_background(&image, x as u32, y) {
                holes += 1;
            } else {
                terrain_pixels += 1;
            }
        }
    }
    println!(
        "{} patches over levels {levels:?}; {terrain_pixels} terrain pixels, {holes} showing the \
         background below the terrain's top",
        patches.selection.patches.len()
    );
    assert!(
        levels.len() >= 3,
        "patches of several levels meet: {levels:?}"
    );
    assert!(terrain_pixels as u32 > W * H / 3);
    assert_eq!(holes, 0, "cracks");
}

/// Screen-space geometric error at the default precision: a grazing perspective view over a
/// 512 m terrain of 1 m heights, drawn at the default precision, at twice its vertex spacing,
/// and at full resolution (every patch at the finest level: vertices on every height texel) in
/// the same run; per pixel column, how far the terrain's top (its silhouette against the
/// background) is from the full mesh's.
#[test]
fn the_default_precision_keeps_the_silhouette_within_a_pixel_of_the_full_mesh() {
    const W: u32 = 320;
    const H: u32 = 180;
    let camera = (
        Camera3d::default(),
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
        Transform::from_xyz(80.0, 95.0, 60.0).looking_at(Vec3::new(300.0, 30.0, 380.0), Vec3::Y),
    );
    // 4 pyramid levels of 64² tiles: 512 texels of 1 m.
    let Some((mut harness, terrain)) = relief_harness(
        "terrain_relief_error",
        W,
        H,
        Ground {
            terrain_m: 512.0,
            levels: 4,
            ..Ground::white(terrain_height)
        },
        camera,
    ) else {
        return;
    };
    let mut render_at = |precision: TerrainPrecision| {
        harness
            .world_mut()
            .get_mut::<TerrainGeometry>(terrain)
            .unwrap()
            .precision = precision;
        harness.run_frames(3).unwrap();
        render_patches(&mut harness, terrain, None)
    };
    let (default_image, default) = render_at(TerrainPrecision::VertexPixels(DEFAULT_VERTEX_PIXELS));
    let (coarse_image, coarse) =
        render_at(TerrainPrecision::VertexPixels(2.0 * DEFAULT_VERTEX_PIXELS));
    let (full_image, full) = render_at(TerrainPrecision::Rho(1.0e6));
    let grid = full.grid.unwrap();
    assert!(
        full.selection
            .patches
            .iter()
            .all(|p| p.id.level == grid.max_level),
        "full resolution: every patch at the finest level"
    );
    strip(&[&coarse_image, &default_image, &full_image])
        .save_png(bevy_nature_harness::artifacts_dir().join("terrain_relief_error.png"))
        .ok();
    let reference = silhouette(&full_image);
    let error = |image: &RgbaImage| {
        let (mut worst, mut total) = (0u32, 0u32);
        for (x, y) in silhouette(image).iter().zip(&reference) {
            let (x, y) = (
                x.expect("terrain in every column"),
                y.expect("terrain in every column"),
            );
            worst = worst.max(x.abs_diff(y));
            total += x.abs_diff(y);
        }
        (worst, total as f32 / W as f32)
    };
    let (worst, mean) = error(&default_image);
    let (coarse_worst, coarse_mean) = error(&coarse_image);
    println!(
        "full resolution: {} triangles; default ({DEFAULT_VERTEX_PIXELS} px between vertices): {} \
         triangles, silhouette within {worst} px ({mean:.2} px on average); twice as coarse: {} \
         triangles, within {coarse_worst} px ({coarse_mean:.2} px)",
        full.triangles, default.triangles, coarse.triangles
    );
    assert!(default.triangles < full.triangles && coarse.triangles < default.triangles);
    assert!(
        worst <= 1,
        "the default mesh's silhouette is {worst} px off the full mesh's"
    );
}

/// Heights over a 2^20 m texture of 1 m texels (level 20): ridges and bumps tens of metres across,
/// as a function of the texel centre's metres from the texture's corner.
fn far_height(level: u32, x: u64, y: u64) -> f32 {
    let texel_m = (1u64 << (20 - level)) as f64;
    let (u, v) = ((x as f64 + 0.5) * texel_m, (y as f64 + 0.5) * texel_m);
    (18.0 * (u / 23.0).sin() * (v / 31.0).cos()
        + 9.0 * ((u + v) / 11.0).sin()
        + 12.0 * (u / 97.0 + v / 131.0).sin()) as f32
}

/// 4 m squares of two colours each way over a 2^20 m texture (level 20: 1 m texels), so that a
/// vertex or a texel out of place shows.
fn far_colour(level: u32, x: u64, y: u64) -> [u8; 4] {
    let texel_m = 1u64 << (20 - level);
    let (u, v) = (x * texel_m / 4, y * texel_m / 4);
    [
        60 + 150 * (u & 1) as u8,
        60 + 150 * (v & 1) as u8,
        (40 + (u * 37 + v * 11) % 180) as u8,
        255,
    ]
}

/// Precision far from the origin: a view over relief 10^6 m from the world's origin on
/// a 2^20-texel height texture (render space following the camera, [`RenderOrigin`]) and the
/// same camera relative to the terrain with the terrain moved so that the camera is at the
/// world's origin give the same image.
#[test]
fn relief_10_6_m_from_the_origin_draws_as_at_the_origin() {
    const W: u32 = 160;
    const H: u32 = 96;
    let camera = || {
        (
            Camera3d::default(),
            Msaa::Off,
            Tonemapping::None,
            DebandDither::Disabled,
            Transform::from_xyz(0.3, 45.0, 0.7).looking_at(Vec3::new(40.0, 0.0, 60.0), Vec3::Y),
        )
    };
    // The camera's world position 10^6 m out, relative to the texture's corner.
    let relative = DVec2::new(1.0e6 + 0.3, 1.0e6 + 0.7);
    let render = |texture_origin: DVec2, render_origin: DVec3, tag: &str| {
        let (mut harness, terrain) = relief_harness(
            &format!("terrain_relief_far_{tag}"),
            W,
            H,
            Ground {
                height: far_height,
                colour: far_colour,
                terrain_m: 1_048_576.0,
                levels: 15,
                texture_origin,
                render_origin: RenderOrigin(render_origin),
            },
            camera(),
        )?;
        Some(render_patches(
            &mut harness,
            terrain,
            Some(&format!("terrain_relief_far_{tag}.png")),
        ))
    };
    let Some((far, far_patches)) = render(DVec2::ZERO, DVec3::new(1.0e6, 0.0, 1.0e6), "10e6")
    else {
        return;
    };
    let (near, near_patches) =
        render(DVec2::new(0.3, 0.7) - relative, DVec3::ZERO, "origin").unwrap();
    let terrain = (0..W * H)
        .filter(|i| !is_background(&far, i % W, i / W))
        .count();
    let colours: std::collections::HashSet<&[u8]> = far.data.chunks(4).collect();
    let differing = far
        .data
        .chunks(4)
        .zip(near.data.chunks(4))
        .filter(|(p, q)| (0..3).any(|c| (p[c] as i32 - q[c] as i32).abs() > 2))
        .count();
    println!(
        "{} patches, {terrain} terrain pixels; {differing} pixels differ between the terrain \
         10^6 m out and at the origin",
        far_patches.selection.patches.len()
    );
    strip(&[&far, &near])
        .save_png(bevy_nature_harness::artifacts_dir().join("terrain_relief_far.png"))
        .ok();
    assert_eq!(
        far_patches.selection.patches.len(),
        near_patches.selection.patches.len()
    );
    assert!(
        terrain as u32 * 10 >= W * H * 9,
        "the terrain fills the view"
    );
    assert!(
        colours.len() >= 8,
        "the squares show: {} colours",
        colours.len()
    );
    assert!(
        differing * 1000 <= (W * H) as usize,
        "{differing} pixels differ"
    );
}

/// Images side by side.
fn strip(images: &[&RgbaImage]) -> RgbaImage {
    let (w, h) = (images[0].width, images[0].height);
    let mut data = vec![0u8; (w * h * 4) as usize * images.len()];
    for (k, image) in images.iter().enumerate() {
        for y in 0..h {
            let src = (y * w * 4) as usize;
            let dst = ((y * w * images.len() as u32 + k as u32 * w) * 4) as usize;
            data[dst..dst + (w * 4) as usize]
                .copy_from_slice(&image.data[src..src + (w * 4) as usize]);
        }
    }
    RgbaImage::new(w * images.len() as u32, h, data)
}
