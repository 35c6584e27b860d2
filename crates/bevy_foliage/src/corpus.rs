//! A corpus of real-world-like trees, written as glTF files the way tree generators and artists
//! export them — for trying pruning on content nobody tuned it for, in tests, benchmarks and by
//! hand (`cargo run --example pruning_corpus`).
//!
//! | tree | what it stresses |
//! |---|---|
//! | [`small_sparse_tree`] | 560 alpha-masked leaf cards on a 12 m tree: about one leaf per cell at the thesis' 512 cells |
//! | [`alpha_card_tree`] | 1,800 large cards, each a cluster of leaves on a texture opaque over a fifth of its area |
//! | [`centimetre_tree`] | an oak of 3,000 textured leaves authored in centimetres (1,300 units tall) |
//! | [`frond_tree`] | a palm whose fronds are welded grids (one connected mesh each), on an island with a water plane, as Bevy's own `PalmTree` sample is |
//!
//! Everything is generated deterministically (seeded) and written with [`GltfBuilder`]: a small
//! glTF 2.0 writer (one embedded base64 buffer, PNG textures embedded as data URIs) that the
//! tests of the glTF reader use too.

use crate::pruning::leaves::LeafSet;
use crate::pruning::procedural::{CrownShape, MeshData, TreeSpecies, generate};
use crate::rng::SplitMix64;
use base64::Engine;
use bevy::math::{Quat, Vec2, Vec3};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

/// How a glTF material treats alpha.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AlphaModeDesc {
    /// Opaque.
    Opaque,
    /// Alpha-masked at this cutoff.
    Mask(f32),
    /// Alpha-blended.
    Blend,
}

/// A glTF material to write.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialDesc {
    /// Name.
    pub name: String,
    /// Linear RGBA base colour factor.
    pub base_color: [f32; 4],
    /// Base colour texture (a texture index from [`GltfBuilder::texture_png`]).
    pub texture: Option<usize>,
    /// Alpha mode.
    pub alpha: AlphaModeDesc,
    /// Two-sided.
    pub double_sided: bool,
    /// Perceptual roughness.
    pub roughness: f32,
}

impl MaterialDesc {
    /// An opaque, one-sided material.
    pub fn opaque(name: &str, base_color: [f32; 4]) -> Self {
        Self {
            name: name.into(),
            base_color,
            texture: None,
            alpha: AlphaModeDesc::Opaque,
            double_sided: false,
            roughness: 0.9,
        }
    }
}

/// One primitive (triangle list) to write.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PrimitiveDesc {
    /// Material index.
    pub material: Option<usize>,
    /// Positions.
    pub positions: Vec<Vec3>,
    /// Normals (written when not empty).
    pub normals: Vec<Vec3>,
    /// Texture coordinates (written when not empty).
    pub uvs: Vec<Vec2>,
    /// Triangle list.
    pub indices: Vec<u32>,
}

impl PrimitiveDesc {
    /// A primitive of bark geometry.
    pub fn from_mesh(material: usize, mesh: &MeshData) -> Self {
        Self {
            material: Some(material),
            positions: mesh.positions.clone(),
            normals: mesh.normals.clone(),
            uvs: mesh.uvs.clone(),
            indices: mesh.indices.clone(),
        }
    }

    /// A primitive of every leaf of a leaf set.
    pub fn from_leaves(material: usize, leaves: &LeafSet) -> Self {
        Self {
            material: Some(material),
            positions: leaves.positions.clone(),
            normals: leaves.normals.clone(),
            uvs: leaves.uvs.clone(),
            indices: leaves.leaf_indices(),
        }
    }

    /// This primitive with every position (and normal) transformed by `scale` then `offset`.
    pub fn scaled(mut self, scale: f32, offset: Vec3) -> Self {
        for p in &mut self.positions {
            *p = *p * scale + offset;
        }
        self
    }
}

