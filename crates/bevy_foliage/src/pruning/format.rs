//! The on-disk format of a [`BakedFoliage`] (`*.foliage`): versioned, little-endian, checksummed.
//!
//! ```text
//! magic    8 bytes  "BNFOLIAG"
//! version  u32      FORMAT_VERSION
//! length   u64      payload bytes
//! payload           sections, each a u32 element count then the elements
//! checksum u64      FNV-1a 64 of the payload
//! ```
//!
//! Decoding checks everything the GPU will rely on (monotonic ranges, indices in range, finite
//! floats), so a corrupt or mismatched file is a clear [`FormatError`], never a panic or an
//! out-of-bounds read on the GPU. Files are written to a temporary name and renamed, so a crash
//! mid-write never leaves a truncated cache behind.

use super::bake::BakedFoliage;
use super::cells::Obb;
use super::leaves::SkippedLeaves;
use bevy::math::{Mat3, Vec2, Vec3};
use std::path::Path;

/// File signature.
pub const MAGIC: &[u8; 8] = b"BNFOLIAG";
/// Current format version; bump on any layout change.
///
/// Version 7 added each leaf's open map ([`BakedFoliage::leaf_open`]); version 6 added the leaves' opacity the bake traced them with
/// ([`BakedFoliage::leaf_opacity`]); version 5 the bounce ratios, 4 the crown's hotspot.
pub const FORMAT_VERSION: u32 = 7;

/// Why a baked foliage file could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FormatError {
    /// Not a baked foliage file.
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

impl std::fmt::Display for FormatError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BadMagic => write!(f, "not a baked foliage file (bad signature)"),
            Self::UnsupportedVersion { found, expected } => write!(
                f,
                "baked foliage format version {found}, this build reads version {expected}: re-bake the tree"
            ),
            Self::Truncated => write!(f, "baked foliage file is truncated"),
            Self::Checksum => write!(f, "baked foliage file is corrupt (checksum mismatch)"),
            Self::Invalid(s) => write!(f, "baked foliage file is inconsistent: {s}"),
            Self::Io(s) => write!(f, "baked foliage file: {s}"),
        }
    }
}

impl std::error::Error for FormatError {}

/// FNV-1a, 64 bits.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

struct Writer(Vec<u8>);

