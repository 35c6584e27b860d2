//! The sun's light on each leaf from maps rendered from the sun, as plain Rust: a crown's
//! light-space foliage maps (Gumbau 2011, §5.2: the nearest and farthest leaf depths and the leaf
//! count per texel, self-shadowing by eq. 5.3), a plain shadow map read with a 3×3 filter as
//! Bevy reads its own, and the crown's extinction applied to the depth of leaves in front
//! (Beer–Lambert over the shadow map) — each measured leaf by leaf against the path tracer's
//! shadow rays ([`sun_visibility_against_tracer`]), beside the eight baked attenuations' blend
//! the tree lighting uses ([`super::model::sun_through_crown`]). What the leaf-on-leaf shadows of
//! the leaf shaders read, and up to which texel size, is chosen from this measurement and from
//! the images of [`super::image_error`]: the four texels around the point, each compared with
//! the depth the leaf's own plane has at that texel's centre
//! ([`FoliageMaps::shadow_map_receiver_plane`], [`LeafShadowPlane::SHADERS`]), trusted fully at
//! texels up to [`LEAF_SHADOW_FINE`] of the leaf's size and not at all from
//! [`LEAF_SHADOW_COARSE`] ([`shadow_map_trust`]).

use super::envelope::{crown_envelope, proxies};
use super::model::{SunThroughCrown, sun_through_crown};
use super::path_trace::LeafScene;
use crate::pruning::leaves::LeafSet;
use crate::pruning::visibility::rasterize_triangle;
use crate::rng::SplitMix64;
#[cfg(test)]
use bevy::math::Quat;
use bevy::math::{Vec2, Vec3};

/// A slope-scaled depth bias: the point of a leaf moved towards the sun by
/// `texels + slope · min(tan θ, max_slope)` texels of the map before one bilinear comparison, θ
/// the leaf's tilt from the sun. What the leaf shaders read the map with before
/// [`LeafShadowPlane`]; kept to measure against it (`tree_lighting_error --leaf-shadow-offset`).
///
/// A shadow map cannot tell a leaf from its neighbour: too small an offset and a leaf tilted to
/// the sun shades itself across the lookup's texels (its own depth changes by a texel times
/// tan θ: stripes of shadow acne); too large and the leaf just in front of it lets the sun
/// through. The offset is in texels, so it grows with them: at texels a quarter of a leaf it
/// lets enough leaves through to brighten the sun on the crown by 13–24 %
/// ([`LeafShadowPlane::SHADERS`]'s table).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafShadowOffset {
    /// The offset of a leaf facing the sun, in texels.
    pub texels: f32,
    /// Texels more per unit of tan θ.
    pub slope: f32,
    /// The steepest tilt (its tangent) the slope term follows: leaves seen edge-on by the sun
    /// would otherwise let everything in front of them through.
    pub max_slope: f32,
}

impl LeafShadowOffset {
    /// The best of the offsets measured: a texel, half a texel more per unit of tan θ up to
    /// tan θ = 4.
    ///
    /// Leaf by leaf against the tracer's shadow rays (`tree_lighting_error --sun-maps
    /// --leaf-shadow-offset T,S`, the four procedural trees at 2,000 leaves, one bilinear
    /// lookup, texels 1/16 of a leaf): a constant 0.5 texel is 20–25 % off, 1 texel 20–22 %,
    /// 1.5 texels 20–25 %, 2 texels 22–30 %; 1 texel with slopes 0.25 and 0.5 is 21–23 % and
    /// 20–31 %; a 3×3 filter with a texel's offset is 24–30 % off (it blurs the crown's
    /// sunflecks into their shade). The constant texel is the most accurate on average but
    /// shows acne on Bevy's shadow map: in the render test of a crown under cascades of texels
    /// under a sixteenth of a leaf, 80 of 1,090 leaf pixels differ from shadow rays cast from
    /// the moved points by more than 3/255 (worst 11.7/255, in stripes across steep leaves);
    /// with the slope term 0.25 it is 37 of 1,097 (worst 6.7), with 0.5, 33 of 1,097 (worst
    /// 4.4).
    pub const SLOPE_SCALED: Self = Self {
        texels: 1.0,
        slope: 0.5,
        max_slope: 4.0,
    };

    /// The offset, in texels, for a leaf with normal `n` (either side) under the sun towards
    /// `to_sun` (unit).
    pub fn texels_for(&self, n: Vec3, to_sun: Vec3) -> f32 {
        let c = n.normalize_or_zero().dot(to_sun).abs().max(1e-3);
        let tan = (1.0 - c * c).max(0.0).sqrt() / c;
        self.texels + self.slope * tan.min(self.max_slope)
    }
}

impl Default for LeafShadowOffset {
    fn default() -> Self {
        Self::SLOPE_SCALED
    }
}

/// A receiver-plane depth comparison: each of the four texels a bilinear lookup blends is
/// compared with the depth the leaf's own plane has at that texel's centre, not with the
/// point's depth, so a leaf's own texels never shade it however tilted it is and however large
/// the texels, and nothing in front of it is let through.
///
/// A leaf is flat and its normal is known, so the depth of its plane across the map is exact:
/// `∂w/∂u = (n·u)/(n·l)`, `∂w/∂v = (n·v)/(n·l)` (w the depth away from the sun along `l`, u and
/// v the map's axes). No offset has to grow with the texel, which is why the map can be read at
/// the leaf deep into coarser cascades than a slope-scaled bias allows ([`LeafShadowOffset`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafShadowPlane {
    /// How far, in texels, a texel's nearest leaf may lie in front of the leaf's plane and still
    /// count as the leaf itself: the map's depth precision and the plane's at the leaf's edges.
    pub slack_texels: f32,
    /// The steepest depth gradient (tan θ, θ the leaf's tilt from the sun) the plane follows:
    /// a leaf seen edge-on by the sun would otherwise reach far in front of itself.
    pub max_slope: f32,
}

