//! Visibility from a *filtered* shadow map (Gumbau 2011, ch. 7): the shadow map stores
//! statistics of the occluders' depths instead of one depth — moments, or a mean with the range —
//! so it can be blurred and mip-mapped like any texture; a receiver at depth `zr` then asks the
//! filtered statistics what share of the occluders within the filter lies behind it.
//!
//! Each function here takes the filtered statistics a texel holds and the receiver's depth and
//! returns its visibility in `[0, 1]` (1 lit). Depths are light-space, normalised to `[0, 1]`,
//! larger farther from the light. The GPU samples the same functions; these are their
//! references.
//!
//! - [`chebyshev`]: variance shadow maps (Donnelly and Lauritzen 2006), the one-tailed
//!   Chebyshev bound `σ² / (σ² + (zr − μ)²)` — the baseline, and the one that bleeds light
//!   where occluders are stacked.
//! - [`exponential`]: exponential shadow maps (Annen et al. 2008), `E[e^{c·zo}] · e^{−c·zr}`.
//! - [`gaussian_cdf`]: eq. 7.4, the occluder depths taken as a normal distribution of the same
//!   two moments, biased by eq. 7.1–7.2 so an unoccluded plane is fully lit.
//! - [`power_cdf`]: eq. 7.6–7.7, a power law between the texel's minimum and maximum depth whose
//!   mean is the filtered mean — three channels that survive 16-bit storage.
//! - [`hamburger_msm`]: four-moment shadow maps (Peters and Klein 2015, Hamburger variant), the
//!   best published filterable method since the thesis; a baseline beside ours.

/// The two moments `(E[z], E[z²])` of occluder depths `depths` with weights (a filter's taps).
pub fn moments2(depths: &[(f32, f32)]) -> [f32; 2] {
    let total: f32 = depths.iter().map(|d| d.1).sum();
    let mut m = [0.0f32; 2];
    for &(z, w) in depths {
        m[0] += w * z;
        m[1] += w * z * z;
    }
    m.map(|v| v / total.max(f32::MIN_POSITIVE))
}

/// The four moments `(E[z], E[z²], E[z³], E[z⁴])` of weighted occluder depths.
pub fn moments4(depths: &[(f32, f32)]) -> [f32; 4] {
    let total: f32 = depths.iter().map(|d| d.1).sum();
    let mut m = [0.0f32; 4];
    for &(z, w) in depths {
        let z2 = z * z;
        m[0] += w * z;
        m[1] += w * z2;
        m[2] += w * z2 * z;
        m[3] += w * z2 * z2;
    }
    m.map(|v| v / total.max(f32::MIN_POSITIVE))
}

/// What the power CDF stores of weighted occluder depths: `(mean, min, max)` (eq. 7.6). The mean
/// filters linearly; the minimum and maximum filter as a minimum and a maximum.
pub fn mean_range(depths: &[(f32, f32)]) -> [f32; 3] {
    let total: f32 = depths.iter().map(|d| d.1).sum();
    let mean = depths.iter().map(|&(z, w)| z * w).sum::<f32>() / total.max(f32::MIN_POSITIVE);
    let min = depths.iter().map(|d| d.0).fold(f32::INFINITY, f32::min);
    let max = depths.iter().map(|d| d.0).fold(f32::NEG_INFINITY, f32::max);
    [mean, min, max]
}

/// The mean of `e^{c·z}` over weighted occluder depths: what an exponential shadow map stores.
pub fn exponential_moment(depths: &[(f32, f32)], c: f32) -> f32 {
    let total: f32 = depths.iter().map(|d| d.1).sum();
    depths.iter().map(|&(z, w)| w * (c * z).exp()).sum::<f32>() / total.max(f32::MIN_POSITIVE)
}

/// Variance shadow maps: the one-tailed Chebyshev bound on the share of occluders at or behind
/// `zr`, from the moments `m = (E[z], E[z²])`; the variance is kept at least `min_variance` (the
/// usual guard against a flat texel's zero variance and depth quantisation).
pub fn chebyshev(m: [f32; 2], zr: f32, min_variance: f32) -> f32 {
    let mean = m[0];
    if zr <= mean {
        return 1.0;
    }
    let variance = (m[1] - mean * mean).max(min_variance);
    let d = zr - mean;
    (variance / (variance + d * d)).clamp(0.0, 1.0)
}

/// Exponential shadow maps: `E[e^{c·zo}] · e^{−c·zr}`, clamped to `[0, 1]` (exact for one
/// occluder in front of the receiver; light leaks where the receiver is close behind it).
pub fn exponential(moment: f32, zr: f32, c: f32) -> f32 {
    (moment * (-c * zr).exp()).clamp(0.0, 1.0)
}

