//! The area-light reference (jittered hard-shadowed lights, averaged) on the pole scene of
//! issue 6's render test (a) (`common`): a light of angular diameter θ gives a penumbra of full
//! width `w = Δ·2tan(θ/2)` (eq. 6.1 for a light at infinity) and a 10–90 % width of `k·w` (`k`
//! from the disk's visibility profile). The reference must reproduce that — it is what SSSS and
//! Bevy's PCSS are measured against — while Bevy's hard shadow stays a step.

mod common;

use bevy_nature_harness::compare::RgbaImage;
use bevy_nature_harness::{RenderHarness, artifacts_dir};
use bevy_soft_shadows::reference::{disk_rise_fraction, rise_width};
use common::*;

#[test]
fn the_area_light_reference_has_eq_6_1_penumbrae_and_the_hard_shadow_does_not() {
    let Some(mut harness) = RenderHarness::for_test("area_light_reference", SIZE, SIZE) else {
        return;
    };
    setup(&mut harness);
    harness.wait_until_ready().unwrap();

    let hard_image = harness.render().unwrap();
    let hard = to_linear(&hard_image);
    let average = area_light_reference(&mut harness);
    let reference = average.linear();
    let dir = artifacts_dir().join("area_light_reference");
    std::fs::create_dir_all(&dir).ok();
    hard_image.save_png(dir.join("hard.png")).ok();
    RgbaImage::new(SIZE, SIZE, average.srgb8())
        .save_png(dir.join("reference.png"))
        .ok();

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
