//! Pruning measured on the corpus of real-world-like trees (`bevy_foliage::corpus`), shared by
//! the `pruning_corpus` example (the table) and the `pruning_corpus` render test (its bounds).
//!
//! Each tree is written as a glTF file, read and baked as a user's would be
//! (`TreeAssets::bake_gltf`: the file's own materials and textures, the alpha-masked bake), and
//! rendered in one headless run at a few crown screen sizes, three ways: full detail (pruning
//! off), pruned with area compensation, pruned without. Per size: the leaves kept, the image
//! RMSE against full detail, and the crown coverage (pixels that are not sky).

#![allow(dead_code)]

use bevy::ecs::system::RunSystemOnce;
use bevy::light::GlobalAmbientLight;
use bevy::prelude::*;
use bevy_foliage::corpus::CorpusTree;
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage};
use bevy_foliage::pruning::components::{PrunedFoliage, PruningParams};
use bevy_foliage::pruning::extract::kept_index_total;
use bevy_foliage::pruning::gltf::GltfLeafSettings;
use bevy_foliage::pruning::spawn::{GltfTreeAssets, TreeAssets};
use bevy_foliage::{FoliagePlugin, FoliagePruningSettings};
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::compare::{Comparison, RgbaImage, coverage_against_background};
use std::path::Path;

/// The sky behind the trees.
pub const SKY: [u8; 4] = [140, 179, 230, 255];

/// How the corpus is measured.
#[derive(Clone, Debug)]
pub struct CorpusSettings {
    /// Crown diameters on screen (fractions of the view height) to render at.
    pub screen_sizes: Vec<f32>,
    /// The bake.
    pub bake: BakeSettings,
    /// Pruning (its `enabled` and `area_compensation` are switched per render).
    pub pruning: FoliagePruningSettings,
    /// Where to write the images (none: not written).
    pub images: Option<std::path::PathBuf>,
}

impl Default for CorpusSettings {
    fn default() -> Self {
        Self {
            screen_sizes: vec![0.5, 0.1, 0.03],
            bake: BakeSettings::default(),
            pruning: FoliagePruningSettings::default(),
            images: None,
        }
    }
}

/// One tree at one screen size.
#[derive(Clone, Debug, Default)]
pub struct SizeRow {
    /// Crown diameter on screen (fraction of the view height).
    pub screen_size: f32,
    /// Distance factor of eq. 3.4.
    pub distance_factor: f32,
    /// Leaf triangles kept, per cent of the tree's.
    pub kept_percent: f64,
    /// RMSE against full detail, with compensation and without (0–1 per channel).
    pub rmse_compensated: f64,
    /// RMSE against full detail without compensation.
    pub rmse_plain: f64,
    /// Crown coverage (fraction of pixels not sky) at full detail.
    pub coverage_full: f64,
    /// With compensation.
    pub coverage_compensated: f64,
    /// Without compensation.
    pub coverage_plain: f64,
    /// Pixels in the image.
    pub pixels: u32,
}

/// One tree.
#[derive(Clone, Debug, Default)]
pub struct CorpusRow {
    /// The corpus tree's name.
    pub name: String,
    /// Leaves baked.
    pub leaves: usize,
    /// Cells.
    pub cells: usize,
    /// Bake time (ms).
    pub bake_ms: f64,
    /// Opaque share of the leaf texture over the leaves.
    pub opaque_fraction: f32,
    /// Per screen size.
    pub sizes: Vec<SizeRow>,
}

fn to_rgba(c: [u8; 4]) -> Color {
    Color::srgba_u8(c[0], c[1], c[2], c[3])
}

fn render(
    harness: &mut RenderHarness,
    enabled: bool,
    compensation: bool,
) -> Result<RgbaImage, String> {
    {
        let mut s = harness.world_mut().resource_mut::<FoliagePruningSettings>();
        s.enabled = enabled;
        s.area_compensation = compensation;
    }
    // Let the settings reach the pruning parameters, the leaf materials and the GPU.
    for _ in 0..8 {
        harness.step();
    }
    harness.render().map_err(|e| e.to_string())
}

