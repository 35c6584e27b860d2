//! Registration of grass: the settings, components, material and the main-world systems.

use super::field::{GrassField, GrassSettings, GrassSpecies, sanitize_grass_settings};
use super::ground::WindMap;
use super::ground_map::{GrassWindMap, wind_image};
use super::systems::{
    GEOMETRY_BLADES, GEOMETRY_CELLS, MACRO_CELLS, SELECT_MS, SLICE_BLOCKS, attach_slice_bakes,
    prepare_grass_fields, resolve_density_maps, resolve_ground_maps, resolve_occlusion_maps,
    update_grass_cells,
};
use bevy::camera::visibility::VisibilitySystems;
use bevy::diagnostic::{Diagnostic, RegisterDiagnostic};
use bevy::prelude::*;
use bevy::transform::TransformSystems;

/// Grass to the horizon (Boulanger 2008, thesis ch. 4): add it, then spawn [`GrassField`]s and
/// tune [`GrassSettings`].
#[derive(Default)]
pub struct GrassPlugin;

/// The grass systems, in order, in `PostUpdate` after transforms propagate.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GrassSystems {
    /// Fields are built and their density maps read.
    Prepare,
    /// Cells are selected and their entities kept.
    Cells,
}

impl Plugin for GrassPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<GrassSettings>()
            .register_type::<GrassField>()
            .register_type::<GrassSpecies>()
            .register_type::<super::ground::GrassWind>()
            .init_resource::<GrassSettings>()
            .add_systems(
                PreUpdate,
                sanitize_grass_settings.run_if(resource_changed::<GrassSettings>),
            );
        // The rendering side needs Bevy's asset and render plugins (absent in pure logic tests).
        if !app.world().contains_resource::<AssetServer>() {
            return;
        }
        for path in [
            GEOMETRY_BLADES,
            GEOMETRY_CELLS,
            SLICE_BLOCKS,
            MACRO_CELLS,
            SELECT_MS,
        ] {
            app.register_diagnostic(Diagnostic::new(path).with_max_history_length(1));
        }
        // The wind map the shaders read (a game may swap it).
        if !app.world().contains_resource::<GrassWindMap>()
            && let Some(mut images) = app.world_mut().get_resource_mut::<Assets<Image>>()
        {
            let map = WindMap::gusts(64, 0x9e37_79b9);
            let image = images.add(wind_image(&map));
            app.insert_resource(GrassWindMap { map, image });
        }
        super::material::build(app);
        super::bake::build(app);
        super::slice_material::build(app);
        app.configure_sets(
            PostUpdate,
            (GrassSystems::Prepare, GrassSystems::Cells)
                .chain()
                .after(TransformSystems::Propagate)
                .before(VisibilitySystems::CheckVisibility),
        )
        .add_systems(
            PostUpdate,
            (
                (
                    prepare_grass_fields,
                    resolve_density_maps,
                    resolve_ground_maps,
                    resolve_occlusion_maps,
                    attach_slice_bakes,
                )
                    .chain()
                    .in_set(GrassSystems::Prepare),
                update_grass_cells.in_set(GrassSystems::Cells),
            ),
        );
    }
}
