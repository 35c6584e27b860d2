//! Shadows keep their leaves: the ground shadow of a pruned tree, drawn from the shadow light's
//! own selection, keeps the darkness of the unpruned tree's shadow; drawn from the camera's
//! selection (as before) it thins. All three rendered in the same run, with the crown out of
//! the frame so only the shadow on the ground is compared. Inside `near` the shadow is the
//! unpruned one, pixel for pixel. Images go to `target/nature-artifacts/shadow_selection/`.

mod common;

use bevy::camera::{PerspectiveProjection, Projection};
use bevy::light::{CascadeShadowConfigBuilder, DirectionalLightShadowMap, GlobalAmbientLight};
use bevy::prelude::*;
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage, bake};
use bevy_foliage::pruning::components::{PrunedFoliage, PruningParams};
use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
use bevy_foliage::pruning::procedural::generate;
use bevy_foliage::pruning::render::PruningFrame;
use bevy_foliage::{FoliagePlugin, FoliagePruningSettings, LodDistances};
use bevy_nature_harness::compare::{Comparison, RgbaImage};
use bevy_nature_harness::{RenderHarness, artifacts_dir};
use common::render_with_settings;

const SIZE: u32 = 128;

/// Darkness the shadow casts on the ground: Σ over pixels of `max(0, lit − luma) / lit`, with
/// `lit` the luma of the sunlit ground (the brightest pixels).
fn shadow_mass(image: &RgbaImage) -> f64 {
    let mut lumas: Vec<f64> = (0..image.height)
        .flat_map(|y| (0..image.width).map(move |x| (x, y)))
        .map(|(x, y)| image.luma(x, y))
        .collect();
    lumas.sort_by(f64::total_cmp);
    let lit = lumas[lumas.len() * 95 / 100].max(1e-6);
    lumas.iter().map(|l| ((lit - l) / lit).max(0.0)).sum()
}

