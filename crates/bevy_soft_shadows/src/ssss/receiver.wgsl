// A StandardMaterial whose directional light's shadow term is Screen Space Soft Shadows.
//
// Bevy's lighting runs unchanged (`apply_pbr_lighting`, with the light's own shadow lookup);
// then the SSSS light's direct contribution D is re-weighted from Bevy's visibility v_b to the
// soft visibility v_s: colour += exposure · D · (v_s − v_b). That is exactly the lighting Bevy
// would compute had its shadow lookup returned v_s — a change of the light's shadow term, not a
// darkening of the image: ambient, emissive and other lights are untouched. The soft visibility
// is read from the SSSS passes' output at this fragment's pixel (-1 there: SSSS inactive).
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, apply_pbr_lighting, main_pass_post_lighting_processing,
        calculate_diffuse_color, calculate_F0, calculate_F0_dielectric},
    forward_io::{VertexOutput, FragmentOutput},
    mesh_view_bindings as view_bindings,
    mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT,
    lighting,
    shadows::fetch_directional_shadow,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var soft_visibility: texture_2d<f32>;

fn ssss_light() -> u32 {
    for (var i = 0u; i < view_bindings::lights.n_directional_lights; i += 1u) {
        if (view_bindings::lights.directional_lights[i].flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            return i;
        }
    }
    return 0xffffffffu;
}

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    var out: FragmentOutput;
    if (pbr_input.material.flags & STANDARD_MATERIAL_FLAGS_UNLIT_BIT) != 0u {
        out.color = pbr_input.material.base_color;
        out.color = main_pass_post_lighting_processing(pbr_input, out.color);
        return out;
    }
    out.color = apply_pbr_lighting(pbr_input);

    let light = ssss_light();
    let pixel = vec2<u32>(in.position.xy);
    let dims = textureDimensions(soft_visibility);
    if light != 0xffffffffu && (pbr_input.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) != 0u && all(pixel < dims) {
        let soft = textureLoad(soft_visibility, pixel, 0).r;
        if soft >= 0.0 {
            let view = view_bindings::view.view_from_world;
            let view_z = dot(vec4(view[0].z, view[1].z, view[2].z, view[3].z), pbr_input.world_position);
            let bevy_visibility = fetch_directional_shadow(
                light, pbr_input.world_position, pbr_input.world_normal, view_z, in.position.xy);
            // The base layer's lighting input, as `apply_pbr_lighting` builds it.
            let m = pbr_input.material;
            let roughness = lighting::perceptualRoughnessToRoughness(m.perceptual_roughness);
            let NdotV = max(dot(pbr_input.N, pbr_input.V), 0.0001);
            var input: lighting::LightingInput;
            input.layers[0].NdotV = NdotV;
            input.layers[0].N = pbr_input.N;
            input.layers[0].R = reflect(-pbr_input.V, pbr_input.N);
            input.layers[0].perceptual_roughness = m.perceptual_roughness;
            input.layers[0].roughness = roughness;
            input.P = pbr_input.world_position.xyz;
            input.V = pbr_input.V;
            input.diffuse_color = calculate_diffuse_color(
                m.base_color.rgb, m.metallic, m.specular_transmission, m.diffuse_transmission);
            input.metallic = m.metallic;
            input.F0_dielectric = calculate_F0_dielectric(m.reflectance);
            input.F0_metallic = m.base_color.rgb;
            input.F_ab = lighting::F_AB(m.perceptual_roughness, NdotV);
            let direct = lighting::directional_light(light, &input, true);
            out.color += vec4(view_bindings::view.exposure * direct * (soft - bevy_visibility), 0.0);
        }
    }
    out.color = main_pass_post_lighting_processing(pbr_input, out.color);
    return out;
}
