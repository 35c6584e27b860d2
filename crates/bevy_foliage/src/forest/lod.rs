//! Desired level of detail and urgency of one tree (Gumbau 2011, eq. 3.11–3.12 and 4.2–4.3).
//!
//! A tree's LoD is a number in [0, 1]: the distance factor of the pruning pass (1 keeps every
//! visible leaf, 0 none). The thesis' chapter 3 writes LoD_desired as the sum of the cells' LoDs;
//! with a single distance factor per tree (the cells' view-dependent visibility then splits it)
//! that sum is proportional to the factor itself, so the scalar is used here.

/// Desired LoD of a tree at `distance` (eq. 4.2 with eq. 4.3): the distance is clamped to
/// `[near, far]`, `lod = (far − d)/(far − near)`, and the frame-rate feedback exponent `n` gives
/// `d_lod = lod^n` (n > 1 lowers detail, n < 1 raises it).
pub fn desired_lod(distance: f32, near: f32, far: f32, exponent: f32) -> f32 {
    if !distance.is_finite() {
        return 0.0;
    }
    let d = distance.clamp(near, far);
    let lod = if far > near {
        (far - d) / (far - near)
    } else {
        1.0
    };
    // lod ∈ [0, 1]: 0 and 1 are fixed points of the exponent, as they must be (the exact LoD 0
    // and LoD 1 cache slots).
    lod.clamp(0.0, 1.0).powf(exponent.max(1e-3))
}

/// The LoD error of a tree (eq. 3.11): how far its stored LoD is from the desired one.
pub fn lod_error(desired: f32, stored: f32) -> f32 {
    (desired - stored).abs()
}

/// Urgency of re-extracting a tree (eq. 3.12): `LoD error · frames since its last update /
/// distance`. Near trees with a large error that have waited long come first. The distance is
/// floored at `min_distance` so a tree at the camera does not get an infinite urgency.
pub fn urgency(error: f32, frames_since_update: u32, distance: f32, min_distance: f32) -> f32 {
    let d = if distance.is_finite() {
        distance.max(min_distance).max(1e-6)
    } else {
        return 0.0;
    };
    error * frames_since_update as f32 / d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn desired_lod_follows_eq_4_2_and_4_3() {
        assert_eq!(desired_lod(0.0, 10.0, 110.0, 1.0), 1.0);
        assert_eq!(desired_lod(10.0, 10.0, 110.0, 1.0), 1.0);
        assert!((desired_lod(60.0, 10.0, 110.0, 1.0) - 0.5).abs() < 1e-6);
        assert_eq!(desired_lod(500.0, 10.0, 110.0, 1.0), 0.0);
        // n = 2 squares it: less detail; n = 0.5 takes the root: more.
        assert!((desired_lod(60.0, 10.0, 110.0, 2.0) - 0.25).abs() < 1e-6);
        assert!((desired_lod(60.0, 10.0, 110.0, 0.5) - 0.5f32.sqrt()).abs() < 1e-6);
        assert_eq!(desired_lod(f32::NAN, 10.0, 110.0, 1.0), 0.0);
    }

    #[test]
    fn urgency_follows_eq_3_12() {
        assert_eq!(urgency(0.5, 4, 10.0, 1.0), 0.2);
        // Twice as far, half as urgent; twice as old, twice as urgent.
        assert_eq!(urgency(0.5, 4, 20.0, 1.0), 0.1);
        assert_eq!(urgency(0.5, 8, 10.0, 1.0), 0.4);
        assert_eq!(urgency(0.5, 4, 0.0, 1.0), 2.0);
        assert_eq!(urgency(0.0, 100, 10.0, 1.0), 0.0);
        assert_eq!(lod_error(0.25, 0.75), 0.5);
    }
}
