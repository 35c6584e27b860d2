//! Billboard-cloud impostors on the GPU: the atlas the GPU bake renders equals the CPU reference
//! texel by texel (coverage, albedo, normals, leaf or bark, the tree lighting's attenuations), a
//! bake that cannot work fails with a message and no
//! panic, and a forest tree beyond the pruning's `far` is drawn by its impostor — close to the full
//! tree rendered in the same run — instead of by nothing.

use bevy::prelude::*;
use bevy_foliage::FoliagePlugin;
use bevy_foliage::impostor::bake::{
    ImpostorBakeRaw, ImpostorBakeRequest, ImpostorBakeResult, ImpostorBakeSettings,
};
use bevy_foliage::impostor::format::ImpostorData;
use bevy_foliage::impostor::texture::{BakeSurface, ImpostorSource, bake_reference};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_nature_harness::RenderHarness;
use std::sync::Arc;

fn solid(r: f32, g: f32, b: f32) -> BakeSurface {
    BakeSurface {
        base_color: Vec4::new(r, g, b, 1.0),
        texture: None,
        alpha_cutoff: 0.5,
    }
}

/// A small olive tree: leaves green, bark brown.
pub fn olive_source(leaves: usize) -> ImpostorSource {
    let tree = generate(&TreeSpecies::olea().with_leaf_count(leaves));
    let mut source = ImpostorSource::default();
    source.push_leaves(&tree.leaves, solid(0.12, 0.35, 0.08));
    source.push_bark(&tree.bark, solid(0.3, 0.2, 0.12));
    source
}

/// The billboard cloud of `data` as an asset, built the way the loader builds it.
fn cloud_asset(
    world: &mut World,
    data: &ImpostorData,
) -> Handle<bevy_foliage::impostor::assets::BillboardCloudAsset> {
    use bevy_foliage::impostor::assets::BillboardCloudAsset;
    let asset = BillboardCloudAsset::from_data_in(world, data);
    world
        .resource_mut::<Assets<BillboardCloudAsset>>()
        .add(asset)
}

/// Fraction of the image that is not the sky colour `sky`.
fn coverage(image: &bevy_nature_harness::compare::RgbaImage, sky: Color) -> f64 {
    let bg = sky.to_srgba();
    let bg = [
        (bg.red * 255.0).round() as u8,
        (bg.green * 255.0).round() as u8,
        (bg.blue * 255.0).round() as u8,
        255,
    ];
    bevy_nature_harness::compare::coverage_against_background(image, bg, 12)
}

/// Steps until the request's result arrives.
fn bake(
    harness: &mut RenderHarness,
    source: ImpostorSource,
    atlas_size: u32,
) -> (Entity, Result<Arc<ImpostorData>, String>) {
    let entity = harness
        .world_mut()
        .spawn(ImpostorBakeRequest {
            label: "test olive".into(),
            source: Arc::new(source),
            settings: ImpostorBakeSettings {
                atlas_size,
                ..default()
            },
            save_to: None,
        })
        .id();
    for _ in 0..200 {
        harness.step();
        if let Some(result) = harness.world_mut().get::<ImpostorBakeResult>(entity) {
            return (entity, result.0.clone());
        }
    }
    panic!("the bake never finished");
}

/// A glTF tree of the corpus: alpha-textured leaf cards (their own texture and cutoff).
fn alpha_card_source() -> ImpostorSource {
    use bevy_foliage::corpus::alpha_card_tree;
    use bevy_foliage::pruning::gltf::{GltfLeafSettings, load_gltf_tree};
    let tree = alpha_card_tree();
    let gltf = load_gltf_tree(tree.gltf.as_bytes(), None, &GltfLeafSettings::default()).unwrap();
    let source = ImpostorSource::from_gltf(&gltf);
    assert!(source.surfaces.iter().any(|s| s.texture.is_some()));
    source
}

#[test]
fn gpu_bake_matches_the_cpu_reference() {
    check_gpu_bake_against_reference("impostor_bake", olive_source(400));
}

#[test]
fn gpu_bake_of_a_gltf_tree_matches_the_cpu_reference() {
    check_gpu_bake_against_reference("impostor_bake_gltf", alpha_card_source());
}

