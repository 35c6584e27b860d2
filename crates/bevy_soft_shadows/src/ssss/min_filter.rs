//! The "coarse", dilated shadow map of §6.2.1: each coarse texel keeps the depth nearest the
//! light over a block of `B²` shadow-map texels, then a separable filter keeps the nearest over a
//! square of `2R + 1` coarse texels, so pixels in the outer penumbra (lit in the hard shadow map)
//! still find the blocker whose penumbra covers them. It is only used for the blocker distance,
//! never for the shadow itself. The blocks make it cheap — the full-resolution filter cost
//! ~180 ms a frame on a software rasteriser for a 2048² map, the coarse one a fraction — and
//! widen the reach by less than one block, which only makes the search a little more generous.
//!
//! The block is chosen per frame ([`dilation_block`]): [`DILATION_BLOCK`] while the widest reach
//! fits in [`MAX_COARSE_RADIUS`] coarse texels, doubled until it does beyond (the segment filter
//! keeps a segment of `2R + 1` texels in registers). A large light over tall blockers — a palm's
//! fronds 9 m above the sand under a 0.25 rad sun — gets a coarser map of the same cost instead
//! of a window cut short; only reaches past [`MAX_DILATION_TEXELS`] are capped.
//!
//! Bevy's shadow maps use reverse Z (1 at the light's near plane, 0 at the far one), so "nearest
//! the light" is the *largest* stored value: [`DepthConvention`] says which.

/// Side of the shadow-map blocks one texel of the coarse map stands for, at the finest.
pub const DILATION_BLOCK: usize = 4;

/// The widest coarse radius `R` the filter runs at (`MAX_SEGMENT` in `min_filter.wgsl`).
pub const MAX_COARSE_RADIUS: usize = 16;

/// The coarsest block [`dilation_block`] picks.
pub const MAX_DILATION_BLOCK: usize = 64;

/// The widest fine reach the dilation searches, in shadow-map texels: [`MAX_COARSE_RADIUS`]
/// coarse texels of the coarsest block.
pub const MAX_DILATION_TEXELS: usize = MAX_COARSE_RADIUS * MAX_DILATION_BLOCK;

/// The fine reach `r = ⌈max_occluder_distance · tan(θ/2) / texel⌉` (texels) of a directional
/// light: half the penumbra of the farthest blocker searched for.
pub fn fine_reach(max_occluder_distance: f32, angular_diameter: f32, texel: f32) -> f32 {
    let half_width = max_occluder_distance * (0.5 * angular_diameter).tan();
    (half_width / texel.max(1e-6)).ceil().max(0.0)
}

/// The block for a widest fine reach of `reach` texels: the finest of [`DILATION_BLOCK`]·2ᵏ
/// (at most [`MAX_DILATION_BLOCK`]) that covers it within [`MAX_COARSE_RADIUS`] coarse texels.
pub fn dilation_block(reach: f32) -> usize {
    let mut block = DILATION_BLOCK;
    while block < MAX_DILATION_BLOCK && reach > (MAX_COARSE_RADIUS * block) as f32 {
        block *= 2;
    }
    block
}

/// The coarse radius `R = ⌈r / block⌉` of a fine reach `r` (capped at
/// [`MAX_COARSE_RADIUS`]).
pub fn coarse_radius_of(reach: f32, block: usize) -> usize {
    ((reach.max(0.0) / block as f32).ceil() as usize).min(MAX_COARSE_RADIUS)
}

/// The coarse radius of a directional light's cascade of texel size `texel` at `block`
/// ([`fine_reach`], [`coarse_radius_of`]).
pub fn coarse_radius(
    max_occluder_distance: f32,
    angular_diameter: f32,
    texel: f32,
    block: usize,
) -> usize {
    coarse_radius_of(
        fine_reach(max_occluder_distance, angular_diameter, texel),
        block,
    )
}

/// From this coarse radius on, [`SsssDilationFilter::Auto`](super::dilation::SsssDilationFilter)
/// runs the segment filter ([`segment_filter_1d`]) instead of the direct one: the direct
/// filter's cost grows with `2R + 1` reads per texel and pass, the segment filter's does not
/// but starts higher. On llvmpipe (issue 6's note: `soft_shadows --bench [--spot]`, 512² coarse
/// map, the two timed side by side) the direct filter took 2.8 / 4.0 / 6.4 ms at R = 1 / 3 / 6
/// (sun) and 10.3 / 21.1 / 23.5 ms at R = 5 / 14 / 16 (lamp); the segments ~10 ms (sun) and
/// ~14 ms (lamp) at any R. Growing by 0.7–1.2 ms per unit of R, the direct filter meets the
/// segments near R = 10–12.
pub const SEGMENT_FILTER_FROM_RADIUS: usize = 12;

