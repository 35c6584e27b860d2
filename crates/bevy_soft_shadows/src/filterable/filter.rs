//! How a filterable shadow map is made and read (Gumbau 2011, §7.2–7.3), on the CPU — the
//! reference of the passes that will do it on the GPU: each shadow-map depth becomes a texel of
//! statistics ([`FilterableMethod::encode`]); the map is pre-filtered by a separable Gaussian
//! ([`blur`]) and mip-mapped ([`mip_chain`]); a receiver reads it with the hardware's trilinear
//! filter at the mip its footprint asks for ([`sample`]) and turns the texel into a visibility
//! ([`FilterableMethod::visibility`]).
//!
//! Moments filter linearly — a blurred texel holds the moments of the depths under the kernel.
//! The power CDF's range does not: its minimum and maximum filter as a minimum and a maximum over
//! the kernel's support (and over the four texels below a mip texel), so the range always holds
//! every depth the mean was made from.

use super::visibility::{chebyshev, exponential, gaussian_cdf, hamburger_msm, power_cdf};
use bevy::reflect::Reflect;

/// Which statistics a filterable shadow map stores, and so which visibility function reads it.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub enum FilterableMethod {
    /// The thesis' Gaussian CDF (eq. 7.4) over `(E[z], E[z²])`.
    GaussianCdf,
    /// The thesis' power CDF (eq. 7.6–7.7) over `(mean, min, max)`.
    PowerCdf,
    /// Variance shadow maps: Chebyshev's bound over `(E[z], E[z²])`.
    Variance,
    /// Exponential shadow maps over `E[e^{c·z}]`.
    Exponential {
        /// The exponent's scale `c` (80 is usual for 32-bit storage).
        c: f32,
    },
    /// Four-moment shadow maps (Hamburger) over `(E[z], E[z²], E[z³], E[z⁴])`.
    Moments4,
}

/// How one channel of a texel filters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelFilter {
    /// A weighted mean (moments, the power CDF's mean).
    Mean,
    /// The minimum over the support.
    Min,
    /// The maximum over the support.
    Max,
}

/// The floor on the variance the two-moment methods read (depth quantisation and a flat texel's
/// zero variance; the usual VSM guard).
pub const MIN_VARIANCE: f32 = 1e-6;

/// The four-moment methods' moment bias for 32-bit storage (Peters and Klein 2015).
pub const MOMENT_BIAS: f32 = 3e-5;

impl FilterableMethod {
    /// The texel of one occluder depth `z` (light space, `[0, 1]`).
    pub fn encode(&self, z: f32) -> [f32; 4] {
        match self {
            Self::GaussianCdf | Self::Variance => [z, z * z, 0.0, 0.0],
            Self::PowerCdf => [z, z, z, 0.0],
            Self::Exponential { c } => [(c * z).exp(), 0.0, 0.0, 0.0],
            Self::Moments4 => {
                let z2 = z * z;
                [z, z2, z2 * z, z2 * z2]
            }
        }
    }

    /// How each channel filters.
    pub fn channels(&self) -> [ChannelFilter; 4] {
        use ChannelFilter::*;
        match self {
            Self::PowerCdf => [Mean, Min, Max, Mean],
            _ => [Mean; 4],
        }
    }

    /// The visibility of a receiver at depth `zr` read from a filtered texel.
    pub fn visibility(&self, texel: [f32; 4], zr: f32) -> f32 {
        match self {
            Self::GaussianCdf => gaussian_cdf([texel[0], texel[1]], zr, MIN_VARIANCE),
            Self::Variance => chebyshev([texel[0], texel[1]], zr, MIN_VARIANCE),
            Self::PowerCdf => power_cdf([texel[0], texel[1], texel[2]], zr),
            Self::Exponential { c } => exponential(texel[0], zr, *c),
            Self::Moments4 => hamburger_msm(texel, zr, MOMENT_BIAS),
        }
    }
}

