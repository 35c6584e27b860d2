//! The switch and the inputs of the tree lighting in the leaf shaders (Boulanger 2008, ch. 5):
//! whether leaves are lit as a volume ([`super::model`], evaluated per leaf vertex) or by Bevy's
//! PBR, the leaves' optics, the ground's albedo for the light coming from below, and which
//! estimate of the sun through the crown to use.

use super::model::{LeafMaterial, SunThroughCrown};
use bevy::prelude::*;

/// How pruned leaves are lit (a reflected resource).
///
/// With `enabled`, every leaf material's main pass drops Bevy's PBR lighting for the light of
/// [`super::model::leaf_radiance`], computed per leaf vertex from the leaf's eight baked
/// attenuations and the crown's extinction τ: the sky (Bevy's `GlobalAmbientLight`, its colour
/// times its brightness, as the radiance of the upper hemisphere) and the ground under it
/// (that radiance times `ground_albedo`) through the crown (eq. 5.6); the sun — the brightest
/// `DirectionalLight` — through the crown (eq. 5.8); and one bounce of the sun's light off the
/// neighbouring leaves (eq. 5.24), scaled by each leaf's gathered ratios (blended from the
/// bake's fourteen suns, or read off its type's ring re-gathered at the sun's elevation,
/// `bounce_ring`). A leaf's reflectances and transmittances are `optics` times its
/// material's base colour (linear), and its texture's colour multiplies the light it sends, so
/// leaves keep their materials' colours. The sun's direct light on a leaf goes through Bevy's
/// shadow map of the sun read at the leaf where the map's texels are at most half the leaf
/// (leaf-on-leaf shadows; each of the four texels compared with the depth of the leaf's own
/// plane there, so a leaf never shades itself and the leaf in front is never let through;
/// measured closer to a path tracer than the baked attenuations: [`super::sun_maps`]; the
/// cascades nearer the eye, or a larger `DirectionalLightShadowMap`, reach that); where they
/// are a leaf or larger, through the crown's baked
/// attenuations times the shadow map read on the plane touching the crown's bounding sphere on
/// the sun's side (what stands outside the crown, its own leaves not counted twice); a smooth
/// hand-over between. Screen-space soft shadows are not read in this mode, and an environment
/// map light is not part of the sky. Prepasses and shadow maps are unchanged.
#[derive(Resource, Clone, Debug, PartialEq, Reflect)]
#[reflect(Resource, Default, Debug, PartialEq)]
pub struct TreeLightingSettings {
    /// Light leaves as a volume (off: Bevy's PBR lighting).
    pub enabled: bool,
    /// The leaves' reflectances and transmittances (eq. 5.4) as multiples of their material's
    /// base colour: ρ_rf = `reflectance_front` × base colour, and so on.
    pub optics: LeafMaterial,
    /// Albedo of the ground under the trees: the lower hemisphere's radiance is the sky's times
    /// this (§5.3.1).
    pub ground_albedo: Vec3,
    /// Which estimate of the sun's light through the crown the leaves use.
    pub sun_through_crown: SunThroughCrown,
    /// Add one bounce of sunlight off the neighbouring leaves (eq. 5.24).
    pub bounce: bool,
    /// Scale the bounce on each face of a leaf by its baked ratios of the bounce gathered from
    /// its own neighbours to eq. 5.24's ([`crate::lighting::gathered_bounce`]; a bake without
    /// them leaves eq. 5.24 as it is).
    pub gathered_bounce: bool,
    /// Scale each leaf's sky and blended sun by its baked gain towards the eye, and its bounce
    /// by the covered part's gain: the part of a leaf in view is more open than the leaf's mean
    /// ([`crate::lighting::seen_part`]); and apply the crown's hotspot by the angle between
    /// the eye and the sun, measured with those gains ([`crate::lighting::hotspot`]).
    pub seen_part: bool,
    /// Re-gather each tree type's bounce ratios, while the app runs, on a ring of suns at the
    /// sun's elevation ([`crate::lighting::bounce_ring`]), which the leaves read where the sun
    /// is at it (with `gathered_bounce`).
    pub bounce_ring: BounceRingSettings,
}

