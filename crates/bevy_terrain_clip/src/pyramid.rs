//! Tile pyramids on disk in the layout real users have: XYZ or TMS directories of image tiles
//! (`z/x/y.png`, what GDAL's `gdal2tiles` and tile servers produce) plus a small JSON manifest,
//! `pyramid.json`, saying how the pyramid maps onto the world.
//!
//! Level `z` of the pyramid is `2^z × 2^z` tiles of `tile_size²` texels, so virtual-texture level
//! `z + log2(tile_size)`. XYZ counts rows from the top (north), TMS from the bottom. Finer levels
//! may be partial (insets): their manifest entry bounds the tiles that exist, and tiles outside
//! are known absent without touching the disk.
//!
//! ```json
//! {
//!   "version": 1,
//!   "scheme": "xyz",
//!   "extension": "png",
//!   "tile_size": 512,
//!   "levels": 12,
//!   "origin_m": [500000.0, 4000000.0],
//!   "metres_per_texel": 0.25,
//!   "partial_levels": [{ "z": 11, "min": [300, 410], "max": [420, 530] }],
//!   "texel": "rgba8"
//! }
//! ```
//! `origin_m` is the world (x, z) of the texture's north-west corner, in f64 (real projected
//! coordinates are millions of metres); `metres_per_texel` is the finest level's.

use crate::cache::TileKey;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Manifest file name inside a pyramid directory.
pub const MANIFEST: &str = "pyramid.json";

/// Row order of the tile directories.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TileScheme {
    /// Row 0 at the top (north): slippy-map tiles.
    Xyz,
    /// Row 0 at the bottom (south): Tile Map Service.
    Tms,
}

/// The tiles that exist in a partial level, `[min, max)` in tiles.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PartialLevel {
    /// The level.
    pub z: u32,
    /// First column and row that exist (XYZ rows).
    pub min: [u32; 2],
    /// One past the last.
    pub max: [u32; 2],
}

/// What a pyramid's texels are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TexelFormat {
    /// 8-bit RGBA imagery (what the clip stack streams).
    #[default]
    Rgba8,
    /// 16-bit single-channel heights (16-bit grayscale PNG tiles), metres by the manifest's
    /// `height_offset_m` and `height_scale_m`.
    Height16,
    /// Terrarium-encoded heights (8-bit RGB: `R·256 + G + B/256 − 32768` m).
    Terrarium,
    /// Mapbox Terrain-RGB heights (8-bit RGB: `−10000 + (R·65536 + G·256 + B)·0.1` m).
    Mapbox,
}

impl TexelFormat {
    /// Whether the texels are heights (any encoding).
    pub fn is_height(self) -> bool {
        !matches!(self, Self::Rgba8)
    }

    /// The manifest's name and what it means, for messages.
    pub fn describe(self) -> String {
        match self {
            Self::Rgba8 => "rgba8 (imagery)",
            Self::Height16 => "height16 (16-bit grayscale heights)",
            Self::Terrarium => "terrarium (RGB-encoded heights)",
            Self::Mapbox => "mapbox (RGB-encoded heights)",
        }
        .to_string()
    }
}

fn zero() -> f64 {
    0.0
}

fn one() -> f64 {
    1.0
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn is_one(v: &f64) -> bool {
    *v == 1.0
}

/// A pyramid's manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PyramidManifest {
    /// Format version (1).
    pub version: u32,
    /// Row order.
    pub scheme: TileScheme,
    /// Tile file extension (`png`).
    pub extension: String,
    /// Tile side in texels (a power of two).
    pub tile_size: u32,
    /// Levels, `0..levels`.
    pub levels: u32,
    /// World (x, z) of the north-west corner (m).
    pub origin_m: [f64; 2],
    /// Size of a texel of the finest level (m).
    pub metres_per_texel: f64,
    /// Levels with only some tiles.
    #[serde(default)]
    pub partial_levels: Vec<PartialLevel>,
    /// Texel format (`rgba8` when absent).
    #[serde(default)]
    pub texel: TexelFormat,
    /// `height16`: the height of stored value 0 (m).
    #[serde(default = "zero", skip_serializing_if = "is_zero")]
    pub height_offset_m: f64,
    /// `height16`: metres per stored unit.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub height_scale_m: f64,
    /// The source image's size in finest-level texels `[width, height]`, from the north-west
    /// corner: the rest of the pyramid's square is padding, not data. Absent (older pyramids):
    /// all of it is data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extent_texels: Option<[u32; 2]>,
}

/// The largest height (m, either sign) a manifest's 16-bit scale may give.
pub const MAX_HEIGHT_M: f64 = 1e7;

/// Why a manifest was rejected.
#[derive(Debug)]
pub enum ManifestError {
    /// The file could not be read.
    Io(PathBuf, std::io::Error),
    /// Not valid manifest JSON.
    Parse(PathBuf, String),
    /// Parsed, but inconsistent.
    Invalid(PathBuf, String),
}