/// A node to write.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NodeDesc {
    /// Name.
    pub name: String,
    /// Mesh index.
    pub mesh: Option<usize>,
    /// Translation.
    pub translation: Vec3,
    /// Rotation.
    pub rotation: Quat,
    /// Uniform scale.
    pub scale: f32,
    /// Child node indices.
    pub children: Vec<usize>,
}

impl NodeDesc {
    /// A node drawing `mesh`, untransformed.
    pub fn mesh(name: &str, mesh: usize) -> Self {
        Self {
            name: name.into(),
            mesh: Some(mesh),
            rotation: Quat::IDENTITY,
            scale: 1.0,
            ..Default::default()
        }
    }
}

/// A minimal glTF 2.0 writer: meshes, nodes, materials and PNG textures, in one JSON document
/// with an embedded buffer.
#[derive(Clone, Debug, Default)]
pub struct GltfBuilder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
    meshes: Vec<Value>,
    nodes: Vec<Value>,
    materials: Vec<Value>,
    images: Vec<Value>,
    textures: Vec<Value>,
    roots: Vec<usize>,
}

impl GltfBuilder {
    /// An empty document.
    pub fn new() -> Self {
        Self::default()
    }

    fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.views.push(json!({
            "buffer": 0, "byteOffset": offset, "byteLength": bytes.len()
        }));
        self.views.len() - 1
    }

    fn accessor_vec(&mut self, values: &[f32], components: usize, with_bounds: bool) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes);
        let kind = ["SCALAR", "VEC2", "VEC3", "VEC4"][components - 1];
        let mut accessor = json!({
            "bufferView": view, "componentType": 5126,
            "count": values.len() / components, "type": kind
        });
        if with_bounds {
            let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
            let bound = |pick: fn(f32, f32) -> f32, init: f32| -> Vec<f32> {
                (0..components)
                    .map(|c| {
                        values
                            .iter()
                            .skip(c)
                            .step_by(components)
                            .fold(init, |a, &v| pick(a, finite(v)))
                    })
                    .collect()
            };
            accessor["min"] = json!(bound(f32::min, f32::INFINITY));
            accessor["max"] = json!(bound(f32::max, f32::NEG_INFINITY));
        }
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    fn accessor_indices(&mut self, indices: &[u32]) -> usize {
        let bytes: Vec<u8> = indices.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.accessors.push(json!({
            "bufferView": view, "componentType": 5125, "count": indices.len(), "type": "SCALAR"
        }));
        self.accessors.len() - 1
    }

    /// Adds a texture from 8-bit RGBA texels, encoded as PNG; returns its texture index.
    pub fn texture_png(&mut self, name: &str, width: u32, height: u32, rgba: &[u8]) -> usize {
        let png = encode_png(width, height, rgba);
        let uri = format!(
            "data:image/png;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(png)
        );
        self.images.push(json!({ "name": name, "uri": uri }));
        self.textures
            .push(json!({ "source": self.images.len() - 1 }));
        self.textures.len() - 1
    }

    /// Adds a material; returns its index.
    pub fn material(&mut self, m: &MaterialDesc) -> usize {
        let mut pbr = json!({
            "baseColorFactor": m.base_color,
            "metallicFactor": 0.0,
            "roughnessFactor": m.roughness,
        });
        if let Some(t) = m.texture {
            pbr["baseColorTexture"] = json!({ "index": t });
        }
        let mut material = json!({
            "name": m.name, "pbrMetallicRoughness": pbr, "doubleSided": m.double_sided
        });
        match m.alpha {
            AlphaModeDesc::Opaque => {}
            AlphaModeDesc::Mask(cutoff) => {
                material["alphaMode"] = json!("MASK");
                material["alphaCutoff"] = json!(cutoff);
            }
            AlphaModeDesc::Blend => material["alphaMode"] = json!("BLEND"),
        }
        self.materials.push(material);
        self.materials.len() - 1
    }

    /// Adds a mesh of `primitives`; returns its index.
    pub fn mesh(&mut self, name: &str, primitives: &[PrimitiveDesc]) -> usize {
        let prims: Vec<Value> = primitives
            .iter()
            .map(|p| {
                let flat3 = |v: &[Vec3]| v.iter().flat_map(|x| x.to_array()).collect::<Vec<_>>();
                let pos = self.accessor_vec(&flat3(&p.positions), 3, true);
                let mut attributes = json!({ "POSITION": pos });
                if !p.normals.is_empty() {
                    attributes["NORMAL"] = json!(self.accessor_vec(&flat3(&p.normals), 3, false));
                }
                if !p.uvs.is_empty() {
                    let uv: Vec<f32> = p.uvs.iter().flat_map(|x| x.to_array()).collect();
                    attributes["TEXCOORD_0"] = json!(self.accessor_vec(&uv, 2, false));
                }
                let indices = self.accessor_indices(&p.indices);
                let mut prim = json!({ "attributes": attributes, "indices": indices });
                if let Some(m) = p.material {
                    prim["material"] = json!(m);
                }
                prim
            })
            .collect();
        self.meshes
            .push(json!({ "name": name, "primitives": prims }));
        self.meshes.len() - 1
    }

    /// Adds a node; returns its index. Call [`root`](Self::root) for the scene's root nodes.
    pub fn node(&mut self, n: &NodeDesc) -> usize {
        let mut node = json!({ "name": n.name });
        if let Some(m) = n.mesh {
            node["mesh"] = json!(m);
        }
        if n.translation != Vec3::ZERO {
            node["translation"] = json!(n.translation.to_array());
        }
        if n.rotation != Quat::IDENTITY {
            node["rotation"] = json!(n.rotation.to_array());
        }
        if n.scale != 1.0 {
            node["scale"] = json!([n.scale, n.scale, n.scale]);
        }
        if !n.children.is_empty() {
            node["children"] = json!(n.children);
        }
        self.nodes.push(node);
        self.nodes.len() - 1
    }

    /// Makes `node` a root of the scene.
    pub fn root(&mut self, node: usize) {
        self.roots.push(node);
    }

    /// The document as glTF JSON text.
    pub fn to_json(&self) -> String {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bin)
        );
        self.document(Some(uri)).to_string()
    }

    /// The same document as a binary glTF (`.glb`): the JSON chunk, then the buffer as the
    /// binary chunk (glTF 2.0 spec, "Binary glTF Layout").
    pub fn to_glb(&self) -> Vec<u8> {
        let mut json = self.document(None).to_string().into_bytes();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }

    /// The glTF document; its buffer at `uri`, or the GLB binary chunk without one.
    fn document(&self, uri: Option<String>) -> Value {
        let buffer = match uri {
            Some(uri) => json!({ "byteLength": self.bin.len(), "uri": uri }),
            None => json!({ "byteLength": self.bin.len() }),
        };
        let mut doc = json!({
            "asset": { "version": "2.0", "generator": "bevy_foliage corpus" },
            "scene": 0,
            "scenes": [{ "nodes": self.roots }],
            "nodes": self.nodes,
            "meshes": self.meshes,
            "accessors": self.accessors,
            "bufferViews": self.views,
            "buffers": [buffer],
        });
        if !self.materials.is_empty() {
            doc["materials"] = json!(self.materials);
        }
        if !self.images.is_empty() {
            doc["images"] = json!(self.images);
            doc["textures"] = json!(self.textures);
        }
        doc
    }
}

