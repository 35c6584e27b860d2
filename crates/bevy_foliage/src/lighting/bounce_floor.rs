//! What values stored per leaf can make of the bounce, for one sun: measured by
//! `tree_lighting_error --images` against the path tracer (`--bounce-planes`,
//! `--through-planes`), to tell the gather's noise from what one value a face cannot hold.
//!
//! The leaf shaders scale eq. 5.24's bounce (Boulanger 2008, §5.4.3) face by face by ratios
//! gathered from each leaf's own neighbours ([`super::gathered_bounce`]): one value a face, the
//! leaf's mean. Against the sun the bounce so drawn stays well above the thesis' 6 % (§5.7) on
//! the procedural trees. Two things stand between a leaf's value and the traced image:
//!
//! - **The gather's noise.** A ray finds a neighbour or not, and the neighbour is in sun at the
//!   hit or not. [`gather_through_planes`] takes the second coin away: at each neighbour hit the
//!   neighbour's sunlit share is read off its plane ([`super::sunlit_share::SharePlane`], which
//!   a ring traces for its suns anyway) in place of a shadow ray.
//! - **One value a face.** The bounce varies across a leaf, and the eye sees part of it.
//!   [`bounce_planes`] fits each face's irradiance with a plane over the leaf, from a jittered
//!   grid of points each gathering a few rays ([`super::sunlit_share::PlaneFit`], as the sunlit
//!   shares are fitted), and [`gather_at`] gathers at the eye ray's own point, what no value
//!   stored per leaf beats.
//!
//! Plain Rust, no render types.

use super::gathered_bounce::gather_irradiance_by;
use super::leaf_scene::LeafScene;
use super::model::LeafMaterial;
use super::sunlit_share::{PlaneFit, SharePlane};
use crate::rng::SplitMix64;
use bevy::math::Vec3;

/// The bounce's irradiance over one leaf for one sun, a plane a face (front, back), in the
/// units of [`super::gathered_bounce::gather_irradiance`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BouncePlanes {
    /// Front face (the side of the leaf's normal), then back.
    pub faces: [SharePlane; 2],
}

impl BouncePlanes {
    /// Each face's irradiance at point `at` of the leaf (never below 0).
    pub fn at(&self, at: Vec3) -> [f32; 2] {
        self.faces
            .map(|f| (f.mean + f.gradient.dot(at - f.centre)).max(0.0))
    }

    /// Each face's mean over the leaf.
    pub fn mean(&self) -> [f32; 2] {
        self.faces.map(|f| f.mean.max(0.0))
    }
}

/// Per leaf of `leaves`, its [`BouncePlanes`] for the sun towards `to_sun`: a jittered grid of
/// `side × side` points over the leaf, each gathering `rays_per_point` rays
/// ([`gather_irradiance_by`] with shadow rays), fitted by least squares a face. `threads`
/// workers.
pub fn bounce_planes(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    to_sun: Vec3,
    side: u32,
    rays_per_point: u32,
    threads: usize,
) -> Vec<BouncePlanes> {
    super::par_map(leaves, threads, |&leaf| {
        let l = leaf as usize;
        if l >= scene.leaf_count() {
            return BouncePlanes::default();
        }
        let mut rng = SplitMix64::new(0xB0F1_u64 ^ scene.leaf_key(l));
        let fit = PlaneFit::jittered(scene, l, side.max(1), &mut rng);
        let at: Vec<[f32; 2]> = fit
            .points
            .iter()
            .map(|&p| {
                one_sun(
                    scene,
                    material,
                    l,
                    rays_per_point,
                    to_sun,
                    &mut rng,
                    &mut |_| p,
                    None,
                )
            })
            .collect();
        let face = |f: usize| fit.fit_values(&at.iter().map(|v| v[f]).collect::<Vec<_>>());
        BouncePlanes {
            faces: [face(0), face(1)],
        }
    })
}

/// The bounce's irradiance on each face of leaf `leaf` at its point `point` for the sun towards
/// `to_sun`, from `rays` rays all from that point (shadow rays at the neighbours' hits).
pub fn gather_at(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaf: usize,
    point: Vec3,
    rays: u32,
    to_sun: Vec3,
    seed: u64,
) -> [f32; 2] {
    let mut rng = SplitMix64::new(seed);
    one_sun(
        scene,
        material,
        leaf,
        rays,
        to_sun,
        &mut rng,
        &mut |_| point,
        None,
    )
}

/// The bounce's irradiance on each face of leaf `leaf` (its mean over the leaf) for the sun
/// towards `to_sun`, from `rays` rays as [`super::gathered_bounce::gather_irradiance`] casts
/// them (the same points and directions for the same `seed`), the sun's share at each
/// neighbour's hit read off that neighbour's sunlit plane for this sun (`planes[neighbour]`)
/// in place of a shadow ray.
pub fn gather_through_planes(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaf: usize,
    rays: u32,
    to_sun: Vec3,
    planes: &[SharePlane],
    seed: u64,
) -> [f32; 2] {
    let mut rng = SplitMix64::new(seed);
    let through = |other: u32, hit: Vec3| planes.get(other as usize).map_or(0.0, |p| p.at(hit));
    one_sun(
        scene,
        material,
        leaf,
        rays,
        to_sun,
        &mut rng,
        &mut |u| scene.point_at(leaf, u),
        Some(&through),
    )
}

