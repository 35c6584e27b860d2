// Vertex pulling for pruned leaves, shared by the forward and prepass vertex shaders.
//
// A pruned tree is drawn as a "slot mesh" whose vertex i carries i in position.x. Vertex i of
// the tree is the i-th index the pruning pass wrote into this instance's region of `output`
// (quad slot meshes: four vertices per leaf, see below); vertices past this frame's kept count
// collapse outside the clip volume (culled before rasterisation). The instance is found through
// its MeshTag (its slot, bit 31 set for quad slot meshes).
//
// Area preservation (Gumbau 2011, eq. 3.7-3.10): a kept leaf of a cell asked to keep the
// fraction u = LoD(cell) of its leaves is scaled about its centroid by sqrt(1/u), so the cells'
// total leaf area, and with it the statistical coverage of the crown (Cook & Halstead 2007), is
// preserved; the scale is capped (`max_scale`).
//
// Sub-pixel fade (§3.4): as the leaf's projected diameter falls from `fade_start` to `fade_end`
// pixels, its texture coordinates converge on its centre texel (one opaque colour instead of a
// mask averaging away in coarse mips) and it shrinks to its texture's opaque area. The CPU
// reference of these formulas is `bevy_foliage::pruning::appearance`.
#define_import_path bevy_foliage::leaf_pulling

#import bevy_pbr::{mesh_functions, mesh_view_bindings::view, view_transformations::position_world_to_clip}
#import bevy_foliage::pruning_types::{Instance, LeafVertex}
#import bevy_foliage::tree_lighting::TreeLightUniform

// The slot mesh's vertex: only its index (in position.x) and the instance are used.
struct SlotVertex {
    @builtin(instance_index) instance_index: u32,
    @location(0) position: vec3<f32>,
}

