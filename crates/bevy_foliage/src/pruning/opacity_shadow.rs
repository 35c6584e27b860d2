//! Pruned leaves drawn into `bevy_soft_shadows`' world-space opacity shadow map of the trees, in
//! the render world: thin code around `opacity_shadow.wgsl` (its CPU reference is
//! [`super::opacity_casting`]).
//!
//! While a sun has `TreeOpacityShadows`, each frame after the pruning pass one compute dispatch
//! draws the shadow selection of every visible pruned tree (one invocation per kept triangle)
//! into the map's accumulation buffer, between the map's clear and its resolve
//! ([`TreeOpacityPass::Draw`]).

use super::components::{ManagedPruning, PrunedFoliage};
use super::material::LeafMaterial;
use super::render::run_pruning;
use super::store::{FoliageSlot, FoliageStore};
use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::prelude::*;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::binding_types::storage_buffer_read_only_sized;
use bevy::render::render_resource::{
    BindGroup, BindGroupEntries, BindGroupLayoutDescriptor, BindGroupLayoutEntries, Buffer,
    BufferDescriptor, BufferUsages, CachedComputePipelineId, ComputePassDescriptor,
    ComputePipelineDescriptor, PipelineCache, ShaderStages,
};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderGraph, RenderQueue};
use bevy::render::storage::{GpuShaderBuffer, ShaderBuffer};
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems};
use bevy_soft_shadows::foliage::render::{TreeOpacityPass, TreeOpacityTargets, caster_layout};

/// Words of one `Caster` of `opacity_shadow.wgsl`.
const CASTER_WORDS: usize = 20;

/// The most trees one frame draws into the map (a dispatch's second dimension).
const MAX_CASTERS: usize = 65_535;

/// One tree to draw this frame.
#[derive(Clone, Copy, Debug)]
struct LeafCaster {
    world_from_local: Mat4,
    /// The tree's camera record; the shader draws its shadow record.
    slot: u32,
    area_compensation: bool,
    max_scale: f32,
    opaque_fraction: f32,
    /// Triangles with every leaf kept (the dispatch's width).
    triangles: u32,
}

impl LeafCaster {
    fn words(&self) -> [u32; CASTER_WORDS] {
        let mut words = [0u32; CASTER_WORDS];
        for (w, v) in words.iter_mut().zip(self.world_from_local.to_cols_array()) {
            *w = v.to_bits();
        }
        words[16] = self.slot;
        words[17] = self.area_compensation as u32;
        words[18] = self.max_scale.to_bits();
        words[19] = self.opaque_fraction.clamp(1e-3, 1.0).sqrt().to_bits();
        words
    }
}

#[derive(Resource, Default)]
struct ExtractedLeafCasters {
    casters: Vec<LeafCaster>,
    instances: Handle<ShaderBuffer>,
    output: Handle<ShaderBuffer>,
    draws: Handle<ShaderBuffer>,
    cell_offsets: Handle<ShaderBuffer>,
    leaf_vertices: Handle<ShaderBuffer>,
}

#[derive(Resource, Default)]
struct LeafCasterFrame {
    buffer: Option<Buffer>,
    bind_group: Option<BindGroup>,
    casters: u32,
    max_triangles: u32,
}

#[derive(Resource)]
struct LeafCasterPipeline {
    layout: BindGroupLayoutDescriptor,
    pipeline: CachedComputePipelineId,
}

fn init_pipeline(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
    targets: Option<Res<TreeOpacityTargets>>,
) {
    // Without `SoftShadowsPlugin` there is no map to draw into (nor the WGSL module to import).
    if targets.is_none() {
        return;
    }
    let read = || storage_buffer_read_only_sized(false, None);
    let layout = BindGroupLayoutDescriptor::new(
        "foliage_opacity_shadow_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (read(), read(), read(), read(), read(), read()),
        ),
    );
    let pipeline = pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
        label: Some("foliage_opacity_shadow".into()),
        layout: vec![layout.clone(), caster_layout()],
        shader: load_embedded_asset!(asset_server.as_ref(), "opacity_shadow.wgsl"),
        entry_point: Some("draw_leaves".into()),
        ..default()
    });
    commands.insert_resource(LeafCasterPipeline { layout, pipeline });
}

