//! Image test of pruning: a test tree rendered at several distances with pruning (with and
//! without area compensation) against full detail rendered in the same run. Crown coverage and
//! RMSE are measured; compensation must lose clearly less coverage than the same pruning
//! uncompensated. The images are written under `target/nature-artifacts/pruning_image/`.

mod common;

use bevy::camera::{PerspectiveProjection, Projection};
use bevy::prelude::*;
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage, CellCount, bake};
use bevy_foliage::pruning::components::{PrunedFoliage, PruningParams};
use bevy_foliage::pruning::extract::kept_index_total;
use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_foliage::{FoliagePlugin, FoliagePruningSettings, LodDistances};
use bevy_nature_harness::compare::{Comparison, RgbaImage, coverage_against_background};
use bevy_nature_harness::{RenderHarness, artifacts_dir};
use common::render_with_settings;

const SIZE: u32 = 128;
const SKY: Color = Color::srgb(0.55, 0.7, 0.9);

fn render_variant(
    harness: &mut RenderHarness,
    enabled: bool,
    area_compensation: bool,
) -> RgbaImage {
    render_with_settings(harness, |s| {
        s.enabled = enabled;
        s.area_compensation = area_compensation;
    })
}

#[test]
fn area_compensation_keeps_crown_coverage_that_plain_pruning_loses() {
    let Some(mut harness) = RenderHarness::for_test("pruning_image", SIZE, SIZE) else {
        return;
    };
    let (near, far) = (8.0, 60.0);
    harness.app_mut().add_plugins(FoliagePlugin);
    harness.app_mut().insert_resource(FoliagePruningSettings {
        distances: LodDistances::World { near, far },
        ..default()
    });
    harness.app_mut().insert_resource(ClearColor(SKY));
    let species = TreeSpecies::fraxinus().with_leaf_count(6000);
    let tree = generate(&species);
    let (baked, _) = bake(
        &tree.leaves,
        &BakeSettings {
            cells: CellCount::Depth(7),
            resolution: 96,
            ..default()
        },
        &|_| {},
    )
    .unwrap();
    let crown = baked.crown_center();
    let handle = harness
        .world_mut()
        .resource_mut::<Assets<BakedFoliage>>()
        .add(baked.clone());
    let material = harness
        .world_mut()
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(StandardMaterial {
            base_color: Color::srgb(0.2, 0.45, 0.15),
            perceptual_roughness: 0.8,
            ..default()
        }));
    let tree_entity = harness
        .world_mut()
        .spawn((
            PrunedFoliage {
                baked: handle,
                material,
            },
            Transform::IDENTITY,
        ))
        .id();
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: 8000.0,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.3, -1.0, -0.4), Vec3::Y),
    ));
    let direction = Vec3::new(0.8, 0.15, 0.6).normalize();
    let camera = harness
        .world_mut()
        .spawn((
            Camera3d::default(),
            Msaa::Off,
            Transform::from_translation(crown + direction * 20.0),
        ))
        .id();
    harness.wait_until_ready().unwrap();

    let dir = artifacts_dir().join("pruning_image");
    let background = {
        let c = SKY.to_srgba();
        [
            (c.red * 255.0).round() as u8,
            (c.green * 255.0).round() as u8,
            (c.blue * 255.0).round() as u8,
            255,
        ]
    };
    let mut report = Vec::new();
    for d in [20.0f32, 34.0, 46.0] {
        // The camera zooms as it backs away so the crown keeps its size on screen: what changes
        // is only what pruning removes.
        let fov = 2.0 * (species.crown_radius * 1.25 / d).atan();
        {
            let world = harness.world_mut();
            *world.get_mut::<Transform>(camera).unwrap() =
                Transform::from_translation(crown + direction * d).looking_at(crown, Vec3::Y);
            *world.get_mut::<Projection>(camera).unwrap() =
                Projection::Perspective(PerspectiveProjection { fov, ..default() });
        }
        let full = render_variant(&mut harness, false, true);

        let compensated = render_variant(&mut harness, true, true);
        let params = *harness
            .world_mut()
            .get::<PruningParams>(tree_entity)
            .unwrap();
        let kept = kept_index_total(
            &baked.pruning_input(),
            &params.camera.weights,
            params.camera.distance_fixed,
        ) as f64
            / baked.indices.len() as f64;
        let plain = render_variant(&mut harness, true, false);
        for (name, image) in [
            ("full", &full),
            ("compensated", &compensated),
            ("plain", &plain),
        ] {
            image
                .save_png(dir.join(format!("d{d:02}_{name}.png")))
                .unwrap();
        }
        let coverage = |img: &RgbaImage| coverage_against_background(img, background, 8);
        let (c_full, c_comp, c_plain) = (coverage(&full), coverage(&compensated), coverage(&plain));
        let loss_comp = (c_full - c_comp) / c_full;
        let loss_plain = (c_full - c_plain) / c_full;
        let cmp_comp = Comparison::new(
            format!("pruning_image/d{d:02}_compensated"),
            &compensated,
            &full,
        );
        let cmp_plain = Comparison::new(format!("pruning_image/d{d:02}_plain"), &plain, &full);
        let coarse_comp = Comparison::new(
            format!("pruning_image/d{d:02}_compensated_8x8"),
            &compensated.box_downsample(8),
            &full.box_downsample(8),
        );
        let coarse_plain = Comparison::new(
            format!("pruning_image/d{d:02}_plain_8x8"),
            &plain.box_downsample(8),
            &full.box_downsample(8),
        );
        let line = format!(
            "d {d:>4} m: leaves kept {:5.1} %, crown coverage full {:.3}, compensated {:.3} (loss {:+.1} %, rmse {:.4}, 8x8 rmse {:.4}), plain {:.3} (loss {:+.1} %, rmse {:.4}, 8x8 rmse {:.4})",
            kept * 100.0,
            c_full,
            c_comp,
            loss_comp * 100.0,
            cmp_comp.rmse,
            coarse_comp.rmse,
            c_plain,
            loss_plain * 100.0,
            cmp_plain.rmse,
            coarse_plain.rmse,
        );
        eprintln!("{line}");
        report.push(line);
        assert!(
            c_full > 0.15,
            "the crown should fill a good part of the frame ({c_full})"
        );
        assert!(
            kept < 0.7,
            "pruning should have removed leaves at {d} m (kept {kept})"
        );
        cmp_plain.assert(
            loss_plain > 0.05,
            "plain pruning should visibly thin the crown",
        );
        cmp_comp.assert(
            loss_comp.abs() < 0.5 * loss_plain,
            &format!("compensated coverage loss {loss_comp:.3} should be well under plain {loss_plain:.3}"),
        );
        // Per pixel both differ from full detail about equally (different leaves are drawn);
        // seen coarser, compensation restores the crown's density and is closer.
        coarse_comp.assert(
            coarse_comp.rmse < coarse_plain.rmse,
            "at 8x8 blocks, compensated pruning should be closer to full detail than plain pruning",
        );
    }
    std::fs::write(dir.join("report.txt"), report.join("\n")).unwrap();
}
