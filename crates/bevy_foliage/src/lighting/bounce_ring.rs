//! The bounce ratios re-gathered while an app runs, on a ring of suns at the sun's elevation.
//!
//! A bake gathers each leaf's bounce for fourteen fixed suns ([`super::gathered_bounce`]) and
//! the leaf shaders blend them towards the sun of the moment. Against the sun the blend is what
//! costs: in images of the four procedural trees at pixels 1.4–2.5 leaves wide it is 21–35 %
//! off where the same rays gathered for the image's own sun are 7–18 % off
//! (`tree_lighting_error --images --bounce-rays 64 --sun-ring 14`). Boulanger 2008 recomputes
//! the bounce's per-tree constants (G1–G3, eq. 5.18, 5.25, 5.26) on the CPU whenever the
//! lighting changes (§5.4.3, §5.6); this is the same step for the gathered part.
//!
//! Re-gathering for the sun alone would serve only trees turned as the bake's: a forest turns
//! its instances about their vertical, and each sees the one sun at its own azimuth in its
//! model's frame. So the ratios are gathered for [`RING_NODES`] suns at the sun's elevation
//! spread round the model's vertical ([`ring_suns`]), which every upright instance, however
//! turned, sees the sun among; the leaf vertex shader reads the ring linearly in azimuth
//! ([`ratio_on_ring`]). Fourteen nodes fill the 28 bytes a leaf's basis ratios take, stored the
//! same way (front face's nodes, then the back's). Measured against a ring of 12 (the table of
//! `tree_lighting_error --sun-ring 6,8,12,14`), fewer nodes cost more between them.
//!
//! The ring holds for the elevation it was gathered at. A sun (in the model's frame) within
//! [`RING_FULL_DEGREES`] of it takes the ring alone, one beyond [`RING_GONE_DEGREES`] the
//! fourteen-sun blend alone, and between them the two are mixed ([`ring_weight`]): a tilted
//! instance, a ring not yet gathered or one the sun has moved away from while its successor is
//! gathered fall back to the bake's ratios without a jump. [`needs_regather`] says when the sun
//! has moved far enough for a new ring. While the sun stays, an app refines the ring's ratios
//! by further passes of their gather, each with the leaves' rays shifted anew
//! ([`RingRefinement`]): at 32 rays a leaf the gather's noise is most of the bounce's error.
//!
//! The same ring carries each leaf's sunlit share towards its suns ([`super::sunlit_share`],
//! traced in the same task) with the share's slope across the leaf, the leaves' sun where the
//! shadow map's texels are too coarse to resolve leaves ([`sun_through_with_ring`],
//! [`ring_shares_at`]): the blend of eight octants loses a sunfleck a few degrees wide. The
//! crown's hotspot on the shares is fitted with the ring, against the shares as drawn
//! ([`ring_sun_hotspot`]; the bake's is fitted against the blend). Traced first, the shares'
//! planes also stand in for the shadow rays of the ratios' gather ([`ring_ratios`]). On the four procedural trees
//! at pixels 1.4–2.5 leaves wide the shares so drawn, with the seen-part gain and that
//! hotspot, put the sun's image error at 4.8 % with the sun behind the eye, 6.1–6.6 % beside
//! and above it and 14–16 % against it, where the blend is at 8–28 % and 52–57 %, the shares
//! with the bake's hotspot at 3.9 %, 6.8–7.4 % and 14–17 % and without their slopes at
//! 4.6–8.5 % and 21–24 % (`tree_lighting_error --images --sun-ring 14 --sunlit-points 16`).
//!
//! Plain Rust, no render types.

use super::envelope::LeafEnvelope;
use super::gathered_bounce::{
    BounceRatios, STORED_RATIOS, quantize_ratio, ratio_of, ratio_towards, sun_ratios_with,
};
use super::hotspot::{HOTSPOT_NODES, Hotspot, HotspotSettings, HotspotSuns, crown_hotspot_for};
use super::leaf_scene::LeafScene;
use super::model::{LeafMaterial, open_share};
use super::sunlit_share::{
    SharePlane, plane_on_ring, quantize_share, quantize_slope, share_of, share_on_ring, slope_of,
    sunlit_planes,
};
use bevy::math::Vec3;
use std::f32::consts::TAU;

/// Suns on a ring: their ratios, front and back, fill a leaf's [`STORED_RATIOS`] bytes.
pub const RING_NODES: usize = STORED_RATIOS / 2;

/// Within this many degrees of elevation of its ring a sun takes the ring alone.
pub const RING_FULL_DEGREES: f32 = 2.0;

/// Beyond this many degrees of elevation from its ring a sun takes the bake's blend alone.
pub const RING_GONE_DEGREES: f32 = 6.0;

/// The default of how far (degrees of elevation) the sun moves from the ring before a new one
/// is gathered: half of [`RING_FULL_DEGREES`], so that the ring in use stays whole while the
/// next is gathered unless the sun moves faster than a degree per re-gather.
pub const DEFAULT_REGATHER_DEGREES: f32 = 1.0;

/// The passes of its rays a ring's ratios are refined to by default ([`RingRefinement`]):
/// 16 of the default 32 rays a leaf, 512 in all.
pub const DEFAULT_RING_PASSES: u32 = 16;

/// The most passes a ring is refined to (a setting above is clamped): past a few hundred the
/// mean moves by less than a stored step.
pub const MAX_RING_PASSES: u32 = 256;

/// The sun height stored for a leaf without a ring (no sun is that high): the blend alone.
pub const NO_RING: f32 = 2.0;

/// How the ring's own hotspot on the sun is traced ([`ring_sun_hotspot`]): as a bake kept on
/// disk traces the crown's ([`HotspotSettings::OFFLINE`]) but without the bounce, whose
/// factors the shaders keep from the bake. Its eye and shadow rays cost a small part of the
/// ring's gather (0.02–0.07 s for a 2,000-leaf crown on two threads, where the ring's ratios
/// and shares take 0.5–0.9 s).
pub const RING_HOTSPOT: HotspotSettings = HotspotSettings {
    bounce_rays: 0,
    ..HotspotSettings::OFFLINE
};

/// A tree type's ring: the height of the suns it was gathered for (the y of the direction
/// towards them in the model's frame, +y up: the sine of their elevation) and, per stored leaf,
/// its ratios for the [`RING_NODES`] suns of [`ring_suns`] as a bake stores ratios
/// ([`quantize_ratio`]): node `k`'s front face at byte `k`, its back face at `RING_NODES + k`;
/// and, where traced, its sunlit share for each of those suns ([`super::sunlit_share`],
/// [`quantize_share`]: node `k` at byte `k`) with the share's slope across the leaf.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BounceRing {
    /// The sine of the ring's elevation.
    pub sun_height: f32,
    /// Per stored leaf, its ring ratios.
    pub leaves: Vec<[u8; STORED_RATIOS]>,
    /// Per stored leaf, its sunlit shares on the ring; empty where none were traced (the sun
    /// through the crown then stays the bake's blend, [`sun_through_with_ring`]).
    pub sunlit: Vec<[u8; RING_NODES]>,
    /// Per stored leaf and node, the gradient of its share's plane over the leaf
    /// ([`super::sunlit_share::SharePlane`]) times the leaf's radius (its farthest vertex
    /// from its vertices' centroid), model space, a [`quantize_slope`] a component: how much
    /// the share changes from the leaf's centre towards a vertex ([`ring_shares_at`]). Beside
    /// [`BounceRing::sunlit`]; all zero, or empty, for none.
    pub sunlit_slopes: Vec<[[i8; 3]; RING_NODES]>,
    /// The crown's hotspot exponents on the sun fitted against the ring's sunlit shares and
    /// their slopes ([`ring_sun_hotspot`]), a node a byte as a bake stores them
    /// ([`Hotspot::quantize`]); all zero where none was fitted (the shares then take the
    /// bake's, [`BounceRing::sun_exponent`]).
    pub sunlit_hotspot: [u8; HOTSPOT_NODES],
    /// Per stored leaf, how much an eye outside the crown sees of it ([`crown_view_weights`]):
    /// the weights of the crown's mean ring a billboard cloud reads ([`crown_mean_ring`]);
    /// empty (or for another number of leaves) for every leaf alike. Not in the leaves' light
    /// buffer.
    pub crown_weights: Vec<f32>,
}

