//! The ECS vocabulary of pruning: what a game puts on its entities ([`PrunedFoliage`],
//! [`FoliageCamera`]) and what the plugin writes on them each frame ([`PruningParams`]).

use super::bake::BakedFoliage;
use super::material::LeafMaterial;
use super::selection::{Selection, ShadowLight};
use bevy::prelude::*;

/// Tags a tree instance whose leaves are pruned every frame. The entity's `GlobalTransform`
/// places the tree.
#[derive(Component, Clone, Debug)]
#[require(Transform, Visibility)]
pub struct PrunedFoliage {
    /// The baked pruning data of the tree type.
    pub baked: Handle<BakedFoliage>,
    /// How the leaves look (see [`leaf_material`](super::material::leaf_material)).
    pub material: Handle<LeafMaterial>,
}

/// Marks the camera that drives pruning. Without one, the active 3D camera with the lowest
/// `order` does.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct FoliageCamera;

/// This frame's pruning inputs of one tree instance (written by the plugin; see
/// [`super::selection`]).
#[derive(Component, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PruningParams {
    /// What the camera views (main pass and prepasses) draw.
    pub camera: Selection,
    /// What shadow views draw; `None`: the camera's selection.
    pub light: Option<Selection>,
}

/// Marks the light whose shadow views draw the light's own leaf selection. Without one, the
/// first shadow-casting directional light does (else the first spot, else point light). Other
/// shadow-casting lights draw that same selection.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct FoliageLight;

/// The light shadow views select leaves for this frame (written by the plugin).
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct FoliageShadowLight(pub Option<ShadowLight>);

/// Marks a [`PrunedFoliage`] entity whose [`PruningParams`] are written by someone else (the
/// forest manager's cache extractions) instead of from the pruning camera every frame, and that
/// is not drawn itself.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct ManagedPruning;
