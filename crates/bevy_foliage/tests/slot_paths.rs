//! Quad-leaf trees are drawn with indexed quad slot meshes (four vertex-stage runs per leaf),
//! other trees with non-indexed triangle slot meshes. Both paths must draw exactly the same
//! image: the same pruned tree is rendered once each way (forcing the triangle path) and the
//! images compared.

use bevy::prelude::*;
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage, CellCount, bake};
use bevy_foliage::pruning::components::PrunedFoliage;
use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_foliage::pruning::store::FoliageStore;
use bevy_foliage::{FoliagePlugin, FoliagePruningSettings, LodDistances};
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::compare::{Comparison, RgbaImage};

fn render(baked: &BakedFoliage, force_triangles: bool) -> Option<RgbaImage> {
    let mut harness = RenderHarness::for_test("slot_paths", 96, 96)?;
    harness.app_mut().add_plugins(FoliagePlugin);
    harness.app_mut().insert_resource(FoliagePruningSettings {
        distances: LodDistances::World {
            near: 5.0,
            far: 60.0,
        },
        ..default()
    });
    let world = harness.world_mut();
    world.resource_mut::<FoliageStore>().force_triangle_slots = force_triangles;
    let handle = world
        .resource_mut::<Assets<BakedFoliage>>()
        .add(baked.clone());
    let material = world
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(StandardMaterial {
            base_color: Color::srgb(0.2, 0.45, 0.15),
            ..default()
        }));
    world.spawn((
        PrunedFoliage {
            baked: handle,
            material,
        },
        Transform::IDENTITY,
    ));
    world.spawn((
        DirectionalLight::default(),
        Transform::default().looking_to(Vec3::new(-0.3, -1.0, -0.4), Vec3::Y),
    ));
    let crown = baked.crown_center();
    world.spawn((
        Camera3d::default(),
        Msaa::Off,
        Transform::from_translation(crown + Vec3::new(14.0, 3.0, 10.0)).looking_at(crown, Vec3::Y),
    ));
    harness.wait_until_ready().unwrap();
    for _ in 0..4 {
        harness.step();
    }
    let quads = harness
        .world_mut()
        .resource::<FoliageStore>()
        .types
        .values()
        .next()
        .unwrap()
        .quads;
    assert_eq!(quads, !force_triangles, "slot path in use");
    Some(harness.render().unwrap())
}

#[test]
fn quad_and_triangle_slot_meshes_draw_the_same_image() {
    let tree = generate(&TreeSpecies::quercus().with_leaf_count(3000));
    let (baked, _) = bake(
        &tree.leaves,
        &BakeSettings {
            cells: CellCount::Depth(6),
            resolution: 64,
            ..default()
        },
        &|_| {},
    )
    .unwrap();
    assert!(baked.quad_leaves());
    let Some(quads) = render(&baked, false) else {
        return;
    };
    let triangles = render(&baked, true).unwrap();
    let cmp = Comparison::new("slot_paths/quads_vs_triangles", &quads, &triangles);
    let background = quads.pixel(0, 0);
    let leaf_pixels = (0..96 * 96)
        .filter(|i| quads.pixel(i % 96, i / 96) != background)
        .count();
    cmp.assert(leaf_pixels > 500, "the tree should be drawn");
    cmp.assert(
        cmp.rmse < 1e-3,
        "both slot paths should draw the same pixels",
    );
}
