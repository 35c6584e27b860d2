//! Billboard-cloud impostors for distant trees (Décoret et al. 2003, extended for vegetation in
//! seed 001, ch. 4; spec F7): a tree simplified to a few tens of textured planes, each plane
//! carrying the albedo, coverage and normals of the triangles that lie within ε of it.
//!
//! Split by role like the pruning pass:
//! - plain Rust, no render types: [`cloud`] (plane selection in the discretised (θ, φ, ρ) space,
//!   greedy cover, vegetation extensions), [`atlas`] (one texture atlas per species),
//!   [`texture`] (what is baked from, and the CPU reference of the bake), [`format`](mod@format) (the
//!   versioned, checksummed `*.bbcloud` file);
//! - main world: [`bake`] (the GPU bake: orthographic cameras into the atlas, read back),
//!   [`assets`] (the `AssetServer` loader, the quads and their `StandardMaterial`),
//!   [`systems`] (drawing a forest tree's impostor beyond the pruning's `far`), [`tree_lit`]
//!   (the material that lights the cloud's leaf texels by the tree lighting), [`tree_lit_ring`]
//!   (its crown's mean of the type's re-gathered bounce ring);
//! - render side: `impostor_bake.wgsl`, the bake's unlit material; `tree_lit_impostor.wgsl`.

pub mod assets;
pub mod atlas;
pub mod bake;
pub mod cloud;
pub mod format;
pub mod systems;
pub mod texture;
pub mod tree_lit;
pub mod tree_lit_ring;

use bevy::prelude::*;

/// Registers the impostor bake, the `*.bbcloud` loader and the forest's impostor systems.
pub(crate) fn build(app: &mut App) {
    app.init_asset::<assets::BillboardCloudAsset>()
        .init_asset_loader::<assets::BillboardCloudLoader>();
    bake::build(app);
    tree_lit::build(app);
    tree_lit_ring::build(app);
    systems::build(app);
}
