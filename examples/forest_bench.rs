//! The forest benchmark (Gumbau 2011, table 3.5), headless, one process: the same forest drawn
//! by our manager (pruning near, billboard clouds beyond `far`) and by what a Bevy user builds
//! without this crate — decimated leaf meshes switched by `VisibilityRange`, bark ranged too —
//! each swept over its own settings, every image compared with a full-detail reference rendered in
//! the same run.
//!
//! Rows:
//! - `reference`: every tree, every leaf, bark, at every distance (rendered once, not timed);
//! - `no_trees`: ground and sky only — no manager work, no pruning pass;
//! - `visibility_range`: the baseline, one row per setting (leaf fractions of the three levels ×
//!   where they end); no manager, no pruning pass, no impostors;
//! - `ours`: the urgency-ranked manager with LoD caches and billboard clouds, one row per
//!   `(near, far)` (impostors beyond `far`) and one per budget of the time-critical mixed LoD
//!   (every visible tree given pruned geometry or its impostor by benefit per cost).
//!
//! Frame time is GPU-synchronised: each frame is `App::update` (the renderer runs inside it,
//! unpipelined) followed by a blocking wait until the GPU has finished everything submitted
//! (`timing: "gpu-synchronised"` in the output). RMSE is per pixel against the reference;
//! `rmse_8x8` compares 8×8 block means (the forest's density more than which leaves were kept).
//! From the two curves of (RMSE, frame ms), the lower envelopes are taken; at each of our envelope
//! points inside the baseline's RMSE range, the baseline's frame time is interpolated on its
//! envelope at our RMSE, and `speedup_at_matched_rmse` is the smallest of those ratios (the
//! headline: our worst case), with every matched point listed. The other way round,
//! `speedup_at_baseline_points` gives, at each point of the baseline's envelope, its frame time
//! over our fastest frame at equal or better RMSE.
//!
//! ```text
//! cargo run --release --example forest_bench -- [--forest dense|sparse|both] [--leaf-scale F]
//!     [--frames N] [--dolly N] [--size WxH] [--screenshot DIR] [--stats FILE]
//! ```
//! `--dolly N` (default 60): frames of the slow dolly that measures popping — the frame-to-frame
//! RMSE at frames where trees switch representation (a tree in view enters or leaves the
//! distance handover band; with the mixed LoD, a tree is fading between its two), against the
//! median frame-to-frame RMSE of the dolly (`dolly` in the output, `<forest>_mixed` for the
//! mixed LoD at the smallest budget of the sweep that mixes the two representations).
//! `--leaf-scale` scales the thesis' leaf counts (default 0.1: the full counts give a software
//! rasteriser reference frames of minutes).

use bevy::camera::visibility::VisibilityRange;
use bevy::prelude::*;
use bevy_nature::bench_curves::{matched_speedups, speedups_at_baseline_points};
use bevy_nature::foliage::forest::systems::{ForestState, LEAF_TRIANGLES, MANAGER_MS};
use bevy_nature::foliage::impostor::systems::IMPOSTORS_DRAWN;
use bevy_nature::foliage::{FoliagePruningSettings, ForestSettings, LodDistances};
use bevy_nature::forest_scene::{
    BaselineLevels, ForestArgs, ForestDraw, ForestKind, ForestScene, ForestScenePlugin,
    camera_transform, forest_impostors_ready, set_forest_draw,
};
use bevy_nature_harness::compare::{Comparison, RgbaImage};
use bevy_nature_harness::headless::HarnessConfig;
use bevy_nature_harness::{ExampleArgs, RenderHarness, require_adapter};

struct Row {
    scene: &'static str,
    mode: &'static str,
    params: String,
    frame_ms: f64,
    frame_ms_p95: f64,
    rmse: f64,
    rmse_8x8: f64,
    leaf_triangles: f64,
    impostors: f64,
    manager_ms: f64,
    /// Whether the pruning pass ran during the measured frames (it must not for `no_trees` and
    /// the baseline).
    pruning_pass: bool,
}

