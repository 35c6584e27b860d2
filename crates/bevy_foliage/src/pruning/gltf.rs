//! Trees from glTF files: which triangles are leaves, and how they are cut into leaves.
//!
//! **Which primitives are leaves.** A primitive is foliage when its material is listed in
//! [`GltfLeafSettings::leaf_materials`], or — with that list empty, the default — when its
//! material is alpha-masked or alpha-blended, or the material, mesh or node name contains
//! "leaf"/"leaves" (any case). Everything else is bark.
//!
//! **How leaves are separated.** Exported trees rarely use one quad per leaf: a leaf may be a
//! fan, a strip, or a card of several triangles. Inside each foliage primitive a leaf is one
//! *connected component* of triangles that share vertex indices (union–find over the index
//! buffer). Triangles of different leaves must not share vertices — true of every leaf-card
//! exporter we know of, because each card has its own UVs. A primitive that welded all leaves
//! into one surface would come out as one big leaf; split it in the modelling tool.
//!
//! Nodes are flattened into model space with their transforms (the default scene, or the first).
//! Only triangle-list primitives are read; others are counted in [`GltfTree::ignored_primitives`].
//! Leaves with NaN or degenerate geometry are kept here and dropped (and counted) by the bake.

use super::leaves::LeafSet;
use super::procedural::MeshData;
use base64::Engine;
use bevy::math::{Mat4, Vec2, Vec3};
use std::path::Path;

/// How foliage is recognised in a glTF file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GltfLeafSettings {
    /// Names of the leaf materials. Empty: detect (alpha mask/blend, or "leaf"/"leaves" in a name).
    pub leaf_materials: Vec<String>,
}

/// What a glTF file holds as a tree.
#[derive(Clone, Debug, Default)]
pub struct GltfTree {
    /// The leaves, one connected component each, in model space.
    pub leaves: LeafSet,
    /// Everything else (trunk, branches), in model space.
    pub bark: MeshData,
    /// Names of every material in the file (`<unnamed #i>` for unnamed ones).
    pub materials: Vec<String>,
    /// Primitives skipped because they are not triangle lists.
    pub ignored_primitives: usize,
}

/// Why a glTF file could not be read as a tree.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GltfTreeError {
    /// Not valid glTF.
    Parse(String),
    /// A buffer could not be read (missing file, bad data URI, too short).
    Buffer(String),
    /// No primitive was recognised as foliage.
    NoLeaves {
        /// Every material found, so the user can name the right one.
        materials: Vec<String>,
    },
}

impl std::fmt::Display for GltfTreeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Parse(e) => write!(f, "not a valid glTF file: {e}"),
            Self::Buffer(e) => write!(f, "glTF buffer: {e}"),
            Self::NoLeaves { materials } => write!(
                f,
                "no leaves found: no material is alpha-masked/blended or named like a leaf, and none \
                 was listed in GltfLeafSettings::leaf_materials. Materials in the file: [{}]",
                materials.join(", ")
            ),
        }
    }
}

impl std::error::Error for GltfTreeError {}

fn contains_leaf_word(name: Option<&str>) -> bool {
    name.map(|n| n.to_ascii_lowercase())
        .is_some_and(|n| n.contains("leaf") || n.contains("leaves"))
}

