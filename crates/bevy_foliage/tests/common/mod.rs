//! Helpers shared by the render tests.

use bevy_foliage::FoliagePruningSettings;
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::compare::RgbaImage;

/// Changes the pruning settings with `change`, lets the change reach the pruning parameters,
/// the store, the leaf materials and the GPU (a few frames), and renders.
pub fn render_with_settings(
    harness: &mut RenderHarness,
    change: impl FnOnce(&mut FoliagePruningSettings),
) -> RgbaImage {
    change(&mut harness.world_mut().resource_mut::<FoliagePruningSettings>());
    for _ in 0..12 {
        harness.step();
    }
    harness.render().unwrap()
}