impl BounceRing {
    /// The ring's own hotspot exponents on the sun, read back as stored; `None` where none
    /// was fitted (or the ring holds no shares).
    pub fn sun_hotspot(&self) -> Option<[f32; HOTSPOT_NODES]> {
        (!self.sunlit.is_empty() && self.sunlit_hotspot.iter().all(|&q| q > 0))
            .then(|| self.sunlit_hotspot.map(Hotspot::dequantize))
    }

    /// The exponent on the sunlit shares for an eye towards `to_eye` and the sun towards
    /// `to_sun` (unit, model space): the ring's own hotspot ([`BounceRing::sun_hotspot`])
    /// interpolated at their phase angle, or where it has none `bake_exponent`, the bake's
    /// (what the leaf vertex shader gives `ring_sun_at`).
    pub fn sun_exponent(&self, bake_exponent: f32, to_eye: Vec3, to_sun: Vec3) -> f32 {
        self.sun_hotspot().map_or(bake_exponent, |sun| {
            Hotspot {
                sun,
                bounce: [1.0; HOTSPOT_NODES],
            }
            .sun_at(to_eye, to_sun)
        })
    }
}

/// The elevation (radians) of a direction whose y is `height` (clamped to [−1, 1]).
pub fn elevation_of(height: f32) -> f32 {
    height.clamp(-1.0, 1.0).asin()
}

/// The [`RING_NODES`] suns of a ring at sun height `height` (the sine of their elevation,
/// clamped to [−1, 1]; not finite: empty): node `k` at azimuth `2π·k / RING_NODES` from +x
/// towards +z (the azimuth of `(x, y, z)` is `atan2(z, x)`).
pub fn ring_suns(height: f32) -> Vec<Vec3> {
    if !height.is_finite() {
        return Vec::new();
    }
    let y = height.clamp(-1.0, 1.0);
    let across = (1.0 - y * y).max(0.0).sqrt();
    (0..RING_NODES)
        .map(|k| {
            let azimuth = TAU * k as f32 / RING_NODES as f32;
            Vec3::new(across * azimuth.cos(), y, across * azimuth.sin())
        })
        .collect()
}

/// The ring at sun height `height` for `leaves` (indices into `scene`, in the order the ring
/// stores them; `envelopes[i]` the envelope of `leaves[i]`) of a crown of extinction `tau`:
/// [`ring_ratios`] for [`ring_suns`], `rays` rays a leaf, quantised; and with
/// `sunlit_points` above 0 each leaf's sunlit share for the same suns from that many points on
/// it, as its plane over the leaf ([`sunlit_planes`]: the share, and its gradient times the
/// leaf's radius `radii[l]` for scene leaf `l`, 0 where missing; 0 points: none traced), which
/// the ratios' gather then reads at its neighbour hits in place of shadow rays, and,
/// with the shares and the leaves' seen-part gains `gains` (`gains[i]` those of `leaves[i]`;
/// empty: none fitted), the crown's hotspot on the sun fitted against the shares
/// ([`ring_sun_hotspot`], traced as `hotspot`). A leaf without an envelope or outside
/// `scene`: ratios of 1 (eq. 5.24 unchanged).
#[allow(clippy::too_many_arguments)]
pub fn gather_ring(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    height: f32,
    rays: u32,
    sunlit_points: u32,
    radii: &[f32],
    gains: &[[f32; 8]],
    hotspot: &HotspotSettings,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    threads: usize,
) -> BounceRing {
    gather_ring_with(
        scene,
        material,
        leaves,
        envelopes,
        tau,
        height,
        rays,
        sunlit_points,
        radii,
        gains,
        hotspot,
        opacity,
        threads,
    )
    .ring
}

/// A ring as [`gather_ring`] gathers it, with what its further passes of rays need
/// ([`ring_pass`], [`RingRefinement`]).
#[derive(Clone, Debug, Default)]
pub struct GatheredRing {
    /// The ring.
    pub ring: BounceRing,
    /// Per leaf and node, its ratios (front, back) before quantising.
    pub ratios: Vec<Vec<[f32; 2]>>,
    /// Per leaf and node, its sunlit share's plane the ratios' gather read at its neighbour
    /// hits; `None` where no shares were traced (shadow rays).
    pub planes: Option<Vec<Vec<SharePlane>>>,
}

/// [`gather_ring`], with the ratios before quantising and the leaves' sunlit planes.
#[allow(clippy::too_many_arguments)]
pub fn gather_ring_with(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    height: f32,
    rays: u32,
    sunlit_points: u32,
    radii: &[f32],
    gains: &[[f32; 8]],
    hotspot: &HotspotSettings,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    threads: usize,
) -> GatheredRing {
    let suns = ring_suns(height);
    let planes = (sunlit_points > 0 && !suns.is_empty())
        .then(|| sunlit_planes(scene, leaves, &suns, sunlit_points, opacity, threads));
    let ratios = ring_ratios(
        scene,
        material,
        leaves,
        envelopes,
        tau,
        &suns,
        rays,
        0,
        planes.as_deref(),
        opacity,
        threads,
    );
    let (sunlit, sunlit_slopes, sunlit_hotspot) = if let Some(planes) = &planes {
        let hotspot = if gains.is_empty() {
            [0; HOTSPOT_NODES]
        } else {
            ring_sun_hotspot(
                scene, material, leaves, envelopes, tau, gains, height, planes, 0.0, opacity,
                hotspot, threads,
            )
            .map(Hotspot::quantize)
        };
        let shares = planes
            .iter()
            .map(|p| std::array::from_fn(|k| quantize_share(p[k].mean)))
            .collect();
        let slopes = planes
            .iter()
            .zip(leaves)
            .map(|(p, &leaf)| {
                let radius = radii.get(leaf as usize).copied().unwrap_or(0.0);
                std::array::from_fn(|k| (p[k].gradient * radius).to_array().map(quantize_slope))
            })
            .collect();
        (shares, slopes, hotspot)
    } else {
        (Vec::new(), Vec::new(), [0; HOTSPOT_NODES])
    };
    let ring = BounceRing {
        sun_height: height.clamp(-1.0, 1.0),
        leaves: ratios
            .iter()
            .map(|nodes| quantize_nodes(nodes, 1.0))
            .collect(),
        sunlit,
        sunlit_slopes,
        sunlit_hotspot,
        crown_weights: crown_view_weights(scene, leaves, envelopes, opacity),
    };
    GatheredRing {
        ring,
        ratios,
        planes,
    }
}

/// A leaf's ratios per node (front, back), each times `scale`, as a ring stores them: node
/// `k`'s front face at byte `k`, its back face at `RING_NODES + k`; a missing node 1.
fn quantize_nodes(nodes: &[[f32; 2]], scale: f32) -> [u8; STORED_RATIOS] {
    std::array::from_fn(|i| {
        let face = i / RING_NODES;
        quantize_ratio(nodes.get(i % RING_NODES).map_or(1.0, |r| r[face] * scale))
    })
}

/// Pass `pass` (from 1; 0 is [`gather_ring`]'s own) of a ring's ratios at sun height
/// `height`: [`ring_ratios`] for [`ring_suns`] with each leaf's rays shifted anew, through the
/// sunlit planes the ring's first gather traced ([`GatheredRing::planes`]).
#[allow(clippy::too_many_arguments)]
pub fn ring_pass(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    height: f32,
    rays: u32,
    pass: u32,
    planes: Option<&[Vec<SharePlane>]>,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    threads: usize,
) -> Vec<Vec<[f32; 2]>> {
    ring_ratios(
        scene,
        material,
        leaves,
        envelopes,
        tau,
        &ring_suns(height),
        rays,
        pass,
        planes,
        opacity,
        threads,
    )
}

