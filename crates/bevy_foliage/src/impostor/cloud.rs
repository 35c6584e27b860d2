//! Billboard-cloud plane selection: the few textured planes a distant tree is reduced to.
//!
//! Decoret, Durand, Sillion & Dorsey 2003 ("Billboard clouds for extreme model simplification")
//! pose simplification as clustering in a dual (Hough) space: a plane is a point `(θ, φ, ρ)`,
//! the planes within ε of a vertex form a slab in that space, and a triangle's *validity domain*
//! is the intersection of its vertices' slabs. The space is discretised, every triangle adds its
//! density to the cells of its validity domain, and planes are picked greedily, densest first,
//! until every triangle has been projected onto one (seed 001 §4.2).
//!
//! Seed 001 §4.3 adapts this to vegetation, and so does this module:
//!
//! - leaves and branches are clustered separately, each with its own ε ("much better results
//!   can be obtained by separating foliage and branches and simplifying them separately, using
//!   different parameters for each part");
//! - a *view-dependent penalty* makes near-horizontal planes less likely to be chosen, because
//!   walkthroughs see trees from eye height, where horizontal planes are edge-on;
//! - for branches, once a plane is chosen, planes orthogonal to it through the members' centre
//!   of gravity are tested; one that covers most of the members is added as a *cardboard* plane,
//!   so a trunk reduced to one plane does not vanish when that plane is seen edge-on (fig. 4.3).
//!
//! ε is a fraction of the bounding-sphere radius; the thesis uses 10–15 % for tens of planes.
//! The result is plain geometry (planes, their member triangles and bounding rectangles); the
//! textures are rendered from it elsewhere, and [`super::atlas`] packs the rectangles.

use bevy::math::{Vec2, Vec3};
use std::f32::consts::{FRAC_PI_2, PI, TAU};

/// Which part of the tree a triangle belongs to (leaves and branches are simplified separately).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TreePart {
    /// Foliage: clustered with [`CloudSettings::epsilon_fraction`].
    Leaves,
    /// Trunk, branches and twigs: clustered with [`CloudSettings::branch_epsilon_fraction`]
    /// and given cardboard planes.
    Branches,
}

/// One input triangle, model space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloudTriangle {
    /// Corner positions.
    pub vertices: [Vec3; 3],
    /// The part it belongs to.
    pub part: TreePart,
}

impl CloudTriangle {
    /// A triangle of `part`.
    pub fn new(vertices: [Vec3; 3], part: TreePart) -> Self {
        Self { vertices, part }
    }

    /// Twice the area times the unit normal (right-handed winding).
    fn cross(&self) -> Vec3 {
        let [a, b, c] = self.vertices;
        (b - a).cross(c - a)
    }

    /// Area.
    pub fn area(&self) -> f32 {
        self.cross().length() * 0.5
    }

    /// Unit face normal (zero for a degenerate triangle).
    pub fn normal(&self) -> Vec3 {
        self.cross().normalize_or_zero()
    }

    /// Centroid.
    pub fn centroid(&self) -> Vec3 {
        (self.vertices[0] + self.vertices[1] + self.vertices[2]) / 3.0
    }

    /// Whether [`build_cloud`] uses the triangle: finite and not degenerate.
    pub fn is_usable(&self) -> bool {
        self.is_finite() && !self.is_degenerate()
    }

    /// Whether every coordinate is finite.
    pub fn is_finite(&self) -> bool {
        self.vertices.iter().all(|v| v.is_finite())
    }

    /// Whether the triangle has (numerically) no area: its smallest altitude is below ~2·10⁻⁶ of
    /// its longest edge. The cross product is taken of edge differences, so its rounding error
    /// scales with the squared edge length, not with the distance from the origin.
    pub fn is_degenerate(&self) -> bool {
        let [a, b, c] = self.vertices;
        let longest = (b - a)
            .length_squared()
            .max((c - b).length_squared())
            .max((a - c).length_squared());
        let area = self.area();
        area.is_nan() || area <= longest * 1e-6
    }
}

/// What a plane was made for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PlaneRole {
    /// A plane of the leaf clustering.
    Leaves,
    /// A plane of the branch clustering.
    Branches,
    /// A plane orthogonal to the branch plane before it, covering most of its members
    /// (seed 001 §4.3, fig. 4.3).
    Cardboard,
}

/// Parameters of [`build_cloud`].
#[derive(Clone, Debug, PartialEq)]
pub struct CloudSettings {
    /// Validity threshold ε as a fraction of the bounding-sphere radius (thesis: 10–15 %).
    pub epsilon_fraction: f32,
    /// Branches may use their own ε fraction (thesis: different parameters per part).
    pub branch_epsilon_fraction: f32,
    /// About how many plane normal directions are sampled on the hemisphere (rings of constant
    /// θ with φ steps proportional to sin θ; the exact count follows from the rounding).
    pub directions: u32,
    /// ρ bins per ε (bin width ε / this).
    pub rho_bins_per_epsilon: u32,
    /// Penalty on near-horizontal planes: density × (1 − horizontal_penalty · h(n)), with
    /// h = smoothstep of |n.y| from 0.5 to 1 (0 for planes steeper than 60°, 1 for a horizontal
    /// plane). 0 disables it, 1 makes horizontal planes the last resort.
    pub horizontal_penalty: f32,
    /// Fraction of a branch plane's member area an orthogonal "cardboard" plane must cover (its
    /// members within the branch ε) to be added; above 1 disables cardboard planes.
    pub cardboard_coverage: f32,
    /// Hard cap on the number of planes; [`build_cloud`] fails with
    /// [`CloudError::TooManyPlanes`] rather than drop triangles.
    pub max_planes: u32,
}

impl Default for CloudSettings {
    fn default() -> Self {
        Self {
            epsilon_fraction: 0.12,
            branch_epsilon_fraction: 0.08,
            directions: 256,
            rho_bins_per_epsilon: 2,
            horizontal_penalty: 0.6,
            cardboard_coverage: 0.8,
            max_planes: 96,
        }
    }
}

/// Largest dual volume (directions × ρ bins) [`CloudSettings::sanitized`] lets through: the
/// volume holds an `f64` and a `u32` per cell, so this is about 200 MB.
const MAX_CELLS: u64 = 1 << 24;

