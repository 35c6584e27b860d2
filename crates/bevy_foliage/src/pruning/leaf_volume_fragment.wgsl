// Leaves lit as volumes (Boulanger 2008, ch. 5): the light the vertex stage computed for the
// leaf (`tree_lighting.wgsl`) times the material's base colour and texture, in place of Bevy's
// PBR lighting; alpha masking, exposure and Bevy's post-lighting steps (fog) as Bevy's own
// fragment stage does them. Used while `TreeLightingSettings::enabled`.
//
// The sun's share at the leaf. Where Bevy's shadow map of the sun resolves leaves (its texels at
// most `LEAF_SHADOW_FINE` of the leaf's size) it is read at the leaf itself: leaf-on-leaf
// shadows and whatever else stands in the way. Where the texels grow to `LEAF_SHADOW_COARSE`
// of a leaf the vertex stage's share takes over (the leaf's sunlit shares on its type's ring
// where the sun is at the ring's elevation, the eight baked attenuations' blend where not), times the shadow map read where the
// sun's light enters the crown (on the plane touching its bounding sphere on the sun's side:
// what stands outside the crown, the crown's own leaves not counted twice), with a smooth
// hand-over between. Both sizes are measured against a path tracer on the procedural trees
// (`lighting::sun_maps`, `lighting::image_error`).
//
// At the leaf the map is read by a receiver-plane comparison: the four texels a bilinear lookup
// blends are loaded, and each is compared with the depth the leaf's own plane has at that
// texel's centre (a leaf is flat, so its depth across the map is exact), less a tenth of a
// texel. A leaf's own texels never shade it however tilted it is, and the leaf just in front of
// it is never let through, which a depth bias growing with the texel does (a slope-scaled bias
// brightens the sun on the crown by 13–24 % at texels a quarter of a leaf; the receiver plane
// is within 3.3 %), so the map is read at the leaf up to texels half a leaf wide. Bevy's filters and biases are made for surfaces: a filter several texels wide
// blurs the crown's sunflecks into their shade.
// The bounce, which is sunlight on the neighbours, takes the outside shadow alone.
#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, main_pass_post_lighting_processing},
    forward_io::{VertexOutput, FragmentOutput},
    mesh_view_bindings as view_bindings,
    mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    shadows::{fetch_directional_shadow, get_cascade_index, world_to_directional_light_local},
}
#import bevy_foliage::leaf_pulling::leaf_params
#import bevy_foliage::tree_lighting::{TreeLitVertexOutput, open_map_gain, through_on_ring}

// How the shadow map is read at the leaf, measured in `lighting::sun_maps`
// (`LeafShadowPlane::SHADERS`): the slack, in texels, by which a texel's nearest leaf may lie in
// front of the leaf's plane and still count as the leaf, and the steepest depth gradient
// (tan θ, θ the leaf's tilt from the sun) the plane follows; the map alone at texels up to
// `LEAF_SHADOW_FINE` of the leaf's size, the baked blend alone from `LEAF_SHADOW_COARSE`.
const LEAF_SHADOW_SLACK: f32 = 0.1;
const LEAF_SHADOW_MAX_SLOPE: f32 = 4.0;
const LEAF_SHADOW_FINE: f32 = 0.5;
const LEAF_SHADOW_COARSE: f32 = 1.0;

// The sun as Bevy's shadow map sees the leaf at `p` (unit plane normal `n`): the shadow term
// where the sun's light enters the crown (`reach` towards the sun), at the leaf itself, and how
// much the latter is to be trusted (1 where the map's texels are at most `LEAF_SHADOW_FINE` of
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

fn shadow_depth(texel: vec2<i32>, array_index: i32) -> f32 {
#ifdef NO_ARRAY_TEXTURES_SUPPORT
    return textureLoad(view_bindings::directional_shadow_textures, texel, 0);
#else
    return textureLoad(view_bindings::directional_shadow_textures, texel, array_index, 0);
#endif
}

