//! The forest manager on the GPU: trees drawn from borrowed cache extractions. Checks that the
//! budget holds every frame, that once the camera holds still every visible tree draws the slot
//! of its desired LoD, that what each extraction's pruning pass wrote equals the CPU reference,
//! that every tree draws its extraction, and that the forest rendered with the manager stays
//! close to the same forest at full detail rendered in the same run, with fewer triangles.

use bevy::mesh::MeshTag;
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy_foliage::forest::cache::LodSlots;
use bevy_foliage::forest::systems::{ForestState, GEOMETRY_TINTS, LEAF_TRIANGLES, geometry_band};
use bevy_foliage::impostor::systems::ImpostorSettings;
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage, CellCount, bake};
use bevy_foliage::pruning::components::{ManagedPruning, PrunedFoliage, PruningParams};
use bevy_foliage::pruning::extract::kept_index_total;
use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_foliage::pruning::render::PruningFrame;
use bevy_foliage::pruning::store::{FoliageSlot, QUAD_TAG_BIT};
use bevy_foliage::{
    FoliagePlugin, FoliagePruningSettings, ForestBudget, ForestSettings, ForestTree, LodDistances,
    TreeLod,
};
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::compare::Comparison;
use bevy_nature_harness::headless::read_buffer_now;

const BUDGET: u32 = 3;
const SLOTS: u32 = 4;

fn small_bake(species: TreeSpecies, leaves: usize) -> BakedFoliage {
    let tree = generate(&species.with_leaf_count(leaves));
    let settings = BakeSettings {
        cells: CellCount::Depth(5),
        resolution: 64,
        ..default()
    };
    bake(&tree.leaves, &settings, &|_| {}).unwrap().0
}

fn triangles(harness: &mut RenderHarness) -> f64 {
    harness
        .diagnostic(&LEAF_TRIANGLES)
        .expect("forest/leaf_triangles diagnostic")
}

