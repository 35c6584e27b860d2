//! A baked billboard cloud ([`ImpostorData`]) and its on-disk format (`*.bbcloud`): versioned,
//! little-endian, checksummed, written beside the pruning bake.
//!
//! ```text
//! magic    8 bytes  "BNBBCLOU"
//! version  u32      FORMAT_VERSION
//! length   u64      payload bytes
//! payload           header, planes, the albedo and normal atlases (RGBA8, `size × size`
//!                   each), the crown's extinction τ (f32), its eight seen-part gains (f32)
//!                   and the three light atlases
//! checksum u64      FNV-1a 64 of the payload
//! ```
//!
//! Decoding checks what the renderer relies on (finite numbers, unit normals, uv rectangles in
//! [0, 1], atlas byte counts), so a corrupt or mismatched file is a clear [`ImpostorFormatError`],
//! never a panic. Files are written to a temporary name and renamed, so an interrupted write never
//! leaves a truncated cache behind.

use crate::pruning::format::fnv1a64;
use bevy::math::{Vec2, Vec3};
use std::path::Path;

/// File signature.
pub const MAGIC: &[u8; 8] = b"BNBBCLOU";
/// Current format version; bump on any layout change.
///
/// Version 2 added the tree lighting's light atlases and the crown's extinction, version 3 the
/// crown's seen-part gains, version 4 the crown's hotspot, version 5 the crown's mean bounce
/// ratios; an older cache is re-baked.
pub const FORMAT_VERSION: u32 = 5;

/// Light atlases of a billboard cloud: three, of three values a texel each (see
/// `impostor::texture`).
pub const LIGHT_ATLASES: usize = 3;

/// One textured quad of a billboard cloud, in model space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImpostorPlane {
    /// Corners in order (u0,v0), (u1,v0), (u1,v1), (u0,v1) of the plane's rectangle, where `u`
    /// runs along `tangent` and `v` along `normal × tangent`.
    pub corners: [Vec3; 4],
    /// Unit normal (the side the baked normals face).
    pub normal: Vec3,
    /// Unit tangent: the texture's `u` direction.
    pub tangent: Vec3,
    /// Atlas uv of corner 0 (top-left texel corner is `uv_min.x`, bottom is `uv_max.y`).
    pub uv_min: Vec2,
    /// Atlas uv of corner 2.
    pub uv_max: Vec2,
    /// 0 leaves, 1 branches, 2 cardboard (see [`super::cloud::PlaneRole`]).
    pub role: u8,
}

/// A baked billboard cloud: its planes and its four atlases (see `impostor::texture`).
#[derive(Clone, Debug, PartialEq)]
pub struct ImpostorData {
    /// Centre of the tree's bounding sphere (model space).
    pub center: Vec3,
    /// Radius of the tree's bounding sphere.
    pub radius: f32,
    /// The planes.
    pub planes: Vec<ImpostorPlane>,
    /// Side of both atlases in texels.
    pub atlas_size: u32,
    /// Albedo (sRGB) and coverage (alpha), RGBA8, row-major from the top.
    pub albedo: Vec<u8>,
    /// Tangent-space normals (x along the plane's tangent, y along its bitangent, z along its
    /// normal) encoded `0.5 + 0.5·n`, linear RGBA8.
    pub normal: Vec<u8>,
    /// The tree lighting's attenuations of each texel's leaf and whether it is a leaf, three
    /// values an atlas (`texture::SourceLight::texel_of_triangle`, stored as
    /// `texture::encode_light` writes them).
    pub light: [Vec<u8>; LIGHT_ATLASES],
    /// The crown's extinction τ per unit of model space (Boulanger 2008, eq. 5.5).
    pub extinction: f32,
    /// The crown's mean seen-part gain per eye octant (`lighting::seen_part`), by which the
    /// tree lighting scales the leaf texels' sky and blended sun.
    pub seen_gains: [f32; 8],
    /// The crown's mean bounce ratios (`lighting::gathered_bounce`), by which the tree
    /// lighting scales the leaf texels' bounce face by face.
    pub bounce_ratios: crate::lighting::gathered_bounce::BounceRatios,
    /// The crown's hotspot (`lighting::hotspot`), by which the tree lighting raises the leaf
    /// texels' blended sun and scales their bounce by the eye's angle to the sun.
    pub hotspot: crate::lighting::hotspot::Hotspot,
    /// Hash of the source geometry and bake settings: a cache whose hash differs is stale.
    pub source_hash: u64,
    /// How long the bake took (ms), for the report.
    pub bake_ms: f32,
}

