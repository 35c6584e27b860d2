// Screen Space Soft Shadows, step 1 (Gumbau 2011, §6.2.1): the "coarse", dilated shadow map.
// Each coarse texel first keeps the depth nearest the light over a block of BLOCK × BLOCK shadow
// map texels (the thesis' coarser map), then a separable filter keeps the nearest over a square
// of 2R + 1 coarse texels. Bevy's shadow maps are reverse Z, so "nearest the light" is the
// maximum. The reach covers half the penumbra of a blocker `max_occluder_distance` in front of
// the receiver, in the texels of each cascade: r = ⌈max_occluder_distance · tan(θ/2) / texel⌉,
// R = ⌈r / BLOCK⌉. A spot light's one layer, and a point light's six cube faces (each dilated on
// its own, in the point lights' cube texture viewed as a 2D array), use the radius computed on
// the CPU (`ssss::min_filter::spot_fine_reach`, `coarse_radius_of`). CPU reference:
// `ssss::min_filter::coarse_dilate`.
#import bevy_pbr::mesh_view_types::{Lights, DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT}
#import bevy_soft_shadows::ssss_types::{
    SsssUniform, MAX_COARSE_RADIUS, NO_LIGHT, LIGHT_KIND_SPOT, LIGHT_KIND_POINT,
}

@group(0) @binding(0) var shadow_depth: texture_depth_2d_array;
@group(0) @binding(1) var rows_in: texture_2d_array<f32>;
@group(0) @binding(2) var dilated_out: texture_storage_2d_array<r32float, write>;
@group(0) @binding(3) var<uniform> lights: Lights;
@group(0) @binding(4) var<uniform> ssss: SsssUniform;
@group(0) @binding(5) var scan_out: texture_storage_2d_array<rg32float, write>;

fn ssss_light() -> u32 {
    for (var i = 0u; i < lights.n_directional_lights; i += 1u) {
        if (lights.directional_lights[i].flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            return i;
        }
    }
    return NO_LIGHT;
}

// Coarse dilation radius R for one layer of the shadow texture array; -1 for layers of other
// lights (left alone).
fn radius_of_layer(layer: u32) -> i32 {
    if ssss.light_kind == LIGHT_KIND_SPOT {
        // Spot shadow maps follow the directional cascades in the array.
        let spot_layer = i32(ssss.light_index) + lights.spot_light_shadowmap_offset;
        return select(-1, i32(ssss.local_radius), i32(layer) == spot_layer);
    }
    if ssss.light_kind == LIGHT_KIND_POINT {
        // `shadow_depth` is then the point lights' cube texture: six faces per light, in its
        // clustered order.
        return select(-1, i32(ssss.local_radius), layer / 6u == ssss.light_index);
    }
    let i = ssss_light();
    if i == NO_LIGHT {
        return -1;
    }
    let light = &lights.directional_lights[i];
    let base = (*light).depth_texture_base_index;
    if layer < base || layer >= base + (*light).num_cascades {
        return -1;
    }
    let texel = (*light).cascades[layer - base].texel_size;
    let half_width = ssss.max_occluder_distance * tan(0.5 * ssss.light_size);
    let r = ceil(max(half_width / max(texel, 1e-6), 0.0));
    return i32(min(ceil(r / f32(ssss.dilation_block)), f32(MAX_COARSE_RADIUS)));
}

// The nearest depth of each BLOCK × BLOCK block of the shadow map.
@compute @workgroup_size(8, 8, 1)
fn reduce(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(textureDimensions(dilated_out));
    if i32(id.x) >= size.x || i32(id.y) >= size.y || radius_of_layer(id.z) < 0 {
        return;
    }
    let fine = vec2<i32>(textureDimensions(shadow_depth)) - 1;
    let block = i32(ssss.dilation_block);
    let origin = vec2<i32>(id.xy) * block;
    var nearest = 0.0;
    for (var y = 0; y < block; y += 1) {
        for (var x = 0; x < block; x += 1) {
            let p = min(origin + vec2(x, y), fine);
            nearest = max(nearest, textureLoad(shadow_depth, p, id.z, 0));
        }
    }
    textureStore(dilated_out, id.xy, id.z, vec4(nearest, 0.0, 0.0, 0.0));
}

// The separable filter, van Herk / Gil-Werman style: O(1) work per texel whatever the radius
// (the direct filter reads 2R + 1 texels per texel and pass, ~60 at the spot light's R = 14).
// Along the filtered axis the line is cut into segments of k = 2R + 1 texels; `scan_*` writes
// for each texel the nearest depth from its segment's start to it (g, in .r) and from it to
// its segment's end (h, in .g). A window [p − R, p + R] is k long, so it covers the end of one
// segment and the start of the next: its nearest depth is max(h[p − R], g[p + R]) (`combine_*`).
// Max is exact, so the result is bit-identical to the direct filter (`nearest_filter_1d`).

// k for R ≤ MAX_COARSE_RADIUS.
const MAX_SEGMENT: u32 = 2u * MAX_COARSE_RADIUS + 1u;

// Texel `i` along the filtered axis of line `line`.
fn texel_on(horizontal: bool, line: i32, i: i32) -> vec2<i32> {
    return select(vec2(line, i), vec2(i, line), horizontal);
}

