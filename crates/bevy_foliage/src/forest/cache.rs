//! The LoD cache of Gumbau 2011, chapter 4 (spec F3): per tree type, slots over the LoD range
//! [0, 1] each holding one extracted LoD that every instance of the type whose desired LoD falls
//! in the slot may borrow, instead of extracting its own.
//!
//! Slot layout: two exact slots, LoD 0 (nothing drawn — never needs extracting) and LoD 1 (full
//! detail: every leaf, no view-dependent pruning — see the forest plugin), then `N` range slots, slot i covering `[b_i, b_{i+1})` (eq. 4.4 with uniform
//! `b_i = i/N`; non-uniform bounds can make the slots finer near the camera, i.e. at high LoD).
//!
//! Algorithm 3: if the tree's current slot is the slot of its desired LoD, nothing is done; else
//! if that slot holds an extraction fresh enough, the tree borrows it; else the slot is
//! re-extracted at the tree's desired LoD and the tree uses it. An extraction stays borrowable
//! for `max_age` frames: extractions are view-dependent, and a camera that moves on makes them
//! stale.
//!
//! The **double-buffered** variant (the thesis' GPU version) keeps a front and a back extraction
//! per slot: an extraction made this frame goes to the back and becomes borrowable only next
//! frame, so no tree ever reads a buffer the GPU is writing in the same frame. Trees that would
//! need the slot before then wait (they stay urgent).

/// Index of the exact LoD 0 slot.
pub const SLOT_LOD_ZERO: usize = 0;
/// Index of the exact LoD 1 slot.
pub const SLOT_LOD_ONE: usize = 1;
/// Index of the first range slot.
pub const FIRST_RANGE_SLOT: usize = 2;

/// Why slot bounds were rejected.
#[derive(Clone, Debug, PartialEq)]
pub enum SlotBoundsError {
    /// Fewer than two bounds.
    TooFew,
    /// Bounds must start at 0, end at 1 and strictly increase.
    NotIncreasing(Vec<f32>),
}

impl std::fmt::Display for SlotBoundsError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::TooFew => write!(f, "LoD slot bounds need at least [0, 1]"),
            Self::NotIncreasing(b) => write!(
                f,
                "LoD slot bounds must start at 0, end at 1 and strictly increase: {b:?}"
            ),
        }
    }
}

impl std::error::Error for SlotBoundsError {}

/// The slots of a tree type's cache.
#[derive(Clone, Debug, PartialEq)]
pub struct LodSlots {
    /// `N + 1` bounds from 0 to 1.
    bounds: Vec<f32>,
}

impl LodSlots {
    /// `n` equal slots (eq. 4.4). `n` is at least 1.
    pub fn uniform(n: u32) -> Self {
        let n = n.max(1);
        Self {
            bounds: (0..=n).map(|i| i as f32 / n as f32).collect(),
        }
    }

    /// Slots with the given bounds (`[0, …, 1]`, strictly increasing).
    pub fn from_bounds(bounds: Vec<f32>) -> Result<Self, SlotBoundsError> {
        if bounds.len() < 2 {
            return Err(SlotBoundsError::TooFew);
        }
        let ok = bounds[0] == 0.0
            && *bounds.last().unwrap() == 1.0
            && bounds.windows(2).all(|w| w[0] < w[1])
            && bounds.iter().all(|b| b.is_finite());
        if !ok {
            return Err(SlotBoundsError::NotIncreasing(bounds));
        }
        Ok(Self { bounds })
    }

    /// Range slots (without the two exact ones).
    pub fn range_count(&self) -> usize {
        self.bounds.len() - 1
    }

    /// All slots, the two exact ones included.
    pub fn len(&self) -> usize {
        self.range_count() + FIRST_RANGE_SLOT
    }

    /// Never empty.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The slot holding `lod`: exact 0 and 1 have their own.
    pub fn slot_of(&self, lod: f32) -> usize {
        // A NaN level goes to the LoD-0 slot as well.
        if lod.is_nan() || lod <= 0.0 {
            return SLOT_LOD_ZERO;
        }
        if lod >= 1.0 {
            return SLOT_LOD_ONE;
        }
        // The last bound ≤ lod: partition_point counts the bounds ≤ lod (≥ 1 since b_0 = 0).
        let i = self.bounds.partition_point(|&b| b <= lod) - 1;
        FIRST_RANGE_SLOT + i.min(self.range_count() - 1)
    }

    /// The LoDs slot `slot` holds: `[lo, hi)` for range slots, `[0, 0]` and `[1, 1]` for the exact
    /// ones.
    pub fn range(&self, slot: usize) -> (f32, f32) {
        match slot {
            SLOT_LOD_ZERO => (0.0, 0.0),
            SLOT_LOD_ONE => (1.0, 1.0),
            s => (
                self.bounds[s - FIRST_RANGE_SLOT],
                self.bounds[s - FIRST_RANGE_SLOT + 1],
            ),
        }
    }

