//! # bevy_foliage
//!
//! Trees and grass for Bevy, from the vegetation level-of-detail research collected in the
//! `bevy_nature` suite (Gumbau 2011, Boulanger 2008 and others):
//!
//! - **GPU view-dependent stochastic pruning of leaves** (Gumbau, ch. 3): each tree's leaves are
//!   grouped in cells with baked per-view visibility; every frame a compute pass keeps, per cell, a
//!   prefix of a stochastically ordered leaf list sized by distance and visibility, and the kept
//!   leaves are enlarged so the crown keeps its area. Distances follow the crown's size on
//!   screen ([`LodDistances`]), shadows draw the light's own selection, and trees come from
//!   glTF files as artists export them ([`pruning::gltf`], [`pruning::spawn`]) or from the
//!   procedural species; [`corpus`] writes real-world-like test trees.
//! - **an urgency-ranked forest LoD manager** under a frame budget with **LoD caches** (Gumbau,
//!   §3.6 and ch. 4): tag instances with [`ForestTree`]; per type, a few cached extractions are
//!   shared by every tree whose desired LoD falls in the same slot ([`forest`]).
//! - **billboard-cloud impostors** for distant trees (seed 001, ch. 4): each species simplified
//!   to a few tens of planes textured from one GPU-baked atlas, drawn beyond the pruning's `far`
//!   with a dithered handover ([`impostor`]).
//! - **grass** with geometry / slice LoD (Boulanger, ch. 4): a [`grass::GrassField`] is drawn
//!   near as blade geometry, at middle distance as GPU-baked volume slices lit through five
//!   baked light directions, far as the horizontal slice on macro-cells, with seamless
//!   transitions and density maps ([`grass`], [`grass::GrassPlugin`]).
//! - **tree lighting** (Boulanger, ch. 5), in progress: the per-leaf envelope of §5.6 — the
//!   light the crown lets through to each leaf in eight directions (traced through the leaves),
//!   the crown's extinction — is baked with every tree and billboard cloud ([`lighting`]); the
//!   leaf and cloud shaders light each leaf by sky, sun and one bounce through its crown behind
//!   [`TreeLightingSettings`].
//!
//! Add [`FoliagePlugin`]; tune [`FoliagePruningSettings`] (a reflected resource, so inspectors can
//! edit it live).
//!
//! The crate is split by role: the algorithms are plain Rust modules with no render types
//! (`pruning::{leaves, cells, visibility, mask, bake, extract, selection, appearance, format,
//! gltf, procedural}`, `forest::{cache, feedback, lod, manager, hlod}`,
//! `impostor::{cloud, atlas, texture, format}`, `grass::{patch, density, transition, quadtree,
//! lighting, ground, slices, slice_shading, slice_mip, slice_format}`, [`distance`]); meshes are
//! built from them in `meshes`,
//! `pruning::slot_mesh` and `grass::mesh`; the main-world ECS code lives in
//! `components`, `systems`, `store`, `spawn`, `bake` and `assets` modules; the render-world code
//! sits beside its WGSL (`pruning::render` with `prune.wgsl`, `pruning::material` with the leaf
//! shaders, `impostor::bake` with `impostor_bake.wgsl`, `grass::material` and
//! `grass::slice_material` with the grass shaders, `grass::bake` with `slice_bake.wgsl`).

use bevy::prelude::*;

pub mod corpus;
pub mod distance;
pub mod forest;
mod gpu_bake;
pub mod grass;
pub mod impostor;
pub mod lighting;
pub mod meshes;
pub mod pruning;
pub mod rng;
pub mod settings;
mod soft_receiver;

pub use distance::LodDistances;
pub use forest::components::{ForestBudget, ForestSettings, ForestTree, TreeLod};
pub use lighting::settings::TreeLightingSettings;
pub use settings::{FoliagePruningSettings, ViewWeighting};

/// The foliage plugin: registers the settings and keeps them valid.
#[derive(Default)]
pub struct FoliagePlugin;

impl Plugin for FoliagePlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<FoliagePruningSettings>()
            .init_resource::<FoliagePruningSettings>()
            .register_type::<TreeLightingSettings>()
            .init_resource::<TreeLightingSettings>()
            .add_systems(
                PreUpdate,
                (
                    settings::sanitize_pruning_settings
                        .run_if(resource_changed::<FoliagePruningSettings>),
                    lighting::settings::sanitize_tree_lighting
                        .run_if(resource_changed::<TreeLightingSettings>),
                ),
            );
        // The rendering side needs Bevy's asset and render plugins (absent in pure logic tests).
        if app.world().contains_resource::<AssetServer>() {
            pruning::plugin::build(app);
            forest::plugin::build(app);
            impostor::build(app);
        }
    }
}

/// Everything a game usually imports.
pub mod prelude {
    pub use crate::{
        FoliagePlugin, FoliagePruningSettings, ForestBudget, ForestSettings, ForestTree,
        LodDistances, TreeLightingSettings, TreeLod, ViewWeighting,
    };
}
