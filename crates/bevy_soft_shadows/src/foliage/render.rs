//! The trees' opacity shadow map in the render world: thin code around `opacity_caster.wgsl`
//! (what casters call to draw), `opacity_map.wgsl` (resolve and mips) and
//! `opacity_receiver.wgsl` (the receivers' lookup).
//!
//! Once a frame, before any camera renders, in the `RenderGraph` schedule:
//! [`TreeOpacityPass::Clear`] zeroes the accumulation buffer; casters draw in
//! [`TreeOpacityPass::Draw`] (compute passes binding [`TreeOpacityTargets::caster_bind_group`]
//! at group 1, [`caster_layout`]); [`TreeOpacityPass::Resolve`] writes the map's level 0 and its
//! mips.

use super::receiver::{TreeOpacityFrame, TreeOpacityImages, receiver_bytes};
use crate::filterable::render::{DirectionalSlotLight, directional_slot};
use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::core_pipeline::schedule::camera_driver;
use bevy::pbr::ExtractedDirectionalLight;
use bevy::prelude::*;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::binding_types::{
    storage_buffer_read_only_sized, storage_buffer_sized, texture_2d, texture_storage_2d,
    uniform_buffer_sized,
};
use bevy::render::render_resource::*;
use bevy::render::renderer::{
    RenderContext, RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue,
};
use bevy::render::storage::GpuShaderBuffer;
use bevy::render::sync_world::RenderEntity;
use bevy::render::texture::GpuImage;
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems};

/// The order of the map's work in the `RenderGraph` schedule, before the cameras render.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TreeOpacityPass {
    /// The accumulation buffer is zeroed.
    Clear,
    /// Casters draw (after their own culling or pruning passes).
    Draw,
    /// Level 0 and the mips are written.
    Resolve,
}

/// The layout casters bind at group 1: the accumulation buffer (two words a texel, read-write)
/// and the plane (`OpacityPlane` of `opacity_caster.wgsl`).
pub fn caster_layout() -> BindGroupLayoutDescriptor {
    BindGroupLayoutDescriptor::new(
        "tree_opacity_caster_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                storage_buffer_sized(false, None),
                uniform_buffer_sized(false, None),
            ),
        ),
    )
}

/// Size of `OpacityPlane` in `opacity_caster.wgsl`.
const PLANE_BYTES: u64 = 48;

/// This frame's map for the casters (render world).
#[derive(Resource, Default)]
pub struct TreeOpacityTargets {
    /// What casters bind at group 1 ([`caster_layout`]); `None` while there is no map.
    pub caster_bind_group: Option<BindGroup>,
    /// The map's side in texels (0 while there is no map).
    pub resolution: u32,
    texels: Option<Buffer>,
    plane: Option<Buffer>,
    /// Dispatches of the resolve: mip 0, then one per coarser level.
    steps: Vec<(bool, BindGroup, UVec2)>,
}

#[derive(Resource)]
struct TreeOpacityPipelines {
    layout: BindGroupLayoutDescriptor,
    resolve: CachedComputePipelineId,
    downsample: CachedComputePipelineId,
}

#[derive(Resource, Default)]
struct ExtractedTreeOpacity {
    frame: Option<(Entity, super::receiver::TreeOpacityLight)>,
    map: AssetId<Image>,
    receiver: AssetId<bevy::render::storage::ShaderBuffer>,
}

fn init_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
) {
    let layout = BindGroupLayoutDescriptor::new(
        "tree_opacity_map_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                storage_buffer_read_only_sized(false, None),
                uniform_buffer_sized(false, None),
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_storage_2d(TextureFormat::Rgba16Float, StorageTextureAccess::WriteOnly),
            ),
        ),
    );
    let shader = load_embedded_asset!(asset_server.as_ref(), "opacity_map.wgsl");
    let queue = |entry: &'static str| {
        pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some(format!("tree_opacity_{entry}").into()),
            layout: vec![layout.clone()],
            shader: shader.clone(),
            entry_point: Some(entry.into()),
            ..default()
        })
    };
    let resolve = queue("resolve");
    let downsample = queue("downsample");
    commands.insert_resource(TreeOpacityPipelines {
        layout,
        resolve,
        downsample,
    });
}

