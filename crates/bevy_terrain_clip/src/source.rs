//! Where tiles come from: the [`TileSource`] trait, asynchronous so loads run on
//! Bevy's IO task pool; a [`DiskTileSource`] over an XYZ/TMS pyramid directory; and a
//! [`ProceduralTileSource`] computing texels from a function (tests, and flights over data too
//! large to store).
//!
//! A load gives `Ok(Some(tile))`, `Ok(None)` when the tile does not exist (outside a partial
//! level, or no file: remembered as absent by the cache), or an error naming the file (corrupt
//! image, wrong size) — never a panic.

use crate::cache::TileKey;
use crate::pyramid::{ManifestError, PyramidManifest};
use bevy::tasks::BoxedFuture;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A decoded tile: `size × size` texels of four bytes, rows top (north) first — RGBA8 for
/// imagery, a little-endian `f32` height in metres for heights ([`TileSource::texels`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileData {
    /// Side in texels.
    pub size: u32,
    /// `size² · 4` bytes.
    pub rgba: Vec<u8>,
}

/// What a source's texels are: what the clip stack's texture holds and how its mips are made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TexelKind {
    /// RGBA8 imagery (sRGB).
    #[default]
    Color,
    /// Heights in metres, one little-endian `f32` a texel.
    Height,
}

impl TexelKind {
    /// For messages.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Color => "imagery (RGBA8)",
            Self::Height => "heights (f32 metres)",
        }
    }

    /// The GPU format of a clip stack of these texels.
    pub fn texture_format(self) -> bevy::render::render_resource::TextureFormat {
        match self {
            Self::Color => bevy::render::render_resource::TextureFormat::Rgba8UnormSrgb,
            Self::Height => bevy::render::render_resource::TextureFormat::R32Float,
        }
    }

    /// The 2×2 box filter of a `side × side` square of these texels: rounded means of each
    /// byte for imagery, means of the heights for heights (paper 4, §3 "Texture pyramid": each
    /// level interpolates the four texels of the finer one).
    pub fn halve(self, texels: &[u8], side: u32) -> Vec<u8> {
        match self {
            Self::Color => halve_rgba8(texels, side),
            Self::Height => {
                let h = (side / 2).max(1);
                let at = |x: u32, y: u32| {
                    let i = ((y.min(side - 1) * side + x.min(side - 1)) * 4) as usize;
                    f32::from_le_bytes([texels[i], texels[i + 1], texels[i + 2], texels[i + 3]])
                };
                let mut out = Vec::with_capacity((h * h * 4) as usize);
                for y in 0..h {
                    for x in 0..h {
                        let sum = at(2 * x, 2 * y)
                            + at(2 * x + 1, 2 * y)
                            + at(2 * x, 2 * y + 1)
                            + at(2 * x + 1, 2 * y + 1);
                        out.extend_from_slice(&(0.25 * sum).to_le_bytes());
                    }
                }
                out
            }
        }
    }
}

/// The 2×2 box filter of a `side × side` RGBA8 square (rounded means of the stored bytes).
pub fn halve_rgba8(texels: &[u8], side: u32) -> Vec<u8> {
    let h = (side / 2).max(1);
    let mut out = vec![0u8; (h * h * 4) as usize];
    for y in 0..h {
        for x in 0..h {
            for c in 0..4 {
                let at = |dx: u32, dy: u32| {
                    texels[(((2 * y + dy).min(side - 1) * side + (2 * x + dx).min(side - 1)) * 4
                        + c) as usize] as u32
                };
                out[((y * h + x) * 4 + c) as usize] =
                    ((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1) + 2) / 4) as u8;
            }
        }
    }
    out
}

impl TileData {
    /// Checks that tile `key` is `tile_size` square and holds its `tile_size² · 4` bytes: a
    /// custom [`TileSource`] may return anything, and a wrong size would be sliced out of
    /// bounds when subtiles are cut from it.
    pub fn check(&self, key: TileKey, tile_size: u32) -> Result<(), TileError> {
        let bytes = tile_size as usize * tile_size as usize * 4;
        if self.size == tile_size && self.rgba.len() == bytes {
            return Ok(());
        }
        let side = ((self.rgba.len() / 4) as f64).sqrt() as u32;
        Err(TileError::WrongSize {
            path: PathBuf::from(format!("tile {}/{}/{} of the source", key.z, key.x, key.y)),
            found: if self.rgba.len() == (self.size * self.size * 4) as usize {
                [self.size, self.size]
            } else {
                [side, side]
            },
            expected: tile_size,
        })
    }