impl std::fmt::Display for ManifestError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Io(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Parse(p, e) => write!(f, "{}: not a pyramid manifest: {e}", p.display()),
            Self::Invalid(p, e) => write!(f, "{}: inconsistent manifest: {e}", p.display()),
        }
    }
}

impl std::error::Error for ManifestError {}

impl PyramidManifest {
    /// Every inconsistency, in words (empty when usable).
    pub fn problems(&self) -> Vec<String> {
        let mut p = Vec::new();
        if self.version != 1 {
            p.push(format!("version {} (this build reads 1)", self.version));
        }
        if !(self.tile_size.is_power_of_two() && (16..=4096).contains(&self.tile_size)) {
            p.push(format!(
                "tile_size {} is not a power of two in 16..=4096",
                self.tile_size
            ));
        }
        if !(1..=24).contains(&self.levels) {
            p.push(format!("levels {} is not in 1..=24", self.levels));
        }
        if !(self.metres_per_texel.is_finite() && self.metres_per_texel > 0.0) {
            p.push(format!(
                "metres_per_texel {} must be positive",
                self.metres_per_texel
            ));
        }
        // Heights are used as f32 metres: every stored value must give one well within range
        // (±10,000 km; a scale of 1e39 would make them infinite).
        let highest = self.height_offset_m + self.height_scale_m * u16::MAX as f64;
        if !(self.height_offset_m.is_finite()
            && self.height_scale_m.is_finite()
            && self.height_scale_m > 0.0
            && self.height_offset_m.abs() <= MAX_HEIGHT_M
            && highest.abs() <= MAX_HEIGHT_M)
        {
            p.push(format!(
                "height_offset_m {} and height_scale_m {} must be finite, the scale positive, \
                 and give heights within ±{MAX_HEIGHT_M} m",
                self.height_offset_m, self.height_scale_m
            ));
        }
        if let Some([w, h]) = self.extent_texels {
            let side = (self.tile_size as u64) << self.levels.clamp(1, 24).saturating_sub(1);
            if w == 0 || h == 0 || w as u64 > side || h as u64 > side {
                p.push(format!(
                    "extent_texels [{w}, {h}] must be positive and within the finest level's \
                     {side} texels"
                ));
            }
        }
        if !self.origin_m.iter().all(|v| v.is_finite()) {
            p.push(format!("origin_m {:?} is not finite", self.origin_m));
        }
        if self.extension.is_empty() || self.extension.contains(['/', '\\', '.']) {
            p.push(format!(
                "extension '{}' is not a file extension",
                self.extension
            ));
        }
        for level in &self.partial_levels {
            let side = 1u64 << level.z.min(40);
            if level.z >= self.levels {
                p.push(format!(
                    "partial level {} is beyond the {} levels",
                    level.z, self.levels
                ));
            } else if (0..2).any(|i| level.min[i] >= level.max[i] || level.max[i] as u64 > side) {
                p.push(format!(
                    "partial level {}: tiles {:?}..{:?} are empty or outside 0..{side}",
                    level.z, level.min, level.max
                ));
            }
        }
        p
    }

    /// Reads and checks `dir/pyramid.json`.
    pub fn load(dir: &Path) -> Result<Self, ManifestError> {
        let path = dir.join(MANIFEST);
        let text =
            std::fs::read_to_string(&path).map_err(|e| ManifestError::Io(path.clone(), e))?;
        Self::parse(&text, &path)
    }

