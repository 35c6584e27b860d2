#define_import_path bevy_soft_shadows::ssss_types

// Mirrors `ssss::render::SsssUniform`.
struct SsssUniform {
    // Angular diameter of a directional light (rad), diameter of a spot light (m).
    light_size: f32,
    max_occluder_distance: f32,
    min_kernel_px: f32,
    max_kernel_px: f32,
    depth_rejection: f32,
    taps_per_side: u32,
    lazy_shadowing: u32,
    // 1 while a light has SSSS; 0 makes the passes write "inactive" (-1) for the receivers.
    enabled: u32,
    // LIGHT_KIND_DIRECTIONAL or LIGHT_KIND_SPOT.
    light_kind: u32,
    // A spot light's index in the clustered light array.
    light_index: u32,
    // A spot light's coarse dilation radius (`ssss::min_filter::spot_coarse_radius`).
    spot_radius: u32,
    // 1: blur every screen tile; 0: only the active ones (`ssss::tiles`).
    all_tiles: u32,
}

const LIGHT_KIND_DIRECTIONAL: u32 = 0u;
const LIGHT_KIND_SPOT: u32 = 1u;

const MAX_DILATION_TEXELS: u32 = 64u;
// Side of the shadow-map blocks one coarse texel of the dilated map stands for
// (`ssss::min_filter::DILATION_BLOCK`).
const DILATION_BLOCK: u32 = 4u;
const NO_LIGHT: u32 = 0xffffffffu;
// Kernel reach in standard deviations (`ssss::kernel::KERNEL_REACH_SIGMAS`).
const KERNEL_REACH_SIGMAS: f32 = 2.5;
// Side of a screen tile of the classification (`ssss::tiles::TILE`).
const TILE: u32 = 8u;
// `ssss::tiles::DEPTH_RANGE_MARGIN`.
const DEPTH_RANGE_MARGIN: f32 = 0.99;
// Half-width of the refined blocker search grid, in samples (`ssss::distance::BLOCKER_GRID`).
const BLOCKER_GRID: i32 = 3;
