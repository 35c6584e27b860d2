//! A map of the open share across each leaf: where the eye looks on a leaf says how open the
//! part in view is, wherever the eye is.
//!
//! The seen-part gains ([`super::seen_part`]) give a leaf one gain per octant of the eye: the
//! part of the leaf in view is its more open part, because the leaves that hide the rest of it
//! from the eye hide the sky too. How much more open depends on the eye's direction sharply,
//! and eight octants blur it (the crown's sky in images is still 2–6 % too dark with them).
//! But the eye sees points, and each point brings its own openness: a map of the open share
//! over the leaf, read where the eye ray meets it, knows which part is in view without being
//! told the eye's direction. Only what the map's cells are too coarse to hold is left to the
//! octants, as eight residual gains `Σ open·V / Σ map·V`.
//!
//! The map's cells lie on a square in the leaf's plane that a leaf shader can find from what
//! each vertex carries ([`MapFrame::of_leaf`]): centred on the leaf's centroid, its half side
//! the leaf's radius, its two axes stored with the map ([`StoredOpenMap`]). Measured on the
//! sky (`tree_lighting_error --images --open-maps CxP[r]`, see [`super::seen_part`]): 3 × 3
//! cells from 32 points, times the residual gains, take the four procedural trees' image
//! error from 18.0 to 15.2 points summed over the trees (four seeds, against the eight gains
//! from as many points). A bake stores each leaf's map with its residual gains
//! ([`LeafOpenMap`], [`open_maps_of`]); the leaf vertex stage blends the residual gains towards
//! the eye on the sky, and the fragment stage reads the cell under the pixel. Plain Rust, no
//! render types.

use super::leaf_scene::LeafScene;
use super::seen_part::{
    GAIN_RANGE, OPEN_RAYS_PER_POINT, direction_in_octant, gain_of, open_share_at, quantize_gain,
    seen_gain,
};
use super::sunlit_share::PlaneFit;
use crate::rng::SplitMix64;
use bevy::math::Vec3;

/// Cells a side of a map as a bake stores it.
pub const STORED_SIDE: u32 = 3;

/// Points per leaf for its map in a bake ([`open_maps_of`]): 3 × 3 cells from 32 points, times
/// their residual gains, measured best of the sides and counts tried (4 × 4 cells from as many
/// points no better; from 16 points a small gain over the eight gains alone). At load time and
/// in `foliage_bake` alike: on the olive's 16,107 leaves they cost 8.5 s on two cores.
pub const DEFAULT_OPEN_MAP_POINTS: u32 = 32;

/// Bytes of a [`LeafOpenMap`] in a bake file: the residual gains (eight `u16`), the nine cell
/// codes and the two axes.
pub const LEAF_OPEN_MAP_BYTES: usize = 29;

/// Where an [`OpenMap`]'s grid lies on its leaf: a rectangle in the leaf's plane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MapFrame {
    /// The middle of the grid, in the leaf's plane.
    pub centre: Vec3,
    /// The grid's two axes, unit vectors in the leaf's plane.
    pub axes: (Vec3, Vec3),
    /// The grid's half extent along each axis.
    pub half: (f32, f32),
}

impl MapFrame {
    /// The square a leaf shader can find from what each vertex carries: centred on the leaf's
    /// centroid, its axes [`Vec3::any_orthonormal_pair`] of the leaf's normal, its half side
    /// the leaf's radius (the farthest corner from the centroid).
    /// The axes are those two bytes each hold ([`encode_axis`]), so that a map binned on
    /// them is read on the same cells from its stored copy ([`StoredOpenMap`]).
    pub fn of_leaf(centroid: Vec3, normal: Vec3, radius: f32) -> Self {
        let (a, b) = normal.normalize_or(Vec3::Y).any_orthonormal_pair();
        Self {
            centre: centroid,
            axes: (decode_axis(encode_axis(a)), decode_axis(encode_axis(b))),
            half: (radius, radius),
        }
    }

