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

/// The RAM tile cache of one virtual texture.
pub struct TileCache {
    source: Arc<dyn TileSource>,
    tiles: LruCache<Arc<TileData>>,
    requests: TileRequests,
    requested_at: std::collections::HashMap<TileKey, Instant>,
    in_flight: Vec<(TileKey, Load)>,
    /// Loads allowed at once.
    pub max_in_flight: usize,
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
            frame: 0,
            latency_sum_ms: 0.0,
            stats: TileCacheStats::default(),
        }
    }

    /// Tiles it holds at most.
    pub fn capacity(&self) -> usize {
        self.tiles.capacity()
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
        self.in_flight
            .retain_mut(|(key, task)| match check_ready(task) {
                Some(result) => {
                    finished.push((*key, result));
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
                    } else if attempts >= max {
                        warn!("terrain tile {key:?} given up after {attempts} failures: {e}");
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
                .push((key, pool.spawn(self.source.load(key))));
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
}
