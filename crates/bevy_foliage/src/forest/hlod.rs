//! The baseline a Bevy user would build without this crate: per tree type, two or three leaf
//! meshes decimated offline, switched by distance with Bevy's `VisibilityRange`. Used by the
//! forest benchmark to compare against the manager.
//!
//! A decimated level keeps a seeded random subset of the leaves and enlarges each kept leaf about
//! its centroid by √(1/fraction), so the crown keeps its leaf area (the same compensation as
//! pruning, eq. 3.9, but static and view-independent).

use crate::pruning::leaves::LeafSet;
use crate::rng::SplitMix64;
use bevy::asset::RenderAssetUsages;
use bevy::math::Vec3;
use bevy::mesh::{Indices, Mesh, PrimitiveTopology};

/// A mesh of about `fraction` of `leaves` (at least one leaf), kept leaves enlarged to keep the
/// total area. Deterministic for a `seed`.
pub fn decimated_leaf_mesh(leaves: &LeafSet, fraction: f32, seed: u64) -> Mesh {
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
    let (mut positions, mut normals, mut uvs, mut indices) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for &leaf in &order {
        let centroid = leaves.centroid(leaf);
        let vertices = leaves.leaf_vertices(leaf);
        let base = positions.len() as u32;
        for &v in &vertices {
            let p: Vec3 = leaves.positions[v as usize];
            positions.push((centroid + (p - centroid) * scale).to_array());
            normals.push(leaves.normals[v as usize].to_array());
            uvs.push(leaves.uvs[v as usize].to_array());
        }
        let range = leaves.leaves[leaf].clone();
        for &i in &leaves.indices[range.start as usize..range.end as usize] {
            let local = vertices.iter().position(|&v| v == i).unwrap() as u32;
            indices.push(base + local);
        }
    }
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    );
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, uvs);
    mesh.insert_indices(Indices::U32(indices));
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pruning::procedural::{TreeSpecies, generate};

    fn area(mesh: &Mesh) -> f32 {
        let Some(bevy::mesh::VertexAttributeValues::Float32x3(p)) =
            mesh.attribute(Mesh::ATTRIBUTE_POSITION)
        else {
            panic!()
        };
        let idx: Vec<usize> = mesh.indices().unwrap().iter().collect();
        idx.chunks(3)
            .map(|t| {
                let [a, b, c] = [t[0], t[1], t[2]].map(|i| Vec3::from(p[i]));
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    #[test]
    fn decimation_keeps_the_fraction_and_the_leaf_area() {
        let tree = generate(&TreeSpecies::olea().with_leaf_count(2000));
        let full = decimated_leaf_mesh(&tree.leaves, 1.0, 1);
        let quarter = decimated_leaf_mesh(&tree.leaves, 0.25, 1);
        assert_eq!(full.indices().unwrap().len(), tree.leaves.indices.len());
        assert_eq!(
            quarter.indices().unwrap().len(),
            tree.leaves.indices.len() / 4
        );
        let (a_full, a_quarter) = (area(&full), area(&quarter));
        assert!(
            (a_quarter / a_full - 1.0).abs() < 0.1,
            "{a_full} vs {a_quarter}"
        );
        // Nonsense fractions fall back to something drawable.
        assert!(
            !decimated_leaf_mesh(&tree.leaves, f32::NAN, 1)
                .indices()
                .unwrap()
                .is_empty()
        );
        assert!(
            !decimated_leaf_mesh(&tree.leaves, -1.0, 1)
                .indices()
                .unwrap()
                .is_empty()
        );
    }
}
