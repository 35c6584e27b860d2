// A StandardMaterial whose SSSS light's shadow term is Screen Space Soft Shadows: Bevy's
// lighting with the SSSS visibility at this fragment's pixel (receiver_functions.wgsl).
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::alpha_discard,
    forward_io::{VertexOutput, FragmentOutput},
}
#import bevy_soft_shadows::receiver_functions::soft_shaded_color

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var soft_visibility: texture_2d<f32>;

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    var out: FragmentOutput;
    out.color = soft_shaded_color(pbr_input, in.position.xy, soft_visibility);
    return out;
}
