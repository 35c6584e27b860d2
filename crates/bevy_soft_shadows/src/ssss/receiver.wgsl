// A StandardMaterial receiving the suite's shadows: Bevy's lighting with the SSSS visibility at
// this fragment's pixel as the SSSS light's shadow term (receiver_functions.wgsl), and the
// filterable shadow maps' visibilities as their lights' (filtered_receiver.wgsl) — where SSSS is
// active, for a filtered spot light other than the SSSS light only. The trees' opacity shadow
// map (opacity_receiver.wgsl) multiplies its sun's shadow term, whichever of the three it is.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, apply_pbr_lighting, main_pass_post_lighting_processing},
    pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT,
    forward_io::{VertexOutput, FragmentOutput},
}
#import bevy_soft_shadows::receiver_functions::{
    apply_directional_transmittance, apply_soft_shadow, soft_shadow_light, soft_visibility_at,
}
#import bevy_soft_shadows::filtered_receiver::{
    FilteredReceiver, apply_filtered_directional_shadow, apply_filtered_spot_shadow,
}
#import bevy_soft_shadows::opacity_receiver::{TreeOpacityReceiver, tree_transmittance}

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var soft_visibility: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var moments: texture_2d_array<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(102) var<storage, read> filtered: FilteredReceiver;
@group(#{MATERIAL_BIND_GROUP}) @binding(103) var spot_moments: texture_2d_array<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(104) var tree_map: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(105) var tree_sampler: sampler;
@group(#{MATERIAL_BIND_GROUP}) @binding(106) var<storage, read> tree: TreeOpacityReceiver;

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    // The pixel's footprint for the filtered map's mip, while control flow is still uniform.
    let dp = mat2x3(dpdx(in.world_position.xyz), dpdy(in.world_position.xyz));
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    var color = pbr_input.material.base_color;
    if (pbr_input.material.flags & STANDARD_MATERIAL_FLAGS_UNLIT_BIT) == 0u {
        color = apply_pbr_lighting(pbr_input);
        let transmittance = tree_transmittance(tree, tree_map, tree_sampler, in.world_position.xyz);
        // Whether the trees' transmittance still has to be applied to its light.
        var trees = transmittance < 1.0;
        let soft = soft_visibility_at(soft_visibility, in.position.xy);
        if soft.x >= 0.0 {
            var s = soft;
            // SSSS on the trees' sun: its visibility times the transmittance.
            if trees && soft.y == -1.0 && soft_shadow_light() == tree.light.x {
                s.x *= transmittance;
                trees = false;
            }
            color = apply_soft_shadow(pbr_input, color, in.position.xy, s);
            // SSSS's light is a spot light's clustered index i ≥ 0, or negative.
            if soft.y < 0.0 || u32(soft.y) != filtered.spot_mode.x {
                color = apply_filtered_spot_shadow(
                    pbr_input, color, in.position.xy, dp, spot_moments, filtered);
            }
        } else {
            var directional_transmittance = 1.0;
            if trees && filtered.mode.x == tree.light.x {
                directional_transmittance = transmittance;
                trees = false;
            }
            color = apply_filtered_directional_shadow(
                pbr_input, color, in.position.xy, dp, moments, filtered, directional_transmittance);
            color = apply_filtered_spot_shadow(
                pbr_input, color, in.position.xy, dp, spot_moments, filtered);
        }
        if trees {
            // The trees' sun keeps Bevy's shadow term, times the transmittance.
            color = apply_directional_transmittance(
                pbr_input, color, tree.light.x, in.position.xy, transmittance);
        }
    }
    var out: FragmentOutput;
    out.color = main_pass_post_lighting_processing(pbr_input, color);
    return out;
}
