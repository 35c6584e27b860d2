//! Pruning on trees no one here tuned it for: the corpus of real-world-like glTF trees
//! (`bevy_foliage::corpus`: a small sparse card tree, a tree of mostly transparent cards, a tree
//! in centimetres, a palm of welded fronds), each read and baked as a user's file would be, then
//! rendered headless at three crown screen sizes — full detail, pruned with area compensation,
//! pruned without — in one run. Prints the table (Markdown) and one JSON object per tree.
//!
//! ```text
//! cargo run --example pruning_corpus -- [--size N] [--out DIR] [--screen-sizes 0.5,0.1,0.03]
//!     [--leaves-per-cell N | --depth D] [--max-leaf-scale X] [--near S --far S] [--no-fade]
//! ```
//! `--near`/`--far` are screen sizes (crown diameter ÷ view height); `--out` keeps the images.

#[path = "../tests/common/pruning_corpus.rs"]
mod pruning_corpus;

use bevy::math::UVec2;
use bevy_nature::foliage::LodDistances;
use bevy_nature::foliage::pruning::bake::CellCount;
use bevy_nature_harness::headless::HarnessConfig;
use bevy_nature_harness::{RenderHarness, require_adapter};
use pruning_corpus::{CorpusSettings, markdown, measure};

fn main() {
    let mut settings = CorpusSettings::default();
    let mut size = 192u32;
    let mut near_far = None::<(f32, f32)>;
    let mut args = std::env::args().skip(1);
    let fail = |msg: String| -> ! {
        eprintln!("pruning_corpus: {msg}");
        std::process::exit(2)
    };
    while let Some(arg) = args.next() {
        let mut value = |flag: &str| {
            args.next()
                .unwrap_or_else(|| fail(format!("{flag} needs a value")))
        };
        let number = |flag: &str, v: String| -> f32 {
            v.parse()
                .unwrap_or_else(|_| fail(format!("{flag} takes a number, not '{v}'")))
        };
        match arg.as_str() {
            "--size" => size = number("--size", value("--size")) as u32,
            "--out" => settings.images = Some(value("--out").into()),
            "--screen-sizes" => {
                settings.screen_sizes = value("--screen-sizes")
                    .split(',')
                    .map(|s| number("--screen-sizes", s.to_string()))
                    .collect()
            }
            "--leaves-per-cell" => {
                settings.bake.cells = CellCount::LeavesPerCell(number(
                    "--leaves-per-cell",
                    value("--leaves-per-cell"),
                ) as u32)
            }
            "--depth" => {
                settings.bake.cells = CellCount::Depth(number("--depth", value("--depth")) as u32)
            }
            "--max-leaf-scale" => {
                settings.pruning.max_leaf_scale =
                    number("--max-leaf-scale", value("--max-leaf-scale"))
            }
            "--near" => {
                near_far = Some((
                    number("--near", value("--near")),
                    near_far.map_or(0.015, |n| n.1),
                ))
            }
            "--far" => {
                near_far = Some((
                    near_far.map_or(0.6, |n| n.0),
                    number("--far", value("--far")),
                ))
            }
            "--no-fade" => settings.pruning.subpixel_fade = false,
            other => fail(format!("unknown flag '{other}'")),
        }
    }
    if let Some((near, far)) = near_far {
        settings.pruning.distances = LodDistances::ScreenSize { near, far };
    }
    if require_adapter("pruning_corpus").is_none() {
        std::process::exit(1);
    }
    if let Some(dir) = &settings.images {
        std::fs::create_dir_all(dir).unwrap_or_else(|e| fail(format!("{}: {e}", dir.display())));
    }
    let dir = std::env::temp_dir().join(format!("pruning_corpus_{}", std::process::id()));
    let mut rows = Vec::new();
    let mut harness = RenderHarness::new(HarnessConfig {
        log: true,
        size: UVec2::splat(size),
        ..HarnessConfig::default()
    })
    .unwrap_or_else(|e| fail(e.to_string()));
    for tree in &bevy_nature::foliage::corpus::all() {
        eprintln!("pruning_corpus: {} ({})", tree.name, tree.description);
        let row = measure(&mut harness, tree, &dir, &settings)
            .unwrap_or_else(|e| fail(format!("{}: {e}", tree.name)));
        println!(
            "{{\"tree\": \"{}\", \"leaves\": {}, \"cells\": {}, \"bake_ms\": {:.1}, \"opaque_fraction\": {:.3}, \"sizes\": [{}]}}",
            row.name,
            row.leaves,
            row.cells,
            row.bake_ms,
            row.opaque_fraction,
            row.sizes
                .iter()
                .map(|s| format!(
                    "{{\"screen_size\": {}, \"distance_factor\": {:.3}, \"kept_percent\": {:.2}, \"rmse_compensated\": {:.5}, \"rmse_plain\": {:.5}, \"coverage_full\": {:.4}, \"coverage_compensated\": {:.4}, \"coverage_plain\": {:.4}}}",
                    s.screen_size, s.distance_factor, s.kept_percent, s.rmse_compensated, s.rmse_plain, s.coverage_full, s.coverage_compensated, s.coverage_plain
                ))
                .collect::<Vec<_>>()
                .join(", ")
        );
        rows.push(row);
    }
    std::fs::remove_dir_all(&dir).ok();
    println!("\n{}", markdown(&rows));
    println!(
        "settings: {:?}, {:?}, max leaf scale {}",
        settings.bake.cells, settings.pruning.distances, settings.pruning.max_leaf_scale
    );
}
