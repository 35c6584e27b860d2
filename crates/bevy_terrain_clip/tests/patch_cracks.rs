//! No cracks in the seamless-patch terrain mesh (paper 4's Claim 1), as a property over random
//! views: eyes anywhere over and beside the terrain, low and high, precisions from coarse to fine,
//! with and without a frustum.
//!
//! - Neighbouring patches differ by at most one level.
//! - Where two selected patches touch, the vertices each has on their shared segment are the same
//!   lattice points (exact integer comparison).
//! - Without culling, the union of all patch meshes covers the terrain square exactly once (areas
//!   add up) and every edge is used by two triangles except on the terrain's border (one): no
//!   T-junction, no hole, no overlap anywhere.

use bevy::math::{Vec2, Vec3, Vec4};
use bevy_terrain_clip::geometry::patch::by_id;
use bevy_terrain_clip::geometry::{
    PatchGrid, PatchId, PatchView, SelectedPatch, patch_mesh, select_patches,
};
use std::collections::{HashMap, HashSet};

/// SplitMix64 (Steele, Lea and Flood 2014): a seeded generator for the cases.
struct Cases(u64);

impl Cases {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, a: f32, b: f32) -> f32 {
        a + (b - a) * self.next()
    }
}

/// A perspective frustum at `eye` looking along `forward` (vertical FOV `fov`, square aspect),
/// as six inward planes `(n, d)`.
fn frustum(eye: Vec3, forward: Vec3, fov: f32, far: f32) -> [Vec4; 6] {
    let f = forward.normalize();
    let right = f.cross(Vec3::Y).normalize();
    let up = right.cross(f);
    let t = (fov / 2.0).tan();
    let plane = |n: Vec3, p: Vec3| {
        let n = n.normalize();
        n.extend(-n.dot(p))
    };
    [
        plane(f, eye + f * 0.1),
        plane(-f, eye + f * far),
        plane(f * t + right, eye),
        plane(f * t - right, eye),
        plane(f * t + up, eye),
        plane(f * t - up, eye),
    ]
}

/// The lattice points of `mesh` on the segment from `a` to `b` (axis-aligned).
fn on_segment(vertices: &[[u32; 2]], a: [u32; 2], b: [u32; 2]) -> Vec<[u32; 2]> {
    let mut v: Vec<[u32; 2]> = vertices
        .iter()
        .copied()
        .filter(|p| {
            (a[0] == b[0] && p[0] == a[0] && p[1] >= a[1].min(b[1]) && p[1] <= a[1].max(b[1]))
                || (a[1] == b[1]
                    && p[1] == a[1]
                    && p[0] >= a[0].min(b[0])
                    && p[0] <= a[0].max(b[0]))
        })
        .collect();
    v.sort();
    v
}

fn covering(map: &HashMap<PatchId, SelectedPatch>, mut id: PatchId) -> Option<PatchId> {
    loop {
        if map.contains_key(&id) {
            return Some(id);
        }
        if id.level == 0 {
            return None;
        }
        id = id.parent();
    }
}

