//! The part of a leaf the eye sees is not the leaf's average: where other leaves cover it from
//! the eye they also shut out the sky, so what is left in view is the more open part. The model
//! of Boulanger 2008 (§5.2, §5.6) gives each leaf one set of bins for its whole area, the mean
//! over the leaf. Against the path tracer leaf by leaf, the four procedural trees' mean sky is
//! right within 2 %; in images of the same crowns (`tree_lighting_error --images`, what the eye
//! sees) it is 11–16 % dark, for that reason.
//!
//! Here, per leaf and per octant the eye may be in, the gain that turns the leaf's mean into
//! the mean over its seen part: `E[open(p) · V(p, e)] / (E[open(p)] · E[V(p, e)])`, with
//! `open(p)` the cosine-weighted share of the sphere open from point `p` (the sky's weighting,
//! both sides of the leaf) and `V(p, e)` the light let through from `p` towards an eye
//! direction `e` of the octant. Plain Rust, baked with the bins (`BakeSettings::seen_points`);
//! the leaf shaders blend a leaf's eight gains by the eye direction's cosine lobes, as they
//! blend the bins for the sun (eq. 5.7's weights; [`seen_gain`]), and scale the sky and the
//! blended sun by it; billboard clouds use the crown's mean gains ([`crown_mean_gains`]).
//!
//! The bounce comes from the other part of the sphere, the part the neighbours cover, and the
//! same rays give its gain: with `covered = 1 − open`, `E[covered·V] / (E[covered]·E[V]) =
//! (1 − g·Ō) / (1 − Ō)` for the sky's gain g and the leaf's mean openness Ō
//! ([`covered_gain`]; the shaders take Ō from the leaf's bins, [`super::model::open_share`]).
//! In the images of the four procedural trees the bounce's bias falls from +16.5…+23 % to
//! +11…+17.5 % with it (`tree_lighting_error --images`).
//!
//! The gain the sun takes here is the sky's, whatever the sun's direction; how the sun's share
//! of the part in view depends on where the sun is from the eye is the crown's hotspot
//! ([`super::hotspot`]), measured with these gains.
//!
//! What eight gains leave (`tree_lighting_error --images --eye X,Y,Z`, 32-ray bins, 16
//! points, pixels 1.4–2.5 leaves wide, five eyes from 17° below the horizon to 55° above):
//! the sky's error is 4.4–5.3 % on the olive, 4.6–5.3 % on the ash, 4.5–5.9 % on the oak and
//! 3.2–4.0 % on the cedar, the crown's bias −4.3…+1.6 %. The gain is sharply directional:
//! traced for the eye's own direction from as many points ([`seen_part_gain_along`]) the
//! bias is −2.5…+1.1 % (within 1.2 % for 15 of the 20 tree and eye pairs, against 4 with the
//! eight gains; the error 2.5–5.4 %, the rest mostly the 16 points' noise), and the open
//! share at the eye ray's own point over the leaf's mean ([`open_share_at`]) gives 1.5–3.2 %:
//! what no value per leaf and eye direction beats. Another seed of the points and rays moves
//! one tree's figure by up to ±0.8 points (`--seen-seed S`). Blending the eight more sharply
//! (the lobes' cosine to the 4th power) helps where the eye sits between octants and costs as
//! much elsewhere (each tree's mean over the five eyes moved by −0.4…+0.3 points, measured
//! with uniform open rays), so eq. 5.7's lobes stay.
//!
//! Most of what is left is where on the leaf the eye looks, which a map of the leaf's open
//! share says wherever the eye is ([`super::open_map`]: cells over the leaf's square, what the
//! map leaves for the eye's direction in eight residual gains; `tree_lighting_error --images
//! --open-maps CxP[r]`). A bake stores it and the leaf shaders draw the sky with it in place of
//! the eight gains (the blended sun and the bounce keep them); measured (32-ray bins, pixels 1.4–2.5
//! leaves wide, the sky's error summed over the four trees): 3 × 3 cells over the square a leaf
//! shader can find ([`super::open_map::MapFrame::of_leaf`]) from 32 points a leaf, times its
//! residual gains, 15.2 points on average over four seeds at eye (0, 0.3, 1) (14.5–16.5), where
//! the eight gains alone from the same 32 points give 18.0 (17.4–18.4) and from a bake's 16
//! points 19.5; every tree 2.8–4.7 %; over the five eyes (seed 0) the olive 3.4–4.6 %, the ash
//! 3.1–3.8, the oak 3.3–3.8, the cedar 1.6–3.1 (the eight gains from 32 points: 4.5–5.5,
//! 4.4–5.4, 3.9–5.0, 2.1–3.7); stored as a bake would store it, within 0.1 point at eye (0,
//! 0.3, 1). At 16 points the map gains little (18.0–18.8), 4 × 4 cells no more than 3 × 3, and
//! the map alone, without its residual gains, leaves the bias at −3…−5.6 %; a plane of open
//! share fitted over each leaf by least squares was worse than the eight gains (sum 21.8).