/// Measures one corpus tree in `harness`. The tree, its light and camera are spawned into it and
/// despawned again before returning, so one harness measures every tree: its pipelines compile
/// once, and a process opens one render device for the corpus instead of one a tree.
pub fn measure(
    harness: &mut RenderHarness,
    tree: &CorpusTree,
    dir: &Path,
    settings: &CorpusSettings,
) -> Result<CorpusRow, String> {
    let path = tree.write(dir).map_err(|e| e.to_string())?;
    if !harness.app_mut().is_plugin_added::<FoliagePlugin>() {
        harness.app_mut().add_plugins(FoliagePlugin);
    }
    harness
        .app_mut()
        .insert_resource(settings.pruning.clone())
        .insert_resource(ClearColor(to_rgba(SKY)));
    let bake = settings.bake.clone();
    let assets: GltfTreeAssets = harness
        .world_mut()
        .run_system_once(move |mut trees: TreeAssets| {
            trees.bake_gltf(&path, &GltfLeafSettings::default(), &bake)
        })
        .map_err(|e| e.to_string())?
        .map_err(|e| e.to_string())?;
    let stats = assets.stats[0];
    let world = harness.world_mut();
    let root = world
        .spawn((Transform::IDENTITY, Visibility::Inherited))
        .id();
    let mut leaf_entities = Vec::new();
    for (baked, material) in &assets.leaves {
        let e = world
            .spawn((
                PrunedFoliage {
                    baked: baked.clone(),
                    material: material.clone(),
                },
                ChildOf(root),
            ))
            .id();
        leaf_entities.push((e, baked.clone()));
    }
    for (mesh, material) in &assets.bark {
        world.spawn((
            Mesh3d(mesh.clone()),
            MeshMaterial3d(material.clone()),
            ChildOf(root),
        ));
    }
    let sun = world
        .spawn((
            DirectionalLight {
                illuminance: 9000.0,
                shadow_maps_enabled: true,
                ..default()
            },
            Transform::default().looking_to(Vec3::new(-0.4, -1.0, -0.5), Vec3::Y),
        ))
        .id();
    world.insert_resource(GlobalAmbientLight {
        brightness: 600.0,
        ..default()
    });
    let baked: Vec<BakedFoliage> = leaf_entities
        .iter()
        .map(|(_, h)| {
            world
                .resource::<Assets<BakedFoliage>>()
                .get(h)
                .unwrap()
                .clone()
        })
        .collect();
    let (center, radius) = (baked[0].crown_center(), baked[0].crown_radius());
    let camera = world
        .spawn((
            Camera3d::default(),
            Msaa::Off,
            Transform::from_xyz(0.0, 0.0, 1.0),
        ))
        .id();
    harness.wait_until_ready().map_err(|e| e.to_string())?;
    let yy = 1.0 / (std::f32::consts::FRAC_PI_8).tan();
    let direction = Vec3::new(0.9, 0.25, 0.35).normalize();
    let mut row = CorpusRow {
        name: tree.name.to_string(),
        leaves: stats.leaves,
        cells: stats.cells,
        bake_ms: stats.timings.total().as_secs_f64() * 1e3,
        opaque_fraction: stats.opaque_fraction,
        sizes: Vec::new(),
    };
    for &size in &settings.screen_sizes {
        // Crown diameter / view height = r·yy/d.
        let distance = radius * yy / size;
        *harness.world_mut().get_mut::<Transform>(camera).unwrap() =
            Transform::from_translation(center + direction * distance).looking_at(center, Vec3::Y);
        let full = render(harness, false, true)?;
        let compensated = render(harness, true, true)?;
        let (kept, total, factor) = {
            let world = harness.world_mut();
            let mut kept = 0u64;
            let mut factor = 0.0;
            for ((e, _), data) in leaf_entities.iter().zip(&baked) {
                let p = *world.get::<PruningParams>(*e).ok_or("no pruning params")?;
                kept += kept_index_total(
                    &data.pruning_input(),
                    &p.camera.weights,
                    p.camera.distance_fixed,
                ) as u64;
                factor = p.camera.distance_fixed.min(65536) as f32 / 65536.0;
            }
            let total: u64 = baked.iter().map(|b| b.indices.len() as u64).sum();
            (kept, total, factor)
        };
        let plain = render(harness, true, false)?;
        if let Some(images) = &settings.images {
            for (what, image) in [
                ("full", &full),
                ("compensated", &compensated),
                ("plain", &plain),
            ] {
                image
                    .save_png(images.join(format!("{}_{:.3}_{what}.png", tree.name, size)))
                    .map_err(|e| e.to_string())?;
            }
        }
        let coverage = |img: &RgbaImage| coverage_against_background(img, SKY, 8);
        row.sizes.push(SizeRow {
            screen_size: size,
            distance_factor: factor,
            kept_percent: 100.0 * kept as f64 / total.max(1) as f64,
            rmse_compensated: Comparison::new("corpus", &compensated, &full).rmse,
            rmse_plain: Comparison::new("corpus", &plain, &full).rmse,
            coverage_full: coverage(&full),
            coverage_compensated: coverage(&compensated),
            coverage_plain: coverage(&plain),
            pixels: full.width * full.height,
        });
    }
    // Leave the harness as it was found (the root takes the leaves and bark with it).
    for entity in [root, sun, camera] {
        harness.world_mut().despawn(entity);
    }
    Ok(row)
}

/// The table as Markdown.
pub fn markdown(rows: &[CorpusRow]) -> String {
    let mut out = String::from(
        "| tree | leaves | cells | bake ms | opaque | screen size | factor | kept % | RMSE comp. | RMSE plain | crown px | coverage comp. | coverage plain |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        for (i, s) in r.sizes.iter().enumerate() {
            let head = if i == 0 {
                format!(
                    "{} | {} | {} | {:.0} | {:.2}",
                    r.name, r.leaves, r.cells, r.bake_ms, r.opaque_fraction
                )
            } else {
                " | | | | ".to_string()
            };
            // Coverage with and without compensation, relative to full detail.
            let relative = |c: f64| 100.0 * (c - s.coverage_full) / s.coverage_full.max(1e-9);
            out += &format!(
                "| {head} | {:.2} | {:.2} | {:.1} | {:.4} | {:.4} | {:.0} | {:+.1} % | {:+.1} % |\n",
                s.screen_size,
                s.distance_factor,
                s.kept_percent,
                s.rmse_compensated,
                s.rmse_plain,
                s.coverage_full * s.pixels as f64,
                relative(s.coverage_compensated),
                relative(s.coverage_plain)
            );
        }
    }
    out
}
