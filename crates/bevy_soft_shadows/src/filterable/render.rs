//! The render-world side of filterable shadow maps: after the shadow passes, the layers of
//! Bevy's directional and spot shadow texture that hold the served lights' maps (a directional
//! light's cascades, a spot light's one map) are resolved into a texel of statistics per depth,
//! blurred by a separable Gaussian and mip-mapped (`moments.wgsl`; `filter` is the CPU
//! reference), into the maps of [`FilteredShadowImages`](super::receiver::FilteredShadowImages),
//! in each method's [`texel_format`]; the receivers' buffer is told which of the view's
//! directional lights and which of Bevy's clustered lights the maps are for.

use super::filter::{DepthSource, FilterableMethod, MIN_VARIANCE, MOMENT_BIAS, gaussian_weights};
pub use super::receiver::texel_format;
use super::receiver::{FilteredShadowCamera, FilteredShadowImages};
use super::settings::FilteredShadowMap;
use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::camera::visibility::RenderLayers;
use bevy::core_pipeline::{Core3d, Core3dSystems};
use bevy::pbr::{
    ExtractedDirectionalLight, ExtractedPointLight, GlobalClusterableObjectMeta, LATE_SHADOW_PASS,
    MAX_CASCADES_PER_LIGHT, MAX_DIRECTIONAL_LIGHTS, ViewShadowBindings, per_view_shadow_pass,
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
    /// y: the Gaussian's radius; z: the light's first layer in Bevy's directional shadow texture;
    /// w: the [`DepthSource`] (0 a cascade, 1 a spot light's map).
    pub mode: UVec4,
    /// x: the exponential's scale; y, z: a spot light's near plane and range.
    pub scale: Vec4,
    /// The Gaussian's weights by distance from the centre, 0..=radius.
    pub weights: [Vec4; 8],
}

