//! Screen Space Soft Shadows from a **point light**: the pole scene (`common`) lit by a bulb 5 m
//! up and 2.5 m to the side, against the area-light reference of the same run (48 hard-shadowed
//! point lights spread over the bulb's disk and averaged in linear light).
//!
//! The bulb's shadow map is a cube: six 90° faces, each dilated on its own. The ground in view
//! straddles two of them — below the bulb (−y) nearer the pole, its side (−x) farther out — so
//! every check below covers both:
//!
//! - each face's coarse dilated map on the GPU equals its CPU reference at the radius
//!   `min_filter::spot_fine_reach` gives for a 90° map;
//! - the distance and refine passes' σ equal their CPU references (`distance::PointProjection`,
//!   `point_penumbra_width`) on the ground's pixels;
//! - the penumbra follows eq. 6.1 for a local light, `w = light_size · (d_r − d_b) / d_b`, at four
//!   distances behind the pole, two on each face;
//! - the image is closer to the reference than Bevy's hard shadow, and no further from it than
//!   Bevy's point-light PCSS (`soft_shadows_enabled`) at the best of a sweep of its `radius`.

mod common;

use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy_nature_harness::RenderHarness;
use bevy_soft_shadows::reference::{LinearAverage, disk_rise_fraction, jittered_positions};
use bevy_soft_shadows::ssss::distance::{
    CoarseMap, FineMap, PointProjection, point_penumbra_width,
};
use bevy_soft_shadows::ssss::min_filter::{
    DepthConvention, coarse_dilate, coarse_radius_of, dilation_block, spot_fine_reach,
};
use bevy_soft_shadows::ssss::receiver::SsssTextures;
use bevy_soft_shadows::ssss::render::SsssDilationReadback;
use bevy_soft_shadows::{ScreenSpaceSoftShadows, SoftShadowsPlugin};
use common::*;

/// The bulb's centre and diameter (m), off the pixel grid's alignment with the cube faces' texels
/// (a pixel centre on a texel edge is a coin toss between GPU and CPU). Ground points nearer the
/// pole than x = −2.47 m are below
/// the bulb on the cube's −y face, those beyond on its −x face.
const BULB: Vec3 = Vec3::new(2.53, 5.0, 0.03);
const DIAMETER: f32 = 0.6;
/// Blockers up to 4.3 m above their receivers, all more than 4.3 m from the bulb.
const MAX_OCCLUDER: f32 = 4.3;
/// The reference's disk faces the middle of the shadow in view; its extent along z (the side
/// edge's direction across) is the full diameter whatever its tilt about z.
const DISK_FACING: Vec3 = Vec3::new(-5.0, -5.0, 0.0);

#[derive(Component)]
struct Bulb;

fn bulb_at(harness: &mut RenderHarness, at: Vec3) {
    let world = harness.world_mut();
    let mut q = world.query_filtered::<&mut Transform, With<Bulb>>();
    for mut t in q.iter_mut(world) {
        *t = Transform::from_translation(at);
    }
}

fn settings() -> ScreenSpaceSoftShadows {
    ScreenSpaceSoftShadows {
        light_size: DIAMETER,
        max_occluder_distance: MAX_OCCLUDER,
        max_kernel_px: 60.0,
        taps_per_side: 11,
        lazy_shadowing: false,
        ..default()
    }
}

/// Eq. 6.1's full width across the shadow's side edge (z = 0.25 on the pole's face nearest the
/// bulb, x = 0.1) at ground x = `x_g`: along the ray through the edge `d_r / d_b = k` (along any
/// axis), and a shift of the bulb by δ along z moves the ground edge by δ·(k − 1).
fn eq_6_1(x_g: f32) -> f32 {
    let k = (BULB.x - x_g) / (BULB.x - 0.1);
    DIAMETER * (k - 1.0)
}