// The receiver-plane comparison (`FoliageMaps::shadow_map_receiver_plane`) in cascade `cascade`
// of directional light `light_id` (towards `l`, texels `texel` wide) at point `p` of a leaf with
// unit normal `n`: 1 lit, 0 shaded, bilinear between the four texels. Outside the cascade's
// volume nothing is known to shade the leaf (Bevy's answer).
fn leaf_shadow_receiver_plane(
    light_id: u32,
    cascade: u32,
    p: vec3<f32>,
    n: vec3<f32>,
    l: vec3<f32>,
    texel: f32,
) -> f32 {
    let light = &view_bindings::lights.directional_lights[light_id];
    let local = world_to_directional_light_local(light_id, cascade, vec4(p, 1.0));
    if local.w == 0.0 {
        return 1.0;
    }
    // The plane's depth away from the sun per unit of sideways displacement d (d ⟂ l):
    // n·(d + h·l) = 0 gives h = −n·d / n·l, so the depth away is G·d with G = n⊥ / (n·l),
    // its length tan θ capped.
    let nl = dot(n, l);
    let n_perp = n - nl * l;
    var g = n_perp / select(max(abs(nl), 1e-4), -max(abs(nl), 1e-4), nl < 0.0);
    let slope = length(g);
    if slope > LEAF_SHADOW_MAX_SLOPE {
        g *= LEAF_SHADOW_MAX_SLOPE / slope;
    }
    // The cascade's orthographic projection: its first two rows are the map's axes scaled to
    // NDC, its third the depth (Bevy's is reversed: nearer the sun is larger, compared with
    // `GreaterEqual`). Moving h towards the sun adds `k·h` to the depth, and a change of uv
    // by (Δu, Δv) is the sideways displacement 2Δu·r0/|r0|² − 2Δv·r1/|r1|² (NDC y is flipped).
    let m = (*light).cascades[cascade].clip_from_world;
    let r0 = vec3(m[0].x, m[1].x, m[2].x);
    let r1 = vec3(m[0].y, m[1].y, m[2].y);
    let r2 = vec3(m[0].z, m[1].z, m[2].z);
    let k = dot(r2, l);
    let dz_duv = -k * vec2(2.0 * dot(g, r0) / dot(r0, r0), -2.0 * dot(g, r1) / dot(r1, r1));
    let slack = LEAF_SHADOW_SLACK * texel * k;
    let size = vec2<f32>(textureDimensions(view_bindings::directional_shadow_textures).xy);
    let array_index = i32((*light).depth_texture_base_index + cascade);
    let q = local.xy * size - 0.5;
    let base = floor(q);
    let f = q - base;
    var lit = 0.0;
    for (var k_y = 0; k_y < 2; k_y += 1) {
        for (var k_x = 0; k_x < 2; k_x += 1) {
            let at = base + vec2(f32(k_x), f32(k_y));
            let w = select(1.0 - f.x, f.x, k_x == 1) * select(1.0 - f.y, f.y, k_y == 1);
            // Texels off the map hold nothing (the CPU reference's answer too).
            var visible = 1.0;
            if all(at >= vec2(0.0)) && all(at < size) {
                let own = local.z + dot(dz_duv, (at + 0.5) / size - local.xy);
                visible = select(0.0, 1.0, own + slack >= shadow_depth(vec2<i32>(at), array_index));
            }
            lit += w * visible;
        }
    }
    return lit;
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
                out.at_leaf = leaf_shadow_receiver_plane(i, cascade, p, n, l, texel);
            }
        }
        return out;
    }
    return out;
}

@fragment
fn fragment(in: TreeLitVertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    // The leaf's plane from the position's derivatives (taken first, in uniform control flow):
    // the plane the shadow pass rasterised, whatever normals the leaf's mesh carries for its
    // shading; the mesh's normal where the derivatives degenerate.
    let across = cross(dpdx(in.world_position.xyz), dpdy(in.world_position.xyz));
    let plane_normal = select(
        normalize(in.world_normal), normalize(across), dot(across, across) > 1e-20);
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
        plane_normal,
        in.through_reach_size.y,
        in.through_reach_size.z,
        in.position.xy,
        pbr_input.flags,
    );
    // The crown's share of the sun where the map does not resolve leaves: the blend, or the
    // leaf's sunlit share on the ring here.
    let crown = through_on_ring(in.through_reach_size.x, in.ring_sun);
    let through = mix(crown * shadow.outside, shadow.at_leaf, shadow.trust);
    // The sky of the part of the leaf in view: the cell of the leaf's open map under the pixel.
    let sky = in.sky * open_map_gain(in.open_map, in.open_at);
    let light = (sky + in.sun * through + in.bounce * shadow.outside) * base.rgb;
    var out: FragmentOutput;
    out.color = main_pass_post_lighting_processing(
        pbr_input, vec4(light * view_bindings::view.exposure, base.a));
    return out;
}
