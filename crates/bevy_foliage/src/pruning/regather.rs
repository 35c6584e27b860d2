//! Re-gathering each tree type's bounce ratios and its leaves' sunlit shares on a ring of suns
//! at the sun's elevation while the app runs ([`crate::lighting::bounce_ring`],
//! [`crate::lighting::sunlit_share`]): when the sun's elevation has moved
//! [`BounceRingSettings::regather_degrees`] from a type's ring, a background task gathers the
//! next one from the type's loaded bake (its leaves as a scene, its envelopes and seen-part
//! gains read back, the opacity it was traced with), the crown's hotspot on the sunlit shares
//! fitted with it ([`crate::lighting::bounce_ring::ring_sun_hotspot`]); when it lands, the
//! leaves' light buffer is rewritten with it. While the sun stays at its elevation, further
//! passes of the ring's ratios are gathered and averaged in
//! ([`crate::lighting::bounce_ring::RingRefinement`]) up to [`BounceRingSettings::passes`],
//! one task at a time, each doubling the ring's passes, the buffer rewritten as each lands;
//! with its last in, the ring lets go of its passes' sums and the sunlit planes they read.
//!
//! The sun's elevation is taken in the world's frame, which is each instance's own for trees
//! turned about their vertical only; the leaf shaders compare the ring's elevation with the
//! sun's in each instance's frame, so a tilted instance falls back to the bake's blend.
//!
//! [`BounceRingSettings::regather_degrees`]: crate::lighting::settings::BounceRingSettings::regather_degrees
//! [`BounceRingSettings::passes`]: crate::lighting::settings::BounceRingSettings::passes

use super::bake::BakedFoliage;
use super::store::FoliageStore;
use super::systems::tree_lights;
use crate::lighting::bounce_ring::{
    BounceRing, GatheredRing, RING_HOTSPOT, RING_NODES, RingRefinement, crown_mean_ring,
    gather_ring_with, needs_regather, ring_pass,
};
use crate::lighting::envelope::LeafEnvelope;
use crate::lighting::leaf_scene::LeafScene;
use crate::lighting::settings::TreeLightingSettings;
use crate::lighting::sunlit_share::SharePlane;
use bevy::asset::AssetId;
use bevy::diagnostic::{DiagnosticPath, Diagnostics};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::storage::ShaderBuffer;
use bevy::tasks::{AsyncComputeTaskPool, Task, block_on, poll_once};
use std::sync::Arc;

/// Diagnostic: seconds the last ring re-gather took (its wall-clock time on its threads).
pub const BOUNCE_RING_SECONDS: DiagnosticPath =
    DiagnosticPath::const_new("foliage/bounce_ring_seconds");
/// Diagnostic: tree types whose ring is being re-gathered (or refined by a further pass).
pub const BOUNCE_RINGS_GATHERING: DiagnosticPath =
    DiagnosticPath::const_new("foliage/bounce_rings_gathering");
/// Diagnostic: the passes of its rays the least refined of the gathered rings is the mean of
/// ([`RingRefinement`]).
pub const BOUNCE_RING_PASSES: DiagnosticPath =
    DiagnosticPath::const_new("foliage/bounce_ring_passes");
/// Diagnostic: seconds one further pass of a ring's refinement took, in the last refinement
/// task that landed (its wall-clock time on its threads over the passes it added).
pub const BOUNCE_RING_PASS_SECONDS: DiagnosticPath =
    DiagnosticPath::const_new("foliage/bounce_ring_pass_seconds");
/// Diagnostic: bytes the rings being refined hold for their further passes, summed over the
/// tree types (0 once every ring has its passes: [`BounceRings::refinement_bytes`]).
pub const BOUNCE_RING_REFINEMENT_BYTES: DiagnosticPath =
    DiagnosticPath::const_new("foliage/bounce_ring_refinement_bytes");

/// What a tree type's re-gathers trace: its stored leaves as a scene, their envelopes and
/// seen-part gains read back, the crown's τ and the opacity the bake traced the leaves with. Built by the type's
/// first re-gather (in its task), kept for the next.
struct RingSource {
    scene: LeafScene,
    envelopes: Vec<LeafEnvelope>,
    /// Per stored leaf, its radius as the leaf shaders have it (the sunlit shares' slopes
    /// are per radius).
    radii: Vec<f32>,
    /// Per stored leaf, its seen-part gains read back (empty for a bake without them: no
    /// hotspot is fitted for the ring's shares).
    gains: Vec<[f32; 8]>,
    tau: f32,
    opacity: f32,
}

