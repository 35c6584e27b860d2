//! Bake step 1: the cell cloud (Gumbau 2011, §3.3.1).
//!
//! An OBB tree (Gottschalk, Lin & Manocha 1996) over the leaves: each node's box is aligned with
//! the principal axes of its leaf centroids; a node is split across its major axis until the
//! given depth, and the leaf nodes are the cells (depth 9 → 512 cells, the thesis' figure).
//! Every leaf belongs to exactly one cell.
//!
//! Choice: nodes are split at the **median** of the centroids projected on the major axis, not at
//! the mean. The cells then hold equal leaf counts (±1), which keeps the per-cell GPU work uniform
//! and avoids empty cells on lopsided crowns; the boxes stay tight because the split axis is
//! still the major one.

use bevy::math::{Mat3, Vec3};

/// An oriented bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Obb {
    /// Centre.
    pub center: Vec3,
    /// Unit axes (columns), major first.
    pub axes: Mat3,
    /// Half extents along each axis.
    pub half_extents: Vec3,
}

impl Obb {
    /// Whether `p` is inside the box grown by `eps`.
    pub fn contains(&self, p: Vec3, eps: f32) -> bool {
        let d = p - self.center;
        (0..3).all(|i| d.dot(self.axes.col(i)).abs() <= self.half_extents[i] + eps)
    }
}

/// A cell: a set of leaves and their box.
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    /// Leaf indices (into the input leaf set).
    pub leaves: Vec<u32>,
    /// Box around the leaves' vertices.
    pub obb: Obb,
}

/// Eigen-decomposition of a symmetric 3×3 matrix by cyclic Jacobi rotations.
/// Returns eigenvalues and the matrix whose columns are the matching unit eigenvectors,
/// sorted by decreasing eigenvalue.
// The Jacobi rotation reads as in the textbook with explicit indices.
#[allow(clippy::needless_range_loop)]
pub fn symmetric_eigen(m: Mat3) -> (Vec3, Mat3) {
    let mut a = [[0.0f64; 3]; 3];
    for (i, row) in a.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = m.col(j)[i] as f64;
        }
    }
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0f64]];
    for _sweep in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off < 1e-15 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A' = Jᵀ A J with the rotation in the (p, q) plane.
            for k in 0..3 {
                let akp = a[k][p];
                let akq = a[k][q];
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let apk = a[p][k];
                let aqk = a[q][k];
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in v.iter_mut() {
                let vkp = row[p];
                let vkq = row[q];
                row[p] = c * vkp - s * vkq;
                row[q] = s * vkp + c * vkq;
            }
        }
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| a[j][j].total_cmp(&a[i][i]));
    let values = Vec3::new(
        a[order[0]][order[0]] as f32,
        a[order[1]][order[1]] as f32,
        a[order[2]][order[2]] as f32,
    );
    let col =
        |k: usize| Vec3::new(v[0][k] as f32, v[1][k] as f32, v[2][k] as f32).normalize_or_zero();
    let mut c0 = col(order[0]);
    let mut c1 = col(order[1]);
    if c0 == Vec3::ZERO {
        c0 = Vec3::X;
    }
    if c1 == Vec3::ZERO || c1.dot(c0).abs() > 0.9 {
        c1 = c0.any_orthonormal_vector();
    }
    let c2 = c0.cross(c1).normalize();
    (values, Mat3::from_cols(c0, c1, c2))
}