/// [`gather_irradiance_by`] for the one sun towards `to_sun` (not a direction: straight up),
/// every leaf opaque: each face's irradiance. The sun's share at a neighbour's hit is
/// `lit(neighbour, hit point)` where given, else a shadow ray's.
#[allow(clippy::too_many_arguments)]
fn one_sun(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaf: usize,
    rays: u32,
    to_sun: Vec3,
    rng: &mut SplitMix64,
    point: &mut dyn FnMut((f32, f32)) -> Vec3,
    lit: Option<&dyn Fn(u32, Vec3) -> f32>,
) -> [f32; 2] {
    let sun = to_sun.normalize_or(Vec3::Y);
    gather_irradiance_by(
        scene,
        material,
        leaf,
        rays,
        &[sun],
        &|_| 1.0,
        rng,
        point,
        &|other, hit, _| match lit {
            Some(lit) => lit(other, hit),
            None => scene.transmittance(hit, sun, other, |_| 1.0),
        },
    )[0]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::gathered_bounce::gather_irradiance;
    use crate::lighting::path_trace::push_square_leaf;
    use crate::pruning::leaves::LeafSet;

    /// A leaf at the origin facing up, and a lit neighbour above it towards +x, tilted to face
    /// it: the part of the lower leaf towards +x sees more of the neighbour.
    fn pair() -> LeafSet {
        let mut leaves = LeafSet::default();
        push_square_leaf(&mut leaves, Vec3::ZERO, 0.5, Vec3::Y);
        push_square_leaf(
            &mut leaves,
            Vec3::new(1.2, 0.6, 0.0),
            0.5,
            Vec3::new(-1.0, -1.0, 0.0).normalize(),
        );
        leaves
    }

    #[test]
    fn the_bounce_plane_leans_towards_the_lit_neighbour() {
        let leaves = pair();
        let scene = LeafScene::new(&leaves);
        let material = LeafMaterial::default();
        // The sun from below the neighbour's lower face's side, nothing in its way.
        let to_sun = Vec3::new(-0.3, -1.0, 0.2).normalize();
        let planes = bounce_planes(&scene, &material, &[0], to_sun, 6, 64, 1);
        let front = planes[0].faces[0];
        assert!(
            front.mean > 0.0,
            "the lit neighbour brings light: {front:?}"
        );
        // Across the unit leaf, the side towards the neighbour gets clearly more.
        let near = planes[0].at(Vec3::new(0.4, 0.0, 0.0))[0];
        let far = planes[0].at(Vec3::new(-0.4, 0.0, 0.0))[0];
        assert!(
            front.gradient.x > 0.0 && near > 1.5 * far,
            "near {near}, far {far}, {front:?}"
        );
        // The gather at a point on the near side agrees with the plane there within its noise.
        let here = gather_at(
            &scene,
            &material,
            0,
            Vec3::new(0.4, 0.0, 0.0),
            4096,
            to_sun,
            7,
        )[0];
        assert!(
            (here - near).abs() < 0.25 * here,
            "at the point {here}, plane {near}"
        );
        // The back face faces away from the neighbour: nothing.
        assert_eq!(planes[0].mean()[1], 0.0);
    }

    #[test]
    fn the_gather_through_planes_reads_the_neighbours_share_for_its_shadow_ray() {
        let leaves = pair();
        let scene = LeafScene::new(&leaves);
        let material = LeafMaterial::default();
        // From below and towards +x, so that no shadow ray from the neighbour meets the lower
        // leaf (towards −x the rays from the neighbour's lowest corner graze its far corner).
        let to_sun = Vec3::new(0.3, -1.0, 0.2).normalize();
        let seed = 11;
        // The neighbour fully in sun: planes of share 1 give the shadow rays' gather exactly
        // (the same rays for the same seed).
        let lit = SharePlane {
            mean: 1.0,
            centre: Vec3::ZERO,
            gradient: Vec3::ZERO,
        };
        let shadowed = gather_irradiance(&scene, &material, 0, 256, &[to_sun], &|_| 1.0, seed)[0];
        let through = gather_through_planes(&scene, &material, 0, 256, to_sun, &[lit, lit], seed);
        assert!(shadowed[0] > 0.0);
        assert_eq!(through, shadowed);
        // The neighbour's plane says half of it is in shade: half the light, ray for ray.
        let half = SharePlane { mean: 0.5, ..lit };
        let halved = gather_through_planes(&scene, &material, 0, 256, to_sun, &[lit, half], seed);
        assert!((halved[0] - 0.5 * shadowed[0]).abs() < 1e-5 * shadowed[0]);
        // A plane lit on the side the lower leaf sees (towards its centre, −x) brings more than
        // one lit on the far side.
        let towards = SharePlane {
            mean: 0.5,
            centre: Vec3::new(1.2, 0.6, 0.0),
            gradient: Vec3::new(-0.7, 0.7, 0.0),
        };
        let away = SharePlane {
            gradient: -towards.gradient,
            ..towards
        };
        let a = gather_through_planes(&scene, &material, 0, 256, to_sun, &[lit, towards], seed)[0];
        let b = gather_through_planes(&scene, &material, 0, 256, to_sun, &[lit, away], seed)[0];
        assert!(a > b, "lit towards the leaf {a}, away {b}");
    }
}
