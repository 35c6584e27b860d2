//! Grass on curved ground (Boulanger 2008, thesis §4.2.7.2): a patch instanced on a grid cell is
//! lifted onto the ground by the bilinear patch through the cell's four corner heights (eq. 4.10)
//! — blades stay vertical, as grass does on slopes — and lit in the patch's own frame, the
//! non-orthogonal (T, N = Y, B) of the ground under it, interpolated across the cell (eq. 4.12),
//! so the light direction is brought into that frame by the inverse of eq. 4.11. Wind shears the
//! patch's volume (§4.2.7.4, after Meyer and Neyret): each corner of the cell takes a wind
//! vector from a map over the ground, and a point is pushed by their bilinear blend in proportion
//! to its height — roots stay, the tops lean, and neighbouring cells, sharing corners, lean
//! together.

use bevy::math::{Vec2, Vec3};

/// Eq. 4.10: the lift at patch coordinates `(x, z) ∈ [0, 1]²` of a cell whose corners have
/// heights `h00` (x = 0, z = 0), `h10`, `h01`, `h11`.
pub fn lift(h00: f32, h10: f32, h01: f32, h11: f32, x: f32, z: f32) -> f32 {
    (1.0 - x) * (1.0 - z) * h00 + x * (1.0 - z) * h10 + (1.0 - x) * z * h01 + x * z * h11
}

/// Eq. 4.12: the frame at `(x, z)` of a cell from its corners' tangents (along x) and binormals
/// (along z), `[00, 10, 01, 11]`: T and B bilinearly interpolated and normalised, N vertical.
pub fn frame(tangents: [Vec3; 4], binormals: [Vec3; 4], x: f32, z: f32) -> (Vec3, Vec3, Vec3) {
    let w = [(1.0 - x) * (1.0 - z), x * (1.0 - z), (1.0 - x) * z, x * z];
    let mix = |v: [Vec3; 4]| (v[0] * w[0] + v[1] * w[1] + v[2] * w[2] + v[3] * w[3]).normalize();
    (mix(tangents), Vec3::Y, mix(binormals))
}

/// Eq. 4.11: a world direction `l` in the patch frame (T, Y, B) — the solution of
/// `[T N B]·l_p = l`, by the closed form the vertical N allows. `None` where T and B are
/// parallel in the ground plane (no frame).
pub fn to_patch_frame(t: Vec3, b: Vec3, l: Vec3) -> Option<Vec3> {
    let det = b.z * t.x - b.x * t.z;
    if det.abs() < 1e-8 {
        return None;
    }
    let row0 = Vec3::new(b.z, 0.0, -b.x);
    let row1 = b.cross(t);
    let row2 = Vec3::new(-t.z, 0.0, t.x);
    Some(Vec3::new(row0.dot(l), row1.dot(l), row2.dot(l)) / det)
}

/// The wind's shear of a point at patch coordinates `(x, z) ∈ [0, 1]²`, `height` above the
/// ground in a volume `volume_height` tall, under corner winds `[00, 10, 01, 11]` (horizontal
/// displacements of the volume's top corners, m): the horizontal offset to add.
pub fn wind_shear(winds: [Vec2; 4], x: f32, z: f32, height: f32, volume_height: f32) -> Vec2 {
    let w = winds[0] * ((1.0 - x) * (1.0 - z))
        + winds[1] * (x * (1.0 - z))
        + winds[2] * ((1.0 - x) * z)
        + winds[3] * (x * z);
    let up = if volume_height > 0.0 {
        (height / volume_height).clamp(0.0, 1.0)
    } else {
        0.0
    };
    w * up
}

/// Eq. 4.11 for the lift's own frame: a world direction `l` in the undeformed patch volume, where
/// the ground under the point rises by `gradient` = (∂h/∂x, ∂h/∂z). The lift maps
/// `(x, y, z) ↦ (x, y + h(x, z), z)`; its tangents `T = (1, ∂h/∂x, 0)` and `B = (0, ∂h/∂z, 1)`
/// with the vertical `N` are the frame, and directions go back through the lift's inverse
/// Jacobian. (Eq. 4.12 normalises T and B before inverting; the unnormalised tangents are the
/// ones the deformed geometry actually has, so the slices see the light and the eye as the
/// lifted blades do.) Not normalised.
pub fn lift_to_patch(gradient: Vec2, l: Vec3) -> Vec3 {
    Vec3::new(l.x, l.y - gradient.x * l.x - gradient.y * l.z, l.z)
}

