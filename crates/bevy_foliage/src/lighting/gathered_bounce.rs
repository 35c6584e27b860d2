//! One bounce of sunlight gathered from a leaf's own neighbours, for the sun from fourteen
//! directions, as ratios to the closed form of Boulanger 2008, eq. 5.24. Baked with the bins
//! (`BakeSettings::bounce_rays`), stored 28 bytes a leaf ([`BounceRatios::quantized`]) in the
//! `.foliage` file and the leaves' light buffer, and blended towards the sun by the leaf vertex
//! shader (`tree_lighting.wgsl`'s `ratio_towards`), which scales eq. 5.24's bins face by face;
//! measured against the path tracer by `tree_lighting_error --images --bounce-rays R`.
//! Billboard clouds, whose texels have no room for their leaves' own, take the crown's mean
//! ([`crown_mean_ratios`]).
//!
//! Eq. 5.24 integrates the light of the neighbours along each bin in closed form by assuming a
//! crown of uniform density and random leaf orientations (§5.2.1), each neighbour lit by the
//! sun through the crown as far as the envelope lets it. Real crowns are not uniform: leaves
//! cluster on twigs, a leaf's neighbours face the way its twig's leaves face, and whether the
//! leaves a leaf sees are in sun depends on where the gaps are — all of which the closed form
//! averages away. Against the path tracer the closed form's bounce is 25–32 % off in images of
//! the four procedural trees at pixels 1.4–2.5 leaves wide (`tree_lighting_error --images`),
//! where the thesis reports 6 % on its uniform crown.
//!
//! Here each leaf casts rays over its two sides, as the tracer gathers (cosine-weighted, from
//! points spread over the leaf), and at each neighbour hit casts a shadow ray towards each of
//! the fourteen [`SUN_BASIS`] directions (the eight sampling directions and the six axes): per
//! direction of the sun, the irradiance the bounce brings to the leaf's front and back faces
//! ([`gather_irradiance`]), divided by what eq. 5.24 brings each face for that sun
//! ([`closed_form_irradiance`]) — the leaf's [`BounceRatios`]. For a sun anywhere the ratios
//! are blended by sharpened cosine lobes ([`basis_weights`]) and scale eq. 5.24's bins on each
//! face ([`super::model::bounce_radiance_by_face`]): the closed form keeps what it gets right (the sun's exact
//! direction in G1–G3, the BSDF's colours on each side), the gather supplies what the crown's
//! real neighbours do.
//!
//! Why ratios, fourteen directions and sharpened lobes (`tree_lighting_error --images
//! --rays-per-bin 32 --seen-points 16 --bounce-rays 64 --sun X,Y,Z`, 2,000-leaf trees, pixels
//! 1.4–2.5 leaves wide, the bounce's image error against the tracer's single bounce, seven suns
//! at α = 4–148° from the eye): the gather for the image's own sun — what no blend over
//! directions beats — is 6.0–17.5 % off on the four procedural trees (the uniform ball
//! 4.4–6.3 %); eq. 5.24 with the covered part's gain 19–45 % with the sun from the side, above
//! or behind the eye and 107–174 % against it, where the eye sees the crown's shaded side.
//! Blending the gathered irradiances themselves over the eight sampling directions by eq.
//! 5.7's lobes loses most of the gather's gain (21–23 % at α = 58°); blending ratios to the
//! closed form keeps more (15–17 %), sharper lobes (the cosine to the fourth) more again
//! (7.8–12.7 %), but with the sun overhead — 54.7° from every sampling direction — eight stay
//! at 14–26 %. With the six axes: 7.5–20.4 % at α = 4–83°, 19–36 % at 137–148°, the ball
//! 4.3–6.5 % at every sun (the thesis reports 6 % on such a crown).
//!
//! Cost: 0.7–1.3 s for a 2,000-leaf crown at 64 rays a leaf on two threads (about 0.6 ms a
//! leaf, some 3.5× the 32-ray traced bins); a bake made while an app runs gathers
//! [`DEFAULT_BOUNCE_RAYS`], `foliage_bake` [`OFFLINE_BOUNCE_RAYS`].
//!
//! Plain Rust, no render types.

