//! One bounce of sunlight gathered from a leaf's own neighbours, for the sun from fourteen
//! directions, as ratios to the closed form of Boulanger 2008, eq. 5.24. Baked with the bins
//! (`BakeSettings::bounce_rays`), stored 28 bytes a leaf ([`BounceRatios::quantized`]) in the
//! `.foliage` file and the leaves' light buffer, and blended towards the sun by the leaf vertex
//! shader (`tree_lighting.wgsl`'s `ratio_towards`), which scales eq. 5.24's bins face by face;
//! measured against the path tracer by `tree_lighting_error --images --bounce-rays R`.
//! Billboard clouds, whose texels have no room for their leaves' own, take the crown's mean
//! ([`crown_mean_ratios`]), each leaf weighted by how much an eye outside the crown sees of it
//! (the cloud shows the outer leaves, not the hidden ones). While an app runs, the ratios are
//! also re-gathered for fourteen suns at the sun's own elevation ([`sun_ratios_of`] on
//! [`super::bounce_ring`]'s ring), which the shaders read in place of the blend where the sun
//! is at that elevation.
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
//! 4.3–6.5 % at every sun (the thesis reports 6 % on such a crown). Neither other lobe
//! powers ([`BASIS_LOBE_POWER`]) nor pooling each leaf's gather with its nearest neighbours'
//! ([`pooled_ratios`], [`DEFAULT_BOUNCE_POOL`]) narrow the gap against the sun: there it is
//! the blend over directions, not the gather's noise, that costs (on the trees at pixels about
//! 1.5 leaves wide 11–18 % for the sun's own gather, 21–37 % blended).
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
use super::path_trace::{cosine_direction_at, luminance};
use super::traced_bins::radical_inverse;
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
/// eq. 5.7's plain cosine spreads a sun over directions up to 90° away. Chosen by the bounce's
/// image error (`tree_lighting_error --images`, pixels about 1.5 leaves, four procedural trees,
/// three suns): powers 1 and 2 blend in directions too far from the sun (the trees' error up
/// to 47 %), 8 and 16 lean on the one or two nearest directions (up to 52 %); summed over the
/// trees and suns 4 is lowest (powers 1, 2, 8, 16: 25, 9.8, 3.6 and 22 % higher), and on every
/// tree and sun lowest or within a point of it but two (olive and oak with the sun towards
/// (0.3, 0.2, −1), where 8 is two points lower).
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
/// side, cosine-distributed, each from its own point on the leaf (directions and points spread
/// evenly, [`gather_irradiance_by`]); at each neighbour hit its BSDF (eq. 5.4) towards the leaf
/// where a shadow ray finds the sun. `opacity(l)` is the share of leaf `l`'s area that stops
/// light (the neighbour sends back that share).
pub fn gather_irradiance(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaf: usize,
    rays: u32,
    suns: &[Vec3],
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
) -> Vec<[f32; 2]> {
    let mut rng = SplitMix64::new(seed);
    gather_irradiance_by(
        scene,
        material,
        leaf,
        rays,
        suns,
        opacity,
        &mut rng,
        &mut |u| scene.point_at(leaf, u),
        &|other, p, k| scene.transmittance(p, suns[k], other, opacity),
    )
}

