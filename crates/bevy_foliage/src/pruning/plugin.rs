//! Registration of pruning: assets, the main-world systems in their order, the leaf material and
//! the render-world pass.

use super::asset::BakedFoliageLoader;
use super::bake::BakedFoliage;
use super::components::FoliageShadowLight;
use super::slot_mesh::SlotMeshes;
use super::store::{FoliageStore, update_foliage_store};
use super::systems::{
    FoliageSystems, KEPT_PERCENT, SHADOW_TRIANGLES_DRAWN, TREES_PRUNED, TRIANGLES_DRAWN,
    TRIANGLES_FULL, assign_slot_meshes, cast_leaves_through_opacity_map, compute_pruning_params,
    refresh_leaf_materials, track_shadow_light,
};
use bevy::camera::visibility::VisibilitySystems;
use bevy::diagnostic::{Diagnostic, RegisterDiagnostic};
use bevy::prelude::*;
use bevy::transform::TransformSystems;

/// Registers everything pruning needs (called by `FoliagePlugin` when rendering is present).
pub(crate) fn build(app: &mut App) {
    for path in [
        TRIANGLES_DRAWN,
        SHADOW_TRIANGLES_DRAWN,
        TRIANGLES_FULL,
        KEPT_PERCENT,
        TREES_PRUNED,
        super::regather::BOUNCE_RING_SECONDS,
        super::regather::BOUNCE_RINGS_GATHERING,
        super::regather::BOUNCE_RING_PASSES,
        super::regather::BOUNCE_RING_PASS_SECONDS,
        super::regather::BOUNCE_RING_REFINEMENT_BYTES,
    ] {
        app.register_diagnostic(Diagnostic::new(path).with_max_history_length(1));
    }
    app.init_asset::<BakedFoliage>()
        .init_asset_loader::<BakedFoliageLoader>()
        .init_resource::<FoliageStore>()
        .init_resource::<SlotMeshes>()
        .init_resource::<FoliageShadowLight>()
        .init_resource::<super::regather::BounceRings>()
        .configure_sets(
            PostUpdate,
            (
                FoliageSystems::PruningParams,
                FoliageSystems::Store,
                FoliageSystems::Draw,
            )
                .chain()
                .after(TransformSystems::Propagate)
                .before(VisibilitySystems::CheckVisibility),
        )
        .add_systems(
            PostUpdate,
            (
                (track_shadow_light, compute_pruning_params)
                    .chain()
                    .in_set(FoliageSystems::PruningParams),
                (update_foliage_store, super::regather::regather_bounce_rings)
                    .chain()
                    .in_set(FoliageSystems::Store),
                (
                    assign_slot_meshes,
                    refresh_leaf_materials,
                    cast_leaves_through_opacity_map,
                )
                    .in_set(FoliageSystems::Draw),
            ),
        );
    super::material::build(app);
    super::render::build(app);
    super::opacity_shadow::build(app);
}