/// How the bounce ratios are re-gathered on a ring of suns at the sun's elevation while the app
/// runs ([`crate::lighting::bounce_ring`]): in the background, one task per tree type, each
/// time the sun's elevation has moved `regather_degrees` from the last ring. Upright instances
/// (turned about their vertical only) take the ring at any turn; a tilted one, or any while the
/// sun is more than [`RING_FULL_DEGREES`](crate::lighting::bounce_ring::RING_FULL_DEGREES) of
/// elevation from its type's ring, takes the bake's blend over fourteen suns in part or whole.
#[derive(Clone, Debug, PartialEq, Reflect)]
#[reflect(Default, Debug, PartialEq)]
pub struct BounceRingSettings {
    /// Gather rings and read them in the leaf shaders (off: the bake's blend alone).
    pub enabled: bool,
    /// Rays a leaf casts over its two sides; at each neighbour hit the neighbour's sunlit share
    /// towards each of the ring's fourteen suns is read off its plane (with
    /// [`BounceRingSettings::sunlit_points`]) or found by a shadow ray (without).
    pub rays: u32,
    /// Passes of [`BounceRingSettings::rays`] rays a leaf a ring's ratios are refined to while
    /// the sun stays at its elevation: the first lands at once, each further pass, its rays
    /// shifted anew, is averaged in as it comes
    /// ([`crate::lighting::bounce_ring::RingRefinement`]); 1: the first alone. While refined a
    /// ring holds about half a kilobyte a leaf (its passes' sums, the sunlit planes they read),
    /// let go once it has its passes; raised after that, the ring is gathered anew.
    pub passes: u32,
    /// Points a leaf its sunlit share towards each of the ring's suns is traced from, the share
    /// fitted with a plane over the leaf ([`crate::lighting::sunlit_share`]), which the leaves
    /// take for the sun through the crown where the sun's shadow map does not resolve leaves;
    /// 0: none traced, the bake's blend there (a ring gathered with or without shares is
    /// gathered again when this changes).
    pub sunlit_points: u32,
    /// Degrees of elevation the sun moves from a tree type's ring before a new one is gathered.
    pub regather_degrees: f32,
    /// Threads each re-gather runs on (0: half the machine's, at least one).
    pub threads: usize,
}

impl Default for BounceRingSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            rays: crate::lighting::gathered_bounce::DEFAULT_BOUNCE_RAYS,
            passes: crate::lighting::bounce_ring::DEFAULT_RING_PASSES,
            sunlit_points: crate::lighting::sunlit_share::DEFAULT_SUNLIT_POINTS,
            regather_degrees: crate::lighting::bounce_ring::DEFAULT_REGATHER_DEGREES,
            threads: 0,
        }
    }
}

impl BounceRingSettings {
    /// The threads a re-gather runs on: `threads`, or for 0 half of `available` (at least one).
    pub fn threads_of(&self, available: usize) -> usize {
        if self.threads == 0 {
            (available / 2).max(1)
        } else {
            self.threads
        }
    }
}

impl Default for TreeLightingSettings {
    fn default() -> Self {
        Self {
            enabled: false,
            optics: LeafMaterial {
                reflectance_front: Vec3::splat(0.8),
                reflectance_back: Vec3::splat(1.0),
                transmittance_front: Vec3::splat(0.6),
                transmittance_back: Vec3::splat(0.6),
            },
            ground_albedo: Vec3::new(0.2, 0.25, 0.15),
            sun_through_crown: SunThroughCrown::default(),
            bounce: true,
            gathered_bounce: true,
            seen_part: true,
            bounce_ring: BounceRingSettings::default(),
        }
    }
}

