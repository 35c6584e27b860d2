//! One layer of the clip stack, as bookkeeping (Seoane et al. 2007, paper 1, §3–4:
//! steps 2–5): its window of `n × n` subtiles around the centre of detail, the toroidal slot each
//! subtile of the window lives in, the state of every slot, the update order (concentric rings
//! from the centre) and the coverage handed to the shader.
//!
//! Coordinates are integers in the layer's virtual level: subtile `(x, y)` covers level texels
//! `[x·s, (x+1)·s) × [y·s, (y+1)·s)`. Toroidal placement: subtile `(x, y)` lives in slot
//! `(x mod n, y mod n)`, so level texel `t` lives at layer texel `t mod c` (c = n·s) — sampling
//! the layer texture with Repeat addressing is then seamless across the wrap.

/// A subtile address in a level (subtiles, not texels).
pub type Subtile = [i64; 2];

/// What a slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotState {
    /// Holds stale or no data for its subtile: must be fetched.
    Invalid,
    /// Its subtile's data was requested and has not arrived.
    Pending,
    /// Holds its subtile's data.
    Valid,
    /// Its subtile does not exist in the pyramid (outside a partial level): nothing to fetch,
    /// and the shader falls back to a coarser layer there.
    Absent,
}

/// One slot of the layer texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Slot {
    /// The subtile it must hold (the one of the current window mapping to it).
    pub subtile: Subtile,
    /// Its state.
    pub state: SlotState,
}

/// The layer's state matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerState {
    /// Virtual level this layer caches.
    pub level: u32,
    /// Subtiles per side of the layer texture, n = c / s.
    pub slots_per_side: u32,
    /// Subtiles per side of the whole level.
    pub level_subtiles: i64,
    /// The subtile holding the centre of detail.
    pub center: Subtile,
    slots: Vec<Slot>,
}

/// Chebyshev ring of `subtile` around `center`.
pub fn ring(subtile: Subtile, center: Subtile) -> u64 {
    (subtile[0] - center[0])
        .unsigned_abs()
        .max((subtile[1] - center[1]).unsigned_abs())
}

/// Texel of the layer texture (side `clip`) holding level texel `texel` (toroidal).
pub fn toroidal_texel(texel: i64, clip: u32) -> u32 {
    texel.rem_euclid(clip as i64) as u32
}

impl LayerState {
    /// A layer of `slots_per_side²` slots over a level `level_subtiles` subtiles wide, all
    /// invalid, centred on subtile `center`.
    pub fn new(level: u32, slots_per_side: u32, level_subtiles: i64, center: Subtile) -> Self {
        let n = slots_per_side.max(1);
        let mut layer = Self {
            level,
            slots_per_side: n,
            level_subtiles: level_subtiles.max(1),
            center,
            slots: vec![
                Slot {
                    subtile: [i64::MIN, i64::MIN],
                    state: SlotState::Invalid,
                };
                (n * n) as usize
            ],
        };
        layer.recenter(center);
        layer
    }

    /// Slot index of `subtile`: `(x mod n, y mod n)` row-major.
    pub fn slot_index(&self, subtile: Subtile) -> usize {
        let n = self.slots_per_side as i64;
        (subtile[1].rem_euclid(n) * n + subtile[0].rem_euclid(n)) as usize
    }

    /// The window `[min, max)` in subtiles: `n` wide around the centre, shifted to stay inside
    /// the level (a level narrower than the window is covered whole).
    pub fn window(&self) -> (Subtile, Subtile) {
        let n = self.slots_per_side as i64;
        let axis = |c: i64| {
            if self.level_subtiles <= n {
                return (0, self.level_subtiles);
            }
            let min = (c - n / 2).clamp(0, self.level_subtiles - n);
            (min, min + n)
        };
        let (x0, x1) = axis(self.center[0]);
        let (y0, y1) = axis(self.center[1]);
        ([x0, y0], [x1, y1])
    }

    /// Whether `subtile` is in the current window.
    pub fn in_window(&self, subtile: Subtile) -> bool {
        let (min, max) = self.window();
        (0..2).all(|i| subtile[i] >= min[i] && subtile[i] < max[i])
    }

