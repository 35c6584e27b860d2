//! How far a tree is, for level of detail: the distances of eq. 3.4 (pruning) and eq. 4.2 (the
//! forest manager's desired LoD).
//!
//! The thesis gives `near` and `far` in metres for its scenes. Absolute distances do not carry
//! over to other content: a 100 m tree is pruned bare at three tree heights while it fills 40 %
//! of the screen, and a tree authored in centimetres is pruned as if it stood a hundred times
//! farther away. [`LodDistances::ScreenSize`] (the default) therefore measures a tree by the size
//! of its crown on screen — its bounding sphere's projected diameter as a fraction of the view
//! height, as engines' "screen size" LoD thresholds do — so trees of any size and unit prune alike
//! at the same size on screen, at any resolution. [`LodDistances::World`] keeps the thesis' metres.
//!
//! Both are reduced to one *LoD distance* ρ on which eq. 3.4 is linear: the world distance from
//! the camera to the crown's centre, or the inverse screen size `1/s`. For a perspective camera
//! `s = r·P₁₁/d` (crown radius r, projection entry `P₁₁ = cot(fov/2)`, distance d), so `1/s` is
//! proportional to d and eq. 3.4 keeps the thesis' shape; for an orthographic camera `s = r·P₁₁`
//! whatever the distance.

use bevy::reflect::Reflect;

/// How the LoD distances `near` and `far` are measured.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub enum LodDistances {
    /// By the crown's size on screen: its projected diameter ÷ the view height. Full detail while
    /// the crown is at least `near` tall on screen, nothing (LoD 0) once it is under `far`;
    /// `near > far > 0`.
    ScreenSize {
        /// Screen size of LoD 1 (full detail at and above).
        near: f32,
        /// Screen size of LoD 0.
        far: f32,
    },
    /// By the world distance from the camera to the crown's centre (the thesis' metres);
    /// `0 ≤ near < far`.
    World {
        /// Distance of LoD 1.
        near: f32,
        /// Distance of LoD 0.
        far: f32,
    },
}

impl Default for LodDistances {
    fn default() -> Self {
        Self::ScreenSize {
            near: DEFAULT_NEAR_SCREEN_SIZE,
            far: DEFAULT_FAR_SCREEN_SIZE,
        }
    }
}

/// Default screen size of full detail: a crown filling 60 % of the view height or more. For the
/// thesis' Olea (crown radius 3.6 m) behind Bevy's default 45° lens that is 14.5 m, near the
/// thesis' scenes' 10–15 m.
pub const DEFAULT_NEAR_SCREEN_SIZE: f32 = 0.6;
/// Default screen size of LoD 0: a crown 1.5 % of the view height (5 px at 360 p, 16 px at
/// 1080 p). The Olea reaches it at 580 m.
pub const DEFAULT_FAR_SCREEN_SIZE: f32 = 0.015;

/// What the LoD distance needs of the camera's projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodView {
    /// The projection's `clip_from_view[1][1]` (`cot(fov_y / 2)` for a perspective camera).
    pub yy: f32,
    /// Orthographic projection (`clip_from_view[3][3] == 1`).
    pub orthographic: bool,
}

impl Default for LodView {
    /// Bevy's default perspective camera (45° vertical field of view).
    fn default() -> Self {
        Self {
            yy: 1.0 / (std::f32::consts::FRAC_PI_8).tan(),
            orthographic: false,
        }
    }
}

impl LodView {
    /// The view of a `clip_from_view` matrix; a matrix with a non-finite or non-positive `[1][1]`
    /// gives the default view.
    pub fn from_clip_from_view(m: bevy::math::Mat4) -> Self {
        let yy = m.y_axis.y;
        if !(yy.is_finite() && yy > 0.0) {
            return Self::default();
        }
        Self {
            yy,
            orthographic: m.w_axis.w == 1.0,
        }
    }
}

impl LodDistances {
    /// The LoD distance ρ of a crown of world radius `radius` whose centre is `distance` from the
    /// camera (module docs): the distance itself, or the inverse screen size.
    pub fn lod_distance(&self, distance: f32, radius: f32, view: &LodView) -> f32 {
        match self {
            Self::World { .. } => distance,
            Self::ScreenSize { .. } => {
                let size = if view.orthographic {
                    radius * view.yy
                } else {
                    radius * view.yy / distance.max(1e-6)
                };
                if size > 0.0 && size.is_finite() {
                    1.0 / size
                } else {
                    f32::INFINITY
                }
            }
        }
    }

    /// `near` and `far` as LoD distances (`near < far`).
    pub fn range(&self) -> (f32, f32) {
        match *self {
            Self::World { near, far } => (near, far),
            Self::ScreenSize { near, far } => (1.0 / near, 1.0 / far),
        }
    }

    /// The distance factor of eq. 3.4 at LoD distance `rho`: 1 under `near`, 0 over `far`,
    /// linear between. Non-finite distances give 0.
    pub fn factor_at(&self, rho: f32) -> f32 {
        let (near, far) = self.range();
        if !rho.is_finite() {
            0.0
        } else if rho <= near {
            1.0
        } else if rho >= far {
            0.0
        } else {
            1.0 - (rho - near) / (far - near)
        }
    }