impl Writer {
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn count(&mut self, n: usize) {
        self.u32(n as u32);
    }
    fn u32s(&mut self, v: &[u32]) {
        self.count(v.len());
        v.iter().for_each(|&x| self.u32(x));
    }
    fn u8s(&mut self, v: &[u8]) {
        self.count(v.len());
        self.0.extend_from_slice(v);
    }
    fn u16s(&mut self, v: &[u16]) {
        self.count(v.len());
        v.iter()
            .for_each(|&x| self.0.extend_from_slice(&x.to_le_bytes()));
    }
    fn vec3s(&mut self, v: &[Vec3]) {
        self.count(v.len());
        v.iter()
            .for_each(|p| p.to_array().iter().for_each(|&x| self.f32(x)));
    }
    fn vec2s(&mut self, v: &[Vec2]) {
        self.count(v.len());
        v.iter()
            .for_each(|p| p.to_array().iter().for_each(|&x| self.f32(x)));
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], FormatError> {
        let end = self.at.checked_add(n).ok_or(FormatError::Truncated)?;
        let s = self.bytes.get(self.at..end).ok_or(FormatError::Truncated)?;
        self.at = end;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32, FormatError> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    fn f32(&mut self) -> Result<f32, FormatError> {
        let v = f32::from_le_bytes(self.take(4)?.try_into().unwrap());
        if v.is_finite() {
            Ok(v)
        } else {
            Err(FormatError::Invalid("non-finite number".into()))
        }
    }
    fn count(&mut self, element_bytes: usize) -> Result<usize, FormatError> {
        let n = self.u32()? as usize;
        // Refuse counts the remaining bytes cannot hold before allocating anything.
        if n.saturating_mul(element_bytes) > self.bytes.len() - self.at {
            return Err(FormatError::Truncated);
        }
        Ok(n)
    }
    fn u32s(&mut self) -> Result<Vec<u32>, FormatError> {
        let n = self.count(4)?;
        (0..n).map(|_| self.u32()).collect()
    }
    fn u8s(&mut self) -> Result<Vec<u8>, FormatError> {
        let n = self.count(1)?;
        Ok(self.take(n)?.to_vec())
    }
    fn u16s(&mut self) -> Result<Vec<u16>, FormatError> {
        let n = self.count(2)?;
        (0..n)
            .map(|_| Ok(u16::from_le_bytes(self.take(2)?.try_into().unwrap())))
            .collect()
    }
    fn vec3s(&mut self) -> Result<Vec<Vec3>, FormatError> {
        let n = self.count(12)?;
        (0..n)
            .map(|_| Ok(Vec3::new(self.f32()?, self.f32()?, self.f32()?)))
            .collect()
    }
    fn vec2s(&mut self) -> Result<Vec<Vec2>, FormatError> {
        let n = self.count(8)?;
        (0..n)
            .map(|_| Ok(Vec2::new(self.f32()?, self.f32()?)))
            .collect()
    }
}

/// Serialises a bake.
pub fn encode(baked: &BakedFoliage) -> Vec<u8> {
    let mut w = Writer(Vec::new());
    w.vec3s(&baked.view_directions);
    w.u32s(&baked.cell_first_leaf);
    let boxes: Vec<Vec3> = baked
        .cell_boxes
        .iter()
        .flat_map(|b| {
            [
                b.center,
                b.axes.x_axis,
                b.axes.y_axis,
                b.axes.z_axis,
                b.half_extents,
            ]
        })
        .collect();
    w.vec3s(&boxes);
    w.u16s(&baked.visibility);
    w.u32s(&baked.leaf_index_start);
    w.u32s(&baked.indices);
    w.vec3s(&baked.positions);
    w.vec3s(&baked.normals);
    w.vec2s(&baked.uvs);
    w.vec3s(&baked.centroid_offsets);
    let light: Vec<u16> = baked.leaf_light.iter().flatten().copied().collect();
    w.u16s(&light);
    let seen: Vec<u16> = baked.leaf_seen.iter().flatten().copied().collect();
    w.u16s(&seen);
    let bounce: Vec<u8> = baked.leaf_bounce.iter().flatten().copied().collect();
    w.u8s(&bounce);
    let open: Vec<u8> = baked.leaf_open.iter().flat_map(|m| m.to_bytes()).collect();
    w.u8s(&open);
    w.u32s(&baked.hotspot.packed());
    w.u32s(&[baked.extinction.to_bits()]);
    w.u32s(&[baked.leaf_opacity.to_bits()]);
    let s = baked.skipped;
    w.u32s(&[s.non_finite as u32, s.degenerate as u32, s.malformed as u32]);
    let payload = w.0;
    let mut out = Vec::with_capacity(payload.len() + 28);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&payload);
    out.extend_from_slice(&fnv1a64(&payload).to_le_bytes());
    out
}

