//! SSSS's tile classification on the GPU (`tiles.wgsl`, CPU reference `ssss::tiles`):
//!
//! - the active tile list the GPU built equals the CPU classification of the GPU's own distance
//!   map of the same frame, tile for tile;
//! - blurring only those tiles gives the same soft shadow as blurring every tile
//!   (`tile_classification: false`), within 1e-4 per pixel, while skipping most of the screen —
//!   on the pole scene with and without lazy shadowing, and on the hovering panel whose hidden
//!   shadow only lazy shadowing finds.

mod common;

use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy_nature_harness::RenderHarness;
use bevy_soft_shadows::ScreenSpaceSoftShadows;
use bevy_soft_shadows::ssss::blur::ScreenBuffers;
use bevy_soft_shadows::ssss::receiver::SsssTextures;
use bevy_soft_shadows::ssss::render::SsssTileReadback;
use bevy_soft_shadows::ssss::tiles::{TileSettings, active_tiles};
use common::*;

/// The GPU's active tiles of the last frame, sorted, and the tile count.
fn read_tiles(harness: &mut RenderHarness) -> (Vec<[u32; 2]>, usize) {
    let mut grid = UVec2::ZERO;
    let args = words(
        &harness
            .read_render_buffer(|world| {
                let r = world.get_resource::<SsssTileReadback>()?;
                grid = r.grid;
                r.args.clone()
            })
            .unwrap(),
    );
    let list = words(
        &harness
            .read_render_buffer(|world| world.get_resource::<SsssTileReadback>()?.list.clone())
            .unwrap(),
    );
    assert_eq!(args[0], 6, "six vertices per tile quad");
    let count = args[1] as usize;
    let mut tiles: Vec<[u32; 2]> = list[..count]
        .iter()
        .map(|&p| [p & 0xffff, p >> 16])
        .collect();
    tiles.sort_by_key(|t| (t[1], t[0]));
    (tiles, (grid.x * grid.y) as usize)
}

/// The soft visibility in grey with the active tiles tinted orange and outlined
/// (`target/nature-artifacts/ssss_tiles/`).
fn save_tile_image(scene: &str, visibility: &[f32], active: &[[u32; 2]]) {
    use bevy_nature_harness::artifacts_dir;
    use bevy_nature_harness::compare::RgbaImage;
    use bevy_soft_shadows::reference::linear_to_srgb;
    let mut data = Vec::with_capacity(visibility.len() * 4);
    for (i, &v) in visibility.iter().enumerate() {
        let (x, y) = (i as u32 % SIZE, i as u32 / SIZE);
        let g = linear_to_srgb(0.15 + 0.85 * v.clamp(0.0, 1.0)) as f32;
        let tile = [x / 8, y / 8];
        let rgb = if active.contains(&tile) {
            let edge = x % 8 == 0 || y % 8 == 0;
            if edge {
                [255.0, 140.0, 0.0]
            } else {
                [0.6 * g + 0.4 * 255.0, 0.6 * g + 0.4 * 150.0, 0.6 * g]
            }
        } else {
            [g, g, g]
        };
        data.extend(rgb.map(|c| c as u8));
        data.push(255);
    }
    let dir = artifacts_dir().join("ssss_tiles");
    std::fs::create_dir_all(&dir).ok();
    let name: String = scene
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    RgbaImage::new(SIZE, SIZE, data)
        .save_png(dir.join(format!("{name}.png")))
        .ok();
}

