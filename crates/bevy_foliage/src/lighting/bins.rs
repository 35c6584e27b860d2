//! The eight sampling directions of the tree lighting and their bins (Boulanger 2008, §5.2.1,
//! §5.6), the leaves as the envelope sees them, and what one leaf sees per bin: shared by the
//! leaf-by-leaf envelope ([`super::envelope`]) and its octree ([`super::leaf_tree`]).

use crate::pruning::leaves::LeafSet;
use bevy::math::Vec3;

/// ξ = √3/3: the sampling directions are (±ξ, ±ξ, ±ξ).
pub const XI: f32 = 0.577_350_26;

/// Sampling directions: `DIRECTIONS` bit 0 set means +x, bit 1 +y, bit 2 +z.
pub const DIRECTIONS: [Vec3; 8] = {
    let mut out = [Vec3::ZERO; 8];
    let mut j = 0;
    while j < 8 {
        out[j] = Vec3::new(
            if j & 1 != 0 { XI } else { -XI },
            if j & 2 != 0 { XI } else { -XI },
            if j & 4 != 0 { XI } else { -XI },
        );
        j += 1;
    }
    out
};

/// The solid angle of one bin: the sphere's eighth.
pub const BIN_SOLID_ANGLE: f32 = std::f32::consts::FRAC_PI_2;

/// The bin (index into [`DIRECTIONS`]) of the direction `d`: its octant.
pub fn bin_of(d: Vec3) -> usize {
    (d.x >= 0.0) as usize | ((d.y >= 0.0) as usize) << 1 | ((d.z >= 0.0) as usize) << 2
}

/// A leaf as the envelope sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafProxy {
    /// Its centre P.
    pub centre: Vec3,
    /// Its unit normal.
    pub normal: Vec3,
    /// Its area.
    pub area: f32,
}

/// The least light a stored attenuation above zero can hold: the lighting takes a bin that lets
/// nothing through as letting this much (its envelope distance stays finite).
pub const DARKEST_LIGHT: f32 = 1.0 / 65535.0;

/// An attenuation in `[0, 1]` as stored in a bake (65,535 = 1).
pub fn quantize_light(a: f32) -> u16 {
    (a.clamp(0.0, 1.0) * 65535.0).round() as u16
}

/// A stored attenuation back in `[0, 1]`.
pub fn light_of(q: u16) -> f32 {
    q as f32 / 65535.0
}

/// The proxies of every leaf of `leaves`: centroid, the unit normal of its first triangle,
/// its area.
pub fn proxies(leaves: &LeafSet) -> Vec<LeafProxy> {
    (0..leaves.len())
        .map(|i| LeafProxy {
            centre: leaves.centroid(i),
            normal: leaves
                .triangles(i)
                .next()
                .and_then(|[a, b, c]| (b - a).cross(c - a).try_normalize())
                .unwrap_or(Vec3::Y),
            area: leaves.area(i),
        })
        .collect()
}

/// The fraction of bin's solid angle leaf `q` occludes seen from `p`, in `]0, 1]`.
pub fn occlusion(p: Vec3, q: &LeafProxy) -> f32 {
    let d = q.centre - p;
    let r2 = d.length_squared();
    if r2 <= 0.0 || !r2.is_finite() {
        return 0.0;
    }
    let cosine = q.normal.dot(d).abs() / r2.sqrt();
    (q.area * cosine / r2 / BIN_SOLID_ANGLE).min(1.0)
}

/// What one leaf sees per bin, summed: the light let through, and the distances of the leaves
/// seen (for the envelope's first estimate).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BinSums {
    /// The light let through per bin.
    pub attenuation: [f32; 8],
    /// The farthest leaf per bin.
    pub farthest: [f32; 8],
    /// The sum of the leaves' distances per bin.
    pub distance_sum: [f32; 8],
    /// The leaves per bin.
    pub count: [u32; 8],
}

impl Default for BinSums {
    fn default() -> Self {
        Self {
            attenuation: [1.0; 8],
            farthest: [0.0; 8],
            distance_sum: [0.0; 8],
            count: [0; 8],
        }
    }
}

impl BinSums {
    /// One leaf at `d` from P occluding `o` of its bin.
    pub fn add_leaf(&mut self, d: Vec3, o: f32) {
        if o <= 0.0 {
            return;
        }
        let j = bin_of(d);
        let r = d.length();
        self.attenuation[j] *= 1.0 - o;
        self.farthest[j] = self.farthest[j].max(r);
        self.distance_sum[j] += r;
        self.count[j] += 1;
    }
}