impl CloudSettings {
    /// These settings with NaN or absurd values replaced by the defaults, and a line for each
    /// replacement: ε fractions outside (0, 1], `directions` 0 or above 16384,
    /// `rho_bins_per_epsilon` 0 or above 64, a penalty outside [0, 1], a negative or non-finite
    /// coverage, `max_planes` 0, and a dual volume above 2²⁴ cells.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let default = Self::default();
        let mut out = self.clone();
        let mut notes = Vec::new();
        let mut fraction = |name: &str, value: &mut f32, fallback: f32| {
            if !(*value > 0.0 && *value <= 1.0) {
                notes.push(format!(
                    "{name} {value} outside (0, 1]: replaced by {fallback}"
                ));
                *value = fallback;
            }
        };
        fraction(
            "epsilon_fraction",
            &mut out.epsilon_fraction,
            default.epsilon_fraction,
        );
        fraction(
            "branch_epsilon_fraction",
            &mut out.branch_epsilon_fraction,
            default.branch_epsilon_fraction,
        );
        if out.directions == 0 || out.directions > 16384 {
            notes.push(format!(
                "directions {} outside [1, 16384]: replaced by {}",
                out.directions, default.directions
            ));
            out.directions = default.directions;
        }
        if out.rho_bins_per_epsilon == 0 || out.rho_bins_per_epsilon > 64 {
            notes.push(format!(
                "rho_bins_per_epsilon {} outside [1, 64]: replaced by {}",
                out.rho_bins_per_epsilon, default.rho_bins_per_epsilon
            ));
            out.rho_bins_per_epsilon = default.rho_bins_per_epsilon;
        }
        if !(0.0..=1.0).contains(&out.horizontal_penalty) {
            notes.push(format!(
                "horizontal_penalty {} outside [0, 1]: replaced by {}",
                out.horizontal_penalty, default.horizontal_penalty
            ));
            out.horizontal_penalty = default.horizontal_penalty;
        }
        if !(out.cardboard_coverage.is_finite() && out.cardboard_coverage >= 0.0) {
            notes.push(format!(
                "cardboard_coverage {} not a finite non-negative fraction: replaced by {}",
                out.cardboard_coverage, default.cardboard_coverage
            ));
            out.cardboard_coverage = default.cardboard_coverage;
        }
        if out.max_planes == 0 {
            notes.push(format!("max_planes 0: replaced by {}", default.max_planes));
            out.max_planes = default.max_planes;
        }
        let cells = |s: &Self| {
            let eps = s.epsilon_fraction.min(s.branch_epsilon_fraction);
            let bins = (2.0 * s.rho_bins_per_epsilon as f32 / eps).ceil() as u64 + 1;
            // The ring layout of `hemisphere_directions` rounds up by a few per ring.
            (s.directions as u64 + 64) * bins
        };
        if cells(&out) > MAX_CELLS {
            notes.push(format!(
                "dual volume of about {} cells exceeds {MAX_CELLS}: directions and \
                 rho_bins_per_epsilon replaced by {} and {}",
                cells(&out),
                default.directions,
                default.rho_bins_per_epsilon
            ));
            out.directions = default.directions;
            out.rho_bins_per_epsilon = default.rho_bins_per_epsilon;
        }
        (out, notes)
    }
}

/// One plane of the cloud, with the triangles projected onto it and their bounding rectangle.
#[derive(Clone, Debug, PartialEq)]
pub struct CloudPlane {
    /// Unit normal; the plane is `{p : normal · p = offset}`.
    pub normal: Vec3,
    /// Signed distance of the plane from the origin along `normal`.
    pub offset: f32,
    /// Unit in-plane texture u axis.
    pub tangent: Vec3,
    /// Unit in-plane texture v axis, `normal × tangent` (right-handed).
    pub bitangent: Vec3,
    /// Lower corner of the member triangles' bounding rectangle, in [`Self::project`]
    /// coordinates.
    pub min: Vec2,
    /// Upper corner of that rectangle.
    pub max: Vec2,
    /// What the plane was made for.
    pub role: PlaneRole,
    /// Indices into the input triangles projected onto this plane, ascending.
    pub triangles: Vec<u32>,
}

impl CloudPlane {
    /// The point of the plane closest to the origin, the origin of [`Self::project`].
    pub fn origin(&self) -> Vec3 {
        self.normal * self.offset
    }

    /// In-plane coordinates `(along tangent, along bitangent)` of `p` projected onto the plane.
    pub fn project(&self, p: Vec3) -> Vec2 {
        let d = p - self.origin();
        Vec2::new(d.dot(self.tangent), d.dot(self.bitangent))
    }

    /// The point of the plane at in-plane coordinates `uv` (inverse of [`Self::project`] on the
    /// plane).
    pub fn point(&self, uv: Vec2) -> Vec3 {
        self.origin() + self.tangent * uv.x + self.bitangent * uv.y
    }

    /// Signed distance of `p` from the plane (positive on the side `normal` points to).
    pub fn distance(&self, p: Vec3) -> f32 {
        self.normal.dot(p) - self.offset
    }

    /// Area of the bounding rectangle (the texture's world-space size).
    pub fn area(&self) -> f32 {
        let size = (self.max - self.min).max(Vec2::ZERO);
        size.x * size.y
    }

    /// World-space width and height of the bounding rectangle.
    pub fn size(&self) -> Vec2 {
        (self.max - self.min).max(Vec2::ZERO)
    }
}

/// The planes a tree is simplified to.
#[derive(Clone, Debug, PartialEq)]
pub struct BillboardCloud {
    /// Centre of the input's bounding sphere (the centre of its bounding box).
    pub center: Vec3,
    /// Radius of the bounding sphere.
    pub radius: f32,
    /// Absolute ε of the leaves.
    pub epsilon: f32,
    /// Absolute ε of the branches.
    pub branch_epsilon: f32,
    /// Leaf planes, then branch planes, each followed by its cardboard plane if it has one.
    pub planes: Vec<CloudPlane>,
}

impl BillboardCloud {
    /// Number of planes with `role`.
    pub fn count(&self, role: PlaneRole) -> usize {
        self.planes.iter().filter(|p| p.role == role).count()
    }

    /// The ε that applies to `part`.
    pub fn epsilon_of(&self, part: TreePart) -> f32 {
        match part {
            TreePart::Leaves => self.epsilon,
            TreePart::Branches => self.branch_epsilon,
        }
    }
}

/// Why no billboard cloud could be built.
#[derive(Clone, Debug, PartialEq)]
pub enum CloudError {
    /// The input has no triangles.
    NoTriangles,
    /// Every triangle has a NaN or infinite coordinate.
    NonFinite,
    /// No triangle has an area (or the input has no extent).
    Degenerate,
    /// Covering every triangle takes more planes than [`CloudSettings::max_planes`].
    TooManyPlanes {
        /// Planes the cover needs.
        needed: usize,
        /// The cap.
        max: u32,
    },
}

impl std::fmt::Display for CloudError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoTriangles => write!(f, "billboard cloud: no triangles"),
            Self::NonFinite => write!(
                f,
                "billboard cloud: every triangle has a NaN or infinite coordinate"
            ),
            Self::Degenerate => write!(f, "billboard cloud: no triangle has an area"),
            Self::TooManyPlanes { needed, max } => write!(
                f,
                "billboard cloud needs {needed} planes, more than the cap of {max}: raise \
                 max_planes or the ε fractions"
            ),
        }
    }
}

impl std::error::Error for CloudError {}

/// About `count` unit normals covering the upper hemisphere evenly, deterministic: the pole,
/// rings of constant θ whose φ steps are proportional to sin θ (a multiple of 4 per ring, so
/// ±X and ±Z lie on the grid), and the equator over φ ∈ [0, π) only, since `n` and `−n` are
/// the same plane (Decoret et al. 2003 discretise the dual space in θ, φ).
pub fn hemisphere_directions(count: u32) -> Vec<Vec3> {
    let target = count.max(1) as f32;
    // Angular spacing of `count` equal cells on the hemisphere's 2π steradians; the rounding
    // of the rings then overshoots (most for small counts), so the spacing is corrected a few
    // times towards the target and the closest layout kept.
    let mut spacing = (TAU / target).sqrt();
    let mut best = rings(spacing);
    for _ in 0..6 {
        spacing *= (best.len() as f32 / target).sqrt();
        let next = rings(spacing);
        if (next.len() as f32 - target).abs() < (best.len() as f32 - target).abs() {
            best = next;
        }
    }
    best
}

