// The terrain's vertex stage with relief, for the main pass and the prepass (depth, normals,
// motion vectors, shadow maps): the tile meshes are flat at y = 0, placed by their transform in
// lattice steps relative to the anchor lattice point (`relief.wgsl`); the vertex takes the
// height of the terrain at its lattice point, the normal from the heights, and its render-space
// position from the anchor's. Bevy's `mesh.wgsl` and
// `prepass.wgsl` otherwise, for meshes with positions, normals and uvs (no skins, morphs,
// tangents or colours).
#import bevy_pbr::{mesh_functions, view_transformations::position_world_to_clip}
#ifdef PREPASS_PIPELINE
#import bevy_pbr::prepass_io::{Vertex, VertexOutput}
#else
#import bevy_pbr::forward_io::{Vertex, VertexOutput}
#endif
#import bevy_terrain_clip::relief::{relief_height, relief_normal, color_uv, lattice_point, render_position}

@vertex
fn vertex(vertex: Vertex) -> VertexOutput {
    var out: VertexOutput;
    let world_from_local = mesh_functions::get_world_from_local(vertex.instance_index);
    // Lattice steps from the anchor: integer scale and translation, so exact.
    let relative = mesh_functions::mesh_position_local_to_world(world_from_local, vec4(vertex.position, 1.0)).xz;
    let lattice = lattice_point(relative);
    let world = vec4(render_position(relative, relief_height(lattice)), 1.0);
    out.world_position = world;
    out.position = position_world_to_clip(world.xyz);
#ifdef UNCLIPPED_DEPTH_ORTHO_EMULATION
    out.unclipped_depth = out.position.z;
    out.position.z = min(out.position.z, 1.0);
#endif
#ifdef VERTEX_UVS_A
    out.uv = color_uv(world.xz);
#endif
#ifdef PREPASS_PIPELINE
#ifdef NORMAL_PREPASS_OR_DEFERRED_PREPASS
    out.world_normal = relief_normal(lattice);
#endif
#ifdef MOTION_VECTOR_PREPASS
    // The ground does not move.
    out.previous_world_position = world;
#endif
#else
    out.world_normal = relief_normal(lattice);
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
