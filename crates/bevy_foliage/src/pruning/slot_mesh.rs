//! Slot meshes: what a pruned tree is drawn with. A slot mesh of `n` vertices carries only each
//! vertex's index; the leaf vertex stage pulls the kept leaf vertex with that index from the
//! pruning pass's output. Per tree and frame the plugin picks the smallest slot mesh (a
//! bucket of √2 steps) that holds the tree's kept index count — known exactly on the CPU because
//! the pruning arithmetic is integer ([`super::extract`]) — so the vertex stage never runs for
//! much more than the kept vertices, and the vertices past the kept count are culled.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;

/// Slot meshes by kind (quad or triangle) and size.
#[derive(Resource, Default)]
pub struct SlotMeshes(HashMap<(bool, u32), Handle<Mesh>>);

impl SlotMeshes {
    /// The slot mesh for `kept` kept indices of a tree type with `full` indices, whose leaves
    /// are all canonical quads if `quads`.
    ///
    /// Every bucket the type can need is created when the type is first seen: slot meshes
    /// created later, while the tree is already drawn, were observed not to be drawn on the
    /// frames that followed (Bevy 0.19, software Vulkan); creating them up front avoids it.
    pub fn fitting(
        &mut self,
        kept: u32,
        full: u32,
        quads: bool,
        meshes: &mut Assets<Mesh>,
    ) -> Handle<Mesh> {
        let per_primitive = if quads { 6 } else { 3 };
        let full_bucket = slot_bucket(full.div_ceil(per_primitive));
        let mut k = 0;
        loop {
            let b = bucket_size(k);
            self.0
                .entry((quads, b))
                .or_insert_with(|| meshes.add(slot_mesh(b, quads)));
            if b >= full_bucket {
                break;
            }
            k += 1;
        }
        let bucket = slot_bucket(kept.div_ceil(per_primitive));
        self.0
            .entry((quads, bucket))
            .or_insert_with(|| meshes.add(slot_mesh(bucket, quads)))
            .clone()
    }
}

/// Size of the `k`-th slot-mesh bucket, in primitives (triangles, or quad leaves):
/// `⌈64 · √2^k⌉`. The √2 steps keep the vertex stage's wasted runs (past the kept count) under
/// 41 %, about 19 % on average, at about 3.4 times the largest slot mesh's memory in all.
pub fn bucket_size(k: u32) -> u32 {
    (64.0 * 2f64.powf(k as f64 / 2.0)).ceil() as u32
}

/// The smallest bucket holding `primitives`.
pub fn slot_bucket(primitives: u32) -> u32 {
    let mut k = 0;
    while bucket_size(k) < primitives {
        k += 1;
    }
    bucket_size(k)
}

/// A slot mesh of `primitives` primitives whose vertex i carries i in `position.x`. Triangle
/// slots are non-indexed (vertex i pulls kept index i); quad slots have four vertices per leaf
/// and the index pattern `0 1 2, 0 2 3` (vertex 4k + c pulls kept index 6k + [0, 1, 2, 5][c]), so
/// the vertex stage runs four times per quad leaf instead of six.
fn slot_mesh(primitives: u32, quads: bool) -> Mesh {
    let vertices = primitives * if quads { 4 } else { 3 };
    let positions: Vec<[f32; 3]> = (0..vertices).map(|i| [i as f32, 0.0, 0.0]).collect();
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    );
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    // Present so the leaf material's texture coordinates are passed on (VERTEX_UVS_A).
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, vec![[0.0f32, 0.0]; vertices as usize]);
    if quads {
        let indices: Vec<u32> = (0..primitives)
            .flat_map(|k| [0, 1, 2, 0, 2, 3].map(|c| 4 * k + c))
            .collect();
        mesh.insert_indices(Indices::U32(indices));
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_hold_the_count_and_waste_under_half() {
        for primitives in [0u32, 1, 63, 64, 65, 1000, 32_000, 262_084] {
            let b = slot_bucket(primitives);
            assert!(b >= primitives, "{primitives} -> {b}");
            if primitives > 64 {
                assert!((b as f64) < 1.42 * primitives as f64, "{primitives} -> {b}");
            }
        }
        assert_eq!(bucket_size(0), 64);
        assert_eq!(bucket_size(2), 128);
    }

    #[test]
    fn quad_slot_meshes_index_four_vertices_per_leaf() {
        let mesh = slot_mesh(2, true);
        let indices: Vec<usize> = mesh.indices().unwrap().iter().collect();
        assert_eq!(indices, vec![0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7]);
        assert_eq!(mesh.count_vertices(), 8);
        let triangles = slot_mesh(2, false);
        assert!(triangles.indices().is_none());
        assert_eq!(triangles.count_vertices(), 6);
    }
}