impl Row {
    fn json(&self) -> String {
        format!(
            "{{\"scene\": \"{}\", \"mode\": \"{}\", \"params\": {}, \"frame_ms\": {:.2}, \"frame_ms_p95\": {:.2}, \"rmse\": {:.5}, \"rmse_8x8\": {:.5}, \"leaf_triangles\": {}, \"impostors\": {}, \"manager_ms\": {:.3}, \"pruning_pass\": {}}}",
            self.scene,
            self.mode,
            self.params,
            self.frame_ms,
            self.frame_ms_p95,
            self.rmse,
            self.rmse_8x8,
            self.leaf_triangles,
            self.impostors,
            self.manager_ms,
            self.pruning_pass
        )
    }
}

fn kind_name(kind: ForestKind) -> &'static str {
    match kind {
        ForestKind::Dense => "dense",
        ForestKind::Sparse => "sparse",
        ForestKind::Huge => "huge",
    }
}

fn settle(harness: &mut RenderHarness) {
    // The manager serves its backlog, new pipelines compile.
    for _ in 0..300 {
        harness.step();
        if harness
            .world_mut()
            .resource::<ForestState>()
            .last
            .candidates
            == 0
        {
            break;
        }
    }
    harness.wait_until_ready().expect("ready");
    for _ in 0..2 {
        harness.step();
    }
}

#[allow(clippy::too_many_arguments)]
fn measure(
    harness: &mut RenderHarness,
    scene: &'static str,
    mode: &'static str,
    params: String,
    frames: u32,
    reference: &RgbaImage,
    baseline_triangles: bool,
    shots: Option<&std::path::Path>,
) -> Row {
    harness.reset_timing();
    harness
        .run_frames_gpu_synchronised(frames)
        .expect("measured frames");
    let stats = harness.frame_stats();
    let image = harness.render().expect("render");
    let cmp = Comparison::new(format!("forest_bench/{scene}/{mode}"), &image, reference);
    let blocks = Comparison::new(
        format!("forest_bench/{scene}/{mode}_8x8"),
        &image.box_downsample(8),
        &reference.box_downsample(8),
    );
    let leaf_triangles = if baseline_triangles {
        // The baseline's leaves are ordinary meshes: the triangles of the levels drawn.
        let world = harness.world_mut();
        let mut levels =
            world.query_filtered::<(&Mesh3d, &ViewVisibility), With<VisibilityRange>>();
        let drawn: Vec<Handle<Mesh>> = levels
            .iter(world)
            .filter(|(_, v)| v.get())
            .map(|(m, _)| m.0.clone())
            .collect();
        let meshes = world.resource::<Assets<Mesh>>();
        drawn
            .iter()
            .filter_map(|h| meshes.get(h))
            .map(|m| m.indices().map_or(0, |i| i.len()) as f64 / 3.0)
            .sum()
    } else {
        harness.diagnostic(&LEAF_TRIANGLES).unwrap_or(0.0)
    };
    if let Some(dir) = shots {
        let name = format!(
            "{scene}_{mode}_{}.png",
            params.replace(|c: char| !c.is_ascii_alphanumeric() && c != '.', "_")
        );
        image.save_png(dir.join(name)).ok();
    }
    let row = Row {
        scene,
        mode,
        params,
        frame_ms: stats.median_ms,
        frame_ms_p95: stats.p95_ms,
        rmse: cmp.rmse,
        rmse_8x8: blocks.rmse,
        // (An empty sum is −0.)
        leaf_triangles: leaf_triangles + 0.0,
        impostors: if mode == "ours" {
            harness.diagnostic(&IMPOSTORS_DRAWN).unwrap_or(0.0)
        } else {
            0.0
        },
        manager_ms: harness.diagnostic(&MANAGER_MS).unwrap_or(0.0),
        pruning_pass: harness.pass_time_ms("foliage_pruning").is_some(),
    };
    eprintln!("{}", row.json());
    row
}