/// The fine reach (texels) for a spot light of diameter `light_size` (m) whose shadow map of
/// `map_size` texels spans `±tan_outer` (Bevy's perspective spot shadow projection).
///
/// From the light, a receiver at distance `d_r` sees its blockers at `d_b` within the light's
/// disk projected onto the blocker's plane: an angle of `(light_size/2)·(1/d_b − 1/d_r)` around
/// it. The window cannot know `d_r` (it is a filter over the map), so it is sized for every
/// blocker at least `max_occluder_distance` (Δ) from the light and at most Δ in front of its
/// receiver: the largest such angle, at `d_b = Δ`, `d_r = 2Δ`, is `light_size / (4Δ)` — the
/// thesis' "fixed safe distance" set by hand, with the same meaning as for a directional light.
/// In texels at the map's centre that angle is `tan(angle) / (2·tan_outer) · map_size`.
pub fn spot_fine_reach(
    light_size: f32,
    max_occluder_distance: f32,
    tan_outer: f32,
    map_size: f32,
) -> f32 {
    // (An angle past ~86° is capped anyway; keep its tangent positive.)
    let angle = (light_size / (4.0 * max_occluder_distance.max(1e-3))).min(1.5);
    let texels = angle.tan() / (2.0 * tan_outer.max(1e-4)) * map_size;
    texels.ceil().max(0.0)
}

/// Which stored depth is nearer the light.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthConvention {
    /// Larger values are nearer (Bevy's reverse Z): the filter keeps the maximum.
    ReverseZ,
    /// Smaller values are nearer: the filter keeps the minimum.
    Forward,
}

impl DepthConvention {
    /// The nearer of two depths.
    pub fn nearest(self, a: f32, b: f32) -> f32 {
        match self {
            Self::ReverseZ => a.max(b),
            Self::Forward => a.min(b),
        }
    }
}

/// One pass of the filter along rows (`horizontal`) or columns, clamped at the borders.
pub fn nearest_filter_1d(
    depth: &[f32],
    width: usize,
    height: usize,
    radius: usize,
    horizontal: bool,
    convention: DepthConvention,
) -> Vec<f32> {
    let mut out = vec![0.0; depth.len()];
    for y in 0..height {
        for x in 0..width {
            let (centre, len) = if horizontal { (x, width) } else { (y, height) };
            let lo = centre.saturating_sub(radius);
            let hi = (centre + radius).min(len - 1);
            let mut best = depth[y * width + x];
            for i in lo..=hi {
                let v = if horizontal {
                    depth[y * width + i]
                } else {
                    depth[i * width + x]
                };
                best = convention.nearest(best, v);
            }
            out[y * width + x] = best;
        }
    }
    out
}

/// One line of the filter the way the GPU runs it (van Herk / Gil-Werman, `min_filter.wgsl`):
/// O(1) work per texel whatever the radius. The line is cut into segments of `k = 2r + 1`;
/// `g` is the nearest depth from a texel's segment start to it, `h` from it to the segment's
/// end. A window `[p − r, p + r]` (clamped to the line) spans the end of one segment and the
/// start of the next, so its nearest depth is `nearest(h[a], g[b])`, or one of them when the
/// clamped window lies in a single segment. Equal to the direct filter (tested): the order of
/// max/min never changes the result.
pub fn segment_filter_1d(line: &[f32], radius: usize, convention: DepthConvention) -> Vec<f32> {
    let (n, k) = (line.len(), 2 * radius + 1);
    let (mut g, mut h) = (line.to_vec(), line.to_vec());
    for start in (0..n).step_by(k) {
        let end = (start + k).min(n);
        for i in start + 1..end {
            g[i] = convention.nearest(g[i - 1], line[i]);
        }
        for i in (start..end - 1).rev() {
            h[i] = convention.nearest(h[i + 1], line[i]);
        }
    }
    (0..n)
        .map(|p| {
            let (a, b) = (p.saturating_sub(radius), (p + radius).min(n - 1));
            if a / k == b / k {
                if a % k == 0 { g[b] } else { h[a] }
            } else {
                convention.nearest(h[a], g[b])
            }
        })
        .collect()
}

