//! Trees from glTF files as artists and tree generators export them: which meshes are the tree,
//! which triangles are leaves, how they are cut into leaves, and the file's own materials.
//!
//! **Which meshes are the tree.** With [`GltfLeafSettings::node`] set, the named node's subtree
//! (its own transform included, its ancestors' left out). Otherwise the file's largest tree:
//! files often carry a ground, an island or a water plane beside the tree (Bevy's `PalmTree`
//! sample does), and a tree's parts are often sibling root nodes, so the hierarchy alone does not
//! say what the tree is. The rule:
//!
//! 1. the foliage primitives (below) are grouped by overlap of their bounding boxes, each grown
//!    by a tenth of its size: the group with the most leaf area is the crown;
//! 2. every other primitive belongs to the tree when its bounding box stands in the crown's
//!    column — horizontally inside the crown's box grown by a quarter of its width on each side,
//!    and not above the crown's top. A trunk under its crown does; a ground, island or water
//!    plane wider than the crown does not; nor does a second tree beside the first.
//!
//! Everything left out is named in [`GltfTree::notes`] (and logged by the spawner).
//!
//! **Which primitives are leaves.** A primitive is foliage when its material is listed in
//! [`GltfLeafSettings::leaf_materials`], or — with that list empty, the default — when its
//! material is alpha-masked or alpha-blended, or the material, mesh or node name contains
//! "leaf"/"leaves"/"frond"/"foliage"/"needle" (any case). The rest of the tree is bark.
//!
//! **How leaves are separated.** Inside each foliage primitive a leaf is one *connected
//! component* of triangles that share vertex indices (union–find over the index buffer): a card,
//! a fan, a strip. Exporters give each card its own vertices (its own UVs), so cards come apart.
//! A component of more than [`GltfLeafSettings::max_leaf_triangles`] triangles is a welded
//! cluster — a palm frond, a twig modelled as one surface — and is cut into leaves of about
//! [`GltfLeafSettings::cluster_leaf_triangles`] triangles: starting from the unassigned triangle
//! lowest along the cluster's longest axis (a frond's base), a leaf grows breadth-first over
//! triangles sharing an edge until it has its count, then the next starts; so a frond is cut
//! into consecutive pieces from base to tip; a piece left under half the count (triangles whose
//! neighbours were all claimed) is folded into its smallest neighbouring piece. Each piece gets
//! its own copy of the vertices it shares with its neighbours, so pruning drops it, and area
//! compensation scales it, alone.
//!
//! **Materials.** Every material is read ([`GltfMaterial`]: base colour, metallic/roughness,
//! emissive, alpha mode and cutoff, double-sidedness, texture references) and the images the
//! tree's materials use are decoded (PNG and JPEG; data URIs, buffer views or files next to the
//! `.gltf`). An image that cannot be decoded is noted and its material drawn without it. The
//! leaf texture's alpha and cutoff give the bake its [`AlphaMask`] and the sub-pixel fade its
//! opaque fraction ([`GltfTree::leaf_mask`]).
//!
//! Attribute arrays shorter than `POSITION`, indices out of range and node cycles are clear
//! errors naming the primitive. Leaves with NaN or degenerate geometry are kept here and dropped
//! (and counted) by the bake. Only triangle-list primitives are read; others are counted in
//! [`GltfTree::ignored_primitives`].

use super::leaves::LeafSet;
use super::mask::AlphaMask;
use super::procedural::MeshData;
use base64::Engine;
use bevy::math::{Mat4, Vec2, Vec3};
use std::collections::{HashMap, VecDeque};
use std::path::Path;

/// How foliage is recognised and cut in a glTF file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GltfLeafSettings {
    /// Names of the leaf materials. Empty: detect (alpha mask/blend, or a leafy name).
    pub leaf_materials: Vec<String>,
    /// The node whose subtree is the tree. `None`: the file's largest tree (module docs).
    pub node: Option<String>,
    /// A connected leaf mesh with more triangles than this is a welded cluster and is cut.
    pub max_leaf_triangles: usize,
    /// Triangles per leaf cut from a welded cluster.
    pub cluster_leaf_triangles: usize,
}

impl Default for GltfLeafSettings {
    fn default() -> Self {
        Self {
            leaf_materials: Vec::new(),
            node: None,
            // Leaf cards are 2–8 triangles and detailed single leaves rarely over 64; fronds and
            // leafy twigs modelled as one surface have hundreds.
            max_leaf_triangles: 64,
            // About a leaflet pair of a frond.
            cluster_leaf_triangles: 8,
        }
    }
}

/// How a material treats alpha.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GltfAlpha {
    /// Opaque.
    Opaque,
    /// Texels under the cutoff are discarded.
    Mask(f32),
    /// Alpha-blended.
    Blend,
}

/// How a texture wraps along one axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GltfWrap {
    /// Repeat (glTF's default).
    Repeat,
    /// Mirrored repeat.
    MirroredRepeat,
    /// Clamp to the edge.
    Clamp,
}

/// A texture a material uses: which decoded image, and how it wraps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfTextureRef {
    /// Index into [`GltfTree::images`].
    pub image: usize,
    /// Wrapping along u and v.
    pub wrap: [GltfWrap; 2],
}

/// A material of the file.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfMaterial {
    /// Name (`<unnamed #i>` when it has none).
    pub name: String,
    /// Linear RGBA base colour factor.
    pub base_color: [f32; 4],
    /// Base colour texture (sRGB; its alpha is the leaf mask).
    pub base_color_texture: Option<GltfTextureRef>,
    /// Tangent-space normal map.
    pub normal_texture: Option<GltfTextureRef>,
    /// Metallic (blue) and roughness (green) texture.
    pub metallic_roughness_texture: Option<GltfTextureRef>,
    /// Metallic factor.
    pub metallic: f32,
    /// Roughness factor.
    pub roughness: f32,
    /// Linear emissive colour.
    pub emissive: [f32; 3],
    /// Alpha mode.
    pub alpha: GltfAlpha,
    /// Drawn from both sides.
    pub double_sided: bool,
}

/// An image decoded to 8-bit RGBA.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedImage {
    /// Texels wide.
    pub width: u32,
    /// Texels high.
    pub height: u32,
    /// Row-major RGBA texels.
    pub rgba: Vec<u8>,
}

