#define_import_path bevy_soft_shadows::filtered_receiver

// A directional or spot light's shadow term from its filterable shadow map (Gumbau 2011, §7.3):
// the map's texel under the receiver, read at the mip of the pixel's footprint in the map,
// turned into a visibility by the method's function. `bevy_soft_shadows::filterable::filter::sample`
// and `FilterableMethod::visibility` are the CPU reference; the cascade selection, the biases
// and the blend between cascades are Bevy's (`bevy_pbr::shadows::fetch_directional_shadow`),
// as are a spot light's projection and biases (`fetch_spot_shadow`; `ssss::distance::SpotProjection`
// is its CPU reference).
//
// A material receives it where its fragment stage would call `apply_pbr_lighting(pbr_input)`:
//
//     let dp = mat2x3(dpdx(in.world_position.xyz), dpdy(in.world_position.xyz)); // uniform control flow
//     color = apply_pbr_lighting(pbr_input);
//     color = apply_filtered_shadow(pbr_input, color, in.position.xy, dp, moments, spot_moments, receiver);
//
// with `moments`, `spot_moments` and `receiver` the `SoftShadowReceiver` bindings.
#import bevy_pbr::{
    mesh_view_bindings as view_bindings,
    pbr_types::PbrInput,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    mesh_view_types::POINT_LIGHT_FLAGS_SPOT_LIGHT_Y_NEGATIVE,
}
#import bevy_render::maths::orthonormalize
#import bevy_soft_shadows::filterable_visibility::{
    chebyshev, exponential, gaussian_cdf, power_cdf, hamburger_msm,
}
#import bevy_soft_shadows::receiver_functions::{apply_directional_visibility, apply_spot_visibility}

struct FilteredReceiver {
    // x: the light's index among the view's directional lights (0xffffffff: no map this
    // frame); y: the method (0 Gaussian CDF, 1 power CDF, 2 variance, 3 exponential, 4 four
    // moments); z: the map's mip count.
    mode: vec4<u32>,
    // x: the exponential's scale c; y: the two-moment methods' least variance; z: the four
    // moments' bias.
    scale: vec4<f32>,
    // The spot light's map: x its index among the clustered lights (0xffffffff: no map), y the
    // method, z the mip count.
    spot_mode: vec4<u32>,
    // As `scale`, and w the spot light's range (the map holds distance along its axis / range).
    spot_scale: vec4<f32>,
}

const NO_MAP: u32 = 0xffffffffu;

// Level `level` of cascade `layer` at `uv`, bilinear between texel centres, edges clamped
// (`filter::bilinear`). The 32-bit float texels are not filterable on every adapter, and
// interpolating by hand keeps the GPU and the reference the same.
fn level_bilinear(moments: texture_2d_array<f32>, layer: i32, level: i32, uv: vec2<f32>) -> vec4<f32> {
    // The level's size from level 0's (llvmpipe answers `textureDimensions` at a level that
    // varies per pixel wrongly for some pixels).
    let size = max(vec2<i32>(textureDimensions(moments, 0)) >> vec2(u32(level)), vec2(1));
    let t = uv * vec2<f32>(size) - 0.5;
    let base = floor(t);
    let f = t - base;
    let p = vec2<i32>(base);
    let hi = size - 1;
    let a = textureLoad(moments, clamp(p, vec2(0), hi), layer, level);
    let b = textureLoad(moments, clamp(p + vec2(1, 0), vec2(0), hi), layer, level);
    let c = textureLoad(moments, clamp(p + vec2(0, 1), vec2(0), hi), layer, level);
    let d = textureLoad(moments, clamp(p + vec2(1, 1), vec2(0), hi), layer, level);
    let top = a + (b - a) * f.x;
    let bottom = c + (d - c) * f.x;
    return top + (bottom - top) * f.y;
}

// The trilinear read at a footprint of `footprint` level-0 texels (`filter::sample`).
fn sample_moments(moments: texture_2d_array<f32>, mips: u32, layer: i32, uv: vec2<f32>, footprint: f32) -> vec4<f32> {
    let last = f32(max(mips, 1u) - 1u);
    let lod = clamp(log2(max(footprint, 1.0)), 0.0, last);
    let lo = floor(lod);
    let f = lod - lo;
    let a = level_bilinear(moments, layer, i32(lo), uv);
    if f <= 0.0 {
        return a;
    }
    let b = level_bilinear(moments, layer, min(i32(lo) + 1, i32(last)), uv);
    return a + (b - a) * f;
}

