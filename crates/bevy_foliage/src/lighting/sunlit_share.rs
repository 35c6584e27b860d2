//! Each leaf's sunlit share: the part of its area that the sun reaches through the crown's
//! other leaves, traced for given suns.
//!
//! Why: where the sun's shadow map has texels wider than a leaf, the leaf shaders fall back
//! on the blend of the leaf's eight baked attenuations (Boulanger 2008, §5.6), whose
//! directions are octants: a sunfleck through a gap a leaf wide spans a few degrees of the
//! sky, and an octant's mean smooths it away. A leaf's share traced for the sun itself is the
//! most any one value per leaf can know of the sun through the crown; traced on a ring of
//! suns at the sun's elevation ([`super::gathered_bounce::sun_ring`]), as the bounce's ratios
//! are re-gathered while an app runs ([`super::bounce_ring`]), it serves every upright
//! instance however turned. [`super::image_error`] measures both against the path tracer;
//! [`super::bounce_ring::gather_ring`] traces the ring beside the bounce ratios while an app
//! runs, and the leaf shaders read it ([`super::bounce_ring::sun_through_with_ring`]).
//!
//! One value a leaf is still its mean: where a sunfleck's edge crosses the leaf it cannot say
//! which side is lit, and with the sun against the eye, where the part of a leaf in view and
//! its sunlit part are least alike, that is most of what is left — the share traced for the
//! image's own sun is 20–22 % off there. So each share is fitted with a plane over the leaf
//! ([`SharePlane`], [`sunlit_planes`]: least squares over the same points), which the leaf
//! vertex shader reads at each vertex and the rasteriser carries across the leaf
//! ([`super::bounce_ring::ring_shares_at`]).
//!
//! Plain Rust, no render types.

use super::leaf_scene::LeafScene;
use crate::rng::SplitMix64;
use bevy::math::Vec3;

/// The sunlit share of each of `leaves` (indices into `scene`) for each of `suns` (unit
/// directions towards the sun): the mean of the light let through along the ray towards that
/// sun from `points` points spread over the leaf (a jittered grid, the same points for every
/// sun, so that neighbouring suns' shares differ by the crown, not by the points), the leaf's
/// own triangles not counted and a leaf `l` letting `1 − opacity(l)` through. `out[i][s]`
/// belongs to `leaves[i]` and `suns[s]`; in `[0, 1]`. Deterministic: each leaf's points are
/// seeded by the leaf ([`LeafScene::leaf_key`]). The means of [`sunlit_planes`].
pub fn sunlit_shares(
    scene: &LeafScene,
    leaves: &[u32],
    suns: &[Vec3],
    points: u32,
    opacity: &(dyn Fn(u32) -> f32 + Sync),
    threads: usize,
) -> Vec<Vec<f32>> {
    sunlit_planes(scene, leaves, suns, points, opacity, threads)
        .into_iter()
        .map(|planes| planes.iter().map(|p| p.mean).collect())
        .collect()
}

/// A leaf's sunlit share towards one sun as a plane over the leaf: the share `mean` at the
/// centroid `centre` of the points it was traced from, changing by `gradient` (in the leaf's
/// plane, per unit of length) across it — the least-squares fit to the light let through at
/// each point. Where a sunfleck's edge crosses a leaf, one value per leaf gives the whole
/// leaf its mean; the plane keeps which side is lit, as values at the leaf's vertices
/// interpolated across it would.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SharePlane {
    /// The share at `centre`: the leaf's sunlit share ([`sunlit_shares`]).
    pub mean: f32,
    /// The centroid of the points it was fitted on.
    pub centre: Vec3,
    /// How the share changes across the leaf, per unit of length (zero for a lone point).
    pub gradient: Vec3,
}

impl SharePlane {
    /// The share at point `at` of the leaf, in [0, 1].
    pub fn at(&self, at: Vec3) -> f32 {
        (self.mean + self.gradient.dot(at - self.centre)).clamp(0.0, 1.0)
    }