impl LeafShadowPlane {
    /// The leaf shaders' (`leaf_volume_fragment.wgsl`): a tenth of a texel's slack, gradients up
    /// to 4.
    ///
    /// Image error of the sun term against the path tracer (`tree_lighting_error --images
    /// --rays-per-bin 32 --seen-points 16 --hotspot --sun 0,0.5,-1 --shadow-texel F`, the sun
    /// 137° from the eye, pixels 1.4–2.5 leaves wide, ball · olive · ash · oak · cedar; bias in
    /// brackets), against the slope-scaled offset the shaders read the map with before:
    ///
    /// | texel (of a leaf) | slope-scaled offset | receiver plane, 0.1 texel | 0.5 texel |
    /// |---|---|---|---|
    /// | 1/16 | 2.0 · 10.4 · 6.5 · 4.6 · 5.6 % (olive +8.4 %) | 2.5 · 4.7 · 5.5 · 3.7 · 4.7 % (−2.1…−0.4 %) | 2.1 · 6.5 · 4.4 · 3.0 · 4.2 % |
    /// | 1/4 | 5.3 · 24.9 · 25.6 · 18.8 · 25.4 % (+13…+24 %) | 4.4 · 8.0 · 10.2 · 7.9 · 9.8 % (−2.1…+3.3 %) | 4.3 · 10.9 · 13.6 · 10.5 · 12.1 % |
    /// | 1/2 | 7.9 · 57.5 · 53.9 · 34.3 · 56.0 % | 6.1 · 26.4 · 24.2 · 14.3 · 18.0 % (−0.5…+17.9 %) | |
    /// | 1 | 15.7 · 125.8 · 103.2 · 53.0 · 101.5 % | 10.9 · 70.4 · 42.6 · 21.7 · 25.6 % (+2.3…+65.9 %) | |
    ///
    /// where the eight baked attenuations' blend is 19.0 · 56.0 · 61.8 · 44.4 · 47.0 %. From
    /// half a leaf up the comparison lets the sun through too often (its point-sampled texels
    /// miss the leaves in front through the crown's gaps). Following the plane only as far as
    /// the leaf reaches (its depth clamped to ±½ diameter · sin θ) took a few points off at one
    /// leaf (olive +65.9 → +62.9 %) and none below half a leaf: not kept.
    pub const SHADERS: Self = Self {
        slack_texels: 0.1,
        max_slope: 4.0,
    };

    /// The depth gradient of a leaf's plane (normal `n`, either side) in `frame`: the change of
    /// its depth away from the sun per model unit along the map's u and v axes, its length
    /// capped at [`LeafShadowPlane::max_slope`].
    pub fn gradient(&self, n: Vec3, frame: &LightFrame) -> Vec2 {
        let n = n.normalize_or_zero();
        let nl = n.dot(frame.to_sun);
        // Edge-on to the sun: the steepest plane the cap allows, along the normal's side.
        let nl = if nl.abs() < 1e-4 {
            1e-4f32.copysign(nl)
        } else {
            nl
        };
        let g = Vec2::new(n.dot(frame.u), n.dot(frame.v)) / nl;
        let length = g.length();
        if length > self.max_slope && length.is_finite() {
            g * (self.max_slope / length)
        } else if length.is_finite() {
            g
        } else {
            Vec2::ZERO
        }
    }
}

impl Default for LeafShadowPlane {
    fn default() -> Self {
        Self::SHADERS
    }
}

/// How a point of a leaf is compared with the shadow map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LeafShadowLookup {
    /// The leaf's own plane against each texel ([`FoliageMaps::shadow_map_receiver_plane`]).
    ReceiverPlane(LeafShadowPlane),
    /// The point moved towards the sun, one bilinear comparison
    /// ([`FoliageMaps::shadow_map_bilinear`]).
    Offset(LeafShadowOffset),
}

impl LeafShadowLookup {
    /// The leaf shaders' lookup.
    pub const SHADERS: Self = Self::ReceiverPlane(LeafShadowPlane::SHADERS);

    /// The sun's share `maps` give point `p` of a leaf with normal `n`.
    pub fn visible(&self, maps: &FoliageMaps, p: Vec3, n: Vec3) -> f32 {
        match self {
            Self::ReceiverPlane(plane) => maps.shadow_map_receiver_plane(p, n, *plane),
            Self::Offset(offset) => maps.shadow_map_bilinear(
                p,
                offset.texels_for(n, maps.frame.to_sun) * maps.frame.texel,
            ),
        }
    }

    /// What the lookup is, for tables.
    pub fn describe(&self) -> String {
        match self {
            Self::ReceiverPlane(plane) => format!(
                "receiver plane, {} texel slack, slopes to {}",
                plane.slack_texels, plane.max_slope
            ),
            Self::Offset(offset) => format!(
                "one bilinear lookup {} + {}·tan θ texels towards the sun",
                offset.texels, offset.slope
            ),
        }
    }
}

