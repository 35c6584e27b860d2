//! Tile classification: which screen tiles the blur passes must run on.
//!
//! SSSS blurs the hard shadow with a per-pixel kernel (§6.2.3), but most of a frame is fully lit
//! or fully shadowed, and there the blur returns the hard shadow it started from. As production
//! screen-space shadow filters do (AMD FidelityFX's shadow denoiser classifies 8×8 tiles), the
//! screen is cut into [`TILE`]×[`TILE`] tiles, and a tile is *active* — blurred — only where
//! the blur could change one of its pixels. Inactive tiles keep the hard visibility the distance
//! pass wrote.
//!
//! The test is exact, not a heuristic: a pixel's final value (vertical pass over horizontal
//! pass) reads the hard shadow of the pixels at most its vertical reach above and below it, and
//! from each of those at most that pixel's horizontal reach to the side ([`blur`](super::blur);
//! a reach is the farthest pixel a kernel reads, [`kernel_extent`](super::kernel::kernel_extent):
//! its last tap `ceil(2.5·σ)`, or the end of that tap's cell once taps spread). Bounding both by tile
//! maxima gives a region of tiles around each tile. The blur of a tile leaves every pixel as it
//! is when either
//!
//! - no pixel of the tile has a kernel (σ = 0: the mask of §6.2.2 — the penumbra is under a
//!   pixel wide — or no blocker was found), or
//! - the hard shadow is uniform over the region and no sample there can be replaced by lazy
//!   shadowing (§6.3.2): lazy shadowing is off, or the region has no background and its depth
//!   range is within the depth-rejection threshold, so every sample is accepted; a Gaussian
//!   mean of equal values (each tap a pixel, or the exact fixed-point mean of its cell) is that
//!   value.
//!
//! Every other tile is active. So the tiled result equals the full-screen one (up to the last
//! bit of a weighted mean), which the render tests check.

use super::blur::ScreenBuffers;

/// Side of a screen tile in pixels (one 8×8 workgroup of the reduction, as in FidelityFX).
pub const TILE: usize = 8;

/// A safety margin on the depth-rejection test: a region whose depth range is within this
/// fraction of the threshold is accepted everywhere, even after the blur's own rounding.
pub const DEPTH_RANGE_MARGIN: f32 = 0.99;

/// What the classification needs to know of one tile (the reduction pass's output;
/// `tiles.wgsl` mirrors it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileStats {
    /// Smallest hard visibility in the tile.
    pub hard_min: f32,
    /// Largest hard visibility in the tile.
    pub hard_max: f32,
    /// Smallest eye depth of the tile's drawn pixels (`f32::MAX` if none).
    pub depth_min: f32,
    /// Largest eye depth of the tile's drawn pixels (0 if none).
    pub depth_max: f32,
    /// Largest horizontal and vertical kernel reach of its pixels (px).
    pub reach: [u32; 2],
    /// Some pixel of the tile shows the background (nothing drawn).
    pub background: bool,
}

/// Settings of the classification.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileSettings {
    /// The blur's depth rejection threshold (fraction of the centre's eye depth).
    pub depth_rejection: f32,
    /// Lazy shadowing on: rejected samples are replaced, not dropped.
    pub lazy_shadowing: bool,
    /// The blur's taps a side at most ([`kernel_reach`] depends on it once taps spread).
    pub taps_per_side: u32,
}

/// The farthest pixel a kernel of standard deviation `sigma` px reads
/// ([`kernel_extent`](super::kernel::kernel_extent): its last tap, or the end of that tap's cell).
pub fn kernel_reach(sigma: f32, taps_per_side: u32) -> u32 {
    super::kernel::kernel_extent(sigma, taps_per_side)
}

/// Tiles across and down a `width × height` screen.
pub fn tile_grid(width: usize, height: usize) -> (usize, usize) {
    (width.div_ceil(TILE), height.div_ceil(TILE))
}

/// The statistics of every tile, row-major.
pub fn tile_stats(buffers: &ScreenBuffers, taps_per_side: u32) -> Vec<TileStats> {
    let (w, h) = (buffers.width, buffers.height);
    let (tx, ty) = tile_grid(w, h);
    let mut stats = vec![
        TileStats {
            hard_min: f32::MAX,
            hard_max: f32::MIN,
            depth_min: f32::MAX,
            depth_max: 0.0,
            reach: [0, 0],
            background: false,
        };
        tx * ty
    ];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let s = &mut stats[(y / TILE) * tx + x / TILE];
            s.hard_min = s.hard_min.min(buffers.hard[i]);
            s.hard_max = s.hard_max.max(buffers.hard[i]);
            let z = buffers.depth[i];
            if z > 0.0 {
                s.depth_min = s.depth_min.min(z);
                s.depth_max = s.depth_max.max(z);
            } else {
                s.background = true;
            }
            for axis in 0..2 {
                s.reach[axis] =
                    s.reach[axis].max(kernel_reach(buffers.sigma[i][axis], taps_per_side));
            }
        }
    }
    stats
}

