//! The per-frame pruning pass in the render world: thin code around `prune.wgsl`.
//!
//! Each frame one instance record per extraction — the camera's selection of every tree, and
//! while there is a shadow light the light's selection too ([`super::selection`]) — is uploaded,
//! and two dispatches (`count_and_scan`, `compact`) write each extraction's kept indices into its
//! region of the shared output buffer and its indexed-indirect draw arguments. The pass runs once
//! per frame before any camera renders; a camera record names the record shadow views draw.

use super::components::PruningParams;
use super::selection::Selection;
use super::store::{FoliageSlot, FoliageStore, INSTANCE_WORDS, Region, StoreBuffers, TypeSlot};
use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::core_pipeline::schedule::camera_driver;
use bevy::prelude::*;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::binding_types::{
    storage_buffer_read_only_sized, storage_buffer_sized,
};
use bevy::render::render_resource::{
    BindGroup, BindGroupEntries, BindGroupLayoutDescriptor, BindGroupLayoutEntries, Buffer,
    CachedComputePipelineId, ComputePassDescriptor, ComputePipelineDescriptor, PipelineCache,
    ShaderStages,
};
use bevy::render::renderer::{
    RenderContext, RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue,
};
use bevy::render::storage::{GpuShaderBuffer, ShaderBuffer};
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems};
use bevy::shader::load_shader_library;

/// Layout of one extraction's output for this frame (render world).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InstanceOutput {
    /// The main-world tree entity.
    pub entity: Entity,
    /// Tree type.
    pub slot: TypeSlot,
    /// First output index of this extraction.
    pub output_base: u32,
    /// Index of its draw arguments in [`PruningFrame::draws`] (its slot).
    pub draw: u32,
    /// The shadow light's selection (else the camera's).
    pub light: bool,
}

/// This frame's pruning work and its outputs (render world).
#[derive(Resource, Default)]
pub struct PruningFrame {
    /// Extractions, camera selections first.
    pub instances: Vec<InstanceOutput>,
    /// Kept indices of every instance.
    pub output: Option<Buffer>,
    /// Indexed-indirect draw arguments, five words per slot.
    pub draws: Option<Buffer>,
    bind_group: Option<BindGroup>,
    max_cells: u32,
    instance_count: u32,
}

/// Pruning inputs extracted from the main world.
#[derive(Resource, Default)]
struct ExtractedPruning {
    instances: Vec<(Entity, FoliageSlot, PruningParams)>,
    buffers: StoreBuffers,
}

#[derive(Resource)]
pub(crate) struct PruningPipelines {
    layout: BindGroupLayoutDescriptor,
    count_and_scan: CachedComputePipelineId,
    compact: CachedComputePipelineId,
}

/// Registers the pruning pass in the render app.
pub(crate) fn build(app: &mut App) {
    load_shader_library!(app, "pruning_types.wgsl");
    embedded_asset!(app, "prune.wgsl");
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedPruning>()
        .init_resource::<PruningFrame>()
        .add_systems(RenderStartup, init_pipelines)
        .add_systems(ExtractSchedule, extract_pruning)
        .add_systems(
            Render,
            prepare_pruning.in_set(RenderSystems::PrepareBindGroups),
        )
        .add_systems(
            RenderGraph,
            run_pruning
                .in_set(RenderGraphSystems::Render)
                .before(camera_driver),
        );
}

fn init_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
) {
    let layout = BindGroupLayoutDescriptor::new(
        "foliage_pruning_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                storage_buffer_read_only_sized(false, None),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
            ),
        ),
    );
    let shader = load_embedded_asset!(asset_server.as_ref(), "prune.wgsl");
    let queue = |entry: &'static str| {
        pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some(format!("foliage_pruning_{entry}").into()),
            layout: vec![layout.clone()],
            shader: shader.clone(),
            entry_point: Some(entry.into()),
            ..default()
        })
    };
    let count_and_scan = queue("count_and_scan");
    let compact = queue("compact");
    commands.insert_resource(PruningPipelines {
        layout,
        count_and_scan,
        compact,
    });
}

fn extract_pruning(
    mut extracted: ResMut<ExtractedPruning>,
    store: Extract<Res<FoliageStore>>,
    trees: Extract<Query<(Entity, &FoliageSlot, &PruningParams)>>,
) {
    extracted.instances.clear();
    extracted
        .instances
        .extend(trees.iter().map(|(e, s, p)| (e, *s, *p)));
    extracted.instances.sort_by_key(|(_, s, _)| s.camera.slot);
    extracted.buffers = store.buffers.clone();
}

