//! Bake step 2: per-cell visibility from a set of viewpoints (Gumbau 2011, §3.3.2, eq. 3.1).
//!
//! `vis(cell, view) = visible pixels of the cell with all leaves drawn ÷ pixels of the cell
//! drawn alone`. The thesis counts both with hardware occlusion queries; here a small CPU
//! rasteriser measures the same ratio:
//!
//! - one pass draws every leaf triangle with a depth test into an *owner* buffer (the cell of the
//!   nearest leaf at each pixel): a cell's visible pixels are the pixels it owns;
//! - a coverage pass draws each cell alone (no depth needed: a pixel counts once however many of
//!   the cell's own leaves cover it, like the thesis' second, depth-equal pass).
//!
//! Leaves are rasterised through their texture's alpha mask when the tree has one
//! ([`AlphaMask`]): a pixel whose interpolated texture coordinates land on a texel under the
//! material's cutoff is not drawn, in either pass, exactly as the leaf material discards it. A
//! card's transparent part then hides nothing, and a cell is measured by its opaque pixels.
//!
//! Views are orthographic (a distant viewer) along directions spread evenly over the whole
//! sphere by a Fibonacci lattice, so that trees seen from below or from the air are covered as
//! well as trees seen from the side. A cell invisible from a view because it covers no pixel at
//! all (smaller than a pixel) gets visibility 1: nothing hides it, so it must not be pruned as if
//! it were occluded. Views are processed in parallel.

use super::mask::AlphaMask;
use bevy::math::{Vec2, Vec3};

/// `count` unit directions spread evenly over the sphere (Fibonacci lattice). Direction `k`
/// points from the tree towards viewpoint `k`.
pub fn fibonacci_directions(count: usize) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..count)
        .map(|k| {
            let y = 1.0 - 2.0 * (k as f32 + 0.5) / count as f32;
            let r = (1.0 - y * y).max(0.0).sqrt();
            let phi = k as f32 * golden;
            Vec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect()
}

/// An orthographic view of the tree along `direction`, fitted to a bounding sphere.
#[derive(Clone, Copy, Debug)]
pub struct OrthoView {
    right: Vec3,
    up: Vec3,
    toward_viewer: Vec3,
    center: Vec3,
    scale: f32,
    resolution: u32,
}

impl OrthoView {
    /// A view from `direction` (tree → viewer) of the sphere `(center, radius)` at
    /// `resolution × resolution` pixels.
    pub fn new(direction: Vec3, center: Vec3, radius: f32, resolution: u32) -> Self {
        let toward_viewer = direction.normalize();
        let right = toward_viewer.any_orthonormal_vector();
        let up = toward_viewer.cross(right);
        Self {
            right,
            up,
            toward_viewer,
            center,
            scale: resolution as f32 / (2.0 * radius.max(1e-6)),
            resolution,
        }
    }

    /// Pixel coordinates and depth (larger is nearer the viewer) of a point.
    pub fn project(&self, p: Vec3) -> (Vec2, f32) {
        let d = p - self.center;
        let half = self.resolution as f32 * 0.5;
        (
            Vec2::new(
                d.dot(self.right) * self.scale + half,
                half - d.dot(self.up) * self.scale,
            ),
            d.dot(self.toward_viewer),
        )
    }
}

/// Calls `plot(x, y, depth, barycentrics)` for every pixel whose centre is inside the triangle
/// (edge functions; pixels on a shared edge go to one triangle only, by the top-left rule). The
/// barycentric weights are those of the triangle's corners in the order given.
pub fn rasterize_triangle(
    tri: [(Vec2, f32); 3],
    resolution: u32,
    mut plot: impl FnMut(u32, u32, f32, Vec3),
) {
    let [(mut a, za), (mut b, zb), (c, zc)] = tri;
    let (mut za, mut zb) = (za, zb);
    let mut area = (b - a).perp_dot(c - a);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let swapped = area < 0.0;
    if swapped {
        std::mem::swap(&mut a, &mut b);
        std::mem::swap(&mut za, &mut zb);
        area = -area;
    }
    let min = a.min(b).min(c).floor().max(Vec2::ZERO);
    let max = a.max(b).max(c).ceil().min(Vec2::splat(resolution as f32));
    if min.x >= max.x || min.y >= max.y {
        return;
    }
    // Top-left rule with y pointing down: an edge owns its pixels if it is a top or left edge.
    let owns = |e0: Vec2, e1: Vec2| {
        let d = e1 - e0;
        (d.y == 0.0 && d.x > 0.0) || d.y < 0.0
    };
    let (own_bc, own_ca, own_ab) = (owns(b, c), owns(c, a), owns(a, b));
    for y in min.y as u32..max.y as u32 {
        for x in min.x as u32..max.x as u32 {
            let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let w0 = (c - b).perp_dot(p - b);
            let w1 = (a - c).perp_dot(p - c);
            let w2 = (b - a).perp_dot(p - a);
            let inside = |w: f32, own: bool| w > 0.0 || (w == 0.0 && own);
            if inside(w0, own_bc) && inside(w1, own_ca) && inside(w2, own_ab) {
                let z = (w0 * za + w1 * zb + w2 * zc) / area;
                let w = Vec3::new(w0, w1, w2) / area;
                plot(x, y, z, if swapped { Vec3::new(w.y, w.x, w.z) } else { w });
            }
        }
    }
}

/// A leaf triangle: corner positions and texture coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafTriangle {
    /// Corner positions (model space).
    pub positions: [Vec3; 3],
    /// Corner texture coordinates.
    pub uvs: [Vec2; 3],
}

