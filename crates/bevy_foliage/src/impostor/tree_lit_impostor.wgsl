// A billboard cloud lit as a volume of leaves (Boulanger 2008, §5.2–5.4), per fragment: a texel
// showing a leaf gets the light the tree lighting gives that leaf — its eight baked attenuations
// (the light atlases), its normal (the normal atlas) and its albedo as the leaf's optics — from
// `bevy_foliage::tree_lighting::leaf_radiance`, the function the leaves' vertex stage calls; a
// texel showing bark gets Bevy's PBR, as the bark near the camera does. `impostor::tree_lit` is
// the Rust side; `lighting::model::leaf_radiance` on the texel's values the CPU reference.
//
// The sun's share: the baked blend times Bevy's shadow map read where the sun's light enters the
// crown (on the plane touching the crown's bounding sphere on the sun's side, so the cloud's own
// planes, which cast into the map, are not counted twice). Impostors are drawn beyond the
// distance where the shadow map's texels still resolve leaves, where the leaves do the same.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, apply_pbr_lighting, main_pass_post_lighting_processing},
    forward_io::{VertexOutput, FragmentOutput},
    mesh_functions,
    mesh_view_bindings as view_bindings,
    mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    shadows::fetch_directional_shadow,
}
#import bevy_foliage::tree_lighting::{TreeLightUniform, covered_gain, hotspot_at, leaf_radiance, lights_of, optics_of, ratio_towards, ratio_with_ring, seen_gain}

struct TreeLitImpostorParams {
    lights: TreeLightUniform,
    // The crown's bounding sphere in model space (centre, radius).
    crown_sphere: vec4<f32>,
    extinction: f32,
    smooth_envelope: u32,
    bounce: u32,
    seen_part: u32,
    // The crown's mean seen-part gain per eye octant (`lighting::seen_part`).
    seen_gains: array<vec4<f32>, 2>,
    // The crown's hotspot (`lighting::hotspot`): the sun's exponent nodes, the bounce's.
    hotspot: vec4<u32>,
    // The crown's mean bounce ratios (`lighting::gathered_bounce`), front face's fourteen then
    // the back's, and whether the bounce takes them.
    bounce_ratios: array<vec4<f32>, 7>,
    gathered_bounce: u32,
    // The sun height of the crown's ring of re-gathered ratios (outside [−1, 1]: none), whether
    // it is read, and its mean ratios, front faces' fourteen nodes then the back faces'
    // (`lighting::bounce_ring::crown_mean_ring`).
    ring_height: f32,
    bounce_ring: u32,
    ring_ratios: array<vec4<f32>, 7>,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var<uniform> params: TreeLitImpostorParams;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var light0: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(102) var light_sampler: sampler;
@group(#{MATERIAL_BIND_GROUP}) @binding(103) var light1: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(104) var light2: texture_2d<f32>;

fn view_depth(p: vec3<f32>) -> f32 {
    let view = view_bindings::view.view_from_world;
    return dot(vec4(view[0].z, view[1].z, view[2].z, view[3].z), vec4(p, 1.0));
}

// Bevy's shadow map of the sun (the light the CPU chose) read at `p`; 1 with no shadow map.
fn sun_shadow_at(p: vec3<f32>, frag_xy: vec2<f32>, flags: u32) -> f32 {
    if (flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) == 0u {
        return 1.0;
    }
    for (var i = 0u; i < view_bindings::lights.n_directional_lights; i += 1u) {
        let light = &view_bindings::lights.directional_lights[i];
        if dot((*light).direction_to_light, params.lights.to_sun.xyz) < 0.9999 {
            continue;
        }
        if ((*light).flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) == 0u {
            return 1.0;
        }
        return fetch_directional_shadow(
            i, vec4(p, 1.0), (*light).direction_to_light, view_depth(p), frag_xy);
    }
    return 1.0;
}

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    var pbr_input = pbr_input_from_standard_material(in, is_front);
    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);
    let base = pbr_input.material.base_color;

