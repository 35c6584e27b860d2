//! The base grass patch and its tiling (Boulanger 2008, thesis §4.2.1–4.2.2, §4.2.7.1): one small
//! square of blades repeated on a grid over the ground, each cell showing one of its four mirrored
//! versions so the repetition does not show, and each blade a two-sided quad strip along the
//! trajectory of a particle launched from its root under gravity.
//!
//! Roots are placed by stratified sampling (one at random in each cell of a fine grid: a random
//! yet uniform spread, so no clump repeats with the tiling), and each blade carries a density
//! threshold, uniform in ]0, 1] over the patch, so that any local density keeps that fraction of
//! the blades. The thesis draws the thresholds at random; here they are stratified too — an 8 × 8
//! ordered-dither (Bayer) rank over the strata, jittered within its 1/64 — so the blades a density
//! keeps are that fraction to within 1/64 in every 8 × 8 block of strata, spread evenly rather
//! than in random clumps.

use crate::rng::SplitMix64;
use bevy::math::{Vec2, Vec3};
use bevy::reflect::Reflect;

/// How the base patch's blades are made.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
#[reflect(Debug, PartialEq)]
pub struct PatchSettings {
    /// Side of the square patch (m; 0.5 in the thesis' figures).
    pub size: f32,
    /// Strata a side: `strata²` blades, one in each.
    pub strata: u32,
    /// Blade height range (m).
    pub height: (f32, f32),
    /// Blade width at the root (m).
    pub width: f32,
    /// Horizontal launch speed as a fraction of the vertical one: how far the blade bends over.
    pub bend: (f32, f32),
    /// Segments along a blade's strip.
    pub segments: u32,
    /// Seed of the patch.
    pub seed: u64,
}

impl Default for PatchSettings {
    fn default() -> Self {
        Self {
            size: 0.5,
            strata: 24,
            height: (0.18, 0.42),
            width: 0.012,
            bend: (0.1, 0.55),
            segments: 4,
            seed: 4,
        }
    }
}

impl PatchSettings {
    /// Most strata a side: `256²` blades in one patch is already far denser than grass grows.
    pub const MAX_STRATA: u32 = 256;

    /// These settings with unusable values replaced, and what was replaced (sizes not finite or
    /// not positive, empty ranges, strata or segments out of `1..=MAX_STRATA` / `1..=16`).
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let d = Self::default();
        let mut s = *self;
        let mut fixes = Vec::new();
        let positive = |v: f32| v.is_finite() && v > 0.0;
        if !positive(s.size) {
            fixes.push(format!(
                "patch size {} must be positive: using {}",
                s.size, d.size
            ));
            s.size = d.size;
        }
        if !(1..=Self::MAX_STRATA).contains(&s.strata) {
            let fixed = s.strata.clamp(1, Self::MAX_STRATA);
            fixes.push(format!(
                "strata {} outside 1..={}: using {fixed}",
                s.strata,
                Self::MAX_STRATA
            ));
            s.strata = fixed;
        }
        if !(positive(s.height.0) && positive(s.height.1) && s.height.0 <= s.height.1) {
            fixes.push(format!(
                "blade heights {:?} must be positive and ordered: using {:?}",
                s.height, d.height
            ));
            s.height = d.height;
        }
        if !positive(s.width) {
            fixes.push(format!(
                "blade width {} must be positive: using {}",
                s.width, d.width
            ));
            s.width = d.width;
        }
        if !(s.bend.0.is_finite()
            && s.bend.1.is_finite()
            && 0.0 <= s.bend.0
            && s.bend.0 <= s.bend.1)
        {
            fixes.push(format!(
                "bend {:?} must be non-negative and ordered: using {:?}",
                s.bend, d.bend
            ));
            s.bend = d.bend;
        }
        if !(1..=16).contains(&s.segments) {
            let fixed = s.segments.clamp(1, 16);
            fixes.push(format!(
                "segments {} outside 1..=16: using {fixed}",
                s.segments
            ));
            s.segments = fixed;
        }
        (s, fixes)
    }
}