#[test]
fn the_lights_selection_keeps_the_shadow_that_the_cameras_thins() {
    let Some(mut harness) = RenderHarness::for_test("shadow_selection", SIZE, SIZE) else {
        return;
    };
    harness.app_mut().add_plugins(FoliagePlugin);
    let (near, far) = (5.0, 60.0);
    harness.app_mut().insert_resource(FoliagePruningSettings {
        distances: LodDistances::World { near, far },
        // Full-size leaves, so the comparison is about which leaves are drawn.
        subpixel_fade: false,
        ..default()
    });
    harness.app_mut().insert_resource(ClearColor(Color::BLACK));
    // Leaves large against the shadow map's texels (1,800 leaves of 0.4 m), so that the shadow
    // compares which leaves are drawn, not how sub-texel leaves alias; a crown sparse enough
    // that its shadow is dappled, not a solid blob.
    let mut species = bevy_foliage::corpus::alpha_card_species();
    species.leaf_size = 0.4;
    let tree = generate(&species);
    let (baked, _) = bake(&tree.leaves, &BakeSettings::default(), &|_| {}).unwrap();
    let crown = baked.crown_center();
    let world = harness.world_mut();
    world.insert_resource(GlobalAmbientLight {
        brightness: 50.0,
        ..default()
    });
    let handle = world
        .resource_mut::<Assets<BakedFoliage>>()
        .add(baked.clone());
    let material = world
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(StandardMaterial {
            base_color: Color::srgb(0.2, 0.5, 0.15),
            ..default()
        }));
    let tree_entity = world
        .spawn((
            PrunedFoliage {
                baked: handle,
                material,
            },
            Transform::IDENTITY,
        ))
        .id();
    let ground = world
        .resource_mut::<Assets<Mesh>>()
        .add(Plane3d::default().mesh().size(200.0, 200.0));
    let white = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::WHITE,
            perceptual_roughness: 1.0,
            ..default()
        });
    world.spawn((Mesh3d(ground), MeshMaterial3d(white)));
    // A sun from +x, 35° up: the shadow falls towards −x. One fine cascade over the scene.
    world.insert_resource(DirectionalLightShadowMap { size: 4096 });
    world.spawn((
        DirectionalLight {
            illuminance: 10_000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        CascadeShadowConfigBuilder {
            num_cascades: 1,
            maximum_distance: 70.0,
            ..default()
        }
        .build(),
        Transform::default().looking_to(Vec3::new(-0.82, -0.57, 0.0), Vec3::Y),
    ));
    // The camera looks down on the shadow from above and aside; the crown is out of frame. It
    // sees the crown from another side than the sun does.
    let target = Vec3::new(-14.0, 0.0, 0.0);
    let far_camera = Transform::from_xyz(-14.0, 32.0, 14.0).looking_at(target, Vec3::Y);
    let camera = world
        .spawn((
            Camera3d::default(),
            Msaa::Off,
            Projection::Perspective(PerspectiveProjection {
                fov: 0.6,
                ..default()
            }),
            far_camera,
        ))
        .id();
    harness.wait_until_ready().unwrap();

    let full = render_with_settings(&mut harness, |s| s.enabled = false);
    let light = render_with_settings(&mut harness, |s| {
        s.enabled = true;
        s.shadow_selection = true;
    });
    let params = *harness
        .world_mut()
        .get::<PruningParams>(tree_entity)
        .unwrap();
    {
        // The pass really ran with a light selection for this tree.
        let render_world = harness
            .app()
            .get_sub_app(bevy::render::RenderApp)
            .unwrap()
            .world();
        let frame = render_world.resource::<PruningFrame>();
        assert!(
            frame
                .instances
                .iter()
                .any(|i| i.entity == tree_entity && i.light)
        );
    }
    let camera_only = render_with_settings(&mut harness, |s| s.shadow_selection = false);
    let factor = params.camera.distance_fixed as f64 / 65536.0;
    let (m_full, m_light, m_camera) = (
        shadow_mass(&full),
        shadow_mass(&light),
        shadow_mass(&camera_only),
    );
    let dir = artifacts_dir().join("shadow_selection");
    for (name, image) in [("full", &full), ("light", &light), ("camera", &camera_only)] {
        image.save_png(dir.join(format!("{name}.png"))).unwrap();
    }
    let blocks = |a: &RgbaImage| {
        Comparison::new("blocks", &a.box_downsample(8), &full.box_downsample(8)).rmse
    };
    let (b_light, b_camera) = (blocks(&light), blocks(&camera_only));
    let report = format!(
        "distance factor {factor:.2}: shadow mass full {m_full:.0}, light's selection {m_light:.0} ({:+.1} %, 8x8 RMSE {b_light:.4}), camera's selection {m_camera:.0} ({:+.1} %, 8x8 RMSE {b_camera:.4})",
        100.0 * (m_light - m_full) / m_full,
        100.0 * (m_camera - m_full) / m_full
    );
    eprintln!("{report}");
    std::fs::write(dir.join("report.txt"), &report).unwrap();
    assert!(
        (0.3..0.7).contains(&factor),
        "the tree should be well into pruning: {factor}"
    );
    assert!(
        m_full > 300.0,
        "the shadow should fill a good part of the frame: {m_full}"
    );
    let light_error = (m_light - m_full).abs() / m_full;
    let camera_error = (m_camera - m_full).abs() / m_full;
    let cmp = Comparison::new("shadow_selection/light", &light, &full);
    cmp.assert(
        light_error < 0.1,
        &format!("the light's selection keeps the shadow's darkness within 10 % ({report})"),
    );
    cmp.assert(
        light_error < camera_error,
        &format!("the light's selection keeps the darkness better than the camera's ({report})"),
    );
    // Seen in 8×8 blocks, the light's shadow is where the full shadow is; the camera's has holes
    // where the leaves it does not see cast shadow, and blobs where its enlarged leaves do.
    Comparison::new("shadow_selection/camera", &camera_only, &full).assert(
        b_camera > 1.3 * b_light,
        &format!("the camera's selection should misplace the shadow clearly more ({report})"),
    );

    // Inside `near` (moved out past the camera) the camera keeps the leaves it sees and the
    // shadow draws the full set: the same image as without pruning, pixel for pixel.
    let near_pruned = render_with_settings(&mut harness, |s| {
        s.enabled = true;
        s.shadow_selection = true;
        s.distances = LodDistances::World {
            near: 45.0,
            far: 90.0,
        };
    });
    let params = *harness
        .world_mut()
        .get::<PruningParams>(tree_entity)
        .unwrap();
    assert_eq!(
        params.camera.distance_fixed, 65536,
        "inside near, outside the crown"
    );
    Comparison::new("shadow_selection/inside_near", &near_pruned, &full).assert_rmse_at_most(0.0);
    let near_camera = render_with_settings(&mut harness, |s| s.shadow_selection = false);
    Comparison::new("shadow_selection/inside_near_camera", &near_camera, &full)
        .assert_rmse_at_least(1e-3);
    let _ = (camera, crown);
}
