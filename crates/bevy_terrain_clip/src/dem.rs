//! Elevation tiles: heights in metres from the encodings real DEM pyramids use.
//!
//! - `height16`: 16-bit grayscale PNG, `h = offset + scale · v` with the manifest's
//!   `height_offset_m` and `height_scale_m` (what `pyramid_build` writes);
//! - `terrarium` (Mapzen / AWS terrain tiles): 8-bit RGB, `h = R·256 + G + B/256 − 32768`;
//! - `mapbox` (Mapbox Terrain-RGB, MapTiler): 8-bit RGB, `h = −10000 + (R·65536 + G·256 + B)·0.1`.
//!
//! A tile whose pixels are not what its manifest says — an RGB tile in a `height16` pyramid, an
//! 8-bit grayscale tile in a `terrarium` one, any tile of an imagery pyramid read as heights — is
//! an error naming the file and both kinds, never a silent conversion (turning a terrarium tile
//! into luminance gives heights that are meaningless yet look plausible).

use crate::cache::TileKey;
use crate::pyramid::{ManifestError, PyramidManifest, TexelFormat};
use crate::source::TileError;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Height of a Terrarium texel (m).
pub fn terrarium_height([r, g, b]: [u8; 3]) -> f32 {
    r as f32 * 256.0 + g as f32 + b as f32 / 256.0 - 32768.0
}

/// Height of a Mapbox Terrain-RGB texel (m).
pub fn mapbox_height([r, g, b]: [u8; 3]) -> f32 {
    // The 24-bit integer is exact in f64; 0.1 m steps from −10 km.
    (-10000.0 + (r as f64 * 65536.0 + g as f64 * 256.0 + b as f64) * 0.1) as f32
}

/// The Terrarium texel of height `h` (m), as the tile servers encode it (to 1/256 m).
pub fn terrarium_texel(h: f32) -> [u8; 3] {
    let v = h + 32768.0;
    let r = (v / 256.0).floor();
    let g = (v - r * 256.0).floor();
    let b = ((v - r * 256.0 - g) * 256.0).round();
    [r as u8, g as u8, b as u8]
}

/// The Mapbox Terrain-RGB texel of height `h` (m), to 0.1 m.
pub fn mapbox_texel(h: f32) -> [u8; 3] {
    let v = ((h as f64 + 10000.0) * 10.0)
        .round()
        .clamp(0.0, 16_777_215.0) as u32;
    [(v >> 16) as u8, (v >> 8) as u8, v as u8]
}

/// The linear map from stored 16-bit values to metres of a `height16` pyramid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeightScale {
    /// Height of value 0 (m).
    pub offset_m: f64,
    /// Metres per unit.
    pub scale_m: f64,
}

impl Default for HeightScale {
    fn default() -> Self {
        Self {
            offset_m: 0.0,
            scale_m: 1.0,
        }
    }
}

impl HeightScale {
    /// The finest scale (at least 1 cm per unit) covering `[min, max]` metres in 16 bits, offset
    /// at `min` rounded down to the centimetre.
    pub fn covering(min: f32, max: f32) -> Self {
        let offset_m = (min as f64 * 100.0).floor() / 100.0;
        let range = (max as f64 - offset_m).max(0.0);
        Self {
            offset_m,
            scale_m: (range / 65535.0).max(0.01),
        }
    }

    /// Metres of a stored value.
    pub fn metres(&self, value: u16) -> f32 {
        (self.offset_m + self.scale_m * value as f64) as f32
    }

    /// The stored value nearest `metres` (clamped to 16 bits).
    pub fn value(&self, metres: f32) -> u16 {
        ((metres as f64 - self.offset_m) / self.scale_m)
            .round()
            .clamp(0.0, 65535.0) as u16
    }
}

/// One tile of heights, rows top (north) first.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightTile {
    /// Side in texels.
    pub size: u32,
    /// `size²` heights (m).
    pub metres: Vec<f32>,
}

impl HeightTile {
    /// The height at column `x`, row `y`.
    pub fn at(&self, x: u32, y: u32) -> f32 {
        self.metres[(y * self.size + x) as usize]
    }
}

/// What the pixels of a decoded image are, in words (for errors).
fn describe(image: &image::DynamicImage) -> String {
    format!("{:?}", image.color()).to_lowercase()
}