    /// The height (m) at column `x`, row `y` of a height tile.
    pub fn height(&self, x: u32, y: u32) -> f32 {
        f32::from_le_bytes(self.texel(x, y))
    }

    /// The texel at column `x`, row `y`.
    pub fn texel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = ((y * self.size + x) * 4) as usize;
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }
}

/// Why a tile could not be loaded.
#[derive(Debug)]
pub enum TileError {
    /// The file exists but could not be read.
    Io(PathBuf, std::io::Error),
    /// The file is not a decodable image.
    Decode(PathBuf, String),
    /// The image's pixels are not what the manifest says (an RGB tile in a 16-bit height
    /// pyramid, imagery read as heights).
    WrongKind {
        /// The file.
        path: PathBuf,
        /// What the manifest says.
        expected: String,
        /// What the image holds.
        found: String,
    },
    /// The image is not `tile_size` square.
    WrongSize {
        /// The file.
        path: PathBuf,
        /// Its size.
        found: [u32; 2],
        /// The manifest's tile size.
        expected: u32,
    },
    /// The source did not answer within the cache's
    /// [`load_timeout`](crate::tile_cache::TileCache::load_timeout).
    TimedOut {
        /// The tile.
        key: TileKey,
        /// How long it was waited for.
        after: std::time::Duration,
    },
}

impl std::fmt::Display for TileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Io(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Decode(p, e) => write!(f, "{}: corrupt tile image: {e}", p.display()),
            Self::WrongKind {
                path,
                expected,
                found,
            } => write!(
                f,
                "{}: the tile's pixels are {found}, the manifest says {expected} (not converted)",
                path.display()
            ),
            Self::WrongSize {
                path,
                found,
                expected,
            } => write!(
                f,
                "{}: tile is {}×{}, the manifest says {expected}×{expected}",
                path.display(),
                found[0],
                found[1]
            ),
            Self::TimedOut { key, after } => write!(
                f,
                "tile {}/{}/{}: the source did not answer within {after:?}",
                key.z, key.x, key.y
            ),
        }
    }
}

impl std::error::Error for TileError {}

/// A source of tiles.
pub trait TileSource: Send + Sync + 'static {
    /// Tile side in texels.
    fn tile_size(&self) -> u32;
    /// Pyramid levels (`0..levels`).
    fn levels(&self) -> u32;
    /// Whether `key` can exist at all (cheap, no I/O).
    fn may_exist(&self, key: TileKey) -> bool;
    /// Loads a tile.
    fn load(&self, key: TileKey) -> BoxedFuture<'static, Result<Option<TileData>, TileError>>;
    /// What its texels are (imagery unless it says otherwise).
    fn texels(&self) -> TexelKind {
        TexelKind::Color
    }
}

/// Tiles read from an XYZ/TMS directory with a `pyramid.json` manifest.
#[derive(Clone, Debug)]
pub struct DiskTileSource {
    /// The pyramid directory.
    pub dir: PathBuf,
    /// Its manifest.
    pub manifest: Arc<PyramidManifest>,
}

impl DiskTileSource {
    /// Opens an imagery pyramid directory (reads and checks its manifest). A pyramid of heights
    /// is an error: streamed as imagery its heights would show as colours
    /// ([`DiskHeightSource`](crate::dem::DiskHeightSource) reads them).
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, ManifestError> {
        let dir = dir.as_ref().to_path_buf();
        let manifest = PyramidManifest::load(&dir)?;
        if manifest.texel.is_height() {
            return Err(ManifestError::Invalid(
                dir.join(crate::pyramid::MANIFEST),
                format!(
                    "the pyramid holds {}, not imagery: open it as heights (dem::DiskHeightSource)",
                    manifest.texel.describe()
                ),
            ));
        }
        Ok(Self {
            dir,
            manifest: Arc::new(manifest),
        })
    }
}