#[allow(clippy::type_complexity)]
fn extract_leaf_casters(
    mut extracted: ResMut<ExtractedLeafCasters>,
    active: Extract<Option<Res<bevy_soft_shadows::foliage::receiver::TreeOpacityActive>>>,
    store: Extract<Res<FoliageStore>>,
    materials: Extract<Res<Assets<LeafMaterial>>>,
    trees: Extract<
        Query<
            (
                &FoliageSlot,
                &GlobalTransform,
                &PrunedFoliage,
                &InheritedVisibility,
            ),
            Without<ManagedPruning>,
        >,
    >,
) {
    extracted.casters.clear();
    if !active.as_ref().is_some_and(|a| a.0) {
        return;
    }
    let b = &store.buffers;
    extracted.instances = b.instances.clone();
    extracted.output = b.output.clone();
    extracted.draws = b.draws.clone();
    extracted.cell_offsets = b.cell_offsets.clone();
    extracted.leaf_vertices = b.leaf_vertices.clone();
    for (slot, transform, foliage, visibility) in &trees {
        if !visibility.get() {
            continue;
        }
        let params = materials
            .get(&foliage.material)
            .map(|m| m.extension.params)
            .unwrap_or_default();
        extracted.casters.push(LeafCaster {
            world_from_local: transform.to_matrix(),
            slot: slot.camera.slot,
            area_compensation: params.area_compensation != 0,
            max_scale: params.max_scale,
            opaque_fraction: params.opaque_fraction,
            triangles: slot.ty.full_index_count / 3,
        });
    }
    if extracted.casters.len() > MAX_CASTERS {
        warn_once!(
            "trees' opacity shadow map: {} pruned trees, only the first {MAX_CASTERS} cast",
            extracted.casters.len()
        );
        extracted.casters.truncate(MAX_CASTERS);
    }
}

#[allow(clippy::too_many_arguments)]
fn prepare_leaf_casters(
    extracted: Res<ExtractedLeafCasters>,
    mut frame: ResMut<LeafCasterFrame>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    gpu_buffers: Res<RenderAssets<GpuShaderBuffer>>,
    pipeline: Option<Res<LeafCasterPipeline>>,
    pipeline_cache: Res<PipelineCache>,
) {
    frame.bind_group = None;
    frame.casters = 0;
    let Some(pipeline) = pipeline else { return };
    if extracted.casters.is_empty() {
        return;
    }
    let get = |h: &Handle<ShaderBuffer>| gpu_buffers.get(h).map(|g| g.buffer.clone());
    let (Some(instances), Some(output), Some(draws), Some(cell_offsets), Some(leaf_vertices)) = (
        get(&extracted.instances),
        get(&extracted.output),
        get(&extracted.draws),
        get(&extracted.cell_offsets),
        get(&extracted.leaf_vertices),
    ) else {
        return;
    };
    let words: Vec<u32> = extracted.casters.iter().flat_map(|c| c.words()).collect();
    let bytes = (words.len() * 4) as u64;
    if frame.buffer.as_ref().is_none_or(|b| b.size() < bytes) {
        frame.buffer = Some(device.create_buffer(&BufferDescriptor {
            label: Some("foliage_opacity_casters"),
            size: bytes.next_power_of_two(),
            usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        }));
    }
    let Some(casters) = frame.buffer.clone() else {
        return;
    };
    queue.write_buffer(&casters, 0, bytemuck::cast_slice(&words));
    frame.bind_group = Some(device.create_bind_group(
        "foliage_opacity_shadow_group",
        &pipeline_cache.get_bind_group_layout(&pipeline.layout),
        &BindGroupEntries::sequential((
            instances.as_entire_binding(),
            output.as_entire_binding(),
            draws.as_entire_binding(),
            cell_offsets.as_entire_binding(),
            leaf_vertices.as_entire_binding(),
            casters.as_entire_binding(),
        )),
    ));
    frame.casters = extracted.casters.len() as u32;
    frame.max_triangles = extracted
        .casters
        .iter()
        .map(|c| c.triangles)
        .max()
        .unwrap_or(0);
}

fn draw_leaf_shadows(
    frame: Res<LeafCasterFrame>,
    targets: Option<Res<TreeOpacityTargets>>,
    pipeline: Option<Res<LeafCasterPipeline>>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (Some(group), Some(targets), Some(pipeline)) = (&frame.bind_group, targets, pipeline)
    else {
        return;
    };
    let (Some(map_group), Some(compute)) = (
        &targets.caster_bind_group,
        pipeline_cache.get_compute_pipeline(pipeline.pipeline),
    ) else {
        return;
    };
    if frame.casters == 0 || frame.max_triangles == 0 {
        return;
    }
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let mut pass = ctx
        .command_encoder()
        .begin_compute_pass(&ComputePassDescriptor {
            label: Some("foliage_opacity_shadow"),
            timestamp_writes: None,
        });
    // GPU time as `render/foliage_opacity_shadow/elapsed_gpu` with `RenderDiagnosticsPlugin`.
    let span = diagnostics.pass_span(&mut pass, "foliage_opacity_shadow");
    pass.set_pipeline(compute);
    pass.set_bind_group(0, group, &[]);
    pass.set_bind_group(1, map_group, &[]);
    pass.dispatch_workgroups(frame.max_triangles.div_ceil(64), frame.casters, 1);
    span.end(&mut pass);
}

/// Registers the render-world side.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "opacity_shadow.wgsl");
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedLeafCasters>()
        .init_resource::<LeafCasterFrame>()
        .add_systems(RenderStartup, init_pipeline)
        .add_systems(ExtractSchedule, extract_leaf_casters)
        .add_systems(
            Render,
            prepare_leaf_casters.in_set(RenderSystems::PrepareBindGroups),
        )
        .add_systems(
            RenderGraph,
            draw_leaf_shadows
                .in_set(TreeOpacityPass::Draw)
                .after(run_pruning),
        );
}
