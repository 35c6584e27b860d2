//! The per-frame pruning pass on the GPU: thin render-world code around `prune.wgsl`.
//!
//! Main world: every entity with [`PrunedFoliage`] gets a [`PruningParams`] each frame — the
//! three nearest baked viewpoints and their weights, and the distance factor — computed on the
//! CPU from the pruning camera (the thesis' `FindCameras` also runs on the host).
//!
//! Render world: the baked data of every tree type lives in shared storage buffers
//! ([`FoliageTypeBuffers`]); each frame [`PruningFrame`] holds one instance record per tree, and
//! two dispatches (`count_and_scan`, `compact`) write each tree's kept indices into its region
//! of the output index buffer and its indexed-indirect draw arguments. The pass runs once per
//! frame before any camera renders, so shadow views and the main view draw the same pruned set.

use super::bake::BakedFoliage;
use super::extract::{FIXED_ONE, ViewWeights, distance_factor_fixed, view_weights};
use crate::settings::FoliagePruningSettings;
use bevy::asset::{AssetId, embedded_asset, load_embedded_asset};
use bevy::core_pipeline::schedule::camera_driver;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::diagnostic::RecordDiagnostics;
use bevy::render::render_resource::binding_types::{
    storage_buffer_read_only_sized, storage_buffer_sized,
};
use bevy::render::render_resource::{
    BindGroup, BindGroupEntries, BindGroupLayoutDescriptor, BindGroupLayoutEntries, Buffer,
    BufferDescriptor, BufferInitDescriptor, BufferUsages, CachedComputePipelineId,
    ComputePassDescriptor, ComputePipelineDescriptor, PipelineCache, ShaderStages,
};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderGraph, RenderGraphSystems};
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems};
use std::sync::Arc;

/// Tags a tree instance whose leaves are pruned every frame. The entity's `GlobalTransform`
/// places the tree.
#[derive(Component, Clone, Debug)]
#[require(Transform, Visibility)]
pub struct PrunedFoliage {
    /// The baked pruning data of the tree type.
    pub baked: Handle<BakedFoliage>,
}

/// Marks the camera that drives pruning. Without one, the active 3D camera with the lowest
/// `order` does.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct FoliageCamera;

/// This frame's pruning inputs of one tree instance (written by the plugin).
#[derive(Component, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PruningParams {
    /// Viewpoints and weights.
    pub weights: ViewWeights,
    /// Distance factor (eq. 3.4), fraction of 65536.
    pub distance_fixed: u32,
}

impl BakedFoliage {
    /// Centre of the crown in model space (mean of the cell box centres).
    pub fn crown_center(&self) -> Vec3 {
        let n = self.cell_boxes.len().max(1) as f32;
        self.cell_boxes.iter().map(|b| b.center).sum::<Vec3>() / n
    }
}

/// Computes [`PruningParams`] for every pruned tree from the pruning camera.
pub fn compute_pruning_params(
    mut commands: Commands,
    settings: Res<FoliagePruningSettings>,
    baked: Res<Assets<BakedFoliage>>,
    marked: Query<&GlobalTransform, With<FoliageCamera>>,
    cameras: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    mut trees: Query<(
        Entity,
        &PrunedFoliage,
        &GlobalTransform,
        Option<&mut PruningParams>,
    )>,
) {
    let camera = marked.iter().next().copied().or_else(|| {
        cameras
            .iter()
            .filter(|(c, _)| c.is_active)
            .min_by_key(|(c, _)| c.order)
            .map(|(_, t)| *t)
    });
    let Some(camera) = camera else { return };
    let camera_position = camera.translation();
    for (entity, pruned, transform, params) in &mut trees {
        let Some(tree) = baked.get(&pruned.baked) else {
            continue;
        };
        let affine = transform.affine();
        let new = if !affine.is_finite()
            || !camera_position.is_finite()
            || affine.matrix3.determinant() == 0.0
        {
            // A tree that cannot be placed draws nothing (and says so once, on insertion).
            if params.is_none() {
                warn!(
                    "PrunedFoliage {entity}: transform is not finite or singular; the tree is not drawn"
                );
            }
            PruningParams::default()
        } else {
            let local_camera = affine.inverse().transform_point3(camera_position);
            let direction = local_camera - tree.crown_center();
            let distance = camera_position.distance(transform.translation());
            PruningParams {
                weights: view_weights(direction, &tree.view_directions, settings.view_weighting),
                distance_fixed: distance_factor_fixed(distance, settings.near, settings.far),
            }
        };
        match params {
            Some(mut p) => {
                if *p != new {
                    *p = new;
                }
            }
            None => {
                commands.entity(entity).insert(new);
            }
        }
    }
}

/// The baked data of every tree type, concatenated in shared GPU buffers.
#[derive(Resource, Default)]
pub struct FoliageTypeBuffers {
    /// Where each type's data starts.
    pub types: HashMap<AssetId<BakedFoliage>, TypeSlot>,
    cpu: TypeData,
    /// Buffers, when at least one type is uploaded.
    pub gpu: Option<TypeGpu>,
}

