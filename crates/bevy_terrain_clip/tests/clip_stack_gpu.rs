//! The clip stack's texture array on the GPU against the pyramid: after streaming settles, every
//! texel of every layer read back from the GPU equals the texel of the virtual texture that the
//! layer's toroidal slot holds (computed on the CPU from the source), before and after the
//! centre moves across the toroidal wrap; and mip 1 of every slot is the box filter of its
//! subtile. Runs on the adapter at hand (software Vulkan in CI;
//! with `CI=true` a missing adapter fails the test).

use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::render_asset::RenderAssets;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::headless::read_texture_now;
use bevy_terrain_clip::source::{ProceduralTileSource, TexelKind, address_texel};
use bevy_terrain_clip::stack_gpu::{ClipStackTexture, TextureMapping};
use bevy_terrain_clip::stack_gpu::{QUALITY, SUBTILES_UPLOADED};
use bevy_terrain_clip::{ClipmapSettings, TerrainClipPlugin, UpdateBudget};
use std::sync::Arc;

const CLIP: u32 = 128;
const SUBTILE: u32 = 32;

fn read_layers(
    harness: &mut RenderHarness,
    image: AssetId<Image>,
    layers: u32,
    mip: u32,
) -> Vec<u8> {
    let render_world = harness.app().get_sub_app(RenderApp).unwrap().world();
    let device = render_world.resource::<RenderDevice>();
    let queue = render_world.resource::<RenderQueue>();
    let gpu = render_world
        .resource::<RenderAssets<GpuImage>>()
        .get(image)
        .expect("texture array prepared");
    read_texture_now(device, queue, &gpu.texture, mip, layers, 4).unwrap()
}

/// Steps until every layer is valid, then compares the whole array with the source. Returns
/// the texels compared and the subtiles uploaded while settling.
fn settle_and_compare(
    harness: &mut RenderHarness,
    entity: Entity,
    texel: impl Fn(u32, u64, u64) -> [u8; 4],
) -> (u32, usize) {
    let mut frames = 0;
    let mut uploaded = 0;
    loop {
        harness.step();
        frames += 1;
        let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
        uploaded += clip.writes().iter().filter(|w| w.mip == 0).count();
        if clip.stack.layers.iter().all(|l| l.complete()) && clip.writes().is_empty() && frames > 1
        {
            break;
        }
        assert!(frames < 400, "the stack never completed");
    }
    // One more frame so the last writes reached the GPU.
    harness.step();
    let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
    let image = clip.layers.id();
    // Per layer: its level and its valid rectangles (origin, size).
    #[allow(clippy::type_complexity)]
    let layers: Vec<(u32, Vec<([i64; 2], [u32; 2])>)> = clip
        .stack
        .layers
        .iter()
        .map(|l| {
            let n = l.slots_per_side as i64;
            (
                l.level,
                l.slots()
                    .iter()
                    .map(|s| {
                        (
                            s.subtile,
                            [
                                (s.subtile[0].rem_euclid(n) as u32) * SUBTILE,
                                (s.subtile[1].rem_euclid(n) as u32) * SUBTILE,
                            ],
                        )
                    })
                    .collect(),
            )
        })
        .collect();
    let (mips, kind) = (clip.layer_mips, clip.texels);
    let data = read_layers(harness, image, layers.len() as u32, 0);
    let mip1 = if mips > 1 {
        read_layers(harness, image, layers.len() as u32, 1)
    } else {
        Vec::new()
    };
    let half = SUBTILE / 2;
    let mut checked = 0u32;
    for (layer, (level, slots)) in layers.iter().enumerate() {
        for (subtile, origin) in slots {
            // Mip 1 of the slot: the 2×2 box filter of the subtile's texels.
            let mut full = Vec::with_capacity((SUBTILE * SUBTILE * 4) as usize);
            for y in 0..SUBTILE as i64 {
                for x in 0..SUBTILE as i64 {
                    full.extend_from_slice(&texel(
                        *level,
                        (subtile[0] * SUBTILE as i64 + x) as u64,
                        (subtile[1] * SUBTILE as i64 + y) as u64,
                    ));
                }
            }
            let expected_mip1 = kind.halve(&full, SUBTILE);
            for y in 0..half * (mips > 1) as u32 {
                for x in 0..half {
                    let (tx, ty) = (origin[0] / 2 + x, origin[1] / 2 + y);
                    let i = (((layer as u32 * (CLIP / 2) + ty) * (CLIP / 2) + tx) * 4) as usize;
                    let j = ((y * half + x) * 4) as usize;
                    assert_eq!(
                        &mip1[i..i + 4],
                        &expected_mip1[j..j + 4],
                        "mip 1 of layer {layer} at {tx},{ty}"
                    );
                }
            }
            for y in 0..SUBTILE {
                for x in 0..SUBTILE {
                    let (tx, ty) = (origin[0] + x, origin[1] + y);
                    let i = (((layer as u32 * CLIP + ty) * CLIP + tx) * 4) as usize;
                    let gpu = &data[i..i + 4];
                    let level_texel = [
                        (subtile[0] * SUBTILE as i64 + x as i64) as u64,
                        (subtile[1] * SUBTILE as i64 + y as i64) as u64,
                    ];
                    let expected = texel(*level, level_texel[0], level_texel[1]);
                    assert_eq!(
                        gpu, expected,
                        "layer {layer} (level {level}) texel {tx},{ty} = level texel {level_texel:?}"
                    );
                    checked += 1;
                }
            }
        }
    }
    eprintln!(
        "settled in {frames} frames ({uploaded} subtiles uploaded); {checked} texels equal the pyramid"
    );
    (checked, uploaded)
}