/// The pole scene under the bulb, for `test` (a pole half as deep as the sun's: the penumbra
/// 4 m behind it ends within the profile, 1.4 m from the middle); with `neighbours`, also a directional light, a
/// spot light and another point light with shadows but no light (they move the bulb's index in
/// the clustered lights, so its faces are other layers of the cube texture). Returns the harness
/// (ready), the bulb and the render with the pole hidden (each pixel's light, for visibility).
fn point_scene(test: &str, neighbours: bool) -> Option<(RenderHarness, Entity, Vec<f32>)> {
    let mut harness = RenderHarness::for_test(test, SIZE, SIZE)?;
    harness.app_mut().add_plugins(SoftShadowsPlugin);
    spawn_ground_blocker_and_camera(
        &mut harness,
        Cuboid::new(0.2, 4.0, 0.5),
        Vec3::new(0.0, 2.0, 0.0),
        CENTRE,
    );
    // With neighbours, shadow-casting point lights spawned before and after the bulb: Bevy sorts
    // point lights by entity, so the bulb is the middle one of three whichever way entities count.
    if neighbours {
        let world = harness.world_mut();
        spawn_dark_bulb(world, Vec3::new(-2.0, 3.0, 2.0));
        spawn_dark_sun(world);
        world.spawn((
            SpotLight {
                intensity: 0.0,
                shadow_maps_enabled: true,
                ..default()
            },
            Transform::from_xyz(-3.0, 4.0, 0.0).looking_at(Vec3::ZERO, Vec3::Y),
        ));
    }
    let bulb = harness
        .world_mut()
        .spawn((
            Bulb,
            PointLight {
                intensity: 1.2e6,
                range: 30.0,
                shadow_maps_enabled: true,
                ..default()
            },
            Transform::from_translation(BULB),
        ))
        .id();
    if neighbours {
        spawn_dark_bulb(harness.world_mut(), Vec3::new(-4.0, 3.0, -2.0));
    }
    harness
        .app_mut()
        .sub_app_mut(RenderApp)
        .init_resource::<SsssDilationReadback>();
    harness.wait_until_ready().unwrap();

    let unshadowed = render_without_blocker(&mut harness);
    Some((harness, bulb, unshadowed))
}

/// Penumbra widths (10–90 %) across the side edge at x = −1, −2 (the −y face) and −3, −4 m (the
/// −x face), against eq. 6.1 within `tolerance` of it and a pixel.
fn assert_widths_follow_eq_6_1(v: &[f32], what: &str, tolerance: f32) -> Vec<f32> {
    let m_per_px = VIEW_M / SIZE as f32;
    let mut widths = Vec::new();
    for x in [-1.0f32, -2.0, -3.0, -4.0] {
        let expected = disk_rise_fraction() * eq_6_1(x);
        let measured = width_at(v, x);
        println!("x = {x} m: {what} {measured:.3} m, eq. 6.1 {expected:.3} m");
        assert!(
            (measured - expected).abs() <= tolerance * expected + m_per_px,
            "x = {x}: {what} {measured} vs eq. 6.1 {expected}"
        );
        widths.push(measured);
    }
    widths
}

/// One face of the bulb's cube shadow texture and of its coarse dilated map, read back (the
/// readback copies the layer it is told, from the next frame on).
fn read_face(harness: &mut RenderHarness, layer: u32) -> ((Vec<f32>, UVec2), (Vec<f32>, UVec2)) {
    harness
        .app_mut()
        .sub_app_mut(RenderApp)
        .world_mut()
        .resource_mut::<SsssDilationReadback>()
        .layer = layer;
    harness.render().unwrap();
    (read_dilation(harness, false), read_dilation(harness, true))
}