    /// The same plane with its mean within [0, 1] (the gradient as it is).
    pub fn clamped(self) -> SharePlane {
        SharePlane {
            mean: self.mean.clamp(0.0, 1.0),
            ..self
        }
    }

    /// The plane a fraction `f` of the way to `other` (the same leaf's, for another sun):
    /// mean and gradient linearly.
    pub fn lerp(&self, other: &SharePlane, f: f32) -> SharePlane {
        SharePlane {
            mean: self.mean + f * (other.mean - self.mean),
            centre: self.centre,
            gradient: self.gradient + f * (other.gradient - self.gradient),
        }
    }
}

/// Each leaf's [`SharePlane`] for each of `suns`, traced as [`sunlit_shares`] (the same
/// points, so the planes' means are those shares): `out[i][s]` belongs to `leaves[i]` and
/// `suns[s]`. A leaf outside `scene`: all 0.
pub fn sunlit_planes(
    scene: &LeafScene,
    leaves: &[u32],
    suns: &[Vec3],
    points: u32,
    opacity: &(dyn Fn(u32) -> f32 + Sync),
    threads: usize,
) -> Vec<Vec<SharePlane>> {
    let suns: Vec<Vec3> = suns
        .iter()
        .map(|s| s.try_normalize().unwrap_or(Vec3::Y))
        .collect();
    super::par_map(leaves, threads, |&leaf| {
        if leaf as usize >= scene.leaf_count() {
            return vec![SharePlane::default(); suns.len()];
        }
        let fit = share_points(scene, leaf as usize, points);
        suns.iter()
            .map(|&sun| {
                fit.fit(|p| scene.transmittance(p, sun, leaf, opacity))
                    .clamped()
            })
            .collect()
    })
}

/// The points leaf `leaf` of `scene` (in it) is traced from for about `points` points: a
/// jittered grid of `⌈√points⌉²`, seeded by the leaf ([`LeafScene::leaf_key`]), the same for
/// every sun and every call ([`sunlit_planes`]).
pub fn share_points(scene: &LeafScene, leaf: usize, points: u32) -> PlaneFit {
    let side = (points.max(1) as f32).sqrt().ceil() as u32;
    let mut rng = SplitMix64::new(0x51A1_5EED ^ scene.leaf_key(leaf));
    PlaneFit::jittered(scene, leaf, side, &mut rng)
}

/// Points spread over a leaf and the least-squares fit of a value linear across them
/// ([`SharePlane`]): the points in the leaf's plane about their centroid, and the normal
/// equations' matrix `[[sxx, sxy], [sxy, syy]]`, set up once for every value fitted on them.
pub struct PlaneFit {
    /// The points, on the leaf.
    pub points: Vec<Vec3>,
    centre: Vec3,
    axes: (Vec3, Vec3),
    xy: Vec<(f32, f32)>,
    sxx: f32,
    sxy: f32,
    syy: f32,
}

impl PlaneFit {
    /// A jittered `side × side` grid of points over leaf `leaf` of `scene` (the unit square
    /// mapped evenly onto the leaf, [`LeafScene::point_at`]), jittered by `rng`.
    pub fn jittered(scene: &LeafScene, leaf: usize, side: u32, rng: &mut SplitMix64) -> Self {
        let side = side.max(1);
        let points: Vec<Vec3> = (0..side * side)
            .map(|k| {
                let u = ((k % side) as f32 + rng.next_f32()) / side as f32;
                let v = ((k / side) as f32 + rng.next_f32()) / side as f32;
                scene.point_at(leaf, (u, v))
            })
            .collect();
        Self::new(points, scene.normal(leaf))
    }

    /// The fit over `points` (at least one) on a leaf facing `normal`.
    pub fn new(points: Vec<Vec3>, normal: Vec3) -> Self {
        let centre = points.iter().copied().sum::<Vec3>() / points.len().max(1) as f32;
        let axes = normal.any_orthonormal_pair();
        let xy: Vec<(f32, f32)> = points
            .iter()
            .map(|p| ((*p - centre).dot(axes.0), (*p - centre).dot(axes.1)))
            .collect();
        let (sxx, sxy, syy) = xy.iter().fold((0.0, 0.0, 0.0), |(a, b, c), (x, y)| {
            (a + x * x, b + x * y, c + y * y)
        });
        Self {
            points,
            centre,
            axes,
            xy,
            sxx,
            sxy,
            syy,
        }
    }