#[test]
fn gpu_layers_hold_the_pyramid_texels_of_their_toroidal_slots() {
    let Some(mut harness) = RenderHarness::for_test("clip_stack_gpu", 16, 16) else {
        return;
    };
    harness.app_mut().add_plugins(TerrainClipPlugin);
    // 64-texel tiles, 6 pyramid levels: virtual levels 0..12. Clip 128 (base level 7) leaves
    // windowed layers for levels 8..=11.
    let source = Arc::new(ProceduralTileSource::new(64, 6, address_texel));
    let entity = {
        let world = harness.world_mut();
        let clip = {
            let mut images = world.resource_mut::<Assets<Image>>();
            ClipStackTexture::from_settings(source, &stack_settings(), [0.37, 0.61], &mut images)
        };
        world.spawn(clip).id()
    };
    harness.world_mut().spawn(Camera3d::default());
    harness.wait_until_ready().unwrap();
    let layers = harness
        .world_mut()
        .get::<ClipStackTexture>(entity)
        .unwrap()
        .stack
        .layers
        .len();
    assert_eq!(layers, 4);
    let (checked, _) = settle_and_compare(&mut harness, entity, address_texel);
    assert_eq!(checked, 4 * CLIP * CLIP);
    // Move the centre by a few subtiles in every layer: the new strips land in slots across the
    // toroidal wrap.
    let moved = [0.37 + 3.5 * 32.0 / 256.0, 0.61 - 2.5 * 32.0 / 256.0];
    let entering = {
        let mut clip = harness
            .world_mut()
            .get_mut::<ClipStackTexture>(entity)
            .unwrap();
        clip.center_uv = moved;
        clip.stack.clone().recenter(moved)
    };
    let (_, uploaded) = settle_and_compare(&mut harness, entity, address_texel);
    assert_eq!(
        harness.diagnostic(&QUALITY),
        Some(100.0),
        "terrain/stack_valid_percent"
    );
    assert_eq!(harness.diagnostic(&SUBTILES_UPLOADED), Some(0.0));
    // Only the subtiles that entered the windows were uploaded, not the whole stack.
    assert!(entering > 0 && entering < 64, "{entering}");
    assert_eq!(uploaded, entering as usize);
}

/// The stacks' sizes in these tests: a `CLIP`-texel clip of `SUBTILE`-texel subtiles, 64 cached
/// tiles, 16 subtiles a frame.
fn stack_settings() -> ClipmapSettings {
    ClipmapSettings {
        clip_size: CLIP,
        subtile_size: SUBTILE,
        cache_tiles: 64,
        budget: UpdateBudget::Subtiles(16),
        ..default()
    }
}

/// A height that says where it was sampled: a different metre value for every level and texel
/// (to the f32's precision), with a fractional part, so a wrong level or texel, a truncation to
/// 8 or 16 bits or a colour conversion would show.
fn address_height(level: u32, x: u64, y: u64) -> f32 {
    level as f32 * 1000.0 + (x % 251) as f32 * 3.25 + (y % 241) as f32 * 0.0625 - 400.0
}

