//! Seeded procedural trees: a trunk, main branches and twigs as bark geometry, and leaf quads
//! placed along the twigs inside a crown envelope.
//!
//! The four presets reproduce the test trees of Gumbau 2011, table 3.1, at their exact leaf
//! counts: Olea europaea 16,107; Fraxinus ornus 28,645; Quercus cerris 41,155; Cedrus atlantica
//! 131,042. Crown shapes follow the species loosely (round olive, oval ash, broad oak, conical
//! cedar); the point is plausible occlusion structure for the visibility bake and realistic
//! leaf counts, not botany.

use super::leaves::LeafSet;
use crate::rng::SplitMix64;
use bevy::math::{Quat, Vec2, Vec3};

/// Overall crown outline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CrownShape {
    /// An ellipsoid of the given horizontal radius and vertical half-height.
    Ellipsoid,
    /// A cone, widest at its base (conifers).
    Cone,
}

/// Parameters of a procedural tree.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeSpecies {
    /// Display name.
    pub name: &'static str,
    /// Exact number of leaves generated.
    pub leaf_count: usize,
    /// Total height (m).
    pub height: f32,
    /// Height of the first branches (clear bole, m).
    pub crown_base: f32,
    /// Crown radius (m).
    pub crown_radius: f32,
    /// Crown outline.
    pub shape: CrownShape,
    /// Trunk radius at the ground (m).
    pub trunk_radius: f32,
    /// Number of main branches.
    pub branches: u32,
    /// Twigs per main branch.
    pub twigs_per_branch: u32,
    /// Mean leaf length (m); width is `leaf_aspect` times it.
    pub leaf_size: f32,
    /// Leaf width / length.
    pub leaf_aspect: f32,
    /// Random seed.
    pub seed: u64,
}

impl TreeSpecies {
    /// *Olea europaea*, 16,107 leaves.
    pub fn olea() -> Self {
        Self {
            name: "Olea europaea",
            leaf_count: 16_107,
            height: 6.0,
            crown_base: 1.6,
            crown_radius: 3.0,
            shape: CrownShape::Ellipsoid,
            trunk_radius: 0.25,
            branches: 9,
            twigs_per_branch: 14,
            leaf_size: 0.22,
            leaf_aspect: 0.45,
            seed: 1,
        }
    }

    /// *Fraxinus ornus*, 28,645 leaves.
    pub fn fraxinus() -> Self {
        Self {
            name: "Fraxinus ornus",
            leaf_count: 28_645,
            height: 10.0,
            crown_base: 2.5,
            crown_radius: 3.6,
            shape: CrownShape::Ellipsoid,
            trunk_radius: 0.3,
            branches: 11,
            twigs_per_branch: 16,
            leaf_size: 0.2,
            leaf_aspect: 0.5,
            seed: 2,
        }
    }

    /// *Quercus cerris*, 41,155 leaves.
    pub fn quercus() -> Self {
        Self {
            name: "Quercus cerris",
            leaf_count: 41_155,
            height: 13.0,
            crown_base: 3.0,
            crown_radius: 5.5,
            shape: CrownShape::Ellipsoid,
            trunk_radius: 0.45,
            branches: 13,
            twigs_per_branch: 18,
            leaf_size: 0.22,
            leaf_aspect: 0.6,
            seed: 3,
        }
    }

    /// *Cedrus atlantica*, 131,042 leaves (needle clusters).
    pub fn cedrus() -> Self {
        Self {
            name: "Cedrus atlantica",
            leaf_count: 131_042,
            height: 20.0,
            crown_base: 2.0,
            crown_radius: 6.0,
            shape: CrownShape::Cone,
            trunk_radius: 0.6,
            branches: 28,
            twigs_per_branch: 14,
            leaf_size: 0.14,
            leaf_aspect: 0.5,
            seed: 4,
        }
    }

    /// The four test trees of the thesis, smallest first.
    pub fn thesis_trees() -> [Self; 4] {
        [
            Self::olea(),
            Self::fraxinus(),
            Self::quercus(),
            Self::cedrus(),
        ]
    }

    /// The same species with a different leaf count and the same total leaf area: the leaves
    /// grow (or shrink) by `√(old / new)`, so a crown with fewer leaves for speed keeps the
    /// coverage of the full count (the probability that a ray through the crown meets a leaf
    /// depends on the leaf area per volume, not on the count).
    pub fn with_leaf_count(mut self, leaf_count: usize) -> Self {
        if leaf_count > 0 && self.leaf_count > 0 {
            self.leaf_size *= (self.leaf_count as f32 / leaf_count as f32).sqrt();
        }
        self.leaf_count = leaf_count;
        self
    }

    /// Total leaf area (m²) of the species' leaves at their mean size.
    pub fn leaf_area(&self) -> f32 {
        self.leaf_count as f32 * self.leaf_size * self.leaf_size * self.leaf_aspect
    }

    /// Centre of the crown envelope.
    pub fn crown_center(&self) -> Vec3 {
        match self.shape {
            CrownShape::Ellipsoid => Vec3::Y * (self.crown_base + self.height) * 0.5,
            CrownShape::Cone => Vec3::Y * self.crown_base,
        }
    }

