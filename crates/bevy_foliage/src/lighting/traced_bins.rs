//! The light each of a leaf's eight bins lets through, traced: rays from points spread on the
//! leaf through the crown's very leaves, instead of §5.6's estimate from the neighbours' solid
//! angles (Boulanger 2008, §5.6; [`super::envelope`]).
//!
//! §5.6 multiplies, per bin, the occlusions `Ω_leaf / Ω_bin` of the leaves in it, as if they
//! were spread independently over the bin's solid angle: leaves that hide behind one another
//! are counted twice, gaps are not seen, and what a leaf's centre sees stands for the whole
//! leaf. Against a path tracer over the same leaves that estimate is tens of per cent off leaf
//! by leaf on real crowns (`tree_lighting_error`). Tracing the bins costs rays at bake time
//! only; the shaders read the same eight numbers either way.
//!
//! Each bin's value is what eq. 5.6's sky integral needs of it: the visibility over the bin's
//! octant weighted by `|n·ω|` (the two-sided BSDF is a cosine on each side), averaged over the
//! leaf's surface. A leaf crossed lets `1 − opacity` through (a textured card its texture's
//! transparent share). The envelope distances and the crown's τ are then fitted from these
//! attenuations as §5.6 does ([`super::envelope`]).

use super::bins::{DIRECTIONS, LeafProxy};
use super::envelope::{
    CrownEnvelope, envelope_from_attenuations, neighbour_sums, parallel_map_with_progress,
};
use super::leaf_scene::LeafScene;
use crate::rng::SplitMix64;
use bevy::math::Vec3;
use bevy::reflect::Reflect;

/// How a bake estimates the light each bin lets through.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Reflect)]
#[reflect(Debug, PartialEq)]
pub enum BinEstimate {
    /// §5.6: the product of the neighbours' occlusions seen from the leaf's centre.
    Neighbours,
    /// Rays through the leaves, this many per bin and leaf.
    Traced {
        /// Rays per bin and leaf (each from its own point on the leaf).
        rays_per_bin: u32,
    },
}

impl Default for BinEstimate {
    fn default() -> Self {
        Self::Traced {
            rays_per_bin: DEFAULT_RAYS_PER_BIN,
        }
    }
}

impl BinEstimate {
    /// These settings if they can be baked, or why not (rays per bin in
    /// 1..=[`MAX_RAYS_PER_BIN`]).
    pub fn checked(self) -> Result<Self, String> {
        match self {
            Self::Traced { rays_per_bin } if !(1..=MAX_RAYS_PER_BIN).contains(&rays_per_bin) => {
                Err(format!(
                    "rays_per_bin = {rays_per_bin} not in 1..={MAX_RAYS_PER_BIN}"
                ))
            }
            other => Ok(other),
        }
    }
}

/// The most rays per bin a bake takes (a bake of 40,000 leaves then traces 1.3 billion rays).
pub const MAX_RAYS_PER_BIN: u32 = 4096;

/// Rays per bin a bake traces by default, one made while an app runs (a tree read from glTF and
/// baked at load, the examples' trees): on the four procedural trees the sky's error per leaf
/// against a path tracer whose own noise is 3–5 % per leaf is 23–37 % of the leaf's light
/// (10–11 % of the crown's mean), against 36–59 % for §5.6's estimate (`tree_lighting_error`).
/// The error falls as 1/√rays; see [`OFFLINE_RAYS_PER_BIN`].
pub const DEFAULT_RAYS_PER_BIN: u32 = 32;

/// Rays per bin `foliage_bake` traces by default (a bake made once and kept on disk): four times
/// [`DEFAULT_RAYS_PER_BIN`]'s time, the sky per leaf 12–18 % off (4–5 % of the crown's mean); 256
/// rays take 7.6–12 % (3.1–3.8 %).
pub const OFFLINE_RAYS_PER_BIN: u32 = 128;

