//! The crown's hotspot: what the eye sees of a crown depends on where the sun is from the eye.
//!
//! The model of Boulanger 2008 (§5.3–5.4) gives each leaf the light the crown lets through
//! towards the sun as the mean over the leaf, and [`super::seen_part`] the gain from that mean
//! to the part of the leaf the eye sees — a gain taken for the sky, the same whatever the sun.
//! But the eye's and the sun's paths out of a crown are not independent: with the sun behind
//! the viewer they leave through the same gaps, so what the eye sees is sunlit (the hotspot, or
//! opposition effect, of vegetation canopies: Kuusk 1985's bidirectional gap probability); with
//! the sun behind the crown, what the eye sees is the side turned from it. In images of the
//! four procedural trees (`tree_lighting_error --images --sun …`, pixels 1.4–1.6 leaves wide, the
//! cedar's 0.6) the
//! blended sun is 40–43 % too dark with the sun behind the eye and 18–63 % too bright against
//! it, the bounce right behind the eye and 94–171 % too bright against it — both tied to the
//! angle between the eye and the sun far more than to either direction.
//!
//! Here, per crown, the ratio of what reaches the eye to what the model gives it, as a function
//! of that phase angle α alone: [`HOTSPOT_NODES`] values from α = 0 (the sun behind the eye)
//! to α = π (the sun facing it), for the sun's direct term and for the bounce, each measured
//! over eye rays cast into the crown from directions spread over the sphere (so a view's
//! points count as an image counts them), the sun's share at each hit point found by a shadow
//! ray and the bounce by gathering the neighbours' sunlight as [`super::path_trace`] does.
//! Plain Rust, baked with the bins; the leaf and cloud shaders interpolate the nodes at the
//! eye's phase angle, raise the blended sun's share to the sun's and scale the bounce by the
//! bounce's. Measured at seven sun directions (`tree_lighting_error --images --hotspot`,
//! the same pixels), the sun's bias on the trees goes from −40…−43 % to −7…−10 % behind
//! the eye and from +18…+63 % to −13…+14 % against it, the bounce's from +94…+171 % to
//! +4.5…+31 % against it and from +9…+45 % to −8.5…+20 % from the side and above (with four
//! nodes instead of eight: −16…−19 %, and +15…+45 % against). What is left lies between the
//! nodes (the hotspot's peak is narrower than a node's span) and in what the angle alone does
//! not say (a low sun crosses more of a tall crown than a high one at the same angle).
//!
//! That last part was measured for the bounce ratios re-gathered on a ring of suns at the
//! sun's height ([`super::bounce_ring`]), whose bounce overhead is 2–7 % too bright with the
//! hotspot measured over the whole sphere against the blended ratios: a hotspot measured for
//! suns at the sun's own height against the ring ([`HotspotSuns::Height`], traced as
//! [`HotspotSettings::OFFLINE`], 0.15–0.5 s for a 2,000-leaf crown on two threads) takes most
//! of that bias away (−2.9…+5.7 %), yet the bounce's image error averaged over the four trees
//! moves by −1.0, −0.05, +0.1 and +0.2 points at four suns (α = 68°, 58°, 137°, 148°;
//! 11.1 → 10.2 % at the best), the sun's by under a point, and traced as a bake made while an
//! app runs would trace it (half the eye rays and bounce rays) it is worse against the sun
//! (15.9 → 17.7 %). So the shaders keep the bake's hotspot for the bounce and the blended sun;
//! `tree_lighting_error --images --hotspot --sun-ring 14` prints the row. The ring's sunlit
//! shares, read where the eye looks, are another thing than the blend, and the ring fits its
//! own exponents on them ([`super::bounce_ring::ring_sun_hotspot`]), with the sun alone and
//! without the bounce's gathers.

use super::envelope::{CrownEnvelope, LeafEnvelope};
use super::gathered_bounce::{BounceRatios, ratio_towards};
use super::leaf_scene::{LeafScene, uniform_direction};
use super::model::{LeafMaterial, SunBounce, bounce_radiance_by_face, lobe_blend, open_share};
use super::path_trace::{TraceLight, TraceSettings, gather, luminance};
use super::seen_part::{covered_gain, seen_gain};
use crate::rng::SplitMix64;
use bevy::math::Vec3;
use std::f32::consts::PI;

