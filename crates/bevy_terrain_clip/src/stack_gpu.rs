//! The clip stack on the GPU: a [`ClipStackTexture`] streams a virtual texture's windowed
//! layers into a `c × c × layers` texture array. Every frame the main world recentres the stack,
//! polls the tile cache, picks the subtiles whose tiles are in RAM (coarsest layer first, rings
//! from the centre, under the per-frame budget), cuts them out of their tiles and queues them;
//! the render world writes them into their toroidal slots with `write_texture`, right after the
//! texture is prepared.
//!
//! Array layer `i` holds stack layer `i + 1` (virtual level `l_b + 1 + i`); level texel `t` of a
//! layer lives at array texel `t mod c`, so the material samples with Repeat addressing.

use crate::cache::TileKey;
use crate::clip::stack::{ClipStack, SubtileUpload, tile_of};
use crate::material::{ClipmapExtension, ClipmapMaterial, ClipmapParams, MAX_LAYERS};
use crate::settings::{ClipmapSettings, UpdateBudget};
use crate::source::{TexelKind, TileData, TileError, TileSource};
use crate::tile_cache::TileCache;
use bevy::asset::RenderAssetUsages;
use bevy::diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy::prelude::*;
use bevy::render::render_asset::{RenderAssets, prepare_assets};
use bevy::render::render_resource::{
    Extent3d, Origin3d, TexelCopyBufferLayout, TexelCopyTextureInfo, TextureAspect,
    TextureDimension, TextureUsages, TextureViewDescriptor, TextureViewDimension,
};
use bevy::render::renderer::RenderQueue;
use bevy::render::texture::GpuImage;
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderSystems};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The render world's cost of writing subtiles, shared with the main world so a
/// [`UpdateBudget::Millis`] budget covers the whole upload: cutting and mip-filtering subtiles
/// (main world, timed as it goes) and `write_texture` (render world, timed last frame and charged
/// per subtile from its running mean).
#[derive(Resource, Clone, Default)]
pub struct UploadCost(Arc<UploadCostInner>);

#[derive(Default)]
struct UploadCostInner {
    /// Nanoseconds spent in `write_texture` by the last render frame.
    last_write_ns: AtomicU64,
    /// Subtiles (all mips of one slot) written by the last render frame.
    last_subtiles: AtomicU64,
}

impl UploadCost {
    /// The last render frame's `write_texture` time (ms) and the subtiles it wrote.
    pub fn last_write(&self) -> (f64, u64) {
        (
            self.0.last_write_ns.load(Ordering::Relaxed) as f64 / 1.0e6,
            self.0.last_subtiles.load(Ordering::Relaxed),
        )
    }
}

/// One subtile's texels on their way to the GPU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SubtileWrite {
    /// Array layer.
    pub layer: u32,
    /// Mip level of the layer.
    pub mip: u32,
    /// Side of the written square (the subtile size halved per mip).
    pub size: u32,
    /// Texel origin of the slot in the layer.
    pub origin: [u32; 2],
    /// `s × s` RGBA8 texels.
    pub texels: Arc<Vec<u8>>,
}

/// Where a virtual texture lies in the world: its north-west corner and side, in f64 metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureMapping {
    /// World (x, z) of virtual-texture coordinates (0, 0).
    pub origin_m: bevy::math::DVec2,
    /// World size of the whole texture (m).
    pub size_m: f64,
}

impl TextureMapping {
    /// The mapping a pyramid manifest describes.
    pub fn from_manifest(m: &crate::pyramid::PyramidManifest) -> Self {
        Self {
            origin_m: bevy::math::DVec2::new(m.origin_m[0], m.origin_m[1]),
            size_m: m.metres_per_texel * 2f64.powi(m.virtual_levels() as i32 - 1),
        }
    }

    /// Virtual-texture coordinates of a world point.
    pub fn uv_of(&self, world: bevy::math::DVec2) -> bevy::math::DVec2 {
        (world - self.origin_m) / self.size_m
    }
}

/// Moves every mapped stack's centre of detail under the active 3D camera (the camera's point
/// straight below, on the texture; its world position under the [`RenderOrigin`](crate::RenderOrigin)).
pub fn follow_camera(
    cameras: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    mut stacks: Query<&mut ClipStackTexture>,
    origin: Option<Res<crate::RenderOrigin>>,
) {
    let origin = origin.as_deref().copied().unwrap_or_default();
    let Some((_, camera)) = cameras
        .iter()
        .filter(|(c, _)| c.is_active)
        .min_by_key(|(c, _)| c.order)
    else {
        return;
    };
    let p = camera.translation();
    if !p.is_finite() {
        return;
    }
    for mut clip in &mut stacks {
        if let Some(mapping) = clip.mapping {
            let uv = mapping.uv_of(origin.world_xz(p));
            let uv = [uv.x.clamp(0.0, 1.0), uv.y.clamp(0.0, 1.0)];
            if clip.center_uv != uv {
                clip.center_uv = uv;
            }
        }
    }
}

/// A virtual texture streamed into a clip stack texture array.
#[derive(Component)]
pub struct ClipStackTexture {
    /// The stack's bookkeeping.
    pub stack: ClipStack,
    /// The RAM tile cache.
    pub cache: TileCache,
    /// The `c × c × layers` texture array (RGBA8 sRGB for imagery, R32Float for heights).
    pub layers: Handle<Image>,
    /// What the stack holds (its source's [`TileSource::texels`]).
    pub texels: TexelKind,
    /// The base level `l_b` (`c × c`, full mip chain), loaded when the stack is made.
    pub base: Handle<Image>,
    /// Layers sampled trilinearly (coverage shrinks by a texel); otherwise nearest, mip 0.
    pub linear_filtering: bool,
    /// Mip levels per layer.
    pub layer_mips: u32,
    materials: Vec<Handle<ClipmapMaterial>>,
    /// Centre of detail in virtual-texture coordinates (f64; set it from the camera).
    pub center_uv: [f64; 2],
    /// Work allowed per frame: subtiles, bytes, or milliseconds of the streaming system.
    pub budget: UpdateBudget,
    /// Where the texture lies in the world; with one, the centre of detail follows the camera
    /// and the material samples at each fragment's position; without, at the mesh's texture
    /// coordinates.
    pub mapping: Option<TextureMapping>,
    /// Shown where there is no data ([`ClipmapSettings::no_data_color`]).
    pub no_data_color: Color,
    writes: Vec<SubtileWrite>,
    /// The base level being read on the IO task pool (its mip chain, concatenated).
    base_task: Option<bevy::tasks::Task<Vec<u8>>>,
    /// The base level's mips on their way to the GPU, sent every frame until written.
    base_writes: Vec<SubtileWrite>,
    /// Set by the render world once the base level is on the GPU.
    base_written: Arc<AtomicBool>,
    /// Running mean of the main world's cost of cutting one subtile and its mips (ms).
    prepare_ms_per_subtile: f64,
    /// For a height stack, the lowest and highest heights sent to the GPU so far.
    height_range: Option<(f32, f32)>,
}

