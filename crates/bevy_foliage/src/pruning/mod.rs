//! View-dependent stochastic pruning of foliage (Gumbau 2011, ch. 3; spec F1).
//!
//! The technique, split by role:
//!
//! - **The algorithm**, plain Rust with no render types: [`leaves`] (the leaf set), [`cells`]
//!   (the cell cloud), [`visibility`] (per-cell visibility from evenly spread viewpoints),
//!   [`bake`] (the whole bake into a [`BakedFoliage`](bake::BakedFoliage)), [`extract`] (the
//!   per-frame extraction: the exact CPU reference of the GPU pass), [`selection`] (which
//!   leaves the camera's and the light's views get), [`appearance`] (area
//!   compensation and the sub-pixel fade: the CPU reference of the leaf vertex stage),
//!   [`format`](mod@format) (the versioned, checksummed `.foliage` file), and the tree sources
//!   [`procedural`] and [`gltf`].
//! - **Main world**: [`components`] (what a game puts on its entities), [`systems`] (pruning
//!   inputs per tree, slot meshes, diagnostics), [`store`] (the shared GPU buffers),
//!   [`regather`] (the tree lighting's bounce ratios re-gathered at the sun's elevation),
//!   [`slot_mesh`], [`spawn`] (one-call tree spawning) and [`asset`] (the `.foliage` loader).
//! - **Render world**, beside its WGSL: [`render`] (`prune.wgsl`, the compute pass) and
//!   [`material`] (`leaf*.wgsl`, the leaf material's vertex stages), [`opacity_shadow`]
//!   (`opacity_shadow.wgsl`: the leaves drawn into the trees' opacity shadow map of
//!   `bevy_soft_shadows`; [`opacity_casting`] is its CPU reference).

pub mod appearance;
pub mod asset;
pub mod bake;
pub mod cells;
pub mod components;
pub mod extract;
pub mod format;
pub mod gltf;
pub mod leaves;
pub mod mask;
pub mod material;
pub mod opacity_casting;
pub mod opacity_shadow;
pub(crate) mod plugin;
pub mod procedural;
pub mod regather;
pub mod render;
pub mod selection;
pub mod slot_mesh;
pub mod spawn;
pub mod store;
pub mod systems;
pub mod visibility;