/// What a shadow map's stored depths are, and so how the resolve turns them into the light-space
/// depth `z ∈ [0, 1]` the statistics are made of — larger farther from the light, linear in
/// distance so that the moments of a texel's depths describe distances (a perspective map's
/// `near / d` would crowd every depth beyond a few near planes into the last percent of the
/// range, where the two-moment methods' variance drowns in rounding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DepthSource {
    /// A directional light's cascade: Bevy stores reversed, linear depth (1 at the near plane),
    /// so `z = 1 − depth`.
    Cascade,
    /// A spot light's map: Bevy's infinite reverse-Z perspective stores `near / d`, `d` the
    /// distance along the spot's axis; `z = d / range`, clamped to 1 (the cleared depth 0 — no
    /// occluder — is `z = 1`).
    Spot {
        /// `SpotLight::shadow_map_near_z`.
        near: f32,
        /// `SpotLight::range`: the distance that maps to `z = 1`.
        range: f32,
    },
}

impl DepthSource {
    /// The light-space depth `z` of a stored depth.
    pub fn linear(&self, stored: f32) -> f32 {
        match *self {
            Self::Cascade => 1.0 - stored,
            Self::Spot { near, range } => {
                if stored <= 0.0 {
                    1.0
                } else {
                    (near / (stored * range)).min(1.0)
                }
            }
        }
    }
}

/// A filterable shadow map: `width × height` texels of statistics, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct MomentMap {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// Row-major texels.
    pub texels: Vec<[f32; 4]>,
}

impl MomentMap {
    /// The map of `depths` (`width × height`, row-major) under `method`.
    pub fn encode(method: FilterableMethod, width: u32, height: u32, depths: &[f32]) -> Self {
        assert_eq!(
            depths.len(),
            (width * height) as usize,
            "depths for every texel"
        );
        Self {
            width,
            height,
            texels: depths.iter().map(|&z| method.encode(z)).collect(),
        }
    }

    /// Texel `(x, y)`, clamped to the edges.
    pub fn at(&self, x: i64, y: i64) -> [f32; 4] {
        let x = x.clamp(0, self.width as i64 - 1) as u32;
        let y = y.clamp(0, self.height as i64 - 1) as u32;
        self.texels[(y * self.width + x) as usize]
    }
}

/// The normalised weights of a Gaussian of standard deviation `sigma` texels over `−r..=r`,
/// `r = ⌈2.5σ⌉` (what the separable blur's passes use).
pub fn gaussian_weights(sigma: f32) -> Vec<f32> {
    let sigma = sigma.max(1e-3);
    let r = (2.5 * sigma).ceil() as i64;
    let w: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let total: f32 = w.iter().sum();
    w.into_iter().map(|v| v / total).collect()
}

/// One pass of the separable filter along x (`horizontal`) or y: mean channels by the weights,
/// minimum and maximum channels over the weights' support, edges clamped.
fn filter_pass(
    map: &MomentMap,
    method: FilterableMethod,
    weights: &[f32],
    horizontal: bool,
) -> MomentMap {
    let r = (weights.len() / 2) as i64;
    let channels = method.channels();
    let mut texels = Vec::with_capacity(map.texels.len());
    for y in 0..map.height as i64 {
        for x in 0..map.width as i64 {
            let mut out = [0.0f32; 4];
            for (c, filter) in channels.iter().enumerate() {
                out[c] = match filter {
                    ChannelFilter::Mean => 0.0,
                    ChannelFilter::Min => f32::INFINITY,
                    ChannelFilter::Max => f32::NEG_INFINITY,
                };
            }
            for (k, w) in weights.iter().enumerate() {
                let o = k as i64 - r;
                let t = if horizontal {
                    map.at(x + o, y)
                } else {
                    map.at(x, y + o)
                };
                for (c, filter) in channels.iter().enumerate() {
                    match filter {
                        ChannelFilter::Mean => out[c] += w * t[c],
                        ChannelFilter::Min => out[c] = out[c].min(t[c]),
                        ChannelFilter::Max => out[c] = out[c].max(t[c]),
                    }
                }
            }
            texels.push(out);
        }
    }
    MomentMap {
        width: map.width,
        height: map.height,
        texels,
    }
}

