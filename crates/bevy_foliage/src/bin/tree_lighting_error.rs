//! The tree lighting model (Boulanger 2008, ch. 5) against a Monte Carlo path tracer over the
//! same leaves, BSDF, sky and sun: per component, the mean relative error per leaf and the
//! error of the crown's mean (the thesis reports 5 % sky direct, 7.5 % sun direct, 6 % sun
//! indirect against renders with 256 rays per point). Each crown is also traced twice with
//! different seeds: those rows are the reference's own noise, below which no model can be shown
//! closer to it leaf by leaf.
//!
//! ```text
//! cargo run --release -p bevy_foliage --bin tree_lighting_error -- [--leaves N] [--stride K]
//!     [--points P] [--directions D] [--rays-per-bin R[,R…]] [--sun-maps]
//!     [--images [--samples G] [--seen-points P] [--seen-below W] [--seen-seed S] [--open-maps CxP[r][,…]] [--hotspot] [--bounce-rays R [--bounce-pool K[,K…]]] [--sun-ring N[,N…] [--ring-offset F] [--ring-rays R] [--ring-passes P]] [--sunlit-points P [--sunlit-maps C[,C…]] [--through-planes R[,R…]]] [--bounce-planes SxP[,…]] [--bounce-covers]]
//!     [--sun X,Y,Z] [--eye X,Y,Z]
//!     [--leaf-shadow-offset T,S | --leaf-shadow-slack S] [--shadow-texel F[,F…]]
//! ```
//! `--sun X,Y,Z`: the direction towards the sun (0.5, 0.7, 0.3 by default); `--eye X,Y,Z` the
//! direction the eye looks from (0, 0.3, 1 by default, the plane between two octants of the
//! bins) — the model's errors depend on the angle between the two, and the seen-part gains'
//! on where the eye is among their octants.
//! `--images`: instead, the thesis' own measure (§5.7, fig. 5.16): the crown rendered by the
//! model and by the tracer (`--directions` rays per intersection point, 256 by default as in
//! the thesis) on a grid of `--samples G` eye rays a side (128), and each image's mean error
//! over its mean light at pixels of 1, 4 and 16 eye rays a side (`lighting::image_error`),
//! and leaf by leaf (each leaf's mean over the eye rays that hit it: the mean relative error
//! per leaf, as the thesis' targets are stated);
//! the last bins also with each leaf's seen-part gains from `--seen-points` points (32;
//! `lighting::seen_part`): on the sky and the sun, and the covered part's on the bounce
//! (`--seen-below W` weighs the directions below the horizon by W in their open share: 1, the
//! bakes' uniform sphere, by default; `--seen-seed S` draws their points and rays from another
//! seed than the bakes' 0, to tell the gains' own noise from a change); and, for the sky, two rows of what no eight gains beat:
//! the gain traced for the eye's own direction from as many points, and the open share at
//! each eye ray's own point over its leaf's mean (with the bounce's covered-part gain from
//! each, for the bounce);
//! `--hotspot` adds rows with the crown's hotspot (`lighting::hotspot`, measured with
//! `HotspotSettings::OFFLINE` from its own rays) on the sun and the bounce, and prints its
//! factors; `--bounce-rays R` adds rows with the bounce gathered from each leaf's own
//! neighbours by R rays (`lighting::gathered_bounce`: eq. 5.24 scaled by the gathered ratios
//! blended from fourteen suns, with and without the covered part's gain, and the gather for
//! the image's own sun alone; with `--hotspot` also the ratios with the gain and a hotspot
//! measured against them, as the leaf shaders draw the bounce; and eq. 5.24 scaled by ratios
//! re-gathered for the image's sun alone, `gathered_bounce::sun_ratios_of`, drawn as the
//! blend's are, with the seconds that re-gather takes; `--sun-ring N[,N…]` a row per ring of
//! N suns at the sun's elevation, `gathered_bounce::sun_ring`, ratios re-gathered on it and
//! read for the sun midway between two nodes, as a tree turned about its vertical sees the
//! sun (`--ring-offset F`: F of a node's step past a node instead, 0 on one; `--ring-rays R`:
//! the ring's ratios gathered by R rays a leaf, where the bake's take `--bounce-rays`;
//! `--ring-passes P`: the mean of P passes of them, each its rays shifted anew, as an app's ring
//! refines them while the sun stays, `bounce_ring::RingRefinement`), and with `--hotspot` also drawn with the ring's own hotspot, measured for suns at the
//! sun's height against the bounce with the ring, `hotspot::HotspotSuns::Height`), each leaf's
//! ratios pooled
//! with its nearest neighbours' (`--bounce-pool K[,K…]`: K leaves a pool, the first for
//! those rows, and a row as drawn for each). The shadow
//! map's row reads it as the leaf shaders do at the leaf (texels of `LEAF_SHADOW_FINE` of a
//! leaf, up to which they take it alone; `--shadow-texel F[,F…]` for a row per share of the
//! leaf's size, and with `--hotspot` a row of the sun as drawn for each share where the
//! shaders blend the map with the baked attenuations): by default the shaders'
//! receiver-plane comparison (`sun_maps::LeafShadowPlane::SHADERS`, `--leaf-shadow-slack S`
//! for another slack in texels), or with `--leaf-shadow-offset T,S` one bilinear lookup at the
//! point moved towards the sun by `T + S·tan θ` texels, θ the leaf's tilt from the sun
//! (`sun_maps::LeafShadowOffset`); also in the `--sun-maps` table.
//!
//! With `--bounce-rays R`, what values stored per leaf can make of the bounce for the image's
//! sun (`lighting::bounce_floor`): `--bounce-planes SxP[,…]` rows from each leaf's bounce
//! fitted with a plane a face over a jittered grid of S × S points gathering P rays each (the
//! mean alone, and the planes at the eye ray's point) and from the gather at the eye ray's own
//! point with as many rays, what no value per leaf beats; `--through-planes R[,…]` (with
//! `--sunlit-points P`) rows gathered by R rays a leaf with shadow rays and with the
//! neighbours' sunlit planes from P points in their place; `--bounce-covers` (with seen-part
//! gains) rows of the sun's own gather and of each ring with its own hotspot with the covered
//! part's gain from the eight gains, from each leaf's stored open map at the eye ray's point,
//! and from the covered share at that point itself.
//!
//! `--open-maps CxP[r][,…]` (with `--images` and seen-part gains): rows of the sky with the
//! gain from each leaf's open-share map of C × C cells traced from P points
//! (`open_map::open_map`) read at the eye ray's point, alone and times the map's residual
//! gains blended towards the eye; the cells over the points' bounding rectangle in the leaf's
//! plane, or with `r` over the square a leaf shader can find from its vertices
//! (`open_map::MapFrame::of_leaf`).
//!
//! `--sunlit-points P` (with `--images`): rows of the sun through the crown from each leaf's
//! sunlit share traced from P points on it (`lighting::sunlit_share`) for the image's sun and,
//! per `--sun-ring N`, on a ring of N suns at its elevation read with the sun midway between
//! two nodes; each as the leaf's share and as the share's plane over the leaf (the
//! least-squares fit to the same points, `SharePlane`) read at the eye ray's point; as it is,
//! with the seen-part gain, with the crown's hotspot, and (rings' shares, with `--hotspot`)
//! with a hotspot fitted against the ring's shares at the sun's height; and each ring's planes
//! as the leaf shaders draw them (stored, read at the vertices, with the crown's and with the
//! ring's own hotspot), a ring of another size than the light buffer's fourteen nodes as they
//! would were the buffer to hold it.
//!
//! `--sunlit-maps C[,C…]` (with `--sunlit-points P`): rows of the sun from a map of each
//! leaf's sunlit share for the image's sun, C × C cells over the leaf's square from the same
//! P points, read at the eye ray's point (alone and with the seen-part gain), and a row of
//! the share at the eye ray's point itself, what no value stored per leaf beats.
//!
//! `--sun-maps`: instead, the sun's share on each leaf from maps rendered from the sun (a shadow
//! map at five texel sizes, 1/16 to one leaf, read as the leaf shaders read it and with a 3×3 filter, the crown's extinction over its depth, eq. 5.3's foliage maps)
//! against the tracer's shadow rays, beside the baked attenuations' blend
//! (`lighting::sun_maps`).