/// PNG bytes of 8-bit RGBA texels.
pub fn encode_png(width: u32, height: u32, rgba: &[u8]) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    image::RgbaImage::from_raw(width, height, rgba.to_vec())
        .expect("rgba holds width × height texels")
        .write_to(&mut out, image::ImageFormat::Png)
        .expect("PNG encoding into memory does not fail");
    out.into_inner()
}

/// A corpus tree: its glTF text and what it is.
#[derive(Clone, Debug)]
pub struct CorpusTree {
    /// File stem.
    pub name: &'static str,
    /// One line on what it is.
    pub description: &'static str,
    /// The glTF document (JSON).
    pub gltf: String,
    /// Total height of the tree in the file's units.
    pub height: f32,
}

impl CorpusTree {
    /// Writes `<dir>/<name>.gltf` and returns its path.
    pub fn write(&self, dir: &Path) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(dir)?;
        let path = dir.join(format!("{}.gltf", self.name));
        std::fs::write(&path, &self.gltf)?;
        Ok(path)
    }
}

/// Every corpus tree.
pub fn all() -> Vec<CorpusTree> {
    vec![
        small_sparse_tree(),
        alpha_card_tree(),
        centimetre_tree(),
        frond_tree(),
    ]
}

/// A leaf texture: one pointed leaf with a midrib on a transparent card, opaque over about 45 %
/// of the card.
pub fn leaf_card_texture(size: u32) -> Vec<u8> {
    let mut rgba = vec![0u8; (size * size * 4) as usize];
    for y in 0..size {
        for x in 0..size {
            // Leaf along v: u across, v from stem (v = 1) to tip (v = 0).
            let u = (x as f32 + 0.5) / size as f32 * 2.0 - 1.0;
            let v = (y as f32 + 0.5) / size as f32;
            let half_width = 0.72 * (std::f32::consts::PI * v).sin().powf(0.8);
            let inside = u.abs() < half_width;
            let i = ((y * size + x) * 4) as usize;
            if inside {
                let vein = (u.abs() < 0.05) as u8;
                rgba[i..i + 4].copy_from_slice(&[60 + 40 * vein, 120 + 30 * vein, 45, 255]);
            } else {
                rgba[i..i + 4].copy_from_slice(&[60, 110, 45, 0]);
            }
        }
    }
    rgba
}

