//! The render-world side of SSSS: the dilation of the shadow map (two compute dispatches), the
//! distance map and the two blur passes (fullscreen passes binding Bevy's mesh view group), run
//! as one system in the `Core3d` schedule after the prepass and the shadow passes and before the
//! main pass, where the receivers read the result. GPU time is recorded as the `ssss` span
//! (`render/ssss/elapsed_gpu` with `RenderDiagnosticsPlugin`).

use super::box_sums::{
    BoxSumsPipelines, LineSums, box_sums_ready, encode_line_sums, init_box_sums_pipelines,
    line_sum_textures,
};
pub use super::dilation::SsssDilationFilter;
use super::receiver::{SoftShadowCamera, SsssActive, SsssTextures};
use crate::settings::ScreenSpaceSoftShadows;
use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::core_pipeline::{Core3d, Core3dSystems, FullscreenShader};
use bevy::pbr::{
    GlobalClusterableObjectMeta, GpuLights, LATE_SHADOW_PASS, LightMeta, MeshPipeline,
    MeshPipelineKey, MeshPipelineSystems, MeshViewBindGroup, ViewKeyCache, ViewLightsUniformOffset,
    ViewShadowBindings, per_view_shadow_pass,
};
use bevy::prelude::*;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::binding_types::{
    storage_buffer_read_only_sized, storage_buffer_sized, texture_2d, texture_2d_array,
    texture_storage_2d_array, uniform_buffer,
};
use bevy::render::render_resource::*;
use bevy::render::renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery};
use bevy::render::sync_world::RenderEntity;
use bevy::render::texture::{CachedTexture, GpuImage, TextureCache};
use bevy::render::view::ExtractedView;
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems};
use bevy::shader::ShaderDefVal;

/// The settings as the shaders see them (`ssss_types.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, ShaderType)]
pub struct SsssUniform {
    /// Angular diameter of the light (rad).
    pub light_size: f32,
    /// Blocker search distance (m).
    pub max_occluder_distance: f32,
    /// Kernel reach limits (px).
    pub min_kernel_px: f32,
    /// Kernel reach limits (px).
    pub max_kernel_px: f32,
    /// Depth rejection threshold (fraction of the eye depth).
    pub depth_rejection: f32,
    /// Taps a side per blur pass.
    pub taps_per_side: u32,
    /// Lazy shadowing on (1) or off (0).
    pub lazy_shadowing: u32,
    /// 1 while a light has SSSS.
    pub enabled: u32,
    /// Which kind of light has SSSS: [`LIGHT_KIND_DIRECTIONAL`], [`LIGHT_KIND_SPOT`] or
    /// [`LIGHT_KIND_POINT`].
    pub light_kind: u32,
    /// For a spot or point light, its index in Bevy's clustered light array (a spot's shadow map
    /// is layer `index + spot_light_shadowmap_offset` of the shadow texture array; a point
    /// light's faces are layers `6 · index ..` of the point lights' cube texture).
    pub light_index: u32,
    /// For a spot or point light, the coarse dilation radius `R` (`min_filter::spot_fine_reach`,
    /// `min_filter::coarse_radius_of`).
    pub local_radius: u32,
    /// 1: blur every screen tile; 0: only the active ones ([`super::tiles`]).
    pub all_tiles: u32,
    /// Shadow-map texels a side per texel of the coarse dilated map
    /// ([`min_filter::dilation_block`](super::min_filter::dilation_block)).
    pub dilation_block: u32,
}

/// [`SsssUniform::light_kind`] of a directional light (`ssss_types.wgsl`).
pub const LIGHT_KIND_DIRECTIONAL: u32 = 0;
/// [`SsssUniform::light_kind`] of a spot light (`ssss_types.wgsl`).
pub const LIGHT_KIND_SPOT: u32 = 1;
/// [`SsssUniform::light_kind`] of a point light (`ssss_types.wgsl`).
pub const LIGHT_KIND_POINT: u32 = 2;

impl SsssUniform {
    /// The uniform for (sanitised) settings.
    pub fn new(s: &ScreenSpaceSoftShadows) -> Self {
        Self {
            light_size: s.light_size,
            max_occluder_distance: s.max_occluder_distance,
            min_kernel_px: s.min_kernel_px,
            max_kernel_px: s.max_kernel_px,
            depth_rejection: s.depth_rejection,
            taps_per_side: s.taps_per_side,
            lazy_shadowing: s.lazy_shadowing as u32,
            enabled: 1,
            light_kind: LIGHT_KIND_DIRECTIONAL,
            light_index: 0,
            local_radius: 0,
            all_tiles: (!s.tile_classification) as u32,
            dilation_block: super::min_filter::DILATION_BLOCK as u32,
        }
    }
}

/// Insert into the render world to get copies of one layer of the SSSS light's shadow texture
/// (the directional and spot lights' array, or the point lights' cube faces) and of the coarse
/// dilated map (both R32Float, row-major, rows padded to 256 bytes) in `fine` and `coarse`
/// after the next frame — for tests of the dilation against its CPU reference.
#[derive(Resource, Default, Clone)]
pub struct SsssDilationReadback {
    /// Which layer to copy (0 unless set).
    pub layer: u32,
    /// That layer of the shadow map: buffer and (width, height).
    pub fine: Option<(Buffer, UVec2)>,
    /// That layer of the coarse dilated map: buffer and (width, height).
    pub coarse: Option<(Buffer, UVec2)>,
    /// The form of the min filter that made it: `Direct` or `Segments`.
    pub filter: Option<SsssDilationFilter>,
}

