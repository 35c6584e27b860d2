//! A tree's crown as a volume of leaves seen from each leaf (Boulanger 2008, §5.2.1 and §5.6):
//! per leaf and per fixed sampling direction ω_j, how much light the leaves between it and the
//! crown's envelope let through, and the envelope's distance `s_max(P, ω_j)`, with the crown's
//! extinction τ fitted to them. Plain Rust, run once per tree type (the CPU side of the tree
//! lighting; its shaders read the results per leaf).
//!
//! **The bins** (§5.6): the eight directions ω_j = (±ξ, ±ξ, ±ξ), ξ = √3/3, split the sphere into
//! their octants, each of solid angle π/2; every other leaf falls in the bin of the octant of
//! the vector from P to its centre.
//!
//! **The attenuation** of bin j: its leaves, nearest first, each occlude the fraction
//! `o = Ω_leaf / Ω_bin` of what remains (Ω_leaf the solid angle the leaf subtends from P,
//! `A·|n·d̂| / r²` for a leaf small against its distance, capped at the bin's); the visibility
//! left after all of them, `a_j = Π (1 − o_k)`, is what eq. 5.5 models as `e^(−τ·s_max)`.
//!
//! **τ and s_max** (§5.6): per leaf and bin, a first estimate of the envelope's distance `s`
//! gives `τ_{P,j} = −ln(a_j) / s`; their mean over every (leaf, bin) with neighbours is the
//! tree's τ, from which `s_max(P, ω_j) = −ln(a_j) / τ` — so `e^(−τ·s_max)` is the attenuation
//! exactly, and the lighting's products of τ and s_max do not depend on the fit.
//!
//! A bake traces the attenuations through the leaves by default ([`super::traced_bins`], far
//! closer leaf by leaf); the neighbours' distances per bin computed here still fit τ then
//! ([`envelope_from_attenuations`]). The thesis
//! takes the bin's farthest leaf for `s`; the attenuation, though, integrates the bin's *mean*
//! path, so in a uniform ball of leaves that fit comes out a third below eq. 5.5's τ = A·ρ/2
//! (0.233 against 0.358 in the test below). Here `s` is 4/3 of the mean distance of the bin's
//! leaves — where leaves spread uniformly in a cone up to `s` lie on average — which comes out a
//! fifth below (0.286): closer, and the bias left is the envelope's varying distance across an
//! off-centre leaf's bins.

pub use super::bins::{
    BIN_SOLID_ANGLE, BinSums, DARKEST_LIGHT, DIRECTIONS, LeafProxy, XI, bin_of, light_of,
    occlusion, proxies, quantize_light,
};
use super::leaf_tree::LeafTree;

/// What one leaf sees in the eight directions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafEnvelope {
    /// `a_j`: the light let through by the leaves of bin j (1: none).
    pub attenuation: [f32; 8],
    /// `s_max(P, ω_j)`: the distance to the envelope, `−ln(a_j) / τ`.
    pub s_max: [f32; 8],
}

impl LeafEnvelope {
    /// The envelope as a bake stores it, back: the attenuations of [`quantize_light`] and
    /// `s_max = −ln(a_j) / τ`, a shut bin letting the least a bake stores through — what the
    /// leaf shaders read (`tree_lighting.wgsl`). A τ of 0 or not finite: no distance.
    pub fn from_stored(stored: &[u16; 8], tau: f32) -> Self {
        let attenuation = stored.map(light_of);
        Self {
            attenuation,
            s_max: attenuation.map(|a| {
                if tau > 0.0 && tau.is_finite() {
                    -a.max(DARKEST_LIGHT).ln() / tau
                } else {
                    0.0
                }
            }),
        }
    }
}

/// A tree's envelope: per leaf, in the order of the leaves given, and the fitted τ.
#[derive(Clone, Debug, PartialEq)]
pub struct CrownEnvelope {
    /// Per leaf.
    pub leaves: Vec<LeafEnvelope>,
    /// The crown's optical thickness per unit distance (eq. 5.5), fitted (§5.6); 0 for a crown
    /// with no leaf behind another.
    pub tau: f32,
}