/// The tile range `[first, last]` covering pixels `start - reach ..= start + TILE - 1 + reach`
/// of a row or column of `tiles` tiles.
fn tile_span(tile: usize, reach: u32, tiles: usize) -> (usize, usize) {
    let start = (tile * TILE) as i64;
    let first = (start - reach as i64).max(0) / TILE as i64;
    let last = ((start + TILE as i64 - 1 + reach as i64) / TILE as i64).min(tiles as i64 - 1);
    (first as usize, last as usize)
}

/// Whether tile `(x, y)` must be blurred (see the module documentation).
pub fn is_active(
    stats: &[TileStats],
    tiles: (usize, usize),
    x: usize,
    y: usize,
    settings: &TileSettings,
) -> bool {
    let (tx, ty) = tiles;
    let own = stats[y * tx + x];
    if own.reach == [0, 0] {
        return false;
    }
    let (mut hard_min, mut hard_max) = (f32::MAX, f32::MIN);
    let (mut depth_min, mut depth_max, mut background) = (f32::MAX, 0.0f32, false);
    let (row_first, row_last) = tile_span(y, own.reach[1], ty);
    for row in row_first..=row_last {
        let (col_first, col_last) = tile_span(x, stats[row * tx + x].reach[0], tx);
        for col in col_first..=col_last {
            let s = stats[row * tx + col];
            hard_min = hard_min.min(s.hard_min);
            hard_max = hard_max.max(s.hard_max);
            depth_min = depth_min.min(s.depth_min);
            depth_max = depth_max.max(s.depth_max);
            background |= s.background;
        }
    }
    if hard_min != hard_max {
        return true;
    }
    settings.lazy_shadowing
        && (background
            || depth_max - depth_min > DEPTH_RANGE_MARGIN * settings.depth_rejection * depth_min)
}

/// The active tiles `(x, y)` of a frame, in row-major order.
pub fn active_tiles(buffers: &ScreenBuffers, settings: &TileSettings) -> Vec<[u32; 2]> {
    let tiles = tile_grid(buffers.width, buffers.height);
    let stats = tile_stats(buffers, settings.taps_per_side);
    let mut active = Vec::new();
    for y in 0..tiles.1 {
        for x in 0..tiles.0 {
            if is_active(&stats, tiles, x, y, settings) {
                active.push([x as u32, y as u32]);
            }
        }
    }
    active
}

