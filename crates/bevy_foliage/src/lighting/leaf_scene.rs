//! The leaves of a tree as triangles in a bounding-volume hierarchy, for rays: the path tracer's
//! scene ([`super::path_trace`]) and the traced bins of the tree lighting's bake
//! ([`super::traced_bins`]).

use crate::pruning::leaves::LeafSet;
use crate::rng::SplitMix64;
use bevy::math::Vec3;
use std::f32::consts::PI;

/// A bounding-volume hierarchy node: a box and either two children or a run of triangles.
#[derive(Clone, Copy, Debug)]
struct Node {
    min: Vec3,
    max: Vec3,
    /// Leaf node: first triangle in `order`; inner node: the first child (the second follows
    /// at `right`).
    first: u32,
    /// Leaf node: triangle count; inner node: 0.
    count: u32,
    right: u32,
}

/// The leaves of a tree as triangles in a bounding-volume hierarchy.
pub struct LeafScene {
    triangles: Vec<[Vec3; 3]>,
    /// The leaf of each triangle.
    leaf_of: Vec<u32>,
    /// Each leaf's unit normal (of its first triangle, as [`super::bins::proxies`] takes it) and
    /// its triangles' range.
    normals: Vec<Vec3>,
    leaf_triangles: Vec<(u32, u32)>,
    /// Each leaf's key ([`LeafScene::leaf_key`]).
    keys: Vec<u64>,
    nodes: Vec<Node>,
    order: Vec<u32>,
}

/// Triangles below which a hierarchy node is always a leaf node.
const NODE_TRIANGLES: usize = 4;

/// Triangles a leaf node may hold when splitting it would cost more (surface-area heuristic).
const MAX_NODE_TRIANGLES: usize = 12;

/// Depth from which nodes are split at the median only (see [`LeafScene::build`]).
const MEDIAN_DEPTH: u32 = 32;

/// What entering an inner node costs, in triangle tests.
const TRAVERSAL_COST: f32 = 1.0;

/// A hash of the corners' bits, in order ([`LeafScene::leaf_key`]).
fn corner_hash(triangles: &[[Vec3; 3]]) -> u64 {
    let mut hash = 0x1EAF_u64;
    for corner in triangles.iter().flatten() {
        for c in corner.to_array() {
            hash = SplitMix64::new(hash ^ c.to_bits() as u64).next_u64();
        }
    }
    hash
}

/// A triangle's centre, times three (only compared).
fn centre([a, b, c]: [Vec3; 3]) -> Vec3 {
    a + b + c
}

impl LeafScene {
    /// A scene of leaves given as triangles: `leaf_of[t]` the leaf of triangle `t`, `normals`
    /// one unit normal per leaf (every `leaf_of` below `normals.len()`).
    pub fn from_triangles(
        triangles: Vec<[Vec3; 3]>,
        leaf_of: Vec<u32>,
        normals: Vec<Vec3>,
    ) -> Self {
        // Triangles grouped by leaf, for each leaf's range.
        let mut by_leaf: Vec<u32> = (0..triangles.len() as u32).collect();
        by_leaf.sort_by_key(|&t| leaf_of[t as usize]);
        let mut sorted = Vec::with_capacity(triangles.len());
        let mut sorted_leaf = Vec::with_capacity(triangles.len());
        let mut leaf_triangles = vec![(0u32, 0u32); normals.len()];
        for &t in &by_leaf {
            let leaf = leaf_of[t as usize] as usize;
            if leaf >= normals.len() {
                continue;
            }
            if leaf_triangles[leaf].1 == 0 {
                leaf_triangles[leaf].0 = sorted.len() as u32;
            }
            leaf_triangles[leaf].1 += 1;
            sorted.push(triangles[t as usize]);
            sorted_leaf.push(leaf as u32);
        }
        Self::build_scene(sorted, sorted_leaf, normals, leaf_triangles)
    }

    fn build_scene(
        triangles: Vec<[Vec3; 3]>,
        leaf_of: Vec<u32>,
        normals: Vec<Vec3>,
        leaf_triangles: Vec<(u32, u32)>,
    ) -> Self {
        let keys = leaf_triangles
            .iter()
            .map(|&(first, count)| {
                let range = first as usize..(first + count) as usize;
                corner_hash(triangles.get(range).unwrap_or(&[]))
            })
            .collect();
        let mut scene = Self {
            order: (0..triangles.len() as u32).collect(),
            keys,
            triangles,
            leaf_of,
            normals,
            leaf_triangles,
            nodes: Vec::new(),
        };
        if !scene.triangles.is_empty() {
            let n = scene.order.len();
            scene.build(0, n, 0);
        }
        scene
    }

