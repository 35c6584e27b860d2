//! The base patch as a mesh (Boulanger 2008, thesis §4.2.2): every blade's two-sided quad strip
//! ([`blade_strip`]) in one triangle list, instanced on the grid cells near the eye. Each vertex
//! carries what the blade shaders need beside its position: texture coordinates across and up
//! the blade (`UV_0`), the blade's density threshold and the vertex's height fraction (`UV_1`:
//! the density test of §4.2.4 and the ambient occlusion rising with height), and the strip's
//! normal (lighting is two-sided, eq. 4.1, so either face's normal will do).

use super::patch::{BasePatch, blade_strip};
use super::slices::{BakeVertex, SliceLayout};
use bevy::asset::RenderAssetUsages;
use bevy::math::Vec3;
use bevy::mesh::VertexAttributeValues;
use bevy::mesh::{Indices, Mesh, PrimitiveTopology};

/// The mesh of `patch`, blades `width` wide at the root with `segments` segments each.
pub fn patch_mesh(patch: &BasePatch, width: f32, segments: u32) -> Mesh {
    let segments = segments.max(1);
    let per_blade = 2 * (segments as usize + 1);
    let n = patch.blades.len() * per_blade;
    let (mut positions, mut normals) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut uv0, mut uv1) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut indices = Vec::with_capacity(patch.blades.len() * segments as usize * 6);
    for blade in &patch.blades {
        let base = positions.len() as u32;
        let strip = blade_strip(blade, width, segments);
        let across = Vec3::new(-blade.lean.y, 0.0, blade.lean.x);
        for (k, (p, h)) in strip.iter().enumerate() {
            // The normal of the strip at this point: across × the curve's tangent.
            let t = (k / 2) as f32 / segments as f32;
            let tangent = (blade.point((t + 1e-3).min(1.0)) - blade.point((t - 1e-3).max(0.0)))
                .normalize_or(Vec3::Y);
            let normal = across.cross(tangent).normalize_or(Vec3::Z);
            positions.push(p.to_array());
            normals.push(normal.to_array());
            uv0.push([(k % 2) as f32, *h]);
            uv1.push([blade.threshold, *h]);
        }
        for s in 0..segments {
            let a = base + 2 * s;
            indices.extend_from_slice(&[a, a + 1, a + 2, a + 1, a + 3, a + 2]);
        }
    }
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD | RenderAssetUsages::MAIN_WORLD,
    );
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, uv0);
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_1, uv1);
    mesh.insert_indices(Indices::U32(indices));
    mesh
}

/// How high above the ground the horizontal slice lies (m): clear of a ground drawn at the
/// same height.
pub const HORIZONTAL_SLICE_LIFT: f32 = 0.01;

/// The quads of the slices over a block of `cells × cells` cells of side `layout.size`
/// (`grass_slice.wgsl` draws them): in every cell, `K` quads across x and `K` across z where the
/// base patch's vertical slices stand (the slab centres, the same in every mirrored version), and
/// the horizontal quad over the block. `UV_1.x` is the quad's axis: 0 across x, 1 across z, 2
/// horizontal. `per_cell`: each quad cut at every cell edge, for ground with relief (see below);
/// else each spans the block (a fraction of the vertices, for flat ground).
pub fn slice_block_mesh(layout: &SliceLayout, cells: u32, per_cell: bool) -> Mesh {
    let cells = cells.max(1);
    let segments = if per_cell { cells } else { 1 };
    let span = cells as f32 / segments as f32;
    let (size, height, k) = (layout.size, layout.height, layout.per_axis);
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let mut normals: Vec<[f32; 3]> = Vec::new();
    let mut uv1: Vec<[f32; 2]> = Vec::new();
    let mut indices: Vec<u32> = Vec::new();
    let mut quad = |corners: [Vec3; 4], normal: Vec3, axis: f32| {
        let base = positions.len() as u32;
        for c in corners {
            positions.push(c.to_array());
            normals.push(normal.to_array());
            uv1.push([axis, 0.0]);
        }
        indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    };
    // Per cell, the vertices lifted onto the ground (eq. 4.10) sit on cell edges, where the lift
    // is linear along the quad: the lifted slices follow the blades' ground exactly. (The wind's
    // shear, bilinear per cell too, is only sampled at the quads' ends on flat ground — beyond
    // the blades' reach, a few centimetres of sway between block corners is lost in the
    // distance.)
    for c in 0..cells {
        for slab in 0..k {
            let at = (c as f32 + (slab as f32 + 0.5) / k as f32) * size;
            for s in 0..segments {
                let (a, b) = (s as f32 * span * size, (s + 1) as f32 * span * size);
                quad(
                    [
                        Vec3::new(at, 0.0, a),
                        Vec3::new(at, 0.0, b),
                        Vec3::new(at, height, b),
                        Vec3::new(at, height, a),
                    ],
                    Vec3::X,
                    0.0,
                );
                quad(
                    [
                        Vec3::new(a, 0.0, at),
                        Vec3::new(b, 0.0, at),
                        Vec3::new(b, height, at),
                        Vec3::new(a, height, at),
                    ],
                    Vec3::Z,
                    1.0,
                );
            }
        }
    }
    for z in 0..segments {
        for x in 0..segments {
            let offset = Vec3::new(x as f32, 0.0, z as f32) * span * size;
            quad(
                horizontal_corners(span * size).map(|c| c + offset),
                Vec3::Y,
                2.0,
            );
        }
    }
    build(positions, normals, uv1, indices)
}

