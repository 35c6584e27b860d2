//! The paper's flight test (Seoane et al. 2007, table 1) as a deterministic simulation
//! of the streaming logic: a camera flies a straight line at constant speed over a virtual
//! texture; every frame the clip stack recentres, tiles arrive from a disk model (latency plus
//! bandwidth, one request at a time, coarsest level first), and subtiles whose tiles are in the
//! RAM cache are uploaded under the per-frame subtile budget, coarsest layer first and in rings.
//!
//! Beyond the paper, tiles are requested for every layer at once (the queue still serves the
//! coarsest first) and one subtile ahead of each window, so the tiles a move needs are usually in
//! RAM when the move happens.
//!
//! It measures what table 1 reports — quality (share of the stack valid) average and minimum,
//! subtiles and tiles per frame, tile latency, upload and disk traffic — for the bookkeeping
//! alone: GPU upload time is represented by the subtile budget (the paper's 1 ms per frame).
//! Beside the paper's slot share it reports the *usable* coverage: the share of each layer's
//! window inside its coverage rectangle (the largest fully valid ring), which is all the shader
//! samples — one invalid subtile near the centre costs a layer little slot share but all of its
//! usable coverage. [`FlightConfig::paper`] is the paper's own setting (21 levels, 0.25 m texels,
//! cold start, a decode stage); prefetch can be switched off.

use crate::cache::{LruCache, TileKey, TileRequests};
use crate::clip::stack::{ClipStack, SubtileUpload, tile_of};
use crate::faults::{Fault, TileFaults};
use std::collections::HashMap;

/// A disk: each tile takes `latency_ms` plus its size over the bandwidth, one at a time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiskModel {
    /// Per-request latency (ms): seek and open.
    pub latency_ms: f64,
    /// Sustained read rate (bytes per second).
    pub bytes_per_second: f64,
    /// Bytes read per tile (compressed size on disk).
    pub tile_bytes: u64,
}

/// A flight.
#[derive(Clone, Debug, PartialEq)]
pub struct FlightConfig {
    /// Virtual-texture levels (level i is 2^i texels wide).
    pub levels: u32,
    /// Tile side (texels).
    pub tile_size: u32,
    /// Clip size c.
    pub clip_size: u32,
    /// Subtile size s.
    pub subtile_size: u32,
    /// Subtiles uploaded per frame at most (the paper's 1 ms budget).
    pub subtiles_per_frame: u32,
    /// RAM cache (tiles).
    pub cache_tiles: usize,
    /// Frames per second of the simulated clock.
    pub fps: f64,
    /// Camera speed (m/s).
    pub speed_m_s: f64,
    /// Metres per texel of the finest level.
    pub metres_per_texel: f64,
    /// The disk.
    pub disk: DiskModel,
    /// Frames simulated.
    pub frames: u32,
    /// Request the tiles one subtile beyond each window too (what the next move will need).
    pub prefetch: bool,
    /// Start with an empty stack and cache (a scene just loaded) instead of a full, warm one.
    pub cold_start: bool,
    /// Time to decode an arrived tile before it can be uploaded (ms; one decoder, serial).
    pub decode_ms: f64,
    /// Shift each level's subtile grid ([`ClipStack::grid_shift`]).
    pub grid_shift: bool,
    /// Faults injected into the disk's reads ([`TileFaults`]; none by default): a failed read
    /// (error, truncated or mis-sized tile) costs its disk time and is retried after the tile
    /// cache's back-off; a read that never answers holds the disk until [`Self::load_timeout_s`]
    /// and fails; a slow one takes the spike longer.
    pub faults: TileFaults,
    /// How long a read that never answers holds the disk before it is abandoned (s).
    pub load_timeout_s: f64,
}

