//! The per-frame pruning pipeline on the CPU (Gumbau 2011, §3.4, algorithm 2): the reference the
//! GPU compute pass is tested against, index for index.
//!
//! 1. [`view_weights`]: the three stored viewpoints nearest the current view direction and
//!    their weights (`FindCameras`, on the host in the thesis too).
//! 2. [`cell_lod`]: `LoD(cell) = dist · Σ_k w_k · vis(cell, k)` (eq. 3.3–3.5).
//! 3. [`carried_kept_leaves`]: `u_n ≈ leaves_n · LoD(cell)`, rounded with the remainder carried
//!    from cell to cell (below).
//! 4. [`exclusive_scan`]: output offsets `o_{n+1} = o_n + u_n` (eq. 3.6).
//! 5. [`extract_indices`]: each cell copies the first `u_n` leaves of its stochastically ordered
//!    list to its offset.
//!
//! **Rounding with a carry.** The thesis keeps `round(leaves_n · LoD)` leaves per cell. With few
//! leaves per cell that loses the tree: at one leaf per cell and LoD 0.45 every cell rounds to
//! zero, and even at LoD 0.98 a crown of one-leaf cells keeps only the cells at ≥ 0.5. Here the
//! cells' wanted counts `e_n = leaves_n · LoD(cell)` are summed in cell order (an inclusive
//! prefix sum `P_n`, the same scan the GPU runs for the offsets) and each cell keeps
//! `u_n = ⌈P_n⌉ − ⌈P_{n−1}⌉`: the remainder a cell cannot keep is carried to the next one, like
//! error diffusion. Every cell keeps within one leaf of what eq. 3.5 asks of it, any run of cells
//! keeps within one leaf of the run's sum, and a tree asked for any leaves at all keeps at least
//! one. The OBB tree orders cells depth first, so neighbours in the scan are neighbours in space
//! and the carried leaves stay spread over the crown.
//!
//! **Fixed point.** LoD arithmetic is done in 16-bit fixed point with integer operations only
//! (`vis` stored as `u16`, weights, the distance factor and LoD as fractions of 65,536). Integer
//! arithmetic gives the same answer on every GPU and on the CPU, so the compacted index buffers
//! can be compared exactly; the quantisation (1/65,536) is far below one leaf for any cell. The
//! prefix sums of wanted leaves (in 1/65,536 of a leaf) wrap around `u32` on large trees; since
//! a cell never holds 65,536 leaves, the difference of two wrapped sums, taken modulo 2¹⁶ leaves,
//! is still exact.
//!
//! **View weighting** (the thesis does not give it; see [`ViewWeighting`]): the default weights
//! the three nearest viewpoints by inverse angle, `w_k ∝ 1 / (θ_k + 0.01 rad)`, normalised. It is
//! continuous as the camera moves between viewpoints except when the set of three nearest
//! changes, and exact (weight ≈ 1) when the view direction coincides with a stored viewpoint.

use crate::settings::ViewWeighting;
use bevy::math::Vec3;

/// One in 16-bit fixed point (weights and distance factor are fractions of this).
pub const FIXED_ONE: u32 = 1 << 16;

/// A distance factor meaning "pruning off": every leaf of every cell is kept (full detail).
pub const KEEP_ALL: u32 = u32::MAX;

/// Set in a distance factor (other than [`KEEP_ALL`]): `LoD(cell)` is the distance factor alone,
/// every cell keeping the same fraction of its leaves whatever the viewpoint sees. The view term
/// of eq. 3.5 drops the leaves a view cannot see, which is right for a depth map (a hidden leaf
/// changes no depth) and wrong for a transmittance map, where every leaf on a ray attenuates it.
pub const UNIFORM_DISTANCE: u32 = 1 << 30;

/// The three viewpoints used for a view direction and their fixed-point weights
/// (summing to [`FIXED_ONE`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ViewWeights {
    /// Viewpoint indices.
    pub views: [u32; 3],
    /// Weights, fractions of [`FIXED_ONE`]; they sum to exactly `FIXED_ONE`.
    pub weights: [u32; 3],
}