/// Phase angles the hotspot is given at, evenly from 0 to π (the shaders interpolate linearly
/// in the angle between them); each node's value is measured over the angles its
/// interpolation covers.
pub const HOTSPOT_NODES: usize = 8;

/// Words a crown's hotspot takes packed ([`Hotspot::packed`]): a byte a node, the sun's nodes
/// then the bounce's.
pub const HOTSPOT_WORDS: usize = HOTSPOT_NODES / 2;

/// Bounds of a hotspot factor as stored (`u8` steps of 1/64, above 0).
pub const HOTSPOT_RANGE: (f32, f32) = (1.0 / 64.0, 255.0 / 64.0);

/// How much a hotspot measurement traces. The default is a bake's made while an app runs;
/// [`HotspotSettings::OFFLINE`] traces eight times as much for a bake kept on disk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HotspotSettings {
    /// (eye, sun) direction pairs per node, their orientation spread over the sphere (0: no
    /// measurement, every factor 1).
    pub pairs: u32,
    /// Eye rays cast into the crown per pair.
    pub eye_rays: u32,
    /// Rays gathered per hit point for the bounce (0: the bounce is not measured, its factors
    /// stay 1).
    pub bounce_rays: u32,
    /// Seed of the random sequences.
    pub seed: u64,
}

impl Default for HotspotSettings {
    fn default() -> Self {
        Self {
            pairs: 8,
            eye_rays: 128,
            bounce_rays: 8,
            seed: 0x407_5907,
        }
    }
}

impl HotspotSettings {
    /// What `foliage_bake` traces: 16 pairs a node, 256 eye rays a pair, 16 bounce rays a hit.
    pub const OFFLINE: Self = Self {
        pairs: 16,
        eye_rays: 256,
        bounce_rays: 16,
        seed: 0x407_5907,
    };

    /// No measurement: the crown's factors stay 1.
    pub const NONE: Self = Self {
        pairs: 0,
        eye_rays: 0,
        bounce_rays: 0,
        seed: 0,
    };

    /// The most a bake accepts of each count.
    pub const MAX: u32 = 4096;

    /// These settings if a bake can run them, or why not (each count at most [`Self::MAX`]).
    pub fn checked(self) -> Result<Self, String> {
        if self.pairs > Self::MAX || self.eye_rays > Self::MAX || self.bounce_rays > Self::MAX {
            Err(format!(
                "hotspot pairs {}, eye rays {}, bounce rays {}: each at most {}",
                self.pairs,
                self.eye_rays,
                self.bounce_rays,
                Self::MAX
            ))
        } else {
            Ok(self)
        }
    }
}

/// A crown's hotspot factors per node of phase angle ([`HOTSPOT_NODES`], α = 0 first).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hotspot {
    /// Exponent on the share of the sun the crown lets through to the leaf (after the
    /// seen-part gain, capped at 1): `t^k`. Below 1 where the eye's and the sun's paths share
    /// their gaps (towards 0 as the sun comes behind the eye: what the eye sees there is lit),
    /// above 1 where what the eye sees is the side turned from the sun. An exponent rather
    /// than a scale: it scales the crown's depth towards the sun as a shared path does
    /// (Kuusk's bidirectional gap probability), and never lifts a share above 1.
    pub sun: [f32; HOTSPOT_NODES],
    /// Scale of the bounce (after the covered part's gain).
    pub bounce: [f32; HOTSPOT_NODES],
}

impl Default for Hotspot {
    /// No correction.
    fn default() -> Self {
        Self {
            sun: [1.0; HOTSPOT_NODES],
            bounce: [1.0; HOTSPOT_NODES],
        }
    }
}

/// The node values `nodes` (α = 0 … π evenly) at the phase angle whose cosine is `cos_alpha`
/// (`to_eye · to_sun`), linearly in the angle.
pub fn at_phase(nodes: &[f32; HOTSPOT_NODES], cos_alpha: f32) -> f32 {
    let alpha = cos_alpha.clamp(-1.0, 1.0).acos();
    let x = alpha / PI * (HOTSPOT_NODES - 1) as f32;
    let i = (x.floor() as usize).min(HOTSPOT_NODES - 2);
    let f = (x - i as f32).clamp(0.0, 1.0);
    nodes[i] * (1.0 - f) + nodes[i + 1] * f
}

