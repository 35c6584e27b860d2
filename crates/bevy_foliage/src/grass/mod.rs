//! Grass to the horizon (Boulanger 2008, thesis ch. 4): one small base patch of blades repeated
//! over the ground in four mirrored versions, drawn near as blade geometry, at middle distance as
//! volume slices with baked lighting, and far as a horizontal slice, with transitions that keep
//! the coverage whole.
//!
//! This module holds the plain-Rust core so far: [`patch`] (the base patch, its stratified roots
//! and density thresholds, the mirrored versions of eq. 4.9, blade strips along a ballistic
//! curve), [`mesh`] (the base patch as one mesh carrying each blade's threshold), [`quadtree`] (the implicit quadtree of cells and macro-cells walked by frustum and
//! distance), [`density`] (density maps), [`transition`] (the weights of eq. 4.3–4.5 and 4.14 and the
//! complementary opacities of algorithm 1 and eq. 4.6), [`slice_mip`] (the slices' custom mip
//! filter), [`lighting`] (eq. 4.1, the blade ambient occlusion, the shadow mask's eq. 4.7, the
//! spherical barycentric BTF weights of appendix A) and [`ground`] (the lift and frame of
//! eq. 4.10–4.12 on curved ground). The slice bake, the render passes and the `GrassPlugin` come
//! next.

pub mod bake;
pub mod density;
pub mod field;
pub mod ground;
pub mod lighting;
pub mod material;
pub mod mesh;
pub mod patch;
pub mod plugin;
pub mod quadtree;
pub mod slice_format;
pub mod slice_material;
pub mod slice_mip;
pub mod slice_shading;
pub mod slices;
pub mod systems;
pub mod transition;

pub use field::{GrassField, GrassFieldError, GrassSettings, GrassSpecies};
pub use plugin::{GrassPlugin, GrassSystems};
