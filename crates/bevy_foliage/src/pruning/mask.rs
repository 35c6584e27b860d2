//! The alpha mask of a leaf texture, as the bake sees it.
//!
//! Leaves are usually *cards*: quads textured with an alpha-masked leaf (or a cluster of leaves)
//! whose transparent texels the material discards. The visibility bake must rasterise them the
//! same way, or a card's transparent part hides the leaves behind it and those leaves are pruned
//! as hidden ([`super::visibility`]). An [`AlphaMask`] holds the texture's alpha and the
//! material's cutoff: a texel is opaque when its alpha reaches the cutoff, the test Bevy's
//! `AlphaMode::Mask` fragment stage makes (`alpha < cutoff` is discarded). Lookups are nearest
//! texel with repeat wrapping, glTF's default sampler.
//!
//! The same mask gives the *opaque fraction* of the leaves (the share of their area that is
//! opaque), which the sub-pixel fade needs ([`super::appearance::fade_shrink`]): measured over
//! each leaf's own texture coordinates, so atlas textures whose leaves use a part of the image
//! are measured on that part.

use super::leaves::LeafSet;
use bevy::math::{Vec2, Vec3};
use std::collections::HashMap;

/// Why a mask could not be made.
#[derive(Clone, Debug, PartialEq)]
pub enum MaskError {
    /// The image has no texel.
    Empty,
    /// The data does not hold `width × height` texels of the given size.
    Size {
        /// Texels wide.
        width: u32,
        /// Texels high.
        height: u32,
        /// Bytes given.
        bytes: usize,
    },
}

impl std::fmt::Display for MaskError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Empty => write!(f, "the leaf texture has no texel"),
            Self::Size {
                width,
                height,
                bytes,
            } => write!(
                f,
                "the leaf texture data ({bytes} bytes) does not match its size {width}×{height}"
            ),
        }
    }
}

impl std::error::Error for MaskError {}

/// A leaf texture's alpha and the cutoff of its material.
#[derive(Clone, Debug, PartialEq)]
pub struct AlphaMask {
    width: u32,
    height: u32,
    opaque: Vec<bool>,
    cutoff: f32,
}

impl AlphaMask {
    /// A mask from one alpha byte per texel (row-major, first row at `v = 0`) and the material's
    /// alpha cutoff (clamped to `[0, 1]`; a non-finite cutoff is taken as glTF's default 0.5).
    pub fn new(width: u32, height: u32, alpha: &[u8], cutoff: f32) -> Result<Self, MaskError> {
        Self::from_strided(width, height, alpha, 1, 0, cutoff)
    }

    /// A mask from 8-bit RGBA texels (row-major), reading the alpha channel.
    pub fn from_rgba8(
        width: u32,
        height: u32,
        rgba: &[u8],
        cutoff: f32,
    ) -> Result<Self, MaskError> {
        Self::from_strided(width, height, rgba, 4, 3, cutoff)
    }

    fn from_strided(
        width: u32,
        height: u32,
        data: &[u8],
        stride: usize,
        channel: usize,
        cutoff: f32,
    ) -> Result<Self, MaskError> {
        let texels = width as usize * height as usize;
        if texels == 0 {
            return Err(MaskError::Empty);
        }
        if data.len() != texels * stride {
            return Err(MaskError::Size {
                width,
                height,
                bytes: data.len(),
            });
        }
        let cutoff = if cutoff.is_finite() {
            cutoff.clamp(0.0, 1.0)
        } else {
            0.5
        };
        let opaque = data
            .chunks_exact(stride)
            .map(|t| t[channel] as f32 / 255.0 >= cutoff)
            .collect();
        Ok(Self {
            width,
            height,
            opaque,
            cutoff,
        })
    }

    /// Texels wide.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Texels high.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The alpha cutoff.
    pub fn cutoff(&self) -> f32 {
        self.cutoff
    }

    /// Whether the texel at texture coordinates `uv` is opaque (nearest texel, repeat wrap).
    /// Non-finite coordinates read as transparent.
    pub fn opaque_at(&self, uv: Vec2) -> bool {
        if !uv.is_finite() {
            return false;
        }
        let texel = |t: f32, n: u32| ((t - t.floor()) * n as f32).min(n as f32 - 1.0) as usize;
        let (x, y) = (texel(uv.x, self.width), texel(uv.y, self.height));
        self.opaque[y * self.width as usize + x]
    }

    /// The fraction of the whole image that is opaque.
    pub fn opaque_fraction(&self) -> f32 {
        self.opaque.iter().filter(|&&o| o).count() as f32 / self.opaque.len() as f32
    }

    /// The opaque share of the leaves' area: each leaf triangle's texture footprint is sampled on
    /// a barycentric lattice at least as fine as the texels it covers, and weighted by the
    /// triangle's area in model space. `None` when the leaves have no area.
    pub fn opaque_fraction_of(&self, leaves: &LeafSet) -> Option<f32> {
        // Cards share their texture coordinates: measure each distinct footprint once.
        let mut measured: HashMap<[u32; 6], f32> = HashMap::new();
        let (mut opaque_area, mut area) = (0.0f64, 0.0f64);
        for leaf in 0..leaves.len() {
            let range = leaves.leaves[leaf].clone();
            for t in leaves.indices[range.start as usize..range.end as usize].chunks_exact(3) {
                let (Some(p), Some(uv)) = (
                    t.iter()
                        .map(|&i| leaves.positions.get(i as usize).copied())
                        .collect::<Option<Vec<Vec3>>>(),
                    t.iter()
                        .map(|&i| Some(leaves.uvs.get(i as usize).copied().unwrap_or(Vec2::ZERO)))
                        .collect::<Option<Vec<Vec2>>>(),
                ) else {
                    continue;
                };
                let a = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
                if !a.is_finite() || a <= 0.0 {
                    continue;
                }
                let key = [
                    uv[0].x.to_bits(),
                    uv[0].y.to_bits(),
                    uv[1].x.to_bits(),
                    uv[1].y.to_bits(),
                    uv[2].x.to_bits(),
                    uv[2].y.to_bits(),
                ];
                let fraction = *measured
                    .entry(key)
                    .or_insert_with(|| self.footprint_fraction([uv[0], uv[1], uv[2]]));
                opaque_area += (a * fraction) as f64;
                area += a as f64;
            }
        }
        (area > 0.0).then(|| (opaque_area / area) as f32)
    }

