//! View-dependent stochastic pruning of foliage (Gumbau 2011, ch. 3; spec F1).
//!
//! Offline, [`bake`] turns a tree's [`LeafSet`](leaves::LeafSet) into a
//! [`BakedFoliage`](bake::BakedFoliage): leaves grouped in cells ([`cells`]), each cell's
//! visibility from evenly spread viewpoints ([`visibility`]), each cell's leaves in a seeded
//! random order, and per-vertex centroid offsets. [`format`](mod@format) stores it as a versioned,
//! checksummed binary file.
//!
//! Every frame, per tree, the pruning pass keeps a prefix of each cell's list sized by distance
//! and view-dependent visibility and compacts the survivors into an index buffer;
//! [`extract`] is the exact CPU reference of that pass.
//!
//! [`appearance`] holds how a kept leaf is drawn (area compensation, sub-pixel fade).
//! [`procedural`] generates the thesis' four test trees at their leaf counts.

pub mod appearance;
pub mod bake;
pub mod cells;
pub mod extract;
pub mod format;
pub mod gltf;
pub mod gpu;
pub mod leaves;
pub mod material;
pub mod procedural;
pub mod spawn;
pub mod visibility;
