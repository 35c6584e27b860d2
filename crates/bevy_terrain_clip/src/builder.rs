//! Building a tile pyramid from one large image: the image is padded to a
//! power-of-two square of whole tiles (transparent beyond its edges), cut into the finest
//! level's tiles, and every coarser tile is the 2×2 box filter of its four children — the exact
//! average for a halving, which is what a mip chain of the whole image would hold.
//!
//! Two texel formats: 8-bit RGBA imagery ([`image::RgbaImage`]) and 16-bit heightmaps
//! ([`image::ImageBuffer`] of [`image::Luma<u16>`], written as 16-bit grayscale PNG tiles, the
//! manifest saying `"texel": "height16"`). Heights beyond the image's edges are 0. Averaging
//! heights is the right prefilter for a geometry LoD (a coarser level is the mean surface), and
//! the sums are taken in 32 bits so no precision is lost before the one rounding per level.
//!
//! Tiles are built depth-first (a few tiles in memory at a time, whatever the image size) and
//! written atomically (temporary file, then rename), the manifest last. An interrupted build
//! resumes: tiles already on disk that decode at the right size are reused, anything else
//! (missing, truncated, left-over temporary files) is rebuilt, so a resumed build writes the same
//! files as an uninterrupted one.

use crate::cache::TileKey;
use crate::pyramid::{MANIFEST, PyramidManifest, TexelFormat, TileScheme};
use crate::source::decode_tile;
use image::{ImageBuffer, Pixel, PixelWithColorType};
use std::path::{Path, PathBuf};

/// A texel type a pyramid can be built of: 8-bit RGBA imagery or 16-bit heights.
pub trait PyramidTexel: Pixel<Subpixel = Self::Channel> + PixelWithColorType + 'static {
    /// The channel type (`u8` or `u16`).
    type Channel: Copy + Into<u32> + TryFrom<u32> + Default;
    /// What the manifest records.
    const FORMAT: TexelFormat;
    /// Decodes a tile written earlier, if it is one of this format at `tile_size`.
    fn decode(
        bytes: &[u8],
        path: &Path,
        tile_size: u32,
    ) -> Option<ImageBuffer<Self, Vec<Self::Channel>>>;
    /// PNG bytes of a tile.
    fn encode(tile: &ImageBuffer<Self, Vec<Self::Channel>>) -> image::ImageResult<Vec<u8>>;
}

fn png_bytes<P: Pixel + PixelWithColorType>(
    tile: &ImageBuffer<P, Vec<P::Subpixel>>,
) -> image::ImageResult<Vec<u8>>
where
    [P::Subpixel]: image::EncodableLayout,
{
    let mut bytes = Vec::new();
    tile.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )?;
    Ok(bytes)
}

impl PyramidTexel for image::Rgba<u8> {
    type Channel = u8;
    const FORMAT: TexelFormat = TexelFormat::Rgba8;
    fn decode(bytes: &[u8], path: &Path, tile_size: u32) -> Option<image::RgbaImage> {
        let tile = decode_tile(bytes, path, tile_size).ok()?;
        image::RgbaImage::from_raw(tile_size, tile_size, tile.rgba)
    }
    fn encode(tile: &image::RgbaImage) -> image::ImageResult<Vec<u8>> {
        png_bytes(tile)
    }
}

impl PyramidTexel for image::Luma<u16> {
    type Channel = u16;
    const FORMAT: TexelFormat = TexelFormat::Height16;
    fn decode(bytes: &[u8], _path: &Path, tile_size: u32) -> Option<ImageBuffer<Self, Vec<u16>>> {
        // Only a 16-bit grayscale tile counts: an 8-bit one would lose the heights' precision.
        match image::load_from_memory(bytes).ok()? {
            image::DynamicImage::ImageLuma16(tile)
                if tile.width() == tile_size && tile.height() == tile_size =>
            {
                Some(tile)
            }
            _ => None,
        }
    }
    fn encode(tile: &ImageBuffer<Self, Vec<u16>>) -> image::ImageResult<Vec<u8>> {
        png_bytes(tile)
    }
}

