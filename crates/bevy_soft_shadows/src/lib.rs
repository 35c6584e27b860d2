//! # bevy_soft_shadows
//!
//! Soft shadows for Bevy whose penumbrae harden at contact and widen with blocker distance:
//!
//! - **Screen Space Soft Shadows** (Gumbau 2011, ch. 6): a min-filtered shadow map gives the
//!   blocker distance, eq. 6.2 the penumbra width in screen space, and a separable anisotropic
//!   Gaussian blurs the hard shadow — O(2n) per pixel where PCSS is O(n²).
//! - statistically filtered shadow maps and foliage shadows (each in its own module as it lands).
//!
//! Every technique is measured against Bevy's own PCSS (`DirectionalLight::soft_shadow_size`)
//! and shadow filters.
//!
//! Add [`SoftShadowsPlugin`] and put [`ScreenSpaceSoftShadows`] (reflected, so inspectors can
//! edit it) on a light.

use bevy::prelude::*;

pub mod reference;
pub mod settings;
pub mod ssss;

pub use settings::ScreenSpaceSoftShadows;

/// The soft shadows plugin: registers the settings and keeps them valid.
#[derive(Default)]
pub struct SoftShadowsPlugin;

impl Plugin for SoftShadowsPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<ScreenSpaceSoftShadows>()
            .add_systems(PreUpdate, settings::sanitize_soft_shadow_settings);
        ssss::build(app);
    }
}

/// Everything a game usually imports.
pub mod prelude {
    pub use crate::{ScreenSpaceSoftShadows, SoftShadowsPlugin};
}
