//! The light a leaf sends to the eye, from the per-leaf envelope of [`super::envelope`]
//! (Boulanger 2008, §5.2–5.4): the leaf's two-sided BSDF (eq. 5.4), the sky and the ground
//! through the crown (eq. 5.6), the sun through the crown (eq. 5.8, with eq. 5.7's cosine lobes
//! blending the eight directions — see [`SunThroughCrown`] for which values they blend) and one
//! bounce of sunlight off the neighbouring leaves in closed form (eq. 5.11 with 5.24). Plain
//! Rust: the CPU
//! reference of the leaf shaders, and what the per-tree constants ([`SunBounce`], [`SkyLight`])
//! are computed with when the lighting changes.
//!
//! Radiances are linear RGB; the leaf's reflectances and transmittances per channel. All
//! directions are unit vectors in the tree's model space, pointing away from the leaf.

use super::bins::DIRECTIONS;
use bevy::math::Vec3;
use bevy::reflect::Reflect;
use std::f32::consts::PI;

/// The four sides of a leaf's material (§5.2.3): what its front and back reflect, and what
/// crosses it entering by either face, per RGB channel, in `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub struct LeafMaterial {
    /// ρ_rf: reflectance of the front face (the side of the leaf's normal).
    pub reflectance_front: Vec3,
    /// ρ_rb: reflectance of the back face.
    pub reflectance_back: Vec3,
    /// ρ_tf: transmittance for light entering the front face.
    pub transmittance_front: Vec3,
    /// ρ_tb: transmittance for light entering the back face.
    pub transmittance_back: Vec3,
}

impl Default for LeafMaterial {
    /// A broad-leaved tree's leaf, illustrative values rather than measured data: the front
    /// darker than the back (§5.2.3's description), about a seventh of the green light
    /// crossing it either way.
    fn default() -> Self {
        Self {
            reflectance_front: Vec3::new(0.06, 0.12, 0.04),
            reflectance_back: Vec3::new(0.10, 0.18, 0.07),
            transmittance_front: Vec3::new(0.05, 0.14, 0.03),
            transmittance_back: Vec3::new(0.05, 0.14, 0.03),
        }
    }
}

impl LeafMaterial {
    /// ρ̄ of eq. 5.19: the sum of the four.
    pub fn rho_bar(&self) -> Vec3 {
        self.reflectance_front
            + self.reflectance_back
            + self.transmittance_front
            + self.transmittance_back
    }

    /// This material with every value clamped into `[0, 1]` (NaN to 0), and whether it changed.
    pub fn sanitized(&self) -> (Self, bool) {
        let fix = |v: Vec3| {
            Vec3::from_array(
                v.to_array()
                    .map(|x| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) }),
            )
        };
        let s = Self {
            reflectance_front: fix(self.reflectance_front),
            reflectance_back: fix(self.reflectance_back),
            transmittance_front: fix(self.transmittance_front),
            transmittance_back: fix(self.transmittance_back),
        };
        (s, s != *self)
    }
}

/// M(x) = max(x, 0).
fn m(x: f32) -> f32 {
    x.max(0.0)
}

/// The cosine-weighted BSDF F(P, ω_o, ω) of eq. 5.4 for a leaf of normal `n`: light from `w`
/// reflected or transmitted towards `wo`, the cosine of incidence included.
pub fn bsdf(material: &LeafMaterial, n: Vec3, wo: Vec3, w: Vec3) -> Vec3 {
    let lit_front = m(n.dot(w));
    let lit_back = m(-n.dot(w));
    if n.dot(wo) >= 0.0 {
        // Seen from the front: the front's reflection and what crossed from the back.
        (material.reflectance_front * lit_front + material.transmittance_back * lit_back) / PI
    } else {
        (material.transmittance_front * lit_front + material.reflectance_back * lit_back) / PI
    }
}

