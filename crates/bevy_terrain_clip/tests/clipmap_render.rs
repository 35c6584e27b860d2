//! The terrain material against its CPU reference: a flat terrain textured from a streamed clip
//! stack, seen from above, and for every pixel the texel the CPU reference sampler picks (finest
//! covering layer, else the base level) at that pixel's world point. The view spans several
//! layers' boundaries and the toroidal wrap of each layer; it is rendered near the world origin
//! and again 10^6 m away from it (texture coordinates computed in f64 on the CPU).

use bevy::camera::{OrthographicProjection, Projection, ScalingMode};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::math::DVec2;
use bevy::prelude::*;
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::compare::RgbaImage;
use bevy_terrain_clip::TerrainClipPlugin;
use bevy_terrain_clip::clip::stack::finest_covering_layer;
use bevy_terrain_clip::material::{ClipmapMaterial, flat_patch_mesh};
use bevy_terrain_clip::source::{ProceduralTileSource, address_texel};
use bevy_terrain_clip::stack_gpu::ClipStackTexture;
use std::sync::Arc;

const SIZE: u32 = 96;
/// World size of the virtual texture (m): level 11 (2048 texels) has 2 m texels.
const TEXTURE_M: f64 = 4096.0;
/// World width of the view (m): wider than the coarsest window (level 8, 128 texels of 16 m),
/// so the base level shows at the edges.
const VIEW_M: f64 = 3000.0;

/// The harness's image assets.
fn images_of(harness: &mut RenderHarness) -> Mut<'_, Assets<Image>> {
    harness.world_mut().resource_mut::<Assets<Image>>()
}

/// Spawns `clip` (nearest filtering) under an unlit flat patch `2·half_m` wide around `center`
/// and an orthographic camera looking straight down at it, `view_m` wide (image right = +x,
/// up = −z); returns the stack's entity.
fn spawn_top_down_view(
    harness: &mut RenderHarness,
    mut clip: ClipStackTexture,
    center: DVec2,
    half_m: f64,
    view_m: f64,
    uv_of: impl Fn(DVec2) -> DVec2,
) -> Entity {
    let world = harness.world_mut();
    clip.set_linear_filtering(false, &mut world.resource_mut::<Assets<Image>>());
    let material = clip.material(
        StandardMaterial {
            unlit: true,
            ..default()
        },
        &mut world.resource_mut::<Assets<ClipmapMaterial>>(),
    );
    let mesh = world.resource_mut::<Assets<Mesh>>().add(flat_patch_mesh(
        center - DVec2::splat(half_m),
        2.0 * half_m,
        16,
        center,
        uv_of,
    ));
    world.spawn((
        Mesh3d(mesh),
        MeshMaterial3d(material),
        Transform::from_xyz(center.x as f32, 0.0, center.y as f32),
    ));
    world.spawn((
        Camera3d::default(),
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
        Projection::Orthographic(OrthographicProjection {
            scaling_mode: ScalingMode::Fixed {
                width: view_m as f32,
                height: view_m as f32,
            },
            ..OrthographicProjection::default_3d()
        }),
        Transform::from_xyz(center.x as f32, 50.0, center.y as f32).looking_at(
            Vec3::new(center.x as f32, 0.0, center.y as f32),
            Vec3::NEG_Z,
        ),
    ));
    world.spawn(clip).id()
}

fn render_and_compare(origin: DVec2) -> Option<(f64, usize)> {
    let mut harness = RenderHarness::for_test("clipmap_render", SIZE, SIZE)?;
    harness.app_mut().add_plugins(TerrainClipPlugin);
    let source = Arc::new(ProceduralTileSource::new(64, 6, address_texel));
    let center_uv = [0.37, 0.61];
    let center = origin + DVec2::new(center_uv[0], center_uv[1]) * TEXTURE_M;
    let uv_of = move |p: DVec2| (p - origin) / TEXTURE_M;
    let clip = ClipStackTexture::new(source, 128, 32, 64, center_uv, &mut images_of(&mut harness));
    let entity = spawn_top_down_view(&mut harness, clip, center, 1800.0, VIEW_M, uv_of);
    harness.wait_until_ready().unwrap();
    for _ in 0..200 {
        harness.step();
        let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
        // Every layer streamed, and the base level read (off the main thread) and written.
        if clip.stack.layers.iter().all(|l| l.complete()) && clip.base_ready() {
            break;
        }
    }
    for _ in 0..3 {
        harness.step();
    }
    let image = harness.render().unwrap();
    let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
    // Camera: right = +x, up = −z; pixel (px, py) centre is at this world point.
    let mut matching = 0usize;
    let mut layers_seen = std::collections::BTreeSet::new();
    let mut expected = RgbaImage::filled(SIZE, SIZE, [0, 0, 0, 255]);
    for py in 0..SIZE {
        for px in 0..SIZE {
            let world = center
                + DVec2::new(
                    ((px as f64 + 0.5) / SIZE as f64 - 0.5) * VIEW_M,
                    ((py as f64 + 0.5) / SIZE as f64 - 0.5) * VIEW_M,
                );
            let uv = uv_of(world);
            let (layer, level, texel) = finest_covering_layer(&clip.stack, [uv.x, uv.y]);
            layers_seen.insert(layer);
            let want = address_texel(level, texel[0] as u64, texel[1] as u64);
            expected.set_pixel(px, py, want);
            let got = image.pixel(px, py);
            if (0..3).all(|c| (got[c] as i32 - want[c] as i32).abs() <= 2) {
                matching += 1;
            }
        }
    }
    let dir = bevy_nature_harness::artifacts_dir().join("clipmap_render");
    image
        .save_png(dir.join(format!("gpu_{}.png", origin.x as u64)))
        .ok();
    expected
        .save_png(dir.join(format!("cpu_{}.png", origin.x as u64)))
        .ok();
    let fraction = matching as f64 / (SIZE * SIZE) as f64;
    eprintln!(
        "origin {origin:?}: {:.2} % of pixels match the CPU reference; layers in view {layers_seen:?}",
        fraction * 100.0
    );
    Some((fraction, layers_seen.len()))
}

