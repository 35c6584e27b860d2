// Grass blades in the main pass lit by Bevy's PBR lighting with screen-space soft shadows
// (bevy_soft_shadows) as the sun's shadow term: `grass_blade.wgsl`'s main-pass stage with
// `soft_shaded_color` in place of `apply_pbr_lighting`. Used only while the blade material holds
// a soft-visibility texture.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::main_pass_post_lighting_processing,
    forward_io::{VertexOutput, FragmentOutput},
}
#import bevy_soft_shadows::receiver_functions::{apply_pbr_lighting_soft, soft_visibility_at}
#import bevy_foliage::grass_blade::{
    blade, BladeVertexOutput, blade_kept_at_density, density_here, forward_input,
}
#import bevy_foliage::grass_blade_light::{shadow_mask_loss, shadow_mask_through, sun_visibility}

@group(#{MATERIAL_BIND_GROUP}) @binding(102) var soft_visibility: texture_2d<f32>;

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
    let h = clamp(in.uv_b.y, 0.0, 1.0);
    pbr_input.material.base_color = vec4(mix(blade.root_color.rgb, blade.tip_color.rgb, h), 1.0);
    pbr_input.diffuse_occlusion *= mix(blade.root_color.w, 1.0, h) * terms.x;
    var out: FragmentOutput;
    var color = apply_pbr_lighting_soft(pbr_input, in.position.xy, soft_visibility);
    // The neighbours' shadows (§4.2.6, eq. 4.7), under the soft shadow term where SSSS is active.
    let through = shadow_mask_through(terms.y, ld);
    var loss = vec3(0.0);
    if through < 1.0 {
        let soft = soft_visibility_at(soft_visibility, in.position.xy);
        var visibility = 1.0;
        if soft.x >= 0.0 && soft.y < -0.5 && soft.y > -1.5 {
            visibility = soft.x;
        } else {
            visibility = sun_visibility(pbr_input, in.position.xy);
        }
        loss = shadow_mask_loss(pbr_input, visibility, through);
    }
    color = vec4(max(color.rgb - loss, vec3(0.0)), color.a);
    out.color = main_pass_post_lighting_processing(pbr_input, color);
    return out;
}
