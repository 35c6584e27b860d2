// View-dependent stochastic pruning, per frame (Gumbau 2011, §3.4, algorithm 2).
//
// Two dispatches per frame over all pruned instances:
//   `count_and_scan`: one workgroup per instance. Each cell wants
//       e_n = leaves_n · LoD(cell), LoD(cell) = dist · Σ_k w_k · vis(cell, k)      (eq. 3.3–3.5)
//       leaves; a workgroup-wide inclusive prefix sum P_n of e_n gives the kept leaves
//       u_n = ceil(P_n) − ceil(P_{n−1}) (rounding with the remainder carried from cell to cell,
//       see `extract.rs`), which are turned into kept index counts; a second prefix sum gives
//       each cell's output offset (eq. 3.6). The total goes into the instance's indexed-indirect
//       draw arguments.
//   `compact`: one invocation per (cell, instance) copies the first kept indices of the cell's
//       stochastically ordered list to its offset.
//
// All LoD arithmetic is 16-bit fixed point on u32, bit-identical to the CPU reference in
// `extract.rs` (see there for why).

#import bevy_foliage::pruning_types::Instance

struct DrawIndexedIndirect {
    index_count: u32,
    instance_count: u32,
    first_index: u32,
    base_vertex: i32,
    first_instance: u32,
}

@group(0) @binding(0) var<storage, read> instances: array<Instance>;
@group(0) @binding(1) var<storage, read> cell_first_leaf: array<u32>;
@group(0) @binding(2) var<storage, read> visibility: array<u32>;
@group(0) @binding(3) var<storage, read> leaf_index_start: array<u32>;
@group(0) @binding(4) var<storage, read> stored_indices: array<u32>;
// Per (instance, cell): kept index count, output offset, LoD(cell) (for area compensation), 0.
@group(0) @binding(5) var<storage, read_write> cell_offsets: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read_write> draws: array<DrawIndexedIndirect>;
@group(0) @binding(7) var<storage, read_write> output: array<u32>;

const WORKGROUP: u32 = 256u;
const FIXED_ONE: u32 = 65536u;
const UNIFORM_DISTANCE: u32 = 0x40000000u;
var<workgroup> partial: array<u32, WORKGROUP>;

// LoD(cell) of eq. 3.5 in 16-bit fixed point, 0..=65536 (`cell_lod` in extract.rs).
fn cell_lod(inst: Instance, cell: u32) -> u32 {
    if inst.distance_fixed == 0xffffffffu {
        // Pruning off: keep every leaf (KEEP_ALL in extract.rs).
        return FIXED_ONE;
    }
    if (inst.distance_fixed & UNIFORM_DISTANCE) != 0u {
        // No view term (UNIFORM_DISTANCE in extract.rs): the selection of a transmittance map.
        return min(inst.distance_fixed & ~UNIFORM_DISTANCE, FIXED_ONE);
    }
    let vis = inst.visibility_base + cell * inst.view_count;
    let sum = inst.weights.x * visibility[vis + inst.views.x]
        + inst.weights.y * visibility[vis + inst.views.y]
        + inst.weights.z * visibility[vis + inst.views.z];
    let view_lod = (sum + 32767u) / 65535u;
    if inst.distance_fixed >= FIXED_ONE {
        return view_lod;
    }
    return (view_lod * inst.distance_fixed + 32768u) >> 16u;
}

// Hillis–Steele inclusive scan of `value` over the workgroup (wrapping u32 sums); returns this
// invocation's inclusive sum and leaves the chunk total in partial[WORKGROUP - 1].
fn inclusive_scan(local: u32, value: u32) -> u32 {
    partial[local] = value;
    workgroupBarrier();
    for (var stride = 1u; stride < WORKGROUP; stride <<= 1u) {
        var add = 0u;
        if local >= stride {
            add = partial[local - stride];
        }
        workgroupBarrier();
        partial[local] += add;
        workgroupBarrier();
    }
    return partial[local];
}

// ceil(P / 65536) of a wrapped prefix sum of wanted leaves, modulo 2^16.
fn carried_ceiling(prefix: u32) -> u32 {
    return (prefix + (FIXED_ONE - 1u)) >> 16u;
}

@compute @workgroup_size(256, 1, 1)
fn count_and_scan(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let instance = group.x;
    let inst = instances[instance];
    let out_base = inst.cell_offsets_base;
    // Running totals of the previous chunks: wanted leaves (wrapping) and kept indices.
    var wanted_carry = 0u;
    var index_carry = 0u;
    // Cells in chunks of WORKGROUP; each chunk is scanned in shared memory and offset by the
    // running totals of the previous chunks.
    for (var chunk = 0u; chunk < inst.cell_count; chunk += WORKGROUP) {
        let cell = chunk + local;
        var leaves = 0u;
        var first = 0u;
        var lod = 0u;
        if cell < inst.cell_count {
            first = cell_first_leaf[inst.cell_base + cell];
            leaves = cell_first_leaf[inst.cell_base + cell + 1u] - first;
            lod = cell_lod(inst, cell);
        }
        let wanted = leaves * lod;
        let after = wanted_carry + inclusive_scan(local, wanted);
        let before = after - wanted;
        let wanted_total = partial[WORKGROUP - 1u];
        workgroupBarrier();
        let kept = (carried_ceiling(after) - carried_ceiling(before)) & 0xffffu;
        var count = 0u;
        if cell < inst.cell_count {
            let leaf = inst.leaf_base + first;
            count = leaf_index_start[leaf + kept] - leaf_index_start[leaf];
        }
        let offset_inclusive = inclusive_scan(local, count);
        if cell < inst.cell_count {
            // Exclusive offset = inclusive − own count.
            cell_offsets[out_base + cell] = vec4<u32>(count, index_carry + offset_inclusive - count, lod, 0u);
        }
        index_carry += partial[WORKGROUP - 1u];
        wanted_carry += wanted_total;
        workgroupBarrier();
    }
    if local == 0u {
        draws[instance] = DrawIndexedIndirect(index_carry, 1u, inst.output_base, 0, instance);
    }
}

@compute @workgroup_size(64, 1, 1)
fn compact(@builtin(global_invocation_id) id: vec3<u32>) {
    let instance = id.y;
    let inst = instances[instance];
    let cell = id.x;
    if cell >= inst.cell_count {
        return;
    }
    let count_offset = cell_offsets[inst.cell_offsets_base + cell];
    let first = cell_first_leaf[inst.cell_base + cell];
    let src = inst.index_base + leaf_index_start[inst.leaf_base + first];
    let dst = inst.output_base + count_offset.y;
    for (var i = 0u; i < count_offset.x; i++) {
        output[dst + i] = stored_indices[src + i] + inst.vertex_base;
    }
}
