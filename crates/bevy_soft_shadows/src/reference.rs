//! The ground truth soft shadows are measured against (issue 6): the same scene lit by many
//! hard-shadowed lights jittered over the area light's disk, averaged in linear light. Each light
//! carries `1/n` of the illuminance, so the average of `n` renders with one jittered light each
//! equals one render with all `n` — light is additive — without `n` shadow maps at once.
//!
//! Also the measurement the render tests share: the 10–90 % width of a penumbra along a line of
//! pixels.

use bevy::math::{Vec2, Vec3};

/// `n` points spread evenly over the unit disk (Vogel's golden-angle spiral: equal area per
/// point, no clumping, deterministic).
pub fn disk_samples(n: usize) -> Vec<Vec2> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|i| {
            let r = ((i as f32 + 0.5) / n as f32).sqrt();
            let a = i as f32 * golden;
            Vec2::new(r * a.cos(), r * a.sin())
        })
        .collect()
}

/// Directions to `n` points of a directional light of `angular_diameter` (radians) centred on
/// `direction_to_light`, spread over its disk by [`disk_samples`].
pub fn jittered_directions(direction_to_light: Vec3, angular_diameter: f32, n: usize) -> Vec<Vec3> {
    let d = direction_to_light.normalize();
    let (t, b) = d.any_orthonormal_pair();
    let radius = (0.5 * angular_diameter).tan();
    disk_samples(n)
        .into_iter()
        .map(|s| (d + radius * (s.x * t + s.y * b)).normalize())
        .collect()
}

/// `n` positions spread evenly over a disk light of `diameter` centred on `centre` and facing
/// along `axis` (a spot light's disk, perpendicular to where it points): the local lights whose
/// average is an area spot light.
pub fn jittered_positions(centre: Vec3, axis: Vec3, diameter: f32, n: usize) -> Vec<Vec3> {
    let (t, b) = axis.normalize().any_orthonormal_pair();
    disk_samples(n)
        .into_iter()
        .map(|s| centre + 0.5 * diameter * (s.x * t + s.y * b))
        .collect()
}

/// sRGB-encoded 8-bit value to linear.
pub fn srgb_to_linear(v: u8) -> f32 {
    let c = v as f32 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear value to sRGB-encoded 8-bit.
pub fn linear_to_srgb(v: f32) -> u8 {
    let c = v.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// Averages RGBA8 sRGB renders in linear light.
#[derive(Clone, Debug, Default)]
pub struct LinearAverage {
    sum: Vec<f64>,
    count: usize,
}

impl LinearAverage {
    /// Adds one render (`rgba`: sRGB-encoded RGBA8, same size every time; alpha is averaged
    /// as is).
    pub fn add(&mut self, rgba: &[u8]) {
        if self.sum.is_empty() {
            self.sum = vec![0.0; rgba.len()];
        }
        assert_eq!(self.sum.len(), rgba.len(), "renders of different sizes");
        for (i, (s, &v)) in self.sum.iter_mut().zip(rgba).enumerate() {
            *s += if i % 4 == 3 {
                v as f64 / 255.0
            } else {
                srgb_to_linear(v) as f64
            };
        }
        self.count += 1;
    }

    /// Renders added so far.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The mean in linear light (RGBA, alpha in 0–1).
    pub fn linear(&self) -> Vec<f32> {
        let n = self.count.max(1) as f64;
        self.sum.iter().map(|s| (s / n) as f32).collect()
    }

    /// The mean, encoded back to sRGB RGBA8.
    pub fn srgb8(&self) -> Vec<u8> {
        self.linear()
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                if i % 4 == 3 {
                    (v * 255.0).round() as u8
                } else {
                    linear_to_srgb(v)
                }
            })
            .collect()
    }
}

/// Width (in samples, interpolated) over which `profile` — a visibility rising from shadow to
/// light along a line — goes from `lo` to `hi` (e.g. 0.1 to 0.9): the first crossing of each
/// level. `None` if the profile never crosses them in that order.
pub fn rise_width(profile: &[f32], lo: f32, hi: f32) -> Option<f32> {
    let crossing = |level: f32| {
        profile.windows(2).enumerate().find_map(|(i, w)| {
            (w[0] < level && w[1] >= level).then(|| i as f32 + (level - w[0]) / (w[1] - w[0]))
        })
    };
    let (a, b) = (crossing(lo)?, crossing(hi)?);
    (b >= a).then_some(b - a)
}