/// The 2×2 box filter of four texels, rounded to nearest.
fn box_filter<P: PyramidTexel>(texels: [&P; 4]) -> P {
    let n = P::CHANNEL_COUNT as usize;
    let mut sum = [0u32; 4];
    for t in texels {
        for (c, v) in t.channels().iter().enumerate() {
            sum[c] += (*v).into();
        }
    }
    let mut out = [P::Channel::default(); 4];
    for c in 0..n {
        // The mean of four channel values fits the channel.
        out[c] = P::Channel::try_from((sum[c] + 2) / 4).unwrap_or_default();
    }
    *P::from_slice(&out[..n])
}

/// How to build.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildSettings {
    /// Tile side (power of two).
    pub tile_size: u32,
    /// Row order on disk.
    pub scheme: TileScheme,
    /// World (x, z) of the image's north-west corner (m).
    pub origin_m: [f64; 2],
    /// Size of one image texel (m).
    pub metres_per_texel: f64,
    /// For a 16-bit height pyramid: what its stored values mean in metres (the manifest's
    /// `height_offset_m` and `height_scale_m`).
    pub heights: crate::dem::HeightScale,
}

impl Default for BuildSettings {
    fn default() -> Self {
        Self {
            tile_size: 512,
            scheme: TileScheme::Xyz,
            origin_m: [0.0, 0.0],
            metres_per_texel: 1.0,
            heights: Default::default(),
        }
    }
}

/// Why a build stopped.
#[derive(Debug)]
pub enum BuildError {
    /// Writing failed.
    Io(PathBuf, std::io::Error),
    /// The settings are unusable.
    Settings(String),
    /// Stopped on request after this many tiles (resume by building again).
    Interrupted(usize),
}

impl std::fmt::Display for BuildError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Io(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Settings(e) => write!(f, "bad build settings: {e}"),
            Self::Interrupted(n) => {
                write!(f, "interrupted after {n} tiles (build again to resume)")
            }
        }
    }
}

impl std::error::Error for BuildError {}

/// What a build did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BuildReport {
    /// Pyramid levels.
    pub levels: u32,
    /// Tiles in the pyramid.
    pub tiles: usize,
    /// Tiles written by this run.
    pub written: usize,
    /// Tiles found valid on disk and reused.
    pub reused: usize,
}

struct Builder<'a, P: PyramidTexel> {
    image: &'a ImageBuffer<P, Vec<P::Channel>>,
    dir: &'a Path,
    manifest: PyramidManifest,
    report: BuildReport,
    stop_after: Option<usize>,
    progress: &'a dyn Fn(usize, usize),
}

/// Pyramid levels for an image of `width × height` with `tile_size` tiles: the smallest square
/// of `tile_size · 2^k` texels holding it has `k + 1` levels.
pub fn levels_for(width: u32, height: u32, tile_size: u32) -> u32 {
    let side = width
        .max(height)
        .max(1)
        .div_ceil(tile_size)
        .next_power_of_two();
    side.trailing_zeros() + 1
}

fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), BuildError> {
    let io = |e| BuildError::Io(path.to_path_buf(), e);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(io)?;
    }
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

fn encode_png<P: PyramidTexel>(
    tile: &ImageBuffer<P, Vec<P::Channel>>,
    path: &Path,
) -> Result<Vec<u8>, BuildError> {
    P::encode(tile).map_err(|e| BuildError::Io(path.to_path_buf(), std::io::Error::other(e)))
}

type Tile<P> = ImageBuffer<P, Vec<<P as PyramidTexel>::Channel>>;

