//! The terrain's loaders fuzzed with seeded mutations (`bevy_nature_harness::fuzz`): the
//! pyramid manifest parser and what a parsed manifest computes, the imagery tile decoder (PNG,
//! JPEG and WebP seeds) and the elevation tile decoder (16-bit PNG, Terrarium and Mapbox seeds).
//! Every input must give a value or an error — never a panic, never a case slower than
//! `fuzz::SLOW_CASE` — and what is accepted must be usable (sizes as asked, heights finite).
//!
//! More cases: `NATURE_FUZZ_CASES=200000 cargo test --release -p bevy_terrain_clip --test fuzz`.

use bevy_nature_harness::fuzz::{cases, crc32, fix_png_crcs, fuzz, fuzz_with};
use bevy_terrain_clip::cache::TileKey;
use bevy_terrain_clip::dem::{HeightScale, decode_height_tile, height_scale_of};
use bevy_terrain_clip::pyramid::{PartialLevel, PyramidManifest, TexelFormat, TileScheme};
use bevy_terrain_clip::source::decode_tile;
use std::path::Path;

fn manifest(scheme: TileScheme, texel: TexelFormat) -> PyramidManifest {
    PyramidManifest {
        version: 1,
        scheme,
        extension: "png".into(),
        tile_size: 256,
        levels: 6,
        origin_m: [-512.0, 1024.0],
        metres_per_texel: 0.5,
        partial_levels: vec![PartialLevel {
            z: 5,
            min: [2, 3],
            max: [20, 31],
        }],
        texel,
        height_offset_m: -100.0,
        height_scale_m: 0.05,
        extent_texels: Some([6000, 7000]),
    }
}

#[test]
fn fuzz_manifest_parser() {
    let seeds: Vec<Vec<u8>> = [
        manifest(TileScheme::Xyz, TexelFormat::Rgba8),
        manifest(TileScheme::Tms, TexelFormat::Height16),
        manifest(TileScheme::Xyz, TexelFormat::Terrarium),
    ]
    .iter()
    .map(|m| serde_json::to_vec_pretty(m).unwrap())
    .collect();
    let path = Path::new("fuzz/pyramid.json");
    let keys = [
        TileKey { z: 0, x: 0, y: 0 },
        TileKey { z: 5, x: 4, y: 30 },
        TileKey {
            z: 23,
            x: u32::MAX,
            y: u32::MAX,
        },
        TileKey {
            z: u32::MAX,
            x: 1,
            y: 1,
        },
    ];
    let report = fuzz("manifest", &seeds, cases(20_000), |bytes| {
        let Ok(text) = std::str::from_utf8(bytes) else {
            return false;
        };
        let Ok(m) = PyramidManifest::parse(text, path) else {
            return false;
        };
        // An accepted manifest is usable: nothing it computes panics or overflows.
        assert!(m.problems().is_empty());
        let _ = m.virtual_levels();
        let uv = m.world_to_uv(0.0, 0.0);
        assert!(uv.iter().all(|v| v.is_finite()), "{uv:?}");
        for key in keys {
            let _ = m.may_exist(key);
            let _ = m.tile_path(Path::new("tiles"), key);
        }
        if m.texel.is_height() {
            let scale = height_scale_of(&m).expect("a height pyramid has a scale");
            assert!(scale.metres(u16::MAX).is_finite());
        }
        true
    });
    eprintln!("manifest: {report:?}");
    assert!(
        report.accepted > 10,
        "mutations never kept a manifest valid"
    );
}

/// Found by the manifest target: a height scale of 1e39 passed the checks and made every
/// height infinite.
#[test]
fn regression_a_huge_height_scale_is_refused() {
    let mut m = manifest(TileScheme::Xyz, TexelFormat::Height16);
    m.height_scale_m = 1e39;
    let text = serde_json::to_string(&m).unwrap();
    let err = PyramidManifest::parse(&text, Path::new("p.json")).unwrap_err();
    assert!(err.to_string().contains("height_scale_m"), "{err}");
    m.height_scale_m = 200.0;
    m.height_offset_m = -1e8;
    assert!(!m.problems().is_empty());
}

/// A 16 × 16 tile in `format`, of RGBA texels varying across it.
fn tile_bytes(format: image::ImageFormat) -> Vec<u8> {
    let rgba = image::RgbaImage::from_fn(16, 16, |x, y| {
        image::Rgba([(x * 16) as u8, (y * 16) as u8, ((x + y) * 8) as u8, 255])
    });
    let image = match format {
        image::ImageFormat::Jpeg => {
            image::DynamicImage::ImageRgb8(image::DynamicImage::ImageRgba8(rgba).to_rgb8())
        }
        _ => image::DynamicImage::ImageRgba8(rgba),
    };
    let mut out = std::io::Cursor::new(Vec::new());
    image.write_to(&mut out, format).unwrap();
    out.into_inner()
}