impl RingSource {
    fn of(tree: &BakedFoliage) -> Self {
        Self {
            scene: tree.leaf_scene(),
            envelopes: tree.leaf_envelopes(),
            radii: tree.leaf_radii(),
            gains: tree.leaf_seen_gains(),
            tau: tree.extinction,
            opacity: tree.leaf_opacity,
        }
    }
}

/// What a re-gather hands back: the ring, with its ratios before quantising and the sunlit
/// planes it read, the seconds it took and what it traced.
struct Gathered {
    ring: GatheredRing,
    seconds: f32,
    source: Arc<RingSource>,
}

/// A ring's refinement taken further by a task ([`refine`]), for the ring at sun height
/// `height`, with the seconds each of the passes it added took.
struct Pass {
    height: f32,
    refinement: RingRefinement,
    seconds_per_pass: Option<f32>,
}

/// What a task hands back.
enum Landed {
    Ring(Gathered),
    Pass(Pass),
}

/// A gathered ring's refinement so far, and what its further passes trace.
struct Refining {
    height: f32,
    /// Passes the ring is the mean of.
    passes: u32,
    /// What further passes add to and trace through: dropped once the ring has the passes the
    /// settings ask for (half a kilobyte a leaf with the sunlit planes; a ring asked for more
    /// passes later is gathered anew).
    further: Option<Further>,
    source: Arc<RingSource>,
}

/// The sums of a ring's passes so far, and the sunlit planes its further passes read.
struct Further {
    refinement: RingRefinement,
    planes: Option<Arc<Vec<Vec<SharePlane>>>>,
}

impl Further {
    /// Bytes held: the refinement's sums and the planes.
    fn heap_bytes(&self) -> usize {
        self.refinement.heap_bytes()
            + self.planes.as_deref().map_or(0, |planes| {
                planes
                    .iter()
                    .map(|p| size_of::<Vec<SharePlane>>() + size_of_val(p.as_slice()))
                    .sum()
            })
    }
}

/// Each tree type's ring of bounce ratios re-gathered at the sun's elevation, and the
/// re-gathers in flight (a resource). A ring put in with [`BounceRings::insert`] is used as if
/// gathered, until the sun moves from its elevation.
#[derive(Resource, Default)]
pub struct BounceRings {
    rings: HashMap<AssetId<BakedFoliage>, BounceRing>,
    /// Per ring, its crown's mean (for billboard clouds).
    means: HashMap<AssetId<BakedFoliage>, [[f32; 2]; RING_NODES]>,
    in_flight: HashMap<AssetId<BakedFoliage>, Task<Landed>>,
    /// Per gathered ring (not one put in), its passes so far.
    refining: HashMap<AssetId<BakedFoliage>, Refining>,
    /// Per tree type, what its re-gathers trace.
    sources: HashMap<AssetId<BakedFoliage>, Arc<RingSource>>,
    /// The leaf light buffer last written with the rings (a new one from the store means its
    /// types were uploaded again, without rings).
    written: Option<Handle<ShaderBuffer>>,
    changed: bool,
    generation: u64,
    completed: u64,
    last_seconds: Option<f32>,
    last_pass_seconds: Option<f32>,
}

impl BounceRings {
    /// Tree type `id`'s ring, once one has been gathered or put in.
    pub fn ring(&self, id: AssetId<BakedFoliage>) -> Option<&BounceRing> {
        self.rings.get(&id)
    }

    /// Puts in `ring` as type `id`'s (for the leaves of that type: a ring for another number
    /// of leaves is not drawn); it is drawn from the next frame, and not refined by further
    /// passes.
    pub fn insert(&mut self, id: AssetId<BakedFoliage>, ring: BounceRing) {
        self.refining.remove(&id);
        self.put(id, ring);
    }

    fn put(&mut self, id: AssetId<BakedFoliage>, ring: BounceRing) {
        self.means.insert(id, crown_mean_ring(&ring));
        self.rings.insert(id, ring);
        self.changed = true;
        self.generation += 1;
    }

