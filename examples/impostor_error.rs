//! Image error of a billboard cloud against the full tree it stands for, by distance, for a
//! procedural tree and for glTF trees of the corpus (alpha-textured leaf cards, a palm of welded
//! fronds): each tree rendered in one headless run at a few crown sizes on screen, once at full
//! detail (every leaf, pruning off) and once as its billboard cloud, baked on the GPU in the same
//! run. Per distance: per-pixel RMSE, RMSE of 8×8 block means, and the coverage difference
//! (pixels that are not sky, impostor minus full, relative to full). Also the bake: planes, time,
//! texture bytes.
//!
//! ```text
//! cargo run --example impostor_error -- [--size N] [--out DIR]
//! ```

use bevy::ecs::system::RunSystemOnce;
use bevy::prelude::*;
use bevy_nature::foliage::corpus;
use bevy_nature::foliage::impostor::assets::BillboardCloudAsset;
use bevy_nature::foliage::impostor::bake::{
    ImpostorBakeRequest, ImpostorBakeResult, ImpostorBakeSettings,
};
use bevy_nature::foliage::impostor::texture::{BakeSurface, ImpostorSource};
use bevy_nature::foliage::meshes::{bark_mesh, leaf_set_mesh};
use bevy_nature::foliage::pruning::gltf::{GltfLeafSettings, load_gltf_tree};
use bevy_nature::foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_nature::foliage::pruning::spawn::{
    TreeAssets, default_bark_material, default_leaf_material,
};
use bevy_nature::foliage::{FoliagePlugin, FoliagePruningSettings};
use bevy_nature_harness::compare::{Comparison, RgbaImage, coverage_against_background};
use bevy_nature_harness::headless::HarnessConfig;
use bevy_nature_harness::{RenderHarness, require_adapter};
use std::path::PathBuf;
use std::sync::Arc;

const SKY: [u8; 4] = [140, 179, 230, 255];
/// Crown diameters on screen, fractions of the view height.
const SCREEN_SIZES: [f32; 5] = [0.5, 0.25, 0.12, 0.06, 0.03];
const FOV: f32 = 0.6;

#[derive(Component)]
struct Subject;

enum TreeKind {
    Procedural(TreeSpecies),
    Gltf(corpus::CorpusTree),
}

fn surface(look: &StandardMaterial, cutoff: f32) -> BakeSurface {
    let c = look.base_color.to_linear();
    BakeSurface {
        base_color: Vec4::new(c.red, c.green, c.blue, c.alpha),
        texture: None,
        alpha_cutoff: cutoff,
    }
}

