//! [`TileCache`]: the RAM tile cache of one virtual texture, loading through a [`TileSource`]
//! on Bevy's IO task pool. Misses queue a load — coarsest level first, duplicates
//! merged — and [`TileCache::poll`] (once a frame) collects finished loads and starts new ones.
//! Absent tiles are remembered; failed tiles (corrupt image, I/O error) are logged and retried
//! with exponential back-off; latency and traffic are counted in [`TileCacheStats`].

use crate::cache::{LruCache, TileKey, TileRequests};
use crate::source::{TileData, TileError, TileSource};
use bevy::log::warn;
use bevy::tasks::{IoTaskPool, Task, futures::check_ready};
use std::sync::Arc;
use std::time::Instant;

/// Counters of a tile cache.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TileCacheStats {
    /// Lookups served from RAM.
    pub hits: u64,
    /// Lookups that were not.
    pub misses: u64,
    /// Tiles loaded.
    pub loaded: u64,
    /// Tiles found absent.
    pub absent: u64,
    /// Loads that failed.
    pub failed: u64,
    /// Tiles given up after [`MAX_TILE_ATTEMPTS`](crate::cache::MAX_TILE_ATTEMPTS) failures.
    pub given_up: u64,
    /// Requests merged into a queued or running load.
    pub merged: u64,
    /// Tiles evicted to make room.
    pub evicted: u64,
    /// Loads running now.
    pub in_flight: usize,
    /// Loads waiting.
    pub queued: usize,
    /// Mean request-to-arrival time of loaded tiles (ms).
    pub latency_avg_ms: f64,
    /// Longest request-to-arrival time (ms).
    pub latency_max_ms: f64,
}

type Load = Task<Result<Option<TileData>, TileError>>;

/// [`TileCache::load_timeout`]'s default: far beyond any disk or network read of one tile.
pub const DEFAULT_LOAD_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(20);

/// The RAM tile cache of one virtual texture.
pub struct TileCache {
    source: Arc<dyn TileSource>,
    tiles: LruCache<Arc<TileData>>,
    requests: TileRequests,
    requested_at: std::collections::HashMap<TileKey, Instant>,
    /// Running loads and when each started.
    in_flight: Vec<(TileKey, Load, Instant)>,
    /// Loads allowed at once.
    pub max_in_flight: usize,
    /// A load running longer is abandoned and counted as a failure (retried with back-off):
    /// a source that never answers must not hold a load slot forever.
    pub load_timeout: std::time::Duration,
    frame: u64,
    latency_sum_ms: f64,
    /// Counters.
    pub stats: TileCacheStats,
}

impl TileCache {
    /// A cache of `capacity` tiles over `source`.
    pub fn new(source: Arc<dyn TileSource>, capacity: usize) -> Self {
        Self {
            source,
            tiles: LruCache::new(capacity),
            requests: TileRequests::default(),
            requested_at: Default::default(),
            in_flight: Vec::new(),
            max_in_flight: 4,
            load_timeout: DEFAULT_LOAD_TIMEOUT,
            frame: 0,
            latency_sum_ms: 0.0,
            stats: TileCacheStats::default(),
        }
    }

    /// Tiles it holds at most.
    pub fn capacity(&self) -> usize {
        self.tiles.capacity()
    }

    /// Tiles in RAM (at most [`Self::capacity`]).
    pub fn len(&self) -> usize {
        self.tiles.len()
    }

    /// Whether no tile is in RAM.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The source.
    pub fn source(&self) -> &Arc<dyn TileSource> {
        &self.source
    }

    /// The tile, if in RAM; otherwise its load is requested (unless known absent) and `None`
    /// returned.
    pub fn get(&mut self, key: TileKey) -> Option<Arc<TileData>> {
        if let Some(tile) = self.tiles.get(&key) {
            self.stats.hits += 1;
            return Some(tile.clone());
        }
        self.stats.misses += 1;
        if !self.source.may_exist(key) {
            return None;
        }
        if self.requests.request(key, self.frame) {
            self.requested_at.insert(key, Instant::now());
        }
        self.stats.merged = self.requests.merged;
        None
    }

    /// Whether `key` is known not to exist.
    pub fn is_absent(&self, key: TileKey) -> bool {
        !self.source.may_exist(key)
            || self.requests.status(&key) == Some(crate::cache::TileStatus::Absent)
    }

    /// Where a requested tile stands (queued, loading, absent, failed with its back-off).
    pub fn status(&self, key: TileKey) -> Option<crate::cache::TileStatus> {
        self.requests.status(&key)
    }

    /// Frames polled so far.
    pub fn frame(&self) -> u64 {
        self.frame
    }