impl Hotspot {
    /// The sun's exponent for eye and sun directions `to_eye`, `to_sun` (unit, model space).
    pub fn sun_at(&self, to_eye: Vec3, to_sun: Vec3) -> f32 {
        at_phase(&self.sun, to_eye.dot(to_sun))
    }

    /// The share of the sun `through` (the seen-part gain applied, capped at 1) as the
    /// hotspot makes it for those directions.
    pub fn sun_through(&self, through: f32, to_eye: Vec3, to_sun: Vec3) -> f32 {
        through.clamp(0.0, 1.0).powf(self.sun_at(to_eye, to_sun))
    }

    /// The bounce's factor likewise.
    pub fn bounce_at(&self, to_eye: Vec3, to_sun: Vec3) -> f32 {
        at_phase(&self.bounce, to_eye.dot(to_sun))
    }

    /// A factor as a bake stores it: `u8` in steps of 1/64 over [`HOTSPOT_RANGE`] (1 to 255;
    /// not finite: 1.0).
    pub fn quantize(value: f32) -> u8 {
        let v = if value.is_finite() { value } else { 1.0 };
        (v.clamp(HOTSPOT_RANGE.0, HOTSPOT_RANGE.1) * 64.0).round() as u8
    }

    /// A stored factor's value.
    pub fn dequantize(q: u8) -> f32 {
        q as f32 / 64.0
    }

    /// The factors packed as the leaf shaders read them: a byte a node, four to a word, the
    /// low byte first — the sun's nodes, then the bounce's.
    pub fn packed(&self) -> [u32; HOTSPOT_WORDS] {
        let bytes: Vec<u8> = self
            .sun
            .iter()
            .chain(&self.bounce)
            .map(|&x| Self::quantize(x))
            .collect();
        std::array::from_fn(|w| u32::from_le_bytes(std::array::from_fn(|b| bytes[4 * w + b])))
    }

    /// The factors of [`Self::packed`]'s words.
    pub fn unpacked(words: [u32; HOTSPOT_WORDS]) -> Self {
        let byte = |i: usize| Self::dequantize(words[i / 4].to_le_bytes()[i % 4]);
        Self {
            sun: std::array::from_fn(byte),
            bounce: std::array::from_fn(|k| byte(HOTSPOT_NODES + k)),
        }
    }

    /// These factors as stored (quantised) and whether any was out of range or not finite.
    pub fn sanitized(&self) -> (Self, bool) {
        let stored = Self::unpacked(self.packed());
        let bad = self
            .sun
            .iter()
            .chain(&self.bounce)
            .any(|v| !v.is_finite() || !(HOTSPOT_RANGE.0..=HOTSPOT_RANGE.1).contains(v));
        (stored, bad)
    }
}

/// What one (node, pair) job of [`crown_hotspot`] finds: the sun's samples (weight, the model's
/// share, the traced share) and the bounce's sums (traced, modelled).
type JobSums = (Vec<[f32; 3]>, [f64; 2]);

/// A phase angle for node `k`: drawn from the hat function the shaders' linear interpolation
/// gives the node (1 at the node, 0 at its neighbours), so that each node's value is its
/// hat-weighted mean of the crown's ratio — the cusp of the hotspot at α = 0 spread over the
/// interval its interpolation covers, rather than read at its tip.
fn node_angle(k: usize, rng: &mut SplitMix64) -> f32 {
    let step = PI / (HOTSPOT_NODES - 1) as f32;
    // The difference of two uniforms is triangular on (−1, 1); reflected into [0, π] at the ends.
    let x = k as f32 * step + (rng.next_f32() - rng.next_f32()) * step;
    let x = x.abs();
    if x > PI { 2.0 * PI - x } else { x }
}

/// A unit direction at angle `alpha` from unit `axis`, at a random azimuth.
fn at_angle(axis: Vec3, alpha: f32, rng: &mut SplitMix64) -> Vec3 {
    let (u, v) = axis.any_orthonormal_pair();
    let phi = rng.next_f32() * 2.0 * PI;
    (axis * alpha.cos() + (u * phi.cos() + v * phi.sin()) * alpha.sin()).normalize_or(axis)
}