/// The lowest and highest heights of a height stack's valid slots (`address_height`).
#[inline(never)]
fn valid_height_range(clip: &ClipStackTexture) -> (f32, f32) {
    let heights: Vec<f32> = clip
        .stack
        .layers
        .iter()
        .flat_map(|layer| {
            layer
                .slots()
                .iter()
                .filter(|s| s.state == bevy_terrain_clip::clip::layer::SlotState::Valid)
                .flat_map(move |slot| {
                    (0..(SUBTILE * SUBTILE) as i64).map(move |k| {
                        let (x, y) = (k % SUBTILE as i64, k / SUBTILE as i64);
                        address_height(
                            layer.level,
                            (slot.subtile[0] * SUBTILE as i64 + x) as u64,
                            (slot.subtile[1] * SUBTILE as i64 + y) as u64,
                        )
                    })
                })
        })
        .collect();
    (
        heights.iter().copied().fold(f32::INFINITY, f32::min),
        heights.iter().copied().fold(f32::NEG_INFINITY, f32::max),
    )
}

/// Heights stream into an R32Float stack texel for texel: every valid slot of every layer read
/// back equals the source's heights exactly; a source of the wrong kind is refused and streams
/// nothing.
#[test]
fn height_layers_hold_the_pyramid_heights_exactly() {
    let Some(mut harness) = RenderHarness::for_test("clip_stack_gpu_heights", 16, 16) else {
        return;
    };
    harness.app_mut().add_plugins(TerrainClipPlugin);
    let settings = stack_settings();
    let (heights, imagery_as_heights, heights_as_imagery) = {
        let world = harness.world_mut();
        let mut images = world.resource_mut::<Assets<Image>>();
        let mut heights = ClipStackTexture::heights(
            Arc::new(ProceduralTileSource::heights(64, 6, address_height)),
            &settings,
            [0.42, 0.55],
            &mut images,
        );
        // 1 m texels at the finest level (11); the camera below keeps the centre where it is.
        heights.mapping = Some(TextureMapping {
            origin_m: bevy::math::DVec2::ZERO,
            size_m: 2048.0,
        });
        let wrong = ClipStackTexture::heights(
            Arc::new(ProceduralTileSource::new(64, 6, address_texel)),
            &settings,
            [0.42, 0.55],
            &mut images,
        );
        let wrong_too = ClipStackTexture::from_settings(
            Arc::new(ProceduralTileSource::heights(64, 6, address_height)),
            &settings,
            [0.42, 0.55],
            &mut images,
        );
        assert_eq!(heights.texels, TexelKind::Height);
        assert_eq!(heights.layer_mips, 1);
        (
            world.spawn(heights).id(),
            world.spawn(wrong).id(),
            world.spawn(wrong_too).id(),
        )
    };
    harness.world_mut().spawn((
        Camera3d::default(),
        Transform::from_xyz(0.42 * 2048.0, 50.0, 0.55 * 2048.0),
    ));
    harness.wait_until_ready().unwrap();
    let (checked, _) = settle_and_compare(&mut harness, heights, |l, x, y| {
        address_height(l, x, y).to_le_bytes()
    });
    assert_eq!(checked, 4 * CLIP * CLIP);
    // The resident height query: bilinear between the finest level's texel centres.
    let mut clip = harness
        .world_mut()
        .get_mut::<ClipStackTexture>(heights)
        .unwrap();
    for (x, z) in [(861.3, 1126.8), (870.5, 1120.25), (855.0, 1130.9)] {
        let (h, level) = clip
            .resident_height(bevy::math::DVec2::new(x, z))
            .expect("resident");
        assert_eq!(level, 11);
        let (tx, tz) = (x - 0.5, z - 0.5);
        let (x0, z0) = (tx.floor(), tz.floor());
        let (fx, fz) = ((tx - x0) as f32, (tz - z0) as f32);
        let at = |dx: f64, dz: f64| address_height(11, (x0 + dx) as u64, (z0 + dz) as u64);
        let top = at(0.0, 0.0) + (at(1.0, 0.0) - at(0.0, 0.0)) * fx;
        let bottom = at(0.0, 1.0) + (at(1.0, 1.0) - at(0.0, 1.0)) * fx;
        let want = top + (bottom - top) * fz;
        assert!((h - want).abs() < 1e-3, "({x}, {z}): {h} vs {want}");
    }
    assert_eq!(
        clip.resident_height(bevy::math::DVec2::new(-5.0, 10.0)),
        None
    );
    // The normal of the plane the heights make there (3.25 m per metre along x, 1/16 along z).
    let n = clip
        .resident_normal(bevy::math::DVec2::new(861.3, 1126.8))
        .expect("resident");
    let want = Vec3::new(-3.25, 1.0, -0.0625).normalize();
    assert!(n.distance(want) < 1e-4, "{n} vs {want}");
    assert_eq!(
        clip.resident_normal(bevy::math::DVec2::new(-5.0, 10.0)),
        None
    );
    // The range of the heights sent holds every valid texel's (the patches' bounds).
    let (low, high) = clip.height_range().expect("heights were sent");
    let (valid_low, valid_high) = valid_height_range(&clip);
    assert!(
        low <= valid_low && high >= valid_high,
        "{low}..{high} vs {valid_low}..{valid_high}"
    );
    assert!(low >= -400.0 && high <= 11.0 * 1000.0 + 250.0 * 3.25 + 240.0 * 0.0625 - 400.0);
    for refused in [imagery_as_heights, heights_as_imagery] {
        let clip = harness
            .world_mut()
            .get::<ClipStackTexture>(refused)
            .unwrap();
        assert!(
            clip.stack
                .layers
                .iter()
                .flat_map(|l| l.slots())
                .all(|s| s.state != bevy_terrain_clip::clip::layer::SlotState::Valid),
            "a source of the wrong kind streamed"
        );
    }
}

