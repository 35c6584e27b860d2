// Forward vertex stage of pruned leaves: pulls the kept leaf vertex and hands Bevy's PBR fragment
// stage an ordinary VertexOutput, so leaves receive Bevy's lighting and shadows. With the tree
// lighting (`TREE_LIGHTING`), the vertex also carries its leaf's light (`tree_lighting.wgsl`) in
// its own outputs, which `leaf_volume_fragment.wgsl` shows in place of Bevy's lighting.
#import bevy_pbr::forward_io::VertexOutput
#import bevy_foliage::leaf_pulling::{SlotVertex, pull_leaf_vertex}
#ifdef TREE_LIGHTING
#import bevy_pbr::{mesh_functions, mesh_view_bindings::view}
#import bevy_foliage::leaf_pulling::{PulledLeafVertex, leaf_attenuation, leaf_bounce_ratios, leaf_has_ring_shares, leaf_open_map, leaf_open_residual, leaf_params, leaf_ring_height, leaf_ring_hotspot, leaf_ring_ratios, leaf_ring_shares, leaf_seen_gains}
#import bevy_foliage::tree_lighting::{LeafLight, TreeLitVertexOutput, covered_gain, hotspot_at, leaf_radiance, lights_of, open_map_at, has_open_map, optics_of, ratio_towards, ratio_with_ring, ring_sun_at, seen_gain}

// The tree instance's frame, read once per vertex: world directions into the model's frame
// (the transpose undoes a rotation and, once normalised, a uniform scale), the instance's scale
// and the direction towards the sun in the model's frame.
struct TreeFrame {
    local_from_world: mat3x3<f32>,
    scale: f32,
    to_sun: vec3<f32>,
}

fn tree_frame(instance_index: u32) -> TreeFrame {
    let world_from_local = mesh_functions::get_world_from_local(instance_index);
    var frame: TreeFrame;
    frame.local_from_world = transpose(mat3x3<f32>(
        world_from_local[0].xyz, world_from_local[1].xyz, world_from_local[2].xyz));
    frame.scale = (length(world_from_local[0].xyz) + length(world_from_local[1].xyz)
        + length(world_from_local[2].xyz)) / 3.0;
    frame.to_sun = normalize(frame.local_from_world * leaf_params.lights.to_sun.xyz);
    return frame;
}

// A tree-lit leaf vertex: its light, and what the fragment needs to draw the sun from its
// leaf's sunlit shares on the ring (`ring_sun_at`; weight 0 where the blend stands).
struct LitLeafVertex {
    light: LeafLight,
    ring_sun: vec4<f32>,
    open_map: vec4<u32>,
    open_at: vec2<f32>,
}

