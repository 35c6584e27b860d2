//! The implicit patch hierarchy and the per-frame patch selection (paper 4, §3 "Patch
//! hierarchy", "Runtime rendering", "Level of detail"; §4 for the implicit hierarchy and the
//! hierarchical frustum culling).
//!
//! The root patch covers the terrain square; each patch splits into 2 × 2 children — the
//! branching factor is the ratio of the two tile resolutions, `r_high / r_low = 2`, which is what
//! lets a coarse edge meet two finer ones vertex for vertex. Patches are named by their level and
//! position ([`PatchId`]) and never stored: the traversal derives children by shifts.
//!
//! Each frame the hierarchy is walked top down. A patch whose edges all have an error
//! `ε = ρ·l/d` (eq. 1: `l` the edge's length, `d` its distance from the eye, `ρ` the precision
//! factor) of at most 1 is selected; otherwise its children are visited. A selected patch's edge
//! gets the low resolution for `ε ≤ 1/2` and the high one above (the paper's rule).
//!
//! The paper's Claim 1 argues that adjacent patches then agree on their shared edges and differ
//! by at most one level. That holds for the configurations its proof considers but not for every
//! view: a patch can end up next to one two levels finer when ε changes fast along it (30 of
//! 23,637 patches over the random views of `tests/patch_cracks.rs`). So the selection guarantees
//! it: leaves with a neighbour more than one level finer are split (a restricted quadtree), and
//! where two levels meet the coarse side takes the high resolution — which eq. 1 does not always
//! give it once a neighbour was split for balance — and the fine side the low one (which eq. 1
//! gives anyway: its edge is half of a coarse edge with ε ≤ 1 and no nearer the eye). That is the
//! assignment Claim 1 derives, enforced rather than assumed. Edges between patches of one level
//! are computed from the same lattice endpoints in the same order on both sides, so they agree
//! bit for bit.

use bevy::math::{Vec2, Vec3, Vec4};
use std::collections::{HashMap, HashSet};

/// The implicit patch hierarchy over a square terrain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchGrid {
    /// World (x, z) of lattice point [`anchor`](Self::anchor) (the root patch's corner with the
    /// smallest coordinates by default).
    pub origin: Vec2,
    /// The lattice point at `origin`: world positions are taken relative to it, so with an
    /// anchor near the camera they stay exact to f32's precision near the camera however far
    /// the terrain's corner is (a terrain 10^6 m across).
    pub anchor: [u32; 2],
    /// Side of the root patch (m).
    pub size: f32,
    /// Depth of the hierarchy: patches of level `max_level` are the finest, `size / 2^max_level`
    /// wide.
    pub max_level: u8,
    /// Segments along a patch edge at the high tile resolution; the low one is half of it.
    pub r_high: u32,
}

/// Why a [`PatchGrid`] cannot be built.
#[derive(Clone, Debug, PartialEq)]
pub enum PatchGridError {
    /// `r_high` must be a power of two of at least 4 (the low resolution's half-diagonals need
    /// at least one segment).
    Resolution(u32),
    /// The lattice (`r_high · 2^max_level` steps a side) must fit in 2^24, where f32 is exact.
    TooDeep {
        /// The hierarchy's depth asked for.
        max_level: u8,
        /// The high resolution asked for.
        r_high: u32,
    },
    /// The side must be positive and finite.
    Size(f32),
}

impl std::fmt::Display for PatchGridError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Resolution(r) => write!(
                f,
                "patch resolution {r} must be a power of two of at least 4"
            ),
            Self::TooDeep { max_level, r_high } => write!(
                f,
                "{max_level} patch levels at resolution {r_high} need a lattice of \
                 {r_high}·2^{max_level} steps, more than 2^24"
            ),
            Self::Size(s) => write!(f, "terrain side {s} m must be positive and finite"),
        }
    }
}

impl std::error::Error for PatchGridError {}

/// The largest lattice a side (f32 holds every integer up to 2^24 exactly).
pub const MAX_LATTICE: u64 = 1 << 24;

