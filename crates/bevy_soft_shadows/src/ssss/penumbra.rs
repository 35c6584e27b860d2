//! Penumbra width: eq. 6.1 (Fernando 2005, parallel planes) and its screen-space form eq. 6.2
//! (Gumbau 2011, ch. 6), plus the Gaussian that stands in for an area light's penumbra and the
//! screen-space footprint of a surface disk (the anisotropic kernel's axes).

/// Eq. 6.1: world width of the penumbra behind a blocker at `d_blocker` from a light of size
/// `light_size`, on a receiver at `d_receiver` (distances from the light, parallel planes).
/// Zero when the receiver is not behind the blocker.
pub fn penumbra_width(d_receiver: f32, d_blocker: f32, light_size: f32) -> f32 {
    if d_blocker <= 0.0 {
        return 0.0;
    }
    ((d_receiver - d_blocker) * light_size / d_blocker).max(0.0)
}

/// Eq. 6.1 for a directional light, whose light is at infinity: `light_size / d_blocker` becomes
/// the light's angular width `2 tan(θ/2)` (θ = angular diameter in radians), so the penumbra
/// grows linearly with the blocker–receiver distance `receiver_minus_blocker` (m).
pub fn directional_penumbra_width(receiver_minus_blocker: f32, angular_diameter: f32) -> f32 {
    (receiver_minus_blocker * 2.0 * (0.5 * angular_diameter).tan()).max(0.0)
}

/// Eq. 6.2: the penumbra's width on screen, in pixels — the world width divided by the eye
/// distance `d_observer` (the thesis' extra term; the filter is applied in screen space) and
/// scaled by the projection's pixels per unit at unit distance (`P₁₁ · height / 2`).
pub fn screen_penumbra_px(world_width: f32, d_observer: f32, pixels_per_unit_at_1: f32) -> f32 {
    if d_observer <= 0.0 {
        return 0.0;
    }
    world_width * pixels_per_unit_at_1 / d_observer
}

/// Standard deviation of the Gaussian that replaces a penumbra of `width`.
///
/// Across the penumbra of a disk light, a point sees the part of the disk beyond the blocker's
/// edge, so visibility is the cumulative distribution of one coordinate of a uniform disk of
/// diameter `width`. That distribution has variance `R²/4` (`R = width/2`), so a Gaussian of
/// `σ = width/4` has the same spread (its CDF stays within 4.1 % of the disk's everywhere — tested
/// below; the best sup-norm fit, σ = 0.262·width, would only reach 3.0 %).
pub fn penumbra_sigma(width: f32) -> f32 {
    0.25 * width.max(0.0)
}

/// Visibility of a disk light of diameter `width` at signed offset `x` from the middle of its
/// penumbra (negative: towards the umbra): the share of the disk's area beyond the edge.
pub fn disk_visibility(x: f32, width: f32) -> f32 {
    if width <= 0.0 {
        return if x >= 0.0 { 1.0 } else { 0.0 };
    }
    let t = (2.0 * x / width).clamp(-1.0, 1.0);
    // Area of the unit disk with coordinate < t, over π.
    (t * (1.0 - t * t).sqrt() + t.asin() + std::f32::consts::FRAC_PI_2) / std::f32::consts::PI
}

/// The largest blocker gap a receiver can find in its own surface: the dilated map searches
/// `reach` metres around it, across which a plane at angle `acos(cos_nl)` to the light rises
/// towards it by `reach · tan`. Gaps no larger are the surface itself, not a blocker (the
/// distance pass treats them as "no penumbra"); `cos_nl` is clamped at 0.05 (grazing light).
pub fn own_surface_gap(reach: f32, cos_nl: f32) -> f32 {
    if cos_nl <= 0.0 {
        return 0.0;
    }
    reach * (1.0 - cos_nl * cos_nl).max(0.0).sqrt() / cos_nl.max(0.05)
}

/// Screen-space half extents (x, y) of a unit disk lying on a surface whose view-space normal is
/// `normal` (unit): the bounding box of the ellipse it projects to (locally orthographic). A
/// surface facing the camera keeps a round kernel; a floor seen at a grazing angle shrinks it
/// vertically. This is the axis-aligned form of the anisotropic kernel, so the two passes stay
/// horizontal and vertical.
pub fn kernel_axes(normal: [f32; 3]) -> [f32; 2] {
    let [nx, ny, _] = normal;
    [
        (1.0 - nx * nx).max(0.0).sqrt(),
        (1.0 - ny * ny).max(0.0).sqrt(),
    ]
}

