//! The render-world side of filterable shadow maps: after the shadow passes, each layer of
//! Bevy's directional shadow texture is resolved into a texel of statistics per depth, blurred
//! by a separable Gaussian and mip-mapped (`moments.wgsl`; `filter` is the CPU reference), into
//! the map of [`FilteredShadowImages`](super::receiver::FilteredShadowImages) (its cascades'
//! layers only), in the method's [`texel_format`]; the receivers' buffer is told which of the
//! view's directional lights the map is for.

use super::filter::{FilterableMethod, MIN_VARIANCE, MOMENT_BIAS, gaussian_weights};
pub use super::receiver::texel_format;
use super::receiver::{FilteredShadowCamera, FilteredShadowImages, inactive_receiver_bytes};
use super::settings::FilteredShadowMap;
use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::camera::visibility::RenderLayers;
use bevy::core_pipeline::{Core3d, Core3dSystems};
use bevy::pbr::{
    ExtractedDirectionalLight, LATE_SHADOW_PASS, MAX_CASCADES_PER_LIGHT, MAX_DIRECTIONAL_LIGHTS,
    ViewShadowBindings, per_view_shadow_pass,
};
use bevy::prelude::*;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::binding_types::{
    texture_2d_array, texture_storage_2d_array, uniform_buffer,
};
use bevy::render::render_resource::*;
use bevy::render::renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery};
use bevy::render::storage::{GpuShaderBuffer, ShaderBuffer};
use bevy::render::sync_world::RenderEntity;
use bevy::render::texture::{CachedTexture, GpuImage, TextureCache};
use bevy::render::view::ExtractedView;
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems};

/// The largest Gaussian radius (texels) the passes take: its weights fill
/// [`MomentParams::weights`].
pub const MAX_BLUR_RADIUS: u32 = 31;

/// The passes' parameters (`moments.wgsl`).
#[derive(Clone, Copy, Debug, Default, ShaderType)]
pub struct MomentParams {
    /// x: the method (0 Gaussian CDF, 1 power CDF, 2 variance, 3 exponential, 4 four moments);
    /// y: the Gaussian's radius; z: the light's first layer in Bevy's directional shadow texture.
    pub mode: UVec4,
    /// x: the exponential's scale.
    pub scale: Vec4,
    /// The Gaussian's weights by distance from the centre, 0..=radius.
    pub weights: [Vec4; 8],
}

impl MomentParams {
    /// The parameters of `method` blurred by a Gaussian of `sigma` texels, for the light whose
    /// cascades start at layer `base_layer` of Bevy's directional shadow texture.
    pub fn new(method: FilterableMethod, sigma: f32, base_layer: u32) -> Self {
        let (mode, c) = method_code(method);
        let w = gaussian_weights(sigma);
        let r = (w.len() / 2).min(MAX_BLUR_RADIUS as usize);
        let mut weights = [Vec4::ZERO; 8];
        for k in 0..=r {
            weights[k / 4][k % 4] = w[w.len() / 2 + k];
        }
        Self {
            mode: UVec4::new(mode, r as u32, base_layer, 0),
            scale: Vec4::new(c, 0.0, 0.0, 0.0),
            weights,
        }
    }
}

/// The method's number in the shaders, and the exponential's scale (0 for the others).
fn method_code(method: FilterableMethod) -> (u32, f32) {
    match method {
        FilterableMethod::GaussianCdf => (0, 0.0),
        FilterableMethod::PowerCdf => (1, 0.0),
        FilterableMethod::Variance => (2, 0.0),
        FilterableMethod::Exponential { c } => (3, c),
        FilterableMethod::Moments4 => (4, 0.0),
    }
}

/// A directional light as Bevy's `prepare_lights` sees it for a view.
#[derive(Clone, Copy, Debug)]
pub struct DirectionalSlotLight {
    /// The light's render-world entity (Bevy's tie-break).
    pub entity: Entity,
    /// `DirectionalLight::volumetric`.
    pub volumetric: bool,
    /// `DirectionalLight::shadow_maps_enabled`.
    pub shadow_maps_enabled: bool,
    /// Whether the light's render layers intersect the view's.
    pub in_view: bool,
    /// Its cascades (`CascadeShadowConfig::bounds.len()`).
    pub cascades: usize,
}

