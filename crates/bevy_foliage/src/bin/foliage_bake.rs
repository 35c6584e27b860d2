//! Bakes trees for view-dependent stochastic pruning and writes `*.foliage` files.
//!
//! ```text
//! cargo run -p bevy_foliage --bin foliage_bake -- [--out DIR] [--resolution N] [--depth D]
//!     [--leaf-material NAME ...] [--rays-per-bin R | --neighbour-bins] [--seen-points P]
//!     [--open-map-points P] [--bounce-rays R] [--bounce-pool K] [--no-hotspot] [TREE | FILE.gltf | FILE.glb ...]
//! ```
//! TREE is one of `olea`, `fraxinus`, `quercus`, `cedrus` (the thesis' test trees; default: all);
//! a glTF file is split into leaves as `bevy_foliage::pruning::gltf` documents.
//! `--rays-per-bin`: rays per bin of the tree lighting's traced bins (default 128, four times
//! what a bake made at load time takes: see `lighting::traced_bins::OFFLINE_RAYS_PER_BIN`);
//! `--neighbour-bins`: §5.6's estimate from the neighbours instead.
//! `--seen-points`: points per leaf for the gains from a leaf's mean light to the part of it
//! in view (`lighting::seen_part`; default 32, twice a bake at load time's; 0 for none); their time is the envelope stage's.
//! `--open-map-points`: points per leaf for its map of the open share across it, which the
//! sky takes in place of those gains (`lighting::open_map`; default 32, as at load time; 0 for
//! none); the envelope stage's time too.
//! `--bounce-rays`: rays per leaf for the bounce gathered from its neighbours
//! (`lighting::gathered_bounce`; default 64, twice a bake at load time's; 0 for none: eq. 5.24
//! alone); the envelope stage's time too. `--bounce-pool`: leaves whose gathers make each
//! leaf's ratios (the leaf and its nearest neighbours; default 1, the leaf's own alone,
//! `gathered_bounce::DEFAULT_BOUNCE_POOL`, where the measured trade-off is).
//! `--no-hotspot`: leave the crown's hotspot (`lighting::hotspot`) unmeasured, its factors at 1
//! (measured by default with `HotspotSettings::OFFLINE`; its time is the envelope stage's too).
//! Prints progress on stderr and one JSON object per tree on stdout (bake time per stage, leaf
//! count, GPU bytes).

use bevy_foliage::lighting::gathered_bounce::OFFLINE_BOUNCE_RAYS;
use bevy_foliage::lighting::seen_part::OFFLINE_SEEN_POINTS;
use bevy_foliage::lighting::traced_bins::{BinEstimate, OFFLINE_RAYS_PER_BIN};
use bevy_foliage::pruning::bake::{BakeProgress, BakeSettings, BakeStage, CellCount, bake_masked};
use bevy_foliage::pruning::format::save;
use bevy_foliage::pruning::gltf::{GltfLeafSettings, load_gltf_tree};
use bevy_foliage::pruning::leaves::LeafSet;
use bevy_foliage::pruning::mask::AlphaMask;
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use std::io::Write;
use std::path::PathBuf;

