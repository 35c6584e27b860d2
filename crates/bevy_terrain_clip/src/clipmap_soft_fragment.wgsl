// The terrain's fragment stage with screen-space soft shadows (bevy_soft_shadows) as the sun's
// shadow term. Used only when the material has a soft-visibility texture; it imports
// `bevy_soft_shadows::receiver_functions`, which that crate's plugin provides.
#import bevy_pbr::{
    forward_io::{VertexOutput, FragmentOutput},
    pbr_functions::main_pass_post_lighting_processing,
    pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT,
}
#import bevy_terrain_clip::clipmap::clipmap_pbr_input
#import bevy_soft_shadows::receiver_functions::apply_pbr_lighting_soft

@group(#{MATERIAL_BIND_GROUP}) @binding(105) var soft_visibility: texture_2d<f32>;

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    let pbr_input = clipmap_pbr_input(in, is_front);
    var out: FragmentOutput;
    if (pbr_input.material.flags & STANDARD_MATERIAL_FLAGS_UNLIT_BIT) == 0u {
        out.color = apply_pbr_lighting_soft(pbr_input, in.position.xy, soft_visibility);
    } else {
        out.color = pbr_input.material.base_color;
    }
    out.color = main_pass_post_lighting_processing(pbr_input, out.color);
    return out;
}