/// Leaves of one leaf material.
#[derive(Clone, Debug, Default)]
pub struct LeafGroup {
    /// Index into [`GltfTree::materials`].
    pub material: Option<usize>,
    /// The leaves, in model space.
    pub leaves: LeafSet,
    /// Welded clusters that were cut into leaves.
    pub clusters_cut: usize,
}

/// Bark of one material.
#[derive(Clone, Debug, Default)]
pub struct BarkPart {
    /// Index into [`GltfTree::materials`].
    pub material: Option<usize>,
    /// The geometry, in model space.
    pub mesh: MeshData,
}

/// What a glTF file holds as a tree.
#[derive(Clone, Debug, Default)]
pub struct GltfTree {
    /// The leaves, one group per leaf material.
    pub leaf_groups: Vec<LeafGroup>,
    /// Everything else of the tree (trunk, branches), one part per material.
    pub bark: Vec<BarkPart>,
    /// Every material in the file.
    pub materials: Vec<GltfMaterial>,
    /// The file's images: decoded when the tree's materials use them, else `None`.
    pub images: Vec<Option<DecodedImage>>,
    /// What was left out or changed, one sentence each.
    pub notes: Vec<String>,
    /// Primitives skipped because they are not triangle lists.
    pub ignored_primitives: usize,
}

impl GltfTree {
    /// Every leaf of every group in one set.
    pub fn leaves(&self) -> LeafSet {
        let mut all = LeafSet::default();
        for g in &self.leaf_groups {
            let base = all.positions.len() as u32;
            let start = all.indices.len() as u32;
            all.positions.extend_from_slice(&g.leaves.positions);
            all.normals.extend_from_slice(&g.leaves.normals);
            all.uvs.extend_from_slice(&g.leaves.uvs);
            all.indices
                .extend(g.leaves.indices.iter().map(|i| i + base));
            all.leaves.extend(
                g.leaves
                    .leaves
                    .iter()
                    .map(|r| r.start + start..r.end + start),
            );
        }
        all
    }

    /// The material of a group, if any.
    pub fn material_of(&self, group: &LeafGroup) -> Option<&GltfMaterial> {
        group.material.and_then(|m| self.materials.get(m))
    }

    /// The alpha mask of a leaf group's material: its base colour texture's alpha times the
    /// base colour factor's, at the material's cutoff (0.5 for blended leaves, which the leaf
    /// material draws masked). `None` for opaque or untextured leaves.
    pub fn leaf_mask(&self, group: &LeafGroup) -> Option<AlphaMask> {
        let material = self.material_of(group)?;
        let cutoff = match material.alpha {
            GltfAlpha::Opaque => return None,
            GltfAlpha::Mask(c) => c,
            GltfAlpha::Blend => 0.5,
        };
        let texture = material.base_color_texture?;
        let image = self.images.get(texture.image)?.as_ref()?;
        let factor = material.base_color[3].clamp(0.0, 1.0);
        let alpha: Vec<u8> = image
            .rgba
            .chunks_exact(4)
            .map(|t| (t[3] as f32 * factor).round() as u8)
            .collect();
        AlphaMask::new(image.width, image.height, &alpha, cutoff).ok()
    }
}

/// Why a glTF file could not be read as a tree.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GltfTreeError {
    /// Not valid glTF.
    Parse(String),
    /// A buffer could not be read (missing file, bad data URI, too short).
    Buffer(String),
    /// A primitive or node is malformed (what and where is said).
    Invalid(String),
    /// The named node is not in the file.
    NoSuchNode {
        /// The name asked for.
        name: String,
        /// Every named node, so the user can pick.
        nodes: Vec<String>,
    },
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
            Self::Invalid(e) => write!(f, "malformed glTF: {e}"),
            Self::NoSuchNode { name, nodes } => write!(
                f,
                "no node named '{name}'; named nodes in the file: [{}]",
                nodes.join(", ")
            ),
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

fn is_leafy(name: Option<&str>) -> bool {
    name.map(|n| n.to_ascii_lowercase()).is_some_and(|n| {
        ["leaf", "leaves", "frond", "foliage", "needle"]
            .iter()
            .any(|w| n.contains(w))
    })
}