/// The ring layout of [`hemisphere_directions`] at angular `spacing`.
fn rings(spacing: f32) -> Vec<Vec3> {
    let rings = ((FRAC_PI_2 / spacing).round() as usize).max(1);
    let mut dirs = vec![Vec3::Y];
    for ring in 1..=rings {
        let theta = ring as f32 / rings as f32 * FRAC_PI_2;
        let (sin, cos) = if ring == rings {
            (1.0, 0.0)
        } else {
            theta.sin_cos()
        };
        let (steps, span) = if ring == rings {
            let steps = ((PI / spacing).round() as usize).max(1).div_ceil(2) * 2;
            (steps, PI)
        } else {
            let steps = ((TAU * sin / spacing).round() as usize).max(1).div_ceil(4) * 4;
            (steps, TAU)
        };
        for step in 0..steps {
            let phi = step as f32 / steps as f32 * span;
            dirs.push(Vec3::new(sin * phi.cos(), cos, sin * phi.sin()));
        }
    }
    dirs
}

/// The view-dependent weight of a plane with unit `normal` (seed 001 §4.3, "View-dependent
/// Penalty"): `1 − penalty · smoothstep(0.5, 1, |n.y|)`, 1 for planes steeper than 60° and
/// `1 − penalty` for a horizontal one.
pub fn horizontal_weight(normal: Vec3, penalty: f32) -> f32 {
    let t = ((normal.y.abs() - 0.5) / 0.5).clamp(0.0, 1.0);
    1.0 - penalty * t * t * (3.0 - 2.0 * t)
}

/// A valid input triangle of one part, its vertices relative to the bounding-sphere centre.
struct Tri {
    input: u32,
    rel: [Vec3; 3],
    area: f32,
    normal: Vec3,
}

impl Tri {
    /// Whether every vertex lies within `eps` of the plane `{p : n · p = rho}` (relative space).
    fn valid_for(&self, n: Vec3, rho: f32, eps: f32) -> bool {
        self.rel.iter().all(|v| (n.dot(*v) - rho).abs() <= eps)
    }

    fn centroid(&self) -> Vec3 {
        (self.rel[0] + self.rel[1] + self.rel[2]) / 3.0
    }
}

/// A chosen plane of one part (relative space) and the indices of its member triangles.
struct Cluster {
    normal: Vec3,
    rho: f32,
    members: Vec<usize>,
}

/// The discretised dual space of one part (Decoret et al. 2003 §4): per direction, ρ bins of
/// width ε / `rho_bins_per_epsilon` over [−R, R]; each cell holds the penalised density of the
/// uncovered triangles valid for the plane at its bin centre, and their exact count (so float
/// residue left by subtraction never picks a plane without members).
struct Dual<'a> {
    dirs: &'a [Vec3],
    weights: &'a [f32],
    bins: usize,
    width: f32,
    inv_width: f32,
    radius: f32,
    epsilon: f32,
    density: Vec<f64>,
    count: Vec<u32>,
}

impl<'a> Dual<'a> {
    fn new(dirs: &'a [Vec3], weights: &'a [f32], radius: f32, epsilon: f32, per_eps: u32) -> Self {
        let width = epsilon / per_eps as f32;
        let bins = ((2.0 * radius / width).ceil() as usize).max(1);
        Self {
            dirs,
            weights,
            bins,
            width,
            inv_width: 1.0 / width,
            radius,
            epsilon,
            density: vec![0.0; dirs.len() * bins],
            count: vec![0; dirs.len() * bins],
        }
    }

    fn bin_centre(&self, k: usize) -> f32 {
        -self.radius + (k as f32 + 0.5) * self.width
    }

    /// The bins whose centre ρ lies in the triangle's validity interval along `dir`,
    /// `[max ρᵢ − ε, min ρᵢ + ε]`, inclusive. The rounded range is nudged so that the plane at
    /// every returned centre is valid as computed (the validity is exact at bin centres).
    fn bins_for(&self, tri: &Tri, dir: Vec3) -> Option<(usize, usize)> {
        let r = tri.rel.map(|v| dir.dot(v));
        let lo = r[0].max(r[1]).max(r[2]) - self.epsilon;
        let hi = r[0].min(r[1]).min(r[2]) + self.epsilon;
        if lo > hi {
            return None;
        }
        // First and last bins by truncation (no rounding call in this hot loop), then nudged
        // against the bin centres as computed, so the result is exact.
        let last = self.bins - 1;
        let clamp = |x: f32| x.clamp(0.0, last as f32) as usize;
        let mut a = clamp((lo + self.radius) * self.inv_width + 0.5);
        while a > 0 && self.bin_centre(a - 1) >= lo {
            a -= 1;
        }
        while a <= last && self.bin_centre(a) < lo {
            a += 1;
        }
        let mut b = clamp((hi + self.radius) * self.inv_width - 0.5);
        while b < last && self.bin_centre(b + 1) <= hi {
            b += 1;
        }
        while self.bin_centre(b) > hi {
            if b == 0 {
                return None;
            }
            b -= 1;
        }
        (a <= b).then_some((a, b))
    }

    /// Adds (`sign` 1) or removes (`sign` −1) a triangle's contributions: its projected area
    /// `area · |n · face normal|` times the direction's penalty weight, in every valid cell.
    fn accumulate(&mut self, tri: &Tri, sign: i32) {
        for (d, &dir) in self.dirs.iter().enumerate() {
            let Some((a, b)) = self.bins_for(tri, dir) else {
                continue;
            };
            let density =
                sign as f64 * (tri.area * dir.dot(tri.normal).abs() * self.weights[d]) as f64;
            let row = d * self.bins;
            for k in a..=b {
                self.density[row + k] += density;
                self.count[row + k] = self.count[row + k].wrapping_add_signed(sign);
            }
        }
    }

    /// The densest cell that still has uncovered triangles; ties go to the lowest direction,
    /// then the lowest bin, so the result is deterministic.
    fn densest(&self) -> Option<(usize, usize)> {
        let mut best: Option<(usize, f64)> = None;
        for (cell, (&count, &density)) in self.count.iter().zip(&self.density).enumerate() {
            if count > 0 && best.is_none_or(|(_, b)| density > b) {
                best = Some((cell, density));
            }
        }
        best.map(|(cell, _)| (cell / self.bins, cell % self.bins))
    }
}

