//! The world-space opacity shadow map of trees (Boulanger 2008, §5.5.2), on the CPU — the
//! reference of its render pass.
//!
//! **The map** (§5.5.2.1) lies in a horizontal plane at the terrain's lowest height under the
//! trees (`plane_y`), which spreads its texels evenly over the ground. Every occluder point P is
//! projected along the sun's direction ω onto the plane at P′ (eq. 5.27:
//! `P′ = P − ω·(P.y − plane_y)/ω.y`); a texel keeps
//!
//! - the height above the plane of the occluder nearest the sun on its ray — the longest P′P, so
//!   the tallest, kept by a MAX blend;
//! - a transmittance, cleared to 1 and multiplied by each occluder fragment's transparency: 0.9
//!   for a leaf (the thesis' value), 0 for a branch or any opaque occluder. The product over the
//!   leaves a ray crosses is the exponential attenuation of eq. 5.5, so the shadow is dark where
//!   leaves pile up and light where they are sparse.
//!
//! **The lookup** (§5.5.2.2, algorithm 7) projects the receiver V the same way, reads the
//! occluders' height at a coarse mip (the thesis reads level 4) to estimate how far V is from the
//! occluders along its ray to the sun, and reads the transmittance at the mip whose texels span
//! the sun's disk at that distance — the shadow softens away from its casters. The thesis scales
//! the distance by a free "blur factor"; here the factor is the sun's angular diameter, so the
//! penumbra is as wide as an area light's (`d·θ`). Two choices the thesis leaves open: a mip
//! texel keeps the *maximum* height of the four below it (a mean would count empty texels as
//! occluders on the ground and shrink the blur at a crown's edge), and a receiver at or above the
//! occluders' height is lit (the thesis' listing never compares heights; its text says the
//! comparison makes the map "equivalent to traditional shadow mapping").
//!
//! **Pruned crowns** keep their darkness through the pruning's area compensation alone: a crown
//! drawing a fraction u of its leaves, each scaled to 1/u of its area, puts as many leaf
//! fragments on a sun ray on average as the full crown (the leaves a ray meets stay Poisson
//! distributed with the same mean), so the mean transmittance is kept — tested below.

use crate::filterable::filter::{ChannelFilter, MomentMap, mip_chain_of_channels, sample};
use bevy::math::{Vec2, Vec3};

/// The transparency factor of one leaf fragment (§5.5.2.1: 0.9).
pub const LEAF_TRANSPARENCY: f32 = 0.9;

/// The mip level the lookup reads the occluders' height at (algorithm 7 reads level 4).
pub const HEIGHT_SEARCH_LEVEL: f32 = 4.0;

/// The smallest `to_light.y` a map is made for: a sun lower than about 3° above the horizon
/// would stretch the shadows over more than 20 times the casters' height.
pub const MIN_SUN_HEIGHT: f32 = 0.05;

/// Where the map lies and how the sun projects onto it (eq. 5.27).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpacityShadowPlane {
    /// The plane's height (the thesis' `planeY`): the lowest ground under the trees.
    pub plane_y: f32,
    /// Unit direction from the scene towards the sun (`y ≥` [`MIN_SUN_HEIGHT`]).
    pub to_light: Vec3,
    /// World `(x, z)` of the map's corner at uv `(0, 0)`.
    pub origin: Vec2,
    /// World extent `(x, z)` of the map.
    pub extent: Vec2,
    /// Texels across (x) and down (z).
    pub resolution: (u32, u32),
}

impl OpacityShadowPlane {
    /// The plane at `plane_y` whose map holds the shadow of everything inside the box
    /// `min..=max` (the casters' bounds) under a sun towards `to_light`, at `resolution`; `None`
    /// for a sun lower than [`MIN_SUN_HEIGHT`], a non-finite input or an empty resolution.
    pub fn fit(
        min: Vec3,
        max: Vec3,
        to_light: Vec3,
        plane_y: f32,
        resolution: (u32, u32),
    ) -> Option<Self> {
        let to_light = to_light.try_normalize()?;
        if !(min.is_finite() && max.is_finite() && plane_y.is_finite())
            || to_light.y < MIN_SUN_HEIGHT
            || resolution.0 == 0
            || resolution.1 == 0
        {
            return None;
        }
        let mut plane = Self {
            plane_y,
            to_light,
            origin: Vec2::ZERO,
            extent: Vec2::ONE,
            resolution,
        };
        let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
        for corner in 0..8 {
            let p = Vec3::new(
                if corner & 1 == 0 { min.x } else { max.x },
                if corner & 2 == 0 { min.y } else { max.y },
                if corner & 4 == 0 { min.z } else { max.z },
            );
            let q = plane.project_world(p);
            lo = lo.min(q);
            hi = hi.max(q);
        }
        plane.origin = lo;
        plane.extent = (hi - lo).max(Vec2::splat(1e-3));
        Some(plane)
    }