impl Default for LeafShadowLookup {
    fn default() -> Self {
        Self::SHADERS
    }
}

/// The texel side, as a share of the leaf's size, up to which the leaf shaders take the sun's
/// share at a leaf from the shadow map alone (read by [`LeafShadowLookup::SHADERS`]).
///
/// Chosen on the thesis' own measure, image error (`tree_lighting_error --images
/// --rays-per-bin 32 --seen-points 16 --hotspot --sun X,Y,Z --shadow-texel
/// 0.0625,0.125,0.25,0.5,0.625,0.75,0.875,1,1.5`, seven suns, the four procedural trees at
/// 2,000 leaves, pixels 1.4–2.5 leaves wide): the sun term's mean error over the mean light,
/// averaged over the trees and the suns (the range of the seven suns' means in brackets):
///
/// | texel (of a leaf) | 1/16 | 1/8 | 1/4 | 1/2 | 3/4 | 1 | 3/2 |
/// |---|---|---|---|---|---|---|---|
/// | the map at the leaf | 3.1 % (2.1–4.6) | 4.4 % (3.1–6.5) | 7.8 % (4.6–13.1) | 15.0 % (9.3–21.8) | 20.7 % (13.1–33.8) | 27.3 % (14.7–44.5) | 34.8 % (19.3–69.2) |
///
/// where the eight baked attenuations' blend, with the crown's hotspot, is 30.2 % (8.9–56.5).
/// Up to half a leaf the map beats the blend at six of the seven suns, by half on average;
/// with the sun behind the eye (α = 4°), where the blend is at its best (8.9 %), the map wins
/// only up to an eighth of a leaf (its texels' nearest leaf is ever more often a neighbour in
/// front of the leaf seen: too dark, −15 % at a quarter of a leaf). Leaf by leaf (`--sun-maps`,
/// mean relative error per leaf, which weighs dim leaves as much as bright ones) the map is
/// 18–20 % off at 1/16 of a leaf, 23–29 % at 1/8, 38–45 % at 1/4, 58–76 % at 1/2 and 73–92 % at
/// one leaf, the blend 47–57 %. (The leaf's size is its length in these tables and its
/// diameter in the shaders, about 1.1 times longer.)
pub const LEAF_SHADOW_FINE: f32 = 0.5;

/// The texel side, as a share of the leaf's size, from which the leaf shaders no longer read
/// the shadow map at the leaf (the baked blend alone, under the map read where the sun's light
/// enters the crown): where the map, read as the shaders read it, is about as far off as the
/// blend ([`LEAF_SHADOW_FINE`]'s table: 27.3 % against 30.2 % at one leaf, 34.8 % at one and a
/// half). Between the two sizes the two are blended smoothly ([`shadow_map_trust`]); as drawn
/// there the sun is 16.1 %, 21.4 % and 27.1 % off at 5/8, 3/4 and 7/8 of a leaf.
pub const LEAF_SHADOW_COARSE: f32 = 1.0;

/// How far the leaf shaders trust the shadow map read at the leaf under texels `texel_share`
/// of the leaf's size: 1 up to [`LEAF_SHADOW_FINE`], 0 from [`LEAF_SHADOW_COARSE`], WGSL's
/// `smoothstep` between (`leaf_volume_fragment.wgsl`'s `SunShadow::trust`); the baked blend
/// takes the rest.
pub fn shadow_map_trust(texel_share: f32) -> f32 {
    if texel_share.is_nan() {
        return 0.0;
    }
    let t = ((texel_share - LEAF_SHADOW_FINE) / (LEAF_SHADOW_COARSE - LEAF_SHADOW_FINE))
        .clamp(0.0, 1.0);
    1.0 - t * t * (3.0 - 2.0 * t)
}

/// An orthographic frame looking down the sun's light over a crown.
#[derive(Clone, Copy, Debug)]
pub struct LightFrame {
    /// Unit direction towards the sun.
    pub to_sun: Vec3,
    u: Vec3,
    v: Vec3,
    /// The (u, v) of texel (0, 0)'s corner.
    origin: Vec2,
    /// Texel side, in model units.
    pub texel: f32,
    /// Texels a side.
    pub size: u32,
}

impl LightFrame {
    /// The frame over every vertex of `leaves` for the sun towards `to_sun`, with texels of side
    /// `texel` (at most 4096 a side: coarser if the crown needs more).
    pub fn around(leaves: &LeafSet, to_sun: Vec3, texel: f32) -> Self {
        let to_sun = to_sun.normalize();
        let u = to_sun.any_orthonormal_vector();
        let v = to_sun.cross(u);
        let (mut min, mut max) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
        for p in &leaves.positions {
            let q = Vec2::new(p.dot(u), p.dot(v));
            min = min.min(q);
            max = max.max(q);
        }
        if !min.is_finite() {
            (min, max) = (Vec2::ZERO, Vec2::ONE);
        }
        let extent = (max - min).max_element().max(1e-6);
        let texel = texel.max(extent / 4000.0);
        let size = ((extent / texel).ceil() as u32 + 4).min(4096);
        Self {
            to_sun,
            u,
            v,
            origin: min - Vec2::splat(2.0 * texel),
            texel,
            size,
        }
    }

    /// Point `p` in texel coordinates and its depth away from the sun (larger: farther).
    pub fn project(&self, p: Vec3) -> (Vec2, f32) {
        (
            (Vec2::new(p.dot(self.u), p.dot(self.v)) - self.origin) / self.texel,
            -p.dot(self.to_sun),
        )
    }
}

