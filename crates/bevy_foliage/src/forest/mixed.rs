//! Time-critical mixed level-of-detail selection (seed 001, ch. 8, eq. 8.1–8.12 and 8.20): each
//! frame, every visible tree is drawn either by its billboard cloud (a discrete representation)
//! or by pruned geometry at a continuous resolution `x ∈ (0, 1]` (the pruning's distance factor),
//! so that the summed benefit is as large as the frame budget allows.
//!
//! - **Benefit** (eq. 8.20, one tree per group): `k·S·√x` for geometry at resolution `x`, where
//!   `S` is the tree's size on screen; the billboard cloud counts as geometry at a fixed
//!   equivalent resolution `x_I` (its benefit `k·S·√x_I`).
//! - **Cost**: a per-tree draw overhead plus the triangles drawn — `x·N` for pruned geometry of
//!   `N` leaf triangles, the cloud's quads times a fill weight for an impostor (large alpha-tested
//!   quads cost more per triangle than small leaves).
//! - **Selection**: start with every tree on its impostor (the cheapest feasible assignment) and
//!   repeatedly take the step with the best added benefit per added cost (eq. 8.8–8.9) — the
//!   discrete step of switching a tree from its impostor to geometry at the smallest resolution,
//!   or a continuous step doubling a tree's resolution — while it fits the budget. With the
//!   concave `√x` benefit, the continuous steps of a tree have falling slopes, so a greedy ascent
//!   over a max-heap of next steps is the thesis' gradient ascent in discrete steps.
//!
//! Trees without an impostor can only be geometry: they start at the smallest resolution.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// A visible tree as the selection sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MixedTree {
    /// Size on screen: the crown's projected diameter over the view height.
    pub screen_size: f32,
    /// Leaf triangles at full detail.
    pub leaf_triangles: u32,
    /// Triangles of its billboard cloud; `None`: it has none (geometry only).
    pub impostor_triangles: Option<u32>,
}

/// Settings of the selection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MixedSettings {
    /// Cost allowed per frame, in triangle units.
    pub budget: f32,
    /// The weighting constant `k` of eq. 8.20 (the thesis uses 50; it scales every benefit alike,
    /// so it does not change the choice, only the reported benefit).
    pub k: f32,
    /// The resolution of pruned geometry the billboard cloud is worth (`x_I`).
    pub impostor_equivalent_lod: f32,
    /// The smallest resolution of pruned geometry.
    pub min_lod: f32,
    /// Draw overhead of one tree, in triangles.
    pub tree_cost: f32,
    /// Cost of one impostor triangle in leaf triangles.
    pub impostor_fill_weight: f32,
}

impl Default for MixedSettings {
    fn default() -> Self {
        Self {
            budget: 500_000.0,
            k: 50.0,
            // A billboard cloud keeps the crown's coverage and colour but not its parallax or
            // its leaves' shading: taken as worth a quarter of the leaves.
            impostor_equivalent_lod: 0.25,
            min_lod: 0.125,
            tree_cost: 64.0,
            // Measured in the dense forest on the software rasteriser: an impostor of about 80
            // triangles costs as much as 300–600 leaf triangles (large alpha-tested quads).
            impostor_fill_weight: 4.0,
        }
    }
}

/// What a tree is drawn with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Representation {
    /// Its billboard cloud.
    Impostor,
    /// Pruned geometry at this resolution (distance factor) in (0, 1].
    Geometry(f32),
}

/// What one selection did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MixedReport {
    /// Summed cost of the assignment.
    pub cost: f32,
    /// Summed benefit.
    pub benefit: f32,
    /// Trees on geometry.
    pub geometry: u32,
    /// Trees on their impostor.
    pub impostors: u32,
    /// Steps taken.
    pub steps: u32,
}

impl MixedSettings {
    fn geometry_cost(&self, tree: &MixedTree, x: f32) -> f32 {
        self.tree_cost + x * tree.leaf_triangles as f32
    }

    fn impostor_cost(&self, triangles: u32) -> f32 {
        self.tree_cost + triangles as f32 * self.impostor_fill_weight
    }

    fn benefit(&self, tree: &MixedTree, representation: Representation) -> f32 {
        let x = match representation {
            Representation::Impostor => self.impostor_equivalent_lod,
            Representation::Geometry(x) => x,
        };
        self.k * tree.screen_size.max(0.0) * x.clamp(0.0, 1.0).sqrt()
    }

    /// The next step of a tree from `current`: the representation it leads to, with its added
    /// benefit and cost.
    fn next_step(&self, tree: &MixedTree, current: Representation) -> Option<Step> {
        let next = match current {
            Representation::Impostor => Representation::Geometry(self.first_lod()),
            Representation::Geometry(x) if x < 1.0 => Representation::Geometry((2.0 * x).min(1.0)),
            Representation::Geometry(_) => return None,
        };
        let cost = |r: Representation| match r {
            Representation::Impostor => self.impostor_cost(tree.impostor_triangles.unwrap_or(0)),
            Representation::Geometry(x) => self.geometry_cost(tree, x),
        };
        let added_benefit = self.benefit(tree, next) - self.benefit(tree, current);
        let added_cost = cost(next) - cost(current);
        if added_benefit <= 0.0 {
            return None;
        }
        // A step that costs nothing (or saves) is always worth taking first.
        let slope = if added_cost <= 0.0 {
            f32::INFINITY
        } else {
            added_benefit / added_cost
        };
        Some(Step {
            slope,
            next,
            added_cost,
        })
    }

