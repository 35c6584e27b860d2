//! Which leaves each view of a tree draws this frame: the camera's selection, and the
//! shadow-casting light's own.
//!
//! The camera's selection is the thesis' (§3.4): the three baked viewpoints nearest the view
//! direction (`FindCameras`), and the distance factor of eq. 3.4 ([`crate::distance`]).
//!
//! **Shadows keep their leaves.** Pruning for the camera drops the leaves the camera does not
//! see — the far side of the crown, the leaves behind others — and those are exactly the leaves
//! that cast much of the ground shadow. So shadow views draw the *light's* selection: the
//! viewpoints nearest the direction towards the light, at the camera's distance factor (the
//! shadow is seen from where the tree is seen, so it needs the detail the tree needs), with area
//! compensation, so the crown keeps its coverage seen from the light — the darkness of its
//! shadow. While the camera keeps every visible leaf (distance factor 1, inside `near`), the
//! shadow draws the full set: near the camera the shadow's outline is seen at its sharpest.

use super::extract::{FIXED_ONE, KEEP_ALL, UNIFORM_DISTANCE, ViewWeights, view_weights};
use crate::distance::LodView;
use crate::settings::FoliagePruningSettings;
use bevy::math::{Affine3A, Vec3};

/// One extraction's inputs: baked viewpoints and their weights, and the distance factor.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Selection {
    /// Viewpoints and weights.
    pub weights: ViewWeights,
    /// Distance factor (eq. 3.4), fraction of [`FIXED_ONE`]; [`KEEP_ALL`]: every leaf.
    pub distance_fixed: u32,
}

impl Selection {
    /// Draws nothing.
    pub const NONE: Self = Self {
        weights: ViewWeights {
            views: [0; 3],
            weights: [FIXED_ONE, 0, 0],
        },
        distance_fixed: 0,
    };

    /// The same selection without the view term: every cell keeps the distance factor's
    /// fraction of its leaves ([`UNIFORM_DISTANCE`]). What the trees' opacity shadow map draws,
    /// since every leaf on a sun ray attenuates it, seen from the sun or not.
    pub fn without_view_term(self) -> Self {
        if self.distance_fixed == KEEP_ALL {
            return self;
        }
        Self {
            distance_fixed: self.distance_fixed.min(FIXED_ONE) | UNIFORM_DISTANCE,
            ..self
        }
    }

    /// Draws every leaf.
    pub const ALL: Self = Self {
        weights: ViewWeights {
            views: [0; 3],
            weights: [FIXED_ONE, 0, 0],
        },
        distance_fixed: KEEP_ALL,
    };
}

/// The light whose shadow views draw the light's selection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ShadowLight {
    /// A directional light; `toward_light` is the unit world direction from the scene to it.
    Directional {
        /// From the scene towards the light.
        toward_light: Vec3,
    },
    /// A spot or point light at a world position.
    Positional {
        /// Where the light is.
        position: Vec3,
    },
}

/// A distance factor as a fraction of [`FIXED_ONE`].
pub fn factor_fixed(factor: f32) -> u32 {
    ((factor.clamp(0.0, 1.0) * FIXED_ONE as f32).round() as u32).min(FIXED_ONE)
}

/// What selecting needs of a tree.
#[derive(Clone, Copy, Debug)]
pub struct TreeView<'a> {
    /// The tree type's baked viewpoint directions (model space).
    pub view_directions: &'a [Vec3],
    /// Crown centre (model space).
    pub crown_center: Vec3,
    /// Crown radius (model space).
    pub crown_radius: f32,
    /// Where the tree stands.
    pub world_from_local: Affine3A,
}

