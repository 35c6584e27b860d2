//! The RAM side of the virtual texture: an LRU cache of decoded tiles and the request
//! queue feeding the loaders — coarsest level first, duplicates merged, absent tiles (outside
//! partial levels) remembered, failed tiles retried with exponential back-off. Plain Rust; the
//! plugin runs the loads on Bevy's IO task pool.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};

/// A tile of the pyramid: level `z`, column `x`, row `y` (XYZ order: row 0 at the top).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileKey {
    /// Level (0 = one tile for the whole texture).
    pub z: u32,
    /// Column.
    pub x: u32,
    /// Row.
    pub y: u32,
}

/// A least-recently-used cache of at most `capacity` values.
#[derive(Clone, Debug)]
pub struct LruCache<V> {
    capacity: usize,
    clock: u64,
    entries: HashMap<TileKey, (V, u64)>,
    by_age: BTreeMap<u64, TileKey>,
}

impl<V> LruCache<V> {
    /// An empty cache of `capacity` (at least 1) entries.
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity: capacity.max(1),
            clock: 0,
            entries: HashMap::new(),
            by_age: BTreeMap::new(),
        }
    }

    /// Entries it holds at most.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Entries held.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether it holds nothing.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Whether `key` is held (does not count as a use).
    pub fn contains(&self, key: &TileKey) -> bool {
        self.entries.contains_key(key)
    }

    fn touch(&mut self, key: TileKey) {
        self.clock += 1;
        if let Some((_, age)) = self.entries.get_mut(&key) {
            self.by_age.remove(age);
            *age = self.clock;
            self.by_age.insert(self.clock, key);
        }
    }

    /// The value of `key`, marking it most recently used.
    pub fn get(&mut self, key: &TileKey) -> Option<&V> {
        if !self.entries.contains_key(key) {
            return None;
        }
        self.touch(*key);
        self.entries.get(key).map(|(v, _)| v)
    }

    /// Stores `value` as most recently used; returns the entry evicted to make room, if any.
    pub fn insert(&mut self, key: TileKey, value: V) -> Option<(TileKey, V)> {
        self.clock += 1;
        if let Some((_, age)) = self.entries.remove(&key) {
            self.by_age.remove(&age);
        }
        let mut evicted = None;
        if self.entries.len() >= self.capacity
            && let Some((_, oldest)) = self.by_age.pop_first()
        {
            evicted = self.entries.remove(&oldest).map(|(v, _)| (oldest, v));
        }
        self.entries.insert(key, (value, self.clock));
        self.by_age.insert(self.clock, key);
        evicted
    }
}

/// Where a requested tile stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileStatus {
    /// Waiting in the queue.
    Queued,
    /// Being loaded.
    Loading,
    /// Known not to exist (outside a partial level): never requested again.
    Absent,
    /// Failed `attempts` times; not retried before frame `retry_at`.
    Failed {
        /// Failures so far.
        attempts: u32,
        /// First frame a retry may start.
        retry_at: u64,
    },
    /// Failed [`MAX_TILE_ATTEMPTS`] times: the terrain shows the no-data colour there, and
    /// the tile is only probed again — one load every [`GIVEN_UP_PROBE_FRAMES`] — so that a
    /// source which comes back (a server after an outage, a file rewritten) heals the terrain
    /// without a restart, while a tile that is truly broken costs one read every few seconds.
    GivenUp {
        /// First frame the next probe may start.
        retry_at: u64,
    },
}

/// Loads of one tile that may fail before it is given up: with the doubling back-off, about
/// 2⁶ frames of retrying — a file being written, a server's brief outage — then only probes.
pub const MAX_TILE_ATTEMPTS: u32 = 6;

/// Frames between probes of a given-up tile (about four seconds at 60 frames a second).
pub const GIVEN_UP_PROBE_FRAMES: u64 = 256;