    /// The plane of least squares through `value(p)` at each point (not clamped). Points all
    /// on a line (or one point) fit no plane: the mean alone.
    pub fn fit(&self, mut value: impl FnMut(Vec3) -> f32) -> SharePlane {
        let values: Vec<f32> = self.points.iter().map(|&p| value(p)).collect();
        self.fit_values(&values)
    }

    /// The plane through `values`, one a point in the order of `points`. A list of another
    /// length fits no slope: its mean alone, with a zero gradient.
    pub fn fit_values(&self, values: &[f32]) -> SharePlane {
        let mean = values.iter().sum::<f32>() / values.len().max(1) as f32;
        if values.len() != self.points.len() {
            return SharePlane {
                mean,
                centre: self.centre,
                gradient: Vec3::ZERO,
            };
        }
        let (bx, by) = self
            .xy
            .iter()
            .zip(values)
            .fold((0.0, 0.0), |(a, b), ((x, y), v)| {
                (a + x * (v - mean), b + y * (v - mean))
            });
        let (sxx, sxy, syy) = (self.sxx, self.sxy, self.syy);
        let det = sxx * syy - sxy * sxy;
        let gradient = if det > 1e-6 * (sxx + syy).powi(2) && det > 0.0 {
            self.axes.0 * ((syy * bx - sxy * by) / det)
                + self.axes.1 * ((sxx * by - sxy * bx) / det)
        } else {
            Vec3::ZERO
        };
        SharePlane {
            mean,
            centre: self.centre,
            gradient,
        }
    }
}

/// Each leaf's plane towards `to_sun` from planes traced on a ring of `ring.len()` suns at
/// azimuths from `phase`: linear in azimuth between the two nodes either side, as
/// [`share_on_ring`]. No ring: fully lit.
pub fn plane_on_ring(ring: &[SharePlane], phase: f32, to_sun: Vec3) -> SharePlane {
    match super::gathered_bounce::nodes_either_side(ring.len(), phase, to_sun) {
        Some((i, j, f)) => ring[i].lerp(&ring[j], f),
        None => SharePlane {
            mean: 1.0,
            ..Default::default()
        },
    }
}

/// The share towards `to_sun` from shares traced on a ring of `ring.len()` suns at azimuths
/// from `phase` ([`super::gathered_bounce::sun_ring`]): linear in azimuth between the two
/// nodes either side. No ring: fully lit.
pub fn share_on_ring(ring: &[f32], phase: f32, to_sun: Vec3) -> f32 {
    match super::gathered_bounce::nodes_either_side(ring.len(), phase, to_sun) {
        Some((i, j, f)) => ring[i] + f * (ring[j] - ring[i]),
        None => 1.0,
    }
}

/// Points a leaf a ring of sunlit shares is traced from by default while an app runs
/// (`BounceRingSettings::sunlit_points`). A plane fitted to few points is mostly their noise:
/// for the image's own sun, the plane read at the eye ray's point is 10.4, 8.8, 7.8 and 7.2 %
/// off from 16, 36, 64 and 144 points with the sun against the eye (four procedural trees,
/// pixels 1.4–2.5 leaves wide, `tree_lighting_error --images --sunlit-points P --sun
/// 0.3,0.2,-1`), where a map of 3 × 3 or 4 × 4 cells from the same points is within 1.4
/// points of the plane either way (`--sunlit-maps`). Drawn from a ring of fourteen (`--sun-ring 14`, the sun midway between
/// two nodes, as the leaf shaders draw it), 36 points in place of 16 take the sun's error
/// averaged over the trees from 9.4 to 8.3 % over five suns (against the eye 15.9 → 13.9 %
/// and 13.8 → 12.1 %, behind it 4.8 → 4.5 %) for 1.7–1.9 times the shares' tracing time;
/// 64 points are no better than 36.
pub const DEFAULT_SUNLIT_POINTS: u32 = 36;