    /// Takes in a finished task of type `id`: a ring, whose refinement starts with it, or a
    /// further pass of the ring being refined (one for a ring since replaced is dropped). Once
    /// the ring is the mean of `wanted` passes, what would refine it further is let go.
    fn land(&mut self, id: AssetId<BakedFoliage>, landed: Landed, wanted: u32) {
        match landed {
            Landed::Ring(gathered) => {
                let GatheredRing {
                    ring,
                    ratios,
                    planes,
                } = gathered.ring;
                self.last_seconds = Some(gathered.seconds);
                self.sources.insert(id, gathered.source.clone());
                let further = (wanted > 1).then(|| Further {
                    refinement: RingRefinement::new(ratios),
                    planes: planes.map(Arc::new),
                });
                self.refining.insert(
                    id,
                    Refining {
                        height: ring.sun_height,
                        passes: 1,
                        further,
                        source: gathered.source,
                    },
                );
                self.put(id, ring);
                self.completed += 1;
            }
            Landed::Pass(pass) => {
                let Some(refining) = self.refining.get_mut(&id) else {
                    return;
                };
                let Some(ring) = self.rings.get(&id) else {
                    return;
                };
                let Some(further) = refining.further.as_mut() else {
                    return;
                };
                if refining.height != pass.height
                    || ring.sun_height != pass.height
                    || pass.refinement.passes() <= refining.passes
                {
                    return;
                }
                refining.passes = pass.refinement.passes();
                if pass.seconds_per_pass.is_some() {
                    self.last_pass_seconds = pass.seconds_per_pass;
                }
                let ring = BounceRing {
                    leaves: pass.refinement.quantized(),
                    ..ring.clone()
                };
                further.refinement = pass.refinement;
                if refining.passes >= wanted {
                    refining.further = None;
                }
                self.put(id, ring);
            }
        }
    }

    /// The passes of its rays type `id`'s ring is the mean of so far; `None` for a ring put in
    /// ([`BounceRings::insert`]) or none.
    pub fn passes(&self, id: AssetId<BakedFoliage>) -> Option<u32> {
        self.refining.get(&id).map(|r| r.passes)
    }

    /// Bytes type `id`'s ring holds to be refined further (its passes' sums and the sunlit
    /// planes they trace through): none once it has the passes the settings ask for, or for a
    /// ring put in.
    pub fn refinement_bytes(&self, id: AssetId<BakedFoliage>) -> usize {
        self.refining
            .get(&id)
            .and_then(|r| r.further.as_ref())
            .map_or(0, Further::heap_bytes)
    }

    /// Bumped whenever a ring comes in.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Tree type `id`'s ring as its crown's mean, with its sun height: what the type's
    /// tree-lit billboard clouds read ([`crown_mean_ring`]).
    pub fn crown_mean(&self, id: AssetId<BakedFoliage>) -> Option<(f32, [[f32; 2]; RING_NODES])> {
        Some((self.rings.get(&id)?.sun_height, *self.means.get(&id)?))
    }

    /// Whether type `id`'s ring is being re-gathered, or refined by a further pass.
    pub fn is_gathering(&self, id: AssetId<BakedFoliage>) -> bool {
        self.in_flight.contains_key(&id)
    }

    /// Re-gathers completed since the app started.
    pub fn completed(&self) -> u64 {
        self.completed
    }

    /// Seconds the last completed re-gather took.
    pub fn last_seconds(&self) -> Option<f32> {
        self.last_seconds
    }

    /// Seconds one further pass took in the last refinement task that landed (the first pass,
    /// which also traces the sunlit planes, is [`BounceRings::last_seconds`]).
    pub fn last_pass_seconds(&self) -> Option<f32> {
        self.last_pass_seconds
    }
}

/// Where a re-gather takes its leaves from: what an earlier one traced, or the bake itself (a
/// copy, made once per type).
enum Leaves {
    Traced(Arc<RingSource>),
    Baked(Box<BakedFoliage>),
}

