// Terrain fragment stage sampling a clip stack (Seoane et al. 2007, paper 1).
//
// The mesh's first texture coordinates are virtual-texture coordinates, computed on the CPU in
// f64 (exact far from the world origin). Level texel t = uv * 2^level. The finest windowed layer
// whose coverage rectangle holds t is sampled at t / c with Repeat addressing (the toroidal
// slot); where no layer covers, the resident base level is. textureSampleLevel avoids
// derivatives, which jump across the toroidal wrap. CPU reference: `clip::stack::finest_covering_layer`.
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
    // Coverage of windowed layer i (level base_level + 1 + i), in level texels: min.xy, max.xy.
    coverage: array<vec4<f32>, 16>,
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


// `footprint` is the pixel's size in virtual-texture coordinates (taken outside the loop, in
// uniform control flow); in layer i it spans footprint * 2^level texels, which picks the mip.
fn sample_clip_stack(uv: vec2<f32>, footprint: f32) -> vec4<f32> {
    if any(uv < vec2(0.0)) || any(uv >= vec2(1.0)) {
        return clipmap.no_data;
    }
    return over_no_data(sample_resident(uv, footprint));
}

fn over_no_data(texel: vec4<f32>) -> vec4<f32> {
    return vec4(texel.rgb + (1.0 - texel.a) * clipmap.no_data.rgb, 1.0);
}

fn sample_resident(uv: vec2<f32>, footprint: f32) -> vec4<f32> {
    for (var i = i32(clipmap.layer_count) - 1; i >= 0; i -= 1) {
        let level = clipmap.base_level + 1u + u32(i);
        let scale = exp2(f32(level));
        let t = uv * scale;
        let c = clipmap.coverage[i];
        if all(t >= c.xy) && all(t < c.zw) {
            let lod = clamp(log2(max(footprint * scale, 1e-8)), 0.0, f32(clipmap.mips - 1u));
            return textureSampleLevel(layers, layers_sampler, t / clipmap.clip_size, i, lod);
        }
    }
    let base_lod = select(0.0, max(log2(max(footprint * exp2(f32(clipmap.base_level)), 1e-8)), 0.0), clipmap.mips > 1u);
    return textureSampleLevel(base, base_sampler, uv, base_lod);
}

// The standard material's PBR input with the clip stack's colour as base colour.
fn clipmap_pbr_input(in: VertexOutput, is_front: bool) -> PbrInput {
    var pbr_input = pbr_input_from_standard_material(in, is_front);
#ifdef VERTEX_UVS_A
    let footprint = max(length(dpdx(in.uv)), length(dpdy(in.uv)));
    pbr_input.material.base_color = pbr_input.material.base_color * sample_clip_stack(in.uv, footprint);
#endif
    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    return pbr_input;
}
