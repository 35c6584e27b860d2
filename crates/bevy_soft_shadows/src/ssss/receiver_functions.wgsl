#define_import_path bevy_soft_shadows::receiver_functions

// The SSSS light's shadow term inside Bevy's lighting, for any material built on
// `pbr_input_from_standard_material` + `apply_pbr_lighting` (the `SoftShadowMaterial`, the
// terrain clipmap and leaf materials, your own): where the fragment stage would call
// `apply_pbr_lighting(pbr_input)`, call
//
//     apply_pbr_lighting_soft(pbr_input, in.position.xy, visibility)
//
// (or `soft_shaded_color` for the whole tail: unlit check, lighting, post-lighting processing),
// with `visibility` the `SsssTextures::visibility` texture bound in the material (.r the soft
// visibility, negative where SSSS is inactive; .g which light), or `apply_soft_shadow` on an
// already lit colour. The light's direct contribution D is re-weighted from Bevy's
// visibility v_b to v_s: color += exposure · D · (v_s − v_b) — the lighting Bevy would compute
// had its shadow lookup returned v_s. Ambient, emissive and other lights are untouched.
#import bevy_pbr::{
    pbr_functions::{
        apply_pbr_lighting, calculate_diffuse_color, calculate_F0_dielectric,
        main_pass_post_lighting_processing,
    },
    pbr_types::{PbrInput, STANDARD_MATERIAL_FLAGS_UNLIT_BIT},
    mesh_view_bindings as view_bindings,
    mesh_view_types::{DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT, POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT},
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    lighting,
    shadows::{fetch_directional_shadow, fetch_point_shadow, fetch_spot_shadow},
}

// A directional SSSS light: the first shadow-casting directional light.
fn soft_shadow_light() -> u32 {
    for (var i = 0u; i < view_bindings::lights.n_directional_lights; i += 1u) {
        if (view_bindings::lights.directional_lights[i].flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            return i;
        }
    }
    return 0xffffffffu;
}

// The base layer's lighting input, as `apply_pbr_lighting` builds it.
fn lighting_input(pbr_input: PbrInput) -> lighting::LightingInput {
    let m = pbr_input.material;
    let NdotV = max(dot(pbr_input.N, pbr_input.V), 0.0001);
    var input: lighting::LightingInput;
    input.layers[0].NdotV = NdotV;
    input.layers[0].N = pbr_input.N;
    input.layers[0].R = reflect(-pbr_input.V, pbr_input.N);
    input.layers[0].perceptual_roughness = m.perceptual_roughness;
    input.layers[0].roughness = lighting::perceptualRoughnessToRoughness(m.perceptual_roughness);
    input.P = pbr_input.world_position.xyz;
    input.V = pbr_input.V;
    input.diffuse_color = calculate_diffuse_color(
        m.base_color.rgb, m.metallic, m.specular_transmission, m.diffuse_transmission);
    input.metallic = m.metallic;
    input.F0_dielectric = calculate_F0_dielectric(m.reflectance);
    input.F0_metallic = m.base_color.rgb;
    input.F_ab = lighting::F_AB(m.perceptual_roughness, NdotV);
    return input;
}

// Directional light `light`'s unshadowed direct contribution to `pbr_input` times the view's
// exposure (xyz), and Bevy's own shadow visibility v_b for it (w): what both re-weightings
// below start from.
fn directional_direct_and_visibility(pbr_input: PbrInput, light: u32, frag_xy: vec2<f32>) -> vec4<f32> {
    var input = lighting_input(pbr_input);
    let view = view_bindings::view.view_from_world;
    let view_z = dot(vec4(view[0].z, view[1].z, view[2].z, view[3].z), pbr_input.world_position);
    let bevy_visibility = fetch_directional_shadow(
        light, pbr_input.world_position, pbr_input.world_normal, view_z, frag_xy);
    let direct = lighting::directional_light(light, &input, true);
    return vec4(view_bindings::view.exposure * direct, bevy_visibility);
}

// `color` (Bevy's lighting of `pbr_input`) with directional light `light`'s shadow term
// replaced by `visibility`: its direct contribution D re-weighted from Bevy's visibility v_b,
// color += exposure · D · (visibility − v_b). For any shadow term computed outside Bevy's
// lookup (SSSS, filterable shadow maps).
fn apply_directional_visibility(
    pbr_input: PbrInput,
    color: vec4<f32>,
    light: u32,
    frag_xy: vec2<f32>,
    visibility: f32,
) -> vec4<f32> {
    if (pbr_input.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) == 0u
        || (view_bindings::lights.directional_lights[light].flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) == 0u {
        return color;
    }
    let d = directional_direct_and_visibility(pbr_input, light, frag_xy);
    return color + vec4(d.xyz * (visibility - d.w), 0.0);
}

