//! The per-frame pruning pass on the GPU: thin ECS and render-world code around `prune.wgsl`.
//!
//! Main world:
//! - every entity with [`PrunedFoliage`] gets a [`PruningParams`] each frame — the three nearest
//!   baked viewpoints and their weights, and the distance factor — computed on the CPU from the
//!   pruning camera (the thesis' `FindCameras` also runs on the host);
//! - [`FoliageStore`] owns the GPU buffers as [`ShaderBuffer`] assets: the baked data of every
//!   tree type concatenated (static), and per-instance regions of the output index buffer, per-cell
//!   offsets and indirect draw arguments (written by the GPU each frame). The leaf material binds
//!   the same buffers, so the vertex stage reads exactly what the compute pass wrote.
//!
//! Render world: each frame one instance record per tree is uploaded and two dispatches
//! (`count_and_scan`, `compact`) write each tree's kept indices into its region and its
//! indexed-indirect draw arguments. The pass runs once per frame before any camera renders, so
//! shadow views and the main view draw the same pruned set.

use super::bake::BakedFoliage;
use super::extract::{FIXED_ONE, KEEP_ALL, ViewWeights, distance_factor_fixed, view_weights};
use crate::settings::FoliagePruningSettings;
use bevy::asset::{AssetId, RenderAssetUsages, embedded_asset, load_embedded_asset};
use bevy::core_pipeline::schedule::camera_driver;
use bevy::platform::collections::HashMap;
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

/// Tags a tree instance whose leaves are pruned every frame. The entity's `GlobalTransform`
/// places the tree.
#[derive(Component, Clone, Debug)]
#[require(Transform, Visibility)]
pub struct PrunedFoliage {
    /// The baked pruning data of the tree type.
    pub baked: Handle<BakedFoliage>,
    /// How the leaves look (see [`leaf_material`](super::material::leaf_material)).
    pub material: Handle<super::material::LeafMaterial>,
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

/// Where a pruned tree's data lives in the shared buffers this frame (written by the plugin).
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub struct FoliageSlot {
    /// Instance record index (also the entity's `MeshTag`).
    pub slot: u32,
    /// Tree type layout.
    pub ty: TypeSlot,
    /// First output index of this instance.
    pub output_base: u32,
    /// First per-cell offset entry of this instance.
    pub cell_offsets_base: u32,
}

impl BakedFoliage {
    /// Centre of the crown in model space (mean of the cell box centres).
    pub fn crown_center(&self) -> Vec3 {
        let n = self.cell_boxes.len().max(1) as f32;
        self.cell_boxes.iter().map(|b| b.center).sum::<Vec3>() / n
    }