fn load_buffers(
    document: &::gltf::Document,
    blob: Option<Vec<u8>>,
    base_dir: Option<&Path>,
) -> Result<Vec<Vec<u8>>, GltfTreeError> {
    let mut blob = blob;
    document
        .buffers()
        .map(|buffer| {
            let data = match buffer.source() {
                ::gltf::buffer::Source::Bin => blob
                    .take()
                    .ok_or_else(|| GltfTreeError::Buffer("GLB binary chunk missing".into()))?,
                ::gltf::buffer::Source::Uri(uri) => {
                    if let Some(rest) = uri.strip_prefix("data:") {
                        let (_, payload) = rest.split_once(";base64,").ok_or_else(|| {
                            GltfTreeError::Buffer("only base64 data URIs are supported".into())
                        })?;
                        base64::engine::general_purpose::STANDARD
                            .decode(payload)
                            .map_err(|e| GltfTreeError::Buffer(format!("bad base64: {e}")))?
                    } else {
                        let path = base_dir.unwrap_or(Path::new(".")).join(uri);
                        std::fs::read(&path).map_err(|e| {
                            GltfTreeError::Buffer(format!("{}: {e}", path.display()))
                        })?
                    }
                }
            };
            if data.len() < buffer.length() {
                return Err(GltfTreeError::Buffer(format!(
                    "buffer {} has {} bytes, {} declared",
                    buffer.index(),
                    data.len(),
                    buffer.length()
                )));
            }
            Ok(data)
        })
        .collect()
}

/// Connected components of a triangle list (triangles sharing a vertex index are connected).
/// Returns, per triangle, its component id, numbered in order of first triangle.
pub fn triangle_components(indices: &[u32]) -> Vec<u32> {
    let vertex_count = indices.iter().copied().max().map_or(0, |m| m as usize + 1);
    let mut parent: Vec<u32> = (0..vertex_count as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for t in indices.chunks_exact(3) {
        let a = find(&mut parent, t[0]);
        for &v in &t[1..] {
            let b = find(&mut parent, v);
            if a != b {
                parent[b as usize] = a;
            }
        }
    }
    let mut ids = vec![u32::MAX; vertex_count];
    let mut next = 0;
    indices
        .chunks_exact(3)
        .map(|t| {
            let root = find(&mut parent, t[0]) as usize;
            if ids[root] == u32::MAX {
                ids[root] = next;
                next += 1;
            }
            ids[root]
        })
        .collect()
}

/// Reads a tree from glTF (`.gltf` with embedded or external buffers, or `.glb`) bytes.
/// `base_dir` resolves external buffer files.
pub fn load_gltf_tree(
    bytes: &[u8],
    base_dir: Option<&Path>,
    settings: &GltfLeafSettings,
) -> Result<GltfTree, GltfTreeError> {
    let gltf = ::gltf::Gltf::from_slice(bytes).map_err(|e| GltfTreeError::Parse(e.to_string()))?;
    let document = gltf.document;
    let buffers = load_buffers(&document, gltf.blob, base_dir)?;
    let mut tree = GltfTree {
        materials: document
            .materials()
            .enumerate()
            .map(|(i, m)| {
                m.name()
                    .map_or_else(|| format!("<unnamed #{i}>"), str::to_string)
            })
            .collect(),
        ..Default::default()
    };
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next());
    let roots: Vec<::gltf::Node> = match scene {
        Some(scene) => scene.nodes().collect(),
        None => document.nodes().collect(),
    };
    let mut stack: Vec<(::gltf::Node, Mat4)> =
        roots.into_iter().map(|n| (n, Mat4::IDENTITY)).collect();
    let mut any_leaf_primitive = false;
    while let Some((node, parent)) = stack.pop() {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        for child in node.children() {
            stack.push((child, world));
        }
        let Some(mesh) = node.mesh() else { continue };
        let normal_matrix = world.inverse().transpose();
        for primitive in mesh.primitives() {
            if primitive.mode() != ::gltf::mesh::Mode::Triangles {
                tree.ignored_primitives += 1;
                continue;
            }
            let material = primitive.material();
            let is_leaf = if settings.leaf_materials.is_empty() {
                material.alpha_mode() != ::gltf::material::AlphaMode::Opaque
                    || contains_leaf_word(material.name())
                    || contains_leaf_word(mesh.name())
                    || contains_leaf_word(node.name())
            } else {
                material
                    .name()
                    .is_some_and(|n| settings.leaf_materials.iter().any(|l| l == n))
            };
            let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
            let Some(positions) = reader.read_positions() else {
                continue;
            };
            let positions: Vec<Vec3> = positions
                .map(|p| world.transform_point3(Vec3::from_array(p)))
                .collect();
            let normals: Vec<Vec3> = match reader.read_normals() {
                Some(n) => n
                    .map(|n| {
                        normal_matrix
                            .transform_vector3(Vec3::from_array(n))
                            .normalize_or(Vec3::Y)
                    })
                    .collect(),
                None => vec![Vec3::Y; positions.len()],
            };
            let uvs: Vec<Vec2> = match reader.read_tex_coords(0) {
                Some(t) => t.into_f32().map(Vec2::from_array).collect(),
                None => vec![Vec2::ZERO; positions.len()],
            };
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..positions.len() as u32).collect(),
            };
            // Indices out of range make the file invalid for this primitive: keep in-range triangles.
            let indices: Vec<u32> = indices
                .chunks_exact(3)
                .filter(|t| t.iter().all(|&i| (i as usize) < positions.len()))
                .flatten()
                .copied()
                .collect();
            if is_leaf {
                any_leaf_primitive = true;
                append_leaves(&mut tree.leaves, &positions, &normals, &uvs, &indices);
            } else {
                let base = tree.bark.positions.len() as u32;
                tree.bark.positions.extend(&positions);
                tree.bark.normals.extend(&normals);
                tree.bark.uvs.extend(&uvs);
                tree.bark.indices.extend(indices.iter().map(|i| i + base));
            }
        }
    }
    if !any_leaf_primitive {
        return Err(GltfTreeError::NoLeaves {
            materials: tree.materials,
        });
    }
    Ok(tree)
}