/// [`gather_irradiance`] with each ray's point on the leaf given by `point` from a place in the
/// unit square (a constant point: the irradiance there), and the sun's share at a neighbour's
/// hit given by
/// `lit(neighbour, hit point, index of the sun in suns)` — a shadow ray for
/// [`gather_irradiance`], the neighbour's sunlit plane for
/// [`super::bounce_floor::gather_through_planes`].
#[allow(clippy::too_many_arguments)]
pub fn gather_irradiance_by(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaf: usize,
    rays: u32,
    suns: &[Vec3],
    opacity: &(impl Fn(u32) -> f32 + Sync),
    rng: &mut SplitMix64,
    point: &mut dyn FnMut((f32, f32)) -> Vec3,
    lit: &dyn Fn(u32, Vec3, usize) -> f32,
) -> Vec<[f32; 2]> {
    let mut out = vec![[0.0f32; 2]; suns.len()];
    if leaf >= scene.leaf_count() || scene.triangle_count(leaf) == 0 {
        return out;
    }
    let unit = luminance(material.rho_bar()) / 4.0;
    if unit <= 0.0 {
        return out;
    }
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
        // The rays' directions and places on the leaf are a four-dimensional low-discrepancy
        // set (Hammersley's for the direction, Halton's bases 3 and 5 for the place), shifted
        // at random per leaf and side (a Cranley–Patterson rotation), as the traced bins'
        // are: uniform on average, but a gather of a few dozen rays covers the hemisphere and
        // the leaf evenly rather than by chance, where the bounce's noise at the rays an app
        // can afford is most of its error. Measured as the leaf shaders draw the bounce (the
        // ring of 14 with its own hotspot, 32 rays a leaf, `tree_lighting_error --images`,
        // five suns from behind the eye to against it, pixels 1.4–2.5 leaves wide), against
        // independent rays: the uniform ball 6.3 → 5.7 % on average, better at four suns and
        // equal at the fifth; the four procedural trees 10.5 → 9.9 % on average (behind the
        // eye 8.4 → 6.9, against it 13.2–13.7 → 13.2–14.2), where one tree's figure moves by
        // up to ±3 points with the rays alone.
        let shift: [f32; 4] = std::array::from_fn(|_| rng.next_f32());
        for i in 0..count {
            let x = point((
                (radical_inverse(i, 3) + shift[2]).fract(),
                (radical_inverse(i, 5) + shift[3]).fract(),
            ));
            let w = cosine_direction_at(
                axis,
                (
                    ((i as f32 + 0.5) / count as f32 + shift[0]).fract(),
                    (radical_inverse(i, 2) + shift[1]).fract(),
                ),
            );
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
                out[k][side] += f * lit(other, p, k) * share * per_ray;
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

/// What a leaf's [`BounceRatios`] are made of: per [`SUN_BASIS`] direction and face (front,
/// back), the irradiance gathered from its neighbours ([`gather_irradiance`]) and eq. 5.24's
/// ([`closed_form_irradiance`]), in the same units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BounceGather {
    /// The gathered irradiance per sun direction, front then back face.
    pub gathered: [[f32; 2]; 14],
    /// Eq. 5.24's.
    pub closed: [[f32; 2]; 14],
}

/// A face's ratio: `gathered / closed` in `[0, RATIO_MAX]`, 1 where eq. 5.24 brings the face
/// nothing (or the gather is not finite).
fn face_ratio(gathered: f32, closed: f32) -> f32 {
    if closed > 1e-6 && gathered.is_finite() {
        (gathered / closed).clamp(0.0, RATIO_MAX)
    } else {
        1.0
    }
}

impl BounceGather {
    /// The leaf's ratios from its own gather alone.
    pub fn ratios(&self) -> BounceRatios {
        BounceRatios {
            front: std::array::from_fn(|k| face_ratio(self.gathered[k][0], self.closed[k][0])),
            back: std::array::from_fn(|k| face_ratio(self.gathered[k][1], self.closed[k][1])),
        }
    }
}

/// The [`BounceGather`] of leaf `leaf` (its envelope `envelope`, in a crown of extinction
/// `tau` whose constants per basis sun are `bounces`, [`basis_bounces`]), from `rays` rays.
/// The sun's share at the leaf is taken as the shaders take it for eq. 5.24, the blend of its
/// attenuations ([`SunThroughCrown::BlendedAttenuation`]).
#[allow(clippy::too_many_arguments)]
pub fn bounce_gather(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaf: usize,
    envelope: &LeafEnvelope,
    tau: f32,
    bounces: &[SunBounce; 14],
    rays: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
) -> BounceGather {
    let mut out = BounceGather::default();
    if leaf >= scene.leaf_count() {
        return out;
    }
    let faces = gathered_and_closed(
        scene, material, leaf, envelope, tau, &SUN_BASIS, bounces, rays, opacity, None, seed,
    );
    for (k, (gathered, closed)) in faces.into_iter().enumerate() {
        out.gathered[k] = gathered;
        out.closed[k] = closed;
    }
    out
}

/// Per sun of `suns` (unit, towards the sun; `bounces[k]` eq. 5.24's constants for `suns[k]`),
/// the irradiance leaf `leaf` (in `scene`, envelope `envelope`, in a crown of extinction `tau`)
/// gathers from its neighbours on each face ([`gather_irradiance`], `rays` rays, `seed`) and
/// eq. 5.24's ([`closed_form_irradiance`]), the sun's share at the leaf taken as the shaders
/// take it for eq. 5.24, the blend of its attenuations ([`SunThroughCrown::BlendedAttenuation`]).
/// What the bake's ratios ([`bounce_gather`]) and those re-gathered for given suns
/// ([`sun_ratios_of`]) are both made of.
#[allow(clippy::too_many_arguments)]
fn gathered_and_closed(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaf: usize,
    envelope: &LeafEnvelope,
    tau: f32,
    suns: &[Vec3],
    bounces: &[SunBounce],
    rays: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    lit: Option<&(dyn Fn(u32, Vec3, usize) -> f32 + Sync)>,
    seed: u64,
) -> Vec<([f32; 2], [f32; 2])> {
    let gathered = match lit {
        Some(lit) => gather_irradiance_by(
            scene,
            material,
            leaf,
            rays,
            suns,
            opacity,
            &mut SplitMix64::new(seed),
            &mut |u| scene.point_at(leaf, u),
            lit,
        ),
        None => gather_irradiance(scene, material, leaf, rays, suns, opacity, seed),
    };
    let n = scene.normal(leaf);
    suns.iter()
        .zip(bounces)
        .zip(gathered)
        .map(|((&sun, bounce), gathered)| {
            let through = sun_through_crown(
                SunThroughCrown::BlendedAttenuation,
                tau,
                &envelope.attenuation,
                &envelope.s_max,
                sun,
            );
            let closed = closed_form_irradiance(material, bounce, through, &envelope.s_max, n);
            (gathered, closed)
        })
        .collect()
}

/// The [`BounceRatios`] of leaf `leaf` from its own gather alone ([`bounce_gather`]'s
/// arguments; [`BounceGather::ratios`]).
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
    bounce_gather(
        scene, material, leaf, envelope, tau, bounces, rays, opacity, seed,
    )
    .ratios()
}

/// The [`BounceGather`] of each of `leaves` (indices into `scene`; `envelopes[i]` the envelope
/// of `leaves[i]`, none: an empty gather, whose ratios are 1) on up to `threads` threads.
#[allow(clippy::too_many_arguments)]
pub fn bounce_gathers_of(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    rays: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    threads: usize,
) -> Vec<BounceGather> {
    let bounces = basis_bounces(material, tau);
    let jobs: Vec<(u32, Option<&LeafEnvelope>)> = leaves
        .iter()
        .enumerate()
        .map(|(i, &leaf)| (leaf, envelopes.get(i)))
        .collect();
    super::par_map(&jobs, threads, |&(leaf, envelope)| {
        let Some(envelope) = envelope else {
            return BounceGather::default();
        };
        bounce_gather(
            scene,
            material,
            leaf as usize,
            envelope,
            tau,
            &bounces,
            rays,
            opacity,
            leaf_seed(scene, leaf),
        )
    })
}