/// A ring's ratios refined by further passes of its gather while the sun stays at the ring's
/// elevation: the mean of the passes so far, each pass the leaf's rays shifted anew
/// ([`ring_pass`]).
///
/// Why: at the 32 rays a leaf a ring can gather in a fraction of a second, the bounce's noise
/// is most of its error where the sun is behind the eye, beside it or above. On the four
/// procedural trees at pixels 1.4–2.5 leaves wide, as the leaf shaders draw the bounce (the
/// ring of 14 with its own hotspot, the sun midway between two nodes; `tree_lighting_error
/// --images --bounce-rays 32 --ring-rays R --sun-ring 14 --sunlit-points 36`), the ring's
/// rays alone take it with the sun behind the eye (α = 4°) from 7.3 % at 32 rays to 5.6 % at
/// 512. Against the sun (α = 148°) more rays take it from 16.2 to 13 %, and no further: what
/// is left there is one value a face, not the noise. The first pass lands at once; the rest
/// come while nothing has changed, at the cost of one gather of the ratios each (no shares,
/// no hotspot: those are traced once, with the first).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RingRefinement {
    passes: u32,
    /// Per leaf and node, the ratios (front, back) summed over the passes.
    sums: Vec<Vec<[f32; 2]>>,
}

impl RingRefinement {
    /// The refinement of a ring whose first pass gathered `ratios` ([`GatheredRing::ratios`]).
    pub fn new(ratios: Vec<Vec<[f32; 2]>>) -> Self {
        Self {
            passes: 1,
            sums: ratios,
        }
    }

    /// Passes summed so far.
    pub fn passes(&self) -> u32 {
        self.passes
    }

    /// Adds a pass's ratios, for as many leaves and nodes as the first's; one of another shape
    /// (not the same ring's) is not added and gives `false`.
    pub fn add(&mut self, ratios: &[Vec<[f32; 2]>]) -> bool {
        let same_shape = ratios.len() == self.sums.len()
            && ratios
                .iter()
                .zip(&self.sums)
                .all(|(a, b)| a.len() == b.len());
        if !same_shape {
            return false;
        }
        for (sum, pass) in self.sums.iter_mut().zip(ratios) {
            for (s, r) in sum.iter_mut().zip(pass) {
                s[0] += r[0];
                s[1] += r[1];
            }
        }
        self.passes += 1;
        true
    }

    /// Takes the refinement on to `passes` passes, each gathered by `pass(p)` for pass `p` and
    /// added in turn (a pass of another shape ends it).
    pub fn refine_to(&mut self, passes: u32, mut pass: impl FnMut(u32) -> Vec<Vec<[f32; 2]>>) {
        for p in self.passes..passes {
            if !self.add(&pass(p)) {
                break;
            }
        }
    }

    /// The passes' mean ratios, per leaf and node (front, back).
    pub fn mean(&self) -> Vec<Vec<[f32; 2]>> {
        let scale = 1.0 / self.passes.max(1) as f32;
        self.sums
            .iter()
            .map(|nodes| nodes.iter().map(|r| [r[0] * scale, r[1] * scale]).collect())
            .collect()
    }

    /// Bytes the refinement holds: its sums, per leaf a list of the nodes' two ratios.
    pub fn heap_bytes(&self) -> usize {
        self.sums
            .iter()
            .map(|nodes| size_of::<Vec<[f32; 2]>>() + size_of_val(nodes.as_slice()))
            .sum()
    }

    /// The passes' mean ratios, per leaf, as a ring stores them ([`BounceRing::leaves`]).
    pub fn quantized(&self) -> Vec<[u8; STORED_RATIOS]> {
        let scale = 1.0 / self.passes.max(1) as f32;
        self.sums
            .iter()
            .map(|nodes| quantize_nodes(nodes, scale))
            .collect()
    }
}

/// [`gather_ring`] refined to `passes` passes of `rays` rays a leaf ([`RingRefinement`]; 0 or 1:
/// the gather alone): what an app's ring holds once its passes are in.
#[allow(clippy::too_many_arguments)]
pub fn gather_ring_refined(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    height: f32,
    rays: u32,
    passes: u32,
    sunlit_points: u32,
    radii: &[f32],
    gains: &[[f32; 8]],
    hotspot: &HotspotSettings,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    threads: usize,
) -> BounceRing {
    let GatheredRing {
        mut ring,
        ratios,
        planes,
    } = gather_ring_with(
        scene,
        material,
        leaves,
        envelopes,
        tau,
        height,
        rays,
        sunlit_points,
        radii,
        gains,
        hotspot,
        opacity,
        threads,
    );
    let mut refinement = RingRefinement::new(ratios);
    refinement.refine_to(passes, |pass| {
        ring_pass(
            scene,
            material,
            leaves,
            envelopes,
            tau,
            height,
            rays,
            pass,
            planes.as_deref(),
            opacity,
            threads,
        )
    });
    ring.leaves = refinement.quantized();
    ring
}

/// Each of `leaves`' bounce ratios for the ring's `suns` ([`sun_ratios_with`], `rays` rays a
/// leaf shifted for pass `pass`, 0 for a ring's first, not quantised): with the leaves' sunlit planes for those suns (`planes[i][k]` of
/// `leaves[i]` for `suns[k]`), each neighbour hit reads the neighbour's share there off its
/// plane in place of a shadow ray, and a neighbour outside `leaves` casts its shadow ray.
///
/// Why the planes: a ray's gather tosses two coins, whether it finds a neighbour and whether
/// that neighbour is in sun where it hits; the plane takes the second away. For the image's
/// own sun on the four procedural trees at pixels 1.4–2.5 leaves wide (`tree_lighting_error
/// --images --bounce-rays 32 --sunlit-points 36 --through-planes 32,128`, five suns from behind
/// the eye to against it, [`super::bounce_floor`]) the bounce at 32 rays a leaf is 0.3–2.6
/// points closer to the tracer with the planes (α = 148°: 15.7 → 13.4 %), with no shadow rays
/// to cast; at 128 rays the planes' own error shows (0–1.2 points farther).
#[allow(clippy::too_many_arguments)]
pub fn ring_ratios(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    suns: &[Vec3],
    rays: u32,
    pass: u32,
    planes: Option<&[Vec<SharePlane>]>,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    threads: usize,
) -> Vec<Vec<[f32; 2]>> {
    // `sun_ratios_with` numbers only the suns that are directions (a sun that is none gets
    // ratio 1, as from `sun_ratios_of`); `given[k]` is where its k-th stands in `suns`, which
    // is how `planes` are numbered.
    let (given, directions): (Vec<usize>, Vec<Vec3>) = suns
        .iter()
        .enumerate()
        .filter_map(|(k, s)| Some((k, s.try_normalize()?)))
        .unzip();
    let mut position = vec![u32::MAX; scene.leaf_count()];
    for (i, &leaf) in leaves.iter().enumerate() {
        if let Some(p) = position.get_mut(leaf as usize) {
            *p = i as u32;
        }
    }
    let through_planes = |other: u32, hit: Vec3, k: usize| -> f32 {
        let plane = planes.and_then(|planes| {
            let i = *position.get(other as usize)?;
            planes.get(i as usize)?.get(given[k])
        });
        match plane {
            Some(plane) => plane.at(hit),
            None => scene.transmittance(hit, directions[k], other, opacity),
        }
    };
    sun_ratios_with(
        scene,
        material,
        leaves,
        envelopes,
        tau,
        suns,
        rays,
        pass,
        opacity,
        planes.map(|_| &through_planes as &(dyn Fn(u32, Vec3, usize) -> f32 + Sync)),
        threads,
    )
}

