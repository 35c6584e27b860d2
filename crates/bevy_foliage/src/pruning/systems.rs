//! Main-world systems of pruning: each frame they compute every tree's pruning inputs from the
//! pruning camera (the thesis' `FindCameras` also runs on the host), give each tree the slot
//! mesh that fits its kept count, keep the leaf materials bound to the current buffers, and
//! publish the leaf counts as diagnostics.

use super::bake::BakedFoliage;
use super::components::{
    FoliageCamera, FoliageLight, FoliageShadowLight, ManagedPruning, PrunedFoliage, PruningParams,
};
use super::extract::kept_index_total;
use super::material::{LeafExtension, LeafMaterial, LeafParams, TreeLightUniform};
use super::selection::{ShadowLight, TreeView, select};
use super::slot_mesh::SlotMeshes;
use super::store::{FoliageSlot, FoliageStore};
use crate::TreeLightingSettings;
use crate::distance::LodView;
use crate::lighting::model::SunThroughCrown;
use crate::settings::FoliagePruningSettings;
use bevy::camera::visibility::NoFrustumCulling;
use bevy::diagnostic::{DiagnosticPath, Diagnostics};
use bevy::light::NotShadowCaster;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;

/// The pruning camera: the one marked [`FoliageCamera`], else the active 3D camera with the
/// lowest `order`. Returns its position and the LoD view of its projection.
pub fn pruning_camera(
    marked: &Query<(&Camera, &GlobalTransform), With<FoliageCamera>>,
    cameras: &Query<(&Camera, &GlobalTransform), With<Camera3d>>,
) -> Option<(Mat4, Vec3, LodView)> {
    let (camera, transform) = marked.iter().next().or_else(|| {
        cameras
            .iter()
            .filter(|(c, _)| c.is_active)
            .min_by_key(|(c, _)| c.order)
    })?;
    let clip_from_view = camera.clip_from_view();
    Some((
        clip_from_view * transform.to_matrix().inverse(),
        transform.translation(),
        LodView::from_clip_from_view(clip_from_view),
    ))
}

/// Finds the light whose shadow views draw the light's leaf selection: the one marked
/// [`FoliageLight`], else the first shadow-casting directional light, spot light, point light.
#[allow(clippy::type_complexity)]
pub fn track_shadow_light(
    mut shadow: ResMut<FoliageShadowLight>,
    marked: Query<(Entity, &GlobalTransform, Has<DirectionalLight>), With<FoliageLight>>,
    directional: Query<(Entity, &DirectionalLight, &GlobalTransform)>,
    spots: Query<(Entity, &SpotLight, &GlobalTransform)>,
    points: Query<(Entity, &PointLight, &GlobalTransform)>,
) {
    let toward = |t: &GlobalTransform| ShadowLight::Directional {
        toward_light: -t.forward().as_vec3(),
    };
    let at = |t: &GlobalTransform| ShadowLight::Positional {
        position: t.translation(),
    };
    let found = marked
        .iter()
        .min_by_key(|(e, ..)| *e)
        .map(|(_, t, is_directional)| if is_directional { toward(t) } else { at(t) })
        .or_else(|| {
            directional
                .iter()
                .filter(|(_, l, _)| l.shadow_maps_enabled)
                .min_by_key(|(e, ..)| *e)
                .map(|(_, _, t)| toward(t))
        })
        .or_else(|| {
            spots
                .iter()
                .filter(|(_, l, _)| l.shadow_maps_enabled)
                .min_by_key(|(e, ..)| *e)
                .map(|(_, _, t)| at(t))
        })
        .or_else(|| {
            points
                .iter()
                .filter(|(_, l, _)| l.shadow_maps_enabled)
                .min_by_key(|(e, ..)| *e)
                .map(|(_, _, t)| at(t))
        })
        .filter(|l| match l {
            ShadowLight::Directional { toward_light } => toward_light.is_finite(),
            ShadowLight::Positional { position } => position.is_finite(),
        });
    if shadow.0 != found {
        shadow.0 = found;
    }
}

