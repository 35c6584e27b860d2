//! One square texture atlas per species for the billboard cloud's planes.
//!
//! Seed 001 §4.4 notes the rendering rate of billboard clouds "can very likely be further
//! improved through the use of a texture atlas": every plane of a tree then samples one texture,
//! so a species draws with one material. All planes share one texel density (texels per world
//! unit), so the impostor's resolution is uniform over the tree; the density is the largest at
//! which shelf packing (rectangles sorted by height, placed left to right in rows) fits every
//! plane's rectangle, found by bisection. Each rectangle keeps `padding` texels of gutter on every
//! side so bilinear filtering and mip-mapping do not bleed neighbours into it.

use bevy::math::Vec2;

/// Where one plane's texture lives in the atlas (texel rectangle, inclusive min, exclusive max).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AtlasRect {
    /// First texel column and row.
    pub min: [u32; 2],
    /// Width and height in texels (at least 1 each).
    pub size: [u32; 2],
}

impl AtlasRect {
    /// One past the last texel column and row.
    pub fn max(&self) -> [u32; 2] {
        [self.min[0] + self.size[0], self.min[1] + self.size[1]]
    }

    /// uv of a point given as a fraction (0..1, 0..1) of the rect: the texel-space position
    /// divided by the atlas size.
    pub fn uv(&self, fraction: Vec2, atlas_size: u32) -> Vec2 {
        let min = Vec2::new(self.min[0] as f32, self.min[1] as f32);
        let size = Vec2::new(self.size[0] as f32, self.size[1] as f32);
        (min + fraction * size) / atlas_size.max(1) as f32
    }

    /// This rectangle grown by `padding` texels on every side (its gutter), as `(min, max)`
    /// with exclusive max; the gutters of a layout's rectangles never overlap.
    pub fn padded(&self, padding: u32) -> ([u32; 2], [u32; 2]) {
        let max = self.max();
        (
            [
                self.min[0].saturating_sub(padding),
                self.min[1].saturating_sub(padding),
            ],
            [max[0] + padding, max[1] + padding],
        )
    }
}

/// The packing of a species' planes into one atlas.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasLayout {
    /// Side of the square atlas in texels.
    pub size: u32,
    /// Texels per world unit, the same for every rectangle (0 when every world size is 0).
    pub texels_per_unit: f32,
    /// One rectangle per input size, in input order.
    pub rects: Vec<AtlasRect>,
    /// Gutter in texels around every rectangle, also kept from the atlas border.
    pub padding: u32,
}

/// Why the rectangles could not be packed.
#[derive(Clone, Debug, PartialEq)]
pub enum AtlasError {
    /// No rectangles.
    Empty,
    /// A world size is NaN, infinite or negative.
    NonFinite,
    /// Even at 1×1 texel each (plus their gutters) the rectangles do not fit an atlas of this
    /// side.
    TooSmall {
        /// The atlas side that was asked for.
        size: u32,
    },
}

impl std::fmt::Display for AtlasError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Empty => write!(f, "impostor atlas: no rectangles to pack"),
            Self::NonFinite => write!(
                f,
                "impostor atlas: a rectangle size is NaN, infinite or negative"
            ),
            Self::TooSmall { size } => write!(
                f,
                "impostor atlas: the rectangles and their padding do not fit {size}×{size} texels \
                 even at one texel each"
            ),
        }
    }
}

impl std::error::Error for AtlasError {}

/// The texel size of a rectangle of world size `world` at `texels_per_unit`: rounded, at least 1.
fn texel_size(world: Vec2, texels_per_unit: f32) -> [u32; 2] {
    let s = (world * texels_per_unit).round().max(Vec2::ONE);
    // Saturating casts: a density far too large simply fails to fit.
    [s.x as u32, s.y as u32]
}