/// Insert into the render world to get, after the next frame, copies of the tile
/// classification's output: the indirect draw arguments of the blur passes (four `u32`: vertex
/// count, active tile count, 0, 0) and the active tile list (`x | y << 16` each, in no particular
/// order; only the first count are valid), with the tile grid — for tests against
/// [`tiles::active_tiles`](super::tiles::active_tiles) and for the active-tile fraction.
#[derive(Resource, Default, Clone)]
pub struct SsssTileReadback {
    /// The draw arguments.
    pub args: Option<Buffer>,
    /// The tile list.
    pub list: Option<Buffer>,
    /// Tiles across and down.
    pub grid: UVec2,
}

/// The classification's buffers, sized to the screen's tile grid.
#[derive(Resource, Default)]
struct SsssTileBuffers {
    grid: UVec2,
    stats: Option<Buffer>,
    row_stats: Option<Buffer>,
    list: Option<Buffer>,
    args: Option<Buffer>,
}

/// The blur's prefix sums for this frame's screen (`box_sums`).
#[derive(Resource, Default)]
struct SsssLineSums(Option<LineSums>);

fn prepare_line_sums(
    device: Res<RenderDevice>,
    extracted: Res<ExtractedSsss>,
    mut cache: ResMut<TextureCache>,
    mut sums: ResMut<SsssLineSums>,
) {
    let size = extracted.textures.size.max(UVec2::ONE);
    sums.0 = Some(line_sum_textures(&device, &mut cache, size));
}

fn prepare_tile_buffers(
    device: Res<RenderDevice>,
    extracted: Res<ExtractedSsss>,
    mut buffers: ResMut<SsssTileBuffers>,
) {
    let size = extracted.textures.size.max(UVec2::ONE);
    let tile = super::tiles::TILE as u32;
    let grid = UVec2::new(size.x.div_ceil(tile), size.y.div_ceil(tile));
    if buffers.grid == grid && buffers.args.is_some() {
        return;
    }
    let tiles = (grid.x * grid.y) as u64;
    let buffer = |label: &'static str, size: u64, usage: BufferUsages| {
        Some(device.create_buffer(&BufferDescriptor {
            label: Some(label),
            size,
            usage: usage | BufferUsages::STORAGE | BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        }))
    };
    *buffers = SsssTileBuffers {
        grid,
        // `TileStats`: eight 4-byte fields.
        stats: buffer("ssss_tile_stats", tiles * 32, BufferUsages::empty()),
        row_stats: buffer("ssss_tile_row_stats", tiles * 32, BufferUsages::empty()),
        list: buffer("ssss_tile_list", tiles * 4, BufferUsages::empty()),
        args: buffer(
            "ssss_tile_draw_args",
            16,
            BufferUsages::INDIRECT | BufferUsages::COPY_DST,
        ),
    };
}

#[derive(Resource, Default)]
struct ExtractedSsss {
    uniform: SsssUniform,
    textures: SsssTextures,
    /// The render-world entity of the spot or point light with SSSS (its clustered index is only
    /// known after Bevy's `prepare_lights`).
    local: Option<Entity>,
    /// The largest coarse dilation radius over the light's shadow maps (for
    /// [`SsssDilationFilter::Auto`]).
    max_radius: usize,
    /// The dilation's block (sizes the coarse map).
    block: usize,
}

/// The light SSSS shades: the first directional light with [`ScreenSpaceSoftShadows`], else the
/// first spot light with it, else the first point light with it (a local light's shadows must be
/// on: without a shadow map there is nothing to soften, and SSSS stays off with a warning).
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn extract_ssss(
    mut extracted: ResMut<ExtractedSsss>,
    directional: Extract<Query<&ScreenSpaceSoftShadows, With<DirectionalLight>>>,
    dilation: Extract<Res<super::dilation::SsssDilationRadius>>,
    spots: Extract<Query<(Entity, &ScreenSpaceSoftShadows, &SpotLight, &RenderEntity)>>,
    points: Extract<Query<(Entity, &ScreenSpaceSoftShadows, &PointLight, &RenderEntity)>>,
    textures: Extract<Res<SsssTextures>>,
    active: Extract<Res<SsssActive>>,
    mut warned: Local<bool>,
) {
    extracted.textures = textures.clone();
    extracted.local = None;
    extracted.uniform = SsssUniform::default();
    extracted.max_radius = 0;
    extracted.block = super::min_filter::DILATION_BLOCK;
    if !active.0 {
        return;
    }
    extracted.max_radius = dilation.radius;
    extracted.block = dilation.block;
    if let Some(settings) = directional.iter().next() {
        let settings = settings.sanitized().0;
        extracted.uniform = SsssUniform {
            dilation_block: dilation.block as u32,
            ..SsssUniform::new(&settings)
        };
        return;
    }
    let spot = spots
        .iter()
        .next()
        .map(|(entity, settings, spot, render_entity)| {
            (
                entity,
                settings,
                spot.shadow_maps_enabled,
                render_entity,
                LIGHT_KIND_SPOT,
            )
        });
    let point = || {
        points
            .iter()
            .next()
            .map(|(entity, settings, point, render_entity)| {
                (
                    entity,
                    settings,
                    point.shadow_maps_enabled,
                    render_entity,
                    LIGHT_KIND_POINT,
                )
            })
    };
    let Some((entity, settings, shadows, render_entity, kind)) = spot.or_else(point) else {
        return;
    };
    if !shadows {
        if !*warned {
            let what = if kind == LIGHT_KIND_SPOT {
                "spot"
            } else {
                "point"
            };
            warn!(
                "ScreenSpaceSoftShadows on {what} light {entity}: its shadow maps are off \
                 (shadow_maps_enabled = false), so SSSS is off too"
            );
            *warned = true;
        }
        return;
    }
    *warned = false;
    let settings = settings.sanitized().0;
    extracted.local = Some(render_entity.id());
    extracted.uniform = SsssUniform {
        light_kind: kind,
        local_radius: extracted.max_radius as u32,
        dilation_block: extracted.block as u32,
        ..SsssUniform::new(&settings)
    };
}