fn run_forest(
    kind: ForestKind,
    leaf_scale: f32,
    size: UVec2,
    frames: u32,
    dolly_frames: usize,
    shots: Option<&std::path::Path>,
) -> (Vec<Row>, [Dolly; 2]) {
    let scene = kind_name(kind);
    let mut harness = RenderHarness::new(HarnessConfig::sized(size.x, size.y)).expect("harness");
    harness
        .app_mut()
        .add_plugins((bevy_nature::NaturePlugins, ForestScenePlugin))
        .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)))
        .insert_resource(ForestScene {
            kind,
            leaf_scale,
            draw: ForestDraw::Nothing,
            impostors: true,
        })
        .insert_resource(ForestSettings {
            budget: bevy_nature::foliage::ForestBudget::Extractions(64),
            ..default()
        });
    harness
        .world_mut()
        .spawn((Camera3d::default(), Msaa::Off, camera_transform()));
    // The billboard clouds: baked on the GPU at the first run, loaded from the cache after.
    let started = std::time::Instant::now();
    for _ in 0..2000 {
        harness.step();
        if forest_impostors_ready(harness.world_mut()) {
            break;
        }
    }
    eprintln!(
        "{scene}: impostors ready after {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let (near, far) = kind.near_far();

    set_forest_draw(harness.world_mut(), &ForestDraw::Reference);
    settle(&mut harness);
    let reference = harness.render().expect("reference");
    if let Some(dir) = shots {
        reference
            .save_png(dir.join(format!("{scene}_reference.png")))
            .ok();
    }
    let mut rows = Vec::new();

    set_forest_draw(harness.world_mut(), &ForestDraw::Nothing);
    settle(&mut harness);
    rows.push(measure(
        &mut harness,
        scene,
        "no_trees",
        "{}".into(),
        frames,
        &reference,
        true,
        shots,
    ));

    // The baseline at its best settings: three leaf fractions × where the levels end (the last
    // level at `far`, at twice `far`, or never culled).
    let fractions: [[f32; 3]; 3] = [[1.0, 0.4, 0.12], [1.0, 0.25, 0.06], [1.0, 0.5, 0.25]];
    let ends: [f32; 3] = [far, 2.0 * far, f32::MAX];
    let mut settings: Vec<([f32; 3], f32)> = Vec::new();
    for f in &fractions[..2] {
        for &e in &ends {
            settings.push((*f, e));
        }
    }
    settings.push((fractions[2], f32::MAX));
    settings.push((fractions[2], 2.0 * far));
    for (f, last_end) in settings {
        // Level ends at 20 % and 55 % of [near, D], D = the last end (or 3·far when never culled).
        let span = if last_end == f32::MAX {
            3.0 * far
        } else {
            last_end
        };
        let levels = BaselineLevels(vec![
            (f[0], near + 0.2 * (span - near)),
            (f[1], near + 0.55 * (span - near)),
            (f[2], last_end),
        ]);
        let params = format!(
            "{{\"fractions\": [{}, {}, {}], \"ends_m\": [{:.0}, {:.0}, {}]}}",
            f[0],
            f[1],
            f[2],
            levels.0[0].1,
            levels.0[1].1,
            if last_end == f32::MAX {
                "null".to_string()
            } else {
                format!("{last_end:.0}")
            }
        );
        set_forest_draw(harness.world_mut(), &ForestDraw::Baseline(levels));
        settle(&mut harness);
        rows.push(measure(
            &mut harness,
            scene,
            "visibility_range",
            params,
            frames,
            &reference,
            true,
            shots,
        ));
    }

    // Ours over its settings: where full detail ends (`near`) and where pruning hands over to
    // the billboard clouds (`far`).
    let _ = near;
    set_forest_draw(harness.world_mut(), &ForestDraw::Managed);
    // Fractions of the scene's `far` (360 m dense, 115 m sparse): from aggressive to generous.
    let ours: Vec<(f32, f32)> = [
        (0.04, 0.16),
        (0.1, 0.3),
        (0.2, 0.5),
        (0.3, 0.6),
        (0.5, 1.0),
        (0.7, 1.4),
    ]
    .iter()
    .map(|&(n, f)| (n * far, f * far))
    .collect();
    for (n, f) in ours {
        harness
            .world_mut()
            .resource_mut::<FoliagePruningSettings>()
            .distances = LodDistances::World { near: n, far: f };
        for _ in 0..3 {
            harness.step();
        }
        settle(&mut harness);
        rows.push(measure(
            &mut harness,
            scene,
            "ours",
            format!("{{\"near_m\": {n:.1}, \"far_m\": {f:.1}}}"),
            frames,
            &reference,
            false,
            shots,
        ));
    }
    // Ours with the time-critical mixed LoD, over its budget (leaf-triangle units per frame).
    for budget in MIXED_BUDGETS {
        set_mixed(&mut harness, Some(budget));
        settle(&mut harness);
        rows.push(measure(
            &mut harness,
            scene,
            "ours",
            format!("{{\"mixed_budget\": {budget}}}"),
            frames,
            &reference,
            false,
            shots,
        ));
    }
    set_mixed(&mut harness, None);
    let by_distance = dolly(&mut harness, kind, dolly_frames, shots, None);
    // The mixed LoD's dolly at the smallest budget that mixes (some trees on geometry, some on
    // impostors): at a budget that puts every tree on one side nothing switches.
    let mixing = rows
        .iter()
        .filter(|r| r.mode == "ours" && r.params.contains("mixed_budget"))
        .position(|r| r.leaf_triangles > 0.0 && r.impostors > 0.0)
        .map_or(MIXED_BUDGETS[2], |i| MIXED_BUDGETS[i]);
    let mixed = dolly(&mut harness, kind, dolly_frames, shots, Some(mixing));
    (rows, [by_distance, mixed])
}