/// A cluster texture: five small round leaves scattered on a transparent card, opaque over about
/// a fifth of it (the card-heavy exports of tree generators).
pub fn leaf_cluster_texture(size: u32) -> Vec<u8> {
    let leaves = [
        (0.28, 0.3, 0.13),
        (0.7, 0.25, 0.12),
        (0.5, 0.55, 0.11),
        (0.25, 0.75, 0.1),
        (0.75, 0.75, 0.12),
    ];
    let mut rgba = vec![0u8; (size * size * 4) as usize];
    for y in 0..size {
        for x in 0..size {
            let p = Vec2::new(
                (x as f32 + 0.5) / size as f32,
                (y as f32 + 0.5) / size as f32,
            );
            let inside = leaves
                .iter()
                .any(|&(cx, cy, r)| p.distance(Vec2::new(cx, cy)) < r);
            let i = ((y * size + x) * 4) as usize;
            rgba[i..i + 4].copy_from_slice(&[70, 125, 50, if inside { 255 } else { 0 }]);
        }
    }
    rgba
}

const BARK_COLOR: [f32; 4] = [0.18, 0.11, 0.07, 1.0];

/// Writes a tree whose bark and card leaves come from a procedural species, with a leaf texture.
fn card_tree(species: &TreeSpecies, texture: (&str, u32, Vec<u8>), scale: f32) -> (String, f32) {
    let tree = generate(species);
    let mut b = GltfBuilder::new();
    let bark = b.material(&MaterialDesc::opaque("Bark", BARK_COLOR));
    let tex = b.texture_png(texture.0, texture.1, texture.1, &texture.2);
    let leaf = b.material(&MaterialDesc {
        name: "Leaf".into(),
        base_color: [1.0; 4],
        texture: Some(tex),
        alpha: AlphaModeDesc::Mask(0.5),
        double_sided: true,
        roughness: 0.7,
    });
    let trunk = b.mesh(
        "Trunk",
        &[PrimitiveDesc::from_mesh(bark, &tree.bark).scaled(scale, Vec3::ZERO)],
    );
    let crown = b.mesh(
        "Leaves",
        &[PrimitiveDesc::from_leaves(leaf, &tree.leaves).scaled(scale, Vec3::ZERO)],
    );
    let trunk = b.node(&NodeDesc::mesh("trunk", trunk));
    let crown = b.node(&NodeDesc::mesh("crown", crown));
    let root = b.node(&NodeDesc {
        name: "tree".into(),
        rotation: Quat::IDENTITY,
        scale: 1.0,
        children: vec![trunk, crown],
        ..Default::default()
    });
    b.root(root);
    (b.to_json(), species.height * scale)
}

