//! Baked grass slices on disk (`*.grassslices`): versioned, little-endian, checksummed, written
//! through a temporary file and a rename so an interrupted write never leaves a truncated cache.
//!
//! ```text
//! magic    8 bytes  "BNGRSLIC"
//! version  u32      FORMAT_VERSION
//! length   u64      payload bytes
//! payload           source hash u64, bake ms f32, size f32, height f32, per_axis u32,
//!                   resolution u32, then every texel as four IEEE half floats
//! checksum u64      FNV-1a 64 of the payload
//! ```

use super::slices::{LAYERS, SliceLayout, SliceTextures};
use crate::pruning::format::fnv1a64;
use half::f16;
use std::path::Path;

/// File signature.
pub const MAGIC: &[u8; 8] = b"BNGRSLIC";
/// Current format version; bump on any layout change.
pub const FORMAT_VERSION: u32 = 1;
/// Largest slice image side a file may hold.
pub const MAX_RESOLUTION: u32 = 1024;
/// Most vertical slices per axis a file may hold.
pub const MAX_PER_AXIS: u32 = 32;

/// A baked set of slices and where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct SliceBake {
    /// The images.
    pub textures: SliceTextures,
    /// Hash of the species and layout it was baked from: a cache whose hash differs is stale.
    pub source_hash: u64,
    /// How long the bake took (ms).
    pub bake_ms: f32,
}

/// Why a slice file could not be read or written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SliceFormatError {
    /// Not a grass slice file.
    BadMagic,
    /// Written by another version of the format.
    UnsupportedVersion {
        /// Version in the file.
        found: u32,
        /// Version this build reads.
        expected: u32,
    },
    /// The file ends early or has trailing bytes.
    Truncated,
    /// The checksum does not match: the file is corrupt.
    Checksum,
    /// The content is inconsistent (what is wrong is said).
    Invalid(String),
    /// Reading or writing the file failed.
    Io(String),
}

impl std::fmt::Display for SliceFormatError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BadMagic => write!(f, "not a grass slice file (bad signature)"),
            Self::UnsupportedVersion { found, expected } => write!(
                f,
                "grass slice format version {found}, this build reads version {expected}: re-bake"
            ),
            Self::Truncated => write!(f, "grass slice file is truncated"),
            Self::Checksum => write!(f, "grass slice file is corrupt (checksum mismatch)"),
            Self::Invalid(s) => write!(f, "grass slice file is inconsistent: {s}"),
            Self::Io(s) => write!(f, "grass slice file: {s}"),
        }
    }
}

impl std::error::Error for SliceFormatError {}

/// Serialises a bake.
pub fn encode(bake: &SliceBake) -> Vec<u8> {
    let l = &bake.textures.layout;
    let mut p = Vec::with_capacity(32 + bake.textures.texels.len() * 8);
    p.extend_from_slice(&bake.source_hash.to_le_bytes());
    for v in [bake.bake_ms, l.size, l.height] {
        p.extend_from_slice(&v.to_le_bytes());
    }
    p.extend_from_slice(&l.per_axis.to_le_bytes());
    p.extend_from_slice(&l.resolution.to_le_bytes());
    for t in &bake.textures.texels {
        for c in t {
            p.extend_from_slice(&f16::from_f32(*c).to_le_bytes());
        }
    }
    let mut out = Vec::with_capacity(p.len() + 28);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(p.len() as u64).to_le_bytes());
    out.extend_from_slice(&p);
    out.extend_from_slice(&fnv1a64(&p).to_le_bytes());
    out
}

fn take<'a>(bytes: &'a [u8], at: &mut usize, n: usize) -> Result<&'a [u8], SliceFormatError> {
    let end = at.checked_add(n).ok_or(SliceFormatError::Truncated)?;
    let s = bytes.get(*at..end).ok_or(SliceFormatError::Truncated)?;
    *at = end;
    Ok(s)
}

fn u32_at(bytes: &[u8], at: &mut usize) -> Result<u32, SliceFormatError> {
    Ok(u32::from_le_bytes(take(bytes, at, 4)?.try_into().unwrap()))
}

fn f32_at(bytes: &[u8], at: &mut usize) -> Result<f32, SliceFormatError> {
    Ok(f32::from_le_bytes(take(bytes, at, 4)?.try_into().unwrap()))
}

