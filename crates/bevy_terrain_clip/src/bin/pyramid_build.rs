//! Tiles a large image into an XYZ/TMS pyramid with a `pyramid.json` manifest (box-filtered
//! levels, atomic writes; run it again after an interruption to resume).
//!
//! ```text
//! cargo run --release -p bevy_terrain_clip --bin pyramid_build -- IMAGE.png OUT_DIR
//!     [--tile 512] [--scheme xyz|tms] [--origin X,Z] [--metres-per-texel F] [--height]
//! ```
//! A 16-bit grayscale image (or any image with `--height`) builds a 16-bit heightmap pyramid;
//! anything else builds 8-bit RGBA imagery.

use bevy_terrain_clip::builder::{BuildSettings, build_pyramid};
use bevy_terrain_clip::pyramid::TileScheme;
use std::io::Write;

fn usage(message: &str) -> ! {
    eprintln!(
        "{message}\nusage: pyramid_build IMAGE OUT_DIR [--tile N] [--scheme xyz|tms] [--origin X,Z] [--metres-per-texel F] [--height]"
    );
    std::process::exit(2)
}

fn main() {
    let mut positional = Vec::new();
    let mut settings = BuildSettings::default();
    let mut force_height = false;
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
            _ if arg.starts_with("--") => usage(&format!("unknown flag {arg}")),
            _ => positional.push(arg),
        }
    }
    let [image_path, out_dir] = positional.as_slice() else {
        usage("expected IMAGE and OUT_DIR");
    };
    let image = match image::open(image_path) {
        Ok(i) => i,
        Err(e) => {
            eprintln!("{image_path}: {e}");
            std::process::exit(1)
        }
    };
    let height = force_height || matches!(image, image::DynamicImage::ImageLuma16(_));
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