use super::bins::DIRECTIONS;
use super::envelope::LeafEnvelope;
use super::leaf_scene::LeafScene;
use super::model::{
    LeafMaterial, SunBounce, SunThroughCrown, bounce_sample, bsdf, sun_through_crown,
};
use super::path_trace::{cosine_direction, luminance};
use crate::rng::SplitMix64;
use bevy::math::Vec3;
use std::f32::consts::PI;

/// The directions of the sun the neighbours are lit from at the bake: the eight sampling
/// directions [`DIRECTIONS`] (indices 0–7) then +x, −x, +y, −y, +z, −z. No sun is more than
/// 36.2° from one of them (the eight alone leave the axes 54.7° away).
pub const SUN_BASIS: [Vec3; 14] = {
    let mut out = [Vec3::ZERO; 14];
    let mut j = 0;
    while j < 8 {
        out[j] = DIRECTIONS[j];
        j += 1;
    }
    out[8] = Vec3::X;
    out[9] = Vec3::NEG_X;
    out[10] = Vec3::Y;
    out[11] = Vec3::NEG_Y;
    out[12] = Vec3::Z;
    out[13] = Vec3::NEG_Z;
    out
};

/// The power the blend raises each basis direction's cosine lobe to ([`basis_weights`]):
/// eq. 5.7's plain cosine spreads a sun over directions up to 90° away.
pub const BASIS_LOBE_POWER: f32 = 4.0;

/// Rays per leaf a bake made while an app runs gathers for its ratios
/// ([`crate::pruning::bake::BakeSettings::bounce_rays`]).
pub const DEFAULT_BOUNCE_RAYS: u32 = 32;

/// Rays per leaf `foliage_bake` gathers (a bake kept on disk).
pub const OFFLINE_BOUNCE_RAYS: u32 = 64;

/// The most rays per leaf a bake accepts.
pub const MAX_BOUNCE_RAYS: u32 = 4096;

/// The most a ratio is taken as: a leaf eq. 5.24 puts in deep shade may see lit neighbours.
pub const RATIO_MAX: f32 = 16.0;

/// The blend weights of the [`SUN_BASIS`] directions for the sun towards `to_sun` (unit):
/// `M(ω_l · ω_k)^`[`BASIS_LOBE_POWER`], normalised to sum to 1. Continuous in the sun's
/// direction, and some direction always within 36.2°, so the sum is never 0.
pub fn basis_weights(to_sun: Vec3) -> [f32; 14] {
    let mut w = SUN_BASIS.map(|d| to_sun.dot(d).max(0.0).powf(BASIS_LOBE_POWER));
    let sum: f32 = w.iter().sum();
    if sum > 0.0 && sum.is_finite() {
        w.iter_mut().for_each(|x| *x /= sum);
    } else {
        w = [1.0 / 14.0; 14];
    }
    w
}

/// The irradiance one bounce brings to the front face (the side of its normal) and the back
/// face of leaf `leaf` of `scene`, for the sun from each of `suns` with unit irradiance, in
/// units of the material's mean albedo `ρ̄ / 4` (eq. 5.19; luminance): `rays` rays, half on each
/// side, cosine-distributed, each from its own point on the leaf; at each neighbour hit its
/// BSDF (eq. 5.4) towards the leaf where a shadow ray finds the sun. `opacity(l)` is the share
/// of leaf `l`'s area that stops light (the neighbour sends back that share).
pub fn gather_irradiance(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaf: usize,
    rays: u32,
    suns: &[Vec3],
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
) -> Vec<[f32; 2]> {
    let mut out = vec![[0.0f32; 2]; suns.len()];
    if leaf >= scene.leaf_count() || scene.triangle_count(leaf) == 0 {
        return out;
    }
    let unit = luminance(material.rho_bar()) / 4.0;
    if unit <= 0.0 {
        return out;
    }
    let mut rng = SplitMix64::new(seed);
    let n = scene.normal(leaf);
    let id = leaf as u32;
    let rays = rays.max(2);
    for (side, axis) in [n, -n].into_iter().enumerate() {
        let count = if side == 0 {
            rays.div_ceil(2)
        } else {
            rays / 2
        };
        // E = ∫ L cos dω = π · mean(L) over cosine-distributed directions.
        let per_ray = PI / count as f32 / unit;
        for _ in 0..count {
            let x = scene.point_on(leaf, &mut rng);
            let w = cosine_direction(axis, &mut rng);
            let Some((t, other)) = scene.hit(x, w, id) else {
                continue;
            };
            let share = opacity(other).clamp(0.0, 1.0);
            if share <= 0.0 {
                continue;
            }
            let p = x + w * t;
            let m = scene.normal(other as usize);
            for (k, &sun) in suns.iter().enumerate() {
                let f = luminance(bsdf(material, m, -w, sun));
                if f <= 0.0 {
                    continue;
                }
                let lit = scene.transmittance(p, sun, other, opacity);
                out[k][side] += f * lit * share * per_ray;
            }
        }
    }
    out
}