/// Computes [`PruningParams`] for every pruned tree from the pruning camera and the shadow
/// light ([`super::selection`]).
#[allow(clippy::too_many_arguments)]
pub fn compute_pruning_params(
    mut commands: Commands,
    mut asset_events: MessageReader<AssetEvent<BakedFoliage>>,
    settings: Res<FoliagePruningSettings>,
    shadow_light: Res<FoliageShadowLight>,
    baked: Res<Assets<BakedFoliage>>,
    marked: Query<(&Camera, &GlobalTransform), With<FoliageCamera>>,
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
    opacity_map: Option<Res<bevy_soft_shadows::foliage::receiver::TreeOpacityActive>>,
) {
    // Leaves cast through the trees' opacity shadow map: the light's selection keeps every
    // cell's share (see `Selection::without_view_term`).
    let transmittance = opacity_map.is_some_and(|a| a.0);
    for event in asset_events.read() {
        if let AssetEvent::Modified { id } | AssetEvent::Removed { id } = event {
            crowns.remove(id);
        }
    }
    let Some((_, camera, view)) = pruning_camera(&marked, &cameras) else {
        return;
    };
    for (entity, pruned, transform, params) in &mut trees {
        let Some(tree) = baked.get(&pruned.baked) else {
            continue;
        };
        // The crown sphere, once per tree type (and again if the asset changes).
        let (crown_center, crown_radius) = *crowns
            .entry(pruned.baked.id())
            .or_insert_with(|| (tree.crown_center(), tree.crown_radius()));
        let (camera_selection, light) = select(
            &TreeView {
                view_directions: &tree.view_directions,
                crown_center,
                crown_radius,
                world_from_local: transform.affine(),
            },
            camera,
            &view,
            shadow_light.0,
            &settings,
        );
        let new = PruningParams {
            camera: camera_selection,
            light: light.map(|l| {
                if transmittance {
                    l.without_view_term()
                } else {
                    l
                }
            }),
        };
        match params {
            Some(mut p) => {
                if *p != new {
                    *p = new;
                }
            }
            None => {
                // A tree that cannot be placed draws nothing; say so once, on insertion.
                let affine = transform.affine();
                if !affine.is_finite() || affine.matrix3.determinant() == 0.0 {
                    warn!(
                        "PrunedFoliage {entity}: transform is not finite or singular; the tree is not drawn"
                    );
                }
                commands.entity(entity).insert(new);
            }
        }
    }
}

/// Indices a pruned tree draws this frame for the camera and for shadow views (the light's
/// selection, or the camera's when it has none). The slot mesh must hold both.
pub fn drawn_indices(tree: &BakedFoliage, params: &PruningParams) -> (u32, u32) {
    let input = tree.pruning_input();
    let camera = kept_index_total(&input, &params.camera.weights, params.camera.distance_fixed);
    let light = params.light.map_or(camera, |l| {
        kept_index_total(&input, &l.weights, l.distance_fixed)
    });
    (camera, light)
}