impl FlightConfig {
    /// The paper's own setting (§5, table 1): 2^20 × 2^20 texels in 21 levels with 0.25 m texels
    /// at the finest (its insets), 512² tiles, clip 1024 (its test), 128² subtiles, 250 m/s, from
    /// a cold start, with a decode stage (8 ms a 512² tile: a JPEG on one core of the time — an
    /// assumption, the paper gives none) before a tile can be uploaded.
    pub fn paper() -> Self {
        Self {
            levels: 21,
            metres_per_texel: 0.25,
            cold_start: true,
            decode_ms: 8.0,
            ..Self::default()
        }
    }
}

impl Default for FlightConfig {
    /// Table 1's setting: 250 m/s, tile 512, clip 1024, subtile 128, 20 levels (2^19 texels of
    /// 0.5 m: 262 km), a disk of about 53 MB/s with 8 ms per request, a 256-tile cache, one
    /// minute at 60 fps. The paper's 1 ms of texture updates a frame is taken as 16 subtiles
    /// (1 MiB): a texture upload of 1 GB/s, well under what a PCIe GPU sustains.
    fn default() -> Self {
        Self {
            levels: 20,
            tile_size: 512,
            clip_size: 1024,
            subtile_size: 128,
            subtiles_per_frame: 16,
            cache_tiles: 256,
            fps: 60.0,
            speed_m_s: 250.0,
            metres_per_texel: 0.5,
            disk: DiskModel {
                latency_ms: 8.0,
                bytes_per_second: 53.0e6,
                tile_bytes: 512 * 512 * 4 / 3,
            },
            frames: 3600,
            prefetch: true,
            cold_start: false,
            decode_ms: 0.0,
            grid_shift: true,
            faults: TileFaults::NONE,
            load_timeout_s: 2.0,
        }
    }
}

/// What a flight measured.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlightReport {
    /// Mean share of the stack valid (0–1).
    pub quality_avg: f64,
    /// Lowest share of the stack valid in any frame.
    pub quality_min: f64,
    /// Mean usable coverage: the share of the windowed layers' area inside their coverage
    /// rectangles (what the shader samples), with the base level counted as one full layer.
    pub usable_avg: f64,
    /// Lowest usable coverage in any frame.
    pub usable_min: f64,
    /// Subtiles uploaded per frame, mean.
    pub subtiles_per_frame_avg: f64,
    /// Most subtiles uploaded in one frame.
    pub subtiles_per_frame_max: u32,
    /// Tiles read per frame, mean.
    pub tiles_per_frame_avg: f64,
    /// Request-to-arrival time of tiles, mean (ms).
    pub tile_latency_avg_ms: f64,
    /// Longest request-to-arrival time (ms).
    pub tile_latency_max_ms: f64,
    /// Texture upload traffic (MB/s).
    pub upload_mb_s: f64,
    /// Disk traffic (MB/s).
    pub disk_mb_s: f64,
    /// Reads that failed (injected [`FlightConfig::faults`]), retried after a back-off.
    pub failed_reads: u64,
    /// Tiles given up after [`MAX_TILE_ATTEMPTS`](crate::cache::MAX_TILE_ATTEMPTS) failed reads.
    pub given_up: u64,
}

/// The seed of the flight's fault draws (fixed: a flight is a deterministic simulation).
const FLIGHT_FAULT_SEED: u64 = 0x5EED;