    /// Whether `lod` belongs to `slot`.
    pub fn contains(&self, slot: usize, lod: f32) -> bool {
        self.slot_of(lod) == slot
    }

    /// Width of the slot (0 for the exact ones).
    pub fn width(&self, slot: usize) -> f32 {
        let (lo, hi) = self.range(slot);
        hi - lo
    }
}

/// One extraction held by a slot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CachedLod {
    /// The LoD it was extracted at.
    pub lod: f32,
    /// The frame it was extracted in.
    pub frame: u64,
    /// The tree whose view it was extracted for.
    pub tree: usize,
    /// Which of the slot's two GPU copies holds it (always 0 unless double-buffered).
    pub copy: usize,
}

/// What Algorithm 3 decides for a tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CacheAction {
    /// The tree's current slot already covers its desired LoD.
    Keep,
    /// Use the extraction slot `slot` holds.
    Borrow {
        /// The slot.
        slot: usize,
        /// What it holds.
        entry: CachedLod,
    },
    /// Extract slot `slot` anew at the tree's desired LoD.
    Extract {
        /// The slot.
        slot: usize,
    },
    /// Double-buffered only: the slot was extracted this frame and has no older extraction
    /// to lend; try again next frame.
    Wait,
}

/// The LoD cache of one tree type.
#[derive(Clone, Debug)]
pub struct LodCache {
    /// The slots.
    pub slots: LodSlots,
    /// Frames an extraction stays borrowable.
    pub max_age: u64,
    /// Borrow only extractions made in earlier frames (two GPU copies per slot).
    pub double_buffered: bool,
    copies: Vec<[Option<CachedLod>; 2]>,
}

/// The exact LoD 0 "extraction": nothing drawn, never extracted.
const LOD_ZERO_ENTRY: CachedLod = CachedLod {
    lod: 0.0,
    frame: 0,
    tree: usize::MAX,
    copy: 0,
};

impl LodCache {
    /// An empty cache.
    pub fn new(slots: LodSlots, max_age: u64, double_buffered: bool) -> Self {
        let n = slots.len();
        Self {
            slots,
            max_age,
            double_buffered,
            copies: vec![[None; 2]; n],
        }
    }

    /// GPU copies per slot: 2 when double-buffered, else 1.
    pub fn copies_per_slot(&self) -> usize {
        if self.double_buffered { 2 } else { 1 }
    }

    /// The newest extraction of `slot` made before frame `frame` (double-buffered) or up to it.
    fn newest(&self, slot: usize, frame: u64) -> Option<CachedLod> {
        if slot == SLOT_LOD_ZERO {
            return Some(LOD_ZERO_ENTRY);
        }
        self.copies[slot]
            .iter()
            .flatten()
            .filter(|e| !self.double_buffered || e.frame < frame)
            .max_by_key(|e| e.frame)
            .copied()
    }

    /// What a tree drawing copy `copy` of `slot` sees.
    pub fn entry(&self, slot: usize, copy: usize) -> Option<CachedLod> {
        if slot == SLOT_LOD_ZERO {
            return Some(LOD_ZERO_ENTRY);
        }
        self.copies[slot][copy]
    }

    /// Algorithm 3 for a tree currently drawing `current` (None: nothing yet) that wants
    /// `desired`, in frame `frame`.
    pub fn decide(&self, current: Option<usize>, desired: f32, frame: u64) -> CacheAction {
        let slot = self.slots.slot_of(desired);
        if current == Some(slot) {
            return CacheAction::Keep;
        }
        if let Some(entry) = self.newest(slot, frame)
            && (slot == SLOT_LOD_ZERO || frame.saturating_sub(entry.frame) <= self.max_age)
        {
            return CacheAction::Borrow { slot, entry };
        }
        if self.double_buffered && self.copies[slot].iter().flatten().any(|e| e.frame == frame) {
            return CacheAction::Wait;
        }
        CacheAction::Extract { slot }
    }

    /// Records an extraction of `slot` at `lod` for `tree` in `frame` and returns it. When
    /// double-buffered it goes to the copy not being lent (the older one).
    pub fn store(&mut self, slot: usize, lod: f32, tree: usize, frame: u64) -> CachedLod {
        debug_assert!(self.slots.contains(slot, lod), "{lod} not in slot {slot}");
        let copy = if self.double_buffered {
            let [a, b] = self.copies[slot];
            match (a, b) {
                (None, _) => 0,
                (_, None) => 1,
                (Some(a), Some(b)) => usize::from(a.frame > b.frame),
            }
        } else {
            0
        };
        let entry = CachedLod {
            lod,
            frame,
            tree,
            copy,
        };
        self.copies[slot][copy] = Some(entry);
        entry
    }

