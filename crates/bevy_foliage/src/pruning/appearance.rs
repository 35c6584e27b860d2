//! How a kept leaf is drawn: area compensation and the sub-pixel fade (Gumbau 2011, §3.4).
//! This is the CPU reference of the vertex stage in `leaf_pulling.wgsl`, which computes the same
//! formulas per vertex.
//!
//! **Area compensation** (eq. 3.7–3.9): a cell asked to keep the fraction u = LoD(cell) of its
//! leaves (eq. 3.5, distance *and* visibility) scales each kept leaf's area by s = 1/u, so by √s
//! linearly about its centroid. The thesis derives u from distance alone, which ignores that the
//! count kept also depends on visibility. u is the fraction eq. 3.5 asks for rather than the
//! count a cell ends up with: the kept counts are rounded with the remainder carried from cell to
//! cell ([`super::extract`]), so a cell may keep one leaf more or less than asked — and a small
//! cell none — while its neighbours make up for it; dividing by the fraction asked keeps the
//! area of every run of cells, where dividing by the count kept would drop the area of every
//! cell that rounded to zero. The linear scale is capped by
//! [`FoliagePruningSettings::max_leaf_scale`]: a cell asked for 1 leaf of 30 would otherwise
//! draw it 5.5 times larger.
//!
//! **Sub-pixel fade**: alpha-masked leaf textures lose their opacity in the coarse mip levels
//! (the mask averages to below the cutoff), so distant crowns thin out. As the projected leaf
//! diameter falls from `fade_start_pixels` to `fade_end_pixels`, the fade f goes from 0 to 1 and
//!
//! - the leaf's texture coordinates converge on its centre texel,
//!   `uv' = uv + f·(uv_centre − uv)`: the whole leaf samples one opaque texel, in one colour
//!   (the thesis "gradually disables the alpha values … till the whole leaf is rendered with a
//!   single colour"); doing it with coordinates keeps Bevy's own fragment stages, so the colour,
//!   the depth prepass and the shadow pass all see the same faded leaf;
//! - the leaf shrinks so that it keeps covering the area its opaque texels covered, o being the
//!   opaque fraction of its texture: the converging window of the texture is assumed opaque over
//!   `o + f·(1 − o)` of it (o unfaded, 1 when it has shrunk to the centre texel), so the leaf's
//!   area is scaled by `o / (o + f·(1 − o))` — linearly by its square root. Without it a solid
//!   quad would cover 1/o times the leaf's area and distant crowns would get denser instead of
//!   thinner.
//!
//! [`FoliagePruningSettings::max_leaf_scale`]: crate::FoliagePruningSettings::max_leaf_scale

/// Linear scale of a kept leaf of a cell at `LoD(cell) = lod_fixed` (fixed point, see
/// [`super::extract::cell_lod`]): `√(1/u)` (eq. 3.9), capped at `max_scale`.
pub fn compensation_scale(lod_fixed: u32, max_scale: f32) -> f32 {
    (65536.0 / lod_fixed.max(1) as f32).sqrt().min(max_scale)
}

/// Projected diameter in pixels of a leaf of radius `radius` (world units) at clip-space depth
/// `w`: `clip_from_view_yy` is the projection's `[1][1]` entry and `viewport_height` the target
/// height in pixels. Works for perspective (`w` = view depth) and orthographic (`w` = 1)
/// projections alike.
pub fn projected_diameter_pixels(
    radius: f32,
    w: f32,
    clip_from_view_yy: f32,
    viewport_height: f32,
) -> f32 {
    2.0 * radius * clip_from_view_yy / w.max(1e-6) * 0.5 * viewport_height
}

/// The fade f ∈ [0, 1] of a leaf `pixels` across: 0 from `start` up, 1 at `end` and below,
/// linear between.
pub fn fade(pixels: f32, start: f32, end: f32) -> f32 {
    ((start - pixels) / (start - end).max(1e-6)).clamp(0.0, 1.0)
}

/// The linear shrink of a leaf faded by `fade` whose texture is opaque over `opaque_fraction` of
/// its area: `√(o / (o + f·(1 − o)))`, 1 unfaded, √o fully faded.
pub fn fade_shrink(fade: f32, opaque_fraction: f32) -> f32 {
    let o = opaque_fraction.clamp(1e-3, 1.0);
    (o / (o + fade * (1.0 - o))).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compensation_preserves_area_until_the_cap() {
        // Keeping a quarter doubles each leaf linearly: 1/4 of the leaves × 4× the area.
        assert!((compensation_scale(1 << 14, 4.0) - 2.0).abs() < 1e-6);
        assert_eq!(compensation_scale(1 << 16, 4.0), 1.0);
        // 1 leaf of 30 would be √30 ≈ 5.48: capped.
        assert_eq!(compensation_scale(65536 / 30, 4.0), 4.0);
        // LoD 0: never divides by zero.
        assert!(compensation_scale(0, 4.0).is_finite());
    }

    #[test]
    fn projected_size_halves_at_twice_the_distance() {
        let yy = 1.0 / (0.5f32).tan(); // 1 rad vertical field of view
        let near = projected_diameter_pixels(0.1, 10.0, yy, 720.0);
        let far = projected_diameter_pixels(0.1, 20.0, yy, 720.0);
        assert!((near / far - 2.0).abs() < 1e-5);
        // 0.2 m at 10 m spans 0.02 rad of 1 rad over 720 px, ≈ 13.3 px (small-angle).
        assert!((near - 0.2 / 10.0 * yy * 360.0).abs() < 1e-3, "{near}");
    }

    #[test]
    fn fade_ramps_between_start_and_end() {
        assert_eq!(fade(8.0, 4.0, 1.0), 0.0);
        assert_eq!(fade(4.0, 4.0, 1.0), 0.0);
        assert!((fade(2.5, 4.0, 1.0) - 0.5).abs() < 1e-6);
        assert_eq!(fade(1.0, 4.0, 1.0), 1.0);
        assert_eq!(fade(0.1, 4.0, 1.0), 1.0);
        assert_eq!(fade_shrink(0.0, 0.25), 1.0);
        assert!((fade_shrink(1.0, 0.25) - 0.5).abs() < 1e-6);
        // Half faded, the window is opaque over 0.25 + 0.5·0.75 = 0.625: area × 0.25/0.625.
        assert!((fade_shrink(0.5, 0.25).powi(2) - 0.4).abs() < 1e-6);
        assert_eq!(fade_shrink(0.7, 1.0), 1.0);
        // Area of a fully faded (solid) leaf = opaque area of the textured leaf.
        let s = fade_shrink(1.0, 0.49);
        assert!((s * s - 0.49).abs() < 1e-6);
    }
}