#[test]
fn terrain_material_samples_what_the_cpu_reference_picks() {
    let Some((near_origin, layers)) = render_and_compare(DVec2::ZERO) else {
        return;
    };
    assert!(
        layers >= 3,
        "the view should cross layer boundaries ({layers} layers)"
    );
    assert!(near_origin >= 0.99, "{:.4} of pixels match", near_origin);
    let (far, _) = render_and_compare(DVec2::new(1.0e6, 1.0e6)).unwrap();
    assert!(far >= 0.99, "{far:.4} of pixels match at 10^6 m");
}

/// A pyramid much smaller than the clip (32 texels across under a 128-texel clip; users' partial
/// pyramids are like this), its right quarter transparent padding, seen with ground all around
/// it: the data shows (magnified from its finest level), and outside it and over the padding the
/// documented no-data colour — never repeated copies of the texture, never dark padding.
#[test]
fn a_small_pyramid_renders_inside_its_extent_and_no_data_around_it() {
    use bevy_terrain_clip::clip::stack::over_no_data;
    use bevy_terrain_clip::settings::NO_DATA_COLOR;
    let Some(mut harness) = RenderHarness::for_test("clipmap_small", SIZE, SIZE) else {
        return;
    };
    harness.app_mut().add_plugins(TerrainClipPlugin);
    // 16-texel tiles, 2 levels: virtual level 5 is the finest, 32 texels of 10 m.
    let texel = |level: u32, x: u64, y: u64| {
        let side = 1u64 << level;
        if x * 4 >= side * 3 {
            [0, 0, 0, 0]
        } else {
            [(x * 255 / side) as u8, (y * 255 / side) as u8, 90, 255]
        }
    };
    let source = Arc::new(ProceduralTileSource::new(16, 2, texel));
    const SMALL_M: f64 = 320.0;
    const VIEW: f64 = 480.0;
    let center = DVec2::splat(SMALL_M / 2.0);
    let uv_of = move |p: DVec2| p / SMALL_M;
    let clip = ClipStackTexture::new(
        source,
        128,
        16,
        64,
        [0.5, 0.5],
        &mut images_of(&mut harness),
    );
    let entity = spawn_top_down_view(&mut harness, clip, center, VIEW, VIEW, uv_of);
    harness.wait_until_ready().unwrap();
    // The base level (all there is of this pyramid) is read off the main thread.
    for _ in 0..200 {
        harness.step();
        if harness
            .world_mut()
            .get::<ClipStackTexture>(entity)
            .unwrap()
            .base_ready()
        {
            break;
        }
    }
    for _ in 0..3 {
        harness.step();
    }
    let image = harness.render().unwrap();
    let no_data = NO_DATA_COLOR.to_linear();
    let no_data = [no_data.red, no_data.green, no_data.blue];
    let srgb = |linear: [f32; 4]| {
        let c = Color::linear_rgba(linear[0], linear[1], linear[2], 1.0).to_srgba();
        [c.red, c.green, c.blue].map(|v| (v * 255.0).round() as i32)
    };
    let (mut matching, mut outside, mut padding, mut data) = (0usize, 0usize, 0usize, 0usize);
    let mut expected = RgbaImage::filled(SIZE, SIZE, [0, 0, 0, 255]);
    for py in 0..SIZE {
        for px in 0..SIZE {
            let world = center
                + DVec2::new(
                    ((px as f64 + 0.5) / SIZE as f64 - 0.5) * VIEW,
                    ((py as f64 + 0.5) / SIZE as f64 - 0.5) * VIEW,
                );
            let uv = uv_of(world);
            let inside = (0.0..1.0).contains(&uv.x) && (0.0..1.0).contains(&uv.y);
            let sampled = inside.then(|| {
                let t = texel(5, (uv.x * 32.0) as u64, (uv.y * 32.0) as u64);
                // Stored sRGB; the sampler returns linear.
                let c = Color::srgba_u8(t[0], t[1], t[2], t[3]).to_linear();
                [
                    c.red * c.alpha,
                    c.green * c.alpha,
                    c.blue * c.alpha,
                    c.alpha,
                ]
            });
            match sampled {
                None => outside += 1,
                Some(t) if t[3] == 0.0 => padding += 1,
                Some(_) => data += 1,
            }
            let want = srgb(over_no_data(sampled, no_data));
            expected.set_pixel(px, py, [want[0] as u8, want[1] as u8, want[2] as u8, 255]);
            let got = image.pixel(px, py);
            if (0..3).all(|c| (got[c] as i32 - want[c]).abs() <= 2) {
                matching += 1;
            }
        }
    }
    let dir = bevy_nature_harness::artifacts_dir().join("clipmap_small");
    std::fs::create_dir_all(&dir).ok();
    image.save_png(dir.join("gpu.png")).ok();
    expected.save_png(dir.join("cpu.png")).ok();
    let fraction = matching as f64 / (SIZE * SIZE) as f64;
    eprintln!(
        "small pyramid: {:.2} % of pixels match ({outside} outside, {padding} padding, {data} data)",
        fraction * 100.0
    );
    assert!(outside > 2000 && padding > 500 && data > 2000);
    assert!(fraction >= 0.99, "{fraction:.4} of pixels match");
}