impl ClipStackTexture {
    /// A stack of `clip_size` layers in `subtile_size` subtiles over `source`, with a
    /// `cache_tiles` RAM cache, centred on `center_uv`; creates its texture array in `images`.
    pub fn new(
        source: Arc<dyn TileSource>,
        clip_size: u32,
        subtile_size: u32,
        cache_tiles: usize,
        center_uv: [f64; 2],
        images: &mut Assets<Image>,
    ) -> Self {
        Self::new_with_mips(
            source,
            clip_size,
            subtile_size,
            cache_tiles,
            center_uv,
            1,
            images,
        )
    }

    /// Like [`new`](Self::new), with `mips` mip levels per layer (1 ..= log2(subtile) + 1): mip
    /// j of a layer holds the same window one level coarser per step, refreshed with every
    /// subtile upload, for trilinear filtering.
    pub fn new_with_mips(
        source: Arc<dyn TileSource>,
        clip_size: u32,
        subtile_size: u32,
        cache_tiles: usize,
        center_uv: [f64; 2],
        mips: u32,
        images: &mut Assets<Image>,
    ) -> Self {
        Self::build(
            source,
            [clip_size, subtile_size, mips],
            cache_tiles,
            center_uv,
            TexelKind::Color,
            images,
        )
    }

    /// A stack of heights: `source`'s heights (`TexelKind::Height`: an elevation pyramid's
    /// [`DiskHeightSource`](crate::dem::DiskHeightSource), or
    /// [`ProceduralTileSource::heights`](crate::source::ProceduralTileSource::heights)) streamed
    /// into an R32Float texture array, one mip a layer, sized by `settings` like
    /// [`from_settings`](Self::from_settings). The terrain geometry's vertex shader reads it with
    /// `textureLoad` (32-bit float textures are not filterable everywhere). A source of imagery is
    /// refused with an error and the stack stays empty (no data), never converted. Where the
    /// pyramid lacks a tile, a finer layer falls back to the coarser ones and the base level holds
    /// 0 m (logged when the base level is read).
    pub fn heights(
        source: Arc<dyn TileSource>,
        settings: &ClipmapSettings,
        center_uv: [f64; 2],
        images: &mut Assets<Image>,
    ) -> Self {
        Self::sized_by(source, settings, center_uv, TexelKind::Height, images)
    }

    /// A stack of `kind` sized by `settings` (heights: one mip a layer, read texel by texel).
    fn sized_by(
        source: Arc<dyn TileSource>,
        settings: &ClipmapSettings,
        center_uv: [f64; 2],
        kind: TexelKind,
        images: &mut Assets<Image>,
    ) -> Self {
        let (settings, fixes) = settings.sanitized();
        for fix in fixes {
            warn!("ClipmapSettings: {fix}");
        }
        let mips = match kind {
            TexelKind::Color => settings.layer_mips,
            TexelKind::Height => 1,
        };
        let mut clip = Self::build(
            source,
            [settings.clip_size, settings.subtile_size, mips],
            settings.cache_tiles as usize,
            center_uv,
            kind,
            images,
        );
        clip.budget = settings.budget;
        clip.no_data_color = settings.no_data_color;
        clip.linear_filtering = kind == TexelKind::Color;
        clip
    }

    fn build(
        source: Arc<dyn TileSource>,
        [clip_size, subtile_size, mips]: [u32; 3],
        cache_tiles: usize,
        center_uv: [f64; 2],
        kind: TexelKind,
        images: &mut Assets<Image>,
    ) -> Self {
        // A stack holds one kind of texel: a source of the other kind is an error, and the stack
        // shows no data rather than heights as colours or colours as heights.
        let source = if source.texels() != kind {
            error!(
                "clip stack: the source holds {}, the stack is for {}; nothing is streamed",
                source.texels().describe(),
                kind.describe()
            );
            Arc::new(NoTiles {
                tile_size: source.tile_size(),
                levels: source.levels(),
                kind,
            }) as Arc<dyn TileSource>
        } else {
            source
        };
        // A subtile is cut from one tile: no larger than the source's tiles (`pyramid_build
        // --tile 64` under the default 128-texel subtiles).
        let subtile_size = if subtile_size > source.tile_size() {
            warn!(
                "ClipmapSettings: subtile_size {subtile_size} -> {} (the source's tiles are {0} texels)",
                source.tile_size()
            );
            source.tile_size()
        } else {
            subtile_size
        };
        let mips = mips.clamp(1, subtile_size.trailing_zeros() + 1);
        let levels = source.levels() + source.tile_size().trailing_zeros();
        let stack = ClipStack::new(levels, clip_size, subtile_size, center_uv);
        let layer_count = stack.layers.len().max(1) as u32;
        let mut image = Image::new_uninit(
            Extent3d {
                width: clip_size,
                height: clip_size,
                depth_or_array_layers: layer_count,
            },
            TextureDimension::D2,
            kind.texture_format(),
            RenderAssetUsages::RENDER_WORLD,
        );
        image.sampler = repeat_sampler(kind == TexelKind::Color);
        image.texture_descriptor.mip_level_count = mips;
        image.texture_descriptor.usage |=
            TextureUsages::COPY_DST | TextureUsages::COPY_SRC | TextureUsages::TEXTURE_BINDING;
        image.texture_view_descriptor = Some(TextureViewDescriptor {
            dimension: Some(TextureViewDimension::D2Array),
            ..default()
        });
        // The base level is read off the main thread: until it arrives the placeholder is
        // transparent, which the material shows as no data.
        let base = images.add(base_image(
            clip_size,
            vec![0; base_level_bytes(clip_size)],
            kind,
        ));
        let base_task = {
            let source = source.clone();
            bevy::tasks::IoTaskPool::get_or_init(bevy::tasks::TaskPool::new)
                .spawn(async move { base_level_data(source.as_ref(), clip_size) })
        };
        Self {
            cache: TileCache::new(source, cache_tiles),
            stack,
            layers: images.add(image),
            texels: kind,
            base,
            linear_filtering: true,
            layer_mips: mips,
            materials: Vec::new(),
            center_uv,
            budget: UpdateBudget::Subtiles(16),
            mapping: None,
            no_data_color: crate::settings::NO_DATA_COLOR,
            writes: Vec::new(),
            base_task: Some(base_task),
            base_writes: Vec::new(),
            base_written: Arc::new(AtomicBool::new(false)),
            prepare_ms_per_subtile: 0.0,
            height_range: None,
        }
    }