/// The pre-filter: a separable Gaussian of `sigma` texels, horizontal then vertical.
pub fn blur(map: &MomentMap, method: FilterableMethod, sigma: f32) -> MomentMap {
    let weights = gaussian_weights(sigma);
    let h = filter_pass(map, method, &weights, true);
    filter_pass(&h, method, &weights, false)
}

/// The mip chain of `map` down to 1 × 1: each coarser texel the mean of the (up to) four below
/// it for mean channels, their minimum or maximum for range channels.
pub fn mip_chain(map: &MomentMap, method: FilterableMethod) -> Vec<MomentMap> {
    mip_chain_of_channels(map, method.channels())
}

/// [`mip_chain`] for texels whose channels filter as `channels` say.
pub fn mip_chain_of_channels(map: &MomentMap, channels: [ChannelFilter; 4]) -> Vec<MomentMap> {
    let mut chain = vec![map.clone()];
    while let Some(level) = chain.last().filter(|l| l.width > 1 || l.height > 1) {
        let (w, h) = (level.width.div_ceil(2), level.height.div_ceil(2));
        let mut texels = Vec::with_capacity((w * h) as usize);
        for y in 0..h {
            for x in 0..w {
                let below: Vec<[f32; 4]> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                    .iter()
                    .map(|&(dx, dy)| (2 * x + dx, 2 * y + dy))
                    .filter(|&(sx, sy)| sx < level.width && sy < level.height)
                    .map(|(sx, sy)| level.texels[(sy * level.width + sx) as usize])
                    .collect();
                let n = below.len() as f32;
                texels.push(std::array::from_fn(|c| match channels[c] {
                    ChannelFilter::Mean => below.iter().map(|t| t[c]).sum::<f32>() / n,
                    ChannelFilter::Min => below.iter().map(|t| t[c]).fold(f32::INFINITY, f32::min),
                    ChannelFilter::Max => {
                        below.iter().map(|t| t[c]).fold(f32::NEG_INFINITY, f32::max)
                    }
                }));
            }
        }
        chain.push(MomentMap {
            width: w,
            height: h,
            texels,
        });
    }
    chain
}

/// Level `level` at `uv` (`[0, 1]²`), bilinear between texel centres, edges clamped.
fn bilinear(level: &MomentMap, uv: [f32; 2]) -> [f32; 4] {
    let t = [
        uv[0] * level.width as f32 - 0.5,
        uv[1] * level.height as f32 - 0.5,
    ];
    let base = [t[0].floor(), t[1].floor()];
    let f = [t[0] - base[0], t[1] - base[1]];
    let (x, y) = (base[0] as i64, base[1] as i64);
    let (a, b, c, d) = (
        level.at(x, y),
        level.at(x + 1, y),
        level.at(x, y + 1),
        level.at(x + 1, y + 1),
    );
    std::array::from_fn(|i| {
        let top = a[i] + (b[i] - a[i]) * f[0];
        let bottom = c[i] + (d[i] - c[i]) * f[0];
        top + (bottom - top) * f[1]
    })
}

/// The hardware's trilinear read of `chain` at `uv` for a receiver whose footprint spans
/// `footprint` texels of level 0: the mips at `log2(footprint)` (clamped to the chain), each
/// bilinear, blended linearly. Every channel interpolates linearly here, range channels too —
/// what a sampler does; the range stays conservative within a texel of its true extent.
pub fn sample(chain: &[MomentMap], uv: [f32; 2], footprint: f32) -> [f32; 4] {
    let last = (chain.len() - 1) as f32;
    let lod = footprint.max(1.0).log2().clamp(0.0, last);
    let (lo, f) = (lod.floor(), lod - lod.floor());
    let a = bilinear(&chain[lo as usize], uv);
    if f <= 0.0 {
        return a;
    }
    let b = bilinear(&chain[(lo as usize + 1).min(chain.len() - 1)], uv);
    std::array::from_fn(|i| a[i] + (b[i] - a[i]) * f)
}

#[cfg(test)]
mod tests {
    use super::*;

    const METHODS: [FilterableMethod; 5] = [
        FilterableMethod::GaussianCdf,
        FilterableMethod::PowerCdf,
        FilterableMethod::Variance,
        FilterableMethod::Exponential { c: 80.0 },
        FilterableMethod::Moments4,
    ];

