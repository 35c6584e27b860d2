// Pruned leaves drawn into the trees' world-space opacity shadow map (Boulanger 2008, §5.5.2.1).
//
// One invocation per (kept triangle, tree): the tree's shadow selection — what its shadow views
// draw, the light's own pruned set (`selection.rs`) — pulled from the pruning pass's output as
// `leaf_pulling.wgsl` pulls it, each leaf enlarged about its centroid by the area compensation
// of eq. 3.9 (so a pruned crown keeps its darkness: the leaves a sun ray meets stay Poisson
// distributed with the same mean), and shrunk to its texture's opaque area (the map has no
// alpha test: a leaf card counts as the fraction of it that is leaf). CPU reference:
// `draw_pruned_leaves` in `opacity_shadow.rs`.
#import bevy_soft_shadows::opacity_caster::draw_occluder_triangle
#import bevy_foliage::pruning_types::{Instance, LeafVertex}

struct Caster {
    world_from_local: mat4x4<f32>,
    // The tree's camera record (its MeshTag slot); shadows draw its `shadow_slot`.
    slot: u32,
    // 1: enlarge kept leaves to preserve area; the cap of the linear scale.
    area_compensation: u32,
    max_scale: f32,
    // sqrt of the leaf texture's opaque fraction.
    opaque_scale: f32,
}

@group(0) @binding(0) var<storage, read> instances: array<Instance>;
@group(0) @binding(1) var<storage, read> output: array<u32>;
@group(0) @binding(2) var<storage, read> draws: array<u32>;
@group(0) @binding(3) var<storage, read> cell_offsets: array<vec4<u32>>;
@group(0) @binding(4) var<storage, read> leaf_vertices: array<LeafVertex>;
@group(0) @binding(5) var<storage, read> casters: array<Caster>;

@compute @workgroup_size(64, 1, 1)
fn draw_leaves(@builtin(global_invocation_id) id: vec3<u32>) {
    let caster = casters[id.y];
    let slot = instances[caster.slot].shadow_slot;
    let first = id.x * 3u;
    if first + 3u > draws[slot * 5u] {
        return;
    }
    let inst = instances[slot];
    var corners: array<vec3<f32>, 3>;
    for (var k = 0u; k < 3u; k++) {
        let v = leaf_vertices[output[inst.output_base + first + k]];
        var scale = caster.opaque_scale;
        if caster.area_compensation != 0u {
            // Eq. 3.9 as in `leaf_pulling.wgsl`: linear scale sqrt(1/u), u = LoD(cell), capped.
            let lod = cell_offsets[inst.cell_offsets_base + v.cell].z;
            scale *= min(sqrt(65536.0 / f32(max(lod, 1u))), caster.max_scale);
        }
        let local = v.position - v.offset + v.offset * scale;
        corners[k] = (caster.world_from_local * vec4(local, 1.0)).xyz;
    }
    draw_occluder_triangle(corners[0], corners[1], corners[2], 1u);
}