/// How far the ground's corner heights may stray from one plane for a quadtree node to count as
/// planar (m).
pub const FLAT_TOLERANCE: f32 = 0.05;

/// A macro-cell is drawn as a grid of `2^MACRO_FACET_LEVELS` facets a side, each lifted onto
/// the ground at its corners (`grass::mesh::horizontal_slice_mesh`): so a node may be a
/// macro-cell when each of those facets is planar — the thesis' flatness flag, relaxed from
/// the whole node to its facets so that rolling hills need not be split down to single blocks.
pub const MACRO_FACET_LEVELS: u8 = 3;

/// Most corner-sample steps a side of a [`GroundGrid`]: `2^10`. Larger fields sample every
/// `2^k`-th cell corner, the lift staying the bilinear patch of eq. 4.10 over those coarser
/// cells.
pub const MAX_GROUND_LEVELS: u8 = 10;

/// The ground under a field: heights (m, relative to the field's plane) at the corners of its
/// cells — every `2^stride`-th corner on fields more than `2^MAX_GROUND_LEVELS` cells across —
/// lifted between them by eq. 4.10, with the lowest and highest ground and the flatness flag of
/// every quadtree node (thesis §4.2.7.2) precomputed bottom-up.
#[derive(Clone, Debug)]
pub struct GroundGrid {
    /// World (x, z) of sample (0, 0): the cell grid's origin.
    pub origin: Vec2,
    /// Distance between samples (m): the cell side times `2^stride`.
    pub spacing: f32,
    /// Samples a side: `2^levels + 1`.
    pub samples: u32,
    levels: u8,
    heights: Vec<f32>,
    /// Per level (0: the root … `levels`: single sample quads), row-major.
    low: Vec<Vec<f32>>,
    high: Vec<Vec<f32>>,
    flat: Vec<Vec<bool>>,
    /// Per level: every descendant `MACRO_FACET_LEVELS` down (or the finest) is planar.
    facets_flat: Vec<Vec<bool>>,
}

impl GroundGrid {
    /// Samples `height` (m above the field's plane, at world (x, z)) at the corners of `grid`'s
    /// cells; non-finite heights count as 0 and are counted in the second value.
    pub fn sample(grid: &super::quadtree::CellGrid, height: impl Fn(Vec2) -> f32) -> (Self, usize) {
        let levels = grid.levels.min(MAX_GROUND_LEVELS);
        let stride = 1u32 << (grid.levels - levels);
        let spacing = grid.cell * stride as f32;
        let samples = (1u32 << levels) + 1;
        let mut bad = 0;
        let mut heights = Vec::with_capacity((samples * samples) as usize);
        for j in 0..samples {
            for i in 0..samples {
                let h = height(grid.origin + Vec2::new(i as f32, j as f32) * spacing);
                if h.is_finite() {
                    heights.push(h);
                } else {
                    bad += 1;
                    heights.push(0.0);
                }
            }
        }
        let mut ground = Self {
            origin: grid.origin,
            spacing,
            samples,
            levels,
            heights,
            low: Vec::new(),
            high: Vec::new(),
            flat: Vec::new(),
            facets_flat: Vec::new(),
        };
        ground.build_bounds();
        (ground, bad)
    }

    /// The samples, row-major (rows along z), as the shaders read them.
    pub fn heights(&self) -> &[f32] {
        &self.heights
    }

    fn at(&self, i: u32, j: u32) -> f32 {
        self.heights[(j * self.samples + i) as usize]
    }

