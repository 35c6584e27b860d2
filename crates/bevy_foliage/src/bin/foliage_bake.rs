//! Bakes trees for view-dependent stochastic pruning and writes `*.foliage` files.
//!
//! ```text
//! cargo run -p bevy_foliage --bin foliage_bake -- [--out DIR] [--resolution N] [--depth D] [TREE ...]
//! ```
//! TREE is one of `olea`, `fraxinus`, `quercus`, `cedrus` (the thesis' test trees; default: all).
//! Prints progress on stderr and one JSON object per tree on stdout (bake time per stage, leaf
//! count, GPU bytes).

use bevy_foliage::pruning::bake::{BakeProgress, BakeSettings, BakeStage, bake};
use bevy_foliage::pruning::format::save;
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use std::io::Write;
use std::path::PathBuf;

fn main() {
    let mut out = PathBuf::from("assets/trees");
    let mut settings = BakeSettings::default();
    let mut names: Vec<String> = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let mut value = |flag: &str| {
            args.next().unwrap_or_else(|| {
                eprintln!("{flag} needs a value");
                std::process::exit(2)
            })
        };
        match arg.as_str() {
            "--out" => out = value("--out").into(),
            "--resolution" => {
                settings.resolution = value("--resolution").parse().expect("--resolution N")
            }
            "--depth" => settings.cell_depth = value("--depth").parse().expect("--depth D"),
            "--help" | "-h" => {
                eprintln!(
                    "foliage_bake [--out DIR] [--resolution N] [--depth D] [olea|fraxinus|quercus|cedrus ...]"
                );
                return;
            }
            name => names.push(name.to_ascii_lowercase()),
        }
    }
    let all = TreeSpecies::thesis_trees();
    let selected: Vec<TreeSpecies> = if names.is_empty() {
        all.to_vec()
    } else {
        names
            .iter()
            .map(|n| {
                all.iter()
                    .find(|s| s.name.to_ascii_lowercase().starts_with(n.as_str()))
                    .cloned()
                    .unwrap_or_else(|| {
                        eprintln!("unknown tree '{n}' (olea, fraxinus, quercus, cedrus)");
                        std::process::exit(2)
                    })
            })
            .collect()
    };
    for species in selected {
        let tree = generate(&species);
        let progress = |p: BakeProgress| {
            let stage = match p.stage {
                BakeStage::Cells => "cells",
                BakeStage::Visibility => "visibility",
                BakeStage::Order => "order",
            };
            eprint!("\r{}: {stage} {}/{}        ", species.name, p.done, p.total);
            let _ = std::io::stderr().flush();
        };
        let (baked, timings) = match bake(&tree.leaves, &settings, &progress) {
            Ok(result) => result,
            Err(e) => {
                eprintln!("\n{}: {e}", species.name);
                std::process::exit(1);
            }
        };
        eprintln!();
        let file = out.join(format!(
            "{}.foliage",
            species
                .name
                .split_whitespace()
                .next()
                .unwrap_or("tree")
                .to_ascii_lowercase()
        ));
        if let Err(e) = save(&baked, &file) {
            eprintln!("{e}");
            std::process::exit(1);
        }
        println!(
            "{{\"tree\": \"{}\", \"leaves\": {}, \"cells\": {}, \"views\": {}, \"resolution\": {}, \"bake_ms\": {{\"cells\": {:.1}, \"visibility\": {:.1}, \"order\": {:.1}, \"total\": {:.1}}}, \"gpu_bytes\": {}, \"file\": \"{}\"}}",
            species.name,
            baked.leaf_count(),
            baked.cell_count(),
            baked.view_count(),
            settings.resolution,
            timings.cells.as_secs_f64() * 1e3,
            timings.visibility.as_secs_f64() * 1e3,
            timings.order.as_secs_f64() * 1e3,
            timings.total().as_secs_f64() * 1e3,
            baked.gpu_bytes(),
            file.display()
        );
    }
}