#[derive(Resource, Default)]
struct SsssUniformBuffer(UniformBuffer<SsssUniform>);

fn prepare_uniform(
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut extracted: ResMut<ExtractedSsss>,
    clustered: Res<GlobalClusterableObjectMeta>,
    mut buffer: ResMut<SsssUniformBuffer>,
) {
    // A local light's place in the clustered light array (Bevy sorts it every frame).
    if let Some(light) = extracted.local {
        match clustered.entity_to_index.get(&light) {
            Some(&index) => extracted.uniform.light_index = index as u32,
            None => extracted.uniform.enabled = 0,
        }
    }
    buffer.0.set(extracted.uniform);
    buffer.0.write_buffer(&device, &queue);
}

/// With no light left with SSSS its passes stop (the camera loses its prepasses, receivers get
/// their standard materials back), but materials that keep reading the visibility texture (the
/// terrain and leaf receivers bind it themselves) must then see "inactive" (−1) rather than the
/// last soft shadow: the texture is cleared to −1 once, when SSSS goes off.
fn clear_visibility_when_off(
    extracted: Res<ExtractedSsss>,
    images: Res<RenderAssets<GpuImage>>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut cleared: Local<bool>,
) {
    if extracted.uniform.enabled != 0 {
        *cleared = false;
        return;
    }
    if *cleared {
        return;
    }
    // Before SSSS first ran the handle is Bevy's default image: nothing to clear.
    let Some(image) = images
        .get(&extracted.textures.visibility)
        .filter(|i| i.texture.usage().contains(TextureUsages::RENDER_ATTACHMENT))
    else {
        return;
    };
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor {
        label: Some("ssss_clear_visibility"),
    });
    encoder.begin_render_pass(&RenderPassDescriptor {
        label: Some("ssss_clear_visibility"),
        color_attachments: &[Some(RenderPassColorAttachment {
            view: &image.texture_view,
            depth_slice: None,
            resolve_target: None,
            ops: Operations {
                load: LoadOp::Clear(LinearRgba::new(-1.0, -1.0, 0.0, 1.0).into()),
                store: StoreOp::Store,
            },
        })],
        ..default()
    });
    queue.submit([encoder.finish()]);
    *cleared = true;
}

/// Which fullscreen pass a pipeline runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum SsssPass {
    Distance,
    Refine,
    BlurHorizontal,
    BlurVertical,
}

#[derive(Resource)]
struct SsssPipelines {
    mesh_pipeline: MeshPipeline,
    fullscreen: FullscreenShader,
    shader: Handle<Shader>,
    screen_layout: BindGroupLayoutDescriptor,
    dilate_layout: BindGroupLayoutDescriptor,
    dilate_reduce: CachedComputePipelineId,
    /// Scan and combine along rows, then along columns (`min_filter.wgsl`).
    dilate_passes: [CachedComputePipelineId; 4],
    /// The direct filter along rows, then columns.
    dilate_direct: [CachedComputePipelineId; 2],
    copy_shadow: CachedComputePipelineId,
    tiles_layout: BindGroupLayoutDescriptor,
    /// Tile statistics, their spread along rows, then the active tile list (`tiles.wgsl`).
    tile_reduce: CachedComputePipelineId,
    tile_spread: CachedComputePipelineId,
    tile_classify: CachedComputePipelineId,
}

fn init_pipelines(
    mut commands: Commands,
    mesh_pipeline: Res<MeshPipeline>,
    fullscreen: Res<FullscreenShader>,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
) {
    let unfiltered = TextureSampleType::Float { filterable: false };
    let dilate_layout = BindGroupLayoutDescriptor::new(
        "ssss_dilate_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                texture_2d_array(TextureSampleType::Depth),
                texture_2d_array(unfiltered),
                texture_storage_2d_array(TextureFormat::R32Float, StorageTextureAccess::WriteOnly),
                uniform_buffer::<GpuLights>(true),
                uniform_buffer::<SsssUniform>(false),
                texture_storage_2d_array(TextureFormat::Rg32Float, StorageTextureAccess::WriteOnly),
            ),
        ),
    );
    let screen_layout = BindGroupLayoutDescriptor::new(
        "ssss_screen_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::FRAGMENT,
            (
                texture_2d_array(unfiltered),
                uniform_buffer::<SsssUniform>(false),
                // The tile quads' vertex stage reads the screen size from it.
                texture_2d(unfiltered).visibility(ShaderStages::VERTEX_FRAGMENT),
                texture_2d(unfiltered),
                storage_buffer_read_only_sized(false, None).visibility(ShaderStages::VERTEX),
                texture_2d(TextureSampleType::Uint),
                texture_2d_array(TextureSampleType::Depth),
            ),
        ),
    );
    let tiles_layout = BindGroupLayoutDescriptor::new(
        "ssss_tiles_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                texture_2d(unfiltered),
                uniform_buffer::<SsssUniform>(false),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
            ),
        ),
    );
    let tiles_shader = load_embedded_asset!(asset_server.as_ref(), "tiles.wgsl");
    let tile_pipeline = |entry: &'static str| {
        pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some(format!("ssss_tiles_{entry}").into()),
            layout: vec![tiles_layout.clone()],
            shader: tiles_shader.clone(),
            entry_point: Some(entry.into()),
            ..default()
        })
    };
    let tile_reduce = tile_pipeline("reduce");
    let tile_spread = tile_pipeline("spread");
    let tile_classify = tile_pipeline("classify");
    let dilate_shader = load_embedded_asset!(asset_server.as_ref(), "min_filter.wgsl");
    let queue = |entry: &'static str| {
        pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some(format!("ssss_dilate_{entry}").into()),
            layout: vec![dilate_layout.clone()],
            shader: dilate_shader.clone(),
            entry_point: Some(entry.into()),
            ..default()
        })
    };
    let dilate_reduce = queue("reduce");
    let dilate_passes = [
        queue("scan_horizontal"),
        queue("combine_horizontal"),
        queue("scan_vertical"),
        queue("combine_vertical"),
    ];
    let dilate_direct = [queue("direct_horizontal"), queue("direct_vertical")];
    let copy_shadow = queue("copy_shadow");
    commands.insert_resource(SsssPipelines {
        mesh_pipeline: mesh_pipeline.clone(),
        fullscreen: fullscreen.clone(),
        shader: load_embedded_asset!(asset_server.as_ref(), "ssss.wgsl"),
        screen_layout,
        dilate_layout,
        dilate_reduce,
        dilate_passes,
        dilate_direct,
        copy_shadow,
        tiles_layout,
        tile_reduce,
        tile_spread,
        tile_classify,
    });
}