fn extract_tree_opacity(
    mut extracted: ResMut<ExtractedTreeOpacity>,
    frame: Extract<Res<TreeOpacityFrame>>,
    images: Extract<Res<TreeOpacityImages>>,
    lights: Extract<Query<&RenderEntity>>,
) {
    extracted.frame = frame
        .0
        .and_then(|f| Some((lights.get(f.light).ok()?.id(), f)));
    extracted.map = images.map.id();
    extracted.receiver = images.receiver.id();
}

fn plane_bytes(frame: Option<&super::receiver::TreeOpacityLight>) -> Vec<u8> {
    let mut bytes = vec![0u8; PLANE_BYTES as usize];
    if let Some(f) = frame {
        let p = &f.plane;
        for (i, v) in super::receiver::plane_floats(p).iter().enumerate() {
            bytes[i * 4..i * 4 + 4].copy_from_slice(&v.to_le_bytes());
        }
        for (i, v) in [p.resolution.0, p.resolution.1, 1, 0].iter().enumerate() {
            bytes[32 + i * 4..36 + i * 4].copy_from_slice(&v.to_le_bytes());
        }
    }
    bytes
}

#[allow(clippy::too_many_arguments)]
fn prepare_tree_opacity(
    extracted: Res<ExtractedTreeOpacity>,
    mut targets: ResMut<TreeOpacityTargets>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    images: Res<RenderAssets<GpuImage>>,
    buffers: Res<RenderAssets<GpuShaderBuffer>>,
    pipelines: Option<Res<TreeOpacityPipelines>>,
    pipeline_cache: Res<PipelineCache>,
    lights: Query<(Entity, &ExtractedDirectionalLight)>,
) {
    targets.caster_bind_group = None;
    targets.steps.clear();
    targets.resolution = 0;
    let receiver = buffers.get(extracted.receiver);
    let job = extracted.frame.and_then(|(light, frame)| {
        let image = images.get(extracted.map)?;
        let side = frame.plane.resolution.0;
        // The main world resizes the image from the same settings; a mismatch lasts a frame.
        (image.texture.width() == side && image.texture.height() == side)
            .then_some((light, frame, image))
    });
    let Some((light, frame, image)) = job else {
        if let Some(receiver) = receiver {
            queue.write_buffer(
                &receiver.buffer,
                0,
                &super::receiver::inactive_receiver_bytes(),
            );
        }
        return;
    };
    // Bevy's index of the light among the directional lights the shaders see.
    let slots: Vec<DirectionalSlotLight> = lights
        .iter()
        .map(|(entity, l)| DirectionalSlotLight {
            entity,
            volumetric: l.volumetric,
            shadow_maps_enabled: l.shadow_maps_enabled,
            in_view: true,
            cascades: l.cascade_shadow_config.bounds.len(),
        })
        .collect();
    let Some((light_index, _)) = directional_slot(&slots, light) else {
        return;
    };
    let mips = image.texture.mip_level_count();
    if let Some(receiver) = receiver {
        queue.write_buffer(
            &receiver.buffer,
            0,
            &receiver_bytes(&frame, mips, light_index),
        );
    }
    let side = frame.plane.resolution.0;
    let texel_bytes = side as u64 * side as u64 * 8;
    if targets.texels.as_ref().map(|b| b.size()) != Some(texel_bytes) {
        targets.texels = Some(device.create_buffer(&BufferDescriptor {
            label: Some("tree_opacity_texels"),
            size: texel_bytes,
            usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        }));
    }
    let plane = targets
        .plane
        .get_or_insert_with(|| {
            device.create_buffer(&BufferDescriptor {
                label: Some("tree_opacity_plane"),
                size: PLANE_BYTES,
                usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
        .clone();
    queue.write_buffer(&plane, 0, &plane_bytes(Some(&frame)));
    let Some(texels) = targets.texels.clone() else {
        return;
    };
    targets.caster_bind_group = Some(device.create_bind_group(
        "tree_opacity_caster_group",
        &pipeline_cache.get_bind_group_layout(&caster_layout()),
        &BindGroupEntries::sequential((texels.as_entire_binding(), plane.as_entire_binding())),
    ));
    targets.resolution = side;
    let Some(pipelines) = pipelines else { return };
    let layout = pipeline_cache.get_bind_group_layout(&pipelines.layout);
    let views: Vec<TextureView> = (0..mips)
        .map(|level| {
            image.texture.create_view(&TextureViewDescriptor {
                label: Some("tree_opacity_mip"),
                base_mip_level: level,
                mip_level_count: Some(1),
                ..default()
            })
        })
        .collect();
    // The resolve reads only the buffer (its source slot holds a level it does not write).
    let source_of_resolve = &views[(mips as usize - 1).min(1)];
    for level in 0..mips as usize {
        let source = if level == 0 {
            source_of_resolve
        } else {
            &views[level - 1]
        };
        let group = device.create_bind_group(
            "tree_opacity_map_group",
            &layout,
            &BindGroupEntries::sequential((
                texels.as_entire_binding(),
                plane.as_entire_binding(),
                source,
                &views[level],
            )),
        );
        let size = (side >> level).max(1);
        targets.steps.push((level == 0, group, UVec2::splat(size)));
    }
}

fn clear_tree_opacity(targets: Res<TreeOpacityTargets>, mut ctx: RenderContext) {
    if targets.caster_bind_group.is_none() {
        return;
    }
    if let Some(texels) = &targets.texels {
        ctx.command_encoder().clear_buffer(texels, 0, None);
    }
}

fn resolve_tree_opacity(
    targets: Res<TreeOpacityTargets>,
    pipelines: Option<Res<TreeOpacityPipelines>>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let Some(pipelines) = pipelines else { return };
    let (Some(resolve), Some(downsample)) = (
        pipeline_cache.get_compute_pipeline(pipelines.resolve),
        pipeline_cache.get_compute_pipeline(pipelines.downsample),
    ) else {
        return;
    };
    if targets.steps.is_empty() {
        return;
    }
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let mut pass = ctx
        .command_encoder()
        .begin_compute_pass(&ComputePassDescriptor {
            label: Some("tree_opacity_resolve"),
            timestamp_writes: None,
        });
    // GPU time as `render/tree_opacity_resolve/elapsed_gpu` with `RenderDiagnosticsPlugin`.
    let span = diagnostics.pass_span(&mut pass, "tree_opacity_resolve");
    for (first, group, size) in &targets.steps {
        pass.set_pipeline(if *first { resolve } else { downsample });
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups(size.x.div_ceil(8), size.y.div_ceil(8), 1);
    }
    span.end(&mut pass);
}

/// Registers the render-world side.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "opacity_map.wgsl");
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedTreeOpacity>()
        .init_resource::<TreeOpacityTargets>()
        .add_systems(RenderStartup, init_pipelines)
        .add_systems(ExtractSchedule, extract_tree_opacity)
        .add_systems(
            Render,
            prepare_tree_opacity.in_set(RenderSystems::PrepareBindGroups),
        )
        .configure_sets(
            RenderGraph,
            (
                TreeOpacityPass::Clear,
                TreeOpacityPass::Draw,
                TreeOpacityPass::Resolve,
            )
                .chain()
                .in_set(RenderGraphSystems::Render)
                .before(camera_driver),
        )
        .add_systems(
            RenderGraph,
            (
                clear_tree_opacity.in_set(TreeOpacityPass::Clear),
                resolve_tree_opacity.in_set(TreeOpacityPass::Resolve),
            ),
        );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plane_matches_the_wgsl_struct() {
        assert_eq!(plane_bytes(None), vec![0; PLANE_BYTES as usize]);
        let plane = super::super::opacity_map::OpacityShadowPlane::fit(
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(1.0, 2.0, 1.0),
            Vec3::Y,
            0.0,
            (32, 32),
        )
        .unwrap();
        let bytes = plane_bytes(Some(&super::super::receiver::TreeOpacityLight {
            light: Entity::PLACEHOLDER,
            plane,
            sun_angle: 0.0,
        }));
        let word = |i: usize| u32::from_le_bytes(bytes[i * 4..i * 4 + 4].try_into().unwrap());
        assert_eq!(f32::from_bits(word(1)), 1.0);
        assert_eq!((word(8), word(9), word(10)), (32, 32, 1));
    }
}