/// The eight bins' attenuations for leaf `leaf` of `scene` (see the module docs); `opacity(l)`
/// the share of leaf `l`'s area that stops light; `seed` the leaf's random sequence.
pub fn traced_bins_of(
    scene: &LeafScene,
    leaf: usize,
    rays_per_bin: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
) -> [f32; 8] {
    let mut rng = SplitMix64::new(seed);
    let n = scene.normal(leaf);
    let has_surface = scene.triangle_count(leaf) > 0;
    let centre = scene.centre(leaf);
    std::array::from_fn(|j| {
        let sign = DIRECTIONS[j].signum();
        let (mut lit, mut weight) = (0.0f32, 0.0f32);
        let rays = rays_per_bin.max(1);
        // The directions are a Hammersley set over the octant, shifted at random per leaf and
        // bin (a Cranley–Patterson rotation): still uniform on average, but spread evenly, so
        // a bin shut along one smooth edge is found with far less noise than by independent
        // directions. Inside a crown, where the leaves cut a bin into many small pieces, the
        // gain is a few per cent: the noise falls as 1/√rays either way.
        // The ray's place on the leaf likewise, from the next two dimensions of the set
        // (Halton's, bases 3 and 5): across a leaf in a dense crown the sky seen changes as
        // much as from one direction to the next.
        let shift: [f32; 4] = std::array::from_fn(|_| rng.next_f32());
        for i in 0..rays {
            let u = (
                ((i as f32 + 0.5) / rays as f32 + shift[0]).fract(),
                (radical_inverse(i, 2) + shift[1]).fract(),
            );
            let w = octant_direction(u, sign);
            let cosine = n.dot(w).abs();
            let origin = if has_surface {
                scene.point_at(
                    leaf,
                    (
                        (radical_inverse(i, 3) + shift[2]).fract(),
                        (radical_inverse(i, 5) + shift[3]).fract(),
                    ),
                )
            } else {
                centre
            };
            lit += cosine * scene.transmittance(origin, w, leaf as u32, opacity);
            weight += cosine;
        }
        if weight > 0.0 { lit / weight } else { 1.0 }
    })
}

/// The digits of `i` in `base` mirrored about the point (base 2: 1 → ½, 2 → ¼, 3 → ¾, …): the
/// van der Corput sequence, which fills [0, 1) evenly at every length.
pub(crate) fn radical_inverse(mut i: u32, base: u32) -> f32 {
    let (mut value, mut scale) = (0.0f64, 1.0f64 / base as f64);
    while i > 0 {
        value += (i % base) as f64 * scale;
        i /= base;
        scale /= base as f64;
    }
    value.min(1.0 - f64::EPSILON) as f32
}

/// The direction of the octant whose axes point along `sign` at `u` in the unit square: `u.0`
/// the height along y (uniform in [0, 1] is uniform in solid angle), `u.1` the azimuth over the
/// quarter turn.
fn octant_direction(u: (f32, f32), sign: Vec3) -> Vec3 {
    let y = u.0;
    let phi = u.1 * std::f32::consts::FRAC_PI_2;
    let r = (1.0 - y * y).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), y, r * phi.sin()) * sign
}