/// Decodes an elevation tile of a pyramid whose texels are `texel` into metres, checking its
/// size and that its pixels are that encoding.
pub fn decode_height_tile(
    bytes: &[u8],
    path: &Path,
    tile_size: u32,
    texel: TexelFormat,
    scale: HeightScale,
) -> Result<HeightTile, TileError> {
    let image = crate::source::decode_tile_image(bytes, path, tile_size)?;
    let wrong_kind = |image: &image::DynamicImage| TileError::WrongKind {
        path: path.to_path_buf(),
        expected: texel.describe(),
        found: describe(image),
    };
    let rgb = |decode: fn([u8; 3]) -> f32, image: &image::DynamicImage| {
        let metres: Vec<f32> = match image {
            image::DynamicImage::ImageRgb8(tile) => {
                tile.pixels().map(|p| decode([p[0], p[1], p[2]])).collect()
            }
            image::DynamicImage::ImageRgba8(tile) => {
                tile.pixels().map(|p| decode([p[0], p[1], p[2]])).collect()
            }
            other => return Err(wrong_kind(other)),
        };
        Ok(metres)
    };
    let metres = match texel {
        TexelFormat::Height16 => match &image {
            image::DynamicImage::ImageLuma16(tile) => {
                tile.pixels().map(|p| scale.metres(p[0])).collect()
            }
            other => return Err(wrong_kind(other)),
        },
        TexelFormat::Terrarium => rgb(terrarium_height, &image)?,
        TexelFormat::Mapbox => rgb(mapbox_height, &image)?,
        TexelFormat::Rgba8 => return Err(wrong_kind(&image)),
    };
    Ok(HeightTile {
        size: tile_size,
        metres,
    })
}

/// The heights of a manifest's pyramid: its 16-bit scale, or an error when it holds imagery.
pub fn height_scale_of(manifest: &PyramidManifest) -> Result<HeightScale, String> {
    if !manifest.texel.is_height() {
        return Err(format!(
            "the pyramid holds {}, not heights",
            manifest.texel.describe()
        ));
    }
    Ok(HeightScale {
        offset_m: manifest.height_offset_m,
        scale_m: manifest.height_scale_m,
    })
}

/// Heights read from an XYZ/TMS directory of elevation tiles (`height16`, `terrarium` or
/// `mapbox`, per its manifest), in metres ([`crate::dem`]).
#[derive(Clone, Debug)]
pub struct DiskHeightSource {
    /// The pyramid directory.
    pub dir: PathBuf,
    /// Its manifest.
    pub manifest: Arc<PyramidManifest>,
    scale: HeightScale,
}

impl DiskHeightSource {
    /// Opens an elevation pyramid directory. An imagery pyramid is an error.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, ManifestError> {
        let dir = dir.as_ref().to_path_buf();
        let manifest = PyramidManifest::load(&dir)?;
        let scale = height_scale_of(&manifest)
            .map_err(|e| ManifestError::Invalid(dir.join(crate::pyramid::MANIFEST), e))?;
        Ok(Self {
            dir,
            manifest: Arc::new(manifest),
            scale,
        })
    }

    /// The heights of tile `key`: `Ok(None)` when it does not exist, an error naming the file
    /// when it is corrupt, wrongly sized or not the manifest's encoding.
    pub fn load_heights(&self, key: TileKey) -> Result<Option<HeightTile>, TileError> {
        if !self.manifest.may_exist(key) {
            return Ok(None);
        }
        let path = self.manifest.tile_path(&self.dir, key);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(TileError::Io(path, e)),
        };
        decode_height_tile(
            &bytes,
            &path,
            self.manifest.tile_size,
            self.manifest.texel,
            self.scale,
        )
        .map(Some)
    }
}

impl HeightTile {
    /// As a [`TileData`](crate::source::TileData) of `f32` texels, for a height clip stack.
    pub fn into_tile_data(self) -> crate::source::TileData {
        crate::source::TileData {
            size: self.size,
            rgba: self.metres.iter().flat_map(|h| h.to_le_bytes()).collect(),
        }
    }
}

/// A height pyramid streams into a height clip stack
/// ([`ClipStackTexture::heights`](crate::stack_gpu::ClipStackTexture::heights)): its tiles
/// decoded to `f32` metres.
impl crate::source::TileSource for DiskHeightSource {
    fn tile_size(&self) -> u32 {
        self.manifest.tile_size
    }

    fn levels(&self) -> u32 {
        self.manifest.levels
    }

    fn may_exist(&self, key: TileKey) -> bool {
        self.manifest.may_exist(key)
    }

    fn load(
        &self,
        key: TileKey,
    ) -> bevy::tasks::BoxedFuture<'static, Result<Option<crate::source::TileData>, TileError>> {
        let source = self.clone();
        Box::pin(async move { Ok(source.load_heights(key)?.map(HeightTile::into_tile_data)) })
    }

    fn texels(&self) -> crate::source::TexelKind {
        crate::source::TexelKind::Height
    }
}

/// Heights of the ground for gameplay: `height_at(x, z)` in metres at any world point over an
/// elevation pyramid, bilinear between texel centres of its finest level (the surface the
/// heights describe), and the surface normal. Decoded tiles stay in an LRU of `capacity` tiles;
/// a tile not yet in it is read from disk on the calling thread, so the first query of a new
/// area costs a file read (a few milliseconds for a 256² PNG).
pub struct HeightQuery {
    source: DiskHeightSource,
    tiles: crate::cache::LruCache<Option<Arc<HeightTile>>>,
}

