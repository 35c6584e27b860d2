// The terrain's heights from a height clip stack, for the vertex stage (paper 4 fetches heights
// in the vertex shader). CPU reference: `geometry::relief` (`height_level`, `height_at`,
// `normal_at`).
//
// Positions are points of the patch lattice (`geometry::patch::PatchGrid`): the tile meshes are
// placed in lattice steps relative to an anchor lattice point near the camera, so a vertex's
// lattice point and its level texel coordinates are exact in f32 (the lattice side is a power of
// two below 2^24), and its render-space position is the anchor's (computed in f64 on the CPU)
// plus a short offset — exact enough 10^6 m from the world's origin, and a function of the
// lattice point alone, so vertices shared by two patches land on the same spot.
//
// A vertex at lattice point (x, z) takes the height of the finest windowed layer whose valid rectangle
// holds the 2 × 2 level texels around it, bilinear between their centres (`textureLoad`: R32Float
// is not filterable everywhere), else of the resident base level clamped at the texture's edges.
// It depends on the position alone, so vertices shared by two patches get one height.
#define_import_path bevy_terrain_clip::relief

struct ReliefParams {
    // Coverage of windowed layer i (level base_level + 1 + i), in level texels: min.xy, max.xy.
    coverage: array<vec4<f32>, 16>,
    base_level: u32,
    layer_count: u32,
    clip_size: f32,
    // Lattice steps along the height texture's side (a power of two).
    lattice_side: f32,
    // The anchor lattice point the tiles are placed relative to, and its render-space (x, z).
    anchor: vec2<f32>,
    anchor_render: vec2<f32>,
    // Metres per lattice step.
    lattice_step: f32,
    // Render-space y of height 0 (minus the render origin's world y).
    height_offset: f32,
    // Render-space (x, z) of the colour texture's (0, 0), and its side: the mesh uv a colour
    // stack without a world mapping is sampled by.
    color_origin: vec2<f32>,
    color_size: f32,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(106) var height_layers: texture_2d_array<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(107) var height_base: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(108) var<uniform> relief: ReliefParams;

fn level_texel(xz: vec2<f32>, level: u32) -> vec2<f32> {
    return xz * (exp2(f32(level)) / relief.lattice_side) - 0.5;
}

fn lerp(a: f32, b: f32, f: f32) -> f32 {
    return a + (b - a) * f;
}

// `height_level`: the finest windowed layer (index + 1) holding the 2 × 2 texels around `xz`, 0
// for the base level.
fn height_layer(xz: vec2<f32>) -> u32 {
    for (var i = i32(relief.layer_count) - 1; i >= 0; i -= 1) {
        let t0 = floor(level_texel(xz, relief.base_level + 1u + u32(i)));
        let c = relief.coverage[i];
        if all(t0 >= c.xy) && all(t0 + 1.0 < c.zw) {
            return u32(i) + 1u;
        }
    }
    return 0u;
}

fn layer_texel(p: vec2<i32>, layer: u32) -> f32 {
    let c = i32(relief.clip_size);
    let slot = ((p % c) + c) % c;
    return textureLoad(height_layers, slot, i32(layer) - 1, 0).r;
}

fn base_texel(p: vec2<i32>) -> f32 {
    let last = i32(exp2(f32(relief.base_level))) - 1;
    return textureLoad(height_base, clamp(p, vec2(0), vec2(last)), 0).r;
}

// `height_at`.
fn relief_height(xz: vec2<f32>) -> f32 {
    let layer = height_layer(xz);
    let level = relief.base_level + layer;
    let t = level_texel(xz, level);
    let t0 = floor(t);
    let f = t - t0;
    let p = vec2<i32>(t0);
    var h = vec4(0.0);
    if layer == 0u {
        h = vec4(base_texel(p), base_texel(p + vec2(1, 0)), base_texel(p + vec2(0, 1)), base_texel(p + vec2(1, 1)));
    } else {
        h = vec4(
            layer_texel(p, layer), layer_texel(p + vec2(1, 0), layer),
            layer_texel(p + vec2(0, 1), layer), layer_texel(p + vec2(1, 1), layer));
    }
    return lerp(lerp(h.x, h.y, f.x), lerp(h.z, h.w, f.x), f.y);
}

// `normal_at`: central differences over one texel of the level at `xz`.
fn relief_normal(xz: vec2<f32>) -> vec3<f32> {
    let e = relief.lattice_side / exp2(f32(relief.base_level + height_layer(xz)));
    let dx = relief_height(xz + vec2(e, 0.0)) - relief_height(xz - vec2(e, 0.0));
    let dz = relief_height(xz + vec2(0.0, e)) - relief_height(xz - vec2(0.0, e));
    return normalize(vec3(-dx, 2.0 * e * relief.lattice_step, -dz));
}

// The lattice point of a tile vertex placed relative to the anchor (exact integers, or halves).
fn lattice_point(relative: vec2<f32>) -> vec2<f32> {
    return relative + relief.anchor;
}

// Render-space (x, y, z) of a vertex placed at `relative` lattice steps from the anchor, at
// height `height`.
fn render_position(relative: vec2<f32>, height: f32) -> vec3<f32> {
    let xz = relief.anchor_render + relative * relief.lattice_step;
    return vec3(xz.x, height + relief.height_offset, xz.y);
}

// The colour stack's texture coordinates at render-space `xz` (for a colour stack without a
// world mapping).
fn color_uv(xz: vec2<f32>) -> vec2<f32> {
    return (xz - relief.color_origin) / relief.color_size;
}
