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