use bevy::math::Vec3;
use bevy_foliage::lighting::model::{LeafMaterial, SunThroughCrown};
use bevy_foliage::lighting::path_trace::{
    ComponentError, LightingError, TraceLight, TraceSettings, models_against_tracer,
    tracer_against_itself, uniform_ball,
};
use bevy_foliage::lighting::traced_bins::{BinEstimate, DEFAULT_RAYS_PER_BIN};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};

fn main() {
    let mut leaves = 2000usize;
    let mut stride = 10usize;
    let mut rays_per_bin = vec![DEFAULT_RAYS_PER_BIN];
    let mut settings = TraceSettings {
        points: 8,
        directions: 256,
        bounces: 4,
        seed: 1,
    };
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let sun_maps = args.iter().any(|a| a == "--sun-maps");
    let images = args.iter().any(|a| a == "--images");
    let hotspot = args.iter().any(|a| a == "--hotspot");
    args.retain(|a| a != "--sun-maps" && a != "--images" && a != "--hotspot");
    let mut samples = 128u32;
    let mut bounce_rays = 0u32;
    let mut ring_rays = 0u32;
    let mut ring_passes = 1u32;
    let mut sunlit_points = 0u32;
    let mut sunlit_maps: Vec<u32> = Vec::new();
    let mut ring_offset = 0.5f32;
    let mut bounce_planes: Vec<(u32, u32)> = Vec::new();
    let mut through_planes: Vec<u32> = Vec::new();
    let bounce_covers = args.iter().any(|a| a == "--bounce-covers");
    args.retain(|a| a != "--bounce-covers");
    use bevy_foliage::lighting::gathered_bounce::{DEFAULT_BOUNCE_POOL, MAX_BOUNCE_POOL};
    let mut bounce_pools = vec![DEFAULT_BOUNCE_POOL];
    let mut sun_rings: Vec<usize> = Vec::new();
    let mut open_maps: Vec<(u32, u32, bool)> = Vec::new();
    let mut seen_points = bevy_foliage::lighting::seen_part::OFFLINE_SEEN_POINTS;
    let mut seen_below = 1.0f32;
    let mut seen_seed = 0u64;
    let mut to_sun = Vec3::new(0.5, 0.7, 0.3).normalize();
    let mut to_eye = Vec3::new(0.0, 0.3, 1.0).normalize();
    use bevy_foliage::lighting::sun_maps::{
        LEAF_SHADOW_FINE, LeafShadowLookup, LeafShadowOffset, LeafShadowPlane,
    };
    let mut leaf_shadow = LeafShadowLookup::SHADERS;
    let mut shadow_texels = vec![LEAF_SHADOW_FINE];
    let mut i = 0;
    while i < args.len() {
        let value = |i: usize| -> usize {
            args.get(i + 1)
                .and_then(|v| v.parse().ok())
                .filter(|v| *v > 0)
                .unwrap_or_else(|| {
                    eprintln!("{} takes a whole number > 0", args[i]);
                    std::process::exit(2)
                })
        };
        match args[i].as_str() {
            "--leaves" => leaves = value(i),
            "--stride" => stride = value(i),
            "--points" => settings.points = value(i) as u32,
            "--directions" => settings.directions = value(i) as u32,
            "--samples" => samples = value(i) as u32,
            "--seen-points" => seen_points = value(i) as u32,
            "--seen-below" => {
                seen_below = args
                    .get(i + 1)
                    .and_then(|v| v.parse::<f32>().ok())
                    .filter(|w| w.is_finite() && *w >= 0.0)
                    .unwrap_or_else(|| {
                        eprintln!("--seen-below takes a weight ≥ 0");
                        std::process::exit(2)
                    })
            }
            "--seen-seed" => {
                seen_seed = args
                    .get(i + 1)
                    .and_then(|v| v.parse::<u64>().ok())
                    .unwrap_or_else(|| {
                        eprintln!("--seen-seed takes a whole number ≥ 0");
                        std::process::exit(2)
                    })
            }
            "--bounce-rays" => bounce_rays = value(i) as u32,
            "--ring-rays" => ring_rays = value(i) as u32,
            "--ring-passes" => ring_passes = value(i) as u32,
            "--sunlit-points" => sunlit_points = value(i) as u32,
            "--ring-offset" => {
                ring_offset = args
                    .get(i + 1)
                    .and_then(|v| v.parse::<f32>().ok())
                    .filter(|f| (0.0..1.0).contains(f))
                    .unwrap_or_else(|| {
                        eprintln!("--ring-offset takes a share of a node's step in [0, 1)");
                        std::process::exit(2)
                    })
            }
            "--bounce-planes" => {
                bounce_planes = list_flag(
                    "--bounce-planes",
                    args.get(i + 1),
                    "SxP or SxP,SxP,… (S × S points a leaf, S in 1..=32; P rays a point in 1..=4096)",
                    |m| side_by_count(m, 1..=32, 1..=4096),
                );
            }
            "--through-planes" => {
                through_planes = list_flag(
                    "--through-planes",
                    args.get(i + 1),
                    "R or R,R,… (rays a leaf, each in 1..=4096)",
                    |r| r.parse().ok().filter(|r| (1..=4096).contains(r)),
                );
            }
            "--sunlit-maps" => {
                sunlit_maps = list_flag(
                    "--sunlit-maps",
                    args.get(i + 1),
                    "C or C,C,… (cells a side, each in 1..=16)",
                    |c| c.parse().ok().filter(|c| (1..=16).contains(c)),
                );
            }
            "--leaf-shadow-offset" => {
                let parts: Option<Vec<f32>> = args
                    .get(i + 1)
                    .and_then(|v| v.split(',').map(|c| c.trim().parse::<f32>().ok()).collect());
                match parts.as_deref() {
                    Some(&[texels, slope])
                        if (0.0..=10.0).contains(&texels) && (0.0..=10.0).contains(&slope) =>
                    {
                        leaf_shadow = LeafShadowLookup::Offset(LeafShadowOffset {
                            texels,
                            slope,
                            ..LeafShadowOffset::SLOPE_SCALED
                        });
                    }
                    _ => {
                        eprintln!(
                            "--leaf-shadow-offset takes T,S (texels and texels per tan θ, each in 0..=10)"
                        );
                        std::process::exit(2)
                    }
                }
            }
            "--leaf-shadow-slack" => match args.get(i + 1).and_then(|v| v.parse::<f32>().ok()) {
                Some(slack) if (0.0..=10.0).contains(&slack) => {
                    let plane = match leaf_shadow {
                        LeafShadowLookup::ReceiverPlane(plane) => plane,
                        LeafShadowLookup::Offset(_) => LeafShadowPlane::SHADERS,
                    };
                    leaf_shadow = LeafShadowLookup::ReceiverPlane(LeafShadowPlane {
                        slack_texels: slack,
                        ..plane
                    });
                }
                _ => {
                    eprintln!("--leaf-shadow-slack takes texels in 0..=10");
                    std::process::exit(2)
                }
            },
            "--shadow-texel" => {
                let shares: Option<Vec<f32>> = args.get(i + 1).map(|v| {
                    v.split(',')
                        .filter_map(|x| x.parse::<f32>().ok())
                        .filter(|share| (1.0 / 256.0..=4.0).contains(share))
                        .collect()
                });
                match shares {
                    Some(shares)
                        if !shares.is_empty() && shares.len() == args[i + 1].split(',').count() =>
                    {
                        shadow_texels = shares
                    }
                    _ => {
                        eprintln!(
                            "--shadow-texel takes shares of the leaf's size in 1/256..=4, separated by commas"
                        );
                        std::process::exit(2)
                    }
                }
            }
            "--sun" => {
                to_sun = direction(args.get(i + 1)).unwrap_or_else(|| {
                    eprintln!("--sun takes x,y,z (a direction towards the sun)");
                    std::process::exit(2)
                })
            }
            "--eye" => {
                to_eye = direction(args.get(i + 1)).unwrap_or_else(|| {
                    eprintln!("--eye takes x,y,z (a direction towards the eye)");
                    std::process::exit(2)
                })
            }
            "--bounce-pool" => {
                bounce_pools = list_flag(
                    "--bounce-pool",
                    args.get(i + 1),
                    &format!("K or K,K,… with each K in 1..={MAX_BOUNCE_POOL}"),
                    |k| k.parse().ok().filter(|k| (1..=MAX_BOUNCE_POOL).contains(k)),
                )
            }
            "--open-maps" => {
                open_maps = list_flag(
                    "--open-maps",
                    args.get(i + 1),
                    "CxP[r] or CxP[r],… (C × C cells in 1..=16, P points in 1..=4096; r: cells over the square a leaf shader finds)",
                    |m| {
                        let (m, of_leaf) = match m.strip_suffix('r') {
                            Some(m) => (m, true),
                            None => (m, false),
                        };
                        let (side, points) = side_by_count(m, 1..=16, 1..=4096)?;
                        Some((side, points, of_leaf))
                    },
                );
            }
            "--sun-ring" => {
                sun_rings = list_flag(
                    "--sun-ring",
                    args.get(i + 1),
                    "N or N,N,… with each N in 1..=64",
                    |n| n.parse().ok().filter(|n| (1..=64).contains(n)),
                )
            }
            "--rays-per-bin" => {
                rays_per_bin = list_flag(
                    "--rays-per-bin",
                    args.get(i + 1),
                    "R or R,R,… with each R in 1..=4096",
                    |r| r.parse().ok().filter(|r| (1..=4096).contains(r)),
                )
            }
            other => {
                eprintln!(
                    "unknown flag {other}; flags: [--leaves N] [--stride K] [--points P] [--directions D] [--rays-per-bin R[,R…]] [--sun-maps] [--images [--samples G] [--seen-points P] [--seen-below W] [--seen-seed S] [--open-maps CxP[r][,…]] [--hotspot] [--bounce-rays R [--bounce-pool K[,K…]]] [--sun-ring N[,N…] [--ring-offset F] [--ring-rays R] [--ring-passes P]] [--sunlit-points P [--sunlit-maps C[,C…]] [--through-planes R[,R…]]] [--bounce-planes SxP[,…]] [--bounce-covers]] [--sun x,y,z] [--eye x,y,z] [--leaf-shadow-offset T,S | --leaf-shadow-slack S] [--shadow-texel F[,F…]]"
                );
                std::process::exit(2)
            }
        }
        i += 2;
    }
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    let material = LeafMaterial::default();
    let light = TraceLight {
        sky: Vec3::new(0.35, 0.45, 0.65),
        ground: Vec3::new(0.35, 0.45, 0.65) * 0.15,
        to_sun,
        sun: Vec3::new(3.2, 3.0, 2.7),
    };
    if sun_maps {
        sun_map_table(
            leaves,
            stride,
            settings.points,
            light.to_sun,
            leaf_shadow,
            threads,
        );
        return;
    }
    if images {
        image_table(
            leaves,
            &material,
            &light,
            &bevy_foliage::lighting::image_error::ImageSettings {
                samples,
                directions: settings.directions,
                seen_points,
                seen_below,
                seen_seed,
                hotspot,
                leaf_shadow,
                shadow_texels: shadow_texels.clone(),
                bounce_rays,
                ring_rays,
                ring_passes,
                bounce_pools: bounce_pools.clone(),
                sun_rings: sun_rings.clone(),
                open_maps: open_maps.clone(),
                sunlit_points,
                sunlit_maps: sunlit_maps.clone(),
                ring_offset,
                bounce_planes: bounce_planes.clone(),
                through_planes: through_planes.clone(),
                bounce_covers,
                ..Default::default()
            },
            &rays_per_bin,
            to_eye,
            threads,
        );
        return;
    }
    println!(
        "| tree | leaves | τ | component | mean relative error per leaf | mean error / mean light | error of the mean (> 0: model brighter) | share of the light |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    // The crown the model assumes (uniform density, random orientations), then the procedural
    // versions of the pruning thesis' four trees.
    let mut crowns = vec![(
        "uniform ball".to_string(),
        uniform_ball(leaves, 1.5, 0.05, 5),
    )];
    for species in TreeSpecies::thesis_trees() {
        crowns.push((
            species.name.to_string(),
            generate(&species.with_leaf_count(leaves)).leaves,
        ));
    }
    for (name, crown) in crowns {
        let centre =
            crown.positions.iter().copied().sum::<Vec3>() / crown.positions.len().max(1) as f32;
        let started = std::time::Instant::now();
        let eye = centre + to_eye * 30.0;
        let neighbours = BinEstimate::Neighbours;
        let mut models = vec![
            (SunThroughCrown::SmoothEnvelope, neighbours),
            (SunThroughCrown::BlendedAttenuation, neighbours),
        ];
        models.extend(rays_per_bin.iter().map(|&rays_per_bin| {
            (
                SunThroughCrown::BlendedAttenuation,
                BinEstimate::Traced { rays_per_bin },
            )
        }));
        let runs = models_against_tracer(
            &crown, &material, &light, eye, stride, &settings, threads, &models,
        );
        let floor =
            tracer_against_itself(&crown, &material, &light, eye, stride, &settings, threads);
        let bins_label = |k: usize| match models[k].1 {
            BinEstimate::Neighbours => "§5.6 bins".to_string(),
            BinEstimate::Traced { rays_per_bin } => format!("traced bins, {rays_per_bin} rays"),
        };
        let mut rows: Vec<(String, LightingError, ComponentError)> = Vec::new();
        // Each model's run but the eq. 5.7 one, with the name of its bins.
        let blended: Vec<(String, LightingError)> = runs
            .iter()
            .enumerate()
            .skip(1)
            .map(|(k, run)| (bins_label(k), *run))
            .collect();
        for (bins, run) in &blended {
            rows.push((format!("sky direct, {bins}"), *run, run.sky));
        }
        rows.push((
            "sun direct, eq. 5.7 envelope blend".into(),
            runs[0],
            runs[0].sun,
        ));
        for (bins, run) in &blended {
            rows.push((
                format!("sun direct, attenuation blend, {bins}"),
                *run,
                run.sun,
            ));
        }
        rows.push((
            "sun indirect (1 bounce), eq. 5.7".into(),
            runs[0],
            runs[0].bounce,
        ));
        for (bins, run) in &blended {
            rows.push((
                format!("sun indirect (1 bounce), attenuation blend, {bins}"),
                *run,
                run.bounce,
            ));
        }
        for (bins, run) in &blended {
            rows.push((
                format!("sun indirect, attenuation blend vs 1–4 bounces, {bins}"),
                *run,
                run.bounces,
            ));
        }
        for (label, c) in [
            ("sky direct", floor.sky),
            ("sun direct", floor.sun),
            ("sun indirect (1 bounce)", floor.bounce),
        ] {
            rows.push((
                format!("{label}, the tracer against itself (its noise)"),
                floor,
                c,
            ));
        }
        for (label, run, c) in rows {
            println!(
                "| {name} | {} | {:.3} | {label} | {:.1} % | {:.1} % | {:.1} % | {:.0} % |",
                run.leaves,
                run.tau,
                100.0 * c.mean_relative,
                100.0 * c.mean_absolute,
                100.0 * c.of_the_mean,
                100.0 * c.share
            );
        }
        eprintln!("{name}: {:.1} s", started.elapsed().as_secs_f32());
    }
}

/// The `--sun-maps` table: for each procedural tree, the sun's share per leaf by each map
/// against the tracer's shadow rays. Texel sides are in leaf sizes (the species' leaf length).
fn sun_map_table(
    leaves: usize,
    stride: usize,
    points: u32,
    to_sun: Vec3,
    leaf_shadow: bevy_foliage::lighting::sun_maps::LeafShadowLookup,
    threads: usize,
) {
    use bevy_foliage::lighting::sun_maps::sun_visibility_against_tracer;
    println!(
        "| tree | leaf size | estimate of the sun's share | mean relative error per leaf | mean error / mean light | error of the mean |"
    );
    println!("|---|---|---|---|---|---|");
    for species in TreeSpecies::thesis_trees() {
        // The leaves' size at this count (fewer leaves are larger, `with_leaf_count`).
        let species = species.with_leaf_count(leaves);
        let leaf = species.leaf_size;
        let crown = generate(&species).leaves;
        let rows = sun_visibility_against_tracer(
            &crown,
            to_sun,
            stride,
            points,
            &[leaf / 16.0, leaf / 8.0, leaf / 4.0, leaf / 2.0, leaf],
            leaf * 4.0,
            leaf,
            leaf_shadow,
            threads,
        );
        for r in rows {
            println!(
                "| {} | {leaf:.3} | {} | {:.1} % | {:.1} % | {:.1} % |",
                species.name,
                r.method,
                100.0 * r.mean_relative,
                100.0 * r.mean_absolute,
                100.0 * r.of_the_mean
            );
        }
    }
}

/// The `--images` table: for the uniform ball and each procedural tree, the model's images
/// against the tracer's at three pixel sizes.
fn image_table(
    leaves: usize,
    material: &LeafMaterial,
    light: &TraceLight,
    settings: &bevy_foliage::lighting::image_error::ImageSettings,
    rays_per_bin: &[u32],
    to_eye: Vec3,
    threads: usize,
) {
    use bevy_foliage::lighting::image_error::{ImageError, images_against_tracer};
    println!(
        "| tree | leaves | eye rays hitting | pixel (leaves wide) | pixels across | component | estimate | mean error / mean light | mean relative error per pixel (leaf by leaf: per leaf) | error of the mean (> 0: model brighter) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let mut crowns = vec![(
        "uniform ball".to_string(),
        0.1f32,
        uniform_ball(leaves, 1.5, 0.05, 5),
    )];
    for species in TreeSpecies::thesis_trees() {
        // The leaves' size at this count (fewer leaves are larger, `with_leaf_count`).
        let species = species.with_leaf_count(leaves);
        crowns.push((
            species.name.to_string(),
            species.leaf_size,
            generate(&species).leaves,
        ));
    }
    let mut models = vec![(SunThroughCrown::BlendedAttenuation, BinEstimate::Neighbours)];
    models.extend(rays_per_bin.iter().map(|&rays_per_bin| {
        (
            SunThroughCrown::BlendedAttenuation,
            BinEstimate::Traced { rays_per_bin },
        )
    }));
    for (name, leaf_size, crown) in crowns {
        let started = std::time::Instant::now();
        let run = images_against_tracer(
            &crown,
            material,
            light,
            to_eye,
            leaf_size,
            settings,
            threads,
            &models,
            // Pixels of 1, 4 and 16 eye rays a side, and the leaves themselves.
            &[1, 4, 16, 0],
        );
        let label = |k: usize| match models[k].1 {
            BinEstimate::Neighbours => "§5.6 bins".to_string(),
            BinEstimate::Traced { rays_per_bin } => format!("traced bins, {rays_per_bin} rays"),
        };
        let row = |e: &ImageError, component: &str, estimate: &str, c: &ComponentError| {
            let (pixel, across) = if e.pixels_across == 0 {
                ("leaf by leaf".to_string(), "-".to_string())
            } else {
                (
                    format!("{:.2}", e.pixel_in_leaves),
                    e.pixels_across.to_string(),
                )
            };
            println!(
                "| {name} | {} | {} | {pixel} | {across} | {component} | {estimate} | {:.1} % | {:.1} % | {:.1} % |",
                crown.len(),
                run.hits,
                100.0 * c.mean_absolute,
                100.0 * c.mean_relative,
                100.0 * c.of_the_mean
            );
        };
        for size in 0..run.noise.len() {
            for (k, (_, errors)) in run.models.iter().enumerate() {
                row(&errors[size], "sky direct", &label(k), &errors[size].sky);
            }
            let seen_label = format!("{}, seen-part gain", label(models.len() - 1));
            let hotspot_label = format!(
                "{}, the crown's hotspot",
                if run.seen.is_empty() {
                    label(models.len() - 1)
                } else {
                    seen_label.clone()
                }
            );
            if let Some(seen) = run.seen.get(size) {
                row(seen, "sky direct", &seen_label, &seen.sky);
            }
            // What no eight blended gains beat (the sky is the component they are for).
            if let (Some(along), Some(at_point)) =
                (run.seen_along.get(size), run.open_at_point.get(size))
            {
                row(
                    along,
                    "sky direct",
                    &format!("{seen_label} traced for the eye's own direction (no blend)"),
                    &along.sky,
                );
                row(
                    at_point,
                    "sky direct",
                    &format!(
                        "{}, the open share at the eye ray's own point over the leaf's mean",
                        label(models.len() - 1)
                    ),
                    &at_point.sky,
                );
            }
            for ((side, points, of_leaf), alone, with_residual, stored) in &run.open_maps {
                let frame = if *of_leaf { ", the leaf's square" } else { "" };
                for (errors, how) in [
                    (alone, ""),
                    (with_residual, " times its residual gains"),
                    (stored, " times its residual gains, as stored"),
                ] {
                    if let Some(map) = errors.get(size) {
                        row(
                            map,
                            "sky direct",
                            &format!(
                                "{}, the leaf's open-share map ({side}x{side} cells, {points} points{frame}) at the eye ray's point{how}",
                                label(models.len() - 1)
                            ),
                            &map.sky,
                        );
                    }
                }
            }
            row(
                &run.noise[size],
                "sky direct",
                "the tracer against itself",
                &run.noise[size].sky,
            );
            for (k, (_, errors)) in run.models.iter().enumerate() {
                row(
                    &errors[size],
                    "sun direct",
                    &format!("attenuation blend, {}", label(k)),
                    &errors[size].sun,
                );
            }
            if let Some(seen) = run.seen.get(size) {
                row(
                    seen,
                    "sun direct",
                    &format!("attenuation blend, {seen_label}"),
                    &seen.sun,
                );
            }
            if let Some(spot) = run.hotspot.get(size) {
                row(spot, "sun direct", &hotspot_label, &spot.sun);
            }
            for (share, errors) in &run.shadow_map_sun {
                row(
                    &errors[size],
                    "sun direct",
                    &format!(
                        "shadow map, texels {share} of a leaf, {}{}",
                        settings.leaf_shadow.describe(),
                        if settings.leaf_shadow
                            == bevy_foliage::lighting::sun_maps::LeafShadowLookup::SHADERS
                        {
                            " (the leaf shaders')"
                        } else {
                            ""
                        }
                    ),
                    &errors[size].sun,
                );
            }
            for (share, trust, errors) in &run.drawn {
                row(
                    &errors[size],
                    "sun direct",
                    &format!(
                        "as drawn under texels {share} of a leaf: the hotspot's blend moved {trust:.2} of the way to the shadow map"
                    ),
                    &errors[size].sun,
                );
            }
            for (label, errors) in &run.sunlit {
                row(&errors[size], "sun direct", label, &errors[size].sun);
            }
            for (k, (_, errors)) in run.models.iter().enumerate() {
                row(
                    &errors[size],
                    "sun indirect (1 bounce)",
                    &format!("attenuation blend, {}", label(k)),
                    &errors[size].bounce,
                );
            }
            if let Some(seen) = run.seen.get(size) {
                row(
                    seen,
                    "sun indirect (1 bounce)",
                    &format!(
                        "attenuation blend, {}, covered-part gain",
                        label(models.len() - 1)
                    ),
                    &seen.bounce,
                );
            }
            // The covered part's gain from the limits' gains (the sky's rows above).
            if let (Some(along), Some(at_point)) =
                (run.seen_along.get(size), run.open_at_point.get(size))
            {
                row(
                    along,
                    "sun indirect (1 bounce)",
                    &format!(
                        "attenuation blend, {}, covered-part gain from the eye's own direction",
                        label(models.len() - 1)
                    ),
                    &along.bounce,
                );
                row(
                    at_point,
                    "sun indirect (1 bounce)",
                    &format!(
                        "attenuation blend, {}, the covered share at the eye ray's own point",
                        label(models.len() - 1)
                    ),
                    &at_point.bounce,
                );
            }
            if let Some(spot) = run.hotspot.get(size) {
                row(
                    spot,
                    "sun indirect (1 bounce)",
                    &hotspot_label,
                    &spot.bounce,
                );
            }
            for (g, name) in run.gathered.iter().zip([
                "eq. 5.24 × gathered ratios (14 suns blended), covered-part gain",
                "gathered for this sun alone, covered-part gain",
                "gathered for this sun alone, no gain",
                "eq. 5.24 × gathered ratios, no gain",
                "eq. 5.24 × gathered ratios, covered-part gain, hotspot measured with them (as the leaf shaders draw it)",
            ]) {
                row(&g[size], "sun indirect (1 bounce)", name, &g[size].bounce);
            }
            if let Some(g) = run.regathered.get(size) {
                row(
                    g,
                    "sun indirect (1 bounce)",
                    "eq. 5.24 × ratios re-gathered for this sun, covered-part gain, the blend's hotspot",
                    &g.bounce,
                );
            }
            for (count, g, _) in &run.rings {
                row(
                    &g[size],
                    "sun indirect (1 bounce)",
                    &format!(
                        "eq. 5.24 × ratios re-gathered on a ring of {count} suns at its elevation, {}",
                        bevy_foliage::lighting::image_error::sun_between(settings.ring_offset)
                    ),
                    &g[size].bounce,
                );
            }
            for (count, g, _, _) in &run.ring_spots {
                for (component, errors) in [
                    ("sun direct", &g[size].sun),
                    ("sun indirect (1 bounce)", &g[size].bounce),
                ] {
                    row(
                        &g[size],
                        component,
                        &format!(
                            "ring of {count} suns, the ring's own hotspot (measured at the sun's height against the ring)"
                        ),
                        errors,
                    );
                }
            }
            for (name, g) in &run.bounce_floor {
                row(&g[size], "sun indirect (1 bounce)", name, &g[size].bounce);
            }
            for (pool, g) in &run.pooled {
                row(
                    &g[size],
                    "sun indirect (1 bounce)",
                    &format!("ratios pooled over {pool} leaves, as the leaf shaders draw them"),
                    &g[size].bounce,
                );
            }
            row(
                &run.noise[size],
                "sun indirect (1 bounce)",
                "the tracer against itself",
                &run.noise[size].bounce,
            );
        }
        if let Some(h) = &run.hotspot_factors {
            eprintln!("{name}: hotspot sun {:.3?} bounce {:.3?}", h.sun, h.bounce);
        }
        if !run.gathered.is_empty() {
            eprintln!(
                "{name}: bounce ratios of {} leaves gathered in {:.2} s on {threads} threads",
                crown.len(),
                run.gathered_seconds
            );
            eprintln!(
                "{name}: ratios of {} leaves re-gathered for one sun in {:.2} s on {threads} threads",
                crown.len(),
                run.regathered_seconds
            );
            for (count, _, h, seconds) in &run.ring_spots {
                eprintln!(
                    "{name}: ring of {count}: its own hotspot sun {:.3?} bounce {:.3?}, measured in {seconds:.2} s on {threads} threads",
                    h.sun, h.bounce
                );
            }
            for (count, _, seconds) in &run.rings {
                eprintln!(
                    "{name}: ratios of {} leaves re-gathered on a ring of {count} suns in {seconds:.2} s on {threads} threads",
                    crown.len()
                );
            }
        }
        for (count, seconds) in &run.sunlit_seconds {
            eprintln!(
                "{name}: sunlit shares of {} leaves traced on a ring of {count} suns in {seconds:.2} s on {threads} threads",
                crown.len()
            );
        }
        for seconds in &run.ring_hotspot_seconds {
            eprintln!(
                "{name}: the ring's own hotspot on its shares fitted in {seconds:.2} s on {threads} threads"
            );
        }
        eprintln!("{name}: {:.1} s", started.elapsed().as_secs_f32());
    }
}