/// Shelf packing (rows of rectangles sorted by decreasing height, ties by decreasing width,
/// then input order): each rectangle is placed with `padding` texels of gutter on every side,
/// so neighbours are `2 · padding` apart and every rectangle `padding` from the border.
/// Returns the layout, or `None` if the rectangles do not fit.
pub fn layout_at(
    world_sizes: &[Vec2],
    size: u32,
    padding: u32,
    texels_per_unit: f32,
) -> Option<AtlasLayout> {
    let sizes: Vec<[u32; 2]> = world_sizes
        .iter()
        .map(|&w| texel_size(w, texels_per_unit))
        .collect();
    let gutter = 2 * padding as u64;
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by(|&a, &b| {
        sizes[b][1]
            .cmp(&sizes[a][1])
            .then(sizes[b][0].cmp(&sizes[a][0]))
            .then(a.cmp(&b))
    });
    let side = size as u64;
    let mut rects = vec![
        AtlasRect {
            min: [0, 0],
            size: [0, 0]
        };
        sizes.len()
    ];
    let (mut x, mut y, mut row) = (0u64, 0u64, 0u64);
    for i in order {
        let (w, h) = (sizes[i][0] as u64 + gutter, sizes[i][1] as u64 + gutter);
        if w > side {
            return None;
        }
        if x + w > side {
            y += row;
            x = 0;
            row = 0;
        }
        if y + h > side {
            return None;
        }
        rects[i] = AtlasRect {
            min: [(x + padding as u64) as u32, (y + padding as u64) as u32],
            size: sizes[i],
        };
        x += w;
        row = row.max(h);
    }
    Some(AtlasLayout {
        size,
        texels_per_unit,
        rects,
        padding,
    })
}

