//! The clip stack of one virtual texture, as bookkeeping: layer t_0 is the base level
//! `l_b = log2 c` with its full mip chain (always resident, so every coarser level is too);
//! layers t_1… cache `c × c` windows of levels `l_b + 1 …` around the centre of detail.
//!
//! [`ClipStack::plan`] picks the subtiles to upload this frame: the coarsest incomplete layer
//! first, a layer finished before the next starts (so coarse data is always complete), rings
//! from the centre outward inside a layer, until the per-frame budget is spent.
//! [`finest_covering_layer`] is the CPU reference of the shader's layer choice.

use super::layer::{LayerState, SlotState, Subtile};

/// A per-frame update budget, in units a test can count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameBudget {
    /// At most this many subtiles per frame.
    Subtiles(u32),
    /// At most this many bytes uploaded per frame (at least one subtile always goes).
    Bytes(u64),
}

/// One subtile to upload.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SubtileUpload {
    /// Layer index in the stack (1 = the first windowed layer).
    pub layer: usize,
    /// Virtual level.
    pub level: u32,
    /// The subtile.
    pub subtile: Subtile,
}

/// The stack's bookkeeping.
#[derive(Clone, Debug)]
pub struct ClipStack {
    /// Clip size c (texels).
    pub clip_size: u32,
    /// Subtile size s (texels).
    pub subtile_size: u32,
    /// Base level l_b = log2 c.
    pub base_level: u32,
    /// Windowed layers t_1…, coarsest first (index 0 here is t_1).
    pub layers: Vec<LayerState>,
    /// Shift each level's subtile grid by a golden-ratio fraction ([`center_subtile`]); on by
    /// default, switchable to measure what it buys.
    pub grid_shift: bool,
}

impl ClipStack {
    /// A stack for a virtual texture of `levels` levels (level i is 2^i texels wide), centred on
    /// `center_uv` (virtual texture coordinates in [0, 1]).
    pub fn new(levels: u32, clip_size: u32, subtile_size: u32, center_uv: [f64; 2]) -> Self {
        let base_level = clip_size.trailing_zeros();
        let n = clip_size / subtile_size;
        let layers = (base_level + 1..levels)
            .map(|level| {
                let level_subtiles = (1i64 << level) / subtile_size as i64;
                LayerState::new(
                    level,
                    n,
                    level_subtiles,
                    center_subtile(center_uv, level, subtile_size, true),
                )
            })
            .collect();
        Self {
            clip_size,
            subtile_size,
            base_level,
            layers,
            grid_shift: true,
        }
    }

    /// The share of the stack the shader can sample: the base level (always resident here)
    /// and, per windowed layer, the part of its window inside its coverage rectangle (the
    /// largest fully valid ring). Never more than [`quality`](Self::quality), the share of
    /// valid slots: one invalid subtile near a layer's centre costs it little slot share but
    /// all of its usable coverage.
    pub fn usable_coverage(&self) -> f64 {
        let mut sum = 1.0;
        let s = self.subtile_size as i64;
        for (layer, coverage) in self.layers.iter().zip(self.coverage()) {
            let (min, max) = layer.window();
            let window = ((max[0] - min[0]) * s) as f64 * ((max[1] - min[1]) * s) as f64;
            let covered = coverage.map_or(0.0, |(lo, hi)| {
                ((hi[0] - lo[0]).max(0) as f64) * ((hi[1] - lo[1]).max(0) as f64)
            });
            sum += if window > 0.0 { covered / window } else { 1.0 };
        }
        sum / (self.layers.len() as f64 + 1.0)
    }

    /// Moves the centre of detail; returns the subtiles invalidated over all layers.
    pub fn recenter(&mut self, center_uv: [f64; 2]) -> u32 {
        let s = self.subtile_size;
        self.layers
            .iter_mut()
            .map(|l| l.recenter(center_subtile(center_uv, l.level, s, self.grid_shift)))
            .sum()
    }

    /// The subtiles to upload this frame, in order, marked pending. `bytes_per_subtile` prices a
    /// subtile for a byte budget.
    pub fn plan(&mut self, budget: FrameBudget, bytes_per_subtile: u64) -> Vec<SubtileUpload> {
        let mut out = Vec::new();
        let mut bytes = 0u64;
        for (i, layer) in self.layers.iter_mut().enumerate() {
            let todo = layer.invalid_in_ring_order();
            for subtile in todo {
                let fits = match budget {
                    FrameBudget::Subtiles(n) => (out.len() as u32) < n,
                    FrameBudget::Bytes(b) => out.is_empty() || bytes + bytes_per_subtile <= b,
                };
                if !fits {
                    return out;
                }
                layer.set_state(subtile, SlotState::Pending);
                bytes += bytes_per_subtile;
                out.push(SubtileUpload {
                    layer: i + 1,
                    level: layer.level,
                    subtile,
                });
            }
            // A layer is finished before the next starts: pending subtiles still hold it.
            if !layer.complete() {
                return out;
            }
        }
        out
    }

