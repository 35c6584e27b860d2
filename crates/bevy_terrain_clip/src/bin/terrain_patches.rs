//! The seamless-patch selection on the CPU along a flight (paper 4, tables 1–2): for the precision
//! factors ρ0 and 2ρ0, with and without hierarchical frustum culling, the patches traversed,
//! rendered and culled, the triangles drawn, and the CPU time of the selection per frame. The
//! flight crosses a 16 km terrain of 1 m heights (the paper's 16K × 16K) at 250 m/s, 150 m up,
//! looking ahead and 20° down through a 60° × 34° frustum (16:9), once along the middle and once
//! along an edge (the paper's "middle" and "edge" regions). CPU time is wall-clock time of
//! `select_patches` on this thread (no GPU), so run it in release.
//!
//! ```text
//! cargo run --release -p bevy_terrain_clip --bin terrain_patches -- [--frames N] [--stats FILE]
//! ```
//!
//! `--stats FILE` writes `{"rows": [{"region", "precision", "culling", "triangles_avg",
//! "traversed_avg", "rendered_avg", "culled_avg", "selection_us_avg", "selection_us_p95"}],
//! "timing": "cpu wall clock"}`.

use bevy::math::primitives::ViewFrustum;
use bevy::math::{Mat4, Vec2, Vec3, Vec4};
use bevy_terrain_clip::geometry::patch::{PatchGrid, PatchView, select_patches};
use bevy_terrain_clip::geometry::tile::tile_triangles;
use std::collections::HashMap;
use std::time::Instant;

struct Row {
    region: &'static str,
    precision: f32,
    culling: bool,
    triangles: f64,
    traversed: f64,
    rendered: f64,
    culled: f64,
    us_avg: f64,
    us_p95: f64,
}

fn main() {
    let mut frames = 600u32;
    let mut stats = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--frames" => match args.next().and_then(|v| v.parse().ok()) {
                Some(n) if n > 0 => frames = n,
                _ => {
                    eprintln!("--frames takes a positive number");
                    std::process::exit(2)
                }
            },
            "--stats" => stats = args.next(),
            other => {
                eprintln!("unknown argument {other}: [--frames N] [--stats FILE]");
                std::process::exit(2)
            }
        }
    }
    // 16,384 m, 16-segment patches, 10 levels: the finest patches 16 m wide, vertices 1 m apart.
    let grid = PatchGrid::new(Vec2::ZERO, 16_384.0, 10, 16).expect("a valid grid");
    let projection = Mat4::perspective_infinite_reverse_rh(34f32.to_radians(), 16.0 / 9.0, 0.1);
    // Triangles of each tile kind, counted once.
    let mut tile_triangle_counts: HashMap<(u32, u32, u32), usize> = HashMap::new();
    let mut rows = Vec::new();
    let precision0 = 6.0;
    for (region, start, direction) in [
        ("middle", Vec2::new(2_000.0, 8_192.0), Vec2::X),
        ("edge", Vec2::new(2_000.0, 300.0), Vec2::X),
    ] {
        for precision in [precision0, 2.0 * precision0] {
            for culling in [true, false] {
                let (mut tri, mut trav, mut rend, mut cull) = (0.0, 0.0, 0.0, 0.0);
                let mut times = Vec::with_capacity(frames as usize);
                for frame in 0..frames {
                    let p = start + direction * 250.0 * frame as f32 / 60.0;
                    let eye = Vec3::new(p.x, 150.0, p.y);
                    let forward = Vec3::new(direction.x, -(20f32.to_radians().tan()), direction.y)
                        .normalize();
                    let view = Mat4::look_to_rh(eye, forward, Vec3::Y);
                    // Bevy's camera frustum: the projection's planes, the far plane 20 km out.
                    let frustum = ViewFrustum::from_clip_from_world_custom_far(
                        &(projection * view),
                        &eye,
                        &-forward,
                        20_000.0,
                    );
                    let planes: [Vec4; 6] = frustum.half_spaces.map(|h| h.normal_d());
                    let patch_view = PatchView {
                        eye,
                        precision,
                        frustum: culling.then_some(planes),
                        heights: (-50.0, 400.0),
                    };
                    let started = Instant::now();
                    let selection = select_patches(&grid, &patch_view);
                    times.push(started.elapsed().as_secs_f64() * 1e6);
                    trav += selection.stats.traversed as f64;
                    cull += selection.stats.culled as f64;
                    rend += selection.patches.len() as f64;
                    for patch in &selection.patches {
                        for e in 0..4 {
                            let key = (patch.edges[e], patch.diagonal(e), patch.diagonal(e + 1));
                            let n = *tile_triangle_counts.entry(key).or_insert_with(|| {
                                tile_triangles(grid.r_high, key.0, key.1, key.2).len()
                            });
                            tri += n as f64;
                        }
                    }
                }
                times.sort_by(f64::total_cmp);
                let f = frames as f64;
                rows.push(Row {
                    region,
                    precision,
                    culling,
                    triangles: tri / f,
                    traversed: trav / f,
                    rendered: rend / f,
                    culled: cull / f,
                    us_avg: times.iter().sum::<f64>() / f,
                    us_p95: times[((times.len() as f64 * 0.95) as usize).min(times.len() - 1)],
                });
            }
        }
    }
    println!(
        "{:<7} {:>4} {:>8} {:>11} {:>10} {:>9} {:>7} {:>16} {:>16}",
        "region",
        "ρ",
        "culling",
        "triangles",
        "traversed",
        "rendered",
        "culled",
        "selection µs avg",
        "selection µs p95"
    );
    for r in &rows {
        println!(
            "{:<7} {:>4} {:>8} {:>11.0} {:>10.1} {:>9.1} {:>7.1} {:>16.1} {:>16.1}",
            r.region,
            r.precision,
            if r.culling { "on" } else { "off" },
            r.triangles,
            r.traversed,
            r.rendered,
            r.culled,
            r.us_avg,
            r.us_p95
        );
    }
    for region in ["middle", "edge"] {
        for precision in [precision0, 2.0 * precision0] {
            let pick = |c: bool| {
                rows.iter()
                    .find(|r| r.region == region && r.precision == precision && r.culling == c)
                    .map(|r| r.triangles)
                    .unwrap_or(f64::NAN)
            };
            println!(
                "{region}, ρ = {precision}: culling draws {:.2}× fewer triangles",
                pick(false) / pick(true)
            );
        }
    }
    if let Some(path) = stats {
        let rows_json: Vec<String> = rows
            .iter()
            .map(|r| {
                format!(
                    "{{\"region\": \"{}\", \"precision\": {}, \"culling\": {}, \"triangles_avg\": {:.1}, \"traversed_avg\": {:.2}, \"rendered_avg\": {:.2}, \"culled_avg\": {:.2}, \"selection_us_avg\": {:.2}, \"selection_us_p95\": {:.2}}}",
                    r.region, r.precision, r.culling, r.triangles, r.traversed, r.rendered,
                    r.culled, r.us_avg, r.us_p95
                )
            })
            .collect();
        let text = format!(
            "{{\"rows\": [{}], \"timing\": \"cpu wall clock\", \"frames\": {frames}}}\n",
            rows_json.join(", ")
        );
        if let Err(e) = std::fs::write(&path, text) {
            eprintln!("{path}: {e}");
            std::process::exit(1);
        }
        eprintln!("terrain_patches: stats written to {path}");
    }
}