/// What the leaf at `index` sees per bin, every other leaf taken one by one.
fn exact_bins_of(leaves: &[LeafProxy], index: usize) -> BinSums {
    let p = leaves[index].centre;
    let mut sums = BinSums::default();
    for (k, q) in leaves.iter().enumerate() {
        if k != index {
            // The product is the same in any order; the thesis walks the bin nearest first.
            sums.add_leaf(q.centre - p, occlusion(p, q));
        }
    }
    sums
}

/// Per bin, the envelope's distance for the fit: leaves spread uniformly in a cone up to
/// distance s lie at 3s/4 on average (see the module docs).
fn envelope_distances(sums: &BinSums) -> [f32; 8] {
    std::array::from_fn(|j| {
        if sums.count[j] > 0 {
            (4.0 / 3.0 * sums.distance_sum[j] / sums.count[j] as f32).min(sums.farthest[j])
        } else {
            0.0
        }
    })
}

/// Crowns of up to this many leaves are computed leaf by leaf; larger ones through the
/// [`LeafTree`] (far groups of leaves as one occluder).
pub const EXACT_UP_TO: usize = 4096;

/// The envelope of the crown made of `leaves` (§5.6), on up to `threads` threads: leaf by leaf
/// up to [`EXACT_UP_TO`] leaves, through a [`LeafTree`] beyond.
pub fn crown_envelope(leaves: &[LeafProxy], threads: usize) -> CrownEnvelope {
    crown_envelope_with(leaves, threads, leaves.len() > EXACT_UP_TO)
}

/// [`crown_envelope`], through the octree or leaf by leaf as `clustered` says.
pub fn crown_envelope_with(leaves: &[LeafProxy], threads: usize, clustered: bool) -> CrownEnvelope {
    let sums = neighbour_sums_with(leaves, threads, clustered);
    let attenuation: Vec<[f32; 8]> = sums.iter().map(|s| s.attenuation).collect();
    envelope_from_attenuations(&sums, &attenuation)
}

/// What every leaf sees of its neighbours per bin (§5.6), as [`crown_envelope`] computes it.
pub fn neighbour_sums(leaves: &[LeafProxy], threads: usize) -> Vec<BinSums> {
    neighbour_sums_with(leaves, threads, leaves.len() > EXACT_UP_TO)
}

fn neighbour_sums_with(leaves: &[LeafProxy], threads: usize, clustered: bool) -> Vec<BinSums> {
    let tree = clustered.then(|| LeafTree::new(leaves));
    parallel_map(leaves.len(), threads, |i| match &tree {
        Some(tree) => tree.bins_of(i),
        None => exact_bins_of(leaves, i),
    })
}

/// The envelope from every leaf's attenuations per bin (§5.6's or traced ones) and the
/// neighbours' distances per bin: τ_{P,j} = −ln(a_j) / s_j over every (leaf, bin) with a leaf
/// in it, averaged, and `s_max = −ln(a_j) / τ`.
pub fn envelope_from_attenuations(sums: &[BinSums], attenuation: &[[f32; 8]]) -> CrownEnvelope {
    let (mut sum, mut count) = (0.0f64, 0usize);
    for (s, attenuation) in sums.iter().zip(attenuation) {
        let envelope = envelope_distances(s);
        for j in 0..8 {
            if attenuation[j] < 1.0 && attenuation[j] > 0.0 && envelope[j] > 0.0 {
                sum += (-(attenuation[j] as f64).ln()) / envelope[j] as f64;
                count += 1;
            }
        }
    }
    let tau = if count > 0 {
        (sum / count as f64) as f32
    } else {
        0.0
    };
    let leaves = attenuation
        .iter()
        .map(|attenuation| LeafEnvelope {
            attenuation: *attenuation,
            // A bin shut by a leaf lets through the least a bake stores (its distance stays
            // finite, as the lighting's sums need).
            s_max: attenuation.map(|a| {
                if tau > 0.0 {
                    -a.max(DARKEST_LIGHT).ln() / tau
                } else {
                    0.0
                }
            }),
        })
        .collect();
    CrownEnvelope { leaves, tau }
}