/// The OBB of `points` aligned with the principal axes of `centroids`.
fn fit_obb(centroids: &[Vec3], points: impl Iterator<Item = Vec3> + Clone) -> Obb {
    let n = centroids.len().max(1) as f32;
    let mean = centroids.iter().copied().sum::<Vec3>() / n;
    let mut cov = Mat3::ZERO;
    for &c in centroids {
        let d = c - mean;
        cov += Mat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let (_, axes) = symmetric_eigen(cov * (1.0 / n));
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for p in points {
        let local = axes.transpose() * p;
        lo = lo.min(local);
        hi = hi.max(local);
    }
    if !lo.is_finite() {
        lo = Vec3::ZERO;
        hi = Vec3::ZERO;
    }
    Obb {
        center: axes * ((lo + hi) * 0.5),
        axes,
        half_extents: (hi - lo) * 0.5,
    }
}

/// Builds the cell cloud: an OBB tree of `depth` levels over leaves with centroids `centroids`.
/// `leaf_points(i)` lists the vertices of leaf `i` (for the boxes). Produces `2^depth` cells,
/// fewer only when there are fewer leaves than that; never an empty cell.
pub fn build_cells<P, I>(centroids: &[Vec3], depth: u32, leaf_points: P) -> Vec<Cell>
where
    P: Fn(u32) -> I + Copy,
    I: Iterator<Item = Vec3> + Clone,
{
    let mut cells = Vec::with_capacity(1 << depth.min(16));
    let all: Vec<u32> = (0..centroids.len() as u32).collect();
    split(centroids, all, depth, leaf_points, &mut cells);
    cells
}

fn split<P, I>(
    centroids: &[Vec3],
    mut leaves: Vec<u32>,
    depth: u32,
    leaf_points: P,
    out: &mut Vec<Cell>,
) where
    P: Fn(u32) -> I + Copy,
    I: Iterator<Item = Vec3> + Clone,
{
    if leaves.is_empty() {
        return;
    }
    let own: Vec<Vec3> = leaves.iter().map(|&i| centroids[i as usize]).collect();
    if depth == 0 || leaves.len() < 2 {
        let points: Vec<Vec3> = leaves.iter().flat_map(|&i| leaf_points(i)).collect();
        out.push(Cell {
            obb: fit_obb(&own, points.iter().copied()),
            leaves,
        });
        return;
    }
    // Major axis of the centroids; median split along it.
    let obb = fit_obb(&own, own.iter().copied());
    let axis = obb.axes.col(0);
    leaves.sort_by(|&a, &b| {
        centroids[a as usize]
            .dot(axis)
            .total_cmp(&centroids[b as usize].dot(axis))
            .then(a.cmp(&b))
    });
    let upper = leaves.split_off(leaves.len() / 2);
    split(centroids, leaves, depth - 1, leaf_points, out);
    split(centroids, upper, depth - 1, leaf_points, out);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pruning::procedural::{TreeSpecies, generate};

    #[test]
    fn jacobi_recovers_known_eigenvectors() {
        // Diagonal in a rotated frame.
        let r = Mat3::from_rotation_y(0.4) * Mat3::from_rotation_x(0.3);
        let m = r * Mat3::from_diagonal(Vec3::new(9.0, 4.0, 1.0)) * r.transpose();
        let (values, vectors) = symmetric_eigen(m);
        assert!(
            (values - Vec3::new(9.0, 4.0, 1.0)).abs().max_element() < 1e-4,
            "{values}"
        );
        for k in 0..3 {
            let err = (m * vectors.col(k) - vectors.col(k) * values[k]).length();
            assert!(err < 1e-4, "column {k} residual {err}");
        }
        assert!((vectors.col(0).dot(r.col(0)).abs() - 1.0).abs() < 1e-4);
    }

    #[test]
    fn cells_partition_the_leaves_and_bound_them() {
        let tree = generate(&TreeSpecies::quercus().with_leaf_count(5000));
        let leaves = &tree.leaves;
        let centroids: Vec<Vec3> = (0..leaves.len()).map(|i| leaves.centroid(i)).collect();
        let points = |i: u32| {
            leaves
                .leaf_vertices(i as usize)
                .into_iter()
                .map(|v| leaves.positions[v as usize])
        };
        let cells = build_cells(&centroids, 9, points);
        assert_eq!(cells.len(), 512);
        let mut seen = vec![0u8; leaves.len()];
        for cell in &cells {
            assert!(!cell.leaves.is_empty());
            // Median splits: sizes differ by at most one level of rounding.
            assert!(
                (9..=10).contains(&cell.leaves.len()),
                "cell of {}",
                cell.leaves.len()
            );
            for &l in &cell.leaves {
                seen[l as usize] += 1;
                for p in points(l) {
                    assert!(cell.obb.contains(p, 1e-4), "vertex outside its cell box");
                }
            }
        }
        assert!(
            seen.iter().all(|&s| s == 1),
            "every leaf in exactly one cell"
        );
    }

    #[test]
    fn fewer_leaves_than_cells_gives_one_leaf_per_cell() {
        let centroids: Vec<Vec3> = (0..5).map(|i| Vec3::X * i as f32).collect();
        let cells = build_cells(&centroids, 9, |i| std::iter::once(Vec3::X * i as f32));
        assert_eq!(cells.len(), 5);
    }
}