/// The most points a leaf a ring's shares are traced from.
pub const MAX_SUNLIT_POINTS: u32 = 1024;

/// A share as stored: a byte, 255ths (clamped to [0, 1]; not a number: 0).
pub fn quantize_share(share: f32) -> u8 {
    if share.is_nan() {
        return 0;
    }
    (share.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// A stored share read back.
pub fn share_of(stored: u8) -> f32 {
    stored as f32 / 255.0
}

/// The largest share change from a leaf's centre to its farthest corner a stored slope holds
/// ([`quantize_slope`]): a sunfleck's edge across the leaf's middle changes it by 1.5 a leaf
/// side, about 1.1 from the centre to a square leaf's corner.
pub const SLOPE_RANGE: f32 = 2.0;

/// A component of a plane's gradient times its leaf's radius, as stored: a signed byte,
/// [`SLOPE_RANGE`]`/127` a step (clamped; not a number: 0).
pub fn quantize_slope(slope: f32) -> i8 {
    if slope.is_nan() {
        return 0;
    }
    (slope.clamp(-SLOPE_RANGE, SLOPE_RANGE) / SLOPE_RANGE * 127.0).round() as i8
}

/// A stored slope read back.
pub fn slope_of(stored: i8) -> f32 {
    stored as f32 * (SLOPE_RANGE / 127.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::gathered_bounce::sun_ring;
    use crate::pruning::leaves::LeafSet;

    /// A square leaf of side `size` centred at `at`, facing +y.
    fn square(leaves: &mut LeafSet, at: Vec3, size: f32) {
        let h = 0.5 * size;
        leaves.push_quad(
            [
                at + Vec3::new(-h, 0.0, h),
                at + Vec3::new(h, 0.0, h),
                at + Vec3::new(h, 0.0, -h),
                at + Vec3::new(-h, 0.0, -h),
            ],
            Vec3::Y,
        );
    }

    #[test]
    fn a_leaf_half_under_another_is_half_lit_straight_down() {
        let mut leaves = LeafSet::default();
        // Below: a unit leaf centred at the origin; above: one covering its x > 0 half.
        square(&mut leaves, Vec3::ZERO, 1.0);
        square(&mut leaves, Vec3::new(0.5, 1.0, 0.0), 1.0);
        let scene = LeafScene::new(&leaves);
        let shares = sunlit_shares(&scene, &[0, 1], &[Vec3::Y, Vec3::X], 64, &|_| 1.0, 1);
        assert!((shares[0][0] - 0.5).abs() < 0.07, "{:?}", shares[0]);
        // Nothing stands above the upper leaf, nor beside the lower along +x.
        assert_eq!(shares[1][0], 1.0);
        assert_eq!(shares[0][1], 1.0);
        // A card letting 40 % through lets 40 % of the shaded half's light through.
        let through = sunlit_shares(&scene, &[0], &[Vec3::Y], 64, &|_| 0.6, 1);
        assert!(
            (through[0][0] - (shares[0][0] + 0.4 * (1.0 - shares[0][0]))).abs() < 1e-4,
            "{through:?}"
        );
    }

    #[test]
    fn values_a_point_fit_their_slope_and_a_list_of_another_length_its_mean_alone() {
        let points = vec![
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, -1.0),
            Vec3::new(-1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
        ];
        let fit = PlaneFit::new(points.clone(), Vec3::Y);
        // A value of 2 + x: slope 1 along x, none along z, read back exactly at each point.
        let plane = fit.fit_values(&[1.0, 3.0, 1.0, 3.0]);
        assert!((plane.mean - 2.0).abs() < 1e-6);
        assert!(
            (plane.gradient - Vec3::X).length() < 1e-5,
            "{}",
            plane.gradient
        );
        assert_eq!(plane, fit.fit(|p| 2.0 + p.x));
        // Three values for four points: their mean, no slope.
        let short = fit.fit_values(&[1.0, 3.0, 2.0]);
        assert_eq!((short.mean, short.gradient), (2.0, Vec3::ZERO));
    }

    #[test]
    fn a_leaf_half_under_another_has_its_lit_half_on_the_plane() {
        let mut leaves = LeafSet::default();
        square(&mut leaves, Vec3::ZERO, 1.0);
        square(&mut leaves, Vec3::new(0.5, 1.0, 0.0), 1.0);
        let scene = LeafScene::new(&leaves);
        let suns = [Vec3::Y, Vec3::X];
        let planes = sunlit_planes(&scene, &[0, 1], &suns, 64, &|_| 1.0, 1);
        let shares = sunlit_shares(&scene, &[0, 1], &suns, 64, &|_| 1.0, 1);
        // The planes' means are the shares, from the same points.
        for (p, s) in planes.iter().zip(&shares) {
            assert_eq!(p.iter().map(|p| p.mean).collect::<Vec<_>>(), *s);
        }
        let down = planes[0][0];
        // A step from lit (x < 0) to shaded (x > 0) across a unit square: the least-squares
        // line through it falls by 1.5 a unit (the step's covariance with x over x's
        // variance, (1/8) / (1/12)), along −x only.
        assert!((down.gradient.x + 1.5).abs() < 0.2, "{down:?}");
        assert!(
            down.gradient.y.abs() < 1e-5 && down.gradient.z.abs() < 0.2,
            "{down:?}"
        );
        assert!(down.at(Vec3::new(-0.4, 0.0, 0.0)) > 0.9);
        assert!(down.at(Vec3::new(0.4, 0.0, 0.0)) < 0.1);
        // Fully lit leaves: flat planes at 1.
        for p in [planes[0][1], planes[1][0]] {
            assert_eq!(p.mean, 1.0);
            assert!(p.gradient.length() < 1e-5, "{p:?}");
        }
        // Read on a ring: the planes either side blended, a missing ring fully lit.
        let ring = [down, planes[0][1]];
        let half = ring[0].lerp(&ring[1], 0.5);
        assert!((half.mean - 0.5 * (down.mean + 1.0)).abs() < 1e-6);
        assert!((half.gradient - 0.5 * down.gradient).length() < 1e-6);
        assert_eq!(plane_on_ring(&[], 0.0, Vec3::Y).at(Vec3::ZERO), 1.0);
    }

    #[test]
    fn the_ring_reads_its_nodes_and_between_them_linearly() {
        let to_sun = Vec3::new(0.6, 0.8, 0.0);
        let ring = [0.0, 1.0, 0.5, 0.25];
        let suns = sun_ring(to_sun, ring.len(), 0.0);
        for (s, &share) in suns.iter().zip(&ring) {
            assert!((share_on_ring(&ring, 0.0, *s) - share).abs() < 1e-5);
        }
        let midway = (suns[0] + suns[1]).normalize();
        assert!((share_on_ring(&ring, 0.0, midway) - 0.5).abs() < 1e-4);
        assert_eq!(share_on_ring(&[], 0.0, to_sun), 1.0);
    }

    #[test]
    fn a_stored_slope_reads_back_within_half_a_step() {
        for k in -100..=100 {
            let s = k as f32 / 50.0;
            assert!((slope_of(quantize_slope(s)) - s).abs() <= 0.5 * SLOPE_RANGE / 127.0 + 1e-6);
        }
        assert_eq!(quantize_slope(-9.0), -127);
        assert_eq!(quantize_slope(9.0), 127);
        assert_eq!(quantize_slope(f32::NAN), 0);
    }

    #[test]
    fn a_stored_share_reads_back_within_half_a_step() {
        for k in 0..=100 {
            let s = k as f32 / 100.0;
            assert!((share_of(quantize_share(s)) - s).abs() <= 0.5 / 255.0 + 1e-6);
        }
        assert_eq!(quantize_share(-1.0), 0);
        assert_eq!(quantize_share(2.0), 255);
        assert_eq!(quantize_share(f32::NAN), 0);
    }
}
