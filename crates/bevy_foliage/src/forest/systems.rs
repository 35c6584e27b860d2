//! The forest's main-world systems: [`ForestTree`] instances drawn from per-type LoD caches that the
//! [`ForestManager`] fills under a frame budget.
//!
//! How it maps onto the pruning pass: each cache slot (and copy) of a tree type is an
//! *extraction* — a hidden [`PrunedFoliage`] entity marked [`ManagedPruning`], whose
//! [`PruningParams`] the manager sets when it (re-)extracts the slot (from the viewpoint and
//! desired LoD of the tree it extracts for) and otherwise leaves alone. The pruning pass writes
//! each extraction's kept indices into its region; a forest tree draws a slot mesh whose
//! `MeshTag` names the extraction it borrows, placed by its own transform. So GPU memory holds
//! one kept-index region per slot and type, not one per tree (the pool of spec F2), and a whole
//! forest of one type is drawn from a handful of extractions.
//!
//! The pruning pass runs before any camera draws in the same frame, so an extraction is never
//! read while being written; the double-buffered cache variant (`double_buffered`) still keeps two
//! copies per slot and lends only last frame's, as the thesis' GPU version does.
//!
//! Trees outside the frustum (or at LoD 0) are hidden, so they draw nothing and cast no shadow.

use super::cache::{LodSlots, SLOT_LOD_ONE, SLOT_LOD_ZERO};
use super::components::{ForestBudget, ForestSettings, ForestTree, TreeLod};
use super::feedback::ExponentController;
use super::manager::{Budget, ForestManager, Frustum, ManagerSettings, TreeInput, TreeLodState};
use super::mixed::{MixedReport, MixedTree, Representation, select};
use crate::impostor::assets::BillboardCloudAsset;
use crate::impostor::systems::{ImpostorSettings, TreeImpostor};
use crate::pruning::bake::BakedFoliage;
use crate::pruning::components::{
    FoliageCamera, FoliageShadowLight, ManagedPruning, PrunedFoliage, PruningParams,
};
use crate::pruning::extract::{KEEP_ALL, view_weights};
use crate::pruning::material::LeafMaterial;
use crate::pruning::selection::{Selection, ShadowLight, factor_fixed};
use crate::pruning::slot_mesh::SlotMeshes;
use crate::pruning::store::{FoliageSlot, mesh_tag};
use crate::pruning::systems::{drawn_indices, pruning_camera};
use crate::settings::FoliagePruningSettings;
use bevy::camera::visibility::NoFrustumCulling;
use bevy::diagnostic::{DiagnosticPath, Diagnostics};
use bevy::mesh::MeshTag;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use std::time::{Duration, Instant};

/// The manager and its bookkeeping.
#[derive(Resource)]
pub struct ForestState {
    /// The manager (one cache per type, in `types` order).
    pub manager: ForestManager,
    /// Tree types by index.
    pub types: Vec<AssetId<BakedFoliage>>,
    /// Per type, the crown's bounding sphere in model space (centre, radius), computed once.
    pub type_spheres: Vec<(Vec3, f32)>,
    /// Extraction entities by (type, slot, copy).
    pub extractions: HashMap<(usize, usize, usize), Entity>,
    /// The exponent controller.
    pub controller: ExponentController,
    /// What the last frame did.
    pub last: super::manager::FrameReport,
    /// Settings the manager was built with.
    built_with: Option<ForestSettings>,
    inputs: Vec<TreeInput>,
    states: Vec<TreeLodState>,
    entities: Vec<Entity>,
    extraction_list: Vec<super::manager::Extraction>,
    /// Per tree (in `inputs` order): full leaf triangles and billboard-cloud triangles.
    mixed_costs: Vec<(u32, Option<u32>)>,
    mixed_trees: Vec<MixedTree>,
    mixed_index: Vec<usize>,
    mixed_choices: Vec<Representation>,
    /// What the last mixed LoD selection did.
    pub mixed_last: MixedReport,
}

