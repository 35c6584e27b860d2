//! GPU time of whole frames from timestamp queries.
//!
//! Bevy's render diagnostics time the passes that open a span; shadow passes, copies and some
//! plugins' passes open none, and on a real GPU their work is not counted by a sum of spans.
//! This plugin brackets everything the frame's render graph records: the first command buffer
//! of the frame's submission writes a timestamp (pushed in `RenderGraphSystems::Begin`, so it is
//! submitted with the frame's own buffers, ahead of them, and the GPU does not sit idle between
//! them while the CPU records), and right after the submission another one is submitted. A
//! queue executes in order, and the second timestamp is written once the commands before it have
//! completed, so the difference is the GPU time of the whole frame — every pass, whoever added
//! it. (Screenshot and readback copies, submitted after the graph, are outside it.)
//!
//! The readback is asynchronous: a ring of mappable buffers, each frame's result arriving a frame
//! or two later in [`GpuFrameTimes`].

use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::render_resource::{
    Buffer, BufferDescriptor, BufferUsages, CommandEncoderDescriptor, ComputePassDescriptor,
    MapMode,
};
use bevy::render::renderer::{
    PendingCommandBuffers, RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use wgpu::{ComputePassTimestampWrites, QuerySet, QuerySetDescriptor, QueryType};

/// Readback buffers in flight.
const RING: usize = 4;

/// Whole-frame GPU times in ms, oldest first (main world; cleared by the harness between
/// measurements).
#[derive(Resource, Clone, Default)]
pub struct GpuFrameTimes(pub Arc<Mutex<Vec<f64>>>);

struct Slot {
    resolve: Buffer,
    readback: Buffer,
    /// Mapped and ready to read.
    ready: Arc<AtomicBool>,
    /// Holds a frame's timestamps not read yet.
    pending: bool,
}

#[derive(Resource)]
struct FrameTimer {
    queries: QuerySet,
    slots: Vec<Slot>,
    frame: usize,
    /// Nanoseconds per timestamp tick.
    period: f64,
    times: Arc<Mutex<Vec<f64>>>,
}

/// Adds [`GpuFrameTimes`] where the adapter has timestamp queries (nothing otherwise).
pub struct FrameTimerPlugin;

impl Plugin for FrameTimerPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<GpuFrameTimes>();
    }

    fn finish(&self, app: &mut App) {
        let times = app.world().resource::<GpuFrameTimes>().0.clone();
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        let device = render_app.world().resource::<RenderDevice>();
        if !device
            .features()
            .contains(bevy::render::render_resource::WgpuFeatures::TIMESTAMP_QUERY)
        {
            return;
        }
        let queries = device.wgpu_device().create_query_set(&QuerySetDescriptor {
            label: Some("frame_timer"),
            ty: QueryType::Timestamp,
            count: 2 * RING as u32,
        });
        let slots = (0..RING)
            .map(|_| Slot {
                resolve: device.create_buffer(&BufferDescriptor {
                    label: Some("frame_timer_resolve"),
                    size: 16,
                    usage: BufferUsages::QUERY_RESOLVE | BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                readback: device.create_buffer(&BufferDescriptor {
                    label: Some("frame_timer_readback"),
                    size: 16,
                    usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
                ready: Arc::new(AtomicBool::new(false)),
                pending: false,
            })
            .collect();
        let period = render_app
            .world()
            .resource::<RenderQueue>()
            .get_timestamp_period() as f64;
        render_app
            .insert_resource(FrameTimer {
                queries,
                slots,
                frame: 0,
                period,
                times,
            })
            .add_systems(
                RenderGraph,
                (
                    begin_frame.in_set(RenderGraphSystems::Begin),
                    end_frame.in_set(RenderGraphSystems::Finish),
                ),
            );
    }
}

/// A command buffer writing timestamp `index` at the end of an empty compute pass (once
/// everything before it has completed).
fn timestamp_commands(
    device: &RenderDevice,
    queries: &QuerySet,
    index: u32,
) -> bevy::render::render_resource::CommandEncoder {
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor {
        label: Some("frame_timer"),
    });
    encoder.begin_compute_pass(&ComputePassDescriptor {
        label: Some("frame_timer"),
        timestamp_writes: Some(ComputePassTimestampWrites {
            query_set: queries,
            beginning_of_pass_write_index: None,
            end_of_pass_write_index: Some(index),
        }),
    });
    encoder
}

fn begin_frame(
    device: Res<RenderDevice>,
    mut pending: ResMut<PendingCommandBuffers>,
    mut timer: ResMut<FrameTimer>,
) {
    let timer = &mut *timer;
    // Collect the frames whose readback has arrived.
    let period = timer.period;
    let times = timer.times.clone();
    for slot in &mut timer.slots {
        if slot.pending && slot.ready.load(Ordering::Acquire) {
            {
                let data = slot.readback.slice(..).get_mapped_range();
                let ticks: Vec<u64> = data
                    .chunks_exact(8)
                    .map(|c| u64::from_le_bytes(c.try_into().unwrap()))
                    .collect();
                if ticks[1] > ticks[0] {
                    times
                        .lock()
                        .unwrap()
                        .push((ticks[1] - ticks[0]) as f64 * period / 1e6);
                }
            }
            slot.readback.unmap();
            slot.ready.store(false, Ordering::Release);
            slot.pending = false;
        }
    }
    let index = timer.frame % RING;
    if timer.slots[index].pending {
        // Its readback has not arrived yet: this frame is not timed rather than waited for.
        return;
    }
    // The frame's first command buffer: submitted with (and ahead of) the graph's own.
    pending.push([timestamp_commands(&device, &timer.queries, 2 * index as u32).finish()]);
}

fn end_frame(device: Res<RenderDevice>, queue: Res<RenderQueue>, mut timer: ResMut<FrameTimer>) {
    let timer = &mut *timer;
    let index = timer.frame % RING;
    timer.frame += 1;
    if timer.slots[index].pending {
        return;
    }
    let slot = &mut timer.slots[index];
    let mut encoder = timestamp_commands(&device, &timer.queries, 2 * index as u32 + 1);
    let first = 2 * index as u32;
    encoder.resolve_query_set(&timer.queries, first..first + 2, &slot.resolve, 0);
    encoder.copy_buffer_to_buffer(&slot.resolve, 0, &slot.readback, 0, 16);
    queue.submit([encoder.finish()]);
    let ready = slot.ready.clone();
    slot.pending = true;
    slot.readback
        .slice(..)
        .map_async(MapMode::Read, move |result| {
            if result.is_ok() {
                ready.store(true, Ordering::Release);
            }
        });
}
