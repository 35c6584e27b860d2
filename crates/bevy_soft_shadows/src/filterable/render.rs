//! The render-world side of filterable shadow maps: after the shadow passes, each layer of
//! Bevy's directional shadow texture is resolved into a texel of statistics per depth, blurred
//! by a separable Gaussian and mip-mapped (`moments.wgsl`; `filter` is the CPU reference), into
//! [`FilteredShadowTextures`] on the view, in the method's [`texel_format`]. Receivers do not
//! read it yet.

use super::filter::{FilterableMethod, gaussian_weights};
use super::settings::FilteredShadowMap;
use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::core_pipeline::{Core3d, Core3dSystems};
use bevy::pbr::{LATE_SHADOW_PASS, ViewShadowBindings, per_view_shadow_pass};
use bevy::prelude::*;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::render_resource::binding_types::{
    texture_2d_array, texture_storage_2d_array, uniform_buffer,
};
use bevy::render::render_resource::*;
use bevy::render::renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery};
use bevy::render::texture::{CachedTexture, TextureCache};
use bevy::render::view::ExtractedView;
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems};

/// The largest Gaussian radius (texels) the passes take: its weights fill
/// [`MomentParams::weights`].
pub const MAX_BLUR_RADIUS: u32 = 31;

/// The passes' parameters (`moments.wgsl`).
#[derive(Clone, Copy, Debug, Default, ShaderType)]
pub struct MomentParams {
    /// x: the method (0 Gaussian CDF, 1 power CDF, 2 variance, 3 exponential, 4 four moments);
    /// y: the Gaussian's radius.
    pub mode: UVec4,
    /// x: the exponential's scale.
    pub scale: Vec4,
    /// The Gaussian's weights by distance from the centre, 0..=radius.
    pub weights: [Vec4; 8],
}

impl MomentParams {
    /// The parameters of `method` blurred by a Gaussian of `sigma` texels.
    pub fn new(method: FilterableMethod, sigma: f32) -> Self {
        let (mode, c) = match method {
            FilterableMethod::GaussianCdf => (0, 0.0),
            FilterableMethod::PowerCdf => (1, 0.0),
            FilterableMethod::Variance => (2, 0.0),
            FilterableMethod::Exponential { c } => (3, c),
            FilterableMethod::Moments4 => (4, 0.0),
        };
        let w = gaussian_weights(sigma);
        let r = (w.len() / 2).min(MAX_BLUR_RADIUS as usize);
        let mut weights = [Vec4::ZERO; 8];
        for k in 0..=r {
            weights[k / 4][k % 4] = w[w.len() / 2 + k];
        }
        Self {
            mode: UVec4::new(mode, r as u32, 0, 0),
            scale: Vec4::new(c, 0.0, 0.0, 0.0),
            weights,
        }
    }
}

/// The texel format holding `method`'s statistics: as few channels as they need — one for ESM,
/// two for VSM and the Gaussian CDF, four for the power CDF's mean and range and for four
/// moments.
pub fn texel_format(method: FilterableMethod) -> TextureFormat {
    match method {
        FilterableMethod::Exponential { .. } => TextureFormat::R32Float,
        FilterableMethod::GaussianCdf | FilterableMethod::Variance => TextureFormat::Rg32Float,
        FilterableMethod::PowerCdf | FilterableMethod::Moments4 => TextureFormat::Rgba32Float,
    }
}

/// The shader def that declares `format` as the passes' destination in `moments.wgsl`.
fn format_def(format: TextureFormat) -> &'static str {
    match format {
        TextureFormat::R32Float => "FORMAT_R32",
        TextureFormat::Rg32Float => "FORMAT_RG32",
        _ => "FORMAT_RGBA32",
    }
}

/// The formats [`texel_format`] uses, in the order of [`MomentPipelines::by_format`].
const FORMATS: [TextureFormat; 3] = [
    TextureFormat::R32Float,
    TextureFormat::Rg32Float,
    TextureFormat::Rgba32Float,
];

/// The filtered shadow map of the first directional light with [`FilteredShadowMap`], as
/// extracted.
#[derive(Resource, Default, Clone, Copy)]
struct ExtractedFilteredShadow(Option<(FilterableMethod, f32)>);

