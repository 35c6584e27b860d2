//! The bake (Gumbau 2011, §3.3, F1 steps 1–4): leaf set in, [`BakedFoliage`] out.
//!
//! 1. Cell cloud: OBB tree over the leaves ([`super::cells`]), as many cells as the leaf count
//!    calls for ([`CellCount`]).
//! 2. Cell visibility from evenly spread viewpoints ([`super::visibility`]), in parallel, through
//!    the leaf texture's alpha mask when there is one ([`bake_masked`]).
//! 3. Stochastic order: each cell's leaves shuffled with a seeded RNG (Cook & Halstead 2007), so
//!    any prefix of a cell's list is an unbiased sample of the cell.
//! 4. Per-vertex centroid offsets `e_i` (eq. 3.10) for area-preserving scaling.
//!
//! Leaves that are malformed, non-finite or degenerate are skipped and counted; a leaf set with
//! no usable leaf is an error.

use super::cells::{Obb, build_cells};
use super::extract::quantize_visibility;
use super::leaves::{LeafSet, SkippedLeaves};
use super::mask::AlphaMask;
use super::visibility::{LeafTriangle, VisibilityInput, cell_visibility, fibonacci_directions};
use crate::lighting::traced_bins::BinEstimate;
use crate::rng::SplitMix64;
use bevy::asset::Asset;
use bevy::math::{Vec2, Vec3};
use bevy::reflect::TypePath;
use std::time::{Duration, Instant};

/// The leaves per cell [`CellCount::default`] aims at. Measured on the test corpus: see
/// [`CellCount`].
pub const DEFAULT_LEAVES_PER_CELL: u32 = 32;

/// Deepest OBB tree [`CellCount::LeavesPerCell`] builds (4,096 cells).
pub const MAX_AUTO_CELL_DEPTH: u32 = 12;

/// How many cells the cell cloud has.
///
/// The thesis splits every tree into 512 cells (depth 9), for trees of 16,000 to 131,000
/// leaves: 31 to 256 leaves per cell. A cell is the unit of view-dependent LoD, and its kept
/// count is a whole number of leaves: with one or two leaves per cell (a 560-leaf tree in 512
/// cells) a cell keeps all or nothing, and the crown's visibility is resolved finer than the
/// leaves can follow. The default therefore sizes the tree to the leaves: depth
/// `round(log2(leaves / leaves_per_cell))`, so every tree gets cells of 23–45 leaves (up to
/// [`MAX_AUTO_CELL_DEPTH`]), the thesis' own Olea gets its 512 cells, and a 560-leaf tree gets
/// 16 cells of 35 leaves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellCount {
    /// About this many leaves per cell.
    LeavesPerCell(u32),
    /// A fixed OBB tree depth: `2^depth` cells (9 → 512, the thesis' value), fewer when there
    /// are fewer leaves than that.
    Depth(u32),
}

impl Default for CellCount {
    fn default() -> Self {
        Self::LeavesPerCell(DEFAULT_LEAVES_PER_CELL)
    }
}

impl CellCount {
    /// The OBB tree depth for `leaves` leaves. Never so shallow that a cell would hold 65,536
    /// leaves or more (the kept counts are 16-bit).
    pub fn depth(self, leaves: usize) -> u32 {
        let min_depth = (leaves as f64 / 65_535.0).log2().ceil().max(0.0) as u32;
        match self {
            Self::Depth(d) => d,
            Self::LeavesPerCell(per_cell) => {
                let cells = leaves as f64 / per_cell.max(1) as f64;
                let d = if cells > 1.0 {
                    cells.log2().round() as u32
                } else {
                    0
                };
                d.min(MAX_AUTO_CELL_DEPTH).max(min_depth)
            }
        }
    }
}

/// Parameters of the bake.
#[derive(Clone, Debug, PartialEq)]
pub struct BakeSettings {
    /// How many cells (by default about [`DEFAULT_LEAVES_PER_CELL`] leaves each).
    pub cells: CellCount,
    /// Number of viewpoints (16 in the thesis).
    pub views: usize,
    /// Raster resolution of each visibility view, pixels per side.
    pub resolution: u32,
    /// Seed of the stochastic order.
    pub seed: u64,
    /// Worker threads for the visibility pass (0 = all cores).
    pub threads: usize,
    /// How the tree lighting's bins are estimated (§5.6): traced through the leaves by default.
    pub bins: BinEstimate,
    /// Points per leaf for the gains from a leaf's mean light to the part of it the eye sees
    /// ([`crate::lighting::seen_part`]); 0 leaves every gain at 1 (the thesis' model as it is).
    pub seen_points: u32,
    /// Points per leaf for its map of the open share across it
    /// ([`crate::lighting::open_map`]): what the eye sees of the leaf's sky read where the eye
    /// looks on the leaf, times residual gains per octant of the eye, in place of the eight
    /// gains on the sky; 0 stores none (the sky takes the eight gains). Where the bake traces
    /// through the leaves.
    pub open_map_points: u32,
    /// Rays per leaf for the bounce gathered from the leaf's own neighbours
    /// ([`crate::lighting::gathered_bounce`]): per leaf and face, for fourteen suns, the ratio
    /// of the gathered bounce to eq. 5.24's; 0 stores none (eq. 5.24 as it is). Where the bake
    /// traces through the leaves.
    pub bounce_rays: u32,
    /// Leaves whose gathers make each leaf's bounce ratios: the leaf and its nearest
    /// neighbours, a ratio of their sums
    /// ([`crate::lighting::gathered_bounce::pooled_ratios`]); 0 or 1, the leaf's own alone
    /// (the default: pooling trades a lower error with the sun against the eye for a higher
    /// one with it from the side, [`crate::lighting::gathered_bounce::DEFAULT_BOUNCE_POOL`]).
    pub bounce_pool: usize,
    /// How the crown's hotspot is measured — how what the eye sees of the crown's sun and
    /// bounce depends on the angle between the eye and the sun ([`crate::lighting::hotspot`])
    /// — where the bake traces through the leaves (traced bins or seen-part gains);
    /// [`HotspotSettings::NONE`](crate::lighting::hotspot::HotspotSettings::NONE), or a bake
    /// that traces nothing, leaves its factors at 1.
    pub hotspot: crate::lighting::hotspot::HotspotSettings,
}

