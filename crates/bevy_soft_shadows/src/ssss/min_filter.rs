//! The "dilated" shadow map of §6.2.1: a separable filter keeping, over a square of
//! `2r + 1` texels, the depth nearest the light, so pixels in the outer penumbra (lit in the hard
//! shadow map) still find the blocker whose penumbra covers them. It is only used for the
//! blocker distance, never for the shadow itself.
//!
//! Bevy's shadow maps use reverse Z (1 at the light's near plane, 0 at the far one), so "nearest
//! the light" is the *largest* stored value: [`DepthConvention`] says which.

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

#[cfg(test)]
mod tests {
    use super::*;

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