/// Greedy cover of one part (Decoret et al. 2003 §4.2; seed 001 §4.2): densest dual cell first,
/// its plane takes every uncovered triangle valid for it, whose contributions then leave the
/// volume. Triangles valid for no sampled plane get planes through their own supporting plane.
fn cluster(
    tris: &[Tri],
    epsilon: f32,
    radius: f32,
    dirs: &[Vec3],
    weights: &[f32],
    per_eps: u32,
) -> Vec<Cluster> {
    let mut dual = Dual::new(dirs, weights, radius, epsilon, per_eps);
    for tri in tris {
        dual.accumulate(tri, 1);
    }
    let mut covered = vec![false; tris.len()];
    let mut uncovered: Vec<usize> = (0..tris.len()).collect();
    let mut clusters = Vec::new();
    while let Some((d, k)) = dual.densest() {
        let dir = dirs[d];
        let members: Vec<usize> = uncovered
            .iter()
            .copied()
            .filter(|&t| {
                dual.bins_for(&tris[t], dir)
                    .is_some_and(|(a, b)| (a..=b).contains(&k))
            })
            .collect();
        if members.is_empty() {
            // Unreachable while the counts are exact; never loop on a stale cell.
            dual.count[d * dual.bins + k] = 0;
            continue;
        }
        for &t in &members {
            covered[t] = true;
            dual.accumulate(&tris[t], -1);
        }
        uncovered.retain(|&t| !covered[t]);
        clusters.push(Cluster {
            normal: dir,
            rho: dual.bin_centre(k),
            members,
        });
    }
    // Triangles valid for no sampled plane (e.g. a long trunk strip whose normal is far from
    // every sampled direction): the largest takes its own supporting plane, with every remaining
    // triangle valid for it, until none is left, so coverage is guaranteed.
    while !uncovered.is_empty() {
        let seed = uncovered.iter().copied().fold(uncovered[0], |b, t| {
            if tris[t].area > tris[b].area { t } else { b }
        });
        let normal = canonical(tris[seed].normal);
        let rho = normal.dot(tris[seed].centroid());
        let members: Vec<usize> = uncovered
            .iter()
            .copied()
            .filter(|&t| t == seed || tris[t].valid_for(normal, rho, epsilon))
            .collect();
        uncovered.retain(|t| !members.contains(t));
        clusters.push(Cluster {
            normal,
            rho,
            members,
        });
    }
    clusters
}

/// `n` or `−n`, whichever points up (ties broken on z, then x), so equal planes get equal normals.
fn canonical(n: Vec3) -> Vec3 {
    let flip = n.y < 0.0 || (n.y == 0.0 && (n.z < 0.0 || (n.z == 0.0 && n.x < 0.0)));
    if flip { -n } else { n }
}

/// In-plane axes for `normal`: the tangent horizontal and the bitangent up for vertical planes
/// (so textures stand upright), an X-aligned tangent for near-horizontal ones.
fn base_frame(normal: Vec3) -> (Vec3, Vec3) {
    let tangent = if normal.y.abs() < 0.999 {
        Vec3::Y.cross(normal).normalize()
    } else {
        (Vec3::X - normal * normal.x).normalize()
    };
    (tangent, normal.cross(tangent))
}