/// Decodes an image file's bytes (PNG, JPEG or WebP, recognised by content) that must be
/// `tile_size`² texels: the size is read from the header and checked before any pixel is
/// decoded, so a corrupt header claiming gigapixels is refused without allocating them.
pub fn decode_tile_image(
    bytes: &[u8],
    path: &Path,
    tile_size: u32,
) -> Result<image::DynamicImage, TileError> {
    let decode_error = |e: image::ImageError| TileError::Decode(path.to_path_buf(), e.to_string());
    let (width, height) = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| TileError::Decode(path.to_path_buf(), e.to_string()))?
        .into_dimensions()
        .map_err(decode_error)?;
    if width != tile_size || height != tile_size {
        return Err(TileError::WrongSize {
            path: path.to_path_buf(),
            found: [width, height],
            expected: tile_size,
        });
    }
    let image = image::load_from_memory(bytes).map_err(decode_error)?;
    if image.width() != tile_size || image.height() != tile_size {
        return Err(TileError::WrongSize {
            path: path.to_path_buf(),
            found: [image.width(), image.height()],
            expected: tile_size,
        });
    }
    Ok(image)
}

/// Decodes tile bytes (PNG, JPEG or WebP, recognised by content) into RGBA8, checking the size.
pub fn decode_tile(bytes: &[u8], path: &Path, tile_size: u32) -> Result<TileData, TileError> {
    let image = decode_tile_image(bytes, path, tile_size)?.to_rgba8();
    Ok(TileData {
        size: tile_size,
        rgba: image.into_raw(),
    })
}

impl TileSource for DiskTileSource {
    fn tile_size(&self) -> u32 {
        self.manifest.tile_size
    }

    fn levels(&self) -> u32 {
        self.manifest.levels
    }

    fn may_exist(&self, key: TileKey) -> bool {
        self.manifest.may_exist(key)
    }

    fn load(&self, key: TileKey) -> BoxedFuture<'static, Result<Option<TileData>, TileError>> {
        let manifest = self.manifest.clone();
        let path = manifest.tile_path(&self.dir, key);
        Box::pin(async move {
            if !manifest.may_exist(key) {
                return Ok(None);
            }
            let bytes = match std::fs::read(&path) {
                Ok(b) => b,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
                Err(e) => return Err(TileError::Io(path, e)),
            };
            decode_tile(&bytes, &path, manifest.tile_size).map(Some)
        })
    }
}

/// The texel function of a procedural source: `(virtual level, texel x, texel y) → RGBA8`.
pub type TexelFn = dyn Fn(u32, u64, u64) -> [u8; 4] + Send + Sync;

/// Tiles computed from a texel function of the virtual level and texel coordinates.
#[derive(Clone)]
pub struct ProceduralTileSource {
    /// Tile side.
    pub tile_size: u32,
    /// Pyramid levels.
    pub levels: u32,
    /// The texels.
    pub texel: Arc<TexelFn>,
    /// What they are.
    pub kind: TexelKind,
}

impl std::fmt::Debug for ProceduralTileSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ProceduralTileSource")
            .field("tile_size", &self.tile_size)
            .field("levels", &self.levels)
            .field("kind", &self.kind)
            .finish()
    }
}

/// A texel function that says where it was sampled: red and green are the texel's x and y
/// modulo 256, blue is 16 × the virtual level plus bits 8–11 of x — so a test reading one texel
/// back knows which level and position it came from.
pub fn address_texel(level: u32, x: u64, y: u64) -> [u8; 4] {
    [
        (x & 255) as u8,
        (y & 255) as u8,
        ((level & 15) * 16 + ((x >> 8) & 15) as u32) as u8,
        255,
    ]
}