/// The error function by the closed-form approximation the thesis uses (`a ≈ 0.140012`,
/// Winitzki): `sign(x)·√(1 − e^{−x²(4/π + a x²)/(1 + a x²)})`, within 3.3·10⁻⁴ of `erf` (its
/// worst, near x = 1; Winitzki's own a = 0.147 would give 1.3·10⁻⁴).
pub fn erf(x: f32) -> f32 {
    const A: f32 = 0.140_012;
    let x2 = x * x;
    let inner = -x2 * (4.0 / std::f32::consts::PI + A * x2) / (1.0 + A * x2);
    (1.0 - inner.exp()).max(0.0).sqrt().copysign(x)
}

/// Eq. 7.4: the occluder depths as a normal distribution of the filtered moments
/// `m = (E[z], E[z²])` (variance at least `min_variance`); the visibility of eq. 7.1–7.2 biased
/// by the share at the mean, `(1 − F(zr)) / (1 − F(μ))`, which is `1 − erf((zr − μ)/(σ√2))`
/// behind the mean and 1 in front of it.
pub fn gaussian_cdf(m: [f32; 2], zr: f32, min_variance: f32) -> f32 {
    let mean = m[0];
    if zr <= mean {
        return 1.0;
    }
    let sigma = (m[1] - mean * mean).max(min_variance).sqrt();
    (1.0 - erf((zr - mean) / (sigma * std::f32::consts::SQRT_2))).clamp(0.0, 1.0)
}

/// Eq. 7.6–7.7: the occluder depths as the power law `F(t) = t^β` over the texel's range
/// `[min, max]` (`t = (z − min)/(max − min)`), its exponent `β = (μ − min)/(max − μ)` making its
/// mean the filtered mean `μ`; visibility `(1 − t^β)/(1 − t̄^β)` behind the mean
/// (`t̄ = β/(β+1)`), 1 in front. `s = (mean, min, max)` as [`mean_range`] gives it; a texel
/// without range (one depth) is a hard test.
pub fn power_cdf(s: [f32; 3], zr: f32) -> f32 {
    let [mean, min, max] = s;
    let range = max - min;
    if range.is_nan() || range <= 1e-6 {
        return if zr <= max { 1.0 } else { 0.0 };
    }
    let mean = mean.clamp(min, max);
    if zr >= max {
        return 0.0;
    }
    let t = ((zr - min) / range).max(0.0);
    let beta = ((mean - min) / (max - mean).max(1e-6)).max(1e-6);
    let t_mean = beta / (beta + 1.0);
    if t <= t_mean {
        return 1.0;
    }
    let at_mean = 1.0 - t_mean.powf(beta);
    ((1.0 - t.powf(beta)) / at_mean.max(1e-6)).clamp(0.0, 1.0)
}

