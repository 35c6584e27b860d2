//! What the slice shader computes at a fragment, on the CPU (the reference of
//! `grass_slice.wgsl`): the cell under a world point and its mirrored version (eq. 4.9), the
//! base-patch point there, which slice image and which side of it the eye sees and where in it,
//! the opacity algorithm 1 gives the blades drawn there, and their radiance from the five baked
//! light directions blended by appendix A's weights.

use super::lighting::{btf_weights, slice_ambient};
use super::patch::{Mirror, hash32};
use super::quadtree::CellGrid;
use super::slices::{LAYER_UNLIT, LAYERS, SliceAxis, SliceLayout, lit_layer};
use super::transition::{TransitionDistances, slice_opacity};
use bevy::math::{Vec2, Vec3};

/// Where a fragment reads the slices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlicePoint {
    /// The slice.
    pub slice: u32,
    /// Seen from its back.
    pub back: bool,
    /// The uv in its image (`[0, 1]²`, row 0 at the top).
    pub uv: Vec2,
    /// The cell's mirrored version.
    pub mirror: Mirror,
    /// The key of this quad's dither shift ([`shifted_dither`]): its cell and slice hashed.
    ///
    /// [`shifted_dither`]: super::transition::shifted_dither
    pub dither_key: u32,
}

impl SlicePoint {
    /// The first layer of this slice in an array of all slices' layers.
    pub fn base_layer(&self) -> u32 {
        self.slice * LAYERS
    }
}

/// The slice point of world point `p` on a quad of `axis` over a field of cells `grid` whose
/// ground is at `ground_y`, base patch mirrored by `seed`, seen from `eye`.
pub fn slice_point(
    layout: &SliceLayout,
    grid: &CellGrid,
    ground_y: f32,
    seed: u64,
    p: Vec3,
    axis: SliceAxis,
    eye: Vec3,
) -> SlicePoint {
    let size = grid.cell;
    let k = layout.per_axis;
    let cells = (Vec2::new(p.x, p.z) - grid.origin) / size;
    let cell = cells.floor();
    let f = cells - cell;
    let mirror = Mirror::of_cell(cell.x as i64, cell.y as i64, seed);
    let local = Vec2::new(
        if mirror.x { 1.0 - f.x } else { f.x },
        if mirror.z { 1.0 - f.y } else { f.y },
    ) * size;
    let row = (layout.height - (p.y - ground_y)) / layout.height;
    let sign = |m: bool| if m { -1.0 } else { 1.0 };
    let v = (eye - p).normalize_or(Vec3::Y) * Vec3::new(sign(mirror.x), 1.0, sign(mirror.z));
    let slab = size / k as f32;
    let point = match axis {
        SliceAxis::X => {
            let back = v.x < 0.0;
            SlicePoint {
                slice: ((local.x / slab) as u32).min(k - 1),
                back,
                uv: Vec2::new(
                    if back {
                        local.y / size
                    } else {
                        (size - local.y) / size
                    },
                    row,
                ),
                mirror,
                dither_key: 0,
            }
        }
        SliceAxis::Z => {
            let back = v.z < 0.0;
            SlicePoint {
                slice: k + ((local.y / slab) as u32).min(k - 1),
                back,
                uv: Vec2::new(
                    if back {
                        (size - local.x) / size
                    } else {
                        local.x / size
                    },
                    row,
                ),
                mirror,
                dither_key: 0,
            }
        }
        SliceAxis::Horizontal => SlicePoint {
            slice: 2 * k,
            back: false,
            uv: local / size,
            mirror,
            dither_key: 0,
        },
    };
    SlicePoint {
        dither_key: dither_key(cell.x as i64, cell.y as i64, point.slice),
        ..point
    }
}

/// The dither key of `slice` in cell `(i, j)` (32-bit, as the shader computes it).
pub fn dither_key(i: i64, j: i64, slice: u32) -> u32 {
    hash32((i as u32) ^ hash32((j as u32) ^ hash32(slice * LAYERS)))
}

/// The cosine between the view and the normals of the blades a slice texel shows, as the
/// slice's lighting takes it: the blades stand across a vertical slice's quad, facing along its
/// axis, and stand upright under the horizontal slice, their normals level; `to_eye` is the
/// unit view vector in the base patch's frame.
pub fn blade_n_dot_v(axis: SliceAxis, to_eye: Vec3) -> f32 {
    match axis {
        SliceAxis::X => to_eye.x.abs(),
        SliceAxis::Z => to_eye.z.abs(),
        SliceAxis::Horizontal => Vec2::new(to_eye.x, to_eye.z).length(),
    }
}

