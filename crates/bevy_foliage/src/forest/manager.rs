//! The forest LoD manager of Gumbau 2011, §3.6 (spec F2), with the LoD cache of chapter 4 (F3):
//! plain Rust over arrays of trees, so it reads like the paper, tests fast and benchmarks alone.
//!
//! Every frame, for every tree: distance, frustum visibility (bounding sphere), desired LoD
//! (eq. 4.2–4.3), LoD error against the stored LoD (eq. 3.11) and urgency (eq. 3.12). Visible
//! trees with work to do are ranked by urgency — a partial selection of the top chunk
//! (`select_nth_unstable`, O(V)), not a full sort — and served in that order with Algorithm 3 until
//! the budget is spent: borrow a cached extraction of the slot, or extract the slot anew. Only
//! extractions spend a count budget (borrowing is the cheap path the cache exists for); a time
//! budget is checked against the manager's own elapsed time after each chunk.
//!
//! With borrowing off (`borrowing: false`) every tree owns its extraction: the chapter-3 manager.

use super::cache::{CacheAction, LodCache, LodSlots, SLOT_LOD_ZERO};
use super::lod::{desired_lod, lod_error, urgency};
use crate::distance::{LodDistances, LodView};
use bevy::math::{Vec3, Vec4};
use std::time::{Duration, Instant};

/// A tree as the manager sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeInput {
    /// Tree type (index into the manager's caches).
    pub ty: usize,
    /// Centre of its bounding sphere.
    pub center: Vec3,
    /// Radius of its bounding sphere.
    pub radius: f32,
}

/// What the manager remembers of a tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeLodState {
    /// The cache slot it draws (None: nothing assigned yet).
    pub slot: Option<usize>,
    /// Which GPU copy of the slot (double-buffered caches have two).
    pub copy: usize,
    /// The LoD of the extraction it draws.
    pub stored_lod: f32,
    /// Its desired LoD this frame.
    pub desired_lod: f32,
    /// Frames since it was last served.
    pub frames_since_update: u32,
    /// Its urgency this frame (0: nothing to do or not visible).
    pub urgency: f32,
    /// Inside the view frustum this frame.
    pub visible: bool,
    /// LoD distance from the camera this frame (world distance to the crown's centre, or
    /// inverse screen size).
    pub distance: f32,
    /// With the mixed LoD: how far the tree has faded over to its billboard cloud (0 pruned
    /// geometry, 1 impostor).
    pub impostor_weight: f32,
    /// With the mixed LoD: the geometry resolution it was last given (kept while it fades to its
    /// impostor, so its leaves thin out from there).
    pub geometry_lod: f32,
}

impl Default for TreeLodState {
    fn default() -> Self {
        Self {
            slot: None,
            copy: 0,
            stored_lod: 0.0,
            desired_lod: 0.0,
            frames_since_update: 0,
            urgency: 0.0,
            visible: false,
            distance: f32::INFINITY,
            impostor_weight: 0.0,
            geometry_lod: 1.0,
        }
    }
}

/// How much work one frame may do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    /// At most this many extractions per frame (deterministic: tests and benchmarks).
    Extractions(u32),
    /// Stop serving trees once the manager has run this long this frame.
    Time(Duration),
}

/// The camera's view volume as six inward planes `(n, d)` with `n·p + d ≥ 0` inside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    /// The planes.
    pub planes: [Vec4; 6],
}

impl Frustum {
    /// The frustum of a `clip_from_world` matrix (Gribb & Hartmann), for a 0..1 depth range
    /// with reversed or forward Z alike (near and far planes both taken from `w ± z`-style rows
    /// would not fit reversed-Z infinite projections, so the far plane is dropped: distance
    /// limits come from the LoD's `far`).
    pub fn from_clip_from_world(m: bevy::math::Mat4) -> Self {
        let row = |i: usize| Vec4::new(m.x_axis[i], m.y_axis[i], m.z_axis[i], m.w_axis[i]);
        let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
        let normalize = |p: Vec4| p / p.truncate().length().max(1e-20);
        // Left, right, bottom, top, and the z ≥ 0 plane (the near plane for forward-Z, the far
        // one for reversed-Z; harmless either way) twice in place of the dropped one.
        let planes = [
            normalize(r3 + r0),
            normalize(r3 - r0),
            normalize(r3 + r1),
            normalize(r3 - r1),
            normalize(r2),
            normalize(r3 - r2),
        ];
        Self { planes }
    }