/// A crown's light-space maps: per texel the nearest and farthest leaf depths and how many leaf
/// triangles cover the texel's centre.
#[derive(Clone, Debug)]
pub struct FoliageMaps {
    /// The frame the maps are rendered in.
    pub frame: LightFrame,
    /// Nearest depth (`+∞` where no leaf): a plain shadow map.
    pub near: Vec<f32>,
    /// Farthest depth (`−∞` where no leaf).
    pub far: Vec<f32>,
    /// Leaf triangles covering the texel.
    pub count: Vec<u32>,
}

/// Renders the maps of `leaves` in `frame`.
pub fn foliage_maps(leaves: &LeafSet, frame: LightFrame) -> FoliageMaps {
    let n = (frame.size * frame.size) as usize;
    let mut maps = FoliageMaps {
        frame,
        near: vec![f32::INFINITY; n],
        far: vec![f32::NEG_INFINITY; n],
        count: vec![0; n],
    };
    for t in leaves.indices.chunks_exact(3) {
        let tri = [0, 1, 2].map(|k| frame.project(leaves.positions[t[k] as usize]));
        rasterize_triangle(tri, frame.size, |x, y, z, _| {
            let i = (y * frame.size + x) as usize;
            maps.near[i] = maps.near[i].min(z);
            maps.far[i] = maps.far[i].max(z);
            maps.count[i] += 1;
        });
    }
    maps
}

impl FoliageMaps {
    fn texel_of(&self, q: Vec2) -> Option<usize> {
        let (x, y) = (q.x.floor(), q.y.floor());
        let s = self.frame.size as f32;
        (x >= 0.0 && y >= 0.0 && x < s && y < s)
            .then(|| (y as u32 * self.frame.size + x as u32) as usize)
    }

    /// A shadow map's answer at `p`: the share of the 3×3 texels around it whose nearest leaf is
    /// no nearer the sun than `p` less `bias` (model units).
    pub fn shadow_map(&self, p: Vec3, bias: f32) -> f32 {
        let (q, z) = self.frame.project(p);
        let mut lit = 0.0;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let ok = self
                    .texel_of(q + Vec2::new(dx as f32, dy as f32))
                    .is_none_or(|i| z <= self.near[i] + bias);
                lit += ok as u32 as f32;
            }
        }
        lit / 9.0
    }

    /// A shadow map read by a comparison sampler's bilinear lookup, what a GPU's filtered
    /// `textureSampleCompare` returns: the four texels whose centres surround `p`, each lit where
    /// its nearest leaf is no nearer the sun than `p` less `bias` (model units), weighted by
    /// `p`'s place between their centres.
    pub fn shadow_map_bilinear(&self, p: Vec3, bias: f32) -> f32 {
        let (q, z) = self.frame.project(p);
        let corner = q - Vec2::splat(0.5);
        let (base, f) = (corner.floor(), corner - corner.floor());
        [
            (Vec2::new(0.5, 0.5), (1.0 - f.x) * (1.0 - f.y)),
            (Vec2::new(1.5, 0.5), f.x * (1.0 - f.y)),
            (Vec2::new(0.5, 1.5), (1.0 - f.x) * f.y),
            (Vec2::new(1.5, 1.5), f.x * f.y),
        ]
        .into_iter()
        .filter(|&(at, _)| {
            self.texel_of(base + at)
                .is_none_or(|i| z <= self.near[i] + bias)
        })
        .map(|(_, w)| w)
        .sum()
    }

    /// A shadow map read by a receiver-plane comparison ([`LeafShadowPlane`]): the four texels
    /// whose centres surround `p` (a point of a leaf with normal `n`), each lit where its nearest
    /// leaf is no nearer the sun than the leaf's own plane at that centre less
    /// [`LeafShadowPlane::slack_texels`], weighted by `p`'s place between their centres as a
    /// bilinear lookup weights them.
    pub fn shadow_map_receiver_plane(&self, p: Vec3, n: Vec3, plane: LeafShadowPlane) -> f32 {
        let (q, z) = self.frame.project(p);
        let gradient = plane.gradient(n, &self.frame) * self.frame.texel;
        let slack = plane.slack_texels * self.frame.texel;
        let corner = q - Vec2::splat(0.5);
        let (base, f) = (corner.floor(), corner - corner.floor());
        [
            (Vec2::new(0.5, 0.5), (1.0 - f.x) * (1.0 - f.y)),
            (Vec2::new(1.5, 0.5), f.x * (1.0 - f.y)),
            (Vec2::new(0.5, 1.5), (1.0 - f.x) * f.y),
            (Vec2::new(1.5, 1.5), f.x * f.y),
        ]
        .into_iter()
        .filter(|&(at, _)| {
            let centre = base + at;
            let own = z + gradient.dot(centre - q);
            self.texel_of(centre)
                .is_none_or(|i| own <= self.near[i] + slack)
        })
        .map(|(_, w)| w)
        .sum()
    }

    /// Eq. 5.3's self-shadowing at `p`: `1 − (Z_x − Z_n)/(Z_f − Z_n)`, the leaf's place between
    /// the nearest and the farthest leaf along the sun, in `[0, 1]`. (The equation also
    /// multiplies by the leaf's opacity α and the texel's leaf count N_c; taken literally that
    /// brightens dense texels, so opaque leaves (α = 1) are measured with N_c as the map's gate
    /// only: a texel with no leaf lets the sun through.)
    pub fn relative_depth(&self, p: Vec3) -> f32 {
        let (q, z) = self.frame.project(p);
        let Some(i) = self.texel_of(q) else {
            return 1.0;
        };
        if self.count[i] == 0 {
            return 1.0;
        }
        let span = self.far[i] - self.near[i];
        if span <= 1e-9 {
            return 1.0;
        }
        1.0 - ((z - self.near[i]) / span).clamp(0.0, 1.0)
    }

    /// Beer–Lambert over the shadow map: `e^(−τ·(Z_x − Z_n))`, the crown's extinction applied to
    /// the depth of leaves in front of `p` (eq. 5.5's attenuation along the sun's own ray).
    pub fn extinction(&self, p: Vec3, tau: f32) -> f32 {
        let (q, z) = self.frame.project(p);
        match self.texel_of(q) {
            Some(i) if self.near[i].is_finite() => (-tau * (z - self.near[i]).max(0.0)).exp(),
            _ => 1.0,
        }
    }
}