/// The irradiance eq. 5.24's closed form brings to the front and back faces of a leaf of
/// normal `n` (envelope distances `s_max`, the sun's share `through` at the leaf), in the units
/// of [`gather_irradiance`]: each bin's light taken at its direction, as
/// [`super::model::bounce_radiance`] takes it.
pub fn closed_form_irradiance(
    material: &LeafMaterial,
    bounce: &SunBounce,
    through: f32,
    s_max: &[f32; 8],
    n: Vec3,
) -> [f32; 2] {
    let unit = luminance(material.rho_bar()) / 4.0;
    if unit <= 0.0 {
        return [0.0; 2];
    }
    let mut out = [0.0f32; 2];
    for (j, d) in DIRECTIONS.iter().enumerate() {
        let s = luminance(bounce_sample(bounce, through, s_max[j], j, Vec3::ONE)) / unit;
        out[0] += n.dot(*d).max(0.0) * s;
        out[1] += (-n.dot(*d)).max(0.0) * s;
    }
    out
}

/// Eq. 5.24's per-tree constants for the sun from each [`SUN_BASIS`] direction.
pub fn basis_bounces(material: &LeafMaterial, tau: f32) -> [SunBounce; 14] {
    SUN_BASIS.map(|d| SunBounce::new(material, d, tau))
}

/// Per leaf, for the sun from each [`SUN_BASIS`] direction: the gathered bounce on each face
/// over eq. 5.24's (1 where eq. 5.24 brings that face nothing), in `[0, RATIO_MAX]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BounceRatios {
    /// The front face's ratio per sun direction.
    pub front: [f32; 14],
    /// The back face's.
    pub back: [f32; 14],
}

impl Default for BounceRatios {
    /// Eq. 5.24 unchanged.
    fn default() -> Self {
        Self {
            front: [1.0; 14],
            back: [1.0; 14],
        }
    }
}

/// The [`BounceRatios`] of leaf `leaf` (its envelope `envelope`, in a crown of extinction
/// `tau` whose constants per basis sun are `bounces`, [`basis_bounces`]), from `rays` rays.
/// The sun's share at the leaf is taken as the shaders take it for eq. 5.24, the blend of its
/// attenuations ([`SunThroughCrown::BlendedAttenuation`]).
#[allow(clippy::too_many_arguments)]
pub fn bounce_ratios(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaf: usize,
    envelope: &LeafEnvelope,
    tau: f32,
    bounces: &[SunBounce; 14],
    rays: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
) -> BounceRatios {
    if leaf >= scene.leaf_count() {
        return BounceRatios::default();
    }
    let gathered = gather_irradiance(scene, material, leaf, rays, &SUN_BASIS, opacity, seed);
    let n = scene.normal(leaf);
    let mut out = BounceRatios::default();
    for (k, &sun) in SUN_BASIS.iter().enumerate() {
        let through = sun_through_crown(
            SunThroughCrown::BlendedAttenuation,
            tau,
            &envelope.attenuation,
            &envelope.s_max,
            sun,
        );
        let closed = closed_form_irradiance(material, &bounces[k], through, &envelope.s_max, n);
        let ratio = |g: f32, c: f32| {
            if c > 1e-6 && g.is_finite() {
                (g / c).clamp(0.0, RATIO_MAX)
            } else {
                1.0
            }
        };
        out.front[k] = ratio(gathered[k][0], closed[0]);
        out.back[k] = ratio(gathered[k][1], closed[1]);
    }
    out
}

