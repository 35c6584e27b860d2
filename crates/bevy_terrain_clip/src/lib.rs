//! # bevy_terrain_clip
//!
//! Terrain textures far larger than GPU memory, for Bevy. Following the clipmap-style virtual
//! texture of Seoane et al. (WSCG 2007, paper 1 of the proceedings collected in the suite), the
//! full mip pyramid stays on disk as a tile pyramid; a RAM tile cache and a GPU *clip stack* — the
//! base level with its mips plus c × c windows of the finer levels around the viewer — hold what
//! the camera needs, refreshed by toroidal subtile updates under a per-frame budget so a flight
//! never stalls.
//!
//! Built so far: the plain-Rust core — [`clip`] (layer state matrices, toroidal placement,
//! ring-ordered updates under a budget, coverage, the CPU reference of the shader's layer choice)
//! and [`cache`] (LRU tile cache, coarsest-first request queue with merging, absent tiles and
//! back-off), [`pyramid`] (XYZ/TMS tile pyramids with a validated JSON manifest), [`source`] (asynchronous
//! tile sources: disk and procedural), [`dem`] (elevation tiles in metres), [`geometry`] (seamless
//! terrain patches: selection, tiles and stitching strips, the vertex stage's height lookup). On
//! top: [`stack_gpu`] (clip stacks of imagery or heights streamed into texture arrays),
//! [`material`] (the terrain material) and [`terrain`] ([`TerrainGeometry`](terrain::TerrainGeometry):
//! the ground with relief).
//!
//! Add [`TerrainClipPlugin`]; tune [`ClipmapSettings`] (a reflected resource).

use bevy::prelude::*;

pub mod builder;
pub mod cache;
pub mod clip;
pub mod dem;
pub mod faults;
pub mod flight;
pub mod geometry;
pub mod material;
pub mod origin;
pub mod pyramid;
pub mod settings;
pub mod source;
pub mod stack_gpu;
pub mod terrain;
pub mod tile_cache;

pub use origin::RenderOrigin;
pub use settings::{ClipmapSettings, UpdateBudget};

/// The terrain clipmap plugin: registers the settings and keeps them valid.
#[derive(Default)]
pub struct TerrainClipPlugin;

impl Plugin for TerrainClipPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<ClipmapSettings>()
            .register_type::<RenderOrigin>()
            .init_resource::<ClipmapSettings>()
            .init_resource::<RenderOrigin>()
            .add_systems(
                PreUpdate,
                settings::sanitize_clipmap_settings.run_if(resource_changed::<ClipmapSettings>),
            );
        // Streaming into GPU textures needs Bevy's asset and render plugins.
        if app.world().contains_resource::<AssetServer>() {
            stack_gpu::build(app);
            material::build(app);
            terrain::build(app);
        }
    }
}

/// Everything a game usually imports.
pub mod prelude {
    pub use crate::{ClipmapSettings, RenderOrigin, TerrainClipPlugin, UpdateBudget};
}
