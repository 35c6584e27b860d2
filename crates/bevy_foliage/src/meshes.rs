//! Bevy meshes of the crate's plain geometry ([`MeshData`] bark, [`LeafSet`] leaves), for the
//! main world: the algorithm modules stay free of render types.

use crate::pruning::leaves::LeafSet;
use crate::pruning::procedural::MeshData;
use bevy::asset::RenderAssetUsages;
use bevy::math::{Vec2, Vec3};
use bevy::mesh::{Indices, Mesh, PrimitiveTopology};

fn triangle_mesh(positions: &[Vec3], normals: &[Vec3], uvs: &[Vec2], indices: Vec<u32>) -> Mesh {
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    );
    mesh.insert_attribute(
        Mesh::ATTRIBUTE_POSITION,
        positions.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
    );
    mesh.insert_attribute(
        Mesh::ATTRIBUTE_NORMAL,
        normals.iter().map(|n| n.to_array()).collect::<Vec<_>>(),
    );
    mesh.insert_attribute(
        Mesh::ATTRIBUTE_UV_0,
        uvs.iter().map(|t| t.to_array()).collect::<Vec<_>>(),
    );
    mesh.insert_indices(Indices::U32(indices));
    mesh
}

/// A Bevy mesh of bark geometry.
pub fn bark_mesh(data: &MeshData) -> Mesh {
    triangle_mesh(
        &data.positions,
        &data.normals,
        &data.uvs,
        data.indices.clone(),
    )
}

/// A Bevy mesh of every leaf of a leaf set, as an ordinary (unpruned) mesh.
pub fn leaf_set_mesh(leaves: &LeafSet) -> Mesh {
    triangle_mesh(
        &leaves.positions,
        &leaves.normals,
        &leaves.uvs,
        leaves.leaf_indices(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pruning::procedural::{TreeSpecies, generate};

    #[test]
    fn meshes_carry_every_triangle() {
        let tree = generate(&TreeSpecies::olea().with_leaf_count(300));
        let bark = bark_mesh(&tree.bark);
        assert_eq!(bark.indices().unwrap().len(), tree.bark.indices.len());
        assert_eq!(bark.count_vertices(), tree.bark.positions.len());
        let leaves = leaf_set_mesh(&tree.leaves);
        assert_eq!(leaves.indices().unwrap().len(), 300 * 6);
    }
}
