#define_import_path bevy_foliage::grass_functions

// The grass transitions on the GPU (Boulanger 2008, thesis §4.2.5, algorithm 1, eq. 4.3–4.6,
// fig. 4.13) and the density-map lookup (§4.2.4). `grass::transition` and `grass::density` are
// the CPU references of exactly these functions.

// Below this local density nothing is drawn, and under this opacity a fragment is discarded.
const DISCARD: f32 = 0.01;

// clamp((d − start)/(end − start), 0, 1).
fn ramp(d: f32, start: f32, end: f32) -> f32 {
    return clamp((d - start) / (end - start), 0.0, 1.0);
}

// Fig. 4.13: the transition window's half-width for weight w. window = (ω_max, ω₀, …).
fn omega(window: vec4<f32>, w: f32) -> f32 {
    return window.x * (window.y + (1.0 - window.y) * (1.0 - abs(2.0 * w - 1.0)));
}

// Eq. 4.3: the weight of blade geometry at distance d. distances = (min_geom, max_geom, …).
fn geometry_weight(distances: vec4<f32>, d: f32) -> f32 {
    return ramp(d, distances.y, distances.x);
}

// Eq. 4.5: the weight of the horizontal slice at distance d.
fn horizontal_weight(distances: vec4<f32>, d: f32) -> f32 {
    return ramp(d, distances.x, distances.y);
}

// Eq. 4.6: a blade of threshold dth drawn as geometry at distance d where the density is ld.
fn geometry_opacity(distances: vec4<f32>, window: vec4<f32>, d: f32, ld: f32, dth: f32) -> f32 {
    if ld < DISCARD || dth > ld {
        return 0.0;
    }
    let w = 1.0 - geometry_weight(distances, d);
    let o = omega(window, w);
    return clamp((dth - (w - o) * ld) / (2.0 * o * ld), 0.0, 1.0);
}

// Algorithm 1: a blade of threshold dth drawn by a slice of weight w where the density is ld.
fn slice_opacity(window: vec4<f32>, w: f32, ld: f32, dth: f32) -> f32 {
    if ld < DISCARD || dth > ld {
        return 0.0;
    }
    let o = omega(window, w);
    return clamp(((w + o) * ld - dth) / (2.0 * o * ld), 0.0, 1.0);
}

// The local density at world (x, z): bilinear between texel centres of the R32Float map,
// clamped at its edges, zero outside its rectangle rect = (min.x, min.z, size.x, size.z).
fn density_at(map: texture_2d<f32>, rect: vec4<f32>, xz: vec2<f32>) -> f32 {
    let uv = (xz - rect.xy) / rect.zw;
    if any(uv < vec2(0.0)) || any(uv > vec2(1.0)) {
        return 0.0;
    }
    let dims = vec2<i32>(textureDimensions(map));
    let t = uv * vec2<f32>(dims) - 0.5;
    let base = floor(t);
    let f = t - base;
    let i0 = clamp(vec2<i32>(base), vec2(0), dims - 1);
    let i1 = clamp(vec2<i32>(base) + 1, vec2(0), dims - 1);
    let a = textureLoad(map, vec2(i0.x, i0.y), 0).r;
    let b = textureLoad(map, vec2(i1.x, i0.y), 0).r;
    let c = textureLoad(map, vec2(i0.x, i1.y), 0).r;
    let e = textureLoad(map, vec2(i1.x, i1.y), 0).r;
    return mix(mix(a, b, f.x), mix(c, e, f.x), f.y);
}

// The 4 × 4 ordered-dither threshold of a pixel, in ]0, 1[: a fragment of opacity α is kept
// where α exceeds it, so α of the pixels of an even patch are covered.
fn dither(frag: vec2<f32>) -> f32 {
    let p = vec2<u32>(frag) & vec2(3u);
    var m = array<u32, 16>(0u, 8u, 2u, 10u, 12u, 4u, 14u, 6u, 3u, 11u, 1u, 9u, 15u, 7u, 13u, 5u);
    return (f32(m[p.y * 4u + p.x]) + 0.5) / 16.0;
}

// `grass::transition::shifted_dither`: the dither shifted by key's low four bits (sixteenths),
// so the slice quads a view ray crosses keep their blades independently.
fn shifted_dither(frag: vec2<f32>, key: u32) -> f32 {
    return fract(dither(frag) + f32(key & 15u) / 16.0);
}

// `grass::patch::hash32`.
fn hash32(v: u32) -> u32 {
    var x = v;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    x ^= x >> 16u;
    return x;
}

// `grass::patch::Mirror::of_cell`: which axes cell (i, j) mirrors (eq. 4.9's orientation map).
fn mirror_of_cell(i: i32, j: i32, seed: u32) -> vec2<bool> {
    let h = hash32(bitcast<u32>(i) ^ hash32(bitcast<u32>(j) ^ hash32(seed)));
    return vec2((h & 1u) == 1u, (h & 2u) == 2u);
}

