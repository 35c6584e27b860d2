//! The leaves of a crown in an octree whose nodes carry what the envelope needs of their leaves
//! together — so that [`super::envelope`] treats far groups of leaves as one (a Barnes–Hut
//! approximation), in O(n log n) instead of O(n²) for crowns of 10⁵ leaves.
//!
//! A node far from the leaf P (its size over its distance below [`OPENING`]) occludes, in the bin
//! of its centroid's direction, the sum of its leaves' projected areas over r²: with the leaves'
//! area-weighted normal second moment `M = Σ A·n·nᵀ`, `Σ A·|n·d̂| ≈ c·√(ΣA · d̂ᵀ M d̂)`, exact for
//! one leaf up to the constant c = √3/2, which makes it exact on average for uniformly oriented
//! leaves (E|n·d̂| = 1/2, E(n·d̂)² = 1/3). Its leaves are summed as separate small occluders, so
//! the bin's light is multiplied by `e^(−Σ o)`, which the exact product `Π(1 − o)` tends to for
//! the small `o` of far leaves.

use super::bins::{BIN_SOLID_ANGLE, BinSums, LeafProxy, bin_of, occlusion};
use bevy::math::{Mat3, Vec3};

/// A node is used as one occluder when its bounding box's diagonal is less than this fraction
/// of its centroid's distance.
pub const OPENING: f32 = 0.5;

/// Leaves per octree leaf node.
const BUCKET: usize = 16;

/// √3/2: `E|n·d̂| / √E(n·d̂)²` for uniformly oriented normals.
const ORIENTATION: f32 = 0.866_025_4;

struct Node {
    lo: Vec3,
    hi: Vec3,
    centroid: Vec3,
    area: f32,
    moment: Mat3,
    count: u32,
    /// Children (indices into the node list), or the leaves' range in `order`.
    children: Vec<u32>,
    leaves: std::ops::Range<u32>,
}

/// The crown's octree.
pub struct LeafTree<'a> {
    leaves: &'a [LeafProxy],
    order: Vec<u32>,
    nodes: Vec<Node>,
}

impl<'a> LeafTree<'a> {
    /// Builds the octree of `leaves`.
    pub fn new(leaves: &'a [LeafProxy]) -> Self {
        let mut tree = Self {
            leaves,
            order: (0..leaves.len() as u32).collect(),
            nodes: Vec::new(),
        };
        if !leaves.is_empty() {
            tree.build(0, leaves.len(), 0);
        }
        tree
    }

    fn build(&mut self, start: usize, end: usize, depth: u32) -> u32 {
        let index = self.nodes.len() as u32;
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        let (mut weighted, mut area, mut moment) = (Vec3::ZERO, 0.0f32, Mat3::ZERO);
        for &i in &self.order[start..end] {
            let l = &self.leaves[i as usize];
            lo = lo.min(l.centre);
            hi = hi.max(l.centre);
            weighted += l.centre * l.area;
            area += l.area;
            let n = l.normal;
            moment += Mat3::from_cols(n * n.x, n * n.y, n * n.z) * l.area;
        }
        let centroid = if area > 0.0 {
            weighted / area
        } else {
            (lo + hi) * 0.5
        };
        self.nodes.push(Node {
            lo,
            hi,
            centroid,
            area,
            moment,
            count: (end - start) as u32,
            children: Vec::new(),
            leaves: start as u32..end as u32,
        });
        // Split at the box's centre into octants, unless few leaves or all at one point.
        if end - start <= BUCKET || depth >= 24 || (hi - lo).max_element() <= 0.0 {
            return index;
        }
        let mid = (lo + hi) * 0.5;
        let octant = |p: Vec3| {
            (p.x >= mid.x) as usize
                | ((p.y >= mid.y) as usize) << 1
                | ((p.z >= mid.z) as usize) << 2
        };
        let leaves = self.leaves;
        self.order[start..end].sort_by_key(|&i| octant(leaves[i as usize].centre));
        let mut children = Vec::new();
        let mut s = start;
        while s < end {
            let o = octant(leaves[self.order[s] as usize].centre);
            let mut e = s;
            while e < end && octant(leaves[self.order[e] as usize].centre) == o {
                e += 1;
            }
            children.push(self.build(s, e, depth + 1));
            s = e;
        }
        self.nodes[index as usize].children = children;
        index
    }

    /// What the leaf at `index` sees per bin, far nodes taken as one occluder each.
    pub fn bins_of(&self, index: usize) -> BinSums {
        let mut sums = BinSums::default();
        if self.nodes.is_empty() {
            return sums;
        }
        let p = self.leaves[index].centre;
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            let d = node.centroid - p;
            let r2 = d.length_squared();
            let inside = p.cmpge(node.lo).all() && p.cmple(node.hi).all();
            let size2 = (node.hi - node.lo).length_squared();
            if !inside && r2 > 0.0 && size2 < OPENING * OPENING * r2 {
                let dir = d / r2.sqrt();
                let projected =
                    ORIENTATION * (node.area * dir.dot(node.moment * dir)).max(0.0).sqrt();
                let optical = projected / r2 / BIN_SOLID_ANGLE;
                let j = bin_of(d);
                let r = r2.sqrt();
                sums.attenuation[j] *= (-optical).exp();
                sums.farthest[j] = sums.farthest[j].max(r + 0.5 * size2.sqrt());
                sums.distance_sum[j] += r * node.count as f32;
                sums.count[j] += node.count;
                continue;
            }
            if node.children.is_empty() {
                for &i in &self.order[node.leaves.start as usize..node.leaves.end as usize] {
                    if i as usize == index {
                        continue;
                    }
                    let q = &self.leaves[i as usize];
                    sums.add_leaf(q.centre - p, occlusion(p, q));
                }
            } else {
                stack.extend_from_slice(&node.children);
            }
        }
        sums
    }
}
