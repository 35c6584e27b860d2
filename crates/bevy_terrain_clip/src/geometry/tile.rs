//! A patch's mesh: four triangular tiles, one on each edge, meeting along the patch's diagonals
//! (paper 4, §3 "Patch scheme", fig. 2–4).
//!
//! A tile with `n` segments on its edge is the regular grid of spacing `δ = side/n` inside the
//! triangle of that edge and the patch centre, rows parallel to the edge. Two tiles of different
//! resolutions meet along a half-diagonal, where their grids do not match; the paper joins them
//! with stitching strips. Here each tile keeps the band along its two half-diagonals (between the
//! diagonal and the grid line one column in) as its own stitching strip, which joins its grid to
//! the half-diagonal's shared vertices — the coarser tile's spacing, `min(n_a, n_b)/2` segments
//! ([`SelectedPatch::diagonal`]). Strips and rows are triangulated by merging two parallel
//! polylines along their common direction (`zip`), so every triangle has vertices on two
//! distinct parallel lines: none is degenerate, and the mesh needs no T-junctions.
//!
//! Coordinates are integers: within a patch, units of `1/r_high` of its side (the *unit* tile
//! meshes the GPU instances, in four orientations); over the terrain, the lattice of
//! [`PatchGrid`] (a patch's unit is `2^(max_level − level)` lattice steps).

use super::patch::{PatchGrid, SelectedPatch};
use std::collections::HashMap;

/// A point in integer coordinates.
pub type Point = [u32; 2];

/// A mesh in integer coordinates: vertices and triangles, wound counter-clockwise seen from
/// above (+y) once `x` and `y` map to world x and z — Bevy's front faces.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PatchMesh {
    /// Vertex positions.
    pub vertices: Vec<Point>,
    /// Triangles, as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

impl PatchMesh {
    fn add(&mut self, index: &mut HashMap<Point, u32>, t: [Point; 3]) {
        // Front faces: counter-clockwise seen from above, which is clockwise in (x, z).
        let [a, b, c] = t;
        let cross = (b[0] as i64 - a[0] as i64) * (c[1] as i64 - a[1] as i64)
            - (b[1] as i64 - a[1] as i64) * (c[0] as i64 - a[0] as i64);
        debug_assert!(cross != 0, "degenerate triangle {t:?}");
        let ordered = if cross < 0 { [a, b, c] } else { [a, c, b] };
        let mut id = |p: Point| {
            *index.entry(p).or_insert_with(|| {
                self.vertices.push(p);
                self.vertices.len() as u32 - 1
            })
        };
        let tri = ordered.map(&mut id);
        self.triangles.push(tri);
    }
}

/// Triangulates the band between two polylines on parallel lines, both running the same way
/// along it (`t` increasing): the merge of their vertices by `t`, a triangle per step.
fn zip(a: &[Point], b: &[Point], t: impl Fn(Point) -> i64, out: &mut Vec<[Point; 3]>) {
    let (mut i, mut j) = (0, 0);
    while i + 1 < a.len() || j + 1 < b.len() {
        let take_a = if i + 1 == a.len() {
            false
        } else if j + 1 == b.len() {
            true
        } else {
            t(a[i + 1]) <= t(b[j + 1])
        };
        if take_a {
            out.push([a[i], a[i + 1], b[j]]);
            i += 1;
        } else {
            out.push([a[i], b[j + 1], b[j]]);
            j += 1;
        }
    }
}