impl<P: PyramidTexel> Builder<'_, P> {
    /// The tile at `path` if it is on disk and decodes at the right size and format.
    fn on_disk(&self, path: &Path) -> Option<Tile<P>> {
        let bytes = std::fs::read(path).ok()?;
        P::decode(&bytes, path, self.manifest.tile_size)
    }

    fn reuse(&mut self, tile: Tile<P>) -> Tile<P> {
        self.report.reused += 1;
        (self.progress)(self.report.reused + self.report.written, self.report.tiles);
        tile
    }

    /// Builds (or reuses) tile `key` and returns its texels. Children are always visited first,
    /// so a resumed build checks every tile, not only the ones under a missing parent.
    fn tile(&mut self, key: TileKey) -> Result<Tile<P>, BuildError> {
        let t = self.manifest.tile_size;
        let path = self.manifest.tile_path(self.dir, key);
        let finest = self.manifest.levels - 1;
        let tile = if key.z == finest {
            if let Some(tile) = self.on_disk(&path) {
                return Ok(self.reuse(tile));
            }
            let mut tile = Tile::<P>::new(t, t);
            for y in 0..t {
                for x in 0..t {
                    let (sx, sy) = (key.x * t + x, key.y * t + y);
                    if sx < self.image.width() && sy < self.image.height() {
                        tile.put_pixel(x, y, *self.image.get_pixel(sx, sy));
                    }
                }
            }
            tile
        } else {
            let mut children = Vec::with_capacity(4);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let child = self.tile(TileKey {
                    z: key.z + 1,
                    x: key.x * 2 + dx,
                    y: key.y * 2 + dy,
                })?;
                children.push(((dx, dy), child));
            }
            if let Some(tile) = self.on_disk(&path) {
                return Ok(self.reuse(tile));
            }
            let mut tile = Tile::<P>::new(t, t);
            let half = t / 2;
            for ((dx, dy), child) in &children {
                for y in 0..half {
                    for x in 0..half {
                        let texel = |ox, oy| child.get_pixel(2 * x + ox, 2 * y + oy);
                        let mean = box_filter([texel(0, 0), texel(1, 0), texel(0, 1), texel(1, 1)]);
                        tile.put_pixel(dx * half + x, dy * half + y, mean);
                    }
                }
            }
            tile
        };
        if self.stop_after.is_some_and(|n| self.report.written >= n) {
            return Err(BuildError::Interrupted(self.report.written));
        }
        write_atomically(&path, &encode_png(&tile, &path)?)?;
        self.report.written += 1;
        (self.progress)(self.report.reused + self.report.written, self.report.tiles);
        Ok(tile)
    }
}

/// Builds (or resumes building) the pyramid of `image` in `dir`: an [`image::RgbaImage`] gives
/// imagery, an `ImageBuffer<Luma<u16>, _>` a heightmap pyramid. `progress(done, total)` is
/// called after every tile; `stop_after` interrupts the build after that many newly written
/// tiles (for tests of resuming).
pub fn build_pyramid<P: PyramidTexel>(
    image: &ImageBuffer<P, Vec<P::Channel>>,
    dir: &Path,
    settings: &BuildSettings,
    progress: &dyn Fn(usize, usize),
    stop_after: Option<usize>,
) -> Result<BuildReport, BuildError> {
    let levels = levels_for(image.width(), image.height(), settings.tile_size);
    let manifest = PyramidManifest {
        version: 1,
        scheme: settings.scheme,
        extension: "png".into(),
        tile_size: settings.tile_size,
        levels,
        origin_m: settings.origin_m,
        metres_per_texel: settings.metres_per_texel,
        partial_levels: Vec::new(),
        texel: P::FORMAT,
        height_offset_m: settings.heights.offset_m,
        height_scale_m: settings.heights.scale_m,
        extent_texels: Some([image.width(), image.height()]),
    };
    let problems = manifest.problems();
    if !problems.is_empty() {
        return Err(BuildError::Settings(problems.join("; ")));
    }
    let tiles = (0..levels).map(|z| 1usize << (2 * z)).sum();
    let mut builder = Builder {
        image,
        dir,
        manifest,
        report: BuildReport {
            levels,
            tiles,
            ..Default::default()
        },
        stop_after,
        progress,
    };
    builder.tile(TileKey { z: 0, x: 0, y: 0 })?;
    let json = serde_json::to_string_pretty(&builder.manifest).expect("manifest serialises");
    write_atomically(&dir.join(MANIFEST), json.as_bytes())?;
    Ok(builder.report)
}