use super::bins::DIRECTIONS;
use super::leaf_scene::{LeafScene, uniform_direction};
use super::model::lobe_blend;
use crate::rng::SplitMix64;
use bevy::math::Vec3;

/// Points spread on the leaf for its gains in a bake made while an app runs (16 points cost a
/// leaf as many rays as the traced bins' 32 a bin). `tree_lighting_error --images` with 32-ray
/// bins: on the four procedural trees the sky's image error at pixels 1.4–2.5 leaves wide falls
/// from 11–16 % to 4.0–5.3 % (eye (0, 0.3, 1); 3.3–6.5 % before the open rays were stratified,
/// [`open_share_at`]), its bias from −11…−16 % to −2.4…−4.2 %.
pub const DEFAULT_SEEN_POINTS: u32 = 16;

/// Points per leaf in a bake made once and kept on disk (`foliage_bake`): with its 128-ray
/// bins, 2.7–5.2 % there (bias −1.7…−3.6 %; 2.8–5.8 % with uniform open rays).
pub const OFFLINE_SEEN_POINTS: u32 = 32;

/// The most points per leaf a bake accepts.
pub const MAX_SEEN_POINTS: u32 = 4096;

/// Directions sampled from each point for its open share, one per octant ([`open_share_at`];
/// besides one eye ray per octant).
pub const OPEN_RAYS_PER_POINT: u32 = 8;

/// Bounds of a gain: a leaf seen from an octant only through a sliver gets a noisy ratio.
pub const GAIN_RANGE: (f32, f32) = (0.25, 4.0);

/// The eight gains of leaf `leaf` of `scene` (indexed as [`DIRECTIONS`]: the octant of the eye
/// direction), from `points` points spread on the leaf, each tracing
/// eight directions for its open share and one eye direction per octant;
/// `opacity(l)` the share of leaf `l`'s area that stops light. An octant from which no point
/// is seen gets 1 (the leaf is never drawn from there).
///
/// `below` weighs the directions below the horizon (model space, −y) in each point's open
/// share against those above: 1 is the uniform sphere every bake uses, the bounce's
/// [`covered_gain`] identity holding only then; the ground's radiance over the sky's (about
/// 0.2) weighs the open share as eq. 5.6's sky does. Measured on the four procedural trees
/// (`tree_lighting_error --images --seen-below W`, W = 1 and 0.2, pixels 1.4–2.5 leaves wide): at 0.2 the
/// sky's bias falls by 0.3–1.3 points (−2.3…−3.4 % to −1.0…−2.6 % with 128-ray bins and 32
/// points, its error 2.8–5.8 % to 2.7–5.4 %), but with 32-ray bins and 16 points the error
/// moves by −0.1 to +0.3 points and the bounce's by up to +0.5, so bakes keep 1 (measured with
/// uniform open rays, before [`open_share_at`] stratified them).
pub fn seen_part_gains(
    scene: &LeafScene,
    leaf: usize,
    points: u32,
    below: f32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
) -> [f32; 8] {
    // One eye direction per point in each octant.
    seen_part_gains_towards(
        scene,
        leaf,
        points,
        below,
        opacity,
        seed,
        direction_in_octant,
    )
}

/// A direction uniform in octant `j` of [`DIRECTIONS`] (a zero component takes the octant's
/// sign).
pub fn direction_in_octant(j: usize, rng: &mut SplitMix64) -> Vec3 {
    uniform_direction(rng).abs() * DIRECTIONS[j % DIRECTIONS.len()].signum()
}