    /// The smallest geometry resolution worth more than the impostor.
    fn first_lod(&self) -> f32 {
        self.min_lod
            .max(self.impostor_equivalent_lod * 1.5)
            .clamp(1e-4, 1.0)
    }

    /// These settings with unusable values replaced, and what was replaced.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let d = Self::default();
        let mut s = *self;
        let mut fixes = Vec::new();
        let mut check = |name: &str, v: &mut f32, ok: bool, default: f32| {
            if !ok {
                fixes.push(format!("{name} = {v} is unusable: using {default}"));
                *v = default;
            }
        };
        let b = s.budget;
        check("budget", &mut s.budget, b.is_finite() && b >= 0.0, d.budget);
        let k = s.k;
        check("k", &mut s.k, k.is_finite() && k > 0.0, d.k);
        let x = s.impostor_equivalent_lod;
        check(
            "impostor_equivalent_lod",
            &mut s.impostor_equivalent_lod,
            x.is_finite() && (0.0..1.0).contains(&x),
            d.impostor_equivalent_lod,
        );
        let m = s.min_lod;
        check(
            "min_lod",
            &mut s.min_lod,
            m.is_finite() && m > 0.0 && m <= 1.0,
            d.min_lod,
        );
        let t = s.tree_cost;
        check(
            "tree_cost",
            &mut s.tree_cost,
            t.is_finite() && t >= 0.0,
            d.tree_cost,
        );
        let w = s.impostor_fill_weight;
        check(
            "impostor_fill_weight",
            &mut s.impostor_fill_weight,
            w.is_finite() && w >= 0.0,
            d.impostor_fill_weight,
        );
        (s, fixes)
    }
}

#[derive(Clone, Copy, Debug)]
struct Step {
    slope: f32,
    next: Representation,
    added_cost: f32,
}

/// A heap entry: the best slope first, ties to the lower tree index (deterministic).
#[derive(Clone, Copy, Debug)]
struct Entry {
    slope: f32,
    tree: u32,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.slope
            .total_cmp(&other.slope)
            .then(other.tree.cmp(&self.tree))
    }
}

