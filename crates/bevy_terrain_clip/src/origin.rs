//! Where render space lies in the world.
//!
//! Bevy's transforms are f32: 10^6 m from the origin a position is good to 6.25 cm, and a camera
//! there shakes and tears the ground at the centimetre scale of a finest texel. Large worlds
//! therefore keep the camera near render space's origin and move the origin instead (a floating
//! origin, as `big_space` does): [`RenderOrigin`] is the world position, in f64, of render
//! space's (0, 0, 0). The terrain's world coordinates — [`TextureMapping`]s, pyramid manifests,
//! [`resident_height`] — are world positions; the plugin converts them to render space in f64
//! before anything reaches f32, so with the camera near the render origin a terrain 10^6 m from
//! the world's origin draws as it would at the origin. With the default (zero) origin, render
//! space is world space.
//!
//! [`TextureMapping`]: crate::stack_gpu::TextureMapping
//! [`resident_height`]: crate::stack_gpu::ClipStackTexture::resident_height

use bevy::math::{DVec2, DVec3};
use bevy::prelude::*;

/// The world position (f64 metres) of render space's origin. Move it with the camera (and the
/// camera and the scene's other entities by the opposite amount) to keep transforms small.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Reflect)]
#[reflect(Resource, Default)]
pub struct RenderOrigin(pub DVec3);

impl RenderOrigin {
    /// The world position of a render-space point.
    pub fn world_of(&self, render: Vec3) -> DVec3 {
        self.0 + render.as_dvec3()
    }

    /// The world (x, z) of a render-space point.
    pub fn world_xz(&self, render: Vec3) -> DVec2 {
        let w = self.world_of(render);
        DVec2::new(w.x, w.z)
    }

    /// The render-space (x, z) of a world (x, z), computed in f64.
    pub fn render_xz(&self, world: DVec2) -> Vec2 {
        (world - DVec2::new(self.0.x, self.0.z)).as_vec2()
    }

    /// The render-space position of a world position, computed in f64.
    pub fn render_of(&self, world: DVec3) -> Vec3 {
        (world - self.0).as_vec3()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_space_is_world_space_less_the_origin_in_f64() {
        let origin = RenderOrigin(DVec3::new(1.0e6 + 0.3, 5.0, -2.0e6));
        // A world point 10^6 m out lands a few metres from the render origin, to the millimetre
        // (in f32 alone 10^6 + 0.3 rounds to a multiple of 6.25 cm).
        let world = DVec2::new(1.0e6 + 2.0125, -2.0e6 - 1.5);
        let render = origin.render_xz(world);
        assert!(
            (render - Vec2::new(1.7125, -1.5)).abs().max_element() < 1e-6,
            "{render}"
        );
        let back = origin.world_xz(Vec3::new(render.x, 0.0, render.y));
        assert!((back - world).abs().max_element() < 1e-6);
        assert_eq!(
            origin.render_of(DVec3::new(0.0, 7.0, 0.0)).y,
            2.0,
            "heights too"
        );
    }
}