    /// Whether `key` is in RAM (not counted as a use).
    pub fn contains(&self, key: TileKey) -> bool {
        self.tiles.contains(&key)
    }

    /// Once a frame: collects finished loads and starts queued ones, coarsest first.
    pub fn poll(&mut self) {
        self.frame += 1;
        let mut finished = Vec::new();
        let timeout = self.load_timeout;
        self.in_flight
            .retain_mut(|(key, task, started)| match check_ready(task) {
                Some(result) => {
                    finished.push((*key, result));
                    false
                }
                // Dropping the task cancels it (a load blocked inside the source finishes on
                // its own thread and is discarded).
                None if started.elapsed() > timeout => {
                    finished.push((
                        *key,
                        Err(TileError::TimedOut {
                            key: *key,
                            after: started.elapsed(),
                        }),
                    ));
                    false
                }
                None => true,
            });
        let tile_size = self.source().tile_size();
        for (key, result) in finished {
            // A wrongly sized tile from a custom source is a failure, not a slice out of bounds.
            let result = result.and_then(|tile| match tile {
                Some(t) => t.check(key, tile_size).map(|()| Some(t)),
                None => Ok(None),
            });
            match result {
                Ok(Some(tile)) => {
                    if self.tiles.insert(key, Arc::new(tile)).is_some() {
                        self.stats.evicted += 1;
                    }
                    self.requests.loaded(key);
                    self.stats.loaded += 1;
                    if let Some(t) = self.requested_at.remove(&key) {
                        let ms = t.elapsed().as_secs_f64() * 1e3;
                        self.latency_sum_ms += ms;
                        self.stats.latency_max_ms = self.stats.latency_max_ms.max(ms);
                        self.stats.latency_avg_ms = self.latency_sum_ms / self.stats.loaded as f64;
                    }
                }
                Ok(None) => {
                    self.requests.absent(key);
                    self.requested_at.remove(&key);
                    self.stats.absent += 1;
                }
                Err(e) => {
                    let attempts = self.requests.failed(key, self.frame);
                    let max = crate::cache::MAX_TILE_ATTEMPTS;
                    // One warning when a tile first fails, one when it is given up.
                    if attempts == 1 {
                        warn!("terrain tile {key:?} failed (retried up to {max} times): {e}");
                    } else if attempts == max {
                        warn!(
                            "terrain tile {key:?} given up after {attempts} failures (probed \
                             again every {} frames): {e}",
                            crate::cache::GIVEN_UP_PROBE_FRAMES
                        );
                        self.stats.given_up += 1;
                    } else {
                        bevy::log::debug!("terrain tile {key:?} failed again ({attempts}): {e}");
                    }
                    self.requested_at.remove(&key);
                    self.stats.failed += 1;
                }
            }
        }
        let free = self.max_in_flight.saturating_sub(self.in_flight.len());
        let pool = IoTaskPool::get_or_init(bevy::tasks::TaskPool::new);
        for key in self.requests.next_batch(free) {
            self.in_flight
                .push((key, pool.spawn(self.source.load(key)), Instant::now()));
        }
        self.stats.in_flight = self.in_flight.len();
        self.stats.queued = self.requests.queued();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::{ProceduralTileSource, address_texel};
    use bevy::tasks::BoxedFuture;
    use std::sync::Mutex;

    /// A source recording the order of loads, with one corrupt and one absent tile.
    struct Recording {
        inner: ProceduralTileSource,
        order: Mutex<Vec<TileKey>>,
        corrupt: TileKey,
        absent: TileKey,
    }

    impl TileSource for Recording {
        fn tile_size(&self) -> u32 {
            self.inner.tile_size
        }
        fn levels(&self) -> u32 {
            self.inner.levels
        }
        fn may_exist(&self, key: TileKey) -> bool {
            self.inner.may_exist(key)
        }
        fn load(&self, key: TileKey) -> BoxedFuture<'static, Result<Option<TileData>, TileError>> {
            self.order.lock().unwrap().push(key);
            let (corrupt, absent) = (key == self.corrupt, key == self.absent);
            let inner = self.inner.load(key);
            Box::pin(async move {
                if corrupt {
                    return Err(TileError::Decode("4/1/1.png".into(), "bad CRC".into()));
                }
                if absent {
                    return Ok(None);
                }
                inner.await
            })
        }
    }

    fn key(z: u32, x: u32, y: u32) -> TileKey {
        TileKey { z, x, y }
    }

