//! The main scene of the suite: everything `bevy_nature` offers, in one place.
//!
//! ```text
//! cargo run --example nature                 # windowed, with a statistics/settings panel
//! cargo run --example nature -- --headless --frames 60 --screenshot nature.png --stats nature.json
//! ```

use bevy_nature::foliage::FoliagePruningSettings;
use bevy_nature::showcase::{ShowcaseOptions, build_showcase};
use bevy_nature::terrain_clip::ClipmapSettings;
use bevy_nature_harness::ExampleRunner;

fn main() -> bevy::app::AppExit {
    ExampleRunner::new("nature")
        .inspect_resource::<FoliagePruningSettings>()
        .inspect_resource::<ClipmapSettings>()
        .inspect_component::<bevy_nature::soft_shadows::ScreenSpaceSoftShadows>()
        .run(|app| build_showcase(app, ShowcaseOptions::default()))
}