/// One blade of the base patch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blade {
    /// Root (x, z) in the patch, in `[0, size)²`.
    pub root: Vec2,
    /// Density threshold in ]0, 1]: drawn where the local density is at least this.
    pub threshold: f32,
    /// Height of the tip's launch (m).
    pub height: f32,
    /// Unit horizontal direction it leans to.
    pub lean: Vec2,
    /// Horizontal over vertical launch speed.
    pub bend: f32,
}

impl Blade {
    /// The blade's reference point at parameter `t ∈ [0, 1]`: a particle launched from the root
    /// with vertical speed `v` and horizontal speed `bend·v`, under gravity chosen so that its
    /// apex is at `height` when `t = 1` — `y = h(2t − t²)`, horizontal `bend·h·2t`. (A ballistic
    /// curve: tangent vertical-ish at the root, flattening at the tip.)
    pub fn point(&self, t: f32) -> Vec3 {
        let y = self.height * (2.0 * t - t * t);
        let reach = self.bend * self.height * 2.0 * t * 0.5;
        Vec3::new(
            self.root.x + self.lean.x * reach,
            y,
            self.root.y + self.lean.y * reach,
        )
    }
}

/// The base patch.
#[derive(Clone, Debug, PartialEq)]
pub struct BasePatch {
    /// Its side (m).
    pub size: f32,
    /// Its blades.
    pub blades: Vec<Blade>,
}

impl BasePatch {
    /// The patch `settings` describe (stratified roots, uniform thresholds).
    pub fn generate(settings: &PatchSettings) -> Self {
        let mut rng = SplitMix64::new(settings.seed);
        let n = settings.strata.max(1);
        let cell = settings.size / n as f32;
        let mut blades = Vec::with_capacity((n * n) as usize);
        for j in 0..n {
            for i in 0..n {
                let root = Vec2::new(
                    (i as f32 + rng.next_f32()) * cell,
                    (j as f32 + rng.next_f32()) * cell,
                );
                let angle = rng.range(0.0, std::f32::consts::TAU);
                // ]0, 1]: the dither rank, jittered by 1 − [0, 1).
                let threshold = (bayer8(i, j) as f32 + 1.0 - rng.next_f32()) / 64.0;
                blades.push(Blade {
                    root: root.min(Vec2::splat(settings.size * (1.0 - f32::EPSILON))),
                    threshold,
                    height: rng.range(settings.height.0, settings.height.1),
                    lean: Vec2::new(angle.cos(), angle.sin()),
                    bend: rng.range(settings.bend.0, settings.bend.1),
                });
            }
        }
        Self {
            size: settings.size,
            blades,
        }
    }

    /// The blades a local density `ld` keeps (`threshold ≤ ld`).
    pub fn kept(&self, ld: f32) -> impl Iterator<Item = &Blade> {
        self.blades.iter().filter(move |b| b.threshold <= ld)
    }
}

/// Rank 0..63 of stratum (i, j) in the 8 × 8 ordered-dither (Bayer) matrix: any first k ranks
/// are spread evenly over the block.
fn bayer8(i: u32, j: u32) -> u32 {
    let (x, y) = (i & 7, j & 7);
    let mut rank = 0;
    for bit in 0..3 {
        let xy = ((x ^ y) >> bit) & 1;
        let yb = (y >> bit) & 1;
        rank |= (xy << (2 * (2 - bit) + 1)) | (yb << (2 * (2 - bit)));
    }
    rank
}

/// One of the four mirrored versions of the base patch a grid cell shows: the signs of eq. 4.9's
/// orientation map (−1 mirrors that axis).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Mirror {
    /// Mirrors x.
    pub x: bool,
    /// Mirrors z.
    pub z: bool,
}