    fn build_bounds(&mut self) {
        let n = 1usize << self.levels;
        let (mut low, mut high, mut flat) = (Vec::new(), Vec::new(), Vec::new());
        for j in 0..n as u32 {
            for i in 0..n as u32 {
                let c = [
                    self.at(i, j),
                    self.at(i + 1, j),
                    self.at(i, j + 1),
                    self.at(i + 1, j + 1),
                ];
                low.push(c.iter().copied().fold(f32::INFINITY, f32::min));
                high.push(c.iter().copied().fold(f32::NEG_INFINITY, f32::max));
                // A bilinear quad is a plane when it does not twist.
                flat.push((c[0] - c[1] - c[2] + c[3]).abs() <= FLAT_TOLERANCE);
            }
        }
        self.low = vec![low];
        self.high = vec![high];
        self.flat = vec![flat];
        for level in (0..self.levels).rev() {
            let n = 1usize << level;
            let (below_low, below_high, below_flat) = (&self.low[0], &self.high[0], &self.flat[0]);
            let child = |x: usize, z: usize| z * 2 * n + x;
            let (mut low, mut high, mut flat) = (
                Vec::with_capacity(n * n),
                Vec::with_capacity(n * n),
                Vec::with_capacity(n * n),
            );
            let step = 1u32 << (self.levels - level);
            for z in 0..n {
                for x in 0..n {
                    let kids = [
                        child(2 * x, 2 * z),
                        child(2 * x + 1, 2 * z),
                        child(2 * x, 2 * z + 1),
                        child(2 * x + 1, 2 * z + 1),
                    ];
                    low.push(
                        kids.iter()
                            .map(|&k| below_low[k])
                            .fold(f32::INFINITY, f32::min),
                    );
                    high.push(
                        kids.iter()
                            .map(|&k| below_high[k])
                            .fold(f32::NEG_INFINITY, f32::max),
                    );
                    // Four planar children are one plane when the node's nine shared samples
                    // (corners, edge midpoints, centre) are: every child has four of them.
                    let (i0, j0) = (x as u32 * step, z as u32 * step);
                    let h00 = self.at(i0, j0);
                    let (dx, dz) = (self.at(i0 + step, j0) - h00, self.at(i0, j0 + step) - h00);
                    let planar = kids.iter().all(|&k| below_flat[k])
                        && (0..3).all(|v| {
                            (0..3).all(|u| {
                                let h = self.at(i0 + u * step / 2, j0 + v * step / 2);
                                let plane = h00 + dx * u as f32 / 2.0 + dz * v as f32 / 2.0;
                                (h - plane).abs() <= FLAT_TOLERANCE
                            })
                        });
                    flat.push(planar);
                }
            }
            self.low.insert(0, low);
            self.high.insert(0, high);
            self.flat.insert(0, flat);
        }
        // Facets k levels down all planar: F_0 = planar, F_k(node) = F_{k−1} of all four
        // children; the finest levels take the finest quads' flags.
        let mut facets = self.flat.clone();
        for _ in 0..MACRO_FACET_LEVELS {
            let mut next = facets.clone();
            for level in 0..self.levels as usize {
                let n = 1usize << level;
                for z in 0..n {
                    for x in 0..n {
                        let below = &facets[level + 1];
                        let child = |dx: usize, dz: usize| below[(2 * z + dz) * 2 * n + 2 * x + dx];
                        next[level][z * n + x] =
                            child(0, 0) && child(1, 0) && child(0, 1) && child(1, 1);
                    }
                }
            }
            facets = next;
        }
        self.facets_flat = facets;
    }

    /// Eq. 4.10 over the sample grid: the bilinear patch through the four samples around world
    /// `xz` (clamped to the grid at its edges). `grass_functions.wgsl`'s `ground_height` is its
    /// GPU twin.
    pub fn height_at(&self, xz: Vec2) -> f32 {
        let (i, j, f) = self.locate(xz);
        lift(
            self.at(i, j),
            self.at(i + 1, j),
            self.at(i, j + 1),
            self.at(i + 1, j + 1),
            f.x,
            f.y,
        )
    }

    /// The slope of [`Self::height_at`] at `xz`: (∂h/∂x, ∂h/∂z).
    pub fn gradient_at(&self, xz: Vec2) -> Vec2 {
        let (i, j, f) = self.locate(xz);
        let (h00, h10, h01, h11) = (
            self.at(i, j),
            self.at(i + 1, j),
            self.at(i, j + 1),
            self.at(i + 1, j + 1),
        );
        Vec2::new(
            (1.0 - f.y) * (h10 - h00) + f.y * (h11 - h01),
            (1.0 - f.x) * (h01 - h00) + f.x * (h11 - h10),
        ) / self.spacing
    }

    fn locate(&self, xz: Vec2) -> (u32, u32, Vec2) {
        let last = (self.samples - 1) as f32;
        let t = ((xz - self.origin) / self.spacing).clamp(Vec2::ZERO, Vec2::splat(last));
        let base = t.floor().min(Vec2::splat(last - 1.0));
        (base.x as u32, base.y as u32, t - base)
    }

    /// The node's entry in the bounds pyramid: itself, or the sample quad holding it.
    fn entry(&self, node: super::quadtree::CellNode) -> (usize, usize) {
        let level = node.level.min(self.levels);
        let shift = node.level - level;
        let n = 1usize << level;
        (
            level as usize,
            (node.z >> shift) as usize * n + (node.x >> shift) as usize,
        )
    }
}