/// Procedural aerial imagery: fields, forest and water from value-noise octaves, each level
/// carrying only the octaves its texels resolve (wavelength ≥ 2 texels), plus a faint 1 km grid
/// (`texture_m` = world size of the whole texture) so motion and scale read well.
/// Hash of a lattice point and octave to [0, 1).
fn hash(ix: i64, iy: i64, octave: u32) -> f64 {
    let mut h = (ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (iy as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (octave as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 29;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 32;
    (h >> 11) as f64 / (1u64 << 53) as f64
}
/// Value noise (smoothstep between lattice hashes) at (u, v) of one octave.
fn value_noise(u: f64, v: f64, octave: u32) -> f64 {
    let (x0, y0) = (u.floor(), v.floor());
    let (fx, fy) = (u - x0, v - y0);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let (ix, iy) = (x0 as i64, y0 as i64);
    let a = hash(ix, iy, octave) + sx * (hash(ix + 1, iy, octave) - hash(ix, iy, octave));
    let b =
        hash(ix, iy + 1, octave) + sx * (hash(ix + 1, iy + 1, octave) - hash(ix, iy + 1, octave));
    a + sy * (b - a)
}

pub fn imagery_texel(level: u32, x: u64, y: u64, texture_m: f64) -> [u8; 4] {
    let texels = (1u64 << level) as f64;
    let (u, v) = ((x as f64 + 0.5) / texels, (y as f64 + 0.5) / texels);
    let (mut value, mut amplitude, mut total) = (0.0, 1.0, 0.0);
    let mut detail = 0.0;
    for octave in 0..20u32 {
        let frequency = 128.0 * 2f64.powi(octave as i32);
        if frequency * 2.0 > texels {
            break;
        }
        let n = value_noise(u * frequency, v * frequency, octave);
        if octave < 5 {
            value += n * amplitude;
            total += amplitude;
        } else {
            detail += (n - 0.5) * amplitude;
        }
        amplitude *= 0.55;
    }
    let h = if total > 0.0 { value / total } else { 0.5 };
    let d = detail * 0.6;
    let (r, g, b) = if h < 0.38 {
        (0.16, 0.32 + d * 0.2, 0.45 + d * 0.2)
    } else if h < 0.55 {
        (0.42 + d, 0.52 + d, 0.25 + d * 0.5)
    } else if h < 0.7 {
        (0.2 + d * 0.5, 0.36 + d, 0.16 + d * 0.5)
    } else {
        (0.55 + d, 0.5 + d, 0.4 + d)
    };
    // A faint grid line every kilometre, where texels are fine enough to show it.
    let metres_per_texel = texture_m / texels;
    let on_grid = |t: f64| {
        let m = t * texture_m;
        metres_per_texel <= 20.0 && (m.rem_euclid(1000.0)) < metres_per_texel.max(1.5)
    };
    let grid = if on_grid(u) || on_grid(v) { 0.12 } else { 0.0 };
    let q = |c: f64| ((c + grid).clamp(0.0, 1.0) * 255.0).round() as u8;
    [q(r), q(g), q(b), 255]
}

/// Procedural relief (m) at a level texel, to go with [`imagery_texel`]: rolling hills and
/// ridges up to about 700 m from value-noise octaves of wavelengths from `texture_m / 32` down,
/// each level carrying only the octaves its texels resolve (wavelength ≥ 2 texels), so coarser
/// levels are the finer ones without their detail — a pyramid's mips.
pub fn relief_texel(level: u32, x: u64, y: u64, texture_m: f64) -> f32 {
    let texels = (1u64 << level) as f64;
    let (u, v) = ((x as f64 + 0.5) / texels, (y as f64 + 0.5) / texels);
    let (mut height, mut amplitude) = (0.0, 420.0);
    for octave in 0..22u32 {
        let frequency = 32.0 * 2f64.powi(octave as i32);
        if frequency * 2.0 > texels || texture_m / frequency < 4.0 {
            break;
        }
        // Ridged octaves above the first two: sharp crests, rounded valleys.
        let n = value_noise(u * frequency, v * frequency, octave + 40);
        let shaped = if octave < 2 {
            n
        } else {
            1.0 - (2.0 * n - 1.0).abs()
        };
        height += (shaped - 0.5) * amplitude;
        amplitude *= 0.48;
    }
    height as f32
}

impl ProceduralTileSource {
    /// A source of `levels` levels of `tile_size` tiles whose texels come from `texel`.
    pub fn new(
        tile_size: u32,
        levels: u32,
        texel: impl Fn(u32, u64, u64) -> [u8; 4] + Send + Sync + 'static,
    ) -> Self {
        Self {
            tile_size,
            levels,
            texel: Arc::new(texel),
            kind: TexelKind::Color,
        }
    }

    /// A source of heights (m) from `height(virtual level, texel x, texel y)`.
    pub fn heights(
        tile_size: u32,
        levels: u32,
        height: impl Fn(u32, u64, u64) -> f32 + Send + Sync + 'static,
    ) -> Self {
        Self {
            tile_size,
            levels,
            texel: Arc::new(move |l, x, y| height(l, x, y).to_le_bytes()),
            kind: TexelKind::Height,
        }
    }

    /// The tile `key`, computed now.
    pub fn tile(&self, key: TileKey) -> TileData {
        let t = self.tile_size;
        let level = key.z + t.trailing_zeros();
        let mut rgba = Vec::with_capacity((t * t * 4) as usize);
        for row in 0..t as u64 {
            for col in 0..t as u64 {
                let x = key.x as u64 * t as u64 + col;
                let y = key.y as u64 * t as u64 + row;
                rgba.extend_from_slice(&(self.texel)(level, x, y));
            }
        }
        TileData { size: t, rgba }
    }
}

impl TileSource for ProceduralTileSource {
    fn tile_size(&self) -> u32 {
        self.tile_size
    }

    fn levels(&self) -> u32 {
        self.levels
    }

    fn may_exist(&self, key: TileKey) -> bool {
        key.z < self.levels && (key.x as u64) < (1u64 << key.z) && (key.y as u64) < (1u64 << key.z)
    }

    fn load(&self, key: TileKey) -> BoxedFuture<'static, Result<Option<TileData>, TileError>> {
        let source = self.clone();
        Box::pin(async move { Ok(source.may_exist(key).then(|| source.tile(key))) })
    }

    fn texels(&self) -> TexelKind {
        self.kind
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pyramid::{MANIFEST, TileScheme};

    fn write_png(path: &Path, size: u32, fill: [u8; 4]) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let data: Vec<u8> = (0..size * size).flat_map(|_| fill).collect();
        image::RgbaImage::from_raw(size, size, data)
            .unwrap()
            .save_with_format(path, image::ImageFormat::Png)
            .unwrap();
    }

    #[test]
    fn heights_are_halved_as_metres_and_imagery_as_bytes() {
        let heights: Vec<u8> = [1.5f32, -2.0, 100.25, 0.25]
            .iter()
            .flat_map(|h| h.to_le_bytes())
            .collect();
        let half = TexelKind::Height.halve(&heights, 2);
        assert_eq!(f32::from_le_bytes(half[..4].try_into().unwrap()), 25.0);
        // The same bytes halved as RGBA8 are per-byte means: not the mean height.
        assert_ne!(TexelKind::Color.halve(&heights, 2), half);
        let source =
            ProceduralTileSource::heights(8, 2, |l, x, y| l as f32 + x as f32 * 0.5 - y as f32);
        assert_eq!(source.texels(), TexelKind::Height);
        let tile = source.tile(TileKey { z: 1, x: 1, y: 0 });
        assert_eq!(tile.height(3, 2), 4.0 + 11.0 * 0.5 - 2.0);
        assert_eq!(
            ProceduralTileSource::new(8, 2, address_texel).texels(),
            TexelKind::Color
        );
    }

    #[test]
    fn disk_tiles_load_and_bad_ones_are_clear_errors() {
        let dir = std::env::temp_dir().join(format!("terrain_source_{}", std::process::id()));
        let manifest = PyramidManifest {
            version: 1,
            scheme: TileScheme::Tms,
            extension: "png".into(),
            tile_size: 32,
            levels: 3,
            origin_m: [0.0, 0.0],
            metres_per_texel: 1.0,
            partial_levels: Vec::new(),
            texel: Default::default(),
            height_offset_m: 0.0,
            height_scale_m: 1.0,
            extent_texels: None,
        };
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join(MANIFEST),
            serde_json::to_string(&manifest).unwrap(),
        )
        .unwrap();
        let source = DiskTileSource::open(&dir).unwrap();
        // XYZ row 0 of level 1 is TMS row 1.
        write_png(&dir.join("1/0/1.png"), 32, [10, 20, 30, 255]);
        let key = TileKey { z: 1, x: 0, y: 0 };
        let tile = bevy::tasks::block_on(source.load(key)).unwrap().unwrap();
        assert_eq!(tile.texel(5, 7), [10, 20, 30, 255]);
        // Missing file: absent, not an error.
        let missing = TileKey { z: 1, x: 1, y: 1 };
        assert!(
            bevy::tasks::block_on(source.load(missing))
                .unwrap()
                .is_none()
        );
        // Corrupt image and wrong size: errors naming the file.
        std::fs::create_dir_all(dir.join("2/0")).unwrap();
        std::fs::write(dir.join("2/0/3.png"), b"\x89PNG not really").unwrap();
        let e = bevy::tasks::block_on(source.load(TileKey { z: 2, x: 0, y: 0 })).unwrap_err();
        assert!(
            e.to_string().contains("2/0/3.png") && e.to_string().contains("corrupt"),
            "{e}"
        );
        write_png(&dir.join("2/1/3.png"), 16, [0; 4]);
        let e = bevy::tasks::block_on(source.load(TileKey { z: 2, x: 1, y: 0 })).unwrap_err();
        assert!(
            matches!(
                e,
                TileError::WrongSize {
                    found: [16, 16],
                    ..
                }
            ),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn imagery_is_continuous_across_levels() {
        // The same world point at two levels: coarse octaves agree, so colours are close.
        let fine = imagery_texel(12, 2048 * 2 + 1, 1000 * 2 + 1, 8000.0);
        let coarse = imagery_texel(11, 2048, 1000, 8000.0);
        let diff: i32 = (0..3)
            .map(|c| (fine[c] as i32 - coarse[c] as i32).abs())
            .max()
            .unwrap();
        assert!(diff < 60, "{fine:?} vs {coarse:?}");
        assert_eq!(fine[3], 255);
    }

    #[test]
    fn jpeg_and_webp_tiles_decode() {
        let size = 16;
        let image = image::RgbaImage::from_fn(size, size, |x, y| {
            image::Rgba([(x * 16) as u8, (y * 16) as u8, 128, 255])
        });
        let rgb = image::DynamicImage::ImageRgba8(image.clone()).to_rgb8();
        let mut jpeg = Vec::new();
        rgb.write_to(
            &mut std::io::Cursor::new(&mut jpeg),
            image::ImageFormat::Jpeg,
        )
        .unwrap();
        let mut webp = Vec::new();
        image
            .write_to(
                &mut std::io::Cursor::new(&mut webp),
                image::ImageFormat::WebP,
            )
            .unwrap();
        let path = Path::new("t");
        // JPEG is lossy: within a few levels; WebP (lossless here) exact.
        let j = decode_tile(&jpeg, path, size).unwrap();
        assert!(
            j.rgba
                .iter()
                .zip(image.as_raw())
                .all(|(a, b)| (*a as i32 - *b as i32).abs() <= 12)
        );
        assert_eq!(
            decode_tile(&webp, path, size).unwrap().rgba,
            *image.as_raw()
        );
    }

    #[test]
    fn procedural_tiles_encode_their_address() {
        let source = ProceduralTileSource::new(64, 8, address_texel);
        let tile = bevy::tasks::block_on(source.load(TileKey { z: 3, x: 5, y: 2 }))
            .unwrap()
            .unwrap();
        // Virtual level 3 + 6 = 9; texel (5·64 + 1, 2·64 + 3) = (321, 131).
        assert_eq!(tile.texel(1, 3), [(321 & 255) as u8, 131, 9 * 16 + 1, 255]);
        assert!(
            bevy::tasks::block_on(source.load(TileKey { z: 8, x: 0, y: 0 }))
                .unwrap()
                .is_none()
        );
    }
}