    /// The scene of every leaf of `leaves`.
    pub fn new(leaves: &LeafSet) -> Self {
        let mut triangles = Vec::new();
        let mut leaf_of = Vec::new();
        let mut normals = Vec::new();
        let mut leaf_triangles = Vec::new();
        for leaf in 0..leaves.len() {
            let first = triangles.len() as u32;
            for t in leaves.triangles(leaf) {
                triangles.push(t);
                leaf_of.push(leaf as u32);
            }
            leaf_triangles.push((first, triangles.len() as u32 - first));
            normals.push(
                leaves
                    .triangles(leaf)
                    .next()
                    .and_then(|[a, b, c]| (b - a).cross(c - a).try_normalize())
                    .unwrap_or(Vec3::Y),
            );
        }
        Self::build_scene(triangles, leaf_of, normals, leaf_triangles)
    }

    /// The number of leaves.
    pub fn leaf_count(&self) -> usize {
        self.normals.len()
    }

    /// Leaf `leaf`'s key: a hash of its triangles' corners, so the same for the same leaf in
    /// any scene of it, whatever its index (for a leaf the scene does not hold, a hash of the
    /// index). Every per-leaf estimate of the tree lighting seeds its rays with it, so that a
    /// leaf's rays do not depend on where it is stored: a bake's leaves (in their stored
    /// order), the same bake loaded, a billboard cloud's source (in the source's order) and
    /// `tree_lighting_error` all trace the same rays for it.
    pub fn leaf_key(&self, leaf: usize) -> u64 {
        self.keys
            .get(leaf)
            .copied()
            .unwrap_or_else(|| SplitMix64::new(leaf as u64).next_u64())
    }

    /// How many triangles leaf `leaf` has.
    pub fn triangle_count(&self, leaf: usize) -> u32 {
        self.leaf_triangles.get(leaf).map_or(0, |r| r.1)
    }

    /// Leaf `leaf`'s unit normal.
    pub fn normal(&self, leaf: usize) -> Vec3 {
        self.normals[leaf]
    }

    /// Leaf `leaf`'s area (its triangles'); 0 for a leaf the scene does not hold.
    pub fn area(&self, leaf: usize) -> f32 {
        let Some(&(first, count)) = self.leaf_triangles.get(leaf) else {
            return 0.0;
        };
        self.triangles[first as usize..(first + count) as usize]
            .iter()
            .map(triangle_area)
            .sum()
    }

    fn bounds(&self, range: &[u32]) -> (Vec3, Vec3) {
        let mut min = Vec3::splat(f32::INFINITY);
        let mut max = Vec3::splat(f32::NEG_INFINITY);
        for &t in range {
            for v in self.triangles[t as usize] {
                min = min.min(v);
                max = max.max(v);
            }
        }
        (min, max)
    }

