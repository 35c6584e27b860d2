//! The base patch as volume slices (Boulanger 2008, thesis §4.2.3, §4.3.2): `K` vertical slices
//! across x, `K` across z and one horizontal slice, each an image of the blades in its slab as an
//! orthographic camera sees them, baked once per species and drawn in place of the blades at
//! middle and far distance.
//!
//! Every slice image has [`LAYERS`] layers, the thesis' BTF rows: the unlit row (the blades'
//! ambient reflectance `kd·ao` and coverage), the density-threshold row (the nearest blade's
//! `dth`, so a slice thins with the density map exactly as the blades do), and for each of the
//! five baked light directions ([`BTF_DIRECTIONS`]) the blades' direct response
//! `kd·((1 − γ)·max(n·l, 0) + γ·max(−n·l, 0))` seen from the slice's front and from its back:
//! eq. 4.1 without its ambient term, with the energy split of Bevy's diffuse transmission (the
//! lit face keeps `1 − γ`), so the slices answer light as the blade geometry drawn by Bevy's PBR
//! does. At run time the five are blended by the spherical barycentric weights of appendix A.
//!
//! Slice `s` is `0..K` across x (slab `[k, k+1]·size/K` in x, seen along −x from its front, +x
//! from its back), `K..2K` across z, and `2K` the horizontal slice seen from above (front only).
//! [`SliceLayout::project`] is the camera of each: a patch-space point's texel coordinates and
//! depth. [`bake_reference`] is the CPU reference of the GPU bake (`grass::bake`), by the same
//! cameras, triangle by triangle.

use super::field::GrassSpecies;
use super::lighting::{BTF_DIRECTIONS, ShadowMask};
use super::patch::BasePatch;
use super::slice_mip::{MipAlpha, RgbaLevel, mip_chain_with};
use bevy::math::{Vec2, Vec3};

/// Layers of each slice image.
pub const LAYERS: u32 = 12;
/// The unlit layer: rgb `kd·ao`, a coverage.
pub const LAYER_UNLIT: u32 = 0;
/// The density-threshold layer: r the nearest blade's threshold, g its height fraction,
/// a coverage.
pub const LAYER_THRESHOLD: u32 = 1;

/// The layer of baked light direction `direction` (an index into [`BTF_DIRECTIONS`]) seen from
/// the slice's front or back.
pub fn lit_layer(direction: usize, back: bool) -> u32 {
    2 + direction as u32 + if back { 5 } else { 0 }
}

/// Which way a slice faces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SliceAxis {
    /// A vertical slice across x (normal +x).
    X,
    /// A vertical slice across z (normal +z).
    Z,
    /// The horizontal slice (normal +y).
    Horizontal,
}

/// The slices of one base patch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SliceLayout {
    /// The patch's side (m).
    pub size: f32,
    /// Height of the vertical slices (m): the tallest blade point, with a margin.
    pub height: f32,
    /// Vertical slices per axis (`K`).
    pub per_axis: u32,
    /// Texels a side of each slice image.
    pub resolution: u32,
}

/// Where a patch-space point lands in a slice image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projected {
    /// Texel coordinates (column, row; texel `(c, r)` spans `[c, c+1) × [r, r+1)`).
    pub texel: Vec2,
    /// Distance from the camera's plane, in `[0, depth_range]` for points the slice holds.
    pub depth: f32,
}

impl SliceLayout {
    /// The layout for `patch` with `per_axis` vertical slices a side and images of
    /// `resolution²` texels.
    pub fn new(patch: &BasePatch, per_axis: u32, resolution: u32) -> Self {
        let tallest = patch.blades.iter().map(|b| b.height).fold(0.0f32, f32::max);
        Self {
            size: patch.size,
            height: (tallest * 1.02).max(1e-3),
            per_axis: per_axis.max(1),
            resolution: resolution.max(1),
        }
    }

    /// Slices in all: `2K + 1`.
    pub fn slices(&self) -> u32 {
        2 * self.per_axis + 1
    }

    /// The axis and index along it of slice `s`.
    pub fn slice(&self, s: u32) -> (SliceAxis, u32) {
        let k = self.per_axis;
        if s < k {
            (SliceAxis::X, s)
        } else if s < 2 * k {
            (SliceAxis::Z, s - k)
        } else {
            (SliceAxis::Horizontal, 0)
        }
    }

    /// The slab of a vertical slice `k` along its axis: `[lo, hi]`.
    pub fn slab(&self, k: u32) -> (f32, f32) {
        let w = self.size / self.per_axis as f32;
        (k as f32 * w, (k + 1) as f32 * w)
    }