/// The 10–90 % width of a disk light's penumbra as a fraction of its full width (eq. 6.1's
/// `w`), from [`crate::ssss::penumbra::disk_visibility`].
pub fn disk_rise_fraction() -> f32 {
    let profile: Vec<f32> = (0..=2000)
        .map(|i| crate::ssss::penumbra::disk_visibility(i as f32 / 1000.0 - 1.0, 2.0))
        .collect();
    rise_width(&profile, 0.1, 0.9).expect("the disk profile rises") / 2000.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disk_samples_cover_the_disk_uniformly() {
        let s = disk_samples(256);
        assert!(s.iter().all(|p| p.length() <= 1.0));
        let mean = s.iter().copied().sum::<Vec2>() / 256.0;
        assert!(mean.length() < 0.02, "{mean}");
        // E[r²] of a uniform unit disk is 1/2; a quarter of the points inside r = 1/2.
        let r2 = s.iter().map(|p| p.length_squared()).sum::<f32>() / 256.0;
        assert!((r2 - 0.5).abs() < 0.01, "{r2}");
        let inner = s.iter().filter(|p| p.length() < 0.5).count();
        assert_eq!(inner, 64);
    }

    #[test]
    fn jittered_directions_fill_the_lights_disk() {
        let d = Vec3::new(1.0, 1.0, 0.3).normalize();
        let theta = 0.2f32;
        let dirs = jittered_directions(d, theta, 64);
        let mut widest = 0.0f32;
        for v in &dirs {
            assert!((v.length() - 1.0).abs() < 1e-5);
            widest = widest.max(v.angle_between(d));
        }
        assert!(
            widest <= 0.5 * theta + 1e-4 && widest > 0.45 * theta,
            "{widest}"
        );
        let mean = dirs.iter().copied().sum::<Vec3>().normalize();
        assert!(mean.angle_between(d) < 0.005);
    }

    #[test]
    fn jittered_positions_fill_the_spot_lights_disk() {
        let (centre, axis, d) = (Vec3::new(3.0, 6.0, 0.0), Vec3::new(-4.5, -6.0, 0.0), 0.6);
        let points = jittered_positions(centre, axis, d, 64);
        let mut widest = 0.0f32;
        for p in &points {
            // In the disk's plane, within its radius.
            assert!((*p - centre).dot(axis.normalize()).abs() < 1e-5);
            widest = widest.max(p.distance(centre));
        }
        assert!(widest <= 0.5 * d + 1e-5 && widest > 0.45 * d, "{widest}");
        let mean = points.iter().copied().sum::<Vec3>() / 64.0;
        assert!(mean.distance(centre) < 0.01 * d, "{mean}");
    }

    #[test]
    fn averaging_is_in_linear_light() {
        let mut avg = LinearAverage::default();
        avg.add(&[0, 0, 0, 255]);
        avg.add(&[255, 255, 255, 255]);
        // Half of white in linear light is sRGB 188, not 128.
        assert_eq!(avg.srgb8(), vec![188, 188, 188, 255]);
        assert_eq!(avg.count(), 2);
        for v in 0..=255u8 {
            assert_eq!(linear_to_srgb(srgb_to_linear(v)), v);
        }
    }

    #[test]
    fn rise_width_of_a_ramp_and_of_a_disk() {
        let ramp: Vec<f32> = (0..=20)
            .map(|i| (i as f32 / 20.0).clamp(0.0, 1.0))
            .collect();
        let w = rise_width(&ramp, 0.1, 0.9).unwrap();
        assert!((w - 16.0).abs() < 1e-4, "{w}");
        assert_eq!(rise_width(&[1.0, 0.0, 0.0], 0.1, 0.9), None);
        let k = disk_rise_fraction();
        assert!((0.5..0.75).contains(&k), "{k}");
    }
}
