//! The trees' world-space opacity shadow map (Boulanger 2008, §5.5.2) on the GPU, against its CPU
//! reference, in one run:
//!
//! 1. the map the GPU drew from a pruned tree's shadow selection equals, texel for texel, the
//!    CPU's drawing (`opacity_casting::draw_pruned_leaves` into `opacity_map::OpacityShadowMap`)
//!    of the leaves the CPU's extraction keeps for the same selection;
//! 2. the ground's sunlight, divided by the same ground's without the tree, equals at every
//!    pixel the CPU's lookup (`opacity_map::visibility`) in the GPU's own map;
//! 3. the pruned crown's shadow keeps the unpruned crown's darkness (the light's selection
//!    without the view term, area-compensated).
//!
//! The crown is on a render layer the camera does not see, so only its shadow is in the frame;
//! the leaves are out of Bevy's shadow maps while the opacity map is on (asserted). Images go to
//! `target/nature-artifacts/opacity_shadow/`.

use bevy::camera::visibility::RenderLayers;
use bevy::camera::{OrthographicProjection, Projection, ScalingMode};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::light::{GlobalAmbientLight, NotShadowCaster};
use bevy::math::Affine3A;
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::render_asset::RenderAssets;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage, bake};
use bevy_foliage::pruning::components::{PrunedFoliage, PruningParams};
use bevy_foliage::pruning::extract::{UNIFORM_DISTANCE, extract_indices};
use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
use bevy_foliage::pruning::opacity_casting::{LeafCasting, draw_pruned_leaves};
use bevy_foliage::pruning::procedural::generate;
use bevy_foliage::{FoliagePlugin, FoliagePruningSettings, LodDistances};
use bevy_nature_harness::compare::RgbaImage;
use bevy_nature_harness::headless::read_texture_now;
use bevy_nature_harness::{RenderHarness, artifacts_dir};
use bevy_soft_shadows::SoftShadowsPlugin;
use bevy_soft_shadows::filterable::filter::MomentMap;
use bevy_soft_shadows::foliage::TreeOpacityShadows;
use bevy_soft_shadows::foliage::opacity_map::{OpacityShadowMap, visibility};
use bevy_soft_shadows::foliage::receiver::{TreeOpacityFrame, TreeOpacityImages};
use bevy_soft_shadows::reference::srgb_to_linear;

const SIZE: u32 = 96;
/// Metres the orthographic camera sees across.
const VIEW_M: f32 = 16.0;
/// From the ground to the sun: 60° up, from +x.
const TO_SUN: Vec3 = Vec3::new(0.5, 0.866_025_4, 0.0);
const SUN_ANGLE: f32 = 0.03;

/// The GPU's map, every level, as (height, transmittance, 0, 0) texels.
fn read_gpu_map(harness: &RenderHarness) -> Option<Vec<MomentMap>> {
    let handle = harness
        .app()
        .world()
        .resource::<TreeOpacityImages>()
        .map
        .clone();
    let render_world = harness.app().get_sub_app(RenderApp).unwrap().world();
    let device = render_world.resource::<RenderDevice>();
    let queue = render_world.resource::<RenderQueue>();
    let image = render_world
        .resource::<RenderAssets<GpuImage>>()
        .get(&handle)?;
    let texture = &image.texture;
    (0..texture.mip_level_count())
        .map(|level| {
            let bytes = read_texture_now(device, queue, texture, level, 1, 8).ok()?;
            let side = (texture.width() >> level).max(1);
            let texels = bytes
                .chunks_exact(8)
                .map(|t| {
                    let h = |i: usize| half::f16::from_le_bytes([t[i], t[i + 1]]).to_f32();
                    [h(0), h(2), h(4), h(6)]
                })
                .collect();
            Some(MomentMap {
                width: side,
                height: side,
                texels,
            })
        })
        .collect()
}

/// The ground point at the centre of each pixel of the top-down camera centred on `centre`.
fn ground_points(centre: Vec3) -> impl Iterator<Item = (usize, Vec3)> {
    let m_per_px = VIEW_M / SIZE as f32;
    (0..SIZE * SIZE).map(move |i| {
        let (col, row) = (i % SIZE, i / SIZE);
        let x = centre.x - VIEW_M / 2.0 + (col as f32 + 0.5) * m_per_px;
        let z = centre.z - VIEW_M / 2.0 + (row as f32 + 0.5) * m_per_px;
        (i as usize, Vec3::new(x, 0.0, z))
    })
}

/// Per pixel, the green channel in linear light of `image` over `lit`'s: the sun's visibility.
fn visibility_image(image: &RgbaImage, lit: &RgbaImage) -> Vec<f32> {
    (0..(SIZE * SIZE) as usize)
        .map(|i| {
            srgb_to_linear(image.data[i * 4 + 1]) / srgb_to_linear(lit.data[i * 4 + 1]).max(1e-4)
        })
        .collect()
}

