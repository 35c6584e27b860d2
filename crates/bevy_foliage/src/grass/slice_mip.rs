//! The slices' custom mip filter (Boulanger 2008, thesis §4.3.3): each texel of a coarser mip
//! takes the alpha-weighted mean colour of the four finer texels and the *maximum* of their
//! alphas. An ordinary box filter averages thin blades' coverage away, so distant grass thins
//! out and the ground shows through; the maximum keeps the slices opaque with distance, which is
//! also what lets the horizontal slice make up for the vertical slices fading out in the second
//! transition (§4.2.5).
//!
//! The slices here are drawn with their opacity *dithered* rather than alpha-tested, which
//! makes the box filter's mean alpha the expected top-down coverage of the blades a texel stands
//! for — and with each quad of each cell dithering under its own shift (the layers a view ray
//! crosses then keep their blades independently, `1 − Π(1 − αᵢ)`, as real blades do), the mean is
//! also what a grazing view needs. Measured against an all-geometry render of the same field
//! (`grass_bench --preset quick`, camera 1.7 m up, 4 × 4-block colour error): with one dither
//! threshold shared by all layers, the maximum kept the distant grass whole but overcovered it
//! (0.045–0.052: the ground between the blades all but vanished), the mean thinned it (the
//! grazing dolly of the transition test lost up to 0.41 of a region's coverage); with per-quad
//! shifts the mean gives 0.020–0.030 and the dolly keeps its coverage. So the mean is the
//! default here, and the thesis' maximum stays a [`MipAlpha`] choice.

use bevy::reflect::Reflect;

/// How a coarser mip's alpha is made from the four finer texels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Reflect)]
pub enum MipAlpha {
    /// Their maximum (thesis §4.3.3, eq. 4.18): distant slices never thin out, but overcover
    /// where the blades leave ground between them.
    Max,
    /// Their mean: the expected coverage of the blades a texel stands for; with the slices'
    /// per-quad dither, crossed layers add up as the blades do.
    #[default]
    Mean,
}

/// One mip level of a `width × height` RGBA image in linear floats.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbaLevel {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// Row-major RGBA, straight (not premultiplied) colour.
    pub texels: Vec<[f32; 4]>,
}

/// The next coarser level of `level` by the custom filter: `⌈w/2⌉ × ⌈h/2⌉` texels, each from
/// the (up to) four texels below it — colour the alpha-weighted mean (the plain mean where all
/// four are transparent), alpha the maximum.
pub fn next_mip(level: &RgbaLevel) -> RgbaLevel {
    next_mip_with(level, MipAlpha::Max)
}

/// [`next_mip`] with the alpha made as `alpha` says (the mean over the texels present).
pub fn next_mip_with(level: &RgbaLevel, alpha_filter: MipAlpha) -> RgbaLevel {
    let (w, h) = (
        level.width.div_ceil(2).max(1),
        level.height.div_ceil(2).max(1),
    );
    let mut texels = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let mut sum = [0.0f32; 3];
            let mut plain = [0.0f32; 3];
            let (mut weight, mut alpha, mut count) = (0.0f32, 0.0f32, 0.0f32);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (sx, sy) = (2 * x + dx, 2 * y + dy);
                if sx >= level.width || sy >= level.height {
                    continue;
                }
                let t = level.texels[(sy * level.width + sx) as usize];
                for c in 0..3 {
                    sum[c] += t[c] * t[3];
                    plain[c] += t[c];
                }
                weight += t[3];
                alpha = alpha.max(t[3]);
                count += 1.0;
            }
            if alpha_filter == MipAlpha::Mean {
                alpha = weight / count;
            }
            let colour = if weight > 0.0 {
                sum.map(|s| s / weight)
            } else {
                plain.map(|s| s / count)
            };
            texels.push([colour[0], colour[1], colour[2], alpha]);
        }
    }
    RgbaLevel {
        width: w,
        height: h,
        texels,
    }
}

/// The whole chain below `level`, down to 1 × 1, by the thesis' filter (maximum alpha).
pub fn mip_chain(level: &RgbaLevel) -> Vec<RgbaLevel> {
    mip_chain_with(level, MipAlpha::Max)
}

/// The whole chain below `level`, down to 1 × 1, alpha made as `alpha` says.
pub fn mip_chain_with(level: &RgbaLevel, alpha: MipAlpha) -> Vec<RgbaLevel> {
    let mut chain = vec![level.clone()];
    while chain.last().is_some_and(|l| l.width > 1 || l.height > 1) {
        let next = next_mip_with(chain.last().unwrap(), alpha);
        chain.push(next);
    }
    chain
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_is_the_alpha_weighted_mean_and_alpha_the_maximum() {
        let level = RgbaLevel {
            width: 2,
            height: 2,
            texels: vec![
                [1.0, 0.0, 0.0, 1.0],
                [0.0, 1.0, 0.0, 0.5],
                [0.0, 0.0, 1.0, 0.0],
                [9.0, 9.0, 9.0, 0.0],
            ],
        };
        let next = next_mip(&level);
        assert_eq!((next.width, next.height), (1, 1));
        let t = next.texels[0];
        // Transparent texels' colours do not bleed in; the alpha stays that of the blade.
        assert!((t[0] - 1.0 / 1.5).abs() < 1e-6 && (t[1] - 0.5 / 1.5).abs() < 1e-6);
        assert_eq!((t[2], t[3]), (0.0, 1.0));
    }

    /// A thin blade one texel wide keeps its full alpha down the chain, where a box filter's
    /// alpha halves at every level.
    #[test]
    fn a_thin_blade_does_not_fade_with_distance() {
        let (w, h) = (16, 16);
        let texels = (0..w * h)
            .map(|i| {
                if i % w == 5 {
                    [0.2, 0.6, 0.1, 1.0]
                } else {
                    [0.0, 0.0, 0.0, 0.0]
                }
            })
            .collect();
        let chain = mip_chain(&RgbaLevel {
            width: w,
            height: h,
            texels,
        });
        assert_eq!(chain.len(), 5);
        let last = chain.last().unwrap().texels[0];
        assert_eq!(last, [0.2, 0.6, 0.1, 1.0]);
        // Odd sizes round up and keep the edge texels.
        let odd = next_mip(&RgbaLevel {
            width: 3,
            height: 1,
            texels: vec![[0.0; 4], [0.0; 4], [1.0, 1.0, 1.0, 0.5]],
        });
        assert_eq!((odd.width, odd.height), (2, 1));
        assert_eq!(odd.texels[1], [1.0, 1.0, 1.0, 0.5]);
    }

    /// The mean keeps the coverage a blade has: one texel of four at full alpha is a quarter.
    #[test]
    fn the_mean_alpha_is_the_expected_coverage() {
        let level = RgbaLevel {
            width: 2,
            height: 2,
            texels: vec![
                [1.0, 0.0, 0.0, 1.0],
                [0.0; 4],
                [0.0; 4],
                [0.0, 1.0, 0.0, 0.5],
            ],
        };
        let t = next_mip_with(&level, MipAlpha::Mean).texels[0];
        assert_eq!(t[3], 1.5 / 4.0);
        assert!((t[0] - 1.0 / 1.5).abs() < 1e-6 && (t[1] - 0.5 / 1.5).abs() < 1e-6);
        assert_eq!(next_mip_with(&level, MipAlpha::Max).texels[0][3], 1.0);
    }
}