/// The blur run on the active tiles only: the full-screen blur's result where a tile is active,
/// the hard visibility elsewhere — what the tiled passes compute.
pub fn tiled_soft_shadow(
    buffers: &ScreenBuffers,
    blur: super::blur::BlurSettings,
    settings: &TileSettings,
    lazy: &dyn Fn(usize, usize) -> Option<f32>,
) -> Vec<f32> {
    let full = super::blur::soft_shadow(buffers, blur, lazy);
    let tiles = tile_grid(buffers.width, buffers.height);
    let stats = tile_stats(buffers, settings.taps_per_side);
    let mut out = buffers.hard.clone();
    for y in 0..buffers.height {
        for x in 0..buffers.width {
            if is_active(&stats, tiles, x / TILE, y / TILE, settings) {
                out[y * buffers.width + x] = full[y * buffers.width + x];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ssss::blur::{BlurSettings, soft_shadow};

    /// A 48×40 screen: a ground at `depth` with a shadow edge at x = `edge`, blurred where
    /// `blurred(x, y)`.
    fn screen(edge: usize, depth: impl Fn(usize, usize) -> f32, sigma: f32) -> ScreenBuffers {
        let (w, h) = (48, 40);
        let mut b = ScreenBuffers {
            width: w,
            height: h,
            ..Default::default()
        };
        for y in 0..h {
            for x in 0..w {
                b.hard.push(if x < edge { 0.0 } else { 1.0 });
                b.depth.push(depth(x, y));
                b.sigma.push([sigma, sigma]);
            }
        }
        b
    }

    const BLUR: BlurSettings = BlurSettings {
        taps_per_side: 6,
        depth_rejection: 0.05,
    };

    #[test]
    fn kernel_reach_is_the_last_pixel_read() {
        use crate::ssss::kernel::{tap_cell, tap_offset, tap_offsets};
        for sigma in [0.01f32, 0.4, 1.0, 2.3, 7.9, 25.0] {
            let (n, step) = tap_offsets(sigma, 6);
            let last = if step == 1.0 {
                tap_offset(n as i32, step)
            } else {
                tap_cell(n as i32, step).1
            };
            assert_eq!(last as u32, kernel_reach(sigma, 6), "σ {sigma}");
        }
        assert_eq!(kernel_reach(0.0, 6), 0);
        // Spread taps read past the last tap: to the end of its cell.
        assert!(kernel_reach(25.0, 6) > (2.5f32 * 25.0).ceil() as u32);
    }

    #[test]
    fn only_tiles_within_reach_of_an_edge_are_active() {
        let b = screen(20, |_, _| 10.0, 2.0);
        let settings = TileSettings {
            depth_rejection: 0.05,
            lazy_shadowing: true,
            taps_per_side: BLUR.taps_per_side,
        };
        let active = active_tiles(&b, &settings);
        // Reach ceil(5.0) = 5 px: the edge at x = 20 (tile 2) reaches pixels 15..=24, tiles 1–3.
        let columns: Vec<u32> = {
            let mut c: Vec<u32> = active.iter().map(|t| t[0]).collect();
            c.sort();
            c.dedup();
            c
        };
        assert_eq!(columns, vec![1, 2, 3]);
        assert_eq!(active.len(), 3 * 5);
        // Without kernels nothing is active, edge or not.
        let flat = screen(20, |_, _| 10.0, 0.0);
        assert!(active_tiles(&flat, &settings).is_empty());
    }

    #[test]
    fn a_depth_step_is_active_with_lazy_shadowing_only() {
        // Uniformly lit, but a step in depth at x = 30: lazy shadowing may replace samples.
        let b = screen(0, |x, _| if x < 30 { 10.0 } else { 20.0 }, 2.0);
        let lazy = TileSettings {
            depth_rejection: 0.05,
            lazy_shadowing: true,
            taps_per_side: BLUR.taps_per_side,
        };
        let plain = TileSettings {
            lazy_shadowing: false,
            ..lazy
        };
        assert!(!active_tiles(&b, &lazy).is_empty());
        assert!(active_tiles(&b, &plain).is_empty());
    }

    #[test]
    fn the_tiled_blur_equals_the_full_screen_blur() {
        // Edges, depth steps, background and kernels of every size: the tiled result is the
        // full one, while a part of the screen is skipped.
        let mut b = screen(
            17,
            |x, y| {
                if x + y < 60 {
                    8.0 + 0.01 * x as f32
                } else {
                    0.0
                }
            },
            0.0,
        );
        for (i, s) in b.sigma.iter_mut().enumerate() {
            let (x, y) = (i % 48, i / 48);
            // Up to σ 3 px: reach 8 against 6 taps a side, so the widest kernels read cells.
            let sigma = ((x * 7 + y * 3) % 11) as f32 * 0.3;
            *s = [sigma, 0.6 * sigma];
            if y > 30 {
                b.hard[i] = 0.5;
            }
        }
        // A lazy sample that differs from every hard value, so a wrongly skipped tile shows.
        let lazy_value = |_: usize, _: usize| Some(0.25);
        for lazy_shadowing in [false, true] {
            let settings = TileSettings {
                depth_rejection: BLUR.depth_rejection,
                lazy_shadowing,
                taps_per_side: BLUR.taps_per_side,
            };
            let lazy: &dyn Fn(usize, usize) -> Option<f32> = if lazy_shadowing {
                &lazy_value
            } else {
                &|_, _| None
            };
            let full = soft_shadow(&b, BLUR, lazy);
            let tiled = tiled_soft_shadow(&b, BLUR, &settings, lazy);
            let worst = full
                .iter()
                .zip(&tiled)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(worst <= 1e-6, "lazy {lazy_shadowing}: worst {worst}");
            let (tx, ty) = tile_grid(48, 40);
            let active = active_tiles(&b, &settings).len();
            assert!(
                active < tx * ty,
                "lazy {lazy_shadowing}: all {active} tiles active"
            );
        }
    }

    #[test]
    fn the_vertical_pass_reaches_the_horizontal_kernels_of_the_rows_it_reads() {
        // Tile row 0 has wide horizontal kernels (reach 15 px) that cross the edge at x = 40
        // from x = 25 on. Tile (3, 1) (x 24..=31) has only a short vertical kernel and a
        // uniformly dark neighbourhood of its own, but it reads rows 5–7 of the horizontal
        // pass, which are no longer dark: it must be active.
        let mut b = screen(40, |_, _| 10.0, 0.0);
        for (i, s) in b.sigma.iter_mut().enumerate() {
            let (x, y) = (i % 48, i / 48);
            if y < 8 {
                *s = [6.0, 0.0];
            } else if y < 16 && (24..32).contains(&x) {
                *s = [0.0, 1.0];
            }
        }
        let settings = TileSettings {
            depth_rejection: 0.05,
            lazy_shadowing: false,
            taps_per_side: BLUR.taps_per_side,
        };
        let active = active_tiles(&b, &settings);
        assert!(active.contains(&[3, 1]), "{active:?}");
        // Its neighbour (2, 1) has no kernel: inactive.
        assert!(!active.contains(&[2, 1]));
        let full = soft_shadow(&b, BLUR, &|_, _| None);
        let tiled = tiled_soft_shadow(&b, BLUR, &settings, &|_, _| None);
        assert_ne!(full, b.hard, "the blur changes something");
        assert_eq!(full, tiled);
    }
}
