// Prepass / shadow vertex stage of pruned leaves: the camera's pulled vertices in the camera's
// prepasses, the shadow light's selection in shadow views (see `leaf_pulling.wgsl`).
#import bevy_pbr::prepass_io::VertexOutput
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
#ifdef UNCLIPPED_DEPTH_ORTHO_EMULATION
    out.unclipped_depth = out.position.z;
    out.position.z = min(out.position.z, 1.0);
#endif
#ifdef VERTEX_UVS_A
    out.uv = leaf.uv;
#endif
#ifdef NORMAL_PREPASS_OR_DEFERRED_PREPASS
    out.world_normal = leaf.world_normal;
#endif
#ifdef MOTION_VECTOR_PREPASS
    out.previous_world_position = out.world_position;
#endif
#ifdef VERTEX_OUTPUT_INSTANCE_INDEX
    out.instance_index = in.instance_index;
#endif
    return out;
}
