//! Screen Space Soft Shadows from a **spot light**: the pole scene (`common`) lit by a lamp
//! 6 m up instead of the sun, against the area-light reference of the same run (48 hard-shadowed
//! spot lights spread over the lamp's disk and averaged in linear light).
//!
//! - The spot light's coarse dilated map on the GPU equals its CPU reference at the radius
//!   `min_filter::spot_fine_reach` gives (at the block `min_filter::dilation_block` picks).
//! - The distance pass's σ equals its CPU reference (`ssss::distance`) on the ground's pixels.
//! - The penumbra in the final image follows eq. 6.1 for a local light,
//!   `w = light_size · (d_r − d_b) / d_b`, at three distances behind the pole.
//! - The image is closer to the reference than Bevy's hard shadow, and no further from it than
//!   Bevy's spot-light PCSS (`soft_shadows_enabled`) at the best of a sweep of its `radius`.

mod common;

use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy_nature_harness::RenderHarness;
use bevy_soft_shadows::reference::{LinearAverage, disk_rise_fraction, jittered_positions};
use bevy_soft_shadows::ssss::distance::{CoarseMap, FineMap, SpotProjection, spot_penumbra_width};
use bevy_soft_shadows::ssss::min_filter::{
    DepthConvention, coarse_dilate, coarse_radius_of, dilation_block, spot_fine_reach,
};
use bevy_soft_shadows::ssss::receiver::SsssTextures;
use bevy_soft_shadows::ssss::render::SsssDilationReadback;
use bevy_soft_shadows::{ScreenSpaceSoftShadows, SoftShadowsPlugin};
use common::*;

/// The lamp's centre, where it points, its diameter (m) and outer angle (rad).
const LAMP: Vec3 = Vec3::new(3.0, 6.0, 0.0);
const AIM: Vec3 = Vec3::new(-1.5, 0.0, 0.0);
const DIAMETER: f32 = 0.6;
const OUTER: f32 = 0.6;
/// Blockers up to 4.3 m above their receivers (the pole's edge at x_g = −3 m is 4.27 m in front
/// of the ground, and every blocker is more than 4.3 m from the lamp).
const MAX_OCCLUDER: f32 = 4.3;

#[derive(Component)]
struct Lamp;