// `FilterableMethod::visibility` of method `mode.y` with constants `scale`.
fn texel_visibility(mode: vec4<u32>, scale: vec4<f32>, texel: vec4<f32>, zr: f32) -> f32 {
    switch mode.y {
        case 1u: {
            return power_cdf(texel.xyz, zr);
        }
        case 2u: {
            return chebyshev(texel.xy, zr, scale.y);
        }
        case 3u: {
            return exponential(texel.x, zr, scale.x);
        }
        case 4u: {
            return hamburger_msm(texel, zr, scale.z);
        }
        default: {
            return gaussian_cdf(texel.xy, zr, scale.y);
        }
    }
}

// One cascade's filtered visibility: Bevy's normal and depth biases, the cascade's projection,
// and the footprint of the pixel (`dp`: the world position's change to the next pixel across
// and down) in the map's texels.
fn filtered_cascade(
    moments: texture_2d_array<f32>,
    receiver: FilteredReceiver,
    light_id: u32,
    cascade_index: u32,
    position: vec3<f32>,
    normal: vec3<f32>,
    dp: mat2x3<f32>,
) -> f32 {
    let light = &view_bindings::lights.directional_lights[light_id];
    let cascade = &(*light).cascades[cascade_index];
    let normal_offset = (*light).shadow_normal_bias * (*cascade).texel_size * normal;
    let depth_offset = (*light).shadow_depth_bias * (*light).direction_to_light.xyz;
    let clip = (*cascade).clip_from_world * vec4(position + normal_offset + depth_offset, 1.0);
    if clip.w <= 0.0 {
        return 1.0;
    }
    let ndc = clip.xyz / clip.w;
    if any(ndc.xy < vec2(-1.0)) || ndc.z < 0.0 || any(ndc > vec3(1.0)) {
        return 1.0;
    }
    let uv = ndc.xy * vec2(0.5, -0.5) + 0.5;
    // The cascades are orthographic: a world offset moves the map's uv linearly.
    let size = vec2<f32>(textureDimensions(moments, 0));
    let across = ((*cascade).clip_from_world * vec4(dp[0], 0.0)).xy * vec2(0.5, -0.5) * size;
    let down = ((*cascade).clip_from_world * vec4(dp[1], 0.0)).xy * vec2(0.5, -0.5) * size;
    let footprint = max(length(across), length(down));
    let texel = sample_moments(moments, receiver.mode.z, i32(cascade_index), uv, footprint);
    // The map holds z = 1 − depth (Bevy's cascades store reversed depth).
    return texel_visibility(receiver.mode, receiver.scale, texel, 1.0 - ndc.z);
}

// The light's filtered visibility at a world position, cascades chosen and blended as Bevy does.
fn filtered_directional_visibility(
    moments: texture_2d_array<f32>,
    receiver: FilteredReceiver,
    position: vec3<f32>,
    normal: vec3<f32>,
    dp: mat2x3<f32>,
) -> f32 {
    let light_id = receiver.mode.x;
    let light = &view_bindings::lights.directional_lights[light_id];
    let view = view_bindings::view.view_from_world;
    let view_z = dot(vec4(view[0].z, view[1].z, view[2].z, view[3].z), vec4(position, 1.0));
    var cascade_index = (*light).num_cascades;
    for (var i = 0u; i < (*light).num_cascades; i += 1u) {
        if -view_z < (*light).cascades[i].far_bound {
            cascade_index = i;
            break;
        }
    }
    if cascade_index >= (*light).num_cascades {
        return 1.0;
    }
    var visibility = filtered_cascade(moments, receiver, light_id, cascade_index, position, normal, dp);
    let next = cascade_index + 1u;
    if next < (*light).num_cascades {
        let far = (*light).cascades[cascade_index].far_bound;
        let near_next = (1.0 - (*light).cascades_overlap_proportion) * far;
        if -view_z >= near_next {
            let v_next = filtered_cascade(moments, receiver, light_id, next, position, normal, dp);
            visibility = mix(visibility, v_next, (-view_z - near_next) / (far - near_next));
        }
    }
    return visibility;
}

// The spot light's axis reversed (its view's z axis, pointing back towards the light):
// `fetch_spot_shadow`'s `fwd`.
fn spot_backward(id: u32) -> vec3<f32> {
    let light = &view_bindings::clustered_lights.data[id];
    var spot_dir = vec3((*light).light_custom_data.x, 0.0, (*light).light_custom_data.y);
    spot_dir.y = sqrt(max(0.0, 1.0 - spot_dir.x * spot_dir.x - spot_dir.z * spot_dir.z));
    if ((*light).flags & POINT_LIGHT_FLAGS_SPOT_LIGHT_Y_NEGATIVE) != 0u {
        spot_dir.y = -spot_dir.y;
    }
    return -spot_dir;
}