/// Flies `config` and reports table 1's figures.
pub fn simulate_flight(config: &FlightConfig) -> FlightReport {
    let side_m = config.metres_per_texel * 2f64.powi(config.levels as i32 - 1);
    // A diagonal line through the middle of the texture, starting a quarter in.
    let uv_at = |t: f64| {
        let d = config.speed_m_s * t / side_m / std::f64::consts::SQRT_2;
        [0.25 + d, 0.3 + d]
    };
    let mut stack = ClipStack::new(
        config.levels,
        config.clip_size,
        config.subtile_size,
        uv_at(0.0),
    );
    stack.grid_shift = config.grid_shift;
    stack.recenter(uv_at(0.0));
    let mut cache: LruCache<()> = LruCache::new(config.cache_tiles);
    let mut requests = TileRequests::default();
    let mut requested_at: HashMap<TileKey, f64> = HashMap::new();
    // Reads under way: (done at, tile, whether it fails).
    let mut in_flight: Vec<(f64, TileKey, bool)> = Vec::new();
    let (mut reads, mut failed_reads, mut given_up) = (0u64, 0u64, 0u64);
    let mut disk_free_at = 0.0f64;
    let (mut quality_sum, mut quality_min) = (0.0f64, f64::INFINITY);
    let (mut usable_sum, mut usable_min) = (0.0f64, f64::INFINITY);
    // Arrived tiles wait for the decoder: (decoded at, tile).
    let mut decoding: Vec<(f64, TileKey)> = Vec::new();
    let mut decoder_free_at = 0.0f64;
    let (mut subtiles, mut subtiles_max, mut tiles) = (0u64, 0u32, 0u64);
    let (mut latency_sum, mut latency_max) = (0.0f64, 0.0f64);
    let dt = 1.0 / config.fps;
    // Warm-up: the stack starts full and the tiles of each window and its one-subtile margin
    // are cached, as after loading a scene; a cold start skips it.
    let warm_layers = if config.cold_start {
        0
    } else {
        stack.layers.len()
    };
    for (i, layer) in stack.layers.iter_mut().enumerate().take(warm_layers) {
        for s in layer.invalid_in_ring_order() {
            layer.set_state(s, crate::clip::layer::SlotState::Valid);
        }
        let (min, max) = layer.window();
        for y in (min[1] - 1).max(0)..(max[1] + 1).min(layer.level_subtiles) {
            for x in (min[0] - 1).max(0)..(max[0] + 1).min(layer.level_subtiles) {
                let upload = SubtileUpload {
                    layer: i + 1,
                    level: layer.level,
                    subtile: [x, y],
                };
                cache.insert(tile_of(&upload, config.tile_size, config.subtile_size), ());
            }
        }
    }
    for frame in 0..config.frames as u64 {
        let now = frame as f64 * dt;
        stack.recenter(uv_at(now));
        // Tiles that arrived.
        // Tiles read from disk go to the decoder, one at a time.
        in_flight.retain(|&(done, key, failed)| {
            if done <= now && failed {
                failed_reads += 1;
                if requests.failed(key, frame) == crate::cache::MAX_TILE_ATTEMPTS {
                    given_up += 1;
                }
                false
            } else if done <= now {
                let start = decoder_free_at.max(done);
                decoder_free_at = start + config.decode_ms / 1e3;
                decoding.push((decoder_free_at, key));
                false
            } else {
                true
            }
        });
        decoding.retain(|&(decoded, key)| {
            if decoded <= now {
                cache.insert(key, ());
                requests.loaded(key);
                let latency = (decoded - requested_at.remove(&key).unwrap_or(decoded)) * 1e3;
                latency_sum += latency;
                latency_max = latency_max.max(latency);
                tiles += 1;
                false
            } else {
                true
            }
        });
        // Requests: every layer's missing tiles, and the tiles one subtile beyond each window
        // (what the next move will need), coarsest level first — the queue orders them.
        let margin = config.prefetch as i64;
        for (i, layer) in stack.layers.iter().enumerate() {
            let (min, max) = layer.window();
            for y in min[1] - margin..max[1] + margin {
                for x in min[0] - margin..max[0] + margin {
                    if x < 0 || y < 0 || x >= layer.level_subtiles || y >= layer.level_subtiles {
                        continue;
                    }
                    let inside = layer.in_window([x, y]);
                    if inside
                        && layer
                            .slot([x, y])
                            .is_some_and(|s| s.state == crate::clip::layer::SlotState::Valid)
                    {
                        continue;
                    }
                    let upload = SubtileUpload {
                        layer: i + 1,
                        level: layer.level,
                        subtile: [x, y],
                    };
                    let tile = tile_of(&upload, config.tile_size, config.subtile_size);
                    if !cache.contains(&tile) && requests.request(tile, frame) {
                        requested_at.insert(tile, now);
                    }
                }
            }
        }
        // Uploads: the first incomplete layer (coarsest first), rings from the centre; a subtile
        // whose tile is not in RAM yet waits for it.
        let uploaded = stack
            .plan_available(config.subtiles_per_frame, |u| {
                cache
                    .get(&tile_of(u, config.tile_size, config.subtile_size))
                    .is_some()
            })
            .len() as u32;
        // The disk serves queued requests one at a time, coarsest first.
        // Only what the disk can start before the next frame leaves the queue, so a coarse tile
        // requested later still overtakes finer ones queued earlier.
        while disk_free_at < now + dt {
            let Some(&key) = requests.next_batch(1).first() else {
                break;
            };
            let start = disk_free_at.max(now);
            let mut done = start
                + config.disk.latency_ms / 1e3
                + config.disk.tile_bytes as f64 / config.disk.bytes_per_second;
            let fault = config.faults.draw(FLIGHT_FAULT_SEED, key, reads);
            reads += 1;
            let failed = match fault {
                Fault::None => false,
                Fault::Slow => {
                    done += config.faults.spike.as_secs_f64();
                    false
                }
                Fault::Hang => {
                    done = start + config.load_timeout_s.max(0.0);
                    true
                }
                Fault::Error | Fault::Truncated | Fault::WrongSize => true,
            };
            disk_free_at = done;
            in_flight.push((done, key, failed));
        }
        let q = stack.quality() as f64;
        quality_sum += q;
        quality_min = quality_min.min(q);
        let u = stack.usable_coverage();
        usable_sum += u;
        usable_min = usable_min.min(u);
        subtiles += uploaded as u64;
        subtiles_max = subtiles_max.max(uploaded);
    }
    let frames = config.frames.max(1) as f64;
    let seconds = frames * dt;
    let subtile_bytes = (config.subtile_size * config.subtile_size * 4) as f64;
    FlightReport {
        quality_avg: quality_sum / frames,
        quality_min,
        usable_avg: usable_sum / frames,
        usable_min,
        subtiles_per_frame_avg: subtiles as f64 / frames,
        subtiles_per_frame_max: subtiles_max,
        tiles_per_frame_avg: tiles as f64 / frames,
        tile_latency_avg_ms: if tiles > 0 {
            latency_sum / tiles as f64
        } else {
            0.0
        },
        tile_latency_max_ms: latency_max,
        upload_mb_s: subtiles as f64 * subtile_bytes / seconds / 1e6,
        disk_mb_s: tiles as f64 * config.disk.tile_bytes as f64 / seconds / 1e6,
        failed_reads,
        given_up,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_1_flight_keeps_the_stack_valid() {
        // Table 1's setting, 20 s of flight (5 km), with a quarter of the default budget: 4
        // subtiles (256 KiB) a frame.
        let report = simulate_flight(&FlightConfig {
            frames: 1200,
            subtiles_per_frame: 4,
            ..Default::default()
        });
        eprintln!("{report:?}");
        assert!(report.quality_avg >= 0.99, "{report:?}");
        assert!(report.quality_min >= 0.95, "{report:?}");
        assert!(report.subtiles_per_frame_max <= 4);
        assert!(report.tiles_per_frame_avg > 0.0, "tiles were streamed");
        // One subtile a frame (the paper's average) cannot keep up: the budget matters.
        let starved = simulate_flight(&FlightConfig {
            frames: 1200,
            subtiles_per_frame: 1,
            ..Default::default()
        });
        assert!(starved.quality_min < report.quality_min, "{starved:?}");
    }

    #[test]
    fn a_slow_disk_shows_in_the_quality() {
        let slow = simulate_flight(&FlightConfig {
            frames: 600,
            speed_m_s: 2500.0,
            disk: DiskModel {
                latency_ms: 80.0,
                bytes_per_second: 2.0e6,
                tile_bytes: 512 * 512 * 4 / 3,
            },
            ..Default::default()
        });
        let fast = simulate_flight(&FlightConfig {
            frames: 600,
            speed_m_s: 2500.0,
            ..Default::default()
        });
        assert!(slow.quality_min < fast.quality_min, "{slow:?} vs {fast:?}");
        assert!(slow.quality_avg < fast.quality_avg);
        assert!(slow.tiles_per_frame_avg < fast.tiles_per_frame_avg);
    }

    #[test]
    fn usable_coverage_never_exceeds_the_slot_share_and_a_cold_start_shows() {
        let short = |config: FlightConfig| {
            simulate_flight(&FlightConfig {
                frames: 600,
                ..config
            })
        };
        let warm = short(FlightConfig::default());
        let cold = short(FlightConfig {
            cold_start: true,
            ..Default::default()
        });
        let paper = short(FlightConfig::paper());
        let no_prefetch = short(FlightConfig {
            prefetch: false,
            ..FlightConfig::paper()
        });
        for r in [&warm, &cold, &paper, &no_prefetch] {
            eprintln!("{r:?}");
            // The coverage rectangle is a fully valid region: never more than the valid slots.
            assert!(r.usable_avg <= r.quality_avg + 1e-9 && r.usable_min <= r.quality_min + 1e-9);
        }
        // A cold stack starts with the base level alone.
        let base_only =
            1.0 / (ClipStack::new(20, 1024, 128, [0.25, 0.3]).layers.len() as f64 + 1.0);
        assert!((cold.usable_min - base_only).abs() < 1e-9, "{cold:?}");
        assert!(cold.quality_avg < warm.quality_avg);
        // Decoding adds to every tile's latency.
        let no_decode = short(FlightConfig {
            decode_ms: 0.0,
            ..FlightConfig::paper()
        });
        assert!(paper.tile_latency_avg_ms > no_decode.tile_latency_avg_ms);
    }

    #[test]
    fn the_per_level_grid_shift_spreads_the_invalidations() {
        // Without the shift every level's subtile boundaries nest, so a crossing invalidates a
        // strip in several layers in the same frame: the usable coverage dips.
        let fly = |grid_shift| {
            simulate_flight(&FlightConfig {
                frames: 1200,
                grid_shift,
                ..Default::default()
            })
        };
        let (shifted, nested) = (fly(true), fly(false));
        eprintln!("shifted {shifted:?}\nnested {nested:?}");
        assert!(
            nested.usable_min < shifted.usable_min,
            "{nested:?} vs {shifted:?}"
        );
        assert!(nested.quality_min < shifted.quality_min);
    }

    #[test]
    fn subtiles_map_to_their_tiles() {
        let u = SubtileUpload {
            layer: 3,
            level: 13,
            subtile: [9, 4],
        };
        // Level 13 with 512 tiles is pyramid level 4; 4 subtiles of 128 per tile.
        assert_eq!(tile_of(&u, 512, 128), TileKey { z: 4, x: 2, y: 1 });
    }

    /// The same flight with the disk failing, stalling and never answering now and then
    /// (`TileFaults::hostile`: 15 % errors, 5 % truncated, 5 % mis-sized, 3 % hung until the 2 s
    /// timeout, 10 % 200 ms late): quality drops but the stream goes on — every failure is
    /// retried, no frame waits — and it stays close to the clean flight's (measured: quality
    /// 0.90 against 1.0, usable coverage 0.85 against 1.0, 107 failed reads, none given up).
    #[test]
    fn a_faulty_disk_degrades_quality_gracefully() {
        let config = FlightConfig {
            frames: 1800,
            ..Default::default()
        };
        let clean = simulate_flight(&config);
        let faulty = simulate_flight(&FlightConfig {
            faults: TileFaults::hostile(),
            ..config
        });
        eprintln!("clean {clean:?}\nfaulty {faulty:?}");
        assert_eq!((clean.failed_reads, clean.given_up), (0, 0));
        assert!(faulty.failed_reads > 20, "{faulty:?}");
        assert!(
            faulty.quality_avg < clean.quality_avg,
            "the faults cost something"
        );
        assert!(
            faulty.quality_avg > 0.9 * clean.quality_avg
                && faulty.usable_avg > 0.8 * clean.usable_avg,
            "{faulty:?}"
        );
    }
}