    /// The cell of a `side × side` grid a point of the leaf falls in, row by row (the nearest
    /// at the edge).
    pub fn cell(&self, side: u32, at: Vec3) -> usize {
        let side = side.max(1);
        let d = at - self.centre;
        let index = |x: f32, half: f32| {
            let u = if half > 0.0 {
                (x / half + 1.0) * 0.5
            } else {
                0.5
            };
            ((u * side as f32).floor() as i64).clamp(0, side as i64 - 1) as usize
        };
        index(d.dot(self.axes.1), self.half.1) * side as usize
            + index(d.dot(self.axes.0), self.half.0)
    }
}

/// The open share across a leaf as a `side × side` grid of cells in the leaf's plane
/// ([`open_map`]), with what it leaves of the seen part's gain per octant of the eye: where a
/// neighbour covers a patch of the leaf, the part in view is the rest, and the cell the eye
/// looks at says how open it is wherever the eye is.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OpenMap {
    /// The leaf's mean open share (over every point traced).
    pub mean: f32,
    /// Where the grid lies.
    pub frame: MapFrame,
    /// Cells a side.
    pub side: u32,
    /// Each cell's mean open share, row by row (the leaf's mean where no point fell).
    pub cells: Vec<f32>,
    /// Per octant of the eye ([`super::bins::DIRECTIONS`]), the seen part's gain from the same points
    /// ([`super::seen_part::seen_part_gains`]' `Σ open·V / (Σ V · mean)`; 1 where no point
    /// is seen from the octant).
    pub gains: [f32; 8],
    /// Per octant of the eye, what the map leaves of the seen part's gain:
    /// `Σ open·V / Σ map·V` over the points (1 where no point is seen from the octant).
    pub residual: [f32; 8],
}

impl OpenMap {
    /// The gain at point `at` of the leaf: its cell's open share over the leaf's mean, within
    /// [`GAIN_RANGE`] (1 where nothing is open).
    pub fn gain_at(&self, at: Vec3) -> f32 {
        match self.cells.get(self.frame.cell(self.side, at)) {
            Some(&open) if self.mean > 0.0 => (open / self.mean).clamp(GAIN_RANGE.0, GAIN_RANGE.1),
            _ => 1.0,
        }
    }

    /// [`OpenMap::gain_at`] times the residual gains blended towards `to_eye` by eq. 5.7's
    /// lobes, as [`seen_gain`] blends the eight gains.
    pub fn gain_towards(&self, at: Vec3, to_eye: Vec3) -> f32 {
        (self.gain_at(at) * seen_gain(&self.residual, to_eye)).clamp(GAIN_RANGE.0, GAIN_RANGE.1)
    }
}