fn prepare_pruning(
    extracted: Res<ExtractedPruning>,
    mut frame: ResMut<PruningFrame>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    gpu_buffers: Res<RenderAssets<GpuShaderBuffer>>,
    pipelines: Option<Res<PruningPipelines>>,
    pipeline_cache: Res<PipelineCache>,
) {
    frame.instances.clear();
    frame.bind_group = None;
    let Some(pipelines) = pipelines else { return };
    let b = &extracted.buffers;
    let get = |h: &Handle<ShaderBuffer>| gpu_buffers.get(h).map(|g| g.buffer.clone());
    let (
        Some(instances),
        Some(cell_first_leaf),
        Some(visibility),
        Some(leaf_index_start),
        Some(stored_indices),
        Some(cell_offsets),
        Some(draws),
        Some(output),
    ) = (
        get(&b.instances),
        get(&b.cell_first_leaf),
        get(&b.visibility),
        get(&b.leaf_index_start),
        get(&b.stored_indices),
        get(&b.cell_offsets),
        get(&b.draws),
        get(&b.output),
    )
    else {
        return;
    };
    if extracted.instances.is_empty() {
        return;
    }
    let slots = extracted
        .instances
        .iter()
        .map(|(_, s, _)| s.light.unwrap_or(s.camera).slot.max(s.camera.slot) + 1)
        .max()
        .unwrap_or(0);
    // Slots without a live instance this frame (e.g. hidden) draw nothing: zero records.
    let mut records = vec![0u32; slots as usize * INSTANCE_WORDS];
    let mut max_cells = 0;
    let mut write = |region: &Region, ty: &TypeSlot, selection: &Selection, shadow_slot: u32| {
        let w = &selection.weights;
        records[region.slot as usize * INSTANCE_WORDS..][..INSTANCE_WORDS].copy_from_slice(&[
            w.views[0],
            w.views[1],
            w.views[2],
            selection.distance_fixed,
            w.weights[0],
            w.weights[1],
            w.weights[2],
            region.output_base,
            ty.cell_base,
            ty.cell_count,
            ty.view_count,
            ty.visibility_base,
            ty.leaf_base,
            ty.index_base,
            ty.vertex_base,
            region.cell_offsets_base,
            shadow_slot,
            ty.extinction_bits,
            0,
            0,
            ty.crown_sphere_bits[0],
            ty.crown_sphere_bits[1],
            ty.crown_sphere_bits[2],
            ty.crown_sphere_bits[3],
            ty.hotspot[0],
            ty.hotspot[1],
            ty.hotspot[2],
            ty.hotspot[3],
        ]);
    };
    for (entity, slot, params) in &extracted.instances {
        let ty = &slot.ty;
        // Shadow views read the light's record when the tree has a light selection.
        let shadow_slot = match (slot.light, params.light) {
            (Some(region), Some(_)) => region.slot,
            _ => slot.camera.slot,
        };
        write(&slot.camera, ty, &params.camera, shadow_slot);
        frame.instances.push(InstanceOutput {
            entity: *entity,
            slot: *ty,
            output_base: slot.camera.output_base,
            draw: slot.camera.slot,
            light: false,
        });
        if let Some(region) = slot.light {
            // Without a light selection the record keeps nothing (shadows read the camera's).
            let selection = params.light.unwrap_or(Selection::NONE);
            write(&region, ty, &selection, region.slot);
            frame.instances.push(InstanceOutput {
                entity: *entity,
                slot: *ty,
                output_base: region.output_base,
                draw: region.slot,
                light: true,
            });
        }
        max_cells = max_cells.max(ty.cell_count);
    }
    if (records.len() * 4) as u64 > instances.size() {
        return; // The store grows next frame.
    }
    queue.write_buffer(&instances, 0, bytemuck::cast_slice(&records));
    let layout = pipeline_cache.get_bind_group_layout(&pipelines.layout);
    frame.bind_group = Some(device.create_bind_group(
        "foliage_pruning_bind_group",
        &layout,
        &BindGroupEntries::sequential((
            instances.as_entire_binding(),
            cell_first_leaf.as_entire_binding(),
            visibility.as_entire_binding(),
            leaf_index_start.as_entire_binding(),
            stored_indices.as_entire_binding(),
            cell_offsets.as_entire_binding(),
            draws.as_entire_binding(),
            output.as_entire_binding(),
        )),
    ));
    frame.output = Some(output);
    frame.draws = Some(draws);
    frame.max_cells = max_cells;
    frame.instance_count = slots;
}

pub(crate) fn run_pruning(
    frame: Res<PruningFrame>,
    pipelines: Option<Res<PruningPipelines>>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (Some(bind_group), Some(pipelines)) = (&frame.bind_group, pipelines) else {
        return;
    };
    let (Some(count_and_scan), Some(compact)) = (
        pipeline_cache.get_compute_pipeline(pipelines.count_and_scan),
        pipeline_cache.get_compute_pipeline(pipelines.compact),
    ) else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let encoder = ctx.command_encoder();
    let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
        label: Some("foliage_pruning"),
        timestamp_writes: None,
    });
    let span = diagnostics.pass_span(&mut pass, "foliage_pruning");
    pass.set_bind_group(0, bind_group, &[]);
    pass.set_pipeline(count_and_scan);
    pass.dispatch_workgroups(frame.instance_count, 1, 1);
    pass.set_pipeline(compact);
    pass.dispatch_workgroups(frame.max_cells.div_ceil(64), frame.instance_count, 1);
    span.end(&mut pass);
}
