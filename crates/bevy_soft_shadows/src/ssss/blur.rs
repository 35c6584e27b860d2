//! CPU reference of the screen-space part of SSSS (§6.2.3, §6.3.2): the hard shadow blurred by a
//! horizontal then a vertical Gaussian pass, each pixel with its own kernel (eq. 6.2 scaled by the
//! kernel axes of its normal), samples rejected across depth discontinuities — or, with lazy
//! shadowing, replaced by a shadow-map test of the point the sample would be on the centre
//! pixel's tangent plane. Spread taps read the mean of their cell (`kernel::tap_cell`) from
//! fixed-point prefix sums of the pass's input along the pass ([`line_sums`]). The WGSL passes
//! compute exactly this; the render test compares them.

use super::kernel::{cell_mean, gaussian, tap_cell, tap_offset, tap_offsets, to_fixed};

/// Prefix sums of `input` (`width × height`, row-major) along rows (`horizontal`) or columns, in
/// the layout of `box_sums.wgsl`'s targets: rows give `(width + 1) × height` sums, entry
/// `y·(width + 1) + k` summing pixels `0..k` of row `y`; columns give `width × (height + 1)`,
/// entry `k·width + x` summing pixels `0..k` of column `x`. Terms are [`to_fixed`].
pub fn line_sums(input: &[f32], width: usize, height: usize, horizontal: bool) -> Vec<u32> {
    if horizontal {
        let mut sums = vec![0u32; (width + 1) * height];
        for y in 0..height {
            let mut s = 0u32;
            for x in 0..width {
                s = s.wrapping_add(to_fixed(input[y * width + x]));
                sums[y * (width + 1) + x + 1] = s;
            }
        }
        sums
    } else {
        let mut sums = vec![0u32; width * (height + 1)];
        for x in 0..width {
            let mut s = 0u32;
            for y in 0..height {
                s = s.wrapping_add(to_fixed(input[y * width + x]));
                sums[(y + 1) * width + x] = s;
            }
        }
        sums
    }
}

/// The screen-space inputs of the blur, row-major, `width × height`.
#[derive(Clone, Debug, Default)]
pub struct ScreenBuffers {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Hard-shadow visibility (1 lit, 0 shadowed).
    pub hard: Vec<f32>,
    /// Linear eye distance (view-space depth, m); `0` where nothing was drawn.
    pub depth: Vec<f32>,
    /// Kernel standard deviation in pixels along x and y (0 where the pixel is masked out).
    pub sigma: Vec<[f32; 2]>,
}

/// Settings of one blur.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlurSettings {
    /// Taps a side per pass at most.
    pub taps_per_side: u32,
    /// A sample is rejected when its depth differs from the centre's by more than this fraction
    /// of the centre's depth.
    pub depth_rejection: f32,
}

/// Whether a sample at depth `sample` may be blended into a pixel at depth `centre`.
pub fn accepts(centre: f32, sample: f32, depth_rejection: f32) -> bool {
    sample > 0.0 && (sample - centre).abs() <= depth_rejection * centre
}

/// One pass. `lazy(sample, centre)` gives the visibility to use for a rejected sample (lazy
/// shadowing), or `None` to drop it.
pub fn blur_pass(
    input: &[f32],
    buffers: &ScreenBuffers,
    settings: BlurSettings,
    horizontal: bool,
    lazy: &dyn Fn(usize, usize) -> Option<f32>,
) -> Vec<f32> {
    let (w, h) = (buffers.width, buffers.height);
    let mut out = input.to_vec();
    let sums = line_sums(input, w, h, horizontal);
    // The sum of pixels `first..=last` along the pass through `(x, y)`.
    let cell_sum = |x: usize, y: usize, first: usize, last: usize| {
        if horizontal {
            sums[y * (w + 1) + last + 1].wrapping_sub(sums[y * (w + 1) + first])
        } else {
            sums[(last + 1) * w + x].wrapping_sub(sums[first * w + x])
        }
    };
    for y in 0..h {
        for x in 0..w {
            let centre = y * w + x;
            let z = buffers.depth[centre];
            let sigma = buffers.sigma[centre][if horizontal { 0 } else { 1 }];
            if z <= 0.0 || sigma <= 0.0 {
                continue;
            }
            let (n, step) = tap_offsets(sigma, settings.taps_per_side);
            let (mut sum, mut weights) = (0.0f32, 0.0f32);
            for i in -(n as i32)..=n as i32 {
                let offset = tap_offset(i, step);
                let (sx, sy) = if horizontal {
                    (x as i32 + offset, y as i32)
                } else {
                    (x as i32, y as i32 + offset)
                };
                if sx < 0 || sy < 0 || sx >= w as i32 || sy >= h as i32 {
                    continue;
                }
                let sample = sy as usize * w + sx as usize;
                // A spread tap stands for its cell, clamped to the line: it reads the cell's
                // mean and weighs as many pixels. (Depth is tested at the tap itself.)
                let (along, len) = if horizontal { (x, w) } else { (y, h) };
                let (first, last) = tap_cell(i, step);
                let first = (along as i32 + first).max(0) as usize;
                let last = (along as i32 + last).min(len as i32 - 1) as usize;
                let count = (last - first + 1) as u32;
                let value = if accepts(z, buffers.depth[sample], settings.depth_rejection) {
                    if step > 1.0 {
                        cell_mean(cell_sum(x, y, first, last), count)
                    } else {
                        input[sample]
                    }
                } else if let Some(v) = lazy(sample, centre) {
                    v
                } else {
                    continue;
                };
                let weight = gaussian(offset as f32, sigma) * count as f32;
                sum += weight * value;
                weights += weight;
            }
            if weights > 0.0 {
                out[centre] = sum / weights;
            }
        }
    }
    out
}