impl SpecializedRenderPipeline for SsssPipelines {
    type Key = (MeshPipelineKey, SsssPass);

    fn specialize(&self, (key, pass): Self::Key) -> RenderPipelineDescriptor {
        // Only the defs that decide which view bindings the shader declares (and their types),
        // plus the shadow filter of the hard shadow: 2×2 hardware PCF, the thesis' hard shadow.
        let mut shader_defs: Vec<ShaderDefVal> = vec![
            "DEPTH_PREPASS".into(),
            "NORMAL_PREPASS".into(),
            "SHADOW_FILTER_METHOD_HARDWARE_2X2".into(),
        ];
        if key.msaa_samples() > 1 {
            shader_defs.push("MULTISAMPLED".into());
        }
        let layout = self.mesh_pipeline.get_view_layout(key.into());
        let target = |format| {
            Some(ColorTargetState {
                format,
                blend: None,
                write_mask: ColorWrites::ALL,
            })
        };
        // The distance pass covers the screen and also writes both blur targets (what a tile
        // the blur skips keeps); the blur passes draw one quad per active tile.
        let tile_quads = VertexState {
            shader: self.shader.clone(),
            shader_defs: shader_defs.clone(),
            entry_point: Some("tile_vertex".into()),
            buffers: vec![],
        };
        let (entry, vertex, targets, label) = match pass {
            SsssPass::Distance => (
                "distance",
                self.fullscreen.to_vertex_state(),
                vec![
                    target(TextureFormat::Rgba32Float),
                    target(TextureFormat::Rg32Float),
                    target(TextureFormat::Rg32Float),
                ],
                "ssss_distance",
            ),
            SsssPass::Refine => (
                "refine",
                tile_quads.clone(),
                vec![target(TextureFormat::Rgba32Float)],
                "ssss_refine",
            ),
            SsssPass::BlurHorizontal => (
                "blur_horizontal",
                tile_quads,
                vec![target(TextureFormat::Rg32Float)],
                "ssss_blur_h",
            ),
            SsssPass::BlurVertical => (
                "blur_vertical",
                tile_quads,
                vec![target(TextureFormat::Rg32Float)],
                "ssss_blur_v",
            ),
        };
        RenderPipelineDescriptor {
            label: Some(label.into()),
            layout: vec![
                layout.main_layout,
                layout.binding_array_layout,
                self.screen_layout.clone(),
            ],
            vertex,
            fragment: Some(FragmentState {
                shader: self.shader.clone(),
                shader_defs,
                entry_point: Some(entry.into()),
                targets,
            }),
            ..default()
        }
    }
}

#[derive(Component)]
struct SsssViewPipelines {
    distance: CachedRenderPipelineId,
    refine: CachedRenderPipelineId,
    blur_horizontal: CachedRenderPipelineId,
    blur_vertical: CachedRenderPipelineId,
}

fn prepare_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    view_key_cache: Res<ViewKeyCache>,
    pipelines: Res<SsssPipelines>,
    mut specialized: ResMut<SpecializedRenderPipelines<SsssPipelines>>,
    views: Query<(Entity, &ExtractedView), With<SoftShadowCamera>>,
) {
    for (entity, view) in &views {
        let Some(key) = view_key_cache.get(&view.retained_view_entity) else {
            continue;
        };
        let mut get = |pass| specialized.specialize(&pipeline_cache, &pipelines, (*key, pass));
        let ids = SsssViewPipelines {
            distance: get(SsssPass::Distance),
            refine: get(SsssPass::Refine),
            blur_horizontal: get(SsssPass::BlurHorizontal),
            blur_vertical: get(SsssPass::BlurVertical),
        };
        commands.entity(entity).insert(ids);
    }
}

/// The coarse dilated shadow map, its horizontal half-step and the segment scans of the
/// filter: one texel per [`DILATION_BLOCK`](super::min_filter::DILATION_BLOCK)² block of the
/// shadow texture array (`scan_sink`, 1×1, takes the unused scan output of the combine passes).
#[derive(Component)]
struct SsssDilation {
    rows: CachedTexture,
    dilated: CachedTexture,
    scan: CachedTexture,
    scan_sink: CachedTexture,
    size: Extent3d,
}