/// Editing `ClipmapSettings` at run time (the examples' panel does) applies to the live stacks:
/// the budget at once; a size by rebuilding the stack with it — and only with the fields edited,
/// so a stack made with a clip size of its own keeps it — its material then drawing the new
/// textures, streaming to completion again.
#[test]
fn edited_settings_apply_to_live_stacks() {
    let Some(mut harness) = RenderHarness::for_test("clip_stack_gpu_live_settings", 16, 16) else {
        return;
    };
    harness.app_mut().add_plugins(TerrainClipPlugin);
    let (entity, material) = {
        let world = harness.world_mut();
        let mut clip = {
            let mut images = world.resource_mut::<Assets<Image>>();
            ClipStackTexture::from_settings(
                Arc::new(ProceduralTileSource::new(64, 6, address_texel)),
                &stack_settings(),
                [0.37, 0.61],
                &mut images,
            )
        };
        let material = clip.material(
            StandardMaterial::default(),
            &mut world.resource_mut::<Assets<bevy_terrain_clip::material::ClipmapMaterial>>(),
        );
        (world.spawn(clip).id(), material)
    };
    harness.world_mut().spawn(Camera3d::default());
    harness.wait_until_ready().unwrap();
    harness.run_frames(5).unwrap();
    let old_layers = harness
        .world_mut()
        .get::<ClipStackTexture>(entity)
        .unwrap()
        .layers
        .clone();
    {
        let mut settings = harness.world_mut().resource_mut::<ClipmapSettings>();
        settings.subtile_size = 16;
        settings.budget = UpdateBudget::Subtiles(7);
    }
    harness.run_frames(2).unwrap();
    let (layers, budget, clip_size, subtile) = {
        let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
        (
            clip.layers.clone(),
            clip.budget,
            clip.stack.clip_size,
            clip.stack.subtile_size,
        )
    };
    assert_eq!(budget, UpdateBudget::Subtiles(7));
    assert_eq!(
        (clip_size, subtile),
        (CLIP, 16),
        "the clip size is the stack's own"
    );
    assert_ne!(layers, old_layers, "new textures");
    let extension = harness
        .world_mut()
        .resource::<Assets<bevy_terrain_clip::material::ClipmapMaterial>>()
        .get(&material)
        .unwrap()
        .extension
        .clone();
    assert_eq!(extension.layers, layers, "the material draws the new stack");
    // It streams to completion again, in 16-texel subtiles.
    let (mut frames, mut largest) = (0, 0);
    loop {
        harness.step();
        frames += 1;
        let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
        largest = clip
            .writes()
            .iter()
            .filter(|w| w.mip == 0)
            .map(|w| w.size)
            .fold(largest, u32::max);
        if clip.stack.layers.iter().all(|l| l.complete()) && clip.writes().is_empty() {
            break;
        }
        assert!(frames < 600, "the rebuilt stack never completed");
    }
    assert_eq!(largest, 16, "subtiles of the edited size");
}

/// A second virtual texture (e.g. an overlay map) with texels of its own.
fn overlay_texel(level: u32, x: u64, y: u64) -> [u8; 4] {
    let a = address_texel(level, x, y);
    [255 - a[0], a[1] ^ 0x5a, a[2], 255]
}