/// The species of [`small_sparse_tree`].
pub fn small_sparse_species() -> TreeSpecies {
    TreeSpecies {
        name: "small sparse tree",
        leaf_count: 560,
        height: 12.0,
        crown_base: 4.0,
        crown_radius: 4.0,
        shape: CrownShape::Ellipsoid,
        trunk_radius: 0.25,
        branches: 7,
        twigs_per_branch: 6,
        leaf_size: 0.8,
        leaf_aspect: 1.0,
        seed: 11,
    }
}

/// A small, sparse tree: 560 alpha-masked leaf cards of 0.8 m on a 12 m tree.
pub fn small_sparse_tree() -> CorpusTree {
    let (gltf, height) = card_tree(
        &small_sparse_species(),
        ("leaf", 64, leaf_card_texture(64)),
        1.0,
    );
    CorpusTree {
        name: "small_sparse",
        description: "560 alpha-masked leaf cards on a 12 m tree",
        gltf,
        height,
    }
}

/// The species of [`alpha_card_tree`].
pub fn alpha_card_species() -> TreeSpecies {
    TreeSpecies {
        name: "alpha card tree",
        leaf_count: 1800,
        height: 16.0,
        crown_base: 5.0,
        crown_radius: 5.0,
        shape: CrownShape::Ellipsoid,
        trunk_radius: 0.35,
        branches: 10,
        twigs_per_branch: 9,
        leaf_size: 1.4,
        leaf_aspect: 1.0,
        seed: 12,
    }
}

/// A card tree whose 1,800 cards of 1.4 m each carry a cluster of small leaves on a texture
/// opaque over about a fifth of its area: a visibility bake that treats the cards as solid
/// finds most of the crown hidden.
pub fn alpha_card_tree() -> CorpusTree {
    let (gltf, height) = card_tree(
        &alpha_card_species(),
        ("cluster", 64, leaf_cluster_texture(64)),
        1.0,
    );
    CorpusTree {
        name: "alpha_cards",
        description: "1,800 cards, each a leaf cluster opaque over a fifth of the card",
        gltf,
        height,
    }
}

/// The species of [`centimetre_tree`] (in metres: the file is written in centimetres).
pub fn centimetre_species() -> TreeSpecies {
    TreeSpecies::quercus().with_leaf_count(3000)
}

/// An oak of 3,000 textured leaves, authored in centimetres (1,300 units tall): distances that
/// are absolute world units prune it as if it stood 100 times farther away.
pub fn centimetre_tree() -> CorpusTree {
    let (gltf, height) = card_tree(
        &centimetre_species(),
        ("leaf", 64, leaf_card_texture(64)),
        100.0,
    );
    CorpusTree {
        name: "centimetres",
        description: "an oak of 3,000 textured leaves authored in centimetres",
        gltf,
        height,
    }
}

/// Fronds of [`frond_tree`]: the count and segments along each.
pub const FRONDS: usize = 9;
/// Segments along a frond's rachis.
pub const FROND_SEGMENTS: usize = 24;