    /// A 32 × 8 map: an occluder at depth 0.3 over x < 16, nothing (the far plane) beyond.
    fn edge() -> (u32, u32, Vec<f32>) {
        let (w, h) = (32u32, 8u32);
        let depths = (0..w * h)
            .map(|i| if i % w < 16 { 0.3 } else { 1.0 })
            .collect();
        (w, h, depths)
    }

    /// A spot map's stored `near / d` becomes `d / range`: linear in distance, 1 where nothing
    /// was drawn and beyond the range; a cascade's reversed depth is flipped.
    #[test]
    fn depth_sources_give_linear_depth() {
        let spot = DepthSource::Spot {
            near: 0.1,
            range: 20.0,
        };
        for d in [0.1f32, 0.5, 3.0, 7.5, 19.9] {
            let z = spot.linear(0.1 / d);
            assert!((z - d / 20.0).abs() < 1e-6, "{d}: {z}");
        }
        // Equal steps in distance are equal steps in z (not so for the stored depth).
        let step = |a: f32, b: f32| spot.linear(0.1 / b) - spot.linear(0.1 / a);
        assert!((step(4.0, 5.0) - step(14.0, 15.0)).abs() < 1e-6);
        assert_eq!(spot.linear(0.0), 1.0);
        assert_eq!(spot.linear(0.1 / 40.0), 1.0);
        assert_eq!(DepthSource::Cascade.linear(0.25), 0.75);
    }

    /// An unfiltered texel is the hard shadow test, whatever the method.
    #[test]
    fn one_depth_is_the_hard_test() {
        for m in METHODS {
            for (z, zr) in [(0.4f32, 0.3f32), (0.4, 0.39), (0.4, 0.45), (0.4, 0.8)] {
                let v = m.visibility(m.encode(z), zr);
                let want = if zr <= z { 1.0 } else { 0.0 };
                // Chebyshev's variance floor and ESM's exponential (e^{−80·0.05} = 0.018) leave
                // a sliver close behind z.
                let tolerance = if zr - z > 0.04 { 0.02 } else { 0.6 };
                assert!((v - want).abs() <= tolerance, "{m:?}: z {z}, zr {zr}: {v}");
            }
        }
    }

    /// The blur's mean channels hold the Gaussian-weighted moments of the depths under it; its
    /// range channels the minimum and maximum over its support.
    #[test]
    fn the_blur_holds_the_statistics_of_the_depths_under_its_kernel() {
        let (w, h) = (12u32, 9u32);
        let depths: Vec<f32> = (0..w * h)
            .map(|i| 0.2 + 0.6 * (((i * 7919) % 97) as f32 / 97.0))
            .collect();
        let sigma = 1.2;
        let weights = gaussian_weights(sigma);
        let r = (weights.len() / 2) as i64;
        let depth = |x: i64, y: i64| {
            depths[(y.clamp(0, h as i64 - 1) * w as i64 + x.clamp(0, w as i64 - 1)) as usize]
        };
        for m in [FilterableMethod::Moments4, FilterableMethod::PowerCdf] {
            let blurred = blur(&MomentMap::encode(m, w, h, &depths), m, sigma);
            for (x, y) in [(0i64, 0i64), (5, 4), (11, 8), (3, 7)] {
                let mut want = [0.0f32; 4];
                let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                for (j, wy) in weights.iter().enumerate() {
                    for (i, wx) in weights.iter().enumerate() {
                        let z = depth(x + i as i64 - r, y + j as i64 - r);
                        let e = m.encode(z);
                        for c in 0..4 {
                            want[c] += wx * wy * e[c];
                        }
                        lo = lo.min(z);
                        hi = hi.max(z);
                    }
                }
                let got = blurred.at(x, y);
                if m == FilterableMethod::PowerCdf {
                    want[1] = lo;
                    want[2] = hi;
                }
                for c in 0..4 {
                    assert!(
                        (got[c] - want[c]).abs() < 1e-5,
                        "{m:?} ({x}, {y}) channel {c}: {got:?} vs {want:?}"
                    );
                }
            }
        }
    }

