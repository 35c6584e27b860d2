//! The main scene of the suite: everything `bevy_nature` offers, in one place.
//!
//! ```text
//! cargo run --example nature                 # windowed, with a statistics/settings panel
//! cargo run --example nature -- --headless --frames 60 --screenshot nature.png --stats nature.json
//! cargo run --example nature -- --leaf-scale 1   # the backdrop forest at full leaf counts
//! cargo run --release --example nature -- --soak 10000 --size 320x180 --stats soak.json
//! ```
//! `--soak N` flies the camera over the scene for N frames (headless), sampling resident and GPU
//! memory every 500 frames.
//! `--leaf-scale F` sets the backdrop forest's leaf counts as a fraction of the species' full
//! counts (default 0.15; fewer leaves are larger, so the crowns stay as full).
//! `--bevy-lighting` lights the leaves with Bevy's PBR instead of the tree lighting (the panel
//! switches it too: `TreeLightingSettings::enabled`).

use bevy_nature::foliage::FoliagePruningSettings;
use bevy_nature::showcase::{ShowcaseOptions, build_showcase};
use bevy_nature::terrain_clip::ClipmapSettings;
use bevy_nature_harness::{ExampleArgs, ExampleRunner};

fn main() -> bevy::app::AppExit {
    let mut options = ShowcaseOptions::default();
    let mut rest = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--leaf-scale" {
            let v = args.next().unwrap_or_default();
            options.forest_leaf_scale = v
                .parse()
                .ok()
                .filter(|s: &f32| *s > 0.0 && *s <= 1.0)
                .unwrap_or_else(|| {
                    eprintln!("--leaf-scale takes a number in (0, 1], not '{v}'");
                    std::process::exit(2)
                });
        } else if arg == "--bevy-lighting" {
            options.tree_lighting = false;
        } else {
            rest.push(arg);
        }
    }
    let args = ExampleArgs::parse_from(rest).unwrap_or_else(|e| {
        eprintln!("{e} [--leaf-scale F] [--bevy-lighting]");
        std::process::exit(2)
    });
    // A soak run flies the camera, so streaming, LoD and shadows keep changing.
    options.fly = args.soak.is_some();
    ExampleRunner::with_args("nature", args)
        .inspect_resource::<FoliagePruningSettings>()
        .inspect_resource::<ClipmapSettings>()
        .inspect_resource::<bevy_nature::foliage::grass::GrassSettings>()
        .inspect_resource::<bevy_nature::foliage::TreeLightingSettings>()
        .inspect_component::<bevy_nature::soft_shadows::ScreenSpaceSoftShadows>()
        .ready_when(bevy_nature::foliage::grass::systems::grass_ready)
        .run(move |app| build_showcase(app, options))
}