/// An (eye, sun) pair of unit directions at phase angle `alpha` for the suns `suns`: over the
/// sphere, the eye uniform and the sun at `alpha` from it at a uniform azimuth; at a height,
/// the sun at that height at a uniform azimuth and the eye at `alpha` from it likewise.
fn pair_directions(suns: HotspotSuns, alpha: f32, rng: &mut SplitMix64) -> (Vec3, Vec3) {
    match suns {
        HotspotSuns::Height(height) if height.is_finite() => {
            let y = height.clamp(-1.0, 1.0);
            let across = (1.0 - y * y).max(0.0).sqrt();
            let phi = rng.next_f32() * 2.0 * PI;
            let to_sun = Vec3::new(across * phi.cos(), y, across * phi.sin());
            (at_angle(to_sun, alpha, rng), to_sun)
        }
        _ => {
            let to_eye = uniform_direction(rng);
            (to_eye, at_angle(to_eye, alpha, rng))
        }
    }
}

/// The hotspot of the crown of `scene`, whose leaves' envelope `envelope`, seen-part gains
/// `gains` (empty: no gains) and gathered bounce ratios `ratios` ([`super::gathered_bounce`];
/// empty: eq. 5.24 alone) are what its shaders read — `stored(l)` the index in all three of
/// the scene's leaf `l` (`None`: a leaf not drawn, which still casts shade) — lit through leaves
/// of `material` (the ratio does not change when the material is scaled), `opacity(l)` the
/// share of leaf `l`'s area that stops light; on up to `threads` threads. A node at which no
/// eye ray reached a drawn leaf keeps 1.
#[allow(clippy::too_many_arguments)]
pub fn crown_hotspot(
    scene: &LeafScene,
    envelope: &CrownEnvelope,
    gains: &[[f32; 8]],
    ratios: &[BounceRatios],
    stored: &(dyn Fn(u32) -> Option<usize> + Sync),
    material: &LeafMaterial,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    settings: &HotspotSettings,
    threads: usize,
) -> Hotspot {
    let faces =
        |i: usize, to_sun: Vec3| ratios.get(i).map_or([1.0; 2], |r| ratio_towards(r, to_sun));
    crown_hotspot_for(
        scene,
        &envelope.leaves,
        envelope.tau,
        gains,
        &faces,
        HotspotSuns::Sphere,
        None,
        stored,
        material,
        opacity,
        settings,
        threads,
    )
}

/// Which suns a hotspot is measured for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HotspotSuns {
    /// Suns spread over the whole sphere, each pair's orientation uniform: what a bake
    /// stores, for a sun anywhere.
    Sphere,
    /// Suns at one height (the y of the unit direction towards them, model space: the sine of
    /// their elevation) at every azimuth, each pair's eye at the node's angle from the sun at a
    /// uniform azimuth round it: the hotspot of the sun of the moment, for every instance
    /// turned about its vertical (what a re-gathered ring of bounce ratios serves,
    /// [`super::bounce_ring`]). Clamped to [−1, 1]; not finite: [`HotspotSuns::Sphere`].
    Height(f32),
}