/// Packs rectangles of the given world sizes (width, height ≥ 0) into a `size`×`size` atlas at
/// the largest uniform texel density that fits (binary search on texels_per_unit, shelf packing
/// sorted by height), each rect at least 1×1 texel plus `padding` texels of gutter on every side
/// (between rects and at the atlas border).
///
/// Shelf packing is not strictly monotone in the density (rounding can reorder rows), so after
/// the bisection a few densities up to 10 % higher are tried as well and the highest that fits
/// is kept.
pub fn pack(world_sizes: &[Vec2], size: u32, padding: u32) -> Result<AtlasLayout, AtlasError> {
    if world_sizes.is_empty() {
        return Err(AtlasError::Empty);
    }
    if world_sizes
        .iter()
        .any(|w| !w.is_finite() || w.x < 0.0 || w.y < 0.0)
    {
        return Err(AtlasError::NonFinite);
    }
    // At density 0 every rectangle is 1×1: if that does not fit, nothing does.
    let Some(mut best) = layout_at(world_sizes, size, padding, 0.0) else {
        return Err(AtlasError::TooSmall { size });
    };
    let longest = world_sizes.iter().map(|w| w.x.max(w.y)).fold(0.0, f32::max);
    if longest <= 0.0 {
        return Ok(best);
    }
    // No density above this fits: the longest side alone would exceed the atlas.
    let mut hi = (size as f32 + 1.0) / longest;
    if let Some(layout) = layout_at(world_sizes, size, padding, hi) {
        return Ok(layout);
    }
    let mut lo = 0.0f32;
    for _ in 0..48 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        match layout_at(world_sizes, size, padding, mid) {
            Some(layout) => {
                lo = mid;
                best = layout;
            }
            None => hi = mid,
        }
    }
    for step in 1..=10 {
        let density = lo * (1.0 + 0.01 * step as f32);
        if let Some(layout) = layout_at(world_sizes, size, padding, density) {
            best = layout;
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn overlaps(a: ([u32; 2], [u32; 2]), b: ([u32; 2], [u32; 2])) -> bool {
        a.0[0] < b.1[0] && b.0[0] < a.1[0] && a.0[1] < b.1[1] && b.0[1] < a.1[1]
    }

    /// Every invariant of a layout for `world`: gutters disjoint and inside the atlas, sizes
    /// at the layout's density within rounding.
    fn check(world: &[Vec2], layout: &AtlasLayout) {
        assert_eq!(layout.rects.len(), world.len());
        let p = layout.padding;
        for (i, r) in layout.rects.iter().enumerate() {
            assert!(r.size[0] >= 1 && r.size[1] >= 1);
            assert!(
                r.min[0] >= p && r.min[1] >= p,
                "rect {i} in the border gutter"
            );
            let (_, max) = r.padded(p);
            assert!(
                max[0] <= layout.size && max[1] <= layout.size,
                "rect {i} {r:?} outside the atlas"
            );
            for (j, s) in layout.rects[..i].iter().enumerate() {
                assert!(
                    !overlaps(r.padded(p), s.padded(p)),
                    "rects {j} and {i} overlap: {s:?} {r:?}"
                );
            }
            let want = world[i] * layout.texels_per_unit;
            for axis in 0..2 {
                let got = r.size[axis] as f32;
                assert!(
                    (got - want[axis].max(1.0)).abs() <= 1.0,
                    "rect {i}: {got} texels for {}",
                    want[axis]
                );
            }
        }
    }

    fn random_sizes(seed: u64, n: usize) -> Vec<Vec2> {
        let mut r = SplitMix64::new(seed);
        (0..n)
            .map(|_| Vec2::new(r.range(0.2, 6.0), r.range(0.2, 6.0)))
            .collect()
    }

    #[test]
    fn rects_are_disjoint_inside_and_to_scale() {
        for (seed, n, size, padding) in [(1, 30, 1024, 2), (2, 60, 512, 1), (3, 5, 256, 0)] {
            let world = random_sizes(seed, n);
            let layout = pack(&world, size, padding).unwrap();
            check(&world, &layout);
            // Aspect ratios follow the world sizes (within a texel of rounding).
            for (w, r) in world.iter().zip(&layout.rects) {
                let aspect = r.size[0] as f32 / r.size[1] as f32;
                let slack = 1.0 / r.size[0].min(r.size[1]) as f32;
                assert!((aspect / (w.x / w.y) - 1.0).abs() <= 2.0 * slack + 1e-3);
            }
        }
    }

    #[test]
    fn the_density_is_close_to_the_best_that_fits() {
        for (seed, n, size, padding) in [(4, 40, 1024, 2), (5, 12, 512, 1), (6, 90, 2048, 4)] {
            let world = random_sizes(seed, n);
            let layout = pack(&world, size, padding).unwrap();
            let d = layout.texels_per_unit;
            assert!(
                layout_at(&world, size, padding, d * 1.05).is_none(),
                "5 % denser still fits"
            );
            // And the packing uses a fair share of the atlas.
            let used: u64 = layout
                .rects
                .iter()
                .map(|r| r.size[0] as u64 * r.size[1] as u64)
                .sum();
            let fill = used as f64 / (size as f64 * size as f64);
            assert!(fill > 0.5, "atlas {fill:.2} full");
            // Never denser than the area bound.
            let area: f32 = world.iter().map(|w| w.x * w.y).sum();
            assert!(d * d * area <= (size * size) as f32 * 1.05);
        }
    }

    #[test]
    fn one_rect_fills_the_atlas_less_its_gutter() {
        let layout = pack(&[Vec2::new(2.0, 1.0)], 256, 3).unwrap();
        let r = layout.rects[0];
        assert_eq!(r.min, [3, 3]);
        assert_eq!(r.size, [250, 125]);
        assert_eq!(r.uv(Vec2::ZERO, 256), Vec2::splat(3.0 / 256.0));
        assert_eq!(
            r.uv(Vec2::ONE, 256),
            Vec2::new(253.0 / 256.0, 128.0 / 256.0)
        );
    }

    #[test]
    fn zero_sizes_get_one_texel() {
        let world = [Vec2::ZERO, Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0)];
        let layout = pack(&world, 64, 1).unwrap();
        check(&world, &layout);
        assert_eq!(layout.rects[0].size, [1, 1]);
        assert_eq!(layout.rects[1].size[0], 1);
        let all_zero = pack(&[Vec2::ZERO; 3], 64, 1).unwrap();
        assert_eq!(all_zero.texels_per_unit, 0.0);
        assert!(all_zero.rects.iter().all(|r| r.size == [1, 1]));
    }

    #[test]
    fn errors() {
        assert_eq!(pack(&[], 64, 1), Err(AtlasError::Empty));
        assert_eq!(
            pack(&[Vec2::ONE, Vec2::new(f32::NAN, 1.0)], 64, 1),
            Err(AtlasError::NonFinite)
        );
        assert_eq!(
            pack(&[Vec2::new(f32::INFINITY, 1.0)], 64, 1),
            Err(AtlasError::NonFinite)
        );
        assert_eq!(
            pack(&[Vec2::new(-1.0, 1.0)], 64, 1),
            Err(AtlasError::NonFinite)
        );
        // 1 + 2·4 = 9 texels per rect: an 8-texel atlas holds none.
        assert_eq!(
            pack(&[Vec2::ONE], 8, 4),
            Err(AtlasError::TooSmall { size: 8 })
        );
        // 100 rects of 3×3 slots need 30×30 texels at least.
        assert_eq!(
            pack(&[Vec2::ONE; 100], 29, 1),
            Err(AtlasError::TooSmall { size: 29 })
        );
        assert!(pack(&[Vec2::ONE; 100], 30, 1).is_ok());
        assert_eq!(
            pack(&[Vec2::ONE], 0, 0),
            Err(AtlasError::TooSmall { size: 0 })
        );
        assert!(AtlasError::TooSmall { size: 8 }.to_string().contains("8×8"));
    }

    #[test]
    fn packing_is_deterministic() {
        let world = random_sizes(9, 50);
        assert_eq!(pack(&world, 1024, 2), pack(&world, 1024, 2));
    }
}