/// A direction `x,y,z` from the command line, normalised; `None` for anything else (or a
/// zero vector).
/// The comma-separated items of `flag`'s value, each read by `item` (`None`: not one), or a
/// message saying what the flag `takes` and exit status 2: a list with a malformed or
/// out-of-range item is refused whole rather than run without that item.
fn list_flag<T>(
    flag: &str,
    value: Option<&String>,
    takes: &str,
    item: impl Fn(&str) -> Option<T>,
) -> Vec<T> {
    let items: Option<Vec<T>> = value.and_then(|v| v.split(',').map(|c| item(c.trim())).collect());
    match items {
        Some(items) if !items.is_empty() => items,
        _ => {
            eprintln!("{flag} takes {takes}");
            std::process::exit(2)
        }
    }
}

/// An `AxB` list item (`--bounce-planes`' SxP, `--open-maps`' CxP): two whole numbers, each
/// within its range.
fn side_by_count(
    item: &str,
    sides: std::ops::RangeInclusive<u32>,
    counts: std::ops::RangeInclusive<u32>,
) -> Option<(u32, u32)> {
    let (side, count) = item.split_once('x')?;
    let side = side.trim().parse().ok().filter(|s| sides.contains(s))?;
    let count = count.trim().parse().ok().filter(|c| counts.contains(c))?;
    Some((side, count))
}

fn direction(arg: Option<&String>) -> Option<Vec3> {
    arg.map(|v| v.split(',').map(|c| c.trim().parse::<f32>()).collect())
        .and_then(|c: Result<Vec<f32>, _>| c.ok())
        .filter(|c| c.len() == 3 && c.iter().all(|c| c.is_finite()))
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .filter(|v| v.length() > 1e-3)
        .map(Vec3::normalize)
}
