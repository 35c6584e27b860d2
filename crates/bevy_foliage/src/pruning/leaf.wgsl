// Forward vertex stage of pruned leaves: pulls the kept leaf vertex and hands Bevy's PBR fragment
// stage an ordinary VertexOutput, so leaves receive Bevy's lighting and shadows.
#import bevy_pbr::{
    mesh_functions,
    forward_io::VertexOutput,
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
    out.world_normal = mesh_functions::mesh_normal_local_to_world(leaf.local_normal, in.instance_index);
#ifdef VERTEX_UVS_A
    out.uv = leaf.uv;
#endif
#ifdef VERTEX_OUTPUT_INSTANCE_INDEX
    out.instance_index = in.instance_index;
#endif
    return out;
}