// Where a world offset from the receiver lands in spot light `id`'s map: Bevy's spot projection
// (`fetch_spot_shadow`) of `offset` (the receiver's position, biased, minus the light's), as
// (uv, distance along the spot's axis).
fn spot_uv(id: u32, offset: vec3<f32>) -> vec3<f32> {
    let light = &view_bindings::clustered_lights.data[id];
    let projected = offset * orthonormalize(spot_backward(id));
    let distance = -projected.z;
    let ndc = projected.xy / ((*light).spot_light_tan_angle * max(distance, 1e-6));
    return vec3(ndc * vec2(0.5, -0.5) + 0.5, distance);
}

// The spot light's filtered visibility at a world position: Bevy's depth and normal biases and
// projection, the pixel's footprint in the map (`dp` as for the cascades; the perspective
// projection is taken as linear across one pixel), the receiver's depth as the map's
// (`filter::DepthSource::Spot`: distance along the axis over the range).
fn filtered_spot_visibility(
    moments: texture_2d_array<f32>,
    receiver: FilteredReceiver,
    position: vec3<f32>,
    normal: vec3<f32>,
    dp: mat2x3<f32>,
) -> f32 {
    let id = receiver.spot_mode.x;
    let light = &view_bindings::clustered_lights.data[id];
    let surface_to_light = (*light).position_radius.xyz - position;
    let backward = spot_backward(id);
    let distance_to_light = dot(backward, surface_to_light);
    let offset = -surface_to_light
        + (*light).shadow_depth_bias * normalize(surface_to_light)
        + normal * (*light).shadow_normal_bias * distance_to_light;
    let at = spot_uv(id, offset);
    if at.z <= 0.0 || any(at.xy < vec2(0.0)) || any(at.xy > vec2(1.0)) {
        return 1.0;
    }
    let size = vec2<f32>(textureDimensions(moments, 0));
    let across = (spot_uv(id, offset + dp[0]).xy - at.xy) * size;
    let down = (spot_uv(id, offset + dp[1]).xy - at.xy) * size;
    let footprint = max(length(across), length(down));
    let texel = sample_moments(moments, receiver.spot_mode.z, 0, at.xy, footprint);
    return texel_visibility(receiver.spot_mode, receiver.spot_scale, texel, at.z / receiver.spot_scale.w);
}

// `color` with the directional light's shadow term replaced by its filtered visibility (see
// `apply_filtered_shadow`).
// `transmittance` multiplies the visibility (the trees' opacity shadow map's, 1 for none).
fn apply_filtered_directional_shadow(
    pbr_input: PbrInput,
    color: vec4<f32>,
    frag_xy: vec2<f32>,
    dp: mat2x3<f32>,
    moments: texture_2d_array<f32>,
    receiver: FilteredReceiver,
    transmittance: f32,
) -> vec4<f32> {
    let light_id = receiver.mode.x;
    if light_id == NO_MAP || light_id >= view_bindings::lights.n_directional_lights
        || (pbr_input.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) == 0u {
        return color;
    }
    let visibility = filtered_directional_visibility(
        moments, receiver, pbr_input.world_position.xyz, pbr_input.world_normal, dp);
    return apply_directional_visibility(pbr_input, color, light_id, frag_xy, visibility * transmittance);
}

// `color` with the spot light's shadow term replaced by its filtered visibility (see
// `apply_filtered_shadow`).
fn apply_filtered_spot_shadow(
    pbr_input: PbrInput,
    color: vec4<f32>,
    frag_xy: vec2<f32>,
    dp: mat2x3<f32>,
    spot_moments: texture_2d_array<f32>,
    receiver: FilteredReceiver,
) -> vec4<f32> {
    let id = receiver.spot_mode.x;
    if id == NO_MAP || (pbr_input.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) == 0u {
        return color;
    }
    let visibility = filtered_spot_visibility(
        spot_moments, receiver, pbr_input.world_position.xyz, pbr_input.world_normal, dp);
    return apply_spot_visibility(pbr_input, color, id, frag_xy, visibility);
}

// `color` (Bevy's lighting of `pbr_input`) with the served lights' shadow terms replaced by
// their filtered visibilities — the directional light's and the spot light's; each unchanged
// where its map was not made this frame, and both where the mesh receives no shadows.
fn apply_filtered_shadow(
    pbr_input: PbrInput,
    color: vec4<f32>,
    frag_xy: vec2<f32>,
    dp: mat2x3<f32>,
    moments: texture_2d_array<f32>,
    spot_moments: texture_2d_array<f32>,
    receiver: FilteredReceiver,
) -> vec4<f32> {
    let lit = apply_filtered_directional_shadow(pbr_input, color, frag_xy, dp, moments, receiver, 1.0);
    return apply_filtered_spot_shadow(pbr_input, lit, frag_xy, dp, spot_moments, receiver);
}