    /// Builds the node over `order[start..end]`; returns its index. The split is the one of
    /// least surface-area cost over 16 bins of the triangles' centres on each axis (MacDonald
    /// and Booth's heuristic: a ray's chance to enter a box goes with its surface area), the
    /// median on the longest axis where the centres cannot be told apart.
    fn build(&mut self, start: usize, end: usize, depth: u32) -> u32 {
        let (min, max) = self.bounds(&self.order[start..end]);
        let index = self.nodes.len() as u32;
        self.nodes.push(Node {
            min,
            max,
            first: start as u32,
            count: (end - start) as u32,
            right: 0,
        });
        if end - start <= NODE_TRIANGLES {
            return index;
        }
        // From `MEDIAN_DEPTH` down only medians: they halve the triangles, so however the
        // surface areas fall the hierarchy stays shallower than the traversal's stack of 64.
        let split = if depth < MEDIAN_DEPTH {
            self.surface_area_split(start, end, min, max)
        } else {
            None
        };
        let mid = match split {
            Some(mid) => mid,
            None if end - start <= MAX_NODE_TRIANGLES && depth < MEDIAN_DEPTH => return index,
            None => {
                let axis = (max - min).max_position();
                let mid = (start + end) / 2;
                let tris = &self.triangles;
                self.order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                    centre(tris[a as usize])[axis].total_cmp(&centre(tris[b as usize])[axis])
                });
                mid
            }
        };
        let left = self.build(start, mid, depth + 1);
        let right = self.build(mid, end, depth + 1);
        self.nodes[index as usize] = Node {
            min,
            max,
            first: left,
            count: 0,
            right,
        };
        index
    }

    /// Partitions `order[start..end]` at the binned split of least surface-area cost and
    /// returns where the right half starts, or `None` if no split is cheaper than a leaf node
    /// (or the centres all coincide).
    fn surface_area_split(
        &mut self,
        start: usize,
        end: usize,
        min: Vec3,
        max: Vec3,
    ) -> Option<usize> {
        const BINS: usize = 16;
        let tris = &self.triangles;
        let range = &self.order[start..end];
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for &t in range {
            let c = centre(tris[t as usize]);
            lo = lo.min(c);
            hi = hi.max(c);
        }
        // The bin of triangle `t`'s centre along `axis`.
        let bin_of = |t: u32, axis: usize| {
            let extent = hi[axis] - lo[axis];
            (((centre(tris[t as usize])[axis] - lo[axis]) / extent * BINS as f32) as usize)
                .min(BINS - 1)
        };
        let area = |min: Vec3, max: Vec3| {
            let d = (max - min).max(Vec3::ZERO);
            d.x * d.y + d.y * d.z + d.z * d.x
        };
        let parent = area(min, max).max(1e-30);
        // (cost, axis, bins on the left)
        let mut best: Option<(f32, usize, usize)> = None;
        for axis in 0..3 {
            let extent = hi[axis] - lo[axis];
            if extent.is_nan() || extent <= 0.0 {
                continue;
            }
            let bin = |t: u32| bin_of(t, axis);
            let mut count = [0u32; BINS];
            let mut bmin = [Vec3::splat(f32::INFINITY); BINS];
            let mut bmax = [Vec3::splat(f32::NEG_INFINITY); BINS];
            for &t in range {
                let b = bin(t);
                count[b] += 1;
                for v in tris[t as usize] {
                    bmin[b] = bmin[b].min(v);
                    bmax[b] = bmax[b].max(v);
                }
            }
            // Areas and counts of every left part, then sweep the right parts against them.
            let mut left_area = [0.0f32; BINS];
            let mut left_count = [0u32; BINS];
            let (mut m, mut x, mut n) = (bmin[0], bmax[0], 0u32);
            for i in 0..BINS - 1 {
                m = m.min(bmin[i]);
                x = x.max(bmax[i]);
                n += count[i];
                left_area[i] = area(m, x);
                left_count[i] = n;
            }
            let (mut m, mut x, mut n) = (bmin[BINS - 1], bmax[BINS - 1], 0u32);
            for i in (1..BINS).rev() {
                m = m.min(bmin[i]);
                x = x.max(bmax[i]);
                n += count[i];
                let l = left_count[i - 1];
                if l == 0 || n == 0 {
                    continue;
                }
                let cost = (left_area[i - 1] * l as f32 + area(m, x) * n as f32) / parent;
                if best.is_none_or(|b| cost < b.0) {
                    best = Some((cost, axis, i));
                }
            }
        }
        let (cost, axis, split) = best?;
        // A leaf node costs a test of each triangle; an inner node one box test more than
        // its children's expected triangle tests.
        let count = end - start;
        if cost + TRAVERSAL_COST >= count as f32 && count <= MAX_NODE_TRIANGLES {
            return None;
        }
        let goes_left = |t: u32| bin_of(t, axis) < split;
        let mut left: Vec<u32> = Vec::with_capacity(count);
        let mut right: Vec<u32> = Vec::with_capacity(count);
        for &t in range {
            if goes_left(t) {
                left.push(t);
            } else {
                right.push(t);
            }
        }
        let mid = start + left.len();
        self.order[start..mid].copy_from_slice(&left);
        self.order[mid..end].copy_from_slice(&right);
        Some(mid)
    }

    /// The nearest leaf the ray from `origin` along unit `dir` hits, skipping leaf `skip`:
    /// (distance, leaf).
    pub fn hit(&self, origin: Vec3, dir: Vec3, skip: u32) -> Option<(f32, u32)> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv = dir.recip();
        let mut best: Option<(f32, u32)> = None;
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            let limit = best.map_or(f32::INFINITY, |b| b.0);
            if !slab(node.min, node.max, origin, inv, limit) {
                continue;
            }
            if node.count > 0 {
                for &t in &self.order[node.first as usize..(node.first + node.count) as usize] {
                    let leaf = self.leaf_of[t as usize];
                    if leaf == skip {
                        continue;
                    }
                    if let Some(d) = triangle_hit(self.triangles[t as usize], origin, dir)
                        && d < best.map_or(f32::INFINITY, |b| b.0)
                    {
                        best = Some((d, leaf));
                    }
                }
            } else {
                top = self.push_children(&node, origin, inv, limit, &mut stack, top);
            }
        }
        best
    }

    /// Pushes the children of inner node `node` the ray enters before `limit`, the nearer on
    /// top (visited first: a nearest hit found early prunes the rest, an opaque leaf found
    /// early ends a shadow ray); returns the new stack top.
    fn push_children(
        &self,
        node: &Node,
        origin: Vec3,
        inv: Vec3,
        limit: f32,
        stack: &mut [u32; 64],
        mut top: usize,
    ) -> usize {
        let entry = |i: u32| {
            let child = &self.nodes[i as usize];
            slab_entry(child.min, child.max, origin, inv, limit)
        };
        let (a, b) = (node.first, node.right);
        let mut children = [(entry(a), a), (entry(b), b)];
        if children[0].0 < children[1].0 {
            children.swap(0, 1);
        }
        for (near, child) in children {
            if near.is_finite() && top < stack.len() {
                stack[top] = child;
                top += 1;
            }
        }
        top
    }

    /// The light the leaves let through along the ray from `origin` along unit `dir`, leaf
    /// `skip` not counted: the product of `1 − opacity(leaf)` over the leaf triangles the ray
    /// crosses (a leaf is one or two triangles, a ray crosses one of them). Stops once below
    /// 1/65,535 (what a bake can store), returning 0.
    pub fn transmittance(
        &self,
        origin: Vec3,
        dir: Vec3,
        skip: u32,
        opacity: impl Fn(u32) -> f32,
    ) -> f32 {
        if self.nodes.is_empty() {
            return 1.0;
        }
        let inv = dir.recip();
        let mut light = 1.0f32;
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            if !slab(node.min, node.max, origin, inv, f32::INFINITY) {
                continue;
            }
            if node.count > 0 {
                for &t in &self.order[node.first as usize..(node.first + node.count) as usize] {
                    let leaf = self.leaf_of[t as usize];
                    if leaf != skip
                        && triangle_hit(self.triangles[t as usize], origin, dir).is_some()
                    {
                        light *= 1.0 - opacity(leaf).clamp(0.0, 1.0);
                        if light < 1.0 / 65535.0 {
                            return 0.0;
                        }
                    }
                }
            } else {
                top = self.push_children(&node, origin, inv, f32::INFINITY, &mut stack, top);
            }
        }
        light
    }

    /// A point on leaf `leaf` spread uniformly over its area.
    pub fn point_on(&self, leaf: usize, rng: &mut SplitMix64) -> Vec3 {
        let s = rng.next_f32();
        self.point_at(leaf, (s, rng.next_f32()))
    }

    /// The point of leaf `leaf` at `u` in the unit square, the square mapped onto the leaf's
    /// area evenly (`u.0` picks the triangle by area, then goes on across it): points spread
    /// evenly over the square are spread evenly over the leaf.
    pub fn point_at(&self, leaf: usize, u: (f32, f32)) -> Vec3 {
        let (first, count) = self.leaf_triangles[leaf];
        let tris = &self.triangles[first as usize..(first + count) as usize];
        if tris.is_empty() {
            return Vec3::ZERO;
        }
        let total: f32 = tris.iter().map(triangle_area).sum();
        let mut pick = u.0.clamp(0.0, 1.0) * total;
        let mut chosen = (tris.len() - 1, 1.0f32);
        for (i, t) in tris.iter().enumerate() {
            let a = triangle_area(t);
            if pick < a {
                chosen = (i, pick / a);
                break;
            }
            pick -= a;
        }
        let [a, b, c] = tris[chosen.0];
        let (mut s, mut t) = (chosen.1.min(1.0), u.1.clamp(0.0, 1.0));
        if s + t > 1.0 {
            (s, t) = (1.0 - s, 1.0 - t);
        }
        a + (b - a) * s + (c - a) * t
    }

    /// Leaf `leaf`'s centre (the mean of its triangles' vertices, area-weighted).
    pub fn centre(&self, leaf: usize) -> Vec3 {
        let (first, count) = self.leaf_triangles[leaf];
        let mut sum = Vec3::ZERO;
        let mut area = 0.0;
        for t @ [a, b, c] in &self.triangles[first as usize..(first + count) as usize] {
            let w = triangle_area(t);
            sum += (*a + *b + *c) / 3.0 * w;
            area += w;
        }
        if area > 0.0 { sum / area } else { sum }
    }
}

