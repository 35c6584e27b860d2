//! `pyramid_build` on elevation data as users have it: an RGB Terrarium-encoded DEM image is
//! refused by `--height` (it used to be turned into luminance: 2,475 m read back as 9) and
//! decoded to metres by `--dem terrarium`, whose pyramid reads back the known heights.

use bevy_terrain_clip::cache::TileKey;
use bevy_terrain_clip::dem::{DiskHeightSource, terrarium_texel};
use bevy_terrain_clip::pyramid::{PyramidManifest, TexelFormat};
use std::process::Command;

/// The known height of pixel (x, y): a slope from −20 m to 2,475 m with a ripple.
fn height(x: u32, y: u32) -> f32 {
    -20.0 + 2495.0 * (x as f32 / 63.0) + 3.5 * ((y as f32) * 0.7).sin()
}

#[test]
fn rgb_elevation_is_refused_as_luminance_and_decoded_with_dem() {
    let dir = std::env::temp_dir().join(format!("pyramid_build_cli_{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let image_path = dir.join("dem.png");
    image::RgbImage::from_fn(64, 64, |x, y| image::Rgb(terrarium_texel(height(x, y))))
        .save(&image_path)
        .unwrap();
    let run = |out: &str, flags: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_pyramid_build"))
            .arg(&image_path)
            .arg(dir.join(out))
            .args(["--tile", "32"])
            .args(flags)
            .output()
            .unwrap()
    };

    // `--height` on colour: an error that names the way out, and no pyramid.
    let refused = run("as_luminance", &["--height"]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{stderr}");
    assert!(stderr.contains("--dem terrarium"), "{stderr}");
    assert!(!dir.join("as_luminance").join("pyramid.json").exists());

    // `--dem terrarium`: metres in 16 bits over the data's range.
    let built = run("heights", &["--dem", "terrarium"]);
    assert!(
        built.status.success(),
        "{}",
        String::from_utf8_lossy(&built.stderr)
    );
    let manifest = PyramidManifest::load(&dir.join("heights")).unwrap();
    assert_eq!(manifest.texel, TexelFormat::Height16);
    assert!(manifest.height_scale_m <= 0.05, "{manifest:?}");
    let source = DiskHeightSource::open(dir.join("heights")).unwrap();
    // The finest level (1): tile (1, 0) holds pixels x 32..64, y 0..32.
    let tile = source
        .load_heights(TileKey { z: 1, x: 1, y: 0 })
        .unwrap()
        .unwrap();
    let mut worst = 0.0f32;
    for y in 0..32 {
        for x in 0..32 {
            worst = worst.max((tile.at(x, y) - height(32 + x, y)).abs());
        }
    }
    // Terrarium's own 1/256 m step plus half a stored step.
    let bound = 1.0 / 256.0 + 0.5 * manifest.height_scale_m as f32 + 1e-3;
    assert!(worst <= bound, "worst {worst} m against {bound} m");
    assert!((tile.at(31, 0) - 2475.0).abs() < 0.1, "{}", tile.at(31, 0));
    std::fs::remove_dir_all(&dir).ok();
}