    /// Eq. 5.27: the world `(x, z)` of P′, where the sun's ray through `p` meets the plane.
    pub fn project_world(&self, p: Vec3) -> Vec2 {
        let along = (p.y - self.plane_y) / self.to_light.y;
        Vec2::new(p.x - self.to_light.x * along, p.z - self.to_light.z * along)
    }

    /// `p`'s coordinates in the map (uv in `[0, 1]²` over the map, u along x, v along z) and its
    /// height above the plane (the vertical component of P′P, which the map compares).
    pub fn project(&self, p: Vec3) -> (Vec2, f32) {
        (
            (self.project_world(p) - self.origin) / self.extent,
            p.y - self.plane_y,
        )
    }

    /// A texel's world size `(x, z)`.
    pub fn texel_size(&self) -> Vec2 {
        self.extent / Vec2::new(self.resolution.0 as f32, self.resolution.1 as f32)
    }
}

/// The map being drawn: per texel `[height, transmittance, 0, 0]` — the height above the plane
/// of the highest occluder (0 where none) and the product of the occluders' transparencies.
#[derive(Clone, Debug, PartialEq)]
pub struct OpacityShadowMap {
    /// Where the map lies.
    pub plane: OpacityShadowPlane,
    /// Level 0.
    pub texels: MomentMap,
}

impl OpacityShadowMap {
    /// The cleared map: no occluder (height 0, transmittance 1).
    pub fn new(plane: OpacityShadowPlane) -> Self {
        let (w, h) = plane.resolution;
        Self {
            plane,
            texels: MomentMap {
                width: w,
                height: h,
                texels: vec![[0.0, 1.0, 0.0, 0.0]; (w * h) as usize],
            },
        }
    }

    /// Draws one occluder triangle of `transparency` ([`LEAF_TRANSPARENCY`] for a leaf, 0 for an
    /// opaque occluder): each texel whose centre its projection covers (either facing; a centre
    /// on an edge two triangles share belongs to one of them, as a rasteriser's fill rule
    /// decides) is one fragment — the height, interpolated across the triangle, kept if higher
    /// (MAX blend), the transmittance multiplied by `transparency`.
    pub fn draw(&mut self, triangle: [Vec3; 3], transparency: f32) {
        let (w, h) = self.plane.resolution;
        let size = Vec2::new(w as f32, h as f32);
        let projected = triangle.map(|p| {
            let (uv, height) = self.plane.project(p);
            (uv * size, height)
        });
        let [(a, ha), (mut b, mut hb), (mut c, mut hc)] = projected;
        let mut area = (b - a).perp_dot(c - a);
        if !area.is_finite() || area.abs() < 1e-12 {
            return;
        }
        // Counter-clockwise, so that an edge two triangles share runs opposite ways in them.
        if area < 0.0 {
            std::mem::swap(&mut b, &mut c);
            std::mem::swap(&mut hb, &mut hc);
            area = -area;
        }
        // A centre exactly on an edge belongs to the triangle for which the edge runs "up", or
        // along x backwards: of two opposite directions exactly one qualifies.
        let owns = |from: Vec2, to: Vec2| {
            let d = to - from;
            d.y > 0.0 || (d.y == 0.0 && d.x < 0.0)
        };
        let inside = |e: f32, from: Vec2, to: Vec2| e > 0.0 || (e == 0.0 && owns(from, to));
        let lo = a.min(b).min(c).floor().max(Vec2::ZERO);
        let hi = a.max(b).max(c).ceil().min(size);
        for y in lo.y as u32..hi.y as u32 {
            for x in lo.x as u32..hi.x as u32 {
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                // Edge functions: twice the areas opposite each corner.
                let ea = (c - b).perp_dot(p - b);
                let eb = (a - c).perp_dot(p - c);
                let ec = (b - a).perp_dot(p - a);
                if !(inside(ea, b, c) && inside(eb, c, a) && inside(ec, a, b)) {
                    continue;
                }
                let height = (ea * ha + eb * hb + ec * hc) / area;
                let texel = &mut self.texels.texels[(y * w + x) as usize];
                texel[0] = texel[0].max(height);
                texel[1] *= transparency;
            }
        }
    }