impl MomentParams {
    /// The parameters of `method` blurred by a Gaussian of `sigma` texels, for the light whose
    /// maps start at layer `base_layer` of Bevy's directional shadow texture and store depths
    /// as `source` says.
    pub fn new(method: FilterableMethod, sigma: f32, base_layer: u32, source: DepthSource) -> Self {
        let (mode, c) = method_code(method);
        let w = gaussian_weights(sigma);
        let r = (w.len() / 2).min(MAX_BLUR_RADIUS as usize);
        let mut weights = [Vec4::ZERO; 8];
        for k in 0..=r {
            weights[k / 4][k % 4] = w[w.len() / 2 + k];
        }
        let (kind, near, range) = match source {
            DepthSource::Cascade => (0, 0.0, 0.0),
            DepthSource::Spot { near, range } => (1, near, range),
        };
        Self {
            mode: UVec4::new(mode, r as u32, base_layer, kind),
            scale: Vec4::new(c, near, range, 0.0),
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

/// A point or spot light as Bevy's `prepare_lights` sorts the clustered lights.
#[derive(Clone, Copy, Debug)]
pub struct ClusteredLight {
    /// Whether it is a spot light.
    pub spot: bool,
    /// `shadow_maps_enabled`.
    pub shadow_maps_enabled: bool,
}

/// Where Bevy 0.19's `prepare_lights` put the shadow map of the spot light at `index` in the
/// clustered lights (`GlobalClusterableObjectMeta::entity_to_index`), given every clustered
/// light and the directional shadow texture's layer count: Bevy sorts point lights before spot
/// lights and shadow-casting ones first, and stacks the spot lights' maps after the directional
/// cascades, so the layer is `layers − shadowed spots + (index − point lights)`. `None` when
/// that light has no map.
pub fn spot_layer(lights: &[ClusteredLight], index: u32, layers: u32) -> Option<u32> {
    let light = lights.get(index as usize)?;
    if !light.spot || !light.shadow_maps_enabled {
        return None;
    }
    let points = lights.iter().filter(|l| !l.spot).count() as u32;
    let shadowed_spots = lights
        .iter()
        .filter(|l| l.spot && l.shadow_maps_enabled)
        .count() as u32;
    let among_spots = index.checked_sub(points)?;
    (among_spots < shadowed_spots && shadowed_spots <= layers)
        .then(|| layers - shadowed_spots + among_spots)
}

/// One served map as the receivers' buffer describes it: the light's index (among the view's
/// directional lights, or Bevy's clustered lights), the method, the mip count, and a spot
/// light's range.
#[derive(Clone, Copy, Debug)]
struct ServedMap {
    light_index: u32,
    method: FilterableMethod,
    mips: u32,
    range: f32,
}

/// The receivers' buffer (`FilteredReceiver` of `filtered_receiver.wgsl`): the directional
/// map's half, then the spot map's; `0xffffffff` for a map not made.
fn receiver_bytes(directional: Option<ServedMap>, spot: Option<ServedMap>) -> Vec<u8> {
    let half = |map: Option<ServedMap>| -> Vec<u8> {
        let Some(map) = map else {
            let mut bytes = vec![0u8; 32];
            bytes[..4].copy_from_slice(&u32::MAX.to_le_bytes());
            return bytes;
        };
        let (code, c) = method_code(map.method);
        [map.light_index, code, map.mips, 0]
            .iter()
            .map(|v| v.to_le_bytes())
            .chain(
                [c, MIN_VARIANCE, MOMENT_BIAS, map.range]
                    .iter()
                    .map(|v| v.to_le_bytes()),
            )
            .flatten()
            .collect()
    };
    [half(directional), half(spot)].concat()
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

/// The filtered shadow maps of the first shadow-casting directional light and the first
/// shadow-casting spot light with [`FilteredShadowMap`], as extracted: their render entities
/// and settings, the maps' images and the receivers' buffer.
#[derive(Resource, Default, Clone)]
struct ExtractedFilteredShadow {
    light: Option<(Entity, FilterableMethod, f32)>,
    spot: Option<(Entity, FilterableMethod, f32)>,
    moments: AssetId<Image>,
    spot_moments: AssetId<Image>,
    receiver: AssetId<ShaderBuffer>,
}

/// The scene view's filterable shadow maps: the directional light's and the spot light's, each
/// where one is made this frame.
#[derive(Component)]
pub struct FilteredShadowViewMaps {
    /// The directional light's map (one layer per cascade).
    pub directional: Option<FilteredShadowTextures>,
    /// The spot light's map (one layer).
    pub spot: Option<FilteredShadowTextures>,
}

/// One filterable shadow map: `raw` the resolved statistics, `moments` the blurred map with its
/// mips, in the method's [`texel_format`].
pub struct FilteredShadowTextures {
    /// The texel format of all three.
    pub format: TextureFormat,
    /// The light's first layer in Bevy's directional shadow texture.
    pub base_layer: u32,
    /// The statistics of each depth, before the blur.
    pub raw: CachedTexture,
    /// The horizontal pass's output.
    pub scratch: CachedTexture,
    /// The blurred map and its mips (the texture of `FilteredShadowImages::moments` or
    /// `spot_moments`).
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

/// The passes' parameters of the directional map and of the spot map.
#[derive(Resource, Default)]
struct MomentParamsBuffers {
    directional: UniformBuffer<MomentParams>,
    spot: UniformBuffer<MomentParams>,
}

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
    spots: Extract<Query<(RenderEntity, &FilteredShadowMap, &SpotLight)>>,
    maps: Extract<Option<Res<FilteredShadowImages>>>,
) {
    let settings = |entity: Entity, settings: &FilteredShadowMap| {
        let s = settings.sanitized().0;
        (entity, s.method, s.blur_sigma)
    };
    extracted.light = lights
        .iter()
        .find(|(_, _, light)| light.shadow_maps_enabled)
        .map(|(entity, s, _)| settings(entity, s));
    extracted.spot = spots
        .iter()
        .find(|(_, _, spot)| spot.shadow_maps_enabled)
        .map(|(entity, s, _)| settings(entity, s));
    if let Some(maps) = maps.as_ref() {
        extracted.moments = maps.moments.id();
        extracted.spot_moments = maps.spot_moments.id();
        extracted.receiver = maps.receiver.id();
    }
}

/// A map to make this frame: its texture, where its light's depths lie in Bevy's shadow texture
/// and what they are, and the receivers' description of it.
struct MapJob {
    moments: Texture,
    base_layer: u32,
    params: MomentParams,
    served: ServedMap,
}

/// Whether `image` is sized for `layers` layers of Bevy's shadow texture `source` in `method`'s
/// format, the layers lying inside it. A mismatch lasts a frame after a change (the main world
/// sizes the map from the same settings); one that lasts (Bevy clamping the shadow map to the
/// adapter's limit) is reported once.
fn fits(
    image: &GpuImage,
    source: &Texture,
    base_layer: u32,
    layers: u32,
    method: FilterableMethod,
    warned: &mut bool,
) -> bool {
    let texture = &image.texture;
    let want = (
        source.width(),
        source.height(),
        layers,
        texel_format(method),
    );
    let have = (
        texture.width(),
        texture.height(),
        texture.depth_or_array_layers(),
        texture.format(),
    );
    if want == have && base_layer + layers <= source.depth_or_array_layers() {
        return true;
    }
    if !*warned && want.3 == have.3 && texture.width() > source.width() {
        warn!(
            "filtered shadow map: Bevy's directional shadow texture is {}² texels, less than \
             DirectionalLightShadowMap asks for; no filtered map is made",
            source.width()
        );
        *warned = true;
    }
    false
}

#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn prepare_textures(
    mut commands: Commands,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut cache: ResMut<TextureCache>,
    extracted: Res<ExtractedFilteredShadow>,
    mut params: ResMut<MomentParamsBuffers>,
    images: Res<RenderAssets<GpuImage>>,
    buffers: Res<RenderAssets<GpuShaderBuffer>>,
    views: Query<
        (Entity, &ViewShadowBindings, Option<&RenderLayers>),
        (With<ExtractedView>, With<FilteredShadowCamera>),
    >,
    lights: Query<(Entity, &ExtractedDirectionalLight, &RenderLayers)>,
    clustered: Res<GlobalClusterableObjectMeta>,
    point_lights: Query<&ExtractedPointLight>,
    holding: Query<Entity, With<FilteredShadowViewMaps>>,
    mut warned: Local<bool>,
) {
    let view = views.iter().next();
    let directional = extracted.light.and_then(|(light, method, sigma)| {
        let (_, shadows, layers) = view?;
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
        let image = images.get(extracted.moments)?;
        fits(image, source, base_layer, cascades, method, &mut warned).then(|| MapJob {
            moments: image.texture.clone(),
            base_layer,
            params: MomentParams::new(method, sigma, base_layer, DepthSource::Cascade),
            served: ServedMap {
                light_index: index,
                method,
                mips: image.texture.mip_level_count(),
                range: 0.0,
            },
        })
    });
    let spot = extracted.spot.and_then(|(light, method, sigma)| {
        let (_, shadows, _) = view?;
        // Bevy's clustered lights in its order, to find the spot's layer.
        let mut order = vec![
            ClusteredLight {
                spot: false,
                shadow_maps_enabled: false,
            };
            clustered.entity_to_index.len()
        ];
        for (&entity, &index) in &clustered.entity_to_index {
            let l = point_lights.get(entity).ok()?;
            *order.get_mut(index)? = ClusteredLight {
                spot: l.spot_light_angles.is_some(),
                shadow_maps_enabled: l.shadow_maps_enabled,
            };
        }
        let index = *clustered.entity_to_index.get(&light)? as u32;
        let source = &shadows.directional_light_depth_texture;
        let base_layer = spot_layer(&order, index, source.depth_or_array_layers())?;
        let lamp = point_lights.get(light).ok()?;
        let depths = DepthSource::Spot {
            near: lamp.shadow_map_near_z,
            range: lamp.range,
        };
        let image = images.get(extracted.spot_moments)?;
        fits(image, source, base_layer, 1, method, &mut warned).then(|| MapJob {
            moments: image.texture.clone(),
            base_layer,
            params: MomentParams::new(method, sigma, base_layer, depths),
            served: ServedMap {
                light_index: index,
                method,
                mips: image.texture.mip_level_count(),
                range: lamp.range,
            },
        })
    });
    // Views that no longer get a map lose theirs (only those: nothing is queued per frame
    // while no light asks for one).
    let served_view = view
        .filter(|_| directional.is_some() || spot.is_some())
        .map(|v| v.0);
    for entity in &holding {
        if Some(entity) != served_view {
            commands.entity(entity).remove::<FilteredShadowViewMaps>();
        }
    }
    let receiver = receiver_bytes(
        directional.as_ref().map(|job| job.served),
        spot.as_ref().map(|job| job.served),
    );
    if let Some(buffer) = buffers.get(extracted.receiver) {
        queue.write_buffer(&buffer.buffer, 0, &receiver);
    }
    let Some(view) = served_view else {
        return;
    };
    let mut make = |job: MapJob, buffer: &mut UniformBuffer<MomentParams>| {
        buffer.set(job.params);
        buffer.write_buffer(&device, &queue);
        let format = job.moments.format();
        let size = Extent3d {
            width: job.moments.width(),
            height: job.moments.height(),
            depth_or_array_layers: job.moments.depth_or_array_layers(),
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
        let mip_views = (0..job.moments.mip_level_count())
            .map(|level| {
                job.moments.create_view(&TextureViewDescriptor {
                    label: Some("filtered_shadow_mip"),
                    dimension: Some(TextureViewDimension::D2Array),
                    base_mip_level: level,
                    mip_level_count: Some(1),
                    ..default()
                })
            })
            .collect();
        FilteredShadowTextures {
            format,
            base_layer: job.base_layer,
            raw,
            scratch,
            moments: job.moments,
            mip_views,
        }
    };
    let params = &mut *params;
    let maps = FilteredShadowViewMaps {
        directional: directional.map(|job| make(job, &mut params.directional)),
        spot: spot.map(|job| make(job, &mut params.spot)),
    };
    commands.entity(view).insert(maps);
}

fn array_view(texture: &Texture) -> TextureView {
    texture.create_view(&TextureViewDescriptor {
        dimension: Some(TextureViewDimension::D2Array),
        ..default()
    })
}

fn filtered_shadow(
    view: ViewQuery<(&ViewShadowBindings, &FilteredShadowViewMaps)>,
    pipelines: Res<MomentPipelines>,
    pipeline_cache: Res<PipelineCache>,
    params: Res<MomentParamsBuffers>,
    mut ctx: RenderContext,
) {
    let (shadows, maps) = view.into_inner();
    let device = ctx.render_device().clone();
    let depth = array_view(&shadows.directional_light_depth_texture);
    // Each map's dispatches: its pipelines, bind groups and sizes.
    let mut steps = Vec::new();
    for (textures, params) in [
        (&maps.directional, &params.directional),
        (&maps.spot, &params.spot),
    ] {
        let Some(textures) = textures else {
            continue;
        };
        let Some(pipelines) = pipelines.of(textures.format) else {
            continue;
        };
        let (Some(resolve), Some(blur_h), Some(blur_v), Some(downsample), Some(binding)) = (
            pipeline_cache.get_compute_pipeline(pipelines.resolve),
            pipeline_cache.get_compute_pipeline(pipelines.blur_horizontal),
            pipeline_cache.get_compute_pipeline(pipelines.blur_vertical),
            pipeline_cache.get_compute_pipeline(pipelines.downsample),
            params.binding(),
        ) else {
            continue;
        };
        let layout = pipeline_cache.get_bind_group_layout(&pipelines.layout);
        let group = |source: &TextureView, target: &TextureView| {
            device.create_bind_group(
                "filtered_shadow_group",
                &layout,
                &BindGroupEntries::sequential((&depth, source, target, binding.clone())),
            )
        };
        let raw = array_view(&textures.raw.texture);
        let scratch = array_view(&textures.scratch.texture);
        let size = textures.raw.texture.size();
        // The resolve reads only the depth (its source slot holds a texture it does not write).
        steps.push((resolve, group(&scratch, &raw), size));
        steps.push((blur_h, group(&raw, &scratch), size));
        steps.push((blur_v, group(&scratch, &textures.mip_views[0]), size));
        let base = textures.moments.size();
        for level in 1..textures.mip_views.len() {
            steps.push((
                downsample,
                group(&textures.mip_views[level - 1], &textures.mip_views[level]),
                base.mip_level_size(level as u32, TextureDimension::D2),
            ));
        }
    }
    if steps.is_empty() {
        return;
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
        .init_resource::<MomentParamsBuffers>()
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
        let bytes = receiver_bytes(
            Some(ServedMap {
                light_index: 2,
                method: FilterableMethod::Exponential { c: 80.0 },
                mips: 12,
                range: 0.0,
            }),
            None,
        );
        assert_eq!(bytes.len(), 64);
        let word = |i: usize| u32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
        assert_eq!((word(0), word(1), word(2)), (2, 3, 12));
        assert_eq!(f32::from_bits(word(4)), 80.0);
        assert_eq!(f32::from_bits(word(5)), MIN_VARIANCE);
        assert_eq!(f32::from_bits(word(6)), MOMENT_BIAS);
        // No spot map.
        assert_eq!(word(8), u32::MAX);
        let bytes = receiver_bytes(
            None,
            Some(ServedMap {
                light_index: 5,
                method: FilterableMethod::PowerCdf,
                mips: 9,
                range: 30.0,
            }),
        );
        let word = |i: usize| u32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
        assert_eq!(word(0), u32::MAX);
        assert_eq!((word(8), word(9), word(10)), (5, 1, 9));
        assert_eq!(f32::from_bits(word(15)), 30.0);
        assert_eq!(bytes, {
            let mut both = crate::filterable::receiver::inactive_receiver_bytes();
            both[32..].copy_from_slice(&bytes[32..]);
            both
        });
    }

    /// Bevy's clustered order: point lights, then spot lights with shadows, then without; the
    /// spots' maps follow the directional cascades in the shadow texture.
    #[test]
    fn the_spot_layer_follows_bevys_order_of_clustered_lights() {
        let l = |spot, shadow_maps_enabled| ClusteredLight {
            spot,
            shadow_maps_enabled,
        };
        // Two point lights, two shadowed spots, one unshadowed spot; 4 cascades + 2 spot maps.
        let lights = [
            l(false, true),
            l(false, false),
            l(true, true),
            l(true, true),
            l(true, false),
        ];
        assert_eq!(spot_layer(&lights, 2, 6), Some(4));
        assert_eq!(spot_layer(&lights, 3, 6), Some(5));
        assert_eq!(spot_layer(&lights, 4, 6), None);
        assert_eq!(spot_layer(&lights, 0, 6), None);
        assert_eq!(spot_layer(&lights, 9, 6), None);
        // No directional cascades: the spots' maps are the first layers.
        assert_eq!(spot_layer(&[l(true, true)], 0, 1), Some(0));
        // A texture too small to hold them (Bevy's limit reached): no layer.
        assert_eq!(spot_layer(&lights, 3, 1), None);
    }
}