fn decode_base64_uri(uri: &str) -> Option<Result<Vec<u8>, String>> {
    let rest = uri.strip_prefix("data:")?;
    Some(match rest.split_once(";base64,") {
        Some((_, payload)) => base64::engine::general_purpose::STANDARD
            .decode(payload)
            .map_err(|e| format!("bad base64: {e}")),
        None => Err("only base64 data URIs are supported".into()),
    })
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
                ::gltf::buffer::Source::Uri(uri) => match decode_base64_uri(uri) {
                    Some(data) => data.map_err(GltfTreeError::Buffer)?,
                    None => {
                        let path = base_dir.unwrap_or(Path::new(".")).join(uri);
                        std::fs::read(&path).map_err(|e| {
                            GltfTreeError::Buffer(format!("{}: {e}", path.display()))
                        })?
                    }
                },
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

/// Cuts a welded cluster (the triangles `triangles` of `indices`, one connected component) into
/// pieces of about `per_piece` triangles, as the module documentation describes (pieces under
/// half the count are folded into their smallest neighbour). Returns the pieces as lists of
/// triangle numbers, in order from the cluster's base.
pub fn cut_cluster(
    indices: &[u32],
    triangles: &[usize],
    positions: &[Vec3],
    per_piece: usize,
) -> Vec<Vec<usize>> {
    let per_piece = per_piece.max(1);
    let centroid = |t: usize| {
        (positions[indices[3 * t] as usize]
            + positions[indices[3 * t + 1] as usize]
            + positions[indices[3 * t + 2] as usize])
            / 3.0
    };
    // The cluster's longest axis (of its bounding box) orders the seeds from base to tip.
    let (lo, hi) = triangles
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &t| {
            (lo.min(centroid(t)), hi.max(centroid(t)))
        });
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        Vec3::X
    } else if extent.y >= extent.z {
        Vec3::Y
    } else {
        Vec3::Z
    };
    // Edge adjacency within the cluster.
    let mut by_edge: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for &t in triangles {
        for k in 0..3 {
            let (a, b) = (indices[3 * t + k], indices[3 * t + (k + 1) % 3]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push(t);
        }
    }
    let by_edge = &by_edge;
    let neighbours = |t: usize| -> Vec<usize> {
        (0..3)
            .flat_map(|k| {
                let (a, b) = (indices[3 * t + k], indices[3 * t + (k + 1) % 3]);
                by_edge[&(a.min(b), a.max(b))].iter().copied()
            })
            .filter(|&n| n != t)
            .collect()
    };
    let mut order: Vec<usize> = triangles.to_vec();
    order.sort_by(|&a, &b| {
        centroid(a)
            .dot(axis)
            .total_cmp(&centroid(b).dot(axis))
            .then(a.cmp(&b))
    });
    let mut assigned: HashMap<usize, bool> = triangles.iter().map(|&t| (t, false)).collect();
    let mut pieces = Vec::new();
    for &seed in &order {
        if assigned[&seed] {
            continue;
        }
        let mut piece = Vec::with_capacity(per_piece);
        let mut queue = VecDeque::from([seed]);
        assigned.insert(seed, true);
        while let Some(t) = queue.pop_front() {
            piece.push(t);
            if piece.len() + queue.len() >= per_piece {
                // Enough claimed: finish with what is queued.
                piece.extend(queue.drain(..));
                break;
            }
            for n in neighbours(t) {
                if !assigned[&n] && piece.len() + queue.len() < per_piece {
                    assigned.insert(n, true);
                    queue.push_back(n);
                }
            }
        }
        pieces.push(piece);
    }
    // Growth can strand a triangle or two whose neighbours were all claimed (the far half of a
    // leaflet): fold pieces under half the count into their smallest neighbouring piece.
    let mut piece_of: HashMap<usize, usize> = HashMap::new();
    for (p, piece) in pieces.iter().enumerate() {
        for &t in piece {
            piece_of.insert(t, p);
        }
    }
    for p in 0..pieces.len() {
        if pieces[p].is_empty() || 2 * pieces[p].len() >= per_piece {
            continue;
        }
        let target = pieces[p]
            .iter()
            .flat_map(|&t| neighbours(t))
            .map(|n| piece_of[&n])
            .filter(|&q| q != p)
            .min_by_key(|&q| (pieces[q].len(), q));
        if let Some(q) = target {
            let moved = std::mem::take(&mut pieces[p]);
            for &t in &moved {
                piece_of.insert(t, q);
            }
            pieces[q].extend(moved);
        }
    }
    pieces.retain(|p| !p.is_empty());
    pieces
}

fn wrap(mode: ::gltf::texture::WrappingMode) -> GltfWrap {
    match mode {
        ::gltf::texture::WrappingMode::Repeat => GltfWrap::Repeat,
        ::gltf::texture::WrappingMode::MirroredRepeat => GltfWrap::MirroredRepeat,
        ::gltf::texture::WrappingMode::ClampToEdge => GltfWrap::Clamp,
    }
}

fn texture_ref(texture: ::gltf::texture::Texture) -> GltfTextureRef {
    let sampler = texture.sampler();
    GltfTextureRef {
        image: texture.source().index(),
        wrap: [wrap(sampler.wrap_s()), wrap(sampler.wrap_t())],
    }
}

fn read_material(index: usize, m: &::gltf::Material) -> GltfMaterial {
    let pbr = m.pbr_metallic_roughness();
    GltfMaterial {
        name: m
            .name()
            .map_or_else(|| format!("<unnamed #{index}>"), str::to_string),
        base_color: pbr.base_color_factor(),
        base_color_texture: pbr.base_color_texture().map(|i| texture_ref(i.texture())),
        normal_texture: m.normal_texture().map(|n| texture_ref(n.texture())),
        metallic_roughness_texture: pbr
            .metallic_roughness_texture()
            .map(|i| texture_ref(i.texture())),
        metallic: pbr.metallic_factor(),
        roughness: pbr.roughness_factor(),
        emissive: m.emissive_factor(),
        alpha: match m.alpha_mode() {
            ::gltf::material::AlphaMode::Opaque => GltfAlpha::Opaque,
            ::gltf::material::AlphaMode::Mask => GltfAlpha::Mask(m.alpha_cutoff().unwrap_or(0.5)),
            ::gltf::material::AlphaMode::Blend => GltfAlpha::Blend,
        },
        double_sided: m.double_sided(),
    }
}

/// The largest texture side read (a corrupt header must not allocate gigapixels).
const MAX_TEXTURE_SIDE: u32 = 16384;

fn decode_image(
    document: &::gltf::Document,
    image: &::gltf::Image,
    buffers: &[Vec<u8>],
    base_dir: Option<&Path>,
) -> Result<DecodedImage, String> {
    // The gltf crate's `Image::source` unwraps what validation lets through: an image needs a
    // uri or a buffer view, and one in a buffer view a MIME type.
    let json = document
        .as_json()
        .images
        .get(image.index())
        .ok_or("it is not in the document")?;
    match (&json.uri, &json.buffer_view, &json.mime_type) {
        (None, None, _) => return Err("it has neither a uri nor a bufferView".into()),
        (_, Some(_), None) => return Err("it is in a bufferView without a mimeType".into()),
        _ => {}
    }
    let bytes = match image.source() {
        ::gltf::image::Source::View { view, .. } => {
            let buffer = buffers
                .get(view.buffer().index())
                .ok_or("its buffer is missing")?;
            buffer
                .get(view.offset()..view.offset() + view.length())
                .ok_or("its buffer view runs past the buffer")?
                .to_vec()
        }
        ::gltf::image::Source::Uri { uri, .. } => match decode_base64_uri(uri) {
            Some(data) => data?,
            None => {
                let path = base_dir.unwrap_or(Path::new(".")).join(uri);
                std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?
            }
        },
    };
    let (width, height) = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?
        .into_dimensions()
        .map_err(|e| e.to_string())?;
    if width > MAX_TEXTURE_SIDE || height > MAX_TEXTURE_SIDE {
        return Err(format!(
            "it claims {width}×{height} texels (at most {MAX_TEXTURE_SIDE} a side are read)"
        ));
    }
    let decoded = image::load_from_memory(&bytes)
        .map_err(|e| e.to_string())?
        .to_rgba8();
    Ok(DecodedImage {
        width: decoded.width(),
        height: decoded.height(),
        rgba: decoded.into_raw(),
    })
}