/// The dilated map: the horizontal pass, then the vertical one on its result — equal to the
/// nearest depth over the `(2r + 1)²` square (min and max are separable).
pub fn dilate(
    depth: &[f32],
    width: usize,
    height: usize,
    radius: usize,
    convention: DepthConvention,
) -> Vec<f32> {
    let rows = nearest_filter_1d(depth, width, height, radius, true, convention);
    nearest_filter_1d(&rows, width, height, radius, false, convention)
}

/// The nearest depth of each `block × block` block (edge blocks clamped to the map).
pub fn reduce_blocks(
    depth: &[f32],
    width: usize,
    height: usize,
    block: usize,
    convention: DepthConvention,
) -> (Vec<f32>, usize, usize) {
    let (cw, ch) = (width.div_ceil(block), height.div_ceil(block));
    let mut out = vec![0.0; cw * ch];
    for cy in 0..ch {
        for cx in 0..cw {
            let mut best =
                depth[(cy * block).min(height - 1) * width + (cx * block).min(width - 1)];
            for y in 0..block {
                for x in 0..block {
                    let (fx, fy) = (
                        (cx * block + x).min(width - 1),
                        (cy * block + y).min(height - 1),
                    );
                    best = convention.nearest(best, depth[fy * width + fx]);
                }
            }
            out[cy * cw + cx] = best;
        }
    }
    (out, cw, ch)
}

