//! The tree lighting against the path tracer as images, the way Boulanger 2008 reports its
//! error (§5.7, fig. 5.16: "an average error of 5 %, 7.5 %, 6 %" for the sky, the sun and the
//! sun's bounce, against Monte Carlo renders with 256 rays per intersection point).
//!
//! A grid of parallel eye rays is cast over the crown; at the point each ray hits, the tracer
//! gathers the light there (the same rays as [`super::path_trace`], all from that one point) and
//! the model gives the leaf's light towards the eye. A pixel is a square block of the grid, so
//! one trace gives the error at several pixel sizes. Why the pixel size matters: leaf by leaf
//! the sun is all or nothing, which a statistical model of the crown cannot know (the per-leaf
//! tables of `tree_lighting_error`); a pixel as wide as several leaves averages leaves in sun
//! and in shade, and that average is what the model estimates.
//!
//! Plain Rust, no render types.

use super::bins::proxies;
use super::envelope::CrownEnvelope;
use super::gathered_bounce::DEFAULT_BOUNCE_POOL;
use super::leaf_scene::LeafScene;
use super::model::{
    LeafMaterial, SkyLight, SunBounce, SunThroughCrown, bsdf, lobe_blend, open_share, sun_radiance,
};
use super::open_map::{LeafOpenMap, MapFrame, STORED_SIDE, open_map};
use super::path_trace::{
    ComponentError, ModelLight, TraceLight, TraceSettings, component_error, envelope_by, gather,
    luminance,
};
use super::seen_part::{
    DEFAULT_SEEN_POINTS, GAIN_RANGE, covered_gain, open_share_at, seen_gain, seen_part_gain_along,
    seen_part_gains_of,
};
use super::sun_maps::{
    LEAF_SHADOW_FINE, LeafShadowLookup, LightFrame, foliage_maps, shadow_map_trust,
};
use super::traced_bins::BinEstimate;
use crate::pruning::leaves::LeafSet;
use crate::rng::SplitMix64;
use bevy::math::Vec3;

/// Rays for each open share of [`ImageComparison::open_at_point`].
pub const OPEN_RAYS: u32 = 64;

/// Points per leaf for the leaf's mean open share of [`ImageComparison::open_at_point`].
pub const OPEN_POINTS: u32 = 64;

/// How the crown is rendered and traced.
#[derive(Clone, Debug)]
pub struct ImageSettings {
    /// Eye rays a side over the crown's square: the pixels of the finest image.
    pub samples: u32,
    /// Rays per intersection point for the sky and each bounce (the thesis' renders: 256).
    pub directions: u32,
    /// Bounces of sunlight followed for the several-bounce figure (at least 1).
    pub bounces: u32,
    /// Seed of the tracer's random sequences (the noise rows trace again with another).
    pub seed: u64,
    /// Points per leaf for the gains of [`super::seen_part`] (0: not measured).
    pub seen_points: u32,
    /// The weight of the directions below the horizon in the open share of those gains
    /// ([`super::seen_part::seen_part_gains`]; 1, what bakes use, by default).
    pub seen_below: f32,
    /// Seed of those gains' points and rays (0, what bakes use, by default; another shows how
    /// much of a figure is the gains' own noise).
    pub seen_seed: u64,
    /// Whether to measure the crown's hotspot ([`super::hotspot`], with another seed than the
    /// images') and render the last model with it.
    pub hotspot: bool,
    /// How the shadow map's row compares each point with the map (the leaf shaders'
    /// [`LeafShadowLookup::SHADERS`] by default).
    pub leaf_shadow: LeafShadowLookup,
    /// The shadow map's texel sides for its rows, as shares of the leaf's size (by default
    /// [`LEAF_SHADOW_FINE`] alone, up to which the leaf shaders take the map alone).
    pub shadow_texels: Vec<f32>,
    /// Rays per leaf for the bounce gathered from the neighbours ([`super::gathered_bounce`];
    /// 0: not measured).
    pub bounce_rays: u32,
    /// Rays per leaf for the ratios re-gathered on each ring of [`ImageSettings::sun_rings`]
    /// (0, by default: [`ImageSettings::bounce_rays`], as many as the bake's gather); an app's
    /// ring gathers [`super::settings::BounceRingSettings::rays`].
    pub ring_rays: u32,
    /// Passes of [`ImageSettings::ring_rays`] each ring's ratios are the mean of
    /// ([`super::bounce_ring::RingRefinement`]; 0 or 1, by default: one gather).
    pub ring_passes: u32,
    /// Leaves pooled into each leaf's gathered ratios
    /// ([`super::gathered_bounce::pooled_ratios`]): the first for the rows of
    /// [`ImageComparison::gathered`], each for a row of [`ImageComparison::pooled`] (by
    /// default [`DEFAULT_BOUNCE_POOL`] alone).
    pub bounce_pools: Vec<usize>,
    /// Suns on each ring of re-gathered ratios measured ([`ImageComparison::rings`]; none by
    /// default).
    pub sun_rings: Vec<usize>,
    /// Points per leaf for each leaf's sunlit share traced for the sun and on each ring of
    /// `sun_rings` ([`super::sunlit_share`], [`ImageComparison::sunlit`]; 0: not measured).
    pub sunlit_points: u32,
    /// Open-share maps measured on the sky, each as (cells a side, points a leaf, whether
    /// over the square the leaf shaders can find, [`super::open_map::MapFrame::of_leaf`],
    /// rather than the points' bounding rectangle) ([`super::open_map::open_map`],
    /// [`ImageComparison::open_maps`]; none by default).
    pub open_maps: Vec<(u32, u32, bool)>,
    /// Cells a side of each map of the sunlit share across each leaf measured for the image's
    /// sun, from [`ImageSettings::sunlit_points`] points a leaf over the square the leaf
    /// shaders can find ([`super::open_map::MapFrame::of_leaf`]), read at the eye ray's point
    /// ([`ImageComparison::sunlit`]; none by default). With any, a row of the share at the
    /// eye ray's point itself, what no map beats.
    pub sunlit_maps: Vec<u32>,
    /// Where the image's sun stands between two nodes of each ring of
    /// [`ImageSettings::sun_rings`], as a share of a node's step in azimuth: 0.5 (by default)
    /// midway, what a tree turned by half a step sees, the farthest from the ring's suns; 0 on
    /// a node. Instances turned at random see every offset.
    pub ring_offset: f32,
    /// Per entry (points a side, rays a point), rows of the bounce for the image's sun from
    /// each leaf's [`super::bounce_floor::bounce_planes`] (the mean, and a plane a face read at
    /// the eye ray's point) and from the gather at the eye ray's own point with as many rays
    /// ([`ImageComparison::bounce_floor`]; none by default).
    pub bounce_planes: Vec<(u32, u32)>,
    /// Per ray count, rows of the bounce for the image's sun gathered with shadow rays and with
    /// the neighbours' sunlit planes from [`ImageSettings::sunlit_points`] points in their place
    /// ([`super::bounce_floor::gather_through_planes`]; none by default, and none without
    /// sunlit points).
    pub through_planes: Vec<u32>,
    /// Rows of the bounce with its covered part's gain from finer than the eight gains: each
    /// leaf's stored open map at the eye ray's point, and the covered share at the point
    /// itself ([`ImageComparison::bounce_floor`]; off by default).
    pub bounce_covers: bool,
}

impl Default for ImageSettings {
    fn default() -> Self {
        Self {
            samples: 128,
            directions: 256,
            bounces: 1,
            seed: 1,
            seen_points: DEFAULT_SEEN_POINTS,
            seen_below: 1.0,
            seen_seed: 0,
            hotspot: false,
            leaf_shadow: LeafShadowLookup::SHADERS,
            shadow_texels: vec![LEAF_SHADOW_FINE],
            bounce_rays: 0,
            ring_rays: 0,
            ring_passes: 1,
            bounce_pools: vec![DEFAULT_BOUNCE_POOL],
            sun_rings: Vec::new(),
            sunlit_points: 0,
            open_maps: Vec::new(),
            sunlit_maps: Vec::new(),
            ring_offset: 0.5,
            bounce_planes: Vec::new(),
            through_planes: Vec::new(),
            bounce_covers: false,
        }
    }
}

/// One image's error, per component, at one pixel size. [`ComponentError::leaves`] counts the
/// pixels in its relative mean, and `mean_relative` is per pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImageError {
    /// Pixels across the crown's square; 0 for the leaves themselves as the pixels (the error
    /// leaf by leaf, [`leaf_means`]).
    pub pixels_across: u32,
    /// A pixel's side in leaf sizes.
    pub pixel_in_leaves: f32,
    /// Sky and ground, direct.
    pub sky: ComponentError,
    /// The sun, direct.
    pub sun: ComponentError,
    /// The sun after one bounce (the model's term against the traced single bounce).
    pub bounce: ComponentError,
}

