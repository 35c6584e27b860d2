//! Grass lighting on the CPU (Boulanger 2008, thesis §4.2.2–4.2.3, §4.2.6, appendix A): the
//! blades' two-sided Lambert with transmission and distance attenuation (eq. 4.1), their ambient
//! occlusion rising with height, the blade shadow mask modulated by the local density (eq. 4.7),
//! and the spherical barycentric weights that blend the slices' five baked light directions
//! (eq. 4.2, A.1–A.6). The shaders compute the same; these are their references.

use bevy::math::{Vec2, Vec3};

/// Eq. 4.1: radiance of a blade point of diffuse reflectance `kd`, ambient occlusion `ao`, under
/// ambient `ia` and a light of intensity `id` at distance `d` from direction `l` (unit, from the
/// point to the light), the blade's unit normal `n`: diffuse on the lit face, `γ` of it
/// transmitted through to the other, attenuated by `1 + β·d²`.
#[allow(clippy::too_many_arguments)]
pub fn blade_radiance(
    kd: Vec3,
    ao: f32,
    ia: f32,
    n: Vec3,
    l: Vec3,
    gamma: f32,
    id: f32,
    beta: f32,
    d: f32,
) -> Vec3 {
    let cos = n.dot(l);
    let direct = cos.max(0.0) + gamma * (-cos).max(0.0);
    kd * ao * ia + kd * direct * id / (1.0 + beta * d * d)
}

/// The blades' perceptual roughness in Bevy's PBR (the blade material's, and what the slices'
/// ambient and specular terms assume).
pub const BLADE_PERCEPTUAL_ROUGHNESS: f32 = 0.8;

/// The blades' specular reflectance in Bevy's PBR (`StandardMaterial::reflectance`; the
/// reflectance at normal incidence is `0.16 · r²`).
pub const BLADE_REFLECTANCE: f32 = 0.3;

/// Bevy's split-sum scale and bias at `perceptual_roughness` and `n·v` (`bevy_pbr::lighting::F_AB`,
/// its polynomial fit, the form a build without the `dfg_lut` feature uses): the environment
/// BRDF of a reflectance `f0` is `f0 · x + y`.
pub fn f_ab(perceptual_roughness: f32, n_dot_v: f32) -> Vec2 {
    let r = [
        1.0 - perceptual_roughness,
        perceptual_roughness * -0.0275 + 0.0425,
        perceptual_roughness * -0.572 + 1.04,
        perceptual_roughness * 0.022 - 0.04,
    ];
    let a004 = (r[0] * r[0]).min((-9.28 * n_dot_v).exp2()) * r[0] + r[1];
    Vec2::new(-1.04 * a004 + r[2], 1.04 * a004 + r[3]).max(Vec2::splat(0.00005))
}

/// The ambient light (`ambient`, before exposure) a slice texel of blade colour `kd_ao` (kd
/// times the blade's occlusion, the unlit layer) sends to the eye, as Bevy's PBR lights the
/// blade it stands for (`bevy_pbr::ambient::ambient_light`): the reflected share `1 − γ` of the
/// diffuse through the environment BRDF at roughness 1, and its specular at the blades'
/// roughness and reflectance, both under the terrain's occlusion `terrain_ao`; the transmitted
/// share `γ`, which Bevy lights from behind at normal incidence and never occludes. `n_dot_v`:
/// the blade normal's cosine with the view.
pub fn slice_ambient(
    kd_ao: Vec3,
    gamma: f32,
    n_dot_v: f32,
    ambient: Vec3,
    terrain_ao: f32,
) -> Vec3 {
    let n_dot_v = n_dot_v.max(1e-4);
    let diffuse = f_ab(1.0, n_dot_v);
    let lit = kd_ao * (1.0 - gamma) * diffuse.x + Vec3::splat(diffuse.y);
    let through_ab = f_ab(1.0, 1.0);
    let through = kd_ao * gamma * through_ab.x + Vec3::splat(through_ab.y);
    let f0 = 0.16 * BLADE_REFLECTANCE * BLADE_REFLECTANCE;
    let specular_ab = f_ab(BLADE_PERCEPTUAL_ROUGHNESS, n_dot_v);
    let specular_occlusion = (f0 * 3.0 * 50.0 * 0.33).clamp(0.0, 1.0);
    let specular = (f0 * specular_ab.x + specular_ab.y) * specular_occlusion;
    ambient * ((lit + Vec3::splat(specular)) * terrain_ao + through)
}

/// The ambient occlusion of a blade point `height_fraction` of the way up the blade (0 root,
/// 1 tip): `root_ao` at the ground rising linearly to 1 at the tip (§4.2.2: neighbours occlude
/// the bottom of a blade most).
pub fn blade_ao(height_fraction: f32, root_ao: f32) -> f32 {
    let h = height_fraction.clamp(0.0, 1.0);
    root_ao + (1.0 - root_ao) * h
}

