//! The heights the terrain's vertex stage reads from a height clip stack (`relief.wgsl`), on the
//! CPU: its reference, and what tests build the expected mesh from.
//!
//! Positions are points of the terrain's patch lattice ([`super::patch::PatchGrid`]), not world
//! metres: the lattice side is a power of two, so a level's texel coordinates are the lattice
//! coordinates times a power of two — exact in f32 for every vertex even 2^20 texels from the
//! texture's corner, where world metres would have lost the texel's fraction.
//!
//! A vertex at lattice point p takes the height of the finest windowed layer whose valid rectangle
//! holds the 2 × 2 level texels around it, bilinear between their centres; the resident base
//! level otherwise (clamped at the texture's edges). The height is a function of the position
//! alone — not of the patch or tile the vertex belongs to — so the vertices two patches share get
//! the same height and the mesh stays closed in 3D as the lattice mesh is in 2D
//! ([`super::tile`]). (Paper 4 fetches each tile's heights from the pyramid level of its
//! resolution; with tiles of two resolutions meeting inside a patch, that would give a shared
//! diagonal vertex two heights.) The normal is the heights' central difference over one texel of
//! the finest level there.

use bevy::math::{Vec2, Vec3};

/// Where the height stack's levels hold data, as the vertex stage sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightLayers {
    /// Per windowed layer `i` (level `base_level + 1 + i`), its valid level texels
    /// `[min.x, min.y, max.x, max.y)`; an empty rectangle when none.
    pub coverage: Vec<[f32; 4]>,
    /// The base level `l_b` (always resident).
    pub base_level: u32,
    /// Lattice steps along the height texture's side (a power of two).
    pub lattice_side: f32,
    /// Metres per lattice step.
    pub lattice_step: f32,
}

/// Where lattice point `p` falls among level `level`'s texels, texel centres at integers.
pub fn level_texel(layers: &HeightLayers, p: Vec2, level: u32) -> Vec2 {
    p * ((level as f32).exp2() / layers.lattice_side) - 0.5
}

fn lerp(a: f32, b: f32, f: f32) -> f32 {
    a + (b - a) * f
}

/// Which level the height at lattice point `xz` comes from: the finest windowed layer holding the 2 × 2 texels
/// around it, else the base level.
pub fn height_level(layers: &HeightLayers, xz: Vec2) -> u32 {
    for (i, c) in layers.coverage.iter().enumerate().rev() {
        let level = layers.base_level + 1 + i as u32;
        let t0 = level_texel(layers, xz, level).floor();
        if t0.x >= c[0] && t0.y >= c[1] && t0.x + 1.0 < c[2] && t0.y + 1.0 < c[3] {
            return level;
        }
    }
    layers.base_level
}

/// The height (m) at lattice point `xz`: bilinear between the texel centres of [`height_level`]'s
/// texels, `texel(level, x, y)` giving a level's heights (clamped to the texture at the base
/// level).
pub fn height_at(layers: &HeightLayers, texel: impl Fn(u32, i64, i64) -> f32, xz: Vec2) -> f32 {
    let level = height_level(layers, xz);
    let t = level_texel(layers, xz, level);
    let t0 = t.floor();
    let f = t - t0;
    let (x0, y0) = (t0.x as i64, t0.y as i64);
    let last = (1i64 << level) - 1;
    let at = |x: i64, y: i64| {
        if level == layers.base_level {
            texel(level, x.clamp(0, last), y.clamp(0, last))
        } else {
            texel(level, x, y)
        }
    };
    lerp(
        lerp(at(x0, y0), at(x0 + 1, y0), f.x),
        lerp(at(x0, y0 + 1), at(x0 + 1, y0 + 1), f.x),
        f.y,
    )
}

/// The surface normal (world axes) at lattice point `xz`: central differences of
/// [`height_at`] over one texel of the level there.
pub fn normal_at(layers: &HeightLayers, texel: impl Fn(u32, i64, i64) -> f32, xz: Vec2) -> Vec3 {
    let e = layers.lattice_side / (height_level(layers, xz) as f32).exp2();
    let h = |d: Vec2| height_at(layers, &texel, xz + d);
    let dx = h(Vec2::new(e, 0.0)) - h(Vec2::new(-e, 0.0));
    let dz = h(Vec2::new(0.0, e)) - h(Vec2::new(0.0, -e));
    Vec3::new(-dx, 2.0 * e * layers.lattice_step, -dz).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layers() -> HeightLayers {
        HeightLayers {
            // Level 5 covers texels 4..12 along both axes; level 6 nothing.
            coverage: vec![[4.0, 4.0, 12.0, 12.0], [0.0, 0.0, 0.0, 0.0]],
            base_level: 4,
            // A 64 m texture of 2^7 lattice steps (0.5 m).
            lattice_side: 128.0,
            lattice_step: 0.5,
        }
    }

    #[test]
    fn heights_come_from_the_finest_covering_level_bilinear_between_texel_centres() {
        let l = layers();
        // A plane in level texels, different per level: bilinear reproduces a plane exactly.
        let texel = |level: u32, x: i64, y: i64| level as f32 * 100.0 + x as f32 * 2.0 - y as f32;
        // Level 5 texels are 4 lattice steps (2 m); lattice 4·(8.5, 6.25) is level texel (8, 5.75).
        let xz = 4.0 * Vec2::new(8.5, 6.25);
        assert_eq!(height_level(&l, xz), 5);
        assert!((height_at(&l, texel, xz) - (500.0 + 8.0 * 2.0 - 5.75)).abs() < 1e-4);
        // Outside level 5's rectangle: the base level (4 m texels), clamped at the texture's edge.
        let far = Vec2::new(120.0, 124.0);
        assert_eq!(height_level(&l, far), 4);
        let t = level_texel(&l, far, 4);
        assert!((height_at(&l, texel, far) - (400.0 + t.x * 2.0 - 15.0)).abs() < 1e-3);
        // The texel rectangle must hold both texels around the point: at texel 11.5 the right
        // neighbour (12) is outside, so the base level answers.
        let edge = 4.0 * Vec2::new(12.0, 8.5);
        assert_eq!(height_level(&l, edge), 4);
        // The normal of a plane rising 1 m per metre along x (level 5: 2 m texels, 2 per texel).
        let n = normal_at(&l, texel, xz);
        let want = Vec3::new(-1.0, 1.0, 0.5).normalize();
        assert!(n.distance(want) < 1e-4, "{n}");
    }
}
