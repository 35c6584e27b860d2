//! Screen Space Soft Shadows on the pole scene (`common`), rendered through the real passes:
//!
//! - the blur passes against their CPU reference (`ssss::blur::soft_shadow`) run on the GPU's own
//!   distance map (hard shadow, σ, eye depth) read back from the same frame;
//! - issue 6's render test (a): the penumbra measured in the final image widens with the distance
//!   from the contact point as eq. 6.1/6.2 predict;
//! - the image is closer to the area-light reference (same run) than Bevy's hard shadow is.

mod common;

use bevy::prelude::*;
use bevy_nature_harness::compare::RgbaImage;
use bevy_nature_harness::{RenderHarness, artifacts_dir};
use bevy_soft_shadows::reference::{disk_rise_fraction, linear_to_srgb, rise_width};
use bevy_soft_shadows::ssss::blur::{BlurSettings, ScreenBuffers, soft_shadow};
use bevy_soft_shadows::ssss::receiver::SsssTextures;
use bevy_soft_shadows::{ScreenSpaceSoftShadows, SoftShadowsPlugin};
use common::*;

fn floats(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn settings() -> ScreenSpaceSoftShadows {
    ScreenSpaceSoftShadows {
        light_size: THETA,
        max_occluder_distance: 6.0,
        max_kernel_px: 60.0,
        taps_per_side: 11,
        lazy_shadowing: false,
        ..default()
    }
}

fn rmse(a: &[f32], b: &[f32]) -> f32 {
    let mut sum = 0.0;
    let mut n = 0;
    for i in (0..a.len()).step_by(4) {
        let d = a[i + 1] - b[i + 1];
        sum += d * d;
        n += 1;
    }
    (sum / n as f32).sqrt()
}

#[test]
fn ssss_matches_its_cpu_reference_and_follows_eq_6_2() {
    let Some(mut harness) = RenderHarness::for_test("ssss_render", SIZE, SIZE) else {
        return;
    };
    harness.app_mut().add_plugins(SoftShadowsPlugin);
    setup(&mut harness);
    harness.wait_until_ready().unwrap();
    // Bevy's hard shadow and the area-light reference, before SSSS is switched on.
    let hard = to_linear(&harness.render().unwrap());
    let reference = area_light_reference(&mut harness).linear();
    {
        let world = harness.world_mut();
        let sun = world
            .query_filtered::<Entity, With<Sun>>()
            .single(world)
            .unwrap();
        world.entity_mut(sun).insert(settings());
    }
    // Pipelines for the new material and passes compile asynchronously: wait until the
    // soft shadow shows (the receiver material replaced the standard one and reads SSSS).
    // Until then the meshes are not drawn (background) or still show the hard shadow.
    let mut ssss_image = harness.render().unwrap();
    let mut frames = 0;
    loop {
        let img = to_linear(&ssss_image);
        let ground_drawn = (lit(&img) - lit(&hard)).abs() < 0.02 * lit(&hard);
        if ground_drawn && rmse(&img, &hard) > 0.003 {
            break;
        }
        frames += 1;
        assert!(frames < 100, "the soft shadow never showed");
        ssss_image = harness.render().unwrap();
    }
    let ssss = to_linear(&ssss_image);
    let textures = harness.world_mut().resource::<SsssTextures>().clone();
    assert_eq!(textures.size, UVec2::splat(SIZE));

    // 1. The blur passes against the CPU reference on the GPU's own distance map.
    let distance = floats(
        &harness
            .read_image(textures.distance.clone(), SIZE, SIZE, 16)
            .unwrap(),
    );
    let visibility = floats(
        &harness
            .read_image(textures.visibility.clone(), SIZE, SIZE, 4)
            .unwrap(),
    );
    let n = (SIZE * SIZE) as usize;
    let buffers = ScreenBuffers {
        width: SIZE as usize,
        height: SIZE as usize,
        hard: (0..n).map(|i| distance[4 * i]).collect(),
        sigma: (0..n)
            .map(|i| [distance[4 * i + 1], distance[4 * i + 2]])
            .collect(),
        depth: (0..n).map(|i| distance[4 * i + 3]).collect(),
    };
    let s = settings();
    let cpu = soft_shadow(
        &buffers,
        BlurSettings {
            taps_per_side: s.taps_per_side,
            depth_rejection: s.depth_rejection,
        },
        &|_, _| None,
    );
    let blurred = buffers.sigma.iter().filter(|s| s[0] > 0.5).count();
    let worst = cpu
        .iter()
        .zip(&visibility)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    println!("{blurred} of {n} pixels blurred; GPU vs CPU blur: worst difference {worst:.2e}");
    assert!(blurred > n / 50, "a penumbra region exists: {blurred}");
    assert!(
        worst < 2e-3,
        "GPU blur differs from its CPU reference by {worst}"
    );

    let dir = artifacts_dir().join("ssss_render");
    std::fs::create_dir_all(&dir).ok();
    ssss_image.save_png(dir.join("ssss.png")).ok();
    let gray = |v: &[f32]| {
        RgbaImage::new(
            SIZE,
            SIZE,
            v.iter()
                .flat_map(|&x| {
                    let g = linear_to_srgb(x);
                    [g, g, g, 255]
                })
                .collect(),
        )
    };
    gray(&visibility).save_png(dir.join("visibility.png")).ok();
    gray(&buffers.hard)
        .save_png(dir.join("hard_shadow.png"))
        .ok();

    // 2. Test (a): penumbra widths in the final image vs eq. 6.1 / 6.2.
    let m_per_px = VIEW_M / SIZE as f32;
    let k = disk_rise_fraction();
    let mut widths = Vec::new();
    for s in [1.0f32, 2.0, 3.0] {
        let expected = k * s * std::f32::consts::SQRT_2 * 2.0 * (0.5 * THETA).tan();
        let measured = rise_width(&profile(&ssss, -s, lit(&ssss)), 0.1, 0.9)
            .expect("the soft penumbra rises")
            * m_per_px;
        println!("s = {s} m: SSSS 10–90 % width {measured:.3} m, eq. 6.1 {expected:.3} m");
        assert!(
            (measured - expected).abs() <= 0.25 * expected + m_per_px,
            "s = {s}: SSSS {measured} vs eq. 6.1 {expected}"
        );
        widths.push(measured);
    }
    let growth = widths[2] / widths[0];
    assert!((2.2..3.8).contains(&growth), "growth {growth}");

    // 3. Closer to the area-light reference than the hard shadow.
    let (e_ssss, e_hard) = (rmse(&ssss, &reference), rmse(&hard, &reference));
    println!("RMSE vs area-light reference: SSSS {e_ssss:.4}, hard {e_hard:.4}");
    assert!(e_ssss < 0.7 * e_hard, "SSSS {e_ssss} vs hard {e_hard}");
}