/// The crown's hotspot exponents on the sun for a ring's sunlit shares: fitted, as the bake
/// fits the crown's against the blend of its attenuations ([`super::hotspot`]), for suns at
/// the ring's height `height` at every azimuth (every turn of an instance), each eye ray's
/// hit against the share drawn there — the plane of its leaf (`planes[i]`, node by node, of
/// `leaves[i]`, `envelopes[i]` its envelope, `gains[i]` its seen-part gains) read at the hit
/// point and linearly in azimuth between the ring's nodes, node 0 at azimuth `phase` (0 for
/// [`ring_suns`]).
///
/// The bake's exponents are fitted against the blend, which the part of a leaf in view
/// differs from more than it does from a share read where the eye looks, so on the shares
/// they over-correct: on the four procedural trees at pixels 1.4–2.5 leaves wide, the sun
/// midway between two nodes (`tree_lighting_error --images --hotspot --sun-ring 14
/// --sunlit-points 16`, the rows as the leaf shaders draw them), the shares' bias with the sun
/// against the eye (α = 137°) is −5.1…+0.2 % with the bake's (the cedar −10.8 %) and
/// −1.3…+2.6 % with these; the image error averaged over the trees goes from 7.4 to 6.6 %
/// at α = 58°, 6.8 to 6.1 % at 68°, 14.5 to 13.8 % at 137° and 16.6 to 16.0 % at 148°, and
/// from 3.9 to 4.8 % with the sun behind the eye (α = 4°), where these leave the shares
/// 1–3.7 % dark. Traced as [`RING_HOTSPOT`], the fit takes 0.02–0.07 s for 2,000 leaves on
/// two threads.
#[allow(clippy::too_many_arguments)]
pub fn ring_sun_hotspot(
    scene: &LeafScene,
    material: &LeafMaterial,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    tau: f32,
    gains: &[[f32; 8]],
    height: f32,
    planes: &[Vec<SharePlane>],
    phase: f32,
    opacity: &(impl Fn(u32) -> f32 + Sync),
    settings: &HotspotSettings,
    threads: usize,
) -> [f32; HOTSPOT_NODES] {
    let count = leaves.len().min(envelopes.len()).min(planes.len());
    let mut stored = vec![None; scene.leaf_count()];
    for (i, &l) in leaves[..count].iter().enumerate() {
        if let Some(slot) = stored.get_mut(l as usize) {
            *slot = Some(i);
        }
    }
    let share = |i: usize, to_sun: Vec3, at: Vec3| plane_on_ring(&planes[i], phase, to_sun).at(at);
    crown_hotspot_for(
        scene,
        &envelopes[..count],
        tau,
        gains,
        &|_, _| [1.0; 2],
        HotspotSuns::Height(height),
        Some(&share),
        &|l| stored.get(l as usize).copied().flatten(),
        material,
        opacity,
        settings,
        threads,
    )
    .sun
}

/// How much an eye outside the crown sees of each of `leaves` (`envelopes` theirs, in the
/// same order), averaged over the eye's directions all round: a leaf of area A, opaque share o
/// and normal n is seen from ω over A·o·|n·ω|·a(ω), a(ω) what the crown lets through towards
/// ω, whose mean over the sphere is A·o·Ō/2, Ō the leaf's open share from its bins (§5.6,
/// [`super::model::open_share`]). So the weights are A·o·Ō: a leaf deep in the crown, whose
/// bins are shut, is hardly in any image of it. 0 for a leaf the scene does not hold or whose
/// values are not finite.
pub fn crown_view_weights(
    scene: &LeafScene,
    leaves: &[u32],
    envelopes: &[LeafEnvelope],
    opacity: &impl Fn(u32) -> f32,
) -> Vec<f32> {
    leaves
        .iter()
        .zip(envelopes)
        .map(|(&l, envelope)| {
            if l as usize >= scene.leaf_count() {
                return 0.0;
            }
            let open = open_share(scene.normal(l as usize), &envelope.attenuation);
            let w = scene.area(l as usize) * opacity(l).clamp(0.0, 1.0) * open;
            if w.is_finite() { w.max(0.0) } else { 0.0 }
        })
        .collect()
}

/// The crown's mean ring: per node and face the mean of its leaves' ring ratios (read back as
/// stored), each leaf weighted by how much an eye outside the crown sees of it
/// ([`BounceRing::crown_weights`], [`crown_view_weights`]; alike where the ring has none), for
/// a billboard cloud, whose texels have no room for their leaves' own (as
/// [`super::gathered_bounce::crown_mean_ratios`] for the bake's): a cloud shows the crown's
/// outer leaves, whose ratios are not the hidden ones'. No leaves, or no weight: all 1.
pub fn crown_mean_ring(ring: &BounceRing) -> [[f32; 2]; RING_NODES] {
    let weighted = ring.crown_weights.len() == ring.leaves.len();
    let mut sum = [[0.0f64; 2]; RING_NODES];
    let mut total = 0.0f64;
    for (i, stored) in ring.leaves.iter().enumerate() {
        let w = if weighted {
            ring.crown_weights[i] as f64
        } else {
            1.0
        };
        if !(w > 0.0 && w.is_finite()) {
            continue;
        }
        total += w;
        for (k, node) in ring_nodes_of(stored).iter().enumerate() {
            sum[k][0] += w * node[0] as f64;
            sum[k][1] += w * node[1] as f64;
        }
    }
    if total <= 0.0 {
        return [[1.0; 2]; RING_NODES];
    }
    sum.map(|[f, b]| [(f / total) as f32, (b / total) as f32])
}

/// A leaf's ring ratios as stored, read back: per node, front and back.
pub fn ring_nodes_of(stored: &[u8; STORED_RATIOS]) -> [[f32; 2]; RING_NODES] {
    std::array::from_fn(|k| [ratio_of(stored[k]), ratio_of(stored[RING_NODES + k])])
}

/// The ratios towards `to_sun` (model space) from a leaf's ring nodes: linear in azimuth
/// between the two nodes either side, continuous all round (a sun straight up or down, whose
/// azimuth is none, takes node 0's: every node is that sun there).
pub fn ratio_on_ring(nodes: &[[f32; 2]; RING_NODES], to_sun: Vec3) -> [f32; 2] {
    super::gathered_bounce::ratio_on_ring(nodes, 0.0, to_sun)
}

/// How much of a leaf's ratios the ring gathered at sun height `ring_height` gives for the sun
/// towards `to_sun` (unit, model space), the bake's blend giving the rest: 1 within
/// [`RING_FULL_DEGREES`] of the ring's elevation, 0 beyond [`RING_GONE_DEGREES`], smooth
/// (smoothstep) between; 0 for no ring ([`NO_RING`], anything outside [−1, 1]) or a sun that
/// is not finite.
pub fn ring_weight(ring_height: f32, to_sun: Vec3) -> f32 {
    if ring_height.is_nan() || ring_height.abs() > 1.0 || !to_sun.is_finite() {
        return 0.0;
    }
    let apart = (elevation_of(to_sun.y) - elevation_of(ring_height))
        .abs()
        .to_degrees();
    let t = ((apart - RING_FULL_DEGREES) / (RING_GONE_DEGREES - RING_FULL_DEGREES)).clamp(0.0, 1.0);
    1.0 - t * t * (3.0 - 2.0 * t)
}

/// A leaf's bounce factors (front, back) for the sun towards `to_sun` (unit, model space): its
/// ring's nodes (`ring`: the ring's sun height and the leaf's stored ring ratios) where the
/// sun is at the ring's elevation, the bake's `basis` ratios blended towards the sun
/// ([`ratio_towards`]) where it is not, mixed by [`ring_weight`] between. What the leaf vertex
/// shader gives eq. 5.24's faces (`tree_lighting.wgsl`'s `ratio_with_ring`).
pub fn ratio_with_ring(
    basis: &BounceRatios,
    ring: Option<(f32, &[u8; STORED_RATIOS])>,
    to_sun: Vec3,
) -> [f32; 2] {
    let nodes = ring.map(|(height, stored)| (height, ring_nodes_of(stored)));
    ratio_with_ring_nodes(basis, nodes.as_ref().map(|(h, n)| (*h, n)), to_sun)
}

/// [`ratio_with_ring`] with the ring's nodes as ratios (a billboard cloud's crown mean,
/// [`crown_mean_ring`]).
pub fn ratio_with_ring_nodes(
    basis: &BounceRatios,
    ring: Option<(f32, &[[f32; 2]; RING_NODES])>,
    to_sun: Vec3,
) -> [f32; 2] {
    let blend = ratio_towards(basis, to_sun);
    let Some((height, nodes)) = ring else {
        return blend;
    };
    let w = ring_weight(height, to_sun);
    if w <= 0.0 {
        return blend;
    }
    let on_ring = ratio_on_ring(nodes, to_sun);
    [0, 1].map(|f| blend[f] + w * (on_ring[f] - blend[f]))
}