fn prepare_dilation(
    mut commands: Commands,
    device: Res<RenderDevice>,
    mut cache: ResMut<TextureCache>,
    extracted: Res<ExtractedSsss>,
    views: Query<(Entity, &ViewShadowBindings), With<SoftShadowCamera>>,
) {
    for (entity, shadows) in &views {
        let texture = shadow_source(&extracted, shadows);
        let block = extracted.block.max(1) as u32;
        let size = Extent3d {
            width: texture.width().div_ceil(block),
            height: texture.height().div_ceil(block),
            depth_or_array_layers: texture.depth_or_array_layers(),
        };
        let mut get = |label: &'static str, size: Extent3d, format: TextureFormat| {
            cache.get(
                &device,
                TextureDescriptor {
                    label: Some(label),
                    size,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: TextureDimension::D2,
                    format,
                    usage: TextureUsages::STORAGE_BINDING
                        | TextureUsages::TEXTURE_BINDING
                        | TextureUsages::COPY_SRC,
                    view_formats: &[],
                },
            )
        };
        let rows = get("ssss_dilation_rows", size, TextureFormat::R32Float);
        let dilated = get("ssss_dilated_shadow_map", size, TextureFormat::R32Float);
        let scan = get("ssss_dilation_scan", size, TextureFormat::Rg32Float);
        let one = Extent3d {
            width: 1,
            height: 1,
            depth_or_array_layers: 1,
        };
        let scan_sink = get("ssss_dilation_scan_sink", one, TextureFormat::Rg32Float);
        commands.entity(entity).insert(SsssDilation {
            rows,
            dilated,
            scan,
            scan_sink,
            size,
        });
    }
}

/// The shadow texture the SSSS light's maps are in: the point lights' cube texture for a point
/// light, else the directional and spot lights' array.
fn shadow_source<'a>(extracted: &ExtractedSsss, shadows: &'a ViewShadowBindings) -> &'a Texture {
    if extracted.uniform.light_kind == LIGHT_KIND_POINT {
        &shadows.point_light_depth_texture
    } else {
        &shadows.directional_light_depth_texture
    }
}

fn array_view(texture: &Texture) -> TextureView {
    texture.create_view(&TextureViewDescriptor {
        dimension: Some(TextureViewDimension::D2Array),
        ..default()
    })
}

