//! The baseline a Bevy user would build without this crate: per tree type, two or three leaf
//! meshes decimated offline, switched by distance with Bevy's `VisibilityRange`. Used by the
//! forest benchmark to compare against the manager.
//!
//! A decimated level keeps a seeded random subset of the leaves and enlarges each kept leaf about
//! its centroid by √(1/fraction), so the crown keeps its leaf area (the same compensation as
//! pruning, eq. 3.9, but static and view-independent).

use crate::pruning::leaves::LeafSet;
use crate::rng::SplitMix64;

/// About `fraction` of `leaves` (at least one leaf), kept leaves enlarged to keep the total
/// area. Deterministic for a `seed`. Draw it with [`crate::meshes::leaf_set_mesh`].
pub fn decimated_leaves(leaves: &LeafSet, fraction: f32, seed: u64) -> LeafSet {
    let fraction = if fraction.is_finite() {
        fraction.clamp(1e-4, 1.0)
    } else {
        1.0
    };
    let mut order: Vec<usize> = (0..leaves.len()).collect();
    SplitMix64::new(seed).shuffle(&mut order);
    let keep = ((leaves.len() as f32 * fraction).round() as usize)
        .clamp(1.min(leaves.len()), leaves.len());
    order.truncate(keep);
    order.sort_unstable();
    let scale = (leaves.len() as f32 / keep.max(1) as f32).sqrt();
    let mut out = LeafSet::default();
    for &leaf in &order {
        let centroid = leaves.centroid(leaf);
        let vertices = leaves.leaf_vertices(leaf);
        let base = out.positions.len() as u32;
        for &v in &vertices {
            let p = leaves.positions[v as usize];
            out.positions.push(centroid + (p - centroid) * scale);
            out.normals.push(leaves.normals[v as usize]);
            out.uvs.push(leaves.uvs[v as usize]);
        }
        let range = leaves.leaves[leaf].clone();
        let start = out.indices.len() as u32;
        for &i in &leaves.indices[range.start as usize..range.end as usize] {
            let local = vertices.iter().position(|&v| v == i).unwrap() as u32;
            out.indices.push(base + local);
        }
        out.leaves.push(start..out.indices.len() as u32);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pruning::procedural::{TreeSpecies, generate};

    fn area(leaves: &LeafSet) -> f32 {
        (0..leaves.len()).map(|l| leaves.area(l)).sum()
    }

    #[test]
    fn decimation_keeps_the_fraction_and_the_leaf_area() {
        let tree = generate(&TreeSpecies::olea().with_leaf_count(2000));
        let full = decimated_leaves(&tree.leaves, 1.0, 1);
        let quarter = decimated_leaves(&tree.leaves, 0.25, 1);
        assert_eq!(full.indices.len(), tree.leaves.indices.len());
        assert_eq!(quarter.indices.len(), tree.leaves.indices.len() / 4);
        assert_eq!(quarter.len(), 500);
        let (a_full, a_quarter) = (area(&full), area(&quarter));
        assert!(
            (a_quarter / a_full - 1.0).abs() < 0.1,
            "{a_full} vs {a_quarter}"
        );
        // Nonsense fractions fall back to something drawable.
        assert!(!decimated_leaves(&tree.leaves, f32::NAN, 1).is_empty());
        assert!(!decimated_leaves(&tree.leaves, -1.0, 1).is_empty());
    }
}
