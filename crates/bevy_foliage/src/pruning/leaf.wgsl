// Forward vertex stage of pruned leaves: pulls the kept leaf vertex and hands Bevy's PBR fragment
// stage an ordinary VertexOutput, so leaves receive Bevy's lighting and shadows.
#import bevy_pbr::forward_io::VertexOutput
#import bevy_foliage::leaf_pulling::{SlotVertex, pull_leaf_vertex}

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
