//! The GPU pruning pass against its CPU reference: for random cameras and tree instances, the
//! compacted index buffer read back from the GPU equals `extract_indices`, index for index, and
//! the indirect draw arguments carry the right counts — for the camera's selections and the
//! shadow light's, on a tree of 1,024 cells (the compute pass scans cells in chunks of 256) and
//! a small one. Runs on the adapter at hand (software Vulkan in CI; with `CI=true` a missing
//! adapter fails the test).

use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage, CellCount, bake};
use bevy_foliage::pruning::components::{FoliageCamera, PrunedFoliage, PruningParams};
use bevy_foliage::pruning::extract::{FIXED_ONE, KEEP_ALL, extract_indices};
use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_foliage::pruning::render::PruningFrame;
use bevy_foliage::pruning::selection::Selection;
use bevy_foliage::rng::SplitMix64;
use bevy_foliage::{FoliagePlugin, FoliagePruningSettings, LodDistances};
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::headless::read_buffer_now;

fn small_bake(species: TreeSpecies, leaves: usize, depth: u32) -> BakedFoliage {
    let tree = generate(&species.with_leaf_count(leaves));
    let settings = BakeSettings {
        cells: CellCount::Depth(depth),
        resolution: 64,
        ..default()
    };
    bake(&tree.leaves, &settings, &|_| {}).unwrap().0
}

