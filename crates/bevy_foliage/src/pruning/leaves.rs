//! The leaf set of a tree: the geometry that pruning simplifies.
//!
//! A *leaf* is the unit of pruning: a small group of triangles that is kept or dropped as a
//! whole. For the procedural trees and for quad-leaf models it is one textured quad (two
//! triangles, four vertices); for glTF models it is one connected component of the leaf
//! material's triangles. Each vertex belongs to exactly one leaf,
//! so per-vertex data such as the area-preserving offset `e_i = v_i − centroid(leaf)` (eq. 3.10)
//! is well defined.

use bevy::math::{Vec2, Vec3};
use std::ops::Range;

/// Triangle geometry of all leaves of a tree, in model space.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LeafSet {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Vertex normals (unit length).
    pub normals: Vec<Vec3>,
    /// Vertex texture coordinates.
    pub uvs: Vec<Vec2>,
    /// Triangle list (indices into the vertex arrays).
    pub indices: Vec<u32>,
    /// Each leaf as a range of `indices` (a whole number of triangles).
    pub leaves: Vec<Range<u32>>,
}

/// Leaves dropped by [`LeafSet::sanitized`], by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SkippedLeaves {
    /// A vertex had a NaN or infinite coordinate.
    pub non_finite: usize,
    /// Total area (numerically) zero: all vertices collinear or coincident.
    pub degenerate: usize,
    /// Index out of range or a triangle count that is not whole.
    pub malformed: usize,
}

impl SkippedLeaves {
    /// Total leaves skipped.
    pub fn total(&self) -> usize {
        self.non_finite + self.degenerate + self.malformed
    }
}

impl LeafSet {
    /// Number of leaves.
    pub fn len(&self) -> usize {
        self.leaves.len()
    }

    /// Whether there are no leaves.
    pub fn is_empty(&self) -> bool {
        self.leaves.is_empty()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// The triangles of leaf `leaf` as vertex positions.
    pub fn triangles(&self, leaf: usize) -> impl Iterator<Item = [Vec3; 3]> + '_ {
        let range = self.leaves[leaf].clone();
        self.indices[range.start as usize..range.end as usize]
            .chunks_exact(3)
            .map(|t| {
                [
                    self.positions[t[0] as usize],
                    self.positions[t[1] as usize],
                    self.positions[t[2] as usize],
                ]
            })
    }

    /// Every leaf's triangles, leaf after leaf, as one index list.
    pub fn leaf_indices(&self) -> Vec<u32> {
        self.leaves
            .iter()
            .flat_map(|r| {
                self.indices[r.start as usize..r.end as usize]
                    .iter()
                    .copied()
            })
            .collect()
    }

    /// The distinct vertices of leaf `leaf`, in first-use order.
    pub fn leaf_vertices(&self, leaf: usize) -> Vec<u32> {
        let range = self.leaves[leaf].clone();
        let mut out: Vec<u32> = Vec::with_capacity(4);
        for &i in &self.indices[range.start as usize..range.end as usize] {
            if !out.contains(&i) {
                out.push(i);
            }
        }
        out
    }

    /// Centroid of a leaf: the mean of its distinct vertices (`0.25 Σ v_j` for a quad, eq. 3.10).
    pub fn centroid(&self, leaf: usize) -> Vec3 {
        let vertices = self.leaf_vertices(leaf);
        let sum: Vec3 = vertices.iter().map(|&v| self.positions[v as usize]).sum();
        sum / vertices.len().max(1) as f32
    }

    /// A leaf's diameter: twice its farthest vertex from its centroid (the leaf size the leaf
    /// shaders take from the radius the vertex record carries).
    pub fn diameter(&self, leaf: usize) -> f32 {
        let c = self.centroid(leaf);
        2.0 * self
            .leaf_vertices(leaf)
            .iter()
            .map(|&v| self.positions[v as usize].distance(c))
            .fold(0.0, f32::max)
    }

    /// Surface area of a leaf.
    pub fn area(&self, leaf: usize) -> f32 {
        self.triangles(leaf)
            .map(|[a, b, c]| 0.5 * (b - a).cross(c - a).length())
            .sum()
    }