impl TreeLightingSettings {
    /// These settings with every optic and the ground's albedo clamped into `[0, 1]` (NaN to 0),
    /// and a description of each fix.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let mut out = self.clone();
        let mut fixes = Vec::new();
        let (optics, changed) = self.optics.sanitized();
        if changed {
            fixes.push(format!(
                "leaf optics {:?} must lie in [0, 1]: clamped",
                self.optics
            ));
            out.optics = optics;
        }
        let albedo = Vec3::from_array(
            self.ground_albedo
                .to_array()
                .map(|x| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) }),
        );
        if albedo != self.ground_albedo {
            fixes.push(format!(
                "ground albedo {} must lie in [0, 1]: clamped",
                self.ground_albedo
            ));
            out.ground_albedo = albedo;
        }
        use crate::lighting::bounce_ring::RING_FULL_DEGREES;
        use crate::lighting::gathered_bounce::MAX_BOUNCE_RAYS;
        let ring = &self.bounce_ring;
        if ring.rays == 0 || ring.rays > MAX_BOUNCE_RAYS {
            fixes.push(format!(
                "bounce ring rays {} must lie in [1, {MAX_BOUNCE_RAYS}]: clamped",
                ring.rays
            ));
            out.bounce_ring.rays = ring.rays.clamp(1, MAX_BOUNCE_RAYS);
        }
        use crate::lighting::bounce_ring::MAX_RING_PASSES;
        if ring.passes == 0 || ring.passes > MAX_RING_PASSES {
            fixes.push(format!(
                "bounce ring passes {} must lie in [1, {MAX_RING_PASSES}]: clamped",
                ring.passes
            ));
            out.bounce_ring.passes = ring.passes.clamp(1, MAX_RING_PASSES);
        }
        // Above the ring's whole span the ring in use would fade before its successor is asked
        // for; below a hundredth of a degree every frame of a moving sun would ask for one.
        if !(ring.regather_degrees >= 0.01 && ring.regather_degrees <= RING_FULL_DEGREES) {
            let fixed = if ring.regather_degrees.is_nan() {
                crate::lighting::bounce_ring::DEFAULT_REGATHER_DEGREES
            } else {
                ring.regather_degrees.clamp(0.01, RING_FULL_DEGREES)
            };
            fixes.push(format!(
                "bounce ring re-gather angle {}° must lie in [0.01, {RING_FULL_DEGREES}]: {fixed}°",
                ring.regather_degrees
            ));
            out.bounce_ring.regather_degrees = fixed;
        }
        use crate::lighting::sunlit_share::MAX_SUNLIT_POINTS;
        if ring.sunlit_points > MAX_SUNLIT_POINTS {
            fixes.push(format!(
                "bounce ring sunlit points {} must be at most {MAX_SUNLIT_POINTS}: clamped",
                ring.sunlit_points
            ));
            out.bounce_ring.sunlit_points = MAX_SUNLIT_POINTS;
        }
        if ring.threads > 1024 {
            fixes.push(format!(
                "bounce ring threads {} is absurd: 0 (half the machine's)",
                ring.threads
            ));
            out.bounce_ring.threads = 0;
        }
        (out, fixes)
    }
}

/// Replaces invalid settings with corrected ones, logging each correction.
pub(crate) fn sanitize_tree_lighting(mut settings: ResMut<TreeLightingSettings>) {
    let (fixed, fixes) = settings.sanitized();
    if !fixes.is_empty() {
        for fix in &fixes {
            warn!("TreeLightingSettings: {fix}");
        }
        *settings = fixed;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_optics_and_albedo_are_clamped_and_reported() {
        let bad = TreeLightingSettings {
            optics: LeafMaterial {
                reflectance_front: Vec3::new(f32::NAN, 2.0, -1.0),
                ..default()
            },
            ground_albedo: Vec3::new(0.5, f32::NAN, 3.0),
            ..default()
        };
        let (fixed, fixes) = bad.sanitized();
        assert_eq!(fixes.len(), 2, "{fixes:?}");
        assert_eq!(fixed.optics.reflectance_front, Vec3::new(0.0, 1.0, 0.0));
        assert_eq!(fixed.ground_albedo, Vec3::new(0.5, 0.0, 1.0));
        let (same, none) = TreeLightingSettings::default().sanitized();
        assert!(none.is_empty());
        assert_eq!(same, TreeLightingSettings::default());
    }

    #[test]
    fn absurd_ring_settings_are_corrected_and_reported() {
        let bad = TreeLightingSettings {
            bounce_ring: BounceRingSettings {
                enabled: true,
                rays: 0,
                passes: 0,
                sunlit_points: u32::MAX,
                regather_degrees: f32::NAN,
                threads: 1 << 20,
            },
            ..default()
        };
        let (fixed, fixes) = bad.sanitized();
        assert_eq!(fixes.len(), 5, "{fixes:?}");
        assert_eq!(fixed.bounce_ring.rays, 1);
        assert_eq!(fixed.bounce_ring.passes, 1);
        assert_eq!(
            fixed.bounce_ring.sunlit_points,
            crate::lighting::sunlit_share::MAX_SUNLIT_POINTS
        );
        assert_eq!(
            fixed.bounce_ring.regather_degrees,
            crate::lighting::bounce_ring::DEFAULT_REGATHER_DEGREES
        );
        assert_eq!(fixed.bounce_ring.threads, 0);
        let wide = TreeLightingSettings {
            bounce_ring: BounceRingSettings {
                regather_degrees: 90.0,
                ..default()
            },
            ..default()
        };
        assert_eq!(
            wide.sanitized().0.bounce_ring.regather_degrees,
            crate::lighting::bounce_ring::RING_FULL_DEGREES
        );
        assert_eq!(BounceRingSettings::default().threads_of(16), 8);
        assert_eq!(BounceRingSettings::default().threads_of(1), 1);
    }
}