    /// Radius, about [`crown_center`](Self::crown_center), of a sphere holding every cell box.
    pub fn crown_radius(&self) -> f32 {
        let c = self.crown_center();
        self.cell_boxes
            .iter()
            .map(|b| (b.center - c).length() + b.half_extents.length())
            .fold(0.0, f32::max)
    }
}

/// Marks a [`PrunedFoliage`] entity whose [`PruningParams`] are written by someone else (the
/// forest manager's cache extractions) instead of from the pruning camera every frame, and that
/// is not drawn itself.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct ManagedPruning;

/// Computes [`PruningParams`] for every pruned tree from the pruning camera.
#[allow(clippy::too_many_arguments)]
pub fn compute_pruning_params(
    mut commands: Commands,
    mut asset_events: MessageReader<AssetEvent<BakedFoliage>>,
    settings: Res<FoliagePruningSettings>,
    baked: Res<Assets<BakedFoliage>>,
    marked: Query<&GlobalTransform, With<FoliageCamera>>,
    cameras: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    mut trees: Query<
        (
            Entity,
            &PrunedFoliage,
            &GlobalTransform,
            Option<&mut PruningParams>,
        ),
        Without<ManagedPruning>,
    >,
    mut crowns: Local<HashMap<AssetId<BakedFoliage>, (Vec3, f32)>>,
) {
    let camera = marked.iter().next().copied().or_else(|| {
        cameras
            .iter()
            .filter(|(c, _)| c.is_active)
            .min_by_key(|(c, _)| c.order)
            .map(|(_, t)| *t)
    });
    for event in asset_events.read() {
        if let AssetEvent::Modified { id } | AssetEvent::Removed { id } = event {
            crowns.remove(id);
        }
    }
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
            PruningParams {
                weights: ViewWeights {
                    views: [0; 3],
                    weights: [FIXED_ONE, 0, 0],
                },
                distance_fixed: 0,
            }
        } else {
            let local_camera = affine.inverse().transform_point3(camera_position);
            // The crown sphere, once per tree type (and again if the asset changes).
            let (crown_center, crown_radius) = *crowns
                .entry(pruned.baked.id())
                .or_insert_with(|| (tree.crown_center(), tree.crown_radius()));
            let direction = local_camera - crown_center;
            let distance = camera_position.distance(transform.translation());
            // Inside the crown the visibility baked from viewpoints around it does not apply:
            // keep every leaf.
            let inside_crown = direction.length() < crown_radius;
            PruningParams {
                weights: view_weights(direction, &tree.view_directions, settings.view_weighting),
                distance_fixed: if settings.enabled && !inside_crown {
                    distance_factor_fixed(distance, settings.near, settings.far)
                } else {
                    KEEP_ALL
                },
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

/// Offsets of one tree type in the shared buffers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TypeSlot {
    /// First entry in `cell_first_leaf` (and in `cell_full`).
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
    /// Added to every written index (types share one vertex buffer).
    pub vertex_base: u32,
    /// Indices with every leaf kept.
    pub full_index_count: u32,
    /// Every leaf is a canonical quad ([`BakedFoliage::quad_leaves`]): drawn with quad slot
    /// meshes.
    pub quads: bool,
}

/// Set in a pruned tree's `MeshTag` when it is drawn with a quad slot mesh; the low bits are the
/// instance slot.
pub const QUAD_TAG_BIT: u32 = 1 << 31;

/// The `MeshTag` of a tree drawing instance `slot` of a type laid out as `ty`.
pub fn mesh_tag(slot: u32, ty: &TypeSlot) -> u32 {
    if ty.quads { slot | QUAD_TAG_BIT } else { slot }
}

/// Words per packed leaf vertex in the `leaf_vertices` buffer:
/// `position.xyz, cell, offset.xyz, leaf radius, normal.xyz, 0, uv.xy, leaf uv centre.xy`.
pub const LEAF_VERTEX_WORDS: usize = 16;

/// Words per instance record (must match `Instance` in `prune.wgsl` and `leaf.wgsl`).
pub const INSTANCE_WORDS: usize = 16;

/// Handles of the shared pruning buffers.
#[derive(Clone, Debug, Default)]
pub struct StoreBuffers {
    /// Per type, `cells + 1` leaf starts (per-type relative).
    pub cell_first_leaf: Handle<ShaderBuffer>,
    /// Per type, `cells × views` visibilities, one `u32` each.
    pub visibility: Handle<ShaderBuffer>,
    /// Per type, `leaves + 1` index starts.
    pub leaf_index_start: Handle<ShaderBuffer>,
    /// Per type, stored leaf indices.
    pub stored_indices: Handle<ShaderBuffer>,
    /// Per type, packed leaf vertices.
    pub leaf_vertices: Handle<ShaderBuffer>,
    /// Per type, `cells + 1` entries: full index count of each cell.
    pub cell_full: Handle<ShaderBuffer>,
    /// Per-instance records (uploaded each frame).
    pub instances: Handle<ShaderBuffer>,
    /// Kept indices, one region per instance (GPU written).
    pub output: Handle<ShaderBuffer>,
    /// Per instance and cell: kept index count and output offset (GPU written).
    pub cell_offsets: Handle<ShaderBuffer>,
    /// Indexed-indirect draw arguments, five words per instance (GPU written).
    pub draws: Handle<ShaderBuffer>,
}

/// The GPU buffers shared by every pruned tree, owned by the main world.
#[derive(Resource, Default)]
pub struct FoliageStore {
    /// Layout of each uploaded tree type.
    pub types: HashMap<AssetId<BakedFoliage>, TypeSlot>,
    /// The buffers.
    pub buffers: StoreBuffers,
    /// Bumped whenever a buffer is replaced, so materials binding them are refreshed.
    pub generation: u32,
    /// Draw every type with triangle slot meshes, even quad-leaf types (for comparing the two
    /// paths; takes effect for types uploaded afterwards).
    pub force_triangle_slots: bool,
    capacity: Capacity,
    vertex_words: u32,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Capacity {
    instances: u32,
    output: u32,
    cell_offsets: u32,
}

fn words_buffer(words: &[u32], label: &'static str) -> ShaderBuffer {
    let data: &[u32] = if words.is_empty() { &[0] } else { words };
    let mut buffer = ShaderBuffer::new(bytemuck::cast_slice(data), RenderAssetUsages::RENDER_WORLD);
    buffer.buffer_description.label = Some(label);
    buffer
}

fn gpu_only_buffer(words: u32, label: &'static str) -> ShaderBuffer {
    let mut buffer =
        ShaderBuffer::with_size(words.max(1) as usize * 4, RenderAssetUsages::RENDER_WORLD);
    buffer.buffer_description.label = Some(label);
    buffer
}

/// Main-world bookkeeping each frame: uploads new tree types, assigns instance slots and regions,
/// grows the buffers when needed.
pub fn update_foliage_store(
    mut commands: Commands,
    mut store: ResMut<FoliageStore>,
    mut buffers: ResMut<Assets<ShaderBuffer>>,
    baked: Res<Assets<BakedFoliage>>,
    trees: Query<(Entity, &PrunedFoliage, Option<&FoliageSlot>), With<PruningParams>>,
) {
    let store = &mut *store;
    let store_force_triangles = store.force_triangle_slots;
    // New tree types.
    let mut new_types: Vec<AssetId<BakedFoliage>> = Vec::new();
    for (_, pruned, _) in &trees {
        let id = pruned.baked.id();
        if !store.types.contains_key(&id) && !new_types.contains(&id) && baked.contains(id) {
            new_types.push(id);
        }
    }
    if !new_types.is_empty() {
        // Re-upload every type in a stable order (types are few; this happens rarely).
        let mut ids: Vec<AssetId<BakedFoliage>> = store.types.keys().copied().collect();
        ids.extend(new_types);
        ids.retain(|id| baked.contains(*id));
        ids.sort_by_key(|id| {
            store
                .types
                .get(id)
                .map(|s| s.vertex_base)
                .unwrap_or(u32::MAX)
        });
        let (mut cfl, mut vis, mut lis, mut idx, mut verts, mut full) = (
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
        );
        store.types.clear();
        for id in ids {
            let tree = baked.get(id).unwrap();
            let slot = TypeSlot {
                cell_base: cfl.len() as u32,
                cell_count: tree.cell_count() as u32,
                view_count: tree.view_count() as u32,
                visibility_base: vis.len() as u32,
                leaf_base: lis.len() as u32,
                index_base: idx.len() as u32,
                vertex_base: (verts.len() / LEAF_VERTEX_WORDS) as u32,
                full_index_count: tree.indices.len() as u32,
                quads: tree.quad_leaves() && !store_force_triangles,
            };
            cfl.extend_from_slice(&tree.cell_first_leaf);
            vis.extend(tree.visibility.iter().map(|&v| v as u32));
            lis.extend_from_slice(&tree.leaf_index_start);
            idx.extend_from_slice(&tree.indices);
            let mut vertex_cell = vec![0u32; tree.positions.len()];
            for c in 0..tree.cell_count() {
                let (a, b) = (tree.cell_first_leaf[c], tree.cell_first_leaf[c + 1]);
                let (start, end) = (
                    tree.leaf_index_start[a as usize],
                    tree.leaf_index_start[b as usize],
                );
                for &v in &tree.indices[start as usize..end as usize] {
                    vertex_cell[v as usize] = c as u32;
                }
                full.push(end - start);
            }
            full.push(0);
            // Per vertex, its leaf's radius and the centre of its leaf's texture coordinates
            // (for the sub-pixel fade, see `appearance`).
            let mut leaf_radius = vec![0.0f32; tree.positions.len()];
            let mut uv_centre = vec![Vec2::ZERO; tree.positions.len()];
            let mut corners: Vec<u32> = Vec::new();
            for leaf in 0..tree.leaf_count() {
                let (start, end) = (
                    tree.leaf_index_start[leaf] as usize,
                    tree.leaf_index_start[leaf + 1] as usize,
                );
                corners.clear();
                corners.extend_from_slice(&tree.indices[start..end]);
                corners.sort_unstable();
                corners.dedup();
                let radius = corners
                    .iter()
                    .map(|&v| tree.centroid_offsets[v as usize].length())
                    .fold(0.0f32, f32::max);
                let centre = corners.iter().map(|&v| tree.uvs[v as usize]).sum::<Vec2>()
                    / corners.len().max(1) as f32;
                for &v in &corners {
                    leaf_radius[v as usize] = radius;
                    uv_centre[v as usize] = centre;
                }
            }
            for v in 0..tree.positions.len() {
                let (p, e, n, uv) = (
                    tree.positions[v],
                    tree.centroid_offsets[v],
                    tree.normals[v],
                    tree.uvs[v],
                );
                verts.extend_from_slice(&[
                    p.x.to_bits(),
                    p.y.to_bits(),
                    p.z.to_bits(),
                    vertex_cell[v],
                    e.x.to_bits(),
                    e.y.to_bits(),
                    e.z.to_bits(),
                    leaf_radius[v].to_bits(),
                    n.x.to_bits(),
                    n.y.to_bits(),
                    n.z.to_bits(),
                    0,
                    uv.x.to_bits(),
                    uv.y.to_bits(),
                    uv_centre[v].x.to_bits(),
                    uv_centre[v].y.to_bits(),
                ]);
            }
            store.types.insert(id, slot);
        }
        let b = &mut store.buffers;
        b.cell_first_leaf = buffers.add(words_buffer(&cfl, "foliage_cell_first_leaf"));
        b.visibility = buffers.add(words_buffer(&vis, "foliage_visibility"));
        b.leaf_index_start = buffers.add(words_buffer(&lis, "foliage_leaf_index_start"));
        b.stored_indices = buffers.add(words_buffer(&idx, "foliage_stored_indices"));
        b.leaf_vertices = buffers.add(words_buffer(&verts, "foliage_leaf_vertices"));
        b.cell_full = buffers.add(words_buffer(&full, "foliage_cell_full"));
        store.vertex_words = verts.len() as u32;
        store.generation += 1;
    }

    // Instance slots in entity order; regions sized for every leaf kept.
    let mut entities: Vec<(Entity, AssetId<BakedFoliage>, Option<FoliageSlot>)> = trees
        .iter()
        .filter(|(_, p, _)| store.types.contains_key(&p.baked.id()))
        .map(|(e, p, s)| (e, p.baked.id(), s.copied()))
        .collect();
    entities.sort_by_key(|(e, _, _)| *e);
    let mut need = Capacity::default();
    for (slot, (entity, id, old)) in entities.iter().enumerate() {
        let ty = store.types[id];
        let new = FoliageSlot {
            slot: slot as u32,
            ty,
            output_base: need.output,
            cell_offsets_base: need.cell_offsets,
        };
        need.instances += 1;
        need.output += ty.full_index_count;
        need.cell_offsets += ty.cell_count;
        if *old != Some(new) {
            commands
                .entity(*entity)
                .insert((new, bevy::mesh::MeshTag(mesh_tag(slot as u32, &ty))));
        }
    }
    let cap = store.capacity;
    if need.instances > cap.instances
        || need.output > cap.output
        || need.cell_offsets > cap.cell_offsets
    {
        // Grow by half again so that adding trees one by one does not reallocate every frame.
        let grow = |n: u32, have: u32| if n > have { n + n / 2 } else { have };
        let cap = Capacity {
            instances: grow(need.instances, cap.instances),
            output: grow(need.output, cap.output),
            cell_offsets: grow(need.cell_offsets, cap.cell_offsets),
        };
        let b = &mut store.buffers;
        b.instances = buffers.add(gpu_only_buffer(
            cap.instances * INSTANCE_WORDS as u32,
            "foliage_instances",
        ));
        b.output = buffers.add(gpu_only_buffer(cap.output, "foliage_pruned_indices"));
        b.cell_offsets = buffers.add(gpu_only_buffer(
            cap.cell_offsets * 2,
            "foliage_cell_offsets",
        ));
        let mut draws = gpu_only_buffer(cap.instances * 5, "foliage_pruned_draws");
        draws.buffer_description.usage |= bevy::render::render_resource::BufferUsages::INDIRECT;
        b.draws = buffers.add(draws);
        store.capacity = cap;
        store.generation += 1;
    }
}

/// Layout of one instance's output for this frame (render world).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InstanceOutput {
    /// The main-world tree entity.
    pub entity: Entity,
    /// Tree type.
    pub slot: TypeSlot,
    /// First output index of this instance.
    pub output_base: u32,
    /// Index of its draw arguments in [`PruningFrame::draws`] (its slot).
    pub draw: u32,
}

/// This frame's pruning work and its outputs (render world).
#[derive(Resource, Default)]
pub struct PruningFrame {
    /// Instances, in slot order.
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
    vertex_words: u32,
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
    app.init_asset::<BakedFoliage>()
        .init_asset_loader::<super::format::BakedFoliageLoader>()
        .init_resource::<FoliageStore>()
        .add_systems(
            PostUpdate,
            (compute_pruning_params, update_foliage_store)
                .chain()
                .after(TransformSystems::Propagate),
        );
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
    extracted.instances.sort_by_key(|(_, s, _)| s.slot);
    extracted.buffers = store.buffers.clone();
    extracted.vertex_words = store.vertex_words;
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
        .last()
        .map(|(_, s, _)| s.slot + 1)
        .unwrap_or(0);
    // Slots without a live instance this frame (e.g. hidden) draw nothing: zero records.
    let mut records = vec![0u32; slots as usize * INSTANCE_WORDS];
    let mut max_cells = 0;
    for (entity, slot, params) in &extracted.instances {
        let w = &params.weights;
        let ty = &slot.ty;
        let r = &mut records[slot.slot as usize * INSTANCE_WORDS..][..INSTANCE_WORDS];
        r.copy_from_slice(&[
            w.views[0],
            w.views[1],
            w.views[2],
            params.distance_fixed,
            w.weights[0],
            w.weights[1],
            w.weights[2],
            slot.output_base,
            ty.cell_base,
            ty.cell_count,
            ty.view_count,
            ty.visibility_base,
            ty.leaf_base,
            ty.index_base,
            ty.vertex_base,
            slot.cell_offsets_base,
        ]);
        max_cells = max_cells.max(ty.cell_count);
        frame.instances.push(InstanceOutput {
            entity: *entity,
            slot: *ty,
            output_base: slot.output_base,
            draw: slot.slot,
        });
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