/// Where Bevy 0.19's `prepare_lights` (`bevy_pbr/src/render/light.rs`) puts light `ours` for a
/// view: its index among the view's directional lights (what shaders index
/// `lights.directional_lights` with) and its first layer in the directional shadow texture
/// (`depth_texture_base_index`). Bevy sorts the lights by (volumetric, shadows on, entity), keeps
/// those in the view's layers, at most `MAX_DIRECTIONAL_LIGHTS`, and stacks the cascades of the
/// shadow-casting ones in that order. `None` when the view does not draw the light's shadows.
pub fn directional_slot(lights: &[DirectionalSlotLight], ours: Entity) -> Option<(u32, u32)> {
    let mut sorted: Vec<&DirectionalSlotLight> = lights.iter().collect();
    sorted.sort_by_key(|l| (l.volumetric, l.shadow_maps_enabled, l.entity));
    let mut base = 0u32;
    for (index, light) in sorted
        .into_iter()
        .filter(|l| l.in_view)
        .take(MAX_DIRECTIONAL_LIGHTS)
        .enumerate()
    {
        if light.entity == ours {
            return light.shadow_maps_enabled.then_some((index as u32, base));
        }
        if light.shadow_maps_enabled {
            base += light.cascades.min(MAX_CASCADES_PER_LIGHT) as u32;
        }
    }
    None
}