fn words(bytes: &[u8]) -> Vec<u32> {
    bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

/// Reads this frame's pruning outputs: instance layouts, output indices and draw arguments.
fn read_frame(
    harness: &mut RenderHarness,
) -> (
    Vec<bevy_foliage::pruning::render::InstanceOutput>,
    Vec<u32>,
    Vec<u32>,
) {
    let render_world = harness.app().get_sub_app(RenderApp).unwrap().world();
    let frame = render_world.resource::<PruningFrame>();
    let device = render_world.resource::<RenderDevice>();
    let queue = render_world.resource::<RenderQueue>();
    let output =
        read_buffer_now(device, queue, frame.output.as_ref().expect("output buffer")).unwrap();
    let draws = read_buffer_now(device, queue, frame.draws.as_ref().expect("draw buffer")).unwrap();
    (frame.instances.clone(), words(&output), words(&draws))
}

/// Checks one extraction read back from the GPU against the CPU reference.
fn check(
    what: &str,
    inst: &bevy_foliage::pruning::render::InstanceOutput,
    selection: &Selection,
    baked: &BakedFoliage,
    output: &[u32],
    draws: &[u32],
) -> f64 {
    let reference = extract_indices(
        &baked.pruning_input(),
        &selection.weights,
        selection.distance_fixed,
    );
    let draw = &draws[inst.draw as usize * 5..inst.draw as usize * 5 + 5];
    let count = draw[0] as usize;
    assert_eq!(count, reference.indices.len(), "{what}: index count");
    assert_eq!(draw[1], 1, "{what}: instance count");
    assert_eq!(draw[2], inst.output_base, "{what}: first index");
    let base = inst.output_base as usize;
    let gpu: Vec<u32> = output[base..base + count]
        .iter()
        .map(|&i| i - inst.slot.vertex_base)
        .collect();
    assert!(
        gpu == reference.indices,
        "{what}: GPU indices differ from the CPU reference"
    );
    count as f64 / baked.indices.len() as f64
}

#[test]
fn gpu_compaction_equals_cpu_reference_for_random_cameras_and_instances() {
    let Some(mut harness) = RenderHarness::for_test("gpu_pruning", 32, 32) else {
        return;
    };
    harness.app_mut().add_plugins(FoliagePlugin);
    harness.app_mut().insert_resource(FoliagePruningSettings {
        distances: LodDistances::World {
            near: 20.0,
            far: 90.0,
        },
        ..default()
    });
    // A tree of 1,024 cells (four chunks of the scan) and a small one of 64, sharing the GPU
    // buffers.
    let types = [
        small_bake(TreeSpecies::fraxinus(), 20_000, 10),
        small_bake(TreeSpecies::olea(), 1200, 6),
    ];
    assert_eq!(types[0].cell_count(), 1024);
    let handles: Vec<Handle<BakedFoliage>> = {
        let mut assets = harness.world_mut().resource_mut::<Assets<BakedFoliage>>();
        types.iter().map(|t| assets.add(t.clone())).collect()
    };
    let material = harness
        .world_mut()
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(StandardMaterial::default()));
    let mut rng = SplitMix64::new(42);
    let mut trees = Vec::new();
    for i in 0..10 {
        let kind = i % 2;
        let transform = Transform::from_xyz(rng.range(-30.0, 30.0), 0.0, rng.range(-30.0, 30.0))
            .with_rotation(Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU)))
            .with_scale(Vec3::splat(rng.range(0.7, 1.4)));
        let entity = harness
            .world_mut()
            .spawn((
                PrunedFoliage {
                    baked: handles[kind].clone(),
                    material: material.clone(),
                },
                transform,
            ))
            .id();
        trees.push((entity, kind));
    }
    // A shadow-casting sun: every tree gets the light's own selection too.
    harness.world_mut().spawn((
        DirectionalLight {
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.4, -1.0, 0.3), Vec3::Y),
    ));
    let camera = harness
        .world_mut()
        .spawn((
            Camera3d::default(),
            FoliageCamera,
            Transform::from_xyz(0.0, 5.0, 40.0),
        ))
        .id();
    harness.wait_until_ready().unwrap();

    let mut kept_fractions = Vec::new();
    let mut light_records = 0;
    for round in 0..6 {
        let position = Vec3::new(
            rng.range(-50.0, 50.0),
            rng.range(-5.0, 30.0),
            rng.range(-50.0, 50.0),
        );
        *harness.world_mut().get_mut::<Transform>(camera).unwrap() =
            Transform::from_translation(position).looking_at(Vec3::ZERO, Vec3::Y);
        harness.step();
        let (instances, output, draws) = read_frame(&mut harness);
        assert_eq!(
            instances.iter().filter(|i| !i.light).count(),
            trees.len(),
            "every tree is pruned"
        );
        for inst in &instances {
            let kind = trees.iter().find(|(e, _)| *e == inst.entity).unwrap().1;
            let params = *harness
                .world_mut()
                .get::<PruningParams>(inst.entity)
                .unwrap();
            assert_eq!(params.camera.weights.weights.iter().sum::<u32>(), FIXED_ONE);
            let what = format!("round {round}, {:?}, light {}", inst.entity, inst.light);
            if inst.light {
                // Trees without a light selection (the camera keeps every leaf) keep nothing
                // here; shadow views draw the camera's record.
                let selection = params.light.unwrap_or(Selection::NONE);
                light_records += params.light.is_some() as u32;
                check(&what, inst, &selection, &types[kind], &output, &draws);
            } else {
                kept_fractions.push(check(
                    &what,
                    inst,
                    &params.camera,
                    &types[kind],
                    &output,
                    &draws,
                ));
            }
        }
    }
    assert!(
        light_records > 20,
        "light selections were checked: {light_records}"
    );
    // Pruning off: every leaf of every tree is written.
    harness
        .world_mut()
        .resource_mut::<FoliagePruningSettings>()
        .enabled = false;
    harness.step();
    harness.step();
    let (instances, output, draws) = read_frame(&mut harness);
    for inst in instances.iter().filter(|i| !i.light) {
        let kind = trees.iter().find(|(e, _)| *e == inst.entity).unwrap().1;
        let all = Selection {
            distance_fixed: KEEP_ALL,
            ..Selection::NONE
        };
        let kept = check("pruning off", inst, &all, &types[kind], &output, &draws);
        assert_eq!(kept, 1.0);
    }
    // The random cameras exercised the whole range: some trees fully pruned, some mostly kept.
    let (min, max) = kept_fractions
        .iter()
        .fold((1.0f64, 0.0f64), |(lo, hi), &f| (lo.min(f), hi.max(f)));
    eprintln!("kept fraction range over rounds: {min:.3} .. {max:.3}");
    assert!(
        min < 0.05 && max > 0.2,
        "cameras should span near and far: {min} .. {max}"
    );
}