#[test]
fn fuzz_imagery_tile_decoder() {
    let seeds = vec![
        tile_bytes(image::ImageFormat::Png),
        tile_bytes(image::ImageFormat::Jpeg),
        tile_bytes(image::ImageFormat::WebP),
    ];
    let path = Path::new("fuzz/0/0/0.png");
    // PNG checksums are made right after each mutation (JPEG and WebP have none to fix).
    let fix = |bytes: &mut Vec<u8>| {
        if bytes.starts_with(b"\x89PNG") {
            fix_png_crcs(bytes)
        }
    };
    let report = fuzz_with("imagery_tile", &seeds, cases(5_000), fix, |bytes| {
        match decode_tile(bytes, path, 16) {
            Ok(tile) => {
                assert_eq!((tile.size, tile.rgba.len()), (16, 16 * 16 * 4));
                true
            }
            Err(e) => {
                // Errors name the tile.
                assert!(e.to_string().contains("0.png"), "{e}");
                false
            }
        }
    });
    eprintln!("imagery tiles: {report:?}");
    assert!(
        report.accepted > 10,
        "mutations never kept a tile decodable"
    );
}

fn height_seeds() -> Vec<(TexelFormat, Vec<u8>)> {
    let encode = |image: image::DynamicImage| {
        let mut out = std::io::Cursor::new(Vec::new());
        image.write_to(&mut out, image::ImageFormat::Png).unwrap();
        out.into_inner()
    };
    let luma = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(16, 16, |x, y| {
        image::Luma([(x * 3000 + y * 7) as u16])
    });
    let rgb = image::RgbImage::from_fn(16, 16, |x, y| image::Rgb([128, (x * 16) as u8, y as u8]));
    vec![
        (
            TexelFormat::Height16,
            encode(image::DynamicImage::ImageLuma16(luma)),
        ),
        (
            TexelFormat::Terrarium,
            encode(image::DynamicImage::ImageRgb8(rgb.clone())),
        ),
        (
            TexelFormat::Mapbox,
            encode(image::DynamicImage::ImageRgb8(rgb)),
        ),
    ]
}

#[test]
fn fuzz_elevation_tile_decoder() {
    let path = Path::new("fuzz/3/1/2.png");
    let scale = HeightScale {
        offset_m: -100.0,
        scale_m: 0.05,
    };
    // Each encoding from its own seed (a tile decoded as another encoding is only an error).
    for (texel, seed) in height_seeds() {
        let target = format!("elevation_tile_{texel:?}");
        // PNG checksums are made right after each mutation, so the decoder sees the damage.
        let fix = |bytes: &mut Vec<u8>| fix_png_crcs(bytes);
        let report = fuzz_with(
            &target,
            &[seed],
            cases(3_000),
            fix,
            |input| match decode_height_tile(input, path, 16, texel, scale) {
                Ok(tile) => {
                    assert_eq!(tile.metres.len(), 16 * 16);
                    assert!(tile.metres.iter().all(|m| m.is_finite()));
                    true
                }
                Err(e) => {
                    assert!(e.to_string().contains("2.png"), "{e}");
                    false
                }
            },
        );
        eprintln!("{target}: {report:?}");
        assert!(
            report.accepted > 10,
            "{target}: mutations never kept a tile decodable"
        );
    }
}

/// A header claiming a huge image is refused from its size alone, before any pixel is decoded.
#[test]
fn a_tile_claiming_gigapixels_is_refused_by_its_header() {
    let mut png = tile_bytes(image::ImageFormat::Png);
    // IHDR's width and height (bytes 16..24) claim 60000 × 60000, its CRC (29..33) made right:
    // a well-formed header of an image of 14 GB.
    png[16..20].copy_from_slice(&60000u32.to_be_bytes());
    png[20..24].copy_from_slice(&60000u32.to_be_bytes());
    let crc = crc32(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    let start = std::time::Instant::now();
    let err = decode_tile(&png, Path::new("big.png"), 16).unwrap_err();
    assert!(start.elapsed() < std::time::Duration::from_secs(1));
    let text = err.to_string();
    assert!(text.contains("big.png") && text.contains("60000"), "{text}");
}
