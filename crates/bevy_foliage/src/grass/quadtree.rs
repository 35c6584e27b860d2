//! Which grid cells of a grass field to draw, and how (Boulanger 2008, thesis §4.2.7.1–4.2.7.2):
//! an implicit quadtree over the grid of base-patch cells, each node bounded by a sphere, walked
//! from the root by frustum and distance. Near the eye the walk goes down to single cells (where
//! blade geometry and vertical slices are drawn); far away a whole node is drawn as one
//! *macro-cell* of horizontal slice, its texture repeated once per cell — but only where the
//! node is flat, since a macro-cell is a single quad and would cut through a hill.
//!
//! The tree is implicit (a node is its level and position; the thesis builds it in a
//! preprocessing step), and the ground is asked for through [`GroundBounds`], so a field of
//! millions of cells costs only the nodes the walk visits.

use bevy::math::{Vec2, Vec3, Vec4};

/// The grid of cells a field is drawn on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellGrid {
    /// World (x, z) of cell (0, 0)'s corner.
    pub origin: Vec2,
    /// Side of a cell: the base patch's (m).
    pub cell: f32,
    /// Depth: the grid is `2^levels` cells a side; the root (level 0) covers it all.
    pub levels: u8,
}

/// A node of the implicit quadtree: `2^(levels − level)` cells a side.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct CellNode {
    /// 0 for the root; `levels` for single cells.
    pub level: u8,
    /// Column among the level's nodes.
    pub x: u32,
    /// Row among the level's nodes (along z).
    pub z: u32,
}

impl CellGrid {
    /// Cells along a side of `node`.
    pub fn cells_across(&self, node: CellNode) -> u32 {
        1 << (self.levels - node.level)
    }

    /// The world rectangle of `node`: its corner (x, z) and side.
    pub fn rect(&self, node: CellNode) -> (Vec2, f32) {
        let side = self.cells_across(node) as f32 * self.cell;
        (
            self.origin + Vec2::new(node.x as f32, node.z as f32) * side,
            side,
        )
    }
}

impl CellNode {
    /// The root.
    pub const ROOT: Self = Self {
        level: 0,
        x: 0,
        z: 0,
    };

    /// Its four children.
    pub fn children(self) -> [Self; 4] {
        let (x, z, level) = (self.x * 2, self.z * 2, self.level + 1);
        [
            Self { level, x, z },
            Self { level, x: x + 1, z },
            Self { level, x, z: z + 1 },
            Self {
                level,
                x: x + 1,
                z: z + 1,
            },
        ]
    }
}

/// What the walk needs to know about the ground under a node.
pub trait GroundBounds {
    /// The lowest and highest ground under the node's rectangle (m), grass tips not included.
    fn height_range(&self, grid: &CellGrid, node: CellNode) -> (f32, f32);
    /// Whether the node's ground lies in one plane (within the field's tolerance): the thesis'
    /// flatness flag. Single cells are drawn however they lie.
    fn is_flat(&self, grid: &CellGrid, node: CellNode) -> bool;
}

/// How a drawn node is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellDraw {
    /// A single cell: every representation its distance calls for.
    Cell,
    /// A flat node beyond the vertical slices' reach: one quad of horizontal slice, repeated
    /// once per cell (eq. 4.8–4.9).
    MacroCell,
}

/// The walk's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellView {
    /// The eye (world).
    pub eye: Vec3,
    /// The view frustum's planes `(n, d)` with `n·p + d ≥ 0` inside; `None`: no culling.
    pub frustum: Option<[Vec4; 6]>,
    /// Nothing is drawn beyond this distance (m).
    pub max_distance: f32,
    /// Macro-cells only beyond this distance (m): `max_btf`, where only the horizontal slice is
    /// left (vertical slices and geometry need single cells).
    pub macro_from: f32,
    /// A node is drawn whole only when the eye is at least this many node sides from it (the
    /// farther, the larger the macro-cells).
    pub split_factor: f32,
    /// Tallest grass (m): the spheres bound the blades too.
    pub grass_height: f32,
}

