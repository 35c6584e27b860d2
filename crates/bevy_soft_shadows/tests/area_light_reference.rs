//! The area-light reference (jittered hard-shadowed lights, averaged) on the pole scene of
//! issue 6's render test (a): a 1 m wide, 4 m tall pole on a white ground under a directional
//! light 45° up, seen from straight above. Across the shadow's side edge, at distance `s` behind
//! the pole, the blocker is `Δ = s·√2` from the ground along the light, so a light of angular
//! diameter θ gives a penumbra of full width `w = Δ·2tan(θ/2)` (eq. 6.1 for a light at infinity)
//! and a 10–90 % width of `k·w` (`k` from the disk's visibility profile). The reference must
//! reproduce that — it is what SSSS and Bevy's PCSS are measured against — while Bevy's hard
//! shadow stays a step.

use bevy::camera::{OrthographicProjection, Projection, ScalingMode};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::light::{
    CascadeShadowConfigBuilder, DirectionalLightShadowMap, GlobalAmbientLight,
    ShadowFilteringMethod,
};
use bevy::prelude::*;
use bevy_nature_harness::compare::RgbaImage;
use bevy_nature_harness::{RenderHarness, artifacts_dir};
use bevy_soft_shadows::reference::{
    LinearAverage, disk_rise_fraction, jittered_directions, rise_width, srgb_to_linear,
};

const SIZE: u32 = 160;
/// World width of the view (m): x from −4.5 to 0.5, z from −2.5 to 2.5.
const VIEW_M: f32 = 5.0;
const CENTRE: Vec3 = Vec3::new(-2.0, 0.0, 0.0);
/// Angular diameter of the light (rad).
const THETA: f32 = 0.15;
const JITTERS: usize = 48;

#[derive(Component)]
struct Sun;

fn sun_direction() -> Vec3 {
    // From the ground towards the light: 45° up, from +x, so the shadow falls towards −x.
    Vec3::new(1.0, 1.0, 0.0).normalize()
}

fn setup(harness: &mut RenderHarness) {
    let world = harness.world_mut();
    world.insert_resource(GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    });
    world.insert_resource(DirectionalLightShadowMap { size: 2048 });
    let (ground, pole) = {
        let mut meshes = world.resource_mut::<Assets<Mesh>>();
        (
            meshes.add(Plane3d::default().mesh().size(40.0, 40.0)),
            meshes.add(Cuboid::new(0.2, 4.0, 1.0)),
        )
    };
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::srgb(0.8, 0.8, 0.8),
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        });
    world.spawn((Mesh3d(ground), MeshMaterial3d(material.clone())));
    world.spawn((
        Mesh3d(pole),
        MeshMaterial3d(material),
        Transform::from_xyz(0.0, 2.0, 0.0),
    ));
    world.spawn((
        Sun,
        DirectionalLight {
            illuminance: 3000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        CascadeShadowConfigBuilder {
            num_cascades: 1,
            minimum_distance: 0.1,
            maximum_distance: 14.0,
            first_cascade_far_bound: 14.0,
            ..default()
        }
        .build(),
        Transform::default().looking_to(-sun_direction(), Vec3::Y),
    ));
    world.spawn((
        Camera3d::default(),
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
        ShadowFilteringMethod::Hardware2x2,
        Projection::Orthographic(OrthographicProjection {
            scaling_mode: ScalingMode::Fixed {
                width: VIEW_M,
                height: VIEW_M,
            },
            ..OrthographicProjection::default_3d()
        }),
        Transform::from_translation(CENTRE + Vec3::Y * 10.0).looking_at(CENTRE, Vec3::NEG_Z),
    ));
}

fn aim_sun(harness: &mut RenderHarness, direction_to_light: Vec3) {
    let world = harness.world_mut();
    let mut q = world.query_filtered::<&mut Transform, With<Sun>>();
    for mut t in q.iter_mut(world) {
        *t = Transform::default().looking_to(-direction_to_light, Vec3::Y);
    }
}

/// Pixel column of world x, pixel row of world z (image right = +x, down = +z).
fn pixel_of(x: f32, z: f32) -> (u32, u32) {
    let m_per_px = VIEW_M / SIZE as f32;
    (
        ((x - (CENTRE.x - VIEW_M / 2.0)) / m_per_px) as u32,
        ((z - (CENTRE.z - VIEW_M / 2.0)) / m_per_px) as u32,
    )
}

/// Visibility down the column at world x, from the pole's middle (z = 0) outwards across its
/// edge at z = 0.5, relative to the lit ground.
fn profile(linear: &[f32], x: f32, lit: f32) -> Vec<f32> {
    let (col, row0) = pixel_of(x, 0.0);
    let (_, row1) = pixel_of(x, 1.4);
    (row0..row1)
        .map(|row| linear[((row * SIZE + col) * 4 + 1) as usize] / lit)
        .collect()
}

#[test]
fn the_area_light_reference_has_eq_6_1_penumbrae_and_the_hard_shadow_does_not() {
    let Some(mut harness) = RenderHarness::for_test("area_light_reference", SIZE, SIZE) else {
        return;
    };
    setup(&mut harness);
    harness.wait_until_ready().unwrap();
    let to_linear =
        |img: &RgbaImage| -> Vec<f32> { img.data.iter().map(|&v| srgb_to_linear(v)).collect() };

    let hard_image = harness.render().unwrap();
    let hard = to_linear(&hard_image);
    let mut average = LinearAverage::default();
    for d in jittered_directions(sun_direction(), THETA, JITTERS) {
        aim_sun(&mut harness, d);
        average.add(&harness.render().unwrap().data);
    }
    let reference = average.linear();
    let dir = artifacts_dir().join("area_light_reference");
    std::fs::create_dir_all(&dir).ok();
    hard_image.save_png(dir.join("hard.png")).ok();
    RgbaImage::new(SIZE, SIZE, average.srgb8())
        .save_png(dir.join("reference.png"))
        .ok();

    // Lit ground, away from the shadow.
    let (lx, lz) = pixel_of(-1.5, 2.2);
    let lit = |img: &[f32]| img[((lz * SIZE + lx) * 4 + 1) as usize];
    assert!(lit(&hard) > 0.2, "the ground is lit: {}", lit(&hard));
    let m_per_px = VIEW_M / SIZE as f32;
    let k = disk_rise_fraction();
    let mut widths = Vec::new();
    for s in [1.0f32, 2.0, 3.0] {
        let expected = k * s * std::f32::consts::SQRT_2 * 2.0 * (0.5 * THETA).tan();
        let reference_w = rise_width(&profile(&reference, -s, lit(&reference)), 0.1, 0.9)
            .expect("the reference penumbra rises")
            * m_per_px;
        let hard_w = rise_width(&profile(&hard, -s, lit(&hard)), 0.1, 0.9)
            .expect("the hard shadow rises")
            * m_per_px;
        println!(
            "s = {s} m: 10–90 % width reference {reference_w:.3} m, eq. 6.1 {expected:.3} m, hard {hard_w:.3} m"
        );
        // Within 20 % plus one pixel (shadow-map texels and the 2×2 filter).
        assert!(
            (reference_w - expected).abs() <= 0.2 * expected + m_per_px,
            "s = {s}: reference {reference_w} vs eq. 6.1 {expected}"
        );
        assert!(hard_w <= 2.0 * m_per_px, "hard shadow edge {hard_w} m");
        widths.push(reference_w);
    }
    // The penumbra widens with the distance from contact, three times wider at 3 m than at 1 m.
    let growth = widths[2] / widths[0];
    assert!((2.4..3.6).contains(&growth), "growth {growth}");
}