/// Splits one foliage primitive into leaves (connected components) and appends them, each with
/// its own copy of its vertices.
fn append_leaves(
    set: &mut LeafSet,
    positions: &[Vec3],
    normals: &[Vec3],
    uvs: &[Vec2],
    indices: &[u32],
) {
    let components = triangle_components(indices);
    let count = components
        .iter()
        .copied()
        .max()
        .map_or(0, |m| m as usize + 1);
    let mut triangles_of: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (t, &c) in components.iter().enumerate() {
        triangles_of[c as usize].push(t);
    }
    let mut remap: Vec<u32> = vec![u32::MAX; positions.len()];
    for triangles in triangles_of {
        let start = set.indices.len() as u32;
        for t in triangles {
            for &v in &indices[t * 3..t * 3 + 3] {
                let v = v as usize;
                if remap[v] == u32::MAX {
                    remap[v] = set.positions.len() as u32;
                    set.positions.push(positions[v]);
                    set.normals.push(normals[v]);
                    set.uvs.push(uvs[v]);
                }
                set.indices.push(remap[v]);
            }
        }
        set.leaves.push(start..set.indices.len() as u32);
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::pruning::bake::{BakeSettings, bake};

    struct Primitive {
        material: usize,
        positions: Vec<[f32; 3]>,
        indices: Vec<u16>,
    }

    /// A minimal glTF (embedded base64 buffer) with one node per primitive, translated by `offset`.
    fn gltf_json(materials: &[(&str, &str)], primitives: &[Primitive], offset: [f32; 3]) -> String {
        let mut bin: Vec<u8> = Vec::new();
        let (mut views, mut accessors, mut meshes, mut nodes) = (vec![], vec![], vec![], vec![]);
        for (i, p) in primitives.iter().enumerate() {
            let pos_offset = bin.len();
            for v in &p.positions {
                for c in v {
                    bin.extend_from_slice(&c.to_le_bytes());
                }
            }
            let idx_offset = bin.len();
            for i in &p.indices {
                bin.extend_from_slice(&i.to_le_bytes());
            }
            while !bin.len().is_multiple_of(4) {
                bin.push(0);
            }
            let min: Vec<f32> = (0..3)
                .map(|c| {
                    p.positions
                        .iter()
                        .map(|v| v[c])
                        .fold(f32::INFINITY, f32::min)
                })
                .collect();
            let max: Vec<f32> = (0..3)
                .map(|c| {
                    p.positions
                        .iter()
                        .map(|v| v[c])
                        .fold(f32::NEG_INFINITY, f32::max)
                })
                .collect();
            let fmt = |v: &[f32]| {
                v.iter()
                    .map(|x| {
                        if x.is_finite() {
                            format!("{x:?}")
                        } else {
                            "0.0".into()
                        }
                    })
                    .collect::<Vec<_>>()
                    .join(",")
            };
            views.push(format!(
                r#"{{"buffer":0,"byteOffset":{pos_offset},"byteLength":{}}}"#,
                p.positions.len() * 12
            ));
            views.push(format!(
                r#"{{"buffer":0,"byteOffset":{idx_offset},"byteLength":{}}}"#,
                p.indices.len() * 2
            ));
            accessors.push(format!(
                r#"{{"bufferView":{},"componentType":5126,"count":{},"type":"VEC3","min":[{}],"max":[{}]}}"#,
                2 * i,
                p.positions.len(),
                fmt(&min),
                fmt(&max)
            ));
            accessors.push(format!(
                r#"{{"bufferView":{},"componentType":5123,"count":{},"type":"SCALAR"}}"#,
                2 * i + 1,
                p.indices.len()
            ));
            meshes.push(format!(
                r#"{{"primitives":[{{"attributes":{{"POSITION":{}}},"indices":{},"material":{}}}]}}"#,
                2 * i,
                2 * i + 1,
                p.material
            ));
            nodes.push(format!(
                r#"{{"mesh":{i},"translation":[{},{},{}]}}"#,
                offset[0], offset[1], offset[2]
            ));
        }
        let mats: Vec<String> = materials
            .iter()
            .map(|(name, mode)| format!(r#"{{"name":"{name}","alphaMode":"{mode}"}}"#))
            .collect();
        let uri = base64::engine::general_purpose::STANDARD.encode(&bin);
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[{}]}}],"nodes":[{}],"meshes":[{}],"materials":[{}],"accessors":[{}],"bufferViews":[{}],"buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{uri}"}}]}}"#,
            (0..primitives.len())
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join(","),
            nodes.join(","),
            meshes.join(","),
            mats.join(","),
            accessors.join(","),
            views.join(","),
            bin.len()
        )
    }

    /// Bark: one triangle. Leaves (alpha-masked material): a quad, a 3-triangle fan, a single
    /// triangle, a degenerate (collinear) leaf and a leaf with a NaN vertex.
    pub(crate) fn sample_tree() -> String {
        let bark = Primitive {
            material: 0,
            positions: vec![[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.1, 2.0, 0.0]],
            indices: vec![0, 1, 2],
        };
        let leaves = Primitive {
            material: 1,
            positions: vec![
                // quad
                [0.0, 2.0, 0.0],
                [0.2, 2.0, 0.0],
                [0.2, 2.2, 0.0],
                [0.0, 2.2, 0.0],
                // fan of 3 triangles around vertex 4
                [1.0, 2.0, 0.0],
                [1.2, 2.0, 0.0],
                [1.2, 2.2, 0.0],
                [1.0, 2.3, 0.0],
                [0.8, 2.2, 0.0],
                // single triangle
                [2.0, 2.0, 0.0],
                [2.2, 2.0, 0.0],
                [2.1, 2.2, 0.0],
                // degenerate
                [3.0, 2.0, 0.0],
                [3.1, 2.0, 0.0],
                [3.2, 2.0, 0.0],
                // NaN
                [f32::NAN, 2.0, 0.0],
                [4.1, 2.0, 0.0],
                [4.0, 2.2, 0.0],
            ],
            indices: vec![
                0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7, 4, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17,
            ],
        };
        gltf_json(
            &[("Bark", "OPAQUE"), ("Needles", "MASK")],
            &[bark, leaves],
            [5.0, 1.0, 0.0],
        )
    }

    #[test]
    fn leaves_are_connected_components_of_the_masked_material() {
        let tree =
            load_gltf_tree(sample_tree().as_bytes(), None, &GltfLeafSettings::default()).unwrap();
        assert_eq!(tree.materials, vec!["Bark", "Needles"]);
        assert_eq!(tree.bark.indices.len(), 3);
        let leaves = &tree.leaves;
        assert_eq!(leaves.len(), 5, "quad, fan, triangle, degenerate, NaN");
        let triangles: Vec<usize> = leaves
            .leaves
            .iter()
            .map(|r| (r.end - r.start) as usize / 3)
            .collect();
        assert_eq!(triangles, vec![2, 3, 1, 1, 1]);
        // Node translation applied: the quad's centroid is at (5.1, 3.1, 0).
        assert!((leaves.centroid(0) - Vec3::new(5.1, 3.1, 0.0)).length() < 1e-5);
        assert!((leaves.area(0) - 0.04).abs() < 1e-5);
        // The bake drops and counts the bad leaves.
        let settings = BakeSettings {
            cell_depth: 1,
            resolution: 32,
            ..Default::default()
        };
        let (baked, _) = bake(leaves, &settings, &|_| {}).unwrap();
        assert_eq!(baked.leaf_count(), 3);
        assert_eq!((baked.skipped.degenerate, baked.skipped.non_finite), (1, 1));
        // A fan and a lone triangle are not quads: drawn with triangle slot meshes.
        assert!(!baked.quad_leaves());
    }

    #[test]
    fn explicit_leaf_material_list_overrides_detection() {
        let settings = GltfLeafSettings {
            leaf_materials: vec!["Bark".into()],
        };
        let tree = load_gltf_tree(sample_tree().as_bytes(), None, &settings).unwrap();
        assert_eq!(
            tree.leaves.len(),
            1,
            "the bark triangle is now the only leaf"
        );
        assert_eq!(tree.bark.indices.len(), 24);
    }

    #[test]
    fn no_leaves_is_an_error_listing_the_materials() {
        let trunk = Primitive {
            material: 0,
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            indices: vec![0, 1, 2],
        };
        let branch = Primitive {
            material: 1,
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            indices: vec![0, 1, 2],
        };
        let json = gltf_json(
            &[("Bark", "OPAQUE"), ("Wood", "OPAQUE")],
            &[trunk, branch],
            [0.0; 3],
        );
        let err = load_gltf_tree(json.as_bytes(), None, &GltfLeafSettings::default()).unwrap_err();
        assert_eq!(
            err,
            GltfTreeError::NoLeaves {
                materials: vec!["Bark".into(), "Wood".into()]
            }
        );
        let message = err.to_string();
        assert!(message.contains("[Bark, Wood]"), "{message}");
    }

    #[test]
    fn malformed_files_are_errors() {
        let err = load_gltf_tree(b"{ not json", None, &GltfLeafSettings::default()).unwrap_err();
        assert!(matches!(err, GltfTreeError::Parse(_)));
        let missing = sample_tree().replace("data:application/octet-stream;base64,", "missing-");
        let err = load_gltf_tree(
            missing.as_bytes(),
            Some(Path::new("/nonexistent")),
            &GltfLeafSettings::default(),
        )
        .unwrap_err();
        assert!(
            matches!(err, GltfTreeError::Buffer(ref m) if m.contains("/nonexistent")),
            "{err}"
        );
    }

    #[test]
    fn components_follow_shared_vertices() {
        assert_eq!(
            triangle_components(&[0, 1, 2, 2, 3, 4, 5, 6, 7]),
            vec![0, 0, 1]
        );
        assert_eq!(
            triangle_components(&[5, 6, 7, 0, 1, 2, 7, 8, 9]),
            vec![0, 1, 0]
        );
        assert!(triangle_components(&[]).is_empty());
    }
}