    /// Like [`plan`](Self::plan), for subtiles whose data may not be at hand: `available` says
    /// whether an upload's data is ready (e.g. its tile is in RAM); unavailable subtiles are
    /// skipped (they stay invalid and wait), the rest of the layer goes on. Chosen uploads are
    /// marked valid at once (the caller uploads them this frame). At most `max` uploads.
    pub fn plan_available(
        &mut self,
        max: u32,
        mut available: impl FnMut(&SubtileUpload) -> bool,
    ) -> Vec<SubtileUpload> {
        let mut out = Vec::new();
        for (i, layer) in self.layers.iter_mut().enumerate() {
            for subtile in layer.invalid_in_ring_order() {
                let upload = SubtileUpload {
                    layer: i + 1,
                    level: layer.level,
                    subtile,
                };
                if available(&upload) {
                    if out.len() as u32 == max {
                        return out;
                    }
                    layer.set_state(subtile, SlotState::Valid);
                    out.push(upload);
                }
            }
            if !layer.complete() {
                break;
            }
        }
        out
    }

    /// Records that an upload arrived (dropped if its slot moved on meanwhile).
    pub fn uploaded(&mut self, upload: SubtileUpload) -> bool {
        self.layers[upload.layer - 1].set_state(upload.subtile, SlotState::Valid)
    }

    /// Records that an upload failed: the subtile is invalid again (retried by a later plan).
    pub fn failed(&mut self, upload: SubtileUpload) {
        self.layers[upload.layer - 1].set_state(upload.subtile, SlotState::Invalid);
    }

    /// Fraction of the whole stack's slots that are valid (the paper's "quality"; the base layer
    /// counts as valid).
    pub fn quality(&self) -> f32 {
        let n = self.layers.len() as f32 + 1.0;
        (1.0 + self.layers.iter().map(|l| l.valid_fraction()).sum::<f32>()) / n
    }

    /// Per windowed layer, the valid level texels around the centre (for the shader).
    pub fn coverage(&self) -> Vec<Option<([i64; 2], [i64; 2])>> {
        self.layers
            .iter()
            .map(|l| l.coverage_texels(self.subtile_size))
            .collect()
    }
}

/// The centre subtile of level `level`'s window for virtual coordinates `uv`, computed in f64
/// (2^20 texels and more exceed f32 precision).
///
/// Each level's subtile grid is shifted by `frac(level · 0.618…)` of a subtile (a golden-ratio
/// sequence) before rounding. Without it, subtile boundaries of every level nest in the finer
/// levels', so whenever the centre crosses a boundary of one level it crosses one in every finer
/// level in the same frame, and several layers invalidate a strip at once — the dips of the
/// paper's minimum quality. Shifted, the crossings of different levels fall on different frames.
pub fn center_subtile(uv: [f64; 2], level: u32, subtile_size: u32, shifted: bool) -> Subtile {
    let texels = (1u64 << level) as f64;
    let s = subtile_size as f64;
    let shift = if shifted {
        (level as f64 * 0.618_033_988_749_895).fract()
    } else {
        0.0
    };
    [
        (uv[0] * texels / s + shift).floor() as i64,
        (uv[1] * texels / s + shift).floor() as i64,
    ]
}

/// The tile holding `upload`'s subtile. The stacks keep subtiles no larger than tiles
/// (`ClipStackTexture` clamps them); a larger one is given the tile of its first texel rather
/// than dividing by zero.
pub fn tile_of(upload: &SubtileUpload, tile_size: u32, subtile_size: u32) -> crate::cache::TileKey {
    let tile = |subtile: i64| (subtile * subtile_size as i64).div_euclid(tile_size.max(1) as i64);
    crate::cache::TileKey {
        z: upload.level - tile_size.trailing_zeros(),
        x: tile(upload.subtile[0]) as u32,
        y: tile(upload.subtile[1]) as u32,
    }
}

/// CPU reference of the shader's no-data fill (`clipmap.wgsl`): a sampled texel (linear RGBA,
/// transparent texels black — padding, missing tiles) over the no-data colour, opaque;
/// `None` outside the texture's `[0, 1)²` gives the no-data colour itself.
pub fn over_no_data(texel: Option<[f32; 4]>, no_data: [f32; 3]) -> [f32; 4] {
    match texel {
        Some([r, g, b, a]) => [
            r + (1.0 - a) * no_data[0],
            g + (1.0 - a) * no_data[1],
            b + (1.0 - a) * no_data[2],
            1.0,
        ],
        None => [no_data[0], no_data[1], no_data[2], 1.0],
    }
}