impl Mirror {
    /// The version grid cell (i, j) shows: a hash of the cell, so any cell's version is known
    /// without storing a map (the orientation map of fig. 4.19, computed).
    pub fn of_cell(i: i64, j: i64, seed: u64) -> Self {
        // 32-bit arithmetic only, so the shaders (`grass_functions.wgsl`) compute the same.
        let h = hash32((i as u32) ^ hash32((j as u32) ^ hash32(seed as u32)));
        Self {
            x: h & 1 == 1,
            z: h & 2 == 2,
        }
    }
}

/// A 32-bit integer hash (Wellons' "lowbias32"): every input bit reaches every output bit.
pub fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

impl Mirror {
    /// Eq. 4.9: the base patch's coordinates (in `[0, 1)²`) of cell-relative coordinates
    /// `(u, v) ∈ [0, 1)²` in a cell showing this version. (The thesis writes it for the macro-
    /// cells' texture coordinates, `frac(patchSize × ±1 × u)`; per cell that is `u` or `1 − u`.)
    pub fn patch_uv(self, u: f32, v: f32) -> (f32, f32) {
        let flip = |c: f32, m: bool| if m { (1.0 - c).fract() } else { c };
        (flip(u, self.x), flip(v, self.z))
    }

    /// A patch-space point of the base patch (x, z in `[0, size]`) as this version places it in
    /// its cell.
    pub fn place(self, p: Vec3, size: f32) -> Vec3 {
        Vec3::new(
            if self.x { size - p.x } else { p.x },
            p.y,
            if self.z { size - p.z } else { p.z },
        )
    }
}