/// erf by Abramowitz–Stegun 7.1.26 (|error| < 1.5e-7), for the tests' Gaussian CDFs.
#[cfg(test)]
pub(crate) fn erf(x: f32) -> f32 {
    let t = 1.0 / (1.0 + 0.3275911 * x.abs());
    let y = 1.0
        - (((((1.061_405_4 * t - 1.453_152_1) * t) + 1.421_413_8) * t - 0.284_496_72) * t
            + 0.254_829_6)
            * t
            * (-x * x).exp();
    y.copysign(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq_6_1_grows_with_blocker_receiver_distance_and_light_size() {
        // Blocker halfway between light and receiver: penumbra as wide as the light.
        assert!((penumbra_width(10.0, 5.0, 0.4) - 0.4).abs() < 1e-6);
        assert!((penumbra_width(15.0, 5.0, 0.4) - 0.8).abs() < 1e-6);
        assert_eq!(penumbra_width(4.0, 5.0, 0.4), 0.0, "receiver in front");
        assert_eq!(penumbra_width(4.0, 0.0, 0.4), 0.0, "degenerate blocker");
        // Directional: linear in distance; the Sun (0.53°) at 10 m gives ~9 cm.
        let sun = 0.53f32.to_radians();
        let w = directional_penumbra_width(10.0, sun);
        assert!((w - 0.0925).abs() < 1e-3, "{w}");
        assert!((directional_penumbra_width(20.0, sun) - 2.0 * w).abs() < 1e-6);
        // Far from the light, eq. 6.1 with d_blocker large approaches the directional form.
        let far = penumbra_width(1.0e4 + 10.0, 1.0e4, 1.0e4 * 2.0 * (0.5 * sun).tan());
        assert!((far - w).abs() < 1e-3);
    }

    #[test]
    fn eq_6_2_divides_by_the_eye_distance() {
        assert!((screen_penumbra_px(0.1, 10.0, 500.0) - 5.0).abs() < 1e-5);
        assert!((screen_penumbra_px(0.1, 20.0, 500.0) - 2.5).abs() < 1e-5);
        assert_eq!(screen_penumbra_px(0.1, 0.0, 500.0), 0.0);
    }

    #[test]
    fn the_gaussian_matches_a_disk_lights_penumbra() {
        let width = 2.0;
        let sigma = penumbra_sigma(width);
        let mut worst = 0.0f32;
        for i in -200..=200 {
            let x = i as f32 * 0.01;
            let gauss = 0.5 * (1.0 + erf(x / (sigma * std::f32::consts::SQRT_2)));
            worst = worst.max((gauss - disk_visibility(x, width)).abs());
        }
        assert!(worst < 0.041, "worst CDF difference {worst}");
        assert_eq!(disk_visibility(-1.0, width), 0.0);
        assert!((disk_visibility(0.0, width) - 0.5).abs() < 1e-6);
        assert!((disk_visibility(1.0, width) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn a_surface_is_not_its_own_blocker() {
        // Light straight above a floor: the floor never rises towards it.
        assert_eq!(own_surface_gap(0.5, 1.0), 0.0);
        // 45°: it rises as far as it reaches.
        assert!((own_surface_gap(0.5, std::f32::consts::FRAC_1_SQRT_2) - 0.5).abs() < 1e-5);
        // Facing away: no gap allowance (the light does not reach it anyway).
        assert_eq!(own_surface_gap(0.5, -0.3), 0.0);
        assert!(own_surface_gap(0.5, 0.0001) <= 0.5 * 20.0);
    }

    #[test]
    fn kernel_axes_follow_the_normal() {
        assert_eq!(kernel_axes([0.0, 0.0, 1.0]), [1.0, 1.0]);
        // A floor seen at 30° above the horizon: normal (0, cos 30°, sin 30°) in view space.
        let a = kernel_axes([0.0, 30f32.to_radians().cos(), 30f32.to_radians().sin()]);
        assert!(
            (a[0] - 1.0).abs() < 1e-6 && (a[1] - 0.5).abs() < 1e-6,
            "{a:?}"
        );
    }
}
