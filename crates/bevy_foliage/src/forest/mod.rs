//! Forests: which tree gets new detail when (Gumbau 2011, §3.6 and ch. 4; spec F2–F3).
//!
//! - [`lod`]: desired LoD (eq. 4.2–4.3), LoD error and urgency (eq. 3.11–3.12);
//! - [`cache`]: the LoD cache — slots over [0, 1], Algorithm 3, the double-buffered variant;
//! - [`feedback`]: the frame-rate feedback exponent and its controller;
//! - [`hlod`]: decimated leaf meshes for the `VisibilityRange` baseline of the benchmark;
//! - [`manager`]: the per-frame ranking and serving under a budget, over plain arrays;
//! - [`plugin`]: the ECS and rendering side — components on tree instances, the systems that run
//!   the manager, and the pruning extractions the trees borrow.

pub mod cache;
pub mod feedback;
pub mod hlod;
pub mod lod;
pub mod manager;
pub mod plugin;