    /// Moves the centre of detail: every slot whose subtile left the window is given the subtile
    /// that entered in its place and becomes invalid. Returns how many slots were invalidated.
    pub fn recenter(&mut self, center: Subtile) -> u32 {
        self.center = center;
        let (min, max) = self.window();
        let mut changed = 0;
        for y in min[1]..max[1] {
            for x in min[0]..max[0] {
                let i = self.slot_index([x, y]);
                let slot = &mut self.slots[i];
                if slot.subtile != [x, y] {
                    *slot = Slot {
                        subtile: [x, y],
                        state: SlotState::Invalid,
                    };
                    changed += 1;
                }
            }
        }
        changed
    }

    /// The slot holding `subtile`, if it is in the window.
    pub fn slot(&self, subtile: Subtile) -> Option<&Slot> {
        self.in_window(subtile)
            .then(|| &self.slots[self.slot_index(subtile)])
    }

    /// Every slot.
    pub fn slots(&self) -> &[Slot] {
        &self.slots
    }

    /// Sets the state of `subtile`'s slot, if the slot still holds that subtile (an upload that
    /// arrives after the window moved on is dropped). Returns whether it did.
    pub fn set_state(&mut self, subtile: Subtile, state: SlotState) -> bool {
        if !self.in_window(subtile) {
            return false;
        }
        let i = self.slot_index(subtile);
        if self.slots[i].subtile != subtile {
            return false;
        }
        self.slots[i].state = state;
        true
    }

    /// Invalid subtiles in update order: concentric rings from the centre outward, row-major
    /// inside a ring.
    pub fn invalid_in_ring_order(&self) -> Vec<Subtile> {
        let mut invalid: Vec<Subtile> = self
            .slots
            .iter()
            .filter(|s| s.state == SlotState::Invalid)
            .map(|s| s.subtile)
            .collect();
        invalid.sort_by_key(|&s| (ring(s, self.center), s[1], s[0]));
        invalid
    }

    /// Whether every slot is settled: valid, or absent from the pyramid (so the next finer layer
    /// may start).
    pub fn complete(&self) -> bool {
        self.slots
            .iter()
            .all(|s| matches!(s.state, SlotState::Valid | SlotState::Absent))
    }

    /// Fraction of valid slots (absent ones count as valid: there is nothing to hold).
    pub fn valid_fraction(&self) -> f32 {
        let valid = self
            .slots
            .iter()
            .filter(|s| matches!(s.state, SlotState::Valid | SlotState::Absent))
            .count();
        valid as f32 / self.slots.len() as f32
    }

    /// The largest ring r such that every window subtile within ring r of the centre is valid
    /// (None: not even the centre subtile).
    pub fn coverage_ring(&self) -> Option<u64> {
        let mut best = None;
        let max_ring = self.slots_per_side as u64;
        for r in 0..=max_ring {
            let all_valid = self
                .slots
                .iter()
                .filter(|s| ring(s.subtile, self.center) == r)
                .all(|s| s.state == SlotState::Valid);
            let any_left = self.slots.iter().any(|s| ring(s.subtile, self.center) >= r);
            if !all_valid {
                break;
            }
            best = Some(r);
            if !any_left {
                break;
            }
        }
        best
    }