impl ImpostorData {
    /// Texture bytes on the GPU of the atlases Bevy's lighting draws with (albedo and normals,
    /// with their mip chains, about 4/3 of level 0).
    pub fn texture_bytes(&self) -> u64 {
        let level0 = self.atlas_size as u64 * self.atlas_size as u64 * 4;
        2 * (level0 * 4).div_ceil(3)
    }

    /// Texture bytes on the GPU of the light atlases the tree lighting adds.
    pub fn light_texture_bytes(&self) -> u64 {
        self.texture_bytes() / 2 * LIGHT_ATLASES as u64
    }

    /// Fraction of atlas texels covered (alpha ≥ 128).
    pub fn atlas_coverage(&self) -> f32 {
        let covered = self.albedo.chunks_exact(4).filter(|p| p[3] >= 128).count();
        covered as f32 / (self.albedo.len() / 4).max(1) as f32
    }
}

/// Why a billboard cloud file could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ImpostorFormatError {
    /// Not a billboard cloud file.
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

impl std::fmt::Display for ImpostorFormatError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BadMagic => write!(f, "not a billboard cloud file (bad signature)"),
            Self::UnsupportedVersion { found, expected } => write!(
                f,
                "billboard cloud format version {found}, this build reads version {expected}: re-bake the impostor"
            ),
            Self::Truncated => write!(f, "billboard cloud file is truncated"),
            Self::Checksum => write!(f, "billboard cloud file is corrupt (checksum mismatch)"),
            Self::Invalid(s) => write!(f, "billboard cloud file is inconsistent: {s}"),
            Self::Io(s) => write!(f, "billboard cloud file: {s}"),
        }
    }
}

impl std::error::Error for ImpostorFormatError {}

fn put_f32s(out: &mut Vec<u8>, values: &[f32]) {
    values
        .iter()
        .for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
}

/// Serialises a baked billboard cloud.
pub fn encode(data: &ImpostorData) -> Vec<u8> {
    let mut p = Vec::with_capacity(64 + data.planes.len() * 80 + data.albedo.len() * 2);
    put_f32s(
        &mut p,
        &[data.center.x, data.center.y, data.center.z, data.radius],
    );
    p.extend_from_slice(&data.source_hash.to_le_bytes());
    put_f32s(&mut p, &[data.bake_ms]);
    p.extend_from_slice(&(data.planes.len() as u32).to_le_bytes());
    for plane in &data.planes {
        for c in plane.corners {
            put_f32s(&mut p, &c.to_array());
        }
        put_f32s(&mut p, &plane.normal.to_array());
        put_f32s(&mut p, &plane.tangent.to_array());
        put_f32s(&mut p, &plane.uv_min.to_array());
        put_f32s(&mut p, &plane.uv_max.to_array());
        p.extend_from_slice(&(plane.role as u32).to_le_bytes());
    }
    p.extend_from_slice(&data.atlas_size.to_le_bytes());
    p.extend_from_slice(&data.albedo);
    p.extend_from_slice(&data.normal);
    put_f32s(&mut p, &[data.extinction]);
    put_f32s(&mut p, &data.seen_gains);
    put_f32s(&mut p, &data.bounce_ratios.front);
    put_f32s(&mut p, &data.bounce_ratios.back);
    for word in data.hotspot.packed() {
        p.extend_from_slice(&word.to_le_bytes());
    }
    for atlas in &data.light {
        p.extend_from_slice(atlas);
    }

    let mut out = Vec::with_capacity(p.len() + 28);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(p.len() as u64).to_le_bytes());
    out.extend_from_slice(&p);
    out.extend_from_slice(&fnv1a64(&p).to_le_bytes());
    out
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], ImpostorFormatError> {
        let end = self
            .at
            .checked_add(n)
            .ok_or(ImpostorFormatError::Truncated)?;
        let s = self
            .bytes
            .get(self.at..end)
            .ok_or(ImpostorFormatError::Truncated)?;
        self.at = end;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32, ImpostorFormatError> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    fn u64(&mut self) -> Result<u64, ImpostorFormatError> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    fn f32(&mut self) -> Result<f32, ImpostorFormatError> {
        let v = f32::from_le_bytes(self.take(4)?.try_into().unwrap());
        if v.is_finite() {
            Ok(v)
        } else {
            Err(ImpostorFormatError::Invalid("non-finite number".into()))
        }
    }
    fn vec2(&mut self) -> Result<Vec2, ImpostorFormatError> {
        Ok(Vec2::new(self.f32()?, self.f32()?))
    }
    fn vec3(&mut self) -> Result<Vec3, ImpostorFormatError> {
        Ok(Vec3::new(self.f32()?, self.f32()?, self.f32()?))
    }
}