/// Finds the three stored viewpoints nearest `direction` (tree → camera, in the tree's model
/// space) and weights them. Fewer than three stored viewpoints repeat the last one with weight 0.
pub fn view_weights(direction: Vec3, views: &[Vec3], weighting: ViewWeighting) -> ViewWeights {
    let dir = direction.normalize_or(Vec3::Y);
    let mut best: [(f32, u32); 3] = [(f32::INFINITY, 0); 3];
    for (k, v) in views.iter().enumerate() {
        let angle = dir.dot(*v).clamp(-1.0, 1.0).acos();
        // Insertion into the sorted top three; ties keep the lower index.
        let mut candidate = (angle, k as u32);
        for slot in best.iter_mut() {
            if candidate.0 < slot.0 {
                std::mem::swap(slot, &mut candidate);
            }
        }
    }
    let available = views.len().min(3);
    let raw: [f32; 3] = std::array::from_fn(|i| {
        if i >= available {
            return 0.0;
        }
        match weighting {
            ViewWeighting::Nearest => (i == 0) as u32 as f32,
            ViewWeighting::InverseAngle => 1.0 / (best[i].0 + 0.01),
        }
    });
    let total: f32 = raw.iter().sum();
    let mut weights = [0u32; 3];
    if total > 0.0 {
        weights[1] = (raw[1] / total * FIXED_ONE as f32).floor() as u32;
        weights[2] = (raw[2] / total * FIXED_ONE as f32).floor() as u32;
        weights[0] = FIXED_ONE - weights[1] - weights[2];
    } else {
        weights[0] = FIXED_ONE;
    }
    let views_out = std::array::from_fn(|i| if i < available { best[i].1 } else { best[0].1 });
    ViewWeights {
        views: views_out,
        weights,
    }
}

/// Quantises a visibility in `[0, 1]` to `u16`.
pub fn quantize_visibility(v: f32) -> u16 {
    (v.clamp(0.0, 1.0) * 65535.0).round() as u16
}

/// `LoD(cell)` of eq. 3.5 in fixed point (`0..=FIXED_ONE`): `dist · Σ_k w_k · vis(cell, k)`.
/// `vis` holds the cell's visibility per viewpoint (`u16`, 65,535 = 1). [`KEEP_ALL`] gives
/// [`FIXED_ONE`] whatever the visibility.
pub fn cell_lod(vis: &[u16], weights: &ViewWeights, distance_fixed: u32) -> u32 {
    if distance_fixed == KEEP_ALL {
        return FIXED_ONE;
    }
    if distance_fixed & UNIFORM_DISTANCE != 0 {
        return (distance_fixed & !UNIFORM_DISTANCE).min(FIXED_ONE);
    }
    // Σ w_k vis_k ≤ 65,536 · 65,535 fits a u32; rescaled so that visibility 1 gives exactly 1.
    let sum: u32 = (0..3)
        .map(|k| weights.weights[k] * vis[weights.views[k] as usize] as u32)
        .sum();
    let view_lod = (sum + 32_767) / 65_535;
    if distance_fixed >= FIXED_ONE {
        view_lod
    } else {
        (view_lod * distance_fixed + (1 << 15)) >> 16
    }
}

/// The leaves a cell of `leaves` leaves wants at LoD `lod_fixed`, in 1/65,536 of a leaf
/// (wrapping: only differences of prefix sums are used).
pub fn wanted_leaves(leaves: u32, lod_fixed: u32) -> u32 {
    leaves.wrapping_mul(lod_fixed)
}

/// `⌈P / 65,536⌉` of a (wrapped) prefix sum `P` of wanted leaves, modulo 2¹⁶.
fn carried_ceiling(prefix: u32) -> u32 {
    prefix.wrapping_add(FIXED_ONE - 1) >> 16
}

