//! The per-frame pruning pipeline on the CPU (Gumbau 2011, §3.4, algorithm 2): the reference the
//! GPU compute pass is tested against, index for index.
//!
//! 1. [`view_weights`]: the three stored viewpoints nearest the current view direction and
//!    their weights (`FindCameras`, on the host in the thesis too).
//! 2. [`cell_lod`]: `LoD(cell) = dist · Σ_k w_k · vis(cell, k)` (eq. 3.3–3.5).
//! 3. [`kept_leaves`]: `u_n = round(leaves_n · LoD(cell))`.
//! 4. [`exclusive_scan`]: output offsets `o_{n+1} = o_n + u_n` (eq. 3.6).
//! 5. [`extract_indices`]: each cell copies the first `u_n` leaves of its stochastically ordered
//!    list to its offset.
//!
//! **Fixed point.** LoD arithmetic is done in 16-bit fixed point with integer operations only
//! (`vis` stored as `u16`, weights and the distance factor as fractions of 65,536). Integer
//! arithmetic gives the same answer on every GPU and on the CPU, so the compacted index buffers
//! can be compared exactly; the quantisation (1/65,536) is far below one leaf for any cell.
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

/// The distance factor of eq. 3.4 as a fraction of [`FIXED_ONE`].
pub fn distance_factor_fixed(distance: f32, near: f32, far: f32) -> u32 {
    let f = if distance <= near {
        1.0
    } else if distance >= far {
        0.0
    } else {
        1.0 - (distance - near) / (far - near)
    };
    ((f * FIXED_ONE as f32).round() as u32).min(FIXED_ONE)
}

/// Quantises a visibility in `[0, 1]` to `u16`.
pub fn quantize_visibility(v: f32) -> u16 {
    (v.clamp(0.0, 1.0) * 65535.0).round() as u16
}

/// `LoD(cell)` of eq. 3.5 in fixed point (`0..=65535`): `dist · Σ_k w_k · vis(cell, k)`.
/// `vis` holds the cell's visibility per viewpoint.
pub fn cell_lod(vis: &[u16], weights: &ViewWeights, distance_fixed: u32) -> u32 {
    if distance_fixed == KEEP_ALL {
        return FIXED_ONE - 1;
    }
    let view_lod: u32 = (0..3)
        .map(|k| weights.weights[k] * vis[weights.views[k] as usize] as u32)
        .sum::<u32>()
        >> 16;
    (view_lod * distance_fixed) >> 16
}

/// `u_n = round(leaves · LoD)` in fixed point.
pub fn kept_leaves(leaves: u32, lod_fixed: u32) -> u32 {
    (leaves * lod_fixed + (1 << 15)) >> 16
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
    (0..input.cell_count())
        .map(|c| input.kept_in_cell(c, weights, distance_fixed).1)
        .sum()
}

impl PruningInput<'_> {
    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.cell_first_leaf.len().saturating_sub(1)
    }

    /// Leaves and indices cell `c` keeps: `u_n = round(leaves_n · LoD(cell))` and the index
    /// count of its first `u_n` stored leaves.
    pub fn kept_in_cell(&self, c: usize, weights: &ViewWeights, distance_fixed: u32) -> (u32, u32) {
        let first = self.cell_first_leaf[c];
        let n = self.cell_first_leaf[c + 1] - first;
        let vis = &self.visibility[c * self.views..(c + 1) * self.views];
        let u = kept_leaves(n, cell_lod(vis, weights, distance_fixed));
        let indices =
            self.leaf_index_start[(first + u) as usize] - self.leaf_index_start[first as usize];
        (u, indices)
    }
}

/// Runs the whole per-frame pipeline for one tree.
pub fn extract_indices(
    input: &PruningInput,
    weights: &ViewWeights,
    distance_fixed: u32,
) -> Extraction {
    let cells = input.cell_count();
    let (kept_leaves_v, kept_indices): (Vec<u32>, Vec<u32>) = (0..cells)
        .map(|c| input.kept_in_cell(c, weights, distance_fixed))
        .unzip();
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
        offsets,
        indices,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn distance_factor_matches_eq_3_4() {
        assert_eq!(distance_factor_fixed(5.0, 10.0, 110.0), FIXED_ONE);
        assert_eq!(distance_factor_fixed(60.0, 10.0, 110.0), FIXED_ONE / 2);
        assert_eq!(distance_factor_fixed(200.0, 10.0, 110.0), 0);
    }

    #[test]
    fn full_lod_keeps_everything_and_zero_keeps_nothing() {
        for n in [0, 1, 7, 31, 256, 4096] {
            assert_eq!(
                kept_leaves(
                    n,
                    cell_lod(
                        &[65535],
                        &ViewWeights {
                            views: [0; 3],
                            weights: [FIXED_ONE, 0, 0]
                        },
                        FIXED_ONE
                    )
                ),
                n
            );
            assert_eq!(kept_leaves(n, 0), 0);
        }
        // Half LoD keeps half (rounded).
        assert_eq!(kept_leaves(31, FIXED_ONE / 2), 16);
        assert_eq!(kept_leaves(30, FIXED_ONE / 2), 15);
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
        // View 0 only, full distance factor: cell 0 fully visible (3 leaves), cell 1 half → round(0.5) = 1.
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
