//! The terrain material against its CPU reference: a flat terrain textured from a streamed clip
//! stack, seen from above, and for every pixel the texel the CPU reference sampler picks (finest
//! covering layer, else the base level) at that pixel's world point.
//!
//! The virtual texture is 2^20 texels of 1 m a side (levels 8 to 20 windowed), seen through
//! views from 24 m wide (a finest texel over 4 × 4 pixels) to 5.4 km (many layers' rings), from a
//! camera 10^6 m from the world's origin — kept near render space's origin by the
//! [`RenderOrigin`] — and from the same camera relative to the texture with the texture moved so
//! that the camera is at the world's origin: both images match the CPU layer by layer and each
//! other.

use bevy::camera::{OrthographicProjection, Projection, ScalingMode};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::math::{DVec2, DVec3};
use bevy::prelude::*;
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::compare::RgbaImage;
use bevy_terrain_clip::clip::stack::finest_covering_layer;
use bevy_terrain_clip::faults::TileFaults;
use bevy_terrain_clip::material::{ClipmapMaterial, flat_patch_mesh};
use bevy_terrain_clip::source::ProceduralTileSource;
use bevy_terrain_clip::stack_gpu::{ClipStackTexture, TextureMapping};
use bevy_terrain_clip::{RenderOrigin, TerrainClipPlugin};
use std::collections::BTreeMap;
use std::sync::Arc;

const SIZE: u32 = 96;

/// The harness's image assets.
fn images_of(harness: &mut RenderHarness) -> Mut<'_, Assets<Image>> {
    harness.world_mut().resource_mut::<Assets<Image>>()
}

/// An orthographic projection `view_m` wide, looking straight down.
fn top_down(view_m: f64) -> Projection {
    Projection::Orthographic(OrthographicProjection {
        scaling_mode: ScalingMode::Fixed {
            width: view_m as f32,
            height: view_m as f32,
        },
        ..OrthographicProjection::default_3d()
    })
}

/// Spawns `clip` (nearest filtering) under an unlit flat patch `2·half_m` wide around render
/// point `center` and an orthographic camera looking straight down at it, `view_m` wide (image
/// right = +x, up = −z); returns the stack's and the camera's entities.
fn spawn_top_down_view(
    harness: &mut RenderHarness,
    mut clip: ClipStackTexture,
    center: DVec2,
    half_m: f64,
    view_m: f64,
    uv_of: impl Fn(DVec2) -> DVec2,
) -> (Entity, Entity) {
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
    let camera = world
        .spawn((
            Camera3d::default(),
            Msaa::Off,
            Tonemapping::None,
            DebandDither::Disabled,
            top_down(view_m),
            Transform::from_xyz(center.x as f32, 50.0, center.y as f32).looking_at(
                Vec3::new(center.x as f32, 0.0, center.y as f32),
                Vec3::NEG_Z,
            ),
        ))
        .id();
    (world.spawn(clip).id(), camera)
}

/// A texel that says where it was sampled, neighbours far apart in colour (a texel off by one
/// differs by at least 7 in red or green, well past the comparison's rounding tolerance of 2).
fn scrambled_texel(level: u32, x: u64, y: u64) -> [u8; 4] {
    [
        (x.wrapping_mul(97).wrapping_add(y.wrapping_mul(13)) & 255) as u8,
        (y.wrapping_mul(89).wrapping_add(x.wrapping_mul(7)) & 255) as u8,
        ((level & 15) * 16 + ((x >> 8) & 15) as u32) as u8,
        255,
    ]
}

/// World side of the virtual texture (m): 2^20 texels of 1 m at level 20.
const TEXTURE_M: f64 = 1_048_576.0;
/// The views' widths (m).
const VIEWS: [f64; 4] = [24.0, 150.0, 900.0, 5400.0];

/// Per-layer tallies: pixels, pixels matching the CPU.
type LayerTally = BTreeMap<usize, (usize, usize)>;

