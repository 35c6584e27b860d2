//! The grass components and settings a game touches: a [`GrassField`] on an entity grows grass of
//! one [`GrassSpecies`] over a rectangle of ground, thinned by an optional density map; the
//! [`GrassSettings`] resource holds the transition distances and the cell walk's parameters,
//! shared by every field (a reflected resource, so the panel and inspectors can edit it live).

use super::ground::GrassWind;
use super::patch::PatchSettings;
use super::slice_mip::MipAlpha;
use super::transition::TransitionDistances;
use bevy::prelude::*;

/// One grass species: how its base patch is made and how its blades look.
#[derive(Clone, Debug, PartialEq, Reflect)]
#[reflect(Debug, PartialEq)]
pub struct GrassSpecies {
    /// The base patch (its side is the grid's cell).
    pub patch: PatchSettings,
    /// Blade colour at the root (linear; the diffuse reflectance `kd` of eq. 4.1).
    pub root_color: LinearRgba,
    /// Blade colour at the tip.
    pub tip_color: LinearRgba,
    /// Ambient occlusion at the root, rising linearly to 1 at the tip (§4.2.2).
    pub root_ao: f32,
    /// Light let through a blade to its unlit face (`γ` of eq. 4.1; Bevy's diffuse
    /// transmission).
    pub transmission: f32,
}

impl Default for GrassSpecies {
    fn default() -> Self {
        Self {
            patch: PatchSettings::default(),
            root_color: LinearRgba::rgb(0.035, 0.09, 0.02),
            tip_color: LinearRgba::rgb(0.22, 0.36, 0.08),
            root_ao: 0.35,
            transmission: 0.35,
        }
    }
}

impl GrassSpecies {
    /// This species with unusable values replaced, and what was replaced.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let (patch, mut fixes) = self.patch.sanitized();
        let mut s = Self {
            patch,
            ..self.clone()
        };
        for (name, v) in [
            ("root_ao", &mut s.root_ao),
            ("transmission", &mut s.transmission),
        ] {
            if !(0.0..=1.0).contains(v) {
                let fixed = if v.is_finite() {
                    v.clamp(0.0, 1.0)
                } else {
                    0.5
                };
                fixes.push(format!("{name} = {v} outside [0, 1]: using {fixed}"));
                *v = fixed;
            }
        }
        (s, fixes)
    }
}

/// Grows grass over a rectangle of ground: `size` metres (x, z) centred on the entity's
/// translation, on the plane `y = translation.y` (the field is axis-aligned; the entity's
/// rotation and scale are ignored).
///
/// The base patch is generated once per field from `species.patch` and repeated on a grid of
/// patch-sized cells, each cell showing one of its four mirrored versions (eq. 4.9). The field is
/// built when the component is added or changed (its slices baked again then, or read from the
/// cache); moving the entity afterwards does not move the grass.
#[derive(Component, Clone, Debug, Reflect)]
#[reflect(Component, Debug)]
#[require(Transform, Visibility)]
pub struct GrassField {
    /// Extent (x, z) in metres.
    pub size: Vec2,
    /// What grows.
    pub species: GrassSpecies,
    /// The species' density over the field (the first channel of an 8-, 16- or 32-bit image,
    /// 0 … 1; row 0 at the field's −z edge); `None`: full density everywhere. A map that cannot
    /// be read is a logged error and a [`GrassFieldError`] on the entity, and the field then
    /// grows at full density.
    pub density: Option<Handle<Image>>,
    /// The ground's height (m above the entity's plane) over the field, as a 32-bit float image
    /// (first channel; row 0 at the −z edge; [`height_map_image`] makes one from a function, a
    /// terrain's height query for one); `None`: flat. The grass follows it: the heights are
    /// sampled at the cell corners and every blade and slice lifted by eq. 4.10. A map that cannot
    /// be read is a logged error and a [`GrassFieldError`], and the field stays flat.
    ///
    /// [`height_map_image`]: super::ground_map::height_map_image
    pub ground: Option<Handle<Image>>,
    /// The terrain's ambient occlusion over the field (§4.2.6, fig. 4.17: the share of the sky
    /// each ground point sees past the terrain and other objects; first channel 0 … 1, read as a
    /// density map is; [`ambient_occlusion_map`] computes one from the ground's heights): the
    /// ambient light on blades and slices is multiplied by it. `None`: no occlusion. A map that
    /// cannot be read is a logged error and a [`GrassFieldError`].
    ///
    /// [`ambient_occlusion_map`]: super::ground::ambient_occlusion_map
    pub ambient_occlusion: Option<Handle<Image>>,
}

impl Default for GrassField {
    fn default() -> Self {
        Self {
            size: Vec2::splat(32.0),
            species: GrassSpecies::default(),
            density: None,
            ground: None,
            ambient_occlusion: None,
        }
    }
}

/// Why a field's density map or height map was not used (the field grows at full density, or
/// on flat ground, meanwhile).
#[derive(Component, Clone, Debug, PartialEq)]
pub struct GrassFieldError(pub String);