impl PatchGrid {
    /// A grid, checked.
    pub fn new(
        origin: Vec2,
        size: f32,
        max_level: u8,
        r_high: u32,
    ) -> Result<Self, PatchGridError> {
        if !(size.is_finite() && size > 0.0) {
            return Err(PatchGridError::Size(size));
        }
        if r_high < 4 || !r_high.is_power_of_two() {
            return Err(PatchGridError::Resolution(r_high));
        }
        if max_level >= 40 || (r_high as u64) << max_level > MAX_LATTICE {
            return Err(PatchGridError::TooDeep { max_level, r_high });
        }
        Ok(Self {
            origin,
            anchor: [0, 0],
            size,
            max_level,
            r_high,
        })
    }

    /// The low tile resolution (segments a patch edge).
    pub fn r_low(&self) -> u32 {
        self.r_high / 2
    }

    /// Lattice steps along the root's side.
    pub fn lattice_side(&self) -> u32 {
        self.r_high << self.max_level
    }

    /// Metres per lattice step.
    pub fn lattice_step(&self) -> f32 {
        self.size / self.lattice_side() as f32
    }

    /// The same grid with its positions taken relative to lattice point `anchor` (clamped to
    /// the lattice), which lies at world `origin`.
    pub fn anchored(self, anchor: [u32; 2], origin: Vec2) -> Self {
        let last = self.lattice_side();
        Self {
            anchor: anchor.map(|a| a.min(last)),
            origin,
            ..self
        }
    }

    /// Lattice point `p` relative to the anchor (exact: both are below 2^24).
    pub fn relative(&self, p: [u32; 2]) -> Vec2 {
        Vec2::new(
            (p[0] as i64 - self.anchor[0] as i64) as f32,
            (p[1] as i64 - self.anchor[1] as i64) as f32,
        )
    }

    /// World (x, z) of a lattice point.
    pub fn world(&self, p: [u32; 2]) -> Vec2 {
        self.origin + self.relative(p) * self.lattice_step()
    }
}

/// A patch of the implicit hierarchy: level and position among the `2^level × 2^level`
/// patches of that level (`x` along world x, `y` along world z).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PatchId {
    /// 0 for the root.
    pub level: u8,
    /// Column.
    pub x: u32,
    /// Row (along world z).
    pub y: u32,
}

impl PatchId {
    /// The root patch.
    pub const ROOT: Self = Self {
        level: 0,
        x: 0,
        y: 0,
    };

    /// Its four children.
    pub fn children(self) -> [Self; 4] {
        let (l, x, y) = (self.level + 1, self.x * 2, self.y * 2);
        [
            Self { level: l, x, y },
            Self {
                level: l,
                x: x + 1,
                y,
            },
            Self {
                level: l,
                x,
                y: y + 1,
            },
            Self {
                level: l,
                x: x + 1,
                y: y + 1,
            },
        ]
    }

    /// Its parent (the root is its own).
    pub fn parent(self) -> Self {
        if self.level == 0 {
            return self;
        }
        Self {
            level: self.level - 1,
            x: self.x / 2,
            y: self.y / 2,
        }
    }

    /// Its side in lattice steps.
    pub fn side(self, grid: &PatchGrid) -> u32 {
        grid.r_high << (grid.max_level - self.level)
    }

    /// Its lattice corner with the smallest coordinates.
    pub fn corner(self, grid: &PatchGrid) -> [u32; 2] {
        let s = self.side(grid);
        [self.x * s, self.y * s]
    }

    /// Corner `c` (0: (x0, y0), 1: (x1, y0), 2: (x1, y1), 3: (x0, y1) — counter-clockwise in
    /// (x, y)), in lattice steps. Edge `e` runs from corner `e` to corner `e + 1`.
    pub fn corner_point(self, grid: &PatchGrid, c: usize) -> [u32; 2] {
        let [x0, y0] = self.corner(grid);
        let s = self.side(grid);
        match c % 4 {
            0 => [x0, y0],
            1 => [x0 + s, y0],
            2 => [x0 + s, y0 + s],
            _ => [x0, y0 + s],
        }
    }

    /// The patch of the same level across edge `e` (0: y0 side, 1: x1, 2: y1, 3: x0), if it is
    /// inside the terrain.
    pub fn neighbour(self, e: usize) -> Option<Self> {
        let n = 1u32 << self.level;
        let (x, y) = match e % 4 {
            0 => (Some(self.x), self.y.checked_sub(1)),
            1 => (Some(self.x + 1).filter(|&x| x < n), Some(self.y)),
            2 => (Some(self.x), Some(self.y + 1).filter(|&y| y < n)),
            _ => (self.x.checked_sub(1), Some(self.y)),
        };
        Some(Self {
            level: self.level,
            x: x?,
            y: y?,
        })
    }

