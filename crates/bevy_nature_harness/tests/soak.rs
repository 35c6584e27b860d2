//! The soak run's measurements see what they must: a scene that keeps nothing has flat resident
//! and GPU series after its warm-up, and the same scene with a render system that keeps a new
//! 1 MiB GPU buffer every frame shows the GPU series climbing by that much.

use bevy::prelude::*;
use bevy::render::render_resource::{Buffer, BufferDescriptor, BufferUsages};
use bevy::render::renderer::RenderDevice;
use bevy::render::{Render, RenderApp};
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::soak::{Growth, soak_sampling_every};

/// Frames between samples here (the examples' soak samples every 500).
const INTERVAL: u32 = 100;

/// Buffers leaked so far.
#[derive(Resource, Default)]
struct Leaked(Vec<Buffer>);

const LEAK_BYTES: u64 = 1024 * 1024;

fn leak(device: Res<RenderDevice>, mut leaked: ResMut<Leaked>) {
    leaked.0.push(device.create_buffer(&BufferDescriptor {
        label: Some("leak"),
        size: LEAK_BYTES,
        usage: BufferUsages::STORAGE,
        mapped_at_creation: false,
    }));
}

/// GPU-allocated and resident bytes per sample of a 400-frame soak of a cube, leaking or not.
fn gpu_series(leaking: bool) -> Option<(Vec<u64>, Vec<u64>)> {
    let mut harness = RenderHarness::for_test("soak", 16, 16)?;
    let world = harness.world_mut();
    let mesh = world.resource_mut::<Assets<Mesh>>().add(Cuboid::default());
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial::default());
    world.spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    world.spawn((
        Camera3d::default(),
        Transform::from_xyz(2.0, 2.0, 2.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    if leaking {
        let render_app = harness.app_mut().sub_app_mut(RenderApp);
        render_app
            .init_resource::<Leaked>()
            .add_systems(Render, leak);
    }
    harness.wait_until_ready().unwrap();
    let samples = soak_sampling_every(&mut harness, "soak", 4 * INTERVAL, INTERVAL).unwrap();
    assert_eq!(samples.len(), 5);
    let gpu = samples
        .iter()
        .map(|s| s.gpu_allocated_bytes)
        .collect::<Option<Vec<_>>>();
    let rss = samples
        .iter()
        .map(|s| s.rss_bytes)
        .collect::<Option<Vec<_>>>();
    Some((
        gpu.expect("the Vulkan backend reports its allocations"),
        rss.expect("Linux reports the resident set"),
    ))
}

#[test]
fn the_soak_series_are_flat_without_a_leak_and_climb_with_one() {
    let Some((gpu, rss)) = gpu_series(false) else {
        return;
    };
    let (gpu_growth, rss_growth) = (Growth::of(&gpu).unwrap(), Growth::of(&rss).unwrap());
    eprintln!("no leak: GPU {gpu:?}, resident {rss:?}");
    assert!(gpu_growth.fraction() < 0.01, "{gpu_growth:?}");
    assert!(rss_growth.fraction() < 0.05, "{rss_growth:?}");
    let (leaky, _) = gpu_series(true).unwrap();
    eprintln!("leaking {LEAK_BYTES} bytes a frame: GPU {leaky:?}");
    // Every interval adds about INTERVAL leaked buffers.
    for pair in leaky.windows(2).skip(1) {
        let added = pair[1].saturating_sub(pair[0]);
        assert!(
            added >= INTERVAL as u64 * LEAK_BYTES * 9 / 10,
            "the leak shows: {leaky:?}"
        );
    }
    assert!(Growth::of(&leaky).unwrap().fraction() > 0.5);
}
