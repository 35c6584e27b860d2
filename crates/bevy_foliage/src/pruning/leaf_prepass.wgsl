// Prepass / shadow vertex stage of pruned leaves: the same pulled vertices, so shadows are cast
// by exactly the pruned set the camera sees.
#import bevy_pbr::{
    mesh_functions,
    prepass_io::VertexOutput,
    view_transformations::position_world_to_clip,
}
#import bevy_foliage::leaf_pulling::{pull_leaf_vertex, CULLED}

struct SlotVertex {
    @builtin(instance_index) instance_index: u32,
    @location(0) position: vec3<f32>,
}

@vertex
fn vertex(in: SlotVertex) -> VertexOutput {
    var out: VertexOutput;
    let leaf = pull_leaf_vertex(in.instance_index, in.position);
    if !leaf.kept {
        out.position = CULLED;
        return out;
    }
    let world_from_local = mesh_functions::get_world_from_local(in.instance_index);
    out.world_position = mesh_functions::mesh_position_local_to_world(world_from_local, vec4<f32>(leaf.local_position, 1.0));
    out.position = position_world_to_clip(out.world_position.xyz);
#ifdef UNCLIPPED_DEPTH_ORTHO_EMULATION
    out.unclipped_depth = out.position.z;
    out.position.z = min(out.position.z, 1.0);
#endif
#ifdef VERTEX_UVS_A
    out.uv = leaf.uv;
#endif
#ifdef NORMAL_PREPASS_OR_DEFERRED_PREPASS
    out.world_normal = mesh_functions::mesh_normal_local_to_world(leaf.local_normal, in.instance_index);
#endif
#ifdef MOTION_VECTOR_PREPASS
    out.previous_world_position = out.world_position;
#endif
#ifdef VERTEX_OUTPUT_INSTANCE_INDEX
    out.instance_index = in.instance_index;
#endif
    return out;
}