impl super::quadtree::GroundBounds for GroundGrid {
    fn height_range(
        &self,
        grid: &super::quadtree::CellGrid,
        node: super::quadtree::CellNode,
    ) -> (f32, f32) {
        let _ = grid;
        let (level, i) = self.entry(node);
        (self.low[level][i], self.high[level][i])
    }
    /// Whether the node's macro-cell facets are all planar ([`MACRO_FACET_LEVELS`]).
    fn is_flat(&self, grid: &super::quadtree::CellGrid, node: super::quadtree::CellNode) -> bool {
        let _ = grid;
        let (level, i) = self.entry(node);
        self.facets_flat[level][i]
    }
}

/// The terrain's ambient occlusion map (§4.2.6, fig. 4.17): for each of `texels` points over
/// the rectangle `[min, min + size]` (texel centres), the share of the sky its ground point sees
/// past the ground around it — `height(x, z)` marched outwards `radius` metres in 8 directions,
/// each direction's horizon elevation `θ` taking `sin θ` of the sky (horizon-based, as screen-space
/// AO does). Flat ground and crests see it all (1), hollows less. The thesis precomputes such a
/// map once and multiplies the grass's ambient light by it at each blade's root; paint external
/// occluders (rocks, tree trunks) into it as well.
pub fn ambient_occlusion_map(
    height: impl Fn(Vec2) -> f32,
    min: Vec2,
    size: Vec2,
    texels: bevy::math::UVec2,
    radius: f32,
) -> Vec<f32> {
    const DIRECTIONS: usize = 8;
    const STEPS: usize = 8;
    let texels = texels.max(bevy::math::UVec2::ONE);
    let radius = if radius.is_finite() && radius > 0.0 {
        radius
    } else {
        1.0
    };
    let mut out = Vec::with_capacity((texels.x * texels.y) as usize);
    for j in 0..texels.y {
        for i in 0..texels.x {
            let p = min + (Vec2::new(i as f32, j as f32) + 0.5) / texels.as_vec2() * size;
            let h0 = height(p);
            let mut occluded = 0.0;
            for d in 0..DIRECTIONS {
                let angle = d as f32 / DIRECTIONS as f32 * std::f32::consts::TAU;
                let dir = Vec2::new(angle.cos(), angle.sin());
                let mut slope = 0.0f32;
                for k in 1..=STEPS {
                    let s = radius * k as f32 / STEPS as f32;
                    let rise = height(p + dir * s) - h0;
                    if rise.is_finite() {
                        slope = slope.max(rise / s);
                    }
                }
                // sin of the horizon's elevation.
                occluded += slope / (1.0 + slope * slope).sqrt();
            }
            out.push((1.0 - occluded / DIRECTIONS as f32).clamp(0.0, 1.0));
        }
    }
    out
}

/// How the wind blows over the grass (§4.2.7.4): the [`WindMap`] is laid over the ground, one
/// repeat every `scale` metres, turned so that its x axis points along `direction`, and slid
/// downwind at `speed`; at each cell corner it gives the lean of the grass volume's top.
#[derive(Clone, Copy, Debug, PartialEq, bevy::reflect::Reflect)]
#[reflect(Debug, PartialEq)]
pub struct GrassWind {
    /// Where the wind blows to (x, z; normalised when used).
    pub direction: Vec2,
    /// Lean (m) of the tallest blades' tips where the map reads 1.
    pub strength: f32,
    /// How fast the gusts travel (m/s).
    pub speed: f32,
    /// Metres of ground one repeat of the map covers.
    pub scale: f32,
}

impl Default for GrassWind {
    fn default() -> Self {
        Self {
            direction: Vec2::new(1.0, 0.35),
            strength: 0.06,
            speed: 2.5,
            scale: 24.0,
        }
    }
}