/// [`bounce_ratios`] of each of `leaves` (indices into `scene`; `envelopes[i]` the envelope of
/// `leaves[i]`) on up to `threads` threads.
#[allow(clippy::too_many_arguments)]
pub fn bounce_ratios_of(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    rays: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    threads: usize,
) -> Vec<BounceRatios> {
    let bounces = basis_bounces(material, tau);
    let jobs: Vec<(u32, Option<&LeafEnvelope>)> = leaves
        .iter()
        .enumerate()
        .map(|(i, &leaf)| (leaf, envelopes.get(i)))
        .collect();
    super::par_map(&jobs, threads, |&(leaf, envelope)| {
        let l = leaf as usize;
        let Some(envelope) = envelope else {
            return BounceRatios::default();
        };
        let seed = 0xB0B1_u64 ^ (leaf as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        bounce_ratios(
            scene, material, l, envelope, tau, &bounces, rays, opacity, seed,
        )
    })
}

/// Bytes a leaf's [`BounceRatios`] take as a bake stores them ([`BounceRatios::quantized`]):
/// the front face's fourteen then the back face's.
pub const STORED_RATIOS: usize = 28;

/// Steps of the stored ratios' logarithm: codes 1–255 span `log2` from −4 to +4 ([1/16, 16],
/// each step 2.2 % of the ratio); code 0 is a ratio of 0 (a face that sees no lit neighbour).
const RATIO_LOG2_STEPS: f32 = 254.0;

/// A ratio as a bake stores it: 0 below 1/32, else its base-2 logarithm over [−4, 4] in
/// [`RATIO_LOG2_STEPS`] steps (1 is stored exactly, as code 128); not finite: 1.
pub fn quantize_ratio(ratio: f32) -> u8 {
    let r = if ratio.is_finite() { ratio } else { 1.0 };
    let log2_max = RATIO_MAX.log2();
    if r < 1.0 / (2.0 * RATIO_MAX) {
        return 0;
    }
    let x = (r.clamp(1.0 / RATIO_MAX, RATIO_MAX).log2() + log2_max) / (2.0 * log2_max);
    1 + (x * RATIO_LOG2_STEPS).round() as u8
}

/// The ratio a stored byte holds ([`quantize_ratio`]'s inverse).
pub fn ratio_of(q: u8) -> f32 {
    if q == 0 {
        return 0.0;
    }
    let log2_max = RATIO_MAX.log2();
    ((q - 1) as f32 / RATIO_LOG2_STEPS * 2.0 * log2_max - log2_max).exp2()
}

impl BounceRatios {
    /// The ratios as a bake stores them: the front face's fourteen, then the back face's,
    /// each by [`quantize_ratio`].
    pub fn quantized(&self) -> [u8; STORED_RATIOS] {
        std::array::from_fn(|i| {
            quantize_ratio(if i < 14 {
                self.front[i]
            } else {
                self.back[i - 14]
            })
        })
    }

    /// The ratios a bake stored ([`BounceRatios::quantized`]'s inverse).
    pub fn from_stored(stored: &[u8; STORED_RATIOS]) -> Self {
        Self {
            front: std::array::from_fn(|k| ratio_of(stored[k])),
            back: std::array::from_fn(|k| ratio_of(stored[14 + k])),
        }
    }
}

/// The crown's mean ratios over its leaves' (each face and sun direction its own mean), for
/// a billboard cloud, whose texels have no room for their leaves' own; none: all 1.
pub fn crown_mean_ratios(ratios: &[BounceRatios]) -> BounceRatios {
    if ratios.is_empty() {
        return BounceRatios::default();
    }
    let n = ratios.len() as f32;
    BounceRatios {
        front: std::array::from_fn(|k| ratios.iter().map(|r| r.front[k]).sum::<f32>() / n),
        back: std::array::from_fn(|k| ratios.iter().map(|r| r.back[k]).sum::<f32>() / n),
    }
}

/// A leaf's ratios for the sun towards `to_sun` (unit): front and back, blended by
/// [`basis_weights`].
pub fn ratio_towards(ratios: &BounceRatios, to_sun: Vec3) -> [f32; 2] {
    let w = basis_weights(to_sun);
    let blend = |r: &[f32; 14]| (0..14).map(|k| w[k] * r[k]).sum::<f32>();
    [blend(&ratios.front), blend(&ratios.back)]
}

/// The bounce a leaf of normal `n` and `material` sends towards `wo` when its faces get
/// `irradiance` (front, back; [`gather_irradiance`]'s units) under a sun of irradiance `e_sun`:
/// eq. 5.4's two sides, the neighbours' light in the colour of the mean albedo.
pub fn gathered_bounce_radiance(
    material: &LeafMaterial,
    n: Vec3,
    wo: Vec3,
    irradiance: [f32; 2],
    e_sun: Vec3,
) -> Vec3 {
    let albedo = material.rho_bar() / 4.0;
    let [front, back] = irradiance;
    let seen = if n.dot(wo) >= 0.0 {
        material.reflectance_front * front + material.transmittance_back * back
    } else {
        material.transmittance_front * front + material.reflectance_back * back
    };
    seen * albedo * e_sun / PI
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::bins::proxies;
    use crate::lighting::model::{bounce_radiance, bounce_radiance_by_face};
    use crate::lighting::path_trace::{
        TraceSettings, push_square_leaf, test_light, trace_leaf, uniform_ball,
    };
    use crate::lighting::traced_bins::crown_envelope_traced;
    use crate::pruning::leaves::LeafSet;

    /// A small leaf facing up under a roof wide enough to fill its upper hemisphere: with the
    /// sun above, the roof's underside sends down what crosses it from the front (ρ_tf), with
    /// the sun below it reflects from its back (ρ_rb) — all to the leaf's front face, nothing
    /// to its back, the sun's cosine on the roof included.
    #[test]
    fn a_roof_sends_down_what_crosses_it_or_what_its_underside_reflects() {
        let mut leaves = LeafSet::default();
        push_square_leaf(&mut leaves, Vec3::ZERO, 0.05, Vec3::Y);
        push_square_leaf(&mut leaves, Vec3::Y * 0.2, 200.0, Vec3::Y);
        let scene = LeafScene::new(&leaves);
        let mat = LeafMaterial::default();
        let unit = luminance(mat.rho_bar()) / 4.0;
        let e = gather_irradiance(&scene, &mat, 0, 2048, &SUN_BASIS, &|_| 1.0, 7);
        let crossed = luminance(mat.transmittance_front) / unit;
        let reflected = luminance(mat.reflectance_back) / unit;
        let up = 10;
        assert_eq!(SUN_BASIS[up], Vec3::Y);
        assert!(
            (e[up][0] / crossed - 1.0).abs() < 0.01,
            "{:?} vs {crossed}",
            e[up]
        );
        for (k, d) in SUN_BASIS.iter().enumerate() {
            assert_eq!(e[k][1], 0.0, "nothing below the leaf, sun {k}");
            if d.y > 0.0 {
                let want = crossed * d.y;
                assert!(
                    (e[k][0] / want - 1.0).abs() < 0.01,
                    "sun {k}: {:?} vs {want}",
                    e[k]
                );
            } else if d.y < 0.0 {
                // The leaf's own shadow on the roof takes a few percent of what it sees.
                let want = reflected * -d.y;
                assert!(
                    e[k][0] < want && e[k][0] > 0.85 * want,
                    "sun {k}: {:?} vs {want}",
                    e[k]
                );
            } else {
                assert!(e[k][0] < 1e-3, "sun {k} in the roof's plane: {:?}", e[k]);
            }
        }
        // The ratio to eq. 5.24 for a leaf with nothing around it is 1 (no bins, no bounce).
        let lone = LeafScene::new(&{
            let mut l = LeafSet::default();
            push_square_leaf(&mut l, Vec3::ZERO, 0.05, Vec3::Y);
            l
        });
        let env = LeafEnvelope {
            attenuation: [1.0; 8],
            s_max: [0.0; 8],
        };
        let r = bounce_ratios(
            &lone,
            &mat,
            0,
            &env,
            1.0,
            &basis_bounces(&mat, 1.0),
            64,
            &|_| 1.0,
            1,
        );
        assert_eq!(r, BounceRatios::default());
    }

    /// The gather is the tracer's single bounce by other means: over a ball of leaves the two
    /// agree on the crown's bounced light (each noisy leaf by leaf).
    #[test]
    fn the_gather_finds_the_tracers_single_bounce() {
        let leaves = uniform_ball(800, 1.0, 0.05, 3);
        let scene = LeafScene::new(&leaves);
        let mat = LeafMaterial::default();
        let light = test_light();
        let eye = Vec3::new(0.0, 0.3, 1.0).normalize() * 30.0;
        let settings = TraceSettings {
            points: 8,
            directions: 128,
            bounces: 1,
            seed: 5,
        };
        let (mut traced, mut gathered) = (0.0f32, 0.0f32);
        for leaf in (0..scene.leaf_count()).step_by(20) {
            let wo = (eye - scene.centre(leaf)).normalize();
            traced += luminance(trace_leaf(&scene, &mat, &light, leaf, wo, &settings).bounce);
            let e = gather_irradiance(&scene, &mat, leaf, 512, &[light.to_sun], &|_| 1.0, 9)[0];
            gathered += luminance(gathered_bounce_radiance(
                &mat,
                scene.normal(leaf),
                wo,
                e,
                light.sun,
            ));
        }
        assert!(traced > 0.0);
        assert!(
            (gathered / traced - 1.0).abs() < 0.06,
            "gathered {gathered} traced {traced}"
        );
    }

    /// In the crown eq. 5.24 assumes (uniform, random orientations) the gathered light is eq.
    /// 5.24's on average, so the ratios sit about 1; scaling by ratios of 1 is eq. 5.24 itself,
    /// and a face's ratio scales only the bins on that face.
    #[test]
    fn in_a_uniform_crown_the_ratios_are_about_one() {
        let leaves = uniform_ball(1500, 1.5, 0.05, 5);
        let scene = LeafScene::new(&leaves);
        let mat = LeafMaterial::default();
        let order: Vec<u32> = (0..leaves.len() as u32).collect();
        let env =
            crown_envelope_traced(&proxies(&leaves), &scene, &order, &|_| 1.0, 32, 2, &|_| {});
        let picked: Vec<u32> = (0..leaves.len() as u32).step_by(25).collect();
        let picked_envelopes: Vec<_> = picked.iter().map(|&l| env.leaves[l as usize]).collect();
        let ratios = bounce_ratios_of(
            &scene,
            &mat,
            &picked,
            &picked_envelopes,
            env.tau,
            128,
            &|_| 1.0,
            2,
        );
        for k in [2, 7, 10, 13] {
            let mean: f32 = ratios
                .iter()
                .map(|r| 0.5 * (r.front[k] + r.back[k]))
                .sum::<f32>()
                / ratios.len() as f32;
            assert!((0.75..1.3).contains(&mean), "sun {k}: mean ratio {mean}");
        }
        let bounce = SunBounce::new(&mat, Vec3::Y, env.tau);
        let (n, wo) = (Vec3::new(0.3, 0.9, 0.1).normalize(), Vec3::Z);
        let e = &env.leaves[picked[3] as usize];
        let through = 0.6;
        let plain = bounce_radiance(&mat, n, wo, &bounce, through, &e.s_max, Vec3::ONE);
        let ones =
            bounce_radiance_by_face(&mat, n, wo, &bounce, through, &e.s_max, Vec3::ONE, [1.0; 2]);
        assert!((plain - ones).length() < 1e-6);
        let front = bounce_radiance_by_face(
            &mat,
            n,
            wo,
            &bounce,
            through,
            &e.s_max,
            Vec3::ONE,
            [1.0, 0.0],
        );
        let back = bounce_radiance_by_face(
            &mat,
            n,
            wo,
            &bounce,
            through,
            &e.s_max,
            Vec3::ONE,
            [0.0, 1.0],
        );
        assert!((front + back - plain).length() < 1e-6);
        assert!(front.length() > 0.0 && back.length() > 0.0);
    }

    /// Every sun is within 36.2° of a basis direction, the weights sum to 1, are largest on
    /// the nearest direction and move continuously with the sun.
    #[test]
    fn the_basis_covers_every_sun_and_blends_continuously() {
        let mut rng = SplitMix64::new(11);
        // The farthest suns are equidistant from an axis and two corners: cos = 1 / √(1 + (√3 − 1)²).
        let farthest = 1.0 / (1.0 + (3f32.sqrt() - 1.0).powi(2)).sqrt();
        assert!((farthest.acos().to_degrees() - 36.2).abs() < 0.01);
        let closest = farthest - 1e-4;
        for _ in 0..2000 {
            let sun = crate::lighting::leaf_scene::uniform_direction(&mut rng);
            let best = SUN_BASIS.iter().map(|d| d.dot(sun)).fold(-1.0, f32::max);
            assert!(
                best >= closest,
                "{sun} is {}° from the basis",
                best.acos().to_degrees()
            );
            let w = basis_weights(sun);
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            let nearest = (0..14)
                .max_by(|&a, &b| SUN_BASIS[a].dot(sun).total_cmp(&SUN_BASIS[b].dot(sun)))
                .unwrap();
            assert!(w.iter().all(|&x| x <= w[nearest]));
            let moved = basis_weights((sun + Vec3::splat(1e-3)).normalize());
            assert!(w.iter().zip(moved).all(|(a, b)| (a - b).abs() < 0.02));
        }
        // The eight sampling directions alone leave the axes 54.7° from every one of them.
        let eight = DIRECTIONS
            .iter()
            .map(|d| d.dot(Vec3::Y))
            .fold(-1.0, f32::max);
        assert!(eight < 0.58);
    }

    /// Stored ratios: 1 exactly, 0 as 0, every ratio in [1/16, 16] within 1.15 % (half a step
    /// of the logarithm), monotone; the rest clamped.
    #[test]
    fn stored_ratios_keep_their_value_within_half_a_step() {
        assert_eq!(ratio_of(quantize_ratio(1.0)), 1.0);
        assert_eq!(quantize_ratio(1.0), 128);
        assert_eq!(ratio_of(quantize_ratio(0.0)), 0.0);
        assert_eq!(ratio_of(quantize_ratio(f32::NAN)), 1.0);
        assert_eq!(ratio_of(quantize_ratio(1e9)), RATIO_MAX);
        assert_eq!(ratio_of(quantize_ratio(0.05)), 1.0 / RATIO_MAX);
        let mut last = 0u8;
        for i in 0..=4000 {
            let r = (-4.0 + 8.0 * i as f32 / 4000.0).exp2();
            let q = quantize_ratio(r);
            assert!(q >= last);
            last = q;
            assert!(
                (ratio_of(q) / r - 1.0).abs() < 0.0115,
                "{r} stored as {}",
                ratio_of(q)
            );
        }
        let r = BounceRatios {
            front: std::array::from_fn(|k| 0.5 + k as f32 * 0.25),
            back: std::array::from_fn(|k| 4.0 - k as f32 * 0.2),
        };
        let back = BounceRatios::from_stored(&r.quantized());
        for k in 0..14 {
            assert!((back.front[k] / r.front[k] - 1.0).abs() < 0.0115);
            assert!((back.back[k] / r.back[k] - 1.0).abs() < 0.0115);
        }
    }

    /// A crown's mean ratios are each face's and sun's own mean over the leaves; no leaves
    /// leave eq. 5.24 as it is.
    #[test]
    fn the_crown_mean_keeps_faces_and_suns_apart() {
        assert_eq!(crown_mean_ratios(&[]), BounceRatios::default());
        let a = BounceRatios {
            front: std::array::from_fn(|k| k as f32),
            back: [2.0; 14],
        };
        let b = BounceRatios {
            front: std::array::from_fn(|k| 3.0 * k as f32),
            back: [0.0; 14],
        };
        let mean = crown_mean_ratios(&[a, b]);
        for k in 0..14 {
            assert_eq!(mean.front[k], 2.0 * k as f32);
            assert_eq!(mean.back[k], 1.0);
        }
    }
}
