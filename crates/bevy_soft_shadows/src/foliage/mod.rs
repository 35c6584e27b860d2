//! Trees' shadows that know they are trees (Boulanger 2008, §5.5.2): a crown is not an opaque
//! blocker, so its shadow on the ground is dark where leaves pile up along the sun's rays and
//! light where they are sparse, and it softens with the distance between the leaves and the
//! ground.
//!
//! [`opacity_map`] holds the world-space opacity shadow map as plain Rust: eq. 5.27's projection
//! onto a horizontal plane, the accumulation of leaf fragments (the highest occluder kept by a
//! MAX blend, the transmittance multiplied by 0.9 per leaf fragment), and the soft lookup whose
//! mip grows with the distance from the receiver to the occluder. It is the reference of the
//! render passes: put [`TreeOpacityShadows`] on the sun and the map is fitted each frame
//! ([`receiver`]), cleared, drawn into by the casters' crates and resolved with its mips
//! ([`render`]); [`SoftShadowMaterial`](crate::SoftShadowMaterial) receivers multiply the sun's
//! shadow term by its transmittance.

use bevy::asset::{embedded_asset, load_embedded_asset};
use bevy::prelude::*;

pub mod opacity_map;
pub mod receiver;
pub mod render;
pub mod settings;

pub use settings::TreeOpacityShadows;

/// Keeps the WGSL modules `bevy_soft_shadows::opacity_caster` and
/// `bevy_soft_shadows::opacity_receiver` loaded, so shaders may import them by path.
#[derive(Resource)]
#[allow(dead_code)]
struct OpacityShaders(Handle<Shader>, Handle<Shader>);

pub(crate) fn build(app: &mut App) {
    app.register_type::<TreeOpacityShadows>()
        .add_systems(PreUpdate, settings::sanitize_tree_opacity_settings);
    if !app
        .world()
        .contains_resource::<bevy::asset::io::embedded::EmbeddedAssetRegistry>()
    {
        return;
    }
    embedded_asset!(app, "opacity_caster.wgsl");
    embedded_asset!(app, "opacity_receiver.wgsl");
    let caster: Handle<Shader> = load_embedded_asset!(app, "opacity_caster.wgsl");
    let receiver: Handle<Shader> = load_embedded_asset!(app, "opacity_receiver.wgsl");
    app.insert_resource(OpacityShaders(caster, receiver));
    receiver::build(app);
    render::build(app);
}