/// The triangles of one tile in patch units (side `side`), on the edge from (0, 0) to
/// (side, 0) with the centre at (side/2, side/2): `n` segments on the edge, `d_start` and
/// `d_end` on the half-diagonals from (0, 0) and from (side, 0) to the centre.
///
/// `n` must divide `side`, be even and at least 2; `2·d` must divide `side`.
pub fn tile_triangles(side: u32, n: u32, d_start: u32, d_end: u32) -> Vec<[Point; 3]> {
    debug_assert!(n >= 2 && n.is_multiple_of(2) && side.is_multiple_of(n));
    debug_assert!(d_start >= 1 && d_end >= 1 && side.is_multiple_of(2 * d_start));
    debug_assert!(side.is_multiple_of(2 * d_end));
    let delta = side / n;
    let half = n / 2;
    let mut out = Vec::new();
    // Rows of the inner grid: row j holds columns j + 1 ..= n − j − 1 (one column in from each
    // half-diagonal); the last row is the single point under the centre.
    let row = |j: u32| -> Vec<Point> {
        (j + 1..=n - j - 1)
            .map(|i| [i * delta, j * delta])
            .collect()
    };
    for j in 0..half - 1 {
        zip(&row(j), &row(j + 1), |p| p[0] as i64, &mut out);
    }
    // The stitching strips: the half-diagonal at its shared spacing against the grid line one
    // column in, from the edge up to the point under the centre.
    let centre = side / 2;
    let start_diagonal: Vec<Point> = (0..=d_start)
        .map(|m| {
            let s = m * centre / d_start;
            [s, s]
        })
        .collect();
    let start_inner: Vec<Point> = (0..half).map(|j| [(j + 1) * delta, j * delta]).collect();
    zip(
        &start_diagonal,
        &start_inner,
        |p| p[0] as i64 + p[1] as i64,
        &mut out,
    );
    let end_diagonal: Vec<Point> = (0..=d_end)
        .map(|m| {
            let s = m * centre / d_end;
            [side - s, s]
        })
        .collect();
    let end_inner: Vec<Point> = (0..half)
        .map(|j| [(n - j - 1) * delta, j * delta])
        .collect();
    zip(
        &end_diagonal,
        &end_inner,
        |p| p[1] as i64 - p[0] as i64,
        &mut out,
    );
    out
}

/// A point of the tile on edge 0 turned onto edge `e` of a patch of side `side` (a rotation by
/// `e` quarter turns about the centre: edge `e` runs from corner `e` to corner `e + 1`,
/// counter-clockwise in (x, y), as in [`PatchId::corner_point`](super::PatchId::corner_point)).
pub fn orient(side: u32, e: usize, [u, v]: Point) -> Point {
    match e % 4 {
        0 => [u, v],
        1 => [side - v, u],
        2 => [side - u, side - v],
        _ => [v, side - u],
    }
}

/// The unit mesh of one tile, in patch units (side `r_high`), turned onto edge `e`: what the GPU
/// instances, scaled by the patch's side.
pub fn unit_tile(r_high: u32, e: usize, n: u32, d_start: u32, d_end: u32) -> PatchMesh {
    let mut mesh = PatchMesh::default();
    let mut index = HashMap::new();
    for t in tile_triangles(r_high, n, d_start, d_end) {
        mesh.add(&mut index, t.map(|p| orient(r_high, e, p)));
    }
    mesh
}