    /// A stack sized by [`ClipmapSettings`] (clip and subtile size, cache tiles, budget).
    pub fn from_settings(
        source: Arc<dyn TileSource>,
        settings: &ClipmapSettings,
        center_uv: [f64; 2],
        images: &mut Assets<Image>,
    ) -> Self {
        Self::sized_by(source, settings, center_uv, TexelKind::Color, images)
    }

    /// A terrain material drawing this stack (its coverage is kept current by the plugin);
    /// `look` gives the lighting response (its base colour multiplies the imagery).
    pub fn material(
        &mut self,
        look: StandardMaterial,
        materials: &mut Assets<ClipmapMaterial>,
    ) -> Handle<ClipmapMaterial> {
        let handle = materials.add(ClipmapMaterial {
            base: look,
            extension: ClipmapExtension {
                layers: self.layers.clone(),
                base: self.base.clone(),
                params: clipmap_params(self, &crate::RenderOrigin::default()),
                soft_visibility: None,
                ..default()
            },
        });
        self.materials.push(handle.clone());
        handle
    }

    /// The materials made with [`material`](Self::material).
    pub fn materials(&self) -> &[Handle<ClipmapMaterial>] {
        &self.materials
    }

    /// Switches between bilinear and nearest sampling of the layers and the base level.
    pub fn set_linear_filtering(&mut self, linear: bool, images: &mut Assets<Image>) {
        // Heights are read texel by texel (R32Float is not filterable everywhere).
        let linear = linear && self.texels == TexelKind::Color;
        self.linear_filtering = linear;
        for handle in [&self.layers, &self.base] {
            if let Some(mut image) = images.get_mut(handle) {
                image.sampler = repeat_sampler(linear);
            }
        }
    }

    /// Whether the base level is on the GPU (read off the main thread when the stack is made;
    /// until then the terrain shows the no-data colour where no layer covers).
    pub fn base_ready(&self) -> bool {
        self.base_written.load(Ordering::Acquire)
    }

    /// The uploads queued this frame.
    pub fn writes(&self) -> &[SubtileWrite] {
        &self.writes
    }

    /// For a height stack: the lowest and highest heights (m) sent to the GPU so far — bounds on
    /// what the vertex stage can read, as it reads resident data only (`None` before any).
    pub fn height_range(&self) -> Option<(f32, f32)> {
        self.height_range
    }

    /// Widens [`height_range`](Self::height_range) by the heights of `texels` (f32 a texel).
    fn observe_heights(&mut self, texels: &[u8]) {
        if self.texels != TexelKind::Height {
            return;
        }
        let (mut low, mut high) = self
            .height_range
            .unwrap_or((f32::INFINITY, f32::NEG_INFINITY));
        for h in texels.chunks_exact(4) {
            let h = f32::from_le_bytes([h[0], h[1], h[2], h[3]]);
            if h.is_finite() {
                low = low.min(h);
                high = high.max(h);
            }
        }
        if low <= high {
            self.height_range = Some((low, high));
        }
    }

    /// For a height stack with a [`mapping`](Self::mapping): the ground's height (m) at world
    /// `(x, z)` from the tiles in RAM — the finest pyramid level whose tiles around the point
    /// are resident, bilinear between texel centres (clamped at the texture's edges) — with
    /// the virtual level it came from. Never reads from disk or blocks (gameplay queries, a
    /// camera keeping above the ground); `None` outside the texture, before any tile is in,
    /// or for a stack of imagery.
    pub fn resident_height(&mut self, world: bevy::math::DVec2) -> Option<(f32, u32)> {
        let mapping = self.mapping?;
        if self.texels != TexelKind::Height {
            return None;
        }
        let uv = mapping.uv_of(world);
        if !(0.0..1.0).contains(&uv.x) || !(0.0..1.0).contains(&uv.y) {
            return None;
        }
        let source = self.cache.source().clone();
        let tile = source.tile_size();
        let tile_bits = tile.trailing_zeros();
        for z in (0..source.levels()).rev() {
            let level = z + tile_bits;
            let side = 1i64 << level;
            let t = uv * side as f64 - 0.5;
            let (x0, y0) = (t.x.floor() as i64, t.y.floor() as i64);
            let (fx, fy) = ((t.x - x0 as f64) as f32, (t.y - y0 as f64) as f32);
            let texel = |cache: &mut TileCache, x: i64, y: i64| -> Option<f32> {
                let (x, y) = (x.clamp(0, side - 1) as u64, y.clamp(0, side - 1) as u64);
                let key = TileKey {
                    z,
                    x: (x >> tile_bits) as u32,
                    y: (y >> tile_bits) as u32,
                };
                if !cache.contains(key) {
                    return None;
                }
                let data = cache.get(key)?;
                Some(data.height((x % tile as u64) as u32, (y % tile as u64) as u32))
            };
            let corners = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .map(|(dx, dy)| texel(&mut self.cache, x0 + dx, y0 + dy));
            if let [Some(a), Some(b), Some(c), Some(d)] = corners {
                let top = a + (b - a) * fx;
                let bottom = c + (d - c) * fx;
                return Some((top + (bottom - top) * fy, level));
            }
        }
        None
    }