    /// The opaque fraction of one triangle's texture footprint.
    fn footprint_fraction(&self, uv: [Vec2; 3]) -> f32 {
        let size = Vec2::new(self.width as f32, self.height as f32);
        let extent = uv
            .iter()
            .flat_map(|a| {
                uv.iter()
                    .map(move |b| ((*a - *b) * size).abs().max_element())
            })
            .fold(0.0f32, f32::max);
        // Two samples per texel along the longest edge, between 4 and 256 per side.
        let k = if extent.is_finite() {
            (extent * 2.0).ceil().clamp(4.0, 256.0) as u32
        } else {
            4
        };
        let (mut opaque, mut total) = (0u32, 0u32);
        for i in 0..k {
            for j in 0..k - i {
                // Points at the centres of the lattice's sub-triangles (strictly inside).
                let (a, b) = (
                    (i as f32 + 1.0 / 3.0) / k as f32,
                    (j as f32 + 1.0 / 3.0) / k as f32,
                );
                let p = uv[0] + (uv[1] - uv[0]) * a + (uv[2] - uv[0]) * b;
                opaque += self.opaque_at(p) as u32;
                total += 1;
            }
        }
        opaque as f32 / total.max(1) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4×4 mask whose left half is opaque.
    fn half() -> AlphaMask {
        let alpha: Vec<u8> = (0..16).map(|i| if i % 4 < 2 { 255 } else { 0 }).collect();
        AlphaMask::new(4, 4, &alpha, 0.5).unwrap()
    }

    #[test]
    fn lookups_follow_the_cutoff_and_wrap() {
        let m = half();
        assert!(m.opaque_at(Vec2::new(0.1, 0.5)));
        assert!(!m.opaque_at(Vec2::new(0.9, 0.5)));
        // Repeat wrapping, as glTF's default sampler.
        assert!(m.opaque_at(Vec2::new(1.1, -0.5)));
        assert!(!m.opaque_at(Vec2::new(-0.1, 0.5)));
        assert!(!m.opaque_at(Vec2::new(f32::NAN, 0.5)));
        assert_eq!(m.opaque_fraction(), 0.5);
        // The cutoff decides: alpha 128 is opaque at 0.5, not at 0.6.
        let mid = AlphaMask::new(1, 1, &[128], 0.5).unwrap();
        assert!(mid.opaque_at(Vec2::ZERO));
        assert!(
            !AlphaMask::new(1, 1, &[128], 0.6)
                .unwrap()
                .opaque_at(Vec2::ZERO)
        );
        let rgba = AlphaMask::from_rgba8(2, 1, &[9, 9, 9, 255, 9, 9, 9, 0], 0.5).unwrap();
        assert_eq!(rgba.opaque_fraction(), 0.5);
    }

    #[test]
    fn bad_sizes_are_errors() {
        assert_eq!(AlphaMask::new(0, 4, &[], 0.5), Err(MaskError::Empty));
        assert!(matches!(
            AlphaMask::from_rgba8(2, 2, &[0; 15], 0.5),
            Err(MaskError::Size { bytes: 15, .. })
        ));
        assert_eq!(
            AlphaMask::new(1, 1, &[200], f32::NAN).unwrap().cutoff(),
            0.5
        );
    }

    #[test]
    fn opaque_fraction_is_measured_over_the_leaves_footprints() {
        let m = half();
        let quad = |set: &mut LeafSet, u0: f32, u1: f32| {
            let l = set.push_quad(
                [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
                Vec3::Z,
            );
            let r = set.leaves[l].clone();
            let vs: Vec<u32> = set.indices[r.start as usize..r.end as usize].to_vec();
            for (v, uv) in [vs[0], vs[1], vs[2], vs[5]].into_iter().zip([
                Vec2::new(u0, 1.0),
                Vec2::new(u1, 1.0),
                Vec2::new(u1, 0.0),
                Vec2::new(u0, 0.0),
            ]) {
                set.uvs[v as usize] = uv;
            }
        };
        let mut whole = LeafSet::default();
        quad(&mut whole, 0.0, 1.0);
        let f = m.opaque_fraction_of(&whole).unwrap();
        assert!((f - 0.5).abs() < 0.02, "{f}");
        // Leaves using only the opaque half of an atlas are opaque.
        let mut left = LeafSet::default();
        quad(&mut left, 0.0, 0.5);
        quad(&mut left, 0.05, 0.45);
        assert!(m.opaque_fraction_of(&left).unwrap() > 0.99);
        // Mixed: one opaque leaf, one transparent, equal areas.
        let mut mixed = LeafSet::default();
        quad(&mut mixed, 0.0, 0.5);
        quad(&mut mixed, 0.5, 1.0);
        let f = m.opaque_fraction_of(&mixed).unwrap();
        assert!((f - 0.5).abs() < 0.02, "{f}");
        assert_eq!(m.opaque_fraction_of(&LeafSet::default()), None);
    }
}