/// Algorithm 1 at a slice fragment: the coverage read from the unlit layer times the opacity of
/// the blade (of threshold `dth`, read from the threshold layer) under the slice's weight at
/// distance `d`, density `ld`; `n_dot_v` is the ground normal · unit view (eq. 4.14).
pub fn fragment_opacity(
    t: &TransitionDistances,
    axis: SliceAxis,
    coverage: f32,
    dth: f32,
    d: f32,
    ld: f32,
    n_dot_v: f32,
) -> f32 {
    let w = match axis {
        SliceAxis::Horizontal => t.horizontal_weight(d),
        _ => t.vertical_weight(d, n_dot_v),
    };
    // Where the vertical slices' weight is zero the horizontal slice carries the window's
    // complement alone.
    if axis != SliceAxis::Horizontal && w <= 0.0 {
        return 0.0;
    }
    coverage * slice_opacity(t, w, ld, dth)
}

/// The slice radiance before exposure: the ambient light on the unlit row (`kd·ao`) as Bevy's
/// PBR lights the blades ([`slice_ambient`], the blades' normals at `n_dot_v` to the view, no
/// terrain occlusion) and the sun (`sun` colour × `shadow`) through the baked directions
/// blended by appendix A for the light direction `l` in the base patch's frame, with Lambert's
/// 1/π. `layer(i)` reads layer `i` of the slice point's image.
#[allow(clippy::too_many_arguments)]
pub fn slice_radiance(
    point: &SlicePoint,
    layer: impl Fn(u32) -> [f32; 4],
    gamma: f32,
    n_dot_v: f32,
    ambient: Vec3,
    sun: Vec3,
    shadow: f32,
    l: Vec3,
) -> Vec3 {
    let unlit = layer(LAYER_UNLIT);
    let mut color = slice_ambient(
        Vec3::new(unlit[0], unlit[1], unlit[2]),
        gamma,
        n_dot_v,
        ambient,
        1.0,
    );
    let weights = btf_weights(l);
    let mut direct = Vec3::ZERO;
    for (i, w) in weights.iter().enumerate() {
        if *w > 0.0 {
            let c = layer(lit_layer(i, point.back));
            direct += *w * Vec3::new(c[0], c[1], c[2]);
        }
    }
    color += sun * shadow * direct / std::f32::consts::PI;
    color
}

