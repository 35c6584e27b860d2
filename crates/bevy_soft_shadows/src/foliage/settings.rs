//! The component that gives a sun a world-space opacity shadow map of the trees.

use bevy::prelude::*;

/// Put on a shadow-casting `DirectionalLight` (the sun): the trees inside `bounds_min..=bounds_max`
/// cast their leaves' shadows through a world-space opacity shadow map (Boulanger 2008, §5.5.2;
/// [`super::opacity_map`] is the algorithm as plain Rust) instead of Bevy's shadow map — dark
/// where leaves pile up along the sun's rays, light where they are sparse, softening with the
/// distance from the leaves to the ground.
///
/// Casters are drawn into it by the crates that own them (`bevy_foliage`'s pruned leaves draw the
/// light's own pruned selection, area-compensated); [`SoftShadowMaterial`](crate::SoftShadowMaterial)
/// receivers multiply the light's shadow term by the map's transmittance. While the map is on,
/// `bevy_foliage` takes the pruned leaves out of Bevy's shadow maps (otherwise the ground would be
/// darkened twice).
#[derive(Component, Clone, Copy, Debug, PartialEq, Reflect)]
#[reflect(Component, Debug, PartialEq, Default)]
pub struct TreeOpacityShadows {
    /// Texels across and down the map (a power of two, 16..=4096).
    pub resolution: u32,
    /// The lowest corner of the world box holding every caster.
    pub bounds_min: Vec3,
    /// The highest corner of that box.
    pub bounds_max: Vec3,
    /// The map plane's height (the thesis' `planeY`): the lowest ground under the trees. Shadows
    /// are received at and above it.
    pub plane_y: f32,
    /// The sun's angular diameter in radians (the sun is 0.0093): the penumbra widens by this
    /// many metres per metre between leaves and receiver.
    pub sun_angle: f32,
}

impl Default for TreeOpacityShadows {
    fn default() -> Self {
        Self {
            resolution: 1024,
            bounds_min: Vec3::new(-50.0, 0.0, -50.0),
            bounds_max: Vec3::new(50.0, 30.0, 50.0),
            plane_y: 0.0,
            sun_angle: 0.02,
        }
    }
}

impl TreeOpacityShadows {
    /// The smallest map side.
    pub const MIN_RESOLUTION: u32 = 16;
    /// The largest map side (64 MiB of accumulation at 4096², 128 MiB with the map's mips).
    pub const MAX_RESOLUTION: u32 = 4096;
    /// The widest sun accepted (radians, about 11°).
    pub const MAX_SUN_ANGLE: f32 = 0.2;

    /// The settings with every unusable value replaced, and a sentence per replacement.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let mut out = *self;
        let mut fixes = Vec::new();
        let resolution = out
            .resolution
            .clamp(Self::MIN_RESOLUTION, Self::MAX_RESOLUTION)
            .next_power_of_two()
            .min(Self::MAX_RESOLUTION);
        if resolution != out.resolution {
            fixes.push(format!(
                "resolution {} must be a power of two in {}..={}: using {resolution}",
                out.resolution,
                Self::MIN_RESOLUTION,
                Self::MAX_RESOLUTION
            ));
            out.resolution = resolution;
        }
        let default = Self::default();
        if !(out.bounds_min.is_finite() && out.bounds_max.is_finite())
            || out.bounds_min.cmpgt(out.bounds_max).any()
        {
            fixes.push(format!(
                "bounds {}..={} are not a finite box: using {}..={}",
                out.bounds_min, out.bounds_max, default.bounds_min, default.bounds_max
            ));
            out.bounds_min = default.bounds_min;
            out.bounds_max = default.bounds_max;
        }
        if !out.plane_y.is_finite() {
            fixes.push(format!(
                "plane_y = {} is not finite: using bounds_min.y = {}",
                out.plane_y, out.bounds_min.y
            ));
            out.plane_y = out.bounds_min.y;
        }
        if !(out.sun_angle.is_finite() && (0.0..=Self::MAX_SUN_ANGLE).contains(&out.sun_angle)) {
            let angle = if out.sun_angle.is_finite() {
                out.sun_angle.clamp(0.0, Self::MAX_SUN_ANGLE)
            } else {
                default.sun_angle
            };
            fixes.push(format!(
                "sun_angle = {} is outside 0..={}: using {angle}",
                out.sun_angle,
                Self::MAX_SUN_ANGLE
            ));
            out.sun_angle = angle;
        }
        (out, fixes)
    }
}

/// Replaces unusable [`TreeOpacityShadows`] settings in place, with a warning naming each fix.
pub(crate) fn sanitize_tree_opacity_settings(
    mut lights: Query<(Entity, &mut TreeOpacityShadows), Changed<TreeOpacityShadows>>,
) {
    for (entity, mut settings) in &mut lights {
        let (fixed, fixes) = settings.sanitized();
        if !fixes.is_empty() {
            warn!("TreeOpacityShadows on {entity}: {}", fixes.join("; "));
            *settings = fixed;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_settings_are_corrected() {
        let (ok, fixes) = TreeOpacityShadows::default().sanitized();
        assert!(fixes.is_empty());
        assert_eq!(ok, TreeOpacityShadows::default());
        let (fixed, fixes) = TreeOpacityShadows {
            resolution: 1000,
            bounds_min: Vec3::new(1.0, f32::NAN, 0.0),
            plane_y: f32::INFINITY,
            sun_angle: -1.0,
            ..default()
        }
        .sanitized();
        assert_eq!(fixes.len(), 4, "{fixes:?}");
        assert_eq!(fixed.resolution, 1024);
        assert_eq!(fixed.bounds_min, TreeOpacityShadows::default().bounds_min);
        assert_eq!(fixed.plane_y, fixed.bounds_min.y);
        assert_eq!(fixed.sun_angle, 0.0);
        let (fixed, _) = TreeOpacityShadows {
            resolution: 1 << 20,
            bounds_min: Vec3::ONE,
            bounds_max: Vec3::ZERO,
            ..default()
        }
        .sanitized();
        assert_eq!(fixed.resolution, TreeOpacityShadows::MAX_RESOLUTION);
        assert!(fixed.bounds_min.cmple(fixed.bounds_max).all());
    }
}