/// The gain of [`seen_part_gains`] (the uniform sphere's open share) for the one eye
/// direction `to_eye` rather than an octant of them, from `points` points: what no blend of the
/// eight beats at as many points. A measurement (`tree_lighting_error --images`): the gains
/// are sharply directional, and blended from octants whose middles lie 30–55° from an eye
/// near the horizon they come out low.
pub fn seen_part_gain_along(
    scene: &LeafScene,
    leaf: usize,
    points: u32,
    to_eye: Vec3,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
) -> f32 {
    let e = to_eye.normalize_or(Vec3::Z);
    let [gain] = seen_part_gains_towards(scene, leaf, points, 1.0, opacity, seed, |_, _| e);
    gain
}

/// The estimator both gains share, for `N` eye directions: from each of `points` points on
/// the leaf, its open share ([`open_share_at`], [`OPEN_RAYS_PER_POINT`] rays) and the light
/// let through towards `eye(k, rng)` for each k < N; gain k is `Σ open·V_k / Σ V_k` over the
/// points' mean open share, within [`GAIN_RANGE`], and 1 where no point is seen from
/// direction k or nothing is open.
fn seen_part_gains_towards<const N: usize>(
    scene: &LeafScene,
    leaf: usize,
    points: u32,
    below: f32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
    mut eye: impl FnMut(usize, &mut SplitMix64) -> Vec3,
) -> [f32; N] {
    if leaf >= scene.leaf_count() || scene.triangle_count(leaf) == 0 {
        return [1.0; N];
    }
    let mut rng = SplitMix64::new(seed);
    let id = leaf as u32;
    let points = points.max(1);
    let mut open_sum = 0.0f32;
    let mut seen_open = [0.0f32; N];
    let mut seen = [0.0f32; N];
    for _ in 0..points {
        let p = scene.point_on(leaf, &mut rng);
        let open = open_share_at(
            scene,
            leaf,
            p,
            OPEN_RAYS_PER_POINT,
            below,
            opacity,
            &mut rng,
        );
        open_sum += open;
        for k in 0..N {
            let v = scene.transmittance(p, eye(k, &mut rng), id, opacity);
            seen_open[k] += open * v;
            seen[k] += v;
        }
    }
    let mean_open = open_sum / points as f32;
    std::array::from_fn(|k| {
        if seen[k] <= 0.0 || mean_open <= 0.0 {
            1.0
        } else {
            (seen_open[k] / seen[k] / mean_open).clamp(GAIN_RANGE.0, GAIN_RANGE.1)
        }
    })
}

/// The open share at point `p` of leaf `leaf` from `rays` directions: the light let through
/// the other leaves towards each, weighted by its cosine on either side of the leaf and, below
/// the horizon, by `below` (1: the uniform sphere, what [`super::model::open_share`] sums from
/// the bins). 1 where no ray has weight.
///
/// The directions are stratified by octant, ray k uniform in octant `k mod 8`
/// ([`direction_in_octant`]): the octants have equal solid angles, so the estimate stays
/// unbiased, and a point under a roof always gets as many rays up as down where uniform rays
/// would split them at random (8 rays: spread 0.10 against 0.2). Measured on the gains
/// (`tree_lighting_error --images --rays-per-bin 32 --seen-points 16 --seen-seed S`, pixels
/// 1.4–2.5 leaves wide): the sky's image error summed over the four procedural trees falls
/// from 20.8 to 19.5 points on average over four seeds at eye (0, 0.3, 1), in every seed, and
/// from 18.0 to 17.9 over three at (1, 0.3, 1), one seed 1.2 points worse; each tree's mean
/// over the seeds moves by −0.6…+0.2 points, where one tree's figure spreads by up to ±0.8
/// between seeds. The gain for the eye's own direction, one ratio from 16 points, gains more:
/// at eye (0, 0.3, 1) 5.2 / 5.1 / 4.2 / 3.9 % → 4.2 / 4.4 / 4.7 / 3.0 %.
pub fn open_share_at(
    scene: &LeafScene,
    leaf: usize,
    p: Vec3,
    rays: u32,
    below: f32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    rng: &mut SplitMix64,
) -> f32 {
    let n = scene.normal(leaf);
    let (mut lit, mut weight) = (0.0f32, 0.0f32);
    for k in 0..rays {
        let w = direction_in_octant(k as usize % 8, rng);
        let cosine = n.dot(w).abs() * if w.y < 0.0 { below } else { 1.0 };
        lit += cosine * scene.transmittance(p, w, leaf as u32, opacity);
        weight += cosine;
    }
    if weight > 0.0 { lit / weight } else { 1.0 }
}

