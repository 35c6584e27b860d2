//! # bevy_soft_shadows
//!
//! Soft shadows for Bevy whose penumbrae harden at contact and widen with blocker distance:
//!
//! - **Screen Space Soft Shadows** (Gumbau 2011, ch. 6): a min-filtered shadow map gives the
//!   blocker distance, eq. 6.2 the penumbra width in screen space, and a separable anisotropic
//!   Gaussian blurs the hard shadow — O(2n) per pixel where PCSS is O(n²).
//! - statistically filtered shadow maps (Gumbau 2011, ch. 7): their visibility
//!   functions ([`filterable::visibility`], and as WGSL: the Gaussian and power CDFs beside
//!   variance, exponential and four-moment shadow maps); a [`filterable::FilteredShadowMap`] on
//!   a directional light (its cascades) or a spot light (its map) resolves them into a
//!   blurred, mip-mapped map of statistics after the shadow passes ([`filterable::render`]),
//!   which [`SoftShadowMaterial`]s read at the pixel's footprint as that light's shadow term.
//! - foliage shadows (Boulanger 2008, §5.5.2): a [`foliage::TreeOpacityShadows`] on the sun
//!   gives it a world-space opacity shadow map of the trees ([`foliage::opacity_map`] is the
//!   algorithm as plain Rust), into which `bevy_foliage` draws the light's pruned leaves; the
//!   receivers multiply the sun's shadow term by the leaves' transmittance.
//!
//! Every technique is measured against Bevy's own PCSS (`DirectionalLight::soft_shadow_size`,
//! `SpotLight::soft_shadows_enabled`) and shadow filters.
//!
//! Add [`SoftShadowsPlugin`] and put [`ScreenSpaceSoftShadows`] (reflected, so inspectors can
//! edit it) on a shadow-casting `DirectionalLight` or `SpotLight`. The plugin then adds the
//! depth and normal prepasses to the 3D cameras and turns meshes' `StandardMaterial`s into
//! [`SoftShadowMaterial`]s, whose lighting uses the soft
//! visibility as that light's shadow term (opt out with
//! [`NoSoftShadowReceiver`]).
//!
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_soft_shadows::prelude::*;
//!
//! fn sun(mut commands: Commands) {
//!     commands.spawn((
//!         DirectionalLight { shadow_maps_enabled: true, ..default() },
//!         // A 3° sun: penumbrae widen by 5 cm per metre between blocker and ground.
//!         ScreenSpaceSoftShadows { light_size: 0.05, ..default() },
//!         Transform::default().looking_to(Vec3::new(-1.0, -1.0, -0.5), Vec3::Y),
//!     ));
//! }
//! ```
//!
//! Modules: [`ssss`] (the algorithm as plain Rust — the CPU references — and its render passes),
//! [`filterable`] (filtered shadow maps), [`foliage`] (trees' shadows),
//! [`reference`](mod@reference) (the area-light ground truth the tests and the benchmark measure against).
//!
//! Other materials receive SSSS by calling `apply_soft_shadow` from the WGSL module
//! `bevy_soft_shadows::receiver_functions` after `apply_pbr_lighting`, with the visibility read
//! from [`SsssTextures::visibility`](ssss::receiver::SsssTextures) at the fragment's pixel (the
//! terrain clipmap and leaf materials do, connected by `bevy_nature`'s glue plugin).
//!
//! A spot light works the same way, with `light_size` its diameter in metres:
//!
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_soft_shadows::prelude::*;
//!
//! fn lamp(mut commands: Commands) {
//!     commands.spawn((
//!         SpotLight { shadow_maps_enabled: true, outer_angle: 0.7, ..default() },
//!         // A 30 cm lamp; blockers at least 3 m from it and up to 3 m above their receivers
//!         // get their whole penumbra (`min_filter::spot_fine_reach`).
//!         ScreenSpaceSoftShadows { light_size: 0.3, max_occluder_distance: 3.0, ..default() },
//!         Transform::from_xyz(0.0, 6.0, 0.0).looking_at(Vec3::ZERO, Vec3::Z),
//!     ));
//! }
//! ```
//!
//! So does a point light (its shadow map is Bevy's cube of six 90° faces; each face is dilated
//! on its own, so near a face's edge a receiver does not see the blockers across it and that part
//! of its outer penumbra is cut at the edge):
//!
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_soft_shadows::prelude::*;
//!
//! fn bulb(mut commands: Commands) {
//!     commands.spawn((
//!         PointLight { shadow_maps_enabled: true, ..default() },
//!         ScreenSpaceSoftShadows { light_size: 0.3, max_occluder_distance: 3.0, ..default() },
//!         Transform::from_xyz(0.0, 4.0, 0.0),
//!     ));
//! }
//! ```
//!
//! Diagnostics: `ssss/dilation_radius` (the min filter's coarse radius) and
//! `ssss/segment_filter` (which form of the filter runs,
//! [`SsssDilationFilter`](ssss::render::SsssDilationFilter)); with Bevy's
//! `RenderDiagnosticsPlugin`, the GPU time of the `ssss` span and of its passes (`ssss_reduce`,
//! `ssss_dilate`, `ssss_distance`, `ssss_blur_h`, `ssss_blur_v`), and of the filtered shadow
//! map's passes (`filtered_shadow`).
//!
//! Limits: one SSSS light (a directional light if one has the component — the first
//! shadow-casting directional light in Bevy's order — else the first spot light with it, else
//! the first point light with it), one camera's size for the screen textures.

use bevy::prelude::*;

pub mod filterable;
pub mod foliage;
pub mod reference;
pub mod settings;
pub mod ssss;

pub use settings::ScreenSpaceSoftShadows;
pub use ssss::receiver::{NoSoftShadowReceiver, SoftShadowMaterial};

/// The soft shadows plugin: registers the settings and keeps them valid.
#[derive(Default)]
pub struct SoftShadowsPlugin;

impl Plugin for SoftShadowsPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<ScreenSpaceSoftShadows>()
            .add_systems(PreUpdate, settings::sanitize_soft_shadow_settings);
        ssss::build(app);
        filterable::build(app);
        foliage::build(app);
    }
}

/// Everything a game usually imports.
pub mod prelude {
    pub use crate::foliage::TreeOpacityShadows;
    pub use crate::{
        NoSoftShadowReceiver, ScreenSpaceSoftShadows, SoftShadowMaterial, SoftShadowsPlugin,
    };
}
