//! Trees' shadows that know they are trees (Boulanger 2008, §5.5.2): a crown is not an opaque
//! blocker, so its shadow on the ground is dark where leaves pile up along the sun's rays and
//! light where they are sparse, and it softens with the distance between the leaves and the
//! ground.
//!
//! [`opacity_map`] holds the world-space opacity shadow map as plain Rust: eq. 5.27's projection
//! onto a horizontal plane, the accumulation of leaf fragments (the highest occluder kept by a
//! MAX blend, the transmittance multiplied by 0.9 per leaf fragment), and the soft lookup whose
//! mip grows with the distance from the receiver to the occluder. It is the reference of the
//! render pass still to come.

pub mod opacity_map;