/// The radiance of the sky (upper directions) and of the ground reflecting it (lower
/// directions) averaged over each of the eight solid angles Ω_j (§5.3.1), per tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkyLight {
    /// `L_sky(ω_j)` per direction of [`DIRECTIONS`].
    pub radiance: [Vec3; 8],
}

impl SkyLight {
    /// A uniform sky of radiance `sky` over the upper hemisphere, and below it a Lambertian
    /// ground of albedo `ground_albedo` lit by that sky (radiance `albedo · sky`: the sky's
    /// irradiance π·sky reflected over π), as §5.3.1 models the lower hemisphere.
    pub fn uniform(sky: Vec3, ground_albedo: Vec3) -> Self {
        Self::sky_and_ground(sky, sky * ground_albedo)
    }

    /// Radiance `sky` from every upper direction and `ground` from every lower one.
    pub fn sky_and_ground(sky: Vec3, ground: Vec3) -> Self {
        Self {
            radiance: DIRECTIONS.map(|d| if d.y > 0.0 { sky } else { ground }),
        }
    }
}

/// ∫ max(m · ω, 0) dω over the solid angle Ω_j of bin `j` — the octant of the signs of
/// [`DIRECTIONS`]`[j]` — exactly: the octant's spherical triangle clipped to the side of `m`'s
/// plane, integrated by Lambert's polygon formula (½ Σ_k θ_k · m·n_k over its edges, θ_k the arc,
/// n_k the unit normal of its great circle). Over the eight bins it sums to π.
pub fn octant_cosine(m: Vec3, j: usize) -> f32 {
    let d = DIRECTIONS[j];
    let corners = [
        Vec3::X * d.x.signum(),
        Vec3::Y * d.y.signum(),
        Vec3::Z * d.z.signum(),
    ];
    // Sutherland–Hodgman against the plane m·ω = 0 (through the centre, so a clipped great
    // arc's end is the normalised chord point): at most four corners.
    let mut clipped = [Vec3::ZERO; 4];
    let mut count = 0;
    for k in 0..3 {
        let (a, b) = (corners[k], corners[(k + 1) % 3]);
        let (da, db) = (m.dot(a), m.dot(b));
        if da >= 0.0 {
            clipped[count] = a;
            count += 1;
        }
        if (da >= 0.0) != (db >= 0.0) {
            clipped[count] = (a + (b - a) * (da / (da - db))).normalize_or_zero();
            count += 1;
        }
    }
    if count < 3 {
        return 0.0;
    }
    let mut sum = 0.0;
    for k in 0..count {
        let (a, b) = (clipped[k], clipped[(k + 1) % count]);
        let normal = a.cross(b);
        let length = normal.length();
        if length > 1e-9 {
            sum += a.dot(b).clamp(-1.0, 1.0).acos() * m.dot(normal / length);
        }
    }
    (0.5 * sum).abs()
}

/// Eq. 5.6: the sky and the ground's light the leaf sends towards `wo`, each bin's radiance
/// attenuated by the leaves in it (`attenuation[j]` = e^(−τ·s_max(P, ω_j))). The BSDF is
/// integrated over each bin's solid angle exactly ([`octant_cosine`]) rather than taken at the
/// bin's direction times Ω_j: the eight-direction sum alone is off by 6 % on average (18 % at
/// worst, by the leaf's orientation) for a leaf under a uniform sky with nothing around it.
pub fn sky_radiance(
    material: &LeafMaterial,
    n: Vec3,
    wo: Vec3,
    attenuation: &[f32; 8],
    sky: &SkyLight,
) -> Vec3 {
    // Seen from the front: the front reflects what comes from its side and the back lets
    // through what comes from the other; seen from the back, the other way round (eq. 5.4).
    let (lit_side, far_side) = if n.dot(wo) >= 0.0 {
        (material.reflectance_front, material.transmittance_back)
    } else {
        (material.transmittance_front, material.reflectance_back)
    };
    let cosines: [f32; 8] = std::array::from_fn(|j| octant_cosine(n, j));
    let mut sum = Vec3::ZERO;
    for j in 0..8 {
        // The bin of the opposite signs is the mirror image: ∫_Ω_j max(−n·ω, 0) = cosines[7 − j].
        sum += (lit_side * cosines[j] + far_side * cosines[7 - j])
            * (attenuation[j] * sky.radiance[j]);
    }
    sum / PI
}

