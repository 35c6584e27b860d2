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
    nodes: Vec<Node>,
    order: Vec<u32>,
}

/// Triangles a hierarchy leaf node holds at most.
const NODE_TRIANGLES: usize = 4;

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
        let mut scene = Self {
            order: (0..triangles.len() as u32).collect(),
            triangles,
            leaf_of,
            normals,
            leaf_triangles,
            nodes: Vec::new(),
        };
        if !scene.triangles.is_empty() {
            let n = scene.order.len();
            scene.build(0, n);
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

    /// How many triangles leaf `leaf` has.
    pub fn triangle_count(&self, leaf: usize) -> u32 {
        self.leaf_triangles.get(leaf).map_or(0, |r| r.1)
    }

    /// Leaf `leaf`'s unit normal.
    pub fn normal(&self, leaf: usize) -> Vec3 {
        self.normals[leaf]
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

    /// Builds the node over `order[start..end]`, median split on the longest axis; returns its
    /// index.
    fn build(&mut self, start: usize, end: usize) -> u32 {
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
        let axis = (max - min).max_position();
        let centre = |t: u32, tris: &[[Vec3; 3]]| {
            let [a, b, c] = tris[t as usize];
            (a + b + c)[axis]
        };
        let mid = (start + end) / 2;
        let tris = &self.triangles;
        self.order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
            centre(a, tris).total_cmp(&centre(b, tris))
        });
        let left = self.build(start, mid);
        let right = self.build(mid, end);
        self.nodes[index as usize] = Node {
            min,
            max,
            first: left,
            count: 0,
            right,
        };
        index
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
            } else if top + 2 <= stack.len() {
                stack[top] = node.first;
                stack[top + 1] = node.right;
                top += 2;
            }
        }
        best
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
            } else if top + 2 <= stack.len() {
                stack[top] = node.first;
                stack[top + 1] = node.right;
                top += 2;
            }
        }
        light
    }

    /// A point on leaf `leaf` spread uniformly over its area.
    pub fn point_on(&self, leaf: usize, rng: &mut SplitMix64) -> Vec3 {
        let (first, count) = self.leaf_triangles[leaf];
        let tris = &self.triangles[first as usize..(first + count) as usize];
        if tris.is_empty() {
            return Vec3::ZERO;
        }
        let area = |[a, b, c]: &[Vec3; 3]| 0.5 * (*b - *a).cross(*c - *a).length();
        let total: f32 = tris.iter().map(area).sum();
        let mut pick = rng.next_f32() * total;
        let mut chosen = tris.len() - 1;
        for (i, t) in tris.iter().enumerate() {
            let a = area(t);
            if pick < a {
                chosen = i;
                break;
            }
            pick -= a;
        }
        let [a, b, c] = tris[chosen];
        let (mut u, mut v) = (rng.next_f32(), rng.next_f32());
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        a + (b - a) * u + (c - a) * v
    }

    /// Leaf `leaf`'s centre (the mean of its triangles' vertices, area-weighted).
    pub fn centre(&self, leaf: usize) -> Vec3 {
        let (first, count) = self.leaf_triangles[leaf];
        let mut sum = Vec3::ZERO;
        let mut area = 0.0;
        for [a, b, c] in &self.triangles[first as usize..(first + count) as usize] {
            let w = 0.5 * (*b - *a).cross(*c - *a).length();
            sum += (*a + *b + *c) / 3.0 * w;
            area += w;
        }
        if area > 0.0 { sum / area } else { sum }
    }
}

/// Whether the ray (origin, 1/dir) crosses the box before `limit`.
fn slab(min: Vec3, max: Vec3, origin: Vec3, inv: Vec3, limit: f32) -> bool {
    let t0 = (min - origin) * inv;
    let t1 = (max - origin) * inv;
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element().min(limit);
    near <= far
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