/// The CPU reference of a selected patch's mesh, in lattice coordinates of `grid`: its four
/// tiles with their stitching strips.
pub fn patch_mesh(grid: &PatchGrid, patch: &SelectedPatch) -> PatchMesh {
    let unit = patch.id.side(grid) / grid.r_high;
    let [x0, y0] = patch.id.corner(grid);
    let mut mesh = PatchMesh::default();
    let mut index = HashMap::new();
    for e in 0..4 {
        let tile = tile_triangles(
            grid.r_high,
            patch.edges[e],
            patch.diagonal(e),
            patch.diagonal(e + 1),
        );
        for t in tile {
            mesh.add(
                &mut index,
                t.map(|p| {
                    let [u, v] = orient(grid.r_high, e, p);
                    [x0 + u * unit, y0 + v * unit]
                }),
            );
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::patch::PatchId;
    use std::collections::HashMap;

    fn twice_area(t: &[Point; 3]) -> i64 {
        let [a, b, c] = *t;
        ((b[0] as i64 - a[0] as i64) * (c[1] as i64 - a[1] as i64)
            - (b[1] as i64 - a[1] as i64) * (c[0] as i64 - a[0] as i64))
            .abs()
    }

    /// Edges of a mesh with how many triangles use each.
    fn edge_uses(mesh: &PatchMesh) -> HashMap<(Point, Point), u32> {
        let mut uses = HashMap::new();
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (
                    mesh.vertices[t[k] as usize],
                    mesh.vertices[t[(k + 1) % 3] as usize],
                );
                *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        uses
    }

    #[test]
    fn a_tile_fills_its_triangle_with_its_edge_and_diagonals_as_asked() {
        let side = 16;
        for (n, d0, d1) in [(16, 8, 4), (8, 4, 4), (16, 4, 8), (4, 1, 2), (2, 1, 1)] {
            let tris = tile_triangles(side, n, d0, d1);
            // Area: the triangle of the edge and the centre, side²/4, twice over.
            let area: i64 = tris.iter().map(twice_area).sum();
            assert_eq!(area, (side * side / 2) as i64, "n {n}, d {d0} {d1}");
            assert!(tris.iter().all(|t| twice_area(t) > 0), "degenerate");
            let mesh = {
                let mut m = PatchMesh::default();
                let mut index = HashMap::new();
                for t in tris {
                    m.add(&mut index, t);
                }
                m
            };
            // Inside edges are shared by two triangles; the boundary — the edge and both
            // half-diagonals — by one, at exactly the asked spacings.
            let mut on_edge = Vec::new();
            let mut on_start = Vec::new();
            let mut on_end = Vec::new();
            for ((a, b), uses) in edge_uses(&mesh) {
                let edge = a[1] == 0 && b[1] == 0;
                let start = a[0] == a[1] && b[0] == b[1];
                let end = a[0] + a[1] == side && b[0] + b[1] == side;
                if edge {
                    on_edge.push((a, b));
                } else if start {
                    on_start.push((a, b));
                } else if end {
                    on_end.push((a, b));
                }
                assert_eq!(
                    uses,
                    if edge || start || end { 1 } else { 2 },
                    "{a:?}-{b:?}"
                );
            }
            assert_eq!(on_edge.len() as u32, n);
            assert_eq!(on_start.len() as u32, d0);
            assert_eq!(on_end.len() as u32, d1);
            assert!(on_edge.iter().all(|(a, b)| b[0] - a[0] == side / n));
        }
    }

    #[test]
    fn the_four_orientations_are_quarter_turns_and_keep_the_winding() {
        let side = 8;
        for e in 0..4 {
            let mesh = unit_tile(side, e, 8, 2, 4);
            // Every triangle faces up: clockwise in (x, z).
            for t in &mesh.triangles {
                let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
                let cross = (b[0] as i64 - a[0] as i64) * (c[1] as i64 - a[1] as i64)
                    - (b[1] as i64 - a[1] as i64) * (c[0] as i64 - a[0] as i64);
                assert!(cross < 0);
            }
            // The edge's first vertex is corner e.
            let corner = orient(side, e, [0, 0]);
            let expected = PatchId::ROOT.corner_point(
                &PatchGrid::new(bevy::math::Vec2::ZERO, 1.0, 0, side).unwrap(),
                e,
            );
            assert_eq!(corner, expected);
            assert_eq!(orient(side, e, [4, 4]), [4, 4], "the centre stays");
        }
    }

    #[test]
    fn a_patch_with_mixed_tiles_is_watertight() {
        let grid = PatchGrid::new(bevy::math::Vec2::ZERO, 64.0, 2, 8).unwrap();
        for edges in [
            [8, 4, 8, 4],
            [4, 4, 4, 4],
            [8, 8, 8, 8],
            [8, 8, 4, 4],
            [4, 8, 8, 8],
        ] {
            let patch = SelectedPatch {
                id: PatchId {
                    level: 2,
                    x: 1,
                    y: 2,
                },
                edges,
            };
            let mesh = patch_mesh(&grid, &patch);
            let side = patch.id.side(&grid);
            let area: i64 = mesh
                .triangles
                .iter()
                .map(|t| twice_area(&t.map(|i| mesh.vertices[i as usize])))
                .sum();
            assert_eq!(area, 2 * (side as i64).pow(2), "{edges:?}");
            let [x0, y0] = patch.id.corner(&grid);
            for ((a, b), uses) in edge_uses(&mesh) {
                let border = (a[0] == b[0] && (a[0] == x0 || a[0] == x0 + side))
                    || (a[1] == b[1] && (a[1] == y0 || a[1] == y0 + side));
                assert_eq!(uses, if border { 1 } else { 2 }, "{edges:?}: {a:?}-{b:?}");
            }
        }
    }
}
