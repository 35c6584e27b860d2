// Tile classification of SSSS (CPU reference: `ssss::tiles`): which 8×8 screen tiles the blur
// passes must run on.
//
// - `reduce`: one invocation per tile reads the distance map (hard, σx, σy, eye depth) and writes
//   the tile's statistics: hard visibility range, depth range, background, kernel reaches.
// - `spread`: one invocation per tile combines the statistics of the tiles its own horizontal
//   reach covers (what the horizontal pass reads from its row).
// - `classify`: one invocation per tile combines the spread statistics of the tile rows its
//   vertical reach covers — the region the two blur passes read, in two 1-D walks instead of one
//   2-D one — and appends the tile to the active list (the instance count of an indirect draw)
//   unless the blur cannot change any of its pixels.
#import bevy_soft_shadows::ssss_types::{SsssUniform, TILE, DEPTH_RANGE_MARGIN, kernel_extent}

// Mirrors `ssss::tiles::TileStats`.
struct TileStats {
    hard_min: f32,
    hard_max: f32,
    depth_min: f32,
    depth_max: f32,
    reach_x: u32,
    reach_y: u32,
    background: u32,
    padding: u32,
}

// `DrawIndirectArgs`: six vertices (two triangles) per active tile.
struct TileArgs {
    vertex_count: u32,
    instance_count: atomic<u32>,
    first_vertex: u32,
    first_instance: u32,
}

@group(0) @binding(0) var distances: texture_2d<f32>;
@group(0) @binding(1) var<uniform> ssss: SsssUniform;
@group(0) @binding(2) var<storage, read_write> stats: array<TileStats>;
@group(0) @binding(3) var<storage, read_write> tiles: array<u32>;
@group(0) @binding(4) var<storage, read_write> args: TileArgs;
@group(0) @binding(5) var<storage, read_write> row_stats: array<TileStats>;

const F32_MAX: f32 = 3.40282347e38;

fn tile_grid() -> vec2<u32> {
    return (textureDimensions(distances) + vec2(TILE - 1u)) / TILE;
}

// `tiles::kernel_reach`: the farthest pixel a kernel of σ px reads.
fn kernel_reach(sigma: f32) -> u32 {
    return kernel_extent(sigma, ssss.taps_per_side);
}

// One invocation per tile walks its 64 pixels: no shared memory or barrier, and a tile's
// statistics are a handful of min/max (the classification is a small part of SSSS's cost).
@compute @workgroup_size(64, 1, 1)
fn reduce(@builtin(global_invocation_id) id: vec3<u32>) {
    let grid = tile_grid();
    if id.x >= grid.x * grid.y {
        return;
    }
    let size = textureDimensions(distances);
    let origin = vec2(id.x % grid.x, id.x / grid.x) * TILE;
    var s = TileStats(F32_MAX, -F32_MAX, F32_MAX, 0.0, 0u, 0u, 0u, 0u);
    for (var j = 0u; j < TILE; j += 1u) {
        for (var i = 0u; i < TILE; i += 1u) {
            let p = origin + vec2(i, j);
            if any(p >= size) {
                continue;
            }
            let d = textureLoad(distances, p, 0);
            s.hard_min = min(s.hard_min, d.x);
            s.hard_max = max(s.hard_max, d.x);
            if d.w > 0.0 {
                s.depth_min = min(s.depth_min, d.w);
                s.depth_max = max(s.depth_max, d.w);
            } else {
                s.background = 1u;
            }
            s.reach_x = max(s.reach_x, kernel_reach(d.y));
            s.reach_y = max(s.reach_y, kernel_reach(d.z));
        }
    }
    stats[id.x] = s;
}

// `tiles::tile_span`: the tiles covering pixels `tile·TILE − reach ..= tile·TILE + TILE − 1 +
// reach`.
fn tile_span(tile: u32, reach: u32, count: u32) -> vec2<u32> {
    let start = i32(tile * TILE);
    let first = max(start - i32(reach), 0) / i32(TILE);
    let last = min((start + i32(TILE) - 1 + i32(reach)) / i32(TILE), i32(count) - 1);
    return vec2(u32(first), u32(last));
}

fn combine(a: TileStats, b: TileStats) -> TileStats {
    var s = a;
    s.hard_min = min(a.hard_min, b.hard_min);
    s.hard_max = max(a.hard_max, b.hard_max);
    s.depth_min = min(a.depth_min, b.depth_min);
    s.depth_max = max(a.depth_max, b.depth_max);
    s.background = max(a.background, b.background);
    return s;
}

@compute @workgroup_size(64, 1, 1)
fn spread(@builtin(global_invocation_id) id: vec3<u32>) {
    let grid = tile_grid();
    if id.x >= grid.x * grid.y {
        return;
    }
    let x = id.x % grid.x;
    let y = id.x / grid.x;
    let own = stats[id.x];
    var s = TileStats(F32_MAX, -F32_MAX, F32_MAX, 0.0, own.reach_x, own.reach_y, 0u, 0u);
    let cols = tile_span(x, own.reach_x, grid.x);
    for (var col = cols.x; col <= cols.y; col += 1u) {
        s = combine(s, stats[y * grid.x + col]);
    }
    row_stats[id.x] = s;
}

// `tiles::is_active`: over the tile rows its vertical reach covers, what each row's horizontal
// reach covers.
fn is_active(x: u32, y: u32, grid: vec2<u32>) -> bool {
    let own = stats[y * grid.x + x];
    if own.reach_x == 0u && own.reach_y == 0u {
        return false;
    }
    var s = TileStats(F32_MAX, -F32_MAX, F32_MAX, 0.0, 0u, 0u, 0u, 0u);
    let rows = tile_span(y, own.reach_y, grid.y);
    for (var row = rows.x; row <= rows.y; row += 1u) {
        s = combine(s, row_stats[row * grid.x + x]);
    }
    if s.hard_min != s.hard_max {
        return true;
    }
    return ssss.lazy_shadowing != 0u
        && (s.background != 0u
            || s.depth_max - s.depth_min > DEPTH_RANGE_MARGIN * ssss.depth_rejection * s.depth_min);
}

@compute @workgroup_size(64, 1, 1)
fn classify(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x == 0u {
        args.vertex_count = 6u;
    }
    let grid = tile_grid();
    if id.x >= grid.x * grid.y || ssss.enabled == 0u {
        return;
    }
    let x = id.x % grid.x;
    let y = id.x / grid.x;
    if ssss.all_tiles != 0u || is_active(x, y, grid) {
        let slot = atomicAdd(&args.instance_count, 1u);
        tiles[slot] = x | (y << 16u);
    }
}
