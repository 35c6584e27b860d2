//! Main-world systems of pruning: each frame they compute every tree's pruning inputs from the
//! pruning camera (the thesis' `FindCameras` also runs on the host), give each tree the slot
//! mesh that fits its kept count, keep the leaf materials bound to the current buffers, and
//! publish the leaf counts as diagnostics.

use super::bake::BakedFoliage;
use super::components::{FoliageCamera, ManagedPruning, PrunedFoliage, PruningParams};
use super::extract::{
    FIXED_ONE, KEEP_ALL, ViewWeights, distance_factor_fixed, kept_index_total, view_weights,
};
use super::material::{LeafExtension, LeafMaterial, LeafParams};
use super::slot_mesh::SlotMeshes;
use super::store::{FoliageSlot, FoliageStore};
use crate::settings::FoliagePruningSettings;
use bevy::camera::visibility::NoFrustumCulling;
use bevy::diagnostic::{DiagnosticPath, Diagnostics};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;

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

/// Points every leaf material at the current pruning buffers and settings. Every
/// [`LeafMaterial`] asset is kept bound, whoever draws with it (single pruned trees, forest trees).
pub fn refresh_leaf_materials(
    store: Res<FoliageStore>,
    settings: Res<FoliagePruningSettings>,
    mut materials: ResMut<Assets<LeafMaterial>>,
    mut seen: Local<(u32, Vec<AssetId<LeafMaterial>>)>,
) {
    let mut ids: Vec<AssetId<LeafMaterial>> = materials.ids().collect();
    ids.sort();
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
                params,
                soft_visibility,
            };
        }
    }
    *seen = (store.generation, ids);
}

/// The order of the foliage systems in `PostUpdate`, for plugins that draw from the pruning
/// store (the forest manager) to place themselves.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FoliageSystems {
    /// Pruning inputs of every tree ([`compute_pruning_params`]); after transform propagation.
    PruningParams,
    /// Buffer layout: tree types uploaded, instance slots assigned ([`update_foliage_store`]).
    ///
    /// [`update_foliage_store`]: super::store::update_foliage_store
    Store,
    /// Slot meshes, tags and materials of the drawn trees ([`assign_slot_meshes`],
    /// [`refresh_leaf_materials`]); before visibility checking.
    Draw,
}