/// Eq. 4.7: the light reaching a blade point through the shadow mask's value `mask` (1 lit,
/// 0 shadowed by the neighbour blades it stands for) where the local density is `ld`: the
/// fewer neighbours, the less shadow.
pub fn masked_light(mask: f32, ld: f32) -> f32 {
    1.0 - (1.0 - mask.clamp(0.0, 1.0)) * ld.clamp(0.0, 1.0)
}

/// The blade shadow mask of §4.2.6 (fig. 4.16): the shadows a blade's neighbours cast on it,
/// as a grey image wrapped around a cylinder about the blade — visibility 1 where light passes,
/// 0 where a neighbour blocks it. The thesis renders a thick slab of the patch orthographically,
/// blades black on white; the slice bake already holds exactly that image (a vertical slice's
/// coverage), so the mask is one minus it, the slab's width wrapped once around the cylinder
/// (radius `width / 2π`). A blade point lit from `l` reads the mask where the ray towards the
/// light leaves the cylinder, and eq. 4.7 weakens the shadow where the grass is sparse.
#[derive(Clone, Debug, PartialEq)]
pub struct ShadowMask {
    /// Texels around the cylinder.
    pub width: u32,
    /// Texels up it (row 0 at the top).
    pub height: u32,
    /// Visibility per texel, row-major.
    pub texels: Vec<f32>,
    /// The cylinder's height (m): the slab's.
    pub slab_height: f32,
    /// The cylinder's radius (m).
    pub radius: f32,
}

impl ShadowMask {
    /// The mask of a slab image `width × height` whose texel coverage is `coverage(x, y)`
    /// (row 0 at the top), `slab_width` metres wide and `slab_height` tall.
    pub fn from_coverage(
        width: u32,
        height: u32,
        coverage: impl Fn(u32, u32) -> f32,
        slab_width: f32,
        slab_height: f32,
    ) -> Self {
        let texels = (0..width * height)
            .map(|i| 1.0 - coverage(i % width, i / width).clamp(0.0, 1.0))
            .collect();
        Self {
            width,
            height,
            texels,
            slab_height,
            radius: slab_width / std::f32::consts::TAU,
        }
    }

    /// No shadow anywhere (before a patch's slices are baked).
    pub fn clear() -> Self {
        Self {
            width: 1,
            height: 1,
            texels: vec![1.0],
            slab_height: 1.0,
            radius: 0.0,
        }
    }

    /// The mask at `(u, v)`: `u` around the cylinder (one turn per unit, wrapping), `v` down it
    /// (0 top, 1 bottom, clamped); bilinear between texel centres.
    pub fn sample(&self, u: f32, v: f32) -> f32 {
        let t = Vec2::new(u * self.width as f32, v * self.height as f32) - 0.5;
        let base = t.floor();
        let f = t - base;
        let at = |dx: i64, dy: i64| {
            let x = (base.x as i64 + dx).rem_euclid(self.width as i64) as u32;
            let y = (base.y as i64 + dy).clamp(0, self.height as i64 - 1) as u32;
            self.texels[(y * self.width + x) as usize]
        };
        let top = at(0, 0) + (at(1, 0) - at(0, 0)) * f.x;
        let bottom = at(0, 1) + (at(1, 1) - at(0, 1)) * f.x;
        top + (bottom - top) * f.y
    }

    /// The share of the light from unit direction `l` reaching a blade point `height` metres
    /// above the ground where the local density is `ld`: the mask where the ray towards the
    /// light leaves the cylinder (none above the slab, or with the light straight overhead),
    /// through eq. 4.7. `grass_functions.wgsl`'s `shadow_mask_light` is its GPU twin.
    pub fn light_through(&self, height: f32, l: Vec3, ld: f32) -> f32 {
        let across = Vec2::new(l.x, l.z).length();
        if across < 1e-4 || self.radius <= 0.0 {
            return 1.0;
        }
        let exit = height + self.radius * l.y.max(0.0) / across;
        if exit >= self.slab_height {
            return 1.0;
        }
        let u = l.z.atan2(l.x) / std::f32::consts::TAU;
        let v = 1.0 - exit.max(0.0) / self.slab_height;
        masked_light(self.sample(u, v), ld)
    }
}

/// The slices' baked light directions, in the order of [`btf_weights`]: Y+, X+, X−, Z+, Z−.
pub const BTF_DIRECTIONS: [Vec3; 5] = [Vec3::Y, Vec3::X, Vec3::NEG_X, Vec3::Z, Vec3::NEG_Z];

