// Prefix sums along rows or columns of the value a blur pass reads (.r of its input), so a
// spread tap reads the mean of its cell in two loads (`kernel::tap_cell`): the box prefilter
// that keeps sparse taps from aliasing fine hard-shadow stripes into streaks. Fixed point
// (`kernel::to_fixed`): sums are exact, and equal the CPU reference's
// (`blur::line_sums`) bit for bit. One invocation walks one line; a line is a few hundred to a
// few thousand pixels, a small part of a blur pass's work.
#import bevy_soft_shadows::ssss_types::to_fixed

@group(0) @binding(0) var source: texture_2d<f32>;
// Rows: (width + 1) × height, texel (k, y) sums pixels 0..k of row y. Columns: width ×
// (height + 1), texel (x, k) sums pixels 0..k of column x.
@group(0) @binding(1) var sums: texture_storage_2d<r32uint, write>;

@compute @workgroup_size(64, 1, 1)
fn row_sums(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(source);
    if id.x >= size.y {
        return;
    }
    let y = id.x;
    var s = 0u;
    textureStore(sums, vec2(0u, y), vec4(s));
    for (var x = 0u; x < size.x; x += 1u) {
        s += to_fixed(textureLoad(source, vec2(x, y), 0).r);
        textureStore(sums, vec2(x + 1u, y), vec4(s));
    }
}

@compute @workgroup_size(64, 1, 1)
fn column_sums(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(source);
    if id.x >= size.x {
        return;
    }
    let x = id.x;
    var s = 0u;
    textureStore(sums, vec2(x, 0u), vec4(s));
    for (var y = 0u; y < size.y; y += 1u) {
        s += to_fixed(textureLoad(source, vec2(x, y), 0).r);
        textureStore(sums, vec2(x, y + 1u), vec4(s));
    }
}