// The light leaf vertex `leaf` sends to the eye, worked out in the tree's frame for a leaf of
// the material's base colour, then divided by that colour (the fragment stage multiplies it
// back in with the texture).
fn tree_light(leaf: PulledLeafVertex, frame: TreeFrame) -> LitLeafVertex {
    let to_eye = normalize(frame.local_from_world * (view.world_position - leaf.world_position.xyz));
    let albedo = leaf_params.albedo.rgb;
    // Eq. 5.24 on each face scaled by what the leaf's own neighbours bring it
    // (`lighting::gathered_bounce`), blended towards the sun — or, where the sun is at the
    // elevation of the type's ring of ratios re-gathered while the app runs, read off the ring
    // (`lighting::bounce_ring`).
    var bounce_faces = vec2(1.0);
    if leaf_params.bounce != 0u && leaf_params.gathered_bounce != 0u {
        if leaf_params.bounce_ring != 0u {
            bounce_faces = ratio_with_ring(leaf_bounce_ratios(leaf.leaf),
                leaf_ring_height(leaf.leaf), leaf_ring_ratios(leaf.leaf), frame.to_sun);
        } else {
            bounce_faces = ratio_towards(leaf_bounce_ratios(leaf.leaf), frame.to_sun);
        }
    }
    var light = leaf_radiance(
        optics_of(leaf_params.lights, albedo),
        normalize(leaf.local_normal),
        to_eye,
        leaf_attenuation(leaf.leaf),
        leaf.extinction,
        lights_of(leaf_params.lights, frame.to_sun),
        leaf_params.smooth_envelope != 0u,
        leaf_params.bounce != 0u,
        bounce_faces,
    );
    // The part of the leaf in view is more open than its mean (`lighting::seen_part`): its sky,
    // and the sun where the crown's blend stands for it, scaled by the gain towards the eye;
    // its bounce, from the covered rest of the sphere, by the covered part's gain. Then the
    // crown's hotspot (`lighting::hotspot`) by the angle between the eye and the sun: the
    // blended sun raised to its exponent, the bounce scaled.
    var seen = 1.0;
    var sun_exponent = 1.0;
    var open_map = vec4(0u);
    var open_at = vec2(0.0);
    let cos_alpha = dot(to_eye, frame.to_sun);
    if leaf_params.seen_part != 0u {
        seen = seen_gain(leaf_seen_gains(leaf.leaf), to_eye);
        sun_exponent = hotspot_at(leaf.hotspot.xy, cos_alpha);
        // The sky from the leaf's map of its open share where it has one
        // (`lighting::open_map`): the residual gains towards the eye here, the cell under the
        // pixel in the fragment stage; the eight gains where not.
        let map = leaf_open_map(leaf.leaf);
        if has_open_map(map) {
            light.sky *= seen_gain(leaf_open_residual(leaf.leaf), to_eye);
            open_map = map;
            open_at = open_map_at(map, leaf.offset, leaf.leaf_radius);
        } else {
            light.sky *= seen;
        }
        light.through = pow(min(light.through * seen, 1.0), sun_exponent);
        light.bounce *= covered_gain(seen, light.open) * hotspot_at(leaf.hotspot.zw, cos_alpha);
    }
    // Where the sun is at the elevation of the type's ring and the ring holds the leaves'
    // sunlit shares traced for its suns (`lighting::sunlit_share`), those in place of the blend,
    // with the gain towards the eye and the hotspot fitted against them with the ring (the
    // bake's where it has none; `BounceRing::sun_exponent`): the sun where the shadow map does
    // not resolve leaves. Each share is read at the vertex along its slope across the leaf
    // (which side of the leaf a sunfleck's edge lights), the rasteriser carries it across the
    // leaf, and the fragment bends it by the gain's cap and the exponent (`through_on_ring`).
    var ring_sun = vec4(0.0, 1.0, 1.0, 0.0);
    if leaf_params.bounce_ring != 0u && leaf_has_ring_shares(leaf.leaf) {
        let across = leaf.offset / max(leaf.leaf_radius, 1e-6);
        let ring_spot = leaf_ring_hotspot(leaf.leaf);
        var ring_exponent = sun_exponent;
        if leaf_params.seen_part != 0u && all(ring_spot != vec2(0u)) {
            ring_exponent = hotspot_at(ring_spot, cos_alpha);
        }
        ring_sun = ring_sun_at(leaf_ring_height(leaf.leaf), leaf_ring_shares(leaf.leaf, across),
            seen, ring_exponent, frame.to_sun);
    }
    // A channel the base colour lacks sends no light either.
    let lacks = albedo <= vec3(0.0);
    let inverse = 1.0 / max(albedo, vec3(1e-6));
    light.sky = select(light.sky * inverse, vec3(0.0), lacks);
    light.sun = select(light.sun * inverse, vec3(0.0), lacks);
    light.bounce = select(light.bounce * inverse, vec3(0.0), lacks);
    return LitLeafVertex(light, ring_sun, open_map, open_at);
}

// How far the sun's light travels from the leaf vertex after entering the crown from outside:
// from the plane that touches the crown's bounding sphere on the sun's side, in world units.
// Every leaf of the crown lies behind that plane, so the sun's shadow map read there — even
// filtered over texels larger than the crown — sees only what stands outside the crown.
fn sun_reach(leaf: PulledLeafVertex, frame: TreeFrame) -> f32 {
    let t = max(
        dot(leaf.crown_sphere.xyz - leaf.local_position, frame.to_sun) + leaf.crown_sphere.w, 0.0);
    return t * frame.scale;
}

@vertex
fn vertex(in: SlotVertex) -> TreeLitVertexOutput {
    var out: TreeLitVertexOutput;
    let leaf = pull_leaf_vertex(in.instance_index, in.position);
    out.position = leaf.clip_position;
    if !leaf.kept {
        return out;
    }
    out.world_position = leaf.world_position;
    out.world_normal = leaf.world_normal;
    out.uv = leaf.uv;
    let frame = tree_frame(in.instance_index);
    let lit = tree_light(leaf, frame);
    let light = lit.light;
    out.ring_sun = lit.ring_sun;
    out.open_map = lit.open_map;
    out.open_at = lit.open_at;
    out.sky = light.sky;
    out.sun = light.sun;
    out.bounce = light.bounce;
    out.through_reach_size = vec3(
        light.through, sun_reach(leaf, frame), 2.0 * leaf.leaf_radius * frame.scale);
    out.instance_index = in.instance_index;
    return out;
}
#else
@vertex
fn vertex(in: SlotVertex) -> VertexOutput {
    var out: VertexOutput;
    let leaf = pull_leaf_vertex(in.instance_index, in.position);
    out.position = leaf.clip_position;
    if !leaf.kept {
        return out;
    }
    out.world_position = leaf.world_position;
    out.world_normal = leaf.world_normal;
#ifdef VERTEX_UVS_A
    out.uv = leaf.uv;
#endif
#ifdef VERTEX_OUTPUT_INSTANCE_INDEX
    out.instance_index = in.instance_index;
#endif
    return out;
}
#endif
