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
#import bevy_foliage::grass_blade::{blade, blade_kept, terrain_occlusion}
#import bevy_foliage::grass_blade_light::{shadow_mask_loss, shadow_mask_through, sun_visibility}

@group(#{MATERIAL_BIND_GROUP}) @binding(102) var soft_visibility: texture_2d<f32>;

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    if !blade_kept(in.world_position.xyz, in.uv_b.x, in.position.xy) {
        discard;
    }
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    let h = clamp(in.uv_b.y, 0.0, 1.0);
    pbr_input.material.base_color = vec4(mix(blade.root_color.rgb, blade.tip_color.rgb, h), 1.0);
    pbr_input.diffuse_occlusion *=
        mix(blade.root_color.w, 1.0, h) * terrain_occlusion(in.world_position.xyz);
    var out: FragmentOutput;
    var color = apply_pbr_lighting_soft(pbr_input, in.position.xy, soft_visibility);
    // The neighbours' shadows (§4.2.6, eq. 4.7), under the soft shadow term where SSSS is active.
    let through = shadow_mask_through(pbr_input);
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