/// The budgets the mixed LoD is measured at.
const MIXED_BUDGETS: [f32; 6] = [2e5, 4e5, 8e5, 1.6e6, 3.2e6, 6.4e6];

/// Turns the mixed LoD on with `budget`, or off.
fn set_mixed(harness: &mut RenderHarness, budget: Option<f32>) {
    let mut settings = harness.world_mut().resource_mut::<ForestSettings>();
    settings.mixed.enabled = budget.is_some();
    if let Some(b) = budget {
        settings.mixed.budget_triangles = b;
    }
}

/// Cosine of the half horizontal field of view of the benchmark camera (45° vertical at 16:9 is
/// 36° either side), with a few degrees of margin.
const HALF_VIEW_COS: f32 = 0.77;

/// Metres the dolly moves per frame.
const DOLLY_STEP: f32 = 0.1;

/// What the slow dolly measured.
struct Dolly {
    /// The mixed LoD's budget (none: the distance handover).
    budget: Option<f32>,
    /// Per frame: frame-to-frame RMSE, and whether a tree crossed a handover band edge.
    per_frame: Vec<(f64, bool)>,
    frames: usize,
    median_rmse: f64,
    switch_frames: usize,
    max_switch_rmse: f64,
}

/// A slow dolly ([`DOLLY_STEP`] per frame, straight ahead) with our default settings: the frame-to-frame
/// RMSE of every frame, and of the frames in which a tree enters or leaves the handover band
/// (its impostor starts to fade in, or its last leaves go).
fn dolly(
    harness: &mut RenderHarness,
    kind: ForestKind,
    frames: usize,
    shots: Option<&std::path::Path>,
    mixed_budget: Option<f32>,
) -> Dolly {
    use bevy_nature::foliage::TreeLod;
    use bevy_nature::foliage::impostor::systems::ImpostorSettings;
    use bevy_nature::forest_scene::ForestTypes;
    let (near, far) = kind.near_far();
    harness
        .world_mut()
        .resource_mut::<FoliagePruningSettings>()
        .distances = LodDistances::World { near, far };
    let band = harness.world_mut().resource::<ImpostorSettings>().fade_band;
    let start = camera_transform();
    let ahead = start.forward().as_vec3() * Vec3::new(1.0, 0.0, 1.0);
    let trees: Vec<Vec3> = harness
        .world_mut()
        .resource::<ForestTypes>()
        .placements
        .iter()
        .map(|(_, t)| t.translation)
        .collect();
    let place = |harness: &mut RenderHarness, i: usize| {
        let world = harness.world_mut();
        let mut cameras = world.query_filtered::<&mut Transform, (
            With<Camera3d>,
            Without<bevy_nature::foliage::impostor::bake::ImpostorBakeCamera>,
        )>();
        let position = start.translation + ahead * DOLLY_STEP * i as f32;
        for mut t in cameras.iter_mut(world) {
            *t = Transform::from_translation(position).with_rotation(start.rotation);
        }
        position
    };
    set_mixed(harness, mixed_budget);
    place(harness, 0);
    settle(harness);
    let mut previous = harness.render().expect("dolly");
    let mut last_position = start.translation;
    let (mut all, mut at_switch, mut per_frame) = (Vec::new(), Vec::new(), Vec::new());
    let mut worst = 0.0;
    for i in 1..=frames {
        let position = place(harness, i);
        let image = harness.render().expect("dolly");
        let rmse = Comparison::new("forest_bench/dolly", &image, &previous).rmse;
        // Trees in view (within the horizontal field of view, with a margin) whose distance to
        // the camera — to the tree's origin, as `VisibilityRange` measures it — crosses an edge
        // of the handover band.
        let crossed = trees.iter().any(|&t| {
            let to = (t - position) * Vec3::new(1.0, 0.0, 1.0);
            if to.normalize_or_zero().dot(ahead.normalize_or_zero()) < HALF_VIEW_COS {
                return false;
            }
            let (a, b) = (t.distance(last_position), t.distance(position));
            [far * (1.0 - band), far]
                .iter()
                .any(|&edge| (a - edge) * (b - edge) <= 0.0)
        });
        // With the mixed LoD a tree switches when the selection changes its representation:
        // frames in which some tree is fading between the two.
        let crossed = if mixed_budget.is_some() {
            let world = harness.world_mut();
            world
                .query::<&TreeLod>()
                .iter(world)
                .any(|l| l.visible && l.impostor_weight > 0.0 && l.impostor_weight < 1.0)
        } else {
            crossed
        };
        if crossed {
            at_switch.push(rmse);
        }
        per_frame.push((rmse, crossed));
        if rmse > worst {
            worst = rmse;
            if let Some(dir) = shots {
                let scene = kind_name(kind);
                let tag = if mixed_budget.is_some() { "_mixed" } else { "" };
                previous
                    .save_png(dir.join(format!("{scene}_dolly{tag}_worst_before.png")))
                    .ok();
                image
                    .save_png(dir.join(format!("{scene}_dolly{tag}_worst_after.png")))
                    .ok();
            }
        }
        all.push(rmse);
        previous = image;
        last_position = position;
    }
    let mut sorted = all.clone();
    sorted.sort_by(f64::total_cmp);
    let d = Dolly {
        budget: mixed_budget,
        per_frame,
        frames,
        median_rmse: sorted.get(sorted.len() / 2).copied().unwrap_or(0.0),
        switch_frames: at_switch.len(),
        max_switch_rmse: at_switch.iter().copied().fold(0.0, f64::max),
    };
    set_mixed(harness, None);
    eprintln!(
        "dolly{}: {} frames, median frame-to-frame RMSE {:.5}, {} frames with trees switching, max {:.5}",
        if mixed_budget.is_some() {
            " (mixed LoD)"
        } else {
            ""
        },
        d.frames,
        d.median_rmse,
        d.switch_frames,
        d.max_switch_rmse
    );
    d
}