/// Parses and validates a bake.
pub fn decode(bytes: &[u8]) -> Result<BakedFoliage, FormatError> {
    if bytes.len() < 8 || &bytes[..8] != MAGIC {
        return Err(FormatError::BadMagic);
    }
    if bytes.len() < 20 {
        return Err(FormatError::Truncated);
    }
    let version = u32::from_le_bytes(bytes[8..12].try_into().unwrap());
    if version != FORMAT_VERSION {
        return Err(FormatError::UnsupportedVersion {
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    let len = u64::from_le_bytes(bytes[12..20].try_into().unwrap()) as usize;
    if bytes.len() != 20usize.saturating_add(len).saturating_add(8) {
        return Err(FormatError::Truncated);
    }
    let payload = &bytes[20..20 + len];
    let checksum = u64::from_le_bytes(bytes[20 + len..].try_into().unwrap());
    if fnv1a64(payload) != checksum {
        return Err(FormatError::Checksum);
    }
    let mut r = Reader {
        bytes: payload,
        at: 0,
    };
    let view_directions = r.vec3s()?;
    let cell_first_leaf = r.u32s()?;
    let boxes = r.vec3s()?;
    if boxes.len() % 5 != 0 {
        return Err(FormatError::Invalid("cell box section".into()));
    }
    let cell_boxes = boxes
        .chunks_exact(5)
        .map(|b| Obb {
            center: b[0],
            axes: Mat3::from_cols(b[1], b[2], b[3]),
            half_extents: b[4],
        })
        .collect();
    let visibility = r.u16s()?;
    let leaf_index_start = r.u32s()?;
    let indices = r.u32s()?;
    let positions = r.vec3s()?;
    let normals = r.vec3s()?;
    let uvs = r.vec2s()?;
    let centroid_offsets = r.vec3s()?;
    let light = r.u16s()?;
    let seen = r.u16s()?;
    let bounce = r.u8s()?;
    let open = r.u8s()?;
    let hotspot = r.u32s()?;
    let extinction = r.u32s()?;
    let opacity = r.u32s()?;
    if opacity.len() != 1 {
        return Err(FormatError::Invalid("leaf opacity section".into()));
    }
    let hotspot = match <[u32; crate::lighting::hotspot::HOTSPOT_WORDS]>::try_from(hotspot) {
        Ok(words) => crate::lighting::hotspot::Hotspot::unpacked(words),
        Err(_) => return Err(FormatError::Invalid("hotspot section".into())),
    };
    if light.len() % 8 != 0 || seen.len() % 8 != 0 || extinction.len() != 1 {
        return Err(FormatError::Invalid("leaf light section".into()));
    }
    let leaf_light = light
        .chunks_exact(8)
        .map(|c| std::array::from_fn(|j| c[j]))
        .collect();
    let leaf_seen = seen
        .chunks_exact(8)
        .map(|c| std::array::from_fn(|j| c[j]))
        .collect();
    use crate::lighting::gathered_bounce::STORED_RATIOS;
    if bounce.len() % STORED_RATIOS != 0 {
        return Err(FormatError::Invalid("bounce ratio section".into()));
    }
    let leaf_bounce = bounce
        .chunks_exact(STORED_RATIOS)
        .map(|c| std::array::from_fn(|j| c[j]))
        .collect();
    use crate::lighting::open_map::{LEAF_OPEN_MAP_BYTES, LeafOpenMap};
    if open.len() % LEAF_OPEN_MAP_BYTES != 0 {
        return Err(FormatError::Invalid("open map section".into()));
    }
    let leaf_open = open
        .chunks_exact(LEAF_OPEN_MAP_BYTES)
        .map(|c| LeafOpenMap::from_bytes(c.try_into().expect("chunk of the map's size")))
        .collect();
    let skipped = r.u32s()?;
    if r.at != payload.len() || skipped.len() != 3 {
        return Err(FormatError::Invalid("unexpected trailing data".into()));
    }
    let baked = BakedFoliage {
        view_directions,
        cell_first_leaf,
        cell_boxes,
        visibility,
        leaf_index_start,
        indices,
        positions,
        normals,
        uvs,
        centroid_offsets,
        leaf_light,
        leaf_seen,
        leaf_open,
        leaf_bounce,
        hotspot,
        extinction: f32::from_bits(extinction[0]),
        leaf_opacity: f32::from_bits(opacity[0]),
        skipped: SkippedLeaves {
            non_finite: skipped[0] as usize,
            degenerate: skipped[1] as usize,
            malformed: skipped[2] as usize,
        },
    };
    validate(&baked)?;
    Ok(baked)
}

/// Checks every invariant the runtime relies on.
pub fn validate(b: &BakedFoliage) -> Result<(), FormatError> {
    let bad = |s: String| Err(FormatError::Invalid(s));
    let views = b.view_directions.len();
    if views == 0 {
        return bad("no viewpoints".into());
    }
    if b.cell_first_leaf.len() < 2 || b.cell_first_leaf[0] != 0 {
        return bad("cell ranges must start at 0".into());
    }
    let cells = b.cell_count();
    if b.cell_first_leaf.windows(2).any(|w| w[0] > w[1]) {
        return bad("cell ranges not increasing".into());
    }
    if b.cell_first_leaf.windows(2).any(|w| w[1] - w[0] >= 1 << 16) {
        return bad("a cell holds more than 65535 leaves".into());
    }
    if *b.cell_first_leaf.last().unwrap() as usize != b.leaf_count() {
        return bad(format!(
            "cells cover {} leaves, file has {}",
            b.cell_first_leaf.last().unwrap(),
            b.leaf_count()
        ));
    }
    if b.cell_boxes.len() != cells {
        return bad(format!(
            "{} cell boxes for {cells} cells",
            b.cell_boxes.len()
        ));
    }
    if b.visibility.len() != cells * views {
        return bad(format!(
            "{} visibility entries for {cells} cells × {views} views",
            b.visibility.len()
        ));
    }
    if b.leaf_index_start.first() != Some(&0)
        || b.leaf_index_start.windows(2).any(|w| w[0] > w[1])
        || *b.leaf_index_start.last().unwrap() as usize != b.indices.len()
    {
        return bad("leaf index ranges inconsistent".into());
    }
    let n = b.positions.len();
    if b.normals.len() != n || b.uvs.len() != n || b.centroid_offsets.len() != n {
        return bad("vertex arrays differ in length".into());
    }
    if let Some(i) = b.indices.iter().find(|&&i| i as usize >= n) {
        return bad(format!("index {i} out of range ({n} vertices)"));
    }
    if b.leaf_light.len() != b.leaf_count() {
        return bad(format!(
            "leaf light for {} leaves, file has {}",
            b.leaf_light.len(),
            b.leaf_count()
        ));
    }
    if !b.leaf_seen.is_empty() && b.leaf_seen.len() != b.leaf_count() {
        return bad(format!(
            "seen-part gains for {} leaves, file has {}",
            b.leaf_seen.len(),
            b.leaf_count()
        ));
    }
    if !b.leaf_open.is_empty() && b.leaf_open.len() != b.leaf_count() {
        return bad(format!(
            "open maps for {} leaves, file has {}",
            b.leaf_open.len(),
            b.leaf_count()
        ));
    }
    if !b.leaf_bounce.is_empty() && b.leaf_bounce.len() != b.leaf_count() {
        return bad(format!(
            "bounce ratios for {} leaves, file has {}",
            b.leaf_bounce.len(),
            b.leaf_count()
        ));
    }
    let (_, bad_hotspot) = b.hotspot.sanitized();
    if bad_hotspot {
        return bad(format!(
            "hotspot factors {:?} / {:?} outside {:?}",
            b.hotspot.sun,
            b.hotspot.bounce,
            crate::lighting::hotspot::HOTSPOT_RANGE
        ));
    }
    if !(b.extinction.is_finite() && b.extinction >= 0.0) {
        return bad(format!("extinction {} is not a finite τ ≥ 0", b.extinction));
    }
    if !(b.leaf_opacity > 0.0 && b.leaf_opacity <= 1.0) {
        return bad(format!("leaf opacity {} is not in (0, 1]", b.leaf_opacity));
    }
    Ok(())
}

/// Writes a bake to `path` atomically (temporary file + rename).
pub fn save(baked: &BakedFoliage, path: &Path) -> Result<(), FormatError> {
    let io = |e: std::io::Error| FormatError::Io(format!("{}: {e}", path.display()));
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(io)?;
    }
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    std::fs::write(&tmp, encode(baked)).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// Reads a bake from `path`.
pub fn load(path: &Path) -> Result<BakedFoliage, FormatError> {
    let bytes =
        std::fs::read(path).map_err(|e| FormatError::Io(format!("{}: {e}", path.display())))?;
    decode(&bytes)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::pruning::bake::{BakeSettings, CellCount, bake};
    use crate::pruning::procedural::{TreeSpecies, generate};

    /// A small bake for file and loader tests.
    pub(crate) fn sample() -> BakedFoliage {
        let tree = generate(&TreeSpecies::fraxinus().with_leaf_count(500));
        let settings = BakeSettings {
            cells: CellCount::Depth(4),
            resolution: 48,
            ..Default::default()
        };
        bake(&tree.leaves, &settings, &|_| {}).unwrap().0
    }

    #[test]
    fn round_trips_through_a_file() {
        let b = sample();
        let dir = std::env::temp_dir().join(format!("foliage-format-{}", std::process::id()));
        let path = dir.join("tree.foliage");
        save(&b, &path).unwrap();
        assert_eq!(load(&path).unwrap(), b);
        // No temporary file left behind.
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("tree.foliage")]);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn corrupt_or_mismatched_files_are_clear_errors() {
        let bytes = encode(&sample());
        assert_eq!(decode(b"nonsense"), Err(FormatError::BadMagic));
        // Version 1 (before the leaf light) is refused: re-bake.
        let mut v1 = bytes.clone();
        v1[8] = 1;
        assert_eq!(
            decode(&v1),
            Err(FormatError::UnsupportedVersion {
                found: 1,
                expected: FORMAT_VERSION
            })
        );
        let mut short_light = sample();
        short_light.leaf_light.pop();
        assert!(matches!(
            decode(&encode(&short_light)),
            Err(FormatError::Invalid(_))
        ));
        // Seen-part gains: none (all 1) or one set a leaf.
        let mut short_seen = sample();
        assert!(!short_seen.leaf_seen.is_empty());
        short_seen.leaf_seen.pop();
        assert!(matches!(
            decode(&encode(&short_seen)),
            Err(FormatError::Invalid(_))
        ));
        let mut no_seen = sample();
        no_seen.leaf_seen.clear();
        assert_eq!(decode(&encode(&no_seen)), Ok(no_seen));
        // Open maps likewise: none (the sky takes the gains) or one a leaf, kept byte for byte.
        let mut short_open = sample();
        assert!(short_open.leaf_open.iter().any(|m| m.is_map()));
        short_open.leaf_open.pop();
        assert!(matches!(
            decode(&encode(&short_open)),
            Err(FormatError::Invalid(_))
        ));
        let mut no_open = sample();
        no_open.leaf_open.clear();
        assert_eq!(decode(&encode(&no_open)), Ok(no_open));
        // Bounce ratios likewise: none (eq. 5.24 alone) or one set a leaf, kept byte for byte.
        let mut short_bounce = sample();
        assert!(!short_bounce.leaf_bounce.is_empty());
        short_bounce.leaf_bounce.pop();
        assert!(matches!(
            decode(&encode(&short_bounce)),
            Err(FormatError::Invalid(_))
        ));
        let mut no_bounce = sample();
        no_bounce.leaf_bounce.clear();
        assert_eq!(decode(&encode(&no_bounce)), Ok(no_bounce));
        // The hotspot: measured in a bake (not the all-1 default), kept through a file, and
        // a factor out of range refused.
        let measured = sample();
        assert_ne!(
            measured.hotspot,
            crate::lighting::hotspot::Hotspot::default()
        );
        assert_eq!(
            decode(&encode(&measured)).unwrap().hotspot,
            measured.hotspot
        );
        let mut bad_hotspot = sample();
        bad_hotspot.hotspot.bounce[2] = 0.0;
        assert!(matches!(
            validate(&bad_hotspot),
            Err(FormatError::Invalid(_))
        ));
        bad_hotspot.hotspot.bounce[2] = f32::NAN;
        assert!(matches!(
            validate(&bad_hotspot),
            Err(FormatError::Invalid(_))
        ));
        let mut bad_tau = sample();
        bad_tau.extinction = f32::NAN;
        assert!(matches!(
            decode(&encode(&bad_tau)),
            Err(FormatError::Invalid(_))
        ));
        for opacity in [0.0, -0.5, 1.5, f32::NAN] {
            let mut bad_opacity = sample();
            bad_opacity.leaf_opacity = opacity;
            assert!(matches!(
                decode(&encode(&bad_opacity)),
                Err(FormatError::Invalid(_))
            ));
        }
        assert_eq!(
            decode(&bytes[..bytes.len() - 1]),
            Err(FormatError::Truncated)
        );
        assert_eq!(decode(&bytes[..30]), Err(FormatError::Truncated));
        // Flip one bit in every region of the payload: always an error, never a panic.
        for at in (20..bytes.len() - 8).step_by(97) {
            let mut corrupt = bytes.clone();
            corrupt[at] ^= 0x10;
            assert_eq!(
                decode(&corrupt),
                Err(FormatError::Checksum),
                "bit flip at {at}"
            );
        }
        // A consistent checksum over inconsistent content is caught by validation.
        let mut b = sample();
        b.indices[3] = b.positions.len() as u32 + 5;
        assert!(
            matches!(decode(&encode(&b)), Err(FormatError::Invalid(s)) if s.contains("out of range"))
        );
        let mut b = sample();
        b.cell_first_leaf.swap(1, 2);
        assert!(matches!(decode(&encode(&b)), Err(FormatError::Invalid(_))));
        let err = load(Path::new("/nonexistent/tree.foliage")).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/tree.foliage"));
    }
}