// `color` (Bevy's lighting of `pbr_input`) with directional light `light`'s shadow term
// multiplied by `transmittance` (the trees' opacity shadow map's): Bevy's own visibility v_b
// stays, color += exposure · D · v_b · (transmittance − 1).
fn apply_directional_transmittance(
    pbr_input: PbrInput,
    color: vec4<f32>,
    light: u32,
    frag_xy: vec2<f32>,
    transmittance: f32,
) -> vec4<f32> {
    if light >= view_bindings::lights.n_directional_lights
        || (pbr_input.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) == 0u
        || (view_bindings::lights.directional_lights[light].flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) == 0u {
        return color;
    }
    let d = directional_direct_and_visibility(pbr_input, light, frag_xy);
    return color + vec4(d.xyz * d.w * (transmittance - 1.0), 0.0);
}

// `soft` is what `soft_visibility_at` read: (visibility, light), the light being a spot light's
// clustered index i, a point light's as −2 − i, or −1 for the directional light.
fn apply_soft_shadow(pbr_input: PbrInput, color: vec4<f32>, frag_xy: vec2<f32>, soft: vec2<f32>) -> vec4<f32> {
    if soft.x < 0.0 || (pbr_input.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) == 0u {
        return color;
    }
    if soft.y > -1.5 && soft.y < 0.0 {
        let light = soft_shadow_light();
        if light == 0xffffffffu {
            return color;
        }
        return apply_directional_visibility(pbr_input, color, light, frag_xy, soft.x);
    }
    var input = lighting_input(pbr_input);
    var bevy_visibility = 1.0;
    var direct = vec3(0.0);
    if soft.y <= -1.5 {
        // A point light: Bevy's `fetch_point_shadow` and `lighting::point_light`, as its
        // clustered light loop calls them.
        let id = u32(-soft.y - 2.0 + 0.5);
        let light = &view_bindings::clustered_lights.data[id];
        if ((*light).flags & POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) == 0u {
            return color;
        }
        bevy_visibility = fetch_point_shadow(
            id, pbr_input.world_position, pbr_input.world_normal, frag_xy);
        direct = lighting::point_light(id, &input, true, true);
    } else {
        return apply_spot_visibility(pbr_input, color, u32(soft.y), frag_xy, soft.x);
    }
    return color + vec4(view_bindings::view.exposure * direct * (soft.x - bevy_visibility), 0.0);
}

// `color` (Bevy's lighting of `pbr_input`) with spot light `id`'s (its index among the clustered
// lights) shadow term replaced by `visibility`, as `apply_directional_visibility` does for a
// directional light: Bevy's `fetch_spot_shadow` and `lighting::spot_light`, as its clustered
// light loop calls them, give v_b and D.
fn apply_spot_visibility(
    pbr_input: PbrInput,
    color: vec4<f32>,
    id: u32,
    frag_xy: vec2<f32>,
    visibility: f32,
) -> vec4<f32> {
    let light = &view_bindings::clustered_lights.data[id];
    if (pbr_input.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) == 0u
        || ((*light).flags & POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) == 0u {
        return color;
    }
    var input = lighting_input(pbr_input);
    let bevy_visibility = fetch_spot_shadow(
        id, pbr_input.world_position, pbr_input.world_normal, (*light).shadow_map_near_z, frag_xy);
    let direct = lighting::spot_light(id, &input, true);
    return color + vec4(view_bindings::view.exposure * direct * (visibility - bevy_visibility), 0.0);
}

// The SSSS (visibility, light) at a fragment (visibility negative — "inactive" — outside the
// texture).
fn soft_visibility_at(visibility: texture_2d<f32>, frag_xy: vec2<f32>) -> vec2<f32> {
    let pixel = vec2<u32>(frag_xy);
    if any(pixel >= textureDimensions(visibility)) {
        return vec2(-1.0);
    }
    return textureLoad(visibility, pixel, 0).rg;
}

// Bevy's PBR lighting with the SSSS visibility texture as the SSSS light's shadow term: what a
// receiving material's fragment stage calls where it would call `apply_pbr_lighting`.
fn apply_pbr_lighting_soft(pbr_input: PbrInput, frag_xy: vec2<f32>, visibility: texture_2d<f32>) -> vec4<f32> {
    return apply_soft_shadow(
        pbr_input, apply_pbr_lighting(pbr_input), frag_xy, soft_visibility_at(visibility, frag_xy));
}

// A receiving material's main-pass colour from its `PbrInput`: unlit materials keep their base
// colour, lit ones get `apply_pbr_lighting_soft`, then Bevy's post-lighting processing — the
// tail of Bevy's own PBR fragment stage, with the SSSS shadow term.
fn soft_shaded_color(pbr_input: PbrInput, frag_xy: vec2<f32>, visibility: texture_2d<f32>) -> vec4<f32> {
    var color = pbr_input.material.base_color;
    if (pbr_input.material.flags & STANDARD_MATERIAL_FLAGS_UNLIT_BIT) == 0u {
        color = apply_pbr_lighting_soft(pbr_input, frag_xy, visibility);
    }
    return main_pass_post_lighting_processing(pbr_input, color);
}