/// Every image comparison of one crown, each per pixel size (finest first).
#[derive(Clone, Debug, Default)]
pub struct ImageComparison {
    /// Per model, in the order given, its errors per pixel size, and the crown's fitted τ.
    pub models: Vec<(f32, Vec<ImageError>)>,
    /// Per texel side of [`ImageSettings::shadow_texels`] (a share of the leaf's size), the sun
    /// read at each eye ray's point from a shadow map of such texels as the leaf shaders read
    /// it at the leaf ([`ImageSettings::leaf_shadow`]), per pixel size; sky and bounce are
    /// those of the first model.
    pub shadow_map_sun: Vec<(f32, Vec<ImageError>)>,
    /// The tracer against itself (a second trace with another seed): its own noise per pixel
    /// size, below which no model can be shown closer to it.
    pub noise: Vec<ImageError>,
    /// The last model with its sky and sun scaled by each leaf's seen-part gain towards the
    /// eye (the sun's share capped at 1, as the leaf shaders cap it) and its bounce by the
    /// covered part's gain ([`super::seen_part`]), per pixel size; empty when
    /// [`ImageSettings::seen_points`] is 0.
    pub seen: Vec<ImageError>,
    /// As `seen`, with each leaf's gain traced for the eye's own direction
    /// ([`super::seen_part::seen_part_gain_along`], as many points) in place of the eight
    /// blended: what no blend of eight gains beats at those points. Empty with `seen`.
    pub seen_along: Vec<ImageError>,
    /// As `seen`, with the gain at each eye ray's own point: the open share there over the
    /// leaf's mean ([`super::seen_part::open_share_at`], [`OPEN_RAYS`] rays, the mean from
    /// [`OPEN_POINTS`] points): what no gain per leaf and eye direction beats. Empty with
    /// `seen`.
    pub open_at_point: Vec<ImageError>,
    /// Per map of [`ImageSettings::open_maps`], as `seen` with the gain from each leaf's
    /// open-share map read at the eye ray's point, then that times the map's residual gains
    /// blended towards the eye, then (for a map of [`STORED_SIDE`] cells over the leaf's
    /// square) that as a bake stores it ([`LeafOpenMap`], the residual gains quantised as
    /// the gains are): what a bake stores and the leaf shaders draw. Empty with `seen`.
    pub open_maps: Vec<OpenMapRows>,
    /// As `seen` (or the last model), the sun's term and the bounce scaled by the crown's
    /// hotspot at the image's phase angle; empty unless [`ImageSettings::hotspot`].
    pub hotspot: Vec<ImageError>,
    /// As `seen` (or the last model) with the bounce from the leaves' own neighbours
    /// ([`super::gathered_bounce`]): eq. 5.24 scaled by each leaf's gathered ratios blended
    /// towards the sun, then the gather for the sun's own direction alone (what no blend
    /// beats); both scaled by the covered part's gain where the gains were measured; then the
    /// sun's own gather without that gain; the ratios without it; and, with
    /// [`ImageSettings::hotspot`], the ratios with the gain and the crown's hotspot measured
    /// against them — what the leaf shaders draw. The ratios as a bake stores them. Empty
    /// unless [`ImageSettings::bounce_rays`].
    pub gathered: Vec<Vec<ImageError>>,
    /// Seconds the ratios of every leaf took to gather (on the threads given), when measured.
    pub gathered_seconds: f32,
    /// The bounce with each leaf's ratios re-gathered for the image's sun alone
    /// ([`super::gathered_bounce::sun_ratios_of`], quantised as a bake stores ratios) in place
    /// of the blend over the fourteen basis suns, drawn as the leaf shaders draw the blend's
    /// (the covered part's gain where the gains were measured, the hotspot measured against the
    /// blend's ratios where [`ImageSettings::hotspot`]), per pixel size. Empty unless
    /// [`ImageSettings::bounce_rays`].
    pub regathered: Vec<ImageError>,
    /// Seconds that re-gather took for every leaf (on the threads given).
    pub regathered_seconds: f32,
    /// Per ring of [`ImageSettings::sun_rings`]: its count, the bounce with each leaf's ratios
    /// re-gathered on a ring of that many suns at the sun's elevation
    /// ([`super::gathered_bounce::sun_ring`]), the sun midway between two of them, drawn as
    /// `regathered` is, per pixel size; and the seconds that gather took.
    pub rings: Vec<(usize, Vec<ImageError>, f32)>,
    /// Per ring of `rings`, with [`ImageSettings::hotspot`]: the images drawn with the ring's
    /// own hotspot in place of the blend's — measured for suns at the sun's height
    /// ([`super::hotspot::HotspotSuns::Height`]) against the bounce with the ring's ratios,
    /// traced as `foliage_bake` traces a bake's ([`super::hotspot::HotspotSettings::OFFLINE`]),
    /// both its sun and its bounce factors applied — per pixel size; that hotspot; and the
    /// seconds its measurement took.
    pub ring_spots: Vec<(usize, Vec<ImageError>, super::hotspot::Hotspot, f32)>,
    /// Per pool of [`ImageSettings::bounce_pools`]: the bounce as the leaf shaders draw it
    /// with the ratios so pooled (eq. 5.24 scaled by them, the covered part's gain where the
    /// gains were measured, and with [`ImageSettings::hotspot`] the crown's hotspot measured
    /// against them), per pixel size. Empty unless [`ImageSettings::bounce_rays`].
    pub pooled: Vec<(usize, Vec<ImageError>)>,
    /// The sun as the leaf shaders draw it under a shadow map of each texel side of
    /// `shadow_map_sun` that lies between [`super::sun_maps::LEAF_SHADOW_FINE`] and
    /// [`super::sun_maps::LEAF_SHADOW_COARSE`] of a leaf: `hotspot`'s sun (the baked blend)
    /// moved towards that map's by the shaders' trust in it
    /// ([`super::sun_maps::shadow_map_trust`]), sky and bounce `hotspot`'s; per texel side
    /// (with the trust), per pixel size. Empty unless [`ImageSettings::hotspot`].
    pub drawn: Vec<(f32, f32, Vec<ImageError>)>,
    /// The sun through the crown from each leaf's sunlit share ([`super::sunlit_share`],
    /// [`ImageSettings::sunlit_points`] points a leaf) in place of the baked attenuations'
    /// blend, under a label: traced for the image's sun, then on each ring of
    /// [`ImageSettings::sun_rings`] with the sun midway between two nodes (read linearly in
    /// azimuth); each as the leaf's share (one value a leaf) and as its share's plane over
    /// the leaf read at the eye ray's point ([`super::sunlit_share::SharePlane`]); each as it
    /// is, scaled by the leaf's seen-part gain towards the eye (capped at 1, where the gains
    /// were measured), with that the crown's hotspot exponent (where measured; fitted against
    /// the blend), and for a ring's shares with [`ImageSettings::hotspot`] a hotspot fitted
    /// against them for suns at the sun's height ([`super::hotspot::HotspotSuns::Height`]).
    /// Sky and bounce are the first model's; per pixel size. Empty unless `sunlit_points`.
    pub sunlit: Vec<(String, Vec<ImageError>)>,
    /// Per ring of [`ImageSettings::sun_rings`] with [`ImageSettings::sunlit_points`]: its
    /// count and the seconds every leaf's shares on it took to trace (on the threads given).
    pub sunlit_seconds: Vec<(usize, f32)>,
    /// Seconds each fit of a ring's own hotspot on its shares took
    /// ([`super::bounce_ring::ring_sun_hotspot`], on the threads given).
    pub ring_hotspot_seconds: Vec<f32>,
    /// What values stored per leaf make of the bounce, under a label (with
    /// [`ImageSettings::bounce_rays`]): for the image's sun per [`ImageSettings::bounce_planes`]
    /// the planes' mean, the planes at the eye ray's point and the gather at that point; per
    /// [`ImageSettings::through_planes`] the gather with shadow rays and through the neighbours'
    /// sunlit planes; with [`ImageSettings::bounce_covers`] (and the gains), the sun's own
    /// gather and each ring with its own hotspot with the covered part's gain from the eight
    /// gains, from each leaf's stored open map at the eye ray's point, and from the covered
    /// share at the point itself over the leaf's mean. Sky and sun as the first rows of
    /// [`ImageComparison::gathered`].
    pub bounce_floor: Vec<(String, Vec<ImageError>)>,
    /// The hotspot measured, when it was.
    pub hotspot_factors: Option<super::hotspot::Hotspot>,
    /// Eye rays that hit a leaf.
    pub hits: usize,
}

/// The rows of one open-share map of [`ImageComparison::open_maps`]: the map as settings give
/// it (cells a side, points a leaf, over the leaf's square), the images with the map's gain
/// alone, with it times the map's residual gains blended towards the eye, and that as a bake
/// stores it (empty unless stored).
pub type OpenMapRows = (
    (u32, u32, bool),
    Vec<ImageError>,
    Vec<ImageError>,
    Vec<ImageError>,
);

/// Where the bounce's covered-part gain comes from in an image.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Cover {
    /// None.
    Not,
    /// The eight seen-part gains blended towards the eye.
    Gains,
    /// The leaf's stored open map at the eye ray's point (the eight gains where it has none).
    Map,
    /// The covered share at the eye ray's point over the leaf's mean.
    Point,
}

/// Leaf `leaf`'s mean open share ([`open_share_at`] at [`OPEN_POINTS`] points, [`OPEN_RAYS`]
/// rays each; seeded by the leaf).
fn mean_open_share(scene: &LeafScene, leaf: u32) -> f32 {
    let mut rng = SplitMix64::new(0x09E4 ^ (leaf as u64).wrapping_mul(0x9E37_79B9));
    (0..OPEN_POINTS)
        .map(|_| {
            let p = scene.point_on(leaf as usize, &mut rng);
            open_share_at(scene, leaf as usize, p, OPEN_RAYS, 1.0, &|_| 1.0, &mut rng)
        })
        .sum::<f32>()
        / OPEN_POINTS as f32
}

/// The open share at eye ray `k`'s point ([`OPEN_RAYS`] rays; seeded by the eye ray).
fn open_at_sample(scene: &LeafScene, k: usize, s: &Sample) -> f32 {
    let mut rng = SplitMix64::new(0x0BE4 ^ (k as u64).wrapping_mul(0x9E37_79B9));
    open_share_at(
        scene,
        s.leaf as usize,
        s.point,
        OPEN_RAYS,
        1.0,
        &|_| 1.0,
        &mut rng,
    )
}

/// What one eye ray found: the leaf, the point, and the traced light there from two seeds
/// (luminance of sky, sun, one bounce, all bounces).
struct Sample {
    leaf: u32,
    point: Vec3,
    traced: [[f32; 4]; 2],
}