/// A view's filterable shadow map: `raw` the resolved statistics (one layer per layer of Bevy's
/// directional shadow texture), `moments` the blurred map with its mips, in the method's
/// [`texel_format`].
#[derive(Component)]
pub struct FilteredShadowTextures {
    /// The texel format of all three.
    pub format: TextureFormat,
    /// The statistics of each depth, before the blur.
    pub raw: CachedTexture,
    /// The horizontal pass's output.
    pub scratch: CachedTexture,
    /// The blurred map and its mips.
    pub moments: CachedTexture,
    /// One view per mip of `moments`.
    pub mip_views: Vec<TextureView>,
}

/// The passes for one texel format.
struct FormatPipelines {
    layout: BindGroupLayoutDescriptor,
    resolve: CachedComputePipelineId,
    blur_horizontal: CachedComputePipelineId,
    blur_vertical: CachedComputePipelineId,
    downsample: CachedComputePipelineId,
}

#[derive(Resource)]
struct MomentPipelines {
    /// One set per format of [`FORMATS`].
    by_format: Vec<FormatPipelines>,
}

impl MomentPipelines {
    fn of(&self, format: TextureFormat) -> Option<&FormatPipelines> {
        FORMATS
            .iter()
            .position(|f| *f == format)
            .map(|i| &self.by_format[i])
    }
}

#[derive(Resource, Default)]
struct MomentParamsBuffer(UniformBuffer<MomentParams>);

fn init_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
) {
    let shader = load_embedded_asset!(asset_server.as_ref(), "moments.wgsl");
    let by_format = FORMATS
        .iter()
        .map(|&format| {
            let def = format_def(format);
            let layout = BindGroupLayoutDescriptor::new(
                "filtered_shadow_layout",
                &BindGroupLayoutEntries::sequential(
                    ShaderStages::COMPUTE,
                    (
                        texture_2d_array(TextureSampleType::Depth),
                        texture_2d_array(TextureSampleType::Float { filterable: false }),
                        texture_storage_2d_array(format, StorageTextureAccess::WriteOnly),
                        uniform_buffer::<MomentParams>(false),
                    ),
                ),
            );
            let queue = |entry: &'static str| {
                pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
                    label: Some(format!("filtered_shadow_{entry}_{def}").into()),
                    layout: vec![layout.clone()],
                    shader: shader.clone(),
                    shader_defs: vec![def.into()],
                    entry_point: Some(entry.into()),
                    ..default()
                })
            };
            FormatPipelines {
                resolve: queue("resolve"),
                blur_horizontal: queue("blur_horizontal"),
                blur_vertical: queue("blur_vertical"),
                downsample: queue("downsample"),
                layout,
            }
        })
        .collect();
    commands.insert_resource(MomentPipelines { by_format });
}

fn extract_filtered_shadow(
    mut extracted: ResMut<ExtractedFilteredShadow>,
    lights: Extract<Query<(&FilteredShadowMap, &DirectionalLight)>>,
) {
    extracted.0 = lights
        .iter()
        .find(|(_, light)| light.shadow_maps_enabled)
        .map(|(settings, _)| {
            let s = settings.sanitized().0;
            (s.method, s.blur_sigma)
        });
}

