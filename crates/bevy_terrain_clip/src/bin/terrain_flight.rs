//! The paper's flight test (table 1) on the streaming logic, simulated: prints one JSON object
//! per configuration. See `bevy_terrain_clip::flight`.
//!
//! ```text
//! cargo run -p bevy_terrain_clip --bin terrain_flight -- [--paper] [--cold] [--no-prefetch]
//!     [--no-grid-shift] [--faults]
//!     [--speed M_S] [--subtiles N] [--frames N] [--latency-ms MS] [--disk-mb-s MB]
//!     [--decode-ms MS] [--stats FILE]
//! ```
//!
//! `--paper` starts from the paper's own setting (`FlightConfig::paper`: 21 levels, 0.25 m
//! texels, cold start, 8 ms decode) instead of this crate's default (20 levels, 0.5 m, warm).
//! `--faults` makes the disk fail, stall and hang now and then (`TileFaults::hostile`: 15 %
//! errors, 5 % truncated, 5 % mis-sized, 3 % never answering until the 2 s timeout, 10 % 200 ms
//! late); the JSON then counts `failed_reads` and `given_up`.
//! `--stats FILE` flies the configuration given and, beside it, the paper's setting with and
//! without prefetch and the per-level grid shift, and the default warm (with and without the
//! shift) and cold, and writes
//! `{"runs": [{"config", "quality_avg", "quality_min", "usable_avg", "usable_min", …}]}`.

use bevy_terrain_clip::flight::{FlightConfig, FlightReport, simulate_flight};

fn run_json(name: &str, config: &FlightConfig, r: &FlightReport) -> String {
    format!(
        "{{\"config\": \"{name}\", \"levels\": {}, \"metres_per_texel\": {}, \"tile\": {}, \"clip\": {}, \"subtile\": {}, \"speed_m_s\": {}, \"subtiles_budget\": {}, \"disk_latency_ms\": {}, \"disk_mb_s\": {:.1}, \"decode_ms\": {}, \"prefetch\": {}, \"grid_shift\": {}, \"cold_start\": {}, \"frames\": {}, \"quality_avg\": {:.4}, \"quality_min\": {:.4}, \"usable_avg\": {:.4}, \"usable_min\": {:.4}, \"subtiles_per_frame_avg\": {:.2}, \"subtiles_per_frame_max\": {}, \"tiles_per_frame_avg\": {:.3}, \"tile_latency_avg_ms\": {:.1}, \"tile_latency_max_ms\": {:.1}, \"upload_mb_s\": {:.2}, \"disk_read_mb_s\": {:.2}, \"failed_reads\": {}, \"given_up\": {}}}",
        config.levels,
        config.metres_per_texel,
        config.tile_size,
        config.clip_size,
        config.subtile_size,
        config.speed_m_s,
        config.subtiles_per_frame,
        config.disk.latency_ms,
        config.disk.bytes_per_second / 1e6,
        config.decode_ms,
        config.prefetch,
        config.grid_shift,
        config.cold_start,
        config.frames,
        r.quality_avg,
        r.quality_min,
        r.usable_avg,
        r.usable_min,
        r.subtiles_per_frame_avg,
        r.subtiles_per_frame_max,
        r.tiles_per_frame_avg,
        r.tile_latency_avg_ms,
        r.tile_latency_max_ms,
        r.upload_mb_s,
        r.disk_mb_s,
        r.failed_reads,
        r.given_up
    )
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut flag = |name: &str| {
        let found = args.iter().any(|a| a == name);
        args.retain(|a| a != name);
        found
    };
    let mut config = if flag("--paper") {
        FlightConfig::paper()
    } else {
        FlightConfig::default()
    };
    if flag("--cold") {
        config.cold_start = true;
    }
    if flag("--no-prefetch") {
        config.prefetch = false;
    }
    if flag("--no-grid-shift") {
        config.grid_shift = false;
    }
    if flag("--faults") {
        config.faults = bevy_terrain_clip::faults::TileFaults::hostile();
    }
    let mut stats = None;
    let mut it = args.into_iter();
    while let Some(flag) = it.next() {
        let value = it.next().unwrap_or_default();
        if flag == "--stats" {
            stats = Some(value);
            continue;
        }
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
            "--decode-ms" => config.decode_ms = number,
            _ => {
                eprintln!(
                    "unknown flag {flag}; flags: --paper --cold --no-prefetch --no-grid-shift \
                     --speed --subtiles --frames --latency-ms --disk-mb-s --decode-ms --stats"
                );
                std::process::exit(2)
            }
        }
    }
    let given = run_json("given", &config, &simulate_flight(&config));
    println!("{given}");
    let Some(path) = stats else {
        return;
    };
    let frames = config.frames;
    let others = [
        ("paper", FlightConfig::paper()),
        (
            "paper_no_prefetch",
            FlightConfig {
                prefetch: false,
                ..FlightConfig::paper()
            },
        ),
        (
            "paper_no_grid_shift",
            FlightConfig {
                grid_shift: false,
                ..FlightConfig::paper()
            },
        ),
        ("default_warm", FlightConfig::default()),
        (
            "default_warm_no_grid_shift",
            FlightConfig {
                grid_shift: false,
                ..FlightConfig::default()
            },
        ),
        (
            "default_cold",
            FlightConfig {
                cold_start: true,
                ..FlightConfig::default()
            },
        ),
    ];
    let mut runs = vec![given];
    for (name, other) in others {
        let other = FlightConfig { frames, ..other };
        let line = run_json(name, &other, &simulate_flight(&other));
        println!("{line}");
        runs.push(line);
    }
    let text = format!("{{\"runs\": [\n  {}\n]}}\n", runs.join(",\n  "));
    // Written whole or not at all.
    let tmp = format!("{path}.tmp");
    if let Err(e) = std::fs::write(&tmp, &text).and_then(|()| std::fs::rename(&tmp, &path)) {
        eprintln!("{path}: {e}");
        std::process::exit(1)
    }
}