/// The block means of a `side × side` grid in blocks of `block × block` (`block` divides
/// `side`): a pixel's value is the mean of its eye rays', background counted as dark.
pub fn block_means(values: &[f32], side: usize, block: usize) -> Vec<f32> {
    let across = side / block.max(1);
    let mut out = vec![0.0; across * across];
    for (i, v) in values.iter().enumerate().take(side * side) {
        let (x, y) = (i % side / block, i / side / block);
        if x < across && y < across {
            out[y * across + x] += v;
        }
    }
    let per = 1.0 / (block * block) as f32;
    out.iter_mut().for_each(|v| *v *= per);
    out
}

/// Each leaf's mean of `values` over the eye rays that hit it (`leaf_of`: per eye ray, the
/// leaf it hit), leaves in order, those no eye ray hit left out: an image whose pixels are the
/// leaves themselves, for the error leaf by leaf (the thesis' measure is per pixel, the
/// error a leaf gets per leaf).
pub fn leaf_means(values: &[f32], leaf_of: &[Option<u32>]) -> Vec<f32> {
    let count = leaf_of
        .iter()
        .flatten()
        .map(|&l| l as usize + 1)
        .max()
        .unwrap_or(0);
    let mut sum = vec![(0.0f64, 0u32); count];
    for (v, leaf) in values.iter().zip(leaf_of) {
        if let Some(l) = leaf {
            let slot = &mut sum[*l as usize];
            slot.0 += *v as f64;
            slot.1 += 1;
        }
    }
    sum.iter()
        .filter(|(_, n)| *n > 0)
        .map(|(s, n)| (s / *n as f64) as f32)
        .collect()
}