/// Whether the gltf crate can read `accessor` as attribute `what` safely: the element type the
/// glTF 2.0 spec allows for it (§3.7.2.1 and §3.7.2.2: the readers assume it), at least one
/// element (and one sparse element), and every element's bytes inside its buffer view, and the
/// view inside its buffer.
fn check_accessor(
    what: &str,
    accessor: &::gltf::Accessor,
    buffers: &[Vec<u8>],
) -> Result<(), String> {
    use ::gltf::accessor::{DataType, Dimensions};
    let (dimensions, data_type) = (accessor.dimensions(), accessor.data_type());
    let allowed = match what {
        "POSITION" | "NORMAL" => dimensions == Dimensions::Vec3 && data_type == DataType::F32,
        "TEXCOORD_0" => {
            dimensions == Dimensions::Vec2
                && matches!(data_type, DataType::F32 | DataType::U8 | DataType::U16)
        }
        _ => {
            dimensions == Dimensions::Scalar
                && matches!(data_type, DataType::U8 | DataType::U16 | DataType::U32)
        }
    };
    if !allowed {
        return Err(format!(
            "{dimensions:?} of {data_type:?} is not a type glTF allows here"
        ));
    }
    let count = accessor.count();
    if count == 0 {
        return Err("no elements".into());
    }
    let size = accessor.size();
    let within = |view: &::gltf::buffer::View, offset: usize, stride: usize, n: usize| {
        let end = stride
            .checked_mul(n - 1)
            .and_then(|b| b.checked_add(offset))
            .and_then(|b| b.checked_add(size));
        let view_end = view.offset().checked_add(view.length());
        let buffer = buffers.get(view.buffer().index()).map_or(0, Vec::len);
        match (end, view_end) {
            (Some(end), Some(view_end)) if end <= view.length() && view_end <= buffer => Ok(()),
            _ => Err(format!(
                "{n} elements of {size} bytes (stride {stride}, offset {offset}) do not fit in \
                 buffer view {} ({} bytes at {} of a {buffer}-byte buffer)",
                view.index(),
                view.length(),
                view.offset()
            )),
        }
    };
    if let Some(view) = accessor.view() {
        within(
            &view,
            accessor.offset(),
            view.stride().unwrap_or(size).max(size),
            count,
        )?;
    }
    if let Some(sparse) = accessor.sparse() {
        let n = sparse.count();
        if n == 0 {
            return Err("a sparse section with no elements".into());
        }
        let indices = sparse.indices();
        let index_size = indices.index_type().size();
        let view = indices.view();
        let end = index_size
            .checked_mul(n)
            .and_then(|b| b.checked_add(indices.offset()));
        if end.is_none_or(|end| end > view.length()) {
            return Err("its sparse indices do not fit in their buffer view".into());
        }
        let values = sparse.values();
        within(&values.view(), values.offset(), size, n)?;
    }
    Ok(())
}

/// One triangle-list primitive placed in the model, before it is sorted into leaves or bark.
struct Placed {
    label: String,
    material: Option<usize>,
    leaf: bool,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    uvs: Vec<Vec2>,
    indices: Vec<u32>,
    lo: Vec3,
    hi: Vec3,
}

impl Placed {
    fn area(&self) -> f32 {
        self.indices
            .chunks_exact(3)
            .map(|t| {
                let [a, b, c] = [0, 1, 2].map(|k| self.positions[t[k] as usize]);
                0.5 * (b - a).cross(c - a).length()
            })
            .filter(|a| a.is_finite())
            .sum()
    }
}

/// Per-vertex normals from the faces (for primitives without normals).
fn face_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    let mut normals = vec![Vec3::ZERO; positions.len()];
    for t in indices.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|k| positions[t[k] as usize]);
        let n = (b - a).cross(c - a);
        if n.is_finite() {
            for &i in t {
                normals[i as usize] += n;
            }
        }
    }
    normals
        .into_iter()
        .map(|n| n.normalize_or(Vec3::Y))
        .collect()
}