impl Default for ForestState {
    fn default() -> Self {
        Self {
            manager: ForestManager::new(0, LodSlots::uniform(1), 0, false),
            types: Vec::new(),
            type_spheres: Vec::new(),
            extractions: HashMap::default(),
            controller: ExponentController::default(),
            last: default(),
            built_with: None,
            inputs: Vec::new(),
            states: Vec::new(),
            entities: Vec::new(),
            extraction_list: Vec::new(),
            mixed_costs: Vec::new(),
            mixed_trees: Vec::new(),
            mixed_index: Vec::new(),
            mixed_choices: Vec::new(),
            mixed_last: MixedReport::default(),
        }
    }
}

impl ForestState {
    /// The index of tree type `id`, registering it (its crown sphere and an empty cache) when new.
    fn type_of(
        &mut self,
        id: AssetId<BakedFoliage>,
        data: &BakedFoliage,
        settings: &ForestSettings,
    ) -> usize {
        if let Some(ty) = self.types.iter().position(|t| *t == id) {
            return ty;
        }
        self.types.push(id);
        self.type_spheres
            .push((data.crown_center(), data.crown_radius()));
        let mut cache = self.manager.caches.first().cloned().unwrap_or_else(|| {
            let slots = settings.lod_slots().unwrap_or(LodSlots::uniform(8));
            super::cache::LodCache::new(
                slots,
                settings.max_age_frames as u64,
                settings.double_buffered,
            )
        });
        cache.clear();
        self.manager.caches.push(cache);
        self.types.len() - 1
    }
}

/// Extractions made this frame.
pub const EXTRACTIONS: DiagnosticPath = DiagnosticPath::const_new("forest/extractions");
/// Borrows made this frame.
pub const BORROWS: DiagnosticPath = DiagnosticPath::const_new("forest/borrows");
/// Trees in the view frustum.
pub const VISIBLE_TREES: DiagnosticPath = DiagnosticPath::const_new("forest/visible_trees");
/// Leaf triangles drawn by forest trees.
pub const LEAF_TRIANGLES: DiagnosticPath = DiagnosticPath::const_new("forest/leaf_triangles");
/// CPU time of the manager (ms).
pub const MANAGER_MS: DiagnosticPath = DiagnosticPath::const_new("forest/manager_ms");
/// Feedback exponent n.
pub const EXPONENT: DiagnosticPath = DiagnosticPath::const_new("forest/exponent");
/// Kept-index GPU bytes of the extractions, per visible tree.
pub const GPU_BYTES_PER_VISIBLE: DiagnosticPath =
    DiagnosticPath::const_new("forest/gpu_bytes_per_visible_tree");