#[allow(clippy::too_many_arguments)]
fn ssss(
    view: ViewQuery<
        (
            &MeshViewBindGroup,
            &ViewShadowBindings,
            &ViewLightsUniformOffset,
            &SsssViewPipelines,
            &SsssDilation,
        ),
        With<SoftShadowCamera>,
    >,
    pipelines: Res<SsssPipelines>,
    pipeline_cache: Res<PipelineCache>,
    extracted: Res<ExtractedSsss>,
    uniform: Res<SsssUniformBuffer>,
    light_meta: Res<LightMeta>,
    images: Res<RenderAssets<GpuImage>>,
    readback: Option<ResMut<SsssDilationReadback>>,
    tile_readback: Option<ResMut<SsssTileReadback>>,
    tile_buffers: Res<SsssTileBuffers>,
    filter: Option<Res<SsssDilationFilter>>,
    box_sums: Res<BoxSumsPipelines>,
    line_sums: Res<SsssLineSums>,
    mut ctx: RenderContext,
) {
    let (mesh_view, shadows, lights_offset, ids, dilation) = view.into_inner();
    let direct = !filter
        .map_or(SsssDilationFilter::Auto, |f| *f)
        .uses_segments(extracted.max_radius);
    let (Some(direct_h), Some(direct_v)) = (
        pipeline_cache.get_compute_pipeline(pipelines.dilate_direct[0]),
        pipeline_cache.get_compute_pipeline(pipelines.dilate_direct[1]),
    ) else {
        return;
    };
    let (
        Some(dilate_reduce),
        Some(scan_h),
        Some(combine_h),
        Some(scan_v),
        Some(combine_v),
        Some(distance_pipeline),
        Some(refine_pipeline),
        Some(blur_h_pipeline),
        Some(blur_v_pipeline),
        Some(uniform_binding),
        Some(lights_binding),
        Some(distance),
        Some(refined),
        Some(horizontal),
        Some(visibility),
        Some(tile_reduce),
        Some(tile_spread),
        Some(tile_classify),
        Some(tile_stats),
        Some(tile_row_stats),
        Some(tile_list),
        Some(tile_args),
        Some(sums),
        true,
    ) = (
        pipeline_cache.get_compute_pipeline(pipelines.dilate_reduce),
        pipeline_cache.get_compute_pipeline(pipelines.dilate_passes[0]),
        pipeline_cache.get_compute_pipeline(pipelines.dilate_passes[1]),
        pipeline_cache.get_compute_pipeline(pipelines.dilate_passes[2]),
        pipeline_cache.get_compute_pipeline(pipelines.dilate_passes[3]),
        pipeline_cache.get_render_pipeline(ids.distance),
        pipeline_cache.get_render_pipeline(ids.refine),
        pipeline_cache.get_render_pipeline(ids.blur_horizontal),
        pipeline_cache.get_render_pipeline(ids.blur_vertical),
        uniform.0.binding(),
        light_meta.view_gpu_lights.binding(),
        images.get(&extracted.textures.distance),
        images.get(&extracted.textures.refined),
        images.get(&extracted.textures.horizontal),
        images.get(&extracted.textures.visibility),
        pipeline_cache.get_compute_pipeline(pipelines.tile_reduce),
        pipeline_cache.get_compute_pipeline(pipelines.tile_spread),
        pipeline_cache.get_compute_pipeline(pipelines.tile_classify),
        tile_buffers.stats.as_ref(),
        tile_buffers.row_stats.as_ref(),
        tile_buffers.list.as_ref(),
        tile_buffers.args.as_ref(),
        line_sums.0.as_ref(),
        box_sums_ready(&box_sums, &pipeline_cache),
    )
    else {
        return;
    };
    let device = ctx.render_device().clone();
    // A point light's cube faces as a 2D array: the dilation and the refined search read single
    // texels, which a cube view does not allow.
    let point_faces = array_view(&shadows.point_light_depth_texture);
    let source = shadow_source(&extracted, shadows);
    let source_view = array_view(source);
    let rows_view = array_view(&dilation.rows.texture);
    let dilated_view = array_view(&dilation.dilated.texture);
    let scan_view = array_view(&dilation.scan.texture);
    let sink_view = array_view(&dilation.scan_sink.texture);
    let dilate_layout = pipeline_cache.get_bind_group_layout(&pipelines.dilate_layout);
    let dilate_group = |input: &TextureView, output: &TextureView, scan: &TextureView| {
        device.create_bind_group(
            "ssss_dilate",
            &dilate_layout,
            &BindGroupEntries::sequential((
                &source_view,
                input,
                output,
                lights_binding.clone(),
                uniform_binding.clone(),
                scan,
            )),
        )
    };
    // reduce: shadow map → dilated (blocks); rows: dilated → scan → rows; columns: rows →
    // scan → dilated. (Inputs and outputs a pass does not use are bound to textures it does
    // not otherwise touch.)
    let reduce_group = dilate_group(&rows_view, &dilated_view, &scan_view);
    let steps = if direct {
        vec![
            (
                direct_h,
                dilate_group(&dilated_view, &rows_view, &scan_view),
            ),
            (
                direct_v,
                dilate_group(&rows_view, &dilated_view, &scan_view),
            ),
        ]
    } else {
        vec![
            (scan_h, dilate_group(&dilated_view, &rows_view, &scan_view)),
            (combine_h, dilate_group(&scan_view, &rows_view, &sink_view)),
            (scan_v, dilate_group(&rows_view, &dilated_view, &scan_view)),
            (
                combine_v,
                dilate_group(&scan_view, &dilated_view, &sink_view),
            ),
        ]
    };
    let screen_layout = pipeline_cache.get_bind_group_layout(&pipelines.screen_layout);
    let screen_group = |distances: &TextureView, blur_in: &TextureView, sums: &TextureView| {
        device.create_bind_group(
            "ssss_screen",
            &screen_layout,
            &BindGroupEntries::sequential((
                &dilated_view,
                uniform_binding.clone(),
                distances,
                blur_in,
                tile_list.as_entire_binding(),
                sums,
                &point_faces,
            )),
        )
    };
    // The distance pass may not sample its own targets: it binds a 1×1 texture there (unused
    // by its shader).
    let unused = dilation
        .scan_sink
        .texture
        .create_view(&TextureViewDescriptor {
            dimension: Some(TextureViewDimension::D2),
            ..default()
        });
    let distance_group = screen_group(&unused, &unused, &sums.rows.default_view);
    // The refine pass reads the screen size from the distance map (its tile quads).
    let refine_group = screen_group(&distance.texture_view, &unused, &sums.rows.default_view);
    // The blurs take each centre's σ from the refined map (valid on the active tiles they
    // draw), the values and depths they blur from the distance map and the horizontal result.
    let blur_h_group = screen_group(
        &refined.texture_view,
        &distance.texture_view,
        &sums.rows.default_view,
    );
    let blur_v_group = screen_group(
        &refined.texture_view,
        &horizontal.texture_view,
        &sums.columns.default_view,
    );
    let tiles_group = device.create_bind_group(
        "ssss_tiles",
        &pipeline_cache.get_bind_group_layout(&pipelines.tiles_layout),
        &BindGroupEntries::sequential((
            &distance.texture_view,
            uniform_binding.clone(),
            tile_stats.as_entire_binding(),
            tile_list.as_entire_binding(),
            tile_args.as_entire_binding(),
            tile_row_stats.as_entire_binding(),
        )),
    );

    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let time_span = diagnostics.time_span(ctx.command_encoder(), "ssss");
    let groups = [
        dilation.size.width.div_ceil(8),
        dilation.size.height.div_ceil(8),
        dilation.size.depth_or_array_layers,
    ];
    // Two compute passes, timed apart: the block reduction reads the whole shadow map; the
    // filter's cost is the separable min filter's. (The scans run one invocation per segment;
    // the grid covers the most segments, at R = 0.)
    let reduce = [(dilate_reduce, reduce_group)];
    for (label, dispatches) in [("ssss_reduce", &reduce[..]), ("ssss_dilate", &steps[..])] {
        let mut pass = ctx
            .command_encoder()
            .begin_compute_pass(&ComputePassDescriptor {
                label: Some(label),
                timestamp_writes: None,
            });
        let span = diagnostics.pass_span(&mut pass, label);
        for (pipeline, group) in dispatches {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, group, &[lights_offset.offset]);
            pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        }
        span.end(&mut pass);
    }
    // The distance pass: every pixel, writing the distance map and, into both blur targets,
    // what a pixel the blur leaves alone keeps.
    let attachment = |view, load| {
        Some(RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: Operations {
                load,
                store: StoreOp::Store,
            },
        })
    };
    {
        let clear = LoadOp::Clear(LinearRgba::NONE.into());
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some("ssss_distance"),
            color_attachments: &[
                attachment(&distance.texture_view, clear),
                attachment(&horizontal.texture_view, clear),
                attachment(&visibility.texture_view, clear),
            ],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        let span = diagnostics.pass_span(&mut pass, "ssss_distance");
        pass.set_render_pipeline(distance_pipeline);
        pass.set_bind_group(0, &mesh_view.main, &mesh_view.main_offsets);
        pass.set_bind_group(1, &mesh_view.binding_array, &[]);
        pass.set_bind_group(2, &distance_group, &[]);
        pass.draw(0..3, 0..1);
        span.end(&mut pass);
    }
    // The classification: tile statistics, then the active tiles appended to the draw
    // arguments' instance count (cleared first).
    ctx.command_encoder().clear_buffer(tile_args, 0, None);
    {
        let grid = tile_buffers.grid;
        let mut pass = ctx
            .command_encoder()
            .begin_compute_pass(&ComputePassDescriptor {
                label: Some("ssss_tiles"),
                timestamp_writes: None,
            });
        let span = diagnostics.pass_span(&mut pass, "ssss_tiles");
        pass.set_bind_group(0, &tiles_group, &[]);
        for pipeline in [tile_reduce, tile_spread, tile_classify] {
            pass.set_pipeline(pipeline);
            pass.dispatch_workgroups((grid.x * grid.y).div_ceil(64), 1, 1);
        }
        span.end(&mut pass);
    }
    // The refined distance map on the active tiles (−1 elsewhere: never read).
    {
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some("ssss_refine"),
            color_attachments: &[attachment(
                &refined.texture_view,
                LoadOp::Clear(LinearRgba::new(-1.0, -1.0, -1.0, -1.0).into()),
            )],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        let span = diagnostics.pass_span(&mut pass, "ssss_refine");
        pass.set_render_pipeline(refine_pipeline);
        pass.set_bind_group(0, &mesh_view.main, &mesh_view.main_offsets);
        pass.set_bind_group(1, &mesh_view.binding_array, &[]);
        pass.set_bind_group(2, &refine_group, &[]);
        pass.draw_indirect(tile_args, 0);
        span.end(&mut pass);
    }
    // The blur passes: one quad per active tile, over what the distance pass wrote, each
    // after the prefix sums of its input along its direction (its spread taps' cell means).
    for (label, pipeline, group, target, source, sums, horizontal) in [
        (
            "ssss_blur_h",
            blur_h_pipeline,
            &blur_h_group,
            horizontal,
            distance,
            &sums.rows,
            true,
        ),
        (
            "ssss_blur_v",
            blur_v_pipeline,
            &blur_v_group,
            visibility,
            horizontal,
            &sums.columns,
            false,
        ),
    ] {
        encode_line_sums(
            ctx.command_encoder(),
            &device,
            &box_sums,
            &pipeline_cache,
            &source.texture_view,
            sums,
            horizontal,
        );
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[attachment(&target.texture_view, LoadOp::Load)],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        let span = diagnostics.pass_span(&mut pass, label);
        pass.set_render_pipeline(pipeline);
        pass.set_bind_group(0, &mesh_view.main, &mesh_view.main_offsets);
        pass.set_bind_group(1, &mesh_view.binding_array, &[]);
        pass.set_bind_group(2, group, &[]);
        pass.draw_indirect(tile_args, 0);
        span.end(&mut pass);
    }
    if let Some(mut tile_readback) = tile_readback {
        let copy = |ctx: &mut RenderContext, source: &Buffer, label: &'static str| {
            let buffer = ctx.render_device().create_buffer(&BufferDescriptor {
                label: Some(label),
                size: source.size(),
                usage: BufferUsages::COPY_SRC | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            ctx.command_encoder()
                .copy_buffer_to_buffer(source, 0, &buffer, 0, source.size());
            buffer
        };
        tile_readback.args = Some(copy(&mut ctx, tile_args, "ssss_tile_args_copy"));
        tile_readback.list = Some(copy(&mut ctx, tile_list, "ssss_tile_list_copy"));
        tile_readback.grid = tile_buffers.grid;
    }
    if let Some(mut readback) = readback {
        readback.filter = Some(if direct {
            SsssDilationFilter::Direct
        } else {
            SsssDilationFilter::Segments
        });
        copy_for_readback(
            &mut ctx,
            &pipelines,
            &pipeline_cache,
            source,
            &dilation.dilated.texture,
            |fine_view| dilate_group(&rows_view, fine_view, &scan_view),
            lights_offset.offset,
            &mut readback,
        );
    }
    time_span.end(ctx.command_encoder());
}