fn check_gpu_bake_against_reference(test: &str, source: ImpostorSource) {
    let Some(mut harness) = RenderHarness::for_test(test, 64, 64) else {
        return;
    };
    harness.app_mut().add_plugins(FoliagePlugin);
    harness
        .world_mut()
        .spawn((Camera3d::default(), Transform::from_xyz(0.0, 2.0, 10.0)));
    let (entity, result) = bake(&mut harness, source.clone(), 256);
    let data = result.expect("bake");
    let raw = harness
        .world_mut()
        .get::<ImpostorBakeRaw>(entity)
        .expect("raw atlases")
        .clone();
    assert!(data.planes.len() >= 3, "{} planes", data.planes.len());
    let light = source.leaf_light(ImpostorBakeSettings::default().bins);
    assert_eq!(data.extinction, light.extinction);
    let reference = bake_reference(&source, &raw.cloud, &raw.layout, &light);
    let (albedo, normal) = (&reference.albedo, &reference.normal);
    let texels = (raw.layout.size * raw.layout.size) as usize;
    let (mut covered_cpu, mut covered_gpu, mut disagree, mut colour_off, mut normal_off, mut both) =
        (0usize, 0usize, 0usize, 0usize, 0usize, 0usize);
    let (mut light_off, mut bark, mut dim) = (0usize, 0usize, 0usize);
    // Per plane, texels only the CPU covers and texels only the GPU covers.
    let mut disagree_by_plane = std::collections::BTreeMap::new();
    for i in 0..texels {
        let (c, g) = (albedo[i * 4 + 3] == 255, raw.albedo[i * 4 + 3] == 255);
        covered_cpu += c as usize;
        covered_gpu += g as usize;
        if c != g {
            disagree += 1;
            let (x, y) = (i as u32 % raw.layout.size, i as u32 / raw.layout.size);
            if let Some(k) = raw.layout.rects.iter().position(|r| {
                (r.min[0]..r.min[0] + r.size[0]).contains(&x)
                    && (r.min[1]..r.min[1] + r.size[1]).contains(&y)
            }) {
                let counts = disagree_by_plane.entry(k).or_insert((0usize, 0usize));
                if c {
                    counts.0 += 1;
                } else {
                    counts.1 += 1;
                }
            }
            continue;
        }
        if !c {
            continue;
        }
        both += 1;
        let diff = |a: &[u8], b: &[u8]| {
            (0..3)
                .map(|k| (a[i * 4 + k] as i32 - b[i * 4 + k] as i32).abs())
                .max()
                .unwrap()
        };
        if diff(albedo, &raw.albedo) > 2 {
            colour_off += 1;
        }
        if diff(normal, &raw.normal) > 4 {
            normal_off += 1;
        }
        // The nine light values of the texel's leaf.
        let light_diff = (0..3)
            .flat_map(|k| (0..3).map(move |c| (k, c)))
            .map(|(k, c)| {
                (reference.light[k][i * 4 + c] as i32 - raw.light[k][i * 4 + c] as i32).abs()
            })
            .max()
            .unwrap();
        if light_diff > 2 {
            light_off += 1;
        }
        bark += (reference.light[2][i * 4 + 2] == 0) as usize;
        dim += (reference.light[0][i * 4 + 1] < 128) as usize;
    }
    eprintln!(
        "{} planes, covered CPU {covered_cpu} GPU {covered_gpu}, disagree {disagree}, colour off {colour_off}, normal off {normal_off}, light off {light_off} ({bark} bark, {dim} dim in bin 1) of {both}",
        data.planes.len()
    );
    let planes_off: Vec<_> = disagree_by_plane
        .iter()
        .filter(|(_, (cpu, gpu))| cpu + gpu > 20)
        .collect();
    if !planes_off.is_empty() {
        eprintln!(
            "planes with more than 20 texels covered by one side only (CPU, GPU): {planes_off:?}"
        );
    }
    // The atlas is not empty, and the GPU covers the same texels: edge texels whose centre lies
    // on a triangle edge may go either way, nothing more (a shifted or flipped plane rectangle
    // disagrees on most covered texels).
    assert!(covered_cpu > texels / 20, "{covered_cpu} of {texels}");
    assert!(
        (disagree as f64) < 0.01 * covered_cpu as f64,
        "{disagree} texels differ in coverage of {covered_cpu}"
    );
    // Where both cover a texel, the same triangle won: same colour, same normal. Leaves and
    // bark differ in colour, so a wrong depth order shows.
    assert!(
        (colour_off as f64) < 0.005 * both as f64,
        "{colour_off} of {both}"
    );
    assert!(
        (normal_off as f64) < 0.01 * both as f64,
        "{normal_off} of {both}"
    );
    // The same leaf's light, leaf and bark told apart: the crown's attenuations vary from leaf
    // to leaf (many texels let less than a fifth of the light through in bin 1), so a texel
    // showing another leaf, or values swapped, shows.
    assert!(bark > 0, "the bark is baked as bark");
    assert!(
        (light_off as f64) < 0.005 * both as f64,
        "{light_off} of {both}"
    );
    assert!(dim > both / 10, "{dim} of {both}");
}