/// A triangle's area.
fn triangle_area([a, b, c]: &[Vec3; 3]) -> f32 {
    0.5 * (*b - *a).cross(*c - *a).length()
}

/// Whether the ray (origin, 1/dir) crosses the box before `limit`.
fn slab(min: Vec3, max: Vec3, origin: Vec3, inv: Vec3, limit: f32) -> bool {
    let t0 = (min - origin) * inv;
    let t1 = (max - origin) * inv;
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element().min(limit);
    near <= far
}

/// The distance at which the ray enters the box (0 from inside), or `+∞` if it misses it or
/// enters it beyond `limit`.
fn slab_entry(min: Vec3, max: Vec3, origin: Vec3, inv: Vec3, limit: f32) -> f32 {
    let t0 = (min - origin) * inv;
    let t1 = (max - origin) * inv;
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element().min(limit);
    if near <= far { near } else { f32::INFINITY }
}

/// Möller–Trumbore: the distance along the ray to the triangle, both sides.
fn triangle_hit([a, b, c]: [Vec3; 3], origin: Vec3, dir: Vec3) -> Option<f32> {
    let e1 = b - a;
    let e2 = c - a;
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - a;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t > 0.0).then_some(t)
}

/// A direction uniform on the sphere.
pub(crate) fn uniform_direction(rng: &mut SplitMix64) -> Vec3 {
    let z = rng.next_f32() * 2.0 - 1.0;
    let phi = rng.next_f32() * 2.0 * PI;
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), z, r * phi.sin())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pruning::procedural::{TreeSpecies, generate};

    /// A leaf's key is its own: the same in a scene of its leaves in another order, distinct
    /// between leaves; an index past the leaves has one too.
    #[test]
    fn a_leafs_key_follows_the_leaf_not_its_index() {
        use crate::lighting::path_trace::push_square_leaf;
        let centres = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let mut forward = LeafSet::default();
        let mut backward = LeafSet::default();
        for c in centres {
            push_square_leaf(&mut forward, c, 0.1, Vec3::Z);
        }
        for &c in centres.iter().rev() {
            push_square_leaf(&mut backward, c, 0.1, Vec3::Z);
        }
        let (a, b) = (LeafScene::new(&forward), LeafScene::new(&backward));
        for i in 0..3 {
            assert_eq!(a.leaf_key(i), b.leaf_key(2 - i), "leaf {i}");
            for j in 0..i {
                assert_ne!(a.leaf_key(i), a.leaf_key(j), "leaves {i} and {j}");
            }
        }
        assert_ne!(a.leaf_key(3), a.leaf_key(4));
        // Every leaf of a real crown its own key.
        let olive = LeafScene::new(&generate(&TreeSpecies::olea().with_leaf_count(800)).leaves);
        let mut keys: Vec<u64> = (0..olive.leaf_count()).map(|l| olive.leaf_key(l)).collect();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), olive.leaf_count());
    }

    /// The hierarchy finds what testing every triangle finds: the nearest hit and the light let
    /// through, for rays from points on a real crown's leaves in every direction.
    #[test]
    fn the_hierarchy_finds_what_every_triangle_finds() {
        let leaves = generate(&TreeSpecies::olea().with_leaf_count(800)).leaves;
        let scene = LeafScene::new(&leaves);
        assert!(scene.nodes.len() > 1);
        let mut rng = SplitMix64::new(7);
        let opacity = |leaf: u32| if leaf.is_multiple_of(3) { 1.0 } else { 0.4 };
        let (mut hits, mut shaded) = (0, 0);
        for k in 0..3000 {
            let leaf = k % scene.leaf_count();
            let origin = scene.point_on(leaf, &mut rng);
            let dir = uniform_direction(&mut rng);
            let skip = leaf as u32;
            let mut nearest: Option<(f32, u32)> = None;
            let mut light = 1.0f32;
            for (t, tri) in scene.triangles.iter().enumerate() {
                let of = scene.leaf_of[t];
                if of == skip {
                    continue;
                }
                if let Some(d) = triangle_hit(*tri, origin, dir) {
                    if nearest.is_none_or(|n| d < n.0) {
                        nearest = Some((d, of));
                    }
                    light *= 1.0 - opacity(of);
                }
            }
            if light < 1.0 / 65535.0 {
                light = 0.0;
            }
            assert_eq!(scene.hit(origin, dir, skip), nearest, "ray {k}");
            let through = scene.transmittance(origin, dir, skip, opacity);
            assert!(
                (through - light).abs() < 1e-5,
                "ray {k}: {through} vs {light}"
            );
            hits += nearest.is_some() as u32;
            shaded += (light < 1.0) as u32;
        }
        // The rays are a real test: many hit, many escape.
        assert!(
            hits > 600 && hits < 2900 && shaded == hits,
            "{hits} {shaded}"
        );
    }
}