/// [`crown_hotspot`] for a crown of extinction `tau` whose stored leaves have the envelopes
/// `envelopes`, with the bounce factors the shaders give each stored leaf's faces as
/// `faces(i, to_sun)` (eq. 5.24 alone: `[1, 1]`), for the suns `suns`, the sun's exponent
/// fitted against `sun_share(i, to_sun, x)`, the share of the sun drawn at point `x` (model
/// space) of stored leaf `i` before its seen-part gain (`None`: the blend of its eight
/// attenuations, as [`crown_hotspot`]; a leaf's sunlit share or its plane across the leaf,
/// [`super::sunlit_share`], for instance). With `settings.bounce_rays` 0 the bounce is not
/// measured (its factors stay 1).
#[allow(clippy::too_many_arguments)]
pub fn crown_hotspot_for(
    scene: &LeafScene,
    envelopes: &[LeafEnvelope],
    tau: f32,
    gains: &[[f32; 8]],
    faces: &(dyn Fn(usize, Vec3) -> [f32; 2] + Sync),
    suns: HotspotSuns,
    sun_share: Option<&(dyn Fn(usize, Vec3, Vec3) -> f32 + Sync)>,
    stored: &(dyn Fn(u32) -> Option<usize> + Sync),
    material: &LeafMaterial,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    settings: &HotspotSettings,
    threads: usize,
) -> Hotspot {
    let leaves = scene.leaf_count();
    if leaves == 0 || envelopes.is_empty() || settings.pairs == 0 || settings.eye_rays == 0 {
        return Hotspot::default();
    }
    let centre = (0..leaves).map(|l| scene.centre(l)).sum::<Vec3>() / leaves as f32;
    let radius = (0..leaves)
        .map(|l| scene.centre(l).distance(centre))
        .fold(0.0f32, f32::max)
        .max(1e-3)
        * 1.05;
    // Per job (node, pair): sums of traced and modelled sun and bounce.
    let jobs: Vec<(usize, u32)> = (0..HOTSPOT_NODES)
        .flat_map(|k| (0..settings.pairs).map(move |i| (k, i)))
        .collect();
    // Per job: the sun's samples (weight, the model's share t, the traced share) and the
    // bounce's sums (traced, modelled).
    let work = |&(k, i): &(usize, u32)| -> JobSums {
        let mut rng = SplitMix64::new(
            settings.seed ^ ((k as u64) << 32 | i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
        );
        let alpha = node_angle(k, &mut rng);
        let (to_eye, to_sun) = pair_directions(suns, alpha, &mut rng);
        let light = TraceLight {
            sky: Vec3::ZERO,
            ground: Vec3::ZERO,
            to_sun,
            sun: Vec3::ONE,
        };
        let bounce = SunBounce::new(material, to_sun, tau);
        let trace = TraceSettings {
            points: 1,
            directions: settings.bounce_rays.max(2),
            bounces: 1,
            seed: rng.next_u64(),
        };
        let (a, b) = to_eye.any_orthonormal_pair();
        let mut sun = Vec::new();
        let mut sums = [0.0f64; 2];
        for _ in 0..settings.eye_rays {
            // A point of the crown's disc seen from the eye, uniform over its area.
            let r = radius * rng.next_f32().sqrt();
            let phi = rng.next_f32() * 2.0 * PI;
            let origin = centre + (a * phi.cos() + b * phi.sin()) * r + to_eye * (2.0 * radius);
            let Some((t, leaf)) = scene.hit(origin, -to_eye, u32::MAX) else {
                continue;
            };
            let l = leaf as usize;
            let Some(i) = stored(leaf).filter(|&i| i < envelopes.len()) else {
                continue;
            };
            // A card lets part of the eye's rays through: its texels weigh as much as they stop.
            let weight = opacity(leaf).clamp(0.0, 1.0);
            let x = origin - to_eye * t;
            let n = scene.normal(l);
            let e = &envelopes[i];
            let gain = gains.get(i).map_or(1.0, |g| seen_gain(g, to_eye));
            // The sun: the leaf's BSDF is a cosine on either side, the same in both sums.
            let cosine = n.dot(to_sun).abs();
            let through = lobe_blend(&e.attenuation, to_sun, 1.0);
            let share = sun_share.map_or(through, |share| share(i, to_sun, x));
            sun.push([
                weight * cosine,
                (share * gain).min(1.0),
                scene.transmittance(x, to_sun, leaf, opacity),
            ]);
            // The bounce: the neighbours' sunlight gathered at the point, against eq. 5.24
            // scaled by the leaf's gathered ratios (where baked) with the covered part's gain.
            if settings.bounce_rays == 0 {
                continue;
            }
            let traced = gather(
                scene,
                material,
                &light,
                l,
                to_eye,
                &trace,
                &mut rng,
                &mut |_| x,
            );
            let faces = faces(i, to_sun);
            let modelled = bounce_radiance_by_face(
                material,
                n,
                to_eye,
                &bounce,
                through,
                &e.s_max,
                Vec3::ONE,
                faces,
            ) * covered_gain(gain, open_share(n, &e.attenuation));
            sums[0] += weight as f64 * luminance(traced.bounce) as f64;
            sums[1] += weight as f64 * luminance(modelled) as f64;
        }
        (sun, sums)
    };
    let chunk = jobs.len().div_ceil(threads.max(1)).max(1);
    let results: Vec<((usize, u32), JobSums)> = std::thread::scope(|s| {
        let handles: Vec<_> = jobs
            .chunks(chunk)
            .map(|part| s.spawn(move || part.iter().map(|j| (*j, work(j))).collect::<Vec<_>>()))
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("hotspot thread"))
            .collect()
    });
    let mut sun: Vec<Vec<[f32; 3]>> = vec![Vec::new(); HOTSPOT_NODES];
    let mut bounce = [[0.0f64; 2]; HOTSPOT_NODES];
    for ((k, _), (samples, sums)) in results {
        sun[k].extend(samples);
        bounce[k][0] += sums[0];
        bounce[k][1] += sums[1];
    }
    Hotspot {
        sun: std::array::from_fn(|k| sun_exponent(&sun[k])),
        bounce: std::array::from_fn(|k| {
            let [traced, model] = bounce[k];
            if model > 0.0 && traced > 0.0 {
                ((traced / model) as f32).clamp(HOTSPOT_RANGE.0, HOTSPOT_RANGE.1)
            } else {
                1.0
            }
        }),
    }
}