/// [`seen_part_gains`] of each of `leaves` (indices into `scene`), on up to `threads` threads.
/// `seed` picks the points and rays (bakes use 0; another shows the gains' own noise, as
/// `tree_lighting_error --seen-seed` does).
pub fn seen_part_gains_of(
    scene: &LeafScene,
    leaves: &[u32],
    points: u32,
    below: f32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
    threads: usize,
) -> Vec<[f32; 8]> {
    let base = 0x5EE1_u64 ^ seed.wrapping_mul(0xD1B5_4A32_D192_ED03);
    let chunk = leaves.len().div_ceil(threads.max(1)).max(1);
    std::thread::scope(|s| {
        let handles: Vec<_> = leaves
            .chunks(chunk)
            .map(|part| {
                s.spawn(move || {
                    part.iter()
                        .map(|&leaf| {
                            let seed = base ^ scene.leaf_key(leaf as usize);
                            seen_part_gains(scene, leaf as usize, points, below, opacity, seed)
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("seen-part thread"))
            .collect()
    })
}

/// The crown's mean of its leaves' gains, octant by octant (1 for a crown without leaves).
pub fn crown_mean_gains(gains: &[[f32; 8]]) -> [f32; 8] {
    if gains.is_empty() {
        return [1.0; 8];
    }
    std::array::from_fn(|j| gains.iter().map(|g| g[j]).sum::<f32>() / gains.len() as f32)
}

/// A gain as a bake stores it: `u16` over [0, [`GAIN_RANGE`]`.1`] (65,535 = the largest).
pub fn quantize_gain(gain: f32) -> u16 {
    let g = if gain.is_finite() { gain } else { 1.0 };
    (g.clamp(0.0, GAIN_RANGE.1) / GAIN_RANGE.1 * 65_535.0).round() as u16
}

/// The gain a stored `u16` holds ([`quantize_gain`]'s inverse).
pub fn gain_of(q: u16) -> f32 {
    q as f32 / 65_535.0 * GAIN_RANGE.1
}

/// The gain for an eye along `to_eye`: the eight gains blended by the cosine lobes of eq. 5.7
/// (continuous as the eye moves).
pub fn seen_gain(gains: &[f32; 8], to_eye: Vec3) -> f32 {
    lobe_blend(gains, to_eye, 1.0)
}

/// The gain of the covered part of the sphere (the bounce's) over the part of a leaf in view,
/// for the sky's gain `gain` ([`seen_gain`]) and the leaf's mean open share `open`
/// ([`super::model::open_share`]): `(1 − gain·open) / (1 − open)`, the module docs' identity,
/// within `[0, GAIN_RANGE.1]`; 1 for a leaf with nothing around it (no bounce to scale).
pub fn covered_gain(gain: f32, open: f32) -> f32 {
    if !(gain.is_finite() && open.is_finite()) || open >= 1.0 - 1e-4 {
        return 1.0;
    }
    let open = open.max(0.0);
    ((1.0 - gain * open) / (1.0 - open)).clamp(0.0, GAIN_RANGE.1)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::lighting::path_trace::push_square_leaf;
    use crate::pruning::leaves::LeafSet;

    #[test]
    fn a_lone_leaf_is_seen_whole() {
        let mut leaves = LeafSet::default();
        push_square_leaf(
            &mut leaves,
            Vec3::ZERO,
            0.1,
            Vec3::new(0.3, 1.0, 0.2).normalize(),
        );
        let scene = LeafScene::new(&leaves);
        for g in seen_part_gains(&scene, 0, 16, 1.0, &|_| 1.0, 7) {
            assert!((g - 1.0).abs() < 1e-6, "{g}");
        }
        assert!((seen_gain(&[1.0; 8], Vec3::new(0.2, 0.9, -0.4).normalize()) - 1.0).abs() < 1e-6);
    }

    /// Leaf 0: side 1 at the origin, facing up; leaf 1, its roof: side 1.2 centred over
    /// x = −0.6, just above, covering x < 0 (and a margin).
    pub(crate) fn leaf_under_a_roof() -> LeafSet {
        let mut leaves = LeafSet::default();
        push_square_leaf(&mut leaves, Vec3::ZERO, 0.5, Vec3::Y);
        push_square_leaf(&mut leaves, Vec3::new(-0.6, 0.02, 0.0), 0.6, Vec3::Y);
        leaves
    }

    /// A leaf facing up with a roof low over its −x half: from above only the +x half shows,
    /// and it is the open one, so the gains of the four upper octants are well above 1; from
    /// below the whole leaf shows, and the gains of the lower four are 1.
    #[test]
    fn the_part_seen_past_a_roof_is_the_open_part() {
        let scene = LeafScene::new(&leaf_under_a_roof());
        let gains = seen_part_gains(&scene, 0, 512, 1.0, &|_| 1.0, 3);
        for (j, d) in DIRECTIONS.iter().enumerate() {
            if d.y > 0.0 {
                assert!(gains[j] > 1.15, "octant {j}: {gains:?}");
            } else {
                assert!((gains[j] - 1.0).abs() < 0.05, "octant {j}: {gains:?}");
            }
        }
        // The eye straight above: the upper octants' gain.
        assert!(seen_gain(&gains, Vec3::Y) > 1.15);
    }

    #[test]
    fn a_gain_along_one_direction_is_that_directions_seen_part() {
        // The roof of the test above: from straight above only the open half (x > 0) is in
        // view, from straight below all of the leaf.
        let scene = LeafScene::new(&leaf_under_a_roof());
        let above = seen_part_gain_along(&scene, 0, 512, Vec3::Y, &|_| 1.0, 3);
        let below = seen_part_gain_along(&scene, 0, 512, -Vec3::Y, &|_| 1.0, 3);
        // Open half ≈ 0.95, covered half 0.5 (its upper hemisphere shut): ≈ 0.95 / 0.73.
        assert!((1.2..1.45).contains(&above), "{above}");
        assert!((below - 1.0).abs() < 1e-4, "{below}");
        // A lone leaf is seen whole from everywhere.
        let mut lone = LeafSet::default();
        push_square_leaf(&mut lone, Vec3::ZERO, 0.1, Vec3::X);
        let lone = LeafScene::new(&lone);
        let g = seen_part_gain_along(&lone, 0, 16, Vec3::new(0.3, 0.2, 1.0), &|_| 1.0, 1);
        assert!((g - 1.0).abs() < 1e-6, "{g}");
    }

    #[test]
    fn a_points_open_share_counts_what_its_neighbours_leave_open() {
        let scene = LeafScene::new(&leaf_under_a_roof());
        let mut rng = SplitMix64::new(9);
        let under = Vec3::new(-0.25, 0.0, 0.0);
        let open = open_share_at(&scene, 0, under, 1024, 1.0, &|_| 1.0, &mut rng);
        // The upper hemisphere shut, the lower open: half of the cosine weight.
        assert!((open - 0.5).abs() < 0.05, "{open}");
        // Below the horizon not counted: nothing is open.
        let sky_only = open_share_at(&scene, 0, under, 1024, 0.0, &|_| 1.0, &mut rng);
        assert!(sky_only < 0.02, "{sky_only}");
        // A roof letting 60 % through.
        let thin = open_share_at(&scene, 0, under, 1024, 1.0, &|_| 0.4, &mut rng);
        assert!((thin - 0.8).abs() < 0.05, "{thin}");
        let clear = Vec3::new(0.2, 0.0, 0.0);
        let open = open_share_at(&scene, 0, clear, 1024, 1.0, &|_| 1.0, &mut rng);
        assert!(open > 0.85, "{open}");
    }

    /// Eight rays at a point under a roof: one per octant, so always four up (shut) and four
    /// down (open). The estimate's mean is the half it should be, and its spread between draws
    /// only the cosines' (about 0.10), where uniform rays splitting up and down at random
    /// spread about 0.2.
    #[test]
    fn a_points_open_rays_are_spread_over_the_octants() {
        let scene = LeafScene::new(&leaf_under_a_roof());
        let mut rng = SplitMix64::new(21);
        let under = Vec3::new(-0.25, 0.0, 0.0);
        let draws: Vec<f32> = (0..400)
            .map(|_| open_share_at(&scene, 0, under, 8, 1.0, &|_| 1.0, &mut rng))
            .collect();
        let mean = draws.iter().sum::<f32>() / draws.len() as f32;
        let spread =
            (draws.iter().map(|o| (o - mean).powi(2)).sum::<f32>() / draws.len() as f32).sqrt();
        assert!((mean - 0.5).abs() < 0.02, "{mean}");
        assert!((0.07..0.13).contains(&spread), "{spread}");
        for (j, octant) in DIRECTIONS.iter().enumerate() {
            let d = direction_in_octant(j, &mut rng);
            assert_eq!(d.signum(), octant.signum(), "octant {j}: {d}");
            assert!((d.length() - 1.0).abs() < 1e-5);
        }
    }

    /// The covered part's gain is the ratio it stands for, from the sky's gain and the mean
    /// openness alone: on any set of points' openness and visibility towards the eye,
    /// `E[(1 − o)·V] / (E[1 − o]·E[V])`.
    #[test]
    fn the_covered_parts_gain_is_the_complement_of_the_open_parts() {
        let mut rng = SplitMix64::new(11);
        for _ in 0..200 {
            let count = 1 + (rng.next_f32() * 40.0) as usize;
            let points: Vec<(f32, f32)> = (0..count)
                .map(|_| (0.95 * rng.next_f32(), rng.next_f32()))
                .collect();
            let mean =
                |f: &dyn Fn(&(f32, f32)) -> f32| points.iter().map(f).sum::<f32>() / count as f32;
            let (open, seen) = (mean(&|p| p.0), mean(&|p| p.1));
            if seen < 1e-3 {
                continue;
            }
            let gain = mean(&|p| p.0 * p.1) / (open * seen);
            let want = mean(&|p| (1.0 - p.0) * p.1) / ((1.0 - open) * seen);
            let got = covered_gain(gain, open);
            assert!(
                (got - want.clamp(0.0, GAIN_RANGE.1)).abs() < 1e-3 * want.max(1.0),
                "{got} against {want}"
            );
        }
        // Nothing around the leaf: no bounce to scale; a seen part no more open than the rest:
        // no change; bad input: no change.
        assert_eq!(covered_gain(1.7, 1.0), 1.0);
        assert_eq!(covered_gain(1.0, 0.6), 1.0);
        assert_eq!(covered_gain(f32::NAN, 0.5), 1.0);
        // A seen part more open than the leaf is less covered.
        assert!(covered_gain(1.2, 0.5) < 0.85);
    }

    #[test]
    fn stored_gains_round_trip_and_the_shaders_agree_on_the_range() {
        for g in [0.25f32, 0.9, 1.0, 1.37, 4.0] {
            assert!((gain_of(quantize_gain(g)) - g).abs() < 1e-4, "{g}");
        }
        assert_eq!(
            gain_of(quantize_gain(f32::NAN)),
            gain_of(quantize_gain(1.0))
        );
        assert_eq!(quantize_gain(9.0), u16::MAX);
        let wgsl = include_str!("../pruning/leaf_pulling.wgsl");
        assert!(
            wgsl.contains(&format!("const SEEN_GAIN_MAX: f32 = {:?};", GAIN_RANGE.1)),
            "leaf_pulling.wgsl's SEEN_GAIN_MAX is not {}",
            GAIN_RANGE.1
        );
        let wgsl = include_str!("../pruning/tree_lighting.wgsl");
        assert!(
            wgsl.contains(&format!(
                "const COVERED_GAIN_MAX: f32 = {:?};",
                GAIN_RANGE.1
            )),
            "tree_lighting.wgsl's COVERED_GAIN_MAX is not {}",
            GAIN_RANGE.1
        );
    }
}