    /// Its ancestor at `level` (itself at its own level or finer).
    pub fn parent_at(self, level: u8) -> Self {
        if level >= self.level {
            return self;
        }
        let shift = self.level - level;
        Self {
            level,
            x: self.x >> shift,
            y: self.y >> shift,
        }
    }

    /// Its two children along edge `e`.
    fn children_along(self, e: usize) -> [Self; 2] {
        let [c00, c10, c01, c11] = self.children();
        match e % 4 {
            0 => [c00, c10],
            1 => [c10, c11],
            2 => [c01, c11],
            _ => [c00, c01],
        }
    }
}

/// What the selection needs of the view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchView {
    /// The eye, in world space.
    pub eye: Vec3,
    /// ρ of eq. 1: an edge `l` long and `d` away has error `ρ·l/d`. Larger gives finer meshes.
    pub precision: f32,
    /// The view frustum as six planes `(n, d)`, a point `p` inside when `n·p + d > 0` for all
    /// (Bevy's `Frustum::half_spaces`); `None` turns culling off.
    pub frustum: Option<[Vec4; 6]>,
    /// The lowest and highest terrain heights (m): the patches' bounding boxes, and the vertical
    /// extent an edge's distance is measured to.
    pub heights: (f32, f32),
}

/// A patch edge's resolution: segments along it.
pub type EdgeResolution = u32;

/// A patch the selection chose, with the segments on each of its edges (`edges[e]`: edge `e`,
/// see [`PatchId::corner_point`]) — its four tiles' resolutions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SelectedPatch {
    /// Which patch.
    pub id: PatchId,
    /// Segments along each edge: `r_low` or `r_high`.
    pub edges: [EdgeResolution; 4],
}

impl SelectedPatch {
    /// Segments along the half-diagonal from corner `c` to the centre, shared by the tiles of
    /// edges `c − 1` and `c`: the coarser tile's own diagonal spacing, `min / 2`, so its
    /// vertices are a subset of both tiles' grids.
    pub fn diagonal(&self, c: usize) -> u32 {
        self.edges[(c + 3) % 4].min(self.edges[c % 4]) / 2
    }
}

/// What the selection did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SelectionStats {
    /// Patches visited by the traversal.
    pub traversed: u32,
    /// Patches (and so their subtrees) culled by the frustum.
    pub culled: u32,
    /// Bounding boxes tested against the frustum (children of a patch wholly inside are not).
    pub frustum_tests: u32,
    /// Leaves split to keep neighbours within one level.
    pub balance_splits: u32,
}

/// The patches to draw this frame, sorted by id.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Selection {
    /// The patches.
    pub patches: Vec<SelectedPatch>,
    /// Counters.
    pub stats: SelectionStats,
}

/// Where a bounding box lies against the frustum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Containment {
    Outside,
    Intersecting,
    Inside,
}

fn classify(planes: &[Vec4; 6], min: Vec3, max: Vec3) -> Containment {
    let mut inside = true;
    for p in planes {
        let n = p.truncate();
        // The box corners farthest along and against the normal.
        let far = Vec3::select(n.cmpge(Vec3::ZERO), max, min);
        let near = Vec3::select(n.cmpge(Vec3::ZERO), min, max);
        if n.dot(far) + p.w <= 0.0 {
            return Containment::Outside;
        }
        if n.dot(near) + p.w <= 0.0 {
            inside = false;
        }
    }
    if inside {
        Containment::Inside
    } else {
        Containment::Intersecting
    }
}

fn bounds(grid: &PatchGrid, view: &PatchView, id: PatchId) -> (Vec3, Vec3) {
    let a = grid.world(id.corner_point(grid, 0));
    let b = grid.world(id.corner_point(grid, 2));
    (
        Vec3::new(a.x, view.heights.0, a.y),
        Vec3::new(b.x, view.heights.1, b.y),
    )
}