impl LeafTriangle {
    /// A triangle with zero texture coordinates (for untextured leaves).
    pub fn untextured(positions: [Vec3; 3]) -> Self {
        Self {
            positions,
            uvs: [Vec2::ZERO; 3],
        }
    }
}

/// Input of the visibility bake: leaf triangles grouped by cell.
pub struct VisibilityInput<'a> {
    /// For each cell, its triangles.
    pub cell_triangles: &'a [Vec<LeafTriangle>],
    /// The leaves' alpha mask: texels under its cutoff are not drawn. `None`: leaves are opaque.
    pub mask: Option<&'a AlphaMask>,
    /// Centre of a sphere bounding every triangle.
    pub center: Vec3,
    /// Its radius.
    pub radius: f32,
    /// Raster resolution per view.
    pub resolution: u32,
}

/// Visibility of every cell from one view: `vis[cell]` in `[0, 1]` (eq. 3.1).
pub fn cell_visibility_for_view(input: &VisibilityInput, direction: Vec3) -> Vec<f32> {
    let res = input.resolution;
    let view = OrthoView::new(direction, input.center, input.radius, res);
    let pixels = (res * res) as usize;
    let mut depth = vec![f32::NEG_INFINITY; pixels];
    let mut owner = vec![u32::MAX; pixels];
    let project = |t: &LeafTriangle| {
        let p = &t.positions;
        [view.project(p[0]), view.project(p[1]), view.project(p[2])]
    };
    // Whether the leaf is drawn at barycentrics `w` of triangle `t`: its mask texel is opaque.
    let drawn = |t: &LeafTriangle, w: Vec3| {
        input
            .mask
            .is_none_or(|m| m.opaque_at(t.uvs[0] * w.x + t.uvs[1] * w.y + t.uvs[2] * w.z))
    };
    for (cell, triangles) in input.cell_triangles.iter().enumerate() {
        for t in triangles {
            rasterize_triangle(project(t), res, |x, y, z, w| {
                let i = (y * res + x) as usize;
                if z > depth[i] && drawn(t, w) {
                    depth[i] = z;
                    owner[i] = cell as u32;
                }
            });
        }
    }
    let mut visible = vec![0u32; input.cell_triangles.len()];
    for &o in &owner {
        if o != u32::MAX {
            visible[o as usize] += 1;
        }
    }
    // Coverage of each cell alone; `stamp` avoids clearing a mask per cell.
    let mut stamp = vec![u32::MAX; pixels];
    input
        .cell_triangles
        .iter()
        .enumerate()
        .map(|(cell, triangles)| {
            let mut covered = 0u32;
            for t in triangles {
                rasterize_triangle(project(t), res, |x, y, _, w| {
                    let i = (y * res + x) as usize;
                    if stamp[i] != cell as u32 && drawn(t, w) {
                        stamp[i] = cell as u32;
                        covered += 1;
                    }
                });
            }
            if covered == 0 {
                1.0
            } else {
                (visible[cell] as f32 / covered as f32).min(1.0)
            }
        })
        .collect()
}

