// Grass blades as geometry (Boulanger 2008, thesis §4.2.2, §4.2.4–4.2.6): the base patch's
// strips, Bevy's PBR lighting with diffuse transmission standing for eq. 4.1's γ, ambient
// occlusion rising with height, the blade shadow mask of eq. 4.7, and each fragment kept or not by its blade's density threshold
// and the geometry opacity of eq. 4.6, turned into coverage by an ordered dither. The prepass
// and shadow passes run the same test, so the blades' depth and shadows match what is drawn.
//
// `uv_b` carries (blade threshold, height fraction) per vertex (`grass::mesh`).
#import bevy_pbr::pbr_fragment::pbr_input_from_standard_material
#ifdef PREPASS_PIPELINE
#import bevy_pbr::prepass_io::{VertexOutput, FragmentOutput}
#ifdef MOTION_VECTOR_PREPASS
#import bevy_pbr::pbr_prepass_functions::calculate_motion_vector
#endif
#else
#import bevy_pbr::forward_io::{VertexOutput, FragmentOutput}
#import bevy_pbr::pbr_functions::{apply_pbr_lighting, main_pass_post_lighting_processing}
#endif
#import bevy_foliage::grass_blade::{blade, blade_kept}
#ifndef PREPASS_PIPELINE
#import bevy_foliage::grass_blade::{BladeVertexOutput, blade_kept_at_density, density_here, forward_input}
#endif
#ifndef PREPASS_PIPELINE
#import bevy_foliage::grass_blade_light::{shadow_mask_loss, shadow_mask_through, sun_visibility}
#endif

#ifdef PREPASS_PIPELINE
#ifdef PREPASS_FRAGMENT
@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    if !blade_kept(in.world_position.xyz, in.uv_b.x, in.position.xy) {
        discard;
    }
    var out: FragmentOutput;
#ifdef NORMAL_PREPASS
    let n = normalize(select(-in.world_normal, in.world_normal, is_front));
    out.normal = vec4(n * 0.5 + vec3(0.5), 1.0);
#endif
#ifdef UNCLIPPED_DEPTH_ORTHO_EMULATION
    out.frag_depth = in.unclipped_depth;
#endif
#ifdef MOTION_VECTOR_PREPASS
    out.motion_vector = calculate_motion_vector(in.world_position, in.previous_world_position);
#endif
    return out;
}
#else
@fragment
fn fragment(in: VertexOutput) {
    if !blade_kept(in.world_position.xyz, in.uv_b.x, in.position.xy) {
        discard;
    }
}
#endif
#else
@fragment
fn fragment(blade_in: BladeVertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    // The terrain's occlusion and the height the vertex stage read; the density, read once
    // here, for the blade test and the shadow mask.
    let terms = blade_in.terms;
    let in = forward_input(blade_in);
    let ld = density_here(in.world_position.xyz);
    if !blade_kept_at_density(in.world_position.xyz, in.uv_b.x, in.position.xy, ld) {
        discard;
    }
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    // kd rising from root to tip; the ambient term darkened by the blade's occlusion (eq. 4.1's
    // ao, §4.2.2) and the terrain's (§4.2.6), the direct light not.
    let h = clamp(in.uv_b.y, 0.0, 1.0);
    pbr_input.material.base_color = vec4(mix(blade.root_color.rgb, blade.tip_color.rgb, h), 1.0);
    let ao = mix(blade.root_color.w, 1.0, h) * terms.x;
    pbr_input.diffuse_occlusion *= ao;
    var out: FragmentOutput;
    out.color = apply_pbr_lighting(pbr_input);
    // The neighbours' shadows (§4.2.6, eq. 4.7).
    let through = shadow_mask_through(terms.y, ld);
    var loss = vec3(0.0);
    if through < 1.0 {
        loss = shadow_mask_loss(pbr_input, sun_visibility(pbr_input, in.position.xy), through);
    }
    out.color = vec4(max(out.color.rgb - loss, vec3(0.0)), out.color.a);
    out.color = main_pass_post_lighting_processing(pbr_input, out.color);
    return out;
}
#endif