/// Leaves kept by a cell whose exclusive and inclusive prefix sums of wanted leaves are
/// `before` and `after`: `⌈after⌉ − ⌈before⌉` (the carried rounding described in the module
/// documentation).
pub fn carried_kept_leaves(before: u32, after: u32) -> u32 {
    carried_ceiling(after).wrapping_sub(carried_ceiling(before)) & 0xFFFF
}

/// Exclusive prefix sum: `out[i] = Σ_{j<i} counts[j]`; returns the offsets and the total.
pub fn exclusive_scan(counts: &[u32]) -> (Vec<u32>, u32) {
    let mut acc = 0u32;
    let offsets = counts
        .iter()
        .map(|&c| {
            let o = acc;
            acc += c;
            o
        })
        .collect();
    (offsets, acc)
}

/// The baked data the per-frame pipeline reads.
pub struct PruningInput<'a> {
    /// `cells + 1` entries: cell `c` holds stored leaves `first_leaf[c]..first_leaf[c + 1]`.
    pub cell_first_leaf: &'a [u32],
    /// `leaves + 1` entries: stored leaf `l` owns `indices[leaf_index_start[l]..leaf_index_start[l + 1]]`.
    pub leaf_index_start: &'a [u32],
    /// Leaf triangle indices in stored (cell, then stochastic) order.
    pub indices: &'a [u32],
    /// `vis[cell * views + view]`.
    pub visibility: &'a [u16],
    /// Number of viewpoints.
    pub views: usize,
}

/// Per-cell result of one extraction.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Extraction {
    /// Leaves kept per cell.
    pub kept_leaves: Vec<u32>,
    /// Indices kept per cell.
    pub kept_indices: Vec<u32>,
    /// `LoD(cell)` of each cell (fixed point): the fraction of its leaves eq. 3.5 asks for,
    /// which area compensation divides by.
    pub lods: Vec<u32>,
    /// Output offset of each cell in the compacted index list.
    pub offsets: Vec<u32>,
    /// The compacted index list.
    pub indices: Vec<u32>,
}

impl Extraction {
    /// Total leaves kept.
    pub fn leaves(&self) -> u32 {
        self.kept_leaves.iter().sum()
    }
}

/// Total indices kept for one tree (what the GPU writes into the draw arguments), without
/// building the index list.
pub fn kept_index_total(input: &PruningInput, weights: &ViewWeights, distance_fixed: u32) -> u32 {
    input
        .kept_per_cell(weights, distance_fixed)
        .map(|(_, indices, _)| indices)
        .sum()
}

impl PruningInput<'_> {
    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.cell_first_leaf.len().saturating_sub(1)
    }

    /// Leaves in cell `c`.
    pub fn cell_leaves(&self, c: usize) -> u32 {
        self.cell_first_leaf[c + 1] - self.cell_first_leaf[c]
    }

    /// `LoD(cell)` of cell `c` (eq. 3.5, fixed point).
    pub fn cell_lod(&self, c: usize, weights: &ViewWeights, distance_fixed: u32) -> u32 {
        cell_lod(
            &self.visibility[c * self.views..(c + 1) * self.views],
            weights,
            distance_fixed,
        )
    }

    /// Per cell, in order: the leaves it keeps (carried rounding), the index count of those
    /// leaves, and its `LoD(cell)`.
    pub fn kept_per_cell<'s>(
        &'s self,
        weights: &'s ViewWeights,
        distance_fixed: u32,
    ) -> impl Iterator<Item = (u32, u32, u32)> + 's {
        let mut prefix = 0u32;
        (0..self.cell_count()).map(move |c| {
            let lod = self.cell_lod(c, weights, distance_fixed);
            let before = prefix;
            prefix = prefix.wrapping_add(wanted_leaves(self.cell_leaves(c), lod));
            let kept = carried_kept_leaves(before, prefix);
            let first = self.cell_first_leaf[c] as usize;
            let indices =
                self.leaf_index_start[first + kept as usize] - self.leaf_index_start[first];
            (kept, indices, lod)
        })
    }
}

