#define_import_path bevy_soft_shadows::ssss_types

// Mirrors `ssss::render::SsssUniform`.
struct SsssUniform {
    // Angular diameter of a directional light (rad), diameter of a spot or point light (m).
    light_size: f32,
    max_occluder_distance: f32,
    min_kernel_px: f32,
    max_kernel_px: f32,
    depth_rejection: f32,
    taps_per_side: u32,
    lazy_shadowing: u32,
    // 1 while a light has SSSS; 0 makes the passes write "inactive" (-1) for the receivers.
    enabled: u32,
    // LIGHT_KIND_DIRECTIONAL, LIGHT_KIND_SPOT or LIGHT_KIND_POINT.
    light_kind: u32,
    // A spot or point light's index in the clustered light array.
    light_index: u32,
    // A spot or point light's coarse dilation radius (`ssss::min_filter::coarse_radius_of`).
    local_radius: u32,
    // 1: blur every screen tile; 0: only the active ones (`ssss::tiles`).
    all_tiles: u32,
    // Shadow-map texels a side per coarse texel (`ssss::min_filter::dilation_block`).
    dilation_block: u32,
}

const LIGHT_KIND_DIRECTIONAL: u32 = 0u;
const LIGHT_KIND_SPOT: u32 = 1u;
const LIGHT_KIND_POINT: u32 = 2u;

// The widest coarse dilation radius (`ssss::min_filter::MAX_COARSE_RADIUS`).
const MAX_COARSE_RADIUS: u32 = 16u;
const NO_LIGHT: u32 = 0xffffffffu;
// Kernel reach in standard deviations (`ssss::kernel::KERNEL_REACH_SIGMAS`).
const KERNEL_REACH_SIGMAS: f32 = 2.5;
// Side of a screen tile of the classification (`ssss::tiles::TILE`).
const TILE: u32 = 8u;
// `ssss::tiles::DEPTH_RANGE_MARGIN`.
const DEPTH_RANGE_MARGIN: f32 = 0.99;
// Half-width of the refined blocker search grid, in samples (`ssss::distance::BLOCKER_GRID`).
const BLOCKER_GRID: i32 = 3;

// `kernel::tap_offset`: the pixel offset of tap `i` at spacing `step`.
fn tap_offset(i: i32, step: f32) -> i32 {
    let magnitude = i32(floor(f32(abs(i)) * step + 0.5));
    return select(magnitude, -magnitude, i < 0);
}

// `kernel::tap_cell`: the pixel offsets [first, last] tap `i` stands for, halfway to the taps
// beside it (past the last tap, a virtual one a spacing further).
fn cell_end(k: i32, step: f32) -> i32 {
    let s = tap_offset(k, step) + tap_offset(k + 1, step);
    return s / 2;
}

fn tap_cell(i: i32, step: f32) -> vec2<i32> {
    let m = abs(i);
    let last = cell_end(m, step);
    var first = -last;
    if m > 0 {
        first = cell_end(m - 1, step) + 1;
    }
    return select(vec2(first, last), vec2(-last, -first), i < 0);
}

// `kernel::tap_offsets`: (taps a side, spacing) of a kernel of σ px.
fn tap_layout(sigma: f32, per_side: u32) -> vec2<f32> {
    let reach = ceil(KERNEL_REACH_SIGMAS * max(sigma, 0.0));
    if reach <= f32(per_side) {
        return vec2(reach, 1.0);
    }
    return vec2(f32(per_side), reach / f32(per_side));
}

// `kernel::kernel_extent`: the farthest pixel a kernel of σ px reads.
fn kernel_extent(sigma: f32, per_side: u32) -> u32 {
    if sigma <= 0.0 {
        return 0u;
    }
    let taps = tap_layout(sigma, per_side);
    return u32(tap_cell(i32(taps.x), taps.y).y);
}

// `kernel::SUM_SCALE`, `kernel::to_fixed`: terms of the prefix sums the cells are read from.
const SUM_SCALE: f32 = 65536.0;

fn to_fixed(v: f32) -> u32 {
    return u32(clamp(v, 0.0, 1.0) * SUM_SCALE + 0.5);
}