/// The re-gather of a tree type's ring at sun height `height`: [`gather_ring_with`] of its stored
/// leaves with the lighting's optics, `rays` rays a leaf, their sunlit shares from
/// `sunlit_points` points a leaf (0: none) and `threads` threads.
fn regather(
    leaves: Leaves,
    optics: &crate::lighting::model::LeafMaterial,
    height: f32,
    rays: u32,
    sunlit_points: u32,
    threads: usize,
) -> Gathered {
    let started = std::time::Instant::now();
    let source = match leaves {
        Leaves::Traced(source) => source,
        Leaves::Baked(tree) => Arc::new(RingSource::of(&tree)),
    };
    let all: Vec<u32> = (0..source.scene.leaf_count() as u32).collect();
    let opacity = source.opacity;
    let ring = gather_ring_with(
        &source.scene,
        optics,
        &all,
        &source.envelopes,
        source.tau,
        height,
        rays,
        sunlit_points,
        &source.radii,
        &source.gains,
        &RING_HOTSPOT,
        &|_| opacity,
        threads,
    );
    Gathered {
        ring,
        seconds: started.elapsed().as_secs_f32(),
        source,
    }
}

/// What a refinement task traces: the type's leaves, the ring's sunlit planes and its height.
type Traced = (Arc<RingSource>, Option<Arc<Vec<Vec<SharePlane>>>>, f32);

/// The ring's `refinement` taken on to `passes` passes ([`ring_pass`], each added in turn,
/// as [`crate::lighting::bounce_ring::gather_ring_refined`] adds them: the same ring).
fn refine(
    traced: Traced,
    mut refinement: RingRefinement,
    optics: &crate::lighting::model::LeafMaterial,
    rays: u32,
    passes: u32,
    threads: usize,
) -> Pass {
    let started = std::time::Instant::now();
    let (source, planes, height) = traced;
    let from = refinement.passes();
    let all: Vec<u32> = (0..source.scene.leaf_count() as u32).collect();
    let opacity = source.opacity;
    refinement.refine_to(passes, |pass| {
        ring_pass(
            &source.scene,
            optics,
            &all,
            &source.envelopes,
            source.tau,
            height,
            rays,
            pass,
            planes.as_deref().map(|p| p.as_slice()),
            &|_| opacity,
            threads,
        )
    });
    let added = refinement.passes().saturating_sub(from);
    Pass {
        height,
        seconds_per_pass: (added > 0).then(|| started.elapsed().as_secs_f32() / added as f32),
        refinement,
    }
}