/// Settings shared by every grass field.
#[derive(Resource, Clone, Debug, PartialEq, Reflect)]
#[reflect(Resource, Debug, PartialEq)]
pub struct GrassSettings {
    /// Where blade geometry hands over to the slices, and the slices to the horizontal slice
    /// (fig. 4.11), and the transition window (fig. 4.13).
    pub transitions: TransitionDistances,
    /// Nothing is drawn beyond this distance (m).
    pub max_distance: f32,
    /// A quadtree node is drawn whole (a macro-cell) only when the eye is at least this many node
    /// sides from it.
    pub split_factor: f32,
    /// Draw blade geometry.
    pub geometry: bool,
    /// Draw the volume slices (vertical and horizontal) beyond the geometry.
    pub slices: bool,
    /// Vertical slices per axis in the base patch (`K`; 1..=32).
    pub slice_per_axis: u32,
    /// Texels a side of each slice image (8..=1024).
    pub slice_resolution: u32,
    /// How the slices' coarser mips make their alpha ([`MipAlpha`]: the mean by default, the
    /// blades' expected coverage, which the slices' per-quad dither adds up across layers as
    /// the blades do; the thesis' maximum keeps distant slices opaque whatever the ground
    /// between the blades). Read when a field's slices are made.
    pub slice_mip_alpha: MipAlpha,
    /// Darken the blades with the blade shadow mask (§4.2.6, eq. 4.7): the shadows of their
    /// neighbours, which a shadow map cannot resolve, on geometry and slices alike.
    pub shadow_mask: bool,
    /// The blade geometry casts into Bevy's shadow maps (the sun's cascades, other lights'
    /// maps): the blades shadow the ground, other objects and, coarsely, one another. Off, the
    /// blades are [`NotShadowCaster`](bevy::light::NotShadowCaster)s: every shadow pass skips
    /// them — the cascades draw each blade up to once per cascade, more than the blade pass
    /// itself — and their shadows on one another come from the blade shadow mask alone, as in
    /// the thesis (§4.2.6). The slices never cast.
    pub cast_shadow_maps: bool,
    /// The wind over every field (the map it reads is the [`GrassWindMap`] resource).
    ///
    /// [`GrassWindMap`]: super::ground_map::GrassWindMap
    pub wind: GrassWind,
    /// A folder to cache slice bakes in (`<species hash>.grassslices`); `None`: bake in memory
    /// at every start.
    #[reflect(ignore)]
    pub slice_cache: Option<std::path::PathBuf>,
}

impl Default for GrassSettings {
    fn default() -> Self {
        Self {
            transitions: TransitionDistances::default(),
            max_distance: 400.0,
            split_factor: 2.0,
            geometry: true,
            slices: true,
            slice_per_axis: 4,
            slice_resolution: 64,
            slice_mip_alpha: MipAlpha::Mean,
            shadow_mask: true,
            cast_shadow_maps: true,
            wind: GrassWind::default(),
            slice_cache: None,
        }
    }
}

impl GrassSettings {
    /// These settings with unusable values replaced, and what was replaced.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let mut s = self.clone();
        let mut fixes = Vec::new();
        if let Err(e) = s.transitions.validate() {
            fixes.push(format!("{e}: using the defaults"));
            s.transitions = TransitionDistances::default();
        }
        if !(s.max_distance.is_finite() && s.max_distance > 0.0) {
            fixes.push(format!(
                "max_distance = {} must be positive: using 400",
                s.max_distance
            ));
            s.max_distance = 400.0;
        }
        if !(s.split_factor.is_finite() && s.split_factor >= 1.0) {
            fixes.push(format!(
                "split_factor = {} must be at least 1: using 2",
                s.split_factor
            ));
            s.split_factor = 2.0;
        }
        let (wind, wind_fixes) = s.wind.sanitized();
        s.wind = wind;
        fixes.extend(wind_fixes);
        (s, fixes)
    }
}

/// Keeps [`GrassSettings`] usable: unusable values are replaced with a warning naming them.
pub fn sanitize_grass_settings(mut settings: ResMut<GrassSettings>) {
    let (fixed, fixes) = settings.sanitized();
    if !fixes.is_empty() {
        for fix in fixes {
            warn!("grass settings: {fix}");
        }
        *settings = fixed;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_settings_and_species_are_replaced_and_named() {
        let mut s = GrassSettings::default();
        assert!(s.sanitized().1.is_empty());
        s.transitions.max_geom = 1.0; // below min_geom
        s.max_distance = f32::NAN;
        s.split_factor = 0.0;
        s.wind.scale = -1.0;
        let (fixed, fixes) = s.sanitized();
        assert_eq!(fixes.len(), 4, "{fixes:?}");
        assert!(fixed.sanitized().1.is_empty());
        let species = GrassSpecies {
            root_ao: 2.0,
            transmission: f32::NAN,
            ..default()
        };
        let (fixed, fixes) = species.sanitized();
        assert_eq!(fixes.len(), 2, "{fixes:?}");
        assert_eq!((fixed.root_ao, fixed.transmission), (1.0, 0.5));
        assert!(GrassSpecies::default().sanitized().1.is_empty());
    }
}