impl Default for BakeSettings {
    fn default() -> Self {
        Self {
            cells: CellCount::default(),
            views: 16,
            resolution: 256,
            seed: 0x5EED,
            threads: 0,
            bins: BinEstimate::default(),
            seen_points: crate::lighting::seen_part::DEFAULT_SEEN_POINTS,
            open_map_points: crate::lighting::open_map::DEFAULT_OPEN_MAP_POINTS,
            bounce_rays: crate::lighting::gathered_bounce::DEFAULT_BOUNCE_RAYS,
            bounce_pool: crate::lighting::gathered_bounce::DEFAULT_BOUNCE_POOL,
            hotspot: Default::default(),
        }
    }
}

/// Progress of a running bake.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakeProgress {
    /// Current stage.
    pub stage: BakeStage,
    /// Units done in this stage.
    pub done: usize,
    /// Units in this stage.
    pub total: usize,
}

/// Stages of the bake.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BakeStage {
    /// Building the OBB tree.
    Cells,
    /// Rasterising visibility views.
    Visibility,
    /// Shuffling and writing the buffers.
    Order,
    /// The crown's envelope: the light each leaf gets through its neighbours.
    Envelope,
}

/// Why a bake failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BakeError {
    /// No usable leaf (after skipping bad ones).
    NoLeaves {
        /// What was skipped.
        skipped: SkippedLeaves,
    },
    /// Settings out of range.
    Settings(String),
}

impl std::fmt::Display for BakeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoLeaves { skipped } => write!(
                f,
                "no usable leaves to bake ({} skipped: {} non-finite, {} degenerate, {} malformed)",
                skipped.total(),
                skipped.non_finite,
                skipped.degenerate,
                skipped.malformed
            ),
            Self::Settings(s) => write!(f, "invalid bake settings: {s}"),
        }
    }
}

impl std::error::Error for BakeError {}

/// Timing of a bake, per stage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BakeTimings {
    /// OBB tree.
    pub cells: Duration,
    /// Visibility views.
    pub visibility: Duration,
    /// Shuffle and buffers.
    pub order: Duration,
    /// The crown's envelope for the tree lighting (§5.6 of Boulanger 2008).
    pub envelope: Duration,
}

impl BakeTimings {
    /// Total bake time.
    pub fn total(&self) -> Duration {
        self.cells + self.visibility + self.order + self.envelope
    }
}

/// The baked pruning data of one tree type: everything the GPU pass and the leaf material read.
/// A Bevy asset (`*.foliage` files load into it).
#[derive(Asset, TypePath, Clone, Debug, PartialEq)]
pub struct BakedFoliage {
    /// Viewpoint directions (tree → viewer, model space).
    pub view_directions: Vec<Vec3>,
    /// `cells + 1` entries: cell `c` holds stored leaves `cell_first_leaf[c]..cell_first_leaf[c + 1]`.
    pub cell_first_leaf: Vec<u32>,
    /// Box of each cell.
    pub cell_boxes: Vec<Obb>,
    /// `vis[cell * views + view]`, quantised to `u16` (eq. 3.1).
    pub visibility: Vec<u16>,
    /// `leaves + 1` entries: stored leaf `l` owns `indices[leaf_index_start[l]..leaf_index_start[l + 1]]`.
    pub leaf_index_start: Vec<u32>,
    /// Leaf triangles in stored order: cell by cell, stochastic within a cell.
    pub indices: Vec<u32>,
    /// Vertex positions (model space), in first-use order of the stored leaves.
    pub positions: Vec<Vec3>,
    /// Vertex normals.
    pub normals: Vec<Vec3>,
    /// Vertex texture coordinates.
    pub uvs: Vec<Vec2>,
    /// Per-vertex offset from its leaf's centroid, `e_i` (eq. 3.10).
    pub centroid_offsets: Vec<Vec3>,
    /// Per stored leaf, the light let through by its neighbours in each of the eight
    /// directions of [`DIRECTIONS`](crate::lighting::envelope::DIRECTIONS) (Boulanger 2008,
    /// §5.6; [`crate::lighting::envelope`]), quantised to `u16` (65,535 = all of it).
    pub leaf_light: Vec<[u16; 8]>,
    /// Per stored leaf, the gains from its mean light to the part of it the eye sees from each
    /// of the eight octants ([`crate::lighting::seen_part`]), quantised by
    /// [`quantize_gain`](crate::lighting::seen_part::quantize_gain); empty: all 1.
    pub leaf_seen: Vec<[u16; 8]>,
    /// Per stored leaf, its map of the open share across it with its residual gains
    /// ([`crate::lighting::open_map::LeafOpenMap`]), which the sky takes in place of the
    /// seen-part gains; empty: none.
    pub leaf_open: Vec<crate::lighting::open_map::LeafOpenMap>,
    /// Per stored leaf, its bounce ratios: the bounce gathered from its neighbours over eq.
    /// 5.24's, per face and sun direction ([`crate::lighting::gathered_bounce`]), as
    /// [`BounceRatios::quantized`](crate::lighting::gathered_bounce::BounceRatios::quantized)
    /// stores them; empty: eq. 5.24 alone.
    pub leaf_bounce: Vec<[u8; crate::lighting::gathered_bounce::STORED_RATIOS]>,
    /// The crown's hotspot: factors on the sun's term and the bounce by the angle between the
    /// eye and the sun ([`crate::lighting::hotspot`]), as stored (quantised); all 1 when not
    /// measured.
    pub hotspot: crate::lighting::hotspot::Hotspot,
    /// The crown's fitted extinction τ per unit of model space (eq. 5.5; 0 for a crown with no
    /// leaf behind another): `s_max(P, ω_j) = −ln(a_j) / τ`.
    pub extinction: f32,
    /// The share of each leaf's area that stops light, as the bake traced the leaves with (the
    /// leaf texture's opaque share, 1 for solid leaves): what a re-gather of the bounce while
    /// an app runs traces them with ([`crate::lighting::bounce_ring`]).
    pub leaf_opacity: f32,
    /// Leaves skipped as unusable.
    pub skipped: SkippedLeaves,
}