/// Convex hull of `points` (Andrew's monotone chain), counter-clockwise, without repeating the
/// first point; fewer than three distinct points come back as they are (deduplicated).
fn convex_hull(points: &[Vec2]) -> Vec<Vec2> {
    let mut sorted = points.to_vec();
    sorted.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    sorted.dedup();
    if sorted.len() < 3 {
        return sorted;
    }
    let turn = |o: Vec2, a: Vec2, b: Vec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<Vec2> = Vec::with_capacity(2 * sorted.len());
    for pass in [
        sorted.as_slice(),
        &sorted.iter().rev().copied().collect::<Vec<_>>(),
    ] {
        let floor = hull.len();
        for &p in pass {
            while hull.len() >= floor + 2
                && turn(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        // The last point of each chain starts the other one.
        hull.pop();
    }
    hull
}

/// Builds the plane `{p : normal · p = offset}` for `triangles` (input indices) with the
/// in-plane rotation whose bounding rectangle of the members is smallest, so the texture wastes
/// the fewest texels. The smallest rectangle has a side along an edge of the members' convex
/// hull (Freeman & Shapira 1975, the rotating-calipers argument), so those edge directions are
/// the candidates, after the upright base frame; a candidate must beat the best so far by
/// 0.01 % to win, so near-ties keep the base frame and the result is deterministic.
fn make_plane(
    normal: Vec3,
    offset: f32,
    role: PlaneRole,
    mut triangles: Vec<u32>,
    input: &[CloudTriangle],
) -> CloudPlane {
    triangles.sort_unstable();
    let origin = normal * offset;
    let (t0, b0) = base_frame(normal);
    let flat: Vec<Vec2> = triangles
        .iter()
        .flat_map(|&t| input[t as usize].vertices)
        .map(|v| {
            let d = v - origin;
            Vec2::new(d.dot(t0), d.dot(b0))
        })
        .collect();
    let hull = convex_hull(&flat);
    let mut angles = vec![0.0f32];
    for (i, &a) in hull.iter().enumerate() {
        let edge = hull[(i + 1) % hull.len()] - a;
        if edge != Vec2::ZERO {
            // The rectangle is the same every quarter turn.
            angles.push(edge.y.atan2(edge.x).rem_euclid(FRAC_PI_2));
        }
    }
    let mut best = (0.0f32, f32::INFINITY);
    for angle in angles {
        let (sin, cos) = angle.sin_cos();
        let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
        for p in &hull {
            // Coordinates along t0·cos + b0·sin and normal × that = b0·cos − t0·sin.
            let uv = Vec2::new(p.x * cos + p.y * sin, p.y * cos - p.x * sin);
            lo = lo.min(uv);
            hi = hi.max(uv);
        }
        let size = hi - lo;
        let area = size.x * size.y;
        if area < best.1 * (1.0 - 1e-4) {
            best = (angle, area);
        }
    }
    let (sin, cos) = best.0.sin_cos();
    let best = ((t0 * cos + b0 * sin).normalize(), best.1);
    let tangent = best.0;
    let mut plane = CloudPlane {
        normal,
        offset,
        tangent,
        bitangent: normal.cross(tangent),
        min: Vec2::ZERO,
        max: Vec2::ZERO,
        role,
        triangles,
    };
    // The rectangle from `project` itself, so every member's projection lies inside it exactly.
    let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
    for &t in &plane.triangles {
        for v in input[t as usize].vertices {
            let uv = plane.project(v);
            lo = lo.min(uv);
            hi = hi.max(uv);
        }
    }
    plane.min = lo;
    plane.max = hi;
    plane
}

/// Directions tried for a cardboard plane, spanning a half turn around the primary normal.
const CARDBOARD_DIRECTIONS: u32 = 16;

/// The best cardboard plane for a branch cluster (seed 001 §4.3, fig. 4.3): planes orthogonal
/// to the primary plane through the members' area-weighted centre of gravity; coverage is the
/// member area within ε of the plane over the members' area. Returns the normal, ρ (relative
/// space) and the covered members when the best coverage reaches `threshold`.
fn cardboard(
    primary: &Cluster,
    tris: &[Tri],
    epsilon: f32,
    threshold: f32,
) -> Option<(Vec3, f32, Vec<usize>)> {
    let total: f32 = primary.members.iter().map(|&t| tris[t].area).sum();
    if total.is_nan() || total <= 0.0 {
        return None;
    }
    let gravity = primary
        .members
        .iter()
        .map(|&t| tris[t].centroid() * tris[t].area)
        .sum::<Vec3>()
        / total;
    let (t0, b0) = base_frame(primary.normal);
    let mut best: Option<(f32, Vec3)> = None;
    for k in 0..CARDBOARD_DIRECTIONS {
        let angle = k as f32 / CARDBOARD_DIRECTIONS as f32 * PI;
        let (sin, cos) = angle.sin_cos();
        let m = (t0 * cos + b0 * sin).normalize();
        let rho = m.dot(gravity);
        let covered: f32 = primary
            .members
            .iter()
            .filter(|&&t| tris[t].valid_for(m, rho, epsilon))
            .map(|&t| tris[t].area)
            .sum();
        let coverage = covered / total;
        if best.is_none_or(|(c, _)| coverage > c) {
            best = Some((coverage, m));
        }
    }
    let (coverage, m) = best?;
    if coverage < threshold {
        return None;
    }
    let normal = canonical(m);
    let rho = normal.dot(gravity);
    let members: Vec<usize> = primary
        .members
        .iter()
        .copied()
        .filter(|&t| tris[t].valid_for(normal, rho, epsilon))
        .collect();
    (!members.is_empty()).then_some((normal, rho, members))
}

/// Simplifies `triangles` to a billboard cloud (Decoret et al. 2003 with the vegetation
/// extensions of seed 001 §4.3; see the module docs).
///
/// Triangles with a non-finite coordinate or no area ([`CloudTriangle::is_usable`]) are
/// ignored; `settings` are [sanitized](CloudSettings::sanitized) first.
/// Every remaining triangle ends up on at least one plane with each vertex within its part's ε.
pub fn build_cloud(
    triangles: &[CloudTriangle],
    settings: &CloudSettings,
) -> Result<BillboardCloud, CloudError> {
    if triangles.is_empty() {
        return Err(CloudError::NoTriangles);
    }
    let (settings, _) = settings.sanitized();
    let mut degenerate = 0usize;
    let mut valid: Vec<u32> = Vec::with_capacity(triangles.len());
    for (i, tri) in triangles.iter().enumerate() {
        if !tri.is_finite() {
            continue;
        } else if tri.is_degenerate() {
            degenerate += 1;
        } else {
            valid.push(i as u32);
        }
    }
    if valid.is_empty() {
        // Only non-finite triangles, or at least one finite one without area.
        return Err(if degenerate == 0 {
            CloudError::NonFinite
        } else {
            CloudError::Degenerate
        });
    }

    // Bounding sphere: centre of the bounding box, radius to the farthest vertex.
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &i in &valid {
        for v in triangles[i as usize].vertices {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    let center = (lo + hi) * 0.5;
    let radius = valid
        .iter()
        .flat_map(|&i| triangles[i as usize].vertices)
        .map(|v| v.distance(center))
        .fold(0.0f32, f32::max);
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(CloudError::Degenerate);
    }
    let epsilon = settings.epsilon_fraction * radius;
    let branch_epsilon = settings.branch_epsilon_fraction * radius;

    let dirs = hemisphere_directions(settings.directions);
    let weights: Vec<f32> = dirs
        .iter()
        .map(|&n| horizontal_weight(n, settings.horizontal_penalty))
        .collect();
    let prepare = |part: TreePart| -> Vec<Tri> {
        valid
            .iter()
            .filter(|&&i| triangles[i as usize].part == part)
            .map(|&i| {
                let tri = &triangles[i as usize];
                Tri {
                    input: i,
                    rel: tri.vertices.map(|v| v - center),
                    area: tri.area(),
                    normal: tri.normal(),
                }
            })
            .collect()
    };
    let inputs = |tris: &[Tri], members: &[usize]| -> Vec<u32> {
        members.iter().map(|&t| tris[t].input).collect()
    };

    let mut planes = Vec::new();
    let leaves = prepare(TreePart::Leaves);
    for c in cluster(
        &leaves,
        epsilon,
        radius,
        &dirs,
        &weights,
        settings.rho_bins_per_epsilon,
    ) {
        planes.push(make_plane(
            c.normal,
            c.rho + c.normal.dot(center),
            PlaneRole::Leaves,
            inputs(&leaves, &c.members),
            triangles,
        ));
    }
    let branches = prepare(TreePart::Branches);
    for c in cluster(
        &branches,
        branch_epsilon,
        radius,
        &dirs,
        &weights,
        settings.rho_bins_per_epsilon,
    ) {
        planes.push(make_plane(
            c.normal,
            c.rho + c.normal.dot(center),
            PlaneRole::Branches,
            inputs(&branches, &c.members),
            triangles,
        ));
        if let Some((normal, rho, members)) =
            cardboard(&c, &branches, branch_epsilon, settings.cardboard_coverage)
        {
            planes.push(make_plane(
                normal,
                rho + normal.dot(center),
                PlaneRole::Cardboard,
                inputs(&branches, &members),
                triangles,
            ));
        }
    }

    if planes.len() > settings.max_planes as usize {
        return Err(CloudError::TooManyPlanes {
            needed: planes.len(),
            max: settings.max_planes,
        });
    }
    Ok(BillboardCloud {
        center,
        radius,
        epsilon,
        branch_epsilon,
        planes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pruning::procedural::{TreeSpecies, generate};
    use crate::rng::SplitMix64;

    /// The olea test tree: leaf quads as `Leaves`, bark as `Branches`.
    fn tree(leaf_count: usize) -> Vec<CloudTriangle> {
        tree_of(&TreeSpecies::olea().with_leaf_count(leaf_count))
    }

    /// A procedural tree: leaf quads as `Leaves`, bark as `Branches`.
    fn tree_of(species: &TreeSpecies) -> Vec<CloudTriangle> {
        let t = generate(species);
        let tri = |pos: &[Vec3], c: &[u32], part| {
            CloudTriangle::new(
                [pos[c[0] as usize], pos[c[1] as usize], pos[c[2] as usize]],
                part,
            )
        };
        let mut out: Vec<CloudTriangle> = t
            .leaves
            .indices
            .chunks_exact(3)
            .map(|c| tri(&t.leaves.positions, c, TreePart::Leaves))
            .collect();
        out.extend(
            t.bark
                .indices
                .chunks_exact(3)
                .map(|c| tri(&t.bark.positions, c, TreePart::Branches)),
        );
        out
    }

    /// A quad of half extents `a`, `b` around `centre` as two triangles.
    fn quad(centre: Vec3, a: Vec3, b: Vec3, part: TreePart) -> [CloudTriangle; 2] {
        let [p0, p1, p2, p3] = [
            centre - a - b,
            centre + a - b,
            centre + a + b,
            centre - a + b,
        ];
        [
            CloudTriangle::new([p0, p1, p2], part),
            CloudTriangle::new([p0, p2, p3], part),
        ]
    }

    /// Random triangles of mixed sizes (some long and thin) in a 2 m cube, both parts.
    fn soup(seed: u64, n: usize) -> Vec<CloudTriangle> {
        let mut r = SplitMix64::new(seed);
        let v =
            |s: f32, r: &mut SplitMix64| Vec3::new(r.range(-s, s), r.range(-s, s), r.range(-s, s));
        (0..n)
            .map(|i| {
                let c = v(1.0, &mut r);
                let s = if i % 7 == 0 { 0.9 } else { 0.15 };
                let part = if i % 3 == 0 {
                    TreePart::Branches
                } else {
                    TreePart::Leaves
                };
                CloudTriangle::new([c + v(s, &mut r), c + v(s, &mut r), c + v(s, &mut r)], part)
            })
            .collect()
    }

    /// Checks every invariant of a cloud: each member within its part's ε of its plane and
    /// inside the plane's rectangle, parts never mixed, roles matching parts, orthonormal
    /// right-handed frames, and every valid input triangle on a primary plane.
    fn check_cloud(input: &[CloudTriangle], cloud: &BillboardCloud) {
        let tolerance = 1e-4 * cloud.radius;
        let mut covered = vec![false; input.len()];
        for (i, plane) in cloud.planes.iter().enumerate() {
            assert!((plane.normal.length() - 1.0).abs() < 1e-4, "plane {i}");
            assert!((plane.tangent.length() - 1.0).abs() < 1e-4, "plane {i}");
            assert!(plane.normal.dot(plane.tangent).abs() < 1e-4, "plane {i}");
            assert!(
                plane.bitangent.distance(plane.normal.cross(plane.tangent)) < 1e-4,
                "plane {i}: bitangent = normal × tangent"
            );
            assert!(!plane.triangles.is_empty(), "plane {i} has no triangles");
            let part = input[plane.triangles[0] as usize].part;
            let expected = match plane.role {
                PlaneRole::Leaves => TreePart::Leaves,
                PlaneRole::Branches | PlaneRole::Cardboard => TreePart::Branches,
            };
            assert_eq!(part, expected, "plane {i} role {:?}", plane.role);
            let eps = cloud.epsilon_of(part);
            for &t in &plane.triangles {
                let tri = &input[t as usize];
                assert_eq!(tri.part, part, "plane {i} mixes leaves and branches");
                for v in tri.vertices {
                    let d = plane.distance(v).abs();
                    assert!(
                        d <= eps + tolerance,
                        "plane {i} ({:?}), triangle {t}: vertex {d} from the plane, ε {eps}",
                        plane.role
                    );
                    let uv = plane.project(v);
                    assert!(
                        uv.cmpge(plane.min - tolerance).all()
                            && uv.cmple(plane.max + tolerance).all(),
                        "plane {i}, triangle {t}: {uv} outside {}..{}",
                        plane.min,
                        plane.max
                    );
                }
                if plane.role != PlaneRole::Cardboard {
                    covered[t as usize] = true;
                }
            }
        }
        let mut valid = 0;
        for (t, tri) in input.iter().enumerate() {
            if tri.is_usable() {
                valid += 1;
                assert!(covered[t], "triangle {t} on no plane");
            } else {
                assert!(!covered[t], "skipped triangle {t} on a plane");
            }
        }
        assert!(valid > 0);
    }

    #[test]
    fn tree_members_lie_within_epsilon_and_inside_their_rectangles() {
        let input = tree(1500);
        let start = std::time::Instant::now();
        let cloud = build_cloud(&input, &CloudSettings::default()).unwrap();
        println!(
            "olea 1500 leaves + bark: {} triangles, {:?}: {} leaf, {} branch, {} cardboard planes",
            input.len(),
            start.elapsed(),
            cloud.count(PlaneRole::Leaves),
            cloud.count(PlaneRole::Branches),
            cloud.count(PlaneRole::Cardboard)
        );
        check_cloud(&input, &cloud);
        assert!((cloud.epsilon / cloud.radius - 0.12).abs() < 1e-6);
        assert!((cloud.branch_epsilon / cloud.radius - 0.08).abs() < 1e-6);
    }

    #[test]
    fn forty_thousand_triangles_stay_fast() {
        // Quercus at 20,000 leaves: 40,000 leaf triangles plus bark. The crate is built at
        // opt-level 3 even in dev, so this is a real timing; the bound is loose for slow CI.
        let input = tree_of(&TreeSpecies::quercus().with_leaf_count(20_000));
        let start = std::time::Instant::now();
        let cloud = build_cloud(&input, &CloudSettings::default()).unwrap();
        let elapsed = start.elapsed();
        println!(
            "quercus 20,000 leaves + bark: {} triangles in {elapsed:?}, {} planes",
            input.len(),
            cloud.planes.len()
        );
        check_cloud(&input, &cloud);
        assert!(elapsed.as_secs_f32() < 10.0, "{elapsed:?}");
    }

    #[test]
    fn a_tree_reduces_to_far_fewer_planes_than_triangles() {
        let input = tree(1500);
        let cloud = build_cloud(&input, &CloudSettings::default()).unwrap();
        assert!(
            cloud.planes.len() <= 64,
            "{} planes for {} triangles",
            cloud.planes.len(),
            input.len()
        );
        assert!(cloud.count(PlaneRole::Leaves) >= 2);
        assert!(cloud.count(PlaneRole::Branches) >= 1);
        // Leaf planes come first, branch planes after, each cardboard right after a branch plane.
        let roles: Vec<PlaneRole> = cloud.planes.iter().map(|p| p.role).collect();
        let first_branch = roles.iter().position(|&r| r != PlaneRole::Leaves).unwrap();
        assert!(
            roles[first_branch..]
                .iter()
                .all(|&r| r != PlaneRole::Leaves)
        );
        for w in roles.windows(2) {
            if w[1] == PlaneRole::Cardboard {
                assert_eq!(w[0], PlaneRole::Branches);
            }
        }
        // The greedy cover puts most leaf area on few planes: the densest plane carries more
        // than its share.
        let leaf_planes = cloud.count(PlaneRole::Leaves);
        let leaves = input.iter().filter(|t| t.part == TreePart::Leaves).count();
        assert!(cloud.planes[0].triangles.len() * leaf_planes > leaves);
    }

    #[test]
    fn random_soups_are_fully_covered() {
        for seed in 0..4 {
            let input = soup(seed, 400);
            let settings = CloudSettings {
                max_planes: 10_000,
                ..Default::default()
            };
            let cloud = build_cloud(&input, &settings).unwrap();
            check_cloud(&input, &cloud);
        }
    }

    #[test]
    fn triangles_valid_for_no_sampled_plane_get_their_own_plane() {
        // Directions 1: only the pole and two equator directions are sampled; a large triangle
        // tilted 45° (extent along each of them far above 2ε) is valid for none.
        let tilted = CloudTriangle::new(
            [
                Vec3::new(-2.0, -2.0, 0.0),
                Vec3::new(2.0, -2.0, 0.0),
                Vec3::new(0.0, 2.0, 2.0),
            ],
            TreePart::Leaves,
        );
        let small = CloudTriangle::new(
            [
                Vec3::new(0.0, 0.0, 1.0),
                Vec3::new(0.1, 0.0, 1.0),
                Vec3::new(0.0, 0.1, 1.0),
            ],
            TreePart::Leaves,
        );
        let input = [tilted, small];
        let settings = CloudSettings {
            directions: 1,
            ..Default::default()
        };
        assert!(hemisphere_directions(1).len() <= 4);
        let cloud = build_cloud(&input, &settings).unwrap();
        check_cloud(&input, &cloud);
        let own = cloud
            .planes
            .iter()
            .find(|p| p.triangles.contains(&0))
            .unwrap();
        assert!(own.normal.dot(tilted.normal()).abs() > 0.9999);
    }

    /// A strip of leaves along x (4 m long, 0.2 m wide, 0.1 m thick) whose leaves face mostly
    /// up, tilted about x: unpenalised, the horizontal plane has the largest projected area.
    fn leaf_strip() -> Vec<CloudTriangle> {
        let mut r = SplitMix64::new(11);
        let mut out = Vec::new();
        for i in 0..200 {
            let c = Vec3::new(
                -2.0 + 4.0 * (i as f32 + 0.5) / 200.0,
                r.range(-0.03, 0.03),
                r.range(-0.05, 0.05),
            );
            let n = Vec3::new(r.range(-0.3, 0.3), 1.0, r.range(-1.0, 1.0)).normalize();
            let a = n.any_orthonormal_vector();
            out.extend(quad(c, a * 0.03, n.cross(a) * 0.03, TreePart::Leaves));
        }
        out
    }

    #[test]
    fn horizontal_penalty_steers_planes_away_from_horizontal() {
        let input = leaf_strip();
        let mean_ny = |penalty: f32| {
            let settings = CloudSettings {
                horizontal_penalty: penalty,
                ..Default::default()
            };
            let cloud = build_cloud(&input, &settings).unwrap();
            check_cloud(&input, &cloud);
            let ny: Vec<f32> = cloud.planes.iter().map(|p| p.normal.y.abs()).collect();
            (ny[0], ny.iter().sum::<f32>() / ny.len() as f32, ny.len())
        };
        let (first_off, mean_off, n_off) = mean_ny(0.0);
        let (first_on, mean_on, n_on) = mean_ny(0.6);
        println!("penalty off: {n_off} planes, mean |n.y| {mean_off}; on: {n_on}, {mean_on}");
        assert!(first_off > 0.99, "unpenalised best plane is horizontal");
        assert!(
            first_on < 0.9,
            "penalised best plane tilts: |n.y| {first_on}"
        );
        assert!(mean_on < mean_off - 0.2, "{mean_on} vs {mean_off}");
    }

    /// A vertical capless cylinder (trunk) of `sides` sides as branch triangles.
    fn trunk(radius: f32, height: f32, sides: u32) -> Vec<CloudTriangle> {
        let ring = |i: u32, y: f32| {
            let a = i as f32 / sides as f32 * TAU;
            Vec3::new(a.cos() * radius, y, a.sin() * radius)
        };
        (0..sides)
            .flat_map(|i| {
                let [a, b, c, d] = [
                    ring(i, 0.0),
                    ring(i + 1, 0.0),
                    ring(i + 1, height),
                    ring(i, height),
                ];
                [
                    CloudTriangle::new([a, c, b], TreePart::Branches),
                    CloudTriangle::new([a, d, c], TreePart::Branches),
                ]
            })
            .collect()
    }

    #[test]
    fn a_trunk_gets_an_orthogonal_cardboard_plane() {
        let input = trunk(0.1, 4.0, 12);
        let cloud = build_cloud(&input, &CloudSettings::default()).unwrap();
        check_cloud(&input, &cloud);
        assert_eq!(cloud.count(PlaneRole::Branches), 1, "{:#?}", cloud.planes);
        assert_eq!(cloud.count(PlaneRole::Cardboard), 1);
        let (primary, board) = (&cloud.planes[0], &cloud.planes[1]);
        assert_eq!(board.role, PlaneRole::Cardboard);
        assert!(primary.normal.y.abs() < 1e-3, "the trunk plane is vertical");
        assert!(primary.normal.dot(board.normal).abs() < 1e-3, "orthogonal");
        assert_eq!(
            board.triangles.len(),
            input.len(),
            "it covers the whole trunk"
        );
        // Upright textures: the bitangent of a vertical plane points up.
        assert!(primary.bitangent.y > 0.99 && board.bitangent.y > 0.99);
        assert!((primary.size().y - 4.0).abs() < 1e-3);

        let strict = CloudSettings {
            cardboard_coverage: 1.01,
            ..Default::default()
        };
        let cloud = build_cloud(&input, &strict).unwrap();
        assert_eq!(cloud.count(PlaneRole::Cardboard), 0);
        assert_eq!(cloud.count(PlaneRole::Branches), 1);
    }

    #[test]
    fn a_flat_branch_fan_gets_no_cardboard() {
        // Twigs spread over a 3 m vertical fan: an orthogonal plane covers only a sliver.
        let input: Vec<CloudTriangle> = (0..24)
            .map(|i| {
                let a = i as f32 / 24.0 * PI;
                let dir = Vec3::new(a.cos(), a.sin(), 0.0);
                let side = Vec3::Z.cross(dir) * 0.02;
                CloudTriangle::new([side, -side, dir * 3.0], TreePart::Branches)
            })
            .collect();
        let cloud = build_cloud(&input, &CloudSettings::default()).unwrap();
        check_cloud(&input, &cloud);
        assert_eq!(cloud.count(PlaneRole::Branches), 1);
        assert_eq!(cloud.count(PlaneRole::Cardboard), 0);
    }

    #[test]
    fn leaves_and_branches_are_clustered_separately() {
        // Leaves and twigs interleaved in one vertical layer: one plane would fit them all.
        let mut input = Vec::new();
        for i in 0..10 {
            let c = Vec3::new(i as f32 * 0.3 - 1.5, 1.0, 0.0);
            let part = if i % 2 == 0 {
                TreePart::Leaves
            } else {
                TreePart::Branches
            };
            input.extend(quad(c, Vec3::X * 0.1, Vec3::Y * 0.5, part));
        }
        let cloud = build_cloud(&input, &CloudSettings::default()).unwrap();
        check_cloud(&input, &cloud);
        assert_eq!(cloud.count(PlaneRole::Leaves), 1);
        assert_eq!(cloud.count(PlaneRole::Branches), 1);
        // And in the tree.
        let input = tree(400);
        check_cloud(
            &input,
            &build_cloud(&input, &CloudSettings::default()).unwrap(),
        );
    }

    #[test]
    fn the_texture_rectangle_is_the_smallest_over_rotations() {
        // A 2 × 0.5 rectangle in the plane z = 1, rotated 30° in it.
        let rot = bevy::math::Quat::from_rotation_z(30f32.to_radians());
        let input = quad(
            Vec3::Z,
            rot * Vec3::X,
            rot * Vec3::Y * 0.25,
            TreePart::Leaves,
        );
        let cloud = build_cloud(&input, &CloudSettings::default()).unwrap();
        check_cloud(&input, &cloud);
        assert_eq!(cloud.planes.len(), 1);
        let plane = &cloud.planes[0];
        assert!(plane.normal.z.abs() > 0.999);
        // The exact 1 m², not the 1.87 m² of the axis-aligned box.
        assert!((plane.area() - 1.0).abs() < 1e-3, "area {}", plane.area());
        let axis = plane
            .tangent
            .dot(rot * Vec3::X)
            .abs()
            .max(plane.tangent.dot(rot * Vec3::Y).abs());
        assert!(axis > 0.9999, "the rectangle follows the quad");
        assert!((plane.distance(Vec3::Z)).abs() < cloud.epsilon);
    }

    #[test]
    fn project_and_point_are_inverse_on_the_plane() {
        let input = tree(200);
        let cloud = build_cloud(&input, &CloudSettings::default()).unwrap();
        for plane in &cloud.planes {
            for uv in [Vec2::ZERO, plane.min, plane.max, Vec2::new(0.3, -1.2)] {
                let p = plane.point(uv);
                assert!(plane.distance(p).abs() < 1e-4);
                assert!(plane.project(p).distance(uv) < 1e-4);
            }
        }
    }

    #[test]
    fn errors_name_what_is_wrong() {
        let settings = CloudSettings::default();
        assert_eq!(build_cloud(&[], &settings), Err(CloudError::NoTriangles));
        let nan = CloudTriangle::new([Vec3::NAN, Vec3::X, Vec3::Y], TreePart::Leaves);
        let inf = CloudTriangle::new([Vec3::ZERO, Vec3::INFINITY, Vec3::Y], TreePart::Branches);
        assert_eq!(
            build_cloud(&[nan, inf], &settings),
            Err(CloudError::NonFinite)
        );
        let collinear = CloudTriangle::new([Vec3::ZERO, Vec3::X, Vec3::X * 2.0], TreePart::Leaves);
        let point = CloudTriangle::new([Vec3::ONE; 3], TreePart::Branches);
        assert_eq!(
            build_cloud(&[collinear, point], &settings),
            Err(CloudError::Degenerate)
        );
        assert_eq!(
            build_cloud(&[nan, collinear], &settings),
            Err(CloudError::Degenerate)
        );
        // Bad triangles among good ones are skipped, not fatal.
        let mut input = soup(5, 50);
        input.extend([nan, inf, collinear, point]);
        let cloud = build_cloud(
            &input,
            &CloudSettings {
                max_planes: 1000,
                ..settings.clone()
            },
        )
        .unwrap();
        assert_eq!(input.iter().filter(|t| !t.is_usable()).count(), 4);
        check_cloud(&input, &cloud);
        let needed = cloud.planes.len();
        assert!(needed > 2);
        let capped = CloudSettings {
            max_planes: 2,
            ..settings
        };
        let err = build_cloud(&input, &capped).unwrap_err();
        assert_eq!(err, CloudError::TooManyPlanes { needed, max: 2 });
        assert!(err.to_string().contains("max_planes"));
    }

    #[test]
    fn absurd_settings_are_sanitized() {
        let (same, notes) = CloudSettings::default().sanitized();
        assert_eq!(same, CloudSettings::default());
        assert!(notes.is_empty());
        let absurd = CloudSettings {
            epsilon_fraction: f32::NAN,
            branch_epsilon_fraction: 1.5,
            directions: 0,
            rho_bins_per_epsilon: 1000,
            horizontal_penalty: -1.0,
            cardboard_coverage: f32::INFINITY,
            max_planes: 0,
        };
        let (fixed, notes) = absurd.sanitized();
        assert_eq!(fixed, CloudSettings::default(), "{notes:?}");
        assert_eq!(notes.len(), 7, "{notes:?}");
        assert!(notes[0].contains("epsilon_fraction"));
        // A huge dual volume (16384 directions × 2·64/0.001 bins) is refused too.
        let huge = CloudSettings {
            epsilon_fraction: 0.001,
            directions: 16384,
            rho_bins_per_epsilon: 64,
            ..Default::default()
        };
        let (fixed, notes) = huge.sanitized();
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert_eq!(fixed.directions, 256);
        // build_cloud sanitizes: absurd settings behave like the defaults.
        let input = tree(200);
        assert_eq!(
            build_cloud(&input, &absurd),
            build_cloud(&input, &CloudSettings::default())
        );
    }

    #[test]
    fn same_input_same_cloud() {
        let input = tree(600);
        let a = build_cloud(&input, &CloudSettings::default()).unwrap();
        let b = build_cloud(&input, &CloudSettings::default()).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn hemisphere_directions_are_distinct_unit_and_cover_every_plane() {
        for count in [16, 256, 1024] {
            let dirs = hemisphere_directions(count);
            println!("{count}: {} directions", dirs.len());
            let n = dirs.len() as f32;
            assert!(
                (n / count as f32 - 1.0).abs() < 0.25,
                "{} for {count}",
                dirs.len()
            );
            for (i, a) in dirs.iter().enumerate() {
                assert!((a.length() - 1.0).abs() < 1e-5 && a.y >= 0.0);
                for b in &dirs[..i] {
                    assert!(a.dot(*b).abs() < 0.9999, "{a} and {b} are the same plane");
                }
            }
            // Every unit normal (as a plane, ±) is near some sampled one.
            let spacing = (TAU / count as f32).sqrt();
            let mut r = SplitMix64::new(count as u64);
            for _ in 0..500 {
                let u = Vec3::new(r.range(-1.0, 1.0), r.range(-1.0, 1.0), r.range(-1.0, 1.0))
                    .normalize_or(Vec3::X);
                let best = dirs.iter().map(|d| d.dot(u).abs()).fold(0.0, f32::max);
                assert!(best.acos() < spacing * 1.1, "{u}: {} rad", best.acos());
            }
        }
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            assert!(
                hemisphere_directions(256)
                    .iter()
                    .any(|d| d.dot(axis).abs() > 0.99999)
            );
        }
    }

    #[test]
    fn dual_bins_are_exactly_the_valid_bin_centres() {
        let dirs = hemisphere_directions(64);
        let weights = vec![1.0; dirs.len()];
        let dual = Dual::new(&dirs, &weights, 1.7, 0.2, 3);
        for (i, t) in soup(8, 300).iter().enumerate() {
            let tri = Tri {
                input: i as u32,
                rel: t.vertices.map(|v| v * 0.8),
                area: t.area(),
                normal: t.normal(),
            };
            for &dir in &dirs {
                let range = dual.bins_for(&tri, dir);
                for k in 0..dual.bins {
                    let inside = range.is_some_and(|(a, b)| (a..=b).contains(&k));
                    let valid = tri.valid_for(dir, dual.bin_centre(k), dual.epsilon);
                    // Exact up to the rounding of the two formulas (max ρ − ε vs |ρ − c| ≤ ε).
                    let margin = tri
                        .rel
                        .iter()
                        .map(|v| ((dir.dot(*v) - dual.bin_centre(k)).abs() - dual.epsilon).abs())
                        .fold(f32::INFINITY, f32::min);
                    if margin > 1e-5 {
                        assert_eq!(inside, valid, "triangle {i}, bin {k}, {dir}");
                    }
                }
            }
        }
    }

    #[test]
    fn penalty_weight_spares_steep_planes() {
        assert_eq!(horizontal_weight(Vec3::X, 0.6), 1.0);
        assert_eq!(
            horizontal_weight(Vec3::new(0.9, 0.45, 0.0).normalize(), 0.6),
            1.0
        );
        assert!((horizontal_weight(Vec3::Y, 0.6) - 0.4).abs() < 1e-6);
        assert!((horizontal_weight(-Vec3::Y, 1.0)).abs() < 1e-6);
    }
}