#[allow(clippy::too_many_arguments)]
fn prepare_textures(
    mut commands: Commands,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut cache: ResMut<TextureCache>,
    extracted: Res<ExtractedFilteredShadow>,
    mut params: ResMut<MomentParamsBuffer>,
    views: Query<(Entity, &ViewShadowBindings), With<ExtractedView>>,
    holding: Query<Entity, With<FilteredShadowTextures>>,
) {
    let Some((method, sigma)) = extracted.0 else {
        // Only views that still hold a map: nothing is queued while no light asks for one.
        for entity in &holding {
            commands.entity(entity).remove::<FilteredShadowTextures>();
        }
        return;
    };
    let format = texel_format(method);
    params.0.set(MomentParams::new(method, sigma));
    params.0.write_buffer(&device, &queue);
    for (entity, shadows) in &views {
        let source = &shadows.directional_light_depth_texture;
        let size = Extent3d {
            width: source.width(),
            height: source.height(),
            depth_or_array_layers: source.depth_or_array_layers(),
        };
        let mips = size.width.max(size.height).max(1).ilog2() + 1;
        let mut get = |label: &'static str, mip_level_count: u32| {
            cache.get(
                &device,
                TextureDescriptor {
                    label: Some(label),
                    size,
                    mip_level_count,
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
        let raw = get("filtered_shadow_raw", 1);
        let scratch = get("filtered_shadow_scratch", 1);
        let moments = get("filtered_shadow_moments", mips);
        let mip_views = (0..mips)
            .map(|level| {
                moments.texture.create_view(&TextureViewDescriptor {
                    label: Some("filtered_shadow_mip"),
                    dimension: Some(TextureViewDimension::D2Array),
                    base_mip_level: level,
                    mip_level_count: Some(1),
                    ..default()
                })
            })
            .collect();
        commands.entity(entity).insert(FilteredShadowTextures {
            format,
            raw,
            scratch,
            moments,
            mip_views,
        });
    }
}

fn array_view(texture: &Texture) -> TextureView {
    texture.create_view(&TextureViewDescriptor {
        dimension: Some(TextureViewDimension::D2Array),
        ..default()
    })
}

fn filtered_shadow(
    view: ViewQuery<(&ViewShadowBindings, &FilteredShadowTextures)>,
    pipelines: Res<MomentPipelines>,
    pipeline_cache: Res<PipelineCache>,
    params: Res<MomentParamsBuffer>,
    mut ctx: RenderContext,
) {
    let (shadows, textures) = view.into_inner();
    let Some(pipelines) = pipelines.of(textures.format) else {
        return;
    };
    let (Some(resolve), Some(blur_h), Some(blur_v), Some(downsample), Some(binding)) = (
        pipeline_cache.get_compute_pipeline(pipelines.resolve),
        pipeline_cache.get_compute_pipeline(pipelines.blur_horizontal),
        pipeline_cache.get_compute_pipeline(pipelines.blur_vertical),
        pipeline_cache.get_compute_pipeline(pipelines.downsample),
        params.0.binding(),
    ) else {
        return;
    };
    let device = ctx.render_device().clone();
    let layout = pipeline_cache.get_bind_group_layout(&pipelines.layout);
    let depth = array_view(&shadows.directional_light_depth_texture);
    let group = |source: &TextureView, target: &TextureView| {
        device.create_bind_group(
            "filtered_shadow_group",
            &layout,
            &BindGroupEntries::sequential((&depth, source, target, binding.clone())),
        )
    };
    let raw = array_view(&textures.raw.texture);
    let scratch = array_view(&textures.scratch.texture);
    let mut steps = vec![
        // The resolve reads only the depth (its source slot holds a texture it does not write).
        (resolve, group(&scratch, &raw), textures.raw.texture.size()),
        (blur_h, group(&raw, &scratch), textures.raw.texture.size()),
        (
            blur_v,
            group(&scratch, &textures.mip_views[0]),
            textures.raw.texture.size(),
        ),
    ];
    let base = textures.moments.texture.size();
    for level in 1..textures.mip_views.len() {
        let size = base.mip_level_size(level as u32, TextureDimension::D2);
        steps.push((
            downsample,
            group(&textures.mip_views[level - 1], &textures.mip_views[level]),
            size,
        ));
    }
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let mut pass = ctx
        .command_encoder()
        .begin_compute_pass(&ComputePassDescriptor {
            label: Some("filtered_shadow"),
            timestamp_writes: None,
        });
    // GPU time as `render/filtered_shadow/elapsed_gpu` with Bevy's `RenderDiagnosticsPlugin`.
    let span = diagnostics.pass_span(&mut pass, "filtered_shadow");
    for (pipeline, group, size) in &steps {
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups(
            size.width.div_ceil(8),
            size.height.div_ceil(8),
            size.depth_or_array_layers,
        );
    }
    span.end(&mut pass);
}

/// Registers the render-world side.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "moments.wgsl");
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedFilteredShadow>()
        .init_resource::<MomentParamsBuffer>()
        .add_systems(RenderStartup, init_pipelines)
        .add_systems(ExtractSchedule, extract_filtered_shadow)
        .add_systems(
            Render,
            prepare_textures.in_set(RenderSystems::PrepareResources),
        )
        .add_systems(
            Core3d,
            filtered_shadow
                .after(Core3dSystems::Prepass)
                .after(per_view_shadow_pass::<LATE_SHADOW_PASS>)
                .before(Core3dSystems::MainPass),
        );
}