fn scan(id: vec3<u32>, horizontal: bool) {
    let size = vec2<i32>(textureDimensions(rows_in));
    let r = radius_of_layer(id.z);
    // One invocation per segment: (segment, line) is (x, y) for rows, (y, x) for columns.
    let segment = i32(select(id.y, id.x, horizontal));
    let line = i32(select(id.x, id.y, horizontal));
    let n = select(size.y, size.x, horizontal);
    let lines = select(size.x, size.y, horizontal);
    if r < 0 || line >= lines {
        return;
    }
    let k = 2 * r + 1;
    let start = segment * k;
    if start >= n {
        return;
    }
    let len = min(k, n - start);
    var depth: array<f32, MAX_SEGMENT>;
    for (var i = 0; i < len; i += 1) {
        depth[i] = textureLoad(rows_in, texel_on(horizontal, line, start + i), id.z, 0).r;
    }
    // Suffix maxima, then prefix maxima on the way out.
    var suffix: array<f32, MAX_SEGMENT>;
    var nearest = 0.0;
    for (var i = len - 1; i >= 0; i -= 1) {
        nearest = max(nearest, depth[i]);
        suffix[i] = nearest;
    }
    nearest = 0.0;
    for (var i = 0; i < len; i += 1) {
        nearest = max(nearest, depth[i]);
        textureStore(scan_out, texel_on(horizontal, line, start + i), id.z, vec4(nearest, suffix[i], 0.0, 0.0));
    }
}

fn combine(id: vec3<u32>, horizontal: bool) {
    let size = vec2<i32>(textureDimensions(rows_in));
    let r = radius_of_layer(id.z);
    if r < 0 || i32(id.x) >= size.x || i32(id.y) >= size.y {
        return;
    }
    let k = 2 * r + 1;
    let p = i32(select(id.y, id.x, horizontal));
    let line = i32(select(id.x, id.y, horizontal));
    let n = select(size.y, size.x, horizontal);
    // The window, clamped to the line (as the direct filter clamps it).
    let a = max(p - r, 0);
    let b = min(p + r, n - 1);
    let h = textureLoad(rows_in, texel_on(horizontal, line, a), id.z, 0).g;
    let g = textureLoad(rows_in, texel_on(horizontal, line, b), id.z, 0).r;
    var nearest = max(h, g);
    if a / k == b / k {
        // Inside one segment (only when clamped, or exactly one whole segment): it starts at
        // the segment's start (g alone) or ends at its end (h alone).
        nearest = select(h, g, a % k == 0);
    }
    textureStore(dilated_out, vec2<i32>(id.xy), id.z, vec4(nearest, 0.0, 0.0, 0.0));
}

@compute @workgroup_size(8, 8, 1)
fn scan_horizontal(@builtin(global_invocation_id) id: vec3<u32>) {
    scan(id, true);
}

@compute @workgroup_size(8, 8, 1)
fn combine_horizontal(@builtin(global_invocation_id) id: vec3<u32>) {
    combine(id, true);
}

@compute @workgroup_size(8, 8, 1)
fn scan_vertical(@builtin(global_invocation_id) id: vec3<u32>) {
    scan(id, false);
}

@compute @workgroup_size(8, 8, 1)
fn combine_vertical(@builtin(global_invocation_id) id: vec3<u32>) {
    combine(id, false);
}

// The direct form of the same filter (2R + 1 reads per texel and pass): cheaper than the
// segments for small radii, so `SsssDilationFilter::Auto` runs it below
// `min_filter::SEGMENT_FILTER_FROM_RADIUS`. Both give the same map bit for bit.
fn direct(id: vec3<u32>, horizontal: bool) {
    let size = vec2<i32>(textureDimensions(rows_in));
    let r = radius_of_layer(id.z);
    if r < 0 || i32(id.x) >= size.x || i32(id.y) >= size.y {
        return;
    }
    let p = i32(select(id.y, id.x, horizontal));
    let line = i32(select(id.x, id.y, horizontal));
    let n = select(size.y, size.x, horizontal);
    var nearest = 0.0;
    for (var o = -r; o <= r; o += 1) {
        let i = clamp(p + o, 0, n - 1);
        nearest = max(nearest, textureLoad(rows_in, texel_on(horizontal, line, i), id.z, 0).r);
    }
    textureStore(dilated_out, vec2<i32>(id.xy), id.z, vec4(nearest, 0.0, 0.0, 0.0));
}

@compute @workgroup_size(8, 8, 1)
fn direct_horizontal(@builtin(global_invocation_id) id: vec3<u32>) {
    direct(id, true);
}

@compute @workgroup_size(8, 8, 1)
fn direct_vertical(@builtin(global_invocation_id) id: vec3<u32>) {
    direct(id, false);
}

// Debug copy of the shadow map into a float texture that can be read back (tests compare the
// dilated map with its CPU reference computed from it).
@compute @workgroup_size(8, 8, 1)
fn copy_shadow(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(textureDimensions(shadow_depth));
    if i32(id.x) >= size.x || i32(id.y) >= size.y {
        return;
    }
    textureStore(dilated_out, id.xy, id.z, vec4(textureLoad(shadow_depth, id.xy, id.z, 0), 0.0, 0.0, 0.0));
}
