// Leaves lit by Bevy's PBR lighting with screen-space soft shadows (bevy_soft_shadows) as the
// sun's shadow term. Used only for leaf materials holding a soft-visibility texture.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, main_pass_post_lighting_processing},
    forward_io::{VertexOutput, FragmentOutput},
    pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT,
}
#import bevy_soft_shadows::receiver_functions::apply_pbr_lighting_soft

@group(#{MATERIAL_BIND_GROUP}) @binding(107) var soft_visibility: texture_2d<f32>;

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    var out: FragmentOutput;
    if (pbr_input.material.flags & STANDARD_MATERIAL_FLAGS_UNLIT_BIT) != 0u {
        out.color = pbr_input.material.base_color;
    } else {
        out.color = apply_pbr_lighting_soft(pbr_input, in.position.xy, soft_visibility);
    }
    out.color = main_pass_post_lighting_processing(pbr_input, out.color);
    return out;
}
