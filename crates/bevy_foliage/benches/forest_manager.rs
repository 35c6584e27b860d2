//! One forest-manager frame at 1k, 10k and 100k tree instances (4 types, 8 slots, budget of 16
//! extractions), the camera walking through the forest so every frame has work. Ranking is a
//! partial selection of the budget's chunk, so a frame should grow close to linearly with the
//! instance count, well under n·log n.
//!
//! `cargo bench --workspace --profile dev --bench forest_manager` (the dev profile builds
//! `bevy_foliage` at opt-level 3 and reuses the test build of Bevy; `cargo bench` works too but
//! first builds Bevy in release, about 14 minutes here).

use bevy::math::{Mat4, Vec3};
use bevy_foliage::forest::cache::LodSlots;
use bevy_foliage::forest::manager::{
    Budget, ForestManager, Frustum, ManagerSettings, TreeInput, TreeLodState,
};
use bevy_foliage::rng::SplitMix64;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

fn forest(n: usize) -> Vec<TreeInput> {
    // Density of the thesis' dense forest: 6,450 trees on about 800 m × 800 m.
    let side = 800.0 * (n as f32 / 6450.0).sqrt();
    let mut rng = SplitMix64::new(7);
    (0..n)
        .map(|_| TreeInput {
            ty: rng.below(4) as usize,
            center: Vec3::new(
                rng.range(-side, side) / 2.0,
                5.0,
                rng.range(-side, side) / 2.0,
            ),
            radius: 5.0,
        })
        .collect()
}

fn manager_frame(c: &mut Criterion) {
    let mut group = c.benchmark_group("forest_manager_frame");
    for n in [1_000usize, 10_000, 100_000] {
        let trees = forest(n);
        let mut states = vec![TreeLodState::default(); n];
        let mut manager = ForestManager::new(4, LodSlots::uniform(8), 30, false);
        let settings = ManagerSettings::default();
        let mut out = Vec::new();
        let mut step = 0u32;
        group.throughput(Throughput::Elements(n as u64));
        group.bench_function(BenchmarkId::from_parameter(n), |b| {
            b.iter(|| {
                step += 1;
                let t = step as f32 * 0.37;
                let camera = Vec3::new(60.0 * t.cos(), 2.0, 60.0 * t.sin());
                let look = camera + Vec3::new(-t.sin(), 0.0, t.cos());
                let frustum = Frustum::from_clip_from_world(
                    Mat4::perspective_infinite_reverse_rh(1.0, 16.0 / 9.0, 0.1)
                        * Mat4::look_at_rh(camera, look, Vec3::Y),
                );
                out.clear();
                manager.run_frame(
                    &trees,
                    &mut states,
                    camera,
                    Some(&frustum),
                    1.0,
                    &settings,
                    Budget::Extractions(16),
                    &mut out,
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, manager_frame);
criterion_main!(benches);