/// `f(0..n)` on up to `threads` threads, in order.
pub(crate) fn parallel_map<T: Send + Clone + Default>(
    n: usize,
    threads: usize,
    f: impl Fn(usize) -> T + Sync,
) -> Vec<T> {
    parallel_map_with_progress(n, threads, f, &|_| {})
}

/// [`parallel_map`], calling `progress(done)` after every chunk.
pub(crate) fn parallel_map_with_progress<T: Send + Clone + Default>(
    n: usize,
    threads: usize,
    f: impl Fn(usize) -> T + Sync,
    progress: &(dyn Fn(usize) + Sync),
) -> Vec<T> {
    let done = std::sync::atomic::AtomicUsize::new(0);
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results = std::sync::Mutex::new(vec![T::default(); n]);
    const CHUNK: usize = 32;
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, n.div_ceil(CHUNK).max(1)) {
            scope.spawn(|| {
                loop {
                    let start = next.fetch_add(CHUNK, std::sync::atomic::Ordering::Relaxed);
                    if start >= n {
                        break;
                    }
                    let chunk: Vec<T> = (start..(start + CHUNK).min(n)).map(&f).collect();
                    results.lock().unwrap()[start..start + chunk.len()].clone_from_slice(&chunk);
                    let so_far = done.fetch_add(chunk.len(), std::sync::atomic::Ordering::Relaxed)
                        + chunk.len();
                    progress(so_far);
                }
            });
        }
    });
    results.into_inner().unwrap()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use bevy::math::Vec3;

    /// A deterministic uniform source, with unit vectors.
    struct Random(SplitMix64);
    impl Random {
        fn next(&mut self) -> f32 {
            self.0.next_f32()
        }
        fn unit(&mut self) -> Vec3 {
            loop {
                let v = Vec3::new(self.next(), self.next(), self.next()) * 2.0 - 1.0;
                if v.length_squared() > 1e-4 && v.length_squared() <= 1.0 {
                    return v.normalize();
                }
            }
        }
    }

    /// `count` leaves of area `area`, uniform in a ball of `radius`, uniformly oriented.
    fn ball(count: usize, radius: f32, area: f32, seed: u64) -> Vec<LeafProxy> {
        let mut random = Random(SplitMix64::new(seed));
        let mut out = Vec::with_capacity(count);
        while out.len() < count {
            let p = Vec3::new(random.next(), random.next(), random.next()) * 2.0 - 1.0;
            if p.length_squared() <= 1.0 {
                out.push(LeafProxy {
                    centre: p * radius,
                    normal: random.unit(),
                    area,
                });
            }
        }
        out
    }

    /// A real crown (the procedural olive, 2,000 leaves): leaves deep in the crown get less
    /// light than leaves on its surface, and the light from below (through the crown's base)
    /// is less than from above for a leaf in the crown's upper half.
    #[test]
    fn a_real_crown_is_darker_inside() {
        use crate::pruning::procedural::{TreeSpecies, generate};
        let tree = generate(&TreeSpecies::olea().with_leaf_count(2000));
        let leaves = proxies(&tree.leaves);
        let start = std::time::Instant::now();
        let envelope = crown_envelope(&leaves, 2);
        let centre = leaves.iter().map(|l| l.centre).sum::<Vec3>() / leaves.len() as f32;
        let mean_light = |e: &LeafEnvelope| e.attenuation.iter().sum::<f32>() / 8.0;
        let mut by_depth: Vec<(f32, f32)> = leaves
            .iter()
            .zip(&envelope.leaves)
            .map(|(l, e)| (l.centre.distance(centre), mean_light(e)))
            .collect();
        by_depth.sort_by(|a, b| a.0.total_cmp(&b.0));
        let tenth = by_depth.len() / 10;
        let inner = by_depth[..tenth].iter().map(|x| x.1).sum::<f32>() / tenth as f32;
        let outer = by_depth[by_depth.len() - tenth..]
            .iter()
            .map(|x| x.1)
            .sum::<f32>()
            / tenth as f32;
        eprintln!(
            "olive of {} leaves in {:?}: τ {}, mean light inner tenth {inner}, outer tenth {outer}",
            leaves.len(),
            start.elapsed(),
            envelope.tau
        );
        assert!(envelope.tau > 0.0);
        assert!(inner < outer - 0.1, "inner {inner} vs outer {outer}");
    }

    /// The octree's envelope is the exact one within a few percent of light, in a real crown
    /// and in the uniform ball, and a crown of 40,000 leaves takes seconds, not minutes.
    #[test]
    fn the_clustered_envelope_matches_the_exact_one() {
        use crate::pruning::procedural::{TreeSpecies, generate};
        let olive = proxies(&generate(&TreeSpecies::olea().with_leaf_count(3000)).leaves);
        for (name, leaves) in [("olive", olive), ("ball", ball(3000, 2.0, 0.008, 3))] {
            let exact = crown_envelope_with(&leaves, 2, false);
            let clustered = crown_envelope_with(&leaves, 2, true);
            let mut errors: Vec<f32> = exact
                .leaves
                .iter()
                .zip(&clustered.leaves)
                .flat_map(|(e, c)| (0..8).map(move |j| (e.attenuation[j] - c.attenuation[j]).abs()))
                .collect();
            errors.sort_by(f32::total_cmp);
            let mean = errors.iter().sum::<f32>() / errors.len() as f32;
            let p99 = errors[errors.len() * 99 / 100];
            eprintln!(
                "{name}: |Δa| mean {mean:.4}, 99th percentile {p99:.3}, worst {:.3}; τ exact {} \
                 clustered {}",
                errors[errors.len() - 1],
                exact.tau,
                clustered.tau
            );
            // A far node lies in one bin: near a bin's edge its leaves' light goes to one side.
            assert!(mean < 0.01 && p99 < 0.06, "{name}: {mean} {p99}");
            assert!(
                (clustered.tau - exact.tau).abs() < 0.05 * exact.tau,
                "{name}"
            );
        }
        let big = proxies(&generate(&TreeSpecies::quercus()).leaves);
        let start = std::time::Instant::now();
        let envelope = crown_envelope(&big, 2);
        eprintln!(
            "{} leaves: {:?}, τ {}",
            big.len(),
            start.elapsed(),
            envelope.tau
        );
        assert_eq!(envelope.leaves.len(), big.len());
    }

    #[test]
    fn the_bins_are_the_octants_of_the_directions() {
        for (j, d) in DIRECTIONS.iter().enumerate() {
            assert_eq!(bin_of(*d), j);
            assert!((d.length() - 1.0).abs() < 1e-6);
        }
        assert_eq!(bin_of(Vec3::new(0.1, -3.0, 0.2)), 0b101);
    }

    /// A lone leaf sees nothing: full light every way, the envelope at the leaf.
    #[test]
    fn a_single_leaf_is_unoccluded() {
        let leaf = LeafProxy {
            centre: Vec3::ONE,
            normal: Vec3::Y,
            area: 0.01,
        };
        let envelope = crown_envelope(&[leaf], 2);
        assert_eq!(envelope.tau, 0.0);
        assert_eq!(envelope.leaves[0].attenuation, [1.0; 8]);
        assert_eq!(envelope.leaves[0].s_max, [0.0; 8]);
    }

    /// A leaf straight above another, facing it, at distance r: only the upper bins see it, and
    /// each occludes `A / r² / (π/2)` of them — the lower leaf's upward bins hold it (it lies
    /// on the bins' shared edge, so it falls in the +x +z one).
    #[test]
    fn one_neighbour_occludes_its_solid_angle() {
        let below = LeafProxy {
            centre: Vec3::ZERO,
            normal: Vec3::Y,
            area: 0.02,
        };
        let above = LeafProxy {
            centre: Vec3::Y * 0.5,
            ..below
        };
        let envelope = crown_envelope(&[below, above], 1);
        let expected = 1.0 - 0.02 / 0.25 / BIN_SOLID_ANGLE;
        let a = envelope.leaves[0].attenuation;
        assert!((a[0b111] - expected).abs() < 1e-6, "{a:?}");
        assert_eq!(a.iter().filter(|&&x| x < 1.0).count(), 1);
        // τ from the one (leaf, bin) pair each: −ln(a)/0.5.
        assert!((envelope.tau - (-expected.ln() / 0.5)).abs() < 1e-5);
        assert!((envelope.leaves[0].s_max[0b111] - 0.5).abs() < 1e-5);
    }

    /// A uniform ball of leaves: the fitted τ is eq. 5.5's `A·ρ/2`, and the centre leaf's light
    /// in every direction is close to `e^(−τ·R)` — the envelope a sphere of radius R around it.
    #[test]
    fn a_uniform_ball_has_the_extinction_of_eq_5_5() {
        let (count, radius, area) = (6000usize, 2.0f32, 0.004f32);
        let mut leaves = ball(count, radius, area, 7);
        // A leaf at the very centre.
        leaves[0].centre = Vec3::ZERO;
        let envelope = crown_envelope(&leaves, 2);
        let density = count as f32 / (4.0 / 3.0 * std::f32::consts::PI * radius.powi(3));
        let predicted = area * density / 2.0;
        let centre = envelope.leaves[0];
        let expected = -predicted * radius;
        let log_mean = centre.attenuation.iter().map(|a| a.ln()).sum::<f32>() / 8.0;
        eprintln!(
            "τ fitted {} vs A·ρ/2 = {predicted}; centre attenuations {:?}, geometric mean {} vs \
             e^(−A·ρ/2·R) = {}",
            envelope.tau,
            centre.attenuation,
            log_mean.exp(),
            expected.exp()
        );
        // The attenuation itself is eq. 5.5's, whatever the fit.
        assert!(
            (log_mean - expected).abs() < 0.15 * expected.abs(),
            "{log_mean} vs {expected}"
        );
        let mut sorted = centre.attenuation;
        sorted.sort_by(f32::total_cmp);
        assert!((sorted[4] - expected.exp()).abs() < 0.08, "{sorted:?}");
        // The fit, a fifth low (see the module docs).
        assert!(
            (0.75 * predicted..1.05 * predicted).contains(&envelope.tau),
            "τ {} vs {predicted}",
            envelope.tau
        );
        // s_max reproduces the attenuation exactly.
        for leaf in &envelope.leaves {
            for j in 0..8 {
                let a = leaf.attenuation[j];
                if a > 0.0 {
                    assert!(((-envelope.tau * leaf.s_max[j]).exp() - a).abs() < 1e-4);
                }
            }
            // And so does the envelope a bake stores, read back: within a quantisation step
            // of the attenuation, its distance within what that step moves it.
            let back =
                LeafEnvelope::from_stored(&leaf.attenuation.map(quantize_light), envelope.tau);
            for j in 0..8 {
                assert!((back.attenuation[j] - leaf.attenuation[j]).abs() <= 0.5 / 65535.0 + 1e-7);
                let a = leaf.attenuation[j].max(DARKEST_LIGHT);
                let step = 1.0 / (65535.0 * a * envelope.tau);
                assert!(
                    (back.s_max[j] - leaf.s_max[j]).abs() <= step + 1e-4,
                    "bin {j}: {} vs {}",
                    back.s_max[j],
                    leaf.s_max[j]
                );
            }
        }
        // A crown with no τ (or a broken one) has no distances.
        for tau in [0.0, f32::NAN, f32::INFINITY] {
            assert_eq!(LeafEnvelope::from_stored(&[0; 8], tau).s_max, [0.0; 8]);
        }
        // A leaf at the surface sees the whole ball on one side and nothing on the other.
        let surface = leaves
            .iter()
            .position(|l| {
                l.centre.x > 0.95 * radius && l.centre.y.abs() < 0.3 && l.centre.z.abs() < 0.3
            })
            .expect("a leaf near +x");
        let s = envelope.leaves[surface].s_max;
        let (inward, outward) = (s[0b000].max(s[0b010]), s[0b001].min(s[0b011]));
        assert!(inward > 3.0 * outward.max(0.05), "{s:?}");
    }
}