#[test]
fn a_bake_that_cannot_work_fails_with_a_message() {
    let Some(mut harness) = RenderHarness::for_test("impostor_bake_bad", 32, 32) else {
        return;
    };
    harness.app_mut().add_plugins(FoliagePlugin);
    harness.world_mut().spawn(Camera3d::default());
    // No triangles at all.
    let (_, empty) = bake(&mut harness, ImpostorSource::default(), 256);
    assert!(empty.unwrap_err().contains("no triangles"));
    // Only degenerate triangles (a tree collapsed to a point).
    let mut degenerate = olive_source(50);
    for t in &mut degenerate.triangles {
        t.positions = [Vec3::ONE; 3];
    }
    let (_, collapsed) = bake(&mut harness, degenerate, 256);
    assert!(collapsed.is_err());
}

/// A camera on the ground looking at one olive `distance` m away, with `far` at half that: the
/// tree is beyond `far`, where pruning leaves it no leaves.
#[test]
fn a_tree_beyond_far_is_drawn_by_its_impostor_close_to_the_full_tree() {
    use bevy_foliage::impostor::systems::{ImpostorSettings, TreeBark, TreeImpostor};
    use bevy_foliage::meshes::{bark_mesh, leaf_set_mesh};
    use bevy_foliage::pruning::bake::{BakeSettings, bake as bake_pruning};
    use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
    use bevy_foliage::{FoliagePruningSettings, ForestTree, LodDistances};
    use bevy_nature_harness::compare::Comparison;

    let Some(mut harness) = RenderHarness::for_test("impostor_forest", 96, 96) else {
        return;
    };
    let sky = Color::srgb(0.55, 0.7, 0.9);
    harness
        .app_mut()
        .add_plugins(FoliagePlugin)
        .insert_resource(ClearColor(sky))
        .insert_resource(FoliagePruningSettings {
            distances: LodDistances::World {
                near: 5.0,
                far: 20.0,
            },
            ..default()
        });
    let distance = 40.0;
    harness.world_mut().spawn((
        Camera3d::default(),
        Msaa::Off,
        Projection::Perspective(PerspectiveProjection {
            fov: 0.25,
            ..default()
        }),
        Transform::from_xyz(0.0, 3.5, distance).looking_at(Vec3::new(0.0, 3.5, 0.0), Vec3::Y),
    ));
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: 8000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.3, -1.0, -0.5), Vec3::Y),
    ));
    let tree = generate(&TreeSpecies::olea().with_leaf_count(600));
    let leaf_colour = Vec4::new(0.12, 0.35, 0.08, 1.0);
    let bark_colour = Vec4::new(0.3, 0.2, 0.12, 1.0);
    let mut source = ImpostorSource::default();
    source.push_leaves(
        &tree.leaves,
        solid(leaf_colour.x, leaf_colour.y, leaf_colour.z),
    );
    source.push_bark(
        &tree.bark,
        solid(bark_colour.x, bark_colour.y, bark_colour.z),
    );
    let (_, result) = bake(&mut harness, source, 512);
    let data = result.expect("bake");

    let world = harness.world_mut();
    let leaf_look = StandardMaterial {
        base_color: Color::linear_rgb(leaf_colour.x, leaf_colour.y, leaf_colour.z),
        double_sided: true,
        cull_mode: None,
        ..default()
    };
    let bark_look = StandardMaterial {
        base_color: Color::linear_rgb(bark_colour.x, bark_colour.y, bark_colour.z),
        ..default()
    };
    let cloud = cloud_asset(world, &data);
    let baked = bake_pruning(&tree.leaves, &BakeSettings::default(), &|_| {})
        .unwrap()
        .0;
    let baked = world.resource_mut::<Assets<_>>().add(baked);
    let leaf_mat = world
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(leaf_look.clone()));
    let bark_mat = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(bark_look);
    let bark = world
        .resource_mut::<Assets<Mesh>>()
        .add(bark_mesh(&tree.bark));
    let managed = world
        .spawn((
            ForestTree {
                baked,
                material: leaf_mat,
            },
            TreeImpostor(cloud),
            Transform::IDENTITY,
        ))
        .with_child((
            Mesh3d(bark.clone()),
            MeshMaterial3d(bark_mat.clone()),
            TreeBark,
        ))
        .id();
    for _ in 0..20 {
        harness.step();
    }
    harness.wait_until_ready().unwrap();
    let with_impostor = harness.render().unwrap();
    {
        use bevy_foliage::impostor::systems::ImpostorOf;
        let world = harness.world_mut();
        let n = world
            .query_filtered::<(), With<ImpostorOf>>()
            .iter(world)
            .count();
        assert_eq!(n, 1, "one impostor child per tree");
    }
    harness
        .world_mut()
        .resource_mut::<ImpostorSettings>()
        .enabled = false;
    for _ in 0..6 {
        harness.step();
    }
    let without = harness.render().unwrap();

    // The reference: the same tree, every leaf, as plain meshes.
    let world = harness.world_mut();
    world.entity_mut(managed).despawn();
    let leaves = world
        .resource_mut::<Assets<Mesh>>()
        .add(leaf_set_mesh(&tree.leaves));
    let leaf_std = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(leaf_look);
    world
        .spawn((Transform::IDENTITY, Visibility::Inherited))
        .with_children(|t| {
            t.spawn((Mesh3d(bark), MeshMaterial3d(bark_mat)));
            t.spawn((Mesh3d(leaves), MeshMaterial3d(leaf_std)));
        });
    for _ in 0..6 {
        harness.step();
    }
    harness.wait_until_ready().unwrap();
    let reference = harness.render().unwrap();

    let cov = |img| coverage(img, sky);
    let (c_ref, c_imp, c_none) = (cov(&reference), cov(&with_impostor), cov(&without));
    let blocks = |img: &bevy_nature_harness::compare::RgbaImage| {
        Comparison::new(
            "impostor_8x8",
            &img.box_downsample(8),
            &reference.box_downsample(8),
        )
        .rmse
    };
    eprintln!(
        "coverage: reference {c_ref:.4}, impostor {c_imp:.4}, impostors off {c_none:.4}; 8x8 RMSE impostor {:.4}, off {:.4}",
        blocks(&with_impostor),
        blocks(&without)
    );
    assert!(c_ref > 0.05, "the tree fills part of the view: {c_ref}");
    // Without its impostor the tree beyond `far` is its bare trunk; with it, a crown of about the
    // full tree's coverage.
    assert!(c_none < 0.35 * c_ref, "{c_none} vs {c_ref}");
    assert!(
        (c_imp - c_ref).abs() < 0.2 * c_ref,
        "impostor coverage {c_imp} vs the full tree's {c_ref}"
    );
    assert!(blocks(&with_impostor) < 0.5 * blocks(&without));
}