/// Reads a bake, checking everything the renderer relies on.
pub fn decode(bytes: &[u8]) -> Result<SliceBake, SliceFormatError> {
    if bytes.len() < 8 || &bytes[..8] != MAGIC {
        return Err(SliceFormatError::BadMagic);
    }
    let mut at = 8;
    let version = u32_at(bytes, &mut at)?;
    if version != FORMAT_VERSION {
        return Err(SliceFormatError::UnsupportedVersion {
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    let length = u64::from_le_bytes(take(bytes, &mut at, 8)?.try_into().unwrap());
    let end = (at as u64)
        .checked_add(length)
        .filter(|&e| e + 8 == bytes.len() as u64)
        .ok_or(SliceFormatError::Truncated)? as usize;
    let payload = &bytes[at..end];
    if fnv1a64(payload) != u64::from_le_bytes(bytes[end..].try_into().unwrap()) {
        return Err(SliceFormatError::Checksum);
    }
    let mut at = 0;
    let source_hash = u64::from_le_bytes(take(payload, &mut at, 8)?.try_into().unwrap());
    let bake_ms = f32_at(payload, &mut at)?;
    if !(bake_ms.is_finite() && bake_ms >= 0.0) {
        return Err(SliceFormatError::Invalid(format!(
            "bake time {bake_ms} ms is not a duration"
        )));
    }
    let size = f32_at(payload, &mut at)?;
    let height = f32_at(payload, &mut at)?;
    let per_axis = u32_at(payload, &mut at)?;
    let resolution = u32_at(payload, &mut at)?;
    if !(size.is_finite() && size > 0.0 && height.is_finite() && height > 0.0) {
        return Err(SliceFormatError::Invalid(format!(
            "patch size {size} and height {height} must be positive"
        )));
    }
    if !(1..=MAX_PER_AXIS).contains(&per_axis) || !(1..=MAX_RESOLUTION).contains(&resolution) {
        return Err(SliceFormatError::Invalid(format!(
            "{per_axis} slices per axis (1..={MAX_PER_AXIS}) of {resolution}² texels \
             (1..={MAX_RESOLUTION})"
        )));
    }
    let layout = SliceLayout {
        size,
        height,
        per_axis,
        resolution,
    };
    let count = layout.slices() as usize * LAYERS as usize * layout.texels_per_layer();
    let data = take(payload, &mut at, count * 8)?;
    if at != payload.len() {
        return Err(SliceFormatError::Truncated);
    }
    let mut texels = Vec::with_capacity(count);
    for t in data.chunks_exact(8) {
        let c = |k: usize| f16::from_le_bytes([t[2 * k], t[2 * k + 1]]).to_f32();
        let texel = [c(0), c(1), c(2), c(3)];
        if texel.iter().any(|v| !v.is_finite()) {
            return Err(SliceFormatError::Invalid("a texel is not finite".into()));
        }
        texels.push(texel);
    }
    Ok(SliceBake {
        textures: SliceTextures { layout, texels },
        source_hash,
        bake_ms,
    })
}

/// Writes a bake to `path` (through a temporary file and a rename).
pub fn save(bake: &SliceBake, path: &Path) -> Result<(), SliceFormatError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| SliceFormatError::Io(e.to_string()))?;
    }
    let tmp = path.with_extension(format!("grassslices.tmp{}", std::process::id()));
    std::fs::write(&tmp, encode(bake))
        .and_then(|_| std::fs::rename(&tmp, path))
        .map_err(|e| {
            std::fs::remove_file(&tmp).ok();
            SliceFormatError::Io(format!("{}: {e}", path.display()))
        })
}

/// Reads a slice file.
pub fn load(path: &Path) -> Result<SliceBake, SliceFormatError> {
    let bytes = std::fs::read(path)
        .map_err(|e| SliceFormatError::Io(format!("{}: {e}", path.display())))?;
    decode(&bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> SliceBake {
        let layout = SliceLayout {
            size: 0.5,
            height: 0.4,
            per_axis: 1,
            resolution: 2,
        };
        let mut textures = SliceTextures::empty(layout);
        for (i, t) in textures.texels.iter_mut().enumerate() {
            *t = [i as f32 / 64.0, 0.25, 0.5, (i % 2) as f32];
        }
        SliceBake {
            textures,
            source_hash: 77,
            bake_ms: 12.5,
        }
    }

    #[test]
    fn round_trips_and_refuses_corrupt_files() {
        let bake = sample();
        let bytes = encode(&bake);
        assert_eq!(decode(&bytes).unwrap(), bake);
        let dir = std::env::temp_dir().join(format!("grass_slices_{}", std::process::id()));
        let path = dir.join("a.grassslices");
        save(&bake, &path).unwrap();
        assert_eq!(load(&path).unwrap(), bake);
        std::fs::remove_dir_all(&dir).ok();

        assert_eq!(decode(b"nonsense"), Err(SliceFormatError::BadMagic));
        assert_eq!(
            decode(&bytes[..bytes.len() - 3]),
            Err(SliceFormatError::Truncated)
        );
        let mut flipped = bytes.clone();
        flipped[40] ^= 1;
        assert_eq!(decode(&flipped), Err(SliceFormatError::Checksum));
        let mut version = bytes.clone();
        version[8] = 9;
        assert!(matches!(
            decode(&version),
            Err(SliceFormatError::UnsupportedVersion { found: 9, .. })
        ));
        // A consistent checksum over an absurd header is still refused.
        let mut absurd = sample();
        absurd.textures.layout.per_axis = 1000;
        let bytes = encode(&absurd);
        assert!(matches!(decode(&bytes), Err(SliceFormatError::Invalid(_))));
    }
}