/// The soft shadow: the horizontal pass, then the vertical pass on its result.
pub fn soft_shadow(
    buffers: &ScreenBuffers,
    settings: BlurSettings,
    lazy: &dyn Fn(usize, usize) -> Option<f32>,
) -> Vec<f32> {
    let horizontal = blur_pass(&buffers.hard, buffers, settings, true, lazy);
    blur_pass(&horizontal, buffers, settings, false, lazy)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ssss::penumbra::erf;

    fn plane(w: usize, h: usize, sigma: f32) -> ScreenBuffers {
        ScreenBuffers {
            width: w,
            height: h,
            // A vertical shadow edge: shadowed left of x = w/2.
            hard: (0..w * h)
                .map(|i| if i % w < w / 2 { 0.0 } else { 1.0 })
                .collect(),
            depth: vec![10.0; w * h],
            sigma: vec![[sigma, sigma]; w * h],
        }
    }

    const SETTINGS: BlurSettings = BlurSettings {
        taps_per_side: 11,
        depth_rejection: 0.05,
    };

    #[test]
    fn a_hard_edge_becomes_the_gaussian_cdf() {
        let (w, h, sigma) = (64, 8, 3.0f32);
        let soft = soft_shadow(&plane(w, h, sigma), SETTINGS, &|_, _| None);
        for x in 20..44 {
            // Pixel x is lit when x ≥ 32: the discrete CDF of the kernel at x − 32 + ½.
            let d = x as f32 - 31.5;
            let expected = 0.5 * (1.0 + erf(d / (sigma * std::f32::consts::SQRT_2)));
            let got = soft[4 * w + x];
            assert!((got - expected).abs() < 0.04, "x {x}: {got} vs {expected}");
        }
        // Rows are identical (the vertical pass leaves a vertical edge alone).
        for x in 0..w {
            assert!((soft[w + x] - soft[5 * w + x]).abs() < 1e-5);
        }
    }

    #[test]
    fn samples_across_a_depth_discontinuity_are_rejected_or_lazily_shadowed() {
        let (w, h) = (32, 4);
        let mut b = plane(w, h, 4.0);
        // Left half: a near object in shadow; right half: far ground, lit.
        for i in 0..w * h {
            b.depth[i] = if i % w < w / 2 { 5.0 } else { 50.0 };
        }
        let soft = soft_shadow(&b, SETTINGS, &|_, _| None);
        assert_eq!(soft[w + 15], 0.0, "no light bleeds onto the near object");
        assert_eq!(soft[w + 16], 1.0, "no shadow bleeds onto the far ground");
        // Lazy shadowing: rejected samples re-tested (here: all in shadow) darken the ground.
        let lazy = soft_shadow(&b, SETTINGS, &|_, _| Some(0.0));
        assert!(lazy[w + 16] < 0.7, "{}", lazy[w + 16]);
    }

    #[test]
    fn masked_pixels_keep_their_hard_shadow() {
        let soft = soft_shadow(&plane(16, 4, 0.0), SETTINGS, &|_, _| None);
        assert_eq!(soft, plane(16, 4, 0.0).hard);
    }
}
