//! Drawing pruned leaves with Bevy's PBR material: [`LeafMaterial`] is a `StandardMaterial`
//! extended with a vertex stage that pulls the kept leaves written by the pruning pass, so leaves
//! get Bevy's lighting, shadows (cast and received) and prepasses unchanged.
//!
//! A pruned tree is drawn with a *slot mesh*: `n` vertices whose positions only carry their
//! index. The plugin picks, per tree and frame, the smallest slot mesh (a power-of-two bucket)
//! that holds the tree's kept index count — known exactly on the CPU because the pruning
//! arithmetic is integer ([`super::extract`]) — so the vertex stage never runs for more than
//! twice the kept vertices, and the vertices past the kept count are culled.

use super::bake::BakedFoliage;
use super::extract::kept_index_total;
use super::gpu::{FoliageSlot, FoliageStore, ManagedPruning, PrunedFoliage, PruningParams};
use crate::settings::FoliagePruningSettings;
use bevy::asset::{RenderAssetUsages, embedded_asset};
use bevy::camera::visibility::NoFrustumCulling;
use bevy::diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::pbr::{ExtendedMaterial, MaterialExtension, MaterialPlugin};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::render_resource::{AsBindGroup, ShaderType};
use bevy::render::storage::ShaderBuffer;
use bevy::shader::ShaderRef;
use bevy::shader::load_shader_library;

/// The material of pruned leaves: a `StandardMaterial` (colour, texture, alpha mode) whose vertex
/// stage draws the pruned leaf set. Make one with [`leaf_material`].
pub type LeafMaterial = ExtendedMaterial<StandardMaterial, LeafExtension>;

/// Per-material parameters of the leaf vertex stage (see [`super::appearance`]). The switches and
/// fade thresholds follow [`FoliagePruningSettings`]; `opaque_fraction` is the material's own.
#[derive(Clone, Copy, Debug, PartialEq, ShaderType, Reflect)]
pub struct LeafParams {
    /// 1 to enlarge kept leaves so total leaf area is preserved (eq. 3.7–3.9).
    pub area_compensation: u32,
    /// 1 to fade sub-pixel leaves to a solid colour.
    pub subpixel_fade: u32,
    /// Cap of the linear compensation scale.
    pub max_scale: f32,
    /// Fraction of the leaf texture that is opaque (1 for untextured leaves); a fully faded leaf
    /// shrinks to this fraction of its area.
    pub opaque_fraction: f32,
    /// Projected diameter (pixels) where the fade starts.
    pub fade_start: f32,
    /// Projected diameter (pixels) where leaves are fully solid.
    pub fade_end: f32,
    /// Padding.
    pub pad_x: u32,
    /// Padding.
    pub pad_y: u32,
}

impl Default for LeafParams {
    fn default() -> Self {
        let s = FoliagePruningSettings::default();
        Self {
            area_compensation: s.area_compensation as u32,
            subpixel_fade: s.subpixel_fade as u32,
            max_scale: s.max_leaf_scale,
            opaque_fraction: 1.0,
            fade_start: s.fade_start_pixels,
            fade_end: s.fade_end_pixels,
            pad_x: 0,
            pad_y: 0,
        }
    }
}

/// The extension binding the pruning buffers (managed by the plugin: leave them default).
#[derive(Asset, AsBindGroup, Reflect, Debug, Clone, Default)]
#[bind_group_data(LeafKey)]
pub struct LeafExtension {
    /// Instance records.
    #[storage(100, read_only, visibility(vertex))]
    pub instances: Handle<ShaderBuffer>,
    /// Kept indices.
    #[storage(101, read_only, visibility(vertex))]
    pub output: Handle<ShaderBuffer>,
    /// Indirect draw arguments (kept counts).
    #[storage(102, read_only, visibility(vertex))]
    pub draws: Handle<ShaderBuffer>,
    /// Per instance and cell kept counts.
    #[storage(103, read_only, visibility(vertex))]
    pub cell_offsets: Handle<ShaderBuffer>,
    /// Packed leaf vertices.
    #[storage(104, read_only, visibility(vertex))]
    pub leaf_vertices: Handle<ShaderBuffer>,
    /// Full index count per cell.
    #[storage(105, read_only, visibility(vertex))]
    pub cell_full: Handle<ShaderBuffer>,
    /// Switches.
    #[uniform(106, visibility(vertex))]
    pub params: LeafParams,
    /// A screen-space soft-shadow visibility texture (`bevy_soft_shadows`'
    /// `SsssTextures::visibility`) to use as the sun's shadow term. With one, the main pass's
    /// fragment stage is `leaf_soft_fragment.wgsl`, which imports
    /// `bevy_soft_shadows::receiver_functions` (so that plugin must be added); without, leaves
    /// use Bevy's PBR fragment stage and shadows.
    #[texture(107, sample_type = "float", filterable = false)]
    pub soft_visibility: Option<Handle<Image>>,
}

