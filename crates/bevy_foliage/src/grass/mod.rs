//! Grass to the horizon (Boulanger 2008, thesis ch. 4): one small base patch of blades repeated
//! over the ground in four mirrored versions, drawn near as blade geometry, at middle distance as
//! volume slices with baked lighting, and far as a horizontal slice, with transitions that keep
//! the coverage whole.
//!
//! Add [`GrassPlugin`] (part of `bevy_nature`'s `NaturePlugins`), spawn a [`GrassField`] (a
//! rectangle, a [`GrassSpecies`], an optional density map) and tune [`GrassSettings`]. Each field
//! bakes its species' slices on the GPU once ([`bake`], cached on disk when
//! `GrassSettings::slice_cache` names a folder), then every frame walks its cells from the camera
//! ([`systems`]): cells within the geometry's reach become blade-geometry entities
//! ([`material`], `grass_blade.wgsl`), blocks of cells beyond become slice quads and, past the
//! vertical slices' reach, macro-cells of horizontal slice ([`slice_material`],
//! `grass_slice.wgsl`). Blades receive Bevy's shadows, and screen-space soft shadows through
//! `bevy_nature`'s glue.
//!
//! The plain-Rust core: [`patch`] (the base patch, its stratified roots and density thresholds,
//! the mirrored versions of eq. 4.9, blade strips along a ballistic curve), [`mesh`] (the patch
//! and slice meshes), [`quadtree`] (the implicit quadtree of cells and macro-cells walked by
//! frustum and distance), [`density`] (density maps, procedural meadows), [`transition`] (the
//! weights of eq. 4.3–4.5 and 4.14, the complementary opacities of algorithm 1 and eq. 4.6, the
//! ordered dither), [`slices`] (the slice layout and cameras, the CPU reference of the bake),
//! [`slice_shading`] (the CPU reference of the slice shader), [`slice_mip`] (the slices' mip
//! filter), [`slice_format`] (the `*.grassslices` cache), [`lighting`] (eq. 4.1, the blade
//! ambient occlusion, the shadow mask's eq. 4.7, the spherical barycentric BTF weights of
//! appendix A) and [`ground`] (the ground's corner samples, the lift of eq. 4.10 and the frame of
//! eq. 4.11, node bounds and flatness flags, the wind's shear of the patch corners).
//! [`ground_map`] turns a height map and the wind map into what the shaders read.

pub mod bake;
pub mod density;
pub mod field;
pub mod ground;
pub mod ground_map;
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
pub use ground::GrassWind;
pub use ground_map::{GrassWindMap, height_map_image};
pub use plugin::{GrassPlugin, GrassSystems};