    /// How deep slice `s`'s camera sees.
    pub fn depth_range(&self, s: u32) -> f32 {
        match self.slice(s).0 {
            SliceAxis::Horizontal => self.height,
            _ => self.size / self.per_axis as f32,
        }
    }

    /// Whether slice `s` has back layers (the horizontal slice is seen from above only).
    pub fn has_back(&self, s: u32) -> bool {
        self.slice(s).0 != SliceAxis::Horizontal
    }

    /// The unit direction from the slice towards its camera, from the front or the back.
    pub fn view_direction(&self, s: u32, back: bool) -> Vec3 {
        let sign = if back { -1.0 } else { 1.0 };
        match self.slice(s).0 {
            SliceAxis::X => Vec3::X * sign,
            SliceAxis::Z => Vec3::Z * sign,
            SliceAxis::Horizontal => Vec3::Y,
        }
    }

    /// The camera of slice `s` (front or back): where patch-space point `p` lands.
    pub fn project(&self, s: u32, back: bool, p: Vec3) -> Projected {
        let (axis, k) = self.slice(s);
        let res = self.resolution as f32;
        let (size, height) = (self.size, self.height);
        let row = (height - p.y) / height * res;
        let (texel, depth) = match (axis, back) {
            (SliceAxis::X, false) => {
                let (_, hi) = self.slab(k);
                (Vec2::new((size - p.z) / size * res, row), hi - p.x)
            }
            (SliceAxis::X, true) => {
                let (lo, _) = self.slab(k);
                (Vec2::new(p.z / size * res, row), p.x - lo)
            }
            (SliceAxis::Z, false) => {
                let (_, hi) = self.slab(k);
                (Vec2::new(p.x / size * res, row), hi - p.z)
            }
            (SliceAxis::Z, true) => {
                let (lo, _) = self.slab(k);
                (Vec2::new((size - p.x) / size * res, row), p.z - lo)
            }
            (SliceAxis::Horizontal, _) => {
                (Vec2::new(p.x / size * res, p.z / size * res), height - p.y)
            }
        };
        Projected { texel, depth }
    }

    /// Texels of one slice image layer.
    pub fn texels_per_layer(&self) -> usize {
        (self.resolution * self.resolution) as usize
    }

    /// Index of texel `(c, r)` of layer `layer` of slice `s` in [`SliceTextures::texels`].
    pub fn index(&self, s: u32, layer: u32, c: u32, r: u32) -> usize {
        ((s * LAYERS + layer) as usize) * self.texels_per_layer()
            + (r * self.resolution + c) as usize
    }
}

/// The slice images of one species: `slices × LAYERS` layers of `resolution²` linear RGBA
/// texels (straight alpha), layer-major.
#[derive(Clone, Debug, PartialEq)]
pub struct SliceTextures {
    /// The slices.
    pub layout: SliceLayout,
    /// Every layer's texels.
    pub texels: Vec<[f32; 4]>,
}

impl SliceTextures {
    /// All transparent.
    pub fn empty(layout: SliceLayout) -> Self {
        Self {
            layout,
            texels: vec![
                [0.0; 4];
                layout.slices() as usize * LAYERS as usize * layout.texels_per_layer()
            ],
        }
    }

    /// Layer `layer` of slice `s`.
    pub fn layer(&self, s: u32, layer: u32) -> &[[f32; 4]] {
        let start = self.layout.index(s, layer, 0, 0);
        &self.texels[start..start + self.layout.texels_per_layer()]
    }

    /// The blade shadow mask (§4.2.6) these slices hold: one minus the coverage of the vertical
    /// slices' unlit layers — each a thick slab of the patch seen orthographically — averaged
    /// over all of them.
    pub fn shadow_mask(&self) -> ShadowMask {
        let l = self.layout;
        let vertical = 2 * l.per_axis;
        ShadowMask::from_coverage(
            l.resolution,
            l.resolution,
            |c, r| {
                (0..vertical)
                    .map(|s| self.texels[l.index(s, LAYER_UNLIT, c, r)][3])
                    .sum::<f32>()
                    / vertical as f32
            },
            l.size,
            l.height,
        )
    }

    /// Each layer's mip chain by the slices' custom filter ([`super::slice_mip`]) with its alpha
    /// made as `alpha` says, layer by layer: `result[layer][level]`.
    pub fn mips(&self, alpha: MipAlpha) -> Vec<Vec<RgbaLevel>> {
        (0..self.layout.slices() * LAYERS)
            .map(|l| {
                let start = l as usize * self.layout.texels_per_layer();
                mip_chain_with(
                    &RgbaLevel {
                        width: self.layout.resolution,
                        height: self.layout.resolution,
                        texels: self.texels[start..start + self.layout.texels_per_layer()].to_vec(),
                    },
                    alpha,
                )
            })
            .collect()
    }
}

