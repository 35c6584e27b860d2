//! Grass on curved ground (Boulanger 2008, thesis §4.2.7.2): a patch instanced on a grid cell is
//! lifted onto the ground by the bilinear patch through the cell's four corner heights (eq. 4.10)
//! — blades stay vertical, as grass does on slopes — and lit in the patch's own frame, the
//! non-orthogonal (T, N = Y, B) of the ground under it, interpolated across the cell (eq. 4.12),
//! so the light direction is brought into that frame by the inverse of eq. 4.11. Wind shears the
//! patch's volume (§4.2.7.4, after Meyer and Neyret): each corner of the cell takes a wind
//! vector from a map over the ground, and a point is pushed by their bilinear blend in proportion
//! to its height — roots stay, the tops lean, and neighbouring cells, sharing corners, lean
//! together.

use bevy::math::Vec3;

/// Eq. 4.10: the lift at patch coordinates `(x, z) ∈ [0, 1]²` of a cell whose corners have
/// heights `h00` (x = 0, z = 0), `h10`, `h01`, `h11`.
pub fn lift(h00: f32, h10: f32, h01: f32, h11: f32, x: f32, z: f32) -> f32 {
    (1.0 - x) * (1.0 - z) * h00 + x * (1.0 - z) * h10 + (1.0 - x) * z * h01 + x * z * h11
}

/// Eq. 4.12: the frame at `(x, z)` of a cell from its corners' tangents (along x) and binormals
/// (along z), `[00, 10, 01, 11]`: T and B bilinearly interpolated and normalised, N vertical.
pub fn frame(tangents: [Vec3; 4], binormals: [Vec3; 4], x: f32, z: f32) -> (Vec3, Vec3, Vec3) {
    let w = [(1.0 - x) * (1.0 - z), x * (1.0 - z), (1.0 - x) * z, x * z];
    let mix = |v: [Vec3; 4]| (v[0] * w[0] + v[1] * w[1] + v[2] * w[2] + v[3] * w[3]).normalize();
    (mix(tangents), Vec3::Y, mix(binormals))
}

/// Eq. 4.11: a world direction `l` in the patch frame (T, Y, B) — the solution of
/// `[T N B]·l_p = l`, by the closed form the vertical N allows. `None` where T and B are
/// parallel in the ground plane (no frame).
pub fn to_patch_frame(t: Vec3, b: Vec3, l: Vec3) -> Option<Vec3> {
    let det = b.z * t.x - b.x * t.z;
    if det.abs() < 1e-8 {
        return None;
    }
    let row0 = Vec3::new(b.z, 0.0, -b.x);
    let row1 = b.cross(t);
    let row2 = Vec3::new(-t.z, 0.0, t.x);
    Some(Vec3::new(row0.dot(l), row1.dot(l), row2.dot(l)) / det)
}

/// The wind's shear of a point at patch coordinates `(x, z) ∈ [0, 1]²`, `height` above the
/// ground in a volume `volume_height` tall, under corner winds `[00, 10, 01, 11]` (horizontal
/// displacements of the volume's top corners, m): the horizontal offset to add.
pub fn wind_shear(
    winds: [bevy::math::Vec2; 4],
    x: f32,
    z: f32,
    height: f32,
    volume_height: f32,
) -> bevy::math::Vec2 {
    let w = winds[0] * ((1.0 - x) * (1.0 - z))
        + winds[1] * (x * (1.0 - z))
        + winds[2] * ((1.0 - x) * z)
        + winds[3] * (x * z);
    let up = if volume_height > 0.0 {
        (height / volume_height).clamp(0.0, 1.0)
    } else {
        0.0
    };
    w * up
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    #[test]
    fn the_lift_is_the_bilinear_patch_through_the_corners() {
        assert_eq!(lift(1.0, 2.0, 3.0, 4.0, 0.0, 0.0), 1.0);
        assert_eq!(lift(1.0, 2.0, 3.0, 4.0, 1.0, 0.0), 2.0);
        assert_eq!(lift(1.0, 2.0, 3.0, 4.0, 0.0, 1.0), 3.0);
        assert_eq!(lift(1.0, 2.0, 3.0, 4.0, 1.0, 1.0), 4.0);
        assert!((lift(1.0, 2.0, 3.0, 4.0, 0.5, 0.5) - 2.5).abs() < 1e-6);
        // Shared edges agree: the right edge of one cell is the left edge of the next.
        for k in 0..=10 {
            let z = k as f32 / 10.0;
            assert_eq!(
                lift(1.0, 2.0, 3.0, 4.0, 1.0, z),
                lift(2.0, 7.0, 4.0, 9.0, 0.0, z)
            );
        }
    }

    #[test]
    fn wind_leans_the_tops_and_keeps_the_roots_and_shared_edges() {
        use bevy::math::Vec2;
        let winds = [
            Vec2::new(0.1, 0.0),
            Vec2::new(0.2, 0.05),
            Vec2::new(0.0, 0.1),
            Vec2::new(0.3, 0.3),
        ];
        assert_eq!(wind_shear(winds, 0.3, 0.7, 0.0, 0.5), Vec2::ZERO);
        assert_eq!(wind_shear(winds, 1.0, 1.0, 0.5, 0.5), winds[3]);
        assert!((wind_shear(winds, 0.0, 0.0, 0.25, 0.5) - winds[0] * 0.5).length() < 1e-6);
        // The next cell along x shares corners 10 and 11 as its 00 and 01: same shear there.
        let next = [winds[1], Vec2::new(-0.2, 0.0), winds[3], Vec2::ZERO];
        for k in 0..=8 {
            let z = k as f32 / 8.0;
            let a = wind_shear(winds, 1.0, z, 0.4, 0.5);
            let b = wind_shear(next, 0.0, z, 0.4, 0.5);
            assert!((a - b).length() < 1e-6);
        }
    }

    #[test]
    fn eq_4_11_inverts_the_non_orthogonal_frame() {
        let mut rng = SplitMix64::new(11);
        for _ in 0..2000 {
            // Slopes up to 60°: T along x rising, B along z rising.
            let t = Vec3::new(1.0, rng.range(-1.7, 1.7), rng.range(-0.3, 0.3)).normalize();
            let b = Vec3::new(rng.range(-0.3, 0.3), rng.range(-1.7, 1.7), 1.0).normalize();
            let l = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            let p = to_patch_frame(t, b, l).unwrap();
            let back = t * p.x + Vec3::Y * p.y + b * p.z;
            assert!(back.distance(l) < 1e-4, "{l} → {p} → {back}");
        }
        // On flat ground the frame is the world's.
        let p = to_patch_frame(Vec3::X, Vec3::Z, Vec3::new(0.3, 0.5, -0.2)).unwrap();
        assert!(p.distance(Vec3::new(0.3, 0.5, -0.2)) < 1e-6);
        assert_eq!(to_patch_frame(Vec3::X, Vec3::X, Vec3::Y), None);
        // Eq. 4.12: interpolated frames are continuous and unit.
        let (t, n, b) = frame(
            [
                Vec3::X,
                Vec3::new(1.0, 1.0, 0.0).normalize(),
                Vec3::X,
                Vec3::X,
            ],
            [Vec3::Z; 4],
            0.5,
            0.0,
        );
        assert!((t.length() - 1.0).abs() < 1e-6 && t.y > 0.0 && n == Vec3::Y && b == Vec3::Z);
    }
}