    /// The level texels `[min, max)` the layer covers with valid data around the centre — what
    /// the shader gets to decide whether this layer can be sampled at a point.
    pub fn coverage_texels(&self, subtile_size: u32) -> Option<([i64; 2], [i64; 2])> {
        let r = self.coverage_ring()? as i64;
        let (wmin, wmax) = self.window();
        let s = subtile_size as i64;
        let min = [
            (self.center[0] - r).max(wmin[0]) * s,
            (self.center[1] - r).max(wmin[1]) * s,
        ];
        let max = [
            (self.center[0] + r + 1).min(wmax[0]) * s,
            (self.center[1] + r + 1).min(wmax[1]) * s,
        ];
        Some((min, max))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toroidal_slots_are_a_bijection_over_any_window() {
        let mut layer = LayerState::new(12, 8, 1 << 12, [100, 200]);
        for center in [[100, 200], [101, 200], [97, 205], [4, 4], [4090, 1]] {
            layer.recenter(center);
            let (min, max) = layer.window();
            assert_eq!([max[0] - min[0], max[1] - min[1]], [8, 8]);
            let mut seen = [false; 64];
            for y in min[1]..max[1] {
                for x in min[0]..max[0] {
                    let i = layer.slot_index([x, y]);
                    assert!(!seen[i], "slot {i} used twice");
                    seen[i] = true;
                    assert_eq!(layer.slot([x, y]).unwrap().subtile, [x, y]);
                }
            }
        }
        // Negative and huge coordinates wrap the same way (level texel → layer texel).
        assert_eq!(toroidal_texel(-1, 1024), 1023);
        assert_eq!(toroidal_texel(1024 * 977 + 5, 1024), 5);
    }

    #[test]
    fn moving_one_subtile_invalidates_one_strip() {
        let mut layer = LayerState::new(12, 8, 1 << 12, [100, 200]);
        for s in layer.invalid_in_ring_order() {
            assert!(layer.set_state(s, SlotState::Valid));
        }
        assert!(layer.complete());
        assert_eq!(layer.recenter([101, 200]), 8, "one column of 8 entered");
        assert_eq!(layer.recenter([101, 202]), 16, "two rows of 8 entered");
        assert_eq!(layer.recenter([101, 202]), 0);
        // The entered subtiles are exactly the invalid ones.
        for s in layer.invalid_in_ring_order() {
            assert!(s[0] == 101 + 3 || s[1] >= 202 + 2, "{s:?}");
        }
    }

    #[test]
    fn updates_go_in_rings_from_the_centre() {
        let layer = LayerState::new(10, 8, 1 << 10, [50, 50]);
        let order = layer.invalid_in_ring_order();
        assert_eq!(order.len(), 64);
        assert_eq!(order[0], [50, 50]);
        let rings: Vec<u64> = order.iter().map(|&s| ring(s, [50, 50])).collect();
        assert!(rings.windows(2).all(|w| w[0] <= w[1]), "{rings:?}");
        assert_eq!(&rings[..9], &[0, 1, 1, 1, 1, 1, 1, 1, 1]);
    }

    #[test]
    fn coverage_is_the_largest_fully_valid_ring() {
        let mut layer = LayerState::new(10, 8, 1 << 10, [50, 50]);
        assert_eq!(layer.coverage_ring(), None);
        let order = layer.invalid_in_ring_order();
        for &s in &order[..9] {
            layer.set_state(s, SlotState::Valid);
        }
        assert_eq!(layer.coverage_ring(), Some(1));
        assert_eq!(
            layer.coverage_texels(128),
            Some(([49 * 128, 49 * 128], [52 * 128, 52 * 128]))
        );
        // A pending subtile in ring 0 drops coverage to nothing.
        layer.set_state([50, 50], SlotState::Pending);
        assert_eq!(layer.coverage_ring(), None);
        // Data for a subtile that left the window is refused.
        layer.recenter([80, 80]);
        assert!(!layer.set_state([50, 50], SlotState::Valid));
    }

    #[test]
    fn absent_subtiles_settle_the_layer_but_bound_its_coverage() {
        let mut layer = LayerState::new(10, 8, 1 << 10, [50, 50]);
        for s in layer.invalid_in_ring_order() {
            let state = if s == [52, 50] {
                SlotState::Absent
            } else {
                SlotState::Valid
            };
            layer.set_state(s, state);
        }
        assert!(layer.complete(), "nothing left to fetch");
        assert!(layer.invalid_in_ring_order().is_empty());
        // Ring 2 holds the absent subtile: the shader may use this layer only within ring 1.
        assert_eq!(layer.coverage_ring(), Some(1));
    }

    #[test]
    fn windows_stay_inside_the_level() {
        let layer = LayerState::new(10, 8, 1 << 3, [0, 0]);
        assert_eq!(layer.window(), ([0, 0], [8, 8]));
        let edge = LayerState::new(10, 8, 64, [63, 1]);
        assert_eq!(edge.window(), ([56, 0], [64, 8]));
    }
}