/// One estimate of the sun on the leaves against the tracer's shadow rays.
#[derive(Clone, Debug, PartialEq)]
pub struct SunEstimateError {
    /// What was measured.
    pub method: String,
    /// Mean over the leaves of |estimate − traced| / traced, over the leaves the tracer finds at
    /// least a hundredth of the mean sunlit share.
    pub mean_relative: f32,
    /// Σ |estimate − traced| / Σ traced.
    pub mean_absolute: f32,
    /// |Σ estimate − Σ traced| / Σ traced: the crown's mean.
    pub of_the_mean: f32,
}

fn errors(method: String, estimate: &[f32], traced: &[f32]) -> SunEstimateError {
    let sum_t: f32 = traced.iter().sum();
    let sum_e: f32 = estimate.iter().sum();
    let floor = 0.01 * sum_t / traced.len().max(1) as f32;
    let (mut sum, mut n) = (0.0, 0);
    for (e, t) in estimate.iter().zip(traced) {
        if *t >= floor && *t > 0.0 {
            sum += (e - t).abs() / t;
            n += 1;
        }
    }
    let absolute: f32 = estimate
        .iter()
        .zip(traced)
        .map(|(e, t)| (e - t).abs())
        .sum();
    SunEstimateError {
        method,
        mean_relative: if n > 0 { sum / n as f32 } else { 0.0 },
        mean_absolute: if sum_t > 0.0 { absolute / sum_t } else { 0.0 },
        of_the_mean: if sum_t > 0.0 {
            (sum_e - sum_t).abs() / sum_t
        } else {
            0.0
        },
    }
}