/// What a slice layer records at a blade point: `kd` the blade's colour there, `ao` its
/// occlusion, `threshold` and `height_fraction` the blade's, `n` its unit normal, `view` the unit
/// direction to the camera, `gamma` the transmission.
#[allow(clippy::too_many_arguments)]
pub fn layer_value(
    layer: u32,
    kd: Vec3,
    ao: f32,
    threshold: f32,
    height_fraction: f32,
    n: Vec3,
    view: Vec3,
    gamma: f32,
) -> [f32; 4] {
    match layer {
        LAYER_UNLIT => {
            let c = kd * ao;
            [c.x, c.y, c.z, 1.0]
        }
        LAYER_THRESHOLD => [threshold, height_fraction, 0.0, 1.0],
        _ => {
            // The face towards the camera is the lit or the transmitting one (eq. 4.1).
            let n = if n.dot(view) < 0.0 { -n } else { n };
            let l = BTF_DIRECTIONS[((layer - 2) % 5) as usize];
            let cos = n.dot(l);
            let c = kd * ((1.0 - gamma) * cos.max(0.0) + gamma * (-cos).max(0.0));
            [c.x, c.y, c.z, 1.0]
        }
    }
}

/// The blade colour (`kd`) and ambient occlusion of `species` at height fraction `h`.
pub fn blade_shade(species: &GrassSpecies, h: f32) -> (Vec3, f32) {
    let h = h.clamp(0.0, 1.0);
    let root = Vec3::new(
        species.root_color.red,
        species.root_color.green,
        species.root_color.blue,
    );
    let tip = Vec3::new(
        species.tip_color.red,
        species.tip_color.green,
        species.tip_color.blue,
    );
    (
        root.lerp(tip, h),
        species.root_ao + (1.0 - species.root_ao) * h,
    )
}

/// One vertex of the base patch's mesh as the bake sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakeVertex {
    /// Patch-space position.
    pub position: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    /// The blade's density threshold.
    pub threshold: f32,
    /// Height fraction along the blade.
    pub height_fraction: f32,
}