/// One welded frond: a rachis strip along an arching curve with a leaflet on each side of every
/// segment, all sharing the rachis vertices — one connected mesh of `6 · segments` triangles.
fn frond(base: Vec3, azimuth: f32, length: f32, rng: &mut SplitMix64) -> PrimitiveDesc {
    let out = Vec3::new(azimuth.cos(), 0.0, azimuth.sin());
    let side = Vec3::Y.cross(out).normalize();
    let droop = rng.range(0.6, 1.1);
    let mut p = PrimitiveDesc::default();
    let along =
        |t: f32| base + out * (length * t) + Vec3::Y * (length * (0.35 * t - droop * 0.5 * t * t));
    for s in 0..=FROND_SEGMENTS {
        let t = s as f32 / FROND_SEGMENTS as f32;
        let c = along(t);
        let w = 0.05 * (1.0 - t) + 0.01;
        // Rachis edge vertices (shared by the strip and both leaflets).
        p.positions.push(c - side * w);
        p.positions.push(c + side * w);
        p.uvs.push(Vec2::new(0.0, t));
        p.uvs.push(Vec2::new(1.0, t));
    }
    let tangent = |t: f32| (along((t + 0.01).min(1.0)) - along((t - 0.01).max(0.0))).normalize();
    for s in 0..FROND_SEGMENTS {
        let (a, b) = (2 * s as u32, 2 * s as u32 + 2);
        // Rachis quad.
        p.indices.extend_from_slice(&[a, a + 1, b + 1, a, b + 1, b]);
        // A leaflet on each side: a quad from the rachis edge outwards and down the frond.
        let t = (s as f32 + 0.5) / FROND_SEGMENTS as f32;
        let reach = length * 0.28 * (std::f32::consts::PI * (0.15 + 0.85 * t)).sin();
        for (edge_a, edge_b, dir) in [(a, b, -side), (a + 1, b + 1, side)] {
            let tip = p.positions[edge_a as usize]
                + (dir * 0.9 - Vec3::Y * 0.3 + tangent(t) * 0.4) * reach;
            let k = p.positions.len() as u32;
            p.positions.push(tip);
            p.positions
                .push(tip + tangent(t) * (length / FROND_SEGMENTS as f32));
            p.uvs.push(Vec2::new(0.5, t));
            p.uvs.push(Vec2::new(0.5, t));
            p.indices
                .extend_from_slice(&[edge_a, k, k + 1, edge_a, k + 1, edge_b]);
        }
    }
    // Normals: mostly up, as a frond seen from above.
    p.normals = vec![Vec3::Y; p.positions.len()];
    p
}

