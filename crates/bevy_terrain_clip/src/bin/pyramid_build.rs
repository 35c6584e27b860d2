//! Tiles a large image into an XYZ/TMS pyramid with a `pyramid.json` manifest (box-filtered
//! levels, atomic writes; run it again after an interruption to resume).
//!
//! ```text
//! cargo run --release -p bevy_terrain_clip --bin pyramid_build -- IMAGE.png OUT_DIR
//!     [--tile 512] [--scheme xyz|tms] [--origin X,Z] [--metres-per-texel F]
//!     [--height | --dem terrarium|mapbox]
//! ```
//! A 16-bit grayscale image (or a grayscale one with `--height`) builds a 16-bit heightmap
//! pyramid of its values (`height_scale_m` 1); `--dem` decodes an RGB-encoded elevation image
//! (Terrarium or Mapbox Terrain-RGB) to metres and stores them in 16 bits over their range (the
//! manifest's `height_offset_m` and `height_scale_m`). `--height` on a colour image is an error,
//! not a conversion to luminance. Anything else builds 8-bit RGBA imagery.

use bevy_terrain_clip::builder::{BuildSettings, build_pyramid};
use bevy_terrain_clip::dem::{HeightScale, mapbox_height, terrarium_height};
use bevy_terrain_clip::pyramid::{TexelFormat, TileScheme};
use std::io::Write;

fn usage(message: &str) -> ! {
    eprintln!(
        "{message}\nusage: pyramid_build IMAGE OUT_DIR [--tile N] [--scheme xyz|tms] [--origin X,Z] [--metres-per-texel F] [--height | --dem terrarium|mapbox]"
    );
    std::process::exit(2)
}

fn main() {
    let mut positional = Vec::new();
    let mut settings = BuildSettings::default();
    let mut force_height = false;
    let mut dem: Option<TexelFormat> = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let mut value = || {
            args.next()
                .unwrap_or_else(|| usage(&format!("{arg} needs a value")))
        };
        match arg.as_str() {
            "--tile" => {
                settings.tile_size = value()
                    .parse()
                    .unwrap_or_else(|_| usage("--tile takes a number"))
            }
            "--scheme" => {
                settings.scheme = match value().as_str() {
                    "xyz" => TileScheme::Xyz,
                    "tms" => TileScheme::Tms,
                    other => usage(&format!("--scheme takes xyz or tms, not '{other}'")),
                }
            }
            "--origin" => {
                let v = value();
                let parts: Vec<f64> = v.split(',').filter_map(|p| p.trim().parse().ok()).collect();
                if parts.len() != 2 {
                    usage(&format!("--origin takes X,Z, not '{v}'"));
                }
                settings.origin_m = [parts[0], parts[1]];
            }
            "--metres-per-texel" => {
                settings.metres_per_texel = value()
                    .parse()
                    .unwrap_or_else(|_| usage("--metres-per-texel takes a number"))
            }
            "--height" => force_height = true,
            "--dem" => {
                dem = Some(match value().as_str() {
                    "terrarium" => TexelFormat::Terrarium,
                    "mapbox" => TexelFormat::Mapbox,
                    other => usage(&format!("--dem takes terrarium or mapbox, not '{other}'")),
                })
            }
            _ if arg.starts_with("--") => usage(&format!("unknown flag {arg}")),
            _ => positional.push(arg),
        }
    }
    let [image_path, out_dir] = positional.as_slice() else {
        usage("expected IMAGE and OUT_DIR");
    };
    let mut image = match image::open(image_path) {
        Ok(i) => i,
        Err(e) => {
            eprintln!("{image_path}: {e}");
            std::process::exit(1)
        }
    };
    let gray = matches!(
        image,
        image::DynamicImage::ImageLuma8(_) | image::DynamicImage::ImageLuma16(_)
    );
    if force_height && !gray {
        // Heights encoded in colour would turn into meaningless luminance.
        eprintln!(
            "{image_path}: --height needs a grayscale heightmap, this image is {:?}; for \
             RGB-encoded elevation pass --dem terrarium or --dem mapbox",
            image.color()
        );
        std::process::exit(1)
    }
    let height =
        force_height || dem.is_some() || matches!(image, image::DynamicImage::ImageLuma16(_));
    if let Some(encoding) = dem {
        // Decode to metres, then store 16 bits over the data's range (the manifest's scale).
        let rgb = image.to_rgb8();
        let decode = match encoding {
            TexelFormat::Mapbox => mapbox_height,
            _ => terrarium_height,
        };
        let metres: Vec<f32> = rgb.pixels().map(|p| decode([p[0], p[1], p[2]])).collect();
        let (lo, hi) = metres
            .iter()
            .fold((f32::MAX, f32::MIN), |(lo, hi), &h| (lo.min(h), hi.max(h)));
        settings.heights = HeightScale::covering(lo, hi);
        eprintln!(
            "{image_path}: {encoding:?} heights {lo:.2}..{hi:.2} m, stored in steps of {:.3} m",
            settings.heights.scale_m
        );
        let (scale, width) = (settings.heights, rgb.width());
        image = image::DynamicImage::ImageLuma16(image::ImageBuffer::from_fn(
            width,
            rgb.height(),
            |x, y| image::Luma([scale.value(metres[(y * width + x) as usize])]),
        ));
    }
    eprintln!(
        "{image_path}: {}×{}, tiles of {}, {}",
        image.width(),
        image.height(),
        settings.tile_size,
        if height {
            "16-bit heights"
        } else {
            "RGBA imagery"
        }
    );
    let started = std::time::Instant::now();
    let progress = |done: usize, total: usize| {
        if done == total || done.is_multiple_of(16) {
            eprint!(
                "\r  {done}/{total} tiles ({:.0} %)",
                100.0 * done as f64 / total as f64
            );
            std::io::stderr().flush().ok();
        }
    };
    let out_dir = std::path::Path::new(out_dir);
    let built = if height {
        build_pyramid(&image.to_luma16(), out_dir, &settings, &progress, None)
    } else {
        build_pyramid(&image.to_rgba8(), out_dir, &settings, &progress, None)
    };
    match built {
        Ok(r) => {
            eprintln!();
            println!(
                "{{\"levels\": {}, \"tiles\": {}, \"written\": {}, \"reused\": {}, \"seconds\": {:.2}}}",
                r.levels,
                r.tiles,
                r.written,
                r.reused,
                started.elapsed().as_secs_f64()
            );
        }
        Err(e) => {
            eprintln!("\n{e}");
            std::process::exit(1)
        }
    }
}