#[derive(Default)]
struct TypeData {
    cell_first_leaf: Vec<u32>,
    visibility: Vec<u32>,
    leaf_index_start: Vec<u32>,
    indices: Vec<u32>,
    vertex_count: u32,
}

/// Offsets of one tree type in the shared buffers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TypeSlot {
    /// First `cell_first_leaf` entry.
    pub cell_base: u32,
    /// Cells.
    pub cell_count: u32,
    /// Viewpoints.
    pub view_count: u32,
    /// First visibility entry.
    pub visibility_base: u32,
    /// First `leaf_index_start` entry.
    pub leaf_base: u32,
    /// First stored index.
    pub index_base: u32,
    /// Added to every written index.
    pub vertex_base: u32,
    /// Indices with every leaf kept.
    pub full_index_count: u32,
}

/// GPU copies of the shared baked buffers.
pub struct TypeGpu {
    /// Cell leaf ranges.
    pub cell_first_leaf: Buffer,
    /// Visibility, one `u32` per (cell, view).
    pub visibility: Buffer,
    /// Leaf index ranges.
    pub leaf_index_start: Buffer,
    /// Stored (ordered) leaf indices.
    pub stored_indices: Buffer,
}

/// Layout of one instance's output for this frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InstanceOutput {
    /// The main-world tree entity.
    pub entity: Entity,
    /// Tree type.
    pub slot: TypeSlot,
    /// First output index of this instance.
    pub output_base: u32,
    /// Index of its draw arguments in [`PruningFrame::draws`].
    pub draw: u32,
}

/// This frame's pruning work and its outputs.
#[derive(Resource, Default)]
pub struct PruningFrame {
    /// Instances, in draw order.
    pub instances: Vec<InstanceOutput>,
    /// Kept indices of every instance (`STORAGE | INDEX | COPY_SRC`).
    pub output: Option<Buffer>,
    /// Indexed-indirect draw arguments, one per instance (`STORAGE | INDIRECT | COPY_SRC`).
    pub draws: Option<Buffer>,
    bind_group: Option<BindGroup>,
    max_cells: u32,
}

/// Pruning inputs extracted from the main world.
#[derive(Resource, Default)]
struct ExtractedPruning {
    instances: Vec<(Entity, AssetId<BakedFoliage>, PruningParams)>,
    new_types: Vec<(AssetId<BakedFoliage>, Arc<BakedFoliage>)>,
}

#[derive(Resource)]
struct PruningPipelines {
    layout: BindGroupLayoutDescriptor,
    count_and_scan: CachedComputePipelineId,
    compact: CachedComputePipelineId,
}

/// Registers the pruning pass.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "prune.wgsl");
    app.init_asset::<BakedFoliage>().add_systems(
        PostUpdate,
        compute_pruning_params.after(TransformSystems::Propagate),
    );
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedPruning>()
        .init_resource::<FoliageTypeBuffers>()
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
                storage_buffer_read_only_sized(false, None),
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
    types: Res<FoliageTypeBuffers>,
    baked: Extract<Res<Assets<BakedFoliage>>>,
    trees: Extract<Query<(Entity, &PrunedFoliage, &PruningParams, &InheritedVisibility)>>,
) {
    extracted.instances.clear();
    extracted.new_types.clear();
    for (entity, pruned, params, visibility) in &trees {
        if !visibility.get() {
            continue;
        }
        let id = pruned.baked.id();
        if !types.types.contains_key(&id) && !extracted.new_types.iter().any(|(t, _)| *t == id) {
            match baked.get(id) {
                Some(tree) => extracted.new_types.push((id, Arc::new(tree.clone()))),
                None => continue,
            }
        }
        extracted.instances.push((entity, id, *params));
    }
    extracted.instances.sort_by_key(|(e, _, _)| *e);
}

fn upload(device: &RenderDevice, label: &str, data: &[u32], usage: BufferUsages) -> Buffer {
    // Storage bindings may not be empty.
    let data: &[u32] = if data.is_empty() { &[0] } else { data };
    device.create_buffer_with_data(&BufferInitDescriptor {
        label: Some(label),
        contents: bytemuck::cast_slice(data),
        usage: usage | BufferUsages::COPY_SRC,
    })
}