/// A palm (9 m trunk, nine fronds of 4.5 m) whose fronds are welded grids, one connected mesh of
/// 144 triangles each, in an opaque material named "Leaves"; the file also holds an island and a
/// water plane under the tree, as Bevy's `PalmTree` sample does.
pub fn frond_tree() -> CorpusTree {
    let mut rng = SplitMix64::new(13);
    let mut b = GltfBuilder::new();
    let bark = b.material(&MaterialDesc::opaque("Trunk", [0.45, 0.3, 0.18, 1.0]));
    let leaves = b.material(&MaterialDesc {
        double_sided: true,
        ..MaterialDesc::opaque("Leaves", [0.15, 0.5, 0.1, 1.0])
    });
    let sand = b.material(&MaterialDesc::opaque("Sand", [0.9, 0.85, 0.6, 1.0]));
    let water = b.material(&MaterialDesc::opaque("Water", [0.1, 0.3, 0.6, 1.0]));
    // A leaning trunk.
    let mut trunk = MeshData::default();
    let top = Vec3::new(0.8, 9.0, 0.2);
    let mut prev = Vec3::ZERO;
    for i in 1..=6 {
        let t = i as f32 / 6.0;
        let p = Vec3::new(top.x * t * t, top.y * t, top.z * t * t);
        trunk.push_cylinder(prev, p, 0.28 - 0.1 * (t - 1.0 / 6.0), 0.28 - 0.1 * t, 10);
        prev = p;
    }
    let trunk_mesh = b.mesh("Trunk", &[PrimitiveDesc::from_mesh(bark, &trunk)]);
    let trunk_node = b.node(&NodeDesc::mesh("Trunk", trunk_mesh));
    b.root(trunk_node);
    // Fronds, each its own mesh under its own root node (as Blender exports them).
    for f in 0..FRONDS {
        let azimuth = f as f32 / FRONDS as f32 * std::f32::consts::TAU + rng.range(-0.2, 0.2);
        let mut prim = frond(Vec3::ZERO, azimuth, rng.range(4.0, 5.0), &mut rng);
        prim.material = Some(leaves);
        let mesh = b.mesh(&format!("Frond.{f:03}"), &[prim]);
        let node = b.node(&NodeDesc {
            translation: top,
            ..NodeDesc::mesh(&format!("Frond.{f:03}"), mesh)
        });
        b.root(node);
    }
    // The island (a low disc, 60 m across) and the sea (a 400 m plane).
    let mut island = PrimitiveDesc {
        material: Some(sand),
        ..Default::default()
    };
    island.positions.push(Vec3::new(0.0, 0.3, 0.0));
    island.normals.push(Vec3::Y);
    for i in 0..32 {
        let a = i as f32 / 32.0 * std::f32::consts::TAU;
        island
            .positions
            .push(Vec3::new(a.cos() * 30.0, -0.5, a.sin() * 30.0));
        island.normals.push(Vec3::Y);
        island
            .indices
            .extend_from_slice(&[0, 1 + (i + 1) % 32, 1 + i]);
    }
    island.uvs = vec![Vec2::ZERO; island.positions.len()];
    let island = b.mesh("Landscape", &[island]);
    let island = b.node(&NodeDesc::mesh("Landscape", island));
    b.root(island);
    let sea = PrimitiveDesc {
        material: Some(water),
        positions: vec![
            Vec3::new(-200.0, 0.0, -200.0),
            Vec3::new(200.0, 0.0, -200.0),
            Vec3::new(200.0, 0.0, 200.0),
            Vec3::new(-200.0, 0.0, 200.0),
        ],
        normals: vec![Vec3::Y; 4],
        uvs: vec![Vec2::ZERO; 4],
        indices: vec![0, 2, 1, 0, 3, 2],
    };
    let sea = b.mesh("Landscape_plane", &[sea]);
    let sea = b.node(&NodeDesc::mesh("Landscape_plane", sea));
    b.root(sea);
    CorpusTree {
        name: "fronds",
        description: "a palm of nine welded fronds on an island with a water plane",
        gltf: b.to_json(),
        height: 9.0 + 1.5,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn textures_have_the_stated_opaque_share() {
        let share = |rgba: &[u8]| {
            rgba.chunks_exact(4).filter(|t| t[3] >= 128).count() as f32 / (rgba.len() / 4) as f32
        };
        let leaf = share(&leaf_card_texture(64));
        let cluster = share(&leaf_cluster_texture(64));
        assert!((0.38..0.52).contains(&leaf), "{leaf}");
        assert!((0.15..0.25).contains(&cluster), "{cluster}");
    }

    #[test]
    fn every_corpus_file_is_valid_gltf() {
        for tree in all() {
            let gltf = ::gltf::Gltf::from_slice(tree.gltf.as_bytes())
                .unwrap_or_else(|e| panic!("{}: {e}", tree.name));
            assert!(gltf.document.meshes().count() >= 2, "{}", tree.name);
            assert!(tree.height > 0.0);
        }
        // PNG round trip.
        let png = encode_png(2, 1, &[1, 2, 3, 4, 5, 6, 7, 8]);
        let back = image::load_from_memory(&png).unwrap().to_rgba8();
        assert_eq!(back.into_raw(), vec![1, 2, 3, 4, 5, 6, 7, 8]);
    }
}