/// The camera's and the light's selections of one tree (module docs). A tree whose transform
/// is not finite or not invertible draws nothing. The light's selection is `None` when shadow
/// views can draw the camera's (no shadow light, or the camera keeps every leaf anyway).
pub fn select(
    tree: &TreeView,
    camera: Vec3,
    view: &LodView,
    light: Option<ShadowLight>,
    settings: &FoliagePruningSettings,
) -> (Selection, Option<Selection>) {
    let m = tree.world_from_local;
    if !m.is_finite() || !camera.is_finite() || m.matrix3.determinant() == 0.0 {
        return (Selection::NONE, None);
    }
    let local_from_world = m.inverse();
    let direction = local_from_world.transform_point3(camera) - tree.crown_center;
    let weights = view_weights(direction, tree.view_directions, settings.view_weighting);
    // Inside the crown the visibility baked from viewpoints around it does not apply.
    let inside_crown = direction.length() < tree.crown_radius;
    if !settings.enabled || inside_crown {
        return (
            Selection {
                weights,
                distance_fixed: KEEP_ALL,
            },
            None,
        );
    }
    let scale = m
        .matrix3
        .x_axis
        .length()
        .max(m.matrix3.y_axis.length())
        .max(m.matrix3.z_axis.length());
    let center = m.transform_point3(tree.crown_center);
    let factor = settings.distances.distance_factor(
        camera.distance(center),
        tree.crown_radius * scale,
        view,
    );
    let camera_selection = Selection {
        weights,
        distance_fixed: factor_fixed(factor),
    };
    let light = light.filter(|_| settings.shadow_selection);
    let light_selection = light.map(|light| {
        if factor >= 1.0 {
            return Selection::ALL;
        }
        let toward = match light {
            ShadowLight::Directional { toward_light } => {
                local_from_world.transform_vector3(toward_light)
            }
            ShadowLight::Positional { position } => {
                local_from_world.transform_point3(position) - tree.crown_center
            }
        };
        Selection {
            weights: view_weights(toward, tree.view_directions, settings.view_weighting),
            distance_fixed: factor_fixed(factor),
        }
    });
    (camera_selection, light_selection)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distance::LodDistances;
    use crate::pruning::visibility::fibonacci_directions;
    use crate::settings::ViewWeighting;
    use bevy::math::Quat;

    #[test]
    fn without_the_view_term_keeps_the_distance_factor() {
        let s = Selection {
            distance_fixed: FIXED_ONE / 4,
            ..Selection::NONE
        };
        assert_eq!(
            s.without_view_term().distance_fixed,
            (FIXED_ONE / 4) | UNIFORM_DISTANCE
        );
        assert_eq!(Selection::ALL.without_view_term(), Selection::ALL);
        assert_eq!(
            Selection::NONE.without_view_term().distance_fixed,
            UNIFORM_DISTANCE
        );
    }

    fn tree<'a>(views: &'a [Vec3], m: Affine3A) -> TreeView<'a> {
        TreeView {
            view_directions: views,
            crown_center: Vec3::Y * 5.0,
            crown_radius: 3.0,
            world_from_local: m,
        }
    }

    fn settings() -> FoliagePruningSettings {
        FoliagePruningSettings {
            distances: LodDistances::World {
                near: 10.0,
                far: 110.0,
            },
            ..Default::default()
        }
    }

    #[test]
    fn the_light_selects_from_its_own_direction_at_the_cameras_factor() {
        let views = fibonacci_directions(16);
        let t = tree(&views, Affine3A::IDENTITY);
        let camera = Vec3::new(60.0, 5.0, 0.0);
        let sun = ShadowLight::Directional {
            toward_light: Vec3::new(0.0, 1.0, 0.0),
        };
        let (cam, light) = select(&t, camera, &LodView::default(), Some(sun), &settings());
        let light = light.unwrap();
        assert_eq!(cam.distance_fixed, FIXED_ONE / 2, "60 m of 10..110 m");
        assert_eq!(light.distance_fixed, cam.distance_fixed);
        assert_eq!(
            light.weights,
            view_weights(Vec3::Y, &views, ViewWeighting::InverseAngle)
        );
        assert_ne!(light.weights, cam.weights);
        // A rotated tree sees the light in its own frame.
        let turned = tree(
            &views,
            Affine3A::from_rotation_translation(Quat::from_rotation_z(0.5), Vec3::ZERO),
        );
        let (_, turned_light) =
            select(&turned, camera, &LodView::default(), Some(sun), &settings());
        assert_eq!(
            turned_light.unwrap().weights,
            view_weights(
                Quat::from_rotation_z(-0.5) * Vec3::Y,
                &views,
                ViewWeighting::InverseAngle
            )
        );
        // A lamp: the direction from the crown to it.
        let lamp = ShadowLight::Positional {
            position: Vec3::new(0.0, 5.0, 20.0),
        };
        let (_, lamp_light) = select(&t, camera, &LodView::default(), Some(lamp), &settings());
        assert_eq!(
            lamp_light.unwrap().weights,
            view_weights(Vec3::Z, &views, ViewWeighting::InverseAngle)
        );
    }

    #[test]
    fn near_trees_cast_the_full_set_and_unplaceable_trees_nothing() {
        let views = fibonacci_directions(16);
        let t = tree(&views, Affine3A::IDENTITY);
        let sun = Some(ShadowLight::Directional {
            toward_light: Vec3::Y,
        });
        let (cam, light) = select(
            &t,
            Vec3::new(8.0, 5.0, 0.0),
            &LodView::default(),
            sun,
            &settings(),
        );
        assert_eq!(
            cam.distance_fixed, FIXED_ONE,
            "inside near, the camera drops hidden leaves"
        );
        assert_eq!(
            light,
            Some(Selection::ALL),
            "while the shadow keeps them all"
        );
        // Inside the crown: everything, and shadows draw the same.
        let (cam, light) = select(
            &t,
            Vec3::new(1.0, 5.0, 0.0),
            &LodView::default(),
            sun,
            &settings(),
        );
        assert_eq!((cam.distance_fixed, light), (KEEP_ALL, None));
        // Pruning off: the same.
        let off = FoliagePruningSettings {
            enabled: false,
            ..settings()
        };
        let (cam, light) = select(
            &t,
            Vec3::new(80.0, 5.0, 0.0),
            &LodView::default(),
            sun,
            &off,
        );
        assert_eq!((cam.distance_fixed, light), (KEEP_ALL, None));
        // Switched off: shadows draw the camera's selection.
        let off = FoliagePruningSettings {
            shadow_selection: false,
            ..settings()
        };
        let (_, light) = select(
            &t,
            Vec3::new(80.0, 5.0, 0.0),
            &LodView::default(),
            sun,
            &off,
        );
        assert_eq!(light, None);
        // No light: no light selection.
        let (_, light) = select(
            &t,
            Vec3::new(80.0, 5.0, 0.0),
            &LodView::default(),
            None,
            &settings(),
        );
        assert_eq!(light, None);
        // NaN or singular transforms draw nothing.
        for m in [
            Affine3A::from_translation(Vec3::NAN),
            Affine3A::from_scale(Vec3::ZERO),
        ] {
            let (cam, light) = select(
                &tree(&views, m),
                Vec3::X * 50.0,
                &LodView::default(),
                sun,
                &settings(),
            );
            assert_eq!((cam, light), (Selection::NONE, None));
        }
    }

    #[test]
    fn screen_size_distances_prune_a_tree_in_centimetres_like_one_in_metres() {
        let views = fibonacci_directions(16);
        let metres = tree(&views, Affine3A::IDENTITY);
        let centimetres = TreeView {
            crown_center: Vec3::Y * 500.0,
            crown_radius: 300.0,
            ..metres
        };
        let s = FoliagePruningSettings::default();
        for d in [12.0f32, 30.0, 90.0, 300.0] {
            let (a, _) = select(
                &metres,
                Vec3::new(d, 5.0, 0.0),
                &LodView::default(),
                None,
                &s,
            );
            let (b, _) = select(
                &centimetres,
                Vec3::new(d * 100.0, 500.0, 0.0),
                &LodView::default(),
                None,
                &s,
            );
            assert!(
                a.distance_fixed.abs_diff(b.distance_fixed) <= 1,
                "{d}: {a:?} {b:?}"
            );
        }
        // And so does a tree scaled by its transform.
        let scaled = tree(&views, Affine3A::from_scale(Vec3::splat(100.0)));
        let (a, _) = select(
            &metres,
            Vec3::new(40.0, 5.0, 0.0),
            &LodView::default(),
            None,
            &s,
        );
        let (b, _) = select(
            &scaled,
            Vec3::new(4000.0, 500.0, 0.0),
            &LodView::default(),
            None,
            &s,
        );
        assert!(a.distance_fixed.abs_diff(b.distance_fixed) <= 1);
    }
}