#[test]
fn several_virtual_textures_stream_at_once() {
    let Some(mut harness) = RenderHarness::for_test("clip_stack_gpu_two", 16, 16) else {
        return;
    };
    harness.app_mut().add_plugins(TerrainClipPlugin);
    let (imagery, overlay) = {
        let world = harness.world_mut();
        let mut images = world.resource_mut::<Assets<Image>>();
        let imagery = ClipStackTexture::new_with_mips(
            Arc::new(ProceduralTileSource::new(64, 6, address_texel)),
            CLIP,
            SUBTILE,
            64,
            [0.2, 0.8],
            2,
            &mut images,
        );
        let overlay = ClipStackTexture::new_with_mips(
            Arc::new(ProceduralTileSource::new(64, 6, overlay_texel)),
            CLIP,
            SUBTILE,
            64,
            [0.7, 0.3],
            2,
            &mut images,
        );
        (world.spawn(imagery).id(), world.spawn(overlay).id())
    };
    harness.world_mut().spawn(Camera3d::default());
    harness.wait_until_ready().unwrap();
    let (a, _) = settle_and_compare(&mut harness, imagery, address_texel);
    let (b, _) = settle_and_compare(&mut harness, overlay, overlay_texel);
    assert_eq!((a, b), (4 * CLIP * CLIP, 4 * CLIP * CLIP));
}

/// A source with a hole: the finest pyramid level's tile (x, y) = (23, 19) loads as absent (no
/// file), like a partial level's edge.
struct Holey(ProceduralTileSource);

impl bevy_terrain_clip::source::TileSource for Holey {
    fn tile_size(&self) -> u32 {
        self.0.tile_size
    }
    fn levels(&self) -> u32 {
        self.0.levels
    }
    fn may_exist(&self, key: bevy_terrain_clip::cache::TileKey) -> bool {
        self.0.may_exist(key)
    }
    fn load(
        &self,
        key: bevy_terrain_clip::cache::TileKey,
    ) -> bevy::tasks::BoxedFuture<
        'static,
        Result<Option<bevy_terrain_clip::source::TileData>, bevy_terrain_clip::source::TileError>,
    > {
        if key.z == 5 && key.x == 23 && key.y == 19 {
            return Box::pin(async { Ok(None) });
        }
        self.0.load(key)
    }
}

#[test]
fn a_missing_tile_falls_back_to_coarser_layers_without_stalling() {
    let Some(mut harness) = RenderHarness::for_test("clip_stack_gpu_hole", 16, 16) else {
        return;
    };
    harness.app_mut().add_plugins(TerrainClipPlugin);
    // Centre on the hole: level 11 (2048 texels, 32 tiles a side) texel (23.5·64, 19.5·64).
    let center = [23.5 * 64.0 / 2048.0, 19.5 * 64.0 / 2048.0];
    let entity = {
        let world = harness.world_mut();
        let mut images = world.resource_mut::<Assets<Image>>();
        let clip = ClipStackTexture::new(
            Arc::new(Holey(ProceduralTileSource::new(64, 6, address_texel))),
            CLIP,
            SUBTILE,
            64,
            center,
            &mut images,
        );
        world.spawn(clip).id()
    };
    harness.world_mut().spawn(Camera3d::default());
    harness.wait_until_ready().unwrap();
    for _ in 0..100 {
        harness.step();
    }
    let clip = harness.world_mut().get::<ClipStackTexture>(entity).unwrap();
    // Every layer settled: the absent tile did not hold the stack back.
    assert!(clip.stack.layers.iter().all(|l| l.complete()));
    let finest = clip.stack.layers.last().unwrap();
    let absent = finest
        .slots()
        .iter()
        .filter(|s| s.state == bevy_terrain_clip::clip::layer::SlotState::Absent)
        .count();
    // The hole is one 64² tile: 2 × 2 subtiles of 32.
    assert_eq!(absent, 4);
    // Where the hole is, the finest layer is not used: the shader's choice falls back.
    let (layer, level, _) =
        bevy_terrain_clip::clip::stack::finest_covering_layer(&clip.stack, center);
    assert!(
        layer < clip.stack.layers.len(),
        "fell back from the finest layer"
    );
    assert!(level < 11);
    // Coarser layers are complete and valid there.
    assert!(
        clip.stack.layers[..clip.stack.layers.len() - 1]
            .iter()
            .all(|l| l.valid_fraction() == 1.0)
    );
}
