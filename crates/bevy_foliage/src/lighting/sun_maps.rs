//! The sun's light on each leaf from maps rendered from the sun, as plain Rust: a crown's
//! light-space foliage maps (Gumbau 2011, §5.2: the nearest and farthest leaf depths and the leaf
//! count per texel, self-shadowing by eq. 5.3), a plain shadow map read with a 3×3 filter as
//! Bevy reads its own, and the crown's extinction applied to the depth of leaves in front
//! (Beer–Lambert over the shadow map) — each measured leaf by leaf against the path tracer's
//! shadow rays ([`sun_visibility_against_tracer`]), beside the eight baked attenuations' blend
//! the tree lighting uses ([`super::model::sun_through_crown`]). What the leaf-on-leaf shadows of
//! the leaf shaders read, and up to which texel size, is chosen from this measurement: one
//! comparison sampler's bilinear lookup ([`FoliageMaps::shadow_map_bilinear`]) at the point
//! moved towards the sun by [`LeafShadowOffset::SHADERS`], trusted fully at texels up to
//! [`LEAF_SHADOW_FINE`] of the leaf's size and not at all from [`LEAF_SHADOW_COARSE`].

use super::envelope::{crown_envelope, proxies};
use super::model::{SunThroughCrown, sun_through_crown};
use super::path_trace::LeafScene;
use crate::pruning::leaves::LeafSet;
use crate::pruning::visibility::rasterize_triangle;
use crate::rng::SplitMix64;
use bevy::math::{Vec2, Vec3};

/// How far towards the sun the leaf shaders move a point of a leaf before they read the shadow
/// map there, in the map's texels: `texels + slope · min(tan θ, max_slope)`, θ the leaf's tilt
/// from the sun (a slope-scaled depth bias).
///
/// A shadow map cannot tell a leaf from its neighbour: too small an offset and a leaf tilted to
/// the sun shades itself across the lookup's texels (its own depth changes by a texel times
/// tan θ: stripes of shadow acne); too large and the leaf just in front of it lets the sun
/// through. See [`LeafShadowOffset::SHADERS`] for the measurement.
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
    /// The leaf shaders' (`leaf_volume_fragment.wgsl`): a texel, half a texel more per unit of
    /// tan θ up to tan θ = 4.
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
    pub const SHADERS: Self = Self {
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
        Self::SHADERS
    }
}

/// The texel side, as a share of the leaf's size, up to which the leaf shaders take the sun's
/// share at a leaf from the shadow map alone.
///
/// Leaf by leaf (`tree_lighting_error --sun-maps`, read as the shaders read it) the map is
/// 20–31 % off at texels of 1/16 of a leaf, 35–66 % at 1/8, 67–124 % at 1/4 and 182–220 % at one
/// leaf, where the eight baked attenuations' blend is 45–69 % (the offset, in texels, grows
/// with them and lets ever more leaves in front through; a 3×3 filter is 24–30 %, 29–46 %,
/// 49–74 % and 78–127 %). (The leaf's size is its length in these tables and its diameter in
/// the shaders, about 1.1 times longer.)
pub const LEAF_SHADOW_FINE: f32 = 1.0 / 16.0;

/// The texel side, as a share of the leaf's size, from which the leaf shaders no longer read
/// the shadow map at the leaf (the baked blend alone, under the map read where the sun's light
/// enters the crown): where the map, read as the shaders read it, is no closer than the blend
/// ([`LEAF_SHADOW_FINE`]'s table). Between the two sizes the two are blended smoothly.
pub const LEAF_SHADOW_COARSE: f32 = 1.0 / 8.0;

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
/// read it (one bilinear lookup at the point moved towards the sun by `offset`: the shaders'
/// [`LeafShadowOffset::SHADERS`]), read with a 3×3 filter (its depth bias a texel, at most half
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
    offset: LeafShadowOffset,
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
            let offset_texels = offset.texels_for(scene.normal(leaf), to_sun);
            let mut sums = vec![0.0f32; 2 + 3 * maps.len() + 1];
            for _ in 0..points.max(1) {
                let x = scene.point_on(leaf, &mut rng);
                sums[0] += scene.hit(x, to_sun, leaf as u32).is_none() as u32 as f32;
                sums[1] += blend;
                for (k, m) in maps.iter().enumerate() {
                    sums[2 + 3 * k] += m.shadow_map_bilinear(x, offset_texels * m.frame.texel);
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
                "shadow map, one bilinear lookup {} + {}·tan θ texels towards the sun, texel {:.3} ({}²)",
                offset.texels, offset.slope, m.frame.texel, m.frame.size
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
    fn the_leaf_shaders_bias_keeps_a_tilted_leaf_from_shading_itself() {
        // One leaf at 45° to an overhead sun: across a texel its own depth changes by a texel,
        // which a lookup without the offset takes for a leaf in front; the shaders' offset is
        // a texel and a half there.
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
        let offset = LeafShadowOffset::SHADERS.texels_for(normal, Vec3::Y);
        assert!((offset - 1.5).abs() < 1e-4, "{offset}");
        let biased = lit(offset * maps.frame.texel);
        assert!(biased > 0.999, "{biased}");
        assert!(lit(0.0) < 0.9, "{}", lit(0.0));
        // The slope term: steeper leaves move further, up to the cap; a leaf facing the sun by
        // the constant alone, from either side.
        let at = |deg: f32| {
            let t = deg.to_radians();
            LeafShadowOffset::SHADERS.texels_for(Vec3::new(t.sin(), t.cos(), 0.0), Vec3::Y)
        };
        assert!((at(0.0) - 1.0).abs() < 1e-6 && (at(180.0) - 1.0).abs() < 1e-5);
        assert!(at(30.0) < at(60.0) && at(60.0) < at(75.0));
        assert!((at(89.9) - 3.0).abs() < 1e-4, "{}", at(89.9));
    }

    #[test]
    fn the_leaf_shaders_read_the_map_as_measured_here() {
        let wgsl = include_str!("../pruning/leaf_volume_fragment.wgsl");
        let offset = LeafShadowOffset::SHADERS;
        for (name, value) in [
            ("LEAF_SHADOW_TEXELS", offset.texels),
            ("LEAF_SHADOW_SLOPE", offset.slope),
            ("LEAF_SHADOW_MAX_SLOPE", offset.max_slope),
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
            LeafShadowOffset::SHADERS,
            1,
        );
        // The top leaf is lit, the bottom one shaded: the traced share has one leaf above the
        // floor, which a fine shadow map gets right.
        let fine = &errors[1];
        assert!(fine.method.starts_with("shadow map"));
        assert!(fine.mean_relative < 0.05, "{errors:?}");
    }
}