/// Runs the whole per-frame pipeline for one tree.
pub fn extract_indices(
    input: &PruningInput,
    weights: &ViewWeights,
    distance_fixed: u32,
) -> Extraction {
    let cells = input.cell_count();
    let mut kept_leaves_v = Vec::with_capacity(cells);
    let mut kept_indices = Vec::with_capacity(cells);
    let mut lods = Vec::with_capacity(cells);
    for (leaves, indices, lod) in input.kept_per_cell(weights, distance_fixed) {
        kept_leaves_v.push(leaves);
        kept_indices.push(indices);
        lods.push(lod);
    }
    let (offsets, total) = exclusive_scan(&kept_indices);
    let mut indices = vec![0u32; total as usize];
    for c in 0..cells {
        let start = input.leaf_index_start[input.cell_first_leaf[c] as usize] as usize;
        let count = kept_indices[c] as usize;
        let o = offsets[c] as usize;
        indices[o..o + count].copy_from_slice(&input.indices[start..start + count]);
    }
    Extraction {
        kept_leaves: kept_leaves_v,
        kept_indices,
        lods,
        offsets,
        indices,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Without the view term every cell keeps the distance factor's fraction, whatever its
    /// visibility; with it, a cell no viewpoint sees keeps nothing.
    #[test]
    fn a_uniform_distance_ignores_visibility() {
        let weights = ViewWeights {
            views: [0, 1, 2],
            weights: [FIXED_ONE, 0, 0],
        };
        let half = FIXED_ONE / 2;
        for vis in [[0u16; 3], [65535; 3], [1000, 40000, 65535]] {
            assert_eq!(cell_lod(&vis, &weights, half | UNIFORM_DISTANCE), half);
        }
        assert_eq!(cell_lod(&[0; 3], &weights, half), 0);
        assert_eq!(cell_lod(&[65535; 3], &weights, half), half);
        // A factor above one is one.
        assert_eq!(
            cell_lod(&[0; 3], &weights, (2 * FIXED_ONE) | UNIFORM_DISTANCE),
            FIXED_ONE
        );
    }

    #[test]
    fn weights_sum_to_one_and_favour_the_nearest_view() {
        let views = crate::pruning::visibility::fibonacci_directions(16);
        for dir in [Vec3::X, Vec3::new(0.3, -0.8, 0.2), views[5]] {
            let w = view_weights(dir, &views, ViewWeighting::InverseAngle);
            assert_eq!(w.weights.iter().sum::<u32>(), FIXED_ONE);
            assert!(
                w.weights[0] >= w.weights[1] && w.weights[1] >= w.weights[2],
                "{w:?}"
            );
            // The first view is the nearest by angle.
            let nearest = (0..16)
                .max_by(|&a, &b| {
                    dir.normalize()
                        .dot(views[a])
                        .total_cmp(&dir.normalize().dot(views[b]))
                })
                .unwrap();
            assert_eq!(w.views[0], nearest as u32);
        }
        // On a viewpoint, that viewpoint dominates.
        let w = view_weights(views[5], &views, ViewWeighting::InverseAngle);
        assert_eq!(w.views[0], 5);
        assert!(w.weights[0] > FIXED_ONE * 9 / 10);
        let n = view_weights(Vec3::X, &views, ViewWeighting::Nearest);
        assert_eq!(n.weights, [FIXED_ONE, 0, 0]);
    }

    /// Cells of the given sizes, one leaf = one quad (6 indices), one viewpoint.
    struct Cells {
        cell_first_leaf: Vec<u32>,
        leaf_index_start: Vec<u32>,
        indices: Vec<u32>,
        visibility: Vec<u16>,
    }

    impl Cells {
        fn new(sizes: &[u32], visibility: &[u16]) -> Self {
            let mut cell_first_leaf = vec![0];
            for s in sizes {
                cell_first_leaf.push(cell_first_leaf.last().unwrap() + s);
            }
            let leaves = *cell_first_leaf.last().unwrap();
            Self {
                cell_first_leaf,
                leaf_index_start: (0..=leaves).map(|l| l * 6).collect(),
                indices: (0..leaves * 6).collect(),
                visibility: visibility.to_vec(),
            }
        }

        fn input(&self) -> PruningInput<'_> {
            PruningInput {
                cell_first_leaf: &self.cell_first_leaf,
                leaf_index_start: &self.leaf_index_start,
                indices: &self.indices,
                visibility: &self.visibility,
                views: 1,
            }
        }
    }

    const ONE_VIEW: ViewWeights = ViewWeights {
        views: [0; 3],
        weights: [FIXED_ONE, 0, 0],
    };

    #[test]
    fn full_lod_keeps_everything_and_zero_keeps_nothing() {
        let sizes = [1, 7, 31, 256, 4096, 0, 3];
        let cells = Cells::new(&sizes, &[65535; 7]);
        for distance in [FIXED_ONE, KEEP_ALL] {
            let e = extract_indices(&cells.input(), &ONE_VIEW, distance);
            assert_eq!(e.kept_leaves, sizes.to_vec());
            assert!(e.lods.iter().all(|&l| l == FIXED_ONE));
        }
        let hidden = Cells::new(&sizes, &[0; 7]);
        assert_eq!(
            extract_indices(&hidden.input(), &ONE_VIEW, FIXED_ONE).leaves(),
            0
        );
        // Pruning off keeps the hidden cells too.
        assert_eq!(
            extract_indices(&hidden.input(), &ONE_VIEW, KEEP_ALL).leaves(),
            sizes.iter().sum::<u32>()
        );
        assert_eq!(extract_indices(&cells.input(), &ONE_VIEW, 0).leaves(), 0);
    }

    #[test]
    fn one_leaf_cells_keep_the_fraction_asked_for_not_zero() {
        // 560 leaves in 512 cells: the small tree that per-cell rounding left bare.
        let sizes: Vec<u32> = (0..512).map(|c| 1 + (c % 11 == 0) as u32).collect();
        let total: u32 = sizes.iter().sum();
        let cells = Cells::new(&sizes, &vec![65535; 512]);
        for factor in [0.98f32, 0.7, 0.45, 0.2, 0.01, 0.001] {
            let distance = (factor * FIXED_ONE as f32).round() as u32;
            let e = extract_indices(&cells.input(), &ONE_VIEW, distance);
            let asked: f64 = sizes
                .iter()
                .zip(&e.lods)
                .map(|(&n, &l)| n as f64 * l as f64 / FIXED_ONE as f64)
                .sum();
            let kept = e.leaves() as f64;
            assert!(
                kept >= asked && kept < asked + 1.0,
                "factor {factor}: kept {kept} of {total}, eq. 3.5 asks {asked:.2}"
            );
            assert!(kept >= 1.0, "a tree asked for leaves keeps at least one");
        }
    }

    #[test]
    fn carried_rounding_stays_within_one_leaf_per_cell_and_per_run() {
        let mut rng = crate::rng::SplitMix64::new(7);
        for _ in 0..200 {
            let n = 1 + rng.below(300) as usize;
            let sizes: Vec<u32> = (0..n).map(|_| rng.below(200)).collect();
            let vis: Vec<u16> = (0..n).map(|_| rng.below(65536) as u16).collect();
            let distance = rng.below(FIXED_ONE + 1);
            let cells = Cells::new(&sizes, &vis);
            let e = extract_indices(&cells.input(), &ONE_VIEW, distance);
            let wanted: Vec<f64> = sizes
                .iter()
                .zip(&e.lods)
                .map(|(&s, &l)| s as f64 * l as f64 / FIXED_ONE as f64)
                .collect();
            let mut run_kept = 0.0;
            let mut run_wanted = 0.0;
            for c in 0..n {
                let k = e.kept_leaves[c] as f64;
                assert!(e.kept_leaves[c] <= sizes[c]);
                assert!(
                    (k - wanted[c]).abs() < 1.0,
                    "cell {c}: {k} vs {}",
                    wanted[c]
                );
                run_kept += k;
                run_wanted += wanted[c];
                // Any prefix (hence any run) keeps within one leaf of what it asks.
                assert!(run_kept >= run_wanted - 1e-9 && run_kept < run_wanted + 1.0);
                assert_eq!(e.kept_indices[c], e.kept_leaves[c] * 6);
            }
            assert_eq!(
                kept_index_total(&cells.input(), &ONE_VIEW, distance),
                e.indices.len() as u32
            );
        }
    }

    #[test]
    fn wrapped_prefix_sums_give_the_same_counts() {
        // Prefix sums of a large tree pass 2^32 (in 1/65,536 of a leaf): the wrapped u32
        // arithmetic of the GPU gives the counts of exact arithmetic.
        let mut rng = crate::rng::SplitMix64::new(3);
        let (mut exact, mut wrapped) = (0u64, 0u32);
        for _ in 0..5000 {
            let leaves = rng.below(65_535);
            let lod = rng.below(FIXED_ONE + 1);
            let (e0, w0) = (exact, wrapped);
            exact += leaves as u64 * lod as u64;
            wrapped = wrapped.wrapping_add(wanted_leaves(leaves, lod));
            let ceil = |p: u64| p.div_ceil(FIXED_ONE as u64);
            assert_eq!(
                carried_kept_leaves(w0, wrapped) as u64,
                ceil(exact) - ceil(e0)
            );
        }
        assert!(exact > u32::MAX as u64 * 100);
    }

    #[test]
    fn scan_and_compaction_concatenate_cell_prefixes() {
        // Two cells: cell 0 has leaves {0,1,2} (quads, 6 indices each), cell 1 has {3}.
        let cell_first_leaf = [0, 3, 4];
        let leaf_index_start = [0, 6, 12, 18, 21];
        let indices: Vec<u32> = (100..121).collect();
        let visibility = [65535u16, 0, 32768, 65535]; // 2 views
        let input = PruningInput {
            cell_first_leaf: &cell_first_leaf,
            leaf_index_start: &leaf_index_start,
            indices: &indices,
            visibility: &visibility,
            views: 2,
        };
        // View 0 only, full distance factor: cell 0 fully visible (3 leaves), cell 1 half → ⌈0.5⌉ = 1.
        let w = ViewWeights {
            views: [0, 1, 1],
            weights: [FIXED_ONE, 0, 0],
        };
        let e = extract_indices(&input, &w, FIXED_ONE);
        assert_eq!(e.kept_leaves, vec![3, 1]);
        assert_eq!(e.kept_indices, vec![18, 3]);
        assert_eq!(e.offsets, vec![0, 18]);
        assert_eq!(e.indices, (100..121).collect::<Vec<_>>());
        // View 1 only: cell 0 hidden, cell 1 visible.
        let w = ViewWeights {
            views: [1, 0, 0],
            weights: [FIXED_ONE, 0, 0],
        };
        let e = extract_indices(&input, &w, FIXED_ONE);
        assert_eq!(e.kept_leaves, vec![0, 1]);
        assert_eq!(e.indices, (118..121).collect::<Vec<_>>());
        assert_eq!(kept_index_total(&input, &w, FIXED_ONE), 3);
        // Pruning off keeps everything whatever the visibility.
        let all = extract_indices(&input, &w, KEEP_ALL);
        assert_eq!(all.indices, (100..121).collect::<Vec<_>>());
        assert_eq!(kept_index_total(&input, &w, KEEP_ALL), 21);
        assert_eq!(exclusive_scan(&[3, 0, 2]), (vec![0, 3, 3], 5));
    }
}