/// The share of the sphere around a leaf of normal `n` its bins let through, each direction
/// weighted by its cosine on either side of the leaf (∫ |n·ω| a(ω) dω / 2π): what eq. 5.6 sums
/// for a uniform sky, the leaf's openness. `1 − open` is the share its neighbours cover, from
/// which the bounce comes.
pub fn open_share(n: Vec3, attenuation: &[f32; 8]) -> f32 {
    let cosines: [f32; 8] = std::array::from_fn(|j| octant_cosine(n, j));
    (0..8)
        .map(|j| (cosines[j] + cosines[7 - j]) * attenuation[j])
        .sum::<f32>()
        / (2.0 * PI)
}

/// The cosine lobe weights M(ω_l · ω_j) of eq. 5.7 and their sum.
fn lobes(wl: Vec3) -> ([f32; 8], f32) {
    let w = DIRECTIONS.map(|d| m(wl.dot(d)));
    let sum = w.iter().sum();
    (w, sum)
}

/// Eight values of the sampling directions blended towards `w` by their cosine lobes (eq. 5.7's
/// weights: continuous as `w` moves); `empty` where no lobe reaches `w`.
pub fn lobe_blend(values: &[f32; 8], w: Vec3, empty: f32) -> f32 {
    let (weights, sum) = lobes(w);
    if sum <= 0.0 {
        return empty;
    }
    (0..8).map(|j| weights[j] * values[j]).sum::<f32>() / sum
}

/// Eq. 5.7: the envelope's distance towards an arbitrary direction `wl`, the s_max of the
/// directions in its hemisphere blended by cosine lobes (continuous as the sun moves).
pub fn smooth_s_max(s_max: &[f32; 8], wl: Vec3) -> f32 {
    let (w, sum) = lobes(wl);
    if sum <= 0.0 {
        return 0.0;
    }
    (0..8).map(|j| w[j] * s_max[j]).sum::<f32>() / sum
}

/// How the light reaching a leaf from the sun through the crown is estimated from the eight
/// directions' values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Reflect)]
pub enum SunThroughCrown {
    /// The thesis' eq. 5.7–5.8: `e^(−τ·s̃)`, the envelope distances s_max blended by cosine
    /// lobes around the sun's direction. Darker than the light that gets through in real
    /// crowns (measured against the path tracer: −57 % on the procedural olive's mean): the
    /// exponential of a mean distance is below the mean of the exponentials, and a bin shut by
    /// one near leaf — common where leaves cluster on twigs — drags the blend to black.
    SmoothEnvelope,
    /// The same cosine lobes blending the eight directions' attenuations `a_j = e^(−τ·s_max)`
    /// themselves (equal to the thesis' form where the s_max agree; −8 % on the olive's mean).
    #[default]
    BlendedAttenuation,
}

/// The light let through by the crown towards `wl` for a leaf whose eight directions let
/// through `attenuation` (envelope distances `s_max`, extinction τ), by `blend`.
pub fn sun_through_crown(
    blend: SunThroughCrown,
    tau: f32,
    attenuation: &[f32; 8],
    s_max: &[f32; 8],
    wl: Vec3,
) -> f32 {
    match blend {
        SunThroughCrown::SmoothEnvelope => (-tau * smooth_s_max(s_max, wl)).exp(),
        SunThroughCrown::BlendedAttenuation => lobe_blend(attenuation, wl, 1.0),
    }
}