#[test]
fn ssss_softens_point_light_shadows_as_eq_6_1_predicts() {
    let Some((mut harness, bulb, unshadowed)) = point_scene("ssss_point", false) else {
        return;
    };
    let hard = to_linear(&harness.render().unwrap());
    let mut average = LinearAverage::default();
    for p in jittered_positions(BULB, DISK_FACING, DIAMETER, JITTERS) {
        bulb_at(&mut harness, p);
        average.add(&harness.render().unwrap().data);
    }
    bulb_at(&mut harness, BULB);
    let reference = average.linear();

    // Bevy's point-light PCSS: its kernel is `radius · (d_r/d_b − 1)` times a fixed 0.003 of the
    // distance to the light (`POINT_SHADOW_SCALE`), not metres, so the bulb's true radius softens
    // next to nothing: it gets the best of a sweep of multiples, up to where the error climbs.
    let set_pcss = |harness: &mut RenderHarness, radius: Option<f32>| {
        let mut light = harness.world_mut().get_mut::<PointLight>(bulb).unwrap();
        light.soft_shadows_enabled = radius.is_some();
        light.radius = radius.unwrap_or(0.0);
    };
    let radii = [1.0f32, 30.0, 100.0, 200.0, 300.0, 1000.0].map(|k| k * 0.5 * DIAMETER);
    let (e_pcss, pcss_radius, pcss) = best_local_pcss(&mut harness, set_pcss, &radii, &reference);
    let pcss_scale = pcss_radius / (0.5 * DIAMETER);

    harness.world_mut().entity_mut(bulb).insert(settings());
    let ssss = render_until(&mut harness, &hard, |img| rmse(img, &hard) > 0.003);
    harness.run_frames(1).unwrap();

    // Hard | Bevy's best point PCSS | SSSS | area-light reference.
    save_comparison("ssss_point", &hard, &pcss, &ssss, &reference);

    // 1. Each face's dilated map against the CPU reference at the radius the settings give (the
    //    bulb is the only point light: its faces are layers 0–5).
    let mut faces = Vec::new();
    for face in 0..6u32 {
        let ((fine, fine_size), (gpu, coarse_size)) = read_face(&mut harness, face);
        let reach = spot_fine_reach(DIAMETER, MAX_OCCLUDER, 1.0, fine_size.x as f32);
        let block = dilation_block(reach);
        let radius = coarse_radius_of(reach, block);
        let (cpu, cw, ch) = coarse_dilate(
            &fine,
            fine_size.x as usize,
            fine_size.y as usize,
            radius,
            block,
            DepthConvention::ReverseZ,
        );
        assert_eq!((cw as u32, ch as u32), (coarse_size.x, coarse_size.y));
        let differing = cpu.iter().zip(&gpu).filter(|(a, b)| a != b).count();
        let holding = fine.iter().filter(|&&d| d > 0.0).count();
        println!(
            "face {face}: {holding} texels hold the scene; R = {radius}, block {block}: \
             {differing} of {} coarse texels differ",
            cpu.len()
        );
        assert_eq!(
            differing, 0,
            "face {face}: the GPU dilation equals the CPU's"
        );
        faces.push((fine, fine_size, gpu, cw, ch, radius, block));
    }
    // The ground and pole are below and beside the bulb: the −x and −y faces see them.
    for face in [1usize, 3] {
        assert!(
            faces[face].0.iter().any(|&d| d > 0.0),
            "face {face} holds the scene"
        );
    }

    // 2. The distance and refine passes against their CPU references on the ground's pixels:
    //    Bevy's cube faces (`PointProjection`), eq. 6.1, eq. 6.2 and the mask.
    let light = *harness.world_mut().get::<PointLight>(bulb).unwrap();
    let projection = PointProjection {
        position: BULB,
        near: light.shadow_map_near_z,
    };
    let coarse: Vec<CoarseMap> = faces
        .iter()
        .map(|(_, fine_size, gpu, cw, ch, radius, block)| CoarseMap {
            depth: gpu,
            width: *cw,
            height: *ch,
            map_size: fine_size.x as f32,
            radius: *radius,
            block: *block,
        })
        .collect();
    let fine: Vec<FineMap> = faces
        .iter()
        .map(|(fine, size, ..)| FineMap {
            depth: fine,
            width: size.x as usize,
            height: size.y as usize,
        })
        .collect();
    let s = settings();
    let cpu_width_at = |fine: Option<&[FineMap]>, world: Vec3| {
        point_penumbra_width(&projection, &coarse, fine, world, Vec3::Y, s.light_size)
    };
    // Which faces the ground in view falls on.
    let mut ground_faces = [false; 6];
    for (x, z) in [(-4.4, 0.0), (-1.0, 0.0), (0.4, 2.4), (-4.4, 2.4)] {
        ground_faces[projection.project(Vec3::new(x, 0.0, z)).unwrap().0] = true;
    }
    assert_eq!(ground_faces, [false, true, false, true, false, false]);
    assert_distance_pass_matches(
        &mut harness,
        &s,
        |world| cpu_width_at(None, world),
        |world| cpu_width_at(Some(&fine), world),
    );

    // 3. Penumbra widths across the side edge, in visibility (over the unshadowed render).
    let (v_ref, v_ssss) = (
        visibility(&reference, &unshadowed),
        visibility(&ssss, &unshadowed),
    );
    assert_widths_follow_eq_6_1(&v_ref, "reference", 0.2);
    let widths = assert_widths_follow_eq_6_1(&v_ssss, "SSSS", 0.25);
    let growth = widths[3] / widths[0];
    let expected_growth = eq_6_1(-4.0) / eq_6_1(-1.0);
    assert!(
        (growth / expected_growth - 1.0).abs() < 0.3,
        "growth {growth} vs eq. 6.1 {expected_growth}"
    );

    // 4. Against the area-light reference.
    let (e_ssss, e_hard) = (rmse(&ssss, &reference), rmse(&hard, &reference));
    println!(
        "RMSE vs area-light reference: SSSS {e_ssss:.4}, best PCSS {e_pcss:.4} \
         ({pcss_scale}× radius), hard {e_hard:.4}"
    );
    assert!(e_ssss < 0.7 * e_hard, "SSSS {e_ssss} vs hard {e_hard}");
    assert!(
        e_ssss <= e_pcss,
        "SSSS {e_ssss} is worse than Bevy's point PCSS {e_pcss}"
    );
}