/// What the leaf pipeline is specialised on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct LeafKey {
    /// The leaves receive screen-space soft shadows.
    pub soft_shadows: bool,
}

impl From<&LeafExtension> for LeafKey {
    fn from(material: &LeafExtension) -> Self {
        Self {
            soft_shadows: material.soft_visibility.is_some(),
        }
    }
}

/// The soft-shadow fragment stage, loaded at start-up and swapped in by `specialize`.
static LEAF_SOFT_SHADER: std::sync::OnceLock<Handle<bevy::shader::Shader>> =
    std::sync::OnceLock::new();

const LEAF_SHADER: &str = "embedded://bevy_foliage/pruning/leaf.wgsl";
const LEAF_PREPASS_SHADER: &str = "embedded://bevy_foliage/pruning/leaf_prepass.wgsl";

impl MaterialExtension for LeafExtension {
    fn vertex_shader() -> ShaderRef {
        ShaderRef::Path(LEAF_SHADER.into())
    }
    fn prepass_vertex_shader() -> ShaderRef {
        ShaderRef::Path(LEAF_PREPASS_SHADER.into())
    }
    fn deferred_vertex_shader() -> ShaderRef {
        ShaderRef::Path(LEAF_PREPASS_SHADER.into())
    }

    fn specialize(
        _pipeline: &bevy::pbr::MaterialExtensionPipeline,
        descriptor: &mut bevy::render::render_resource::RenderPipelineDescriptor,
        _layout: &bevy::mesh::MeshVertexBufferLayoutRef,
        key: bevy::pbr::MaterialExtensionKey<Self>,
    ) -> Result<(), bevy::render::render_resource::SpecializedMeshPipelineError> {
        // Only the main pass: the prepass and shadow pipelines keep Bevy's prepass shader.
        if key.bind_group_data.soft_shadows
            && let (Some(fragment), Some(soft)) =
                (descriptor.fragment.as_mut(), LEAF_SOFT_SHADER.get())
            && !fragment
                .shader_defs
                .iter()
                .any(|d| *d == bevy::shader::ShaderDefVal::from("PREPASS_PIPELINE"))
        {
            fragment.shader = soft.clone();
        }
        Ok(())
    }
}

/// A leaf material from a `StandardMaterial`; leaves are two-sided. For alpha-masked leaf
/// textures use [`leaf_material_textured`] so faded leaves keep the right area.
pub fn leaf_material(base: StandardMaterial) -> LeafMaterial {
    leaf_material_textured(base, 1.0)
}

/// A leaf material whose texture is opaque over `opaque_fraction` of its area (measure it with
/// [`opaque_fraction`](super::appearance::opaque_fraction)): sub-pixel leaves, drawn solid,
/// shrink to that area so distant crowns keep their density.
pub fn leaf_material_textured(base: StandardMaterial, opaque_fraction: f32) -> LeafMaterial {
    let opaque_fraction = if opaque_fraction.is_finite() && opaque_fraction > 0.0 {
        opaque_fraction.min(1.0)
    } else {
        warn!("leaf opaque fraction {opaque_fraction} must be in (0, 1]: using 1");
        1.0
    };
    LeafMaterial {
        base: StandardMaterial {
            double_sided: true,
            cull_mode: None,
            ..base
        },
        extension: LeafExtension {
            params: LeafParams {
                opaque_fraction,
                ..default()
            },
            ..default()
        },
    }
}

/// Slot meshes by kind (quad or triangle) and size.
#[derive(Resource, Default)]
pub struct SlotMeshes(HashMap<(bool, u32), Handle<Mesh>>);

impl SlotMeshes {
    /// The slot mesh for `kept` kept indices of a tree type with `full` indices, whose leaves
    /// are all canonical quads if `quads`.
    ///
    /// Every bucket the type can need is created when the type is first seen: slot meshes
    /// created later, while the tree is already drawn, were observed not to be drawn on the
    /// frames that followed (Bevy 0.19, software Vulkan); creating them up front avoids it.
    pub fn fitting(
        &mut self,
        kept: u32,
        full: u32,
        quads: bool,
        meshes: &mut Assets<Mesh>,
    ) -> Handle<Mesh> {
        let per_primitive = if quads { 6 } else { 3 };
        let full_bucket = slot_bucket(full.div_ceil(per_primitive));
        let mut k = 0;
        loop {
            let b = bucket_size(k);
            self.0
                .entry((quads, b))
                .or_insert_with(|| meshes.add(slot_mesh(b, quads)));
            if b >= full_bucket {
                break;
            }
            k += 1;
        }
        let bucket = slot_bucket(kept.div_ceil(per_primitive));
        self.0
            .entry((quads, bucket))
            .or_insert_with(|| meshes.add(slot_mesh(bucket, quads)))
            .clone()
    }
}