    fn settle(cache: &mut TileCache) {
        for _ in 0..2000 {
            cache.poll();
            if cache.stats.in_flight == 0 && cache.stats.queued == 0 {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        panic!("loads never finished: {:?}", cache.stats);
    }

    #[test]
    fn loads_coarsest_first_remembers_absent_and_retries_failures() {
        let source = Arc::new(Recording {
            inner: ProceduralTileSource::new(16, 6, address_texel),
            order: Mutex::new(Vec::new()),
            corrupt: key(4, 1, 1),
            absent: key(3, 2, 2),
        });
        let mut cache = TileCache::new(source.clone(), 8);
        cache.max_in_flight = 1;
        for k in [
            key(5, 3, 3),
            key(2, 1, 1),
            key(4, 1, 1),
            key(3, 2, 2),
            key(2, 1, 1),
        ] {
            assert!(cache.get(k).is_none());
        }
        assert_eq!(cache.stats.merged, 1, "the second (2,1,1) request merged");
        settle(&mut cache);
        assert_eq!(
            *source.order.lock().unwrap(),
            vec![key(2, 1, 1), key(3, 2, 2), key(4, 1, 1), key(5, 3, 3)],
            "coarsest level first"
        );
        // Loaded tiles are hits and carry their texels.
        let tile = cache.get(key(5, 3, 3)).unwrap();
        assert_eq!(tile.texel(0, 0), address_texel(5 + 4, 48, 48));
        // The absent tile is remembered: no second load.
        assert!(cache.is_absent(key(3, 2, 2)));
        assert!(cache.get(key(3, 2, 2)).is_none());
        // The corrupt tile failed, waits out its back-off, then is retried.
        assert_eq!(cache.stats.failed, 1);
        let Some(crate::cache::TileStatus::Failed {
            attempts: 1,
            retry_at,
        }) = cache.status(key(4, 1, 1))
        else {
            panic!("{:?}", cache.status(key(4, 1, 1)));
        };
        if cache.frame() < retry_at {
            assert!(cache.get(key(4, 1, 1)).is_none());
            cache.poll();
            assert_eq!(
                cache.stats.in_flight + cache.stats.queued,
                0,
                "not during the back-off"
            );
        }
        while cache.frame() < retry_at {
            cache.poll();
        }
        assert!(cache.get(key(4, 1, 1)).is_none());
        settle(&mut cache);
        assert_eq!(cache.stats.failed, 2, "retried after the back-off");
        let loads = source.order.lock().unwrap().clone();
        assert_eq!(loads.iter().filter(|k| **k == key(3, 2, 2)).count(), 1);
        assert_eq!(loads.iter().filter(|k| **k == key(4, 1, 1)).count(), 2);
        assert!(cache.stats.latency_max_ms >= cache.stats.latency_avg_ms);
    }

    /// A source whose tiles are half the size it claims.
    struct Shrunk;

    impl TileSource for Shrunk {
        fn tile_size(&self) -> u32 {
            16
        }
        fn levels(&self) -> u32 {
            3
        }
        fn may_exist(&self, _: TileKey) -> bool {
            true
        }
        fn load(&self, _: TileKey) -> BoxedFuture<'static, Result<Option<TileData>, TileError>> {
            Box::pin(async {
                Ok(Some(TileData {
                    size: 8,
                    rgba: vec![0; 8 * 8 * 4],
                }))
            })
        }
    }

    #[test]
    fn a_wrongly_sized_tile_from_a_source_fails_instead_of_panicking() {
        let mut cache = TileCache::new(Arc::new(Shrunk), 4);
        assert!(cache.get(key(1, 0, 1)).is_none());
        settle(&mut cache);
        assert_eq!((cache.stats.loaded, cache.stats.failed), (0, 1));
        assert!(!cache.contains(key(1, 0, 1)));
        let error = TileData {
            size: 8,
            rgba: vec![0; 256],
        }
        .check(key(1, 0, 1), 16)
        .unwrap_err()
        .to_string();
        assert!(error.contains("1/0/1") && error.contains("8×8"), "{error}");
    }

    #[test]
    fn the_cache_evicts_beyond_its_capacity() {
        let source = Arc::new(ProceduralTileSource::new(8, 4, address_texel));
        let mut cache = TileCache::new(source, 3);
        for x in 0..5 {
            cache.get(key(3, x, 0));
        }
        settle(&mut cache);
        assert_eq!(cache.stats.loaded, 5);
        assert_eq!(cache.stats.evicted, 2);
        assert!((0..5).filter(|&x| cache.contains(key(3, x, 0))).count() == 3);
    }

    /// Streaming through a source that fails, truncates, mis-sizes, stalls and never answers
    /// (`faults::TileFaults`), against the same flight without faults: nothing panics, the cache
    /// and the loads in flight stay within their bounds, loads that never answer are abandoned
    /// after the timeout (their slots freed), coverage of the working set drops but stays
    /// useful while the faults last, and once they stop every tile arrives (a given-up tile through
    /// its probe).
    #[test]
    fn streaming_degrades_under_faults_and_recovers() {
        use crate::faults::{FaultyTileSource, TileFaults};
        let faults = TileFaults {
            error: 0.15,
            truncated: 0.05,
            wrong_size: 0.05,
            hang: 0.03,
            slow: 0.10,
            spike: std::time::Duration::from_millis(5),
        };
        // The working set of frame f: levels 0–3 over a corner, and a 4 × 4 window of level 5
        // moving a column every 5 frames (a flight): 38 tiles, new ones every few frames.
        let window = |frame: u32| -> Vec<TileKey> {
            let mut keys: Vec<TileKey> = (0..=3u32)
                .flat_map(|z| {
                    let n = ((1u32 << z) / 2).max(1);
                    (0..n).flat_map(move |x| (0..n).map(move |y| key(z, x, y)))
                })
                .collect();
            let x0 = (frame / 5) % 28;
            keys.extend((x0..x0 + 4).flat_map(|x| (0..4).map(move |y| key(5, x, y))));
            keys
        };
        let resident = |cache: &TileCache, keys: &[TileKey]| {
            keys.iter().filter(|k| cache.contains(**k)).count()
        };
        let fly = |faults: TileFaults| {
            let inner: Arc<dyn TileSource> =
                Arc::new(ProceduralTileSource::new(16, 8, address_texel));
            let source = Arc::new(FaultyTileSource::new(inner, faults, 3));
            let mut cache = TileCache::new(source.clone(), 48);
            cache.max_in_flight = 12;
            // Far beyond a procedural tile's load, even on a loaded machine.
            cache.load_timeout = std::time::Duration::from_millis(150);
            let mut coverage = 0.0;
            let mut slowest_poll = std::time::Duration::ZERO;
            for frame in 0..600u32 {
                let keys = window(frame);
                for &k in &keys {
                    let _ = cache.get(k);
                }
                let t = std::time::Instant::now();
                cache.poll();
                slowest_poll = slowest_poll.max(t.elapsed());
                assert!(cache.len() <= cache.capacity(), "{} tiles", cache.len());
                assert!(cache.stats.in_flight <= cache.max_in_flight);
                coverage += resident(&cache, &keys) as f32 / keys.len() as f32 / 600.0;
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            eprintln!(
                "{faults:?}: mean coverage {coverage:.3}; {:?}; {} loads, {} faulted, {} never \
                 answered; slowest poll {slowest_poll:?}",
                cache.stats,
                source
                    .counts
                    .loads
                    .load(std::sync::atomic::Ordering::Relaxed),
                source
                    .counts
                    .faulted
                    .load(std::sync::atomic::Ordering::Relaxed),
                source
                    .counts
                    .hung
                    .load(std::sync::atomic::Ordering::Relaxed),
            );
            (cache, source, coverage)
        };
        let (clean_cache, _, clean) = fly(TileFaults::NONE);
        let (mut cache, source, faulty) = fly(faults);
        let hung = source
            .counts
            .hung
            .load(std::sync::atomic::Ordering::Relaxed);
        // The faults bit: loads failed, some never answered and were abandoned (else their
        // slots would have stopped the stream), and coverage fell — but not below 75 % of the
        // clean flight's, nor the tiles loaded (measured: coverage 0.91 against 0.97, 541
        // tiles against 562; without the timeout the hung loads pile up in the slots: 0.74,
        // 239 tiles, and the stream never recovers).
        assert!(hung > 0 && cache.stats.failed > hung, "{:?}", cache.stats);
        assert!(
            cache.stats.loaded as f32 > 0.75 * clean_cache.stats.loaded as f32,
            "{:?}",
            cache.stats
        );
        assert!(
            faulty < clean && faulty > 0.75 * clean,
            "{faulty} vs {clean}"
        );
        // Recovery: faults off, the last window held still. Every tile arrives, those given
        // up during the faults too (through their probes, within a probe interval).
        source.set_enabled(false);
        let keys = window(599);
        let mut recovered = false;
        let given_up_during_faults = cache.stats.given_up;
        for _ in 0..3000 {
            for &k in &keys {
                let _ = cache.get(k);
            }
            cache.poll();
            assert!(cache.len() <= cache.capacity());
            if resident(&cache, &keys) == keys.len() && cache.stats.in_flight == 0 {
                recovered = true;
                eprintln!(
                    "recovered: {} resident ({given_up_during_faults} tiles given up during \
                     the faults)",
                    keys.len()
                );
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        assert!(recovered, "{:?}", cache.stats);
    }
}