/// Four-moment shadow maps, Hamburger variant (Peters and Klein 2015, algorithm 3): from the
/// moments `b = (E[z], E[z²], E[z³], E[z⁴])`, pulled towards `(0.5, 0.5, 0.5, 0.5)` by
/// `moment_bias` (3·10⁻⁵ for 32-bit storage) so the Hankel matrix stays positive definite, the
/// sharpest lower bound on the share of occluders in front of `zr` that any distribution with
/// these moments allows; visibility is one minus it.
pub fn hamburger_msm(b: [f32; 4], zr: f32, moment_bias: f32) -> f32 {
    // In f64: the Cholesky factors of nearly singular Hankel matrices lose the f32 digits.
    let bias = moment_bias as f64;
    let b = b.map(|v| v as f64 * (1.0 - bias) + 0.5 * bias);
    let z0 = zr as f64;
    // Solve B·c = (1, z, z²) for the Hankel matrix of (1, b1, b2; b1, b2, b3; b2, b3, b4) by its
    // Cholesky factorisation.
    let l32_d22 = -b[0] * b[1] + b[2];
    let d22 = -b[0] * b[0] + b[1];
    let squared_depth_variance = -b[1] * b[1] + b[3];
    let d33_d22 = squared_depth_variance * d22 - l32_d22 * l32_d22;
    if !(d22 > 0.0 && d33_d22 > 0.0) {
        // A degenerate distribution (one depth): a hard test against its mean.
        return if zr as f64 <= b[0] + 1e-6 { 1.0 } else { 0.0 };
    }
    let inv_d22 = 1.0 / d22;
    let l32 = l32_d22 * inv_d22;
    let mut c = [1.0, z0, z0 * z0];
    c[1] -= b[0];
    c[2] -= b[1] + l32 * c[1];
    c[1] *= inv_d22;
    c[2] *= d22 / d33_d22;
    c[1] -= l32 * c[2];
    c[0] -= c[1] * b[0] + c[2] * b[1];
    // The roots z1 ≤ z2 of c₂z² + c₁z + c₀: with z0 the support of the bounding distribution.
    let p = c[1] / c[2];
    let q = c[0] / c[2];
    let r = (p * p * 0.25 - q).max(0.0).sqrt();
    let (z1, z2) = (-p * 0.5 - r, -p * 0.5 + r);
    let switch = if z2 < z0 {
        [z1, z0, 1.0, 1.0]
    } else if z1 < z0 {
        [z0, z1, 0.0, 1.0]
    } else {
        [0.0, 0.0, 0.0, 0.0]
    };
    let quotient =
        (switch[0] * z2 - b[0] * (switch[0] + z2) + b[1]) / ((z2 - switch[1]) * (z0 - z1));
    let shadow = (switch[2] + switch[3] * quotient).clamp(0.0, 1.0);
    (1.0 - shadow) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SplitMix64 (Steele et al. 2014): seeded uniforms for the sampled distributions.
    struct SplitMix64(u64);

    impl SplitMix64 {
        fn new(seed: u64) -> Self {
            Self(seed)
        }
        fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }
        /// Uniform in [0, 1).
        fn next_f32(&mut self) -> f32 {
            (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
        }
        fn range(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (hi - lo) * self.next_f32()
        }
    }

    /// Depth samples of a distribution: `n` draws of `sample(u)` for uniform `u`, equal weights.
    fn draws(n: usize, seed: u64, sample: impl Fn(f32) -> f32) -> Vec<(f32, f32)> {
        let mut rng = SplitMix64::new(seed);
        (0..n).map(|_| (sample(rng.next_f32()), 1.0)).collect()
    }

    /// The exact visibility of a receiver among occluders `depths` (lit by those at or behind it).
    fn truth(depths: &[(f32, f32)], zr: f32) -> f32 {
        let total: f32 = depths.iter().map(|d| d.1).sum();
        depths
            .iter()
            .filter(|d| d.0 >= zr)
            .map(|d| d.1)
            .sum::<f32>()
            / total
    }

    #[test]
    fn erf_is_within_its_stated_error() {
        // Reference values of erf.
        for (x, want) in [
            (0.0f32, 0.0f32),
            (0.25, 0.276_326_4),
            (0.5, 0.520_499_9),
            (1.0, 0.842_700_8),
            (1.5, 0.966_105_2),
            (2.0, 0.995_322_3),
            (3.0, 0.999_977_9),
        ] {
            assert!((erf(x) - want).abs() < 3.3e-4, "erf({x}) = {}", erf(x));
            assert!((erf(-x) + want).abs() < 3.3e-4);
        }
    }

    /// Every method: in `[0, 1]`, lit in front of all occluders, never brighter farther behind
    /// them, and dark well behind a single flat occluder.
    #[test]
    fn every_method_is_a_monotone_visibility() {
        let mut rng = SplitMix64::new(3);
        for _ in 0..300 {
            let centre = rng.range(0.2, 0.8);
            let spread = rng.range(0.0, 0.15);
            let occluders = draws(64, rng.next_u64(), |u| centre + spread * (u - 0.5));
            let (m2, m4, s, e) = (
                moments2(&occluders),
                moments4(&occluders),
                mean_range(&occluders),
                exponential_moment(&occluders, 80.0),
            );
            let methods = |zr: f32| {
                [
                    chebyshev(m2, zr, 1e-6),
                    exponential(e, zr, 80.0),
                    gaussian_cdf(m2, zr, 1e-6),
                    power_cdf(s, zr),
                    hamburger_msm(m4, zr, 3e-5),
                ]
            };
            let mut previous = [1.0f32; 5];
            for k in 0..=100 {
                let zr = k as f32 / 100.0;
                let v = methods(zr);
                for (i, (&now, &before)) in v.iter().zip(&previous).enumerate() {
                    assert!((0.0..=1.0).contains(&now), "method {i} at {zr}: {now}");
                    assert!(
                        now <= before + 1e-4,
                        "method {i} brightens at {zr}: {before} → {now}"
                    );
                }
                previous = v;
            }
            // In front of every occluder: lit (ESM up to its leak-free margin).
            let front = s[1] - 0.01;
            for (i, v) in methods(front).iter().enumerate() {
                assert!(
                    *v > 0.99 || (i == 1 && *v > 0.4),
                    "method {i} in front: {v}"
                );
            }
        }
        // One flat occluder, the receiver 0.1 behind it: every method dark.
        let flat = [(0.4, 1.0)];
        assert_eq!(chebyshev(moments2(&flat), 0.5, 1e-5), 1e-5 / (1e-5 + 0.01));
        assert!(gaussian_cdf(moments2(&flat), 0.5, 1e-5) < 1e-6);
        assert_eq!(power_cdf(mean_range(&flat), 0.5), 0.0);
        assert!(exponential(exponential_moment(&flat, 80.0), 0.5, 80.0) < 4e-4);
        assert!(hamburger_msm(moments4(&flat), 0.5, 3e-5) < 0.01);
    }

    /// The classic failure of variance shadow maps: two occluders stacked over a receiver that
    /// both shadow fully. Chebyshev leaks a quarter of the light; the Gaussian CDF a tenth of
    /// that; four moments see both occluders (they determine a two-point distribution).
    #[test]
    fn stacked_occluders_bleed_less_light_through_the_gaussian_cdf_than_through_chebyshev() {
        let stacked = [(0.2, 1.0), (0.5, 1.0)];
        let zr = 0.6;
        let (m2, m4) = (moments2(&stacked), moments4(&stacked));
        let vsm = chebyshev(m2, zr, 1e-6);
        let ours = gaussian_cdf(m2, zr, 1e-6);
        let esm = exponential(exponential_moment(&stacked, 80.0), zr, 80.0);
        let msm = hamburger_msm(m4, zr, 3e-5);
        let power = power_cdf(mean_range(&stacked), zr);
        // σ² = 0.0225, (zr − μ)² = 0.0625.
        assert!((vsm - 0.0225 / 0.085).abs() < 1e-4, "{vsm}");
        // 1 − erf(0.25 / (0.15 √2)) = 1 − erf(1.1785) ≈ 0.095.
        assert!((ours - 0.0951).abs() < 2e-3, "{ours}");
        assert!(ours < vsm / 2.5);
        assert!(power == 0.0, "{power}");
        assert!(msm < 0.01, "{msm}");
        // ESM leaks e^{−80·0.1}/2: the nearer occluder's share through the far one.
        assert!(esm < 0.01, "{esm}");
        // Between the two, half the occluders are behind the receiver: four moments say so.
        for zr in [0.3, 0.35, 0.45] {
            let v = hamburger_msm(m4, zr, 3e-5);
            assert!((v - 0.5).abs() < 0.01, "{zr}: {v}");
        }
    }

    /// Against the distributions the methods assume, the filtered visibility follows the true
    /// one: a normal spread of occluder depths for the Gaussian CDF (within 0.03 over the
    /// receiver depths behind the mean, where eq. 7.1 rescales by 1/(1 − F(μ)) = 2), a power-law
    /// spread for the power CDF; Chebyshev is an upper bound of the truth everywhere.
    #[test]
    fn each_cdf_follows_the_distribution_it_assumes() {
        // Normal occluders, μ = 0.5, σ = 0.05 (Box–Muller).
        let mut rng = SplitMix64::new(11);
        let normal: Vec<(f32, f32)> = (0..20_000)
            .map(|_| {
                let (u1, u2) = (rng.next_f32().max(1e-7), rng.next_f32());
                let g = (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos();
                (0.5 + 0.05 * g, 1.0)
            })
            .collect();
        let m2 = moments2(&normal);
        let mut worst = 0.0f32;
        for k in 0..=40 {
            let zr = 0.5 + 0.2 * k as f32 / 40.0;
            // Eq. 7.1–7.2: the truth rescaled by the share behind the mean.
            let want = (truth(&normal, zr) / truth(&normal, m2[0])).min(1.0);
            worst = worst.max((gaussian_cdf(m2, zr, 1e-6) - want).abs());
            assert!(chebyshev(m2, zr, 1e-6) + 1e-4 >= truth(&normal, zr));
        }
        assert!(worst < 0.03, "gaussian worst {worst}");
        // Power-law occluders over [0.3, 0.7], F(t) = t^3.
        let power = draws(20_000, 5, |u| 0.3 + 0.4 * u.powf(1.0 / 3.0));
        let s = mean_range(&power);
        let mut worst = 0.0f32;
        for k in 0..=40 {
            let zr = 0.3 + 0.4 * k as f32 / 40.0;
            let want = (truth(&power, zr) / truth(&power, s[0])).min(1.0);
            worst = worst.max((power_cdf(s, zr) - want).abs());
        }
        assert!(worst < 0.03, "power worst {worst}");
    }
}
