// The blades' vertex stage, for the main pass and the prepass (depth, normals, shadow maps): the
// base patch placed in its cell by the mesh transform (mirrored, eq. 4.9), then lifted onto the
// ground by eq. 4.10 and sheared by the wind (§4.2.7.4) — `grass_functions.wgsl`'s `on_ground`.
// Blades stay vertical on slopes, so their normals are the mesh's. Bevy's `mesh.wgsl` and
// `prepass.wgsl` otherwise, for meshes with positions, normals and two uv sets (no skins,
// morphs, tangents or colours).
#import bevy_pbr::{mesh_functions, view_transformations::position_world_to_clip}
#ifdef PREPASS_PIPELINE
#import bevy_pbr::prepass_io::{Vertex, VertexOutput}
#else
#import bevy_pbr::forward_io::{Vertex, VertexOutput}
#endif
#import bevy_foliage::grass_blade::{blade, ground_heights, wind_map}
#ifdef BLADE_TERMS
#import bevy_foliage::grass_blade::{BladeVertexOutput, terrain_occlusion_map}
#endif
#import bevy_foliage::grass_functions as grass

// A point of the base patch placed in its cell (`flat`, world) onto the ground and into the wind;
// the mesh's y is its height above the ground.
fn placed(flat: vec3<f32>, height: f32) -> vec4<f32> {
    return vec4(grass::on_ground(ground_heights, wind_map, blade.ground_wind, flat, height), 1.0);
}

#ifdef BLADE_TERMS
// The main pass: Bevy's forward outputs and what the fragments would otherwise read from
// textures, read once per vertex (`BladeVertexOutput::terms`): the terrain's occlusion where the
// blade stands and this point's height above the ground (the mesh's y).
@vertex
fn vertex(vertex: Vertex) -> BladeVertexOutput {
    var out: BladeVertexOutput;
    let world_from_local = mesh_functions::get_world_from_local(vertex.instance_index);
    let flat = mesh_functions::mesh_position_local_to_world(world_from_local, vec4(vertex.position, 1.0));
    let world = placed(flat.xyz, vertex.position.y);
    out.world_position = world;
    out.position = position_world_to_clip(world.xyz);
    out.world_normal = mesh_functions::mesh_normal_local_to_world(vertex.normal, vertex.instance_index);
    out.uv_b = vertex.uv_b;
    out.terms = vec2(
        grass::density_at(terrain_occlusion_map, blade.density_rect, flat.xz),
        vertex.position.y,
    );
    out.instance_index = vertex.instance_index;
#ifdef VISIBILITY_RANGE_DITHER
    out.visibility_range_dither = mesh_functions::get_visibility_range_dither_level(
        vertex.instance_index, world_from_local[3]);
#endif
    return out;
}
#else
@vertex
fn vertex(vertex: Vertex) -> VertexOutput {
    var out: VertexOutput;
    let world_from_local = mesh_functions::get_world_from_local(vertex.instance_index);
    let flat = mesh_functions::mesh_position_local_to_world(world_from_local, vec4(vertex.position, 1.0));
    let world = placed(flat.xyz, vertex.position.y);
    out.world_position = world;
    out.position = position_world_to_clip(world.xyz);
#ifdef UNCLIPPED_DEPTH_ORTHO_EMULATION
    out.unclipped_depth = out.position.z;
    out.position.z = min(out.position.z, 1.0);
#endif
#ifdef VERTEX_UVS_A
    out.uv = vertex.uv;
#endif
#ifdef VERTEX_UVS_B
    out.uv_b = vertex.uv_b;
#endif
#ifdef PREPASS_PIPELINE
#ifdef NORMAL_PREPASS_OR_DEFERRED_PREPASS
    out.world_normal = mesh_functions::mesh_normal_local_to_world(vertex.normal, vertex.instance_index);
#endif
#ifdef MOTION_VECTOR_PREPASS
    // The wind's sway is slow beside a frame: no motion vector for it.
    out.previous_world_position = world;
#endif
#else
    out.world_normal = mesh_functions::mesh_normal_local_to_world(vertex.normal, vertex.instance_index);
#endif
#ifdef VERTEX_OUTPUT_INSTANCE_INDEX
    out.instance_index = vertex.instance_index;
#endif
#ifdef VISIBILITY_RANGE_DITHER
    out.visibility_range_dither = mesh_functions::get_visibility_range_dither_level(
        vertex.instance_index, world_from_local[3]);
#endif
    return out;
}
#endif