/// The time-critical mixed LoD: under a small budget the nearest trees get pruned geometry and
/// the rest their billboard clouds, within the budget; when the budget grows, trees fade back to
/// geometry over the configured frames instead of popping; with no budget at all the forest is
/// impostors and still covers about what it covers at full detail.
#[test]
fn the_mixed_lod_chooses_under_the_budget_and_fades_over_frames() {
    use bevy_foliage::forest::components::MixedLodSettings;
    use bevy_foliage::forest::systems::ForestState;
    use bevy_foliage::impostor::systems::{TreeBark, TreeImpostor};
    use bevy_foliage::meshes::bark_mesh;
    use bevy_foliage::pruning::bake::{BakeSettings, bake as bake_pruning};
    use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
    use bevy_foliage::{
        FoliagePruningSettings, ForestBudget, ForestSettings, ForestTree, LodDistances, TreeLod,
    };

    let Some(mut harness) = RenderHarness::for_test("impostor_mixed_lod", 128, 64) else {
        return;
    };
    let sky = Color::srgb(0.55, 0.7, 0.9);
    const FADE: u32 = 4;
    harness
        .app_mut()
        .add_plugins(FoliagePlugin)
        .insert_resource(ClearColor(sky))
        .insert_resource(FoliagePruningSettings {
            distances: LodDistances::World {
                near: 5.0,
                far: 1000.0,
            },
            ..default()
        })
        .insert_resource(ForestSettings {
            budget: ForestBudget::Extractions(64),
            // Geometry only at full detail, impostors cheap: the choice is tree by tree.
            mixed: MixedLodSettings {
                enabled: true,
                budget_triangles: 0.0,
                fade_frames: FADE,
                min_lod: 1.0,
                impostor_fill_weight: 1.0,
                ..default()
            },
            ..default()
        });
    harness.world_mut().spawn((
        Camera3d::default(),
        Msaa::Off,
        Transform::from_xyz(0.0, 4.0, 12.0).looking_at(Vec3::new(0.0, 4.0, 0.0), Vec3::Y),
    ));
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: 8000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.3, -1.0, -0.5), Vec3::Y),
    ));
    let tree = generate(&TreeSpecies::olea().with_leaf_count(500));
    let mut source = ImpostorSource::default();
    source.push_leaves(&tree.leaves, solid(0.12, 0.35, 0.08));
    source.push_bark(&tree.bark, solid(0.3, 0.2, 0.12));
    let (_, result) = bake(&mut harness, source, 256);
    let data = result.expect("bake");
    let world = harness.world_mut();
    let cloud = cloud_asset(world, &data);
    let baked = bake_pruning(&tree.leaves, &BakeSettings::default(), &|_| {})
        .unwrap()
        .0;
    let leaf_triangles = (baked.indices.len() / 3) as f32;
    let baked = world.resource_mut::<Assets<_>>().add(baked);
    let leaf_mat = world
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(StandardMaterial {
            base_color: Color::linear_rgb(0.12, 0.35, 0.08),
            ..default()
        }));
    let bark_mat = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial::default());
    let bark = world
        .resource_mut::<Assets<Mesh>>()
        .add(bark_mesh(&tree.bark));
    // Six trees in a row going away from the camera, a little to the side of each other.
    let mut trees = Vec::new();
    for i in 0..6 {
        let z = -(i as f32) * 12.0;
        let x = if i % 2 == 0 { -3.0 } else { 3.0 };
        trees.push(
            world
                .spawn((
                    ForestTree {
                        baked: baked.clone(),
                        material: leaf_mat.clone(),
                    },
                    TreeImpostor(cloud.clone()),
                    Transform::from_xyz(x, 0.0, z),
                ))
                .with_child((
                    Mesh3d(bark.clone()),
                    MeshMaterial3d(bark_mat.clone()),
                    TreeBark,
                ))
                .id(),
        );
    }
    let weights = |harness: &mut RenderHarness| -> Vec<f32> {
        trees
            .iter()
            .map(|&t| {
                harness
                    .world_mut()
                    .get::<TreeLod>(t)
                    .unwrap()
                    .impostor_weight
            })
            .collect()
    };
    let cov = |img: &bevy_nature_harness::compare::RgbaImage| coverage(img, sky);

    // No budget: every tree fades to its impostor, one step per frame.
    harness.step();
    let mut last = weights(&mut harness);
    for _ in 0..FADE + 2 {
        harness.step();
        let now = weights(&mut harness);
        for (a, b) in last.iter().zip(&now) {
            assert!(b - a <= 1.0 / FADE as f32 + 1e-4, "a jump: {a} → {b}");
        }
        last = now;
    }
    assert!(last.iter().all(|&w| w == 1.0), "{last:?}");
    harness.wait_until_ready().unwrap();
    let impostors = harness.render().unwrap();

    // A budget of every impostor plus two and a half trees' switch to geometry: the nearest two
    // get it (64 per tree; impostor triangles at weight 1).
    let impostor_cost = 64.0 + 2.0 * data.planes.len() as f32;
    let budget = 6.0 * impostor_cost + 2.5 * (leaf_triangles - 2.0 * data.planes.len() as f32);
    harness
        .world_mut()
        .resource_mut::<ForestSettings>()
        .mixed
        .budget_triangles = budget;
    for _ in 0..FADE + 4 {
        harness.step();
    }
    let now = weights(&mut harness);
    let report = harness.world_mut().resource::<ForestState>().mixed_last;
    assert!(report.cost <= budget, "{} > {budget}", report.cost);
    assert_eq!((report.geometry, report.impostors), (2, 4), "{report:?}");
    // Geometry goes to the nearest trees: the weights never decrease towards the camera.
    for pair in now.windows(2) {
        assert!(pair[0] <= pair[1], "{now:?}");
    }
    assert_eq!(now[0], 0.0);
    assert_eq!(*now.last().unwrap(), 1.0);

    // Budget for everything: all geometry at full detail, faded in over the frames.
    harness
        .world_mut()
        .resource_mut::<ForestSettings>()
        .mixed
        .budget_triangles = 1e9;
    harness.step();
    let after_one = weights(&mut harness);
    assert!(
        after_one.iter().any(|&w| w > 0.0 && w < 1.0),
        "fading, not popping: {after_one:?}"
    );
    for _ in 0..FADE + 20 {
        harness.step();
    }
    assert!(weights(&mut harness).iter().all(|&w| w == 0.0));

    harness.wait_until_ready().unwrap();
    let geometry = harness.render().unwrap();
    let (ci, cg) = (cov(&impostors), cov(&geometry));
    eprintln!("coverage: impostors {ci:.4}, full geometry {cg:.4}, mixed report {report:?}");
    assert!(cg > 0.1, "{cg}");
    assert!(
        (ci - cg).abs() < 0.25 * cg,
        "impostors {ci} vs geometry {cg}"
    );
}