    /// For a height stack with a [`mapping`](Self::mapping): the ground's unit normal at world
    /// `(x, z)` from the tiles in RAM — central differences of [`resident_height`](Self::resident_height)
    /// one texel of the finest level resident there apart — or `None` where that has no answer.
    pub fn resident_normal(&mut self, world: bevy::math::DVec2) -> Option<Vec3> {
        let mapping = self.mapping?;
        let (_, level) = self.resident_height(world)?;
        let e = mapping.size_m / 2f64.powi(level as i32);
        let mut at = |dx: f64, dz: f64| {
            self.resident_height(world + bevy::math::DVec2::new(dx, dz))
                .map(|(h, _)| h as f64)
        };
        let (x0, x1, z0, z1) = (at(-e, 0.0)?, at(e, 0.0)?, at(0.0, -e)?, at(0.0, e)?);
        Some(
            bevy::math::DVec3::new(x0 - x1, 2.0 * e, z0 - z1)
                .normalize()
                .as_vec3(),
        )
    }
}

fn repeat_sampler(linear: bool) -> bevy::image::ImageSampler {
    use bevy::image::{ImageAddressMode, ImageFilterMode, ImageSampler, ImageSamplerDescriptor};
    let filter = if linear {
        ImageFilterMode::Linear
    } else {
        ImageFilterMode::Nearest
    };
    ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        mag_filter: filter,
        min_filter: filter,
        mipmap_filter: filter,
        ..default()
    })
}

/// Bytes of a `c × c` RGBA8 base level with its full mip chain.
fn base_level_bytes(clip_size: u32) -> usize {
    let mut bytes = 0usize;
    let mut size = clip_size as usize;
    loop {
        bytes += size * size * 4;
        if size == 1 {
            return bytes;
        }
        size /= 2;
    }
}

/// The base level `l_b = log2 c` as a `c × c` image with its full mip chain
/// ([`base_level_data`]), read from `source` now, blocking.
pub fn base_level_image(source: &dyn TileSource, clip_size: u32) -> Image {
    base_image(
        clip_size,
        base_level_data(source, clip_size),
        source.texels(),
    )
}

