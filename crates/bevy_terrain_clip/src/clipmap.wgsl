// Terrain fragment stage sampling a clip stack (Seoane et al. 2007, paper 1).
//
// A fragment samples at its point p of the material's sampling space: its render-space (x, z)
// for a stack with a world mapping, the mesh's virtual-texture coordinates otherwise. Each
// layer's valid rectangle comes as the place of its min corner in that space (computed in f64
// on the CPU) and its size in level texels, so the level texel is t = (p − corner) / texel: a
// short offset, exact near the camera however far the texture's corner is. The finest windowed
// layer whose rectangle holds t is sampled at (t + corner's slot) / c with Repeat addressing
// (the toroidal slot); where no layer covers, the resident base level is. textureSampleLevel
// avoids derivatives, which jump across the toroidal wrap. CPU reference:
// `clip::stack::finest_covering_layer`.
//
// Where there is no data the terrain shows `clipmap.no_data`: outside the texture's [0, 1)²
// (Repeat addressing would show copies of it), and in proportion to a texel's transparency —
// the builder's padding and the base level's missing tiles are transparent black (a finer layer's
// missing subtile is outside its coverage, so a coarser layer shows), so a texel's colour is taken
// as premultiplied and the rest filled: rgb + (1 − a)·no_data (`clip::stack::over_no_data`).
//
// This module holds the bindings and the lookup; `clipmap_fragment.wgsl` (Bevy's shadows) and
// `clipmap_soft_fragment.wgsl` (screen-space soft shadows) are the fragment stages using it.
#define_import_path bevy_terrain_clip::clipmap

#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::alpha_discard,
    forward_io::VertexOutput,
    pbr_types::PbrInput,
}

struct ClipmapParams {
    // Windowed layer i (level base_level + 1 + i): its valid rectangle's min corner in sampling
    // space (xy) and size in level texels (zw).
    windows: array<vec4<f32>, 16>,
    // Layer i: the corner's level texel modulo c (xy), the level's texel size in sampling space (z).
    slots: array<vec4<f32>, 16>,
    // The texture's (0, 0) in sampling space, and its side.
    texture_origin: vec2<f32>,
    texture_size: f32,
    // 1: sampling space is render-space (x, z); 0: the mesh's uv.
    by_position: u32,
    base_level: u32,
    layer_count: u32,
    clip_size: f32,
    // Mip levels per layer to sample (1: mip 0 only).
    mips: u32,
    // Linear colour where there is no data.
    no_data: vec4<f32>,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var layers: texture_2d_array<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var layers_sampler: sampler;
@group(#{MATERIAL_BIND_GROUP}) @binding(102) var base: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(103) var base_sampler: sampler;
@group(#{MATERIAL_BIND_GROUP}) @binding(104) var<uniform> clipmap: ClipmapParams;


// `footprint` is the pixel's size in sampling space (taken outside the loop, in uniform control
// flow); in layer i it spans footprint / texel texels, which picks the mip.
fn sample_clip_stack(p: vec2<f32>, footprint: f32) -> vec4<f32> {
    let uv = (p - clipmap.texture_origin) / clipmap.texture_size;
    if any(uv < vec2(0.0)) || any(uv >= vec2(1.0)) {
        return clipmap.no_data;
    }
    return over_no_data(sample_resident(p, uv, footprint));
}

fn over_no_data(texel: vec4<f32>) -> vec4<f32> {
    return vec4(texel.rgb + (1.0 - texel.a) * clipmap.no_data.rgb, 1.0);
}

fn sample_resident(p: vec2<f32>, uv: vec2<f32>, footprint: f32) -> vec4<f32> {
    for (var i = i32(clipmap.layer_count) - 1; i >= 0; i -= 1) {
        let w = clipmap.windows[i];
        let s = clipmap.slots[i];
        let t = (p - w.xy) / s.z;
        if all(t >= vec2(0.0)) && all(t < w.zw) {
            let lod = clamp(log2(max(footprint / s.z, 1e-8)), 0.0, f32(clipmap.mips - 1u));
            return textureSampleLevel(layers, layers_sampler, (t + s.xy) / clipmap.clip_size, i, lod);
        }
    }
    let texels = footprint / clipmap.texture_size * exp2(f32(clipmap.base_level));
    let base_lod = select(0.0, max(log2(max(texels, 1e-8)), 0.0), clipmap.mips > 1u);
    return textureSampleLevel(base, base_sampler, uv, base_lod);
}

// The standard material's PBR input with the clip stack's colour as base colour.
fn clipmap_pbr_input(in: VertexOutput, is_front: bool) -> PbrInput {
    var pbr_input = pbr_input_from_standard_material(in, is_front);
#ifdef VERTEX_UVS_A
    let p = select(in.uv, in.world_position.xz, clipmap.by_position == 1u);
#else
    let p = in.world_position.xz;
#endif
    let footprint = max(length(dpdx(p)), length(dpdy(p)));
    pbr_input.material.base_color = pbr_input.material.base_color * sample_clip_stack(p, footprint);
    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    return pbr_input;
}