    /// Parses and checks a manifest's text (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<Self, ManifestError> {
        let manifest: Self = serde_json::from_str(text)
            .map_err(|e| ManifestError::Parse(path.to_path_buf(), e.to_string()))?;
        let problems = manifest.problems();
        if !problems.is_empty() {
            return Err(ManifestError::Invalid(
                path.to_path_buf(),
                problems.join("; "),
            ));
        }
        Ok(manifest)
    }

    /// Virtual-texture levels: pyramid level z is virtual level `z + log2(tile_size)`.
    pub fn virtual_levels(&self) -> u32 {
        self.levels + self.tile_size.trailing_zeros()
    }

    /// Whether tile `key` can exist (inside the level, and inside a partial level's extent).
    pub fn may_exist(&self, key: TileKey) -> bool {
        if key.z >= self.levels {
            return false;
        }
        let side = 1u64 << key.z;
        if key.x as u64 >= side || key.y as u64 >= side {
            return false;
        }
        self.partial_levels
            .iter()
            .filter(|l| l.z == key.z)
            .all(|l| key.x >= l.min[0] && key.x < l.max[0] && key.y >= l.min[1] && key.y < l.max[1])
    }

    /// Path of tile `key` (XYZ rows) under `dir`, flipping the row for TMS (a row outside the
    /// level, which [`Self::may_exist`] rejects, flips to row 0).
    pub fn tile_path(&self, dir: &Path, key: TileKey) -> PathBuf {
        let row = match self.scheme {
            TileScheme::Xyz => key.y,
            TileScheme::Tms => 1u64
                .checked_shl(key.z)
                .unwrap_or(0)
                .saturating_sub(1 + key.y as u64) as u32,
        };
        dir.join(key.z.to_string())
            .join(key.x.to_string())
            .join(format!("{row}.{}", self.extension))
    }

    /// Virtual-texture coordinates in [0, 1]² of world point (x, z), in f64.
    pub fn world_to_uv(&self, x: f64, z: f64) -> [f64; 2] {
        // The finest level, virtual level V − 1, is 2^(V−1) texels wide.
        let finest_side_m = self.metres_per_texel * 2f64.powi(self.virtual_levels() as i32 - 1);
        [
            (x - self.origin_m[0]) / finest_side_m,
            (z - self.origin_m[1]) / finest_side_m,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manifest() -> PyramidManifest {
        PyramidManifest {
            version: 1,
            scheme: TileScheme::Xyz,
            extension: "png".into(),
            tile_size: 256,
            levels: 6,
            origin_m: [1_000_000.0, 2_000_000.0],
            metres_per_texel: 0.5,
            partial_levels: vec![PartialLevel {
                z: 5,
                min: [4, 8],
                max: [12, 16],
            }],
            texel: TexelFormat::Rgba8,
            height_offset_m: 0.0,
            height_scale_m: 1.0,
            extent_texels: None,
        }
    }

    #[test]
    fn paths_follow_xyz_and_tms() {
        let mut m = manifest();
        let key = TileKey { z: 3, x: 2, y: 1 };
        assert_eq!(m.tile_path(Path::new("p"), key), Path::new("p/3/2/1.png"));
        m.scheme = TileScheme::Tms;
        assert_eq!(m.tile_path(Path::new("p"), key), Path::new("p/3/2/6.png"));
    }

    #[test]
    fn partial_levels_bound_the_tiles_that_exist() {
        let m = manifest();
        assert!(m.may_exist(TileKey { z: 4, x: 15, y: 0 }));
        assert!(!m.may_exist(TileKey { z: 4, x: 16, y: 0 }));
        assert!(m.may_exist(TileKey { z: 5, x: 4, y: 8 }));
        assert!(!m.may_exist(TileKey { z: 5, x: 3, y: 8 }));
        assert!(!m.may_exist(TileKey { z: 5, x: 12, y: 8 }));
        assert!(!m.may_exist(TileKey { z: 6, x: 0, y: 0 }));
        assert_eq!(m.virtual_levels(), 14);
    }

    #[test]
    fn world_positions_map_exactly_far_from_the_origin() {
        let m = manifest();
        // The finest level is 2^13 texels of 0.5 m: 4096 m wide.
        let uv = m.world_to_uv(1_000_000.0 + 1024.25, 2_000_000.0 + 3072.0);
        assert_eq!(uv, [1024.25 / 4096.0, 0.75]);
    }

    #[test]
    fn inconsistent_manifests_are_clear_errors() {
        let dir = std::env::temp_dir().join(format!("terrain_manifest_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut bad = manifest();
        bad.tile_size = 300;
        bad.partial_levels[0].max = [40, 16];
        std::fs::write(dir.join(MANIFEST), serde_json::to_string(&bad).unwrap()).unwrap();
        let e = PyramidManifest::load(&dir).unwrap_err().to_string();
        assert!(
            e.contains("tile_size 300") && e.contains("partial level 5"),
            "{e}"
        );
        // An extent wider than the finest level (256 · 2⁵ = 8192 texels), or empty.
        for extent in [[8193, 100], [0, 100]] {
            let wide = PyramidManifest {
                extent_texels: Some(extent),
                ..manifest()
            };
            assert!(
                wide.problems().iter().any(|p| p.contains("extent_texels")),
                "{extent:?}"
            );
        }
        let fits = PyramidManifest {
            extent_texels: Some([8192, 3000]),
            ..manifest()
        };
        assert!(fits.problems().is_empty(), "{:?}", fits.problems());
        std::fs::write(dir.join(MANIFEST), "{ \"version\": 1 }").unwrap();
        let e = PyramidManifest::load(&dir).unwrap_err().to_string();
        assert!(e.contains("not a pyramid manifest"), "{e}");
        std::fs::write(
            dir.join(MANIFEST),
            serde_json::to_string(&manifest()).unwrap(),
        )
        .unwrap();
        assert_eq!(PyramidManifest::load(&dir).unwrap(), manifest());
        std::fs::remove_dir_all(&dir).ok();
        assert!(matches!(
            PyramidManifest::load(Path::new("/nonexistent")),
            Err(ManifestError::Io(..))
        ));
    }
}
