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
//! On the GPU so far: a [`FilteredShadowMap`] on a shadow-casting directional light makes
//! [`render`] resolve every layer of Bevy's directional shadow texture into the method's
//! statistics, blur them and build the mips, each frame after the shadow passes, into
//! [`render::FilteredShadowTextures`] on the view (tested texel for texel against [`filter`]).
//! No receiver reads the map yet.

pub mod filter;
pub mod render;
pub mod settings;
pub mod visibility;

pub use settings::FilteredShadowMap;

use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::prelude::*;

/// Keeps the WGSL module `bevy_soft_shadows::filterable_visibility` loaded, so shaders may import
/// it by path.
#[derive(Resource)]
#[allow(dead_code)]
struct FilterableShaders(Handle<Shader>);

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
    let visibility: Handle<Shader> = load_embedded_asset!(app, "filterable_visibility.wgsl");
    app.insert_resource(FilterableShaders(visibility));
    render::build(app);
}