/// The seed of leaf `leaf`'s gather in `scene`: its rays, from whichever sun and wherever the
/// leaf is stored, are the same rays ([`LeafScene::leaf_key`]).
pub(crate) fn leaf_seed(scene: &LeafScene, leaf: u32) -> u64 {
    0xB0B1_u64 ^ scene.leaf_key(leaf as usize)
}

/// The seed of pass `pass` of a gather seeded `seed`: pass 0 is the gather itself, each later
/// pass another shift of the same low-discrepancy rays (an independent Cranley–Patterson
/// rotation), so that the mean of several passes is an unbiased gather with their rays in all
/// ([`super::bounce_ring::RingRefinement`]).
pub(crate) fn pass_seed(seed: u64, pass: u32) -> u64 {
    seed ^ (pass as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// Per leaf of `leaves` (indices into `scene`; `envelopes[i]` the envelope of `leaves[i]`),
/// its ratios for each of `suns` (towards the sun), front face then back: the
/// [`BounceRatios`] a bake stores for the fourteen [`SUN_BASIS`] directions, gathered instead
/// for the suns given — for the sun of the moment, or a ring of suns at its elevation
/// ([`sun_ring`]) — so that no blend over far directions stands between the gather and the
/// sun: one shadow ray per neighbour hit and sun. For a basis direction they are the bake's
/// ratios for it exactly (the same rays, the same seed per leaf). A leaf without an envelope or not in
/// `scene`, or a sun that is no direction (zero, not finite): 1, eq. 5.24 unchanged.
///
/// What lighting that changes would re-gather when the sun has moved (Boulanger 2008, §5.4.3
/// and §5.6 recompute G1–G3, eq. 5.18, 5.25, 5.26, on the CPU when the lighting changes; this
/// is the same step for the gathered part). Its cost and its image error against the blend
/// are measured by `tree_lighting_error --images --bounce-rays R [--sun-ring N[,N…]]`.
#[allow(clippy::too_many_arguments)]
pub fn sun_ratios_of(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    suns: &[Vec3],
    rays: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    threads: usize,
) -> Vec<Vec<[f32; 2]>> {
    sun_ratios_with(
        scene, material, leaves, envelopes, tau, suns, rays, 0, opacity, None, threads,
    )
}

/// [`sun_ratios_of`], the sun's share at each neighbour's hit given by
/// `lit(neighbour, hit point, index of the sun in suns)` in place of a shadow ray where `lit`
/// is given (a sun of `suns` that is no direction is left out of the indices `lit` sees: give
/// only directions). A ring with its leaves' sunlit planes reads them so
/// ([`super::bounce_ring::gather_ring`], [`super::bounce_floor`]): no shadow rays to cast,
/// and one coin less in each ray's toss. Pass `pass` (0: the gather of [`sun_ratios_of`]) casts
/// the leaf's rays shifted anew ([`pass_seed`]): a ring averages several.
#[allow(clippy::too_many_arguments)]
pub fn sun_ratios_with(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    suns: &[Vec3],
    rays: u32,
    pass: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    lit: Option<&(dyn Fn(u32, Vec3, usize) -> f32 + Sync)>,
    threads: usize,
) -> Vec<Vec<[f32; 2]>> {
    // The suns that are directions, and where each given sun is among them.
    let mut valid = Vec::with_capacity(suns.len());
    let at: Vec<Option<usize>> = suns
        .iter()
        .map(|s| {
            s.try_normalize().map(|s| {
                valid.push(s);
                valid.len() - 1
            })
        })
        .collect();
    let bounces: Vec<SunBounce> = valid
        .iter()
        .map(|&s| SunBounce::new(material, s, tau))
        .collect();
    let jobs: Vec<(u32, Option<&LeafEnvelope>)> = leaves
        .iter()
        .enumerate()
        .map(|(i, &leaf)| (leaf, envelopes.get(i)))
        .collect();
    super::par_map(&jobs, threads, |&(leaf, envelope)| {
        let Some(envelope) = envelope.filter(|_| (leaf as usize) < scene.leaf_count()) else {
            return vec![[1.0; 2]; suns.len()];
        };
        if valid.is_empty() {
            return vec![[1.0; 2]; suns.len()];
        }
        let ratios: Vec<[f32; 2]> = gathered_and_closed(
            scene,
            material,
            leaf as usize,
            envelope,
            tau,
            &valid,
            &bounces,
            rays,
            opacity,
            lit,
            pass_seed(leaf_seed(scene, leaf), pass),
        )
        .into_iter()
        .map(|(gathered, closed)| {
            [
                face_ratio(gathered[0], closed[0]),
                face_ratio(gathered[1], closed[1]),
            ]
        })
        .collect();
        at.iter()
            .map(|k| k.map_or([1.0; 2], |k| ratios[k]))
            .collect()
    })
}

/// `count` suns at the elevation of `to_sun` over the crown's ground (model space, +y up),
/// at azimuths `phase + 2π·i / count` (the azimuth of `(x, y, z)` is `atan2(z, x)`): the
/// suns a tree turned about its vertical by any angle sees the one sun as. Ratios gathered
/// for them ([`sun_ratios_of`]) serve every such tree ([`ratio_on_ring`]), where ratios for
/// the sun alone serve only trees turned as the bake's. Empty for a sun that is no direction
/// or a count of 0.
pub fn sun_ring(to_sun: Vec3, count: usize, phase: f32) -> Vec<Vec3> {
    let Some(to_sun) = to_sun.try_normalize() else {
        return Vec::new();
    };
    if !phase.is_finite() {
        return Vec::new();
    }
    let y = to_sun.y.clamp(-1.0, 1.0);
    let across = (1.0 - y * y).max(0.0).sqrt();
    (0..count)
        .map(|i| {
            let azimuth = phase + std::f32::consts::TAU * i as f32 / count as f32;
            Vec3::new(across * azimuth.cos(), y, across * azimuth.sin())
        })
        .collect()
}

/// The ratios towards `to_sun` from ratios gathered on a [`sun_ring`] of `ring.len()` suns
/// at azimuths from `phase`: linear in azimuth between the two nodes either side (a sun on a
/// node takes its ratios; continuous all round). No ring: eq. 5.24 unchanged (1, 1).
pub fn ratio_on_ring(ring: &[[f32; 2]], phase: f32, to_sun: Vec3) -> [f32; 2] {
    let Some((i, j, f)) = nodes_either_side(ring.len(), phase, to_sun) else {
        return [1.0; 2];
    };
    let (a, b) = (ring[i], ring[j]);
    [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]
}

/// Where `to_sun`'s azimuth falls on a [`sun_ring`] of `count` suns at azimuths from `phase`:
/// the nodes either side, `(i, j)`, and how far from `i` towards `j` it lies, `f` in [0, 1]
/// (a value on the ring is `v[i] + f · (v[j] − v[i])`). A sun whose azimuth is not finite
/// takes node 0 alone. No ring: `None`.
pub fn nodes_either_side(count: usize, phase: f32, to_sun: Vec3) -> Option<(usize, usize, f32)> {
    if count == 0 {
        return None;
    }
    let azimuth = to_sun.z.atan2(to_sun.x) - phase;
    let x = (azimuth / (std::f32::consts::TAU / count as f32)).rem_euclid(count as f32);
    if !x.is_finite() {
        return Some((0, 0, 0.0));
    }
    let i = (x.floor() as usize).min(count - 1);
    Some((i, (i + 1) % count, (x - i as f32).clamp(0.0, 1.0)))
}

/// [`bounce_ratios`] of each of `leaves` (indices into `scene`; `envelopes[i]` the envelope of
/// `leaves[i]`) on up to `threads` threads, each leaf's gather pooled with those of its
/// `pool − 1` nearest neighbours among `leaves` ([`pooled_ratios`]; 0 or 1: its own alone).
#[allow(clippy::too_many_arguments)]
pub fn bounce_ratios_of(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    rays: u32,
    pool: usize,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    threads: usize,
) -> Vec<BounceRatios> {
    let gathers = bounce_gathers_of(
        scene, material, leaves, envelopes, tau, rays, opacity, threads,
    );
    let at = |i: usize| {
        leaves
            .get(i)
            .map(|&l| l as usize)
            .filter(|&l| l < scene.leaf_count())
    };
    let centres: Vec<Vec3> = (0..leaves.len())
        .map(|i| at(i).map_or(Vec3::ZERO, |l| scene.centre(l)))
        .collect();
    let normals: Vec<Vec3> = (0..leaves.len())
        .map(|i| at(i).map_or(Vec3::ZERO, |l| scene.normal(l)))
        .collect();
    pooled_ratios(&centres, &normals, &gathers, pool, threads)
}

/// The default of [`crate::pruning::bake::BakeSettings::bounce_pool`]: leaves (the leaf and
/// its nearest neighbours) whose gathers make each leaf's ratios — the leaf alone. Pooling
/// was measured (`tree_lighting_error --images --rays-per-bin 32 --seen-points 16
/// --bounce-rays 64 --hotspot --bounce-pool 1,4,8,16`, four suns, pixels about 1.5 leaves
/// wide): over 8 leaves the bounce against the sun (α = 137–148°) is 0.2–4.8 points better on
/// the four procedural trees (the ash 31.8 → 29.3 %, the oak 35.7 → 30.9 %) and on the
/// uniform ball at pixels a leaf wide 1.4–2.3 points better at every sun, but with the sun from
/// the side or above 0.1–2.4 points worse on the trees (the oak 11.2 → 13.6 %): the sum over
/// the trees and suns barely moves. What holds the bounce against the sun at 21–37 % is not
/// the gather's noise but the blend over [`SUN_BASIS`]: the same rays gathered for the image's
/// own sun are 11–18 % off there.
pub const DEFAULT_BOUNCE_POOL: usize = 1;

/// The most leaves a pool takes.
pub const MAX_BOUNCE_POOL: usize = 256;

/// Each leaf's [`BounceRatios`] from its gather pooled with those of its `pool − 1` nearest
/// neighbours (by centre; 0 or 1: its own alone): per face and sun direction the sum of the
/// gathered irradiances over the sum of eq. 5.24's — a ratio of sums, which a neighbour with
/// little light does not swing. A neighbour's faces are taken as the leaf's where its normal
/// agrees with the leaf's (dot ≥ 0) and swapped where not, and weighted by the squared
/// cosine between the two normals (the leaf itself by 1): a face's bounce depends on which way
/// it faces. Why: 64 rays a leaf leave each ratio some 25 % noisy — a face sees lit
/// neighbours along a third of its rays, each lit or not — where a leaf's neighbours, lit by
/// the same gaps, share its ratio's cause (the crown's clustering, which eq. 5.24 averages
/// away). `centres`, `normals` and `gathers` are per leaf, of one length (the shortest is
/// taken).
pub fn pooled_ratios(
    centres: &[Vec3],
    normals: &[Vec3],
    gathers: &[BounceGather],
    pool: usize,
    threads: usize,
) -> Vec<BounceRatios> {
    let n = centres.len().min(normals.len()).min(gathers.len());
    let pool = pool.clamp(1, MAX_BOUNCE_POOL);
    if pool == 1 {
        return gathers[..n].iter().map(BounceGather::ratios).collect();
    }
    let nearest = nearest_leaves(&centres[..n], pool, threads);
    let items: Vec<usize> = (0..n).collect();
    super::par_map(&items, threads, |&i| {
        let ni = normals[i];
        let mut sum = BounceGather::default();
        for &j in &nearest[i] {
            let j = j as usize;
            let c = ni.dot(normals[j]);
            let w = if j == i { 1.0 } else { c * c };
            // A weight of 0 or not a number (a degenerate normal) pools nothing.
            if w.is_nan() || w <= 0.0 {
                continue;
            }
            // The neighbour's face on the leaf's front side first.
            let (f, b) = if c >= 0.0 || j == i { (0, 1) } else { (1, 0) };
            for k in 0..14 {
                let (g, cl) = (&gathers[j].gathered[k], &gathers[j].closed[k]);
                if !(g[f].is_finite() && g[b].is_finite() && cl[f].is_finite() && cl[b].is_finite())
                {
                    continue;
                }
                sum.gathered[k][0] += w * g[f];
                sum.gathered[k][1] += w * g[b];
                sum.closed[k][0] += w * cl[f];
                sum.closed[k][1] += w * cl[b];
            }
        }
        sum.ratios()
    })
}

/// For each of `points`, the indices of its `k` nearest among them (itself first, then by
/// distance; fewer where there are fewer points), by a uniform grid searched ring by ring.
pub fn nearest_leaves(points: &[Vec3], k: usize, threads: usize) -> Vec<Vec<u32>> {
    let n = points.len();
    let k = k.min(n);
    if n == 0 || k == 0 {
        return vec![Vec::new(); n];
    }
    let finite = |p: &Vec3| p.is_finite();
    let (lo, hi) = points.iter().filter(|p| finite(p)).fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    if !lo.is_finite() {
        return (0..n as u32).map(|i| vec![i]).collect();
    }
    // Cells of about `k` points where the points filled the box, at most 64 a side.
    let extent = (hi - lo).max(Vec3::splat(1e-6));
    let cell = (extent.x * extent.y * extent.z * k as f32 / n as f32)
        .cbrt()
        .max(extent.max_element() / 64.0)
        .max(1e-6);
    let dims = ((extent / cell).floor().as_uvec3() + 1).min(bevy::math::UVec3::splat(64));
    let cell_of = |p: Vec3| {
        let c = ((p - lo) / cell).floor();
        let c = c.clamp(Vec3::ZERO, (dims - 1).as_vec3());
        c.as_uvec3()
    };
    let index = |c: bevy::math::UVec3| ((c.z * dims.y + c.y) * dims.x + c.x) as usize;
    let mut start = vec![0u32; (dims.x * dims.y * dims.z) as usize + 1];
    let cells: Vec<usize> = points
        .iter()
        .map(|&p| {
            if finite(&p) {
                index(cell_of(p))
            } else {
                usize::MAX
            }
        })
        .collect();
    for &c in cells.iter().filter(|&&c| c != usize::MAX) {
        start[c + 1] += 1;
    }
    for i in 1..start.len() {
        start[i] += start[i - 1];
    }
    let mut fill = start.clone();
    let mut members = vec![0u32; start[start.len() - 1] as usize];
    for (i, &c) in cells.iter().enumerate().filter(|&(_, &c)| c != usize::MAX) {
        members[fill[c] as usize] = i as u32;
        fill[c] += 1;
    }
    let items: Vec<usize> = (0..n).collect();
    let max_ring = dims.max_element() as i32;
    super::par_map(&items, threads, |&i| {
        let p = points[i];
        if !finite(&p) {
            return vec![i as u32];
        }
        let home = cell_of(p).as_ivec3();
        // The best `k` so far, by squared distance, nearest first.
        let mut best: Vec<(f32, u32)> = Vec::with_capacity(k + 1);
        for ring in 0..=max_ring {
            // Points in cells of this ring are at least (ring − 1) cells away.
            let bound = (ring - 1).max(0) as f32 * cell;
            if best.len() == k && best[k - 1].0 <= bound * bound {
                break;
            }
            for z in -ring..=ring {
                for y in -ring..=ring {
                    for x in -ring..=ring {
                        if x.abs().max(y.abs()).max(z.abs()) != ring {
                            continue;
                        }
                        let c = home + bevy::math::IVec3::new(x, y, z);
                        if c.min_element() < 0 || c.cmpge(dims.as_ivec3()).any() {
                            continue;
                        }
                        let c = index(c.as_uvec3());
                        for &j in &members[start[c] as usize..start[c + 1] as usize] {
                            let d = if j as usize == i {
                                -1.0
                            } else {
                                points[j as usize].distance_squared(p)
                            };
                            if best.len() == k && d >= best[k - 1].0 {
                                continue;
                            }
                            let at = best.partition_point(|&(e, _)| e <= d);
                            best.insert(at, (d, j));
                            best.truncate(k);
                        }
                    }
                }
            }
        }
        best.into_iter().map(|(_, j)| j).collect()
    })
}

/// Bytes a leaf's [`BounceRatios`] take as a bake stores them ([`BounceRatios::quantized`]):
/// the front face's fourteen then the back face's.
pub const STORED_RATIOS: usize = 28;

/// Steps of the stored ratios' logarithm: codes 1–255 span `log2` from −4 to +4 ([1/16, 16],
/// each step 2.2 % of the ratio); code 0 is a ratio of 0 (a face that sees no lit neighbour).
const RATIO_LOG2_STEPS: f32 = 254.0;

/// A ratio as a bake stores it: 0 below 1/32, else its base-2 logarithm over [−4, 4] in
/// 254 steps (1 is stored exactly, as code 128); not finite: 1.
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

/// The crown's mean ratios over its leaves' (each face and sun direction its own mean), each
/// leaf weighted by `weights` (how much an eye outside the crown sees of it,
/// [`super::bounce_ring::crown_view_weights`]; every leaf alike where `weights` is not one a
/// leaf), for a billboard cloud, whose texels have no room for their leaves' own; none, or no
/// weight: all 1.
pub fn crown_mean_ratios(ratios: &[BounceRatios], weights: &[f32]) -> BounceRatios {
    let weight = |i: usize| {
        let w = if weights.len() == ratios.len() {
            weights[i]
        } else {
            1.0
        };
        if w > 0.0 && w.is_finite() { w } else { 0.0 }
    };
    let total: f32 = (0..ratios.len()).map(weight).sum();
    if total <= 0.0 {
        return BounceRatios::default();
    }
    let mean = |face: &dyn Fn(&BounceRatios) -> &[f32; 14]| -> [f32; 14] {
        std::array::from_fn(|k| {
            ratios
                .iter()
                .enumerate()
                .map(|(i, r)| weight(i) * face(r)[k])
                .sum::<f32>()
                / total
        })
    };
    BounceRatios {
        front: mean(&|r| &r.front),
        back: mean(&|r| &r.back),
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
            1,
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

    /// Re-gathered for given suns, a leaf's ratios are the bake's for a sun that is a basis
    /// direction — the same rays, one shadow ray per hit and sun instead of fourteen — and move
    /// with the sun between them; a sun that is no direction, a leaf not in the scene or without
    /// an envelope leave eq. 5.24 as it is.
    #[test]
    fn ratios_regathered_for_a_basis_sun_are_the_bakes() {
        let tree = crate::pruning::procedural::generate(
            &crate::pruning::procedural::TreeSpecies::olea().with_leaf_count(400),
        );
        let scene = LeafScene::new(&tree.leaves);
        let mat = LeafMaterial::default();
        let all: Vec<u32> = (0..scene.leaf_count() as u32).collect();
        let env = crown_envelope_traced(
            &proxies(&tree.leaves),
            &scene,
            &all,
            &|_| 1.0,
            16,
            2,
            &|_| {},
        );
        let picked: Vec<u32> = all.iter().copied().step_by(7).collect();
        let envelopes: Vec<_> = picked.iter().map(|&l| env.leaves[l as usize]).collect();
        let rays = 24;
        let regather = |suns: &[Vec3]| {
            sun_ratios_of(
                &scene,
                &mat,
                &picked,
                &envelopes,
                env.tau,
                suns,
                rays,
                &|_| 1.0,
                2,
            )
        };
        let baked: Vec<BounceRatios> = bounce_gathers_of(
            &scene,
            &mat,
            &picked,
            &envelopes,
            env.tau,
            rays,
            &|_| 1.0,
            2,
        )
        .iter()
        .map(BounceGather::ratios)
        .collect();
        let basis = [0, 5, 8, 10, 11, 13];
        let suns: Vec<Vec3> = basis.iter().map(|&k| SUN_BASIS[k]).collect();
        let again = regather(&suns);
        let mut moved = 0;
        for (r, b) in again.iter().zip(&baked) {
            assert_eq!(r.len(), suns.len());
            for (i, &k) in basis.iter().enumerate() {
                // The same rays; the sun renormalised may differ in its last bit.
                for (got, want) in r[i].iter().zip([b.front[k], b.back[k]]) {
                    assert!(
                        (got - want).abs() <= 1e-5 * want.max(1.0),
                        "sun {k}: {r:?} {b:?}"
                    );
                }
                moved += (r[i][0] != 1.0) as usize;
            }
        }
        assert!(
            moved * 2 > basis.len() * picked.len(),
            "{moved} ratios gathered"
        );
        // Between two basis directions the sun's own ratios differ from both.
        let between = (SUN_BASIS[10] + SUN_BASIS[8]).normalize();
        let own = regather(&[between]);
        let differs = |k: usize| {
            own.iter()
                .zip(&baked)
                .filter(|(r, b)| (r[0][0] - b.front[k]).abs() > 1e-3)
                .count()
        };
        assert!(differs(8) * 2 > picked.len() && differs(10) * 2 > picked.len());
        assert!(
            own.iter()
                .flatten()
                .flatten()
                .all(|r| (0.0..=RATIO_MAX).contains(r))
        );
        // Bad input: a sun that is no direction leaves eq. 5.24, the others are gathered.
        let mixed = regather(&[
            Vec3::ZERO,
            SUN_BASIS[5],
            Vec3::NAN,
            Vec3::splat(f32::INFINITY),
        ]);
        for (r, b) in mixed.iter().zip(&baked) {
            assert_eq!(r.len(), 4);
            assert_eq!([r[0], r[2], r[3]], [[1.0; 2]; 3]);
            assert!((r[1][0] - b.front[5]).abs() <= 1e-5 * b.front[5].max(1.0));
            assert!((r[1][1] - b.back[5]).abs() <= 1e-5 * b.back[5].max(1.0));
        }
        let r = sun_ratios_of(
            &scene,
            &mat,
            &[0, scene.leaf_count() as u32, 1],
            &envelopes[..1],
            env.tau,
            &[Vec3::Y],
            rays,
            &|_| 1.0,
            1,
        );
        assert_eq!(r[1], vec![[1.0; 2]]);
        assert_eq!(r[2], vec![[1.0; 2]]);
    }

    /// A ring's suns stand at the sun's elevation, evenly round the vertical from its phase;
    /// a sun on a node takes that node's ratios, one midway the mean of the two, and the
    /// ratios move continuously all round (across the last node to the first too).
    #[test]
    fn a_ring_of_suns_serves_every_turn_of_the_tree() {
        let sun = Vec3::new(0.5, 0.7, 0.3).normalize();
        let phase = 0.4;
        let ring = sun_ring(sun, 8, phase);
        assert_eq!(ring.len(), 8);
        for (i, d) in ring.iter().enumerate() {
            assert!((d.length() - 1.0).abs() < 1e-5);
            assert!((d.y - sun.y).abs() < 1e-6);
            let azimuth = d.z.atan2(d.x);
            let want = phase + std::f32::consts::TAU * i as f32 / 8.0;
            let off = (azimuth - want).rem_euclid(std::f32::consts::TAU);
            assert!(
                !(1e-4..=std::f32::consts::TAU - 1e-4).contains(&off),
                "node {i}"
            );
        }
        let ratios: Vec<[f32; 2]> = (0..8).map(|i| [1.0 + i as f32, 0.5 * i as f32]).collect();
        for (i, d) in ring.iter().enumerate() {
            let r = ratio_on_ring(&ratios, phase, *d);
            assert!((r[0] - ratios[i][0]).abs() < 1e-3 && (r[1] - ratios[i][1]).abs() < 1e-3);
        }
        let midway = sun_ring(sun, 16, phase);
        let r = ratio_on_ring(&ratios, phase, midway[5]);
        assert!(
            (r[0] - 0.5 * (ratios[2][0] + ratios[3][0])).abs() < 1e-3,
            "{r:?}"
        );
        // Across the wrap, from node 7 to node 0.
        let r = ratio_on_ring(&ratios, phase, midway[15]);
        assert!(
            (r[0] - 0.5 * (ratios[7][0] + ratios[0][0])).abs() < 1e-3,
            "{r:?}"
        );
        let mut last = ratio_on_ring(&ratios, phase, Vec3::X);
        for step in 1..=720 {
            let a = step as f32 / 720.0 * std::f32::consts::TAU;
            let r = ratio_on_ring(&ratios, phase, Vec3::new(a.cos(), 0.3, a.sin()));
            assert!(
                (r[0] - last[0]).abs() <= 7.0 * 8.0 / 720.0 + 1e-3,
                "step {step}"
            );
            last = r;
        }
        // Straight up, every node is the sun; bad input gives no ring or eq. 5.24.
        assert!(
            sun_ring(Vec3::Y, 4, 0.0)
                .iter()
                .all(|d| (*d - Vec3::Y).length() < 1e-6)
        );
        assert!(sun_ring(Vec3::ZERO, 4, 0.0).is_empty());
        assert!(sun_ring(sun, 4, f32::NAN).is_empty());
        assert!(sun_ring(sun, 0, 0.0).is_empty());
        assert_eq!(ratio_on_ring(&[], 0.0, sun), [1.0; 2]);
        assert_eq!(ratio_on_ring(&ratios, 0.0, Vec3::NAN), ratios[0]);
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

    /// A crown's mean ratios are each face's and sun's own mean over the leaves, weighted
    /// where there is a weight a leaf; no leaves, or none weighing anything, leave eq. 5.24 as
    /// it is.
    #[test]
    fn the_crown_mean_keeps_faces_and_suns_apart() {
        assert_eq!(crown_mean_ratios(&[], &[]), BounceRatios::default());
        let a = BounceRatios {
            front: std::array::from_fn(|k| k as f32),
            back: [2.0; 14],
        };
        let b = BounceRatios {
            front: std::array::from_fn(|k| 3.0 * k as f32),
            back: [0.0; 14],
        };
        // Weights for another number of leaves: alike.
        for weights in [&[][..], &[1.0][..]] {
            let mean = crown_mean_ratios(&[a, b], weights);
            for k in 0..14 {
                assert_eq!(mean.front[k], 2.0 * k as f32);
                assert_eq!(mean.back[k], 1.0);
            }
        }
        // One weight a leaf: b three times a's, a weight not finite or below 0 counting for none.
        let mean = crown_mean_ratios(&[a, b, a], &[1.0, 3.0, f32::NAN]);
        for k in 0..14 {
            assert!((mean.front[k] - 2.5 * k as f32).abs() < 1e-5);
            assert!((mean.back[k] - 0.5).abs() < 1e-6);
        }
        assert_eq!(
            crown_mean_ratios(&[a, b], &[0.0, -1.0]),
            BounceRatios::default()
        );
    }

    /// The grid's nearest neighbours are a brute-force search's (by distance; the point
    /// itself first), on clustered and spread points, with fewer points than asked and with a
    /// point not finite (its own alone, and nobody's neighbour).
    #[test]
    fn nearest_leaves_are_a_brute_force_searchs() {
        let mut rng = SplitMix64::new(3);
        let mut points: Vec<Vec3> = Vec::new();
        for c in 0..6 {
            let centre = Vec3::new(c as f32 * 0.7, (c % 2) as f32, 0.0);
            for _ in 0..60 {
                points.push(
                    centre
                        + crate::lighting::leaf_scene::uniform_direction(&mut rng)
                            * 0.05
                            * rng.next_f32(),
                );
            }
        }
        for _ in 0..80 {
            points.push(Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0);
        }
        points.push(Vec3::NAN);
        let nan = points.len() - 1;
        for k in [1, 8, 33] {
            let got = nearest_leaves(&points, k, 2);
            for (i, p) in points.iter().enumerate() {
                assert_eq!(got[i][0] as usize, i);
                if i == nan {
                    assert_eq!(got[i].len(), 1);
                    continue;
                }
                let mut want: Vec<f32> = points
                    .iter()
                    .enumerate()
                    .filter(|&(j, q)| j != i && q.is_finite())
                    .map(|(_, q)| q.distance(*p))
                    .collect();
                want.sort_by(f32::total_cmp);
                let found: Vec<f32> = got[i][1..]
                    .iter()
                    .map(|&j| points[j as usize].distance(*p))
                    .collect();
                assert_eq!(found.len(), k - 1, "point {i}");
                for (f, w) in found.iter().zip(&want) {
                    assert!((f - w).abs() < 1e-6, "point {i}: {found:?} vs {want:?}");
                }
                assert!(!got[i].contains(&(nan as u32)));
            }
        }
        let few = nearest_leaves(&points[..3], 8, 1);
        assert!(few.iter().all(|n| n.len() == 3));
        assert!(nearest_leaves(&[], 8, 1).is_empty());
    }

    /// Pooling is a ratio of sums with each neighbour's faces turned to the leaf's: a
    /// neighbour facing the other way lends its back face's light to the leaf's front, one
    /// edge-on (normal at right angles) lends nothing, and a pool of 1 is the leaf's own.
    #[test]
    fn pooling_turns_each_neighbours_faces_to_the_leaf() {
        let g = |front: f32, back: f32, closed: [f32; 2]| BounceGather {
            gathered: [[front, back]; 14],
            closed: [closed; 14],
        };
        let centres = [Vec3::ZERO, Vec3::X * 0.1, Vec3::Z * 0.05, Vec3::X * 50.0];
        let normals = [Vec3::Y, Vec3::NEG_Y, Vec3::X, Vec3::Y];
        let gathers = [
            g(1.0, 0.0, [1.0, 1.0]),
            g(0.0, 3.0, [1.0, 2.0]),
            g(9.0, 9.0, [1.0, 1.0]),
            g(10.0, 10.0, [1.0, 1.0]),
        ];
        let own = pooled_ratios(&centres, &normals, &gathers, 1, 1);
        for (r, g) in own.iter().zip(&gathers) {
            assert_eq!(*r, g.ratios());
        }
        let three = pooled_ratios(&centres, &normals, &gathers, 3, 2);
        // Leaf 0: its own (1, 0 over 1, 1), leaf 1 turned (3, 0 over 2, 1), leaf 2 edge-on.
        assert_eq!(three[0].front, [4.0 / 3.0; 14]);
        assert_eq!(three[0].back, [0.0; 14]);
        // Leaf 1: its own (0, 3 over 1, 2), leaf 0 turned (0, 1 over 1, 1).
        assert_eq!(three[1].front, [0.0; 14]);
        assert_eq!(three[1].back, [4.0 / 3.0; 14]);
        // The far leaf is in no one's pool of three (above); its own takes its nearest two,
        // leaf 1 turned and leaf 0: (10 + 3 + 1, 10 + 0 + 0 over 1 + 2 + 1, 1 + 1 + 1).
        assert_eq!(three[3].front, [14.0 / 4.0; 14]);
        assert_eq!(three[3].back, [10.0 / 3.0; 14]);
        // Broken input is left out: a NaN gather counts for nothing.
        let mut broken = gathers;
        broken[1].gathered[4][1] = f32::NAN;
        let r = pooled_ratios(&centres, &normals, &broken, 3, 1);
        assert_eq!(r[0].front[4], 1.0);
        assert_eq!(r[0].front[5], 4.0 / 3.0);
    }

    /// What pooling is for: in a uniform ball, where neighbours share their causes, ratios
    /// from 32 rays a leaf pooled over 8 leaves are nearer each leaf's ratios from 512 rays
    /// than its own 32 rays' are.
    #[test]
    fn pooled_ratios_are_nearer_a_long_gather_than_a_leafs_own() {
        let leaves = uniform_ball(900, 1.2, 0.05, 8);
        let scene = LeafScene::new(&leaves);
        let mat = LeafMaterial::default();
        let order: Vec<u32> = (0..leaves.len() as u32).collect();
        let env =
            crown_envelope_traced(&proxies(&leaves), &scene, &order, &|_| 1.0, 16, 2, &|_| {});
        let args = (&scene, &mat, &order, &env.leaves, env.tau);
        let short = |pool| {
            bounce_ratios_of(
                args.0,
                args.1,
                args.2,
                args.3,
                args.4,
                32,
                pool,
                &|_| 1.0,
                2,
            )
        };
        let (own, pooled) = (short(1), short(8));
        let bounces = basis_bounces(&mat, env.tau);
        let (mut own_off, mut pooled_off, mut n) = (0.0f32, 0.0f32, 0);
        for leaf in (0..leaves.len()).step_by(10) {
            let long = bounce_ratios(
                &scene,
                &mat,
                leaf,
                &env.leaves[leaf],
                env.tau,
                &bounces,
                512,
                &|_| 1.0,
                77,
            );
            for k in [1, 6, 10, 12] {
                for (l, o, p) in [
                    (long.front[k], own[leaf].front[k], pooled[leaf].front[k]),
                    (long.back[k], own[leaf].back[k], pooled[leaf].back[k]),
                ] {
                    own_off += (o - l).abs();
                    pooled_off += (p - l).abs();
                    n += 1;
                }
            }
        }
        let (own_off, pooled_off) = (own_off / n as f32, pooled_off / n as f32);
        // Over six balls (this one and five more seeds) the pooled ratios' distance is 0.64–0.70
        // of a leaf's own; unpooled it is 1.
        assert!(
            pooled_off < 0.8 * own_off,
            "pooled {pooled_off:.3} own {own_off:.3} from the long gather"
        );
    }
}