/// Area of the spherical triangle with unit vertices `a`, `b`, `c` (its spherical excess, by
/// Van Oosterom and Strackee's formula: the same value as eq. A.3's angle sum, without the
/// arccosines' trouble near degenerate triangles).
fn spherical_area(a: Vec3, b: Vec3, c: Vec3) -> f32 {
    let numerator = a.dot(b.cross(c)).abs();
    let denominator = 1.0 + a.dot(b) + b.dot(c) + c.dot(a);
    2.0 * numerator.atan2(denominator)
}

/// Appendix A: the weights of the five baked directions ([`BTF_DIRECTIONS`]) for light from
/// unit direction `l`: in the quadrant of the upper hemisphere holding `l`, spanned by Y+ and one
/// of X± and one of Z±, each of the three gets the area of the spherical triangle `l` makes with
/// the other two over the quadrant's area π/2 (eq. A.2); the other two directions get 0. The
/// weights sum to 1, give a baked direction all its weight when `l` is it, and change
/// continuously from one quadrant to the next. A light below the horizon is taken at the
/// horizon (the slices were baked from above).
pub fn btf_weights(l: Vec3) -> [f32; 5] {
    let l = Vec3::new(l.x, l.y.max(0.0), l.z);
    let l = if l.length_squared() > 1e-12 {
        l.normalize()
    } else {
        Vec3::Y
    };
    let (x_index, x) = if l.x >= 0.0 {
        (1, Vec3::X)
    } else {
        (2, Vec3::NEG_X)
    };
    let (z_index, z) = if l.z >= 0.0 {
        (3, Vec3::Z)
    } else {
        (4, Vec3::NEG_Z)
    };
    let y = Vec3::Y;
    let quarter = std::f32::consts::FRAC_PI_2;
    let mut w = [0.0; 5];
    // Each direction's weight is the triangle opposite it.
    w[0] = spherical_area(l, x, z) / quarter;
    w[x_index] = spherical_area(l, y, z) / quarter;
    w[z_index] = spherical_area(l, y, x) / quarter;
    // The three triangles partition the quadrant; rounding aside they sum to 1.
    let sum: f32 = w.iter().sum();
    w.map(|v| v / sum)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bevy's polynomial, worked by hand: at roughness 1 the scale is 0.4524 whatever the angle
    /// (the bias clamps to 5e-5); the blades' specular at normal incidence.
    #[test]
    fn the_ambient_follows_bevy_s_environment_brdf() {
        for n_dot_v in [0.05, 0.3, 1.0] {
            let ab = f_ab(1.0, n_dot_v);
            assert!((ab - Vec2::new(0.4524, 0.00005)).length() < 1e-6, "{ab}");
        }
        let ab = f_ab(0.8, 1.0);
        assert!((ab - Vec2::new(0.560745, 0.00005)).length() < 1e-5, "{ab}");
        // kd·ao 0.2, γ 0.25, no terrain occlusion: 0.4524·0.2 + 2·5e-5 diffuse, the specular.
        let specular = (0.0144 * 0.560745 + 0.00005) * 0.7128;
        let c = slice_ambient(Vec3::splat(0.2), 0.25, 1.0, Vec3::ONE, 1.0);
        let want = 0.4524 * 0.2 + 2.0 * 0.00005 + specular;
        assert!((c - Vec3::splat(want)).length() < 1e-5, "{c} vs {want}");
        // The terrain's occlusion darkens the reflected share only.
        let dark = slice_ambient(Vec3::splat(0.2), 0.25, 1.0, Vec3::ONE, 0.0);
        assert!(
            (dark - Vec3::splat(0.4524 * 0.2 * 0.25 + 0.00005)).length() < 1e-5,
            "{dark}"
        );
    }
    use crate::rng::SplitMix64;

    #[test]
    fn eq_4_1_lights_the_front_and_transmits_to_the_back() {
        let kd = Vec3::new(0.2, 0.5, 0.1);
        let n = Vec3::Z;
        let l = Vec3::new(0.0, 0.6, 0.8);
        let front = blade_radiance(kd, 1.0, 0.0, n, l, 0.3, 2.0, 0.0, 10.0);
        assert!((front - kd * 0.8 * 2.0).length() < 1e-6);
        // Seen from the other face, γ of it.
        let back = blade_radiance(kd, 1.0, 0.0, -n, l, 0.3, 2.0, 0.0, 10.0);
        assert!((back - kd * 0.8 * 0.3 * 2.0).length() < 1e-6);
        // Attenuation and ambient.
        let far = blade_radiance(kd, 0.5, 0.4, n, l, 0.3, 2.0, 0.01, 10.0);
        assert!((far - (kd * 0.5 * 0.4 + kd * 0.8 * 2.0 / 2.0)).length() < 1e-6);
        assert_eq!(blade_ao(0.0, 0.3), 0.3);
        assert_eq!(blade_ao(1.0, 0.3), 1.0);
        assert!((blade_ao(0.5, 0.3) - 0.65).abs() < 1e-6);
        assert_eq!(masked_light(0.2, 0.0), 1.0, "no neighbours, no shadow");
        assert!((masked_light(0.2, 0.5) - 0.6).abs() < 1e-6);
        assert!((masked_light(0.2, 1.0) - 0.2).abs() < 1e-6);
    }

    #[test]
    fn the_btf_weights_are_spherical_barycentric() {
        // At a baked direction, all of its weight.
        for (i, d) in BTF_DIRECTIONS.iter().enumerate() {
            let w = btf_weights(*d);
            assert!((w[i] - 1.0).abs() < 1e-5, "{d}: {w:?}");
        }
        // Eq. A.6 itself for a light in the X+ Y+ Z+ quadrant: α_x = A(LBC)/(π/2).
        let l = Vec3::new(0.3, 0.8, 0.5).normalize();
        let a_lbc = (l.z / (l.z * l.z + l.x * l.x).sqrt()).acos()
            + (l.y / (l.x * l.x + l.y * l.y).sqrt()).acos()
            + (-l.y * l.z / ((l.z * l.z + l.x * l.x).sqrt() * (l.x * l.x + l.y * l.y).sqrt()))
                .acos()
            - std::f32::consts::PI;
        let w = btf_weights(l);
        assert!(
            (w[1] - a_lbc / std::f32::consts::FRAC_PI_2).abs() < 1e-4,
            "{w:?} vs {a_lbc}"
        );
        assert_eq!((w[2], w[4]), (0.0, 0.0));
        // On the great circle between Y+ and X+, Z+ gets nothing and the rest splits by angle.
        let mid = Vec3::new(1.0, 1.0, 0.0).normalize();
        let w = btf_weights(mid);
        assert!(w[3].abs() < 1e-5 && (w[0] - 0.5).abs() < 1e-4 && (w[1] - 0.5).abs() < 1e-4);
        // Random lights: the weights sum to 1, lie in [0, 1], and change continuously across
        // quadrant boundaries (x or z crossing 0).
        let mut rng = SplitMix64::new(5);
        for _ in 0..10_000 {
            let l = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(0.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            if l.length() < 0.1 {
                continue;
            }
            let w = btf_weights(l);
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            assert!(w.iter().all(|v| (-1e-6..=1.0 + 1e-6).contains(v)));
            let across = btf_weights(Vec3::new(-l.x.signum() * 1e-6, l.y, l.z));
            let here = btf_weights(Vec3::new(l.x.signum() * 1e-6, l.y, l.z));
            let jump: f32 = across.iter().zip(&here).map(|(a, b)| (a - b).abs()).sum();
            assert!(jump < 1e-3, "{l}: {here:?} vs {across:?}");
        }
        // Below the horizon: as at the horizon.
        let below = btf_weights(Vec3::new(1.0, -0.5, 0.0));
        assert!((below[1] - 1.0).abs() < 1e-5);
    }

    #[test]
    fn the_shadow_mask_darkens_low_points_under_a_low_sun_and_thins_with_density() {
        // A slab whose lower half is all blades, upper half clear.
        let mask =
            ShadowMask::from_coverage(16, 8, |_, y| if y >= 4 { 1.0 } else { 0.0 }, 0.5, 0.4);
        assert!((mask.radius - 0.5 / std::f32::consts::TAU).abs() < 1e-6);
        let low_sun = Vec3::new(1.0, 0.2, 0.0).normalize();
        // A root under a low sun: the ray leaves the cylinder among the blades.
        assert!(mask.light_through(0.02, low_sun, 1.0) < 0.05);
        // Sparse grass lets more through (eq. 4.7), none gives no shadow.
        let sparse = mask.light_through(0.02, low_sun, 0.3);
        assert!((sparse - 0.7).abs() < 0.06, "{sparse}");
        assert_eq!(mask.light_through(0.02, low_sun, 0.0), 1.0);
        // A tip above the blades, the sun overhead, or above the slab: lit.
        assert!(mask.light_through(0.35, low_sun, 1.0) > 0.95);
        assert_eq!(mask.light_through(0.02, Vec3::Y, 1.0), 1.0);
        assert_eq!(mask.light_through(0.5, low_sun, 1.0), 1.0);
        // A higher sun lifts the exit point out of the blades.
        let high_sun = Vec3::new(1.0, 3.0, 0.0).normalize();
        assert!(mask.light_through(0.1, high_sun, 1.0) > mask.light_through(0.1, low_sun, 1.0));
        // The mask wraps around the cylinder.
        assert!((mask.sample(0.01, 0.3) - mask.sample(1.01, 0.3)).abs() < 1e-6);
        assert_eq!(ShadowMask::clear().light_through(0.0, low_sun, 1.0), 1.0);
    }
}
