// Leaves lit as volumes (Boulanger 2008, ch. 5): the light the vertex stage computed for the
// leaf (`tree_lighting.wgsl`) times the material's base colour and texture, in place of Bevy's
// PBR lighting; alpha masking, exposure and Bevy's post-lighting steps (fog) as Bevy's own
// fragment stage does them. Used while `TreeLightingSettings::enabled`.
//
// The crown's own leaves shade the leaf through its baked attenuations; what stands outside the
// crown (another tree, a wall, the terrain) shades it through Bevy's shadow map of the sun, read
// where the sun's light enters the crown on its way to the leaf — on the crown's bounding sphere
// — so the crown's own leaves, already in the attenuations, are not counted twice.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, main_pass_post_lighting_processing},
    forward_io::{VertexOutput, FragmentOutput},
    mesh_view_bindings as view_bindings,
    mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    shadows::fetch_directional_shadow,
}
#import bevy_foliage::leaf_pulling::leaf_params
#import bevy_foliage::tree_lighting::TreeLitVertexOutput


// The sun's shadow term from outside the crown at `p`, reached over `reach` towards the sun.
fn outside_shadow(p: vec3<f32>, reach: f32, frag_xy: vec2<f32>, flags: u32) -> f32 {
    if (flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) == 0u {
        return 1.0;
    }
    // Bevy's light of the sun the CPU chose (the brightest directional light).
    let to_sun = leaf_params.to_sun.xyz;
    for (var i = 0u; i < view_bindings::lights.n_directional_lights; i += 1u) {
        let light = &view_bindings::lights.directional_lights[i];
        if dot((*light).direction_to_light, to_sun) < 0.9999 {
            continue;
        }
        if ((*light).flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) == 0u {
            return 1.0;
        }
        let entry = p + (*light).direction_to_light * reach;
        let view = view_bindings::view.view_from_world;
        let view_z = dot(vec4(view[0].z, view[1].z, view[2].z, view[3].z), vec4(entry, 1.0));
        return fetch_directional_shadow(i, vec4(entry, 1.0), (*light).direction_to_light, view_z, frag_xy);
    }
    return 1.0;
}

@fragment
fn fragment(in: TreeLitVertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    // Bevy's material input (base colour times texture, alpha) from the forward inputs.
    var forward: VertexOutput;
    forward.position = in.position;
    forward.world_position = in.world_position;
    forward.world_normal = in.world_normal;
#ifdef VERTEX_UVS_A
    forward.uv = in.uv;
#endif
#ifdef VERTEX_OUTPUT_INSTANCE_INDEX
    forward.instance_index = in.instance_index;
#endif
    var pbr_input = pbr_input_from_standard_material(forward, is_front);
    let base = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    let shadow = outside_shadow(in.world_position.xyz, in.sun_reach, in.position.xy, pbr_input.flags);
    let light = (in.sky + in.sun * shadow) * base.rgb;
    var out: FragmentOutput;
    out.color = main_pass_post_lighting_processing(
        pbr_input, vec4(light * view_bindings::view.exposure, base.a));
    return out;
}