impl HeightQuery {
    /// A query over `source` keeping up to `capacity` decoded tiles.
    pub fn new(source: DiskHeightSource, capacity: usize) -> Self {
        Self {
            source,
            tiles: crate::cache::LruCache::new(capacity.max(4)),
        }
    }

    /// The finest level's texel `(i, j)` (north-west origin), `None` outside the data or where
    /// its tile is absent.
    fn texel(&mut self, i: i64, j: i64) -> Result<Option<f32>, TileError> {
        let manifest = &self.source.manifest;
        let side = (manifest.tile_size as i64) << (manifest.levels - 1);
        if i < 0 || j < 0 || i >= side || j >= side {
            return Ok(None);
        }
        let t = manifest.tile_size as i64;
        let key = TileKey {
            z: manifest.levels - 1,
            x: (i / t) as u32,
            y: (j / t) as u32,
        };
        if self.tiles.get(&key).is_none() {
            let tile = self.source.load_heights(key)?.map(Arc::new);
            self.tiles.insert(key, tile);
        }
        Ok(self
            .tiles
            .get(&key)
            .and_then(|tile| tile.as_ref())
            .map(|tile| tile.at((i % t) as u32, (j % t) as u32)))
    }

    /// The ground's height (m) at world `(x, z)`: bilinear between the four nearest texel
    /// centres of the finest level (clamped to the data at its edges); `None` outside the data
    /// (the source image's extent, where the manifest records it — not the padding that rounds
    /// the pyramid up to a power of two) and where a finest-level tile is absent (outside a partial level's inset) — coarser
    /// levels are not consulted yet.
    pub fn height_at(&mut self, x: f64, z: f64) -> Result<Option<f32>, TileError> {
        let manifest = self.source.manifest.clone();
        let fx = (x - manifest.origin_m[0]) / manifest.metres_per_texel - 0.5;
        let fz = (z - manifest.origin_m[1]) / manifest.metres_per_texel - 0.5;
        // The data: the source image's extent where the manifest records it (beyond, the
        // pyramid's square is padding), else the whole finest level.
        let side = (manifest.tile_size as i64) << (manifest.levels - 1);
        let [w, h] = manifest
            .extent_texels
            .map_or([side, side], |[w, h]| [w as i64, h as i64]);
        let (wf, hf) = (w as f64, h as f64);
        if !(fx >= -0.5 && fz >= -0.5 && fx < wf - 0.5 && fz < hf - 0.5) {
            return Ok(None);
        }
        let (fx, fz) = (fx.clamp(0.0, wf - 1.0), fz.clamp(0.0, hf - 1.0));
        let (i, j) = (fx.floor() as i64, fz.floor() as i64);
        let (tx, tz) = ((fx - i as f64) as f32, (fz - j as f64) as f32);
        let mut corner = |di: i64, dj: i64| -> Result<Option<f32>, TileError> {
            let (ci, cj) = ((i + di).min(w - 1), (j + dj).min(h - 1));
            self.texel(ci, cj)
        };
        let (Some(h00), Some(h10), Some(h01), Some(h11)) =
            (corner(0, 0)?, corner(1, 0)?, corner(0, 1)?, corner(1, 1)?)
        else {
            return Ok(None);
        };
        let top = h00 + (h10 - h00) * tx;
        let bottom = h01 + (h11 - h01) * tx;
        Ok(Some(top + (bottom - top) * tz))
    }