/// The receivers' buffer (`FilteredReceiver` of `filtered_receiver.wgsl`) for the light at
/// `light_index` among the view's directional lights.
fn receiver_bytes(light_index: u32, method: FilterableMethod, mips: u32) -> Vec<u8> {
    let (code, c) = method_code(method);
    [light_index, code, mips, 0]
        .iter()
        .map(|v| v.to_le_bytes())
        .chain(
            [c, MIN_VARIANCE, MOMENT_BIAS, 0.0]
                .iter()
                .map(|v| v.to_le_bytes()),
        )
        .flatten()
        .collect()
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

/// The filtered shadow map of the first shadow-casting directional light with
/// [`FilteredShadowMap`], as extracted: its settings and render entity, the map's image and the
/// receivers' buffer.
#[derive(Resource, Default, Clone)]
struct ExtractedFilteredShadow {
    light: Option<(Entity, FilterableMethod, f32)>,
    moments: AssetId<Image>,
    receiver: AssetId<ShaderBuffer>,
}

/// The scene view's filterable shadow map: `raw` the resolved statistics (one layer per cascade
/// of the light), `moments` the blurred map with its mips, in the method's [`texel_format`].
#[derive(Component)]
pub struct FilteredShadowTextures {
    /// The texel format of all three.
    pub format: TextureFormat,
    /// The light's first layer in Bevy's directional shadow texture.
    pub base_layer: u32,
    /// The statistics of each depth, before the blur.
    pub raw: CachedTexture,
    /// The horizontal pass's output.
    pub scratch: CachedTexture,
    /// The blurred map and its mips (the texture of `FilteredShadowImages::moments`).
    pub moments: Texture,
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
    lights: Extract<Query<(RenderEntity, &FilteredShadowMap, &DirectionalLight)>>,
    maps: Extract<Option<Res<FilteredShadowImages>>>,
) {
    extracted.light = lights
        .iter()
        .find(|(_, _, light)| light.shadow_maps_enabled)
        .map(|(entity, settings, _)| {
            let s = settings.sanitized().0;
            (entity, s.method, s.blur_sigma)
        });
    if let Some(maps) = maps.as_ref() {
        extracted.moments = maps.moments.id();
        extracted.receiver = maps.receiver.id();
    }
}

#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn prepare_textures(
    mut commands: Commands,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut cache: ResMut<TextureCache>,
    extracted: Res<ExtractedFilteredShadow>,
    mut params: ResMut<MomentParamsBuffer>,
    images: Res<RenderAssets<GpuImage>>,
    buffers: Res<RenderAssets<GpuShaderBuffer>>,
    views: Query<
        (Entity, &ViewShadowBindings, Option<&RenderLayers>),
        (With<ExtractedView>, With<FilteredShadowCamera>),
    >,
    lights: Query<(Entity, &ExtractedDirectionalLight, &RenderLayers)>,
    holding: Query<Entity, With<FilteredShadowTextures>>,
    mut warned: Local<bool>,
) {
    let mut receiver = inactive_receiver_bytes();
    let served = extracted.light.and_then(|(light, method, sigma)| {
        let (entity, shadows, layers) = views.iter().next()?;
        let view_layers = layers.cloned().unwrap_or_default();
        let slots: Vec<DirectionalSlotLight> = lights
            .iter()
            .map(|(entity, l, layers)| DirectionalSlotLight {
                entity,
                volumetric: l.volumetric,
                shadow_maps_enabled: l.shadow_maps_enabled,
                in_view: layers.intersects(&view_layers),
                cascades: l.cascade_shadow_config.bounds.len(),
            })
            .collect();
        let (index, base_layer) = directional_slot(&slots, light)?;
        let cascades = lights
            .get(light)
            .ok()?
            .1
            .cascade_shadow_config
            .bounds
            .len()
            .clamp(1, MAX_CASCADES_PER_LIGHT) as u32;
        let source = &shadows.directional_light_depth_texture;
        let format = texel_format(method);
        let image = images.get(extracted.moments)?;
        let want = (source.width(), source.height(), cascades, format);
        let have = (
            image.texture.width(),
            image.texture.height(),
            image.texture.depth_or_array_layers(),
            image.texture.format(),
        );
        if want != have || base_layer + cascades > source.depth_or_array_layers() {
            // The main world sizes the map from the same settings a frame earlier; a lasting
            // mismatch (Bevy clamping the shadow map to the adapter's limit) is reported once.
            if !*warned && want.3 == have.3 && image.texture.width() > source.width() {
                warn!(
                    "filtered shadow map: Bevy's directional shadow texture is {}² texels, less \
                     than DirectionalLightShadowMap asks for; no filtered map is made",
                    source.width()
                );
                *warned = true;
            }
            return None;
        }
        Some((
            entity,
            index,
            base_layer,
            method,
            sigma,
            image.texture.clone(),
        ))
    });
    // Views that no longer get a map lose theirs (only those: nothing is queued per frame
    // while no light asks for one).
    let served_view = served.as_ref().map(|s| s.0);
    for entity in &holding {
        if Some(entity) != served_view {
            commands.entity(entity).remove::<FilteredShadowTextures>();
        }
    }
    if let Some((entity, index, base_layer, method, sigma, moments)) = served {
        let format = moments.format();
        params.0.set(MomentParams::new(method, sigma, base_layer));
        params.0.write_buffer(&device, &queue);
        let size = Extent3d {
            width: moments.width(),
            height: moments.height(),
            depth_or_array_layers: moments.depth_or_array_layers(),
        };
        let mut get = |label: &'static str| {
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
        let raw = get("filtered_shadow_raw");
        let scratch = get("filtered_shadow_scratch");
        let mips = moments.mip_level_count();
        let mip_views = (0..mips)
            .map(|level| {
                moments.create_view(&TextureViewDescriptor {
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
            base_layer,
            raw,
            scratch,
            moments,
            mip_views,
        });
        receiver = receiver_bytes(index, method, mips);
    }
    if let Some(buffer) = buffers.get(extracted.receiver) {
        queue.write_buffer(&buffer.buffer, 0, &receiver);
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
    let base = textures.moments.size();
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

#[cfg(test)]
mod tests {
    use super::*;

    fn light(
        index: u32,
        volumetric: bool,
        shadows: bool,
        in_view: bool,
        cascades: usize,
    ) -> DirectionalSlotLight {
        DirectionalSlotLight {
            entity: Entity::from_raw_u32(index).unwrap(),
            volumetric,
            shadow_maps_enabled: shadows,
            in_view,
            cascades,
        }
    }

    /// Bevy's order: lights without shadows first, then by entity; only the view's lights
    /// count, and only shadow-casting ones take layers (at most four cascades each).
    #[test]
    fn the_slot_follows_bevys_order_of_directional_lights() {
        let lights = [
            light(7, false, true, true, 4),
            light(3, false, true, true, 6),
            light(5, false, false, true, 4),
            light(2, false, true, false, 4),
            light(9, true, true, true, 2),
        ];
        let e = |i| Entity::from_raw_u32(i).unwrap();
        // Sorted in view: 5 (no shadows), then 3 and 7 in `Entity`'s order, then 9
        // (volumetric).
        let (first, second) = if e(3) < e(7) { (3, 7) } else { (7, 3) };
        assert_eq!(directional_slot(&lights, e(5)), None);
        assert_eq!(directional_slot(&lights, e(first)), Some((1, 0)));
        assert_eq!(directional_slot(&lights, e(second)), Some((2, 4)));
        assert_eq!(directional_slot(&lights, e(9)), Some((3, 8)));
        // Out of the view's layers: no slot.
        assert_eq!(directional_slot(&lights, e(2)), None);
        assert_eq!(
            directional_slot(&[light(1, false, true, true, 4)], e(1)),
            Some((0, 0))
        );
    }

    #[test]
    fn the_receivers_buffer_names_light_method_and_mips() {
        let bytes = receiver_bytes(2, FilterableMethod::Exponential { c: 80.0 }, 12);
        assert_eq!(bytes.len(), 32);
        let word = |i: usize| u32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
        assert_eq!((word(0), word(1), word(2)), (2, 3, 12));
        assert_eq!(f32::from_bits(word(4)), 80.0);
        assert_eq!(f32::from_bits(word(5)), MIN_VARIANCE);
        assert_eq!(f32::from_bits(word(6)), MOMENT_BIAS);
    }
}