/// Runs the forest manager: ranks the visible trees by urgency, serves them within the budget
/// (borrowing or re-extracting cache slots) and sets the extraction entities' pruning inputs.
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn run_forest_manager(
    mut commands: Commands,
    mut state: ResMut<ForestState>,
    settings: Res<ForestSettings>,
    pruning: Res<FoliagePruningSettings>,
    shadow_light: Res<FoliageShadowLight>,
    time: Res<Time<Real>>,
    baked: Res<Assets<BakedFoliage>>,
    mut diagnostics: Diagnostics,
    marked: Query<(&Camera, &GlobalTransform), With<FoliageCamera>>,
    cameras: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    mut trees: Query<(
        Entity,
        &ForestTree,
        &GlobalTransform,
        &mut TreeLod,
        &mut Visibility,
        Option<&TreeImpostor>,
    )>,
    clouds: Res<Assets<BillboardCloudAsset>>,
    mut params: Query<&mut PruningParams, With<ManagedPruning>>,
    mut asset_events: MessageReader<AssetEvent<BakedFoliage>>,
) {
    let started = Instant::now();
    let state = &mut *state;
    // A tree type whose data changed: new crown sphere, and its cached extractions are stale.
    for event in asset_events.read() {
        if let AssetEvent::Modified { id } = event
            && let Some(ty) = state.types.iter().position(|t| t == id)
            && let Some(data) = baked.get(*id)
        {
            state.type_spheres[ty] = (data.crown_center(), data.crown_radius());
            if let Some(cache) = state.manager.caches.get_mut(ty) {
                cache.clear();
            }
        }
    }
    // (Re)build the caches when the slot settings change.
    if state.built_with.as_ref().is_none_or(|b| {
        b.slots != settings.slots
            || b.slot_bounds != settings.slot_bounds
            || b.max_age_frames != settings.max_age_frames
            || b.double_buffered != settings.double_buffered
            || b.borrowing != settings.borrowing
            || b.enabled != settings.enabled
    }) {
        let slots = settings.lod_slots().unwrap_or_else(|e| {
            warn!(
                "ForestSettings: {e}; using {} uniform slots",
                settings.slots.max(1)
            );
            LodSlots::uniform(settings.slots.max(1))
        });
        let types = state.types.len();
        state.manager = ForestManager::new(
            types,
            slots,
            settings.max_age_frames as u64,
            settings.double_buffered,
        );
        for (_, entity) in state.extractions.drain() {
            commands.entity(entity).despawn();
        }
        for (_, _, _, mut lod, ..) in &mut trees {
            *lod = TreeLod::default();
        }
        state.states.clear();
        state.entities.clear();
        state.built_with = Some(settings.clone());
    }
    let Some((clip_from_world, camera, view)) = pruning_camera(&marked, &cameras) else {
        return;
    };
    let frustum = Frustum::from_clip_from_world(clip_from_world);

    // Gather the trees (new types get a cache).
    state.inputs.clear();
    state.entities.clear();
    state.states.clear();
    state.mixed_costs.clear();
    // Assets are looked up once per type and impostor per frame, not once per tree: at 100,000
    // trees the per-tree lookups were most of the manager's CPU time.
    let mut known_types: Vec<(AssetId<BakedFoliage>, Option<(usize, u32)>)> = Vec::new();
    let mut known_clouds: Vec<(AssetId<BillboardCloudAsset>, Option<u32>)> = Vec::new();
    for (entity, tree, transform, lod, _, impostor) in &trees {
        let id = tree.baked.id();
        let known = match known_types.iter().find(|(t, _)| *t == id) {
            Some(&(_, known)) => known,
            None => {
                let known = baked.get(id).map(|data| {
                    (
                        state.type_of(id, data, &settings),
                        data.indices.len() as u32 / 3,
                    )
                });
                known_types.push((id, known));
                known
            }
        };
        let Some((ty, leaf_triangles)) = known else {
            continue;
        };
        let cloud_triangles = impostor.and_then(|i| {
            let id = i.0.id();
            match known_clouds.iter().find(|(c, _)| *c == id) {
                Some(&(_, triangles)) => triangles,
                None => {
                    let triangles = clouds.get(id).map(|c| c.planes * 2);
                    known_clouds.push((id, triangles));
                    triangles
                }
            }
        });
        state.mixed_costs.push((leaf_triangles, cloud_triangles));
        let affine = transform.affine();
        // The largest axis scale: the longest basis column (what `scale().abs().max_element()`
        // gives, without decomposing the rotation).
        let scale = affine
            .matrix3
            .x_axis
            .length_squared()
            .max(affine.matrix3.y_axis.length_squared())
            .max(affine.matrix3.z_axis.length_squared())
            .sqrt();
        let (crown_center, crown_radius) = state.type_spheres[ty];
        let (center, radius) = if affine.is_finite() && scale > 0.0 {
            (affine.transform_point3(crown_center), crown_radius * scale)
        } else {
            // Not placeable: never visible.
            (Vec3::splat(f32::INFINITY), 0.0)
        };
        state.inputs.push(TreeInput { ty, center, radius });
        state.entities.push(entity);
        // What the manager remembers of it, kept on the tree itself.
        state.states.push(lod.state);
    }

    // A forest with no trees left holds no extractions: nothing is pruned for it.
    if state.entities.is_empty() && !state.extractions.is_empty() {
        for (_, entity) in state.extractions.drain() {
            commands.entity(entity).despawn();
        }
        for cache in &mut state.manager.caches {
            cache.clear();
        }
    }

    // The feedback exponent.
    let exponent = if settings.feedback {
        let (fixed, _) = settings.feedback_settings.sanitized();
        state.controller.update(time.delta_secs() * 1000.0, &fixed)
    } else {
        state.controller = ExponentController::default();
        if settings.exponent.is_finite() && settings.exponent > 0.0 {
            settings.exponent
        } else {
            1.0
        }
    };

    let manager_settings = ManagerSettings {
        distances: pruning.distances,
        view,
        // 1 m, or a crown filling the view height.
        min_distance: 1.0,
        borrowing: settings.borrowing,
    };
    let budget = match settings.budget {
        ForestBudget::Extractions(n) => Budget::Extractions(n),
        ForestBudget::Milliseconds(ms) => {
            Budget::Time(Duration::from_secs_f32(ms.clamp(0.0, 1000.0) / 1000.0))
        }
    };
    // The time-critical mixed LoD picks every visible tree's representation under the budget;
    // the manager then serves the geometry LoDs it chose.
    if settings.enabled && settings.mixed.enabled {
        choose_mixed_lods(state, &settings.mixed, camera, &view, &frustum);
    } else {
        state.manager.desired_override.clear();
        for s in &mut state.states {
            s.impostor_weight = 0.0;
        }
    }
    state.extraction_list.clear();
    let report = if settings.enabled {
        let ForestState {
            manager,
            inputs,
            states,
            extraction_list,
            ..
        } = state;
        manager.run_frame(
            inputs,
            states,
            camera,
            Some(&frustum),
            exponent,
            &manager_settings,
            budget,
            extraction_list,
        )
    } else {
        let mut report_visible = 0;
        // Manager off: every tree the manager would show (in the frustum, nearer than `far`)
        // draws every leaf, from one extraction per type.
        for (i, s) in state.states.iter_mut().enumerate() {
            let tree = state.inputs[i];
            s.visible = tree.center.is_finite()
                && pruning
                    .distances
                    .lod_distance(tree.center.distance(camera), tree.radius, &view)
                    < pruning.distances.range().1
                && frustum.intersects_sphere(tree.center, tree.radius);
            if s.visible {
                report_visible += 1;
            }
            if s.slot != Some(SLOT_LOD_ONE) {
                s.slot = Some(SLOT_LOD_ONE);
                s.stored_lod = 1.0;
                state.extraction_list.push(super::manager::Extraction {
                    tree: i,
                    ty: tree.ty,
                    slot: SLOT_LOD_ONE,
                    copy: 0,
                    lod: 1.0,
                });
            }
        }
        super::manager::FrameReport {
            visible: report_visible,
            ..default()
        }
    };
    // Without borrowing every tree extracts its own LoD: its extraction is keyed by the tree.
    let per_tree = settings.enabled && !settings.borrowing;

    // Perform the extractions: set (or create) the extraction entities' pruning inputs.
    let mut done: Vec<(usize, usize, usize)> = Vec::new();
    for e in state.extraction_list.iter().rev() {
        let key = if per_tree {
            (e.ty, usize::MAX, state.entities[e.tree].to_bits() as usize)
        } else {
            (e.ty, e.slot, e.copy)
        };
        if !per_tree && !settings.enabled && done.contains(&key) {
            continue;
        }
        done.push(key);
        let tree_entity = state.entities[e.tree];
        let Ok((_, tree, transform, ..)) = trees.get(tree_entity) else {
            continue;
        };
        let Some(data) = baked.get(&tree.baked) else {
            continue;
        };
        let local_from_world = transform.affine().inverse();
        let crown_center = state.type_spheres[e.ty].0;
        let weights_towards = |direction: Vec3| {
            view_weights(direction, &data.view_directions, pruning.view_weighting)
        };
        let new = if !settings.enabled || !pruning.enabled || e.slot == SLOT_LOD_ONE {
            // Full detail: every leaf, as with pruning off, and shadows draw the same. The
            // exact LoD 1 slot is full detail too: it holds the trees nearer than `near`, which
            // cover the most pixels and may stand around the camera, where visibility baked from
            // viewpoints outside the crown does not apply.
            PruningParams {
                camera: Selection {
                    weights: weights_towards(
                        local_from_world.transform_point3(camera) - crown_center,
                    ),
                    distance_fixed: KEEP_ALL,
                },
                light: None,
            }
        } else {
            let distance_fixed = factor_fixed(e.lod);
            PruningParams {
                camera: Selection {
                    weights: weights_towards(
                        local_from_world.transform_point3(camera) - crown_center,
                    ),
                    distance_fixed,
                },
                // The light's own selection at the same LoD, seen from the tree extracted for
                // (trees borrowing it stand turned otherwise, as for the camera's).
                light: shadow_light
                    .0
                    .filter(|_| pruning.shadow_selection)
                    .map(|light| Selection {
                        weights: weights_towards(match light {
                            ShadowLight::Directional { toward_light } => {
                                local_from_world.transform_vector3(toward_light)
                            }
                            ShadowLight::Positional { position } => {
                                local_from_world.transform_point3(position) - crown_center
                            }
                        }),
                        distance_fixed,
                    }),
            }
        };
        match state.extractions.get(&key) {
            Some(&entity) => {
                if let Ok(mut p) = params.get_mut(entity) {
                    *p = new;
                } else {
                    commands.entity(entity).insert(new);
                }
            }
            None => {
                let entity = commands
                    .spawn((
                        Name::new(format!("forest extraction {key:?}")),
                        PrunedFoliage {
                            baked: tree.baked.clone(),
                            material: tree.material.clone(),
                        },
                        ManagedPruning,
                        new,
                        Visibility::Hidden,
                    ))
                    .id();
                state.extractions.insert(key, entity);
            }
        }
    }
    if per_tree {
        // Trees gone from the forest release their extraction.
        let alive: bevy::platform::collections::HashSet<usize> = state
            .entities
            .iter()
            .map(|e| e.to_bits() as usize)
            .collect();
        state.extractions.retain(|&(_, slot, tree), entity| {
            let keep = slot != usize::MAX || alive.contains(&tree);
            if !keep {
                commands.entity(*entity).despawn();
            }
            keep
        });
    }

    // Write back the per-tree state, walking the query in the order the trees were gathered.
    let mut i = 0;
    for (entity, _, _, mut lod, mut visibility, _) in &mut trees {
        if state.entities.get(i) != Some(&entity) {
            // Skipped when gathered (its baked data is not loaded).
            continue;
        }
        let s = state.states[i];
        i += 1;
        let new = TreeLod {
            slot: s.slot.map(|x| x as u32),
            stored_lod: s.stored_lod,
            desired_lod: s.desired_lod,
            frames_since_update: s.frames_since_update,
            urgency: s.urgency,
            visible: s.visible,
            impostor_weight: s.impostor_weight,
            state: s,
        };
        if *lod != new {
            *lod = new;
        }
        // Where its leaves are gone the tree is hidden, bark and all (the bark has faded out by
        // then); its billboard cloud is an entity of its own beside it.
        let shown = s.visible && !ForestManager::draws_nothing(&s);
        let v = if shown {
            Visibility::Inherited
        } else {
            Visibility::Hidden
        };
        if *visibility != v {
            *visibility = v;
        }
    }
    state.last = report;
    let elapsed = started.elapsed().as_secs_f64() * 1e3;
    diagnostics.add_measurement(&EXTRACTIONS, || report.extractions as f64);
    diagnostics.add_measurement(&BORROWS, || report.borrows as f64);
    diagnostics.add_measurement(&VISIBLE_TREES, || report.visible as f64);
    diagnostics.add_measurement(&MANAGER_MS, || elapsed);
    diagnostics.add_measurement(&EXPONENT, || exponent as f64);
}

