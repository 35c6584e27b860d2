//! The paper's flight test (table 1) on the streaming logic, simulated: prints one JSON object
//! per configuration. See `bevy_terrain_clip::flight`.
//!
//! ```text
//! cargo run -p bevy_terrain_clip --bin terrain_flight -- [--speed M_S] [--subtiles N]
//!     [--frames N] [--latency-ms MS] [--disk-mb-s MB]
//! ```

use bevy_terrain_clip::flight::{FlightConfig, simulate_flight};

fn main() {
    let mut config = FlightConfig::default();
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let value = args.next().unwrap_or_default();
        let number: f64 = value.parse().unwrap_or_else(|_| {
            eprintln!("{flag} takes a number, not '{value}'");
            std::process::exit(2)
        });
        match flag.as_str() {
            "--speed" => config.speed_m_s = number,
            "--subtiles" => config.subtiles_per_frame = number as u32,
            "--frames" => config.frames = number as u32,
            "--latency-ms" => config.disk.latency_ms = number,
            "--disk-mb-s" => config.disk.bytes_per_second = number * 1e6,
            _ => {
                eprintln!(
                    "unknown flag {flag}; flags: --speed --subtiles --frames --latency-ms --disk-mb-s"
                );
                std::process::exit(2)
            }
        }
    }
    let r = simulate_flight(&config);
    println!(
        "{{\"levels\": {}, \"tile\": {}, \"clip\": {}, \"subtile\": {}, \"speed_m_s\": {}, \"subtiles_budget\": {}, \"disk_latency_ms\": {}, \"disk_mb_s\": {:.1}, \"frames\": {}, \"quality_avg_pct\": {:.2}, \"quality_min_pct\": {:.2}, \"subtiles_per_frame_avg\": {:.2}, \"subtiles_per_frame_max\": {}, \"tiles_per_frame_avg\": {:.3}, \"tile_latency_avg_ms\": {:.1}, \"tile_latency_max_ms\": {:.1}, \"upload_mb_s\": {:.2}, \"disk_read_mb_s\": {:.2}}}",
        config.levels,
        config.tile_size,
        config.clip_size,
        config.subtile_size,
        config.speed_m_s,
        config.subtiles_per_frame,
        config.disk.latency_ms,
        config.disk.bytes_per_second / 1e6,
        config.frames,
        r.quality_avg * 100.0,
        r.quality_min * 100.0,
        r.subtiles_per_frame_avg,
        r.subtiles_per_frame_max,
        r.tiles_per_frame_avg,
        r.tile_latency_avg_ms,
        r.tile_latency_max_ms,
        r.upload_mb_s,
        r.disk_mb_s
    );
}
