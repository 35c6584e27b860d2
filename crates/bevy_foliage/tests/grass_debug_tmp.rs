use bevy::prelude::*;
use bevy_foliage::grass::bake::GrassSliceBakeResult;
use bevy_foliage::grass::systems::GrassFieldState;
use bevy_foliage::grass::{GrassField, GrassPlugin};
use bevy_nature_harness::RenderHarness;
#[test]
fn debug_field_bake() {
    let mut harness = RenderHarness::for_test("dbg", 64, 32).unwrap();
    harness.app_mut().add_plugins(GrassPlugin);
    harness.world_mut().spawn((
        Camera3d::default(),
        Transform::from_xyz(0.0, 1.6, -10.0).looking_to(Vec3::new(0.15, -0.18, 1.0), Vec3::Y),
    ));
    harness.world_mut().spawn(GrassField {
        size: Vec2::splat(60.0),
        ..default()
    });
    harness.world_mut().spawn((
        DirectionalLight {
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.5, -0.7, 0.6), Vec3::Y),
    ));
    for f in 0..14 {
        let t = std::time::Instant::now();
        harness.step();
        let w = harness.world_mut();
        let results = w.query::<&GrassSliceBakeResult>().iter(w).count();
        let ready = w
            .query::<&GrassFieldState>()
            .iter(w)
            .map(|s| (s.slices_settled(), s.slice_nodes))
            .collect::<Vec<_>>();
        let (waiting, total) = (0, 0);
        eprintln!(
            "frame {f} {:?} results {results} ready {ready:?} pipelines {waiting}/{total}",
            t.elapsed()
        );
    }
}