/// Chooses every tree's representation under `settings.budget`, into `out` (one per tree).
/// Trees with a non-finite or non-positive screen size get their impostor (or the smallest
/// geometry when they have none).
pub fn select(
    trees: &[MixedTree],
    settings: &MixedSettings,
    out: &mut Vec<Representation>,
) -> MixedReport {
    let (s, _) = settings.sanitized();
    out.clear();
    let mut report = MixedReport::default();
    let mut heap = BinaryHeap::with_capacity(trees.len());
    for (i, tree) in trees.iter().enumerate() {
        let start = if tree.impostor_triangles.is_some() {
            Representation::Impostor
        } else {
            Representation::Geometry(s.first_lod())
        };
        report.cost += match start {
            Representation::Impostor => s.impostor_cost(tree.impostor_triangles.unwrap_or(0)),
            Representation::Geometry(x) => s.geometry_cost(tree, x),
        };
        out.push(start);
        if tree.screen_size.is_finite()
            && tree.screen_size > 0.0
            && let Some(step) = s.next_step(tree, start)
        {
            heap.push(Entry {
                slope: step.slope,
                tree: i as u32,
            });
        }
    }
    while let Some(Entry { tree: i, .. }) = heap.pop() {
        let tree = &trees[i as usize];
        let Some(step) = s.next_step(tree, out[i as usize]) else {
            continue;
        };
        if report.cost + step.added_cost > s.budget {
            // This tree's next step does not fit; a cheaper step of another tree may.
            continue;
        }
        report.cost += step.added_cost;
        report.steps += 1;
        out[i as usize] = step.next;
        if let Some(next) = s.next_step(tree, step.next) {
            heap.push(Entry {
                slope: next.slope,
                tree: i,
            });
        }
    }
    for (tree, r) in trees.iter().zip(out.iter()) {
        report.benefit += s.benefit(tree, *r);
        match r {
            Representation::Impostor => report.impostors += 1,
            Representation::Geometry(_) => report.geometry += 1,
        }
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn forest(n: usize, seed: u64) -> Vec<MixedTree> {
        let mut rng = SplitMix64::new(seed);
        (0..n)
            .map(|_| MixedTree {
                // Sizes as in a forest seen from inside: many small, few large.
                screen_size: 0.5 / rng.range(1.0, 60.0),
                leaf_triangles: 2000 + rng.below(8000),
                impostor_triangles: Some(80),
            })
            .collect()
    }

    fn cost(trees: &[MixedTree], s: &MixedSettings, out: &[Representation]) -> f32 {
        trees
            .iter()
            .zip(out)
            .map(|(t, r)| match r {
                Representation::Impostor => s.impostor_cost(t.impostor_triangles.unwrap()),
                Representation::Geometry(x) => s.geometry_cost(t, *x),
            })
            .sum()
    }

    #[test]
    fn the_budget_holds_and_every_tree_gets_a_representation() {
        let trees = forest(500, 1);
        let mut out = Vec::new();
        for budget in [0.0, 2e5, 1e6, 4e6] {
            let s = MixedSettings {
                budget,
                ..Default::default()
            };
            let report = select(&trees, &s, &mut out);
            assert_eq!(out.len(), trees.len());
            let floor = cost(&trees, &s, &vec![Representation::Impostor; trees.len()]);
            let spent = cost(&trees, &s, &out);
            assert!(
                (spent - report.cost).abs() < 1.0,
                "{spent} vs {}",
                report.cost
            );
            // Never over budget, except that every tree always gets at least its impostor.
            assert!(spent <= budget.max(floor) + 1e-3, "{spent} > {budget}");
        }
    }

    #[test]
    fn larger_trees_on_screen_get_detail_first() {
        let trees = forest(400, 2);
        let mut out = Vec::new();
        select(
            &trees,
            &MixedSettings {
                budget: 6e5,
                ..Default::default()
            },
            &mut out,
        );
        let lod = |r: &Representation| match r {
            Representation::Impostor => 0.0,
            Representation::Geometry(x) => *x,
        };
        // A continuous step's slope is ∝ S / (N·√x): where the budget ran out, √x ∝ S/N. So a
        // tree with clearly more screen size per leaf triangle never gets less detail (the margin
        // leaves room for one doubling step and the budget's last fill).
        let mut worse = 0;
        for (a, ra) in trees.iter().zip(&out) {
            for (b, rb) in trees.iter().zip(&out) {
                let density = |t: &MixedTree| t.screen_size / t.leaf_triangles as f32;
                if density(a) > 4.0 * density(b) && lod(ra) < lod(rb) {
                    worse += 1;
                }
            }
        }
        assert_eq!(worse, 0);
        let geometry = out
            .iter()
            .filter(|r| **r != Representation::Impostor)
            .count();
        assert!(geometry > 10 && geometry < 400, "{geometry}");
    }

    #[test]
    fn more_budget_buys_more_benefit() {
        let trees = forest(300, 3);
        let mut out = Vec::new();
        let mut last = 0.0;
        for budget in [1e5, 3e5, 1e6, 3e6, 1e7] {
            let r = select(
                &trees,
                &MixedSettings {
                    budget,
                    ..Default::default()
                },
                &mut out,
            );
            assert!(r.benefit >= last, "{} < {last}", r.benefit);
            last = r.benefit;
        }
        // Enough budget for everything: every tree at full detail.
        assert!(out.iter().all(|r| *r == Representation::Geometry(1.0)));
    }

    #[test]
    fn the_greedy_choice_is_close_to_the_best_on_a_small_forest() {
        // Exhaustive search over impostor / 1/8 / 1/4 / 1/2 / 1 for five trees.
        let trees = forest(5, 4);
        let s = MixedSettings {
            budget: 12_000.0,
            ..Default::default()
        };
        let options = [
            Representation::Impostor,
            Representation::Geometry(0.125),
            Representation::Geometry(0.25),
            Representation::Geometry(0.5),
            Representation::Geometry(1.0),
        ];
        let mut best = 0.0f32;
        for code in 0..5usize.pow(5) {
            let assignment: Vec<Representation> =
                (0..5).map(|i| options[code / 5usize.pow(i) % 5]).collect();
            if cost(&trees, &s, &assignment) <= s.budget {
                let b: f32 = trees
                    .iter()
                    .zip(&assignment)
                    .map(|(t, r)| s.benefit(t, *r))
                    .sum();
                best = best.max(b);
            }
        }
        let mut out = Vec::new();
        let greedy = select(&trees, &s, &mut out);
        assert!(greedy.benefit >= 0.9 * best, "{} vs {best}", greedy.benefit);
        assert!(greedy.benefit <= best + 1e-3);
    }

    #[test]
    fn trees_without_an_impostor_are_geometry_and_bad_input_is_handled() {
        let trees = [
            MixedTree {
                screen_size: 0.1,
                leaf_triangles: 1000,
                impostor_triangles: None,
            },
            MixedTree {
                screen_size: f32::NAN,
                leaf_triangles: 1000,
                impostor_triangles: Some(40),
            },
        ];
        let mut out = Vec::new();
        select(&trees, &MixedSettings::default(), &mut out);
        assert!(matches!(out[0], Representation::Geometry(_)));
        assert_eq!(out[1], Representation::Impostor);
        let (fixed, fixes) = MixedSettings {
            budget: f32::NAN,
            min_lod: 0.0,
            ..Default::default()
        }
        .sanitized();
        assert_eq!(fixes.len(), 2);
        assert_eq!(fixed.budget, MixedSettings::default().budget);
    }
}