/// Eq. 5.8: the sun's light (direction to the sun `wl`, irradiance `e_sun` on a surface facing
/// it) the leaf sends towards `wo`, the crown letting `through` of it reach the leaf
/// ([`sun_through_crown`]).
pub fn sun_radiance(
    material: &LeafMaterial,
    n: Vec3,
    wo: Vec3,
    wl: Vec3,
    through: f32,
    e_sun: Vec3,
) -> Vec3 {
    bsdf(material, n, wo, wl) * through * e_sun
}

/// The per-tree constants of one bounce of sunlight (eq. 5.18, 5.25, 5.26), computed on the CPU
/// when the sun, the leaves' material or τ change; the leaves' shaders then evaluate eq. 5.24
/// with their own s_max alone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunBounce {
    /// `A·G1(j, ω_l)` per direction and channel: G1 of eq. 5.18 times the leaf area A of
    /// eq. 5.11 (A·ρ = 2τ, so the product needs τ alone).
    pub a_g1: [Vec3; 8],
    /// G2(ω_l) of eq. 5.25.
    pub g2: f32,
    /// G3(j, ω_l) of eq. 5.26 per direction.
    pub g3: [f32; 8],
    /// M(ω_l · ω_j) per direction (the lobes eq. 5.24 sums s_max with).
    pub lobes: [f32; 8],
}

impl SunBounce {
    /// The constants for the sun in direction `wl` (towards the sun), a crown of extinction τ
    /// and leaves of `material`.
    pub fn new(material: &LeafMaterial, wl: Vec3, tau: f32) -> Self {
        let (lobes, lobe_sum) = lobes(wl);
        let rho_bar = material.rho_bar();
        let through = material.transmittance_front + material.transmittance_back;
        let a_g1 = DIRECTIONS.map(|d| {
            let alpha = d.dot(wl).clamp(-1.0, 1.0).acos();
            // Eq. 5.18 with A·ρ = 2τ (eq. 5.5): 2ρ·A = 4τ.
            (rho_bar * (alpha.sin() - alpha * alpha.cos()) + through * (PI * alpha.cos()))
                * (4.0 * tau / (3.0 * PI * 8.0))
        });
        let g2 = if lobe_sum > 0.0 { tau / lobe_sum } else { 0.0 };
        let g3 = DIRECTIONS.map(|d| {
            let mean = if lobe_sum > 0.0 {
                (0..8).map(|k| lobes[k] * d.dot(DIRECTIONS[k])).sum::<f32>() / lobe_sum
            } else {
                0.0
            };
            tau * (1.0 - mean)
        });
        Self {
            a_g1,
            g2,
            g3,
            lobes,
        }
    }
}

/// `(1 − e^(−g·s)) / g`, and its limit `s` as `g` goes to 0.
fn one_minus_exp_over(g: f32, s: f32) -> f32 {
    let x = g * s;
    if x.abs() < 1e-4 {
        s * (1.0 - 0.5 * x)
    } else {
        -(-x).exp_m1() / g
    }
}

/// Eq. 5.24 (times the leaf area A): the light the leaves of bin j send back towards the leaf,
/// lit by the sun through the crown, for a leaf whose envelope distance towards ω_j is
/// `s_max_j` and which the crown lets `through` of the sun reach. Eq. 5.24's first exponential,
/// `exp(−G2·Σ M(ω_l·ω_j')·s_max(P, ω_j'))`, is `e^(−τ·s̃)` — the sun's light at the leaf itself,
/// eq. 5.8's — so it takes [`sun_through_crown`]'s value; the integral along the bin keeps the
/// thesis' closed form.
pub fn bounce_sample(
    bounce: &SunBounce,
    through: f32,
    s_max_j: f32,
    j: usize,
    e_sun: Vec3,
) -> Vec3 {
    bounce.a_g1[j] * e_sun * through * one_minus_exp_over(bounce.g3[j], s_max_j)
}

/// Eq. 5.11 with eq. 5.24: one bounce of sunlight off the neighbouring leaves, sent towards `wo`.
pub fn bounce_radiance(
    material: &LeafMaterial,
    n: Vec3,
    wo: Vec3,
    bounce: &SunBounce,
    through: f32,
    s_max: &[f32; 8],
    e_sun: Vec3,
) -> Vec3 {
    bounce_radiance_by_face(material, n, wo, bounce, through, s_max, e_sun, [1.0; 2])
}