/// Size of the `k`-th slot-mesh bucket, in primitives (triangles, or quad leaves):
/// `⌈64 · √2^k⌉`. The √2 steps keep the vertex stage's wasted runs (past the kept count) under
/// 41 %, about 19 % on average, at about 3.4 times the largest slot mesh's memory in all.
pub fn bucket_size(k: u32) -> u32 {
    (64.0 * 2f64.powf(k as f64 / 2.0)).ceil() as u32
}

/// The smallest bucket holding `primitives`.
pub fn slot_bucket(primitives: u32) -> u32 {
    let mut k = 0;
    while bucket_size(k) < primitives {
        k += 1;
    }
    bucket_size(k)
}

/// A slot mesh of `primitives` primitives whose vertex i carries i in `position.x`. Triangle
/// slots are non-indexed (vertex i pulls kept index i); quad slots have four vertices per leaf
/// and the index pattern `0 1 2, 0 2 3` (vertex 4k + c pulls kept index 6k + [0, 1, 2, 5][c]), so
/// the vertex stage runs four times per quad leaf instead of six.
fn slot_mesh(primitives: u32, quads: bool) -> Mesh {
    let vertices = primitives * if quads { 4 } else { 3 };
    let positions: Vec<[f32; 3]> = (0..vertices).map(|i| [i as f32, 0.0, 0.0]).collect();
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    );
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    // Present so the leaf material's texture coordinates are passed on (VERTEX_UVS_A).
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, vec![[0.0f32, 0.0]; vertices as usize]);
    if quads {
        let indices: Vec<u32> = (0..primitives)
            .flat_map(|k| [0, 1, 2, 0, 2, 3].map(|c| 4 * k + c))
            .collect();
        mesh.insert_indices(Indices::U32(indices));
    }
    mesh
}

/// Leaf triangles drawn this frame, over all pruned trees.
pub const TRIANGLES_DRAWN: DiagnosticPath = DiagnosticPath::const_new("foliage/triangles_drawn");
/// Leaf triangles of the same trees at full detail.
pub const TRIANGLES_FULL: DiagnosticPath = DiagnosticPath::const_new("foliage/triangles_full");
/// `100 · drawn / full`.
pub const KEPT_PERCENT: DiagnosticPath = DiagnosticPath::const_new("foliage/kept_percent");
/// Pruned trees this frame.
pub const TREES_PRUNED: DiagnosticPath = DiagnosticPath::const_new("foliage/trees_pruned");

/// Gives every pruned tree the slot mesh that fits its kept count, its material and its tag,
/// and publishes the leaf counts as diagnostics.
#[allow(clippy::type_complexity)]
pub fn assign_slot_meshes(
    mut commands: Commands,
    mut diagnostics: Diagnostics,
    mut slot_meshes: ResMut<SlotMeshes>,
    mut meshes: ResMut<Assets<Mesh>>,
    baked: Res<Assets<BakedFoliage>>,
    store: Res<FoliageStore>,
    trees: Query<
        (
            Entity,
            &PrunedFoliage,
            &PruningParams,
            Option<&Mesh3d>,
            Option<&MeshMaterial3d<LeafMaterial>>,
        ),
        (With<FoliageSlot>, Without<ManagedPruning>),
    >,
) {
    let (mut drawn, mut full, mut count) = (0u64, 0u64, 0u32);
    for (entity, pruned, params, mesh, material) in &trees {
        let Some(tree) = baked.get(&pruned.baked) else {
            continue;
        };
        let kept = kept_index_total(
            &tree.pruning_input(),
            &params.weights,
            params.distance_fixed,
        );
        drawn += kept as u64 / 3;
        full += tree.indices.len() as u64 / 3;
        count += 1;
        let quads = store.types.get(&pruned.baked.id()).is_some_and(|t| t.quads);
        let handle = slot_meshes.fitting(kept, tree.indices.len() as u32, quads, &mut meshes);
        let mut e = commands.entity(entity);
        if mesh.map(|m| m.0.id()) != Some(handle.id()) {
            e.insert((Mesh3d(handle), NoFrustumCulling));
        }
        if material.map(|m| m.0.id()) != Some(pruned.material.id()) {
            e.insert(MeshMaterial3d(pruned.material.clone()));
        }
    }
    diagnostics.add_measurement(&TRIANGLES_DRAWN, || drawn as f64);
    diagnostics.add_measurement(&TRIANGLES_FULL, || full as f64);
    diagnostics.add_measurement(&TREES_PRUNED, || count as f64);
    diagnostics.add_measurement(&KEPT_PERCENT, || {
        if full == 0 {
            100.0
        } else {
            100.0 * drawn as f64 / full as f64
        }
    });
}