/// The envelope of a crown (§5.6) with every bin's attenuation traced through `scene`: `leaves`
/// the crown's leaves as the envelope sees them, `scene_leaf[i]` leaf i's index in `scene`,
/// `opacity` per scene leaf; on up to `threads` threads, calling `progress(leaves done)` as
/// leaves are traced.
pub fn crown_envelope_traced(
    leaves: &[LeafProxy],
    scene: &LeafScene,
    scene_leaf: &[u32],
    opacity: &(impl Fn(u32) -> f32 + Sync),
    rays_per_bin: u32,
    threads: usize,
    progress: &(dyn Fn(usize) + Sync),
) -> CrownEnvelope {
    let n = leaves.len().min(scene_leaf.len());
    let sums = neighbour_sums(&leaves[..n], threads);
    let traced: Vec<[f32; 8]> = parallel_map_with_progress(
        n,
        threads,
        |i| {
            let leaf = scene_leaf[i] as usize;
            if leaf < scene.leaf_count() {
                // Seeded by the leaf itself, so that its rays are the same whatever its order
                // in the scene or in `leaves`.
                let seed = 0x5EED ^ scene.leaf_key(leaf);
                traced_bins_of(scene, leaf, rays_per_bin, opacity, seed)
            } else {
                sums[i].attenuation
            }
        },
        progress,
    );
    envelope_from_attenuations(&sums, &traced)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::bins::proxies;
    use crate::lighting::path_trace::push_square_leaf;
    use crate::pruning::leaves::LeafSet;
    use bevy::math::Vec3;

    fn traced(leaves: &LeafSet, leaf: usize, rays: u32, opacity: f32) -> [f32; 8] {
        traced_bins_of(&LeafScene::new(leaves), leaf, rays, &|_| opacity, 1)
    }

    #[test]
    fn a_lone_leaf_sees_every_bin_open() {
        let mut leaves = LeafSet::default();
        push_square_leaf(
            &mut leaves,
            Vec3::ZERO,
            0.05,
            Vec3::new(0.3, 1.0, 0.2).normalize(),
        );
        assert_eq!(traced(&leaves, 0, 64, 1.0), [1.0; 8]);
    }

    /// A small leaf under a roof over the half-sky x > 0: the bins looking up and towards +x are
    /// shut (all but the grazing rays that pass the roof's far edge), the others open; a roof
    /// letting half the light through lets half through in those bins.
    #[test]
    fn a_roof_over_half_the_sky_shuts_those_bins_only() {
        for opacity in [1.0f32, 0.5] {
            let mut leaves = LeafSet::default();
            push_square_leaf(
                &mut leaves,
                Vec3::ZERO,
                0.001,
                Vec3::new(0.2, 1.0, -0.4).normalize(),
            );
            // Centre (200, 1, 0), side 400: covers x in [0, 400] at y = 1.
            push_square_leaf(&mut leaves, Vec3::new(200.0, 1.0, 0.0), 200.0, Vec3::Y);
            let bins = traced(&leaves, 0, 256, opacity);
            for (j, a) in bins.iter().enumerate() {
                let under_roof = j & 1 != 0 && j & 2 != 0;
                let expected = if under_roof { 1.0 - opacity } else { 1.0 };
                assert!(
                    (a - expected).abs() < 0.02,
                    "opacity {opacity}: bin {j}: {a}"
                );
            }
        }
    }

    /// A roof over exactly half of one bin — the directions of the octant +x +y +z with x > z —
    /// shuts half its (cosine-weighted) light. The bin's directions are spread evenly, so at
    /// the default 32 rays every seed finds that half within 0.04; independent random
    /// directions are off by 0.09 (one standard deviation) and miss it on most seeds.
    #[test]
    fn a_half_shut_bin_is_found_without_the_noise_of_random_directions() {
        let mut leaves = LeafSet::default();
        push_square_leaf(&mut leaves, Vec3::ZERO, 0.0005, Vec3::Y);
        // The wedge 0 ≤ z ≤ x at y = 1 (the quad's fourth corner on its diagonal).
        leaves.push_quad(
            [
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(4000.0, 1.0, 4000.0),
                Vec3::new(4000.0, 1.0, 0.0),
                Vec3::new(2000.0, 1.0, 2000.0),
            ],
            -Vec3::Y,
        );
        let scene = LeafScene::new(&leaves);
        let mut worst = 0.0f32;
        for seed in 0..24 {
            let bins = traced_bins_of(&scene, 0, DEFAULT_RAYS_PER_BIN, &|_| 1.0, seed);
            worst = worst.max((bins[7] - 0.5).abs());
            // The mirror bin (x < 0, z > 0) is open.
            assert_eq!(bins[6], 1.0);
        }
        assert!(worst < 0.04, "worst error over 24 seeds: {worst}");
    }

    /// Through a crown the traced bins and §5.6's estimate agree on the crown's mean light per
    /// bin within a quarter (they estimate the same quantity; the leaf-by-leaf difference is what
    /// `path_trace`'s test measures), and the traced envelope keeps τ and s_max consistent:
    /// `e^(−τ·s_max)` is the attenuation.
    #[test]
    fn traced_envelope_of_a_crown_is_consistent() {
        use crate::pruning::procedural::{TreeSpecies, generate};
        let tree = generate(&TreeSpecies::olea().with_leaf_count(600));
        let proxies = proxies(&tree.leaves);
        let scene = LeafScene::new(&tree.leaves);
        let order: Vec<u32> = (0..proxies.len() as u32).collect();
        let traced = crown_envelope_traced(&proxies, &scene, &order, &|_| 1.0, 16, 2, &|_| {});
        let neighbours = crate::lighting::envelope::crown_envelope(&proxies, 2);
        assert_eq!(traced.leaves.len(), proxies.len());
        assert!(traced.tau > 0.0);
        let mean = |e: &CrownEnvelope| {
            e.leaves
                .iter()
                .map(|l| l.attenuation.iter().sum::<f32>())
                .sum::<f32>()
                / (8 * e.leaves.len()) as f32
        };
        let (t, n) = (mean(&traced), mean(&neighbours));
        eprintln!(
            "mean light per bin: traced {t:.3}, §5.6 {n:.3}; τ {} / {}",
            traced.tau, neighbours.tau
        );
        assert!(t > 0.1 && t < 0.95 && (t - n).abs() < 0.25 * n, "{t} {n}");
        for l in &traced.leaves {
            for j in 0..8 {
                let a = l.attenuation[j].max(crate::lighting::bins::DARKEST_LIGHT);
                assert!(((-traced.tau * l.s_max[j]).exp() - a).abs() < 1e-3 * a.max(1e-2));
            }
        }
    }

    #[test]
    fn absurd_ray_counts_are_refused() {
        assert!(BinEstimate::Traced { rays_per_bin: 0 }.checked().is_err());
        assert!(
            BinEstimate::Traced {
                rays_per_bin: MAX_RAYS_PER_BIN + 1
            }
            .checked()
            .is_err()
        );
        assert!(BinEstimate::default().checked().is_ok());
        assert!(BinEstimate::Neighbours.checked().is_ok());
    }
}