fn prepare_pruning(
    mut extracted: ResMut<ExtractedPruning>,
    mut types: ResMut<FoliageTypeBuffers>,
    mut frame: ResMut<PruningFrame>,
    device: Res<RenderDevice>,
    pipelines: Option<Res<PruningPipelines>>,
    pipeline_cache: Res<PipelineCache>,
) {
    // New tree types: append to the shared buffers and re-upload them (rare).
    let new_types = std::mem::take(&mut extracted.new_types);
    if !new_types.is_empty() {
        for (id, tree) in new_types {
            let cpu = &mut types.cpu;
            let slot = TypeSlot {
                cell_base: cpu.cell_first_leaf.len() as u32,
                cell_count: tree.cell_count() as u32,
                view_count: tree.view_count() as u32,
                visibility_base: cpu.visibility.len() as u32,
                leaf_base: cpu.leaf_index_start.len() as u32,
                index_base: cpu.indices.len() as u32,
                vertex_base: cpu.vertex_count,
                full_index_count: tree.indices.len() as u32,
            };
            cpu.cell_first_leaf.extend_from_slice(&tree.cell_first_leaf);
            cpu.visibility
                .extend(tree.visibility.iter().map(|&v| v as u32));
            cpu.leaf_index_start
                .extend_from_slice(&tree.leaf_index_start);
            cpu.indices.extend_from_slice(&tree.indices);
            cpu.vertex_count += tree.positions.len() as u32;
            types.types.insert(id, slot);
        }
        let cpu = &types.cpu;
        let gpu = TypeGpu {
            cell_first_leaf: upload(
                &device,
                "foliage_cell_first_leaf",
                &cpu.cell_first_leaf,
                BufferUsages::STORAGE,
            ),
            visibility: upload(
                &device,
                "foliage_visibility",
                &cpu.visibility,
                BufferUsages::STORAGE,
            ),
            leaf_index_start: upload(
                &device,
                "foliage_leaf_index_start",
                &cpu.leaf_index_start,
                BufferUsages::STORAGE,
            ),
            stored_indices: upload(
                &device,
                "foliage_stored_indices",
                &cpu.indices,
                BufferUsages::STORAGE,
            ),
        };
        types.gpu = Some(gpu);
    }

    frame.instances.clear();
    frame.bind_group = None;
    let (Some(gpu), Some(pipelines)) = (&types.gpu, pipelines) else {
        return;
    };
    let mut records: Vec<u32> = Vec::with_capacity(extracted.instances.len() * 16);
    let mut cell_bases: Vec<u32> = Vec::with_capacity(extracted.instances.len());
    let (mut output_len, mut cells_len, mut max_cells) = (0u32, 0u32, 0u32);
    for (draw, (entity, id, params)) in extracted.instances.iter().enumerate() {
        let Some(&slot) = types.types.get(id) else {
            continue;
        };
        let w = &params.weights;
        records.extend_from_slice(&[
            w.views[0],
            w.views[1],
            w.views[2],
            params.distance_fixed,
            w.weights[0],
            w.weights[1],
            w.weights[2],
            output_len,
            slot.cell_base,
            slot.cell_count,
            slot.view_count,
            slot.visibility_base,
            slot.leaf_base,
            slot.index_base,
            slot.vertex_base,
            0,
        ]);
        debug_assert_eq!(w.weights.iter().sum::<u32>(), FIXED_ONE);
        cell_bases.push(cells_len);
        frame.instances.push(InstanceOutput {
            entity: *entity,
            slot,
            output_base: output_len,
            draw: draw as u32,
        });
        output_len += slot.full_index_count;
        cells_len += slot.cell_count;
        max_cells = max_cells.max(slot.cell_count);
    }
    if frame.instances.is_empty() {
        return;
    }
    let instances = upload(
        &device,
        "foliage_pruning_instances",
        &records,
        BufferUsages::STORAGE,
    );
    let instance_cell_base = upload(
        &device,
        "foliage_instance_cell_base",
        &cell_bases,
        BufferUsages::STORAGE,
    );
    let sized = |label: &str, words: u32, usage: BufferUsages| {
        device.create_buffer(&BufferDescriptor {
            label: Some(label),
            size: (words.max(1) as u64) * 4,
            usage: usage | BufferUsages::COPY_SRC | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    };
    let cell_offsets = sized("foliage_cell_offsets", cells_len * 2, BufferUsages::STORAGE);
    let draws = sized(
        "foliage_pruned_draws",
        frame.instances.len() as u32 * 5,
        BufferUsages::STORAGE | BufferUsages::INDIRECT,
    );
    let output = sized(
        "foliage_pruned_indices",
        output_len,
        BufferUsages::STORAGE | BufferUsages::INDEX,
    );
    let layout = pipeline_cache.get_bind_group_layout(&pipelines.layout);
    frame.bind_group = Some(device.create_bind_group(
        "foliage_pruning_bind_group",
        &layout,
        &BindGroupEntries::sequential((
            instances.as_entire_binding(),
            gpu.cell_first_leaf.as_entire_binding(),
            gpu.visibility.as_entire_binding(),
            gpu.leaf_index_start.as_entire_binding(),
            gpu.stored_indices.as_entire_binding(),
            cell_offsets.as_entire_binding(),
            draws.as_entire_binding(),
            output.as_entire_binding(),
            instance_cell_base.as_entire_binding(),
        )),
    ));
    frame.output = Some(output);
    frame.draws = Some(draws);
    frame.max_cells = max_cells;
}

fn run_pruning(
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
    let instances = frame.instances.len() as u32;
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
    pass.dispatch_workgroups(instances, 1, 1);
    pass.set_pipeline(compact);
    pass.dispatch_workgroups(frame.max_cells.div_ceil(64), instances, 1);
    span.end(&mut pass);
}