fn step(harness: &mut RenderHarness, frames: u32) {
    for _ in 0..frames {
        harness.step();
    }
}

#[test]
fn the_gpu_map_and_its_lookup_match_the_cpu_and_pruning_keeps_the_darkness() {
    let Some(mut harness) = RenderHarness::for_test("opacity_shadow", SIZE, SIZE) else {
        return;
    };
    harness
        .app_mut()
        .add_plugins((FoliagePlugin, SoftShadowsPlugin));
    harness.app_mut().insert_resource(FoliagePruningSettings {
        distances: LodDistances::World {
            near: 10.0,
            far: 60.0,
        },
        subpixel_fade: false,
        ..default()
    });
    harness.app_mut().insert_resource(ClearColor(Color::BLACK));
    let mut species = bevy_foliage::corpus::alpha_card_species();
    // A dense crown of large leaves: a ray through it meets tens of leaves, its shadow dark.
    species.leaf_size = 0.5;
    species.leaf_count = 6000;
    let tree = generate(&species);
    let (baked, _) = bake(&tree.leaves, &BakeSettings::default(), &|_| {}).unwrap();
    let (lo, hi) = baked
        .positions
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        });
    let crown = baked.crown_center();
    // The shadow of the crown's centre on the ground.
    let centre = Vec3::new(crown.x - crown.y * TO_SUN.x / TO_SUN.y, 0.0, crown.z);
    let world = harness.world_mut();
    world.insert_resource(GlobalAmbientLight {
        brightness: 0.0,
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
                material: material.clone(),
            },
            Transform::IDENTITY,
            RenderLayers::layer(1),
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
            reflectance: 0.0,
            ..default()
        });
    world.spawn((Mesh3d(ground), MeshMaterial3d(white)));
    world.spawn((
        DirectionalLight {
            illuminance: 2_000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        TreeOpacityShadows {
            resolution: 256,
            bounds_min: lo - 0.5,
            bounds_max: hi + 0.5,
            plane_y: 0.0,
            sun_angle: SUN_ANGLE,
        },
        Transform::default().looking_to(-TO_SUN, Vec3::Y),
        RenderLayers::from_layers(&[0, 1]),
    ));
    world.spawn((
        Camera3d::default(),
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
        Projection::Orthographic(OrthographicProjection {
            scaling_mode: ScalingMode::Fixed {
                width: VIEW_M,
                height: VIEW_M,
            },
            ..OrthographicProjection::default_3d()
        }),
        Transform::from_translation(centre + Vec3::Y * 45.0).looking_at(centre, Vec3::NEG_Z),
    ));
    harness.wait_until_ready().expect("pipelines");
    step(&mut harness, 8);
    let pruned_image = harness.render().expect("render");
    let chain = read_gpu_map(&harness).expect("the map was made");
    let world = harness.world_mut();
    assert!(
        world.get::<NotShadowCaster>(tree_entity).is_some(),
        "the leaves are out of Bevy's shadow maps while the opacity map is on"
    );
    let params = *world.get::<PruningParams>(tree_entity).unwrap();
    let plane = world.resource::<TreeOpacityFrame>().0.expect("a map").plane;
    let casting = {
        let p = world
            .resource::<Assets<LeafMaterial>>()
            .get(&material)
            .unwrap()
            .extension
            .params;
        LeafCasting {
            area_compensation: p.area_compensation != 0,
            max_scale: p.max_scale,
            opaque_fraction: p.opaque_fraction,
        }
    };

    // 1. The map, texel for texel.
    let light = params.light.expect("a light selection");
    let factor = (light.distance_fixed & !UNIFORM_DISTANCE) as f32 / 65536.0;
    assert!(
        light.distance_fixed & UNIFORM_DISTANCE != 0 && (0.3..0.8).contains(&factor),
        "the light's selection is pruned, without the view term: {:#x}",
        light.distance_fixed
    );
    let extraction = extract_indices(&baked.pruning_input(), &light.weights, light.distance_fixed);
    let mut cpu = OpacityShadowMap::new(plane);
    draw_pruned_leaves(&mut cpu, &baked, &extraction, Affine3A::IDENTITY, &casting);
    let gpu = &chain[0];
    assert_eq!((gpu.width, gpu.height), plane.resolution);
    let shaded = cpu.texels.texels.iter().filter(|t| t[1] < 1.0).count();
    let (mut t_off, mut h_off, mut worst_t) = (0usize, 0usize, 0f32);
    for (g, c) in gpu.texels.iter().zip(&cpu.texels.texels) {
        let dt = (g[1] - c[1]).abs();
        worst_t = worst_t.max(dt);
        t_off += (dt > 0.01) as usize;
        h_off += ((g[0] - c[0]).abs() > 0.01 + 0.002 * c[0]) as usize;
    }
    let texels = gpu.texels.len();
    let report = format!(
        "{shaded} of {texels} texels shaded by {} kept leaves (distance factor {factor:.2}); \
         transmittance off by > 0.01 at {t_off} (worst {worst_t:.3}), height off at {h_off}",
        extraction.leaves()
    );
    eprintln!("{report}");
    assert!(
        shaded > texels / 10,
        "the crown shades a good part of the map: {report}"
    );
    // A texel centre exactly on an edge may fall the other way on the GPU (fused arithmetic).
    assert!(t_off * 1000 <= shaded * 5, "{report}");
    assert!(h_off * 1000 <= shaded * 5, "{report}");
    // The mips: maximum height and mean transmittance of the four below.
    let cpu_chain = {
        let mut from_gpu = cpu.clone();
        from_gpu.texels = gpu.clone();
        from_gpu.mips()
    };
    for (level, (g, c)) in chain.iter().zip(&cpu_chain).enumerate().skip(1) {
        let worst = g
            .texels
            .iter()
            .zip(&c.texels)
            .map(|(g, c)| {
                (g[1] - c[1])
                    .abs()
                    .max((g[0] - c[0]).abs() / (1.0 + c[0]) * 0.2)
            })
            .fold(0f32, f32::max);
        assert!(worst < 0.004, "mip {level}: worst {worst}");
    }

    // 2. The receivers' lookup, pixel for pixel, against the CPU's in the GPU's own map.
    harness
        .world_mut()
        .entity_mut(tree_entity)
        .insert(Visibility::Hidden);
    step(&mut harness, 6);
    let lit = harness.render().expect("render");
    let dir = artifacts_dir().join("opacity_shadow");
    for (name, image) in [("pruned", &pruned_image), ("lit", &lit)] {
        image.save_png(dir.join(format!("{name}.png"))).unwrap();
    }
    let gpu_visibility = visibility_image(&pruned_image, &lit);
    let mut worst = 0f32;
    let mut within = 0usize;
    let mut shadowed = 0usize;
    for (i, point) in ground_points(centre) {
        let v = visibility(&plane, &chain, point, SUN_ANGLE);
        let d = (gpu_visibility[i] - v).abs();
        worst = worst.max(d);
        within += (d <= 0.015) as usize;
        shadowed += (v < 0.9) as usize;
    }
    let pixels = (SIZE * SIZE) as usize;
    let lookup = format!(
        "{shadowed} of {pixels} pixels in shadow; {within} within 0.015 of the CPU, worst {worst:.3}"
    );
    eprintln!("{lookup}");
    assert!(
        shadowed > pixels / 8,
        "the shadow fills the frame: {lookup}"
    );
    assert!(worst < 0.04 && within * 100 >= pixels * 99, "{lookup}");

    // 3. The unpruned crown's shadow, and the pruned one's darkness beside it.
    harness
        .world_mut()
        .entity_mut(tree_entity)
        .insert(Visibility::Inherited);
    harness
        .world_mut()
        .resource_mut::<FoliagePruningSettings>()
        .enabled = false;
    step(&mut harness, 8);
    let full_image = harness.render().expect("render");
    let full_visibility = visibility_image(&full_image, &lit);
    let in_shadow: Vec<usize> = (0..pixels).filter(|&i| full_visibility[i] < 0.9).collect();
    let mean = |v: &[f32]| in_shadow.iter().map(|&i| v[i]).sum::<f32>() / in_shadow.len() as f32;
    let (m_full, m_pruned) = (mean(&full_visibility), mean(&gpu_visibility));
    let darkness = format!(
        "mean sunlight in the unpruned shadow: unpruned {m_full:.3}, pruned to {factor:.2} {m_pruned:.3} \
         over {} pixels",
        in_shadow.len()
    );
    eprintln!("{darkness}");
    let dir = artifacts_dir().join("opacity_shadow");
    for (name, image) in [
        ("pruned", &pruned_image),
        ("full", &full_image),
        ("lit", &lit),
    ] {
        image.save_png(dir.join(format!("{name}.png"))).unwrap();
    }
    std::fs::write(
        dir.join("report.txt"),
        format!("{report}\n{lookup}\n{darkness}\n"),
    )
    .unwrap();
    assert!(m_full < 0.7, "the crown's shadow is dark: {darkness}");
    assert!((m_pruned - m_full).abs() < 0.03, "{darkness}");
}