#[test]
fn triangles_drawn_fall_with_distance_as_eq_3_4_and_3_5_predict() {
    let Some(mut harness) = RenderHarness::for_test("pruning_distance", 32, 32) else {
        return;
    };
    let (near, far) = (20.0, 80.0);
    harness.app_mut().add_plugins(FoliagePlugin);
    harness.app_mut().insert_resource(FoliagePruningSettings {
        distances: LodDistances::World { near, far },
        ..default()
    });
    let tree = small_bake(TreeSpecies::quercus(), 4000, 7);
    let handle = harness
        .world_mut()
        .resource_mut::<Assets<BakedFoliage>>()
        .add(tree.clone());
    let material = harness_material(&mut harness);
    let good = harness
        .world_mut()
        .spawn((
            PrunedFoliage {
                baked: handle.clone(),
                material,
            },
            Transform::IDENTITY,
        ))
        .id();
    let direction = Vec3::new(1.0, 0.3, 0.5).normalize();
    let camera = harness
        .world_mut()
        .spawn((
            Camera3d::default(),
            Transform::from_translation(direction * 20.0),
        ))
        .id();
    // Bad transforms: logged once, drawn as nothing, and the good tree is unaffected.
    let bad_material = harness_material(&mut harness);
    let bad: Vec<Entity> = [
        Transform::from_xyz(f32::NAN, 0.0, 0.0),
        Transform::from_scale(Vec3::ZERO),
    ]
    .into_iter()
    .map(|t| {
        harness
            .world_mut()
            .spawn((
                PrunedFoliage {
                    baked: handle.clone(),
                    material: bad_material.clone(),
                },
                t,
            ))
            .id()
    })
    .collect();
    harness.wait_until_ready().unwrap();
    {
        let (instances, _, draws) = read_frame(&mut harness);
        for entity in &bad {
            let inst = instances
                .iter()
                .find(|i| i.entity == *entity)
                .expect("bad tree still has a slot");
            assert_eq!(
                draws[inst.draw as usize * 5],
                0,
                "a tree that cannot be placed draws nothing"
            );
        }
    }

    // The camera moves away along a fixed direction from the crown centre, so the view-dependent
    // factor stays the same and only the distance factor (eq. 3.4, camera to crown centre)
    // changes.
    let crown = tree.crown_center();
    let drawn_at = |harness: &mut RenderHarness, s: f32| {
        *harness.world_mut().get_mut::<Transform>(camera).unwrap() =
            Transform::from_translation(crown + direction * s).looking_at(crown, Vec3::Y);
        harness.step();
        let (instances, _, draws) = read_frame(harness);
        let slot = instances.iter().find(|i| i.entity == good).unwrap().draw as usize;
        draws[slot * 5] / 3
    };
    // Inside the crown the exterior viewpoints' visibility does not apply: every leaf is kept.
    assert_eq!(
        drawn_at(&mut harness, 1.0) as usize * 3,
        tree.indices.len(),
        "inside the crown every leaf is drawn"
    );
    let r = tree.crown_radius();
    let mut drawn = Vec::new();
    for s in [r + 0.5, r + 1.5, 25.0, 38.0, 50.0, 62.0, 79.0, 85.0, 120.0] {
        drawn.push((s, drawn_at(&mut harness, s)));
    }
    eprintln!("(distance, triangles drawn): {drawn:?}");
    let full = drawn[0].1 as f32;
    assert!(drawn[0].0 < near && drawn[1].0 < near && full > 0.0);
    for &(d, tris) in &drawn {
        if d <= near {
            // Under `near` nothing is pruned by distance.
            assert_eq!(tris as f32, full, "at {d} m");
        } else if d >= far {
            // Beyond `far` everything is.
            assert_eq!(tris, 0, "at {d} m");
        } else {
            // In between, triangles = dist(d) · (triangles at full distance factor), eq. 3.4–3.5:
            // the carried rounding keeps the whole tree within one leaf of what it asks, so
            // within two leaves (four triangles) of the prediction.
            let predicted = (1.0 - (d - near) / (far - near)) * full;
            assert!(
                (tris as f32 - predicted).abs() <= 4.0,
                "at {d} m: {tris} triangles, eq. 3.4-3.5 predict {predicted:.1}"
            );
            assert!(tris > 0, "a factor above 0 keeps leaves at {d} m");
        }
    }
    assert!(drawn.iter().filter(|(d, _)| *d > near && *d < far).count() >= 4);
    assert!(
        drawn.windows(2).all(|w| w[1].1 <= w[0].1),
        "monotone in distance"
    );
}

fn harness_material(harness: &mut RenderHarness) -> Handle<LeafMaterial> {
    harness
        .world_mut()
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(StandardMaterial::default()))
}