/// Renders `leaves` seen along `-to_eye` (parallel eye rays) with the model's every
/// `(blend, bins)` of `models` and with the tracer, and measures each image against the
/// traced one at pixels of `blocks × blocks` eye rays (block sizes that do not divide
/// [`ImageSettings::samples`] are skipped), a block of 0 standing for the leaves themselves
/// ([`leaf_means`]: `pixels_across` 0, a pixel a leaf wide), where `mean_relative` is the mean
/// relative error per leaf. `leaf_size` sets the shadow map's texels (a quarter of it) and the
/// pixel sizes reported.
#[allow(clippy::too_many_arguments)]
pub fn images_against_tracer(
    leaves: &LeafSet,
    material: &LeafMaterial,
    light: &TraceLight,
    to_eye: Vec3,
    leaf_size: f32,
    settings: &ImageSettings,
    threads: usize,
    models: &[(SunThroughCrown, BinEstimate)],
    blocks: &[u32],
) -> ImageComparison {
    let scene = LeafScene::new(leaves);
    if scene.leaf_count() == 0 {
        return ImageComparison::default();
    }
    let view = to_eye.normalize_or(Vec3::Z);
    let centre = leaves.positions.iter().copied().sum::<Vec3>() / leaves.positions.len() as f32;
    let radius = leaves
        .positions
        .iter()
        .map(|p| p.distance(centre))
        .fold(0.0f32, f32::max)
        .max(1e-3);
    let side = settings.samples.max(1) as usize;
    let cell = 2.0 * radius / side as f32;
    let (a, b) = view.any_orthonormal_pair();
    let trace = TraceSettings {
        points: 1,
        directions: settings.directions,
        bounces: settings.bounces.max(1),
        seed: settings.seed,
    };
    let again = TraceSettings {
        seed: settings.seed.wrapping_add(0x5851_F42D),
        ..trace
    };
    let sample = |index: usize| -> Option<Sample> {
        let mut rng =
            SplitMix64::new(settings.seed ^ (index as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        // Jittered in its cell: a pixel's eye rays spread over its whole area.
        let u = -radius + ((index % side) as f32 + rng.next_f32()) * cell;
        let v = radius - ((index / side) as f32 + rng.next_f32()) * cell;
        let origin = centre + a * u + b * v + view * (2.0 * radius + 1.0);
        let (t, leaf) = scene.hit(origin, -view, u32::MAX)?;
        let x = origin - view * t;
        let n = scene.normal(leaf as usize);
        let sun = if scene.hit(x, light.to_sun, leaf).is_none() {
            luminance(bsdf(material, n, view, light.to_sun) * light.sun)
        } else {
            0.0
        };
        let mut traced = [[0.0; 4]; 2];
        for (k, s) in [trace, again].iter().enumerate() {
            let mut rng =
                SplitMix64::new(s.seed ^ (index as u64).wrapping_mul(0xD1B5_4A32_D192_ED03));
            let g = gather(
                &scene,
                material,
                light,
                leaf as usize,
                view,
                s,
                &mut rng,
                &mut |_| x,
            );
            traced[k] = [
                luminance(g.sky),
                sun,
                luminance(g.bounce),
                luminance(g.bounces),
            ];
        }
        Some(Sample {
            leaf,
            point: x,
            traced,
        })
    };
    let indices: Vec<usize> = (0..side * side).collect();
    let chunk = indices.len().div_ceil(threads.max(1)).max(1);
    let samples: Vec<Option<Sample>> = std::thread::scope(|s| {
        let handles: Vec<_> = indices
            .chunks(chunk)
            .map(|part| s.spawn(move || part.iter().map(|&i| sample(i)).collect::<Vec<_>>()))
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("image tracer thread"))
            .collect()
    });
    let traced_column = |seed: usize, k: usize| -> Vec<f32> {
        samples
            .iter()
            .map(|s| s.as_ref().map_or(0.0, |s| s.traced[seed][k]))
            .collect()
    };
    let blocks: Vec<usize> = blocks
        .iter()
        .map(|&b| b as usize)
        .filter(|&b| b == 0 || side.is_multiple_of(b))
        .collect();
    let leaf_of: Vec<Option<u32>> = samples.iter().map(|s| s.as_ref().map(|s| s.leaf)).collect();
    // Measures images given per eye ray (sky, sun, bounce) against the first trace.
    let reference: [Vec<f32>; 4] = std::array::from_fn(|k| traced_column(0, k));
    let measure = |image: &[Vec<f32>; 3]| -> Vec<ImageError> {
        blocks
            .iter()
            .map(|&block| {
                let px = |v: &[f32]| {
                    if block == 0 {
                        leaf_means(v, &leaf_of)
                    } else {
                        block_means(v, side, block)
                    }
                };
                let (sky, sun, bounce, bounces) = (
                    px(&reference[0]),
                    px(&reference[1]),
                    px(&reference[2]),
                    px(&reference[3]),
                );
                let total: f32 = sky.iter().chain(&sun).chain(&bounces).sum();
                ImageError {
                    pixels_across: side.checked_div(block).unwrap_or(0) as u32,
                    pixel_in_leaves: if block == 0 {
                        1.0
                    } else {
                        cell * block as f32 / leaf_size.max(1e-6)
                    },
                    sky: component_error(&px(&image[0]), &sky, total),
                    sun: component_error(&px(&image[1]), &sun, total),
                    bounce: component_error(&px(&image[2]), &bounce, total),
                }
            })
            .collect()
    };
    let noise = measure(&[
        traced_column(1, 0),
        traced_column(1, 1),
        traced_column(1, 2),
    ]);

    let leaf_proxies = proxies(leaves);
    let sky = SkyLight::sky_and_ground(light.sky, light.ground);
    let mut first_model: Option<[Vec<f32>; 3]> = None;
    let mut last_model: Option<([Vec<f32>; 3], CrownEnvelope)> = None;
    let models: Vec<(f32, Vec<ImageError>)> = models
        .iter()
        .map(|&(blend, bins)| {
            let envelope = envelope_by(bins, &leaf_proxies, &scene, threads);
            let tau = envelope.tau;
            let bounce = SunBounce::new(material, light.to_sun, tau);
            let model = ModelLight {
                material,
                light,
                sky: &sky,
                bounce: &bounce,
                blend,
                tau,
            };
            let mut image: [Vec<f32>; 3] = Default::default();
            for s in &samples {
                let values = s.as_ref().map_or([0.0; 3], |s| {
                    let leaf = s.leaf as usize;
                    model.of(&envelope.leaves[leaf], scene.normal(leaf), view)
                });
                for k in 0..3 {
                    image[k].push(values[k]);
                }
            }
            let errors = measure(&image);
            if first_model.is_none() {
                first_model = Some(image.clone());
            }
            last_model = Some((image, envelope));
            (tau, errors)
        })
        .collect();

    // The shadow map's sun at each eye ray's point, as the leaf shaders read it at the leaf,
    // at each texel side asked for (by default `LEAF_SHADOW_FINE` of a leaf alone).
    let mapped_suns: Vec<(f32, Vec<f32>)> = settings
        .shadow_texels
        .iter()
        .map(|&share| {
            let texel = share.max(1e-3) * leaf_size.max(1e-6);
            let maps = foliage_maps(leaves, LightFrame::around(leaves, light.to_sun, texel));
            let mapped: Vec<f32> = samples
                .iter()
                .map(|s| {
                    s.as_ref().map_or(0.0, |s| {
                        let n = scene.normal(s.leaf as usize);
                        let visible = settings.leaf_shadow.visible(&maps, s.point, n);
                        luminance(sun_radiance(
                            material,
                            n,
                            view,
                            light.to_sun,
                            visible,
                            light.sun,
                        ))
                    })
                })
                .collect();
            (share, mapped)
        })
        .collect();
    let [model_sky, _, model_bounce] = first_model.unwrap_or_else(|| {
        [
            reference[0].clone(),
            reference[1].clone(),
            reference[2].clone(),
        ]
    });
    let shadow_map_sun: Vec<(f32, Vec<ImageError>)> = mapped_suns
        .iter()
        .map(|(share, mapped)| {
            (
                *share,
                measure(&[model_sky.clone(), mapped.clone(), model_bounce.clone()]),
            )
        })
        .collect();
    let gains = (settings.seen_points > 0).then(|| {
        let all: Vec<u32> = (0..scene.leaf_count() as u32).collect();
        seen_part_gains_of(
            &scene,
            &all,
            settings.seen_points,
            settings.seen_below,
            &|_| 1.0,
            settings.seen_seed,
            threads,
        )
    });
    let hotspot_factors = match (&last_model, settings.hotspot) {
        (Some((_, envelope)), true) => Some(super::hotspot::crown_hotspot(
            &scene,
            envelope,
            gains.as_deref().unwrap_or(&[]),
            &[],
            &|l| Some(l as usize),
            material,
            &|_| 1.0,
            &super::hotspot::HotspotSettings::OFFLINE,
            threads,
        )),
        _ => None,
    };
    // Each leaf's sunlit plane towards the image's sun, traced once for the rows that read it
    // (the bounce through the planes, the sun from the planes).
    let own_planes = std::cell::OnceCell::new();
    let own_planes = || -> &Vec<super::sunlit_share::SharePlane> {
        own_planes.get_or_init(|| {
            let all: Vec<u32> = (0..scene.leaf_count() as u32).collect();
            super::sunlit_share::sunlit_planes(
                &scene,
                &all,
                &[light.to_sun],
                settings.sunlit_points,
                &|_| 1.0,
                threads,
            )
            .iter()
            .map(|p| p[0])
            .collect()
        })
    };
    let mut gathered_seconds = 0.0;
    let (mut regathered, mut regathered_seconds) = (Vec::new(), 0.0);
    let mut rings = Vec::new();
    let mut ring_spots = Vec::new();
    let mut pooled = Vec::new();
    let mut bounce_floor = Vec::new();
    let gathered = match (&last_model, settings.bounce_rays) {
        (Some(([sky, sun, _], envelope)), rays) if rays > 0 => {
            use super::gathered_bounce::{
                BounceRatios, bounce_gathers_of, gather_irradiance, pooled_ratios, quantize_ratio,
                ratio_of, ratio_on_ring, ratio_towards, sun_ring,
            };
            use super::model::bounce_radiance_by_face;
            let all: Vec<u32> = (0..scene.leaf_count() as u32).collect();
            let tau = envelope.tau;
            let started = std::time::Instant::now();
            let gathers = bounce_gathers_of(
                &scene,
                material,
                &all,
                &envelope.leaves,
                tau,
                rays,
                &|_| 1.0,
                threads,
            );
            gathered_seconds = started.elapsed().as_secs_f32();
            let centres: Vec<Vec3> = (0..scene.leaf_count()).map(|l| scene.centre(l)).collect();
            let normals: Vec<Vec3> = (0..scene.leaf_count()).map(|l| scene.normal(l)).collect();
            // Pooled, as a bake stores them.
            let pooled_by = |pool: usize| -> Vec<BounceRatios> {
                pooled_ratios(&centres, &normals, &gathers, pool, threads)
                    .iter()
                    .map(|r| BounceRatios::from_stored(&r.quantized()))
                    .collect()
            };
            let pools = if settings.bounce_pools.is_empty() {
                vec![DEFAULT_BOUNCE_POOL]
            } else {
                settings.bounce_pools.clone()
            };
            let ratios = pooled_by(pools[0]);
            // The crown's hotspot measured against the bounce with the ratios, as a bake
            // measures it when it stores them.
            let spot_of = |ratios: &[BounceRatios]| {
                settings.hotspot.then(|| {
                    super::hotspot::crown_hotspot(
                        &scene,
                        envelope,
                        gains.as_deref().unwrap_or(&[]),
                        ratios,
                        &|l| Some(l as usize),
                        material,
                        &|_| 1.0,
                        &super::hotspot::HotspotSettings::OFFLINE,
                        threads,
                    )
                })
            };
            let spot = spot_of(&ratios);
            // The same gather for the sun's own direction: what no blend over directions beats.
            let exact: Vec<[f32; 2]> = super::par_map(&all, threads, |&leaf| {
                let seed = super::gathered_bounce::leaf_seed(&scene, leaf);
                gather_irradiance(
                    &scene,
                    material,
                    leaf as usize,
                    rays,
                    &[light.to_sun],
                    &|_| 1.0,
                    seed,
                )[0]
            });
            let here = SunBounce::new(material, light.to_sun, tau);
            // Where the covered part's gain can come from finer than the eight gains: each
            // leaf's stored open map read at the eye ray's point (as the bake stores it), and the
            // covered share at the point itself over the leaf's mean (what no map beats).
            let point_cover: Option<(Vec<LeafOpenMap>, Vec<f32>)> =
                gains.as_ref().filter(|_| settings.bounce_covers).map(|_| {
                    let stored = super::open_map::open_maps_of(
                        &scene,
                        &all,
                        &|l| {
                            MapFrame::of_leaf(
                                leaves.centroid(l),
                                scene.normal(l),
                                (0.5 * leaves.diameter(l)).max(1e-6),
                            )
                        },
                        super::open_map::DEFAULT_OPEN_MAP_POINTS,
                        &|_| 1.0,
                        settings.seen_seed,
                        threads,
                    );
                    let mean_open =
                        super::par_map(&all, threads, |&leaf| mean_open_share(&scene, leaf));
                    let at_point: Vec<f32> = super::par_map(&indices, threads, |&k| {
                        samples[k].as_ref().map_or(1.0, |s| {
                            let (open, mean) =
                                (open_at_sample(&scene, k, s), mean_open[s.leaf as usize]);
                            if mean < 1.0 - 1e-4 {
                                ((1.0 - open) / (1.0 - mean)).clamp(0.0, GAIN_RANGE.1)
                            } else {
                                1.0
                            }
                        })
                    });
                    (stored, at_point)
                });
            // The image with the gains (where measured) and the bounce `bounce(leaf, n)`,
            // scaled by the covered part's gain when `covered`, both by the hotspot `spot`
            // where given.
            let image_with = |bounce_of: &dyn Fn(usize, Vec3) -> f32,
                              covered: Cover,
                              spot: Option<&super::hotspot::Hotspot>| {
                let (mut sky, mut sun) = (sky.clone(), sun.clone());
                let mut bounce = vec![0.0; samples.len()];
                for (k, s) in samples.iter().enumerate() {
                    if let Some(s) = s {
                        let leaf = s.leaf as usize;
                        let e = &envelope.leaves[leaf];
                        let n = scene.normal(leaf);
                        let mut b = bounce_of(leaf, n);
                        if let Some(g) = &gains {
                            let gain = seen_gain(&g[leaf], view);
                            let old = lobe_blend(&e.attenuation, light.to_sun, 1.0);
                            let new = match spot {
                                Some(h) => h.sun_through((old * gain).min(1.0), view, light.to_sun),
                                None => (old * gain).min(1.0),
                            };
                            sun[k] *= if old > 0.0 { new / old } else { 1.0 };
                            sky[k] *= gain;
                            let open = open_share(n, &e.attenuation);
                            match (covered, &point_cover) {
                                (Cover::Not, _) => {}
                                (Cover::Map, Some((stored, _))) if stored[leaf].is_map() => {
                                    let at = stored[leaf].sky_gain(
                                        s.point - leaves.centroid(leaf),
                                        (0.5 * leaves.diameter(leaf)).max(1e-6),
                                        view,
                                    );
                                    b *= covered_gain(at, open);
                                }
                                (Cover::Point, Some((_, at_point))) => b *= at_point[k],
                                _ => b *= covered_gain(gain, open),
                            }
                        }
                        if let Some(h) = spot {
                            b *= h.bounce_at(view, light.to_sun);
                        }
                        bounce[k] = b;
                    }
                }
                measure(&[sky, sun, bounce])
            };
            let image = |bounce_of: &dyn Fn(usize, Vec3) -> f32, covered: Cover| {
                image_with(bounce_of, covered, None)
            };
            let scaled_with = |ratio: [f32; 2], leaf: usize, n: Vec3| {
                let e = &envelope.leaves[leaf];
                let through = lobe_blend(&e.attenuation, light.to_sun, 1.0);
                luminance(bounce_radiance_by_face(
                    material, n, view, &here, through, &e.s_max, light.sun, ratio,
                ))
            };
            let scaled_by = |ratios: &[BounceRatios], leaf: usize, n: Vec3| {
                scaled_with(ratio_towards(&ratios[leaf], light.to_sun), leaf, n)
            };
            let scaled = |leaf: usize, n: Vec3| scaled_by(&ratios, leaf, n);
            let own = |leaf: usize, n: Vec3| {
                luminance(super::gathered_bounce::gathered_bounce_radiance(
                    material,
                    n,
                    view,
                    exact[leaf],
                    light.sun,
                ))
            };
            let mut rows = vec![
                image(&scaled, Cover::Gains),
                image(&own, Cover::Gains),
                image(&own, Cover::Not),
                image(&scaled, Cover::Not),
            ];
            if let Some(h) = &spot {
                rows.push(image_with(&scaled, Cover::Gains, Some(h)));
            }
            // Ratios re-gathered for the given suns, stored as a bake stores ratios, and the
            // seconds the gather took.
            // A ring (`on_ring`) with sunlit points gathers as an app's does: through its
            // leaves' sunlit planes for its suns (`bounce_ring::ring_ratios`; their tracing in
            // the seconds).
            let regather = |suns: &[Vec3], on_ring: bool| {
                let rays = match settings.ring_rays {
                    r if on_ring && r > 0 => r,
                    _ => rays,
                };
                let started = std::time::Instant::now();
                let planes = (on_ring && settings.sunlit_points > 0).then(|| {
                    super::sunlit_share::sunlit_planes(
                        &scene,
                        &all,
                        suns,
                        settings.sunlit_points,
                        &|_| 1.0,
                        threads,
                    )
                });
                // A ring refined by further passes ([`super::bounce_ring::RingRefinement`]) is
                // the mean of its passes.
                let passes = if on_ring {
                    settings.ring_passes.max(1)
                } else {
                    1
                };
                let pass = |pass: u32| {
                    super::bounce_ring::ring_ratios(
                        &scene,
                        material,
                        &all,
                        &envelope.leaves,
                        tau,
                        suns,
                        rays,
                        pass,
                        planes.as_deref(),
                        &|_| 1.0,
                        threads,
                    )
                };
                let mut refinement = super::bounce_ring::RingRefinement::new(pass(0));
                refinement.refine_to(passes, pass);
                let ratios = refinement.mean();
                let seconds = started.elapsed().as_secs_f32();
                let stored: Vec<Vec<[f32; 2]>> = ratios
                    .iter()
                    .map(|r| {
                        r.iter()
                            .map(|r| r.map(|x| ratio_of(quantize_ratio(x))))
                            .collect()
                    })
                    .collect();
                (stored, seconds)
            };
            // For this sun alone, drawn as the leaf shaders draw the blend's (the hotspot, where
            // measured, the blend's).
            let (resun, seconds) = regather(&[light.to_sun], false);
            regathered_seconds = seconds;
            regathered = image_with(
                &|leaf, n| scaled_with(resun[leaf][0], leaf, n),
                Cover::Gains,
                spot.as_ref(),
            );
            // What values per leaf can make of the bounce for this sun (`bounce_floor`): a
            // plane a face from a grid of points, the gather at the eye ray's point, and the
            // gather with the neighbours' sunlit planes in place of shadow rays.
            let drawn_from = |irradiance: &dyn Fn(usize, &Sample) -> [f32; 2]| {
                let mut bounce = vec![0.0; samples.len()];
                for (k, s) in samples.iter().enumerate() {
                    if let Some(s) = s {
                        let leaf = s.leaf as usize;
                        bounce[k] = luminance(super::gathered_bounce::gathered_bounce_radiance(
                            material,
                            scene.normal(leaf),
                            view,
                            irradiance(k, s),
                            light.sun,
                        ));
                    }
                }
                measure(&[sky.clone(), sun.clone(), bounce])
            };
            for &(side, per_point) in &settings.bounce_planes {
                use super::bounce_floor::{bounce_planes, gather_at};
                let planes = bounce_planes(
                    &scene,
                    material,
                    &all,
                    light.to_sun,
                    side,
                    per_point,
                    threads,
                );
                let rays = side * side * per_point;
                bounce_floor.push((
                    format!("{side}x{side} points x {per_point} rays ({rays}) a leaf, the mean"),
                    drawn_from(&|_, s| planes[s.leaf as usize].mean()),
                ));
                bounce_floor.push((
                    format!(
                        "{side}x{side} points x {per_point} rays ({rays}) a leaf, a plane a face, at the eye ray's point"
                    ),
                    drawn_from(&|_, s| planes[s.leaf as usize].at(s.point)),
                ));
                let at_point: Vec<[f32; 2]> = super::par_map(&indices, threads, |&k| {
                    samples[k].as_ref().map_or([0.0; 2], |s| {
                        gather_at(
                            &scene,
                            material,
                            s.leaf as usize,
                            s.point,
                            rays,
                            light.to_sun,
                            0xA7 ^ (k as u64).wrapping_mul(0x9E37_79B9),
                        )
                    })
                });
                bounce_floor.push((
                    format!("gathered at the eye ray's own point, {rays} rays"),
                    drawn_from(&|k, _| at_point[k]),
                ));
            }
            if !settings.through_planes.is_empty() && settings.sunlit_points > 0 {
                use super::bounce_floor::gather_through_planes;
                let planes = own_planes();
                for &count in &settings.through_planes {
                    for through in [false, true] {
                        let e: Vec<[f32; 2]> = super::par_map(&all, threads, |&leaf| {
                            let seed = super::gathered_bounce::leaf_seed(&scene, leaf);
                            if through {
                                gather_through_planes(
                                    &scene,
                                    material,
                                    leaf as usize,
                                    count,
                                    light.to_sun,
                                    planes,
                                    seed,
                                )
                            } else {
                                gather_irradiance(
                                    &scene,
                                    material,
                                    leaf as usize,
                                    count,
                                    &[light.to_sun],
                                    &|_| 1.0,
                                    seed,
                                )[0]
                            }
                        });
                        bounce_floor.push((
                            format!(
                                "gathered for this sun alone, {count} rays a leaf, no gain, {}",
                                if through {
                                    format!(
                                        "the neighbours' sunlit planes ({} points) for shadow rays",
                                        settings.sunlit_points
                                    )
                                } else {
                                    "shadow rays".to_string()
                                }
                            ),
                            drawn_from(&|_, s| e[s.leaf as usize]),
                        ));
                    }
                }
            }
            if point_cover.is_some() {
                for (cover, name) in [
                    (Cover::Gains, "eight gains"),
                    (Cover::Map, "the open map's gain at the point"),
                    (Cover::Point, "the covered share at the eye ray's own point"),
                ] {
                    bounce_floor.push((
                        format!("gathered for this sun alone, covered part by {name}"),
                        image(&own, cover),
                    ));
                }
            }
            // For rings of suns at the sun's elevation, the sun `ring_offset` of a node's step
            // past a node (midway by default: what a tree turned by half a step sees, the
            // farthest from the ring's gather).
            for &count in &settings.sun_rings {
                let phase = ring_phase(light.to_sun, count, settings.ring_offset);
                let (ring, seconds) = regather(&sun_ring(light.to_sun, count, phase), true);
                let drawn = image_with(
                    &|leaf, n| {
                        scaled_with(ratio_on_ring(&ring[leaf], phase, light.to_sun), leaf, n)
                    },
                    Cover::Gains,
                    spot.as_ref(),
                );
                if settings.hotspot {
                    let started = std::time::Instant::now();
                    let own = super::hotspot::crown_hotspot_for(
                        &scene,
                        &envelope.leaves,
                        envelope.tau,
                        gains.as_deref().unwrap_or(&[]),
                        &|leaf, to_sun| ratio_on_ring(&ring[leaf], phase, to_sun),
                        super::hotspot::HotspotSuns::Height(light.to_sun.y),
                        None,
                        &|l| Some(l as usize),
                        material,
                        &|_| 1.0,
                        &super::hotspot::HotspotSettings::OFFLINE,
                        threads,
                    );
                    let seconds = started.elapsed().as_secs_f32();
                    let drawn = image_with(
                        &|leaf, n| {
                            scaled_with(ratio_on_ring(&ring[leaf], phase, light.to_sun), leaf, n)
                        },
                        Cover::Gains,
                        Some(&own),
                    );
                    if point_cover.is_some() {
                        for (cover, name) in [
                            (Cover::Map, "the open map's gain at the point"),
                            (Cover::Point, "the covered share at the eye ray's own point"),
                        ] {
                            bounce_floor.push((
                                format!("ring of {count}, its own hotspot, covered part by {name}"),
                                image_with(
                                    &|leaf, n| {
                                        scaled_with(
                                            ratio_on_ring(&ring[leaf], phase, light.to_sun),
                                            leaf,
                                            n,
                                        )
                                    },
                                    cover,
                                    Some(&own),
                                ),
                            ));
                        }
                    }
                    ring_spots.push((count, drawn, own, seconds));
                }
                rings.push((count, drawn, seconds));
            }
            for &pool in &pools {
                let ratios = pooled_by(pool);
                let spot = spot_of(&ratios);
                let drawn = |leaf: usize, n: Vec3| scaled_by(&ratios, leaf, n);
                pooled.push((pool, image_with(&drawn, Cover::Gains, spot.as_ref())));
            }
            rows
        }
        _ => Vec::new(),
    };
    let (seen, seen_along, open_at_point, open_maps, hotspot, drawn) = match &last_model {
        Some(([sky, sun, bounce], envelope)) => {
            // The images with the gain `gain_of(k, sample)` of eye ray k on the sky (and, by
            // the covered part's gain, on the bounce), the sun through the crown as
            // `through(leaf, blend, gain)` makes the leaf's share of it (the gain applied), and
            // the bounce scaled by `bounce_factor`.
            let with_gain = |through: &dyn Fn(usize, f32, f32) -> f32,
                             bounce_factor: f32,
                             gain_of: &dyn Fn(usize, &Sample) -> f32| {
                let (mut sky, mut sun, mut bounce) = (sky.clone(), sun.clone(), bounce.clone());
                for (k, s) in samples.iter().enumerate() {
                    if let Some(s) = s {
                        let leaf = s.leaf as usize;
                        let e = &envelope.leaves[leaf];
                        let old = lobe_blend(&e.attenuation, light.to_sun, 1.0);
                        let gain = gain_of(k, s);
                        let new = through(leaf, old, gain);
                        // The sun's term is linear in the share let through; the bounce in the
                        // light at the leaf before the gain.
                        sun[k] *= if old > 0.0 { new / old } else { 1.0 };
                        bounce[k] *= bounce_factor;
                        if gains.is_some() {
                            sky[k] *= gain;
                            let open = open_share(scene.normal(leaf), &e.attenuation);
                            bounce[k] *= covered_gain(gain, open);
                        }
                    }
                }
                [sky, sun, bounce]
            };
            // With the stored gains blended towards the eye, as the leaf shaders draw them.
            let with = |through: &dyn Fn(usize, f32, f32) -> f32, bounce_factor: f32| {
                with_gain(through, bounce_factor, &|_, s| {
                    gains
                        .as_ref()
                        .map_or(1.0, |g| seen_gain(&g[s.leaf as usize], view))
                })
            };
            let gained = |old: f32, gain: f32| (old * gain).min(1.0);
            let seen = if gains.is_some() {
                measure(&with(&|_, old, gain| gained(old, gain), 1.0))
            } else {
                Vec::new()
            };
            // What no eight gains beat: the gain for the eye's own direction from as many
            // points, and the open share at the eye ray's own point over the leaf's mean.
            let (seen_along, open_at_point, open_maps) = if gains.is_some() {
                let all: Vec<u32> = (0..scene.leaf_count() as u32).collect();
                let along = super::par_map(&all, threads, |&leaf| {
                    seen_part_gain_along(
                        &scene,
                        leaf as usize,
                        settings.seen_points,
                        view,
                        &|_| 1.0,
                        0x5EE1_u64 ^ (leaf as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
                    )
                });
                let mean_open =
                    super::par_map(&all, threads, |&leaf| mean_open_share(&scene, leaf));
                let at_point: Vec<f32> = super::par_map(&indices, threads, |&k| {
                    samples[k].as_ref().map_or(1.0, |s| {
                        let mean = mean_open[s.leaf as usize];
                        if mean > 0.0 {
                            (open_at_sample(&scene, k, s) / mean).clamp(GAIN_RANGE.0, GAIN_RANGE.1)
                        } else {
                            1.0
                        }
                    })
                });
                let through = |_: usize, old: f32, gain: f32| gained(old, gain);
                // Each leaf's centroid and radius, as its vertices carry them.
                let centroids: Vec<(Vec3, f32)> = (0..scene.leaf_count())
                    .map(|l| {
                        let centre = leaves.centroid(l);
                        let radius = leaves
                            .leaf_vertices(l)
                            .into_iter()
                            .map(|v| (leaves.positions[v as usize] - centre).length())
                            .fold(0.0f32, f32::max);
                        (centre, radius)
                    })
                    .collect();
                let open_maps = settings
                    .open_maps
                    .iter()
                    .map(|&(side, points, of_leaf)| {
                        let maps = super::par_map(&all, threads, |&leaf| {
                            let frame = of_leaf.then(|| {
                                let (centre, radius) = centroids[leaf as usize];
                                MapFrame::of_leaf(centre, scene.normal(leaf as usize), radius)
                            });
                            open_map(
                                &scene,
                                leaf as usize,
                                frame,
                                side,
                                points,
                                &|_| 1.0,
                                0x09E2_u64
                                    ^ settings.seen_seed.wrapping_mul(0xD1B5_4A32_D192_ED03)
                                    ^ (leaf as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
                            )
                        });
                        let drawn = measure(&with_gain(&through, 1.0, &|_, s| {
                            maps[s.leaf as usize].gain_at(s.point)
                        }));
                        let with_residual = measure(&with_gain(&through, 1.0, &|_, s| {
                            maps[s.leaf as usize].gain_towards(s.point, view)
                        }));
                        // As a bake stores the map and the leaf shaders read it: the cell at
                        // the point times the residual gains' blend towards the eye.
                        let stored = if of_leaf && side == STORED_SIDE {
                            let stored: Vec<LeafOpenMap> =
                                maps.iter().map(LeafOpenMap::of).collect();
                            measure(&with_gain(&through, 1.0, &|_, s| {
                                let (centre, radius) = centroids[s.leaf as usize];
                                stored[s.leaf as usize].sky_gain(s.point - centre, radius, view)
                            }))
                        } else {
                            Vec::new()
                        };
                        ((side, points, of_leaf), drawn, with_residual, stored)
                    })
                    .collect();
                (
                    measure(&with_gain(&through, 1.0, &|_, s| along[s.leaf as usize])),
                    measure(&with_gain(&through, 1.0, &|k, _| at_point[k])),
                    open_maps,
                )
            } else {
                Default::default()
            };
            let (hotspot, drawn) = match &hotspot_factors {
                Some(h) => {
                    let [sky, sun, bounce] = with(
                        &|_, old, gain| h.sun_through((old * gain).min(1.0), view, light.to_sun),
                        h.bounce_at(view, light.to_sun),
                    );
                    // The leaf shaders' hand-over between the baked blend (with the hotspot)
                    // and the shadow map at the leaf, at each texel side where they blend.
                    let drawn = mapped_suns
                        .iter()
                        .filter_map(|(share, mapped)| {
                            let trust = shadow_map_trust(*share);
                            (trust > 0.0 && trust < 1.0).then(|| {
                                let mixed: Vec<f32> = sun
                                    .iter()
                                    .zip(mapped)
                                    .map(|(b, m)| b + trust * (m - b))
                                    .collect();
                                (
                                    *share,
                                    trust,
                                    measure(&[sky.clone(), mixed, bounce.clone()]),
                                )
                            })
                        })
                        .collect();
                    (measure(&[sky, sun, bounce]), drawn)
                }
                None => (Vec::new(), Vec::new()),
            };
            (seen, seen_along, open_at_point, open_maps, hotspot, drawn)
        }
        _ => Default::default(),
    };
    let mut sunlit = Vec::new();
    let mut sunlit_seconds = Vec::new();
    let mut ring_hotspot_seconds = Vec::new();
    if settings.sunlit_points > 0 {
        use super::gathered_bounce::sun_ring;
        use super::sunlit_share::{SharePlane, plane_on_ring, sunlit_planes};
        let all: Vec<u32> = (0..scene.leaf_count() as u32).collect();
        // Per source: its label, each leaf's plane towards the image's sun, and for a ring its
        // phase and each leaf's planes on it. Each source is drawn twice: the leaf's share
        // alone (the plane's mean over the whole leaf) and the plane at the eye ray's point.
        type Ring = Option<(f32, Vec<Vec<SharePlane>>)>;
        let mut sources: Vec<(String, Vec<SharePlane>, Ring)> = Vec::new();
        sources.push(("traced for this sun".into(), own_planes().clone(), None));
        for &count in &settings.sun_rings {
            let phase = ring_phase(light.to_sun, count, settings.ring_offset);
            let started = std::time::Instant::now();
            let ring = sunlit_planes(
                &scene,
                &all,
                &sun_ring(light.to_sun, count, phase),
                settings.sunlit_points,
                &|_| 1.0,
                threads,
            );
            sunlit_seconds.push((count, started.elapsed().as_secs_f32()));
            sources.push((
                format!(
                    "on a ring of {count}, {}",
                    sun_between(settings.ring_offset)
                ),
                ring.iter()
                    .map(|r| plane_on_ring(r, phase, light.to_sun))
                    .collect(),
                Some((phase, ring)),
            ));
        }
        // Maps of the sunlit share over the leaf's square for the image's sun, and the share
        // at the eye ray's point itself: how much of the planes' error a finer picture of
        // the sunflecks on each leaf takes away.
        if !settings.sunlit_maps.is_empty() {
            use super::open_map::MapFrame;
            use super::sunlit_share::share_points;
            let sun_at = |leaf: usize, t: f32, gained: bool| {
                let t = match (&gains, gained) {
                    (Some(g), true) => (t * seen_gain(&g[leaf], view)).min(1.0),
                    _ => t,
                };
                luminance(sun_radiance(
                    material,
                    scene.normal(leaf),
                    view,
                    light.to_sun,
                    t,
                    light.sun,
                ))
            };
            let at_point: Vec<f32> = samples
                .iter()
                .map(|s| {
                    s.as_ref().map_or(0.0, |s| {
                        let leaf = s.leaf as usize;
                        sun_at(
                            leaf,
                            scene.transmittance(s.point, light.to_sun, s.leaf, |_| 1.0),
                            false,
                        )
                    })
                })
                .collect();
            sunlit.push((
                "leaf's sunlit share at the eye ray's point".into(),
                measure(&[model_sky.clone(), at_point, model_bounce.clone()]),
            ));
            let frames: Vec<MapFrame> = (0..scene.leaf_count())
                .map(|leaf| {
                    MapFrame::of_leaf(
                        leaves.centroid(leaf),
                        scene.normal(leaf),
                        (0.5 * leaves.diameter(leaf)).max(1e-6),
                    )
                })
                .collect();
            for &cells_a_side in &settings.sunlit_maps {
                let cells_a_side = cells_a_side.max(1);
                // Each leaf's cells from the points its sunlit share is traced from.
                let maps: Vec<Vec<f32>> = super::par_map(&all, threads, |&leaf| {
                    let fit = share_points(&scene, leaf as usize, settings.sunlit_points);
                    let n = (cells_a_side * cells_a_side) as usize;
                    let (mut sum, mut count) = (vec![0.0f32; n], vec![0u32; n]);
                    let mut total = 0.0;
                    for &p in &fit.points {
                        let t = scene.transmittance(p, light.to_sun, leaf, |_| 1.0);
                        let c = frames[leaf as usize].cell(cells_a_side, p);
                        sum[c] += t;
                        count[c] += 1;
                        total += t;
                    }
                    let mean = total / fit.points.len().max(1) as f32;
                    sum.iter()
                        .zip(&count)
                        .map(|(s, &c)| if c > 0 { s / c as f32 } else { mean })
                        .collect()
                });
                for gained in [false, true] {
                    if gained && gains.is_none() {
                        continue;
                    }
                    let sun: Vec<f32> = samples
                        .iter()
                        .map(|s| {
                            s.as_ref().map_or(0.0, |s| {
                                let leaf = s.leaf as usize;
                                let t = maps[leaf][frames[leaf].cell(cells_a_side, s.point)];
                                sun_at(leaf, t, gained)
                            })
                        })
                        .collect();
                    sunlit.push((
                        format!(
                            "leaf's sunlit map {cells_a_side}x{cells_a_side} traced for this sun{}",
                            if gained { ", seen-part gain" } else { "" }
                        ),
                        measure(&[model_sky.clone(), sun, model_bounce.clone()]),
                    ));
                }
            }
        }
        for (source, planes, ring) in sources {
            for plane in [false, true] {
                let label = if plane {
                    format!("leaf's sunlit plane {source}")
                } else {
                    format!("leaf's sunlit share {source}")
                };
                let image = |through: &dyn Fn(usize, f32) -> f32| {
                    let sun: Vec<f32> = samples
                        .iter()
                        .map(|s| {
                            s.as_ref().map_or(0.0, |s| {
                                let leaf = s.leaf as usize;
                                let n = scene.normal(leaf);
                                let share = if plane {
                                    planes[leaf].at(s.point)
                                } else {
                                    planes[leaf].mean
                                };
                                let t = through(leaf, share);
                                luminance(sun_radiance(
                                    material,
                                    n,
                                    view,
                                    light.to_sun,
                                    t,
                                    light.sun,
                                ))
                            })
                        })
                        .collect();
                    measure(&[model_sky.clone(), sun, model_bounce.clone()])
                };
                sunlit.push((label.clone(), image(&|_, t| t)));
                let Some(g) = &gains else { continue };
                let gained = |leaf: usize, t: f32| (t * seen_gain(&g[leaf], view)).min(1.0);
                sunlit.push((format!("{label}, seen-part gain"), image(&gained)));
                if let Some(h) = &hotspot_factors {
                    sunlit.push((
                        format!("{label}, seen-part gain, the crown's hotspot"),
                        image(&|leaf, t| h.sun_through(gained(leaf, t), view, light.to_sun)),
                    ));
                }
                // As the leaf shaders draw a ring (one of another size than the leaf store's
                // fourteen nodes as they would, were the store to hold it): each node's share
                // and slope quantised as stored, read at the vertices of the eye ray's
                // triangle (`bounce_ring::ring_shares_at`) and carried to the point by its
                // barycentric weights, where the gain and the hotspot bend it — the hotspot
                // fitted against the ring's planes with the ring (`ring_sun_hotspot`), and for
                // comparison the bake's.
                if let (Some((phase, ring)), Some(h), Some((_, envelope)), true) =
                    (&ring, &hotspot_factors, &last_model, plane)
                {
                    let started = std::time::Instant::now();
                    let own = super::bounce_ring::ring_sun_hotspot(
                        &scene,
                        material,
                        &all,
                        &envelope.leaves,
                        envelope.tau,
                        g,
                        light.to_sun.y,
                        ring,
                        *phase,
                        &|_| 1.0,
                        &super::bounce_ring::RING_HOTSPOT,
                        threads,
                    );
                    ring_hotspot_seconds.push(started.elapsed().as_secs_f32());
                    let own = super::hotspot::Hotspot {
                        sun: own.map(|x| {
                            super::hotspot::Hotspot::dequantize(super::hotspot::Hotspot::quantize(
                                x,
                            ))
                        }),
                        bounce: [1.0; super::hotspot::HOTSPOT_NODES],
                    };
                    for (spot, name) in
                        [(h, "the crown's hotspot"), (&own, "the ring's own hotspot")]
                    {
                        let drawn = image_as_drawn(
                            leaves,
                            &samples,
                            ring,
                            *phase,
                            &|leaf, share| {
                                spot.sun_through(
                                    (share * seen_gain(&g[leaf], view)).min(1.0),
                                    view,
                                    light.to_sun,
                                )
                            },
                            &|leaf, t| {
                                let n = scene.normal(leaf);
                                luminance(sun_radiance(
                                    material,
                                    n,
                                    view,
                                    light.to_sun,
                                    t,
                                    light.sun,
                                ))
                            },
                            light.to_sun,
                        );
                        sunlit.push((
                            format!(
                                "{label}, seen-part gain, {name}, as the leaf shaders draw it (stored, read at the vertices)"
                            ),
                            measure(&[model_sky.clone(), drawn, model_bounce.clone()]),
                        ));
                    }
                }
                // The ring's own hotspot: fitted for suns at the sun's height against the
                // shares read on the ring.
                if let (Some((phase, ring)), Some((_, envelope)), true, false) =
                    (&ring, &last_model, settings.hotspot, plane)
                {
                    let own = super::hotspot::crown_hotspot_for(
                        &scene,
                        &envelope.leaves,
                        envelope.tau,
                        g,
                        &|_, _| [1.0; 2],
                        super::hotspot::HotspotSuns::Height(light.to_sun.y),
                        Some(&|leaf, to_sun, _| plane_on_ring(&ring[leaf], *phase, to_sun).mean),
                        &|l| Some(l as usize),
                        material,
                        &|_| 1.0,
                        &super::hotspot::HotspotSettings::OFFLINE,
                        threads,
                    );
                    sunlit.push((
                        format!("{label}, seen-part gain, its own hotspot (at the sun's height)"),
                        image(&|leaf, t| own.sun_through(gained(leaf, t), view, light.to_sun)),
                    ));
                }
            }
        }
    }
    ImageComparison {
        sunlit,
        sunlit_seconds,
        ring_hotspot_seconds,
        models,
        seen,
        seen_along,
        open_at_point,
        open_maps,
        hotspot,
        drawn,
        gathered,
        gathered_seconds,
        regathered,
        regathered_seconds,
        rings,
        ring_spots,
        pooled,
        bounce_floor,
        hotspot_factors,
        shadow_map_sun,
        noise,
        hits: samples.iter().flatten().count(),
    }
}

/// The azimuth of node 0 of a ring of `count` suns that puts the sun towards `to_sun` `offset`
/// of a node's step past the node before it.
fn ring_phase(to_sun: Vec3, count: usize, offset: f32) -> f32 {
    to_sun.z.atan2(to_sun.x) - std::f32::consts::TAU * offset / count.max(1) as f32
}

/// Where the sun stands on a ring ([`ImageSettings::ring_offset`]), for a row's label.
pub fn sun_between(offset: f32) -> String {
    if (offset - 0.5).abs() < 1e-6 {
        "the sun midway".into()
    } else {
        format!("the sun {offset} of a step past a node")
    }
}

/// The sun per eye ray as the leaf shaders draw a ring of sunlit shares with their slopes
/// ([`super::bounce_ring::ring_shares_at`]): each leaf's planes on `ring` (at azimuths from
/// `phase`) stored as shares and slopes per the leaf's radius, read at each vertex of the
/// triangle the ray hit along the vertex's offset from the leaf's centroid, on the ring
/// towards `to_sun`, carried to the hit point by its barycentric weights and there turned
/// into the sun through the crown by `through(leaf, share)`; `radiance(leaf, through)` the
/// pixel.
#[allow(clippy::too_many_arguments)]
fn image_as_drawn(
    leaves: &LeafSet,
    samples: &[Option<Sample>],
    ring: &[Vec<super::sunlit_share::SharePlane>],
    phase: f32,
    through: &(dyn Fn(usize, f32) -> f32 + Sync),
    radiance: &(dyn Fn(usize, f32) -> f32 + Sync),
    to_sun: Vec3,
) -> Vec<f32> {
    use super::bounce_ring::ring_shares_at;
    use super::sunlit_share::{quantize_share, quantize_slope, share_on_ring};
    samples
        .iter()
        .map(|s| {
            let Some(s) = s else { return 0.0 };
            let leaf = s.leaf as usize;
            let radius = (0.5 * leaves.diameter(leaf)).max(1e-6);
            let centroid = leaves.centroid(leaf);
            let planes = &ring[leaf];
            let stored: Vec<u8> = planes.iter().map(|p| quantize_share(p.mean)).collect();
            let slopes: Vec<[i8; 3]> = planes
                .iter()
                .map(|p| (p.gradient * radius).to_array().map(quantize_slope))
                .collect();
            let at_vertex = |v: Vec3| {
                let nodes = ring_shares_at(&stored, Some(&slopes), (v - centroid) / radius);
                share_on_ring(&nodes, phase, to_sun)
            };
            // The triangle the point lies in (the one it is least outside of).
            let mut best: Option<(f32, f32)> = None;
            for [a, b, c] in leaves.triangles(leaf) {
                let (v0, v1, v2) = (b - a, c - a, s.point - a);
                let (d00, d01, d11) = (v0.dot(v0), v0.dot(v1), v1.dot(v1));
                let det = d00 * d11 - d01 * d01;
                if det <= 0.0 {
                    continue;
                }
                let v = (d11 * v2.dot(v0) - d01 * v2.dot(v1)) / det;
                let w = (d00 * v2.dot(v1) - d01 * v2.dot(v0)) / det;
                let inside = (1.0 - v - w).min(v).min(w);
                if best.is_none_or(|(b, _)| inside > b) {
                    let share = (1.0 - v - w) * at_vertex(a) + v * at_vertex(b) + w * at_vertex(c);
                    best = Some((inside, share));
                }
            }
            radiance(leaf, best.map_or(0.0, |(_, share)| through(leaf, share)))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::path_trace::{push_square_leaf, test_light as light, uniform_ball};

    #[test]
    fn the_ring_offset_puts_the_sun_that_far_past_a_node() {
        use super::super::gathered_bounce::{nodes_either_side, sun_ring};
        let to_sun = Vec3::new(0.3, 0.2, -1.0).normalize();
        for (count, offset) in [(14, 0.0), (14, 0.25), (14, 0.5), (28, 0.75)] {
            let phase = ring_phase(to_sun, count, offset);
            let ring = sun_ring(to_sun, count, phase);
            let (i, j, f) = nodes_either_side(count, phase, to_sun).expect("a sun off the pole");
            // Round the circle: on a node the sun may read as the end of the step before.
            let d = (f - offset).rem_euclid(1.0);
            assert!(d.min(1.0 - d) < 1e-4, "{count}, {offset}: {f}");
            assert_eq!(j, (i + 1) % count);
            // On a node, that node is the sun itself.
            if offset == 0.0 {
                let nearest = ring[i].distance(to_sun).min(ring[j].distance(to_sun));
                assert!(nearest < 1e-5, "{nearest}");
            }
        }
        assert_eq!(sun_between(0.5), "the sun midway");
    }

    #[test]
    fn the_sunlit_maps_read_the_shares_own_points_cell_by_cell() {
        let leaves = uniform_ball(600, 1.0, 0.05, 3);
        let run = images_against_tracer(
            &leaves,
            &LeafMaterial::default(),
            &light(),
            Vec3::new(0.0, 0.3, 1.0),
            0.1,
            &ImageSettings {
                samples: 16,
                directions: 16,
                sunlit_points: 16,
                sunlit_maps: vec![1, 3],
                ..ImageSettings::default()
            },
            2,
            &[(SunThroughCrown::BlendedAttenuation, BinEstimate::Neighbours)],
            &[1, 4],
        );
        let row = |label: &str| {
            &run.sunlit
                .iter()
                .find(|(l, _)| l == label)
                .unwrap_or_else(|| panic!("no row {label}"))
                .1
        };
        // The tracer's direct sun is a shadow ray from the hit point: the share there is exact.
        for e in row("leaf's sunlit share at the eye ray's point") {
            assert!(e.sun.mean_absolute < 1e-6, "{:?}", e.sun);
        }
        // One cell holds every point: the leaf's share, traced from the same points.
        let (share, one) = (
            row("leaf's sunlit share traced for this sun"),
            row("leaf's sunlit map 1x1 traced for this sun"),
        );
        for (a, b) in share.iter().zip(one) {
            assert!((a.sun.mean_absolute - b.sun.mean_absolute).abs() < 1e-6);
        }
        // Nine cells know which part of a half-shaded leaf the eye looks at.
        let nine = row("leaf's sunlit map 3x3 traced for this sun");
        assert!(
            nine[0].sun.mean_absolute < 0.8 * share[0].sun.mean_absolute,
            "{:?} against {:?}",
            nine[0].sun,
            share[0].sun
        );
    }

    #[test]
    fn a_pixel_is_the_mean_of_its_block() {
        // 4 × 4 grid, values = index; 2 × 2 blocks.
        let values: Vec<f32> = (0..16).map(|i| i as f32).collect();
        let px = block_means(&values, 4, 2);
        assert_eq!(px, vec![2.5, 4.5, 10.5, 12.5]);
        assert_eq!(block_means(&values, 4, 4), vec![7.5]);
        assert_eq!(block_means(&values, 4, 1), values);
    }

    /// A leaf's value is the mean of its eye rays'; the background and leaves no ray hit are
    /// left out, the leaves in order.
    #[test]
    fn a_leaf_is_the_mean_of_its_eye_rays() {
        let values = [1.0, 2.0, 9.0, 4.0, 6.0, 7.0];
        let leaf_of = [Some(3), Some(0), None, Some(3), Some(0), Some(5)];
        assert_eq!(leaf_means(&values, &leaf_of), vec![4.0, 2.5, 7.0]);
        assert!(leaf_means(&values, &[None; 6]).is_empty());
    }

    /// One leaf facing the eye in full sun: every eye ray that hits it sees the whole sky and
    /// the sun, so the tracer is exact against itself (cosine-sampled sides) and the model's
    /// sun — nothing in the way, every bin open — and the shadow map's agree with it exactly.
    #[test]
    fn a_lone_leaf_is_exact_at_every_pixel_size() {
        let mut leaves = LeafSet::default();
        let to_eye = Vec3::new(0.2, 0.5, 1.0).normalize();
        // Facing up: the sky fills its front and the ground its back, so cosine sampling is exact.
        push_square_leaf(&mut leaves, Vec3::ZERO, 0.5, Vec3::Y);
        let run = images_against_tracer(
            &leaves,
            &LeafMaterial::default(),
            &light(),
            to_eye,
            1.0,
            &ImageSettings {
                samples: 16,
                directions: 8,
                ..ImageSettings::default()
            },
            2,
            &[(SunThroughCrown::BlendedAttenuation, BinEstimate::Neighbours)],
            &[1, 4, 16, 0],
        );
        // The leaf (side 1, seen at a slant) inside the square of side 2·0.707 framing it.
        assert!(run.hits > 16 * 16 / 8, "{}", run.hits);
        assert_eq!(run.noise.len(), 4);
        for (noise, model) in run.noise.iter().zip(&run.models[0].1) {
            assert!(noise.sky.mean_absolute < 1e-4, "{noise:?}");
            assert!(model.sun.mean_absolute < 1e-4, "{model:?}");
            assert!(model.sun.share > 0.3);
        }
        assert_eq!(run.shadow_map_sun.len(), 1);
        for mapped in &run.shadow_map_sun[0].1 {
            assert!(mapped.sun.mean_absolute < 1e-4, "{mapped:?}");
        }
        assert_eq!(
            run.noise
                .iter()
                .map(|e| e.pixels_across)
                .collect::<Vec<_>>(),
            vec![16, 4, 1, 0]
        );
        // Leaf by leaf: the one leaf, a pixel a leaf wide.
        let by_leaf = &run.models[0].1[3];
        assert_eq!((by_leaf.sun.leaves, by_leaf.pixel_in_leaves), (1, 1.0));
    }

    /// On the crown the model assumes, leaf by leaf the sun is all or nothing, which eq. 5.8's
    /// expectation cannot follow; pixels several leaves wide average leaves in sun and in shade,
    /// and the sun's error falls towards the error of the crown's mean, which no pixel size
    /// changes. The sky, smooth leaf to leaf, is close at every size.
    #[test]
    fn the_limits_of_the_gains_see_what_a_roof_leaves_open() {
        // A leaf half under a roof just above it, seen from above: only its open half is in
        // view, brighter than the leaf's mean, which the model without a gain gives it. The
        // ground as bright as the sky: the open share the gains weigh is the uniform sphere's.
        let uniform = TraceLight {
            ground: light().sky,
            ..light()
        };
        let mut leaves = LeafSet::default();
        push_square_leaf(&mut leaves, Vec3::ZERO, 0.5, Vec3::Y);
        push_square_leaf(&mut leaves, Vec3::new(-0.6, 0.02, 0.0), 0.6, Vec3::Y);
        let run = images_against_tracer(
            &leaves,
            &LeafMaterial::default(),
            &uniform,
            Vec3::new(0.1, 1.0, 0.05).normalize(),
            1.0,
            &ImageSettings {
                samples: 32,
                directions: 64,
                seen_points: 64,
                ..ImageSettings::default()
            },
            2,
            &[(
                SunThroughCrown::BlendedAttenuation,
                BinEstimate::Traced { rays_per_bin: 256 },
            )],
            &[1],
        );
        let plain = run.models[0].1[0].sky.of_the_mean;
        let along = run.seen_along[0].sky.of_the_mean;
        let at_point = run.open_at_point[0].sky.of_the_mean;
        assert!(plain < -0.04, "{plain}");
        assert!(along.abs() < plain.abs() / 3.0, "{along} against {plain}");
        assert!(
            at_point.abs() < plain.abs() / 3.0,
            "{at_point} against {plain}"
        );
    }

    #[test]
    fn the_suns_image_error_falls_as_pixels_average_more_leaves() {
        let leaves = uniform_ball(1500, 1.5, 0.05, 5);
        let run = images_against_tracer(
            &leaves,
            &LeafMaterial::default(),
            &light(),
            Vec3::new(0.0, 0.3, 1.0),
            0.1,
            &ImageSettings {
                samples: 64,
                directions: 64,
                ..ImageSettings::default()
            },
            2,
            &[(SunThroughCrown::BlendedAttenuation, BinEstimate::Neighbours)],
            &[1, 4, 16],
        );
        let errors = &run.models[0].1;
        for e in errors {
            eprintln!(
                "pixel {:.2} leaves: sky {:.3}, sun {:.3} (mean {:+.3}), bounce {:.3}",
                e.pixel_in_leaves,
                e.sky.mean_absolute,
                e.sun.mean_absolute,
                e.sun.of_the_mean,
                e.bounce.mean_absolute
            );
        }
        let (fine, coarse) = (&errors[0], &errors[2]);
        assert!((fine.pixel_in_leaves - 0.5).abs() < 0.05);
        assert!(fine.sun.mean_absolute > 0.4, "{:?}", fine.sun);
        assert!(
            coarse.sun.mean_absolute < 0.35 * fine.sun.mean_absolute,
            "{:?} against {:?}",
            coarse.sun,
            fine.sun
        );
        assert!(coarse.sun.mean_absolute >= coarse.sun.of_the_mean.abs());
        for e in errors {
            assert!((e.sun.of_the_mean - fine.sun.of_the_mean).abs() < 1e-4);
        }
        // The sky within a few per cent from pixels two leaves wide (the tracer's own noise at
        // 64 rays a point dominates finer ones).
        assert!(errors[1].sky.mean_absolute < 0.06, "{:?}", errors[1].sky);
        assert!(errors[2].sky.mean_absolute < 0.03, "{:?}", errors[2].sky);
        // Finer than the model, the shadow map's sun at each point is closer at every size.
        for (mapped, model) in run.shadow_map_sun[0].1.iter().zip(errors) {
            eprintln!("shadow map {:?}", mapped.sun);
            assert!(mapped.sun.mean_absolute < model.sun.mean_absolute);
        }
    }
}
