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
/// neighbouring leaves (eq. 5.24). A leaf's reflectances and transmittances are `optics` times its
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
}
