// Leaves lit as volumes (Boulanger 2008, ch. 5): the light the vertex stage computed for the
// leaf (`tree_lighting.wgsl`, in the vertex colour) times the material's base colour and texture,
// in place of Bevy's PBR lighting; alpha masking, exposure and Bevy's post-lighting steps (fog)
// as Bevy's own fragment stage does them. Used while `TreeLightingSettings::enabled`.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, main_pass_post_lighting_processing},
    forward_io::{VertexOutput, FragmentOutput},
    mesh_view_bindings::view,
}

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    // With VERTEX_COLORS, Bevy's input starts from the vertex colour (the leaf's light) and
    // multiplies in the material's base colour and texture.
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    let color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    var out: FragmentOutput;
    out.color = main_pass_post_lighting_processing(pbr_input, vec4(color.rgb * view.exposure, color.a));
    return out;
}