impl GrassWind {
    /// These settings with unusable values replaced, and what was replaced.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let mut s = *self;
        let mut fixes = Vec::new();
        if !(s.direction.is_finite() && s.direction.length() > 1e-6) {
            fixes.push(format!(
                "wind direction {} has no direction: using +x",
                s.direction
            ));
            s.direction = Vec2::X;
        }
        for (name, v, fallback) in [
            ("wind strength", &mut s.strength, 0.0),
            ("wind speed", &mut s.speed, 0.0),
        ] {
            if !(v.is_finite() && *v >= 0.0) {
                fixes.push(format!("{name} = {v} must be at least 0: using {fallback}"));
                *v = fallback;
            }
        }
        if !(s.scale.is_finite() && s.scale > 0.0) {
            fixes.push(format!(
                "wind scale = {} must be positive: using 24",
                s.scale
            ));
            s.scale = 24.0;
        }
        (s, fixes)
    }

    /// The wind's lean at world `corner` at `time` (s), from `map`: the map read at the corner
    /// slid back upwind, turned onto the wind's direction, times the strength.
    /// `grass_functions.wgsl`'s `corner_wind` is its GPU twin.
    pub fn corner_wind(&self, map: &WindMap, corner: Vec2, time: f32) -> Vec2 {
        let dir = self.direction.normalize_or(Vec2::X);
        let m = map.sample((corner - dir * self.speed * time) / self.scale);
        (dir * m.x + dir.perp() * m.y) * self.strength
    }

    /// The horizontal offset of a point at world `xz`, `height` above the ground, in a grass
    /// volume `volume_height` tall on `grid`'s cells: [`wind_shear`] of the winds at its cell's
    /// corners. `grass_functions.wgsl`'s `wind_offset` is its GPU twin.
    pub fn offset(
        &self,
        map: &WindMap,
        grid: &super::quadtree::CellGrid,
        xz: Vec2,
        height: f32,
        volume_height: f32,
        time: f32,
    ) -> Vec2 {
        let t = (xz - grid.origin) / grid.cell;
        let base = t.floor();
        let f = t - base;
        let corner = |dx: f32, dz: f32| {
            self.corner_wind(
                map,
                grid.origin + (base + Vec2::new(dx, dz)) * grid.cell,
                time,
            )
        };
        let winds = [
            corner(0.0, 0.0),
            corner(1.0, 0.0),
            corner(0.0, 1.0),
            corner(1.0, 1.0),
        ];
        wind_shear(winds, f.x, f.y, height, volume_height)
    }
}

/// A wind map: a repeating image of wind vectors (x: along the wind, y: across it), read
/// bilinearly between texel centres.
#[derive(Clone, Debug, PartialEq)]
pub struct WindMap {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// Row-major texels.
    pub texels: Vec<Vec2>,
}

impl WindMap {
    /// Gusts: smooth repeating value noise, along the wind between 0.25 and 1 (never calm,
    /// never blowing back), across it between −0.35 and 0.35, `size` texels a side.
    pub fn gusts(size: u32, seed: u64) -> Self {
        let size = size.max(4);
        let lattice = 6u32;
        let mut rng = crate::rng::SplitMix64::new(seed);
        let along: Vec<f32> = (0..lattice * lattice).map(|_| rng.next_f32()).collect();
        let across: Vec<f32> = (0..lattice * lattice).map(|_| rng.next_f32()).collect();
        let noise = |values: &[f32], u: f32, v: f32| {
            let (x, y) = (u * lattice as f32, v * lattice as f32);
            let (i, j) = (x.floor() as u32, y.floor() as u32);
            let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
            let (fx, fy) = (smooth(x - x.floor()), smooth(y - y.floor()));
            let at = |i: u32, j: u32| values[((j % lattice) * lattice + i % lattice) as usize];
            let top = at(i, j) + (at(i + 1, j) - at(i, j)) * fx;
            let bottom = at(i, j + 1) + (at(i + 1, j + 1) - at(i, j + 1)) * fx;
            top + (bottom - top) * fy
        };
        let texels = (0..size * size)
            .map(|k| {
                let (u, v) = (
                    ((k % size) as f32 + 0.5) / size as f32,
                    ((k / size) as f32 + 0.5) / size as f32,
                );
                Vec2::new(
                    0.25 + 0.75 * noise(&along, u, v),
                    0.7 * (noise(&across, u, v) - 0.5),
                )
            })
            .collect();
        Self {
            width: size,
            height: size,
            texels,
        }
    }