    /// Forgets every extraction (e.g. when the tree type's data changed).
    pub fn clear(&mut self) {
        for c in &mut self.copies {
            *c = [None; 2];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_follow_eq_4_4_with_exact_ends() {
        let s = LodSlots::uniform(4);
        assert_eq!(s.len(), 6);
        assert_eq!(s.slot_of(0.0), SLOT_LOD_ZERO);
        assert_eq!(s.slot_of(-1.0), SLOT_LOD_ZERO);
        assert_eq!(s.slot_of(f32::NAN), SLOT_LOD_ZERO);
        assert_eq!(s.slot_of(1.0), SLOT_LOD_ONE);
        assert_eq!(s.slot_of(0.01), FIRST_RANGE_SLOT);
        assert_eq!(s.slot_of(0.25), FIRST_RANGE_SLOT + 1);
        assert_eq!(s.slot_of(0.2499), FIRST_RANGE_SLOT);
        assert_eq!(s.slot_of(0.9999), FIRST_RANGE_SLOT + 3);
        assert_eq!(s.range(FIRST_RANGE_SLOT + 1), (0.25, 0.5));
        for i in 0..1000 {
            let lod = i as f32 / 1000.0;
            let (lo, hi) = s.range(s.slot_of(lod));
            assert!(lo <= lod && (lod < hi || lo == hi), "{lod} -> {lo}..{hi}");
        }
    }

    #[test]
    fn non_uniform_slots_are_validated() {
        let s = LodSlots::from_bounds(vec![0.0, 0.5, 0.75, 0.875, 1.0]).unwrap();
        assert_eq!(s.slot_of(0.3), FIRST_RANGE_SLOT);
        assert_eq!(s.slot_of(0.9), FIRST_RANGE_SLOT + 3);
        assert_eq!(s.width(FIRST_RANGE_SLOT + 3), 0.125);
        assert!(LodSlots::from_bounds(vec![0.0, 0.6, 0.5, 1.0]).is_err());
        assert!(LodSlots::from_bounds(vec![0.1, 1.0]).is_err());
        assert_eq!(
            LodSlots::from_bounds(vec![0.0]),
            Err(SlotBoundsError::TooFew)
        );
    }

    #[test]
    fn algorithm_3_keeps_borrows_then_extracts() {
        let mut cache = LodCache::new(LodSlots::uniform(4), 10, false);
        let slot = cache.slots.slot_of(0.6);
        assert_eq!(cache.decide(None, 0.6, 1), CacheAction::Extract { slot });
        cache.store(slot, 0.6, 7, 1);
        assert_eq!(cache.decide(Some(slot), 0.65, 2), CacheAction::Keep);
        match cache.decide(None, 0.7, 2) {
            CacheAction::Borrow { slot: s, entry } => {
                assert_eq!(s, slot);
                assert_eq!((entry.lod, entry.tree), (0.6, 7));
            }
            other => panic!("{other:?}"),
        }
        // Stale after max_age frames.
        assert_eq!(cache.decide(None, 0.7, 12), CacheAction::Extract { slot });
        // LoD 0 never needs an extraction.
        assert!(matches!(
            cache.decide(Some(slot), 0.0, 3),
            CacheAction::Borrow {
                slot: SLOT_LOD_ZERO,
                ..
            }
        ));
    }

    #[test]
    fn double_buffered_cache_lends_only_last_frames_extractions() {
        let mut cache = LodCache::new(LodSlots::uniform(4), 10, true);
        let slot = cache.slots.slot_of(0.6);
        let first = cache.store(slot, 0.6, 1, 5);
        // Same frame: being written, not lendable.
        assert_eq!(cache.decide(None, 0.6, 5), CacheAction::Wait);
        assert!(matches!(
            cache.decide(None, 0.6, 6),
            CacheAction::Borrow { .. }
        ));
        // A re-extraction in frame 8 goes to the other copy and leaves frame 5's extraction
        // lendable during frame 8.
        let second = cache.store(slot, 0.55, 2, 8);
        assert_ne!(first.copy, second.copy);
        match cache.decide(None, 0.6, 8) {
            CacheAction::Borrow { entry, .. } => {
                assert_eq!((entry.frame, entry.copy), (5, first.copy))
            }
            other => panic!("{other:?}"),
        }
        match cache.decide(None, 0.6, 9) {
            CacheAction::Borrow { entry, .. } => {
                assert_eq!((entry.frame, entry.copy), (8, second.copy))
            }
            other => panic!("{other:?}"),
        }
        // The next extraction overwrites the older copy, never the one being lent.
        let third = cache.store(slot, 0.52, 3, 9);
        assert_eq!(third.copy, first.copy);
    }
}
