// Grass blades in the main pass lit by Bevy's PBR lighting with screen-space soft shadows
// (bevy_soft_shadows) as the sun's shadow term: `grass_blade.wgsl`'s main-pass stage with
// `soft_shaded_color` in place of `apply_pbr_lighting`. Used only while the blade material holds
// a soft-visibility texture.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    forward_io::{VertexOutput, FragmentOutput},
}
#import bevy_soft_shadows::receiver_functions::soft_shaded_color
#import bevy_foliage::grass_blade::{blade, blade_kept}

@group(#{MATERIAL_BIND_GROUP}) @binding(102) var soft_visibility: texture_2d<f32>;

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    if !blade_kept(in.world_position.xyz, in.uv_b.x, in.position.xy) {
        discard;
    }
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    let h = clamp(in.uv_b.y, 0.0, 1.0);
    pbr_input.material.base_color = vec4(mix(blade.root_color.rgb, blade.tip_color.rgb, h), 1.0);
    pbr_input.diffuse_occlusion *= mix(blade.root_color.w, 1.0, h);
    var out: FragmentOutput;
    out.color = soft_shaded_color(pbr_input, in.position.xy, soft_visibility);
    return out;
}