/// The exponent k for which the model's shares raised to it, `t^k`, add up to the traced
/// shares over `samples` (weight, t, traced), by bisection (the sum falls as k grows, every
/// t being at most 1); 1 where nothing was lit or seen.
fn sun_exponent(samples: &[[f32; 3]]) -> f32 {
    let traced: f64 = samples.iter().map(|s| (s[0] * s[2]) as f64).sum();
    let model = |k: f32| -> f64 {
        samples
            .iter()
            .map(|s| (s[0] * s[1].clamp(0.0, 1.0).powf(k)) as f64)
            .sum()
    };
    let (mut lo, mut hi) = HOTSPOT_RANGE;
    // Nothing seen lit, or no share the exponent could change (every share 0 or 1).
    if traced <= 0.0 || model(1.0) <= 0.0 || model(lo) - model(hi) <= 1e-6 * model(1.0) {
        return 1.0;
    }
    if model(lo) <= traced {
        return lo;
    }
    if model(hi) >= traced {
        return hi;
    }
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if model(mid) > traced {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::bins::proxies;
    use crate::lighting::path_trace::{push_square_leaf, uniform_ball};
    use crate::lighting::traced_bins::crown_envelope_traced;
    use crate::pruning::leaves::LeafSet;

    fn hotspot_of(leaves: &LeafSet, settings: &HotspotSettings) -> Hotspot {
        let scene = LeafScene::new(leaves);
        let order: Vec<u32> = (0..scene.leaf_count() as u32).collect();
        let envelope =
            crown_envelope_traced(&proxies(leaves), &scene, &order, &|_| 1.0, 32, 2, &|_| {});
        crown_hotspot(
            &scene,
            &envelope,
            &[],
            &[],
            &|l| Some(l as usize),
            &LeafMaterial::default(),
            &|_| 1.0,
            settings,
            2,
        )
    }

    #[test]
    fn the_nodes_are_interpolated_in_the_angle_and_packed_a_byte_each() {
        // Node k at α = k·π/7, value k + 1.
        let nodes: [f32; HOTSPOT_NODES] = std::array::from_fn(|k| (k + 1) as f32 * 0.25);
        let at = |alpha: f32| at_phase(&nodes, alpha.cos());
        assert!((at(0.0) - 0.25).abs() < 1e-6);
        assert!((at(PI) - 2.0).abs() < 1e-5);
        // Halfway between nodes 3 and 4 (α = π/2), and a quarter of the way from node 1 to 2.
        assert!((at(0.5 * PI) - 1.125).abs() < 1e-4);
        assert!((at(1.25 * PI / 7.0) - 0.5625).abs() < 1e-4);
        let h = Hotspot {
            sun: std::array::from_fn(|k| 0.25 + 0.125 * k as f32),
            bounce: std::array::from_fn(|k| 3.5 - 0.375 * k as f32),
        };
        assert_eq!(Hotspot::unpacked(h.packed()), h);
        assert_eq!(h.sanitized(), (h, false));
        assert_eq!(Hotspot::default().packed(), [0x4040_4040; HOTSPOT_WORDS]);
        // Node 0 of the sun in the first word's low byte, node 0 of the bounce in the third's.
        assert_eq!(h.packed()[0] & 0xff, 16);
        assert_eq!(h.packed()[HOTSPOT_WORDS / 2] & 0xff, 224);
        // Out of range or not a number: clamped (NaN to 1) and reported.
        let mut bad = Hotspot::default();
        bad.sun[..3].copy_from_slice(&[f32::NAN, 0.0, 9.0]);
        let (fixed, was_bad) = bad.sanitized();
        assert!(was_bad);
        assert_eq!(fixed.sun[..4], [1.0, HOTSPOT_RANGE.0, HOTSPOT_RANGE.1, 1.0]);
        // The exponent leaves a share of 0 or 1 as it is.
        assert_eq!(h.sun_through(1.0, Vec3::Y, Vec3::Y), 1.0);
        assert_eq!(h.sun_through(0.0, Vec3::Y, Vec3::Y), 0.0);
        // The sun behind the eye (α = 0: node 0's exponent ¼) and facing it (α = π: 1.125).
        assert!((h.sun_through(0.25, Vec3::Y, Vec3::Y) - 0.25f32.powf(0.25)).abs() < 1e-6);
        assert!((h.sun_through(0.25, Vec3::Y, -Vec3::Y) - 0.25f32.powf(1.125)).abs() < 1e-6);
    }

    /// The pairs' directions: at the phase angle asked, and for suns at a height every sun at
    /// that height, its azimuths all round; over the sphere the suns at every height.
    #[test]
    fn the_pairs_suns_lie_where_they_are_asked_for() {
        let mut rng = SplitMix64::new(17);
        let (mut low, mut high) = (0, 0);
        let mut quadrants = [0u32; 4];
        for i in 0..400 {
            let alpha = i as f32 / 400.0 * PI;
            let (eye, sun) = pair_directions(HotspotSuns::Height(0.3), alpha, &mut rng);
            assert!((sun.length() - 1.0).abs() < 1e-5 && (eye.length() - 1.0).abs() < 1e-5);
            assert!((sun.y - 0.3).abs() < 1e-6, "{sun}");
            assert!((eye.dot(sun).clamp(-1.0, 1.0).acos() - alpha).abs() < 2e-3);
            quadrants[(sun.x > 0.0) as usize * 2 + (sun.z > 0.0) as usize] += 1;
            let (eye, sun) = pair_directions(HotspotSuns::Sphere, alpha, &mut rng);
            assert!((eye.dot(sun).clamp(-1.0, 1.0).acos() - alpha).abs() < 2e-3);
            low += (sun.y < -0.5) as u32;
            high += (sun.y > 0.5) as u32;
        }
        assert!(quadrants.iter().all(|&q| q > 70), "{quadrants:?}");
        assert!(low > 70 && high > 70, "{low} {high}");
        // Straight up, and a height that is no number (the sphere's).
        let (_, sun) = pair_directions(HotspotSuns::Height(1.5), 1.0, &mut rng);
        assert!((sun - Vec3::Y).length() < 1e-6);
        let ys: Vec<f32> = (0..50)
            .map(|_| {
                pair_directions(HotspotSuns::Height(f32::NAN), 1.0, &mut rng)
                    .1
                    .y
            })
            .collect();
        assert!(ys.iter().any(|&y| y < -0.3) && ys.iter().any(|&y| y > 0.3));
    }

    /// A leaf with nothing around it: every share is 1 and nothing bounces, so there is
    /// nothing to correct.
    #[test]
    fn a_lone_leaf_has_no_hotspot() {
        let mut leaves = LeafSet::default();
        push_square_leaf(
            &mut leaves,
            Vec3::ZERO,
            0.5,
            Vec3::new(0.2, 1.0, 0.1).normalize(),
        );
        let h = hotspot_of(&leaves, &HotspotSettings::default());
        assert_eq!(h, Hotspot::default());
    }

    /// Kuusk's hotspot on the crown the model assumes: with the sun behind the eye, what the
    /// eye sees of a ball of leaves is lit more than the leaves' mean says (an exponent below
    /// 1), with the sun facing the eye less (above 1); in between the two are independent.
    /// The eye's and the sun's paths measured from unrelated points would find no hotspot.
    #[test]
    fn a_ball_of_leaves_has_a_hotspot_behind_the_eye() {
        let leaves = uniform_ball(1500, 1.5, 0.05, 5);
        let h = hotspot_of(
            &leaves,
            &HotspotSettings {
                pairs: 8,
                eye_rays: 200,
                bounce_rays: 8,
                ..HotspotSettings::default()
            },
        );
        eprintln!("{h:?}");
        assert!(h.sun[0] < 0.8, "{:?}", h.sun);
        let last = HOTSPOT_NODES - 1;
        assert!(h.sun[last] > 1.02, "{:?}", h.sun);
        assert!(h.sun[0] < h.sun[1] && h.sun[1] < h.sun[last], "{:?}", h.sun);
        // The bounce on the uniform crown is eq. 5.24's own case: within a tenth of the model.
        for b in h.bounce {
            assert!((b - 1.0).abs() < 0.12, "{:?}", h.bounce);
        }
    }
}