/// The mixed LoD of one frame: the selection over the visible trees, each tree's fade between
/// its representations advanced by one frame, and the manager's desired LoDs set from them (a
/// tree fading to its impostor keeps its last geometry resolution, scaled down as it fades).
fn choose_mixed_lods(
    state: &mut ForestState,
    mixed: &super::components::MixedLodSettings,
    camera: Vec3,
    view: &crate::distance::LodView,
    frustum: &Frustum,
) {
    state.mixed_trees.clear();
    state.mixed_index.clear();
    for (i, tree) in state.inputs.iter().enumerate() {
        let d = tree.center.distance(camera);
        if !(d.is_finite() && frustum.intersects_sphere(tree.center, tree.radius)) {
            continue;
        }
        let size = if view.orthographic {
            tree.radius * view.yy
        } else {
            tree.radius * view.yy / d.max(1e-3)
        };
        let (leaf_triangles, impostor_triangles) = state.mixed_costs[i];
        state.mixed_trees.push(MixedTree {
            screen_size: size,
            leaf_triangles,
            impostor_triangles,
        });
        state.mixed_index.push(i);
    }
    let report = select(
        &state.mixed_trees,
        &mixed.selection(),
        &mut state.mixed_choices,
    );
    state.mixed_last = report;
    let step = 1.0 / mixed.fade_frames.max(1) as f32;
    let n = state.inputs.len();
    let mut desired = vec![0.0; n];
    let mut chosen = vec![None; n];
    for (k, &i) in state.mixed_index.iter().enumerate() {
        chosen[i] = Some(state.mixed_choices[k]);
    }
    for (i, s) in state.states.iter_mut().enumerate() {
        match chosen[i] {
            Some(Representation::Geometry(x)) => {
                s.geometry_lod = x;
                s.impostor_weight = (s.impostor_weight - step).max(0.0);
            }
            Some(Representation::Impostor) => {
                s.impostor_weight = (s.impostor_weight + step).min(1.0);
            }
            // Out of view: whatever it shows next is decided when it is back; no fade needed.
            None => {}
        }
        desired[i] = if chosen[i].is_some() {
            s.geometry_lod * (1.0 - s.impostor_weight)
        } else {
            0.0
        };
    }
    state.manager.desired_override = desired;
}