/// Builds (or resumes) a heightmap pyramid in `dir` from `height(x, z)` (metres at world
/// `x, z`), sampled at the texel centres of a `size[0] × size[1]` grid whose north-west corner and
/// texel size are `settings.origin_m` and `settings.metres_per_texel`, stored in 16 bits under
/// `settings.heights` — a procedural or analytic ground as a pyramid, as a DEM would give it.
pub fn build_height_pyramid(
    dir: &Path,
    size: [u32; 2],
    settings: &BuildSettings,
    height: impl Fn(f64, f64) -> f64,
) -> Result<BuildReport, BuildError> {
    let (origin, step) = (settings.origin_m, settings.metres_per_texel);
    let image = ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(size[0], size[1], |i, j| {
        let (x, z) = (
            origin[0] + (i as f64 + 0.5) * step,
            origin[1] + (j as f64 + 0.5) * step,
        );
        image::Luma([settings.heights.value(height(x, z) as f32)])
    });
    build_pyramid(&image, dir, settings, &|_, _| {}, None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::{DiskTileSource, TileSource};

    fn test_image() -> image::RgbaImage {
        image::RgbaImage::from_fn(200, 150, |x, y| {
            image::Rgba([
                (x * 7 % 256) as u8,
                (y * 3 % 256) as u8,
                ((x ^ y) % 256) as u8,
                255,
            ])
        })
    }

    fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
        let mut out = Vec::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    out.push((
                        p.strip_prefix(dir).unwrap().to_path_buf(),
                        std::fs::read(&p).unwrap(),
                    ));
                }
            }
        }
        out.sort();
        out
    }

    #[test]
    fn a_built_pyramid_holds_the_image_and_its_box_filtered_levels() {
        let dir = std::env::temp_dir().join(format!("pyramid_build_{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        let image = test_image();
        let settings = BuildSettings {
            tile_size: 64,
            ..Default::default()
        };
        let report = build_pyramid(&image, &dir, &settings, &|_, _| {}, None).unwrap();
        // 200 × 150 in 64² tiles: a 256² square, levels of 1, 2² and 4² tiles.
        assert_eq!((report.levels, report.tiles, report.written), (3, 21, 21));
        let source = DiskTileSource::open(&dir).unwrap();
        // Imagery is not heights.
        assert!(crate::dem::DiskHeightSource::open(&dir).is_err());
        let load = |z, x, y| {
            bevy::tasks::block_on(source.load(TileKey { z, x, y }))
                .unwrap()
                .unwrap()
        };
        // Finest level: the image itself, transparent beyond it.
        assert_eq!(load(2, 1, 2).texel(3, 4), image.get_pixel(67, 132).0);
        assert_eq!(load(2, 3, 3).texel(0, 0), [0, 0, 0, 0]);
        // Level 0 texel (5, 6) is the mean of the 4×4 image block at (20, 24).
        let mut sum = [0u32; 4];
        for y in 24..28 {
            for x in 20..24 {
                for (s, v) in sum.iter_mut().zip(image.get_pixel(x, y).0) {
                    *s += v as u32;
                }
            }
        }
        let expected = sum.map(|s| s as f32 / 16.0);
        let got = load(0, 0, 0).texel(5, 6);
        for c in 0..4 {
            // Two rounded halvings: within one step of the exact mean.
            assert!(
                (got[c] as f32 - expected[c]).abs() <= 1.0,
                "{got:?} vs {expected:?}"
            );
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_16_bit_heightmap_builds_a_16_bit_pyramid() {
        let dir = std::env::temp_dir().join(format!("pyramid_height_{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        // Heights using all 16 bits: any 8-bit step would show as an error of ≥ 257.
        let heights = ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(130, 100, |x, y| {
            image::Luma([(x * 503 + y * 97 + (x * y) % 13) as u16])
        });
        let scale = crate::dem::HeightScale {
            offset_m: -100.0,
            scale_m: 0.5,
        };
        let settings = BuildSettings {
            tile_size: 32,
            heights: scale,
            ..Default::default()
        };
        let report = build_pyramid(&heights, &dir, &settings, &|_, _| {}, None).unwrap();
        // 130 × 100 in 32² tiles: a 256² square, 4 levels.
        assert_eq!((report.levels, report.tiles), (4, 85));
        let manifest: PyramidManifest =
            serde_json::from_slice(&std::fs::read(dir.join(MANIFEST)).unwrap()).unwrap();
        assert_eq!(manifest.texel, TexelFormat::Height16);
        let load = |z: u32, x: u32, y: u32| {
            let path = dir.join(format!("{z}/{x}/{y}.png"));
            <image::Luma<u16>>::decode(&std::fs::read(&path).unwrap(), &path, 32)
                .expect("a 16-bit grayscale tile")
        };
        // Finest level: the heights themselves, exactly; 0 beyond the image.
        assert_eq!(
            load(3, 2, 1).get_pixel(5, 7).0[0],
            heights.get_pixel(69, 39).0[0]
        );
        assert_eq!(load(3, 7, 7).get_pixel(0, 0).0[0], 0);
        // Level 1 texel (3, 2) is the mean of the 4×4 block at (12, 8) within one step.
        let mut sum = 0u32;
        for y in 8..12 {
            for x in 12..16 {
                sum += heights.get_pixel(x, y).0[0] as u32;
            }
        }
        let got = load(1, 0, 0).get_pixel(3, 2).0[0] as f64;
        assert!(
            (got - sum as f64 / 16.0).abs() <= 1.0,
            "{got} vs {}",
            sum as f64 / 16.0
        );
        // An imagery build does not mistake these tiles for its own: they are rebuilt.
        let as_rgba = <image::Rgba<u8>>::decode(
            &std::fs::read(dir.join("3/2/1.png")).unwrap(),
            Path::new("x"),
            32,
        );
        assert!(
            as_rgba.is_some(),
            "gray tiles still decode as imagery (shown as gray)"
        );
        let again = build_pyramid(&heights, &dir, &settings, &|_, _| {}, None).unwrap();
        assert_eq!((again.written, again.reused), (0, 85));
        // Read as heights, in metres by the manifest's scale; refused as imagery.
        assert_eq!(
            (manifest.height_offset_m, manifest.height_scale_m),
            (-100.0, 0.5)
        );
        let source = crate::dem::DiskHeightSource::open(&dir).unwrap();
        let tile = source
            .load_heights(TileKey { z: 3, x: 2, y: 1 })
            .unwrap()
            .unwrap();
        let stored = heights.get_pixel(69, 39).0[0] as f32;
        assert_eq!(tile.at(5, 7), -100.0 + 0.5 * stored);
        // Streamed as a source of heights: the same metres, one f32 a texel.
        use crate::source::{TexelKind, TileSource};
        assert_eq!(source.texels(), TexelKind::Height);
        let streamed = bevy::tasks::block_on(source.load(TileKey { z: 3, x: 2, y: 1 }))
            .unwrap()
            .unwrap();
        assert_eq!(streamed.height(5, 7), tile.at(5, 7));
        assert_eq!(streamed.rgba.len(), 32 * 32 * 4);
        let refused = DiskTileSource::open(&dir).unwrap_err().to_string();
        assert!(refused.contains("height16"), "{refused}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn the_height_query_reads_the_ground_back_in_metres() {
        use crate::dem::{DiskHeightSource, HeightQuery, HeightScale};
        let dir = std::env::temp_dir().join(format!("pyramid_query_{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        // A tilted plane over 130 × 100 texels of 2 m, its north-west corner at (1000, 5000).
        let (origin, mpt) = ([1000.0f64, 5000.0f64], 2.0f64);
        let plane = |x: f64, z: f64| 100.0 + 0.3 * (x - origin[0]) - 0.2 * (z - origin[1]);
        let scale = HeightScale::covering(0.0, 200.0);
        let settings = BuildSettings {
            tile_size: 32,
            origin_m: origin,
            metres_per_texel: mpt,
            heights: scale,
            ..Default::default()
        };
        build_height_pyramid(&dir, [130, 100], &settings, plane).unwrap();
        let mut query = HeightQuery::new(DiskHeightSource::open(&dir).unwrap(), 8);
        // Anywhere inside the image (a texel in from its edges), across tile boundaries: the
        // plane, to within the 16-bit step (a plane is exact under bilinear interpolation).
        let mut worst = 0.0f64;
        for k in 0..200 {
            let x = origin[0] + mpt * (1.0 + 127.0 * ((k * 37 % 200) as f64 / 200.0));
            let z = origin[1] + mpt * (1.0 + 97.0 * ((k * 91 % 200) as f64 / 200.0));
            let h = query.height_at(x, z).unwrap().unwrap() as f64;
            worst = worst.max((h - plane(x, z)).abs());
        }
        assert!(worst <= scale.scale_m, "worst {worst} m");
        let n = query.normal_at(1100.0, 5100.0).unwrap().unwrap();
        let len = (0.3f32 * 0.3 + 1.0 + 0.2 * 0.2).sqrt();
        let want = [-0.3 / len, 1.0 / len, 0.2 / len];
        assert!((0..3).all(|c| (n[c] - want[c]).abs() < 0.01), "{n:?}");
        // Outside the pyramid: nothing; nor in the padding that rounds the image's 260 × 200 m
        // up to the pyramid's 512 m square, whose last texel centre of data is a texel in.
        assert_eq!(query.height_at(999.0, 5100.0).unwrap(), None);
        assert_eq!(query.height_at(1100.0, 5000.0 + 512.0 + 1.0).unwrap(), None);
        assert_eq!(query.height_at(1000.0 + 260.5, 5100.0).unwrap(), None);
        assert_eq!(query.height_at(1100.0, 5000.0 + 200.5).unwrap(), None);
        let edge = query
            .height_at(1000.0 + 259.5, 5000.0 + 199.5)
            .unwrap()
            .unwrap() as f64;
        assert!(
            (edge - plane(1259.0, 5199.0)).abs() <= scale.scale_m,
            "{edge}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn an_interrupted_build_resumes_to_the_same_files() {
        let base = std::env::temp_dir().join(format!("pyramid_resume_{}", std::process::id()));
        std::fs::remove_dir_all(&base).ok();
        let (clean, resumed) = (base.join("clean"), base.join("resumed"));
        let image = test_image();
        let settings = BuildSettings {
            tile_size: 64,
            scheme: TileScheme::Tms,
            ..Default::default()
        };
        build_pyramid(&image, &clean, &settings, &|_, _| {}, None).unwrap();
        let stopped = build_pyramid(&image, &resumed, &settings, &|_, _| {}, Some(7));
        assert!(
            matches!(stopped, Err(BuildError::Interrupted(7))),
            "{stopped:?}"
        );
        assert!(
            !resumed.join(MANIFEST).exists(),
            "no manifest before the build completes"
        );
        // A crash mid-write leaves a temporary file; a tile truncated by hand must be rebuilt.
        std::fs::write(resumed.join("2/0/0.tmp"), b"half a tile").unwrap();
        let some_tile = files(&resumed)
            .into_iter()
            .find(|(p, _)| p.extension().is_some_and(|e| e == "png"))
            .unwrap()
            .0;
        std::fs::write(resumed.join(&some_tile), b"\x89PNG trunc").unwrap();
        let report = build_pyramid(&image, &resumed, &settings, &|_, _| {}, None).unwrap();
        assert_eq!(report.reused, 6, "{report:?}");
        assert_eq!(report.written, 15);
        let clean_files = files(&clean);
        let resumed_files: Vec<_> = files(&resumed)
            .into_iter()
            .filter(|(p, _)| p.extension().is_none_or(|e| e != "tmp"))
            .collect();
        assert_eq!(clean_files, resumed_files);
        // Even in a finished pyramid, a damaged tile under intact parents is found and rebuilt.
        std::fs::write(resumed.join("2/3/1.png"), b"garbage").unwrap();
        let again = build_pyramid(&image, &resumed, &settings, &|_, _| {}, None).unwrap();
        assert_eq!((again.written, again.reused), (1, 20));
        assert_eq!(files(&clean), files(&resumed));
        std::fs::remove_dir_all(&base).ok();
    }
}