#[test]
fn forest_trees_draw_borrowed_extractions_within_the_budget() {
    let Some(mut harness) = RenderHarness::for_test("forest", 128, 80) else {
        return;
    };
    harness.app_mut().add_plugins(FoliagePlugin);
    harness.app_mut().insert_resource(FoliagePruningSettings {
        distances: LodDistances::World {
            near: 10.0,
            far: 110.0,
        },
        ..default()
    });
    harness.app_mut().insert_resource(ForestSettings {
        slots: SLOTS,
        budget: ForestBudget::Extractions(BUDGET),
        max_age_frames: 5,
        ..default()
    });
    harness
        .app_mut()
        .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)));
    let types: Vec<BakedFoliage> = vec![
        small_bake(TreeSpecies::olea(), 1200),
        small_bake(TreeSpecies::quercus(), 1500),
    ];
    let world = harness.world_mut();
    let handles: Vec<Handle<BakedFoliage>> = types
        .iter()
        .map(|t| world.resource_mut::<Assets<BakedFoliage>>().add(t.clone()))
        .collect();
    let material = world
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(StandardMaterial {
            base_color: Color::srgb(0.2, 0.45, 0.15),
            perceptual_roughness: 0.8,
            ..default()
        }));
    let mut trees = Vec::new();
    for row in 0..8 {
        for col in 0..6 {
            let ty = (row + col) % 2;
            let position = Vec3::new(col as f32 * 11.0 - 27.5, 0.0, -(row as f32) * 12.0 - 8.0);
            trees.push(
                world
                    .spawn((
                        ForestTree {
                            baked: handles[ty].clone(),
                            material: material.clone(),
                        },
                        Transform::from_translation(position)
                            .with_rotation(Quat::from_rotation_y(row as f32 * 1.3 + col as f32)),
                    ))
                    .id(),
            );
        }
    }
    world.spawn((
        DirectionalLight {
            illuminance: 8000.0,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.3, -1.0, -0.4), Vec3::Y),
    ));
    let camera = world
        .spawn((
            Camera3d::default(),
            Msaa::Off,
            Transform::from_xyz(0.0, 30.0, -120.0).looking_at(Vec3::new(0.0, 3.0, -40.0), Vec3::Y),
        ))
        .id();
    harness.wait_until_ready().unwrap();
    // The camera jumps to the other end of the forest: every tree's LoD changes.
    *harness.world_mut().get_mut::<Transform>(camera).unwrap() =
        Transform::from_xyz(0.0, 6.0, 12.0).looking_at(Vec3::new(0.0, 3.0, -40.0), Vec3::Y);

    // The budget holds every frame until every visible tree draws its desired slot.
    let mut frames = 0;
    let (mut extractions, mut borrows) = (0u32, 0u32);
    loop {
        harness.step();
        frames += 1;
        let last = harness.world_mut().resource::<ForestState>().last;
        assert!(
            last.extractions <= BUDGET,
            "frame {frames}: {} extractions",
            last.extractions
        );
        extractions += last.extractions;
        borrows += last.borrows;
        if last.candidates == 0 && frames > 1 {
            break;
        }
        assert!(frames < 200, "the forest never settled: {last:?}");
    }
    for _ in 0..3 {
        harness.step();
    }
    eprintln!("settled after {frames} frames: {extractions} extractions, {borrows} borrows");
    assert!(
        borrows > extractions,
        "trees of a type at similar LoD should share extractions ({borrows} borrows, {extractions} extractions)"
    );
    let slots = LodSlots::uniform(SLOTS);
    let world = harness.world_mut();
    let mut visible = 0;
    for &tree in &trees {
        let lod = *world.get::<TreeLod>(tree).unwrap();
        if lod.visible {
            visible += 1;
            assert_eq!(
                lod.slot,
                Some(slots.slot_of(lod.desired_lod) as u32),
                "{lod:?}"
            );
            assert!(slots.contains(lod.slot.unwrap() as usize, lod.stored_lod));
        }
    }
    assert!(visible >= 20, "{visible} trees visible");
    let extraction_count = world
        .query_filtered::<(), With<ManagedPruning>>()
        .iter(world)
        .count();
    assert!(
        extraction_count <= 2 * (SLOTS as usize + 2),
        "{extraction_count} extractions for 2 types"
    );

    // Each extraction's GPU kept count equals the CPU reference, and every shown tree draws
    // its extraction's instance slot.
    let baked_assets: Vec<(Entity, FoliageSlot, PruningParams, Handle<BakedFoliage>)> = world
        .query_filtered::<(Entity, &FoliageSlot, &PruningParams, &PrunedFoliage), With<ManagedPruning>>()
        .iter(world)
        .map(|(e, s, p, f)| (e, *s, *p, f.baked.clone()))
        .collect();
    let render_world = harness.app().get_sub_app(RenderApp).unwrap().world();
    let frame = render_world.resource::<PruningFrame>();
    let draws = read_buffer_now(
        render_world.resource::<RenderDevice>(),
        render_world.resource::<RenderQueue>(),
        frame.draws.as_ref().unwrap(),
    )
    .unwrap();
    let draws: Vec<u32> = draws
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    for (_, slot, params, baked) in &baked_assets {
        let ty = handles.iter().position(|h| h == baked).unwrap();
        let expected = kept_index_total(
            &types[ty].pruning_input(),
            &params.camera.weights,
            params.camera.distance_fixed,
        );
        assert_eq!(
            draws[slot.camera.slot as usize * 5],
            expected,
            "extraction {slot:?}"
        );
    }
    let world = harness.world_mut();
    let slots_in_use: Vec<u32> = baked_assets
        .iter()
        .map(|(_, s, ..)| s.camera.slot)
        .collect();
    for &tree in &trees {
        if world.get::<Visibility>(tree) == Some(&Visibility::Hidden) {
            continue;
        }
        let tag = world
            .get::<MeshTag>(tree)
            .expect("a shown tree has a tag")
            .0;
        // Procedural leaves are quads: drawn with quad slot meshes (tag bit 31).
        assert_ne!(tag & QUAD_TAG_BIT, 0, "quad leaves use the quad path");
        let instance = tag & !QUAD_TAG_BIT;
        assert!(
            slots_in_use.contains(&instance),
            "tree draws instance {instance}"
        );
    }

    // Colour coding: every shown tree draws its material tinted by the LoD band it draws, and its
    // own material again once switched off.
    harness
        .world_mut()
        .resource_mut::<ImpostorSettings>()
        .show_representation = true;
    harness.step();
    let mut bands = [0usize; 4];
    let world = harness.world_mut();
    for &tree in &trees {
        if world.get::<Visibility>(tree) == Some(&Visibility::Hidden) {
            continue;
        }
        let lod = *world.get::<TreeLod>(tree).unwrap();
        let drawn = world
            .get::<MeshMaterial3d<LeafMaterial>>(tree)
            .unwrap()
            .0
            .id();
        let colour = world
            .resource::<Assets<LeafMaterial>>()
            .get(drawn)
            .unwrap()
            .base
            .base_color;
        let band = geometry_band(lod.stored_lod);
        bands[band] += 1;
        assert_eq!(colour, GEOMETRY_TINTS[band], "{lod:?}");
    }
    assert!(
        bands.iter().filter(|&&n| n > 0).count() >= 2,
        "the settled forest should draw several LoD bands: {bands:?}"
    );
    harness
        .world_mut()
        .resource_mut::<ImpostorSettings>()
        .show_representation = false;
    harness.step();
    let world = harness.world_mut();
    for &tree in &trees {
        if let Some(drawn) = world.get::<MeshMaterial3d<LeafMaterial>>(tree) {
            assert_eq!(drawn.0, material, "colour coding switched off");
        }
    }

    // Image: the managed forest against the same forest at full detail, same run.
    let managed = harness.render().unwrap();
    let managed_triangles = triangles(&mut harness);
    harness.world_mut().resource_mut::<ForestSettings>().enabled = false;
    for _ in 0..8 {
        harness.step();
    }
    let full = harness.render().unwrap();
    let full_triangles = triangles(&mut harness);
    let cmp = Comparison::new("forest/managed_vs_full", &managed, &full);
    // Leaves are a pixel or two here: pruned and full crowns differ leaf by leaf wherever
    // leaves are dropped, so per-pixel RMSE mostly counts leaves; the 8×8 block means compare
    // what the forest looks like, its crowns' density.
    let blocks = Comparison::new(
        "forest/managed_vs_full_8x8",
        &managed.box_downsample(8),
        &full.box_downsample(8),
    );
    eprintln!(
        "managed forest: {managed_triangles} leaf triangles vs {full_triangles} at full detail ({:.1} %), RMSE {:.4} (8x8 blocks {:.4}), SSIM {:.3}",
        100.0 * managed_triangles / full_triangles,
        cmp.rmse,
        blocks.rmse,
        cmp.ssim
    );
    cmp.assert(
        managed_triangles < 0.7 * full_triangles,
        "the manager should draw clearly fewer leaves than full detail",
    );
    blocks.assert(
        blocks.rmse < 0.05,
        "seen in 8x8 blocks, the managed forest should look like the full-detail one",
    );
}