fn main() {
    // `--forest both` (the default) runs the dense and the sparse forest; the scene flags take
    // one.
    let raw: Vec<String> = std::env::args().skip(1).collect();
    let (mut both, mut filtered, mut i) = (true, Vec::new(), 0);
    let mut dolly_frames = 60usize;
    while i < raw.len() {
        if raw[i] == "--dolly" {
            dolly_frames = raw
                .get(i + 1)
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| {
                    eprintln!("--dolly takes a number of frames");
                    std::process::exit(2)
                });
            i += 2;
            continue;
        }
        if raw[i] == "--forest" {
            if raw.get(i + 1).map(String::as_str) == Some("both") {
                i += 2;
                continue;
            }
            both = false;
        }
        filtered.push(raw[i].clone());
        i += 1;
    }
    let ForestArgs {
        kind,
        leaf_scale,
        rest: runner_flags,
    } = ForestArgs::parse(filtered, 0.1).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let args = ExampleArgs::parse_from(runner_flags).unwrap_or_else(|e| {
        eprintln!("{e} [--forest dense|sparse|both] [--leaf-scale F] [--dolly N]");
        std::process::exit(2)
    });
    let size = args.size.unwrap_or(UVec2::new(480, 270));
    let frames = args.frames.unwrap_or(5);

    if require_adapter("forest_bench").is_none() {
        std::process::exit(1);
    }
    if let Some(dir) = &args.screenshot {
        std::fs::create_dir_all(dir).ok();
    }
    let kinds = if both {
        vec![ForestKind::Dense, ForestKind::Sparse]
    } else {
        vec![kind]
    };
    let mut rows = Vec::new();
    let mut speedups = Vec::new();
    let mut dollies = Vec::new();
    let mut at_baseline = Vec::new();
    for kind in kinds {
        let (forest_rows, dolly) = run_forest(
            kind,
            leaf_scale,
            size,
            frames,
            dolly_frames,
            args.screenshot.as_deref(),
        );
        dollies.push((kind_name(kind), dolly));
        let curve = |mode: &str| -> Vec<(f64, f64)> {
            forest_rows
                .iter()
                .filter(|r| r.mode == mode)
                .map(|r| (r.rmse, r.frame_ms))
                .collect()
        };
        let matched = matched_speedups(&curve("ours"), &curve("visibility_range"));
        at_baseline.push((
            kind_name(kind),
            speedups_at_baseline_points(&curve("ours"), &curve("visibility_range")),
        ));
        let worst = matched.iter().map(|m| m.1).min_by(|a, b| a.total_cmp(b));
        speedups.push((kind_name(kind), worst, matched));
        rows.extend(forest_rows);
    }
    let speedup_json = speedups
        .iter()
        .map(|(name, worst, _)| {
            format!(
                "\"{name}\": {}",
                worst.map_or("null".to_string(), |w| format!("{w:.3}"))
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    let matched_json = speedups
        .iter()
        .map(|(name, _, matched)| {
            format!(
                "\"{name}\": [{}]",
                matched
                    .iter()
                    .map(|(rmse, s)| format!("{{\"rmse\": {rmse:.5}, \"speedup\": {s:.3}}}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    let at_baseline_json = at_baseline
        .iter()
        .map(|(name, points)| {
            format!(
                "\"{name}\": [{}]",
                points
                    .iter()
                    .map(|(rmse, s)| format!(
                        "{{\"rmse\": {rmse:.5}, \"speedup\": {}}}",
                        s.map_or("null".to_string(), |s| format!("{s:.3}"))
                    ))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    let dolly_json = dollies
        .iter()
        .flat_map(|(name, [by_distance, mixed])| {
            [(name.to_string(), by_distance), (format!("{name}_mixed"), mixed)]
        })
        .map(|(name, d)| {
            format!(
                "\"{name}\": {{\"budget\": {}, \"frames\": {}, \"median_rmse\": {:.5}, \"switch_frames\": {}, \"max_switch_rmse\": {:.5}, \"ratio\": {:.2}, \"per_frame\": [{}]}}",
                d.budget.map_or("null".to_string(), |b| b.to_string()),
                d.frames,
                d.median_rmse,
                d.switch_frames,
                d.max_switch_rmse,
                d.max_switch_rmse / d.median_rmse.max(1e-9),
                d.per_frame
                    .iter()
                    .map(|(r, c)| format!("[{r:.5}, {c}]"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    let json = format!(
        "{{\"bench\": \"forest\", \"headline\": \"speedup_at_matched_rmse (our worst case over the matched RMSE range; > 1: ours faster)\", \"timing\": \"gpu-synchronised\", \"leaf_scale\": {leaf_scale}, \"size\": [{}, {}], \"frames\": {frames}, \"speedup_at_matched_rmse\": {{{speedup_json}}}, \"matched_points\": {{{matched_json}}}, \"speedup_at_baseline_points\": {{{at_baseline_json}}}, \"dolly\": {{{dolly_json}}}, \"rows\": [\n  {}\n]}}",
        size.x,
        size.y,
        rows.iter().map(Row::json).collect::<Vec<_>>().join(",\n  ")
    );
    println!("{json}");
    if let Some(path) = &args.stats
        && let Err(e) = std::fs::write(path, &json)
    {
        eprintln!("could not write {}: {e}", path.display());
        std::process::exit(1);
    }
}