/// The walk's result.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellSelection {
    /// The nodes drawn, and how.
    pub drawn: Vec<(CellNode, CellDraw)>,
    /// Nodes visited.
    pub visited: u32,
    /// Nodes culled by the frustum or the distance.
    pub culled: u32,
}

/// The bounding sphere of `node` (centre, radius), grass included.
pub fn node_sphere(
    grid: &CellGrid,
    ground: &impl GroundBounds,
    node: CellNode,
    grass_height: f32,
) -> (Vec3, f32) {
    let (corner, side) = grid.rect(node);
    let (low, high) = ground.height_range(grid, node);
    let high = high + grass_height.max(0.0);
    let centre = Vec3::new(
        corner.x + side / 2.0,
        (low + high) / 2.0,
        corner.y + side / 2.0,
    );
    let half = Vec3::new(side / 2.0, (high - low) / 2.0, side / 2.0);
    (centre, half.length())
}

/// Walks the tree for `view`: frustum and distance culling by each node's sphere; a node is drawn
/// as a macro-cell where it is flat, wholly beyond `macro_from` and far enough for its size, else
/// split down to single cells.
pub fn select_cells(grid: &CellGrid, ground: &impl GroundBounds, view: &CellView) -> CellSelection {
    let mut selection = CellSelection::default();
    let mut stack = vec![CellNode::ROOT];
    while let Some(node) = stack.pop() {
        selection.visited += 1;
        let (centre, radius) = node_sphere(grid, ground, node, view.grass_height);
        let distance = (centre.distance(view.eye) - radius).max(0.0);
        let outside = view.frustum.is_some_and(|planes| {
            planes
                .iter()
                .any(|p| p.truncate().dot(centre) + p.w < -radius)
        });
        if outside || distance > view.max_distance {
            selection.culled += 1;
            continue;
        }
        if node.level == grid.levels {
            selection.drawn.push((node, CellDraw::Cell));
            continue;
        }
        let (_, side) = grid.rect(node);
        if distance >= view.macro_from
            && distance >= view.split_factor * side
            && ground.is_flat(grid, node)
        {
            selection.drawn.push((node, CellDraw::MacroCell));
            continue;
        }
        stack.extend(node.children());
    }
    selection
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Flat ground at y = 0 except a hill (not flat) over x ∈ [hill.0, hill.1].
    struct Ground {
        hill: (f32, f32),
    }

    impl GroundBounds for Ground {
        fn height_range(&self, grid: &CellGrid, node: CellNode) -> (f32, f32) {
            if self.overlaps_hill(grid, node) {
                (0.0, 20.0)
            } else {
                (0.0, 0.0)
            }
        }
        fn is_flat(&self, grid: &CellGrid, node: CellNode) -> bool {
            !self.overlaps_hill(grid, node)
        }
    }

    impl Ground {
        fn overlaps_hill(&self, grid: &CellGrid, node: CellNode) -> bool {
            let (corner, side) = grid.rect(node);
            corner.x < self.hill.1 && corner.x + side > self.hill.0
        }
    }

    fn grid() -> CellGrid {
        // 2^10 cells of 0.5 m: a 512 m field.
        CellGrid {
            origin: Vec2::new(-256.0, -256.0),
            cell: 0.5,
            levels: 10,
        }
    }

    fn view() -> CellView {
        CellView {
            eye: Vec3::new(0.0, 1.7, 0.0),
            frustum: None,
            max_distance: 200.0,
            macro_from: 30.0,
            split_factor: 2.0,
            grass_height: 0.4,
        }
    }

    /// Cells covered by the selection, each node counted over its cells.
    fn coverage(grid: &CellGrid, s: &CellSelection) -> std::collections::HashMap<(u32, u32), u32> {
        let mut covered = std::collections::HashMap::new();
        for (node, _) in &s.drawn {
            let n = grid.cells_across(*node);
            for dz in 0..n {
                for dx in 0..n {
                    *covered
                        .entry((node.x * n + dx, node.z * n + dz))
                        .or_insert(0) += 1;
                }
            }
        }
        covered
    }

    #[test]
    fn the_drawn_nodes_cover_every_cell_in_reach_once() {
        let g = grid();
        let ground = Ground { hill: (60.0, 90.0) };
        let v = view();
        let s = select_cells(&g, &ground, &v);
        let covered = coverage(&g, &s);
        assert!(covered.values().all(|&c| c == 1), "overlapping nodes");
        // Every cell whose centre is within reach (less a node's slack) is drawn.
        let cells = 1u32 << g.levels;
        for z in (0..cells).step_by(7) {
            for x in (0..cells).step_by(7) {
                let c = g.origin + (Vec2::new(x as f32, z as f32) + 0.5) * g.cell;
                let d = Vec3::new(c.x, 0.0, c.y).distance(v.eye);
                if d < v.max_distance - 1.0 {
                    assert!(covered.contains_key(&(x, z)), "cell ({x}, {z}) at {d} m");
                }
            }
        }
        // Far fewer nodes than the 5·10^5 cells in reach — most of them the single cells over the
        // hill (48,000) and within macro_from (11,000); on flat ground, a few thousand.
        let in_reach = std::f32::consts::PI * v.max_distance.powi(2) / (g.cell * g.cell);
        assert!(
            (s.drawn.len() as f32) < in_reach / 8.0,
            "{} nodes drawn",
            s.drawn.len()
        );
        let flat = select_cells(&g, &Ground { hill: (1e9, 1e9) }, &v);
        assert!(
            flat.drawn.len() < 16_000,
            "{} nodes drawn on flat ground",
            flat.drawn.len()
        );
        assert!(coverage(&g, &flat).values().all(|&c| c == 1));
    }

    #[test]
    fn macro_cells_are_flat_far_and_larger_with_distance() {
        let g = grid();
        let ground = Ground { hill: (60.0, 90.0) };
        let v = view();
        let s = select_cells(&g, &ground, &v);
        let mut largest_near = 0.0f32;
        let mut largest_far = 0.0f32;
        for (node, how) in &s.drawn {
            let (corner, side) = g.rect(*node);
            let (centre, radius) = node_sphere(&g, &ground, *node, v.grass_height);
            let d = (centre.distance(v.eye) - radius).max(0.0);
            match how {
                CellDraw::MacroCell => {
                    assert!(d >= v.macro_from && d >= v.split_factor * side);
                    assert!(
                        corner.x >= 90.0 || corner.x + side <= 60.0,
                        "a macro-cell over the hill at {corner}"
                    );
                    if d < 60.0 {
                        largest_near = largest_near.max(side);
                    } else if d > 150.0 {
                        largest_far = largest_far.max(side);
                    }
                }
                CellDraw::Cell => assert_eq!(node.level, g.levels),
            }
        }
        assert!(
            largest_far > largest_near,
            "{largest_near} near, {largest_far} far"
        );
        // Over the hill, single cells even far away.
        assert!(s.drawn.iter().any(|(n, how)| {
            let (corner, _) = g.rect(*n);
            *how == CellDraw::Cell && corner.x > 60.0 && corner.x < 90.0 && corner.y.abs() < 10.0
        }));
        // Within macro_from, single cells only.
        for (node, how) in &s.drawn {
            let (centre, radius) = node_sphere(&g, &ground, *node, v.grass_height);
            if centre.distance(v.eye) - radius < v.macro_from {
                assert_eq!(*how, CellDraw::Cell);
            }
        }
    }

    #[test]
    fn the_frustum_culls_nodes_behind_the_eye() {
        let g = grid();
        let ground = Ground { hill: (1e9, 1e9) };
        // Looking along −z: keep z ≤ 0 (plane n = (0, 0, −1), d = 0), the others open.
        let open = Vec4::new(0.0, 1.0, 0.0, 1e6);
        let v = CellView {
            frustum: Some([Vec4::new(0.0, 0.0, -1.0, 0.0), open, open, open, open, open]),
            ..view()
        };
        let s = select_cells(&g, &ground, &v);
        assert!(s.culled > 0);
        for (node, _) in &s.drawn {
            let (corner, _) = g.rect(*node);
            assert!(corner.y < 0.5, "a node behind the eye at {corner}");
        }
        let all = select_cells(&g, &ground, &view());
        assert!(
            s.drawn.len() * 10 < all.drawn.len() * 6,
            "about half culled"
        );
    }
}