/// Leaf `leaf`'s [`OpenMap`] of `side × side` cells from a jittered grid of about `points`
/// points over it, each point's open share from one ray per octant ([`open_share_at`]) and
/// one eye ray per octant for the residual gains; the grid over `frame`, or where `None` over
/// the points' bounding rectangle in the leaf's plane.
pub fn open_map(
    scene: &LeafScene,
    leaf: usize,
    frame: Option<MapFrame>,
    side: u32,
    points: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
) -> OpenMap {
    if leaf >= scene.leaf_count() || scene.triangle_count(leaf) == 0 {
        return OpenMap {
            mean: 1.0,
            ..Default::default()
        };
    }
    let mut rng = SplitMix64::new(seed);
    let grid = (points.max(1) as f32).sqrt().ceil() as u32;
    let spots = PlaneFit::jittered(scene, leaf, grid, &mut rng).points;
    let frame = frame.unwrap_or_else(|| {
        let n = scene.normal(leaf);
        let axes = n.any_orthonormal_pair();
        let (lo, hi) = spots.iter().fold(
            (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
            |(lo, hi), p| {
                let q = Vec3::new(p.dot(axes.0), p.dot(axes.1), 0.0);
                (lo.min(q), hi.max(q))
            },
        );
        MapFrame {
            centre: axes.0 * (lo.x + hi.x) * 0.5
                + axes.1 * (lo.y + hi.y) * 0.5
                + n * spots[0].dot(n),
            axes,
            half: ((hi.x - lo.x) * 0.5, (hi.y - lo.y) * 0.5),
        }
    });
    let side = side.max(1);
    let cells = (side * side) as usize;
    let (mut sum, mut count) = (vec![0.0f32; cells], vec![0u32; cells]);
    let mut opens = Vec::with_capacity(spots.len());
    for &p in &spots {
        let open = open_share_at(scene, leaf, p, OPEN_RAYS_PER_POINT, 1.0, opacity, &mut rng);
        let c = frame.cell(side, p);
        sum[c] += open;
        count[c] += 1;
        opens.push(open);
    }
    let mean = opens.iter().sum::<f32>() / spots.len() as f32;
    let cells: Vec<f32> = sum
        .iter()
        .zip(&count)
        .map(|(s, &c)| if c > 0 { s / c as f32 } else { mean })
        .collect();
    let (mut seen_open, mut seen_map, mut seen) = ([0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
    for (&p, &open) in spots.iter().zip(&opens) {
        let in_map = cells[frame.cell(side, p)];
        for j in 0..8 {
            let v = scene.transmittance(p, direction_in_octant(j, &mut rng), leaf as u32, opacity);
            seen_open[j] += open * v;
            seen_map[j] += in_map * v;
            seen[j] += v;
        }
    }
    OpenMap {
        mean,
        frame,
        side,
        cells,
        gains: std::array::from_fn(|j| {
            if seen[j] > 0.0 && mean > 0.0 {
                (seen_open[j] / seen[j] / mean).clamp(GAIN_RANGE.0, GAIN_RANGE.1)
            } else {
                1.0
            }
        }),
        residual: std::array::from_fn(|j| {
            if seen_map[j] > 0.0 {
                (seen_open[j] / seen_map[j]).clamp(GAIN_RANGE.0, GAIN_RANGE.1)
            } else {
                1.0
            }
        }),
    }
}

/// A map of 3 × 3 cells ([`STORED_SIDE`]) as a bake stores it and the leaf shaders read it:
/// each cell's gain over the leaf's mean ([`quantize_cell_gain`]) and the grid's two axes
/// ([`encode_axis`]); the grid's centre is the leaf's centroid and its half side the leaf's
/// radius, which every leaf vertex carries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StoredOpenMap {
    /// Each cell's code, row by row (all 0: no map, every gain 1).
    pub cells: [u8; 9],
    /// The grid's two axes.
    pub axes: [[u8; 2]; 2],
}

impl StoredOpenMap {
    /// `map` as stored, where it is a map of [`STORED_SIDE`] cells a side (else none).
    pub fn of(map: &OpenMap) -> Self {
        if map.side != STORED_SIDE || map.cells.len() != 9 || map.mean.is_nan() || map.mean <= 0.0 {
            return Self::default();
        }
        Self {
            cells: std::array::from_fn(|c| quantize_cell_gain(map.cells[c] / map.mean)),
            axes: [encode_axis(map.frame.axes.0), encode_axis(map.frame.axes.1)],
        }
    }

    /// The gain at the point `offset` from the leaf's centroid of a leaf of radius `radius`,
    /// as the leaf shaders read it: 1 without a map.
    pub fn gain_at(&self, offset: Vec3, radius: f32) -> f32 {
        if self.cells == [0; 9] {
            return 1.0;
        }
        let r = if radius > 1e-6 { radius } else { 1e-6 };
        let index = |axis: [u8; 2]| {
            let x = (offset.dot(decode_axis(axis)) / r + 1.0) * 0.5 * STORED_SIDE as f32;
            (x.floor() as i64).clamp(0, STORED_SIDE as i64 - 1) as usize
        };
        cell_gain_of(self.cells[index(self.axes[1]) * STORED_SIDE as usize + index(self.axes[0])])
    }
}

/// A leaf's map as a bake stores it: the map ([`StoredOpenMap`]) and its residual gains per
/// octant of the eye, quantised as the seen part's gains ([`quantize_gain`]). The sky the eye
/// sees at a point of the leaf is the leaf's mean sky times [`LeafOpenMap::sky_gain`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LeafOpenMap {
    /// The cells and the grid's axes (all cells 0: no map).
    pub map: StoredOpenMap,
    /// The residual gains, indexed as [`super::bins::DIRECTIONS`].
    pub residual: [u16; 8],
}

impl LeafOpenMap {
    /// `map` as stored: none where it is not a map of [`STORED_SIDE`] cells a side.
    pub fn of(map: &OpenMap) -> Self {
        let stored = StoredOpenMap::of(map);
        if stored == StoredOpenMap::default() {
            return Self::default();
        }
        Self {
            map: stored,
            residual: map.residual.map(quantize_gain),
        }
    }

    /// Whether the leaf has a map (else its sky takes the seen part's eight gains).
    pub fn is_map(&self) -> bool {
        self.map.cells != [0; 9]
    }

    /// The residual gains as stored.
    pub fn residual_gains(&self) -> [f32; 8] {
        self.residual.map(gain_of)
    }

    /// The gain on the leaf's mean sky at the point `offset` from the leaf's centroid (a leaf
    /// of radius `radius`) seen from direction `to_eye`: the cell's gain times the residual
    /// gains blended towards the eye ([`seen_gain`]), as the leaf shaders take them (the
    /// blend at the vertex, the cell at the pixel); 1 without a map.
    pub fn sky_gain(&self, offset: Vec3, radius: f32, to_eye: Vec3) -> f32 {
        if !self.is_map() {
            return 1.0;
        }
        self.map.gain_at(offset, radius) * seen_gain(&self.residual_gains(), to_eye)
    }

    /// The bytes a bake file holds ([`LEAF_OPEN_MAP_BYTES`]): the residual gains little-endian,
    /// the cells, the axes.
    pub fn to_bytes(&self) -> [u8; LEAF_OPEN_MAP_BYTES] {
        let mut out = [0u8; LEAF_OPEN_MAP_BYTES];
        for (j, g) in self.residual.iter().enumerate() {
            out[2 * j..2 * j + 2].copy_from_slice(&g.to_le_bytes());
        }
        out[16..25].copy_from_slice(&self.map.cells);
        out[25..27].copy_from_slice(&self.map.axes[0]);
        out[27..29].copy_from_slice(&self.map.axes[1]);
        out
    }

    /// [`LeafOpenMap::to_bytes`]' inverse.
    pub fn from_bytes(b: &[u8; LEAF_OPEN_MAP_BYTES]) -> Self {
        Self {
            map: StoredOpenMap {
                cells: std::array::from_fn(|c| b[16 + c]),
                axes: [[b[25], b[26]], [b[27], b[28]]],
            },
            residual: std::array::from_fn(|j| u16::from_le_bytes([b[2 * j], b[2 * j + 1]])),
        }
    }

    /// The eight words the leaf shaders read: the residual gains two a word (octant `2k` in
    /// the low half of word `k`), then the bytes from the cells on, four a word, low byte
    /// first (cells 0–8, the axes' four bytes, three of padding).
    pub fn words(&self) -> [u32; 8] {
        let b = self.to_bytes();
        let mut padded = [0u8; 32];
        padded[..LEAF_OPEN_MAP_BYTES].copy_from_slice(&b);
        std::array::from_fn(|k| {
            if k < 4 {
                self.residual[2 * k] as u32 | (self.residual[2 * k + 1] as u32) << 16
            } else {
                let i = 16 + 4 * (k - 4);
                u32::from_le_bytes([padded[i], padded[i + 1], padded[i + 2], padded[i + 3]])
            }
        })
    }
}

/// Each of `leaves`' stored map ([`LeafOpenMap`]) of [`STORED_SIDE`] cells a side from about
/// `points` points, its grid on the square `frames(leaf)` gives it ([`MapFrame::of_leaf`],
/// where the leaf shaders find it); `threads` workers (0: one).
pub fn open_maps_of(
    scene: &LeafScene,
    leaves: &[u32],
    frames: &(impl Fn(usize) -> MapFrame + Sync),
    points: u32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    seed: u64,
    threads: usize,
) -> Vec<LeafOpenMap> {
    // The seeds `tree_lighting_error --open-maps` measures with (`image_error`).
    let base = 0x09E2_u64 ^ seed.wrapping_mul(0xD1B5_4A32_D192_ED03);
    let indexed: Vec<(usize, u32)> = leaves.iter().copied().enumerate().collect();
    super::par_map(&indexed, threads, |&(i, leaf)| {
        let seed = base ^ scene.leaf_key(leaf as usize);
        let map = open_map(
            scene,
            leaf as usize,
            Some(frames(i)),
            STORED_SIDE,
            points,
            opacity,
            seed,
        );
        LeafOpenMap::of(&map)
    })
}

/// Steps of a stored cell gain's logarithm: codes 1–255 span `log2` over [`GAIN_RANGE`]
/// ([−2, 2], each step 1.1 % of the gain; 1 is code 128 exactly); code 0 is no map.
const CELL_LOG2_STEPS: f32 = 254.0;

/// A cell's gain as a bake stores it: its base-2 logarithm within [`GAIN_RANGE`] in 254 steps,
/// codes 1–255; not finite: 1.
pub fn quantize_cell_gain(gain: f32) -> u8 {
    let g = if gain.is_finite() { gain } else { 1.0 };
    let (lo, hi) = (GAIN_RANGE.0.log2(), GAIN_RANGE.1.log2());
    let x = (g.clamp(GAIN_RANGE.0, GAIN_RANGE.1).log2() - lo) / (hi - lo);
    1 + (x * CELL_LOG2_STEPS).round() as u8
}

/// The gain a stored cell code holds ([`quantize_cell_gain`]'s inverse; 0: 1).
pub fn cell_gain_of(q: u8) -> f32 {
    if q == 0 {
        return 1.0;
    }
    let (lo, hi) = (GAIN_RANGE.0.log2(), GAIN_RANGE.1.log2());
    (lo + (q - 1) as f32 / CELL_LOG2_STEPS * (hi - lo)).exp2()
}

/// A unit vector in two bytes, octahedral (the sphere folded onto a square): `x, y` over
/// `|x| + |y| + |z|`, the lower half folded over the diagonals, each in 255ths of [−1, 1].
/// A zero component counts as positive (as the shaders' `select` does).
pub fn encode_axis(v: Vec3) -> [u8; 2] {
    let sign = |x: f32| if x >= 0.0 { 1.0 } else { -1.0 };
    let v = v.normalize_or(Vec3::X);
    let p = v / (v.x.abs() + v.y.abs() + v.z.abs());
    let (x, y) = if p.z < 0.0 {
        ((1.0 - p.y.abs()) * sign(p.x), (1.0 - p.x.abs()) * sign(p.y))
    } else {
        (p.x, p.y)
    };
    let byte = |t: f32| ((t.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u8;
    [byte(x), byte(y)]
}

/// The unit vector two bytes hold ([`encode_axis`]'s inverse, within its rounding).
pub fn decode_axis(q: [u8; 2]) -> Vec3 {
    let sign = |x: f32| if x >= 0.0 { 1.0 } else { -1.0 };
    let (x, y) = (
        q[0] as f32 / 255.0 * 2.0 - 1.0,
        q[1] as f32 / 255.0 * 2.0 - 1.0,
    );
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 {
        ((1.0 - y.abs()) * sign(x), (1.0 - x.abs()) * sign(y))
    } else {
        (x, y)
    };
    Vec3::new(x, y, z).normalize_or(Vec3::X)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::bins::DIRECTIONS;
    use crate::lighting::path_trace::push_square_leaf;
    use crate::lighting::seen_part::tests::leaf_under_a_roof;
    use crate::pruning::leaves::LeafSet;

    /// The roof over the leaf's −x half, in an open-share map of 4 × 4 cells: the cells of the
    /// open half read above the leaf's mean and those under the roof below it, and what the
    /// map leaves for the eye's direction is little — from below, where the whole leaf is in
    /// view, exactly nothing.
    #[test]
    fn an_open_share_map_keeps_which_part_of_the_leaf_is_open() {
        let scene = LeafScene::new(&leaf_under_a_roof());
        let map = open_map(&scene, 0, None, 4, 256, &|_| 1.0, 5);
        assert_eq!(map.cells.len(), 16);
        // Open half ≈ 0.95 (less near the roof's edge), covered half 0.5: mean ≈ 0.7.
        assert!((0.64..0.78).contains(&map.mean), "{}", map.mean);
        let open_side = map.gain_at(Vec3::new(0.4, 0.0, 0.1));
        let covered = map.gain_at(Vec3::new(-0.4, 0.0, -0.2));
        assert!(open_side > 1.25, "{open_side}");
        assert!((0.6..0.8).contains(&covered), "{covered}");
        for (j, d) in DIRECTIONS.iter().enumerate() {
            let r = map.residual[j];
            if d.y > 0.0 {
                // From above only the open half shows, and the map already knows it is open.
                assert!((0.95..1.12).contains(&r), "octant {j}: {:?}", map.residual);
            } else {
                assert!((r - 1.0).abs() < 1e-4, "octant {j}: {:?}", map.residual);
            }
        }
        // From straight above, at the open half: the seen part's gain, as traced along the
        // eye's direction (1.2–1.45 in `seen_part`'s test of the same roof).
        let above = map.gain_towards(Vec3::new(0.4, 0.0, 0.1), Vec3::Y);
        assert!((1.25..1.5).contains(&above), "{above}");
        // A lone leaf: every cell its mean; nothing to leave for the eye.
        let mut lone = LeafSet::default();
        push_square_leaf(
            &mut lone,
            Vec3::ZERO,
            0.1,
            Vec3::new(0.2, 0.5, 1.0).normalize(),
        );
        let lone = LeafScene::new(&lone);
        let map = open_map(&lone, 0, None, 3, 36, &|_| 1.0, 2);
        assert!((map.mean - 1.0).abs() < 1e-6);
        assert!(map.cells.iter().all(|c| (c - 1.0).abs() < 1e-6));
        assert_eq!(map.residual, [1.0; 8]);
        assert_eq!(map.gain_towards(Vec3::new(0.05, 0.0, 0.0), Vec3::X), 1.0);
        // A leaf that is not there: no change.
        assert_eq!(
            open_map(&lone, 3, None, 3, 36, &|_| 1.0, 2).gain_at(Vec3::ZERO),
            1.0
        );
    }

    /// The roofed leaf's scene, and its centroid, radius and square as its vertices give them
    /// ([`MapFrame::of_leaf`]).
    fn roof_square() -> (LeafScene, Vec3, f32, MapFrame) {
        let leaves = leaf_under_a_roof();
        let scene = LeafScene::new(&leaves);
        let centroid = leaves.centroid(0);
        let radius = leaves
            .leaf_vertices(0)
            .into_iter()
            .map(|v| (leaves.positions[v as usize] - centroid).length())
            .fold(0.0f32, f32::max);
        let frame = MapFrame::of_leaf(centroid, scene.normal(0), radius);
        (scene, centroid, radius, frame)
    }

    /// The map as stored reads the cells the map was binned on, at every point of the leaf,
    /// within the codes' rounding; without cells it is no map.
    #[test]
    fn a_stored_map_reads_the_cells_it_was_binned_on() {
        let (scene, centroid, radius, frame) = roof_square();
        let map = open_map(&scene, 0, Some(frame), STORED_SIDE, 144, &|_| 1.0, 4);
        let stored = StoredOpenMap::of(&map);
        let mut rng = SplitMix64::new(8);
        let mut spread = (f32::MAX, f32::MIN);
        for _ in 0..500 {
            let p = scene.point_on(0, &mut rng);
            let (want, got) = (map.gain_at(p), stored.gain_at(p - centroid, radius));
            assert!(
                (got / want - 1.0).abs() < 0.006,
                "{got} against {want} at {p}"
            );
            spread = (spread.0.min(got), spread.1.max(got));
        }
        // The open half and the covered half differ: the read is not one cell.
        assert!(spread.1 > 1.2 && spread.0 < 0.8, "{spread:?}");
        assert_eq!(StoredOpenMap::default().gain_at(Vec3::X, 1.0), 1.0);
        // Another side of cells is not stored.
        let four = open_map(&scene, 0, Some(frame), 4, 64, &|_| 1.0, 4);
        assert_eq!(StoredOpenMap::of(&four), StoredOpenMap::default());
    }

    /// What a bake stores of a leaf's map: the same map as [`open_map`] on the leaf's square,
    /// through bytes and back unchanged, laid out in the words the shaders read, and the sky's
    /// gain the cell's times the residual gains' blend.
    #[test]
    fn a_leaf_open_map_is_the_map_on_its_square_as_stored() {
        let (scene, centroid, radius, frame) = roof_square();
        let stored = open_maps_of(&scene, &[0, 1], &|_| frame, 32, &|_| 1.0, 0, 2);
        assert_eq!(stored.len(), 2);
        let m = stored[0];
        assert!(m.is_map());
        let base = 0x09E2_u64;
        let map = open_map(
            &scene,
            0,
            Some(frame),
            STORED_SIDE,
            32,
            &|_| 1.0,
            base ^ scene.leaf_key(0),
        );
        assert_eq!(m, LeafOpenMap::of(&map));
        assert_eq!(LeafOpenMap::from_bytes(&m.to_bytes()), m);
        let w = m.words();
        assert_eq!(w[1], m.residual[2] as u32 | (m.residual[3] as u32) << 16);
        assert_eq!(
            w[5],
            u32::from_le_bytes(m.map.cells[4..8].try_into().unwrap())
        );
        assert_eq!(w[6] & 0xff, m.map.cells[8] as u32);
        assert_eq!(
            (w[6] >> 8) & 0xffff,
            u16::from_le_bytes(m.map.axes[0]) as u32
        );
        assert_eq!(w[6] >> 24, m.map.axes[1][0] as u32);
        assert_eq!(w[7], m.map.axes[1][1] as u32);
        let (at, to_eye) = (
            Vec3::new(0.4, 0.0, 0.1),
            Vec3::new(0.2, 1.0, 0.3).normalize(),
        );
        let want = m.map.gain_at(at - centroid, radius) * seen_gain(&m.residual_gains(), to_eye);
        assert_eq!(m.sky_gain(at - centroid, radius, to_eye), want);
        // The open half reads brighter than the covered one.
        let covered = m.sky_gain(Vec3::new(-0.4, 0.0, -0.2) - centroid, radius, to_eye);
        assert!(want > 1.2 && covered < 0.9, "{want} {covered}");
        // A leaf that is not there has no map, and no map is no change.
        let none = open_maps_of(&scene, &[7], &|_| frame, 32, &|_| 1.0, 0, 1);
        assert!(!none[0].is_map());
        assert_eq!(none[0].words(), [0; 8]);
        assert_eq!(LeafOpenMap::default().sky_gain(Vec3::X, 1.0, Vec3::Y), 1.0);
    }

    #[test]
    fn cell_gains_and_axes_round_trip() {
        for g in [0.25f32, 0.5, 0.93, 1.0, 1.07, 2.2, 4.0] {
            let back = cell_gain_of(quantize_cell_gain(g));
            assert!((back / g - 1.0).abs() < 0.006, "{g}: {back}");
        }
        assert_eq!(quantize_cell_gain(1.0), 128);
        assert_eq!(cell_gain_of(128), 1.0);
        assert_eq!(quantize_cell_gain(f32::NAN), 128);
        assert_eq!(quantize_cell_gain(100.0), 255);
        assert_eq!(quantize_cell_gain(0.0), 1);
        let mut rng = SplitMix64::new(3);
        for _ in 0..2000 {
            let v = super::super::leaf_scene::uniform_direction(&mut rng);
            let q = encode_axis(v);
            let back = decode_axis(q);
            // Two bytes: within about a degree and a half; and stable once rounded (on the
            // fold two codes may hold one vector).
            assert!(back.dot(v) > 0.9996, "{v} -> {back}");
            assert!((back.length() - 1.0).abs() < 1e-5);
            let again = decode_axis(encode_axis(back));
            assert!((again - back).length() < 1e-5, "{v}: {back} -> {again}");
        }
        for v in [Vec3::X, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z] {
            assert!(decode_axis(encode_axis(v)).dot(v) > 0.9999, "{v}");
        }
    }
}