#[test]
fn random_views_give_a_crack_free_mesh() {
    let grid = PatchGrid::new(Vec2::new(-2000.0, 1000.0), 4096.0, 7, 16).unwrap();
    let mut cases = Cases(2026);
    let (mut balance_splits, mut patches_seen, mut shared_segments) = (0u32, 0usize, 0usize);
    for case in 0..120 {
        let eye = Vec3::new(
            cases.range(-3000.0, 3000.0),
            10f32.powf(cases.range(0.0, 3.3)),
            cases.range(0.0, 6000.0),
        );
        let culling = case % 2 == 1;
        let forward = Vec3::new(
            cases.range(-1.0, 1.0),
            cases.range(-0.8, 0.1),
            cases.range(-1.0, 1.0),
        );
        let view = PatchView {
            eye,
            precision: 10f32.powf(cases.range(-0.3, 1.0)),
            frustum: (culling && forward.length() > 0.1)
                .then(|| frustum(eye, forward, 1.0, 20000.0)),
            heights: (-20.0, 300.0),
        };
        let selection = select_patches(&grid, &view);
        balance_splits += selection.stats.balance_splits;
        patches_seen += selection.patches.len();
        let map = by_id(&selection);
        let meshes: HashMap<PatchId, Vec<[u32; 2]>> = selection
            .patches
            .iter()
            .map(|p| (p.id, patch_mesh(&grid, p).vertices))
            .collect();
        for p in &selection.patches {
            for e in 0..4 {
                let Some(n) = p.id.neighbour(e) else {
                    continue;
                };
                // The neighbour is this level, one coarser, or split once into this level + 1.
                let neighbours: Vec<PatchId> = match covering(&map, n) {
                    Some(c) => {
                        assert!(
                            c.level + 1 >= p.id.level,
                            "case {case}: {:?} next to {c:?}",
                            p.id
                        );
                        vec![c]
                    }
                    None => {
                        // The leaves inside the neighbour's square along this edge.
                        let finer: Vec<PatchId> = selection
                            .patches
                            .iter()
                            .map(|q| q.id)
                            .filter(|q| {
                                q.level > n.level
                                    && q.parent_at(n.level) == n
                                    && q.neighbour((e + 2) % 4).map(|b| b.parent_at(p.id.level))
                                        == Some(p.id)
                            })
                            .collect();
                        for q in &finer {
                            assert_eq!(
                                q.level,
                                p.id.level + 1,
                                "case {case}: {:?} next to {q:?}",
                                p.id
                            );
                        }
                        finer
                    }
                };
                // Shared vertices coincide: on the segment both patches cover, each mesh has
                // the same lattice points.
                let (a, b) = (p.id.corner_point(&grid, e), p.id.corner_point(&grid, e + 1));
                for q in neighbours {
                    let (qa, qb) = (
                        q.corner_point(&grid, (e + 2) % 4),
                        q.corner_point(&grid, (e + 3) % 4),
                    );
                    // The overlap of the two collinear segments.
                    let (lo, hi) = if a[0] == b[0] {
                        let lo = a[1].min(b[1]).max(qa[1].min(qb[1]));
                        let hi = a[1].max(b[1]).min(qa[1].max(qb[1]));
                        ([a[0], lo], [a[0], hi])
                    } else {
                        let lo = a[0].min(b[0]).max(qa[0].min(qb[0]));
                        let hi = a[0].max(b[0]).min(qa[0].max(qb[0]));
                        ([lo, a[1]], [hi, a[1]])
                    };
                    if lo >= hi {
                        continue;
                    }
                    shared_segments += 1;
                    let mine = on_segment(&meshes[&p.id], lo, hi);
                    let theirs = on_segment(&meshes[&q], lo, hi);
                    assert_eq!(
                        mine, theirs,
                        "case {case}: {:?} edge {e} ({:?}) vs {q:?} ({:?})",
                        p.id, p.edges, map[&q].edges
                    );
                    assert!(mine.len() >= 2);
                }
            }
        }
        if view.frustum.is_none() {
            assert_watertight(&grid, &selection.patches, case);
        }
    }
    println!(
        "{patches_seen} patches over 120 views, {shared_segments} shared segments checked; \
         {balance_splits} leaves split to keep neighbours within one level"
    );
    assert!(shared_segments > 10_000);
}

/// The union of the patches' meshes covers the terrain exactly once, and only the terrain's
/// border has edges used by a single triangle.
fn assert_watertight(grid: &PatchGrid, patches: &[SelectedPatch], case: usize) {
    let side = grid.lattice_side();
    let mut uses: HashMap<([u32; 2], [u32; 2]), u32> = HashMap::new();
    let mut area = 0i128;
    let mut vertices = HashSet::new();
    for p in patches {
        let mesh = patch_mesh(grid, p);
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            vertices.extend([a, b, c]);
            area += ((b[0] as i128 - a[0] as i128) * (c[1] as i128 - a[1] as i128)
                - (b[1] as i128 - a[1] as i128) * (c[0] as i128 - a[0] as i128))
                .abs();
            for (u, v) in [(a, b), (b, c), (c, a)] {
                *uses.entry((u.min(v), u.max(v))).or_insert(0) += 1;
            }
        }
    }
    assert_eq!(area, 2 * (side as i128).pow(2), "case {case}: area");
    for ((a, b), n) in uses {
        let border = (a[0] == b[0] && (a[0] == 0 || a[0] == side))
            || (a[1] == b[1] && (a[1] == 0 || a[1] == side));
        assert_eq!(
            n,
            if border { 1 } else { 2 },
            "case {case}: edge {a:?}-{b:?} (a crack or an overlap)"
        );
    }
}