/// Leaf triangles drawn this frame, over all pruned trees.
pub const TRIANGLES_DRAWN: DiagnosticPath = DiagnosticPath::const_new("foliage/triangles_drawn");
/// Leaf triangles shadow views draw this frame (the shadow light's selections), over all pruned
/// trees.
pub const SHADOW_TRIANGLES_DRAWN: DiagnosticPath =
    DiagnosticPath::const_new("foliage/shadow_triangles_drawn");
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
    let (mut drawn, mut shadow_drawn, mut full, mut count) = (0u64, 0u64, 0u64, 0u32);
    for (entity, pruned, params, mesh, material) in &trees {
        let Some(tree) = baked.get(&pruned.baked) else {
            continue;
        };
        let (kept, shadow) = drawn_indices(tree, params);
        let bound = kept.max(shadow);
        drawn += kept as u64 / 3;
        shadow_drawn += shadow as u64 / 3;
        full += tree.indices.len() as u64 / 3;
        count += 1;
        let quads = store.types.get(&pruned.baked.id()).is_some_and(|t| t.quads);
        let handle = slot_meshes.fitting(bound, tree.indices.len() as u32, quads, &mut meshes);
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
    diagnostics.add_measurement(&SHADOW_TRIANGLES_DRAWN, || shadow_drawn as f64);
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
    lighting: Res<TreeLightingSettings>,
    ambient: Option<Res<GlobalAmbientLight>>,
    suns: Query<(&DirectionalLight, &GlobalTransform)>,
    mut materials: ResMut<Assets<LeafMaterial>>,
    mut seen: Local<(u32, Vec<AssetId<LeafMaterial>>)>,
) {
    let lights = tree_lights(
        &lighting,
        ambient.as_deref(),
        suns.iter().map(|(l, t)| (l, t.back().as_vec3())),
    );
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
            // The material's own.
            opaque_fraction: material.extension.params.opaque_fraction,
            albedo: LinearRgba::from(material.base.base_color).to_vec4(),
            ..lights
        };
        let b = &store.buffers;
        let ext = &material.extension;
        let soft_visibility = ext.soft_visibility.clone();
        if fresh
            || changed
            || ext.params != params
            || ext.output != b.output
            || ext.leaf_vertices != b.leaf_vertices
            || ext.leaf_light != b.leaf_light
        {
            let mut material = materials.get_mut(*id).unwrap();
            material.extension = LeafExtension {
                instances: b.instances.clone(),
                output: b.output.clone(),
                draws: b.draws.clone(),
                cell_offsets: b.cell_offsets.clone(),
                leaf_vertices: b.leaf_vertices.clone(),
                leaf_light: b.leaf_light.clone(),
                params,
                soft_visibility,
            };
        }
    }
    *seen = (store.generation, ids);
}

/// The tree lighting's part of the leaf materials' parameters (the rest default): the switches
/// and optics of `lighting`, the sky's radiance from the global ambient light (its colour times
/// its brightness), the ground's from the sky and the ground's albedo, and the sun — the
/// brightest of `suns` (each a light and its world direction towards the light; none: no sun).
pub fn tree_lights<'a>(
    lighting: &TreeLightingSettings,
    ambient: Option<&GlobalAmbientLight>,
    suns: impl Iterator<Item = (&'a DirectionalLight, Vec3)>,
) -> LeafParams {
    let sky = ambient
        .map(|a| LinearRgba::from(a.color).to_vec3() * a.brightness)
        .unwrap_or(Vec3::ZERO);
    let sun = suns
        .filter(|(l, d)| l.illuminance.is_finite() && l.illuminance > 0.0 && d.is_finite())
        .max_by(|a, b| a.0.illuminance.total_cmp(&b.0.illuminance));
    let (to_sun, sun) = match sun {
        Some((light, direction)) => (
            direction.normalize_or(Vec3::Y),
            LinearRgba::from(light.color).to_vec3() * light.illuminance,
        ),
        None => (Vec3::Y, Vec3::ZERO),
    };
    let optics = &lighting.optics;
    LeafParams {
        tree_lighting: lighting.enabled as u32,
        smooth_envelope: (lighting.sun_through_crown == SunThroughCrown::SmoothEnvelope) as u32,
        bounce: lighting.bounce as u32,
        seen_part: lighting.seen_part as u32,
        gathered_bounce: lighting.gathered_bounce as u32,
        bounce_ring: lighting.bounce_ring.enabled as u32,
        lights: TreeLightUniform {
            reflectance_front: optics.reflectance_front.extend(0.0),
            reflectance_back: optics.reflectance_back.extend(0.0),
            transmittance_front: optics.transmittance_front.extend(0.0),
            transmittance_back: optics.transmittance_back.extend(0.0),
            to_sun: to_sun.extend(0.0),
            sun: sun.extend(0.0),
            sky: sky.extend(0.0),
            ground: (sky * lighting.ground_albedo).extend(0.0),
        },
        ..default()
    }
}