/// The queue of tile loads.
#[derive(Clone, Debug, Default)]
pub struct TileRequests {
    queue: BTreeSet<TileKey>,
    status: HashMap<TileKey, TileStatus>,
    absent: HashSet<TileKey>,
    failed_attempts: HashMap<TileKey, u32>,
    /// Requests merged into one already queued or loading.
    pub merged: u64,
}

/// Frames before retry `attempt` (1, 2, 4, … up to 256).
pub fn backoff_frames(attempts: u32) -> u64 {
    1u64 << attempts.min(8)
}

impl TileRequests {
    /// Asks for `key` in frame `frame`; returns whether a new load was queued (false: already
    /// queued or loading, known absent, or waiting out a back-off).
    pub fn request(&mut self, key: TileKey, frame: u64) -> bool {
        if self.absent.contains(&key) {
            return false;
        }
        match self.status.get(&key) {
            Some(TileStatus::Queued | TileStatus::Loading) => {
                self.merged += 1;
                false
            }
            Some(TileStatus::Failed { retry_at, .. } | TileStatus::GivenUp { retry_at })
                if frame < *retry_at =>
            {
                false
            }
            Some(TileStatus::Absent) => false,
            _ => {
                // A retry keeps its failure count (in `failed_attempts`) for the next back-off.
                self.queue.insert(key);
                self.status.insert(key, TileStatus::Queued);
                true
            }
        }
    }

    /// Takes up to `n` queued tiles to load, coarsest level first.
    pub fn next_batch(&mut self, n: usize) -> Vec<TileKey> {
        let batch: Vec<TileKey> = self.queue.iter().take(n).copied().collect();
        for key in &batch {
            self.queue.remove(key);
            self.status.insert(*key, TileStatus::Loading);
        }
        batch
    }

    /// A load finished with data: forget it (the cache holds it now).
    pub fn loaded(&mut self, key: TileKey) {
        self.status.remove(&key);
        self.failed_attempts.remove(&key);
    }

    /// A load found no tile: remember it as absent.
    pub fn absent(&mut self, key: TileKey) {
        self.status.remove(&key);
        self.absent.insert(key);
    }

    /// A load failed (I/O error, corrupt image) in frame `frame`: retry after a back-off, or
    /// give the tile up after [`MAX_TILE_ATTEMPTS`] failures (then probe it every
    /// [`GIVEN_UP_PROBE_FRAMES`]). Returns the failures so far: [`MAX_TILE_ATTEMPTS`] exactly
    /// when the tile has just been given up, more when a probe failed.
    pub fn failed(&mut self, key: TileKey, frame: u64) -> u32 {
        let attempts = self.failed_attempts.get(&key).copied().unwrap_or(0) + 1;
        self.failed_attempts.insert(key, attempts);
        let status = if attempts >= MAX_TILE_ATTEMPTS {
            TileStatus::GivenUp {
                retry_at: frame + GIVEN_UP_PROBE_FRAMES,
            }
        } else {
            TileStatus::Failed {
                attempts,
                retry_at: frame + backoff_frames(attempts),
            }
        };
        self.status.insert(key, status);
        attempts
    }

    /// The status of `key`, if requested.
    pub fn status(&self, key: &TileKey) -> Option<TileStatus> {
        if self.absent.contains(key) {
            return Some(TileStatus::Absent);
        }
        self.status.get(key).copied()
    }