/// Collects finished re-gathers, starts one for each uploaded tree type the sun's elevation
/// has left (while [`TreeLightingSettings::bounce_ring`] and the gathered bounce are on), or
/// else the next pass of its ring's refinement, and rewrites the leaves' light buffer when a
/// ring or a pass has come in or the store uploaded its types again.
#[allow(clippy::too_many_arguments)]
pub fn regather_bounce_rings(
    lighting: Res<TreeLightingSettings>,
    suns: Query<(&DirectionalLight, &GlobalTransform)>,
    baked: Res<Assets<BakedFoliage>>,
    mut store: ResMut<FoliageStore>,
    mut buffers: ResMut<Assets<ShaderBuffer>>,
    mut rings: ResMut<BounceRings>,
    mut diagnostics: Diagnostics,
    mut warned: Local<bool>,
) {
    let rings = &mut *rings;
    // Finished re-gathers (whatever the settings now: a ring gathered is kept).
    let done: Vec<(AssetId<BakedFoliage>, Landed)> = rings
        .in_flight
        .iter_mut()
        .filter_map(|(id, task)| block_on(poll_once(task)).map(|landed| (*id, landed)))
        .collect();
    let settings = &lighting.bounce_ring;
    for (id, landed) in done {
        rings.in_flight.remove(&id);
        rings.land(id, landed, settings.passes);
    }
    if let Some(seconds) = rings.last_seconds {
        diagnostics.add_measurement(&BOUNCE_RING_SECONDS, || seconds as f64);
    }
    if let Some(seconds) = rings.last_pass_seconds {
        diagnostics.add_measurement(&BOUNCE_RING_PASS_SECONDS, || seconds as f64);
    }
    if let Some(fewest) = rings.refining.values().map(|r| r.passes).min() {
        diagnostics.add_measurement(&BOUNCE_RING_PASSES, || fewest as f64);
        let held: usize = rings
            .refining
            .values()
            .filter_map(|r| r.further.as_ref())
            .map(Further::heap_bytes)
            .sum();
        diagnostics.add_measurement(&BOUNCE_RING_REFINEMENT_BYTES, || held as f64);
    }

    let active =
        lighting.enabled && lighting.bounce && lighting.gathered_bounce && settings.enabled;
    let lights = tree_lights(
        &lighting,
        None,
        suns.iter().map(|(l, t)| (l, t.back().as_vec3())),
    );
    let has_sun = lights.lights.sun.truncate() != Vec3::ZERO;
    if active && has_sun {
        let height = lights.lights.to_sun.y;
        let available = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1);
        let threads = settings.threads_of(available);
        let mut ids: Vec<AssetId<BakedFoliage>> = store.types.keys().copied().collect();
        ids.sort();
        for id in ids {
            if rings.in_flight.contains_key(&id) {
                continue;
            }
            let ring = rings.rings.get(&id);
            // A ring whose sunlit shares the settings no longer want (or now want) is gathered
            // again too.
            let shares_as_set =
                ring.is_none_or(|r| r.sunlit.is_empty() == (settings.sunlit_points == 0));
            // A ring that let go of its passes' sums when it had all the settings asked for,
            // and is now asked for more, is gathered anew.
            let refinable = rings
                .refining
                .get(&id)
                .is_none_or(|r| r.passes >= settings.passes || r.further.is_some());
            if !needs_regather(
                height,
                ring.map(|r| r.sun_height),
                settings.regather_degrees,
            ) && shares_as_set
                && refinable
            {
                // The ring holds: refine it, if it wants more passes. Each task doubles its
                // passes, by four at most (1, 2, 4, 8, 12, 16 by default): the ring nears its
                // last within a few landings, each of which rewrites the leaves' light buffer,
                // and a ring the sun has left waits for at most four passes before its
                // successor is gathered.
                let Some(refining) = rings.refining.get_mut(&id) else {
                    continue;
                };
                let done = refining.passes;
                if done >= settings.passes {
                    // It has the passes asked for (or more, the setting since lowered): what
                    // would refine it further is let go.
                    refining.further = None;
                    continue;
                }
                let Some(further) = refining.further.as_ref() else {
                    continue;
                };
                let passes = (done * 2).min(done + 4).min(settings.passes);
                let traced: Traced = (
                    refining.source.clone(),
                    further.planes.clone(),
                    refining.height,
                );
                let refinement = further.refinement.clone();
                let (optics, rays) = (lighting.optics, settings.rays);
                let task = move || {
                    Landed::Pass(refine(traced, refinement, &optics, rays, passes, threads))
                };
                match AsyncComputeTaskPool::try_get() {
                    Some(pool) => {
                        rings
                            .in_flight
                            .insert(id, pool.spawn(async move { task() }));
                    }
                    None => rings.land(id, task(), settings.passes),
                }
                continue;
            }
            let leaves = match rings.sources.get(&id) {
                Some(source) => Leaves::Traced(source.clone()),
                None => match baked.get(id) {
                    Some(tree) if tree.leaf_count() > 0 => Leaves::Baked(Box::new(tree.clone())),
                    _ => continue,
                },
            };
            let (optics, rays, points) = (lighting.optics, settings.rays, settings.sunlit_points);
            match AsyncComputeTaskPool::try_get() {
                Some(pool) => {
                    let task = pool.spawn(async move {
                        Landed::Ring(regather(leaves, &optics, height, rays, points, threads))
                    });
                    rings.in_flight.insert(id, task);
                }
                None => {
                    // An app without Bevy's task pools: gathered here, in this frame.
                    if !*warned {
                        warn!(
                            "bounce ring: no async compute task pool (TaskPoolPlugin); re-gathering in the frame"
                        );
                        *warned = true;
                    }
                    let gathered = regather(leaves, &optics, height, rays, points, threads);
                    rings.land(id, Landed::Ring(gathered), settings.passes);
                }
            }
        }
    }
    diagnostics.add_measurement(&BOUNCE_RINGS_GATHERING, || rings.in_flight.len() as f64);

    // The buffer holds the rings as they are: rewrite it when one came in, or when the store
    // uploaded its types again (without rings).
    let uploaded_again = rings.written.as_ref() != Some(&store.buffers.leaf_light);
    if rings.changed || (uploaded_again && !rings.rings.is_empty()) {
        if !store.types.is_empty() {
            let held = &rings.rings;
            store.rewrite_leaf_light(&mut buffers, &baked, |id| held.get(&id));
            rings.written = Some(store.buffers.leaf_light.clone());
        }
        rings.changed = false;
    }
}