    /// The distance factor of eq. 3.4 of a crown (see [`lod_distance`](Self::lod_distance)).
    pub fn distance_factor(&self, distance: f32, radius: f32, view: &LodView) -> f32 {
        self.factor_at(self.lod_distance(distance, radius, view))
    }

    /// These distances made valid, and what was corrected: non-finite values and inverted or
    /// empty ranges go back to the defaults of their kind.
    pub fn sanitized(&self) -> (Self, Option<String>) {
        match *self {
            Self::World { near, far } => {
                if near.is_finite() && far.is_finite() && near >= 0.0 && far > near {
                    (*self, None)
                } else {
                    let near = if near.is_finite() {
                        near.max(0.0)
                    } else {
                        10.0
                    };
                    let far = if far.is_finite() && far > near {
                        far
                    } else {
                        near * 2.0 + 250.0
                    };
                    (
                        Self::World { near, far },
                        Some(format!(
                            "world distances near = {near}, far = {far} need 0 <= near < far: using near = {near}, far = {far}"
                        )),
                    )
                }
            }
            Self::ScreenSize { near, far } => {
                let ok = |v: f32| v.is_finite() && v > 0.0;
                if ok(near) && ok(far) && near > far {
                    (*self, None)
                } else {
                    let fixed = Self::default();
                    (
                        fixed,
                        Some(format!(
                            "screen sizes near = {near}, far = {far} need near > far > 0: using {fixed:?}"
                        )),
                    )
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn world_distances_follow_eq_3_4() {
        let d = LodDistances::World {
            near: 10.0,
            far: 110.0,
        };
        let v = LodView::default();
        assert_eq!(d.distance_factor(5.0, 3.0, &v), 1.0);
        assert!((d.distance_factor(35.0, 3.0, &v) - 0.75).abs() < 1e-6);
        assert!((d.distance_factor(60.0, 99.0, &v) - 0.5).abs() < 1e-6);
        assert_eq!(d.distance_factor(500.0, 3.0, &v), 0.0);
        assert_eq!(d.distance_factor(f32::NAN, 3.0, &v), 0.0);
    }

    #[test]
    fn screen_size_is_scale_free_and_linear_in_distance() {
        let d = LodDistances::ScreenSize {
            near: 0.5,
            far: 0.05,
        };
        let v = LodView::default();
        // A tree and the same tree in centimetres, at distances in their own units.
        for distance in [1.0f32, 8.0, 20.0, 40.0, 90.0, 300.0] {
            let metres = d.distance_factor(distance, 4.0, &v);
            let centimetres = d.distance_factor(distance * 100.0, 400.0, &v);
            assert!(
                (metres - centimetres).abs() < 1e-5,
                "{metres} vs {centimetres}"
            );
        }
        // Full detail while the crown fills half the view height: r·yy/d ≥ 0.5.
        let near_d = 4.0 * v.yy / 0.5;
        assert_eq!(d.distance_factor(near_d * 0.99, 4.0, &v), 1.0);
        let far_d = 4.0 * v.yy / 0.05;
        assert_eq!(d.distance_factor(far_d * 1.01, 4.0, &v), 0.0);
        // Linear in the world distance between them (eq. 3.4's shape).
        let mid = d.distance_factor((near_d + far_d) / 2.0, 4.0, &v);
        assert!((mid - 0.5).abs() < 1e-5, "{mid}");
        // An orthographic camera sees the same size at any distance.
        let ortho = LodView {
            yy: 0.1,
            orthographic: true,
        };
        assert_eq!(
            d.distance_factor(10.0, 4.0, &ortho),
            d.distance_factor(1000.0, 4.0, &ortho)
        );
        // A zero-radius crown is infinitely far.
        assert_eq!(d.distance_factor(10.0, 0.0, &v), 0.0);
    }

    #[test]
    fn views_come_from_projection_matrices() {
        let p = bevy::math::Mat4::perspective_infinite_reverse_rh(1.0, 1.5, 0.1);
        let v = LodView::from_clip_from_view(p);
        assert!((v.yy - 1.0 / 0.5f32.tan()).abs() < 1e-5);
        assert!(!v.orthographic);
        let o = bevy::math::Mat4::orthographic_rh(-2.0, 2.0, -1.0, 1.0, 0.1, 100.0);
        let v = LodView::from_clip_from_view(o);
        assert!(v.orthographic && (v.yy - 1.0).abs() < 1e-6);
        assert_eq!(
            LodView::from_clip_from_view(bevy::math::Mat4::ZERO),
            LodView::default()
        );
    }

    #[test]
    fn absurd_distances_are_corrected() {
        assert!(LodDistances::default().sanitized().1.is_none());
        let (fixed, note) = LodDistances::ScreenSize {
            near: 0.01,
            far: 0.5,
        }
        .sanitized();
        assert!(note.is_some());
        assert_eq!(fixed, LodDistances::default());
        let (fixed, note) = LodDistances::World {
            near: f32::NAN,
            far: -1.0,
        }
        .sanitized();
        assert!(note.is_some());
        let (near, far) = fixed.range();
        assert!(near >= 0.0 && far > near);
    }
}