    /// Tiles waiting in the queue.
    pub fn queued(&self) -> usize {
        self.queue.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(z: u32, x: u32, y: u32) -> TileKey {
        TileKey { z, x, y }
    }

    #[test]
    fn lru_evicts_the_least_recently_used() {
        let mut cache = LruCache::new(3);
        assert!(cache.insert(key(1, 0, 0), "a").is_none());
        cache.insert(key(1, 1, 0), "b");
        cache.insert(key(1, 0, 1), "c");
        // Using "a" makes "b" the oldest.
        assert_eq!(cache.get(&key(1, 0, 0)), Some(&"a"));
        assert_eq!(cache.insert(key(2, 0, 0), "d"), Some((key(1, 1, 0), "b")));
        assert!(!cache.contains(&key(1, 1, 0)));
        assert_eq!(cache.len(), 3);
        // Re-inserting a held key replaces it without evicting.
        assert!(cache.insert(key(2, 0, 0), "d2").is_none());
        assert_eq!(cache.get(&key(2, 0, 0)), Some(&"d2"));
    }

    #[test]
    fn requests_go_coarsest_first_and_merge_duplicates() {
        let mut r = TileRequests::default();
        assert!(r.request(key(5, 3, 3), 0));
        assert!(r.request(key(2, 1, 0), 0));
        assert!(r.request(key(9, 0, 0), 0));
        assert!(!r.request(key(5, 3, 3), 0));
        assert_eq!(r.merged, 1);
        assert_eq!(r.next_batch(2), vec![key(2, 1, 0), key(5, 3, 3)]);
        // Loading tiles merge too.
        assert!(!r.request(key(2, 1, 0), 1));
        assert_eq!(r.merged, 2);
        r.loaded(key(2, 1, 0));
        assert!(
            r.request(key(2, 1, 0), 2),
            "after loading, a new request is a new load"
        );
    }

    #[test]
    fn absent_tiles_are_remembered_and_failures_back_off() {
        let mut r = TileRequests::default();
        r.request(key(8, 1, 1), 0);
        r.next_batch(1);
        r.absent(key(8, 1, 1));
        assert!(!r.request(key(8, 1, 1), 5));
        assert_eq!(r.status(&key(8, 1, 1)), Some(TileStatus::Absent));

        r.request(key(3, 0, 0), 10);
        r.next_batch(1);
        r.failed(key(3, 0, 0), 10);
        assert!(!r.request(key(3, 0, 0), 11), "waits out the back-off");
        assert!(r.request(key(3, 0, 0), 12));
        r.next_batch(1);
        r.failed(key(3, 0, 0), 12);
        assert_eq!(
            r.status(&key(3, 0, 0)),
            Some(TileStatus::Failed {
                attempts: 2,
                retry_at: 16
            })
        );
        assert_eq!(backoff_frames(30), 256);
        // A tile that keeps failing is given up, and not asked for again.
        let mut frame = 20;
        for attempt in 3..=MAX_TILE_ATTEMPTS {
            frame += 300;
            assert!(r.request(key(3, 0, 0), frame), "attempt {attempt}");
            r.next_batch(1);
            assert_eq!(r.failed(key(3, 0, 0), frame), attempt);
        }
        assert_eq!(
            r.status(&key(3, 0, 0)),
            Some(TileStatus::GivenUp {
                retry_at: frame + GIVEN_UP_PROBE_FRAMES
            })
        );
        // Given up, it is only probed: not before the probe interval, once after it.
        assert!(!r.request(key(3, 0, 0), frame + GIVEN_UP_PROBE_FRAMES - 1));
        frame += GIVEN_UP_PROBE_FRAMES;
        assert!(r.request(key(3, 0, 0), frame));
        assert!(!r.request(key(3, 0, 0), frame), "one probe at a time");
        r.next_batch(1);
        // A failed probe keeps it given up, until the next probe.
        assert_eq!(r.failed(key(3, 0, 0), frame), MAX_TILE_ATTEMPTS + 1);
        assert!(!r.request(key(3, 0, 0), frame + 1));
        frame += GIVEN_UP_PROBE_FRAMES;
        assert!(r.request(key(3, 0, 0), frame));
        r.next_batch(1);
        // A probe that loads heals the tile: a later failure starts the back-off afresh.
        r.loaded(key(3, 0, 0));
        assert_eq!(r.status(&key(3, 0, 0)), None);
        assert!(r.request(key(3, 0, 0), frame + 1));
        r.next_batch(1);
        assert_eq!(r.failed(key(3, 0, 0), frame + 1), 1);
    }
}