/// Largest atlas side a file may declare (keeps a corrupt size from allocating gigabytes).
pub const MAX_ATLAS_SIZE: u32 = 8192;

/// Reads a billboard cloud, checking everything the renderer relies on.
pub fn decode(bytes: &[u8]) -> Result<ImpostorData, ImpostorFormatError> {
    if bytes.len() < 8 || &bytes[..8] != MAGIC {
        return Err(ImpostorFormatError::BadMagic);
    }
    let mut header = Reader { bytes, at: 8 };
    let version = header.u32()?;
    if version != FORMAT_VERSION {
        return Err(ImpostorFormatError::UnsupportedVersion {
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    let length = header.u64()?;
    let start = header.at;
    let end = (start as u64)
        .checked_add(length)
        .filter(|&e| e + 8 == bytes.len() as u64)
        .ok_or(ImpostorFormatError::Truncated)? as usize;
    let payload = &bytes[start..end];
    let stored = u64::from_le_bytes(bytes[end..].try_into().unwrap());
    if fnv1a64(payload) != stored {
        return Err(ImpostorFormatError::Checksum);
    }
    let mut r = Reader {
        bytes: payload,
        at: 0,
    };
    let center = r.vec3()?;
    let radius = r.f32()?;
    let source_hash = r.u64()?;
    let bake_ms = r.f32()?;
    let count = r.u32()? as usize;
    // 4 corners, normal, tangent (3 floats each), two uvs, role: 92 bytes per plane.
    if count.saturating_mul(92) > payload.len() - r.at {
        return Err(ImpostorFormatError::Truncated);
    }
    let mut planes = Vec::with_capacity(count);
    for i in 0..count {
        let corners = [r.vec3()?, r.vec3()?, r.vec3()?, r.vec3()?];
        let normal = r.vec3()?;
        let tangent = r.vec3()?;
        let uv_min = r.vec2()?;
        let uv_max = r.vec2()?;
        let role = r.u32()?;
        let unit = |v: Vec3| (v.length() - 1.0).abs() < 1e-3;
        if !unit(normal) || !unit(tangent) {
            return Err(ImpostorFormatError::Invalid(format!(
                "plane {i}: normal or tangent is not unit length"
            )));
        }
        let in_unit = |v: Vec2| v.cmpge(Vec2::ZERO).all() && v.cmple(Vec2::ONE).all();
        if !in_unit(uv_min) || !in_unit(uv_max) {
            return Err(ImpostorFormatError::Invalid(format!(
                "plane {i}: atlas rectangle outside [0, 1]"
            )));
        }
        if role > 2 {
            return Err(ImpostorFormatError::Invalid(format!(
                "plane {i}: unknown role {role}"
            )));
        }
        planes.push(ImpostorPlane {
            corners,
            normal,
            tangent,
            uv_min,
            uv_max,
            role: role as u8,
        });
    }
    let atlas_size = r.u32()?;
    if atlas_size == 0 || atlas_size > MAX_ATLAS_SIZE {
        return Err(ImpostorFormatError::Invalid(format!(
            "atlas size {atlas_size} outside 1..={MAX_ATLAS_SIZE}"
        )));
    }
    let bytes_per_atlas = atlas_size as usize * atlas_size as usize * 4;
    let albedo = r.take(bytes_per_atlas)?.to_vec();
    let normal = r.take(bytes_per_atlas)?.to_vec();
    let extinction = r.f32()?;
    if extinction < 0.0 {
        return Err(ImpostorFormatError::Invalid(format!(
            "negative extinction {extinction}"
        )));
    }
    let mut seen_gains = [0.0f32; 8];
    for g in &mut seen_gains {
        *g = r.f32()?;
    }
    let (low, high) = crate::lighting::seen_part::GAIN_RANGE;
    if seen_gains.iter().any(|g| !(low..=high).contains(g)) {
        return Err(ImpostorFormatError::Invalid(format!(
            "seen-part gains {seen_gains:?} outside {low}..={high}"
        )));
    }
    let mut bounce_ratios = crate::lighting::gathered_bounce::BounceRatios::default();
    for ratio in bounce_ratios
        .front
        .iter_mut()
        .chain(bounce_ratios.back.iter_mut())
    {
        *ratio = r.f32()?;
    }
    let max = crate::lighting::gathered_bounce::RATIO_MAX;
    if bounce_ratios
        .front
        .iter()
        .chain(&bounce_ratios.back)
        .any(|r| !(0.0..=max).contains(r))
    {
        return Err(ImpostorFormatError::Invalid(format!(
            "bounce ratios {bounce_ratios:?} outside 0..={max}"
        )));
    }
    let mut words = [0u32; crate::lighting::hotspot::HOTSPOT_WORDS];
    for w in &mut words {
        *w = r.u32()?;
    }
    let hotspot = crate::lighting::hotspot::Hotspot::unpacked(words);
    if hotspot.sanitized().1 {
        return Err(ImpostorFormatError::Invalid(format!(
            "hotspot factors {:?} / {:?} outside {:?}",
            hotspot.sun,
            hotspot.bounce,
            crate::lighting::hotspot::HOTSPOT_RANGE
        )));
    }
    let light = [
        r.take(bytes_per_atlas)?.to_vec(),
        r.take(bytes_per_atlas)?.to_vec(),
        r.take(bytes_per_atlas)?.to_vec(),
    ];
    if r.at != payload.len() {
        return Err(ImpostorFormatError::Truncated);
    }
    if radius <= 0.0 || planes.is_empty() {
        return Err(ImpostorFormatError::Invalid(
            "no planes or a zero bounding radius".into(),
        ));
    }
    Ok(ImpostorData {
        center,
        radius,
        planes,
        atlas_size,
        albedo,
        normal,
        light,
        extinction,
        seen_gains,
        bounce_ratios,
        hotspot,
        source_hash,
        bake_ms,
    })
}

/// Writes a billboard cloud to `path` (through a temporary file and a rename).
pub fn save(data: &ImpostorData, path: &Path) -> Result<(), ImpostorFormatError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| ImpostorFormatError::Io(e.to_string()))?;
    }
    let tmp = path.with_extension(format!("bbcloud.tmp{}", std::process::id()));
    std::fs::write(&tmp, encode(data))
        .and_then(|_| std::fs::rename(&tmp, path))
        .map_err(|e| {
            std::fs::remove_file(&tmp).ok();
            ImpostorFormatError::Io(format!("{}: {e}", path.display()))
        })
}