    let l0 = textureSample(light0, light_sampler, in.uv).rgb;
    let l1 = textureSample(light1, light_sampler, in.uv).rgb;
    let l2 = textureSample(light2, light_sampler, in.uv).rgb;
    let leaf = clamp(l2.z, 0.0, 1.0);

    var color = vec3(0.0);
    if leaf < 1.0 {
        color = apply_pbr_lighting(pbr_input).rgb * (1.0 - leaf);
    }
    if leaf > 0.0 {
        // The tree's frame: the transpose undoes the instance's rotation and, normalised, its
        // uniform scale.
        let world_from_local = mesh_functions::get_world_from_local(in.instance_index);
        let local_from_world = transpose(mat3x3<f32>(
            world_from_local[0].xyz, world_from_local[1].xyz, world_from_local[2].xyz));
        let scale = (length(world_from_local[0].xyz) + length(world_from_local[1].xyz)
            + length(world_from_local[2].xyz)) / 3.0;
        let p = in.world_position.xyz;
        let to_eye = normalize(local_from_world * (view_bindings::view.world_position - p));
        let lights = lights_of(
            params.lights, normalize(local_from_world * params.lights.to_sun.xyz));
        let attenuation = array<f32, 8>(l0.x, l0.y, l0.z, l1.x, l1.y, l1.z, l2.x, l2.y);
        // Eq. 5.24 on each face by the crown's mean gathered ratios, towards the sun (a texel
        // has no room for its leaf's own) — or off the crown's mean ring where the sun is at
        // its elevation, as the leaves read theirs.
        var bounce_faces = vec2(1.0);
        if params.bounce != 0u && params.gathered_bounce != 0u {
            var ratios: array<f32, 28>;
            var ring: array<f32, 28>;
            for (var i = 0u; i < 28u; i += 1u) {
                ratios[i] = params.bounce_ratios[i / 4u][i % 4u];
                ring[i] = params.ring_ratios[i / 4u][i % 4u];
            }
            if params.bounce_ring != 0u {
                bounce_faces = ratio_with_ring(ratios, params.ring_height, ring, lights.to_sun);
            } else {
                bounce_faces = ratio_towards(ratios, lights.to_sun);
            }
        }
        let light = leaf_radiance(
            optics_of(params.lights, base.rgb),
            normalize(local_from_world * pbr_input.N),
            to_eye,
            attenuation,
            params.extinction,
            lights,
            params.smooth_envelope != 0u,
            params.bounce != 0u,
            bounce_faces,
        );
        // The leaves in view are more open than their mean (`lighting::seen_part`): the crown's
        // gain towards the eye on the sky and the blended sun, as the leaves have their own,
        // and the covered part's gain on the bounce.
        let g = params.seen_gains;
        let seen = select(1.0, seen_gain(
            array<f32, 8>(g[0].x, g[0].y, g[0].z, g[0].w, g[1].x, g[1].y, g[1].z, g[1].w), to_eye),
            params.seen_part != 0u);
        // The shadow of what stands outside the crown, read where the sun's light enters it.
        let p_local = local_from_world * (p - world_from_local[3].xyz) / (scale * scale);
        let reach = max(dot(params.crown_sphere.xyz - p_local, lights.to_sun)
            + params.crown_sphere.w, 0.0) * scale;
        let outside = sun_shadow_at(p + params.lights.to_sun.xyz * reach, in.position.xy, pbr_input.flags);
        // And the crown's hotspot by the eye's angle to the sun, with the gains.
        var through = min(light.through * seen, 1.0);
        var bounce = light.bounce;
        if params.seen_part != 0u {
            let cos_alpha = dot(to_eye, lights.to_sun);
            through = pow(through, hotspot_at(params.hotspot.xy, cos_alpha));
            bounce *= covered_gain(seen, light.open) * hotspot_at(params.hotspot.zw, cos_alpha);
        }
        let tree_lit = (light.sky * seen + light.sun * through * outside + bounce * outside)
            * view_bindings::view.exposure;
        color += tree_lit * leaf;
    }
    var out: FragmentOutput;
    out.color = main_pass_post_lighting_processing(pbr_input, vec4(color, base.a));
    return out;
}