/// [`bounce_radiance`] with the bins that light the leaf's front face (the side of its normal)
/// scaled by `scale[0]` and those lighting its back by `scale[1]` (the gathered ratios of
/// [`super::gathered_bounce`]).
#[allow(clippy::too_many_arguments)]
pub fn bounce_radiance_by_face(
    material: &LeafMaterial,
    n: Vec3,
    wo: Vec3,
    bounce: &SunBounce,
    through: f32,
    s_max: &[f32; 8],
    e_sun: Vec3,
    scale: [f32; 2],
) -> Vec3 {
    (0..8)
        .map(|j| {
            let face = if n.dot(DIRECTIONS[j]) >= 0.0 { 0 } else { 1 };
            bsdf(material, n, wo, DIRECTIONS[j])
                * bounce_sample(bounce, through, s_max[j], j, e_sun)
                * scale[face]
        })
        .sum()
}

/// The whole of eq. 5.2 for one leaf: sky and ground, sun, one bounce of sunlight.
#[allow(clippy::too_many_arguments)]
pub fn leaf_radiance(
    material: &LeafMaterial,
    n: Vec3,
    wo: Vec3,
    attenuation: &[f32; 8],
    s_max: &[f32; 8],
    tau: f32,
    sky: &SkyLight,
    wl: Vec3,
    e_sun: Vec3,
    bounce: &SunBounce,
    blend: SunThroughCrown,
) -> Vec3 {
    let through = sun_through_crown(blend, tau, attenuation, s_max, wl);
    sky_radiance(material, n, wo, attenuation, sky)
        + sun_radiance(material, n, wo, wl, through, e_sun)
        + bounce_radiance(material, n, wo, bounce, through, s_max, e_sun)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn random_unit(rng: &mut SplitMix64) -> Vec3 {
        loop {
            let v = Vec3::new(
                rng.next_f32() * 2.0 - 1.0,
                rng.next_f32() * 2.0 - 1.0,
                rng.next_f32() * 2.0 - 1.0,
            );
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }

    #[test]
    fn the_bsdf_reflects_on_the_lit_side_and_transmits_through() {
        let mat = LeafMaterial::default();
        let n = Vec3::Y;
        let up = Vec3::new(0.0, 1.0, 0.0);
        let eye_above = Vec3::new(0.6, 0.8, 0.0);
        let eye_below = Vec3::new(0.6, -0.8, 0.0);
        // Lit from above, seen from above: the front's reflection, cos = 1.
        assert!((bsdf(&mat, n, eye_above, up) - mat.reflectance_front / PI).length() < 1e-6);
        // Lit from above, seen from below: what crossed the front face.
        assert!((bsdf(&mat, n, eye_below, up) - mat.transmittance_front / PI).length() < 1e-6);
        // Lit from below at 60°: the back's reflection seen from below, times cos 60°.
        let low = Vec3::new(0.0, -0.5, 0.75_f32.sqrt());
        assert!((bsdf(&mat, n, eye_below, low) - mat.reflectance_back * 0.5 / PI).length() < 1e-6);
        assert!(
            (bsdf(&mat, n, eye_above, low) - mat.transmittance_back * 0.5 / PI).length() < 1e-6
        );
        // Grazing light adds nothing.
        assert_eq!(bsdf(&mat, n, eye_above, Vec3::X), Vec3::ZERO);
    }

    #[test]
    fn the_octant_cosines_are_the_clamped_cosine_integrated_over_each_bin() {
        let mut rng = SplitMix64::new(3);
        for round in 0..50 {
            let m = random_unit(&mut rng);
            // Over the whole sphere: π.
            let total: f32 = (0..8).map(|j| octant_cosine(m, j)).sum();
            assert!((total - PI).abs() < 1e-4, "{total}");
            if round >= 6 {
                continue;
            }
            // Bin by bin, against a Monte Carlo estimate (standard error about 0.007).
            let mut mc = [0.0f32; 8];
            let samples = 200_000;
            for _ in 0..samples {
                let w = random_unit(&mut rng);
                mc[crate::lighting::bins::bin_of(w)] += m.dot(w).max(0.0);
            }
            for (j, sum) in mc.iter().enumerate() {
                let estimate = sum / samples as f32 * 4.0 * PI;
                assert!(
                    (octant_cosine(m, j) - estimate).abs() < 0.035,
                    "bin {j}: {} vs {estimate}",
                    octant_cosine(m, j)
                );
            }
        }
        // Facing straight along a bin's direction: that bin holds the most, the opposite one
        // nothing.
        assert_eq!(octant_cosine(DIRECTIONS[7], 0), 0.0);
        assert!(octant_cosine(DIRECTIONS[7], 7) > octant_cosine(DIRECTIONS[7], 3));
    }

    #[test]
    fn an_unoccluded_leaf_under_a_uniform_sky_gets_eq_5_6s_integral() {
        let mat = LeafMaterial::default();
        let sky = SkyLight::uniform(Vec3::ONE, Vec3::ZERO);
        // Facing up, seen from above, nothing around it: the cosine over the upper hemisphere
        // integrates to π, so the leaf sends ρ_rf times the sky; the lower bins are black.
        let l = sky_radiance(&mat, Vec3::Y, Vec3::Y, &[1.0; 8], &sky);
        assert!((l - mat.reflectance_front).length() < 1e-5, "{l}");
        // A leaf whose every bin is dark receives nothing.
        assert_eq!(
            sky_radiance(&mat, Vec3::Y, Vec3::Y, &[0.0; 8], &sky),
            Vec3::ZERO
        );
        // Facing down: the ground's light (half the sky's) on its front, the sky's through it.
        let ground = SkyLight::uniform(Vec3::ONE, Vec3::splat(0.5));
        let down = sky_radiance(&mat, -Vec3::Y, -Vec3::Y, &[1.0; 8], &ground);
        let want = mat.reflectance_front * 0.5 + mat.transmittance_back;
        assert!((down - want).length() < 1e-5, "{down} vs {want}");
        // Any orientation under a sky equal all round: ρ + τ of the side seen, exactly (the
        // eight-direction sum was off by up to 18 % here).
        let even = SkyLight::sky_and_ground(Vec3::ONE, Vec3::ONE);
        let mut rng = SplitMix64::new(11);
        for _ in 0..100 {
            let n = random_unit(&mut rng);
            let l = sky_radiance(&mat, n, n, &[1.0; 8], &even);
            let want = mat.reflectance_front + mat.transmittance_back;
            assert!((l - want).length() < 1e-5, "{n}: {l} vs {want}");
        }
    }

    #[test]
    fn the_open_share_weights_the_bins_by_their_cosines_on_both_sides() {
        let mut rng = SplitMix64::new(5);
        for _ in 0..50 {
            let n = random_unit(&mut rng);
            // Nothing around: open; everything shut: closed.
            assert!((open_share(n, &[1.0; 8]) - 1.0).abs() < 1e-5);
            assert!(open_share(n, &[0.0; 8]).abs() < 1e-6);
            // Against the integral it stands for, by Monte Carlo over the sphere.
            let a: [f32; 8] = std::array::from_fn(|_| rng.next_f32());
            let (mut sum, mut weight) = (0.0f64, 0.0f64);
            for _ in 0..20_000 {
                let w = random_unit(&mut rng);
                let c = n.dot(w).abs() as f64;
                sum += c * a[crate::lighting::bins::bin_of(w)] as f64;
                weight += c;
            }
            let want = (sum / weight) as f32;
            assert!(
                (open_share(n, &a) - want).abs() < 0.01,
                "{} against {want}",
                open_share(n, &a)
            );
        }
    }

    #[test]
    fn the_smooth_envelope_is_exact_for_a_round_crown_and_continuous() {
        let mut rng = SplitMix64::new(7);
        for _ in 0..100 {
            let wl = random_unit(&mut rng);
            assert!((smooth_s_max(&[2.5; 8], wl) - 2.5).abs() < 1e-5);
        }
        // Continuous in the sun's direction: a small turn changes it a little.
        let s = [0.5, 3.0, 1.0, 2.0, 0.1, 4.0, 2.5, 1.5];
        let mut worst = 0.0_f32;
        for i in 0..2000 {
            let a = i as f32 * 0.00314;
            let b = a + 0.00314;
            let d = (smooth_s_max(&s, Vec3::new(a.cos(), 0.3, a.sin()).normalize())
                - smooth_s_max(&s, Vec3::new(b.cos(), 0.3, b.sin()).normalize()))
            .abs();
            worst = worst.max(d);
        }
        assert!(worst < 0.05, "a step of {worst}");
        // Towards a direction ω_j itself it leans on that direction's s_max.
        let towards = smooth_s_max(&s, DIRECTIONS[5]);
        assert!(towards > 2.0, "{towards}");
    }

    /// Eq. 5.24 is the closed form of eq. 5.21's integral with eq. 5.22–5.23: the same
    /// integral taken numerically must agree.
    #[test]
    fn the_closed_form_bounce_is_the_integral_it_solves() {
        let mat = LeafMaterial::default();
        let mut rng = SplitMix64::new(11);
        let e_sun = Vec3::new(1.0, 0.9, 0.8);
        let mut worst = 0.0_f32;
        for _ in 0..200 {
            let tau = 0.05 + rng.next_f32() * 2.0;
            let wl = random_unit(&mut rng);
            let s_max: [f32; 8] = std::array::from_fn(|_| rng.next_f32() * 4.0);
            let bounce = SunBounce::new(&mat, wl, tau);
            let (lobes, lobe_sum) = lobes(wl);
            for j in 0..8 {
                // I(P, j) = ∫₀^s_max e^(−τs) · E_sun · e^(−τ·s̃(P + s·ω_j, ω_l)) ds, midpoint rule.
                let steps = 4000;
                let ds = s_max[j] / steps as f32;
                let mut integral = 0.0_f64;
                for i in 0..steps {
                    let s = (i as f32 + 0.5) * ds;
                    let moved: f32 = (0..8)
                        .map(|k| lobes[k] * (s_max[k] - DIRECTIONS[j].dot(DIRECTIONS[k]) * s))
                        .sum::<f32>()
                        / lobe_sum;
                    integral += ((-tau * s).exp() * (-tau * moved).exp() * ds) as f64;
                }
                let numeric = bounce.a_g1[j] * e_sun * integral as f32;
                // The sun at the leaf, e^(−τ·s̃(P)) = exp(−G2·Σ M·s_max) (eq. 5.24's form).
                let lit: f32 = (0..8).map(|k| bounce.lobes[k] * s_max[k]).sum();
                let through = (-bounce.g2 * lit).exp();
                let closed = bounce_sample(&bounce, through, s_max[j], j, e_sun);
                let scale = numeric.max_element().abs().max(1e-6);
                worst = worst.max((numeric - closed).abs().max_element() / scale);
            }
        }
        assert!(worst < 2e-3, "closed form off by {worst} (relative)");
    }

    #[test]
    fn g1_is_eq_5_18() {
        // The sun straight along ω_0: α_0 = 0, so A·G1 = 4τ·π(ρ_tf + ρ_tb)/(3π·8) — the
        // leaves behind the leaf, lit from behind them, send it what crosses them; α = π (the
        // opposite direction, ω_7): only what they reflect, 4τ·π(ρ̄ − ρ_tf − ρ_tb)/(3π·8).
        let mat = LeafMaterial::default();
        let tau = 0.7;
        let bounce = SunBounce::new(&mat, DIRECTIONS[0], tau);
        let through = mat.transmittance_front + mat.transmittance_back;
        let want0 = through * (4.0 * tau * PI / (3.0 * PI * 8.0));
        assert!(
            (bounce.a_g1[0] - want0).length() < 1e-5,
            "{} vs {want0}",
            bounce.a_g1[0]
        );
        let want7 =
            (mat.reflectance_front + mat.reflectance_back) * (4.0 * tau * PI / (3.0 * PI * 8.0));
        assert!(
            (bounce.a_g1[7] - want7).length() < 1e-5,
            "{} vs {want7}",
            bounce.a_g1[7]
        );
        // G2 and G3: eq. 5.25 and 5.26 by hand for the sun on ω_0 (only ω_0 and its three
        // neighbours at cos 1/3 are in its hemisphere).
        let lobe_sum = 1.0 + 3.0 / 3.0;
        assert!((bounce.g2 - tau / lobe_sum).abs() < 1e-6);
        // ω_0's own G3: the lobes' mean of ω_0·ω_k is (1 + 3·(1/3)·(1/3)) / 2.
        let mean = (1.0 + 3.0 * (1.0 / 3.0) * (1.0 / 3.0)) / lobe_sum;
        assert!((bounce.g3[0] - tau * (1.0 - mean)).abs() < 1e-5);
    }

    #[test]
    fn a_deeper_leaf_is_darker_in_every_term() {
        let mat = LeafMaterial::default();
        let sky = SkyLight::uniform(Vec3::ONE, Vec3::splat(0.2));
        let wl = Vec3::new(0.3, 0.9, 0.2).normalize();
        let tau = 0.8;
        let bounce = SunBounce::new(&mat, wl, tau);
        let n = Vec3::new(0.2, 0.9, 0.1).normalize();
        let wo = Vec3::new(0.0, 0.5, 0.8).normalize();
        let shallow = [0.3_f32; 8];
        let deep = [2.5_f32; 8];
        let a = |s: &[f32; 8]| s.map(|s| (-tau * s).exp());
        let sky_s = sky_radiance(&mat, n, wo, &a(&shallow), &sky);
        let sky_d = sky_radiance(&mat, n, wo, &a(&deep), &sky);
        assert!(sky_d.max_element() < 0.2 * sky_s.max_element());
        for blend in [
            SunThroughCrown::SmoothEnvelope,
            SunThroughCrown::BlendedAttenuation,
        ] {
            let through = |s: &[f32; 8]| sun_through_crown(blend, tau, &a(s), s, wl);
            let sun_s = sun_radiance(&mat, n, wo, wl, through(&shallow), Vec3::ONE);
            let sun_d = sun_radiance(&mat, n, wo, wl, through(&deep), Vec3::ONE);
            assert!(sun_d.max_element() < 0.2 * sun_s.max_element());
            // Where every direction agrees, the two blends are the same.
            assert!((through(&shallow) - (-tau * 0.3_f32).exp()).abs() < 1e-5);
        }
        // The bounce grows with the leaves around (more neighbours to bounce off) but dies
        // with the depth the sun must cross: at the crown's surface it is zero.
        let none = bounce_radiance(&mat, n, wo, &bounce, 1.0, &[0.0; 8], Vec3::ONE);
        assert_eq!(none, Vec3::ZERO);
        let some = bounce_radiance(&mat, n, wo, &bounce, 0.8, &shallow, Vec3::ONE);
        assert!(some.max_element() > 0.0);
    }

    #[test]
    fn bad_materials_are_clamped() {
        let (m, changed) = LeafMaterial {
            reflectance_front: Vec3::new(f32::NAN, 2.0, -1.0),
            ..LeafMaterial::default()
        }
        .sanitized();
        assert!(changed);
        assert_eq!(m.reflectance_front, Vec3::new(0.0, 1.0, 0.0));
        assert!(!LeafMaterial::default().sanitized().1);
    }
}