/// The CPU reference of a top-down view `view_m` wide centred on world point `centre` of the
/// scrambled texture `clip` streams: each pixel the texel of the finest covering layer (else the
/// base level); adds each pixel to its layer's tally (pixels, pixels of `image` matching).
fn tally_against_cpu(
    image: &RgbaImage,
    clip: &ClipStackTexture,
    mapping: &TextureMapping,
    centre: DVec2,
    view_m: f64,
    tally: &mut LayerTally,
) -> RgbaImage {
    let mut expected = RgbaImage::filled(SIZE, SIZE, [0, 0, 0, 255]);
    for py in 0..SIZE {
        for px in 0..SIZE {
            // Camera: right = +x, up = −z; pixel (px, py) centre is at this world point.
            let world = centre
                + DVec2::new(
                    ((px as f64 + 0.5) / SIZE as f64 - 0.5) * view_m,
                    ((py as f64 + 0.5) / SIZE as f64 - 0.5) * view_m,
                );
            let uv = mapping.uv_of(world);
            let (layer, level, texel) = finest_covering_layer(&clip.stack, [uv.x, uv.y]);
            let want = scrambled_texel(level, texel[0] as u64, texel[1] as u64);
            expected.set_pixel(px, py, want);
            let got = image.pixel(px, py);
            let entry = tally.entry(layer).or_default();
            entry.0 += 1;
            entry.1 += (0..3).all(|c| (got[c] as i32 - want[c] as i32).abs() <= 2) as usize;
        }
    }
    expected
}