struct LeafParams {
    // 1: enlarge kept leaves to preserve area.
    area_compensation: u32,
    // 1: fade sub-pixel leaves to a solid colour.
    subpixel_fade: u32,
    // Cap of the linear area-compensation scale.
    max_scale: f32,
    // Opaque fraction of the leaf texture (1 for untextured leaves).
    opaque_fraction: f32,
    // Projected diameters (pixels) where the fade starts and where leaves are fully solid.
    fade_start: f32,
    fade_end: f32,
    // 1: the bounce on each leaf face scaled by the leaf's gathered ratios.
    gathered_bounce: u32,
    // 1: those ratios from the type's ring re-gathered at the sun's elevation, where the sun is
    // at it (`lighting::bounce_ring`).
    bounce_ring: u32,
    // The tree lighting (`lighting::settings::TreeLightingSettings`, `tree_lighting.wgsl`): on,
    // the sun through the crown by eq. 5.7's envelope blend (else the attenuations' blend), the
    // bounce on, the seen-part gains on.
    tree_lighting: u32,
    smooth_envelope: u32,
    bounce: u32,
    seen_part: u32,
    // The leaves' optics and the scene's lights.
    lights: TreeLightUniform,
    // The material's base colour (linear rgb): the optics are multiples of it.
    albedo: vec4<f32>,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var<storage, read> instances: array<Instance>;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var<storage, read> output: array<u32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(102) var<storage, read> draws: array<u32>;
// Per (instance, cell): kept index count, output offset, LoD(cell), 0.
@group(#{MATERIAL_BIND_GROUP}) @binding(103) var<storage, read> cell_offsets: array<vec4<u32>>;
@group(#{MATERIAL_BIND_GROUP}) @binding(104) var<storage, read> leaf_vertices: array<LeafVertex>;
// Per leaf, seven vec4s: its eight attenuations then its eight seen-part gains, as u16 pairs; its
// 28 bounce ratios as bytes and its type's ring's sun height (f32 bits); its 28 ring ratios as
// bytes and a word of padding; its 14 sunlit shares on the ring as bytes, a byte 1 where the
// ring has them, one of padding (`store::LEAF_LIGHT_WORDS`).
@group(#{MATERIAL_BIND_GROUP}) @binding(105) var<storage, read> leaf_light: array<vec4<u32>>;
@group(#{MATERIAL_BIND_GROUP}) @binding(106) var<uniform> leaf_params: LeafParams;

struct PulledLeafVertex {
    kept: bool,
    local_position: vec3<f32>,
    local_normal: vec3<f32>,
    uv: vec2<f32>,
    world_position: vec4<f32>,
    clip_position: vec4<f32>,
    world_normal: vec3<f32>,
    // The vertex's leaf in `leaf_light`, and its crown's extinction τ per unit of model space.
    leaf: u32,
    extinction: f32,
    // The crown's bounding sphere in model space (centre, radius).
    crown_sphere: vec4<f32>,
    // The crown's hotspot, packed (`Instance::hotspot`).
    hotspot: vec4<u32>,
    // The largest distance of the leaf's corners from its centre, in model space.
    leaf_radius: f32,
    // The vertex's offset from its leaf's centroid as stored, before any area compensation
    // (model space): where on the leaf the vertex is.
    offset: vec3<f32>,
}

// Pulls the vertex and places it in the world; `clip_position` is CULLED for dropped vertices.
fn pull_leaf_vertex(instance_index: u32, slot_position: vec3<f32>) -> PulledLeafVertex {
    var out: PulledLeafVertex;
    let tag = mesh_functions::get_tag(instance_index);
    var slot = tag & 0x7fffffffu;
    // Shadow views draw the light's selection (`selection.rs`). A shadow map's view is not the
    // camera it resolves LoD for: Bevy sets `lod_view_world_position` to the camera's position
    // for shadow views and to the view's own for camera views.
    if any(view.world_position != view.lod_view_world_position) {
        slot = instances[slot].shadow_slot;
    }
    let vertex = u32(slot_position.x);
    // Quad slot meshes (tag bit 31): vertex 4k + c is corner c of kept leaf k, whose six kept
    // indices are a b c a c d; its index is 6k + [0, 1, 2, 5][c].
    var i = vertex;
    if (tag >> 31u) != 0u {
        let corner = vertex % 4u;
        i = (vertex / 4u) * 6u + select(corner, 5u, corner == 3u);
    }
    let kept_count = draws[slot * 5u];
    out.kept = i < kept_count;
    if !out.kept {
        out.clip_position = CULLED;
        return out;
    }
    let inst = instances[slot];
    let v = leaf_vertices[output[inst.output_base + i]];
    var scale = 1.0;
    if leaf_params.area_compensation != 0u {
        // Area scale s = 1/u (eq. 3.9) with u = LoD(cell), the fraction of the cell's leaves
        // eq. 3.5 asks for; linear scale sqrt(s), capped.
        let lod = cell_offsets[inst.cell_offsets_base + v.cell].z;
        scale = min(sqrt(65536.0 / f32(max(lod, 1u))), leaf_params.max_scale);
    }
    let centroid = v.position - v.offset;
    let world_from_local = mesh_functions::get_world_from_local(instance_index);
    out.uv = v.uv;
    if leaf_params.subpixel_fade != 0u {
        // Projected diameter of the (compensated) leaf, in pixels of this view's target.
        let centroid_world = mesh_functions::mesh_position_local_to_world(world_from_local, vec4<f32>(centroid, 1.0));
        let w = position_world_to_clip(centroid_world.xyz).w;
        let instance_scale = (length(world_from_local[0].xyz) + length(world_from_local[1].xyz) + length(world_from_local[2].xyz)) / 3.0;
        let pixels = v.leaf_radius * scale * instance_scale * view.clip_from_view[1][1] / max(w, 1e-6) * view.viewport.w;
        let fade = clamp((leaf_params.fade_start - pixels) / max(leaf_params.fade_start - leaf_params.fade_end, 1e-6), 0.0, 1.0);
        out.uv = mix(v.uv, v.uv_centre, fade);
        // Keep the opaque area: the converging texture window is opaque over o + f(1 - o).
        let o = clamp(leaf_params.opaque_fraction, 1e-3, 1.0);
        scale = scale * sqrt(o / (o + fade * (1.0 - o)));
    }
    out.local_position = centroid + v.offset * scale;
    out.local_normal = v.normal;
    out.leaf = v.leaf;
    out.extinction = bitcast<f32>(inst.extinction_bits);
    out.crown_sphere = bitcast<vec4<f32>>(inst.crown_sphere_bits);
    out.hotspot = inst.hotspot;
    out.leaf_radius = v.leaf_radius;
    out.offset = v.offset;
    out.world_position = mesh_functions::mesh_position_local_to_world(world_from_local, vec4<f32>(out.local_position, 1.0));
    out.clip_position = position_world_to_clip(out.world_position.xyz);
    out.world_normal = mesh_functions::mesh_normal_local_to_world(out.local_normal, instance_index);
    return out;
}

// A clip position outside the view volume: triangles made of it are culled.
const CULLED: vec4<f32> = vec4<f32>(2.0, 2.0, 2.0, 1.0);

// Eight stored u16s as fractions of 65,535.
fn unpack_eight(words: vec4<u32>) -> array<f32, 8> {
    var a: array<f32, 8>;
    for (var k = 0u; k < 4u; k += 1u) {
        a[2u * k] = f32(words[k] & 0xffffu) / 65535.0;
        a[2u * k + 1u] = f32(words[k] >> 16u) / 65535.0;
    }
    return a;
}

// The eight attenuations of leaf `leaf` (`lighting::bins::light_of` of the stored u16s).
fn leaf_attenuation(leaf: u32) -> array<f32, 8> {
    return unpack_eight(leaf_light[LEAF_LIGHT_VECS * leaf]);
}

// The eight seen-part gains of leaf `leaf` (`lighting::seen_part::gain_of` of the stored u16s).
fn leaf_seen_gains(leaf: u32) -> array<f32, 8> {
    var g = unpack_eight(leaf_light[LEAF_LIGHT_VECS * leaf + 1u]);
    for (var j = 0u; j < 8u; j += 1u) {
        g[j] *= SEEN_GAIN_MAX;
    }
    return g;
}

// The residual gains of leaf `leaf`'s open map, as the seen-part gains are stored
// (`lighting::open_map::LeafOpenMap::residual_gains`).
fn leaf_open_residual(leaf: u32) -> array<f32, 8> {
    var g = unpack_eight(leaf_light[LEAF_LIGHT_VECS * leaf + 10u]);
    for (var j = 0u; j < 8u; j += 1u) {
        g[j] *= SEEN_GAIN_MAX;
    }
    return g;
}

// Leaf `leaf`'s open map as stored: nine cell codes a byte each (cells 0–3 in x, 4–7 in y,
// 8 in z's low byte), then its grid's two axes two bytes each (z's upper three bytes, w's low
// byte; `lighting::open_map::LeafOpenMap::words`). All cells 0: no map.
fn leaf_open_map(leaf: u32) -> vec4<u32> {
    return leaf_light[LEAF_LIGHT_VECS * leaf + 11u];
}

// The largest gain a bake stores (`lighting::seen_part::GAIN_RANGE`).
const SEEN_GAIN_MAX: f32 = 4.0;

// vec4s per leaf in `leaf_light` (`store::LEAF_LIGHT_WORDS` / 4).
const LEAF_LIGHT_VECS: u32 = 12u;

// 28 ratios stored a byte each in two vec4s (the last word not read): code 0 is 0, codes 1–255
// the ratio's base-2 logarithm from −4 to 4 (`lighting::gathered_bounce::ratio_of`).
fn unpack_ratios(stored: array<vec4<u32>, 2>) -> array<f32, 28> {
    var words = stored;
    var r: array<f32, 28>;
    for (var i = 0u; i < 28u; i += 1u) {
        let q = (words[i / 16u][(i / 4u) % 4u] >> (8u * (i % 4u))) & 0xffu;
        r[i] = select(0.0, exp2(f32(q - 1u) / 254.0 * 8.0 - 4.0), q != 0u);
    }
    return r;
}

// The bounce ratios of leaf `leaf`, the front face's fourteen then the back face's
// (`lighting::gathered_bounce::BounceRatios::from_stored`).
fn leaf_bounce_ratios(leaf: u32) -> array<f32, 28> {
    return unpack_ratios(array<vec4<u32>, 2>(
        leaf_light[LEAF_LIGHT_VECS * leaf + 2u], leaf_light[LEAF_LIGHT_VECS * leaf + 3u]));
}

// The sun height (sine of the elevation, model space) of the ring of ratios of leaf `leaf`'s
// type; outside [−1, 1] for none (`lighting::bounce_ring::NO_RING`).
fn leaf_ring_height(leaf: u32) -> f32 {
    return bitcast<f32>(leaf_light[LEAF_LIGHT_VECS * leaf + 3u].w);
}

// The ring ratios of leaf `leaf`: node k's front face at k, its back face at 14 + k
// (`lighting::bounce_ring::ring_nodes_of`).
fn leaf_ring_ratios(leaf: u32) -> array<f32, 28> {
    return unpack_ratios(array<vec4<u32>, 2>(
        leaf_light[LEAF_LIGHT_VECS * leaf + 4u], leaf_light[LEAF_LIGHT_VECS * leaf + 5u]));
}

// The ring's own hotspot on the sun for leaf `leaf`'s type, packed as `hotspot_at` reads it (a
// byte a node, nodes 0–3 then 4–7; `lighting::bounce_ring::BounceRing::sunlit_hotspot`): zero
// where the ring has none, the bake's then.
fn leaf_ring_hotspot(leaf: u32) -> vec2<u32> {
    return vec2(leaf_light[LEAF_LIGHT_VECS * leaf + 5u].w, leaf_light[LEAF_LIGHT_VECS * leaf + 9u].w);
}

// Whether leaf `leaf`'s type's ring holds its sunlit shares.
fn leaf_has_ring_shares(leaf: u32) -> bool {
    return ((leaf_light[LEAF_LIGHT_VECS * leaf + 6u].w >> 16u) & 0xffu) != 0u;
}

// The sunlit shares of leaf `leaf` on its type's ring, node k at k, read `across` from the
// leaf's centroid in units of its radius: each share in 255ths
// (`lighting::sunlit_share::share_of`) plus its slope across the leaf, three signed bytes a
// node (`slope_of`), along `across`; not clamped (`lighting::bounce_ring::ring_shares_at`).
fn leaf_ring_shares(leaf: u32, across: vec3<f32>) -> array<f32, 14> {
    let words = leaf_light[LEAF_LIGHT_VECS * leaf + 6u];
    var slopes = array<vec4<u32>, 3>(leaf_light[LEAF_LIGHT_VECS * leaf + 7u],
        leaf_light[LEAF_LIGHT_VECS * leaf + 8u], leaf_light[LEAF_LIGHT_VECS * leaf + 9u]);
    var s: array<f32, 14>;
    for (var k = 0u; k < 14u; k += 1u) {
        var slope: vec3<f32>;
        for (var c = 0u; c < 3u; c += 1u) {
            let b = 3u * k + c;
            // The byte as a signed one: moved to the top and shifted back arithmetically.
            let q = bitcast<i32>(((slopes[b / 16u][(b / 4u) % 4u] >> (8u * (b % 4u))) & 0xffu) << 24u) >> 24u;
            slope[c] = f32(q) * (SLOPE_RANGE / 127.0);
        }
        s[k] = f32((words[k / 4u] >> (8u * (k % 4u))) & 0xffu) / 255.0 + dot(slope, across);
    }
    return s;
}

// The largest stored slope of a sunlit share across a leaf
// (`lighting::sunlit_share::SLOPE_RANGE`).
const SLOPE_RANGE: f32 = 2.0;
