//! The Gaussian kernel of one blur pass (§6.2.3): taps at integer pixel offsets, one per pixel
//! while the kernel fits in `per_side` taps a side, spread evenly (and weighted at their true
//! offsets) beyond, so large penumbrae cost no more than `2·per_side + 1` taps a pass — the
//! thesis' 5×5 / 11×11 / 23×23 kernels are `per_side` 2 / 5 / 11.

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
}
