// The records the pruning pass and the passes that draw its output share.
#define_import_path bevy_foliage::pruning_types

// One extraction's record (`INSTANCE_WORDS` words, written by `render.rs`).
struct Instance {
    // The three viewpoints and their weights (fractions of 65536, summing to 65536).
    views: vec3<u32>,
    distance_fixed: u32,
    weights: vec3<u32>,
    // Where this instance's compacted indices start in `output`.
    output_base: u32,
    // The tree type's ranges inside the shared baked buffers.
    cell_base: u32,        // first entry of this type in `cell_first_leaf`
    cell_count: u32,
    view_count: u32,
    visibility_base: u32,  // first entry of this type in `visibility`
    leaf_base: u32,        // first entry of this type in `leaf_index_start`
    index_base: u32,       // first entry of this type in `stored_indices`
    vertex_base: u32,      // added to every index written (types share one vertex buffer)
    cell_offsets_base: u32, // first `cell_offsets` entry of this instance
    shadow_slot: u32,      // the record shadow views draw (the light's selection, or this one)
    extinction_bits: u32,  // the crown's extinction τ per unit of model space (f32 bits)
    pad_b: u32,
    pad_c: u32,
    // The crown's bounding sphere in model space (centre xyz, radius; f32 bits).
    crown_sphere_bits: vec4<u32>,
    // The crown's hotspot (`lighting::hotspot::Hotspot::packed`): eight u8 nodes over the phase
    // angle each, in 64ths — the sun's exponent in the first two words, the bounce's factor in
    // the last two.
    hotspot: vec4<u32>,
}

// A packed leaf vertex (`LEAF_VERTEX_WORDS` words, `store.rs`).
struct LeafVertex {
    position: vec3<f32>,
    cell: u32,
    offset: vec3<f32>,
    // Largest centroid offset of the vertex's leaf.
    leaf_radius: f32,
    normal: vec3<f32>,
    // The vertex's leaf in `leaf_light`.
    leaf: u32,
    uv: vec2<f32>,
    // Mean texture coordinate of the vertex's leaf.
    uv_centre: vec2<f32>,
}