/// Reads a tree from glTF (`.gltf` with embedded or external buffers, or `.glb`) bytes.
/// `base_dir` resolves external buffer and image files.
pub fn load_gltf_tree(
    bytes: &[u8],
    base_dir: Option<&Path>,
    settings: &GltfLeafSettings,
) -> Result<GltfTree, GltfTreeError> {
    // The gltf crate's binary reader subtracts the header's size from the declared length
    // unchecked: a declared length shorter than the header is refused here.
    if bytes.len() >= 12 && bytes.starts_with(b"glTF") {
        let length = u32::from_le_bytes(bytes[8..12].try_into().unwrap());
        if length < 12 {
            return Err(GltfTreeError::Parse(format!(
                "binary glTF declares {length} bytes, less than its 12-byte header"
            )));
        }
    }
    // gltf-json's validation indexes some arrays unchecked (a POSITION accessor index past the
    // accessors panics in `primitive_validate_hook`): a panic there is a malformed file too.
    let gltf = std::panic::catch_unwind(|| ::gltf::Gltf::from_slice(bytes))
        .map_err(|panic| {
            let message = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            GltfTreeError::Parse(format!("malformed glTF (its validation failed: {message})"))
        })?
        .map_err(|e| GltfTreeError::Parse(e.to_string()))?;
    let document = gltf.document;
    let buffers = load_buffers(&document, gltf.blob, base_dir)?;
    let mut tree = GltfTree {
        materials: document
            .materials()
            .enumerate()
            .map(|(i, m)| read_material(i, &m))
            .collect(),
        images: vec![None; document.images().count()],
        ..Default::default()
    };

    // The nodes to read, with the transform of their parent.
    let roots: Vec<(::gltf::Node, Mat4)> = match &settings.node {
        Some(name) => {
            let node = document
                .nodes()
                .find(|n| n.name() == Some(name.as_str()))
                .ok_or_else(|| GltfTreeError::NoSuchNode {
                    name: name.clone(),
                    nodes: document
                        .nodes()
                        .filter_map(|n| n.name().map(str::to_string))
                        .collect(),
                })?;
            vec![(node, Mat4::IDENTITY)]
        }
        None => {
            let scene = document
                .default_scene()
                .or_else(|| document.scenes().next());
            match scene {
                Some(scene) => scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect(),
                None => document
                    .nodes()
                    .filter(|n| {
                        !document
                            .nodes()
                            .any(|p| p.children().any(|c| c.index() == n.index()))
                    })
                    .map(|n| (n, Mat4::IDENTITY))
                    .collect(),
            }
        }
    };

    // Place every triangle-list primitive.
    let mut placed: Vec<Placed> = Vec::new();
    let mut visited = vec![false; document.nodes().count()];
    let mut stack = roots;
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut visited[node.index()], true) {
            return Err(GltfTreeError::Invalid(format!(
                "node {} ('{}') is reached twice: the node hierarchy has a cycle or a shared child",
                node.index(),
                node.name().unwrap_or("")
            )));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        for child in node.children() {
            stack.push((child, world));
        }
        let Some(mesh) = node.mesh() else { continue };
        let normal_matrix = world.inverse().transpose();
        for primitive in mesh.primitives() {
            let label = format!(
                "mesh '{}' (node '{}') primitive {}",
                mesh.name().unwrap_or("<unnamed>"),
                node.name().unwrap_or("<unnamed>"),
                primitive.index()
            );
            if primitive.mode() != ::gltf::mesh::Mode::Triangles {
                tree.ignored_primitives += 1;
                continue;
            }
            let material = primitive.material();
            let leaf = if settings.leaf_materials.is_empty() {
                material.alpha_mode() != ::gltf::material::AlphaMode::Opaque
                    || is_leafy(material.name())
                    || is_leafy(mesh.name())
                    || is_leafy(node.name())
            } else {
                material
                    .name()
                    .is_some_and(|n| settings.leaf_materials.iter().any(|l| l == n))
            };
            // The gltf crate's readers assume well-formed accessors (an empty one underflows
            // its range arithmetic): check the ones read here first.
            let attributes = [
                ("POSITION", primitive.get(&::gltf::Semantic::Positions)),
                ("NORMAL", primitive.get(&::gltf::Semantic::Normals)),
                ("TEXCOORD_0", primitive.get(&::gltf::Semantic::TexCoords(0))),
                ("indices", primitive.indices()),
            ];
            for (what, accessor) in attributes {
                if let Some(accessor) = accessor {
                    check_accessor(what, &accessor, &buffers).map_err(|problem| {
                        GltfTreeError::Invalid(format!(
                            "{label}: {what} accessor {}: {problem}",
                            accessor.index()
                        ))
                    })?;
                }
            }
            let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
            let Some(positions) = reader.read_positions() else {
                continue;
            };
            let positions: Vec<Vec3> = positions
                .map(|p| world.transform_point3(Vec3::from_array(p)))
                .collect();
            let n = positions.len();
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..n as u32).collect(),
            };
            if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
                return Err(GltfTreeError::Invalid(format!(
                    "{label}: index {bad} out of range ({n} vertices)"
                )));
            }
            if !indices.len().is_multiple_of(3) {
                return Err(GltfTreeError::Invalid(format!(
                    "{label}: {} indices is not a whole number of triangles",
                    indices.len()
                )));
            }
            let normals: Vec<Vec3> = match reader.read_normals() {
                Some(normals) => normals
                    .map(|v| {
                        normal_matrix
                            .transform_vector3(Vec3::from_array(v))
                            .normalize_or(Vec3::Y)
                    })
                    .collect(),
                None => face_normals(&positions, &indices),
            };
            let uvs: Vec<Vec2> = match reader.read_tex_coords(0) {
                Some(t) => t.into_f32().map(Vec2::from_array).collect(),
                None => vec![Vec2::ZERO; n],
            };
            for (what, len) in [("NORMAL", normals.len()), ("TEXCOORD_0", uvs.len())] {
                if len != n {
                    return Err(GltfTreeError::Invalid(format!(
                        "{label}: {what} has {len} entries, POSITION has {n}"
                    )));
                }
            }
            let (lo, hi) =
                indices
                    .iter()
                    .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &i| {
                        let p = positions[i as usize];
                        if p.is_finite() {
                            (lo.min(p), hi.max(p))
                        } else {
                            (lo, hi)
                        }
                    });
            placed.push(Placed {
                label,
                material: material.index(),
                leaf,
                positions,
                normals,
                uvs,
                indices,
                lo,
                hi,
            });
        }
    }

    let foliage: Vec<usize> = (0..placed.len())
        .filter(|&i| placed[i].leaf && placed[i].lo.is_finite())
        .collect();
    if foliage.is_empty() {
        return Err(GltfTreeError::NoLeaves {
            materials: tree.materials.iter().map(|m| m.name.clone()).collect(),
        });
    }

    // Which primitives are the tree.
    let keep: Vec<bool> = if settings.node.is_some() {
        vec![true; placed.len()]
    } else {
        select_tree(&placed, &foliage, &mut tree.notes)
    };

    // Leaves by material, bark by material.
    for (p, _) in placed.iter().zip(&keep).filter(|(_, k)| **k) {
        if p.leaf {
            let group = match tree
                .leaf_groups
                .iter()
                .position(|g| g.material == p.material)
            {
                Some(g) => g,
                None => {
                    tree.leaf_groups.push(LeafGroup {
                        material: p.material,
                        ..Default::default()
                    });
                    tree.leaf_groups.len() - 1
                }
            };
            let cut = append_leaves(&mut tree.leaf_groups[group].leaves, p, settings);
            tree.leaf_groups[group].clusters_cut += cut;
        } else {
            let part = match tree.bark.iter().position(|b| b.material == p.material) {
                Some(b) => b,
                None => {
                    tree.bark.push(BarkPart {
                        material: p.material,
                        ..Default::default()
                    });
                    tree.bark.len() - 1
                }
            };
            let mesh = &mut tree.bark[part].mesh;
            let base = mesh.positions.len() as u32;
            mesh.positions.extend(&p.positions);
            mesh.normals.extend(&p.normals);
            mesh.uvs.extend(&p.uvs);
            mesh.indices.extend(p.indices.iter().map(|i| i + base));
        }
    }
    for group in &tree.leaf_groups {
        if group.clusters_cut > 0 {
            tree.notes.push(format!(
                "{} welded leaf clusters of material '{}' (more than {} triangles each) were cut into leaves of about {} triangles",
                group.clusters_cut,
                group
                    .material
                    .and_then(|m| tree.materials.get(m))
                    .map_or("<none>", |m| m.name.as_str()),
                settings.max_leaf_triangles,
                settings.cluster_leaf_triangles
            ));
        }
    }

    // Decode the images the tree's materials use.
    let used: Vec<usize> = tree
        .leaf_groups
        .iter()
        .map(|g| g.material)
        .chain(tree.bark.iter().map(|b| b.material))
        .flatten()
        .collect();
    for m in used {
        let Some(material) = tree.materials.get(m).cloned() else {
            continue;
        };
        for texture in [
            material.base_color_texture,
            material.normal_texture,
            material.metallic_roughness_texture,
        ]
        .into_iter()
        .flatten()
        {
            if tree.images[texture.image].is_some() {
                continue;
            }
            let Some(image) = document.images().nth(texture.image) else {
                continue;
            };
            match decode_image(&document, &image, &buffers, base_dir) {
                Ok(decoded) => tree.images[texture.image] = Some(decoded),
                Err(e) => tree.notes.push(format!(
                    "image {} ('{}') of material '{}' could not be decoded ({e}); the material is drawn without it",
                    texture.image,
                    image.name().unwrap_or(""),
                    material.name
                )),
            }
        }
    }
    Ok(tree)
}