/// The CPU reference of the GPU slice bake: every triangle of `triangles` (the base patch mesh)
/// rasterised into every layer of every slice by [`SliceLayout::project`], texel centres inside
/// the triangle and within the camera's depth range, the nearest point winning, shaded by
/// [`layer_value`] with the normal interpolated across the triangle.
pub fn bake_reference(
    layout: &SliceLayout,
    species: &GrassSpecies,
    triangles: &[[BakeVertex; 3]],
) -> SliceTextures {
    let mut out = SliceTextures::empty(*layout);
    let res = layout.resolution;
    let texels = layout.texels_per_layer();
    for s in 0..layout.slices() {
        for back in [false, true] {
            if back && !layout.has_back(s) {
                continue;
            }
            let view = layout.view_direction(s, back);
            let range = layout.depth_range(s);
            // Nearest depth and the winning point's interpolated attributes, per texel.
            let mut depth = vec![f32::INFINITY; texels];
            let mut hit: Vec<Option<(Vec3, f32, f32)>> = vec![None; texels];
            for tri in triangles {
                let p = tri.map(|v| layout.project(s, back, v.position));
                let (a, b, c) = (p[0].texel, p[1].texel, p[2].texel);
                let area = (b - a).perp_dot(c - a);
                if area.abs() < 1e-12 {
                    continue;
                }
                let lo = a.min(b).min(c).floor().max(Vec2::ZERO);
                let hi = a.max(b).max(c).ceil().min(Vec2::splat(res as f32));
                for r in lo.y as u32..hi.y as u32 {
                    for col in lo.x as u32..hi.x as u32 {
                        let q = Vec2::new(col as f32 + 0.5, r as f32 + 0.5);
                        let w0 = (b - q).perp_dot(c - q) / area;
                        let w1 = (c - q).perp_dot(a - q) / area;
                        let w2 = 1.0 - w0 - w1;
                        if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                            continue;
                        }
                        let d = w0 * p[0].depth + w1 * p[1].depth + w2 * p[2].depth;
                        let i = (r * res + col) as usize;
                        if !(0.0..=range).contains(&d) || d >= depth[i] {
                            continue;
                        }
                        depth[i] = d;
                        let n = tri[0].normal * w0 + tri[1].normal * w1 + tri[2].normal * w2;
                        let h = tri[0].height_fraction * w0
                            + tri[1].height_fraction * w1
                            + tri[2].height_fraction * w2;
                        hit[i] = Some((n.normalize_or(Vec3::Y), tri[0].threshold, h));
                    }
                }
            }
            for (i, h) in hit.iter().enumerate() {
                let Some((n, threshold, h)) = *h else {
                    continue;
                };
                let (kd, ao) = blade_shade(species, h);
                let (c, r) = (i as u32 % res, i as u32 / res);
                let layers: Vec<u32> = if back {
                    (0..5).map(|d| lit_layer(d, true)).collect()
                } else {
                    [LAYER_UNLIT, LAYER_THRESHOLD]
                        .into_iter()
                        .chain((0..5).map(|d| lit_layer(d, false)))
                        .collect()
                };
                for layer in layers {
                    out.texels[layout.index(s, layer, c, r)] =
                        layer_value(layer, kd, ao, threshold, h, n, view, species.transmission);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grass::patch::{Blade, PatchSettings};

    fn one_blade_patch() -> BasePatch {
        BasePatch {
            size: 0.5,
            blades: vec![Blade {
                root: Vec2::new(0.1, 0.3),
                threshold: 0.4,
                height: 0.3,
                lean: Vec2::X,
                bend: 0.0,
            }],
        }
    }

    #[test]
    fn the_cameras_see_each_slab_from_both_sides() {
        let layout = SliceLayout::new(&BasePatch::generate(&PatchSettings::default()), 4, 64);
        assert_eq!(layout.slices(), 9);
        assert_eq!(layout.slice(5), (SliceAxis::Z, 1));
        assert_eq!(layout.slice(8), (SliceAxis::Horizontal, 0));
        // A point in x-slab 1 (x ∈ [0.125, 0.25]) near z = 0: front camera (looking −x) puts it
        // at the image's right edge, the back camera at the left; the depths add up to the slab.
        let p = Vec3::new(0.2, layout.height / 2.0, 0.01);
        let (f, b) = (layout.project(1, false, p), layout.project(1, true, p));
        assert!(f.texel.x > 62.0 && b.texel.x < 2.0, "{f:?} {b:?}");
        assert!((f.depth + b.depth - 0.125).abs() < 1e-6);
        assert!((f.texel.y - 32.0).abs() < 1e-3);
        // Outside the slab: out of depth range.
        assert!(layout.project(0, false, p).depth < 0.0);
        // Seen from above, x runs right and z down.
        let top = layout.project(8, false, Vec3::new(0.125, 0.0, 0.375));
        assert_eq!(top.texel, Vec2::new(16.0, 48.0));
        assert!((top.depth - layout.height).abs() < 1e-6);
    }

    /// A straight blade at x = 0.1 leaning along x is a strip in the plane x = 0.1, its faces
    /// towards ±x: the x slice of slab 0 sees it face on from both sides, the other x slices
    /// and the edge-on z and horizontal slices not at all; lit head-on from its camera's side it
    /// returns `(1 − γ)·kd`, from the far side `γ·kd`, from above nothing.
    #[test]
    fn the_reference_puts_a_blade_in_the_slices_of_its_slab_only() {
        let patch = one_blade_patch();
        let species = GrassSpecies::default();
        let layout = SliceLayout::new(&patch, 4, 32);
        let triangles = super::super::mesh::bake_triangles(&patch, 0.04, 4);
        let t = bake_reference(&layout, &species, &triangles);
        let covered = |s: u32, layer: u32| t.layer(s, layer).iter().filter(|p| p[3] > 0.0).count();
        assert!(covered(0, LAYER_UNLIT) > 20, "{}", covered(0, LAYER_UNLIT));
        assert_eq!(covered(0, lit_layer(0, true)), covered(0, LAYER_UNLIT));
        for s in [1, 2, 3, 4, 5, 6, 7, 8] {
            assert_eq!(covered(s, LAYER_UNLIT), 0, "slice {s}");
        }
        // Every covered texel of the threshold layer carries the blade's threshold.
        assert!(
            t.layer(0, LAYER_THRESHOLD)
                .iter()
                .filter(|p| p[3] > 0.0)
                .all(|p| p[0] == 0.4)
        );
        let gamma = species.transmission;
        for back in [false, true] {
            let (toward, away) = if back { (2, 1) } else { (1, 2) };
            let lit = t.layer(0, lit_layer(toward, back));
            let through = t.layer(0, lit_layer(away, back));
            let above = t.layer(0, lit_layer(0, back));
            for i in 0..lit.len() {
                if lit[i][3] == 0.0 {
                    continue;
                }
                assert!(
                    (through[i][1] * (1.0 - gamma) - gamma * lit[i][1]).abs() < 1e-4,
                    "{back} {i}"
                );
                assert!(above[i][1].abs() < 1e-4);
                assert!(lit[i][1] > 0.0);
            }
        }
    }
}