fn main() {
    let mut out = PathBuf::from("assets/trees");
    // A bake kept on disk can afford the sky traced closer than one made at load time.
    let mut settings = BakeSettings {
        bins: BinEstimate::Traced {
            rays_per_bin: OFFLINE_RAYS_PER_BIN,
        },
        seen_points: OFFLINE_SEEN_POINTS,
        bounce_rays: OFFLINE_BOUNCE_RAYS,
        hotspot: bevy_foliage::lighting::hotspot::HotspotSettings::OFFLINE,
        ..BakeSettings::default()
    };
    let mut names: Vec<String> = Vec::new();
    let mut gltf_settings = GltfLeafSettings::default();
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
            "--depth" => {
                settings.cells = CellCount::Depth(value("--depth").parse().expect("--depth D"))
            }
            "--leaves-per-cell" => {
                settings.cells = CellCount::LeavesPerCell(
                    value("--leaves-per-cell")
                        .parse()
                        .expect("--leaves-per-cell N"),
                )
            }
            "--leaf-material" => gltf_settings.leaf_materials.push(value("--leaf-material")),
            "--rays-per-bin" => {
                settings.bins = BinEstimate::Traced {
                    rays_per_bin: value("--rays-per-bin").parse().expect("--rays-per-bin R"),
                }
            }
            "--neighbour-bins" => settings.bins = BinEstimate::Neighbours,
            "--no-hotspot" => {
                settings.hotspot = bevy_foliage::lighting::hotspot::HotspotSettings::NONE
            }
            "--seen-points" => {
                settings.seen_points = value("--seen-points").parse().expect("--seen-points P")
            }
            "--open-map-points" => {
                settings.open_map_points = value("--open-map-points")
                    .parse()
                    .expect("--open-map-points P")
            }
            "--bounce-rays" => {
                settings.bounce_rays = value("--bounce-rays").parse().expect("--bounce-rays R")
            }
            "--bounce-pool" => {
                settings.bounce_pool = value("--bounce-pool").parse().expect("--bounce-pool K")
            }
            "--help" | "-h" => {
                eprintln!(
                    "foliage_bake [--out DIR] [--resolution N] [--depth D | --leaves-per-cell N] [--rays-per-bin R | --neighbour-bins] [--seen-points P] [--open-map-points P] [--bounce-rays R] [--bounce-pool K] [--no-hotspot] [olea|fraxinus|quercus|cedrus ...]"
                );
                return;
            }
            name => names.push(name.to_string()),
        }
    }
    let all = TreeSpecies::thesis_trees();
    if names.is_empty() {
        names = all.iter().map(|s| s.name.to_string()).collect();
    }
    // (file stem, leaves, alpha mask) per bake: a glTF tree gives one per leaf material.
    let mut jobs: Vec<(String, LeafSet, Option<AlphaMask>)> = Vec::new();
    for name in names {
        if name.ends_with(".gltf") || name.ends_with(".glb") {
            let path = PathBuf::from(&name);
            let bytes = std::fs::read(&path).unwrap_or_else(|e| {
                eprintln!("{name}: {e}");
                std::process::exit(1)
            });
            let tree = match load_gltf_tree(&bytes, path.parent(), &gltf_settings) {
                Ok(tree) => tree,
                Err(e) => {
                    eprintln!("{name}: {e}");
                    std::process::exit(1)
                }
            };
            for note in &tree.notes {
                eprintln!("{name}: {note}");
            }
            let stem = path
                .file_stem()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned();
            let groups = tree.leaf_groups.len();
            for (i, group) in tree.leaf_groups.iter().enumerate() {
                let label = if groups == 1 {
                    stem.clone()
                } else {
                    format!("{stem}_{i}")
                };
                jobs.push((label, group.leaves.clone(), tree.leaf_mask(group)));
            }
        } else {
            let lower = name.to_ascii_lowercase();
            let species = all
                .iter()
                .find(|s| s.name.to_ascii_lowercase().starts_with(lower.as_str()))
                .unwrap_or_else(|| {
                    eprintln!("unknown tree '{name}' (olea, fraxinus, quercus, cedrus, or a .gltf/.glb file)");
                    std::process::exit(2)
                });
            jobs.push((
                species
                    .name
                    .split_whitespace()
                    .next()
                    .unwrap_or("tree")
                    .to_ascii_lowercase(),
                generate(species).leaves,
                None,
            ));
        }
    }
    for (label, leaves, mask) in jobs {
        let species_name = label.as_str();
        let progress = |p: BakeProgress| {
            let stage = match p.stage {
                BakeStage::Cells => "cells",
                BakeStage::Visibility => "visibility",
                BakeStage::Order => "order",
                BakeStage::Envelope => "envelope",
            };
            eprint!("\r{species_name}: {stage} {}/{}        ", p.done, p.total);
            let _ = std::io::stderr().flush();
        };
        let (baked, timings) = match bake_masked(&leaves, mask.as_ref(), &settings, &progress) {
            Ok(result) => result,
            Err(e) => {
                eprintln!("\n{species_name}: {e}");
                std::process::exit(1);
            }
        };
        eprintln!();
        let file = out.join(format!("{label}.foliage"));
        if let Err(e) = save(&baked, &file) {
            eprintln!("{e}");
            std::process::exit(1);
        }
        println!(
            "{{\"tree\": \"{}\", \"leaves\": {}, \"skipped\": {}, \"cells\": {}, \"views\": {}, \"resolution\": {}, \"bake_ms\": {{\"cells\": {:.1}, \"visibility\": {:.1}, \"order\": {:.1}, \"envelope\": {:.1}, \"total\": {:.1}}}, \"gpu_bytes\": {}, \"file\": \"{}\"}}",
            species_name,
            baked.leaf_count(),
            baked.skipped.total(),
            baked.cell_count(),
            baked.view_count(),
            settings.resolution,
            timings.cells.as_secs_f64() * 1e3,
            timings.visibility.as_secs_f64() * 1e3,
            timings.order.as_secs_f64() * 1e3,
            timings.envelope.as_secs_f64() * 1e3,
            timings.total().as_secs_f64() * 1e3,
            baked.gpu_bytes(),
            file.display()
        );
    }
}