/// The automatic choice of the tree's primitives (module docs): returns, per primitive, whether
/// it is part of the tree, and notes what is left out.
fn select_tree(placed: &[Placed], foliage: &[usize], notes: &mut Vec<String>) -> Vec<bool> {
    // 1. Foliage groups by overlap of grown bounding boxes (union–find).
    let grown = |i: usize| {
        let p = &placed[i];
        let g = (p.hi - p.lo) * 0.1;
        (p.lo - g, p.hi + g)
    };
    let mut group: Vec<usize> = (0..foliage.len()).collect();
    fn root(group: &mut [usize], mut i: usize) -> usize {
        while group[i] != i {
            group[i] = group[group[i]];
            i = group[i];
        }
        i
    }
    for a in 0..foliage.len() {
        for b in a + 1..foliage.len() {
            let ((alo, ahi), (blo, bhi)) = (grown(foliage[a]), grown(foliage[b]));
            if alo.cmple(bhi).all() && blo.cmple(ahi).all() {
                let (ra, rb) = (root(&mut group, a), root(&mut group, b));
                group[rb] = ra;
            }
        }
    }
    let mut area_of: HashMap<usize, f32> = HashMap::new();
    for k in 0..foliage.len() {
        let r = root(&mut group, k);
        *area_of.entry(r).or_default() += placed[foliage[k]].area();
    }
    let crown_root = *area_of
        .iter()
        .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(a.0)))
        .map(|(r, _)| r)
        .unwrap();
    let in_crown: Vec<bool> = (0..foliage.len())
        .map(|k| root(&mut group, k) == crown_root)
        .collect();
    let (lo, hi) = foliage
        .iter()
        .zip(&in_crown)
        .filter(|(_, c)| **c)
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), (&i, _)| {
            (lo.min(placed[i].lo), hi.max(placed[i].hi))
        });
    // 2. The crown's column.
    let margin = (hi - lo) * 0.25;
    let column_lo = Vec3::new(lo.x - margin.x, f32::NEG_INFINITY, lo.z - margin.z);
    let column_hi = Vec3::new(hi.x + margin.x, hi.y + margin.y, hi.z + margin.z);
    let mut keep = vec![false; placed.len()];
    for (k, &i) in foliage.iter().enumerate() {
        keep[i] = in_crown[k];
    }
    for (i, p) in placed.iter().enumerate() {
        if !p.leaf {
            keep[i] =
                p.lo.is_finite() && p.lo.cmpge(column_lo).all() && p.hi.cmple(column_hi).all();
        }
        if !keep[i] {
            notes.push(format!(
                "{} ({}) is not part of the tree and was left out: {}",
                p.label,
                if p.leaf { "foliage" } else { "not foliage" },
                if p.leaf {
                    "it belongs to a smaller group of foliage away from the largest crown"
                } else {
                    "it reaches outside the crown's column"
                }
            ));
        }
    }
    keep
}