/// The base level's `c × c` texture with its full mip chain holding `data`.
fn base_image(clip_size: u32, data: Vec<u8>, kind: TexelKind) -> Image {
    let mut image = Image::new_uninit(
        Extent3d {
            width: clip_size,
            height: clip_size,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        kind.texture_format(),
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.mip_level_count = clip_size.trailing_zeros() + 1;
    image.data = Some(data);
    image.sampler = repeat_sampler(kind == TexelKind::Color);
    image
}

/// A source with no tiles: what a stack streams when given a source of the wrong kind.
struct NoTiles {
    tile_size: u32,
    levels: u32,
    kind: TexelKind,
}

impl TileSource for NoTiles {
    fn tile_size(&self) -> u32 {
        self.tile_size
    }
    fn levels(&self) -> u32 {
        self.levels
    }
    fn may_exist(&self, _: TileKey) -> bool {
        false
    }
    fn load(
        &self,
        _: TileKey,
    ) -> bevy::tasks::BoxedFuture<
        'static,
        Result<Option<crate::source::TileData>, crate::source::TileError>,
    > {
        Box::pin(async { Ok(None) })
    }
    fn texels(&self) -> TexelKind {
        self.kind
    }
}

/// The base level `l_b = log2 c`'s `c × c` texels and its full mip chain (box-filtered),
/// concatenated, read from `source` (blocking: `(c / tile)²` tiles, or one coarser tile
/// downsampled; [`ClipStackTexture`] runs it on the IO task pool). A pyramid
/// whose finest level is narrower than `c` texels gives its finest level, magnified (nearest) to
/// `c`: the same ground, blurrier, rather than a level that does not exist. Missing or failed
/// tiles are left transparent and logged: a tile is tried up to [`BASE_TILE_ATTEMPTS`] times,
/// each waited for at most [`BASE_TILE_TIMEOUT`], so a source that fails for a moment does not
/// leave a hole in the base level for good, and one that never answers does not keep it from
/// arriving.
pub fn base_level_data(source: &dyn TileSource, clip_size: u32) -> Vec<u8> {
    base_level_data_waiting(source, clip_size, BASE_TILE_TIMEOUT)
}

/// How long the base level's read waits for one tile before trying it again.
pub const BASE_TILE_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(5);

/// How many times the base level's read tries a tile that fails (with pauses of 40, 80, 160 ms
/// between, at most a try's wait: a server's brief outage, a file being written).
pub const BASE_TILE_ATTEMPTS: u32 = 4;

/// Loads `key` (of side `t`) for the base level: up to [`BASE_TILE_ATTEMPTS`] tries of at most
/// `timeout` each.
fn load_base_tile(
    source: &dyn TileSource,
    key: TileKey,
    t: u32,
    timeout: std::time::Duration,
) -> Result<Option<TileData>, TileError> {
    let mut result = Ok(None);
    for attempt in 0..BASE_TILE_ATTEMPTS {
        if attempt > 0 {
            // Never longer than a try may wait.
            std::thread::sleep(std::time::Duration::from_millis(20 << attempt).min(timeout));
        }
        result = wait_at_most(source.load(key), key, timeout).and_then(|tile| match tile {
            Some(tile) => tile.check(key, t).map(|()| Some(tile)),
            None => Ok(None),
        });
        if result.is_ok() {
            break;
        }
    }
    result
}

/// Polls `load` until it answers or `timeout` passes (the base level is read on a task of its
/// own, so it may wait; a load that never answers is dropped).
fn wait_at_most<T>(
    mut load: bevy::tasks::BoxedFuture<'static, Result<T, TileError>>,
    key: TileKey,
    timeout: std::time::Duration,
) -> Result<T, TileError> {
    let start = std::time::Instant::now();
    loop {
        if let Some(result) = bevy::tasks::futures::check_ready(&mut load) {
            return result;
        }
        if start.elapsed() >= timeout {
            return Err(TileError::TimedOut {
                key,
                after: timeout,
            });
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

/// [`base_level_data`] waiting at most `timeout` for each try of a tile.
pub fn base_level_data_waiting(
    source: &dyn TileSource,
    clip_size: u32,
    timeout: std::time::Duration,
) -> Vec<u8> {
    let t = source.tile_size();
    let base_level = clip_size.trailing_zeros();
    let tile_bits = t.trailing_zeros();
    // Pyramid level whose tiles cover the base level (or the coarsest if the base is smaller
    // than a tile, the finest if the pyramid is smaller than the base).
    let z = base_level
        .saturating_sub(tile_bits)
        .min(source.levels().saturating_sub(1));
    let side = (1u32 << z) * t;
    let mut texels = vec![0u8; (side * side * 4) as usize];
    for ty in 0..(1u32 << z) {
        for tx in 0..(1u32 << z) {
            let key = TileKey { z, x: tx, y: ty };
            match load_base_tile(source, key, t, timeout) {
                Ok(Some(tile)) => {
                    for row in 0..t {
                        let src = (row * t * 4) as usize;
                        let dst = (((ty * t + row) * side + tx * t) * 4) as usize;
                        texels[dst..dst + (t * 4) as usize]
                            .copy_from_slice(&tile.rgba[src..src + (t * 4) as usize]);
                    }
                }
                Ok(None) => warn!("clip stack base level: tile {key:?} is absent"),
                Err(e) => warn!("clip stack base level: {e}"),
            }
        }
    }
    let (mut level, mut size) = (texels, side);
    if size < clip_size {
        let factor = clip_size / size;
        let mut magnified = vec![0u8; (clip_size * clip_size * 4) as usize];
        for y in 0..clip_size {
            for x in 0..clip_size {
                let src = (((y / factor) * size + x / factor) * 4) as usize;
                let dst = ((y * clip_size + x) * 4) as usize;
                magnified[dst..dst + 4].copy_from_slice(&level[src..src + 4]);
            }
        }
        (level, size) = (magnified, clip_size);
    }
    while size > clip_size {
        level = source.texels().halve(&level, size);
        size /= 2;
    }
    let mut data = level.clone();
    while size > 1 {
        level = source.texels().halve(&level, size);
        size /= 2;
        data.extend_from_slice(&level);
    }
    data
}

/// The 2×2 box filter of a `side × side` RGBA8 square (rounded means of the stored bytes).
pub fn halve(texels: &[u8], side: u32) -> Vec<u8> {
    crate::source::halve_rgba8(texels, side)
}

/// Recentres every clip stack, polls its tile cache and queues this frame's subtile uploads.
pub fn stream_clip_stacks(
    mut stacks: Query<&mut ClipStackTexture>,
    cost: Res<UploadCost>,
    mut write_ms_per_subtile: Local<Option<f64>>,
    mut diagnostics: Diagnostics,
) {
    let (mut quality, mut uploaded, mut loaded, mut latency, mut failed) =
        (f64::INFINITY, 0usize, 0u64, 0.0f64, 0u64);
    let mut usable = f64::INFINITY;
    // Running mean of the render world's write time per subtile (learned from the frames that
    // wrote some); charged to the millisecond budget for every subtile planned.
    let (write_ms, written) = cost.last_write();
    if written > 0 {
        let sample = write_ms / written as f64;
        *write_ms_per_subtile = Some(match *write_ms_per_subtile {
            Some(mean) => 0.9 * mean + 0.1 * sample,
            None => sample,
        });
    }
    let write_estimate_ms = write_ms_per_subtile.unwrap_or(0.0);
    let mut prepare_ms = 0.0f64;
    for mut clip in &mut stacks {
        let started = std::time::Instant::now();
        let clip = &mut *clip;
        clip.writes.clear();
        // The base level, once read: one write per mip, sent until the render world has it.
        if let Some(data) = clip
            .base_task
            .as_mut()
            .and_then(bevy::tasks::futures::check_ready)
        {
            clip.base_task = None;
            let mip0 = (clip.stack.clip_size * clip.stack.clip_size * 4) as usize;
            clip.observe_heights(&data[..mip0.min(data.len())]);
            let (mut offset, mut size) = (0usize, clip.stack.clip_size);
            for mip in 0.. {
                let bytes = (size * size * 4) as usize;
                clip.base_writes.push(SubtileWrite {
                    layer: 0,
                    mip,
                    size,
                    origin: [0, 0],
                    texels: Arc::new(data[offset..offset + bytes].to_vec()),
                });
                offset += bytes;
                if size == 1 {
                    break;
                }
                size /= 2;
            }
        }
        if clip.base_ready() {
            clip.base_writes.clear();
        }
        clip.stack.recenter(clip.center_uv);
        clip.cache.poll();
        let tile_size = clip.cache.source().tile_size();
        let s = clip.stack.subtile_size;
        // One pass over every layer's missing subtiles: a subtile whose tile is known not to
        // exist settles as absent (coarser layers show there, and the layer can complete so the
        // finer ones start); the others ask for their tile (the queue serves the coarsest first).
        for (i, layer) in clip.stack.layers.iter_mut().enumerate() {
            for subtile in layer.invalid_in_ring_order() {
                let upload = SubtileUpload {
                    layer: i + 1,
                    level: layer.level,
                    subtile,
                };
                let key = tile_of(&upload, tile_size, s);
                if clip.cache.is_absent(key) {
                    layer.set_state(subtile, crate::clip::layer::SlotState::Absent);
                } else {
                    clip.cache.get(key);
                }
            }
        }
        let cache = &mut clip.cache;
        let subtile_bytes = (s * s * 4) as u64;
        let plan = match clip.budget {
            UpdateBudget::Subtiles(n) => clip
                .stack
                .plan_available(n, |u| cache.contains(tile_of(u, tile_size, s))),
            UpdateBudget::Bytes(b) => clip
                .stack
                .plan_available((b / subtile_bytes).clamp(1, u32::MAX as u64) as u32, |u| {
                    cache.contains(tile_of(u, tile_size, s))
                }),
            UpdateBudget::Millis(ms) => {
                // One subtile at a time until the time is spent (at least one per frame): the
                // time so far, the cutting and mip filtering of the planned subtiles (measured
                // per subtile below, so estimated from the last frame's mean) and their
                // render-world writes.
                let mut plan = Vec::new();
                let per_subtile = write_estimate_ms + clip.prepare_ms_per_subtile;
                loop {
                    let next = clip
                        .stack
                        .plan_available(1, |u| cache.contains(tile_of(u, tile_size, s)));
                    if next.is_empty() {
                        break;
                    }
                    plan.extend(next);
                    let spent =
                        started.elapsed().as_secs_f64() * 1000.0 + plan.len() as f64 * per_subtile;
                    if spent >= ms.max(0.0) as f64 {
                        break;
                    }
                }
                plan
            }
        };
        let n = clip.stack.clip_size / s;
        let prepare_started = std::time::Instant::now();
        let planned = plan.len();
        for upload in plan {
            let key = tile_of(&upload, tile_size, s);
            let Some(tile) = clip.cache.get(key) else {
                continue;
            };
            // The subtile's texels inside its tile.
            let per_tile = (tile_size / s) as i64;
            let (ox, oy) = (
                upload.subtile[0].rem_euclid(per_tile) as u32 * s,
                upload.subtile[1].rem_euclid(per_tile) as u32 * s,
            );
            let mut texels = Vec::with_capacity((s * s * 4) as usize);
            for row in 0..s {
                let start = (((oy + row) * tile_size + ox) * 4) as usize;
                texels.extend_from_slice(&tile.rgba[start..start + (s * 4) as usize]);
            }
            let slot = [
                upload.subtile[0].rem_euclid(n as i64) as u32,
                upload.subtile[1].rem_euclid(n as i64) as u32,
            ];
            clip.observe_heights(&texels);
            // Mip 0, then each mip the 2×2 box filter of the one before.
            let (mut texels, mut size) = (texels, s);
            for mip in 0..clip.layer_mips {
                let next = (mip + 1 < clip.layer_mips && size > 1)
                    .then(|| clip.texels.halve(&texels, size));
                clip.writes.push(SubtileWrite {
                    layer: upload.layer as u32 - 1,
                    mip,
                    size,
                    origin: [(slot[0] * s) >> mip, (slot[1] * s) >> mip],
                    texels: Arc::new(texels),
                });
                match next {
                    Some(n) => {
                        texels = n;
                        size /= 2;
                    }
                    None => break,
                }
            }
        }
        if planned > 0 {
            let ms = prepare_started.elapsed().as_secs_f64() * 1000.0;
            prepare_ms += ms;
            let sample = ms / planned as f64;
            clip.prepare_ms_per_subtile = if clip.prepare_ms_per_subtile > 0.0 {
                0.9 * clip.prepare_ms_per_subtile + 0.1 * sample
            } else {
                sample
            };
        }
        // What is really resident: the base level counts once it is on the GPU.
        let layers = clip.stack.layers.len() as f64 + 1.0;
        let missing_base = if clip.base_ready() { 0.0 } else { 1.0 / layers };
        quality = quality.min((clip.stack.quality() as f64 - missing_base) * 100.0);
        usable = usable.min((clip.stack.usable_coverage() - missing_base) * 100.0);
        uploaded += planned;
        loaded += clip.cache.stats.loaded;
        failed += clip.cache.stats.failed;
        latency = latency.max(clip.cache.stats.latency_avg_ms);
    }
    if quality.is_finite() {
        diagnostics.add_measurement(&QUALITY, || quality);
        diagnostics.add_measurement(&USABLE, || usable);
        diagnostics.add_measurement(&SUBTILES_UPLOADED, || uploaded as f64);
        diagnostics.add_measurement(&TILES_LOADED, || loaded as f64);
        diagnostics.add_measurement(&TILES_FAILED, || failed as f64);
        diagnostics.add_measurement(&TILE_LATENCY_MS, || latency);
        // This frame's cutting and filtering plus the last render frame's writes.
        diagnostics.add_measurement(&UPLOAD_MS, || prepare_ms + write_ms);
        let per_subtile = write_estimate_ms
            + stacks
                .iter()
                .map(|c| c.prepare_ms_per_subtile)
                .fold(0.0, f64::max);
        if per_subtile > 0.0 {
            diagnostics.add_measurement(&UPLOAD_MS_PER_SUBTILE, || per_subtile);
        }
    }
}

/// Share of the clip stack holding valid data (%, the worst stack).
pub const QUALITY: DiagnosticPath = DiagnosticPath::const_new("terrain/stack_valid_percent");
/// Lowest share of a stack the shader can sample, base level and coverage rectangles (%).
pub const USABLE: DiagnosticPath = DiagnosticPath::const_new("terrain/stack_usable_percent");
/// CPU time of texture updates (ms): this frame's subtile cutting and mip filtering plus the
/// last render frame's `write_texture` calls, all clip stacks together.
pub const UPLOAD_MS: DiagnosticPath = DiagnosticPath::const_new("terrain/upload_ms");
/// Running mean CPU cost of one subtile's update (ms): cutting, mip filtering and writing.
/// `1 / this` is how many subtiles a [`UpdateBudget::Millis`]`(1.0)` budget buys.
pub const UPLOAD_MS_PER_SUBTILE: DiagnosticPath =
    DiagnosticPath::const_new("terrain/upload_ms_per_subtile");
/// Subtiles uploaded this frame (each with its mips).
pub const SUBTILES_UPLOADED: DiagnosticPath =
    DiagnosticPath::const_new("terrain/subtiles_uploaded");
/// Tiles loaded since start.
pub const TILES_LOADED: DiagnosticPath = DiagnosticPath::const_new("terrain/tiles_loaded");
/// Tile loads that failed since start.
pub const TILES_FAILED: DiagnosticPath = DiagnosticPath::const_new("terrain/tiles_failed");
/// Mean tile latency (ms, the slowest stack).
pub const TILE_LATENCY_MS: DiagnosticPath = DiagnosticPath::const_new("terrain/tile_latency_ms");

/// This frame's subtile writes (render world).
#[derive(Resource, Default)]
struct ExtractedClipWrites(Vec<(AssetId<Image>, SubtileWrite, Option<Arc<AtomicBool>>)>);

fn extract_clip_writes(
    mut extracted: ResMut<ExtractedClipWrites>,
    stacks: Extract<Query<&ClipStackTexture>>,
) {
    extracted.0.clear();
    for clip in &stacks {
        for write in &clip.writes {
            extracted.0.push((clip.layers.id(), write.clone(), None));
        }
        for write in &clip.base_writes {
            extracted.0.push((
                clip.base.id(),
                write.clone(),
                Some(clip.base_written.clone()),
            ));
        }
    }
}

fn write_subtiles(
    extracted: Res<ExtractedClipWrites>,
    images: Res<RenderAssets<GpuImage>>,
    queue: Res<RenderQueue>,
    cost: Res<UploadCost>,
) {
    let started = std::time::Instant::now();
    let subtiles = extracted
        .0
        .iter()
        .filter(|(_, w, base)| w.mip == 0 && base.is_none())
        .count();
    for (image, write, base_written) in &extracted.0 {
        let Some(gpu) = images.get(*image) else {
            // The base level is sent again next frame; a subtile is planned again.
            if base_written.is_none() {
                warn!("clip stack texture not prepared yet: a subtile upload was dropped");
            }
            continue;
        };
        if let Some(flag) = base_written {
            flag.store(true, Ordering::Release);
        }
        queue.write_texture(
            TexelCopyTextureInfo {
                texture: &gpu.texture,
                mip_level: write.mip,
                origin: Origin3d {
                    x: write.origin[0],
                    y: write.origin[1],
                    z: write.layer,
                },
                aspect: TextureAspect::All,
            },
            &write.texels,
            TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(write.size * 4),
                rows_per_image: Some(write.size),
            },
            Extent3d {
                width: write.size,
                height: write.size,
                depth_or_array_layers: 1,
            },
        );
    }
    cost.0
        .last_write_ns
        .store(started.elapsed().as_nanos() as u64, Ordering::Relaxed);
    cost.0
        .last_subtiles
        .store(subtiles as u64, Ordering::Relaxed);
}

/// The material parameters of a stack: each layer's valid rectangle, shrunk by one texel when
/// the layers are filtered linearly (so a bilinear footprint never reaches an invalid texel),
/// placed in the sampling space of [`ClipmapParams`] — render space under `origin` for a stack
/// with a mapping, computed in f64.
pub fn clipmap_params(clip: &ClipStackTexture, origin: &crate::RenderOrigin) -> ClipmapParams {
    use bevy::math::DVec2;
    // Sampling space: texture (0, 0) at `corner`, `side` across.
    let (corner, side) = match clip.mapping {
        Some(m) => (m.origin_m - DVec2::new(origin.0.x, origin.0.z), m.size_m),
        None => (DVec2::ZERO, 1.0),
    };
    let mut params = ClipmapParams {
        texture_origin: corner.as_vec2(),
        texture_size: side as f32,
        by_position: clip.mapping.is_some() as u32,
        base_level: clip.stack.base_level,
        layer_count: clip.stack.layers.len().min(MAX_LAYERS) as u32,
        clip_size: clip.stack.clip_size as f32,
        mips: if clip.linear_filtering {
            clip.layer_mips
        } else {
            1
        },
        no_data: Vec4::from(clip.no_data_color.to_linear().to_f32_array()),
        ..default()
    };
    let shrink = if clip.linear_filtering { 1 } else { 0 };
    let c = clip.stack.clip_size as i64;
    for (i, (coverage, layer)) in clip
        .stack
        .coverage()
        .into_iter()
        .zip(&clip.stack.layers)
        .take(MAX_LAYERS)
        .enumerate()
    {
        let texel = side / 2f64.powi(layer.level as i32);
        let Some((min, max)) = coverage else {
            params.slots[i].z = texel as f32;
            continue;
        };
        let min = [min[0] + shrink, min[1] + shrink];
        let size = [
            (max[0] - shrink - min[0]).max(0),
            (max[1] - shrink - min[1]).max(0),
        ];
        let at = corner + DVec2::new(min[0] as f64, min[1] as f64) * texel;
        params.windows[i] = Vec4::new(at.x as f32, at.y as f32, size[0] as f32, size[1] as f32);
        params.slots[i] = Vec4::new(
            min[0].rem_euclid(c) as f32,
            min[1].rem_euclid(c) as f32,
            texel as f32,
            0.0,
        );
    }
    params
}

/// Keeps every stack's materials' coverage current.
/// Edits to [`ClipmapSettings`] after start-up apply to the live stacks: the budget at once, the
/// sizes (clip, subtile, layer mips, cached tiles) by rebuilding each stack — new textures, the
/// same source, centre, mapping and materials, streaming again from the base level. Only the
/// fields edited change: a stack made with sizes of its own keeps the others.
pub fn apply_live_settings(
    settings: Option<Res<ClipmapSettings>>,
    mut last: Local<Option<ClipmapSettings>>,
    mut stacks: Query<&mut ClipStackTexture>,
    mut images: ResMut<Assets<Image>>,
    mut materials: ResMut<Assets<ClipmapMaterial>>,
    origin: Option<Res<crate::RenderOrigin>>,
) {
    let Some(settings) = settings else {
        return;
    };
    // Nothing to do unless the settings changed since they were last seen.
    if last.is_some() && !settings.is_changed() {
        return;
    }
    let (settings, _) = settings.sanitized();
    let Some(before) = last.replace(settings.clone()) else {
        return;
    };
    if before == settings {
        return;
    }
    for mut clip in &mut stacks {
        if settings.budget != before.budget {
            clip.budget = settings.budget;
        }
        let pick = |now: u32, then: u32, own: u32| if now != then { now } else { own };
        let clip_size = pick(settings.clip_size, before.clip_size, clip.stack.clip_size);
        let subtile = pick(
            settings.subtile_size,
            before.subtile_size,
            clip.stack.subtile_size,
        )
        .min(clip_size / 2);
        let mips = match clip.texels {
            TexelKind::Height => 1,
            TexelKind::Color => pick(settings.layer_mips, before.layer_mips, clip.layer_mips),
        };
        let cache = pick(
            settings.cache_tiles,
            before.cache_tiles,
            clip.cache.capacity() as u32,
        );
        if (clip_size, subtile, mips, cache)
            == (
                clip.stack.clip_size,
                clip.stack.subtile_size,
                clip.layer_mips,
                clip.cache.capacity() as u32,
            )
        {
            continue;
        }
        let mut rebuilt = ClipStackTexture::build(
            clip.cache.source().clone(),
            [clip_size, subtile, mips],
            cache as usize,
            clip.center_uv,
            clip.texels,
            &mut images,
        );
        rebuilt.budget = clip.budget;
        rebuilt.mapping = clip.mapping;
        rebuilt.no_data_color = clip.no_data_color;
        rebuilt.stack.grid_shift = clip.stack.grid_shift;
        rebuilt.set_linear_filtering(clip.linear_filtering, &mut images);
        // The materials drawing the old stack now draw the new one.
        rebuilt.materials = std::mem::take(&mut clip.materials);
        for handle in &rebuilt.materials {
            if let Some(mut material) = materials.get_mut(handle) {
                material.extension.layers = rebuilt.layers.clone();
                material.extension.base = rebuilt.base.clone();
                material.extension.params =
                    clipmap_params(&rebuilt, &origin.as_deref().copied().unwrap_or_default());
            }
        }
        info!(
            "ClipmapSettings: a clip stack rebuilt with clip {clip_size}, subtile {subtile}, \
             {mips} mips a layer, {cache} cached tiles"
        );
        *clip = rebuilt;
    }
}

pub fn update_clipmap_materials(
    mut stacks: Query<&mut ClipStackTexture>,
    settings: Option<Res<ClipmapSettings>>,
    origin: Option<Res<crate::RenderOrigin>>,
    mut materials: ResMut<Assets<ClipmapMaterial>>,
) {
    for mut clip in &mut stacks {
        // The no-data colour follows the settings live (the panel edits it).
        if let Some(settings) = settings.as_ref().filter(|s| s.is_changed())
            && clip.no_data_color != settings.no_data_color
        {
            clip.no_data_color = settings.no_data_color;
        }
        let params = clipmap_params(&clip, &origin.as_deref().copied().unwrap_or_default());
        for handle in clip.materials() {
            let Some(material) = materials.get(handle) else {
                continue;
            };
            if material.extension.params != params {
                materials.get_mut(handle).unwrap().extension.params = params;
            }
        }
    }
}

/// Registers the clip stack streaming.
pub(crate) fn build(app: &mut App) {
    for path in [
        QUALITY,
        USABLE,
        SUBTILES_UPLOADED,
        TILES_LOADED,
        TILES_FAILED,
        TILE_LATENCY_MS,
        UPLOAD_MS,
        UPLOAD_MS_PER_SUBTILE,
    ] {
        app.register_diagnostic(Diagnostic::new(path).with_max_history_length(1));
    }
    app.add_systems(
        PostUpdate,
        (
            apply_live_settings,
            follow_camera,
            stream_clip_stacks,
            update_clipmap_materials,
        )
            .chain()
            .after(bevy::transform::TransformSystems::Propagate),
    );
    let cost = UploadCost::default();
    app.insert_resource(cost.clone());
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .insert_resource(cost)
        .init_resource::<ExtractedClipWrites>()
        .add_systems(ExtractSchedule, extract_clip_writes)
        .add_systems(
            Render,
            write_subtiles
                .in_set(RenderSystems::PrepareAssets)
                .after(prepare_assets::<GpuImage>),
        );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::ProceduralTileSource;

    #[test]
    fn a_pyramid_narrower_than_the_clip_fills_the_base_level() {
        // Two levels of 16-texel tiles: 32 texels across, under a 128-texel clip.
        let texel = |level: u32, x: u64, y: u64| [level as u8 * 40, x as u8, y as u8, 255];
        let source = ProceduralTileSource::new(16, 2, texel);
        let image = base_level_image(&source, 128);
        let data = image.data.unwrap();
        assert_eq!(image.texture_descriptor.size.width, 128);
        // Mip 0: the finest level (virtual level 5), each texel magnified 4×.
        for (x, y) in [(0u32, 0u32), (13, 7), (127, 127), (64, 100)] {
            let i = ((y * 128 + x) * 4) as usize;
            assert_eq!(
                data[i..i + 4],
                texel(5, (x / 4) as u64, (y / 4) as u64),
                "({x}, {y})"
            );
        }
    }

    /// A source that fails its first loads of every tile: the first never answers (tile 0/0
    /// only), then errors, then answers; `failures` per tile in all.
    struct Flaky {
        inner: ProceduralTileSource,
        failures: u32,
        seen: std::sync::Mutex<std::collections::HashMap<TileKey, u32>>,
    }

    impl TileSource for Flaky {
        fn tile_size(&self) -> u32 {
            self.inner.tile_size()
        }
        fn levels(&self) -> u32 {
            self.inner.levels()
        }
        fn may_exist(&self, key: TileKey) -> bool {
            self.inner.may_exist(key)
        }
        fn load(
            &self,
            key: TileKey,
        ) -> bevy::tasks::BoxedFuture<'static, Result<Option<TileData>, TileError>> {
            let n = {
                let mut seen = self.seen.lock().unwrap();
                let n = seen.entry(key).or_insert(0);
                *n += 1;
                *n
            };
            if n > self.failures {
                return self.inner.load(key);
            }
            if n == 1 && key.x == 0 && key.y == 0 {
                return Box::pin(std::future::pending());
            }
            Box::pin(async move {
                Err(TileError::Io(
                    "flaky".into(),
                    std::io::Error::other("a brief outage"),
                ))
            })
        }
    }

    /// A base level read through a source that hangs and fails for a while is the clean one;
    /// through one that never recovers it comes back, with holes, instead of waiting forever.
    #[test]
    fn the_base_level_survives_a_flaky_source() {
        let texel = |level: u32, x: u64, y: u64| [level as u8 * 40, x as u8, y as u8, 255];
        let clean = base_level_data(&ProceduralTileSource::new(16, 4, texel), 64);
        let flaky = |failures| Flaky {
            inner: ProceduralTileSource::new(16, 4, texel),
            failures,
            seen: Default::default(),
        };
        let timeout = std::time::Duration::from_millis(10);
        // Three failures (a hang, two errors), within the four tries.
        let recovered = base_level_data_waiting(&flaky(3), 64, timeout);
        assert!(
            recovered == clean,
            "the retried base level is the clean one"
        );
        let broken = base_level_data_waiting(&flaky(u32::MAX), 64, timeout);
        assert_eq!(broken.len(), clean.len());
        assert!(
            broken[..64 * 64 * 4].iter().all(|&b| b == 0),
            "holes, transparent"
        );
    }

    #[test]
    fn subtiles_larger_than_the_sources_tiles_are_clamped_to_them() {
        let source = Arc::new(ProceduralTileSource::new(64, 4, |_, _, _| [0, 0, 0, 255]));
        let mut images = Assets::<Image>::default();
        let clip = ClipStackTexture::new(source, 256, 128, 16, [0.5, 0.5], &mut images);
        assert_eq!(clip.stack.subtile_size, 64);
        assert_eq!(clip.stack.clip_size % clip.stack.subtile_size, 0);
    }
}