/// A horizontal slice quad of `side` cut into `segments × segments` facets (a macro-cell's:
/// scaled to the node by its transform), so that lifted onto the ground at its vertices it
/// follows rolling ground facet by facet.
pub fn horizontal_slice_mesh(side: f32, segments: u32) -> Mesh {
    let n = segments.max(1);
    let step = side / n as f32;
    let (mut positions, mut indices) = (Vec::new(), Vec::new());
    for j in 0..=n {
        for i in 0..=n {
            positions.push([i as f32 * step, HORIZONTAL_SLICE_LIFT, j as f32 * step]);
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            let (b, c, d) = (a + 1, a + n + 2, a + n + 1);
            indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    let count = positions.len();
    build(
        positions,
        vec![[0.0, 1.0, 0.0]; count],
        vec![[2.0, 0.0]; count],
        indices,
    )
}

fn horizontal_corners(side: f32) -> [Vec3; 4] {
    let y = HORIZONTAL_SLICE_LIFT;
    [
        Vec3::new(0.0, y, 0.0),
        Vec3::new(side, y, 0.0),
        Vec3::new(side, y, side),
        Vec3::new(0.0, y, side),
    ]
}

fn build(
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    uv1: Vec<[f32; 2]>,
    indices: Vec<u32>,
) -> Mesh {
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD | RenderAssetUsages::MAIN_WORLD,
    );
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_1, uv1);
    mesh.insert_indices(Indices::U32(indices));
    mesh
}

/// The triangles of [`patch_mesh`] as the slice bake's CPU reference reads them.
pub fn bake_triangles(patch: &BasePatch, width: f32, segments: u32) -> Vec<[BakeVertex; 3]> {
    let mesh = patch_mesh(patch, width, segments);
    let (
        Some(VertexAttributeValues::Float32x3(positions)),
        Some(VertexAttributeValues::Float32x3(normals)),
        Some(VertexAttributeValues::Float32x2(uv1)),
        Some(Indices::U32(indices)),
    ) = (
        mesh.attribute(Mesh::ATTRIBUTE_POSITION),
        mesh.attribute(Mesh::ATTRIBUTE_NORMAL),
        mesh.attribute(Mesh::ATTRIBUTE_UV_1),
        mesh.indices(),
    )
    else {
        unreachable!("patch_mesh writes these attributes")
    };
    let vertex = |i: u32| {
        let i = i as usize;
        BakeVertex {
            position: Vec3::from_array(positions[i]),
            normal: Vec3::from_array(normals[i]),
            threshold: uv1[i][0],
            height_fraction: uv1[i][1],
        }
    };
    indices
        .chunks_exact(3)
        .map(|t| [vertex(t[0]), vertex(t[1]), vertex(t[2])])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grass::patch::PatchSettings;
    use bevy::mesh::VertexAttributeValues;

    #[test]
    fn every_blade_is_one_strip_carrying_its_threshold() {
        let settings = PatchSettings {
            strata: 6,
            ..default_settings()
        };
        let patch = BasePatch::generate(&settings);
        let segments = 4;
        let mesh = patch_mesh(&patch, settings.width, segments);
        let per_blade = 2 * (segments as usize + 1);
        assert_eq!(mesh.count_vertices(), patch.blades.len() * per_blade);
        let Some(VertexAttributeValues::Float32x2(uv1)) = mesh.attribute(Mesh::ATTRIBUTE_UV_1)
        else {
            panic!("UV_1");
        };
        let Some(VertexAttributeValues::Float32x3(normals)) =
            mesh.attribute(Mesh::ATTRIBUTE_NORMAL)
        else {
            panic!("normals");
        };
        let Some(VertexAttributeValues::Float32x3(positions)) =
            mesh.attribute(Mesh::ATTRIBUTE_POSITION)
        else {
            panic!("positions");
        };
        let Some(Indices::U32(indices)) = mesh.indices() else {
            panic!("indices");
        };
        assert_eq!(indices.len(), patch.blades.len() * segments as usize * 6);
        for triangle in indices.chunks(3) {
            // A triangle never joins two blades, and its vertices carry that blade's threshold.
            let blade = triangle[0] as usize / per_blade;
            assert!(triangle.iter().all(|&i| i as usize / per_blade == blade));
            for &i in triangle {
                assert_eq!(uv1[i as usize][0], patch.blades[blade].threshold);
            }
            // Not degenerate but for the tip's (which narrows to a point).
            let [a, b, c] = [0, 1, 2].map(|k| Vec3::from(positions[triangle[k] as usize]));
            let area = (b - a).cross(c - a).length();
            let at_tip = triangle
                .iter()
                .all(|&i| (i as usize % per_blade) >= per_blade - 4);
            assert!(at_tip || area > 1e-8, "degenerate triangle {triangle:?}");
        }
        for (i, n) in normals.iter().enumerate() {
            let n = Vec3::from(*n);
            let blade = &patch.blades[i / per_blade];
            let across = Vec3::new(-blade.lean.y, 0.0, blade.lean.x);
            assert!((n.length() - 1.0).abs() < 1e-4 && n.dot(across).abs() < 1e-4);
        }
        // Heights from 0 at the roots to the blade's height at the tips.
        let tallest = positions.iter().map(|p| p[1]).fold(0.0f32, f32::max);
        assert!(tallest <= settings.height.1 + 1e-6 && tallest > settings.height.0);
    }

    fn default_settings() -> PatchSettings {
        PatchSettings::default()
    }
}
