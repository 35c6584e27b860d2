//! A [`TileSource`] that injects faults into another, to test and measure streaming under the
//! failures real sources have: latency spikes, errors, truncated and wrongly sized tiles, and
//! loads that never answer. Each load draws its fate from a seeded hash of the tile and how
//! many times that tile was loaded before, so a tile's n-th load meets the same fault in every
//! run, whatever order the cache asks for tiles in (a count over all loads would hand the
//! faults to other tiles as soon as one load finished a frame earlier); the faults can be
//! switched off mid-run to watch the terrain recover.

use crate::cache::TileKey;
use crate::source::{TexelKind, TileData, TileError, TileSource};
use bevy::tasks::BoxedFuture;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How often each fault strikes (fractions of loads, summing to at most 1) and how long a
/// latency spike lasts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileFaults {
    /// Loads that fail with an I/O error.
    pub error: f32,
    /// Loads that return half the tile's bytes.
    pub truncated: f32,
    /// Loads that return a tile of half the side.
    pub wrong_size: f32,
    /// Loads that never answer.
    pub hang: f32,
    /// Loads that answer correctly after [`Self::spike`].
    pub slow: f32,
    /// How long a slow load takes.
    pub spike: Duration,
}

impl TileFaults {
    /// No faults.
    pub const NONE: Self = Self {
        error: 0.0,
        truncated: 0.0,
        wrong_size: 0.0,
        hang: 0.0,
        slow: 0.0,
        spike: Duration::ZERO,
    };

    /// A bad network: 15 % errors, 5 % truncated, 5 % wrongly sized, 3 % never answer, 10 %
    /// take 200 ms.
    pub fn hostile() -> Self {
        Self {
            error: 0.15,
            truncated: 0.05,
            wrong_size: 0.05,
            hang: 0.03,
            slow: 0.10,
            spike: Duration::from_millis(200),
        }
    }
}

/// What one load does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Fault {
    /// Answers as the inner source does.
    None,
    /// An I/O error.
    Error,
    /// Half the tile's bytes.
    Truncated,
    /// A tile of half the side.
    WrongSize,
    /// Never answers.
    Hang,
    /// Answers after the spike.
    Slow,
}

/// Counts of the faults injected so far.
#[derive(Debug, Default)]
pub struct FaultCounts {
    /// Loads asked for.
    pub loads: AtomicU64,
    /// Loads given a fault.
    pub faulted: AtomicU64,
    /// Loads that will never answer.
    pub hung: AtomicU64,
}

/// A [`TileSource`] injecting [`TileFaults`] into `inner`'s loads.
pub struct FaultyTileSource {
    inner: Arc<dyn TileSource>,
    faults: TileFaults,
    seed: u64,
    enabled: AtomicBool,
    /// Loads asked for so far, per tile.
    loads_of: Mutex<HashMap<TileKey, u64>>,
    /// What was injected.
    pub counts: FaultCounts,
}

impl FaultyTileSource {
    /// `inner` with `faults`, drawn from `seed`.
    pub fn new(inner: Arc<dyn TileSource>, faults: TileFaults, seed: u64) -> Self {
        Self {
            inner,
            faults,
            seed,
            enabled: AtomicBool::new(true),
            loads_of: Mutex::new(HashMap::new()),
            counts: FaultCounts::default(),
        }
    }

    /// Switches the faults on or off (loads already hanging keep hanging).
    pub fn set_enabled(&self, enabled: bool) {
        self.enabled.store(enabled, Ordering::Relaxed);
    }

    /// The fault of load number `n` of `key` (counted from 0 for each tile).
    pub fn fault(&self, key: TileKey, n: u64) -> Fault {
        if !self.enabled.load(Ordering::Relaxed) {
            return Fault::None;
        }
        self.faults.draw(self.seed, key, n)
    }
}

impl TileFaults {
    /// The fault of load number `n` of `key` in a run seeded `seed`: a uniform draw from a hash
    /// of the three (SplitMix64's finaliser), placed among the rates.
    pub fn draw(&self, seed: u64, key: TileKey, n: u64) -> Fault {
        let mix = |mut z: u64| {
            z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        };
        let mut h = mix(seed);
        for v in [key.z as u64, key.x as u64, key.y as u64, n] {
            h = mix(h ^ v);
        }
        let u = (h >> 40) as f32 / (1u64 << 24) as f32;
        let mut edge = 0.0;
        for (rate, fault) in [
            (self.error, Fault::Error),
            (self.truncated, Fault::Truncated),
            (self.wrong_size, Fault::WrongSize),
            (self.hang, Fault::Hang),
            (self.slow, Fault::Slow),
        ] {
            edge += rate.max(0.0);
            if u < edge {
                return fault;
            }
        }
        Fault::None
    }
}

