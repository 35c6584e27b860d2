//! Forests: which tree gets new detail when (Gumbau 2011, §3.6 and ch. 4; spec F2–F3).
//!
//! - [`lod`]: desired LoD (eq. 4.2–4.3), LoD error and urgency (eq. 3.11–3.12);
//! - [`cache`]: the LoD cache — slots over [0, 1], Algorithm 3, the double-buffered variant;
//! - [`feedback`]: the frame-rate feedback exponent and its controller;
//! - [`hlod`]: decimated leaf sets for the `VisibilityRange` baseline of the benchmark;
//! - [`manager`]: the per-frame ranking and serving under a budget, over plain arrays;
//! - [`mixed`]: the time-critical choice between pruned geometry and billboard clouds;
//!
//! and on the ECS: [`components`] (tree instances, settings), [`systems`] (running the manager
//! and drawing the trees from the pruning extractions they borrow) and the registration.

pub mod cache;
pub mod components;
pub mod feedback;
pub mod hlod;
pub mod lod;
pub mod manager;
pub mod mixed;
pub(crate) mod plugin;
pub mod systems;
