//! The ECS vocabulary of pruning: what a game puts on its entities ([`PrunedFoliage`],
//! [`FoliageCamera`]) and what the plugin writes on them each frame ([`PruningParams`]).

use super::bake::BakedFoliage;
use super::extract::ViewWeights;
use super::material::LeafMaterial;
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

/// This frame's pruning inputs of one tree instance (written by the plugin).
#[derive(Component, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PruningParams {
    /// Viewpoints and weights.
    pub weights: ViewWeights,
    /// Distance factor (eq. 3.4), fraction of 65536.
    pub distance_fixed: u32,
}

/// Marks a [`PrunedFoliage`] entity whose [`PruningParams`] are written by someone else (the
/// forest manager's cache extractions) instead of from the pruning camera every frame, and that
/// is not drawn itself.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct ManagedPruning;