/// CPU reference of the shader's choice: the finest windowed layer whose coverage holds virtual
/// coordinates `uv`, as `(layer index, level, level texel)`; layer 0 (the base level, always
/// resident) otherwise.
pub fn finest_covering_layer(stack: &ClipStack, uv: [f64; 2]) -> (usize, u32, [i64; 2]) {
    let coverage = stack.coverage();
    for (i, layer) in stack.layers.iter().enumerate().rev() {
        let texels = (1u64 << layer.level) as f64;
        let t = [
            (uv[0] * texels).floor() as i64,
            (uv[1] * texels).floor() as i64,
        ];
        if let Some((min, max)) = coverage[i]
            && (0..2).all(|k| t[k] >= min[k] && t[k] < max[k])
        {
            return (i + 1, layer.level, t);
        }
    }
    let texels = (1u64 << stack.base_level) as f64;
    (
        0,
        stack.base_level,
        [
            (uv[0] * texels).floor() as i64,
            (uv[1] * texels).floor() as i64,
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stack() -> ClipStack {
        // 16 levels, clip 1024 (base level 10), subtile 128: layers for levels 11..=15.
        ClipStack::new(16, 1024, 128, [0.3, 0.7])
    }

    #[test]
    fn a_subtile_maps_to_its_tile_whatever_their_sizes() {
        let upload = |subtile: [i64; 2]| SubtileUpload {
            layer: 1,
            level: 12,
            subtile,
        };
        // 128-texel subtiles in 512-texel tiles: four per tile.
        let key = tile_of(&upload([9, 3]), 512, 128);
        assert_eq!((key.z, key.x, key.y), (3, 2, 0));
        // A subtile larger than the tiles (128 over 64): the tile of its first texel, no
        // division by zero.
        let key = tile_of(&upload([5, 1]), 64, 128);
        assert_eq!((key.z, key.x, key.y), (6, 10, 2));
    }

    #[test]
    fn layers_above_the_base_level_each_hold_an_n_by_n_window() {
        let s = stack();
        assert_eq!(s.base_level, 10);
        assert_eq!(
            s.layers.iter().map(|l| l.level).collect::<Vec<_>>(),
            vec![11, 12, 13, 14, 15]
        );
        assert!(s.layers.iter().all(|l| l.slots().len() == 64));
        assert_eq!(s.quality(), 1.0 / 6.0);
    }

    #[test]
    fn plans_coarsest_layer_first_and_finish_it_before_the_next() {
        let mut s = stack();
        let first = s.plan(FrameBudget::Subtiles(40), 0);
        assert_eq!(first.len(), 40);
        assert!(first.iter().all(|u| u.layer == 1));
        // The first layer's remaining 24 come next, and nothing of layer 2 while layer 1 has
        // pending subtiles.
        let second = s.plan(FrameBudget::Subtiles(40), 0);
        assert_eq!(second.len(), 24);
        assert!(second.iter().all(|u| u.layer == 1));
        for u in first.iter().chain(&second) {
            assert!(s.uploaded(*u));
        }
        let third = s.plan(FrameBudget::Subtiles(10), 0);
        assert!(third.iter().all(|u| u.layer == 2));
        // Pending subtiles do not count as valid.
        assert!((s.quality() - 2.0 / 6.0).abs() < 1e-6);
        for u in &third {
            s.uploaded(*u);
        }
        assert!((s.quality() - (2.0 + 10.0 / 64.0) / 6.0).abs() < 1e-6);
    }

    #[test]
    fn byte_budget_counts_bytes_and_always_moves() {
        let mut s = stack();
        let per = 128 * 128 * 4;
        assert_eq!(s.plan(FrameBudget::Bytes(3 * per), per).len(), 3);
        assert_eq!(s.plan(FrameBudget::Bytes(per / 2), per).len(), 1);
    }

    #[test]
    fn failed_uploads_are_retried() {
        let mut s = stack();
        let plan = s.plan(FrameBudget::Subtiles(1), 0);
        s.failed(plan[0]);
        assert_eq!(s.plan(FrameBudget::Subtiles(1), 0), plan);
    }

    #[test]
    fn shader_choice_falls_back_to_coarser_layers() {
        let mut s = stack();
        let uv = [0.3, 0.7];
        assert_eq!(finest_covering_layer(&s, uv).0, 0, "nothing resident yet");
        // Complete layers 1 and 2 only.
        for _ in 0..4 {
            for u in s.plan(FrameBudget::Subtiles(64), 0) {
                if u.layer <= 2 {
                    s.uploaded(u);
                } else {
                    s.failed(u);
                }
            }
        }
        let (layer, level, texel) = finest_covering_layer(&s, uv);
        assert_eq!((layer, level), (2, 12));
        assert_eq!(texel, [(0.3 * 4096.0) as i64, (0.7 * 4096.0) as i64]);
        // Far from the centre only the base level covers.
        assert_eq!(finest_covering_layer(&s, [0.9, 0.1]).0, 0);
    }

    #[test]
    fn centre_subtiles_are_exact_far_from_the_origin() {
        // Level 20 with 1 m texels: 10^6 m from the origin is texel 10^6.
        let uv = [1_000_000.5 / (1u64 << 20) as f64, 0.5];
        assert_eq!(center_subtile(uv, 20, 128, true)[0], 1_000_000 / 128);
        let (_, _, texel) = finest_covering_layer(&ClipStack::new(21, 1024, 128, uv), uv);
        assert_eq!(texel[0], (1_000_000.5f64 / 2f64.powi(10)).floor() as i64);
    }
}
