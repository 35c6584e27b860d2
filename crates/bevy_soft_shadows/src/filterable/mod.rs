//! Statistically filtered shadow maps (Gumbau 2011, ch. 7): shadow maps that store statistics
//! of the occluders' depths, so they filter like textures — blurred once, mip-mapped, sampled
//! with a filter as wide as the pixel's footprint at no extra cost per tap.
//!
//! [`visibility`] holds the visibility functions — the thesis' Gaussian CDF (eq. 7.4) and power
//! CDF (eq. 7.6–7.7), and as baselines variance (Chebyshev), exponential and four-moment shadow
//! maps — as plain Rust, the references of the shaders; [`filter`] how the map is made and
//! read (texels of statistics, the separable Gaussian pre-filter, the mip chain, the trilinear
//! read at the receiver's footprint). The WGSL module `bevy_soft_shadows::filterable_visibility`
//! holds the same visibility functions for shaders (tested against these on the GPU).
//!
//! On the GPU: a [`FilteredShadowMap`] on a shadow-casting directional or spot light makes
//! [`render`] resolve the light's layers of Bevy's directional and spot shadow texture (a
//! directional light's cascades, a spot light's map) into the method's statistics, blur them
//! and build the mips, each frame after the shadow passes, into the maps of
//! [`receiver::FilteredShadowImages`] (tested texel for texel against [`filter`]); meshes'
//! `StandardMaterial`s become [`SoftShadowMaterial`](crate::SoftShadowMaterial)s, whose fragment
//! stage (`filtered_receiver.wgsl`, importable as `bevy_soft_shadows::filtered_receiver`) reads
//! each map at the pixel's footprint and re-weights its light's direct contribution by the
//! filtered visibility in place of Bevy's shadow lookup.

pub mod filter;
pub mod receiver;
pub mod render;
pub mod settings;
pub mod visibility;

pub use settings::FilteredShadowMap;

use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::prelude::*;

/// Keeps the WGSL modules `bevy_soft_shadows::filterable_visibility` and
/// `bevy_soft_shadows::filtered_receiver` loaded, so shaders may import them by path.
#[derive(Resource)]
#[allow(dead_code)]
struct FilterableShaders(Handle<Shader>, Handle<Shader>);

pub(crate) fn build(app: &mut App) {
    app.register_type::<FilteredShadowMap>()
        .add_systems(PreUpdate, settings::sanitize_filtered_shadow_settings);
    if !app
        .world()
        .contains_resource::<bevy::asset::io::embedded::EmbeddedAssetRegistry>()
    {
        // SSSS's build warns once for the plugin; nothing renders without the asset server.
        return;
    }
    embedded_asset!(app, "filterable_visibility.wgsl");
    embedded_asset!(app, "filtered_receiver.wgsl");
    let visibility: Handle<Shader> = load_embedded_asset!(app, "filterable_visibility.wgsl");
    let receiver: Handle<Shader> = load_embedded_asset!(app, "filtered_receiver.wgsl");
    app.insert_resource(FilterableShaders(visibility, receiver));
    receiver::build(app);
    render::build(app);
}