/// SSSS on a point light with other lights beside it — shadow-casting point lights sorted
/// before and after it, a directional light and a spot light: the bulb's clustered index and its
/// faces' layers in the cube texture move; the penumbrae must still follow eq. 6.1, and the
/// receivers must re-weight the bulb (not the other point light) with the soft visibility.
#[test]
fn ssss_finds_the_point_lights_faces_beside_other_lights() {
    let Some((mut harness, bulb, unshadowed)) = point_scene("ssss_point_neighbours", true) else {
        return;
    };
    let hard = to_linear(&harness.render().unwrap());
    harness.world_mut().entity_mut(bulb).insert(settings());
    let ssss = render_until(&mut harness, &hard, |img| rmse(img, &hard) > 0.003);
    let v = visibility(&ssss, &unshadowed);
    assert_widths_follow_eq_6_1(&v, "SSSS", 0.25);
    // The receivers were told which light: a point light's clustered index i as −2 − i.
    let textures = harness.world_mut().resource::<SsssTextures>().clone();
    let written = screen_floats(&mut harness, &textures.visibility, 8);
    let lights: Vec<f32> = written.iter().skip(1).step_by(2).copied().collect();
    assert!(
        lights.iter().all(|&l| l == lights[0]),
        "light tags {:?}",
        &lights[..4]
    );
    assert_eq!(
        lights[0], -3.0,
        "the bulb is the second point light (index 1)"
    );
}

/// Bad input: SSSS on a point light whose shadow maps are off stays off (one warning): the
/// receivers read "inactive" and keep Bevy's lighting, and nothing panics.
#[test]
fn ssss_on_a_point_light_without_shadow_maps_stays_off() {
    let Some((mut harness, bulb, unshadowed)) = point_scene("ssss_point_no_shadows", false) else {
        return;
    };
    harness
        .world_mut()
        .get_mut::<PointLight>(bulb)
        .unwrap()
        .shadow_maps_enabled = false;
    harness.world_mut().entity_mut(bulb).insert(settings());
    let mut image = Vec::new();
    for _ in 0..30 {
        image = to_linear(&harness.render().unwrap());
    }
    let textures = harness.world_mut().resource::<SsssTextures>().clone();
    let written = screen_floats(&mut harness, &textures.visibility, 8);
    let active = written.iter().step_by(2).filter(|&&v| v >= 0.0).count();
    assert_eq!(active, 0, "SSSS ran for a light without shadow maps");
    let (col, row) = pixel_of(-2.0, 0.0);
    let i = ((row * SIZE + col) * 4 + 1) as usize;
    assert!(
        (image[i] - unshadowed[i]).abs() < 0.02 * unshadowed[i],
        "{} vs {}",
        image[i],
        unshadowed[i]
    );
}