    /// The map at `uv` (one repeat per unit), bilinear between texel centres, wrapping.
    pub fn sample(&self, uv: Vec2) -> Vec2 {
        let t = uv * Vec2::new(self.width as f32, self.height as f32) - 0.5;
        let base = t.floor();
        let f = t - base;
        let at = |dx: i64, dz: i64| {
            let i = (base.x as i64 + dx).rem_euclid(self.width as i64) as u32;
            let j = (base.y as i64 + dz).rem_euclid(self.height as i64) as u32;
            self.texels[(j * self.width + i) as usize]
        };
        let top = at(0, 0).lerp(at(1, 0), f.x);
        let bottom = at(0, 1).lerp(at(1, 1), f.x);
        top.lerp(bottom, f.y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    #[test]
    fn the_lift_is_the_bilinear_patch_through_the_corners() {
        assert_eq!(lift(1.0, 2.0, 3.0, 4.0, 0.0, 0.0), 1.0);
        assert_eq!(lift(1.0, 2.0, 3.0, 4.0, 1.0, 0.0), 2.0);
        assert_eq!(lift(1.0, 2.0, 3.0, 4.0, 0.0, 1.0), 3.0);
        assert_eq!(lift(1.0, 2.0, 3.0, 4.0, 1.0, 1.0), 4.0);
        assert!((lift(1.0, 2.0, 3.0, 4.0, 0.5, 0.5) - 2.5).abs() < 1e-6);
        // Shared edges agree: the right edge of one cell is the left edge of the next.
        for k in 0..=10 {
            let z = k as f32 / 10.0;
            assert_eq!(
                lift(1.0, 2.0, 3.0, 4.0, 1.0, z),
                lift(2.0, 7.0, 4.0, 9.0, 0.0, z)
            );
        }
    }

    #[test]
    fn wind_leans_the_tops_and_keeps_the_roots_and_shared_edges() {
        use bevy::math::Vec2;
        let winds = [
            Vec2::new(0.1, 0.0),
            Vec2::new(0.2, 0.05),
            Vec2::new(0.0, 0.1),
            Vec2::new(0.3, 0.3),
        ];
        assert_eq!(wind_shear(winds, 0.3, 0.7, 0.0, 0.5), Vec2::ZERO);
        assert_eq!(wind_shear(winds, 1.0, 1.0, 0.5, 0.5), winds[3]);
        assert!((wind_shear(winds, 0.0, 0.0, 0.25, 0.5) - winds[0] * 0.5).length() < 1e-6);
        // The next cell along x shares corners 10 and 11 as its 00 and 01: same shear there.
        let next = [winds[1], Vec2::new(-0.2, 0.0), winds[3], Vec2::ZERO];
        for k in 0..=8 {
            let z = k as f32 / 8.0;
            let a = wind_shear(winds, 1.0, z, 0.4, 0.5);
            let b = wind_shear(next, 0.0, z, 0.4, 0.5);
            assert!((a - b).length() < 1e-6);
        }
    }

    #[test]
    fn eq_4_11_inverts_the_non_orthogonal_frame() {
        let mut rng = SplitMix64::new(11);
        for _ in 0..2000 {
            // Slopes up to 60°: T along x rising, B along z rising.
            let t = Vec3::new(1.0, rng.range(-1.7, 1.7), rng.range(-0.3, 0.3)).normalize();
            let b = Vec3::new(rng.range(-0.3, 0.3), rng.range(-1.7, 1.7), 1.0).normalize();
            let l = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            let p = to_patch_frame(t, b, l).unwrap();
            let back = t * p.x + Vec3::Y * p.y + b * p.z;
            assert!(back.distance(l) < 1e-4, "{l} → {p} → {back}");
        }
        // On flat ground the frame is the world's.
        let p = to_patch_frame(Vec3::X, Vec3::Z, Vec3::new(0.3, 0.5, -0.2)).unwrap();
        assert!(p.distance(Vec3::new(0.3, 0.5, -0.2)) < 1e-6);
        assert_eq!(to_patch_frame(Vec3::X, Vec3::X, Vec3::Y), None);
        // Eq. 4.12: interpolated frames are continuous and unit.
        let (t, n, b) = frame(
            [
                Vec3::X,
                Vec3::new(1.0, 1.0, 0.0).normalize(),
                Vec3::X,
                Vec3::X,
            ],
            [Vec3::Z; 4],
            0.5,
            0.0,
        );
        assert!((t.length() - 1.0).abs() < 1e-6 && t.y > 0.0 && n == Vec3::Y && b == Vec3::Z);
    }

    fn relief_grid(levels: u8) -> super::super::quadtree::CellGrid {
        super::super::quadtree::CellGrid {
            origin: Vec2::new(-8.0, -8.0),
            cell: 0.5,
            levels,
        }
    }

    #[test]
    fn the_ground_grid_lifts_bounds_and_flags_its_nodes() {
        use super::super::quadtree::{CellNode, GroundBounds};
        let grid = relief_grid(5);
        // A slope everywhere, a bump over x > 4 m.
        let height =
            |p: Vec2| 0.2 * p.x - 0.1 * p.y + if p.x > 4.0 { (p.y * 0.7).sin() } else { 0.0 };
        let (ground, bad) = GroundGrid::sample(&grid, height);
        assert_eq!((bad, ground.samples, ground.spacing), (0, 33, 0.5));
        // Corners are the samples; between them eq. 4.10.
        for (i, j) in [(0u32, 0u32), (3, 7), (32, 32), (20, 5)] {
            let p = grid.origin + Vec2::new(i as f32, j as f32) * 0.5;
            assert!((ground.height_at(p) - height(p)).abs() < 1e-5);
        }
        let p = grid.origin + Vec2::new(3.25, 7.75) * 0.5;
        let corner = |di: f32, dj: f32| height(grid.origin + Vec2::new(3.0 + di, 7.0 + dj) * 0.5);
        let want = lift(
            corner(0.0, 0.0),
            corner(1.0, 0.0),
            corner(0.0, 1.0),
            corner(1.0, 1.0),
            0.25,
            0.75,
        );
        assert!((ground.height_at(p) - want).abs() < 1e-5);
        // The gradient is the lift's slope.
        let g = ground.gradient_at(p);
        let e = 1e-3;
        let fd = Vec2::new(
            ground.height_at(p + Vec2::X * e) - ground.height_at(p - Vec2::X * e),
            ground.height_at(p + Vec2::Y * e) - ground.height_at(p - Vec2::Y * e),
        ) / (2.0 * e);
        assert!((g - fd).length() < 2e-2, "{g} vs {fd}");
        // Every node's bounds hold its samples, and a flat node's samples lie in one plane.
        for level in 0..=grid.levels {
            let n = 1u32 << level;
            for z in 0..n {
                for x in 0..n {
                    let node = CellNode { level, x, z };
                    let (low, high) = ground.height_range(&grid, node);
                    let step = 1u32 << (grid.levels - level);
                    let mut seen = Vec::new();
                    for j in z * step..=(z + 1) * step {
                        for i in x * step..=(x + 1) * step {
                            seen.push(ground.at(i, j));
                        }
                    }
                    let lo = seen.iter().copied().fold(f32::INFINITY, f32::min);
                    let hi = seen.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                    assert_eq!((low, high), (lo, hi), "{node:?}");
                    if ground.is_flat(&grid, node) {
                        // Every facet of its macro-cell lies in a plane.
                        let fl = (level + MACRO_FACET_LEVELS).min(grid.levels);
                        let fstep = 1u32 << (grid.levels - fl);
                        let per = step / fstep;
                        for fz in 0..per {
                            for fx in 0..per {
                                let (i0, j0) = (x * step + fx * fstep, z * step + fz * fstep);
                                let (h00, h10, h01) = (
                                    ground.at(i0, j0),
                                    ground.at(i0 + fstep, j0),
                                    ground.at(i0, j0 + fstep),
                                );
                                for j in 0..=fstep {
                                    for i in 0..=fstep {
                                        let plane = h00
                                            + (h10 - h00) * i as f32 / fstep as f32
                                            + (h01 - h00) * j as f32 / fstep as f32;
                                        let h = ground.at(i0 + i, j0 + j);
                                        assert!(
                                            (h - plane).abs() <= 2.0 * FLAT_TOLERANCE,
                                            "{node:?}"
                                        );
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        // The slope alone is flat; the bump is not.
        let west = CellNode {
            level: 1,
            x: 0,
            z: 0,
        };
        let east = CellNode {
            level: 1,
            x: 1,
            z: 0,
        };
        assert!(ground.is_flat(&grid, west));
        assert!(!ground.is_flat(&grid, east));
        assert!(!ground.is_flat(&grid, CellNode::ROOT));
        // Non-finite heights are counted and lie at 0.
        let (_, bad) = GroundGrid::sample(&grid, |p| if p.x > 7.0 { f32::NAN } else { 0.0 });
        assert_eq!(bad, 33 * 2);
    }

    #[test]
    fn large_fields_sample_every_other_corner_and_keep_the_node_bounds() {
        use super::super::quadtree::{CellNode, GroundBounds};
        let grid = relief_grid(MAX_GROUND_LEVELS + 1);
        let (ground, _) = GroundGrid::sample(&grid, |p| p.x.abs());
        assert_eq!((ground.samples, ground.spacing), (1025, 1.0));
        // A single cell takes the bounds of the sample quad holding it.
        let cell = CellNode {
            level: grid.levels,
            x: 5,
            z: 9,
        };
        let quad = CellNode {
            level: MAX_GROUND_LEVELS,
            x: 2,
            z: 4,
        };
        assert_eq!(
            ground.height_range(&grid, cell),
            ground.height_range(&grid, quad)
        );
    }

    #[test]
    fn directions_go_back_through_the_lift() {
        let mut rng = SplitMix64::new(5);
        for _ in 0..500 {
            let g = Vec2::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
            let d = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            // The lift's Jacobian applied to a direction of the patch volume.
            let world = Vec3::new(d.x, d.y + g.x * d.x + g.y * d.z, d.z);
            assert!(lift_to_patch(g, world).distance(d) < 1e-5);
        }
        assert_eq!(
            lift_to_patch(Vec2::ZERO, Vec3::new(0.1, 0.2, 0.3)),
            Vec3::new(0.1, 0.2, 0.3)
        );
    }

    #[test]
    fn the_wind_map_wraps_and_its_gusts_travel_downwind() {
        let map = WindMap::gusts(32, 3);
        for t in &map.texels {
            assert!((0.25..=1.0).contains(&t.x) && t.y.abs() <= 0.35, "{t}");
        }
        let uv = Vec2::new(0.37, 0.81);
        assert!((map.sample(uv) - map.sample(uv + Vec2::new(1.0, -2.0))).length() < 1e-5);
        // At a texel centre, the texel.
        assert!((map.sample(Vec2::new(2.5, 7.5) / 32.0) - map.texels[7 * 32 + 2]).length() < 1e-6);
        let wind = GrassWind {
            direction: Vec2::new(3.0, 4.0),
            strength: 0.1,
            speed: 2.0,
            scale: 10.0,
        };
        let c = Vec2::new(1.5, -2.0);
        let dir = Vec2::new(0.6, 0.8);
        // What blows at c now blows 2 m/s × 1.5 s downwind 1.5 s later.
        let now = wind.corner_wind(&map, c, 4.0);
        let later = wind.corner_wind(&map, c + dir * 3.0, 5.5);
        assert!((now - later).length() < 1e-5, "{now} vs {later}");
        // Along the wind it always pushes downwind.
        for k in 0..50 {
            let w = wind.corner_wind(&map, Vec2::new(k as f32 * 0.7, k as f32 * -1.3), 0.0);
            assert!(
                w.dot(dir) >= 0.025 - 1e-6 && w.length() <= 0.1 * 1.06,
                "{w}"
            );
        }
        // Offsets: none at the roots, continuous across cells, the tops leaning downwind.
        let grid = relief_grid(4);
        let h = 0.5;
        assert_eq!(
            wind.offset(&map, &grid, Vec2::new(0.3, 0.1), 0.0, h, 0.0),
            Vec2::ZERO
        );
        let edge = grid.origin.x + 3.0 * grid.cell;
        let a = wind.offset(&map, &grid, Vec2::new(edge - 1e-4, 0.2), h, h, 0.0);
        let b = wind.offset(&map, &grid, Vec2::new(edge + 1e-4, 0.2), h, h, 0.0);
        assert!((a - b).length() < 1e-4 && a.dot(dir) > 0.0, "{a} vs {b}");
        let (fixed, fixes) = GrassWind {
            direction: Vec2::ZERO,
            strength: f32::NAN,
            speed: -1.0,
            scale: 0.0,
        }
        .sanitized();
        assert_eq!(fixes.len(), 4);
        assert_eq!(fixed.sanitized().1.len(), 0);
    }

    #[test]
    fn terrain_occlusion_darkens_hollows_and_spares_flats_and_crests() {
        use bevy::math::UVec2;
        let flat =
            ambient_occlusion_map(|_| 0.0, Vec2::ZERO, Vec2::splat(10.0), UVec2::splat(3), 4.0);
        assert!(flat.iter().all(|&a| a == 1.0));
        // A bowl: its bottom sees less sky than its rim; a hill's top sees it all.
        let bowl = |p: Vec2| 0.3 * p.length_squared();
        let ao = ambient_occlusion_map(
            bowl,
            Vec2::splat(-5.0),
            Vec2::splat(10.0),
            UVec2::splat(5),
            2.0,
        );
        let centre = ao[12];
        assert!(centre < 0.7, "{centre}");
        let hill = ambient_occlusion_map(
            |p| -bowl(p),
            Vec2::splat(-5.0),
            Vec2::splat(10.0),
            UVec2::splat(5),
            2.0,
        );
        assert_eq!(hill[12], 1.0);
        // A pit under a vertical wall all round sees almost nothing.
        let pit = ambient_occlusion_map(
            |p| if p.length() < 0.1 { 0.0 } else { 100.0 },
            Vec2::splat(-0.05),
            Vec2::splat(0.1),
            UVec2::ONE,
            1.0,
        );
        assert!(pit[0] < 0.02, "{}", pit[0]);
    }
}