/// Copies one layer of a texture into a new mappable-by-copy buffer.
fn copy_layer(
    ctx: &mut RenderContext,
    texture: &Texture,
    layer: u32,
    label: &'static str,
) -> (Buffer, UVec2) {
    let (w, h) = (texture.width(), texture.height());
    let stride = (w * 4).div_ceil(256) * 256;
    let buffer = ctx.render_device().create_buffer(&BufferDescriptor {
        label: Some(label),
        size: (stride * h) as u64,
        usage: BufferUsages::COPY_SRC | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    ctx.command_encoder().copy_texture_to_buffer(
        TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: Origin3d {
                x: 0,
                y: 0,
                z: layer.min(texture.depth_or_array_layers() - 1),
            },
            aspect: TextureAspect::All,
        },
        TexelCopyBufferInfo {
            buffer: &buffer,
            layout: TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(stride),
                rows_per_image: Some(h),
            },
        },
        Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
    (buffer, UVec2::new(w, h))
}

#[allow(clippy::too_many_arguments)]
fn copy_for_readback(
    ctx: &mut RenderContext,
    pipelines: &SsssPipelines,
    pipeline_cache: &PipelineCache,
    shadow: &Texture,
    dilated: &Texture,
    group_for: impl Fn(&TextureView) -> BindGroup,
    lights_offset: u32,
    readback: &mut SsssDilationReadback,
) {
    let Some(copy) = pipeline_cache.get_compute_pipeline(pipelines.copy_shadow) else {
        return;
    };
    let fine = ctx.render_device().create_texture(&TextureDescriptor {
        label: Some("ssss_shadow_copy"),
        size: Extent3d {
            width: shadow.width(),
            height: shadow.height(),
            depth_or_array_layers: shadow.depth_or_array_layers(),
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: TextureDimension::D2,
        format: TextureFormat::R32Float,
        usage: TextureUsages::STORAGE_BINDING | TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let group = group_for(&array_view(&fine));
    {
        let mut pass = ctx
            .command_encoder()
            .begin_compute_pass(&ComputePassDescriptor {
                label: Some("ssss_shadow_copy"),
                timestamp_writes: None,
            });
        pass.set_pipeline(copy);
        pass.set_bind_group(0, &group, &[lights_offset]);
        pass.dispatch_workgroups(
            shadow.width().div_ceil(8),
            shadow.height().div_ceil(8),
            shadow.depth_or_array_layers(),
        );
    }
    let layer = readback.layer;
    readback.fine = Some(copy_layer(ctx, &fine, layer, "ssss_shadow_copy_buffer"));
    readback.coarse = Some(copy_layer(ctx, dilated, layer, "ssss_dilated_copy_buffer"));
}

#[cfg(test)]
mod tests {
    use super::SsssDilationFilter;
    use crate::ssss::min_filter::{
        DILATION_BLOCK, MAX_COARSE_RADIUS, SEGMENT_FILTER_FROM_RADIUS, coarse_radius_of,
        dilation_block, spot_fine_reach,
    };

    #[test]
    fn auto_picks_the_filter_by_radius() {
        let auto = SsssDilationFilter::Auto;
        assert!(!auto.uses_segments(SEGMENT_FILTER_FROM_RADIUS - 1));
        assert!(auto.uses_segments(SEGMENT_FILTER_FROM_RADIUS));
        assert!(SsssDilationFilter::Segments.uses_segments(0));
        assert!(!SsssDilationFilter::Direct.uses_segments(16));
        // The soft_shadows example's medium lamp (0.70 m, Δ 3.5 m, outer 0.75 rad, 2048²)
        // has R = 14: Auto runs the segments there.
        let reach = spot_fine_reach(0.70, 3.5, 0.75f32.tan(), 2048.0);
        assert_eq!(dilation_block(reach), DILATION_BLOCK);
        let r = coarse_radius_of(reach, DILATION_BLOCK);
        assert_eq!(r, 14);
        assert!(auto.uses_segments(r));
        const { assert!(MAX_COARSE_RADIUS >= SEGMENT_FILTER_FROM_RADIUS) };
    }
}

/// Registers the render-world side.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "ssss_types.wgsl");
    embedded_asset!(app, "min_filter.wgsl");
    embedded_asset!(app, "ssss.wgsl");
    embedded_asset!(app, "tiles.wgsl");
    embedded_asset!(app, "box_sums.wgsl");
    app.add_plugins(bevy::render::extract_component::ExtractComponentPlugin::<
        SoftShadowCamera,
    >::default())
        .add_plugins(bevy::render::extract_resource::ExtractResourcePlugin::<
            SsssDilationFilter,
        >::default())
        .init_resource::<SsssDilationFilter>()
        .register_type::<SsssDilationFilter>();
    embedded_asset!(app, "receiver_functions.wgsl");
    // The shared WGSL modules are imported by path: keep them loaded so the imports resolve.
    let types: Handle<Shader> = load_embedded_asset!(app, "ssss_types.wgsl");
    let receiver: Handle<Shader> = load_embedded_asset!(app, "receiver_functions.wgsl");
    app.insert_resource(SsssTypesShader(types, receiver));
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedSsss>()
        .init_resource::<SsssUniformBuffer>()
        .init_resource::<SsssTileBuffers>()
        .init_resource::<SsssLineSums>()
        .init_resource::<SpecializedRenderPipelines<SsssPipelines>>()
        .add_systems(
            RenderStartup,
            (
                init_pipelines.after(MeshPipelineSystems),
                init_box_sums_pipelines,
            ),
        )
        .add_systems(ExtractSchedule, extract_ssss)
        .add_systems(
            Render,
            (
                prepare_pipelines.in_set(RenderSystems::Prepare),
                (
                    prepare_uniform,
                    prepare_dilation,
                    prepare_tile_buffers,
                    prepare_line_sums,
                    clear_visibility_when_off,
                )
                    .in_set(RenderSystems::PrepareResources),
            ),
        )
        .add_systems(
            Core3d,
            ssss.after(Core3dSystems::Prepass)
                .after(per_view_shadow_pass::<LATE_SHADOW_PASS>)
                .before(Core3dSystems::MainPass),
        );
}

/// Keeps the shared WGSL modules loaded (`bevy_soft_shadows::ssss_types` and
/// `bevy_soft_shadows::receiver_functions`, which other crates' materials may import).
#[derive(Resource)]
#[allow(dead_code)]
struct SsssTypesShader(Handle<Shader>, Handle<Shader>);
