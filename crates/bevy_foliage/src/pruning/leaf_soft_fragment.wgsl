// Leaves lit by Bevy's PBR lighting with screen-space soft shadows (bevy_soft_shadows) as the
// sun's shadow term. Used only for leaf materials holding a soft-visibility texture.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::alpha_discard,
    forward_io::{VertexOutput, FragmentOutput},
}
#import bevy_soft_shadows::receiver_functions::soft_shaded_color

@group(#{MATERIAL_BIND_GROUP}) @binding(107) var soft_visibility: texture_2d<f32>;

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    var out: FragmentOutput;
    out.color = soft_shaded_color(pbr_input, in.position.xy, soft_visibility);
    return out;
}