/// The light direction `l` (world) in the frame of a cell showing `mirror`.
pub fn light_in_patch(l: Vec3, mirror: Mirror) -> Vec3 {
    Vec3::new(
        if mirror.x { -l.x } else { l.x },
        l.y,
        if mirror.z { -l.z } else { l.z },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup() -> (SliceLayout, CellGrid) {
        (
            SliceLayout {
                size: 0.5,
                height: 0.4,
                per_axis: 4,
                resolution: 64,
            },
            CellGrid {
                origin: Vec2::new(-1.0, -1.0),
                cell: 0.5,
                levels: 2,
            },
        )
    }

    #[test]
    fn a_point_reads_its_cell_s_mirrored_patch() {
        let (layout, grid) = setup();
        // Cell (1, 2): x ∈ [−0.5, 0), z ∈ [0, 0.5).
        let p = Vec3::new(-0.4, 0.01, 0.1);
        let top = slice_point(
            &layout,
            &grid,
            0.0,
            4,
            p,
            SliceAxis::Horizontal,
            Vec3::Y * 10.0,
        );
        let m = Mirror::of_cell(1, 2, 4);
        assert_eq!(top.mirror, m);
        let expect = Vec2::new(if m.x { 0.8 } else { 0.2 }, if m.z { 0.8 } else { 0.2 });
        assert!((top.uv - expect).length() < 1e-5, "{top:?}");
        assert_eq!(top.slice, 8);
        // A quad across x at local x in slab 1 or 2 (mirrored): the eye on the +x side sees the
        // front unless the cell mirrors x.
        let q = Vec3::new(-0.5 + 0.1875, 0.2, 0.1);
        let side = slice_point(
            &layout,
            &grid,
            0.0,
            4,
            q,
            SliceAxis::X,
            Vec3::new(5.0, 0.2, 0.1),
        );
        assert_eq!(side.back, m.x);
        assert_eq!(side.slice, if m.x { 2 } else { 1 });
        assert!((side.uv.y - 0.5).abs() < 1e-5);
    }

    #[test]
    fn opacity_follows_the_slice_weight() {
        let t = TransitionDistances::default();
        // Far: the horizontal slice at full weight keeps every blade under the density.
        let h = fragment_opacity(&t, SliceAxis::Horizontal, 1.0, 0.3, 100.0, 0.8, 1.0);
        assert_eq!(h, 1.0);
        // The vertical slices are gone there (off silhouettes).
        assert_eq!(
            fragment_opacity(&t, SliceAxis::X, 1.0, 0.3, 100.0, 0.8, 1.0),
            0.0
        );
        // Half coverage halves it.
        assert_eq!(
            fragment_opacity(&t, SliceAxis::Horizontal, 0.5, 0.3, 100.0, 0.8, 1.0),
            0.5
        );
        // Above the density: nothing.
        assert_eq!(
            fragment_opacity(&t, SliceAxis::Horizontal, 1.0, 0.9, 100.0, 0.8, 1.0),
            0.0
        );
    }

    /// A quad's dither key follows its cell and slice, and seen across a slice the blades face
    /// the eye as the slice's axis does.
    #[test]
    fn each_quad_of_each_cell_has_its_own_dither_key() {
        let (layout, grid) = setup();
        let at = |p: Vec3, axis| slice_point(&layout, &grid, 0.0, 4, p, axis, Vec3::Y * 10.0);
        let a = at(Vec3::new(-0.9, 0.1, -0.9), SliceAxis::Horizontal);
        assert_eq!(a.dither_key, dither_key(0, 0, 8));
        let b = at(Vec3::new(-0.4, 0.1, -0.9), SliceAxis::Horizontal);
        assert_eq!(b.dither_key, dither_key(1, 0, 8));
        let keys: std::collections::HashSet<u32> = (0..4i64)
            .flat_map(|i| (0..4i64).flat_map(move |j| (0..9).map(move |s| dither_key(i, j, s))))
            .map(|k| k & 15)
            .collect();
        assert_eq!(keys.len(), 16, "the shifts spread over all sixteen");
        let v = Vec3::new(0.6, 0.0, 0.8);
        assert_eq!(blade_n_dot_v(SliceAxis::X, v), 0.6);
        assert_eq!(blade_n_dot_v(SliceAxis::Z, -v), 0.8);
        assert!(
            (blade_n_dot_v(SliceAxis::Horizontal, Vec3::new(0.6, 0.8, 0.0)) - 0.6).abs() < 1e-6
        );
    }

    #[test]
    fn the_sun_straight_above_reads_the_top_layer_only() {
        let point = SlicePoint {
            slice: 0,
            back: true,
            uv: Vec2::ZERO,
            mirror: Mirror { x: false, z: false },
            dither_key: 0,
        };
        let layer = |i: u32| {
            if i == lit_layer(0, true) {
                [0.5, 0.5, 0.5, 1.0]
            } else if i == LAYER_UNLIT {
                [0.2, 0.2, 0.2, 1.0]
            } else {
                [9.0, 9.0, 9.0, 1.0]
            }
        };
        let sun = |ambient: Vec3| {
            slice_radiance(
                &point,
                layer,
                0.25,
                1.0,
                ambient,
                Vec3::splat(std::f32::consts::PI),
                1.0,
                Vec3::Y,
            )
        };
        let c = sun(Vec3::ZERO);
        assert!((c - Vec3::splat(0.5)).length() < 1e-5, "{c}");
        // The ambient light on top, as `slice_ambient` has it.
        let with_ambient = sun(Vec3::ONE) - c;
        let want = slice_ambient(Vec3::splat(0.2), 0.25, 1.0, Vec3::ONE, 1.0);
        assert!((with_ambient - want).length() < 1e-6, "{with_ambient}");
        assert_eq!(
            light_in_patch(Vec3::new(1.0, 2.0, 3.0), Mirror { x: true, z: false }),
            Vec3::new(-1.0, 2.0, 3.0)
        );
    }
}