/// Renders the 2^20-texel texture through every view, the camera at render point
/// `camera_render` with the texture's corner at world `texture_origin` under `render_origin`;
/// returns the images and the per-layer tallies against the CPU reference.
fn render_views(
    texture_origin: DVec2,
    render_origin: DVec3,
    camera_render: DVec2,
    tag: &str,
) -> Option<(Vec<RgbaImage>, LayerTally)> {
    let mut harness = RenderHarness::for_test("clipmap_render", SIZE, SIZE)?;
    harness.app_mut().add_plugins(TerrainClipPlugin);
    let origin = RenderOrigin(render_origin);
    harness.world_mut().insert_resource(origin);
    let source = Arc::new(ProceduralTileSource::new(64, 15, scrambled_texel));
    let mapping = TextureMapping {
        origin_m: texture_origin,
        size_m: TEXTURE_M,
    };
    let world_of = move |render: DVec2| render + DVec2::new(render_origin.x, render_origin.z);
    let mut clip = ClipStackTexture::new(
        source,
        128,
        32,
        64,
        mapping.uv_of(world_of(camera_render)).to_array(),
        &mut images_of(&mut harness),
    );
    clip.mapping = Some(mapping);
    let half = VIEWS[VIEWS.len() - 1] * 0.6;
    let (entity, camera) = spawn_top_down_view(
        &mut harness,
        clip,
        camera_render,
        half,
        VIEWS[0],
        move |p| mapping.uv_of(world_of(p)),
    );
    harness.wait_until_ready().unwrap();
    for _ in 0..300 {
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
    let mut images = Vec::new();
    let mut tally = LayerTally::new();
    let dir = bevy_nature_harness::artifacts_dir().join("clipmap_render");
    for view_m in VIEWS {
        *harness.world_mut().get_mut::<Projection>(camera).unwrap() = top_down(view_m);
        harness.run_frames(2).unwrap();
        let image = harness.render().unwrap();
        let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
        assert!(clip.stack.layers.iter().all(|l| l.complete()));
        let expected = tally_against_cpu(
            &image,
            clip,
            &mapping,
            world_of(camera_render),
            view_m,
            &mut tally,
        );
        image
            .save_png(dir.join(format!("gpu_{tag}_{view_m}.png")))
            .ok();
        expected
            .save_png(dir.join(format!("cpu_{tag}_{view_m}.png")))
            .ok();
        images.push(image);
    }
    eprintln!("{tag}: per layer (index: pixels, matching) {tally:?}");
    Some((images, tally))
}

#[test]
fn a_2_20_texel_texture_10_6_m_out_samples_what_the_cpu_picks_as_at_the_origin() {
    // The same camera relative to the texture: 10^6 m from the world's origin (render space
    // follows it), and at the origin with the texture moved.
    let relative = DVec2::new(1.0e6 + 0.37, 1.0e6 + 0.61);
    let camera_render = DVec2::new(0.37, 0.61);
    let Some((far, far_tally)) = render_views(
        DVec2::ZERO,
        DVec3::new(1.0e6, 0.0, 1.0e6),
        camera_render,
        "far",
    ) else {
        return;
    };
    let (near, near_tally) = render_views(
        camera_render - relative,
        DVec3::ZERO,
        camera_render,
        "origin",
    )
    .unwrap();
    for (tag, tally) in [("10^6 m out", &far_tally), ("at the origin", &near_tally)] {
        // The finest layer (level 20, 1 m texels) fills the 24 m view.
        let finest = tally.keys().max().copied().unwrap();
        assert!(
            finest == 13 && tally[&finest].0 >= (SIZE * SIZE) as usize,
            "{tag}: the finest layer covers the narrow view: {tally:?}"
        );
        let seen: Vec<_> = tally.iter().filter(|(_, (n, _))| *n >= 100).collect();
        assert!(seen.len() >= 6, "{tag}: layers in view {tally:?}");
        for (layer, (pixels, matching)) in seen {
            let fraction = *matching as f64 / *pixels as f64;
            assert!(
                fraction >= 0.99,
                "{tag}: layer {layer}: {matching} of {pixels} pixels match the CPU"
            );
        }
    }
    // And the two renders are the same image.
    let differing: usize = far
        .iter()
        .zip(&near)
        .map(|(a, b)| {
            a.data
                .chunks(4)
                .zip(b.data.chunks(4))
                .filter(|(p, q)| (0..3).any(|c| (p[c] as i32 - q[c] as i32).abs() > 2))
                .count()
        })
        .sum();
    eprintln!("{differing} pixels differ between the two renders");
    assert!(
        differing * 1000 <= far.len() * (SIZE * SIZE) as usize,
        "{differing} pixels differ between the render 10^6 m out and the one at the origin"
    );
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
    let (entity, _) = spawn_top_down_view(&mut harness, clip, center, VIEW, VIEW, uv_of);
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

/// What one flight over the scrambled texture saw (see
/// `streaming_through_a_failing_source_degrades_and_recovers`).
struct Flight {
    /// Mean over the flight's frames of the fraction of the stack's layers complete.
    complete: f64,
    /// The cache's counters at the end of the flight.
    stats: bevy_terrain_clip::tile_cache::TileCacheStats,
    /// Loads the source never answered.
    hung: u64,
    /// Frames, after the faults stopped, until every layer was complete again.
    recovery_frames: u32,
    /// Pixels of the final view matching the CPU reference, of `SIZE²`.
    matching: usize,
    /// The longest frame of the flight (CPU; reported, not asserted).
    longest_frame: std::time::Duration,
}

/// The least wall-clock time one frame of a flight through faults takes.
///
/// The faults' latency spikes and the cache's load timeout are wall-clock times while its
/// back-off is counted in frames, so how many layers complete depends on how many frames a
/// spike or a timeout spans. Unpaced, a machine drawing the view in a few milliseconds flies
/// the whole 60 frames inside one timeout and no layer ever completes; paced, a spike spans
/// about two frames and a timeout twelve on any machine that draws a frame faster than this.
const FLIGHT_FRAME_PACE: std::time::Duration = std::time::Duration::from_millis(25);

/// One frame of a flight through faults, stretched to at least [`FLIGHT_FRAME_PACE`]; returns
/// the frame's own (unstretched) time.
fn paced_step(harness: &mut RenderHarness) -> std::time::Duration {
    let frame = harness.step();
    std::thread::sleep(FLIGHT_FRAME_PACE.saturating_sub(frame));
    frame
}

/// Flies 60 frames at 25 m a frame over the texture, looking down at a 150 m view, streaming
/// through `faults`, checking every frame that the tile cache stays within its bound; then
/// switches the faults off and streams until the stack is complete again. Frames are paced
/// ([`FLIGHT_FRAME_PACE`]).
fn fly_through_faults(faults: TileFaults) -> Option<Flight> {
    use bevy_terrain_clip::faults::FaultyTileSource;
    use std::sync::atomic::Ordering;
    let mut harness = RenderHarness::for_test("clipmap_faults", SIZE, SIZE)?;
    harness.app_mut().add_plugins(TerrainClipPlugin);
    let inner: Arc<dyn bevy_terrain_clip::source::TileSource> =
        Arc::new(ProceduralTileSource::new(64, 15, scrambled_texel));
    let source = Arc::new(FaultyTileSource::new(inner, faults, 11));
    let mapping = TextureMapping {
        origin_m: DVec2::splat(-TEXTURE_M / 2.0),
        size_m: TEXTURE_M,
    };
    const VIEW_M: f64 = 150.0;
    const STEP_M: f64 = 25.0;
    let mut clip = ClipStackTexture::new(
        source.clone(),
        128,
        32,
        64,
        mapping.uv_of(DVec2::ZERO).to_array(),
        &mut images_of(&mut harness),
    );
    clip.mapping = Some(mapping);
    // A load that never answers is abandoned after 0.3 s (and retried with back-off).
    clip.cache.load_timeout = std::time::Duration::from_millis(300);
    let (entity, camera) = spawn_top_down_view(
        &mut harness,
        clip,
        DVec2::new(750.0, 0.0),
        2000.0,
        VIEW_M,
        move |p| mapping.uv_of(p),
    );
    harness.wait_until_ready().unwrap();
    let mut complete = 0.0;
    let mut longest_frame = std::time::Duration::ZERO;
    let mut position = DVec2::ZERO;
    const FRAMES: u32 = 60;
    for _ in 0..FRAMES {
        position.x += STEP_M;
        *harness.world_mut().get_mut::<Transform>(camera).unwrap() =
            Transform::from_xyz(position.x as f32, 50.0, position.y as f32).looking_at(
                Vec3::new(position.x as f32, 0.0, position.y as f32),
                Vec3::NEG_Z,
            );
        longest_frame = longest_frame.max(paced_step(&mut harness));
        let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
        assert!(
            clip.cache.len() <= clip.cache.capacity(),
            "the tile cache holds {} of {} tiles",
            clip.cache.len(),
            clip.cache.capacity()
        );
        let layers = &clip.stack.layers;
        complete += layers.iter().filter(|l| l.complete()).count() as f64
            / layers.len() as f64
            / FRAMES as f64;
    }
    source.set_enabled(false);
    let mut recovery_frames = 0;
    while recovery_frames < 400 {
        paced_step(&mut harness);
        recovery_frames += 1;
        let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
        if clip.stack.layers.iter().all(|l| l.complete()) && clip.base_ready() {
            break;
        }
    }
    harness.run_frames(3).unwrap();
    let image = harness.render().unwrap();
    let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
    let mut tally = LayerTally::new();
    tally_against_cpu(&image, clip, &mapping, position, VIEW_M, &mut tally);
    Some(Flight {
        complete,
        stats: clip.cache.stats,
        hung: source.counts.hung.load(Ordering::Relaxed),
        recovery_frames,
        matching: tally.values().map(|(_, m)| m).sum(),
        longest_frame,
    })
}

/// Streaming on the GPU through a source with a bad network's faults (errors, truncated and
/// wrongly sized tiles, loads that never answer, latency spikes): every frame renders (a load
/// that never answers is abandoned, so it cannot hold the stream), the tile cache stays within
/// its bound, fewer layers are complete than in the same flight without faults — but most are —
/// and once the faults stop the stack completes and the view matches the CPU reference.
#[test]
fn streaming_through_a_failing_source_degrades_and_recovers() {
    let Some(clean) = fly_through_faults(TileFaults::NONE) else {
        return;
    };
    let faults = TileFaults {
        spike: std::time::Duration::from_millis(60),
        ..TileFaults::hostile()
    };
    let faulty = fly_through_faults(faults).unwrap();
    let pixels = (SIZE * SIZE) as usize;
    let report = |f: &Flight| {
        format!(
            "layers complete {:.3} on average; {} loaded, {} failed, {} given up, {} never answered; \
             complete again {} frames after the faults stopped; {} of {pixels} pixels match the CPU; \
             longest frame {:?}",
            f.complete,
            f.stats.loaded,
            f.stats.failed,
            f.stats.given_up,
            f.hung,
            f.recovery_frames,
            f.matching,
            f.longest_frame
        )
    };
    let (clean_report, faulty_report) = (report(&clean), report(&faulty));
    eprintln!("clean: {clean_report}\nfaulty: {faulty_report}");
    assert_eq!(clean.stats.failed, 0, "{clean_report}");
    assert!(
        faulty.hung > 0 && faulty.stats.failed > faulty.hung,
        "the faults struck, loads that never answered were abandoned: {faulty_report}"
    );
    assert!(
        // Measured at the 25 ms pace: 0.61–0.71 against 0.85 (seven runs, two loads never
        // answering); with the spike, the timeout and the pace all eight times longer (the
        // frame's own time then negligible) 0.48. Unpaced, a machine drawing frames in a few
        // milliseconds fell to 0.10; and while each load's fate followed the count of all
        // loads, a run whose loads finished in another order drew other faults (five hangs
        // once, 0.08). Fates now follow each tile's own loads. Over seeds 1–8, 0.34 (eleven
        // hangs) to 0.76. The bound only rules out a collapse.
        faulty.complete < clean.complete && faulty.complete > 0.25 * clean.complete,
        "quality degrades, gracefully: {faulty_report} vs {clean_report}"
    );
    for (f, r) in [(&clean, &clean_report), (&faulty, &faulty_report)] {
        assert!(f.recovery_frames < 400, "{r}");
        assert!(f.matching * 100 >= pixels * 99, "{r}");
    }
}
