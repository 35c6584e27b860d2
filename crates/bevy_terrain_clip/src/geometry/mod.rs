//! Terrain geometry from seamless patches (Livny, Kogan and El-Sana, "Seamless patches for
//! GPU-based terrain rendering", paper 4 of the collected proceedings), in plain Rust:
//!
//! - [`patch`]: the implicit patch hierarchy over the terrain square, the per-frame selection —
//!   top-down traversal, edge error ε = ρ·l/d (eq. 1), hierarchical frustum culling — and each
//!   selected patch's edge and diagonal resolutions, agreed with its neighbours so the mesh has no
//!   cracks;
//! - [`tile`]: a patch's four triangular tiles (one per edge, split by the diagonals) with the
//!   stitching strips that join them along the diagonals, as integer lattice meshes — the unit
//!   meshes the GPU instances, and the CPU reference of every vertex position;
//! - [`relief`]: the height of a vertex, read from the height clip stack (the CPU reference of
//!   the vertex stage's lookup).
//!
//! Every vertex lies on one integer lattice over the whole terrain (the finest patch's side is
//! [`PatchGrid::r_high`] lattice steps), so "shared vertices coincide" is an exact comparison.

pub mod patch;
pub mod relief;
pub mod tile;

pub use patch::{
    EdgeResolution, PatchGrid, PatchId, PatchView, SelectedPatch, Selection, SelectionStats,
    select_patches,
};
pub use tile::{PatchMesh, patch_mesh};