    /// Whether a sphere touches the frustum.
    pub fn intersects_sphere(&self, center: Vec3, radius: f32) -> bool {
        self.planes
            .iter()
            .all(|p| p.truncate().dot(center) + p.w >= -radius)
    }
}

/// Settings of the manager.
#[derive(Clone, Debug, PartialEq)]
pub struct ManagerSettings {
    /// `near` (LoD 1) and `far` (LoD 0) of eq. 4.2, in world distance or screen size.
    pub distances: LodDistances,
    /// The camera's projection, for screen-size distances.
    pub view: LodView,
    /// LoD distances (world units, or inverse screen sizes: see [`LodDistances::lod_distance`])
    /// are floored at this in the urgency (eq. 3.12).
    pub min_distance: f32,
    /// Share extractions between trees of a type through the LoD cache.
    pub borrowing: bool,
}

impl Default for ManagerSettings {
    fn default() -> Self {
        Self {
            distances: LodDistances::World {
                near: 10.0,
                far: 250.0,
            },
            view: LodView::default(),
            min_distance: 1.0,
            borrowing: true,
        }
    }
}

/// An extraction the renderer must perform this frame: slot `slot` (copy `copy`) of type `ty`,
/// at LoD `lod`, seen from tree `tree`'s viewpoint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extraction {
    /// The tree whose view and desired LoD it is extracted for.
    pub tree: usize,
    /// Its type.
    pub ty: usize,
    /// Cache slot.
    pub slot: usize,
    /// GPU copy of the slot.
    pub copy: usize,
    /// LoD to extract.
    pub lod: f32,
}

/// What one frame did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameReport {
    /// Trees in the view frustum.
    pub visible: u32,
    /// Visible trees whose LoD left their slot (urgency > 0).
    pub candidates: u32,
    /// Trees served (borrowed or extracted).
    pub served: u32,
    /// Extractions made.
    pub extractions: u32,
    /// Borrows made.
    pub borrows: u32,
    /// Candidates left for later frames.
    pub deferred: u32,
    /// Largest `frames_since_update` among the deferred candidates.
    pub oldest_deferred: u32,
    /// Time the frame took.
    pub elapsed: Duration,
}

/// The forest LoD manager: one LoD cache per tree type, and per-frame scratch space.
#[derive(Clone, Debug)]
pub struct ForestManager {
    /// One cache per tree type.
    pub caches: Vec<LodCache>,
    /// Frames run.
    pub frame: u64,
    /// Desired LoDs chosen elsewhere this frame (the mixed LoD selection), one per tree; when
    /// its length matches the trees', it replaces the distance LoD of eq. 4.2–4.3.
    pub desired_override: Vec<f32>,
    candidates: Vec<(f32, u32)>,
}

impl ForestManager {
    /// A manager for `types` tree types, each cache with `slots`.
    pub fn new(types: usize, slots: LodSlots, max_age: u64, double_buffered: bool) -> Self {
        Self {
            caches: (0..types)
                .map(|_| LodCache::new(slots.clone(), max_age, double_buffered))
                .collect(),
            frame: 0,
            desired_override: Vec::new(),
            candidates: Vec::new(),
        }
    }