/// The sun's share through the crown at a leaf for the sun towards `to_sun` (unit, model
/// space) where the shadow map does not resolve leaves: `blend`, the bake's blend of
/// attenuations (with the seen-part gain and the crown's hotspot), where the sun is off the
/// ring's elevation; the leaf's sunlit shares on its type's ring (`ring`: the ring's sun height
/// and the leaf's shares where it is read, [`ring_shares_at`]), read linearly in azimuth,
/// scaled by the seen-part gain towards the eye `gain` (1 without it), capped at 1 and raised
/// to the crown's hotspot
/// exponent for the eye and the sun `exponent` (1 without it,
/// [`super::hotspot::Hotspot::sun_at`]), where the sun is at it; mixed by [`ring_weight`]
/// between. What the leaf shaders give the sun (`tree_lighting.wgsl`: `ring_sun_at` at each
/// vertex, the share carried across the leaf, then `through_on_ring` per fragment).
///
/// The ring's shares are traced for the sun itself at every turn of the instance, where the
/// blend's eight directions are octants a sunfleck a few degrees wide is lost in. The mean of
/// a leaf is not the part of it in view, least of all with the sun behind the eye, where the
/// eye's and the sun's paths share their gaps: without a hotspot the ring is 26–29 % too dark
/// on the olive there. The leaf shaders give the shares the ring's own hotspot
/// ([`BounceRing::sun_exponent`], [`ring_sun_hotspot`]), the bake's where the ring has none.
pub fn sun_through_with_ring(
    blend: f32,
    ring: Option<(f32, &[f32; RING_NODES])>,
    gain: f32,
    exponent: f32,
    to_sun: Vec3,
) -> f32 {
    let Some((height, nodes)) = ring else {
        return blend;
    };
    let w = ring_weight(height, to_sun);
    if w <= 0.0 {
        return blend;
    }
    let on_ring = (share_on_ring(nodes, 0.0, to_sun) * gain)
        .clamp(0.0, 1.0)
        .powf(exponent);
    blend + w * (on_ring - blend)
}

/// A leaf's stored sunlit shares on its ring read at a point of it `across` from its vertices'
/// centroid, in units of its radius (a vertex's `offset / radius`): each node's share plus
/// its stored slope ([`BounceRing::sunlit_slopes`]; none: the share alone) along `across`, not
/// yet clamped. The leaf vertex shader reads it at each vertex (`leaf_ring_shares`) and the
/// rasteriser carries the shares so read across the leaf, linear as they are, to each
/// fragment ([`sun_through_with_ring`] there): where a sunfleck's edge crosses a leaf,
/// one share a leaf gives it all its mean, and against the sun, where the part of a leaf in
/// view and its sunlit part are least alike, that is most of what the shares miss — on the
/// four procedural trees at pixels 1.4–2.5 leaves wide the sun's image error against it goes
/// from 20.8–23.6 % to 14.3–16.6 % (`tree_lighting_error --images --sun-ring 14
/// --sunlit-points 16`, the row as the leaf shaders draw it).
pub fn ring_shares_at(stored: &[u8], slopes: Option<&[[i8; 3]]>, across: Vec3) -> Vec<f32> {
    stored
        .iter()
        .enumerate()
        .map(|(k, &share)| {
            let slope = slopes
                .and_then(|s| s.get(k))
                .map_or(Vec3::ZERO, |s| Vec3::from_array(s.map(slope_of)));
            share_of(share) + slope.dot(across)
        })
        .collect()
}