    /// Whether `p` lies inside the crown envelope grown by `margin` (relative).
    pub fn inside_crown(&self, p: Vec3, margin: f32) -> bool {
        let grow = 1.0 + margin;
        match self.shape {
            CrownShape::Ellipsoid => {
                let half_h = (self.height - self.crown_base) * 0.5;
                let c = self.crown_center();
                let q = Vec3::new(
                    (p.x - c.x) / self.crown_radius,
                    (p.y - c.y) / half_h,
                    (p.z - c.z) / self.crown_radius,
                );
                q.length_squared() <= grow * grow
            }
            CrownShape::Cone => {
                if p.y < self.crown_base - margin * self.height || p.y > self.height * grow {
                    return false;
                }
                let t = ((p.y - self.crown_base) / (self.height - self.crown_base)).clamp(0.0, 1.0);
                let r = self.crown_radius * (1.0 - t);
                Vec2::new(p.x, p.z).length() <= r * grow + 0.05
            }
        }
    }
}

/// Plain triangle mesh data (bark).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshData {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Vertex normals.
    pub normals: Vec<Vec3>,
    /// Texture coordinates.
    pub uvs: Vec<Vec2>,
    /// Triangle list.
    pub indices: Vec<u32>,
}

impl MeshData {
    /// Appends a tapered, capless cylinder from `a` (radius `ra`) to `b` (radius `rb`).
    pub fn push_cylinder(&mut self, a: Vec3, b: Vec3, ra: f32, rb: f32, sides: u32) {
        let axis = (b - a).normalize_or(Vec3::Y);
        let rot = Quat::from_rotation_arc(Vec3::Y, axis);
        let base = self.positions.len() as u32;
        for i in 0..=sides {
            let angle = i as f32 / sides as f32 * std::f32::consts::TAU;
            let dir = rot * Vec3::new(angle.cos(), 0.0, angle.sin());
            for (end, r, v) in [(a, ra, 0.0), (b, rb, 1.0)] {
                self.positions.push(end + dir * r);
                self.normals.push(dir);
                self.uvs.push(Vec2::new(i as f32 / sides as f32, v));
            }
        }
        for i in 0..sides {
            let k = base + i * 2;
            self.indices
                .extend_from_slice(&[k, k + 1, k + 3, k, k + 3, k + 2]);
        }
    }
}

/// A generated tree: bark geometry and leaves, in model space (ground at `y = 0`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProceduralTree {
    /// Trunk, branches and twigs.
    pub bark: MeshData,
    /// Leaf quads.
    pub leaves: LeafSet,
}

struct Segment {
    a: Vec3,
    b: Vec3,
}