/// Eq. 1's error of the edge between lattice points `a` and `b`: `ρ·l/d`, `d` the distance from
/// the eye to the edge's vertical extent between the terrain's lowest and highest heights (a
/// lower bound on its distance to any terrain on the edge). The endpoints are put in one order
/// first, so both patches sharing the edge get the same value bit for bit.
pub fn edge_error(grid: &PatchGrid, view: &PatchView, a: [u32; 2], b: [u32; 2]) -> f32 {
    let (a, b) = if a <= b { (a, b) } else { (b, a) };
    let (pa, pb) = (grid.world(a), grid.world(b));
    let eye = Vec2::new(view.eye.x, view.eye.z);
    let ab = pb - pa;
    let t = ((eye - pa).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
    let horizontal = eye.distance(pa + t * ab);
    let (low, high) = view.heights;
    let vertical = if view.eye.y < low {
        low - view.eye.y
    } else if view.eye.y > high {
        view.eye.y - high
    } else {
        0.0
    };
    let d = (horizontal * horizontal + vertical * vertical)
        .sqrt()
        .max(1e-6);
    view.precision * ab.length() / d
}

fn patch_error(grid: &PatchGrid, view: &PatchView, id: PatchId) -> f32 {
    (0..4)
        .map(|e| {
            edge_error(
                grid,
                view,
                id.corner_point(grid, e),
                id.corner_point(grid, e + 1),
            )
        })
        .fold(0.0, f32::max)
}

/// The patches to draw for `view`: the top-down traversal with eq. 1's split rule and
/// hierarchical frustum culling (a patch wholly inside the frustum passes its children without a
/// test), neighbours kept within one level, and every edge's resolution.
pub fn select_patches(grid: &PatchGrid, view: &PatchView) -> Selection {
    let mut stats = SelectionStats::default();
    let mut leaves: HashSet<PatchId> = HashSet::new();
    // (patch, its parent wholly inside the frustum)
    let mut stack = vec![(PatchId::ROOT, false)];
    while let Some((id, parent_inside)) = stack.pop() {
        stats.traversed += 1;
        let mut inside = parent_inside || view.frustum.is_none();
        if !inside && let Some(planes) = &view.frustum {
            stats.frustum_tests += 1;
            let (min, max) = bounds(grid, view, id);
            match classify(planes, min, max) {
                Containment::Outside => {
                    stats.culled += 1;
                    continue;
                }
                Containment::Inside => inside = true,
                Containment::Intersecting => {}
            }
        }
        if id.level < grid.max_level && patch_error(grid, view, id) > 1.0 {
            stack.extend(id.children().map(|c| (c, inside)));
        } else {
            leaves.insert(id);
        }
    }
    balance(grid, view, &mut leaves, &mut stats);
    let mut patches: Vec<SelectedPatch> = leaves
        .iter()
        .map(|&id| SelectedPatch {
            id,
            edges: std::array::from_fn(|e| edge_resolution(grid, view, &leaves, id, e)),
        })
        .collect();
    patches.sort_by_key(|p| p.id);
    Selection { patches, stats }
}

/// The leaf covering patch `id`'s square: `id` itself or an ancestor.
fn covering_leaf(leaves: &HashSet<PatchId>, mut id: PatchId) -> Option<PatchId> {
    loop {
        if leaves.contains(&id) {
            return Some(id);
        }
        if id.level == 0 {
            return None;
        }
        id = id.parent();
    }
}

/// Splits leaves until no leaf has an edge neighbour more than one level finer (a restricted
/// quadtree). New children outside the frustum are dropped, like culled patches.
fn balance(
    grid: &PatchGrid,
    view: &PatchView,
    leaves: &mut HashSet<PatchId>,
    stats: &mut SelectionStats,
) {
    let mut work: Vec<PatchId> = leaves.iter().copied().collect();
    work.sort();
    while let Some(id) = work.pop() {
        if !leaves.contains(&id) {
            continue;
        }
        for e in 0..4 {
            let Some(n) = id.neighbour(e) else {
                continue;
            };
            let Some(cover) = covering_leaf(leaves, n) else {
                continue;
            };
            if cover.level + 1 >= id.level {
                continue;
            }
            // Too coarse: split it, and look again at its children and at this leaf.
            leaves.remove(&cover);
            stats.balance_splits += 1;
            for c in cover.children() {
                let keep = view.frustum.as_ref().is_none_or(|planes| {
                    let (min, max) = bounds(grid, view, c);
                    classify(planes, min, max) != Containment::Outside
                });
                if keep {
                    leaves.insert(c);
                    work.push(c);
                }
            }
            work.push(id);
            break;
        }
    }
}

/// Segments along edge `e` of leaf `id`: where the neighbour across is one level coarser, the
/// low resolution (the coarse edge, twice as long, takes the high one: the same vertex spacing);
/// where it is finer, the high resolution; otherwise (the same level, the terrain's border, a
/// culled neighbour) eq. 1's rule on the edge.
fn edge_resolution(
    grid: &PatchGrid,
    view: &PatchView,
    leaves: &HashSet<PatchId>,
    id: PatchId,
    e: usize,
) -> EdgeResolution {
    let by_error = || {
        let epsilon = edge_error(
            grid,
            view,
            id.corner_point(grid, e),
            id.corner_point(grid, e + 1),
        );
        if epsilon <= 0.5 {
            grid.r_low()
        } else {
            grid.r_high
        }
    };
    let Some(n) = id.neighbour(e) else {
        return by_error();
    };
    match covering_leaf(leaves, n) {
        Some(cover) if cover.level < id.level => grid.r_low(),
        Some(_) => by_error(),
        None => {
            // Subdivided (its children along the shared edge are leaves), or culled.
            let across = (e + 2) % 4;
            if n.level < grid.max_level
                && n.children_along(across)
                    .iter()
                    .any(|c| covering_leaf(leaves, *c).is_some_and(|l| l.level > n.level))
            {
                grid.r_high
            } else {
                by_error()
            }
        }
    }
}

/// The selected patches by id, for neighbour lookups in tests and tools.
pub fn by_id(selection: &Selection) -> HashMap<PatchId, SelectedPatch> {
    selection.patches.iter().map(|p| (p.id, *p)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> PatchGrid {
        PatchGrid::new(Vec2::new(-512.0, -512.0), 1024.0, 6, 16).unwrap()
    }

    fn view(eye: Vec3) -> PatchView {
        PatchView {
            eye,
            precision: 2.0,
            frustum: None,
            heights: (0.0, 50.0),
        }
    }

    #[test]
    fn bad_grids_are_refused() {
        assert_eq!(
            PatchGrid::new(Vec2::ZERO, 100.0, 4, 12),
            Err(PatchGridError::Resolution(12))
        );
        assert_eq!(
            PatchGrid::new(Vec2::ZERO, 100.0, 4, 2),
            Err(PatchGridError::Resolution(2))
        );
        assert!(matches!(
            PatchGrid::new(Vec2::ZERO, 100.0, 22, 16),
            Err(PatchGridError::TooDeep { .. })
        ));
        assert!(matches!(
            PatchGrid::new(Vec2::ZERO, f32::NAN, 4, 16),
            Err(PatchGridError::Size(_))
        ));
        assert!(PatchGrid::new(Vec2::ZERO, -1.0, 4, 16).is_err());
        assert!(PatchGrid::new(Vec2::ZERO, 100.0, 20, 16).is_ok());
    }

    #[test]
    fn eq_1_splits_near_the_eye_and_not_far_from_it() {
        let g = grid();
        let s = select_patches(&g, &view(Vec3::new(0.0, 10.0, 0.0)));
        let finest = s.patches.iter().map(|p| p.id.level).max().unwrap();
        let coarsest = s.patches.iter().map(|p| p.id.level).min().unwrap();
        assert_eq!(finest, g.max_level, "the patch under the eye is the finest");
        assert!(
            coarsest + 3 <= finest,
            "the far corners stay coarse: {coarsest}"
        );
        // Every selected patch's edges have ε ≤ 1 unless it is at the finest level.
        let v = view(Vec3::new(0.0, 10.0, 0.0));
        for p in &s.patches {
            let e = patch_error(&g, &v, p.id);
            assert!(p.id.level == g.max_level || e <= 1.0, "{:?}: ε {e}", p.id);
            // And its parent needed splitting (or the patch was split for balance).
        }
        // The patches tile the terrain: their areas add up to the root's.
        let area: u64 = s
            .patches
            .iter()
            .map(|p| (p.id.side(&g) as u64).pow(2))
            .sum();
        assert_eq!(area, (g.lattice_side() as u64).pow(2));
        // A higher eye gives fewer patches.
        let high = select_patches(&g, &view(Vec3::new(0.0, 400.0, 0.0)));
        assert!(high.patches.len() < s.patches.len());
    }

    #[test]
    fn edge_resolutions_follow_eq_1_and_agree_across_levels() {
        let g = grid();
        let v = view(Vec3::new(30.0, 5.0, -70.0));
        let s = select_patches(&g, &v);
        let map = by_id(&s);
        let mut same_level = 0;
        let mut across_levels = 0;
        for p in &s.patches {
            for e in 0..4 {
                let Some(n) = p.id.neighbour(e) else {
                    continue;
                };
                let eps = edge_error(
                    &g,
                    &v,
                    p.id.corner_point(&g, e),
                    p.id.corner_point(&g, e + 1),
                );
                if let Some(q) = map.get(&n) {
                    same_level += 1;
                    assert_eq!(p.edges[e], q.edges[(e + 2) % 4], "{:?} edge {e}", p.id);
                    let expected = if eps <= 0.5 { g.r_low() } else { g.r_high };
                    assert_eq!(p.edges[e], expected, "eq. 1 on {:?} edge {e}", p.id);
                } else if let Some(q) = map.get(&n.parent()) {
                    across_levels += 1;
                    assert_eq!(p.edges[e], g.r_low());
                    assert_eq!(q.edges[(e + 2) % 4], g.r_high);
                }
            }
        }
        assert!(
            same_level > 20 && across_levels > 10,
            "{same_level} {across_levels}"
        );
    }

    /// A camera looking along +x from the middle: patches behind it and beside the frustum are
    /// culled, and patches wholly inside pass their children untested.
    #[test]
    fn hierarchical_culling_skips_the_children_of_patches_inside() {
        let g = grid();
        let eye = Vec3::new(0.0, 20.0, 0.0);
        // A 90° frustum looking along +x, level: planes through the eye with inward normals.
        let plane = |n: Vec3, p: Vec3| n.extend(-n.dot(p));
        let planes = [
            plane(Vec3::new(1.0, 0.0, 1.0).normalize(), eye),
            plane(Vec3::new(1.0, 0.0, -1.0).normalize(), eye),
            plane(Vec3::new(1.0, 1.0, 0.0).normalize(), eye),
            plane(Vec3::new(1.0, -1.0, 0.0).normalize(), eye),
            plane(Vec3::X, eye + Vec3::X * 0.1),
            plane(Vec3::NEG_X, eye + Vec3::X * 5000.0),
        ];
        // A high precision, so that patches wholly inside get split.
        let fine = PatchView {
            precision: 8.0,
            ..view(eye)
        };
        let culled_view = PatchView {
            frustum: Some(planes),
            ..fine
        };
        let all = select_patches(&g, &fine);
        let culled = select_patches(&g, &culled_view);
        println!("{:?}\n{:?}", all.stats, culled.stats);
        assert!(culled.patches.len() < all.patches.len() / 2);
        assert!(culled.stats.culled > 0);
        // Fewer tests than patches visited: children of patches inside are not tested.
        assert!(culled.stats.frustum_tests < culled.stats.traversed);
        for p in &culled.patches {
            let (min, max) = bounds(&g, &culled_view, p.id);
            assert_ne!(classify(&planes, min, max), Containment::Outside);
        }
        // Every patch drawn without culling that is inside the frustum is still covered.
        let kept = by_id(&culled);
        for p in &all.patches {
            let (min, max) = bounds(&g, &culled_view, p.id);
            if classify(&planes, min, max) == Containment::Inside {
                let mut a = p.id;
                let mut covered = kept.contains_key(&a);
                while !covered && a.level > 0 {
                    a = a.parent();
                    covered = kept.contains_key(&a);
                }
                let finer = culled
                    .patches
                    .iter()
                    .any(|q| q.id.level > p.id.level && q.id.parent_at(p.id.level) == p.id);
                assert!(covered || finer, "{:?} lost", p.id);
            }
        }
    }
}