/// What the GPU computes: [`reduce_blocks`] by `block`, then [`dilate`] by the coarse radius.
/// Returns the coarse map and its size.
pub fn coarse_dilate(
    depth: &[f32],
    width: usize,
    height: usize,
    coarse_radius: usize,
    block: usize,
    convention: DepthConvention,
) -> (Vec<f32>, usize, usize) {
    let (blocks, cw, ch) = reduce_blocks(depth, width, height, block, convention);
    (dilate(&blocks, cw, ch, coarse_radius, convention), cw, ch)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_spot_window_covers_every_blocker_within_the_safe_distance() {
        // A spot of 0.3 m, 45° outer angle, 1024² map; blockers ≥ Δ from the light and ≤ Δ in
        // front of the receiver, on the axis: the light disk seen from the receiver, projected
        // on the blocker's plane, must fall inside the window R·BLOCK texels around it.
        let (w, delta, tan_outer, size) = (0.3f32, 3.0f32, 1.0f32, 1024.0f32);
        let r = coarse_radius_of(spot_fine_reach(w, delta, tan_outer, size), DILATION_BLOCK);
        let window = (r * DILATION_BLOCK) as f32;
        let texels_of = |lateral: f32, d: f32| lateral / d / (2.0 * tan_outer) * size;
        let mut widest = 0.0f32;
        for i in 0..=20 {
            let d_b = delta * (1.0 + 4.0 * i as f32 / 20.0);
            for j in 1..=20 {
                let d_r = d_b + delta * j as f32 / 20.0;
                // The disk's radius projected from the receiver onto the blocker's plane.
                let lateral = 0.5 * w * (d_r - d_b) / d_r;
                widest = widest.max(texels_of(lateral, d_b));
            }
        }
        assert!(widest <= window, "search {widest} texels, window {window}");
        // … and not much more than needed: the worst case sits exactly on the bound.
        assert!(
            window < widest + 2.0 * DILATION_BLOCK as f32,
            "{widest} vs {window}"
        );
        // A blocker nearer the light than Δ needs more than the window (documented limit).
        let lateral = 0.5 * w * delta / (1.5 * delta);
        assert!(texels_of(lateral, 0.5 * delta) > window);
    }

    #[test]
    fn the_block_grows_with_the_reach_so_the_window_is_never_cut_short() {
        assert_eq!(dilation_block(0.0), DILATION_BLOCK);
        assert_eq!(dilation_block(64.0), 4);
        assert_eq!(dilation_block(65.0), 8);
        assert_eq!(dilation_block(139.0), 16);
        assert_eq!(dilation_block(1e9), MAX_DILATION_BLOCK);
        for reach in [1.0f32, 30.0, 64.0, 65.0, 139.0, 500.0, 1024.0] {
            let block = dilation_block(reach);
            let r = coarse_radius_of(reach, block);
            assert!(r <= MAX_COARSE_RADIUS);
            assert!(
                (r * block) as f32 >= reach,
                "reach {reach}: R {r} × {block}"
            );
            // The finest block that does: half of it would need more than the widest radius.
            if block > DILATION_BLOCK {
                assert!(reach > (MAX_COARSE_RADIUS * block / 2) as f32);
            }
        }
        // Past the coarsest block's reach, capped.
        assert_eq!(
            coarse_radius_of(5000.0, MAX_DILATION_BLOCK),
            MAX_COARSE_RADIUS
        );
    }

    #[test]
    fn the_segment_filter_equals_the_direct_filter() {
        // Every radius against lines shorter and longer than a segment, both conventions.
        let mut seed = 7u32;
        for n in [1usize, 2, 5, 16, 33, 34, 100] {
            let line: Vec<f32> = (0..n)
                .map(|_| {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (seed >> 8) as f32 / (1u32 << 24) as f32
                })
                .collect();
            for radius in 0..=17 {
                for convention in [DepthConvention::ReverseZ, DepthConvention::Forward] {
                    let direct = nearest_filter_1d(&line, n, 1, radius, true, convention);
                    assert_eq!(
                        segment_filter_1d(&line, radius, convention),
                        direct,
                        "n {n}, r {radius}, {convention:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn separable_dilation_equals_the_square_filter() {
        let (w, h) = (23, 17);
        let depth: Vec<f32> = (0..w * h)
            .map(|i| ((i * 7919) % 113) as f32 / 113.0)
            .collect();
        for convention in [DepthConvention::ReverseZ, DepthConvention::Forward] {
            for radius in [0, 1, 3, 8] {
                let fast = dilate(&depth, w, h, radius, convention);
                for y in 0..h {
                    for x in 0..w {
                        let mut best = depth[y * w + x];
                        for yy in y.saturating_sub(radius)..=(y + radius).min(h - 1) {
                            for xx in x.saturating_sub(radius)..=(x + radius).min(w - 1) {
                                best = convention.nearest(best, depth[yy * w + xx]);
                            }
                        }
                        assert_eq!(fast[y * w + x], best, "({x}, {y}) r {radius}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_coarse_map_covers_at_least_the_fine_reach() {
        let (w, h) = (37, 29);
        let depth: Vec<f32> = (0..w * h)
            .map(|i| ((i * 6151) % 97) as f32 / 97.0)
            .collect();
        let conv = DepthConvention::ReverseZ;
        for r in [0usize, 3, 4, 9] {
            let big_r = r.div_ceil(DILATION_BLOCK);
            let (coarse, cw, ch) = coarse_dilate(&depth, w, h, big_r, DILATION_BLOCK, conv);
            let fine = dilate(&depth, w, h, r, conv);
            for y in 0..h {
                for x in 0..w {
                    // The coarse texel holding (x, y) is at least as near as the fine filter
                    // (its footprint contains the fine square) ...
                    let c = coarse[(y / DILATION_BLOCK) * cw + x / DILATION_BLOCK];
                    assert!(c >= fine[y * w + x], "r {r} ({x}, {y})");
                }
            }
            // ... and no nearer than the fine filter over the reach plus one block.
            let wider = dilate(&depth, w, h, r + 2 * DILATION_BLOCK, conv);
            for cy in 0..ch {
                for cx in 0..cw {
                    let (x, y) = (
                        (cx * DILATION_BLOCK).min(w - 1),
                        (cy * DILATION_BLOCK).min(h - 1),
                    );
                    assert!(coarse[cy * cw + cx] <= wider[y * w + x]);
                }
            }
        }
        assert_eq!(coarse_radius(5.0, 0.1, 0.03, DILATION_BLOCK), 3); // r = ⌈8.34⌉ = 9 → R = 3
        assert_eq!(
            coarse_radius(5.0, 0.1, 1e-9, DILATION_BLOCK),
            MAX_COARSE_RADIUS
        );
    }

    #[test]
    fn a_blocker_spreads_by_the_radius_and_no_further() {
        let (w, h) = (9, 9);
        let mut depth = vec![0.1; w * h];
        depth[4 * w + 4] = 0.9; // one blocker texel near the light (reverse Z)
        let d = dilate(&depth, w, h, 2, DepthConvention::ReverseZ);
        for y in 0..h {
            for x in 0..w {
                let inside = x.abs_diff(4) <= 2 && y.abs_diff(4) <= 2;
                assert_eq!(d[y * w + x], if inside { 0.9 } else { 0.1 });
            }
        }
    }
}