/// The share of every `stride`-th leaf of `leaves` the sun (towards `to_sun`) reaches, by the
/// tracer's shadow rays from `points` points spread on the leaf, against: the eight baked
/// attenuations' blend; at each texel side of `texels`, a shadow map read as the leaf shaders
/// read it (`lookup`: the shaders' [`LeafShadowLookup::SHADERS`]), read with a 3×3 filter (its depth bias a texel, at most half
/// of `leaf_size`: a leaf's own depth across a texel, without letting the leaves behind it
/// through) and the crown's extinction over its depth; eq. 5.3 on foliage maps with texels of
/// `foliage_texel`. Every estimate averages the same points on the leaf.
#[allow(clippy::too_many_arguments)]
pub fn sun_visibility_against_tracer(
    leaves: &LeafSet,
    to_sun: Vec3,
    stride: usize,
    points: u32,
    texels: &[f32],
    foliage_texel: f32,
    leaf_size: f32,
    lookup: LeafShadowLookup,
    threads: usize,
) -> Vec<SunEstimateError> {
    let to_sun = to_sun.normalize();
    let scene = LeafScene::new(leaves);
    let envelope = crown_envelope(&proxies(leaves), threads);
    let tau = envelope.tau;
    let maps: Vec<FoliageMaps> = texels
        .iter()
        .map(|&t| foliage_maps(leaves, LightFrame::around(leaves, to_sun, t)))
        .collect();
    let coarse = foliage_maps(leaves, LightFrame::around(leaves, to_sun, foliage_texel));
    let picked: Vec<usize> = (0..scene.leaf_count()).step_by(stride.max(1)).collect();
    // Per leaf: traced, baked blend, then per texel (the shaders' lookup, 3×3, extinction),
    // then eq. 5.3.
    let per_leaf: Vec<Vec<f32>> = picked
        .iter()
        .map(|&leaf| {
            let mut rng = SplitMix64::new(0x5EED ^ (leaf as u64).wrapping_mul(0x9E37_79B9));
            let e = &envelope.leaves[leaf];
            let blend = sun_through_crown(
                SunThroughCrown::BlendedAttenuation,
                tau,
                &e.attenuation,
                &e.s_max,
                to_sun,
            );
            let normal = scene.normal(leaf);
            let mut sums = vec![0.0f32; 2 + 3 * maps.len() + 1];
            for _ in 0..points.max(1) {
                let x = scene.point_on(leaf, &mut rng);
                sums[0] += scene.hit(x, to_sun, leaf as u32).is_none() as u32 as f32;
                sums[1] += blend;
                for (k, m) in maps.iter().enumerate() {
                    sums[2 + 3 * k] += lookup.visible(m, x, normal);
                    sums[3 + 3 * k] += m.shadow_map(x, m.frame.texel.min(0.5 * leaf_size));
                    sums[4 + 3 * k] += m.extinction(x, tau);
                }
                sums[2 + 3 * maps.len()] += coarse.relative_depth(x);
            }
            sums.iter().map(|s| s / points.max(1) as f32).collect()
        })
        .collect();
    let column = |c: usize| -> Vec<f32> { per_leaf.iter().map(|v| v[c]).collect() };
    let traced = column(0);
    let mut out = vec![errors(
        "eight baked attenuations, blended (the tree lighting's)".into(),
        &column(1),
        &traced,
    )];
    for (k, m) in maps.iter().enumerate() {
        out.push(errors(
            format!(
                "shadow map, {}, texel {:.3} ({}²)",
                lookup.describe(),
                m.frame.texel,
                m.frame.size
            ),
            &column(2 + 3 * k),
            &traced,
        ));
        out.push(errors(
            format!(
                "shadow map, 3×3 filter, texel {:.3} ({}²)",
                m.frame.texel, m.frame.size
            ),
            &column(3 + 3 * k),
            &traced,
        ));
        out.push(errors(
            format!(
                "extinction over the shadow map's depth, texel {:.3}",
                m.frame.texel
            ),
            &column(4 + 3 * k),
            &traced,
        ));
    }
    out.push(errors(
        format!(
            "foliage maps, eq. 5.3, texel {:.3} ({}²)",
            coarse.frame.texel, coarse.frame.size
        ),
        &column(2 + 3 * maps.len()),
        &traced,
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::path_trace::push_square_leaf;

    /// Two leaves, one straight above the other under an overhead sun.
    fn stack() -> LeafSet {
        let mut leaves = LeafSet::default();
        push_square_leaf(&mut leaves, Vec3::new(0.0, 1.0, 0.0), 0.5, Vec3::Y);
        push_square_leaf(&mut leaves, Vec3::ZERO, 0.25, Vec3::Y);
        leaves
    }

    #[test]
    fn the_maps_see_the_leaf_in_front_and_the_leaf_behind() {
        let leaves = stack();
        let maps = foliage_maps(&leaves, LightFrame::around(&leaves, Vec3::Y, 0.05));
        let (top, bottom) = (Vec3::new(0.0, 1.0, 0.0), Vec3::ZERO);
        // Over a texel both leaves cover, the upper leaf is the nearest depth and the lower the
        // farthest, and one triangle of each covers the texel's centre.
        let (q, z_top) = maps.frame.project(top + Vec3::new(0.1, 0.0, 0.1));
        let i = (q.y as u32 * maps.frame.size + q.x as u32) as usize;
        assert!((maps.near[i] - z_top).abs() < 1e-5);
        assert!((maps.far[i] - maps.frame.project(bottom).1).abs() < 1e-5);
        assert_eq!(maps.count[i], 2);
        // The shadow map lights the top leaf and shades the one under it; eq. 5.3 gives the
        // extremes; the extinction falls off with the metre between them.
        let p = bottom + Vec3::new(0.1, 0.0, 0.1);
        assert_eq!(maps.shadow_map(top + Vec3::new(0.1, 0.0, 0.1), 0.05), 1.0);
        assert_eq!(maps.shadow_map(p, 0.05), 0.0);
        assert_eq!(maps.relative_depth(p), 0.0);
        assert_eq!(maps.relative_depth(top + Vec3::new(0.1, 0.0, 0.1)), 1.0);
        assert!((maps.extinction(p, 2.0) - (-2.0f32).exp()).abs() < 1e-4);
        // Outside the upper leaf's shadow the sun reaches the lower leaf's rim.
        let rim = Vec3::new(0.6, 0.0, 0.0);
        assert_eq!(maps.shadow_map(rim, 0.05), 1.0);
    }

    #[test]
    fn the_bilinear_lookup_blends_the_two_texels_across_a_shadow_edge() {
        let leaves = stack();
        let texel = 0.05;
        let maps = foliage_maps(&leaves, LightFrame::around(&leaves, Vec3::Y, texel));
        // Along x under the upper leaf's edge (x = 0.5): shade well inside, sun well outside,
        // and between them a blend no wider than one texel, rising monotonically.
        let at = |x: f32| maps.shadow_map_bilinear(Vec3::new(x, 0.0, 0.1), 0.05);
        assert_eq!(at(0.4), 0.0);
        assert_eq!(at(0.6), 1.0);
        let xs: Vec<f32> = (0..=400).map(|k| 0.3 + 0.001 * k as f32).collect();
        let values: Vec<f32> = xs.iter().map(|&x| at(x)).collect();
        assert!(values.windows(2).all(|w| w[1] >= w[0] - 1e-6), "{values:?}");
        let blended: Vec<f32> = xs
            .iter()
            .zip(&values)
            .filter(|(_, v)| **v > 1e-4 && **v < 1.0 - 1e-4)
            .map(|(x, _)| *x)
            .collect();
        assert!(!blended.is_empty(), "no blend across the edge: {values:?}");
        let width = blended.last().unwrap() - blended.first().unwrap();
        assert!(width <= texel + 0.002, "blend {width} wide");
        // Halfway between the last shaded and the first lit texel centre, half and half.
        let mid = 0.5 * (blended.first().unwrap() + blended.last().unwrap());
        assert!((at(mid) - 0.5).abs() < 0.05, "{}", at(mid));
    }

    #[test]
    fn the_slope_scaled_offset_keeps_a_tilted_leaf_from_shading_itself() {
        // One leaf at 45° to an overhead sun: across a texel its own depth changes by a texel,
        // which a lookup without the offset takes for a leaf in front; the offset is a texel and
        // a half there.
        let mut leaves = LeafSet::default();
        let normal = Vec3::new(1.0, 1.0, 0.0).normalize();
        push_square_leaf(&mut leaves, Vec3::ZERO, 0.5, normal);
        let diameter = leaves.diameter(0);
        assert!((diameter - 2.0f32.sqrt()).abs() < 1e-5);
        let texel = LEAF_SHADOW_FINE * diameter;
        let maps = foliage_maps(&leaves, LightFrame::around(&leaves, Vec3::Y, texel));
        let scene = LeafScene::new(&leaves);
        let mut rng = SplitMix64::new(3);
        let points: Vec<Vec3> = (0..400).map(|_| scene.point_on(0, &mut rng)).collect();
        let lit = |bias: f32| {
            points
                .iter()
                .map(|&p| maps.shadow_map_bilinear(p, bias))
                .sum::<f32>()
                / points.len() as f32
        };
        let offset = LeafShadowOffset::SLOPE_SCALED.texels_for(normal, Vec3::Y);
        assert!((offset - 1.5).abs() < 1e-4, "{offset}");
        let biased = lit(offset * maps.frame.texel);
        assert!(biased > 0.999, "{biased}");
        assert!(lit(0.0) < 0.9, "{}", lit(0.0));
        // The slope term: steeper leaves move further, up to the cap; a leaf facing the sun by
        // the constant alone, from either side.
        let at = |deg: f32| {
            let t = deg.to_radians();
            LeafShadowOffset::SLOPE_SCALED.texels_for(Vec3::new(t.sin(), t.cos(), 0.0), Vec3::Y)
        };
        assert!((at(0.0) - 1.0).abs() < 1e-6 && (at(180.0) - 1.0).abs() < 1e-5);
        assert!(at(30.0) < at(60.0) && at(60.0) < at(75.0));
        assert!((at(89.9) - 3.0).abs() < 1e-4, "{}", at(89.9));
    }

    /// The mean of `visible` over 400 points spread on leaf `leaf` of `leaves`.
    fn mean_on_leaf(leaves: &LeafSet, leaf: usize, visible: impl Fn(Vec3) -> f32) -> f32 {
        let scene = LeafScene::new(leaves);
        let mut rng = SplitMix64::new(7);
        (0..400)
            .map(|_| visible(scene.point_on(leaf, &mut rng)))
            .sum::<f32>()
            / 400.0
    }

    #[test]
    fn the_receiver_plane_keeps_a_lone_tilted_leaf_lit_at_every_texel_size() {
        // A leaf alone, at 0°, 45° and 70° to a sun that is not along any of the map's axes,
        // under texels from a sixteenth of the leaf to the whole leaf: its own depth across
        // the lookup's texels is its plane's, so it is lit at every point, from either side.
        let to_sun = Vec3::new(0.3, 1.0, 0.2).normalize();
        for deg in [0.0f32, 45.0, 70.0] {
            let (a, _) = to_sun.any_orthonormal_pair();
            let normal = Quat::from_axis_angle(a, deg.to_radians()) * to_sun;
            for normal in [normal, -normal] {
                let mut leaves = LeafSet::default();
                push_square_leaf(&mut leaves, Vec3::new(0.2, -0.1, 0.4), 0.5, normal);
                let diameter = leaves.diameter(0);
                for share in [1.0 / 16.0, 1.0 / 4.0, 1.0 / 2.0, 1.0] {
                    let frame = LightFrame::around(&leaves, to_sun, share * diameter);
                    let maps = foliage_maps(&leaves, frame);
                    let lit = mean_on_leaf(&leaves, 0, |p| {
                        maps.shadow_map_receiver_plane(p, normal, LeafShadowPlane::SHADERS)
                    });
                    assert!(lit > 0.999, "tilt {deg}°, texel {share} of a leaf: {lit}");
                    // Compared with the point's own depth, the tilted leaf shades itself
                    // wherever it covers the lookup's texels (texels up to a quarter of it;
                    // coarser texels are mostly empty around it).
                    let plain = mean_on_leaf(&leaves, 0, |p| maps.shadow_map_bilinear(p, 0.0));
                    if deg > 0.0 && share <= 0.25 {
                        assert!(plain < 0.9, "tilt {deg}°, texel {share}: {plain}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_receiver_plane_shades_a_leaf_behind_another_however_close() {
        // Two parallel leaves at 45° to an overhead sun, the back one a quarter of a coarse
        // texel (a quarter of its leaf) behind the front one along the sun: the slope-scaled
        // offset moves the back leaf's points a texel and a half towards the sun, past the
        // front leaf, and lets the sun through; the receiver plane compares the back leaf's own
        // plane with the front leaf's depths and shades it.
        let normal = Vec3::new(1.0, 1.0, 0.0).normalize();
        let mut near = LeafSet::default();
        push_square_leaf(&mut near, Vec3::ZERO, 1.0, normal);
        push_square_leaf(&mut near, Vec3::ZERO, 0.4, normal);
        let texel = near.diameter(1) / 4.0;
        near.positions[..4]
            .iter_mut()
            .for_each(|p| *p += Vec3::Y * (0.25 * texel));
        let maps = foliage_maps(&near, LightFrame::around(&near, Vec3::Y, texel));
        let plane = mean_on_leaf(&near, 1, |p| {
            maps.shadow_map_receiver_plane(p, normal, LeafShadowPlane::SHADERS)
        });
        assert!(plane < 0.02, "the leaf behind: {plane}");
        let front = mean_on_leaf(&near, 0, |p| {
            maps.shadow_map_receiver_plane(p, normal, LeafShadowPlane::SHADERS)
        });
        assert!(front > 0.999, "the leaf in front: {front}");
        let offset = LeafShadowLookup::Offset(LeafShadowOffset::SLOPE_SCALED);
        let moved = mean_on_leaf(&near, 1, |p| offset.visible(&maps, p, normal));
        assert!(
            moved > 0.9,
            "the offset lets the sun through to the leaf behind: {moved}"
        );
    }

    #[test]
    fn the_receiver_plane_gradient_is_the_leafs_own_depth_and_capped() {
        let to_sun = Vec3::new(-0.2, 0.9, 0.4).normalize();
        let mut leaves = LeafSet::default();
        push_square_leaf(&mut leaves, Vec3::ZERO, 1.0, Vec3::Y);
        let frame = LightFrame::around(&leaves, to_sun, 0.1);
        let n = Vec3::new(0.5, 0.6, -0.2).normalize();
        let g = LeafShadowPlane::SHADERS.gradient(n, &frame);
        // Two points on the plane through the origin: their depth difference is the gradient
        // times their offset in the map's axes.
        let t = n.any_orthonormal_vector() * 0.3;
        let ((q0, z0), (q1, z1)) = (frame.project(Vec3::ZERO), frame.project(t));
        let predicted = g.dot((q1 - q0) * frame.texel);
        assert!(
            (predicted - (z1 - z0)).abs() < 1e-5,
            "{predicted} vs {}",
            z1 - z0
        );
        // Edge-on to the sun: capped at tan θ = 4, never NaN.
        let edge = LeafShadowPlane::SHADERS.gradient(to_sun.any_orthonormal_vector(), &frame);
        assert!((edge.length() - 4.0).abs() < 1e-4, "{edge}");
        let none = LeafShadowPlane::SHADERS.gradient(Vec3::ZERO, &frame);
        assert_eq!(none, Vec2::ZERO);
        let nan = LeafShadowPlane::SHADERS.gradient(Vec3::NAN, &frame);
        assert!(nan.is_finite(), "{nan}");
    }

    #[test]
    fn the_shaders_trust_in_the_map_falls_smoothly_from_fine_to_coarse_texels() {
        assert_eq!(shadow_map_trust(0.0), 1.0);
        assert_eq!(shadow_map_trust(LEAF_SHADOW_FINE), 1.0);
        assert_eq!(shadow_map_trust(LEAF_SHADOW_COARSE), 0.0);
        assert_eq!(shadow_map_trust(4.0 * LEAF_SHADOW_COARSE), 0.0);
        assert_eq!(shadow_map_trust(f32::NAN), 0.0);
        let middle = 0.5 * (LEAF_SHADOW_FINE + LEAF_SHADOW_COARSE);
        assert!((shadow_map_trust(middle) - 0.5).abs() < 1e-6);
        let steps: Vec<f32> = (0..=32)
            .map(|i| {
                let t = i as f32 / 32.0;
                shadow_map_trust(LEAF_SHADOW_FINE + t * (LEAF_SHADOW_COARSE - LEAF_SHADOW_FINE))
            })
            .collect();
        assert!(steps.windows(2).all(|w| w[1] < w[0]), "{steps:?}");
        // Smooth at both ends (smoothstep's flat tangents): the first and last steps are small.
        assert!(1.0 - steps[1] < 0.01 && steps[31] < 0.01, "{steps:?}");
    }

    #[test]
    fn the_leaf_shaders_read_the_map_as_measured_here() {
        let wgsl = include_str!("../pruning/leaf_volume_fragment.wgsl");
        let plane = LeafShadowPlane::SHADERS;
        assert_eq!(
            LeafShadowLookup::SHADERS,
            LeafShadowLookup::ReceiverPlane(plane)
        );
        for (name, value) in [
            ("LEAF_SHADOW_SLACK", plane.slack_texels),
            ("LEAF_SHADOW_MAX_SLOPE", plane.max_slope),
            ("LEAF_SHADOW_FINE", LEAF_SHADOW_FINE),
            ("LEAF_SHADOW_COARSE", LEAF_SHADOW_COARSE),
        ] {
            let line = format!("const {name}: f32 = {value:?};");
            assert!(
                wgsl.contains(&line),
                "leaf_volume_fragment.wgsl lacks `{line}`"
            );
        }
    }

    #[test]
    fn a_fine_shadow_map_agrees_with_the_tracer_on_a_simple_stack() {
        let leaves = stack();
        let errors = sun_visibility_against_tracer(
            &leaves,
            Vec3::Y,
            1,
            64,
            &[0.01],
            0.05,
            0.5,
            LeafShadowLookup::SHADERS,
            1,
        );
        // The top leaf is lit, the bottom one shaded: the traced share has one leaf above the
        // floor, which a fine shadow map gets right.
        let fine = &errors[1];
        assert!(fine.method.starts_with("shadow map"));
        assert!(fine.mean_relative < 0.05, "{errors:?}");
    }
}