/// Visibility of every cell from every view, computed on `threads` threads.
/// Returns `vis[cell * views + view]`.
pub fn cell_visibility(
    input: &VisibilityInput,
    directions: &[Vec3],
    threads: usize,
    progress: &(dyn Fn(usize) + Sync),
) -> Vec<f32> {
    let cells = input.cell_triangles.len();
    let views = directions.len();
    let per_view: Vec<Vec<f32>> = {
        let next = std::sync::atomic::AtomicUsize::new(0);
        let done = std::sync::atomic::AtomicUsize::new(0);
        let results = std::sync::Mutex::new(vec![Vec::new(); views]);
        std::thread::scope(|scope| {
            for _ in 0..threads.clamp(1, views.max(1)) {
                scope.spawn(|| {
                    loop {
                        let v = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        if v >= views {
                            break;
                        }
                        let vis = cell_visibility_for_view(input, directions[v]);
                        results.lock().unwrap()[v] = vis;
                        let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                        progress(n);
                    }
                });
            }
        });
        results.into_inner().unwrap()
    };
    let mut out = vec![0.0; cells * views];
    for (v, vis) in per_view.iter().enumerate() {
        for (c, &x) in vis.iter().enumerate() {
            out[c * views + v] = x;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square card at depth `z`, texture coordinates spanning the unit square.
    fn square(z: f32, half: f32) -> Vec<LeafTriangle> {
        let p = |x: f32, y: f32| Vec3::new(x, y, z);
        let t = |x: f32, y: f32| Vec2::new(x, y);
        vec![
            LeafTriangle {
                positions: [p(-half, -half), p(half, -half), p(half, half)],
                uvs: [t(0.0, 1.0), t(1.0, 1.0), t(1.0, 0.0)],
            },
            LeafTriangle {
                positions: [p(-half, -half), p(half, half), p(-half, half)],
                uvs: [t(0.0, 1.0), t(1.0, 0.0), t(0.0, 0.0)],
            },
        ]
    }

    #[test]
    fn directions_are_unit_and_spread() {
        let d = fibonacci_directions(16);
        assert_eq!(d.len(), 16);
        assert!(d.iter().all(|v| (v.length() - 1.0).abs() < 1e-5));
        let mean = d.iter().copied().sum::<Vec3>() / 16.0;
        assert!(mean.length() < 0.1, "evenly spread: mean {mean}");
        // Both hemispheres.
        assert!(d.iter().any(|v| v.y > 0.8) && d.iter().any(|v| v.y < -0.8));
    }

    #[test]
    fn rasteriser_covers_area_without_double_counting_shared_edges() {
        let res = 64;
        let view = OrthoView::new(Vec3::Z, Vec3::ZERO, 1.0, res);
        let mut hits = vec![0u8; (res * res) as usize];
        for t in square(0.0, 0.5) {
            let p = t.positions;
            let tri = [view.project(p[0]), view.project(p[1]), view.project(p[2])];
            rasterize_triangle(tri, res, |x, y, _, w| {
                assert!((w.x + w.y + w.z - 1.0).abs() < 1e-5 && w.min_element() >= -1e-6);
                hits[(y * res + x) as usize] += 1
            });
        }
        assert!(hits.iter().all(|&h| h <= 1), "shared diagonal drawn twice");
        let covered = hits.iter().filter(|&&h| h == 1).count();
        // The square covers a quarter of the view: 32 × 32 pixels.
        assert_eq!(covered, 32 * 32);
    }

    #[test]
    fn front_cell_hides_half_of_back_cell() {
        // Cell 0: a big square at z = 0; cell 1: a square twice as wide behind it... seen from +z
        // the front one (half the size) hides a quarter of the back one.
        let front = square(1.0, 0.25);
        let back = square(0.0, 0.5);
        let cells = vec![front, back];
        let input = VisibilityInput {
            cell_triangles: &cells,
            mask: None,
            center: Vec3::ZERO,
            radius: 1.0,
            resolution: 64,
        };
        let from_front = cell_visibility_for_view(&input, Vec3::Z);
        assert_eq!(from_front[0], 1.0);
        assert!((from_front[1] - 0.75).abs() < 1e-6, "{from_front:?}");
        // From behind, the back square hides the whole front one.
        let from_back = cell_visibility_for_view(&input, -Vec3::Z);
        assert_eq!(from_back[1], 1.0);
        assert_eq!(from_back[0], 0.0);
        // All views at once, in parallel, agree with the single-view function.
        let dirs = [Vec3::Z, -Vec3::Z];
        let all = cell_visibility(&input, &dirs, 2, &|_| {});
        assert_eq!(all, vec![1.0, 0.0, from_front[1], 1.0]);
    }

    #[test]
    fn barycentrics_interpolate_the_corners_whatever_the_winding() {
        let view = OrthoView::new(Vec3::Z, Vec3::ZERO, 1.0, 32);
        for t in square(0.0, 0.8) {
            for order in [[0, 1, 2], [1, 0, 2]] {
                let p = order.map(|i| t.positions[i]);
                let tri = [view.project(p[0]), view.project(p[1]), view.project(p[2])];
                rasterize_triangle(tri, 32, |x, y, _, w| {
                    // The interpolated position is the pixel centre.
                    let at = p[0] * w.x + p[1] * w.y + p[2] * w.z;
                    let (pixel, _) = view.project(at);
                    assert!((pixel - Vec2::new(x as f32 + 0.5, y as f32 + 0.5)).length() < 1e-3);
                });
            }
        }
    }

    #[test]
    fn a_cards_transparent_part_hides_nothing() {
        // Front card: opaque only on the left quarter of its texture; back card: fully opaque
        // and the same size. Without the mask the front card hides the whole back card.
        let front = square(1.0, 0.5);
        let back = square(0.0, 0.5);
        let cells = vec![front, back];
        let alpha: Vec<u8> = (0..64).map(|i| if i % 8 < 2 { 255 } else { 0 }).collect();
        let mask = AlphaMask::new(8, 8, &alpha, 0.5).unwrap();
        let solid = VisibilityInput {
            cell_triangles: &cells,
            mask: None,
            center: Vec3::ZERO,
            radius: 1.0,
            resolution: 64,
        };
        assert_eq!(cell_visibility_for_view(&solid, Vec3::Z)[1], 0.0);
        // The back card is masked too: its opaque quarter is exactly behind the front card's.
        let masked = VisibilityInput {
            mask: Some(&mask),
            ..solid
        };
        let vis = cell_visibility_for_view(&masked, Vec3::Z);
        assert_eq!(vis[0], 1.0);
        assert_eq!(vis[1], 0.0, "opaque parts aligned: hidden");
        // Shift the back card so its opaque quarter sits behind the front card's transparent
        // part: fully visible.
        let shifted: Vec<LeafTriangle> = square(0.0, 0.5)
            .into_iter()
            .map(|mut t| {
                for p in &mut t.positions {
                    p.x += 0.5;
                }
                t
            })
            .collect();
        let cells = vec![square(1.0, 0.5), shifted];
        let vis = cell_visibility_for_view(
            &VisibilityInput {
                cell_triangles: &cells,
                ..masked
            },
            Vec3::Z,
        );
        assert_eq!(vis[1], 1.0, "behind the transparent part: visible");
    }
}