/// Generates `species` deterministically from its seed.
pub fn generate(species: &TreeSpecies) -> ProceduralTree {
    let mut rng = SplitMix64::new(species.seed ^ 0x7EE5_0000);
    let mut bark = MeshData::default();
    let top = Vec3::Y * species.height;
    bark.push_cylinder(
        Vec3::ZERO,
        top * 0.92,
        species.trunk_radius,
        species.trunk_radius * 0.2,
        8,
    );

    let mut twigs: Vec<Segment> = Vec::new();
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    for i in 0..species.branches {
        let t = (i as f32 + rng.range(0.2, 0.8)) / species.branches as f32;
        let y = species.crown_base + t * (species.height - species.crown_base) * 0.85;
        let azimuth = i as f32 * golden + rng.range(-0.2, 0.2);
        let outward = Vec3::new(azimuth.cos(), 0.0, azimuth.sin());
        // Branch length: reach towards the envelope at this height.
        let reach = match species.shape {
            CrownShape::Ellipsoid => {
                let c = species.crown_center();
                let half_h = (species.height - species.crown_base) * 0.5;
                let dy = ((y - c.y) / half_h).clamp(-1.0, 1.0);
                species.crown_radius * (1.0 - dy * dy).max(0.05).sqrt()
            }
            CrownShape::Cone => {
                let tt = ((y - species.crown_base) / (species.height - species.crown_base))
                    .clamp(0.0, 1.0);
                species.crown_radius * (1.0 - tt).max(0.08)
            }
        };
        let rise = match species.shape {
            CrownShape::Ellipsoid => rng.range(0.3, 0.7),
            CrownShape::Cone => rng.range(-0.05, 0.1),
        };
        let start = Vec3::Y * y;
        let end = start + (outward + Vec3::Y * rise).normalize() * reach * rng.range(0.8, 0.95);
        let r0 = species.trunk_radius * 0.35 * (1.0 - t * 0.6);
        bark.push_cylinder(start, end, r0, r0 * 0.3, 5);
        for j in 0..species.twigs_per_branch {
            let s = (j as f32 + rng.range(0.0, 1.0)) / species.twigs_per_branch as f32;
            let origin = start.lerp(end, 0.25 + 0.75 * s);
            let random = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-0.4, 1.0),
                rng.range(-1.0, 1.0),
            );
            let dir = (outward * 0.6 + random).normalize_or(Vec3::Y);
            let len = reach * rng.range(0.2, 0.4);
            let tip = origin + dir * len;
            bark.push_cylinder(origin, tip, r0 * 0.25, r0 * 0.08, 3);
            twigs.push(Segment { a: origin, b: tip });
        }
    }

    // Leaves: along twigs (weighted by length), jittered, kept inside the crown envelope.
    let lengths: Vec<f32> = twigs.iter().map(|s| (s.b - s.a).length()).collect();
    let total: f32 = lengths.iter().sum();
    let mut cumulative = Vec::with_capacity(lengths.len());
    let mut acc = 0.0;
    for l in &lengths {
        acc += l / total;
        cumulative.push(acc);
    }
    let mut leaves = LeafSet::default();
    let mut attempts = 0usize;
    while leaves.len() < species.leaf_count {
        attempts += 1;
        let u = rng.next_f32();
        let k = cumulative.partition_point(|&c| c < u).min(twigs.len() - 1);
        let twig = &twigs[k];
        let along = twig.a.lerp(twig.b, rng.next_f32());
        let jitter = Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ) * species.leaf_size
            * 2.5;
        let center = along + jitter;
        // After many rejections (tiny test trees) accept anyway so generation always ends.
        if !species.inside_crown(center, 0.05) && attempts < species.leaf_count * 50 {
            continue;
        }
        let size = species.leaf_size * rng.range(0.75, 1.25);
        // Leaves face roughly outward and up, with random tilt.
        let outward = (center - Vec3::Y * center.y).normalize_or(Vec3::X);
        let normal = (outward * 0.6
            + Vec3::Y * 0.5
            + Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ) * 0.7)
            .normalize_or(Vec3::Y);
        let tangent = normal.any_orthonormal_vector();
        let spin = Quat::from_axis_angle(normal, rng.range(0.0, std::f32::consts::TAU));
        let along_leaf = spin * tangent * size * 0.5;
        let across = spin * normal.cross(tangent) * size * species.leaf_aspect * 0.5;
        leaves.push_quad(
            [
                center - along_leaf - across,
                center + along_leaf - across,
                center + along_leaf + across,
                center - along_leaf + across,
            ],
            normal,
        );
    }
    ProceduralTree { bark, leaves }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_have_the_thesis_leaf_counts() {
        let counts: Vec<usize> = TreeSpecies::thesis_trees()
            .iter()
            .map(|s| s.leaf_count)
            .collect();
        assert_eq!(counts, vec![16_107, 28_645, 41_155, 131_042]);
    }

    #[test]
    fn generation_is_exact_deterministic_and_inside_the_crown() {
        let species = TreeSpecies::olea().with_leaf_count(3000);
        let a = generate(&species);
        let b = generate(&species);
        assert_eq!(a, b, "same seed, same tree");
        assert_eq!(a.leaves.len(), 3000);
        assert_eq!(a.leaves.triangle_count(), 6000);
        let inside = (0..a.leaves.len())
            .filter(|&i| species.inside_crown(a.leaves.centroid(i), 0.06))
            .count();
        assert_eq!(inside, 3000, "every leaf inside the (slightly grown) crown");
        let (_, skipped) = a.leaves.sanitized();
        assert_eq!(skipped.total(), 0);
        assert!(!a.bark.indices.is_empty());
        let mut other = species.clone();
        other.seed += 1;
        assert_ne!(generate(&other).leaves.positions, a.leaves.positions);
    }

    #[test]
    fn fewer_leaves_keep_the_crowns_leaf_area() {
        let full = TreeSpecies::quercus();
        let reduced = full.clone().with_leaf_count(4000);
        assert!((reduced.leaf_area() / full.leaf_area() - 1.0).abs() < 1e-4);
        let area = |s: &TreeSpecies| {
            let t = generate(s);
            (0..t.leaves.len()).map(|l| t.leaves.area(l)).sum::<f32>()
        };
        let (a_reduced, a_more) = (area(&reduced), area(&full.clone().with_leaf_count(12_000)));
        assert!(
            (a_reduced / a_more - 1.0).abs() < 0.05,
            "generated leaf area {a_reduced} vs {a_more}"
        );
    }

    #[test]
    fn cedrus_crown_is_conical() {
        let species = TreeSpecies::cedrus().with_leaf_count(4000);
        let tree = generate(&species);
        // Mean horizontal spread of leaves in the lower third exceeds that of the upper third.
        let spread = |lo: f32, hi: f32| {
            let v: Vec<f32> = (0..tree.leaves.len())
                .map(|i| tree.leaves.centroid(i))
                .filter(|c| c.y >= lo && c.y < hi)
                .map(|c| Vec2::new(c.x, c.z).length())
                .collect();
            v.iter().sum::<f32>() / v.len().max(1) as f32
        };
        let h = species.height;
        assert!(spread(0.0, h / 3.0) > 1.5 * spread(2.0 * h / 3.0, h));
    }
}
