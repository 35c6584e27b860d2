// The filterable shadow map's passes (Gumbau 2011, §7.2–7.3), per layer of the light in Bevy's
// directional and spot shadow texture (a directional light's cascades, or a spot light's one
// map): `resolve` turns each depth into a texel of statistics, `blur_horizontal` and
// `blur_vertical` pre-filter it by a separable Gaussian, `downsample` builds each mip from the
// one below. `bevy_soft_shadows::filterable::filter` is the CPU reference of each.

struct MomentParams {
    // x: the method (0 Gaussian CDF, 1 power CDF, 2 variance, 3 exponential, 4 four moments);
    // y: the Gaussian's radius r in texels; z: the light's first layer in Bevy's directional
    // shadow texture (the map's layer i is the light's cascade i); w: what the depths are
    // (`filter::DepthSource`: 0 a cascade, 1 a spot light's map).
    mode: vec4<u32>,
    // x: the exponential's scale c; y, z: a spot light's near plane and range.
    scale: vec4<f32>,
    // The Gaussian's weights w[k], k = |offset| = 0..=r, four a vector.
    weights: array<vec4<f32>, 8>,
}

@group(0) @binding(0) var shadow_depth: texture_depth_2d_array;
@group(0) @binding(1) var source: texture_2d_array<f32>;
// Each method's statistics in as few channels as they need.
#ifdef FORMAT_R32
@group(0) @binding(2) var destination: texture_storage_2d_array<r32float, write>;
#else
#ifdef FORMAT_RG32
@group(0) @binding(2) var destination: texture_storage_2d_array<rg32float, write>;
#else
@group(0) @binding(2) var destination: texture_storage_2d_array<rgba32float, write>;
#endif
#endif
@group(0) @binding(3) var<uniform> params: MomentParams;

const POWER_CDF: u32 = 1u;

// `FilterableMethod::encode`: the statistics of one occluder depth z.
fn encode(z: f32) -> vec4<f32> {
    switch params.mode.x {
        case 1u: {
            return vec4(z, z, z, 0.0);
        }
        case 3u: {
            return vec4(exp(params.scale.x * z), 0.0, 0.0, 0.0);
        }
        case 4u: {
            let z2 = z * z;
            return vec4(z, z2, z2 * z, z2 * z2);
        }
        default: {
            return vec4(z, z * z, 0.0, 0.0);
        }
    }
}

fn weight(k: i32) -> f32 {
    let i = u32(abs(k));
    return params.weights[i / 4u][i % 4u];
}

// `DepthSource::linear`: Bevy's cascades store reversed, linear depth (1 at the cascade's near
// plane), so z = 1 − depth; a spot light's map stores near / d, so z = d / range (1 where
// nothing was drawn). Larger farther from the light.
fn linear_depth(depth: f32) -> f32 {
    if params.mode.w == 0u {
        return 1.0 - depth;
    }
    if depth <= 0.0 {
        return 1.0;
    }
    return min(params.scale.y / (depth * params.scale.z), 1.0);
}

@compute @workgroup_size(8, 8, 1)
fn resolve(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(destination);
    if any(id.xy >= size) {
        return;
    }
    let depth = textureLoad(shadow_depth, vec2<i32>(id.xy), i32(id.z + params.mode.z), 0);
    textureStore(destination, vec2<i32>(id.xy), i32(id.z), encode(linear_depth(depth)));
}

// One pass of the separable Gaussian along `step`: moments by the weights, the power CDF's
// minimum and maximum over the kernel's support, edges clamped.
fn blur(id: vec3<u32>, step: vec2<i32>) {
    let size = vec2<i32>(textureDimensions(destination));
    let p = vec2<i32>(id.xy);
    if any(p >= size) {
        return;
    }
    let r = i32(params.mode.y);
    var sum = vec4(0.0);
    var lo = 1e30;
    var hi = -1e30;
    for (var o = -r; o <= r; o += 1) {
        let q = clamp(p + step * o, vec2(0), size - 1);
        let t = textureLoad(source, q, i32(id.z), 0);
        sum += weight(o) * t;
        lo = min(lo, t.y);
        hi = max(hi, t.z);
    }
    if params.mode.x == POWER_CDF {
        sum.y = lo;
        sum.z = hi;
    }
    textureStore(destination, p, i32(id.z), sum);
}

@compute @workgroup_size(8, 8, 1)
fn blur_horizontal(@builtin(global_invocation_id) id: vec3<u32>) {
    blur(id, vec2(1, 0));
}

@compute @workgroup_size(8, 8, 1)
fn blur_vertical(@builtin(global_invocation_id) id: vec3<u32>) {
    blur(id, vec2(0, 1));
}

// A mip texel from the (up to) four below it: the mean, the power CDF's minimum and maximum.
@compute @workgroup_size(8, 8, 1)
fn downsample(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(textureDimensions(destination));
    let below = vec2<i32>(textureDimensions(source));
    let p = vec2<i32>(id.xy);
    if any(p >= size) {
        return;
    }
    var sum = vec4(0.0);
    var n = 0.0;
    var lo = 1e30;
    var hi = -1e30;
    for (var k = 0; k < 4; k += 1) {
        let q = 2 * p + vec2(k & 1, k >> 1u);
        if all(q < below) {
            let t = textureLoad(source, q, i32(id.z), 0);
            sum += t;
            n += 1.0;
            lo = min(lo, t.y);
            hi = max(hi, t.z);
        }
    }
    var out = sum / n;
    if params.mode.x == POWER_CDF {
        out.y = lo;
        out.z = hi;
    }
    textureStore(destination, p, i32(id.z), out);
}
