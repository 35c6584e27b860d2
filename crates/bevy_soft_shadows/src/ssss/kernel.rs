//! The Gaussian kernel of one blur pass (§6.2.3): taps at integer pixel offsets, one per pixel
//! while the kernel fits in `per_side` taps a side, spread evenly (and weighted at their true
//! offsets) beyond, so large penumbrae cost no more than `2·per_side + 1` taps a pass — the
//! thesis' 5×5 / 11×11 / 23×23 kernels are `per_side` 2 / 5 / 11.
//!
//! Spread taps sample the hard shadow more sparsely than it varies where fine blockers (slats,
//! leaflets) cast stripes narrower than the tap spacing: point samples alias those stripes into
//! streaks across the penumbra. So a spread tap stands for its whole *cell* — the pixels nearer
//! to it than to its neighbours ([`tap_cell`]) — and reads their mean from prefix sums along the
//! pass ([`to_fixed`], `box_sums.wgsl`): a box prefilter of the tap spacing, for two reads a tap.

/// How far a kernel reaches, in standard deviations.
pub const KERNEL_REACH_SIGMAS: f32 = 2.5;

/// One tap: pixel offset and normalised weight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tap {
    /// Offset from the centre pixel along the pass.
    pub offset: i32,
    /// Weight (the taps of a kernel sum to 1).
    pub weight: f32,
}

/// The offset of tap `i ∈ [−n, n]` of a kernel of standard deviation `sigma_px` with at most
/// `per_side` taps a side, and `n` (the taps a side actually used).
pub fn tap_offsets(sigma_px: f32, per_side: u32) -> (u32, f32) {
    let reach = (KERNEL_REACH_SIGMAS * sigma_px.max(0.0)).ceil();
    if reach <= per_side as f32 {
        (reach as u32, 1.0)
    } else {
        (per_side, reach / per_side as f32)
    }
}

/// The pixel offset of tap `i` at spacing `step`: `sign(i)·⌊|i|·step + ½⌋`, symmetric and the
/// same in WGSL (whose `round` rounds halves to even, unlike Rust's).
pub fn tap_offset(i: i32, step: f32) -> i32 {
    let magnitude = ((i.unsigned_abs() as f32) * step + 0.5).floor() as i32;
    if i < 0 { -magnitude } else { magnitude }
}

/// The last pixel offset of the cell of tap `k ≥ 0`: halfway (rounded down) between taps `k` and
/// `k + 1` — past the last tap, a virtual one a spacing further.
fn cell_end(k: u32, step: f32) -> i32 {
    let (a, b) = (tap_offset(k as i32, step), tap_offset(k as i32 + 1, step));
    (a + b).div_euclid(2)
}

/// The pixel offsets `[first, last]` tap `i` stands for: the pixels nearer to it than to the
/// taps beside it (its own pixel while taps are one per pixel). The cells of a kernel tile its
/// reach without gap or overlap and are symmetric about the centre.
pub fn tap_cell(i: i32, step: f32) -> (i32, i32) {
    let m = i.unsigned_abs();
    let last = cell_end(m, step);
    let first = if m == 0 {
        -last
    } else {
        cell_end(m - 1, step) + 1
    };
    if i < 0 {
        (-last, -first)
    } else {
        (first, last)
    }
}

/// The farthest pixel a kernel of standard deviation `sigma_px` with at most `per_side` taps a
/// side reads: the last tap itself (`⌈2.5σ⌉`) while taps are one per pixel, the end of its cell
/// once they spread.
pub fn kernel_extent(sigma_px: f32, per_side: u32) -> u32 {
    if sigma_px <= 0.0 {
        return 0;
    }
    let (n, step) = tap_offsets(sigma_px, per_side);
    tap_cell(n as i32, step).1 as u32
}

/// Fixed-point scale of the prefix sums the cells are read from: sums of whole lines are exact
/// (a 65,535-pixel line of ones stays below 2³²), so a constant run of pixels reads back exactly
/// and the GPU's sums equal the CPU's bit for bit.
pub const SUM_SCALE: f32 = 65536.0;

/// A visibility in [0, 1] as a prefix-sum term (`box_sums.wgsl`'s `to_fixed`).
pub fn to_fixed(v: f32) -> u32 {
    (v.clamp(0.0, 1.0) * SUM_SCALE + 0.5) as u32
}

/// The mean of a cell of `count` pixels from the difference of two prefix sums.
pub fn cell_mean(sum: u32, count: u32) -> f32 {
    sum as f32 / (SUM_SCALE * count as f32)
}