/// With [`ImpostorSettings::show_representation`], the tints of trees drawn by leaf geometry, by
/// LoD band ([`geometry_band`]): full detail blue, then cyan, green and magenta as pruning keeps
/// fewer leaves. Billboard clouds are tinted orange.
pub const GEOMETRY_TINTS: [Color; 4] = [
    Color::srgb(0.25, 0.45, 1.0),
    Color::srgb(0.2, 0.9, 0.9),
    Color::srgb(0.35, 0.9, 0.2),
    Color::srgb(0.9, 0.3, 0.9),
];

/// The LoD band of leaf geometry drawn at `lod`, an index into [`GEOMETRY_TINTS`]: 0 full detail,
/// 1 from one half, 2 from one quarter, 3 below.
pub fn geometry_band(lod: f32) -> usize {
    if lod >= 0.999 {
        0
    } else if lod >= 0.5 {
        1
    } else if lod >= 0.25 {
        2
    } else {
        3
    }
}

/// Points every shown forest tree at the extraction it draws: its `MeshTag` (the extraction's
/// instance slot) and the slot mesh that fits the extraction's kept count.
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn draw_forest_trees(
    mut commands: Commands,
    state: Res<ForestState>,
    settings: Res<ForestSettings>,
    baked: Res<Assets<BakedFoliage>>,
    mut slot_meshes: ResMut<SlotMeshes>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut diagnostics: Diagnostics,
    extractions: Query<(&FoliageSlot, &PruningParams, &PrunedFoliage), With<ManagedPruning>>,
    impostor_settings: Option<Res<ImpostorSettings>>,
    mut leaf_materials: ResMut<Assets<LeafMaterial>>,
    mut tinted: Local<Vec<(AssetId<LeafMaterial>, usize, Handle<LeafMaterial>)>>,
    trees: Query<(
        Entity,
        &ForestTree,
        &TreeLod,
        &Visibility,
        Option<&MeshTag>,
        Option<&Mesh3d>,
        Option<&MeshMaterial3d<LeafMaterial>>,
    )>,
) {
    let per_tree = settings.enabled && !settings.borrowing;
    // Each tree's index in the manager's lists: found by walking in step (both queries visit the
    // trees in the same order unless one changed archetype in between), by a map otherwise.
    let mut index: Option<HashMap<Entity, usize>> = None;
    let mut cursor = 0;
    let mut kept_cache: HashMap<Entity, (u32, u32, u32, u32)> = HashMap::default();
    let show = impostor_settings
        .as_ref()
        .is_some_and(|i| i.show_representation);
    let (mut triangles, mut visible) = (0u64, 0u32);
    for (entity, tree, lod, visibility, tag, mesh, material) in &trees {
        let i = if state.entities.get(cursor) == Some(&entity) {
            cursor += 1;
            cursor - 1
        } else {
            let map = index.get_or_insert_with(|| {
                state
                    .entities
                    .iter()
                    .enumerate()
                    .map(|(i, e)| (*e, i))
                    .collect()
            });
            match map.get(&entity) {
                Some(&i) => {
                    cursor = i + 1;
                    i
                }
                None => continue,
            }
        };
        if *visibility == Visibility::Hidden {
            continue;
        }
        let Some(slot) = lod.slot.map(|s| s as usize) else {
            continue;
        };
        if slot == SLOT_LOD_ZERO {
            continue;
        }
        let s = state.states[i];
        let ty = state.inputs[i].ty;
        let key = if per_tree {
            (ty, usize::MAX, entity.to_bits() as usize)
        } else {
            (ty, slot, s.copy)
        };
        let Some(&extraction) = state.extractions.get(&key) else {
            continue;
        };
        let Ok((foliage_slot, params, pruned)) = extractions.get(extraction) else {
            // Created this frame: its slot is assigned next frame.
            continue;
        };
        let (tag_value, kept, bound, full) = *kept_cache.entry(extraction).or_insert_with(|| {
            let tag = mesh_tag(foliage_slot.camera.slot, &foliage_slot.ty);
            let Some(data) = baked.get(&pruned.baked) else {
                return (tag, 0, 0, 0);
            };
            let (kept, shadow) = drawn_indices(data, params);
            (tag, kept, kept.max(shadow), data.indices.len() as u32)
        });
        visible += 1;
        triangles += kept as u64 / 3;
        let handle = slot_meshes.fitting(bound, full, foliage_slot.ty.quads, &mut meshes);
        let mut e = commands.entity(entity);
        if tag.map(|t| t.0) != Some(tag_value) {
            e.insert(MeshTag(tag_value));
        }
        if mesh.map(|m| m.0.id()) != Some(handle.id()) {
            e.insert((Mesh3d(handle), NoFrustumCulling));
        }
        let wanted = if show {
            // The tree's own material tinted by the LoD band it draws (one copy per band).
            let band = geometry_band(s.stored_lod);
            let source = tree.material.id();
            match tinted.iter().find(|(m, b, _)| *m == source && *b == band) {
                Some((.., handle)) => handle.clone(),
                None => {
                    let mut m = leaf_materials.get(source).cloned().unwrap_or_else(|| {
                        crate::pruning::material::leaf_material(StandardMaterial::default())
                    });
                    m.base.base_color = GEOMETRY_TINTS[band];
                    let handle = leaf_materials.add(m);
                    tinted.push((source, band, handle.clone()));
                    handle
                }
            }
        } else {
            tree.material.clone()
        };
        if material.map(|m| m.0.id()) != Some(wanted.id()) {
            e.insert(MeshMaterial3d(wanted));
        }
    }
    // Kept-index bytes of the extraction regions (each holds up to its type's full count).
    let bytes: u64 = state
        .extractions
        .values()
        .filter_map(|e| extractions.get(*e).ok())
        .map(|(s, ..)| s.ty.full_index_count as u64 * 4 * (1 + s.light.is_some() as u64))
        .sum();
    diagnostics.add_measurement(&LEAF_TRIANGLES, || triangles as f64);
    diagnostics.add_measurement(&GPU_BYTES_PER_VISIBLE, || {
        bytes as f64 / visible.max(1) as f64
    });
}

/// Replaces unusable [`ForestSettings`] values, with a warning for each.
pub fn sanitize_forest_settings(mut settings: ResMut<ForestSettings>) {
    let (fixed, fixes) = settings.sanitized();
    if !fixes.is_empty() {
        for fix in &fixes {
            warn!("ForestSettings: {fix}");
        }
        *settings = fixed;
    }
}
