//! Screen Space Soft Shadows (Gumbau 2011, ch. 6) — the algorithm in plain Rust, the
//! CPU reference of every GPU pass:
//!
//! 1. [`min_filter`]: the shadow map dilated by a separable nearest-depth filter (§6.2.1), so
//!    outer-penumbra pixels find their blocker.
//! 2. [`penumbra`]: the blocker–receiver distance gives the penumbra's width (eq. 6.1), divided
//!    by the eye distance for screen space (eq. 6.2); a Gaussian of σ = width/4 stands in for the
//!    area light, its axes shortened by the surface's slant. [`distance`] composes them per
//!    pixel as the distance pass does (with Bevy's spot-light projection).
//! 3. [`kernel`] and [`blur`]: the hard shadow blurred by a horizontal then a vertical pass, with
//!    depth rejection and lazy shadowing (§6.2.3, §6.3.2).

pub mod blur;
mod box_sums;
pub mod dilation;
pub mod distance;
pub mod kernel;
pub mod min_filter;
pub mod penumbra;
pub mod tiles;

pub mod receiver;
pub mod render;

/// Registers SSSS (main and render world). Without Bevy's asset plugin (a bare `App`, as in
/// unit tests of the settings) only the settings are registered, with a warning.
pub(crate) fn build(app: &mut bevy::prelude::App) {
    if !app
        .world()
        .contains_resource::<bevy::asset::io::embedded::EmbeddedAssetRegistry>()
    {
        bevy::log::warn!(
            "SoftShadowsPlugin added without AssetPlugin (add it after DefaultPlugins): \
             Screen Space Soft Shadows will not render"
        );
        return;
    }
    receiver::build(app);
    render::build(app);
    dilation::build(app);
}