// Eq. 4.4 / 4.14: the weight of the vertical slices at distance d, where the ground's normal
// and the unit view vector make n_dot_v.
fn vertical_weight(distances: vec4<f32>, window: vec4<f32>, d: f32, n_dot_v: f32) -> f32 {
    let near = ramp(d, distances.x, distances.y) * ramp(d, distances.w, distances.z);
    var silhouette = 0.0;
    if d >= distances.w && d <= window.z {
        silhouette = 1.0 - min(abs(n_dot_v) / max(window.w, 1e-6), 1.0);
    }
    return min(near + silhouette, 1.0);
}

// Van Oosterom–Strackee: the area of the spherical triangle a, b, c.
fn spherical_area(a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> f32 {
    let numerator = abs(dot(a, cross(b, c)));
    let denominator = 1.0 + dot(a, b) + dot(b, c) + dot(c, a);
    return 2.0 * atan2(numerator, denominator);
}

// Appendix A (`grass::lighting::btf_weights`): the weights of the baked directions Y+, X+, X−,
// Z+, Z− for light from unit direction l (below the horizon: taken at the horizon).
fn btf_weights(light: vec3<f32>) -> array<f32, 5> {
    var l = vec3(light.x, max(light.y, 0.0), light.z);
    if dot(l, l) > 1e-12 {
        l = normalize(l);
    } else {
        l = vec3(0.0, 1.0, 0.0);
    }
    var x_index = 1u;
    var x = vec3(1.0, 0.0, 0.0);
    if l.x < 0.0 {
        x_index = 2u;
        x = vec3(-1.0, 0.0, 0.0);
    }
    var z_index = 3u;
    var z = vec3(0.0, 0.0, 1.0);
    if l.z < 0.0 {
        z_index = 4u;
        z = vec3(0.0, 0.0, -1.0);
    }
    let y = vec3(0.0, 1.0, 0.0);
    var w = array<f32, 5>(0.0, 0.0, 0.0, 0.0, 0.0);
    w[0] = spherical_area(l, x, z);
    w[x_index] = spherical_area(l, y, z);
    w[z_index] = spherical_area(l, y, x);
    let sum = w[0] + w[1] + w[2] + w[3] + w[4];
    for (var i = 0u; i < 5u; i += 1u) {
        w[i] /= sum;
    }
    return w;
}

// The ground and the wind of a field (`grass::ground_map::GroundWindUniform`).
struct GroundWind {
    // (origin x, origin z, sample spacing, cell side)
    ground: vec4<f32>,
    // (unit direction x, z, strength, speed)
    wind: vec4<f32>,
    // (map scale, volume height, time, the field's plane y)
    wind_shape: vec4<f32>,
}

struct GroundSample {
    height: f32,
    // (∂h/∂x, ∂h/∂z)
    gradient: vec2<f32>,
}

// Eq. 4.10 over the ground's samples (`GroundGrid::height_at`, `gradient_at`): the bilinear patch
// through the four samples around world xz, clamped to the grid at its edges.
fn ground_at(heights: texture_2d<f32>, gw: GroundWind, xz: vec2<f32>) -> GroundSample {
    let last = f32(textureDimensions(heights).x) - 1.0;
    let t = clamp((xz - gw.ground.xy) / gw.ground.z, vec2(0.0), vec2(last));
    let base = min(floor(t), vec2(last - 1.0));
    let f = t - base;
    let i = vec2<i32>(base);
    let h00 = textureLoad(heights, i, 0).r;
    let h10 = textureLoad(heights, i + vec2(1, 0), 0).r;
    let h01 = textureLoad(heights, i + vec2(0, 1), 0).r;
    let h11 = textureLoad(heights, i + vec2(1, 1), 0).r;
    var out: GroundSample;
    out.height = (1.0 - f.x) * (1.0 - f.y) * h00 + f.x * (1.0 - f.y) * h10
        + (1.0 - f.x) * f.y * h01 + f.x * f.y * h11;
    out.gradient = vec2(
        (1.0 - f.y) * (h10 - h00) + f.y * (h11 - h01),
        (1.0 - f.x) * (h01 - h00) + f.x * (h11 - h10),
    ) / gw.ground.z;
    return out;
}

// `WindMap::sample`: bilinear between texel centres, wrapping.
fn wind_map_at(map: texture_2d<f32>, uv: vec2<f32>) -> vec2<f32> {
    let dims = vec2<i32>(textureDimensions(map));
    let t = uv * vec2<f32>(dims) - 0.5;
    let base = floor(t);
    let f = t - base;
    let i = vec2<i32>(base);
    let a = textureLoad(map, ((i % dims) + dims) % dims, 0).rg;
    let b = textureLoad(map, (((i + vec2(1, 0)) % dims) + dims) % dims, 0).rg;
    let c = textureLoad(map, (((i + vec2(0, 1)) % dims) + dims) % dims, 0).rg;
    let e = textureLoad(map, (((i + vec2(1, 1)) % dims) + dims) % dims, 0).rg;
    return mix(mix(a, b, f.x), mix(c, e, f.x), f.y);
}

// `GrassWind::corner_wind`: the lean of the volume's top at a cell corner.
fn corner_wind(map: texture_2d<f32>, gw: GroundWind, corner: vec2<f32>) -> vec2<f32> {
    let dir = gw.wind.xy;
    let m = wind_map_at(map, (corner - dir * gw.wind.w * gw.wind_shape.z) / gw.wind_shape.x);
    return (dir * m.x + vec2(-dir.y, dir.x) * m.y) * gw.wind.z;
}

// `GrassWind::offset`: a point at world xz, `height` above the ground, pushed by the bilinear
// blend of its cell's corner winds in proportion to its height (§4.2.7.4).
fn wind_offset(map: texture_2d<f32>, gw: GroundWind, xz: vec2<f32>, height: f32) -> vec2<f32> {
    if gw.wind.z <= 0.0 || gw.wind_shape.y <= 0.0 {
        return vec2(0.0);
    }
    let cell = gw.ground.w;
    let t = (xz - gw.ground.xy) / cell;
    let base = floor(t);
    let f = t - base;
    let w00 = corner_wind(map, gw, gw.ground.xy + base * cell);
    let w10 = corner_wind(map, gw, gw.ground.xy + (base + vec2(1.0, 0.0)) * cell);
    let w01 = corner_wind(map, gw, gw.ground.xy + (base + vec2(0.0, 1.0)) * cell);
    let w11 = corner_wind(map, gw, gw.ground.xy + (base + vec2(1.0, 1.0)) * cell);
    let w = w00 * ((1.0 - f.x) * (1.0 - f.y)) + w10 * (f.x * (1.0 - f.y))
        + w01 * ((1.0 - f.x) * f.y) + w11 * (f.x * f.y);
    return w * clamp(height / gw.wind_shape.y, 0.0, 1.0);
}

// A point of the flat grass volume (world xz and y on the field's plane, `height` above it) on
// the ground and in the wind: lifted by eq. 4.10, then sheared.
fn on_ground(heights: texture_2d<f32>, map: texture_2d<f32>, gw: GroundWind, flat: vec3<f32>, height: f32) -> vec3<f32> {
    let lift = ground_at(heights, gw, flat.xz).height;
    let push = wind_offset(map, gw, flat.xz, height);
    return vec3(flat.x + push.x, flat.y + lift, flat.z + push.y);
}

// How high above the ground a point of the lifted grass is.
fn height_above_ground(heights: texture_2d<f32>, gw: GroundWind, world: vec3<f32>) -> f32 {
    return world.y - gw.wind_shape.w - ground_at(heights, gw, world.xz).height;
}

// `ground::lift_to_patch`: a world direction in the unlifted patch volume (eq. 4.11 with the
// lift's own tangents), not normalised.
fn lift_to_patch(gradient: vec2<f32>, l: vec3<f32>) -> vec3<f32> {
    return vec3(l.x, l.y - gradient.x * l.x - gradient.y * l.z, l.z);
}

// `lighting::ShadowMask::light_through`: the share of the light from unit direction l reaching
// a blade point `height` above the ground where the density is ld — the blade shadow mask
// (§4.2.6) read where the ray towards the light leaves the cylinder around the blade, through
// eq. 4.7. shape = (slab height, cylinder radius, 0, 0); a radius of 0 casts no shadow.
fn shadow_mask_light(mask: texture_2d<f32>, shape: vec4<f32>, height: f32, l: vec3<f32>, ld: f32) -> f32 {
    let across = length(l.xz);
    if across < 1e-4 || shape.y <= 0.0 {
        return 1.0;
    }
    let exit = height + shape.y * max(l.y, 0.0) / across;
    if exit >= shape.x {
        return 1.0;
    }
    let dims = vec2<i32>(textureDimensions(mask));
    let uv = vec2(atan2(l.z, l.x) / 6.28318530718, 1.0 - max(exit, 0.0) / shape.x);
    let t = uv * vec2<f32>(dims) - 0.5;
    let base = floor(t);
    let f = t - base;
    let i = vec2<i32>(base);
    let x0 = ((i.x % dims.x) + dims.x) % dims.x;
    let x1 = (((i.x + 1) % dims.x) + dims.x) % dims.x;
    let y0 = clamp(i.y, 0, dims.y - 1);
    let y1 = clamp(i.y + 1, 0, dims.y - 1);
    let a = textureLoad(mask, vec2(x0, y0), 0).r;
    let b = textureLoad(mask, vec2(x1, y0), 0).r;
    let c = textureLoad(mask, vec2(x0, y1), 0).r;
    let e = textureLoad(mask, vec2(x1, y1), 0).r;
    let m = mix(mix(a, b, f.x), mix(c, e, f.x), f.y);
    // Eq. 4.7.
    return 1.0 - (1.0 - clamp(m, 0.0, 1.0)) * clamp(ld, 0.0, 1.0);
}