/// Reads a billboard cloud file.
pub fn load(path: &Path) -> Result<ImpostorData, ImpostorFormatError> {
    let bytes = std::fs::read(path)
        .map_err(|e| ImpostorFormatError::Io(format!("{}: {e}", path.display())))?;
    decode(&bytes)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn sample() -> ImpostorData {
        let size = 8;
        ImpostorData {
            center: Vec3::new(0.0, 4.0, 0.0),
            radius: 3.0,
            planes: vec![ImpostorPlane {
                corners: [
                    Vec3::new(-1.0, 1.0, 0.0),
                    Vec3::new(1.0, 1.0, 0.0),
                    Vec3::new(1.0, 7.0, 0.0),
                    Vec3::new(-1.0, 7.0, 0.0),
                ],
                normal: Vec3::Z,
                tangent: Vec3::X,
                uv_min: Vec2::new(0.0, 0.0),
                uv_max: Vec2::new(0.5, 1.0),
                role: 1,
            }],
            atlas_size: size,
            albedo: (0..size * size * 4).map(|i| i as u8).collect(),
            normal: (0..size * size * 4).map(|i| (i * 7) as u8).collect(),
            light: [
                (0..size * size * 4).map(|i| (i * 3) as u8).collect(),
                (0..size * size * 4).map(|i| (i * 5) as u8).collect(),
                (0..size * size * 4).map(|i| (i * 11) as u8).collect(),
            ],
            extinction: 1.5,
            seen_gains: [1.0, 1.1, 1.2, 1.3, 0.9, 1.0, 1.05, 1.15],
            bounce_ratios: crate::lighting::gathered_bounce::BounceRatios {
                front: std::array::from_fn(|k| 0.5 + 0.1 * k as f32),
                back: std::array::from_fn(|k| 3.0 - 0.2 * k as f32),
            },
            hotspot: crate::lighting::hotspot::Hotspot {
                sun: [0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0],
                bounce: [1.0, 0.875, 0.75, 0.625, 0.5, 0.375, 0.25, 0.125],
            },
            source_hash: 0xDEAD_BEEF,
            bake_ms: 12.5,
        }
    }

    #[test]
    fn round_trips_through_a_file() {
        let data = sample();
        let dir = std::env::temp_dir().join(format!("bbcloud-{}", std::process::id()));
        let path = dir.join("sample.bbcloud");
        save(&data, &path).unwrap();
        assert_eq!(load(&path).unwrap(), data);
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn corrupt_or_mismatched_files_are_clear_errors() {
        let bytes = encode(&sample());
        assert_eq!(decode(b"nonsense"), Err(ImpostorFormatError::BadMagic));
        let mut flipped = bytes.clone();
        let middle = flipped.len() / 2;
        flipped[middle] ^= 0x40;
        assert_eq!(decode(&flipped), Err(ImpostorFormatError::Checksum));
        let mut old = bytes.clone();
        old[8] = 99;
        assert!(matches!(
            decode(&old),
            Err(ImpostorFormatError::UnsupportedVersion { found: 99, .. })
        ));
        for cut in [9, 20, bytes.len() - 1] {
            assert_eq!(decode(&bytes[..cut]), Err(ImpostorFormatError::Truncated));
        }
        // Consistent checksum but nonsense content: a plane outside the atlas.
        let mut bad = sample();
        bad.planes[0].uv_max = Vec2::new(1.5, 1.0);
        assert!(matches!(
            decode(&encode(&bad)),
            Err(ImpostorFormatError::Invalid(_))
        ));
        let mut bad = sample();
        bad.planes[0].normal = Vec3::new(0.0, 0.0, 2.0);
        assert!(matches!(
            decode(&encode(&bad)),
            Err(ImpostorFormatError::Invalid(_))
        ));
        let mut bad = sample();
        bad.planes.clear();
        assert!(matches!(
            decode(&encode(&bad)),
            Err(ImpostorFormatError::Invalid(_))
        ));
        let mut bad = sample();
        bad.extinction = -1.0;
        assert!(matches!(
            decode(&encode(&bad)),
            Err(ImpostorFormatError::Invalid(_))
        ));
        for ratio in [f32::NAN, -0.5, 17.0] {
            let mut bad = sample();
            bad.bounce_ratios.back[5] = ratio;
            assert!(matches!(
                decode(&encode(&bad)),
                Err(ImpostorFormatError::Invalid(_))
            ));
        }
        for gain in [f32::NAN, 0.0, 9.0] {
            let mut bad = sample();
            bad.seen_gains[3] = gain;
            assert!(matches!(
                decode(&encode(&bad)),
                Err(ImpostorFormatError::Invalid(_))
            ));
        }
        // An atlas size whose bytes are not there.
        let mut bad = sample();
        bad.atlas_size = 16;
        assert_eq!(decode(&encode(&bad)), Err(ImpostorFormatError::Truncated));
    }
}