/// Splits one foliage primitive into leaves (connected components, welded clusters cut) and
/// appends them, each with its own copy of its vertices. Returns the clusters cut.
fn append_leaves(set: &mut LeafSet, p: &Placed, settings: &GltfLeafSettings) -> usize {
    let components = triangle_components(&p.indices);
    let count = components
        .iter()
        .copied()
        .max()
        .map_or(0, |m| m as usize + 1);
    let mut triangles_of: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (t, &c) in components.iter().enumerate() {
        triangles_of[c as usize].push(t);
    }
    let mut cut = 0;
    let mut pieces: Vec<Vec<usize>> = Vec::with_capacity(count);
    for triangles in triangles_of {
        if triangles.len() > settings.max_leaf_triangles.max(1) {
            cut += 1;
            pieces.extend(cut_cluster(
                &p.indices,
                &triangles,
                &p.positions,
                settings.cluster_leaf_triangles,
            ));
        } else {
            pieces.push(triangles);
        }
    }
    let mut remap: Vec<u32> = vec![u32::MAX; p.positions.len()];
    for triangles in pieces {
        let start = set.indices.len() as u32;
        let mut touched = Vec::new();
        for t in triangles {
            for &v in &p.indices[t * 3..t * 3 + 3] {
                let v = v as usize;
                if remap[v] == u32::MAX {
                    remap[v] = set.positions.len() as u32;
                    set.positions.push(p.positions[v]);
                    set.normals.push(p.normals[v]);
                    set.uvs.push(p.uvs[v]);
                    touched.push(v);
                }
                set.indices.push(remap[v]);
            }
        }
        // The next leaf gets its own copies of shared vertices.
        for v in touched {
            remap[v] = u32::MAX;
        }
        set.leaves.push(start..set.indices.len() as u32);
    }
    cut
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::corpus::{
        AlphaModeDesc, GltfBuilder, MaterialDesc, NodeDesc, PrimitiveDesc, frond_tree,
    };
    use crate::pruning::bake::{BakeSettings, CellCount, bake};

    fn primitive(material: usize, positions: Vec<[f32; 3]>, indices: Vec<u32>) -> PrimitiveDesc {
        PrimitiveDesc {
            material: Some(material),
            positions: positions.into_iter().map(Vec3::from_array).collect(),
            indices,
            ..Default::default()
        }
    }

    /// Bark: one triangle. Leaves (alpha-masked material): a quad, a 3-triangle fan, a single
    /// triangle, a degenerate (collinear) leaf and a leaf with a NaN vertex. One node per
    /// primitive, translated by (5, 1, 0).
    pub(crate) fn sample_tree() -> String {
        let mut b = GltfBuilder::new();
        let bark = b.material(&MaterialDesc::opaque("Bark", [0.3, 0.2, 0.1, 1.0]));
        let needles = b.material(&MaterialDesc {
            alpha: AlphaModeDesc::Mask(0.5),
            ..MaterialDesc::opaque("Needles", [0.2, 0.5, 0.1, 1.0])
        });
        let trunk = primitive(
            bark,
            vec![[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.1, 2.0, 0.0]],
            vec![0, 1, 2],
        );
        let leaves = primitive(
            needles,
            vec![
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
            vec![
                0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7, 4, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17,
            ],
        );
        for (name, prim) in [("trunk", trunk), ("needles", leaves)] {
            let mesh = b.mesh(name, &[prim]);
            let node = b.node(&NodeDesc {
                translation: Vec3::new(5.0, 1.0, 0.0),
                ..NodeDesc::mesh(name, mesh)
            });
            b.root(node);
        }
        b.to_json()
    }

    fn read(json: &str, settings: &GltfLeafSettings) -> Result<GltfTree, GltfTreeError> {
        load_gltf_tree(json.as_bytes(), None, settings)
    }

    #[test]
    fn leaves_are_connected_components_of_the_masked_material() {
        let tree = read(&sample_tree(), &GltfLeafSettings::default()).unwrap();
        assert_eq!(
            tree.materials
                .iter()
                .map(|m| m.name.as_str())
                .collect::<Vec<_>>(),
            vec!["Bark", "Needles"]
        );
        assert_eq!(tree.bark.len(), 1);
        assert_eq!(tree.bark[0].mesh.indices.len(), 3);
        assert_eq!(tree.leaf_groups.len(), 1);
        let leaves = &tree.leaf_groups[0].leaves;
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
        // Missing normals are computed from the faces (the sample lies in the z = 0 plane).
        assert!(leaves.normals[0].z.abs() > 0.99);
        // The bake drops and counts the bad leaves.
        let settings = BakeSettings {
            cells: CellCount::Depth(1),
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
            ..Default::default()
        };
        let tree = read(&sample_tree(), &settings).unwrap();
        assert_eq!(
            tree.leaves().len(),
            1,
            "the bark triangle is now the only leaf"
        );
        // The needles, now bark, reach far outside that one-triangle "crown": left out, noted.
        assert!(tree.bark.is_empty());
        assert!(tree.notes[0].contains("needles"), "{:?}", tree.notes);
    }

    #[test]
    fn no_leaves_is_an_error_listing_the_materials() {
        let mut b = GltfBuilder::new();
        let bark = b.material(&MaterialDesc::opaque("Bark", [1.0; 4]));
        let wood = b.material(&MaterialDesc::opaque("Wood", [1.0; 4]));
        for (name, m) in [("trunk", bark), ("branch", wood)] {
            let mesh = b.mesh(
                name,
                &[primitive(
                    m,
                    vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                    vec![0, 1, 2],
                )],
            );
            let node = b.node(&NodeDesc::mesh(name, mesh));
            b.root(node);
        }
        let err = read(&b.to_json(), &GltfLeafSettings::default()).unwrap_err();
        assert_eq!(
            err,
            GltfTreeError::NoLeaves {
                materials: vec!["Bark".into(), "Wood".into()]
            }
        );
        assert!(err.to_string().contains("[Bark, Wood]"), "{err}");
    }

    #[test]
    fn malformed_files_are_errors() {
        let err = read("{ not json", &GltfLeafSettings::default()).unwrap_err();
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
        // A normal accessor shorter than POSITION: an error naming the primitive.
        let mut b = GltfBuilder::new();
        let leaf = b.material(&MaterialDesc::opaque("Leaf", [1.0; 4]));
        let mut p = primitive(
            leaf,
            vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![0, 1, 2],
        );
        p.normals = vec![Vec3::Y; 2];
        let mesh = b.mesh("twig", &[p]);
        let node = b.node(&NodeDesc::mesh("twig", mesh));
        b.root(node);
        let err = read(&b.to_json(), &GltfLeafSettings::default()).unwrap_err();
        let text = err.to_string();
        assert!(
            matches!(err, GltfTreeError::Invalid(_))
                && text.contains("twig")
                && text.contains("NORMAL"),
            "{text}"
        );
        // A missing named node lists the nodes.
        let err = read(
            &sample_tree(),
            &GltfLeafSettings {
                node: Some("oak".into()),
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(err.to_string().contains("[trunk, needles]"), "{err}");
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

    #[test]
    fn welded_fronds_are_cut_into_leaves_from_base_to_tip() {
        // A strip of 40 quads along x, all welded.
        let mut positions = Vec::new();
        for i in 0..=40 {
            positions.push(Vec3::new(i as f32, 0.0, 0.0));
            positions.push(Vec3::new(i as f32, 0.0, 1.0));
        }
        let mut indices = Vec::new();
        for i in 0..40u32 {
            let a = 2 * i;
            indices.extend_from_slice(&[a, a + 1, a + 3, a, a + 3, a + 2]);
        }
        let triangles: Vec<usize> = (0..80).collect();
        let pieces = cut_cluster(&indices, &triangles, &positions, 8);
        assert_eq!(pieces.len(), 10);
        let mut all: Vec<usize> = pieces.concat();
        all.sort();
        assert_eq!(all, triangles, "every triangle in exactly one piece");
        // Pieces are compact and ordered along the strip.
        let centre = |piece: &Vec<usize>| {
            piece
                .iter()
                .map(|&t| positions[indices[3 * t] as usize].x)
                .sum::<f32>()
                / piece.len() as f32
        };
        for w in pieces.windows(2) {
            assert!(centre(&w[1]) > centre(&w[0]));
        }
        for p in &pieces {
            let xs: Vec<f32> = p
                .iter()
                .map(|&t| positions[indices[3 * t] as usize].x)
                .collect();
            let span = xs.iter().cloned().fold(f32::MIN, f32::max)
                - xs.iter().cloned().fold(f32::MAX, f32::min);
            assert!(span <= 5.0, "piece spans {span} quads");
        }
    }

    #[test]
    fn the_largest_tree_is_read_and_the_island_and_sea_left_out() {
        let tree = read(&frond_tree().gltf, &GltfLeafSettings::default()).unwrap();
        // Fronds (detected by the name "Leaves") cut into leaves; the trunk is bark.
        assert_eq!(tree.leaf_groups.len(), 1);
        let fronds = &tree.leaf_groups[0];
        assert_eq!(fronds.clusters_cut, crate::corpus::FRONDS);
        let per_frond = 6 * crate::corpus::FROND_SEGMENTS;
        let pieces = fronds.leaves.len();
        assert!(
            (crate::corpus::FRONDS * per_frond / 12..=crate::corpus::FRONDS * per_frond / 6)
                .contains(&pieces),
            "{pieces} leaves cut from {} fronds of {per_frond} triangles",
            crate::corpus::FRONDS
        );
        for leaf in &fronds.leaves.leaves {
            let triangles = (leaf.end - leaf.start) / 3;
            assert!(
                (4..=16).contains(&triangles),
                "a piece of {triangles} triangles"
            );
        }
        assert_eq!(tree.bark.len(), 1);
        assert_eq!(tree.materials[tree.bark[0].material.unwrap()].name, "Trunk");
        let notes = tree.notes.join("\n");
        assert!(
            notes.contains("Landscape'") && notes.contains("Landscape_plane"),
            "{notes}"
        );
        assert!(notes.contains("cut into leaves"), "{notes}");
        // Naming the trunk's node reads only it: no leaves there.
        let err = read(
            &frond_tree().gltf,
            &GltfLeafSettings {
                node: Some("Trunk".into()),
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(matches!(err, GltfTreeError::NoLeaves { .. }));
        // Naming one frond reads it alone.
        let one = read(
            &frond_tree().gltf,
            &GltfLeafSettings {
                node: Some("Frond.003".into()),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(one.leaves().len(), pieces / crate::corpus::FRONDS);
        assert!(one.bark.is_empty());
    }

    #[test]
    fn a_second_tree_beside_the_first_is_left_out() {
        let mut b = GltfBuilder::new();
        let leaf = b.material(&MaterialDesc {
            alpha: AlphaModeDesc::Mask(0.5),
            ..MaterialDesc::opaque("Leaf", [1.0; 4])
        });
        let bark = b.material(&MaterialDesc::opaque("Bark", [1.0; 4]));
        for (name, x, leaves) in [("big", 0.0f32, 30u32), ("small", 20.0, 5)] {
            let mut p = PrimitiveDesc {
                material: Some(leaf),
                ..Default::default()
            };
            for i in 0..leaves {
                let c = Vec3::new(
                    x + (i % 5) as f32 * 0.8 - 2.0,
                    5.0 + (i / 5) as f32 * 0.5,
                    0.0,
                );
                let base = p.positions.len() as u32;
                p.positions.extend([
                    c,
                    c + Vec3::X * 0.3,
                    c + Vec3::new(0.3, 0.3, 0.0),
                    c + Vec3::Y * 0.3,
                ]);
                p.indices
                    .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
            }
            let trunk = primitive(
                bark,
                vec![[x - 0.2, 0.0, 0.0], [x + 0.2, 0.0, 0.0], [x, 5.0, 0.0]],
                vec![0, 1, 2],
            );
            let mesh = b.mesh(name, &[p, trunk]);
            let node = b.node(&NodeDesc::mesh(name, mesh));
            b.root(node);
        }
        let tree = read(&b.to_json(), &GltfLeafSettings::default()).unwrap();
        assert_eq!(tree.leaves().len(), 30, "the larger crown");
        assert_eq!(tree.bark[0].mesh.indices.len(), 3, "its own trunk only");
        assert_eq!(tree.notes.len(), 2, "{:?}", tree.notes);
    }

    #[test]
    fn materials_textures_and_the_leaf_mask_come_from_the_file() {
        let tree = read(
            &crate::corpus::alpha_card_tree().gltf,
            &GltfLeafSettings::default(),
        )
        .unwrap();
        let group = &tree.leaf_groups[0];
        let material = tree.material_of(group).unwrap();
        assert_eq!(material.name, "Leaf");
        assert_eq!(material.alpha, GltfAlpha::Mask(0.5));
        assert!(material.double_sided);
        let texture = material.base_color_texture.unwrap();
        let image = tree.images[texture.image].as_ref().unwrap();
        assert_eq!((image.width, image.height), (64, 64));
        let mask = tree.leaf_mask(group).unwrap();
        let f = mask.opaque_fraction_of(&group.leaves).unwrap();
        assert!(
            (0.15..0.25).contains(&f),
            "cluster cards are a fifth opaque: {f}"
        );
        let bark = &tree.materials[tree.bark[0].material.unwrap()];
        assert_eq!(
            (bark.name.as_str(), bark.alpha),
            ("Bark", GltfAlpha::Opaque)
        );
        // An undecodable image is noted, not fatal.
        let broken = crate::corpus::alpha_card_tree()
            .gltf
            .replace("data:image/png;base64,", "data:image/png;base64,AAAA");
        let tree = read(&broken, &GltfLeafSettings::default()).unwrap();
        assert!(tree.images.iter().all(Option::is_none));
        assert!(
            tree.notes
                .iter()
                .any(|n| n.contains("could not be decoded")),
            "{:?}",
            tree.notes
        );
        assert!(tree.leaf_mask(&tree.leaf_groups[0]).is_none());
    }
}
