//! The clip stack's bookkeeping, in plain Rust (Seoane et al. 2007, paper 1): layer
//! state matrices, toroidal placement, ring-ordered updates under a budget, coverage, and the
//! CPU reference of the shader's layer choice. The render side (texture array, uploads, the
//! terrain material) is built on top.

pub mod layer;
pub mod stack;