/// Points every leaf material in use at the current pruning buffers and settings.
pub fn refresh_leaf_materials(
    store: Res<FoliageStore>,
    settings: Res<FoliagePruningSettings>,
    mut materials: ResMut<Assets<LeafMaterial>>,
    trees: Query<&PrunedFoliage>,
    forest: Query<&crate::forest::plugin::ForestTree>,
    mut seen: Local<(u32, Vec<AssetId<LeafMaterial>>)>,
) {
    let mut ids: Vec<AssetId<LeafMaterial>> = trees
        .iter()
        .map(|t| t.material.id())
        .chain(forest.iter().map(|t| t.material.id()))
        .collect();
    ids.sort();
    ids.dedup();
    let changed = store.is_changed() && seen.0 != store.generation;
    for id in &ids {
        let fresh = !seen.1.contains(id);
        let Some(material) = materials.get(*id) else {
            continue;
        };
        let params = LeafParams {
            area_compensation: settings.area_compensation as u32,
            subpixel_fade: settings.subpixel_fade as u32,
            max_scale: settings.max_leaf_scale,
            fade_start: settings.fade_start_pixels,
            fade_end: settings.fade_end_pixels,
            ..material.extension.params
        };
        let b = &store.buffers;
        let ext = &material.extension;
        let soft_visibility = ext.soft_visibility.clone();
        if fresh
            || changed
            || ext.params != params
            || ext.output != b.output
            || ext.leaf_vertices != b.leaf_vertices
        {
            let mut material = materials.get_mut(*id).unwrap();
            material.extension = LeafExtension {
                instances: b.instances.clone(),
                output: b.output.clone(),
                draws: b.draws.clone(),
                cell_offsets: b.cell_offsets.clone(),
                leaf_vertices: b.leaf_vertices.clone(),
                cell_full: b.cell_full.clone(),
                params,
                soft_visibility,
            };
        }
    }
    *seen = (store.generation, ids);
}

/// Keeps the soft-shadow leaf fragment stage loaded.
#[derive(Resource)]
#[allow(dead_code)]
struct LeafSoftShader(Handle<bevy::shader::Shader>);

/// Registers the leaf material and its systems.
pub(crate) fn build(app: &mut App) {
    load_shader_library!(app, "leaf_pulling.wgsl");
    embedded_asset!(app, "leaf.wgsl");
    embedded_asset!(app, "leaf_prepass.wgsl");
    embedded_asset!(app, "leaf_soft_fragment.wgsl");
    let soft: Handle<bevy::shader::Shader> =
        bevy::asset::load_embedded_asset!(app, "leaf_soft_fragment.wgsl");
    let _ = LEAF_SOFT_SHADER.set(soft.clone());
    app.insert_resource(LeafSoftShader(soft));
    for path in [TRIANGLES_DRAWN, TRIANGLES_FULL, KEPT_PERCENT, TREES_PRUNED] {
        app.register_diagnostic(Diagnostic::new(path).with_max_history_length(1));
    }
    app.add_plugins(MaterialPlugin::<LeafMaterial>::default())
        .init_resource::<SlotMeshes>()
        .add_systems(
            PostUpdate,
            (assign_slot_meshes, refresh_leaf_materials)
                .after(super::gpu::update_foliage_store)
                .before(bevy::camera::visibility::VisibilitySystems::CheckVisibility),
        );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_hold_the_count_and_waste_under_half() {
        for primitives in [0u32, 1, 63, 64, 65, 1000, 32_000, 262_084] {
            let b = slot_bucket(primitives);
            assert!(b >= primitives, "{primitives} -> {b}");
            if primitives > 64 {
                assert!((b as f64) < 1.42 * primitives as f64, "{primitives} -> {b}");
            }
        }
        assert_eq!(bucket_size(0), 64);
        assert_eq!(bucket_size(2), 128);
    }

    #[test]
    fn quad_slot_meshes_index_four_vertices_per_leaf() {
        let mesh = slot_mesh(2, true);
        let indices: Vec<usize> = mesh.indices().unwrap().iter().collect();
        assert_eq!(indices, vec![0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7]);
        assert_eq!(mesh.count_vertices(), 8);
        let triangles = slot_mesh(2, false);
        assert!(triangles.indices().is_none());
        assert_eq!(triangles.count_vertices(), 6);
    }
}