/// Unnormalised Gaussian weight at `offset`.
pub fn gaussian(offset: f32, sigma_px: f32) -> f32 {
    if sigma_px <= 0.0 {
        return if offset == 0.0 { 1.0 } else { 0.0 };
    }
    (-offset * offset / (2.0 * sigma_px * sigma_px)).exp()
}

/// The taps of a kernel of standard deviation `sigma_px` (see the module doc).
pub fn gaussian_taps(sigma_px: f32, per_side: u32) -> Vec<Tap> {
    let (n, step) = tap_offsets(sigma_px, per_side);
    let mut taps: Vec<Tap> = (-(n as i32)..=n as i32)
        .map(|i| {
            let offset = tap_offset(i, step);
            Tap {
                offset,
                weight: gaussian(offset as f32, sigma_px),
            }
        })
        .collect();
    let sum: f32 = taps.iter().map(|t| t.weight).sum();
    for t in &mut taps {
        t.weight /= sum;
    }
    taps
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_are_normalised_symmetric_and_have_the_right_spread() {
        for (sigma, per_side) in [
            (0.0, 5),
            (0.7, 5),
            (2.0, 5),
            (4.0, 11),
            (9.0, 5),
            (20.0, 11),
        ] {
            let taps = gaussian_taps(sigma, per_side);
            assert!(taps.len() <= 2 * per_side as usize + 1);
            let sum: f32 = taps.iter().map(|t| t.weight).sum();
            assert!((sum - 1.0).abs() < 1e-5);
            for (a, b) in taps.iter().zip(taps.iter().rev()) {
                assert_eq!(a.offset, -b.offset);
                assert!((a.weight - b.weight).abs() < 1e-6);
            }
            let variance: f32 = taps
                .iter()
                .map(|t| t.weight * (t.offset * t.offset) as f32)
                .sum();
            if sigma >= 2.0 {
                // Truncated at 2.5σ and sampled: within 12 % of σ².
                let ratio = variance / (sigma * sigma);
                assert!(
                    (0.78..=1.05).contains(&ratio),
                    "σ {sigma}: variance ratio {ratio}"
                );
            } else if sigma == 0.0 {
                assert_eq!(
                    taps,
                    vec![Tap {
                        offset: 0,
                        weight: 1.0
                    }]
                );
            }
        }
    }

    #[test]
    fn small_kernels_tap_every_pixel_and_large_ones_spread() {
        let (n, step) = tap_offsets(1.5, 5);
        assert_eq!((n, step), (4, 1.0));
        let (n, step) = tap_offsets(10.0, 5);
        assert_eq!(n, 5);
        assert!((step - 5.0).abs() < 1e-6);
        let offsets: Vec<i32> = gaussian_taps(10.0, 5).iter().map(|t| t.offset).collect();
        assert_eq!(offsets, vec![-25, -20, -15, -10, -5, 0, 5, 10, 15, 20, 25]);
    }

    #[test]
    fn cells_tile_the_kernel_and_hold_their_taps() {
        for (sigma, per_side) in [(1.5f32, 5u32), (10.0, 5), (7.3, 11), (25.0, 11), (3.9, 2)] {
            let (n, step) = tap_offsets(sigma, per_side);
            let n = n as i32;
            let mut next = tap_cell(-n, step).0;
            for i in -n..=n {
                let (first, last) = tap_cell(i, step);
                assert_eq!(
                    first,
                    next,
                    "σ {sigma}: cell {i} starts where {} ended",
                    i - 1
                );
                assert!(first <= tap_offset(i, step) && tap_offset(i, step) <= last);
                assert_eq!(tap_cell(-i, step), (-last, -first));
                next = last + 1;
            }
            assert_eq!(next - 1, kernel_extent(sigma, per_side) as i32);
            if step == 1.0 {
                assert_eq!(kernel_extent(sigma, per_side), n as u32);
            } else {
                // Cells are a spacing wide, give or take the rounding.
                let (first, last) = tap_cell(1, step);
                assert!(((last - first + 1) as f32 - step).abs() <= 1.0);
            }
        }
        assert_eq!(kernel_extent(0.0, 5), 0);
        assert_eq!(tap_cell(3, 1.0), (3, 3));
    }

    #[test]
    fn fixed_point_sums_are_exact_over_constant_runs() {
        assert_eq!(to_fixed(1.0), SUM_SCALE as u32);
        assert_eq!(to_fixed(-0.5), 0);
        let ones = 4000 * to_fixed(1.0);
        assert_eq!(cell_mean(ones, 4000), 1.0);
        assert!((cell_mean(3 * to_fixed(0.3), 3) - 0.3).abs() < 1e-5);
    }
}