    /// Appends one quad leaf (`corners` counter-clockwise seen from the front) and returns its
    /// leaf index.
    pub fn push_quad(&mut self, corners: [Vec3; 4], normal: Vec3) -> usize {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&corners);
        self.normals.extend_from_slice(&[normal; 4]);
        self.uvs.extend_from_slice(&[
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 0.0),
        ]);
        let start = self.indices.len() as u32;
        self.indices
            .extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
        self.leaves.push(start..start + 6);
        self.leaves.len() - 1
    }

    /// Per-vertex offsets from the owning leaf's centroid, `e_i = v_i − centroid` (eq. 3.10).
    /// The vertex shader moves a kept leaf's vertex to `centroid + e_i · √s` to scale its area
    /// by `s` (eq. 3.9).
    pub fn centroid_offsets(&self) -> Vec<Vec3> {
        let mut offsets = vec![Vec3::ZERO; self.positions.len()];
        for leaf in 0..self.leaves.len() {
            let c = self.centroid(leaf);
            for v in self.leaf_vertices(leaf) {
                offsets[v as usize] = self.positions[v as usize] - c;
            }
        }
        offsets
    }

    /// Returns a copy without leaves that are malformed, have non-finite vertices, or have
    /// (numerically) zero area, and how many of each were skipped. Vertex arrays are kept as
    /// they are; only the leaf list shrinks.
    pub fn sanitized(&self) -> (LeafSet, SkippedLeaves) {
        let mut skipped = SkippedLeaves::default();
        let mut out = LeafSet {
            positions: self.positions.clone(),
            normals: self.normals.clone(),
            uvs: self.uvs.clone(),
            indices: Vec::with_capacity(self.indices.len()),
            leaves: Vec::with_capacity(self.leaves.len()),
        };
        let n = self.positions.len() as u32;
        for (leaf, range) in self.leaves.iter().enumerate() {
            let well_formed = range.start <= range.end
                && range.end as usize <= self.indices.len()
                && (range.end - range.start) % 3 == 0
                && range.end > range.start
                && self.indices[range.start as usize..range.end as usize]
                    .iter()
                    .all(|&i| i < n);
            if !well_formed {
                skipped.malformed += 1;
                continue;
            }
            if self
                .leaf_vertices(leaf)
                .iter()
                .any(|&v| !self.positions[v as usize].is_finite())
            {
                skipped.non_finite += 1;
                continue;
            }
            let area = self.area(leaf);
            let extent = self
                .triangles(leaf)
                .flat_map(|t| t.into_iter())
                .map(|p| p.abs().max_element())
                .fold(0.0f32, f32::max)
                .max(1e-30);
            // Relative threshold: a leaf whose area is below ~1e-12 of its squared coordinate
            // scale is a line or a point, whatever the model's units.
            if area.is_nan() || area <= extent * extent * 1e-12 {
                skipped.degenerate += 1;
                continue;
            }
            let start = out.indices.len() as u32;
            out.indices
                .extend_from_slice(&self.indices[range.start as usize..range.end as usize]);
            out.leaves.push(start..out.indices.len() as u32);
        }
        (out, skipped)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_quad(at: Vec3) -> [Vec3; 4] {
        [at, at + Vec3::X, at + Vec3::X + Vec3::Y, at + Vec3::Y]
    }

    #[test]
    fn quad_has_unit_area_and_centred_offsets() {
        let mut set = LeafSet::default();
        set.push_quad(unit_quad(Vec3::new(2.0, 0.0, 0.0)), Vec3::Z);
        assert_eq!(set.len(), 1);
        assert_eq!(set.triangle_count(), 2);
        assert!((set.area(0) - 1.0).abs() < 1e-6);
        assert_eq!(set.centroid(0), Vec3::new(2.5, 0.5, 0.0));
        let e = set.centroid_offsets();
        assert_eq!(e[0], Vec3::new(-0.5, -0.5, 0.0));
        assert_eq!(e.iter().copied().sum::<Vec3>(), Vec3::ZERO);
        // Scaling every e_i by √s scales the area by s (eq. 3.9).
        let s = 4.0f32;
        let mut scaled = set.clone();
        for (p, e) in scaled.positions.iter_mut().zip(&e) {
            *p = set.centroid(0) + *e * s.sqrt();
        }
        assert!((scaled.area(0) - s).abs() < 1e-5);
    }

    #[test]
    fn sanitize_skips_and_counts_bad_leaves() {
        let mut set = LeafSet::default();
        set.push_quad(unit_quad(Vec3::ZERO), Vec3::Z);
        set.push_quad([Vec3::ZERO, Vec3::X, Vec3::X * 2.0, Vec3::X * 3.0], Vec3::Z); // collinear
        set.push_quad(unit_quad(Vec3::new(f32::NAN, 0.0, 0.0)), Vec3::Z);
        set.push_quad(unit_quad(Vec3::splat(5.0)), Vec3::Z);
        set.leaves.push(0..4); // not whole triangles
        set.leaves.push(0..3);
        set.indices.extend_from_slice(&[0, 1, 999]);
        let n = set.indices.len() as u32;
        set.leaves.push(n - 3..n); // index out of range
        let (clean, skipped) = set.sanitized();
        assert_eq!(
            skipped,
            SkippedLeaves {
                non_finite: 1,
                degenerate: 1,
                malformed: 2
            }
        );
        // The two good quads and the valid single-triangle leaf survive.
        assert_eq!(clean.len(), 3);
        assert!((clean.area(1) - 1.0).abs() < 1e-6);
        assert_eq!(
            clean.centroid(1),
            Vec3::splat(5.0) + Vec3::new(0.5, 0.5, 0.0)
        );
    }
}
