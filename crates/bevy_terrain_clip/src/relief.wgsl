// The terrain's heights from a height clip stack, for the vertex stage (paper 4 fetches heights
// in the vertex shader). CPU reference: `geometry::relief` (`height_level`, `height_at`,
// `normal_at`).
//
// A vertex at world (x, z) takes the height of the finest windowed layer whose valid rectangle
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
    // World side of the height texture (m).
    size: f32,
    // World (x, z) of the height texture's (0, 0).
    origin: vec2<f32>,
    // World (x, z) of the colour texture's (0, 0), and its side: the fragment stage's uv.
    color_origin: vec2<f32>,
    color_size: f32,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(106) var height_layers: texture_2d_array<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(107) var height_base: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(108) var<uniform> relief: ReliefParams;

fn level_texel(xz: vec2<f32>, level: u32) -> vec2<f32> {
    return (xz - relief.origin) / relief.size * exp2(f32(level)) - 0.5;
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
    let e = relief.size / exp2(f32(relief.base_level + height_layer(xz)));
    let dx = relief_height(xz + vec2(e, 0.0)) - relief_height(xz - vec2(e, 0.0));
    let dz = relief_height(xz + vec2(0.0, e)) - relief_height(xz - vec2(0.0, e));
    return normalize(vec3(-dx, 2.0 * e, -dz));
}

// The colour stack's texture coordinates at `xz`.
fn color_uv(xz: vec2<f32>) -> vec2<f32> {
    return (xz - relief.color_origin) / relief.color_size;
}