fn main() {
    let mut size = 192u32;
    let mut out: Option<PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--size" => size = args.next().and_then(|v| v.parse().ok()).unwrap_or(size),
            "--out" => out = args.next().map(PathBuf::from),
            other => {
                eprintln!("unknown flag {other}: [--size N] [--out DIR]");
                std::process::exit(2);
            }
        }
    }
    if require_adapter("impostor_error").is_none() {
        std::process::exit(1);
    }
    let dir = std::env::temp_dir().join(format!("impostor-error-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let trees = vec![
        (
            "procedural olive",
            TreeKind::Procedural(TreeSpecies::olea().with_leaf_count(3000)),
        ),
        (
            "glTF alpha cards",
            TreeKind::Gltf(corpus::alpha_card_tree()),
        ),
        ("glTF palm fronds", TreeKind::Gltf(corpus::frond_tree())),
    ];
    let mut harness = RenderHarness::new(HarnessConfig::sized(size, size)).expect("harness");
    harness
        .app_mut()
        .add_plugins(FoliagePlugin)
        .insert_resource(ClearColor(Color::srgba_u8(SKY[0], SKY[1], SKY[2], 255)))
        .insert_resource(FoliagePruningSettings {
            enabled: false,
            ..default()
        });
    harness.world_mut().spawn((
        Camera3d::default(),
        Msaa::Off,
        Projection::Perspective(PerspectiveProjection {
            fov: FOV,
            ..default()
        }),
    ));
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: 9000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.4, -1.0, -0.6), Vec3::Y),
    ));
    let mut rows = Vec::new();
    for (name, kind) in trees {
        // The source of the bake, and the full tree as a user's scene draws it.
        let source = match &kind {
            TreeKind::Procedural(species) => {
                let tree = generate(species);
                let mut s = ImpostorSource::default();
                s.push_leaves(&tree.leaves, surface(&default_leaf_material(), 0.5));
                s.push_bark(&tree.bark, surface(&default_bark_material(), 0.0));
                let world = harness.world_mut();
                let leaves = world
                    .resource_mut::<Assets<Mesh>>()
                    .add(leaf_set_mesh(&tree.leaves));
                let bark = world
                    .resource_mut::<Assets<Mesh>>()
                    .add(bark_mesh(&tree.bark));
                let leaf_mat =
                    world
                        .resource_mut::<Assets<StandardMaterial>>()
                        .add(StandardMaterial {
                            double_sided: true,
                            cull_mode: None,
                            ..default_leaf_material()
                        });
                let bark_mat = world
                    .resource_mut::<Assets<StandardMaterial>>()
                    .add(default_bark_material());
                world
                    .spawn((Subject, Transform::IDENTITY, Visibility::Inherited))
                    .with_children(|t| {
                        t.spawn((Mesh3d(leaves), MeshMaterial3d(leaf_mat)));
                        t.spawn((Mesh3d(bark), MeshMaterial3d(bark_mat)));
                    });
                s
            }
            TreeKind::Gltf(tree) => {
                let path = tree.write(&dir).expect("write glTF");
                let bytes = std::fs::read(&path).unwrap();
                let gltf = load_gltf_tree(&bytes, path.parent(), &GltfLeafSettings::default())
                    .expect("glTF");
                let p = path.clone();
                harness
                    .world_mut()
                    .run_system_once(move |mut commands: Commands, mut assets: TreeAssets| {
                        let root = assets
                            .spawn_gltf(
                                &mut commands,
                                &p,
                                &GltfLeafSettings::default(),
                                Transform::IDENTITY,
                            )
                            .expect("spawn glTF");
                        commands.entity(root).insert(Subject);
                    })
                    .unwrap();
                ImpostorSource::from_gltf(&gltf)
            }
        };
        let request = harness
            .world_mut()
            .spawn(ImpostorBakeRequest {
                label: name.into(),
                source: Arc::new(source),
                settings: ImpostorBakeSettings::default(),
                save_to: None,
            })
            .id();
        let data = loop {
            harness.step();
            if let Some(r) = harness.world_mut().get::<ImpostorBakeResult>(request) {
                break r.0.clone().expect("bake");
            }
        };
        let world = harness.world_mut();
        let asset = BillboardCloudAsset::from_data_in(world, &data);
        let impostor = world
            .spawn((
                Mesh3d(asset.mesh.clone()),
                MeshMaterial3d(asset.material.clone()),
                Transform::IDENTITY,
                Visibility::Hidden,
            ))
            .id();
        eprintln!(
            "{name}: {} planes, bake {:.0} ms, {:.2} MiB of textures",
            data.planes.len(),
            data.bake_ms,
            data.texture_bytes() as f64 / (1 << 20) as f64
        );
        if let Some(out) = &out {
            // The atlas itself: albedo over coverage (empty texels grey), and the normals.
            let mut albedo = data.albedo.clone();
            for p in albedo.chunks_exact_mut(4) {
                if p[3] < 128 {
                    p.copy_from_slice(&[64, 64, 64, 255]);
                }
            }
            let tag = name.replace(' ', "_");
            RgbaImage::new(data.atlas_size, data.atlas_size, albedo)
                .save_png(out.join(format!("{tag}_atlas_albedo.png")))
                .ok();
            RgbaImage::new(data.atlas_size, data.atlas_size, data.normal.clone())
                .save_png(out.join(format!("{tag}_atlas_normal.png")))
                .ok();
        }
        let yy = 1.0 / (FOV / 2.0).tan();
        for s in SCREEN_SIZES {
            // Crown diameter 2R spans s of the view height: d = R·cot(fov/2)/s.
            let d = data.radius * yy / s;
            let eye = data.center + Vec3::new(0.3, 0.05, 1.0).normalize() * d;
            let world = harness.world_mut();
            let mut cams = world.query_filtered::<&mut Transform, With<Camera3d>>();
            for mut t in cams.iter_mut(world) {
                *t = Transform::from_translation(eye).looking_at(data.center, Vec3::Y);
            }
            let render = |harness: &mut RenderHarness, full: bool| {
                let world = harness.world_mut();
                let subjects: Vec<Entity> = world
                    .query_filtered::<Entity, With<Subject>>()
                    .iter(world)
                    .collect();
                for e in subjects {
                    *world.get_mut::<Visibility>(e).unwrap() = if full {
                        Visibility::Inherited
                    } else {
                        Visibility::Hidden
                    };
                }
                *world.get_mut::<Visibility>(impostor).unwrap() = if full {
                    Visibility::Hidden
                } else {
                    Visibility::Inherited
                };
                for _ in 0..4 {
                    harness.step();
                }
                harness.wait_until_ready().unwrap();
                harness.render().unwrap()
            };
            let full = render(&mut harness, true);
            let imp = render(&mut harness, false);
            let rmse = Comparison::new("impostor_error", &imp, &full).rmse;
            let blocks = Comparison::new(
                "impostor_error_8x8",
                &imp.box_downsample(8),
                &full.box_downsample(8),
            )
            .rmse;
            let (cf, ci) = (
                coverage_against_background(&full, SKY, 12),
                coverage_against_background(&imp, SKY, 12),
            );
            if let Some(out) = &out {
                let tag = format!("{}_{s}", name.replace(' ', "_"));
                full.save_png(out.join(format!("{tag}_full.png"))).ok();
                imp.save_png(out.join(format!("{tag}_impostor.png"))).ok();
            }
            rows.push(format!(
                "{{\"tree\": \"{name}\", \"planes\": {}, \"bake_ms\": {:.0}, \"texture_bytes\": {}, \"screen_size\": {s}, \"distance_m\": {d:.1}, \"distance_radii\": {:.1}, \"rmse\": {rmse:.4}, \"rmse_8x8\": {blocks:.4}, \"coverage_full\": {cf:.4}, \"coverage_impostor\": {ci:.4}, \"coverage_difference\": {:.3}}}",
                data.planes.len(),
                data.bake_ms,
                data.texture_bytes(),
                d / data.radius,
                (ci - cf) / cf.max(1e-9)
            ));
            eprintln!("{}", rows.last().unwrap());
        }
        // Clear the stage for the next tree.
        let world = harness.world_mut();
        let subjects: Vec<Entity> = world
            .query_filtered::<Entity, With<Subject>>()
            .iter(world)
            .collect();
        for e in subjects {
            world.entity_mut(e).despawn();
        }
        world.entity_mut(impostor).despawn();
    }
    println!(
        "{{\"bench\": \"impostor_error\", \"size\": {size}, \"rows\": [\n  {}\n]}}",
        rows.join(",\n  ")
    );
    std::fs::remove_dir_all(dir).ok();
}