    /// Runs one frame: updates `states` (one per tree), and appends the extractions to make to
    /// `extractions`. `trees` and `states` have the same length; trees of unknown type are left
    /// alone.
    #[allow(clippy::too_many_arguments)]
    pub fn run_frame(
        &mut self,
        trees: &[TreeInput],
        states: &mut [TreeLodState],
        camera: Vec3,
        frustum: Option<&Frustum>,
        exponent: f32,
        settings: &ManagerSettings,
        budget: Budget,
        extractions: &mut Vec<Extraction>,
    ) -> FrameReport {
        let start = Instant::now();
        self.frame += 1;
        let frame = self.frame;
        let mut report = FrameReport::default();
        self.candidates.clear();
        let (near, far) = settings.distances.range();
        for (i, (tree, state)) in trees.iter().zip(states.iter_mut()).enumerate() {
            let Some(cache) = self.caches.get(tree.ty) else {
                continue;
            };
            state.frames_since_update = state.frames_since_update.saturating_add(1);
            let distance = settings.distances.lod_distance(
                tree.center.distance(camera),
                tree.radius,
                &settings.view,
            );
            state.distance = distance;
            state.visible = distance.is_finite()
                && frustum.is_none_or(|f| f.intersects_sphere(tree.center, tree.radius));
            state.desired_lod = if self.desired_override.len() == trees.len() {
                self.desired_override[i].clamp(0.0, 1.0)
            } else {
                desired_lod(distance, near, far, exponent)
            };
            state.urgency = 0.0;
            if !state.visible {
                continue;
            }
            report.visible += 1;
            let slot = cache.slots.slot_of(state.desired_lod);
            if state.slot == Some(slot) {
                continue;
            }
            // A tree whose LoD left its slot has at least half a slot of error, so a tree
            // that just crossed a bound is not starved by a tiny error.
            let floor = 0.5
                * cache
                    .slots
                    .width(slot)
                    .max(1.0 / cache.slots.range_count() as f32);
            let error = lod_error(state.desired_lod, state.stored_lod).max(floor);
            state.urgency = urgency(
                error,
                state.frames_since_update,
                distance,
                settings.min_distance,
            );
            self.candidates.push((state.urgency, i as u32));
        }
        report.candidates = self.candidates.len() as u32;

        // Serve in urgency order, a chunk at a time: partial selection of the chunk's top, then
        // a sort of that chunk only.
        let mut remaining = &mut self.candidates[..];
        let mut extractions_left = match budget {
            Budget::Extractions(n) => n,
            Budget::Time(_) => u32::MAX,
        };
        let chunk = match budget {
            Budget::Extractions(n) => (2 * n as usize).max(64),
            Budget::Time(_) => 256,
        };
        let by_urgency = |a: &(f32, u32), b: &(f32, u32)| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1));
        'serve: while !remaining.is_empty() && extractions_left > 0 {
            let k = chunk.min(remaining.len());
            if k < remaining.len() {
                remaining.select_nth_unstable_by(k - 1, by_urgency);
            }
            let (top, rest) = remaining.split_at_mut(k);
            top.sort_unstable_by(by_urgency);
            for (served, &(_, i)) in top.iter().enumerate() {
                let i = i as usize;
                let tree = trees[i];
                let state = &mut states[i];
                let cache = &mut self.caches[tree.ty];
                let action = if settings.borrowing || state.desired_lod <= 0.0 {
                    cache.decide(state.slot, state.desired_lod, frame)
                } else {
                    // Chapter 3: every tree extracts its own LoD.
                    CacheAction::Extract {
                        slot: cache.slots.slot_of(state.desired_lod),
                    }
                };
                match action {
                    CacheAction::Keep | CacheAction::Wait => continue,
                    CacheAction::Borrow { slot, entry } => {
                        state.slot = Some(slot);
                        state.copy = entry.copy;
                        state.stored_lod = entry.lod;
                        report.borrows += 1;
                    }
                    CacheAction::Extract { slot } => {
                        let copy = if settings.borrowing {
                            cache.store(slot, state.desired_lod, i, frame).copy
                        } else {
                            0
                        };
                        extractions.push(Extraction {
                            tree: i,
                            ty: tree.ty,
                            slot,
                            copy,
                            lod: state.desired_lod,
                        });
                        state.slot = Some(slot);
                        state.copy = copy;
                        state.stored_lod = state.desired_lod;
                        report.extractions += 1;
                        extractions_left -= 1;
                    }
                }
                state.frames_since_update = 0;
                state.urgency = 0.0;
                report.served += 1;
                if extractions_left == 0 {
                    // What is left of this chunk waits for the next frames.
                    let left = &top[served + 1..];
                    report.deferred += left.len() as u32;
                    for &(_, j) in left {
                        report.oldest_deferred = report
                            .oldest_deferred
                            .max(states[j as usize].frames_since_update);
                    }
                    remaining = rest;
                    break 'serve;
                }
            }
            remaining = rest;
            if let Budget::Time(limit) = budget
                && start.elapsed() >= limit
            {
                break;
            }
        }
        report.deferred += remaining.len() as u32;
        for &(_, j) in remaining.iter() {
            report.oldest_deferred = report
                .oldest_deferred
                .max(states[j as usize].frames_since_update);
        }
        report.elapsed = start.elapsed();
        report
    }

    /// Whether tree state `state` of type `ty` draws nothing (LoD 0 or unassigned).
    pub fn draws_nothing(state: &TreeLodState) -> bool {
        state.slot.is_none_or(|s| s == SLOT_LOD_ZERO)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::forest::cache::FIRST_RANGE_SLOT;
    use crate::rng::SplitMix64;

    fn forest(n: usize, types: usize, seed: u64) -> Vec<TreeInput> {
        let mut rng = SplitMix64::new(seed);
        (0..n)
            .map(|_| TreeInput {
                ty: rng.below(types as u32) as usize,
                center: Vec3::new(rng.range(-200.0, 200.0), 4.0, rng.range(-200.0, 200.0)),
                radius: 4.0,
            })
            .collect()
    }

    fn settings(borrowing: bool) -> ManagerSettings {
        ManagerSettings {
            distances: LodDistances::World {
                near: 10.0,
                far: 150.0,
            },
            view: LodView::default(),
            min_distance: 1.0,
            borrowing,
        }
    }

    #[test]
    fn the_most_urgent_trees_are_served_first() {
        let trees = forest(3000, 4, 1);
        let mut states = vec![TreeLodState::default(); trees.len()];
        let mut m = ForestManager::new(4, LodSlots::uniform(16), 30, false);
        let mut rng = SplitMix64::new(9);
        let mut out = Vec::new();
        for frame in 0..40 {
            let camera = Vec3::new(rng.range(-100.0, 100.0), 2.0, rng.range(-100.0, 100.0));
            let before: Vec<TreeLodState> = {
                // Urgencies as the manager will rank them this frame.
                let mut probe = m.clone();
                let mut s = states.clone();
                probe.run_frame(
                    &trees,
                    &mut s,
                    camera,
                    None,
                    1.0,
                    &settings(false),
                    Budget::Extractions(0),
                    &mut Vec::new(),
                );
                s
            };
            out.clear();
            let report = m.run_frame(
                &trees,
                &mut states,
                camera,
                None,
                1.0,
                &settings(false),
                Budget::Extractions(50),
                &mut out,
            );
            assert!(report.extractions <= 50);
            if report.candidates > 50 {
                assert_eq!(report.extractions, 50, "frame {frame}");
            }
            // Served this frame: extracted, or borrowed the LoD 0 slot.
            let served: Vec<usize> = (0..trees.len())
                .filter(|&i| before[i].urgency > 0.0 && states[i].frames_since_update == 0)
                .collect();
            assert!(out.iter().all(|e| served.contains(&e.tree)));
            let min_served = served
                .iter()
                .map(|&i| before[i].urgency)
                .fold(f32::INFINITY, f32::min);
            let max_unserved = before
                .iter()
                .enumerate()
                .filter(|(i, s)| s.urgency > 0.0 && !served.contains(i))
                .map(|(_, s)| s.urgency)
                .fold(0.0f32, f32::max);
            assert!(
                min_served >= max_unserved,
                "frame {frame}: served urgency {min_served} < waiting {max_unserved}"
            );
        }
    }

    #[test]
    fn no_visible_tree_waits_longer_than_the_budget_allows() {
        // After each camera jump, while the camera holds still, the V trees whose LoD left their
        // slot are served B per frame, most urgent first, and served trees have nothing left to
        // do: every one is served within ⌈V / B⌉ frames.
        let trees = forest(4000, 4, 2);
        let mut states = vec![TreeLodState::default(); trees.len()];
        let mut m = ForestManager::new(4, LodSlots::uniform(16), 1000, false);
        let frustum = Frustum::from_clip_from_world(
            bevy::math::Mat4::perspective_infinite_reverse_rh(1.0, 1.5, 0.1)
                * bevy::math::Mat4::look_at_rh(
                    Vec3::new(0.0, 2.0, 0.0),
                    Vec3::new(1.0, 2.0, 0.3),
                    Vec3::Y,
                ),
        );
        let budget = 40;
        let mut out = Vec::new();
        let mut rng = SplitMix64::new(4);
        for jump in 0..6 {
            let camera = Vec3::new(rng.range(-50.0, 50.0), 2.0, rng.range(-50.0, 50.0));
            let frustum = Frustum {
                planes: frustum.planes.map(|p| {
                    let n = p.truncate();
                    Vec4::new(
                        n.x,
                        n.y,
                        n.z,
                        p.w - n.dot(camera - Vec3::new(0.0, 2.0, 0.0)),
                    )
                }),
            };
            let first = m.run_frame(
                &trees,
                &mut states,
                camera,
                Some(&frustum),
                1.0,
                &settings(false),
                Budget::Extractions(budget),
                &mut out,
            );
            let needing = first.candidates;
            assert!(
                first.visible > 100 && needing > budget,
                "jump {jump}: {first:?}"
            );
            let bound = needing.div_ceil(budget);
            let mut frames = 1;
            let mut report = first;
            while report.deferred > 0 {
                report = m.run_frame(
                    &trees,
                    &mut states,
                    camera,
                    Some(&frustum),
                    1.0,
                    &settings(false),
                    Budget::Extractions(budget),
                    &mut out,
                );
                frames += 1;
            }
            assert!(
                frames <= bound,
                "jump {jump}: {frames} frames for {needing} trees at {budget} per frame"
            );
            // Everything visible now draws its desired slot.
            for (t, s) in trees.iter().zip(&states) {
                if s.visible {
                    assert_eq!(s.slot, Some(m.caches[t.ty].slots.slot_of(s.desired_lod)));
                }
            }
        }
    }

    #[test]
    fn borrowing_never_hands_a_tree_a_lod_outside_its_slot() {
        let trees = forest(5000, 3, 3);
        for double_buffered in [false, true] {
            // Each manager starts from fresh trees (states name the slots of their manager).
            let mut states = vec![TreeLodState::default(); trees.len()];
            let mut m = ForestManager::new(
                3,
                LodSlots::from_bounds(vec![0.0, 0.2, 0.4, 0.55, 0.7, 0.8, 0.9, 0.95, 1.0]).unwrap(),
                20,
                double_buffered,
            );
            let mut rng = SplitMix64::new(11);
            let (mut borrows, mut extractions) = (0, 0);
            let mut out = Vec::new();
            for _ in 0..60 {
                let camera = Vec3::new(rng.range(-150.0, 150.0), 2.0, rng.range(-150.0, 150.0));
                out.clear();
                let r = m.run_frame(
                    &trees,
                    &mut states,
                    camera,
                    None,
                    1.3,
                    &settings(true),
                    Budget::Extractions(30),
                    &mut out,
                );
                borrows += r.borrows;
                extractions += r.extractions;
                for (t, s) in trees.iter().zip(&states) {
                    let Some(slot) = s.slot else { continue };
                    let slots = &m.caches[t.ty].slots;
                    // What the tree draws is an extraction of its slot, at a LoD in that slot.
                    assert!(slots.contains(slot, s.stored_lod), "{s:?}");
                    let entry = m.caches[t.ty].entry(slot, s.copy).unwrap();
                    assert!(slots.contains(slot, entry.lod), "{entry:?} for {s:?}");
                }
                // Extractions are only ever made for slots that had none fresh enough.
                assert!(out.iter().all(|e| e.slot >= FIRST_RANGE_SLOT - 1));
            }
            assert!(
                borrows > 10 * extractions,
                "borrows {borrows}, extractions {extractions}"
            );
        }
    }

    #[test]
    fn a_time_budget_serves_the_most_urgent_chunk_first_and_stops() {
        let trees = forest(3000, 2, 5);
        let mut states = vec![TreeLodState::default(); trees.len()];
        let mut m = ForestManager::new(2, LodSlots::uniform(16), 30, false);
        let mut out = Vec::new();
        // A zero budget still serves one chunk (progress every frame), not everything.
        let r = m.run_frame(
            &trees,
            &mut states,
            Vec3::ZERO,
            None,
            1.0,
            &settings(false),
            Budget::Time(Duration::ZERO),
            &mut out,
        );
        assert!(r.candidates > 256, "{r:?}");
        assert_eq!(r.served, 256);
        assert_eq!(r.deferred, r.candidates - 256);
        // A generous budget serves everything.
        let r = m.run_frame(
            &trees,
            &mut states,
            Vec3::ZERO,
            None,
            1.0,
            &settings(false),
            Budget::Time(Duration::from_secs(10)),
            &mut out,
        );
        assert_eq!(r.deferred, 0, "{r:?}");
    }

    #[test]
    fn frustum_rejects_trees_behind_the_camera() {
        let m = bevy::math::Mat4::perspective_infinite_reverse_rh(1.0, 1.0, 0.1)
            * bevy::math::Mat4::look_at_rh(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y);
        let f = Frustum::from_clip_from_world(m);
        assert!(f.intersects_sphere(Vec3::new(0.0, 0.0, -50.0), 1.0));
        assert!(!f.intersects_sphere(Vec3::new(0.0, 0.0, 50.0), 1.0));
        assert!(!f.intersects_sphere(Vec3::new(100.0, 0.0, -10.0), 1.0));
        // A sphere straddling the side plane counts.
        assert!(f.intersects_sphere(Vec3::new(5.5, 0.0, -10.0), 1.0));
    }
}
