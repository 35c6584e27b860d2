//! Registration of the forest manager.

use super::components::{ForestSettings, TreeLod};
use super::systems::{
    BORROWS, EXPONENT, EXTRACTIONS, ForestState, GPU_BYTES_PER_VISIBLE, LEAF_TRIANGLES, MANAGER_MS,
    VISIBLE_TREES, draw_forest_trees, run_forest_manager, sanitize_forest_settings,
};
use crate::pruning::systems::{FoliageSystems, track_shadow_light};
use bevy::diagnostic::{Diagnostic, RegisterDiagnostic};
use bevy::prelude::*;

/// Registers the forest manager.
pub(crate) fn build(app: &mut App) {
    for path in [
        EXTRACTIONS,
        BORROWS,
        VISIBLE_TREES,
        LEAF_TRIANGLES,
        MANAGER_MS,
        EXPONENT,
        GPU_BYTES_PER_VISIBLE,
    ] {
        app.register_diagnostic(Diagnostic::new(path).with_max_history_length(1));
    }
    app.register_type::<ForestSettings>()
        .register_type::<TreeLod>()
        .init_resource::<ForestSettings>()
        .init_resource::<ForestState>()
        .add_systems(
            PreUpdate,
            sanitize_forest_settings.run_if(resource_changed::<ForestSettings>),
        )
        .add_systems(
            PostUpdate,
            (
                // It writes the extraction entities' pruning inputs, which the store lays out.
                run_forest_manager
                    .in_set(FoliageSystems::PruningParams)
                    .after(track_shadow_light),
                draw_forest_trees.in_set(FoliageSystems::Draw),
            ),
        );
}