    /// A mip texel holds the mean of the level-0 texels it covers (their minimum and maximum for
    /// the range), down to one texel of the whole map.
    #[test]
    fn mips_hold_the_statistics_of_the_texels_they_cover() {
        let (w, h, depths) = edge();
        for m in METHODS {
            let chain = mip_chain(&MomentMap::encode(m, w, h, &depths), m);
            assert_eq!(chain.len(), 6);
            let top = chain.last().unwrap();
            assert_eq!((top.width, top.height), (1, 1));
            let mean: [f32; 4] = std::array::from_fn(|c| {
                depths.iter().map(|&z| m.encode(z)[c]).sum::<f32>() / depths.len() as f32
            });
            for (c, filter) in m.channels().iter().enumerate() {
                let want = match filter {
                    ChannelFilter::Mean => mean[c],
                    ChannelFilter::Min => 0.3,
                    ChannelFilter::Max => 1.0,
                };
                let scale = want.abs().max(1.0);
                assert!((top.texels[0][c] - want).abs() < 1e-5 * scale, "{m:?} {c}");
            }
            // Level 2 over x < 16: texels wholly in the occluder.
            let left = chain[2].at(1, 0);
            assert!((left[0] - m.encode(0.3)[0]).abs() < 1e-3 * m.encode(0.3)[0].max(1.0));
        }
    }

    /// Across a shadow edge blurred by σ texels, a receiver behind the occluder goes from dark
    /// to lit monotonically over a few σ, half lit within 1.5 σ of the edge on the occluder's
    /// side for the Gaussian CDF, the power CDF and four moments; read through a coarser mip,
    /// the penumbra reaches further into the shadow.
    #[test]
    fn a_blurred_edge_is_a_monotone_penumbra() {
        let (w, h, depths) = edge();
        let zr = 0.6;
        for m in [
            FilterableMethod::GaussianCdf,
            FilterableMethod::PowerCdf,
            FilterableMethod::Moments4,
            FilterableMethod::Variance,
        ] {
            let chain = mip_chain(&blur(&MomentMap::encode(m, w, h, &depths), m, 2.0), m);
            let ramp = |footprint: f32| -> Vec<f32> {
                (0..w)
                    .map(|x| {
                        let uv = [(x as f32 + 0.5) / w as f32, 0.5];
                        m.visibility(sample(&chain, uv, footprint), zr)
                    })
                    .collect()
            };
            let sharp = ramp(1.0);
            for pair in sharp.windows(2) {
                assert!(pair[1] >= pair[0] - 1e-4, "{m:?} not monotone: {sharp:?}");
            }
            assert!(
                sharp[..9].iter().all(|&v| v < 0.05),
                "{m:?} dark side: {sharp:?}"
            );
            assert!(
                sharp[22..].iter().all(|&v| v > 0.95),
                "{m:?} lit side: {sharp:?}"
            );
            let half = sharp.iter().position(|&v| v >= 0.5).unwrap() as i32;
            // Eq. 7.1–7.2 light a receiver wherever it is in front of the filtered mean depth,
            // which lies on the occluder's side of the edge: the half-light point comes before
            // the edge, by at most 1.5 σ for ours and four moments (Chebyshev only before it).
            eprintln!("{m:?}: half light at {half}");
            assert!(half <= 16, "{m:?}: half light at {half}");
            if m != FilterableMethod::Variance {
                assert!(half >= 13, "{m:?}: half light at {half}");
            }
            // Read through a coarser mip (a footprint of 4 texels) the penumbra stays monotone
            // and reaches further into the shadow.
            let wide = ramp(4.0);
            for pair in wide.windows(2) {
                assert!(
                    pair[1] >= pair[0] - 1e-4,
                    "{m:?} wide, not monotone: {wide:?}"
                );
            }
            let dark = |r: &[f32]| r.iter().filter(|&&v| v < 0.05).count();
            assert!(dark(&wide) < dark(&sharp), "{m:?}: {wide:?} vs {sharp:?}");
        }
    }
}