impl TileSource for FaultyTileSource {
    fn tile_size(&self) -> u32 {
        self.inner.tile_size()
    }
    fn levels(&self) -> u32 {
        self.inner.levels()
    }
    fn may_exist(&self, key: TileKey) -> bool {
        self.inner.may_exist(key)
    }
    fn texels(&self) -> TexelKind {
        self.inner.texels()
    }
    fn load(&self, key: TileKey) -> BoxedFuture<'static, Result<Option<TileData>, TileError>> {
        self.counts.loads.fetch_add(1, Ordering::Relaxed);
        let n = {
            // A poisoned lock only means another load panicked mid-count; the counts are
            // still whole numbers, so carry on with them.
            let mut loads_of = self.loads_of.lock().unwrap_or_else(|e| e.into_inner());
            let n = loads_of.entry(key).or_insert(0);
            *n += 1;
            *n - 1
        };
        let fault = self.fault(key, n);
        if fault != Fault::None {
            self.counts.faulted.fetch_add(1, Ordering::Relaxed);
        }
        if fault == Fault::Hang {
            self.counts.hung.fetch_add(1, Ordering::Relaxed);
            return Box::pin(std::future::pending());
        }
        let inner = self.inner.load(key);
        let spike = self.faults.spike;
        Box::pin(async move {
            match fault {
                Fault::Error => {
                    return Err(TileError::Io(
                        PathBuf::from(format!("injected/{}/{}/{}", key.z, key.x, key.y)),
                        std::io::Error::other("injected fault"),
                    ));
                }
                // A slow disk or network: the IO thread is held for the spike.
                Fault::Slow => std::thread::sleep(spike),
                _ => {}
            }
            let tile = inner.await?;
            Ok(tile.map(|mut t| {
                match fault {
                    Fault::Truncated => t.rgba.truncate(t.rgba.len() / 2),
                    Fault::WrongSize => {
                        t.size /= 2;
                        t.rgba.truncate((t.size * t.size * 4) as usize);
                    }
                    _ => {}
                }
                t
            }))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::{ProceduralTileSource, address_texel};

    #[test]
    fn faults_strike_at_their_rates_and_stop_when_switched_off() {
        let inner: Arc<dyn TileSource> = Arc::new(ProceduralTileSource::new(16, 8, address_texel));
        let source = FaultyTileSource::new(inner, TileFaults::hostile(), 5);
        let mut counts = std::collections::HashMap::new();
        for n in 0..20_000u64 {
            let key = TileKey {
                z: 7,
                x: (n % 128) as u32,
                y: (n / 128 % 128) as u32,
            };
            *counts.entry(source.fault(key, n)).or_insert(0u32) += 1;
        }
        let rate = |f| counts.get(&f).copied().unwrap_or(0) as f32 / 20_000.0;
        let h = TileFaults::hostile();
        for (fault, want) in [
            (Fault::Error, h.error),
            (Fault::Truncated, h.truncated),
            (Fault::WrongSize, h.wrong_size),
            (Fault::Hang, h.hang),
            (Fault::Slow, h.slow),
        ] {
            assert!(
                (rate(fault) - want).abs() < 0.01,
                "{fault:?}: {}",
                rate(fault)
            );
        }
        // The same load, the same fate.
        let key = TileKey { z: 3, x: 1, y: 2 };
        assert_eq!(source.fault(key, 9), source.fault(key, 9));
        source.set_enabled(false);
        assert!((0..1000).all(|n| source.fault(key, n) == Fault::None));
    }

    #[test]
    fn a_tiles_fates_do_not_depend_on_the_loads_of_other_tiles() {
        // Errors only, so every load answers at once: the fates can be read off the results.
        let faults = TileFaults {
            error: 0.5,
            ..TileFaults::NONE
        };
        let fates = |others_between: u32| {
            let inner: Arc<dyn TileSource> =
                Arc::new(ProceduralTileSource::new(16, 8, address_texel));
            let source = FaultyTileSource::new(inner, faults, 9);
            let key = TileKey { z: 4, x: 3, y: 5 };
            (0..12)
                .map(|i| {
                    for j in 0..others_between {
                        let other = TileKey { z: 5, x: j, y: i };
                        let _ = bevy::tasks::block_on(source.load(other));
                    }
                    bevy::tasks::block_on(source.load(key)).is_err()
                })
                .collect::<Vec<bool>>()
        };
        let alone = fates(0);
        assert!(
            alone.contains(&true) && alone.contains(&false),
            "both fates drawn: {alone:?}"
        );
        assert_eq!(alone, fates(3));
        assert_eq!(alone, fates(7));
    }
}