fn words(bytes: &[u8]) -> Vec<u32> {
    bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// Renders with `settings` (tiles on) until `frames` frames after the receivers drew the lit
/// ground, checks the GPU's tile list against the CPU's, then renders with every tile blurred
/// and compares. Returns the active fraction.
fn check_scene(
    harness: &mut RenderHarness,
    sun: Entity,
    settings: ScreenSpaceSoftShadows,
    hard: &[f32],
    scene: &str,
) -> f32 {
    harness
        .app_mut()
        .get_sub_app_mut(RenderApp)
        .unwrap()
        .world_mut()
        .init_resource::<SsssTileReadback>();
    harness
        .world_mut()
        .entity_mut(sun)
        .insert(ScreenSpaceSoftShadows {
            tile_classification: true,
            ..settings.clone()
        });
    let mut frames = 0;
    loop {
        let img = to_linear(&harness.render().unwrap());
        if (lit(&img) - lit(hard)).abs() < 0.02 * lit(hard) && frames > 3 {
            break;
        }
        frames += 1;
        assert!(frames < 100, "{scene}: the receivers were never drawn");
    }
    let (tiled, buffers, bounds) = read_ssss_screen(harness);
    let (gpu_tiles, total) = read_tiles(harness);
    // The classification runs on the distance pass's σ bounds.
    let classified = ScreenBuffers {
        sigma: bounds,
        ..buffers.clone()
    };
    let cpu_tiles = active_tiles(
        &classified,
        &TileSettings {
            depth_rejection: settings.depth_rejection,
            lazy_shadowing: settings.lazy_shadowing,
            taps_per_side: settings.taps_per_side,
        },
    );
    let blurred = buffers.sigma.iter().filter(|s| s[0] > 0.0).count();
    assert!(
        blurred > buffers.sigma.len() / 50,
        "{scene}: a penumbra to classify ({blurred} pixels)"
    );
    assert_eq!(
        gpu_tiles, cpu_tiles,
        "{scene}: the GPU's active tiles differ from the CPU classification"
    );
    save_tile_image(scene, &tiled, &gpu_tiles);
    let fraction = gpu_tiles.len() as f32 / total as f32;
    assert!(
        !gpu_tiles.is_empty() && fraction < 0.6,
        "{scene}: {} of {total} tiles active",
        gpu_tiles.len()
    );

    // Every tile blurred: the same soft shadow.
    harness
        .world_mut()
        .entity_mut(sun)
        .insert(ScreenSpaceSoftShadows {
            tile_classification: false,
            ..settings
        });
    harness.render().unwrap();
    harness.render().unwrap();
    let (full, _, _) = read_ssss_screen(harness);
    let (all_tiles, _) = read_tiles(harness);
    assert_eq!(all_tiles.len(), total, "{scene}: every tile blurred");
    let worst = tiled
        .iter()
        .zip(&full)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    let changed = full
        .iter()
        .zip(&buffers.hard)
        .filter(|(a, b)| (*a - *b).abs() > 1e-3)
        .count();
    println!(
        "{scene}: {} of {total} tiles active ({:.1} %), {changed} pixels changed by the blur, tiled vs full worst difference {worst:.2e}",
        gpu_tiles.len(),
        100.0 * fraction
    );
    assert!(changed > 0, "{scene}: the blur changes the hard shadow");
    assert!(
        worst <= 1e-4,
        "{scene}: tiled and full-screen SSSS differ by {worst}"
    );
    fraction
}

#[test]
fn active_tiles_match_the_cpu_and_give_the_full_screen_result() {
    let Some(mut harness) = pole_harness("ssss_tiles") else {
        return;
    };
    harness.wait_until_ready().unwrap();
    let hard = to_linear(&harness.render().unwrap());
    let sun = sun_entity(&mut harness);
    for lazy_shadowing in [false, true] {
        check_scene(
            &mut harness,
            sun,
            ScreenSpaceSoftShadows {
                light_size: THETA,
                max_occluder_distance: 6.0,
                max_kernel_px: 60.0,
                taps_per_side: 11,
                lazy_shadowing,
                ..default()
            },
            &hard,
            &format!("pole (lazy {lazy_shadowing})"),
        );
    }
}

#[test]
fn the_hidden_shadow_of_a_hovering_panel_is_classified_with_lazy_shadowing() {
    let Some(mut harness) = panel_harness("ssss_tiles_panel") else {
        return;
    };
    let hard = to_linear(&harness.render().unwrap());
    let sun = sun_entity(&mut harness);
    check_scene(
        &mut harness,
        sun,
        ScreenSpaceSoftShadows {
            light_size: 0.3,
            max_occluder_distance: 3.0,
            max_kernel_px: 60.0,
            taps_per_side: 11,
            lazy_shadowing: true,
            ..default()
        },
        &hard,
        "hovering panel (lazy)",
    );
}

#[test]
fn switching_ssss_off_leaves_the_scene_as_it_was() {
    use bevy::core_pipeline::prepass::{DepthPrepass, NormalPrepass};
    use bevy_soft_shadows::ssss::receiver::SoftShadowCamera;
    let Some(mut harness) = pole_harness("ssss_off") else {
        return;
    };
    harness.wait_until_ready().unwrap();
    let hard = to_linear(&harness.render().unwrap());
    let sun = sun_entity(&mut harness);
    harness
        .world_mut()
        .entity_mut(sun)
        .insert(ScreenSpaceSoftShadows {
            light_size: THETA,
            max_occluder_distance: 6.0,
            ..default()
        });
    let soft = render_until(&mut harness, &hard, |img| rmse(img, &hard) > 0.003);
    let camera_has = |harness: &mut RenderHarness| {
        let world = harness.world_mut();
        let mut q = world.query_filtered::<(Has<SoftShadowCamera>, Has<DepthPrepass>, Has<NormalPrepass>), With<Camera3d>>();
        q.single(world).unwrap()
    };
    assert_eq!(camera_has(&mut harness), (true, true, true));
    harness
        .world_mut()
        .entity_mut(sun)
        .remove::<ScreenSpaceSoftShadows>();
    harness.render().unwrap();
    let off = to_linear(&harness.render().unwrap());
    // The prepasses SSSS added are gone (the camera had none), the receivers read "inactive",
    // and the image is the hard-shadow one.
    assert_eq!(camera_has(&mut harness), (false, false, false));
    let textures = harness.world_mut().resource::<SsssTextures>().clone();
    let visibility = floats(
        &harness
            .read_image(textures.visibility.clone(), SIZE, SIZE, 8)
            .unwrap(),
    );
    assert!(
        visibility.iter().step_by(2).all(|&v| v == -1.0),
        "the visibility texture reads 'inactive' for materials that keep it bound"
    );
    let (e_off, e_soft) = (rmse(&off, &hard), rmse(&soft, &hard));
    println!("RMSE against hard: SSSS on {e_soft:.4}, switched off {e_off:.5}");
    assert!(e_off < 0.1 * e_soft, "off {e_off} vs on {e_soft}");
}