    /// The ground's unit normal (y up) at `(x, z)`, from central differences one texel apart;
    /// `None` outside the data.
    pub fn normal_at(&mut self, x: f64, z: f64) -> Result<Option<[f32; 3]>, TileError> {
        let d = self.source.manifest.metres_per_texel;
        let (Some(west), Some(east), Some(north), Some(south)) = (
            self.height_at(x - d, z)?,
            self.height_at(x + d, z)?,
            self.height_at(x, z - d)?,
            self.height_at(x, z + d)?,
        ) else {
            return Ok(None);
        };
        let (dx, dz) = (
            (east - west) / (2.0 * d as f32),
            (south - north) / (2.0 * d as f32),
        );
        let n = [-dx, 1.0, -dz];
        let len = (n[0] * n[0] + 1.0 + n[2] * n[2]).sqrt();
        Ok(Some([n[0] / len, n[1] / len, n[2] / len]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png(image: image::DynamicImage) -> Vec<u8> {
        let mut bytes = Vec::new();
        image
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .unwrap();
        bytes
    }

    #[test]
    fn the_published_formulas_give_known_heights() {
        // Terrarium: sea level is (128, 0, 0); Mont Blanc's 4808 m is 128 + 18.78 · 256.
        assert_eq!(terrarium_height([128, 0, 0]), 0.0);
        assert_eq!(terrarium_height([146, 200, 128]), 4808.5);
        assert_eq!(terrarium_height([127, 255, 0]), -1.0);
        // Mapbox: (1, 134, 160) is 0 m; 0.1 m steps.
        assert!(mapbox_height([1, 134, 160]).abs() < 1e-3);
        assert!((mapbox_height([1, 134, 161]) - 0.1).abs() < 1e-3);
        assert_eq!(mapbox_height([0, 0, 0]), -10000.0);
        for h in [-420.3f32, 0.0, 2475.0, 8848.9] {
            assert!((terrarium_height(terrarium_texel(h)) - h).abs() < 1.0 / 256.0 + 1e-3);
            assert!((mapbox_height(mapbox_texel(h)) - h).abs() < 0.051);
        }
    }

    #[test]
    fn hand_made_tiles_decode_to_their_heights() {
        let size = 4;
        let heights: Vec<f32> = (0..size * size)
            .map(|i| -50.0 + 731.25 * i as f32)
            .collect();
        let path = Path::new("z/x/y.png");
        for (texel, encode) in [
            (
                TexelFormat::Terrarium,
                terrarium_texel as fn(f32) -> [u8; 3],
            ),
            (TexelFormat::Mapbox, mapbox_texel),
        ] {
            let image = image::RgbImage::from_fn(size, size, |x, y| {
                image::Rgb(encode(heights[(y * size + x) as usize]))
            });
            let tile = decode_height_tile(
                &png(image.into()),
                path,
                size,
                texel,
                HeightScale::default(),
            )
            .unwrap();
            for (got, want) in tile.metres.iter().zip(&heights) {
                assert!((got - want).abs() < 0.051, "{texel:?}: {got} vs {want}");
            }
        }
        // 16-bit heights with the manifest's scale: 2,475 m survives (an 8-bit read gives 9).
        let scale = HeightScale::covering(-100.0, 5000.0);
        let image = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(size, size, |x, y| {
            image::Luma([scale.value(heights[(y * size + x) as usize].min(2475.0))])
        });
        let tile = decode_height_tile(
            &png(image::DynamicImage::ImageLuma16(image)),
            path,
            size,
            TexelFormat::Height16,
            scale,
        )
        .unwrap();
        assert!((tile.at(3, 3) - 2475.0).abs() <= scale.scale_m as f32);
        assert!((tile.at(0, 0) - -50.0).abs() <= scale.scale_m as f32);
    }

    #[test]
    fn a_tile_of_another_kind_is_an_error_not_a_conversion() {
        let path = Path::new("9/1/2.png");
        let rgb = png(image::RgbImage::from_pixel(4, 4, image::Rgb([128, 0, 0])).into());
        let gray8 = png(image::GrayImage::from_pixel(4, 4, image::Luma([9])).into());
        let scale = HeightScale::default();
        // An RGB (terrarium) tile in a 16-bit height pyramid.
        let e = decode_height_tile(&rgb, path, 4, TexelFormat::Height16, scale).unwrap_err();
        assert!(
            matches!(e, TileError::WrongKind { .. }) && e.to_string().contains("9/1/2.png"),
            "{e}"
        );
        assert!(e.to_string().contains("rgb8"), "{e}");
        // An 8-bit grayscale tile in a terrarium pyramid, and imagery read as heights.
        assert!(decode_height_tile(&gray8, path, 4, TexelFormat::Terrarium, scale).is_err());
        assert!(decode_height_tile(&rgb, path, 4, TexelFormat::Rgba8, scale).is_err());
        // Wrong size and corrupt bytes.
        assert!(matches!(
            decode_height_tile(&rgb, path, 8, TexelFormat::Terrarium, scale),
            Err(TileError::WrongSize { .. })
        ));
        assert!(matches!(
            decode_height_tile(&rgb[..20], path, 4, TexelFormat::Terrarium, scale),
            Err(TileError::Decode(..))
        ));
    }

    #[test]
    fn a_height_scale_covers_its_range_in_16_bits() {
        let s = HeightScale::covering(-432.17, 8848.86);
        assert_eq!(s.offset_m, -432.18);
        assert!(s.scale_m > 0.14 && s.scale_m < 0.15);
        for h in [-432.17f32, 0.0, 1234.5, 8848.86] {
            assert!((s.metres(s.value(h)) - h).abs() <= 0.5 * s.scale_m as f32 + 1e-3);
        }
        // A small range keeps centimetres.
        assert_eq!(HeightScale::covering(10.0, 20.0).scale_m, 0.01);
        assert_eq!(s.value(1e9), 65535);
        assert_eq!(s.value(-1e9), 0);
    }
}
