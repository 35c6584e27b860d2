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
//! runs, and the leaf vertex shader reads it ([`super::bounce_ring::sun_through_with_ring`]).
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
/// seeded by its index.
pub fn sunlit_shares(
    scene: &LeafScene,
    leaves: &[u32],
    suns: &[Vec3],
    points: u32,
    opacity: &(dyn Fn(u32) -> f32 + Sync),
    threads: usize,
) -> Vec<Vec<f32>> {
    let side = (points.max(1) as f32).sqrt().ceil() as u32;
    let suns: Vec<Vec3> = suns
        .iter()
        .map(|s| s.try_normalize().unwrap_or(Vec3::Y))
        .collect();
    super::par_map(leaves, threads, |&leaf| {
        if leaf as usize >= scene.leaf_count() {
            return vec![0.0; suns.len()];
        }
        let mut rng = SplitMix64::new(0x51A1_5EED ^ (leaf as u64).wrapping_mul(0x9E37_79B9));
        let spots: Vec<Vec3> = (0..side * side)
            .map(|k| {
                let u = ((k % side) as f32 + rng.next_f32()) / side as f32;
                let v = ((k / side) as f32 + rng.next_f32()) / side as f32;
                scene.point_at(leaf as usize, (u, v))
            })
            .collect();
        suns.iter()
            .map(|&sun| {
                let lit: f32 = spots
                    .iter()
                    .map(|&p| scene.transmittance(p, sun, leaf, opacity))
                    .sum();
                (lit / spots.len() as f32).clamp(0.0, 1.0)
            })
            .collect()
    })
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
/// (`BounceRingSettings::sunlit_points`): the 16 measured in `tree_lighting_error --images
/// --sunlit-points 16`.
pub const DEFAULT_SUNLIT_POINTS: u32 = 16;

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
