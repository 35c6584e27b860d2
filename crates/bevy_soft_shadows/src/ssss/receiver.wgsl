// A StandardMaterial receiving the suite's shadows: Bevy's lighting with the SSSS visibility at
// this fragment's pixel as the SSSS light's shadow term (receiver_functions.wgsl), or where SSSS
// is inactive, the filterable shadow map's visibility as its light's (filtered_receiver.wgsl).
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, apply_pbr_lighting, main_pass_post_lighting_processing},
    pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT,
    forward_io::{VertexOutput, FragmentOutput},
}
#import bevy_soft_shadows::receiver_functions::{apply_soft_shadow, soft_visibility_at}
#import bevy_soft_shadows::filtered_receiver::{FilteredReceiver, apply_filtered_shadow}

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var soft_visibility: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var moments: texture_2d_array<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(102) var<storage, read> filtered: FilteredReceiver;

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    // The pixel's footprint for the filtered map's mip, while control flow is still uniform.
    let dp = mat2x3(dpdx(in.world_position.xyz), dpdy(in.world_position.xyz));
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    var color = pbr_input.material.base_color;
    if (pbr_input.material.flags & STANDARD_MATERIAL_FLAGS_UNLIT_BIT) == 0u {
        color = apply_pbr_lighting(pbr_input);
        let soft = soft_visibility_at(soft_visibility, in.position.xy);
        if soft.x >= 0.0 {
            color = apply_soft_shadow(pbr_input, color, in.position.xy, soft);
        } else {
            color = apply_filtered_shadow(pbr_input, color, in.position.xy, dp, moments, filtered);
        }
    }
    var out: FragmentOutput;
    out.color = main_pass_post_lighting_processing(pbr_input, color);
    return out;
}