/// The vertices of a blade's two-sided strip: `segments + 1` pairs along the curve, `width`
/// across at the root narrowing to a point at the tip, across the direction it leans; with each
/// vertex's height fraction (for the ambient occlusion rising with height, §4.2.2).
pub fn blade_strip(blade: &Blade, width: f32, segments: u32) -> Vec<(Vec3, f32)> {
    let segments = segments.max(1);
    let across = Vec3::new(-blade.lean.y, 0.0, blade.lean.x);
    let mut vertices = Vec::with_capacity(2 * (segments as usize + 1));
    for k in 0..=segments {
        let t = k as f32 / segments as f32;
        let p = blade.point(t);
        let half = 0.5 * width * (1.0 - t);
        let h = if blade.height > 0.0 {
            p.y / blade.height
        } else {
            0.0
        };
        vertices.push((p - across * half, h));
        vertices.push((p + across * half, h));
    }
    vertices
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_are_stratified_and_thresholds_uniform() {
        let s = PatchSettings::default();
        let patch = BasePatch::generate(&s);
        assert_eq!(patch.blades.len(), (s.strata * s.strata) as usize);
        // One root in each stratum.
        let cell = s.size / s.strata as f32;
        let mut seen = vec![false; patch.blades.len()];
        for b in &patch.blades {
            assert!(b.root.x >= 0.0 && b.root.x < s.size && b.root.y >= 0.0 && b.root.y < s.size);
            let (i, j) = ((b.root.x / cell) as u32, (b.root.y / cell) as u32);
            let k = (j * s.strata + i) as usize;
            assert!(!seen[k], "two roots in stratum ({i}, {j})");
            seen[k] = true;
            assert!(b.threshold > 0.0 && b.threshold <= 1.0);
        }
        // Any density keeps about that fraction of the blades, spread over the whole patch.
        for ld in [0.1, 0.35, 0.8] {
            let kept: Vec<_> = patch.kept(ld).collect();
            let fraction = kept.len() as f32 / patch.blades.len() as f32;
            assert!(
                (fraction - ld).abs() <= 1.0 / 64.0,
                "{fraction} kept at {ld}"
            );
            for quadrant in 0..4 {
                let in_q = kept
                    .iter()
                    .filter(|b| {
                        ((b.root.x >= s.size / 2.0) as u32
                            | (((b.root.y >= s.size / 2.0) as u32) << 1))
                            == quadrant
                    })
                    .count() as f32;
                let share = in_q / kept.len() as f32;
                assert!(
                    (share - 0.25).abs() < 0.04,
                    "quadrant {quadrant}: {share} at {ld}"
                );
            }
        }
    }

    #[test]
    fn the_dither_ranks_each_stratum_of_a_block_once() {
        let mut ranks: Vec<u32> = (0..8)
            .flat_map(|j| (0..8).map(move |i| bayer8(i, j)))
            .collect();
        assert_eq!(&ranks[..4], &[0, 32, 8, 40]);
        ranks.sort();
        assert_eq!(ranks, (0..64).collect::<Vec<_>>());
        // The first 16 ranks fall one in each 2 × 2 of the block.
        for (bi, bj) in (0..4).flat_map(|a| (0..4).map(move |b| (a, b))) {
            let in_cell = (0..2)
                .flat_map(|dj| (0..2).map(move |di| bayer8(2 * bi + di, 2 * bj + dj)))
                .filter(|&r| r < 16)
                .count();
            assert_eq!(in_cell, 1, "2 × 2 cell ({bi}, {bj})");
        }
    }

    #[test]
    fn the_four_mirrored_versions_tile_without_gaps() {
        // Every cell picks one of the four, all four appear, and each is a bijection of the cell.
        let mut counts = std::collections::HashMap::new();
        for i in -20..20 {
            for j in -20..20 {
                *counts.entry(Mirror::of_cell(i, j, 7)).or_insert(0) += 1;
            }
        }
        assert_eq!(counts.len(), 4);
        assert!(counts.values().all(|&c| c > 300), "{counts:?}");
        let m = Mirror { x: true, z: false };
        assert_eq!(m.patch_uv(0.25, 0.75), (0.75, 0.75));
        assert_eq!(m.patch_uv(0.0, 0.0), (0.0, 0.0), "frac keeps [0, 1)");
        let p = m.place(Vec3::new(0.1, 0.3, 0.2), 0.5);
        assert_eq!(p, Vec3::new(0.4, 0.3, 0.2));
    }

    #[test]
    fn a_blade_rises_from_its_root_and_bends_to_its_lean() {
        let blade = Blade {
            root: Vec2::new(0.1, 0.2),
            threshold: 0.5,
            height: 0.4,
            lean: Vec2::new(1.0, 0.0),
            bend: 0.5,
        };
        assert_eq!(blade.point(0.0), Vec3::new(0.1, 0.0, 0.2));
        let tip = blade.point(1.0);
        assert!((tip.y - 0.4).abs() < 1e-6 && tip.x > 0.1 && (tip.z - 0.2).abs() < 1e-6);
        // Rising ever more slowly: the ballistic curve's apex is the tip.
        let (a, b, c) = (blade.point(0.3).y, blade.point(0.6).y, blade.point(0.9).y);
        assert!(a < b && b < c && b - a > c - b);
        let strip = blade_strip(&blade, 0.02, 4);
        assert_eq!(strip.len(), 10);
        // Width 2 cm at the root, a point at the tip; the height fraction 0 → 1.
        assert!((strip[0].0.distance(strip[1].0) - 0.02).abs() < 1e-6);
        assert!(strip[8].0.distance(strip[9].0) < 1e-6);
        assert_eq!((strip[0].1, strip[9].1), (0.0, 1.0));
    }

    #[test]
    fn absurd_patch_settings_are_replaced_and_named() {
        let bad = PatchSettings {
            size: f32::NAN,
            strata: 100_000,
            height: (0.5, 0.1),
            width: -1.0,
            bend: (f32::INFINITY, 0.0),
            segments: 0,
            seed: 1,
        };
        let (fixed, fixes) = bad.sanitized();
        assert_eq!(fixes.len(), 6, "{fixes:?}");
        assert_eq!(fixed.strata, PatchSettings::MAX_STRATA);
        assert_eq!(fixed.segments, 1);
        assert_eq!(fixed.sanitized().1, Vec::<String>::new());
        assert_eq!(PatchSettings::default().sanitized().1, Vec::<String>::new());
    }
}