    /// The mip chain the lookup reads: each coarser texel the maximum height and the mean
    /// transmittance of the (up to) four below it.
    pub fn mips(&self) -> Vec<MomentMap> {
        use ChannelFilter::*;
        mip_chain_of_channels(&self.texels, [Max, Mean, Mean, Mean])
    }
}

/// How much sunlight reaches `receiver` through the trees (1 lit, 0 fully shadowed): the soft
/// lookup of §5.5.2.2 in the map `chain` ([`OpacityShadowMap::mips`]) of `plane`, for a sun of
/// angular diameter `sun_angle` (radians).
pub fn visibility(
    plane: &OpacityShadowPlane,
    chain: &[MomentMap],
    receiver: Vec3,
    sun_angle: f32,
) -> f32 {
    let (uv, receiver_height) = plane.project(receiver);
    if !uv.is_finite() || uv.cmplt(Vec2::ZERO).any() || uv.cmpgt(Vec2::ONE).any() {
        return 1.0;
    }
    let uv = [uv.x, uv.y];
    let coarse = sample(chain, uv, HEIGHT_SEARCH_LEVEL.exp2());
    if coarse[1] >= 0.99 || coarse[0] <= receiver_height {
        return 1.0;
    }
    // From the receiver up its ray to the occluders, and the sun's disk's width there.
    let distance = (coarse[0] - receiver_height) / plane.to_light.y;
    let footprint = distance * sun_angle.max(0.0) / plane.texel_size().min_element();
    sample(chain, uv, footprint.max(1.0))[1].clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy::math::Quat;

    /// A deterministic uniform in `[0, 1)` (SplitMix64).
    struct Random(u64);
    impl Random {
        fn next(&mut self) -> f32 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// A leaf: a square of side `side` at `centre`, randomly oriented, as two triangles.
    fn leaf(centre: Vec3, side: f32, random: &mut Random) -> [[Vec3; 3]; 2] {
        let rotation = Quat::from_euler(
            bevy::math::EulerRot::XYZ,
            random.next() * std::f32::consts::TAU,
            random.next() * std::f32::consts::TAU,
            random.next() * std::f32::consts::TAU,
        );
        let h = side / 2.0;
        let corner = |x: f32, z: f32| centre + rotation * Vec3::new(x, 0.0, z);
        let (a, b, c, d) = (corner(-h, -h), corner(h, -h), corner(h, h), corner(-h, h));
        [[a, b, c], [a, c, d]]
    }

    /// A crown of `count` leaf centres uniform in a sphere of radius 2 m centred 5 m up.
    fn crown(count: usize, seed: u64) -> Vec<Vec3> {
        let mut random = Random(seed);
        let mut out = Vec::with_capacity(count);
        while out.len() < count {
            let p = Vec3::new(random.next(), random.next(), random.next()) * 2.0 - 1.0;
            if p.length_squared() <= 1.0 {
                out.push(Vec3::new(0.0, 5.0, 0.0) + p * 2.0);
            }
        }
        out
    }

    /// A plane under the crown's box, sun 60° up.
    fn plane(resolution: u32) -> OpacityShadowPlane {
        OpacityShadowPlane::fit(
            Vec3::new(-2.5, 2.5, -2.5),
            Vec3::new(2.5, 7.5, 2.5),
            Vec3::new(0.5, 0.866, 0.0),
            0.0,
            (resolution, resolution),
        )
        .unwrap()
    }

    /// The map of leaves at `centres`, each `side` across.
    fn map_of(centres: &[Vec3], side: f32, seed: u64) -> OpacityShadowMap {
        let mut map = OpacityShadowMap::new(plane(128));
        let mut random = Random(seed);
        for &c in centres {
            for t in leaf(c, side, &mut random) {
                map.draw(t, LEAF_TRANSPARENCY);
            }
        }
        map
    }

    /// Mean visibility over the ground in the crown's shadow (the disk the sphere projects to).
    fn mean_shadow(map: &OpacityShadowMap, sun_angle: f32) -> f32 {
        let chain = map.mips();
        let centre = map.plane.project_world(Vec3::new(0.0, 5.0, 0.0));
        let mut sum = 0.0;
        let mut n = 0;
        for i in -20..=20 {
            for j in -20..=20 {
                let offset = Vec2::new(i as f32, j as f32) * 0.075;
                if offset.length() > 1.5 {
                    continue;
                }
                let ground = Vec3::new(centre.x + offset.x, 0.0, centre.y + offset.y);
                sum += visibility(&map.plane, &chain, ground, sun_angle);
                n += 1;
            }
        }
        sum / n as f32
    }

    #[test]
    fn points_on_one_sun_ray_project_to_one_texel() {
        let plane = plane(64);
        let ground = Vec3::new(0.3, 0.0, -0.7);
        let (uv0, h0) = plane.project(ground);
        assert_eq!(h0, 0.0);
        for t in [0.5f32, 2.0, 6.0] {
            let p = ground + plane.to_light * t;
            let (uv, h) = plane.project(p);
            assert!((uv - uv0).length() < 1e-5, "{uv} vs {uv0}");
            assert!((h - plane.to_light.y * t).abs() < 1e-5);
        }
        // Every corner of the casters' box lands inside the map.
        for corner in [Vec3::new(-2.5, 7.5, 2.5), Vec3::new(2.5, 2.5, -2.5)] {
            let (uv, _) = plane.project(corner);
            assert!(
                uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all(),
                "{uv}"
            );
        }
    }

    #[test]
    fn unusable_suns_and_bounds_make_no_map() {
        let fit = |to_light: Vec3, min: Vec3| {
            OpacityShadowPlane::fit(min, Vec3::ONE, to_light, 0.0, (64, 64))
        };
        assert!(fit(Vec3::new(1.0, 0.01, 0.0), Vec3::ZERO).is_none());
        assert!(fit(Vec3::new(0.0, -1.0, 0.0), Vec3::ZERO).is_none());
        assert!(fit(Vec3::NAN, Vec3::ZERO).is_none());
        assert!(fit(Vec3::Y, Vec3::splat(f32::NAN)).is_none());
        assert!(OpacityShadowPlane::fit(Vec3::ZERO, Vec3::ONE, Vec3::Y, 0.0, (0, 4)).is_none());
        assert!(fit(Vec3::Y, Vec3::ZERO).is_some());
    }

    /// k leaves stacked over a texel leave 0.9^k of the light; the highest is kept; an opaque
    /// occluder blocks it all.
    #[test]
    fn stacked_leaves_attenuate_exponentially() {
        let mut map = OpacityShadowMap::new(
            OpacityShadowPlane::fit(
                Vec3::new(-1.0, 0.0, -1.0),
                Vec3::new(1.0, 4.0, 1.0),
                Vec3::Y,
                0.0,
                (16, 16),
            )
            .unwrap(),
        );
        let square = |y: f32, half: f32| {
            let c = |x: f32, z: f32| Vec3::new(x, y, z);
            [
                [c(-half, -half), c(half, -half), c(half, half)],
                [c(-half, -half), c(half, half), c(-half, half)],
            ]
        };
        for (k, y) in [1.0f32, 2.0, 3.0].into_iter().enumerate() {
            // Each leaf smaller than the last: the centre is under all three, the rim under one.
            for t in square(y, 0.9 - 0.25 * k as f32) {
                map.draw(t, LEAF_TRANSPARENCY);
            }
        }
        let at = |map: &OpacityShadowMap, x: u32, y: u32| map.texels.texels[(y * 16 + x) as usize];
        let centre = at(&map, 8, 8);
        assert!((centre[1] - 0.9f32.powi(3)).abs() < 1e-6, "{centre:?}");
        assert!(
            (centre[0] - 3.0).abs() < 1e-5,
            "the highest leaf: {centre:?}"
        );
        let rim = at(&map, 8, 1);
        assert!(
            (rim[1] - 0.9).abs() < 1e-6 && (rim[0] - 1.0).abs() < 1e-5,
            "{rim:?}"
        );
        assert_eq!(
            at(&map, 0, 0),
            [0.0, 1.0, 0.0, 0.0],
            "nothing drawn at the corner"
        );
        for t in square(0.5, 0.3) {
            map.draw(t, 0.0);
        }
        assert_eq!(at(&map, 8, 8)[1], 0.0);
        assert!(
            (at(&map, 8, 8)[0] - 3.0).abs() < 1e-5,
            "a lower occluder keeps the height"
        );
    }

    /// The ground under denser crowns is darker: the mean visibility in the shadow falls with
    /// every doubling of the leaf count, roughly as the exponential attenuation predicts.
    #[test]
    fn denser_crowns_cast_darker_shadows() {
        let counts = [50usize, 100, 200, 400, 800];
        let means: Vec<f32> = counts
            .iter()
            .map(|&n| mean_shadow(&map_of(&crown(n, 7), 0.3, 11), 0.01))
            .collect();
        eprintln!("leaves {counts:?}: mean visibility in the shadow {means:?}");
        for pair in means.windows(2) {
            assert!(pair[1] < pair[0] - 0.02, "{means:?}");
        }
        assert!(means[0] > 0.95 && means[4] < 0.75, "{means:?}");
    }

    /// A crown pruned to a quarter of its leaves, each drawn at four times its area (the
    /// pruning's compensation, a linear scale of 2), casts a shadow as dark as the full crown;
    /// without the compensation it is much lighter.
    #[test]
    fn a_pruned_crown_keeps_its_darkness() {
        let full = crown(800, 3);
        let mut random = Random(99);
        let kept: Vec<Vec3> = full
            .iter()
            .copied()
            .filter(|_| random.next() < 0.25)
            .collect();
        let whole = mean_shadow(&map_of(&full, 0.3, 5), 0.01);
        let compensated = mean_shadow(&map_of(&kept, 0.6, 5), 0.01);
        let bare = mean_shadow(&map_of(&kept, 0.3, 5), 0.01);
        eprintln!(
            "{} of 800 leaves kept: mean visibility full {whole:.3}, compensated \
             {compensated:.3}, uncompensated {bare:.3}",
            kept.len()
        );
        assert!(
            (compensated - whole).abs() < 0.04,
            "{compensated} vs {whole}"
        );
        assert!(bare > whole + 0.15, "{bare} vs {whole}");
    }

    /// An opaque plate's shadow edge widens with the plate's height above the ground, as an
    /// area light's penumbra does (`d·θ`), and a receiver above the plate is lit.
    #[test]
    fn the_shadow_softens_away_from_its_casters() {
        let width_at = |height: f32| {
            let plane = OpacityShadowPlane::fit(
                Vec3::new(-4.0, 0.0, -4.0),
                Vec3::new(4.0, height, 4.0),
                Vec3::Y,
                0.0,
                (256, 256),
            )
            .unwrap();
            let mut map = OpacityShadowMap::new(plane);
            // A 4 m plate, its edge along x = 0.
            let c = |x: f32, z: f32| Vec3::new(x, height, z);
            map.draw([c(-4.0, -2.0), c(0.0, -2.0), c(0.0, 2.0)], 0.0);
            map.draw([c(-4.0, -2.0), c(0.0, 2.0), c(-4.0, 2.0)], 0.0);
            let chain = map.mips();
            let v = |x: f32| visibility(&plane, &chain, Vec3::new(x, 0.0, 0.0), 0.1);
            assert!(v(-1.5) < 0.05 && v(1.5) > 0.95, "{} {}", v(-1.5), v(1.5));
            assert_eq!(visibility(&plane, &chain, c(-1.0, 0.0) + Vec3::Y, 0.1), 1.0);
            // The 10–90 % rise across the edge.
            let xs: Vec<f32> = (0..=600).map(|i| -1.5 + i as f32 * 0.005).collect();
            let first = |level: f32| xs.iter().copied().find(|&x| v(x) >= level).unwrap();
            first(0.9) - first(0.1)
        };
        let (low, high) = (width_at(0.5), width_at(4.0));
        eprintln!("10–90 % edge: plate 0.5 m up {low:.3} m, 4 m up {high:.3} m");
        assert!(high > 3.0 * low, "{low} {high}");
        // A box filter as wide as the sun's disk at 4 m (0.4 m) rises over 0.8 of it; the mips'
        // power-of-two widths put it within a factor of two.
        assert!(high > 0.16 && high < 0.64, "{high}");
    }
}