fn lamp_at(harness: &mut RenderHarness, at: Vec3) {
    let world = harness.world_mut();
    let mut q = world.query_filtered::<&mut Transform, With<Lamp>>();
    for mut t in q.iter_mut(world) {
        // The disk's samples keep the lamp's orientation: only its position moves.
        *t = Transform::from_translation(at).looking_to(AIM - LAMP, Vec3::Y);
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

/// Eq. 6.1's full width across the shadow's side edge (z = 0.5 on the pole's face nearest the
/// lamp, x = 0.1) at ground x = `x_g`: along the ray through the edge, `d_r / d_b = k`, and a
/// shift of the lamp by δ along z moves the ground edge by δ·(k − 1).
fn eq_6_1(x_g: f32) -> f32 {
    let k = (LAMP.x - x_g) / (LAMP.x - 0.1);
    DIAMETER * (k - 1.0)
}

/// The pole scene under the lamp, for `test`; with `neighbours`, also a directional light and
/// two point lights with shadows but no light (their shadow maps move the spot's layer in the shadow
/// texture array and its index in the clustered lights). Returns the harness (ready), the lamp
/// and the render with the pole hidden (each pixel's light, for visibility).
fn spot_scene(test: &str, neighbours: bool) -> Option<(RenderHarness, Entity, Vec<f32>)> {
    let mut harness = RenderHarness::for_test(test, SIZE, SIZE)?;
    harness.app_mut().add_plugins(SoftShadowsPlugin);
    spawn_ground_blocker_and_camera(
        &mut harness,
        Cuboid::new(0.2, 4.0, 1.0),
        Vec3::new(0.0, 2.0, 0.0),
        CENTRE,
    );
    let lamp = harness
        .world_mut()
        .spawn((
            Lamp,
            SpotLight {
                intensity: 1.2e6,
                range: 30.0,
                shadow_maps_enabled: true,
                outer_angle: OUTER,
                inner_angle: 0.5,
                ..default()
            },
            Transform::from_translation(LAMP).looking_to(AIM - LAMP, Vec3::Y),
        ))
        .id();
    if neighbours {
        let world = harness.world_mut();
        spawn_dark_sun(world);
        for x in [-2.0, 2.0] {
            spawn_dark_bulb(world, Vec3::new(x, 3.0, 2.0));
        }
    }
    harness
        .app_mut()
        .sub_app_mut(RenderApp)
        .init_resource::<SsssDilationReadback>();
    harness.wait_until_ready().unwrap();

    // The light alone (blocker hidden): the spot light's falloff varies over the view, so
    // visibility is each pixel over this.
    let unshadowed = render_without_blocker(&mut harness);
    Some((harness, lamp, unshadowed))
}

/// SSSS on a spot light with a directional light and two point lights beside it: the spot's shadow
/// map is then a later layer of the array and its clustered index moves; the penumbrae must
/// still follow eq. 6.1.
#[test]
fn ssss_finds_the_spot_lights_shadow_map_beside_other_lights() {
    let Some((mut harness, lamp, unshadowed)) = spot_scene("ssss_spot_neighbours", true) else {
        return;
    };
    let hard = to_linear(&harness.render().unwrap());
    harness.world_mut().entity_mut(lamp).insert(settings());
    let ssss = render_until(&mut harness, &hard, |img| rmse(img, &hard) > 0.003);
    let v = visibility(&ssss, &unshadowed);
    let m_per_px = VIEW_M / SIZE as f32;
    for x in [-1.0f32, -2.0, -3.0] {
        let expected = disk_rise_fraction() * eq_6_1(x);
        let measured = width_at(&v, x);
        println!("x = {x} m: SSSS {measured:.3} m, eq. 6.1 {expected:.3} m");
        assert!(
            (measured - expected).abs() <= 0.25 * expected + m_per_px,
            "x = {x}: SSSS {measured} vs eq. 6.1 {expected}"
        );
    }
}

#[test]
fn ssss_softens_spot_light_shadows_as_eq_6_1_predicts() {
    let Some((mut harness, lamp, unshadowed)) = spot_scene("ssss_spot", false) else {
        return;
    };
    let hard = to_linear(&harness.render().unwrap());
    let mut average = LinearAverage::default();
    for p in jittered_positions(LAMP, AIM - LAMP, DIAMETER, JITTERS) {
        lamp_at(&mut harness, p);
        average.add(&harness.render().unwrap().data);
    }
    lamp_at(&mut harness, LAMP);
    let reference = average.linear();

    // Bevy's spot-light PCSS. Its kernel is `radius · (d_r − d_b) / d_b` in units of a fixed
    // `SPOT_SHADOW_TEXEL_SIZE` times an empirical 0.015–0.035 factor, not in metres, so the
    // lamp's true radius barely softens anything: it gets the best of a sweep of multiples.
    let set_pcss = |harness: &mut RenderHarness, radius: Option<f32>| {
        let mut light = harness.world_mut().get_mut::<SpotLight>(lamp).unwrap();
        light.soft_shadows_enabled = radius.is_some();
        light.radius = radius.unwrap_or(0.0);
    };
    let radii = [1.0f32, 10.0, 20.0, 30.0, 45.0, 60.0, 100.0].map(|k| k * 0.5 * DIAMETER);
    let (e_pcss, pcss_radius, pcss) = best_local_pcss(&mut harness, set_pcss, &radii, &reference);
    let pcss_scale = pcss_radius / (0.5 * DIAMETER);

    harness.world_mut().entity_mut(lamp).insert(settings());
    let ssss = render_until(&mut harness, &hard, |img| rmse(img, &hard) > 0.003);
    harness.run_frames(1).unwrap();

    // Hard | Bevy's best spot PCSS | SSSS | area-light reference (docs/images/ssss_spot.png).
    save_comparison("ssss_spot", &hard, &pcss, &ssss, &reference);

    // 1. The spot light's dilated map (layer 0: no directional cascades, no point lights)
    //    against the CPU reference at exactly the radius the settings give.
    let (fine, fine_size) = read_dilation(&mut harness, false);
    let (gpu, coarse_size) = read_dilation(&mut harness, true);
    let reach = spot_fine_reach(DIAMETER, MAX_OCCLUDER, OUTER.tan(), fine_size.x as f32);
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
    assert!(
        fine.iter().any(|&d| d > 0.0),
        "the spot shadow map holds the scene"
    );
    assert_eq!((cw as u32, ch as u32), (coarse_size.x, coarse_size.y));
    let differing = cpu.iter().zip(&gpu).filter(|(a, b)| a != b).count();
    println!(
        "spot dilation: R = {radius}, {differing} of {} coarse texels differ",
        cpu.len()
    );
    assert_eq!(
        differing, 0,
        "the GPU dilation equals the CPU reference at R = {radius}"
    );

    // 2. The distance pass against its CPU reference (`ssss::distance`), pixel by pixel on the
    //    ground: the same coarse map, Bevy's spot projection, eq. 6.1, eq. 6.2 and the mask.
    let light = *harness.world_mut().get::<SpotLight>(lamp).unwrap();
    // The lamp's forward as Bevy extracts it: along z it is ±0 up to rounding, and the sign
    // decides the basis `orthonormalize` builds (the map's orientation about the axis).
    let forward = harness
        .world_mut()
        .get::<GlobalTransform>(lamp)
        .unwrap()
        .forward();
    let projection = SpotProjection {
        position: LAMP,
        forward: *forward,
        tan_outer: light.outer_angle.tan(),
        near: light.shadow_map_near_z,
    };
    let coarse = CoarseMap {
        depth: &gpu,
        width: cw,
        height: ch,
        map_size: fine_size.x as f32,
        radius,
        block,
    };
    let fine_map = FineMap {
        depth: &fine,
        width: fine_size.x as usize,
        height: fine_size.y as usize,
    };
    let s = settings();
    let cpu_width_at = |fine: Option<&FineMap>, world: Vec3| {
        spot_penumbra_width(&projection, &coarse, fine, world, Vec3::Y, s.light_size)
    };
    assert_distance_pass_matches(
        &mut harness,
        &s,
        |world| cpu_width_at(None, world),
        |world| cpu_width_at(Some(&fine_map), world),
    );

    // 3. Penumbra widths (10–90 %) across the side edge, in visibility (over the unshadowed
    //    render), against eq. 6.1.
    let (v_ref, v_ssss) = (
        visibility(&reference, &unshadowed),
        visibility(&ssss, &unshadowed),
    );
    let m_per_px = VIEW_M / SIZE as f32;
    let k = disk_rise_fraction();
    let mut widths = Vec::new();
    for x in [-1.0f32, -2.0, -3.0] {
        let expected = k * eq_6_1(x);
        let (r, s) = (width_at(&v_ref, x), width_at(&v_ssss, x));
        println!(
            "x = {x} m: 10–90 % width reference {r:.3} m, SSSS {s:.3} m, eq. 6.1 {expected:.3} m"
        );
        assert!(
            (r - expected).abs() <= 0.2 * expected + m_per_px,
            "x = {x}: the reference {r} does not follow eq. 6.1 ({expected})"
        );
        assert!(
            (s - expected).abs() <= 0.25 * expected + m_per_px,
            "x = {x}: SSSS {s} vs eq. 6.1 {expected}"
        );
        widths.push(s);
    }
    let growth = widths[2] / widths[0];
    let expected_growth = eq_6_1(-3.0) / eq_6_1(-1.0);
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
        "SSSS {e_ssss} is worse than Bevy's spot PCSS {e_pcss}"
    );
}

/// Bad input: SSSS on a spot light whose shadow maps are off has nothing to soften. It stays off
/// (one warning): the passes write "inactive" (−1) for the receivers, which keep Bevy's lighting,
/// and nothing panics.
#[test]
fn ssss_on_a_spot_light_without_shadow_maps_stays_off() {
    let Some((mut harness, lamp, unshadowed)) = spot_scene("ssss_spot_no_shadows", false) else {
        return;
    };
    harness
        .world_mut()
        .get_mut::<SpotLight>(lamp)
        .unwrap()
        .shadow_maps_enabled = false;
    harness.world_mut().entity_mut(lamp).insert(settings());
    // Receivers convert and compile asynchronously: give them time, then read the texture.
    let mut image = Vec::new();
    for _ in 0..30 {
        image = to_linear(&harness.render().unwrap());
    }
    let textures = harness.world_mut().resource::<SsssTextures>().clone();
    let visibility = floats(
        &harness
            .read_image(textures.visibility.clone(), SIZE, SIZE, 8)
            .unwrap(),
    );
    let active = visibility.iter().step_by(2).filter(|&&v| v >= 0.0).count();
    assert_eq!(active, 0, "SSSS ran for a light without shadow maps");
    // Without shadow maps the lamp casts no shadow: the ground is lit as with the pole hidden.
    let (col, row) = pixel_of(-2.0, 0.0);
    let i = ((row * SIZE + col) * 4 + 1) as usize;
    assert!(
        (image[i] - unshadowed[i]).abs() < 0.02 * unshadowed[i],
        "{} vs {}",
        image[i],
        unshadowed[i]
    );
}
