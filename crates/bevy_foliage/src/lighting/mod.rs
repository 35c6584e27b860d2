//! Trees lit as volumes of leaves (Boulanger 2008, ch. 5; in progress): [`envelope`] holds the
//! per-leaf precomputation of §5.6 — the light each leaf receives through its neighbours in
//! eight directions, the distances to the crown's envelope and the crown's fitted extinction τ —
//! as plain Rust, with [`leaf_tree`] taking far groups of leaves as one for large crowns, and
//! [`traced_bins`] the same eight values traced through the leaves ([`leaf_scene`]), which bakes
//! use by default; and
//! [`model`] the light a leaf sends to the eye from it (the leaf BSDF, sky, sun and one bounce
//! of sunlight of §5.2–5.4), the CPU reference of the leaf shaders, with [`path_trace`] the
//! Monte Carlo ground truth it is measured against leaf by leaf, and [`image_error`] as
//! images at several pixel sizes, the way the thesis reports its error, with [`seen_part`] the
//! gain from a leaf's mean to the part of it the eye sees and [`hotspot`] the crown's
//! dependence on the angle between the eye and the sun (the eye's and the sun's paths share
//! their gaps), and [`gathered_bounce`] the bounce gathered from each leaf's own neighbours as
//! ratios to eq. 5.24 (baked with the bins, drawn by the leaf shaders), re-gathered while an
//! app runs on a ring of suns at the sun's elevation by [`bounce_ring`], which also holds each
//! leaf's [`sunlit_share`] towards those suns, the leaves' sun where the shadow map does not
//! resolve leaves, and [`bounce_floor`] what values stored per leaf can make of the bounce;
//! [`settings`] switches the leaf
//! shaders between it and Bevy's lighting; [`sun_maps`] measures maps rendered from the sun (shadow map, foliage
//! maps) as the leaves' sun against the same tracer.

pub mod bins;
pub mod bounce_floor;
pub mod bounce_ring;
pub mod envelope;
pub mod gathered_bounce;
pub mod hotspot;
pub mod image_error;
pub mod leaf_scene;
pub mod leaf_tree;
pub mod model;
pub mod open_map;
pub mod path_trace;
pub mod seen_part;
pub mod settings;
pub mod sun_maps;
pub mod sunlit_share;
pub mod traced_bins;

/// `f` of each of `items`, in order, on up to `threads` scoped threads (the bakes' and the
/// measurements' per-leaf loops).
pub(crate) fn par_map<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let chunk = items.len().div_ceil(threads.max(1)).max(1);
    let f = &f;
    std::thread::scope(|s| {
        let handles: Vec<_> = items
            .chunks(chunk)
            .map(|part| s.spawn(move || part.iter().map(f).collect::<Vec<_>>()))
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("lighting worker thread"))
            .collect()
    })
}