impl BakedFoliage {
    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.cell_first_leaf.len().saturating_sub(1)
    }

    /// Whether every leaf is a quad stored as the two triangles `a b c, a c d` (the procedural
    /// trees' leaves, and quads from most exporters): such trees are drawn with indexed quad slot
    /// meshes, four vertex-stage runs per leaf instead of six.
    pub fn quad_leaves(&self) -> bool {
        self.leaf_count() > 0
            && (0..self.leaf_count()).all(|l| {
                let (a, b) = (
                    self.leaf_index_start[l] as usize,
                    self.leaf_index_start[l + 1] as usize,
                );
                let i = &self.indices[a..b];
                i.len() == 6
                    && i[3] == i[0]
                    && i[4] == i[2]
                    && i[0] != i[1]
                    && i[1] != i[2]
                    && i[2] != i[0]
                    && i[5] != i[0]
                    && i[5] != i[1]
                    && i[5] != i[2]
            })
    }

    /// Number of leaves.
    pub fn leaf_count(&self) -> usize {
        self.leaf_index_start.len().saturating_sub(1)
    }

    /// The stored leaves as a scene to cast rays through, leaf `l` the stored leaf `l`, its
    /// normal that of its first triangle as the bake takes it: what lighting re-gathered while
    /// an app runs traces ([`crate::lighting::gathered_bounce::sun_ratios_of`]). A triangle
    /// whose indices fall outside the vertices is left out.
    pub fn leaf_scene(&self) -> crate::lighting::leaf_scene::LeafScene {
        let mut triangles = Vec::with_capacity(self.indices.len() / 3);
        let mut leaf_of = Vec::with_capacity(self.indices.len() / 3);
        let mut normals = Vec::with_capacity(self.leaf_count());
        for (leaf, range) in self.leaf_index_start.windows(2).enumerate() {
            let range = range[0] as usize..(range[1] as usize).min(self.indices.len());
            let first = triangles.len();
            for t in self.indices.get(range).unwrap_or(&[]).chunks_exact(3) {
                let corner = |i: u32| self.positions.get(i as usize).copied();
                if let (Some(a), Some(b), Some(c)) = (corner(t[0]), corner(t[1]), corner(t[2])) {
                    triangles.push([a, b, c]);
                    leaf_of.push(leaf as u32);
                }
            }
            normals.push(
                triangles
                    .get(first)
                    .and_then(|[a, b, c]| (*b - *a).cross(*c - *a).try_normalize())
                    .unwrap_or(Vec3::Y),
            );
        }
        crate::lighting::leaf_scene::LeafScene::from_triangles(triangles, leaf_of, normals)
    }

    /// Per stored leaf, its eight seen-part gains read back as stored
    /// ([`crate::lighting::seen_part::gain_of`]); empty for a bake without them (or with them
    /// for another number of leaves).
    pub fn leaf_seen_gains(&self) -> Vec<[f32; 8]> {
        if self.leaf_seen.len() != self.leaf_count() {
            return Vec::new();
        }
        self.leaf_seen
            .iter()
            .map(|g| g.map(crate::lighting::seen_part::gain_of))
            .collect()
    }

    /// Per stored leaf, its open map as stored; empty for a bake without them (or with them for
    /// another number of leaves).
    pub fn leaf_open_maps(&self) -> &[crate::lighting::open_map::LeafOpenMap] {
        if self.leaf_open.len() != self.leaf_count() {
            return &[];
        }
        &self.leaf_open
    }

    /// Per stored leaf, the centroid of its vertices as the leaf shaders have it (a vertex's
    /// position less its `centroid_offsets`); the origin for a leaf without vertices.
    pub fn leaf_centroids(&self) -> Vec<Vec3> {
        (0..self.leaf_count())
            .map(|leaf| {
                let start = self.leaf_index_start[leaf] as usize;
                match self.indices.get(start) {
                    Some(&v) if start < self.leaf_index_start[leaf + 1] as usize => {
                        self.positions[v as usize] - self.centroid_offsets[v as usize]
                    }
                    _ => Vec3::ZERO,
                }
            })
            .collect()
    }

    /// Per stored leaf, its radius as the leaf shaders have it: its farthest vertex from its
    /// vertices' centroid (`centroid_offsets`); 0 for a leaf without vertices.
    pub fn leaf_radii(&self) -> Vec<f32> {
        let mut corners: Vec<u32> = Vec::new();
        (0..self.leaf_count())
            .map(|leaf| {
                let start = self.leaf_index_start[leaf] as usize;
                let end = (self.leaf_index_start[leaf + 1] as usize).min(self.indices.len());
                corners.clear();
                corners.extend_from_slice(self.indices.get(start..end).unwrap_or(&[]));
                corners.sort_unstable();
                corners.dedup();
                corners
                    .iter()
                    .filter_map(|&v| self.centroid_offsets.get(v as usize))
                    .map(|e| e.length())
                    .fold(0.0f32, f32::max)
            })
            .collect()
    }

    /// Per stored leaf, its envelope as the leaf shaders read it from the stored attenuations
    /// and the crown's τ ([`crate::lighting::envelope::LeafEnvelope::from_stored`]); a leaf the
    /// bake stored none for lets all light through.
    pub fn leaf_envelopes(&self) -> Vec<crate::lighting::envelope::LeafEnvelope> {
        (0..self.leaf_count())
            .map(|leaf| {
                crate::lighting::envelope::LeafEnvelope::from_stored(
                    self.leaf_light.get(leaf).unwrap_or(&[u16::MAX; 8]),
                    self.extinction,
                )
            })
            .collect()
    }

    /// Number of viewpoints.
    pub fn view_count(&self) -> usize {
        self.view_directions.len()
    }

    /// Input of the CPU reference extraction ([`super::extract::extract_indices`]).
    pub fn pruning_input(&self) -> super::extract::PruningInput<'_> {
        super::extract::PruningInput {
            cell_first_leaf: &self.cell_first_leaf,
            leaf_index_start: &self.leaf_index_start,
            indices: &self.indices,
            visibility: &self.visibility,
            views: self.view_count(),
        }
    }

    /// Bytes the GPU holds for this tree type: the packed leaf vertices, the stored index
    /// list, per-leaf index starts, per-cell leaf starts and visibility, and each leaf's
    /// light (attenuations, seen-part gains, bounce ratios and their ring, the ring's sunlit
    /// shares and their slopes, the open map; `store::LEAF_LIGHT_WORDS`).
    pub fn gpu_bytes(&self) -> usize {
        // 16 words a vertex and 48 a leaf (`store::LEAF_VERTEX_WORDS`, `LEAF_LIGHT_WORDS`).
        self.positions.len() * 16 * 4
            + self.indices.len() * 4
            + self.leaf_index_start.len() * 4
            + self.cell_first_leaf.len() * 4
            + self.visibility.len() * 2
            + self.leaf_count() * 48 * 4
    }
}