/// Whether a tree type needs a new ring for the sun at height `sun_height` (the sine of its
/// elevation): not while the ring it has (`ring`, its sun height) is within
/// `threshold_degrees` of elevation of the sun; else yes. A sun that is not finite needs none.
/// (One being gathered is waited for: a re-gather runs to its end once started.)
pub fn needs_regather(sun_height: f32, ring: Option<f32>, threshold_degrees: f32) -> bool {
    if !sun_height.is_finite() {
        return false;
    }
    !ring.is_some_and(|h| {
        (elevation_of(h) - elevation_of(sun_height))
            .abs()
            .to_degrees()
            <= threshold_degrees
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::gathered_bounce::{
        DEFAULT_BOUNCE_RAYS, SUN_BASIS, basis_bounces, bounce_gather, leaf_seed,
    };
    use crate::lighting::path_trace::uniform_ball;
    use crate::lighting::traced_bins::crown_envelope_traced;

    #[test]
    fn the_ring_lies_at_the_suns_elevation_round_the_vertical() {
        let suns = ring_suns(0.5);
        assert_eq!(suns.len(), RING_NODES);
        for (k, s) in suns.iter().enumerate() {
            assert!((s.length() - 1.0).abs() < 1e-6);
            assert!((s.y - 0.5).abs() < 1e-6);
            let azimuth = s.z.atan2(s.x).rem_euclid(TAU);
            assert!((azimuth - TAU * k as f32 / RING_NODES as f32).abs() < 1e-5);
        }
        assert_eq!(ring_suns(0.0)[0], Vec3::X);
        assert!(ring_suns(f32::NAN).is_empty());
        assert!(ring_suns(3.0).iter().all(|s| *s == Vec3::Y));
    }

    #[test]
    fn the_ring_weight_is_whole_near_the_ring_and_gone_far_from_it() {
        let at = |degrees: f32| {
            let e = degrees.to_radians();
            Vec3::new(e.cos(), e.sin(), 0.0)
        };
        let h = 30f32.to_radians().sin();
        assert_eq!(ring_weight(h, at(30.0)), 1.0);
        assert_eq!(ring_weight(h, at(30.0 + RING_FULL_DEGREES - 0.01)), 1.0);
        assert_eq!(ring_weight(h, at(30.0 - RING_GONE_DEGREES - 0.01)), 0.0);
        assert_eq!(ring_weight(h, at(30.0 + RING_GONE_DEGREES + 0.01)), 0.0);
        let mid = ring_weight(h, at(30.0 + 0.5 * (RING_FULL_DEGREES + RING_GONE_DEGREES)));
        assert!((mid - 0.5).abs() < 1e-3, "{mid}");
        // Monotone in the elevation apart, the same either side.
        let mut last = 1.0;
        for tenth in 0..100 {
            let d = tenth as f32 * 0.1;
            let w = ring_weight(h, at(30.0 + d));
            assert!(w <= last + 1e-6 && (w - ring_weight(h, at(30.0 - d))).abs() < 1e-4);
            last = w;
        }
        // No ring, or a sun that is no direction: the blend alone.
        assert_eq!(ring_weight(NO_RING, at(30.0)), 0.0);
        assert_eq!(ring_weight(f32::NAN, at(30.0)), 0.0);
        assert_eq!(ring_weight(h, Vec3::NAN), 0.0);
        // The azimuth does not matter.
        assert_eq!(
            ring_weight(h, Vec3::new(0.0, h, -(1.0 - h * h).sqrt())),
            1.0
        );
    }

    /// Distinct ratios per node and face, as stored.
    fn distinct_ring() -> [u8; STORED_RATIOS] {
        std::array::from_fn(|i| {
            if i < RING_NODES {
                quantize_ratio(0.4 + 0.1 * i as f32)
            } else {
                quantize_ratio(3.0 + 0.25 * (i - RING_NODES) as f32)
            }
        })
    }

    #[test]
    fn the_ring_gives_its_nodes_and_mixes_with_the_blend_off_its_elevation() {
        let stored = distinct_ring();
        let nodes = ring_nodes_of(&stored);
        let basis = BounceRatios {
            front: std::array::from_fn(|k| 1.0 + 0.05 * k as f32),
            back: std::array::from_fn(|k| 0.7 + 0.02 * k as f32),
        };
        let h = 0.3f32;
        let suns = ring_suns(h);
        // On a node: its ratios exactly, front and back.
        for k in [0, 3, 13] {
            let r = ratio_with_ring(&basis, Some((h, &stored)), suns[k]);
            assert!((r[0] - nodes[k][0]).abs() < 1e-5 && (r[1] - nodes[k][1]).abs() < 1e-5);
        }
        // Midway between nodes 13 and 0 (across the wrap): their mean.
        let mid = (suns[13] + suns[0]).normalize();
        let mid = Vec3::new(mid.x, 0.0, mid.z).normalize() * (1.0 - h * h).sqrt() + Vec3::Y * h;
        let r = ratio_with_ring(&basis, Some((h, &stored)), mid);
        assert!(
            (r[0] - 0.5 * (nodes[13][0] + nodes[0][0])).abs() < 1e-4,
            "{r:?}"
        );
        assert!(
            (r[1] - 0.5 * (nodes[13][1] + nodes[0][1])).abs() < 1e-4,
            "{r:?}"
        );
        // No ring, or a sun far from its elevation: the blend.
        let far = Vec3::new(0.0, 0.9, 0.4359).normalize();
        assert_eq!(
            ratio_with_ring(&basis, None, far),
            ratio_towards(&basis, far)
        );
        assert_eq!(
            ratio_with_ring(&basis, Some((h, &stored)), far),
            ratio_towards(&basis, far)
        );
        // Between: the two mixed by the weight.
        let e = elevation_of(h) + (0.5 * (RING_FULL_DEGREES + RING_GONE_DEGREES)).to_radians();
        let between = Vec3::new(e.cos(), e.sin(), 0.0);
        let w = ring_weight(h, between);
        let (blend, ring) = (
            ratio_towards(&basis, between),
            ratio_on_ring(&nodes, between),
        );
        let r = ratio_with_ring(&basis, Some((h, &stored)), between);
        for f in 0..2 {
            assert!((r[f] - (blend[f] + w * (ring[f] - blend[f]))).abs() < 1e-5);
            assert!((r[f] - blend[f]).abs() > 0.1 && (r[f] - ring[f]).abs() > 0.1);
        }
    }

    #[test]
    fn the_crowns_mean_ring_is_each_node_and_faces_mean() {
        let a = distinct_ring();
        let b: [u8; STORED_RATIOS] = std::array::from_fn(|i| quantize_ratio(1.0 + i as f32 * 0.01));
        let ring = BounceRing {
            sun_height: 0.2,
            leaves: vec![a, b],
            ..Default::default()
        };
        let mean = crown_mean_ring(&ring);
        let (na, nb) = (ring_nodes_of(&a), ring_nodes_of(&b));
        for k in 0..RING_NODES {
            for f in 0..2 {
                assert!((mean[k][f] - 0.5 * (na[k][f] + nb[k][f])).abs() < 1e-5);
            }
        }
        let none = BounceRing {
            sun_height: 0.2,
            ..BounceRing::default()
        };
        assert_eq!(crown_mean_ring(&none), [[1.0; 2]; RING_NODES]);
    }

    /// The crown's mean ring weighs each leaf by how much of it an eye outside the crown sees:
    /// a leaf whose bins are all open by its area, one whose bins are shut not at all, a card
    /// twice as wide, half opaque and half open as much as the first; weights for another
    /// number of leaves count every leaf alike.
    #[test]
    fn the_crowns_mean_ring_weighs_the_leaves_an_eye_sees() {
        use crate::lighting::path_trace::push_square_leaf;
        use crate::pruning::leaves::LeafSet;
        let mut set = LeafSet::default();
        for (x, half) in [(0.0, 0.5), (3.0, 0.5), (6.0, 1.0)] {
            push_square_leaf(&mut set, Vec3::new(x, 0.0, 0.0), half, Vec3::Y);
        }
        let scene = LeafScene::new(&set);
        let envelope = |a: f32| LeafEnvelope {
            attenuation: [a; 8],
            s_max: [0.0; 8],
        };
        let envelopes = [envelope(1.0), envelope(0.0), envelope(0.5)];
        let opacity = |l: u32| if l == 2 { 0.5 } else { 1.0 };
        let weights = crown_view_weights(&scene, &[0, 1, 2], &envelopes, &opacity);
        for (w, want) in weights.iter().zip([1.0, 0.0, 1.0]) {
            assert!((w - want).abs() < 1e-4, "{weights:?}");
        }
        // A leaf the scene does not hold: no weight.
        assert_eq!(
            crown_view_weights(&scene, &[7], &envelopes, &opacity),
            [0.0]
        );
        let a = distinct_ring();
        let b: [u8; STORED_RATIOS] = std::array::from_fn(|i| quantize_ratio(1.0 + i as f32 * 0.01));
        let c: [u8; STORED_RATIOS] = std::array::from_fn(|i| quantize_ratio(2.0 - i as f32 * 0.02));
        let mut ring = BounceRing {
            sun_height: 0.2,
            leaves: vec![a, b, c],
            crown_weights: weights,
            ..Default::default()
        };
        let (na, nb, nc) = (ring_nodes_of(&a), ring_nodes_of(&b), ring_nodes_of(&c));
        let mean = crown_mean_ring(&ring);
        for k in 0..RING_NODES {
            for f in 0..2 {
                assert!((mean[k][f] - 0.5 * (na[k][f] + nc[k][f])).abs() < 1e-4);
            }
        }
        ring.crown_weights.pop();
        let alike = crown_mean_ring(&ring);
        for k in 0..RING_NODES {
            for f in 0..2 {
                let third = (na[k][f] + nb[k][f] + nc[k][f]) / 3.0;
                assert!((alike[k][f] - third).abs() < 1e-4);
            }
        }
        // No leaf seen at all: as no leaves.
        ring.crown_weights = vec![0.0; 3];
        assert_eq!(crown_mean_ring(&ring), [[1.0; 2]; RING_NODES]);
    }

    /// The sun through the crown: the ring's shares at its elevation (linear in azimuth, the
    /// gain applied, capped at 1), the blend off it, half and half midway; no ring: the blend.
    #[test]
    fn the_sun_takes_the_rings_shares_at_its_elevation() {
        let stored: [u8; RING_NODES] = std::array::from_fn(|k| (10 + 17 * k) as u8);
        let shares = stored.map(share_of);
        let h = 30f32.to_radians().sin();
        let sun_at = |elevation: f32, azimuth: f32| {
            let (e, a) = (elevation.to_radians(), azimuth);
            Vec3::new(e.cos() * a.cos(), e.sin(), e.cos() * a.sin())
        };
        let step = TAU / RING_NODES as f32;
        let node3 = sun_at(30.0, 3.0 * step);
        assert!(
            (sun_through_with_ring(0.9, Some((h, &shares)), 1.0, 1.0, node3) - share_of(stored[3]))
                .abs()
                < 1e-5
        );
        let between = sun_at(30.0, 3.25 * step);
        let want = share_of(stored[3]) + 0.25 * (share_of(stored[4]) - share_of(stored[3]));
        assert!(
            (sun_through_with_ring(0.9, Some((h, &shares)), 1.0, 1.0, between) - want).abs() < 1e-4
        );
        // The gain towards the eye scales it, up to full light.
        assert!(
            (sun_through_with_ring(0.9, Some((h, &shares)), 1.5, 1.0, node3)
                - 1.5 * share_of(stored[3]))
            .abs()
                < 1e-5
        );
        assert_eq!(
            sun_through_with_ring(0.9, Some((h, &shares)), 100.0, 1.0, node3),
            1.0
        );
        // The hotspot's exponent on the share (gain applied first).
        let raised = sun_through_with_ring(0.9, Some((h, &shares)), 1.2, 2.0, node3);
        assert!((raised - (1.2 * share_of(stored[3])).min(1.0).powi(2)).abs() < 1e-5);
        // Far from the ring's elevation, or no ring: the blend.
        assert_eq!(
            sun_through_with_ring(0.9, Some((h, &shares)), 1.0, 1.0, sun_at(50.0, 3.0 * step)),
            0.9
        );
        assert_eq!(sun_through_with_ring(0.9, None, 1.0, 1.0, node3), 0.9);
        assert_eq!(
            sun_through_with_ring(0.9, Some((NO_RING, &shares)), 1.0, 1.0, node3),
            0.9
        );
        // Midway between the ring's whole and gone spans: half and half.
        let mid = sun_at(
            30.0 + 0.5 * (RING_FULL_DEGREES + RING_GONE_DEGREES),
            3.0 * step,
        );
        let half = 0.5 * (0.9 + share_of(stored[3]));
        assert!(
            (sun_through_with_ring(0.9, Some((h, &shares)), 1.0, 1.0, mid) - half).abs() < 1e-3
        );
    }

    #[test]
    fn a_new_ring_is_gathered_when_the_sun_leaves_the_last() {
        let deg = |d: f32| d.to_radians().sin();
        // Nothing yet: gather.
        assert!(needs_regather(deg(40.0), None, 1.0));
        // A ring close enough: none.
        assert!(!needs_regather(deg(40.0), Some(deg(39.5)), 1.0));
        assert!(!needs_regather(deg(40.0), Some(deg(40.9)), 1.0));
        // The sun moved on: gather.
        assert!(needs_regather(deg(40.0), Some(deg(38.5)), 1.0));
        assert!(needs_regather(deg(-10.0), Some(deg(-12.0)), 1.0));
        assert!(!needs_regather(f32::NAN, None, 1.0));
    }

    /// A leaf's shares read across it: each node's share plus its slope along the point's
    /// place in radii; no slopes, or at the centre, the shares alone.
    #[test]
    fn the_rings_shares_are_read_along_their_slopes_across_the_leaf() {
        let stored: [u8; RING_NODES] = std::array::from_fn(|k| (10 + 17 * k) as u8);
        let slopes: [[i8; 3]; RING_NODES] =
            std::array::from_fn(|k| [k as i8 * 9 - 60, 40, -(k as i8) * 5]);
        let across = Vec3::new(0.5, -0.25, 1.0);
        let read = ring_shares_at(&stored, Some(&slopes), across);
        assert_eq!(read.len(), RING_NODES);
        for k in 0..RING_NODES {
            let slope = Vec3::from_array(slopes[k].map(slope_of));
            assert!((read[k] - (share_of(stored[k]) + slope.dot(across))).abs() < 1e-6);
        }
        // Not clamped here: the sun through the crown caps it after the gain.
        assert!(read.iter().any(|&s| s < 0.0) || read.iter().any(|&s| s > 1.0));
        assert_eq!(
            ring_shares_at(&stored, Some(&slopes), Vec3::ZERO),
            stored.map(share_of)
        );
        assert_eq!(ring_shares_at(&stored, None, across), stored.map(share_of));
        // A ring of any size (the tool draws rings of 28 and 56): every node its own.
        let stored: Vec<u8> = (0..4 * RING_NODES).map(|k| (3 + 4 * k) as u8).collect();
        let slopes: Vec<[i8; 3]> = (0..4 * RING_NODES)
            .map(|k| [k as i8 * 2 - 50, -(k as i8), 7])
            .collect();
        let read = ring_shares_at(&stored, Some(&slopes), across);
        assert_eq!(read.len(), 4 * RING_NODES);
        for k in 0..4 * RING_NODES {
            let slope = Vec3::from_array(slopes[k].map(slope_of));
            assert!((read[k] - (share_of(stored[k]) + slope.dot(across))).abs() < 1e-6);
        }
    }

    /// A uniform ball of leaves with what a ring is gathered from: its scene, every leaf,
    /// its traced envelope, the default optics and each leaf's radius.
    struct Ball {
        leaves: crate::pruning::leaves::LeafSet,
        scene: LeafScene,
        all: Vec<u32>,
        envelope: crate::lighting::envelope::CrownEnvelope,
        material: LeafMaterial,
        radii: Vec<f32>,
    }

    fn ball(count: usize, seed: u64) -> Ball {
        let leaves = uniform_ball(count, 1.0, 0.12, seed);
        let scene = LeafScene::new(&leaves);
        let proxies = crate::lighting::bins::proxies(&leaves);
        let all: Vec<u32> = (0..leaves.len() as u32).collect();
        let envelope = crown_envelope_traced(&proxies, &scene, &all, &|_| 1.0, 16, 2, &|_| {});
        let material = crate::lighting::settings::TreeLightingSettings::default().optics;
        let radii = (0..leaves.len())
            .map(|l| 0.5 * leaves.diameter(l))
            .collect();
        Ball {
            leaves,
            scene,
            all,
            envelope,
            material,
            radii,
        }
    }

    /// A ring at the horizon has its node 0 at +x, a basis sun: gathered with shadow rays (no
    /// shares traced), the leaves' ring ratios there are the bake's ratios for +x (the same
    /// rays), quantised as stored; with shares, the same rays read the neighbours' planes.
    #[test]
    fn a_ring_node_on_a_basis_sun_takes_the_bakes_ratios_for_it() {
        let Ball {
            leaves,
            scene,
            all,
            envelope,
            material,
            radii,
        } = ball(300, 7);
        let ring = gather_ring(
            &scene,
            &material,
            &all,
            &envelope.leaves,
            envelope.tau,
            0.0,
            DEFAULT_BOUNCE_RAYS,
            16,
            &radii,
            &[],
            &RING_HOTSPOT,
            &|_| 1.0,
            2,
        );
        assert_eq!(ring.leaves.len(), leaves.len());
        // Without seen-part gains no hotspot is fitted for the shares: the bake's serves.
        assert_eq!(ring.sunlit_hotspot, [0; HOTSPOT_NODES]);
        assert_eq!(ring.sun_hotspot(), None);
        assert_eq!(ring.sun_exponent(0.7, Vec3::X, Vec3::Y), 0.7);
        // The sunlit shares: each leaf's for each node's sun, traced as `sunlit_planes` does,
        // with the planes' slopes at the leaf's radius.
        assert_eq!(ring.sunlit.len(), leaves.len());
        assert_eq!(ring.sunlit_slopes.len(), leaves.len());
        let suns = ring_suns(0.0);
        for leaf in [0usize, 57, 299] {
            let traced = sunlit_planes(&scene, &[leaf as u32], &suns, 16, &|_| 1.0, 1);
            let want: Vec<u8> = traced[0].iter().map(|t| quantize_share(t.mean)).collect();
            assert_eq!(ring.sunlit[leaf].as_slice(), want.as_slice(), "leaf {leaf}");
            for (k, plane) in traced[0].iter().enumerate() {
                let slope = (plane.gradient * radii[leaf])
                    .to_array()
                    .map(quantize_slope);
                assert_eq!(ring.sunlit_slopes[leaf][k], slope, "leaf {leaf} node {k}");
            }
        }
        // Partly shaded leaves have their lit side: slopes of a tenth of a share and more.
        let sloped = ring
            .sunlit_slopes
            .iter()
            .filter(|s| s[0].iter().any(|&c| slope_of(c).abs() > 0.1))
            .count();
        assert!(sloped > 30, "{sloped}");
        // Inside a ball of leaves the sun reaches some leaves and not others, by node.
        let lit: usize = ring.sunlit.iter().map(|s| (s[0] > 200) as usize).sum();
        let dark: usize = ring.sunlit.iter().map(|s| (s[0] < 50) as usize).sum();
        assert!(lit > 30 && dark > 30, "lit {lit}, dark {dark}");
        assert_eq!(ring.sun_height, 0.0);
        // With the shares traced, the ratios' gather reads each neighbour's share off its plane
        // in place of a shadow ray: the same rays, another light at their hits.
        let planes = sunlit_planes(&scene, &all, &suns, 16, &|_| 1.0, 2);
        let through = ring_ratios(
            &scene,
            &material,
            &all,
            &envelope.leaves,
            envelope.tau,
            &suns,
            DEFAULT_BOUNCE_RAYS,
            0,
            Some(&planes),
            &|_| 1.0,
            2,
        );
        // Without shares, shadow rays: a ring node on a basis sun is the bake's for it.
        let shadowed = gather_ring(
            &scene,
            &material,
            &all,
            &envelope.leaves,
            envelope.tau,
            0.0,
            DEFAULT_BOUNCE_RAYS,
            0,
            &radii,
            &[],
            &RING_HOTSPOT,
            &|_| 1.0,
            2,
        );
        let mut moved = 0;
        for (leaf, stored) in ring.leaves.iter().enumerate() {
            for k in 0..RING_NODES {
                assert_eq!(
                    stored[k],
                    quantize_ratio(through[leaf][k][0]),
                    "leaf {leaf}"
                );
                assert_eq!(
                    stored[RING_NODES + k],
                    quantize_ratio(through[leaf][k][1]),
                    "leaf {leaf}"
                );
            }
            moved += (stored[0] != shadowed.leaves[leaf][0]) as usize;
        }
        assert!(moved * 2 > leaves.len(), "the planes moved {moved}");
        assert_eq!(SUN_BASIS[8], Vec3::X);
        let bounces = basis_bounces(&material, envelope.tau);
        let mut differ = 0;
        for (leaf, stored) in shadowed.leaves.iter().enumerate() {
            let baked = bounce_gather(
                &scene,
                &material,
                leaf,
                &envelope.leaves[leaf],
                envelope.tau,
                &bounces,
                DEFAULT_BOUNCE_RAYS,
                &|_| 1.0,
                leaf_seed(&scene, leaf as u32),
            )
            .ratios();
            assert_eq!(stored[0], quantize_ratio(baked.front[8]), "leaf {leaf}");
            assert_eq!(
                stored[RING_NODES],
                quantize_ratio(baked.back[8]),
                "leaf {leaf}"
            );
            // Other nodes are other suns.
            differ += (stored[3] != stored[0]) as usize;
        }
        assert!(differ * 2 > leaves.len(), "{differ}");
        // A leaf the scene lacks, or without an envelope: eq. 5.24 unchanged.
        let outside = gather_ring(
            &scene,
            &material,
            &[9999, 0],
            &envelope.leaves[..1],
            envelope.tau,
            0.0,
            8,
            0,
            &radii,
            &[[1.0; 8]; 2],
            &RING_HOTSPOT,
            &|_| 1.0,
            1,
        );
        for stored in &outside.leaves {
            assert!(stored.iter().all(|&q| q == quantize_ratio(1.0)));
        }
        assert!(outside.sunlit.is_empty(), "no points: no shares traced");
        assert!(outside.sunlit_slopes.is_empty());
        assert_eq!(
            outside.sunlit_hotspot, [0; HOTSPOT_NODES],
            "no shares: no hotspot"
        );
    }

    /// The ring's own hotspot on its shares, fitted with it: in a ball of leaves the part of
    /// a leaf the eye sees with the sun behind it is sunlit more often than the share drawn
    /// there says (the eye's and the sun's paths leave through the same gaps), so the first
    /// node's exponent brightens the shares (below 1); with the sun facing the eye it is near
    /// 1 or above. The exponents read back are what the leaves are drawn with.
    #[test]
    fn a_sun_that_is_no_direction_gets_ratio_one_and_leaves_the_others_planes_in_place() {
        let Ball {
            scene,
            all,
            envelope,
            material,
            ..
        } = ball(120, 3);
        let suns = [Vec3::new(0.3, 0.4, -1.0), Vec3::new(-0.5, 0.8, 0.2)];
        let planes = sunlit_planes(&scene, &all, &suns, 9, &|_| 1.0, 2);
        let ratios = |suns: &[Vec3], planes: &[Vec<SharePlane>]| {
            ring_ratios(
                &scene,
                &material,
                &all,
                &envelope.leaves,
                envelope.tau,
                suns,
                24,
                0,
                Some(planes),
                &|_| 1.0,
                2,
            )
        };
        let valid = ratios(&suns, &planes);
        // A NaN sun between the two, its planes a dark stand-in: numbered as given, each valid
        // sun still reads its own planes, and the NaN sun's ratios are 1 as `sun_ratios_of`'s.
        let with_nan = [suns[0], Vec3::NAN, suns[1]];
        let dark = SharePlane::default();
        let planes_nan: Vec<Vec<SharePlane>> =
            planes.iter().map(|p| vec![p[0], dark, p[1]]).collect();
        let nan = ratios(&with_nan, &planes_nan);
        for (leaf, (a, b)) in valid.iter().zip(&nan).enumerate() {
            assert_eq!(b.len(), 3);
            assert_eq!(a[0], b[0], "leaf {leaf}");
            assert_eq!(b[1], [1.0; 2], "leaf {leaf}");
            assert_eq!(a[1], b[2], "leaf {leaf}");
        }
        // The second sun's planes matter: reading the first's in their place moves its ratios.
        let swapped: Vec<Vec<SharePlane>> = planes.iter().map(|p| vec![p[0], p[0]]).collect();
        let moved = ratios(&suns, &swapped)
            .iter()
            .zip(&valid)
            .filter(|(a, b)| a[1] != b[1])
            .count();
        assert!(moved * 2 > all.len(), "{moved}");
    }

    #[test]
    fn the_rings_own_hotspot_brightens_its_shares_behind_the_eye() {
        let Ball {
            leaves,
            scene,
            all,
            envelope,
            material,
            radii,
        } = ball(400, 5);
        let ring = gather_ring(
            &scene,
            &material,
            &all,
            &envelope.leaves,
            envelope.tau,
            0.4,
            8,
            16,
            &radii,
            &vec![[1.0; 8]; leaves.len()],
            &RING_HOTSPOT,
            &|_| 1.0,
            2,
        );
        let spot = ring
            .sun_hotspot()
            .expect("a hotspot fitted with the shares");
        assert!(spot[0] < 0.5, "{spot:?}");
        assert!((0.9..1.25).contains(&spot[HOTSPOT_NODES - 1]), "{spot:?}");
        assert_eq!(ring.sunlit_hotspot.map(Hotspot::dequantize), spot);
        // The exponent at a phase angle: the ring's, not the bake's.
        let to_sun = Vec3::new(0.0, 0.4, (1.0f32 - 0.16).sqrt());
        assert!((ring.sun_exponent(3.0, to_sun, to_sun) - spot[0]).abs() < 1e-6);
        assert!((ring.sun_exponent(3.0, -to_sun, to_sun) - spot[HOTSPOT_NODES - 1]).abs() < 1e-6);
    }

    /// A ring refined by further passes is the mean of its passes (each pass's rays shifted
    /// anew: a ring refined to one pass is the gather itself, its shares and hotspot are the
    /// first pass's), and nearer a long gather than its first pass: eight passes of 16 rays a
    /// leaf against one gather of 1,024, on a ball of leaves, the mean distance of the ratios
    /// under 0.6 of the first pass's (1/√8 ≈ 0.35 for independent passes; the same rays in
    /// every pass: 1, and the test fails).
    #[test]
    fn a_refined_ring_is_nearer_a_long_gather_than_its_first_pass() {
        let Ball {
            scene,
            all,
            envelope,
            material,
            radii,
            ..
        } = ball(300, 11);
        let height = 0.3;
        let ring = |rays: u32, passes: u32| {
            gather_ring_refined(
                &scene,
                &material,
                &all,
                &envelope.leaves,
                envelope.tau,
                height,
                rays,
                passes,
                9,
                &radii,
                &[],
                &RING_HOTSPOT,
                &|_| 1.0,
                2,
            )
        };
        let first = ring(16, 1);
        let plain = gather_ring(
            &scene,
            &material,
            &all,
            &envelope.leaves,
            envelope.tau,
            height,
            16,
            9,
            &radii,
            &[],
            &RING_HOTSPOT,
            &|_| 1.0,
            2,
        );
        assert_eq!(first, plain);
        let refined = ring(16, 8);
        assert_eq!(refined.sunlit, first.sunlit);
        assert_eq!(refined.sunlit_slopes, first.sunlit_slopes);
        assert_eq!(refined.sun_height, first.sun_height);
        let long = ring(1024, 1);
        let distance = |a: &BounceRing| {
            let (mut sum, mut n) = (0.0f32, 0usize);
            for (x, y) in a.leaves.iter().zip(&long.leaves) {
                for (&p, &q) in x.iter().zip(y) {
                    sum += (ratio_of(p) - ratio_of(q)).abs();
                    n += 1;
                }
            }
            sum / n as f32
        };
        let (d_first, d_refined) = (distance(&first), distance(&refined));
        println!(
            "mean distance to 1,024 rays: first pass {d_first:.4}, eight passes {d_refined:.4}"
        );
        assert!(
            d_refined < 0.6 * d_first,
            "eight passes {d_refined} against the first's {d_first}"
        );
    }

    /// The refinement's mean is each leaf, node and face's mean over its passes, stored as a
    /// ring stores ratios; a pass of another shape (another ring's) is not added.
    #[test]
    fn a_refinement_is_the_mean_of_its_passes() {
        let a = vec![vec![[1.0, 2.0]; RING_NODES], vec![[0.5, 0.25]; RING_NODES]];
        let b = vec![vec![[3.0, 0.0]; RING_NODES], vec![[1.5, 0.75]; RING_NODES]];
        let mut refinement = RingRefinement::new(a);
        assert_eq!(refinement.passes(), 1);
        assert!(refinement.add(&b));
        assert_eq!(refinement.passes(), 2);
        let mean = refinement.mean();
        assert_eq!(mean[0][3], [2.0, 1.0]);
        assert_eq!(mean[1][13], [1.0, 0.5]);
        let stored = refinement.quantized();
        assert_eq!(stored[0][3], quantize_ratio(2.0));
        assert_eq!(stored[0][RING_NODES + 3], quantize_ratio(1.0));
        assert_eq!(stored[1][RING_NODES], quantize_ratio(0.5));
        assert!(!refinement.add(&[vec![[1.0, 1.0]; RING_NODES]]));
        assert!(!refinement.add(&[vec![[1.0, 1.0]; 3], vec![[1.0, 1.0]; RING_NODES]]));
        assert_eq!(refinement.passes(), 2);
    }
}