/// Marks a pruned tree taken out of Bevy's shadow maps because its leaves cast through the
/// trees' opacity shadow map (`bevy_soft_shadows::foliage::TreeOpacityShadows`).
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct CastsThroughOpacityMap;

/// While a sun has a trees' opacity shadow map, pruned leaves cast through it only: they get
/// `NotShadowCaster` (else the ground under them would be darkened by Bevy's map and by the
/// opacity map); when the map goes, the leaves this system took out cast again.
#[allow(clippy::type_complexity)]
pub fn cast_leaves_through_opacity_map(
    mut commands: Commands,
    active: Option<Res<bevy_soft_shadows::foliage::receiver::TreeOpacityActive>>,
    trees: Query<
        (Entity, Has<CastsThroughOpacityMap>, Has<NotShadowCaster>),
        (With<PrunedFoliage>, Without<ManagedPruning>),
    >,
) {
    let on = active.is_some_and(|a| a.0);
    for (entity, marked, not_caster) in &trees {
        if on && !marked && !not_caster {
            commands
                .entity(entity)
                .insert((NotShadowCaster, CastsThroughOpacityMap));
        } else if !on && marked {
            commands
                .entity(entity)
                .remove::<(NotShadowCaster, CastsThroughOpacityMap)>();
        }
    }
}

/// The order of the foliage systems in `PostUpdate`, for plugins that draw from the pruning
/// store (the forest manager) to place themselves.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FoliageSystems {
    /// The shadow light ([`track_shadow_light`]) and the pruning inputs of every tree
    /// ([`compute_pruning_params`]); after transform propagation.
    PruningParams,
    /// Buffer layout: tree types uploaded, instance slots assigned ([`update_foliage_store`]).
    ///
    /// [`update_foliage_store`]: super::store::update_foliage_store
    Store,
    /// Slot meshes, tags and materials of the drawn trees ([`assign_slot_meshes`],
    /// [`refresh_leaf_materials`]); before visibility checking.
    Draw,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tree_lights_take_the_brightest_sun_and_the_global_ambient_light() {
        let lighting = TreeLightingSettings {
            enabled: true,
            ground_albedo: Vec3::new(0.5, 0.25, 0.0),
            ..default()
        };
        let ambient = GlobalAmbientLight {
            color: Color::WHITE,
            brightness: 2.0,
            ..default()
        };
        let dim = DirectionalLight {
            illuminance: 100.0,
            ..default()
        };
        let bright = DirectionalLight {
            illuminance: 1000.0,
            color: Color::linear_rgb(1.0, 0.5, 0.25),
            ..default()
        };
        let broken = DirectionalLight {
            illuminance: f32::NAN,
            ..default()
        };
        let params = tree_lights(
            &lighting,
            Some(&ambient),
            [
                (&dim, Vec3::X),
                (&broken, Vec3::Z),
                (&bright, Vec3::new(0.0, 2.0, 0.0)),
            ]
            .into_iter(),
        );
        assert_eq!(params.tree_lighting, 1);
        assert_eq!(params.lights.to_sun.truncate(), Vec3::Y);
        assert_eq!(
            params.lights.sun.truncate(),
            Vec3::new(1000.0, 500.0, 250.0)
        );
        assert_eq!(params.lights.sky.truncate(), Vec3::splat(2.0));
        assert_eq!(params.lights.ground.truncate(), Vec3::new(1.0, 0.5, 0.0));
        assert_eq!(
            params.lights.reflectance_front.truncate(),
            lighting.optics.reflectance_front
        );
        // No sun, no ambient light: nothing lights the leaves but what the settings say.
        let dark = tree_lights(&lighting, None, std::iter::empty());
        assert_eq!(dark.lights.sun, Vec4::ZERO);
        assert_eq!(dark.lights.sky, Vec4::ZERO);
        assert_eq!(dark.lights.to_sun.truncate(), Vec3::Y);
    }
}