impl BakedFoliage {
    /// Centre of the crown in model space: the centre of the leaves' bounding box.
    pub fn crown_center(&self) -> Vec3 {
        let (lo, hi) = self
            .positions
            .iter()
            .filter(|p| p.is_finite())
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            });
        if lo.is_finite() {
            (lo + hi) * 0.5
        } else {
            Vec3::ZERO
        }
    }

    /// Radius, about [`crown_center`](Self::crown_center), of the sphere holding every leaf:
    /// the crown's bounding sphere, whose projected diameter is the crown's screen size.
    pub fn crown_radius(&self) -> f32 {
        let c = self.crown_center();
        self.positions
            .iter()
            .filter(|p| p.is_finite())
            .map(|p| p.distance(c))
            .fold(0.0, f32::max)
    }
}

/// Bakes `leaves` as opaque leaves. `progress` is called as work completes (from worker
/// threads too).
pub fn bake(
    leaves: &LeafSet,
    settings: &BakeSettings,
    progress: &(dyn Fn(BakeProgress) + Sync),
) -> Result<(BakedFoliage, BakeTimings), BakeError> {
    bake_masked(leaves, None, settings, progress)
}

/// Bakes `leaves` whose texture has the alpha mask `mask` (the leaf material's texture and
/// cutoff): the visibility pass draws only their opaque texels, as the material does.
pub fn bake_masked(
    leaves: &LeafSet,
    mask: Option<&AlphaMask>,
    settings: &BakeSettings,
    progress: &(dyn Fn(BakeProgress) + Sync),
) -> Result<(BakedFoliage, BakeTimings), BakeError> {
    if let CellCount::Depth(d) = settings.cells
        && d > 16
    {
        return Err(BakeError::Settings(format!("cell depth {d} > 16")));
    }
    if settings.cells == CellCount::LeavesPerCell(0) {
        return Err(BakeError::Settings("0 leaves per cell".into()));
    }
    if settings.views == 0 || settings.views > 256 {
        return Err(BakeError::Settings(format!(
            "views {} not in 1..=256",
            settings.views
        )));
    }
    if !(8..=4096).contains(&settings.resolution) {
        return Err(BakeError::Settings(format!(
            "resolution {} not in 8..=4096",
            settings.resolution
        )));
    }
    settings.bins.checked().map_err(BakeError::Settings)?;
    if settings.seen_points > crate::lighting::seen_part::MAX_SEEN_POINTS {
        return Err(BakeError::Settings(format!(
            "seen_points {} not in 0..={}",
            settings.seen_points,
            crate::lighting::seen_part::MAX_SEEN_POINTS
        )));
    }
    if settings.open_map_points > crate::lighting::seen_part::MAX_SEEN_POINTS {
        return Err(BakeError::Settings(format!(
            "open_map_points {} not in 0..={}",
            settings.open_map_points,
            crate::lighting::seen_part::MAX_SEEN_POINTS
        )));
    }
    if settings.bounce_rays > crate::lighting::gathered_bounce::MAX_BOUNCE_RAYS {
        return Err(BakeError::Settings(format!(
            "bounce_rays {} not in 0..={}",
            settings.bounce_rays,
            crate::lighting::gathered_bounce::MAX_BOUNCE_RAYS
        )));
    }
    if settings.bounce_pool > crate::lighting::gathered_bounce::MAX_BOUNCE_POOL {
        return Err(BakeError::Settings(format!(
            "bounce_pool {} not in 0..={}",
            settings.bounce_pool,
            crate::lighting::gathered_bounce::MAX_BOUNCE_POOL
        )));
    }
    settings.hotspot.checked().map_err(BakeError::Settings)?;
    let (leaves, skipped) = leaves.sanitized();
    if leaves.is_empty() {
        return Err(BakeError::NoLeaves { skipped });
    }
    let mut timings = BakeTimings::default();

    // 1. Cell cloud.
    let t = Instant::now();
    progress(BakeProgress {
        stage: BakeStage::Cells,
        done: 0,
        total: 1,
    });
    let centroids: Vec<Vec3> = (0..leaves.len()).map(|i| leaves.centroid(i)).collect();
    let cells = build_cells(&centroids, settings.cells.depth(leaves.len()), |i| {
        leaves
            .leaf_vertices(i as usize)
            .into_iter()
            .map(|v| leaves.positions[v as usize])
    });
    if let Some(big) = cells.iter().find(|c| c.leaves.len() >= 1 << 16) {
        return Err(BakeError::Settings(format!(
            "a cell holds {} leaves (at most 65535): use more cells",
            big.leaves.len()
        )));
    }
    progress(BakeProgress {
        stage: BakeStage::Cells,
        done: 1,
        total: 1,
    });
    timings.cells = t.elapsed();

    // 3. Stochastic order (before visibility so triangles are gathered once per cell).
    let t = Instant::now();
    let mut stored_leaves: Vec<u32> = Vec::with_capacity(leaves.len());
    let mut cell_first_leaf = Vec::with_capacity(cells.len() + 1);
    for (c, cell) in cells.iter().enumerate() {
        cell_first_leaf.push(stored_leaves.len() as u32);
        let mut order = cell.leaves.clone();
        SplitMix64::new(settings.seed ^ (c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
            .shuffle(&mut order);
        stored_leaves.extend(order);
    }
    cell_first_leaf.push(stored_leaves.len() as u32);

    // Vertex arrays in first-use order of the stored leaves; indices remapped.
    let offsets_all = leaves.centroid_offsets();
    let mut remap = vec![u32::MAX; leaves.positions.len()];
    let mut baked = BakedFoliage {
        view_directions: fibonacci_directions(settings.views),
        cell_first_leaf,
        cell_boxes: cells.iter().map(|c| c.obb).collect(),
        visibility: Vec::new(),
        leaf_index_start: Vec::with_capacity(leaves.len() + 1),
        indices: Vec::with_capacity(leaves.indices.len()),
        positions: Vec::new(),
        normals: Vec::new(),
        uvs: Vec::new(),
        centroid_offsets: Vec::new(),
        leaf_light: Vec::new(),
        leaf_seen: Vec::new(),
        leaf_open: Vec::new(),
        leaf_bounce: Vec::new(),
        hotspot: Default::default(),
        extinction: 0.0,
        leaf_opacity: 1.0,
        skipped,
    };
    for &leaf in &stored_leaves {
        baked.leaf_index_start.push(baked.indices.len() as u32);
        let range = leaves.leaves[leaf as usize].clone();
        for &v in &leaves.indices[range.start as usize..range.end as usize] {
            let v = v as usize;
            if remap[v] == u32::MAX {
                remap[v] = baked.positions.len() as u32;
                baked.positions.push(leaves.positions[v]);
                baked
                    .normals
                    .push(leaves.normals.get(v).copied().unwrap_or(Vec3::Y));
                baked
                    .uvs
                    .push(leaves.uvs.get(v).copied().unwrap_or(Vec2::ZERO));
                baked.centroid_offsets.push(offsets_all[v]);
            }
            baked.indices.push(remap[v]);
        }
    }
    baked.leaf_index_start.push(baked.indices.len() as u32);
    timings.order = t.elapsed();
    progress(BakeProgress {
        stage: BakeStage::Order,
        done: 1,
        total: 1,
    });

    // 2. Visibility.
    let t = Instant::now();
    let cell_triangles: Vec<Vec<LeafTriangle>> = cells
        .iter()
        .map(|cell| {
            cell.leaves
                .iter()
                .flat_map(|&l| {
                    let range = leaves.leaves[l as usize].clone();
                    leaves.indices[range.start as usize..range.end as usize]
                        .chunks_exact(3)
                        .map(|t| LeafTriangle {
                            positions: [0, 1, 2].map(|k| leaves.positions[t[k] as usize]),
                            uvs: [0, 1, 2].map(|k| {
                                leaves.uvs.get(t[k] as usize).copied().unwrap_or(Vec2::ZERO)
                            }),
                        })
                })
                .collect()
        })
        .collect();
    let (lo, hi) = leaves
        .positions
        .iter()
        .zip(0..)
        .filter(|(_, i)| remap[*i] != u32::MAX)
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), (p, _)| {
            (lo.min(*p), hi.max(*p))
        });
    let center = (lo + hi) * 0.5;
    let radius = ((hi - lo) * 0.5).length().max(1e-4) * 1.01;
    let threads = if settings.threads == 0 {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    } else {
        settings.threads
    };
    let views = baked.view_directions.clone();
    let vis = cell_visibility(
        &VisibilityInput {
            cell_triangles: &cell_triangles,
            mask,
            center,
            radius,
            resolution: settings.resolution,
        },
        &views,
        threads,
        &|done| {
            progress(BakeProgress {
                stage: BakeStage::Visibility,
                done,
                total: views.len(),
            })
        },
    );
    baked.visibility = vis.into_iter().map(quantize_visibility).collect();
    timings.visibility = t.elapsed();

    // 4. The crown's envelope for the tree lighting, in stored order; a textured leaf counts
    // with its texture's opaque area.
    let t = Instant::now();
    progress(BakeProgress {
        stage: BakeStage::Envelope,
        done: 0,
        total: stored_leaves.len(),
    });
    let opaque = mask
        .and_then(|m| m.opaque_fraction_of(&leaves))
        .unwrap_or(1.0);
    // Kept in (0, 1] (a texture with no opaque texel still stops a little light).
    baked.leaf_opacity = if opaque.is_nan() {
        1.0
    } else {
        opaque.clamp(1.0 / 65536.0, 1.0)
    };
    let all = crate::lighting::envelope::proxies(&leaves);
    let stored: Vec<_> = stored_leaves
        .iter()
        .map(|&l| {
            let mut proxy = all[l as usize];
            proxy.area *= opaque;
            proxy
        })
        .collect();
    let needs_scene = settings.seen_points > 0
        || settings.bounce_rays > 0
        || matches!(settings.bins, BinEstimate::Traced { .. });
    // The scene of the leaves as stored, the one a loaded bake gives ([`BakedFoliage::leaf_scene`]),
    // and every per-leaf estimate below seeded by the leaf itself (`LeafScene::leaf_key`): the
    // same bake's leaves, loaded, trace and gather the very rays the bake did (a sun's bounce
    // ratios gathered again at load time are the stored ones where the sun is one the bake
    // gathered for).
    let scene = needs_scene.then(|| baked.leaf_scene());
    let in_scene: Vec<u32> = (0..stored_leaves.len() as u32).collect();
    let envelope = match (settings.bins, &scene) {
        (BinEstimate::Traced { rays_per_bin }, Some(scene)) => {
            crate::lighting::traced_bins::crown_envelope_traced(
                &stored,
                scene,
                &in_scene,
                &|_| opaque,
                rays_per_bin,
                threads,
                &|done| {
                    progress(BakeProgress {
                        stage: BakeStage::Envelope,
                        done,
                        total: stored.len(),
                    })
                },
            )
        }
        _ => crate::lighting::envelope::crown_envelope(&stored, threads),
    };
    baked.leaf_light = envelope
        .leaves
        .iter()
        .map(|e| e.attenuation.map(crate::lighting::envelope::quantize_light))
        .collect();
    baked.extinction = envelope.tau;
    if let (Some(scene), true) = (&scene, settings.seen_points > 0) {
        use crate::lighting::seen_part::{quantize_gain, seen_part_gains_of};
        baked.leaf_seen = seen_part_gains_of(
            scene,
            &in_scene,
            settings.seen_points,
            1.0,
            &|_| opaque,
            0,
            threads,
        )
        .into_iter()
        .map(|g| g.map(quantize_gain))
        .collect();
    }
    if let (Some(scene), true) = (&scene, settings.open_map_points > 0) {
        use crate::lighting::open_map::{MapFrame, open_maps_of};
        // Each map's grid on the square the leaf shaders find from what a leaf vertex
        // carries: the leaf's centroid and radius as stored, the leaf's own normal.
        let (centroids, radii) = (baked.leaf_centroids(), baked.leaf_radii());
        baked.leaf_open = open_maps_of(
            scene,
            &in_scene,
            &|i| MapFrame::of_leaf(centroids[i], scene.normal(i), radii[i]),
            settings.open_map_points,
            &|_| opaque,
            0,
            threads,
        );
    }
    // The leaves' optics the gathered ratios and the hotspot are measured with: the settings'
    // default (both are ratios, unchanged by the base colour that scales the optics).
    let optics = crate::lighting::settings::TreeLightingSettings::default().optics;
    if let (Some(scene), true) = (&scene, settings.bounce_rays > 0) {
        use crate::lighting::gathered_bounce::bounce_ratios_of;
        baked.leaf_bounce = bounce_ratios_of(
            scene,
            &optics,
            &in_scene,
            &envelope.leaves,
            envelope.tau,
            settings.bounce_rays,
            settings.bounce_pool,
            &|_| opaque,
            threads,
        )
        .iter()
        .map(|r| r.quantized())
        .collect();
    }
    if let Some(scene) = &scene {
        use crate::lighting::gathered_bounce::BounceRatios;
        use crate::lighting::hotspot::crown_hotspot;
        use crate::lighting::seen_part::gain_of;
        // What the shaders read: the stored gains and ratios.
        let gains: Vec<[f32; 8]> = baked.leaf_seen.iter().map(|g| g.map(gain_of)).collect();
        let ratios: Vec<BounceRatios> = baked
            .leaf_bounce
            .iter()
            .map(BounceRatios::from_stored)
            .collect();
        baked.hotspot = crown_hotspot(
            scene,
            &envelope,
            &gains,
            &ratios,
            &|l| Some(l as usize),
            &optics,
            &|_| opaque,
            &settings.hotspot,
            threads,
        )
        .sanitized()
        .0;
    }
    progress(BakeProgress {
        stage: BakeStage::Envelope,
        done: stored_leaves.len(),
        total: stored_leaves.len(),
    });
    timings.envelope = t.elapsed();
    Ok((baked, timings))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pruning::procedural::{TreeSpecies, generate};

    fn small_bake() -> BakedFoliage {
        let tree = generate(&TreeSpecies::olea().with_leaf_count(2000));
        let settings = BakeSettings {
            cells: CellCount::Depth(6),
            resolution: 96,
            ..default()
        };
        bake(&tree.leaves, &settings, &|_| {}).unwrap().0
    }

    use bevy::prelude::default;

    /// The bake's leaf light is the crown envelope of its leaves in stored order (the bins
    /// traced through them): each stored leaf's eight values, its seen-part gains, open map and
    /// bounce ratios are those of the leaf at that place, traced in a scene built here from the
    /// stored triangles (the same rays: each leaf's are seeded by the leaf itself) — exactly, so
    /// that a bake loaded from its file can trace and gather them again.
    #[test]
    fn the_leaf_light_follows_the_stored_order() {
        use crate::lighting::envelope::{LeafProxy, quantize_light};
        use crate::lighting::leaf_scene::LeafScene;
        use crate::lighting::traced_bins::{DEFAULT_RAYS_PER_BIN, crown_envelope_traced};
        let mut triangles = Vec::new();
        let mut leaf_of = Vec::new();
        let b = small_bake();
        assert_eq!(b.leaf_light.len(), b.leaf_count());
        assert!(b.extinction > 0.0);
        let proxies: Vec<LeafProxy> = (0..b.leaf_count())
            .map(|l| {
                let range = b.leaf_index_start[l] as usize..b.leaf_index_start[l + 1] as usize;
                let tris: Vec<[Vec3; 3]> = b.indices[range]
                    .chunks_exact(3)
                    .map(|t| {
                        t.iter()
                            .map(|&i| b.positions[i as usize])
                            .collect::<Vec<_>>()
                    })
                    .map(|v| [v[0], v[1], v[2]])
                    .collect();
                for t in &tris {
                    triangles.push(*t);
                    leaf_of.push(l as u32);
                }
                let mut unique: Vec<u32> = b.indices
                    [b.leaf_index_start[l] as usize..b.leaf_index_start[l + 1] as usize]
                    .to_vec();
                unique.sort();
                unique.dedup();
                let centre = unique
                    .iter()
                    .map(|&i| b.positions[i as usize])
                    .sum::<Vec3>()
                    / unique.len() as f32;
                let [a, b2, c] = tris[0];
                LeafProxy {
                    centre,
                    normal: (b2 - a).cross(c - a).normalize(),
                    area: tris
                        .iter()
                        .map(|[a, b, c]| 0.5 * (*b - *a).cross(*c - *a).length())
                        .sum(),
                }
            })
            .collect();
        let normals = proxies.iter().map(|p| p.normal).collect();
        let scene = LeafScene::from_triangles(triangles, leaf_of, normals);
        let order: Vec<u32> = (0..proxies.len() as u32).collect();
        let envelope = crown_envelope_traced(
            &proxies,
            &scene,
            &order,
            &|_| 1.0,
            DEFAULT_RAYS_PER_BIN,
            2,
            &|_| {},
        );
        // Traced in the stored leaves' scene, each leaf seeded by itself: the very
        // rays the bake traced.
        let mut off = 0;
        for (stored, e) in b.leaf_light.iter().zip(&envelope.leaves) {
            for (&q, &a) in stored.iter().zip(&e.attenuation) {
                off += (q != quantize_light(a)) as usize;
            }
        }
        assert_eq!(off, 0, "{off} of {} values differ", b.leaf_count() * 8);
        assert!((envelope.tau - b.extinction).abs() < 1e-5 * b.extinction);

        // The seen-part gains likewise: each stored leaf's are those of the leaf at that place,
        // the same random points and all.
        use crate::lighting::seen_part::{DEFAULT_SEEN_POINTS, quantize_gain, seen_part_gains_of};
        assert_eq!(b.leaf_seen.len(), b.leaf_count());
        let want = seen_part_gains_of(&scene, &order, DEFAULT_SEEN_POINTS, 1.0, &|_| 1.0, 0, 2);
        let same = b
            .leaf_seen
            .iter()
            .zip(&want)
            .filter(|(stored, want)| **stored == want.map(quantize_gain))
            .count();
        assert_eq!(same, b.leaf_count());
        // The open maps likewise, each on the square the shaders find from the stored leaf's
        // vertices.
        use crate::lighting::open_map::{DEFAULT_OPEN_MAP_POINTS, MapFrame, open_maps_of};
        let (centroids, radii) = (b.leaf_centroids(), b.leaf_radii());
        let want_maps = open_maps_of(
            &scene,
            &order,
            &|i| MapFrame::of_leaf(centroids[i], scene.normal(i), radii[i]),
            DEFAULT_OPEN_MAP_POINTS,
            &|_| 1.0,
            0,
            2,
        );
        assert_eq!(b.leaf_open_maps(), want_maps.as_slice());
        assert!(want_maps.iter().filter(|m| m.is_map()).count() * 10 >= b.leaf_count() * 9);
        // The part in view is the more open one: above 1 over the crown, from every octant.
        for j in 0..8 {
            let mean = want.iter().map(|g| g[j]).sum::<f32>() / want.len() as f32;
            assert!(mean > 1.02, "octant {j}: {mean}");
        }

        // The bounce ratios: those the leaf at that place gathers by the same rays (its own
        // seed) against the same envelope.
        use crate::lighting::gathered_bounce::{
            DEFAULT_BOUNCE_POOL, DEFAULT_BOUNCE_RAYS, bounce_ratios_of, ratio_of,
        };
        assert_eq!(b.leaf_bounce.len(), b.leaf_count());
        let optics = crate::lighting::settings::TreeLightingSettings::default().optics;
        let want = bounce_ratios_of(
            &scene,
            &optics,
            &order,
            &envelope.leaves,
            envelope.tau,
            DEFAULT_BOUNCE_RAYS,
            DEFAULT_BOUNCE_POOL,
            &|_| 1.0,
            2,
        );
        let (mut same, mut moved) = (0, 0);
        for (stored, want) in b.leaf_bounce.iter().zip(&want) {
            let want = want.quantized();
            same += stored.iter().zip(&want).filter(|(s, w)| s == w).count();
            moved += want
                .iter()
                .filter(|&&w| (ratio_of(w) - 1.0).abs() > 0.1)
                .count();
        }
        let values = b.leaf_count() * 28;
        assert_eq!(same, values, "{same} of {values} ratios as wanted");
        // And they are not eq. 5.24's all-1: a real crown's neighbours differ from its model.
        assert!(
            moved * 2 >= values,
            "only {moved} of {values} ratios away from 1"
        );
    }

    /// A loaded bake holds what re-gathering its ratios needs: its leaves as a scene and its
    /// envelopes read back give, for each basis sun, the ratios the bake stored, leaf by leaf
    /// (the bake gathered in that scene, with the same rays).
    #[test]
    fn a_loaded_bake_regathers_the_ratios_it_stored() {
        use crate::lighting::gathered_bounce::{
            DEFAULT_BOUNCE_RAYS, SUN_BASIS, quantize_ratio, sun_ratios_of,
        };
        let b = small_bake();
        let scene = b.leaf_scene();
        assert_eq!(scene.leaf_count(), b.leaf_count());
        for leaf in (0..b.leaf_count()).step_by(37) {
            let range = b.leaf_index_start[leaf] as usize..b.leaf_index_start[leaf + 1] as usize;
            let corners: Vec<Vec3> = b.indices[range]
                .chunks_exact(3)
                .flat_map(|t| t.iter().map(|&i| b.positions[i as usize]))
                .collect();
            assert_eq!(scene.triangle_count(leaf) as usize, corners.len() / 3);
            let n = (corners[1] - corners[0])
                .cross(corners[2] - corners[0])
                .normalize();
            assert!(scene.normal(leaf).dot(n) > 0.9999, "leaf {leaf}");
        }
        let envelopes = b.leaf_envelopes();
        assert_eq!(envelopes.len(), b.leaf_count());
        for (e, q) in envelopes.iter().zip(&b.leaf_light) {
            for (j, &stored) in q.iter().enumerate() {
                let a = stored as f32 / 65535.0;
                assert!((e.attenuation[j] - a).abs() < 1e-6);
                assert!(((-b.extinction * e.s_max[j]).exp() - a.max(1.0 / 65535.0)).abs() < 1e-4);
            }
        }
        let optics = crate::lighting::settings::TreeLightingSettings::default().optics;
        let all: Vec<u32> = (0..b.leaf_count() as u32).collect();
        for k in [1, 6, 10, 11] {
            let again = sun_ratios_of(
                &scene,
                &optics,
                &all,
                &envelopes,
                b.extinction,
                &[SUN_BASIS[k]],
                DEFAULT_BOUNCE_RAYS,
                &|_| 1.0,
                2,
            );
            for face in 0..2 {
                // The bake's rays again (its scene was this one, each leaf seeded by itself),
                // against the envelope as stored where the bake's was unrounded: each
                // byte the one stored, or one step off where the rounding of the attenuations
                // carries a ratio over a step's edge (measured: 1,998 to 2,000 of 2,000 the
                // stored byte; with the bake seeded by each leaf's index in the source, 975 of 2,000).
                let (mut same, mut near) = (0, 0);
                for (r, stored) in again.iter().zip(&b.leaf_bounce) {
                    let got = quantize_ratio(r[0][face]) as i32;
                    let stored = stored[14 * face + k] as i32;
                    same += (got == stored) as usize;
                    near += ((got - stored).abs() <= 1) as usize;
                }
                let n = b.leaf_count();
                assert_eq!(near, n, "sun {k} face {face}: {near} of {n} within a step");
                assert!(
                    same * 200 >= n * 199,
                    "sun {k} face {face}: {same} of {n} the stored byte"
                );
            }
        }
        // A malformed bake (an index past the vertices) leaves that triangle out, no panic.
        let mut broken = b.clone();
        broken.indices[0] = u32::MAX;
        let scene = broken.leaf_scene();
        assert_eq!(
            scene.triangle_count(0) as usize,
            b.leaf_index_start[1] as usize / 3 - 1
        );
    }

    /// With no rays for the bounce ratios, the bake stores none (eq. 5.24 as the thesis has
    /// it); an absurd count is refused.
    #[test]
    fn bounce_ratios_can_be_left_out() {
        let tree = generate(&TreeSpecies::olea().with_leaf_count(300));
        let settings = BakeSettings {
            cells: CellCount::Depth(3),
            resolution: 32,
            bounce_rays: 0,
            ..default()
        };
        let (baked, _) = bake(&tree.leaves, &settings, &|_| {}).unwrap();
        assert!(baked.leaf_bounce.is_empty());
        assert!(!baked.leaf_seen.is_empty());
        let absurd_pool = BakeSettings {
            bounce_pool: usize::MAX,
            ..settings.clone()
        };
        assert!(matches!(
            bake(&tree.leaves, &absurd_pool, &|_| {}),
            Err(BakeError::Settings(_))
        ));
        let absurd = BakeSettings {
            bounce_rays: u32::MAX,
            ..settings
        };
        assert!(matches!(
            bake(&tree.leaves, &absurd, &|_| {}),
            Err(BakeError::Settings(_))
        ));
    }

    /// With no points for the seen-part gains, the bake stores none (the leaves' mean light as
    /// the thesis has it); an absurd count is refused.
    #[test]
    fn seen_part_gains_can_be_left_out() {
        let tree = generate(&TreeSpecies::olea().with_leaf_count(300));
        let settings = BakeSettings {
            cells: CellCount::Depth(3),
            resolution: 32,
            seen_points: 0,
            ..default()
        };
        assert!(
            bake(&tree.leaves, &settings, &|_| {})
                .unwrap()
                .0
                .leaf_seen
                .is_empty()
        );
        let absurd = BakeSettings {
            seen_points: u32::MAX,
            ..settings
        };
        assert!(matches!(
            bake(&tree.leaves, &absurd, &|_| {}),
            Err(BakeError::Settings(_))
        ));
    }

    /// With no points for the open maps, the bake stores none (the sky takes the eight gains);
    /// an absurd count is refused.
    #[test]
    fn open_maps_can_be_left_out() {
        let tree = generate(&TreeSpecies::olea().with_leaf_count(300));
        let settings = BakeSettings {
            cells: CellCount::Depth(3),
            resolution: 32,
            open_map_points: 0,
            ..default()
        };
        let baked = bake(&tree.leaves, &settings, &|_| {}).unwrap().0;
        assert!(baked.leaf_open.is_empty() && !baked.leaf_seen.is_empty());
        let absurd = BakeSettings {
            open_map_points: u32::MAX,
            ..settings
        };
        assert!(matches!(
            bake(&tree.leaves, &absurd, &|_| {}),
            Err(BakeError::Settings(_))
        ));
    }

    /// The crown's hotspot is measured in a bake (the olive's sun exponent below 1 with the sun
    /// behind the eye, above 1 facing it), left at 1 with no measurement, and an absurd
    /// measurement is refused.
    #[test]
    fn the_hotspot_is_baked_or_left_out() {
        use crate::lighting::hotspot::{Hotspot, HotspotSettings};
        let tree = generate(&TreeSpecies::olea().with_leaf_count(600));
        let settings = BakeSettings {
            cells: CellCount::Depth(3),
            resolution: 32,
            ..default()
        };
        let h = bake(&tree.leaves, &settings, &|_| {}).unwrap().0.hotspot;
        assert!(h.sun[0] < 0.9 && h.sun[7] > 1.05, "{h:?}");
        assert_eq!(h.sanitized(), (h, false));
        let none = BakeSettings {
            hotspot: HotspotSettings::NONE,
            ..settings.clone()
        };
        assert_eq!(
            bake(&tree.leaves, &none, &|_| {}).unwrap().0.hotspot,
            Hotspot::default()
        );
        let absurd = BakeSettings {
            hotspot: HotspotSettings {
                eye_rays: u32::MAX,
                ..HotspotSettings::default()
            },
            ..settings
        };
        assert!(matches!(
            bake(&tree.leaves, &absurd, &|_| {}),
            Err(BakeError::Settings(_))
        ));
    }

    #[test]
    fn bake_is_consistent() {
        let b = small_bake();
        assert_eq!(b.cell_count(), 64);
        assert_eq!(b.leaf_count(), 2000);
        assert_eq!(b.view_count(), 16);
        assert_eq!(b.visibility.len(), 64 * 16);
        assert_eq!(
            *b.leaf_index_start.last().unwrap() as usize,
            b.indices.len()
        );
        assert_eq!(b.indices.len(), 2000 * 6);
        assert_eq!(b.positions.len(), 2000 * 4);
        assert!(b.indices.iter().all(|&i| (i as usize) < b.positions.len()));
        // Offsets are centred per leaf: the four of a quad sum to zero.
        for l in 0..b.leaf_count() {
            let s = b.leaf_index_start[l] as usize;
            let mut vs: Vec<u32> = b.indices[s..s + 6].to_vec();
            vs.sort();
            vs.dedup();
            let sum: Vec3 = vs.iter().map(|&v| b.centroid_offsets[v as usize]).sum();
            assert!(sum.length() < 1e-4);
        }
        // Deterministic.
        assert_eq!(b, small_bake());
    }

    #[test]
    fn inner_cells_are_less_visible_than_outer_cells() {
        let b = small_bake();
        let centre = TreeSpecies::olea().crown_center();
        let mean_vis = |c: usize| {
            b.visibility[c * 16..(c + 1) * 16]
                .iter()
                .map(|&v| v as f32 / 65535.0)
                .sum::<f32>()
                / 16.0
        };
        let mut by_depth: Vec<(f32, f32)> = (0..b.cell_count())
            .map(|c| ((b.cell_boxes[c].center - centre).length(), mean_vis(c)))
            .collect();
        by_depth.sort_by(|a, b| a.0.total_cmp(&b.0));
        let inner: f32 = by_depth[..16].iter().map(|x| x.1).sum::<f32>() / 16.0;
        let outer: f32 = by_depth[48..].iter().map(|x| x.1).sum::<f32>() / 16.0;
        assert!(inner < outer, "inner {inner} outer {outer}");
        assert!(by_depth.iter().all(|x| (0.0..=1.0).contains(&x.1)));
    }

    #[test]
    fn no_usable_leaves_is_an_error() {
        let mut set = LeafSet::default();
        set.push_quad([Vec3::ZERO; 4], Vec3::Y);
        let err = bake(&set, &BakeSettings::default(), &|_| {}).unwrap_err();
        assert!(matches!(err, BakeError::NoLeaves { skipped } if skipped.degenerate == 1));
        assert!(err.to_string().contains("degenerate"));
    }
}
