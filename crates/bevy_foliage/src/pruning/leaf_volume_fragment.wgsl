// Leaves lit as volumes (Boulanger 2008, ch. 5): the light the vertex stage computed for the
// leaf (`tree_lighting.wgsl`) times the material's base colour and texture, in place of Bevy's
// PBR lighting; alpha masking, exposure and Bevy's post-lighting steps (fog) as Bevy's own
// fragment stage does them. Used while `TreeLightingSettings::enabled`.
//
// The sun's share at the leaf. Where Bevy's shadow map of the sun resolves leaves (its texels at
// most a sixteenth of the leaf's size) it is read at the leaf itself: leaf-on-leaf shadows and
// whatever else stands in the way. Measured against a path tracer's shadow rays on the four
// procedural trees (`lighting::sun_maps`, `tree_lighting_error --sun-maps`), such a map is
// 20–31 % off per leaf where the eight baked attenuations' blend is 45–69 %; at texels of an
// eighth of a leaf the two are alike, and coarser maps are worse. So where the texels grow to an
// eighth of a leaf the baked blend takes over, times the shadow map read where the sun's light
// enters the crown (on the plane touching its bounding sphere on the sun's side: what stands
// outside the crown, the crown's own leaves not counted twice), with a smooth hand-over
// between. At the leaf the map is read by one bilinear comparison at the point moved towards the
// sun by a texel and more the steeper the leaf is to the sun (a slope-scaled bias: less and
// steep leaves shade themselves in stripes, more and the leaf in front lets the sun through),
// not through Bevy's filter and biases, which are made for surfaces: a filter several texels
// wide blurs the crown's sunflecks into their shade.
// The bounce, which is sunlight on the neighbours, takes the outside shadow alone.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, main_pass_post_lighting_processing},
    forward_io::{VertexOutput, FragmentOutput},
    mesh_view_bindings as view_bindings,
    mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    shadows::{fetch_directional_shadow, get_cascade_index, world_to_directional_light_local},
    shadow_sampling::sample_shadow_map_hardware,
}
#import bevy_foliage::leaf_pulling::leaf_params
#import bevy_foliage::tree_lighting::TreeLitVertexOutput

// How the shadow map is read at the leaf, measured in `lighting::sun_maps`: the point moved
// towards the sun by `LEAF_SHADOW_TEXELS + LEAF_SHADOW_SLOPE · min(tan θ, LEAF_SHADOW_MAX_SLOPE)`
// texels, θ the leaf's tilt from the sun (`LeafShadowOffset::SHADERS`); the map alone at texels
// up to `LEAF_SHADOW_FINE` of the leaf's size, the baked blend alone from `LEAF_SHADOW_COARSE`.
const LEAF_SHADOW_TEXELS: f32 = 1.0;
const LEAF_SHADOW_SLOPE: f32 = 0.5;
const LEAF_SHADOW_MAX_SLOPE: f32 = 4.0;
const LEAF_SHADOW_FINE: f32 = 0.0625;
const LEAF_SHADOW_COARSE: f32 = 0.125;

// The sun as Bevy's shadow map sees the leaf at `p` (normal `n`): the shadow term where the
// sun's light enters the crown (`reach` towards the sun), at the leaf itself, and how much the
// latter is to be trusted (1 where the map's texels are at most `LEAF_SHADOW_FINE` of
// `leaf_size`, 0 from `LEAF_SHADOW_COARSE` up). No shadow map: all light, no trust.
struct SunShadow {
    outside: f32,
    at_leaf: f32,
    trust: f32,
}

fn view_depth(p: vec3<f32>) -> f32 {
    let view = view_bindings::view.view_from_world;
    return dot(vec4(view[0].z, view[1].z, view[2].z, view[3].z), vec4(p, 1.0));
}

fn sun_shadow(p: vec3<f32>, n: vec3<f32>, reach: f32, leaf_size: f32, frag_xy: vec2<f32>, flags: u32) -> SunShadow {
    var out = SunShadow(1.0, 1.0, 0.0);
    if (flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) == 0u {
        return out;
    }
    // Bevy's light of the sun the CPU chose (the brightest directional light).
    let to_sun = leaf_params.lights.to_sun.xyz;
    for (var i = 0u; i < view_bindings::lights.n_directional_lights; i += 1u) {
        let light = &view_bindings::lights.directional_lights[i];
        if dot((*light).direction_to_light, to_sun) < 0.9999 {
            continue;
        }
        if ((*light).flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) == 0u {
            return out;
        }
        let l = (*light).direction_to_light;
        let entry = p + l * reach;
        out.outside = fetch_directional_shadow(i, vec4(entry, 1.0), l, view_depth(entry), frag_xy);
        let z = view_depth(p);
        let cascade = get_cascade_index(i, z);
        if cascade < (*light).num_cascades {
            let texel = (*light).cascades[cascade].texel_size;
            out.trust = 1.0 - smoothstep(LEAF_SHADOW_FINE * leaf_size, LEAF_SHADOW_COARSE * leaf_size, texel);
            if out.trust > 0.0 {
                let c = max(abs(dot(normalize(n), l)), 1e-3);
                let slope = min(sqrt(max(1.0 - c * c, 0.0)) / c, LEAF_SHADOW_MAX_SLOPE);
                let offset = (LEAF_SHADOW_TEXELS + LEAF_SHADOW_SLOPE * slope) * texel;
                let moved = vec4(p + l * offset, 1.0);
                let local = world_to_directional_light_local(i, cascade, moved);
                // Outside the cascade's volume nothing is known to shade the leaf (Bevy's answer).
                if local.w != 0.0 {
                    out.at_leaf = sample_shadow_map_hardware(
                        local.xy, local.z, i32((*light).depth_texture_base_index + cascade));
                }
            }
        }
        return out;
    }
    return out;
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
    let shadow = sun_shadow(
        in.world_position.xyz,
        in.world_normal,
        in.through_reach_size.y,
        in.through_reach_size.z,
        in.position.xy,
        pbr_input.flags,
    );
    let through = mix(in.through_reach_size.x * shadow.outside, shadow.at_leaf, shadow.trust);
    let light = (in.sky + in.sun * through + in.bounce * shadow.outside) * base.rgb;
    var out: FragmentOutput;
    out.color = main_pass_post_lighting_processing(
        pbr_input, vec4(light * view_bindings::view.exposure, base.a));
    return out;
}
