//! What the GPU bakes (billboard-cloud atlases, grass volume slices) share: knowing whether the
//! render world is still compiling pipelines, removing a readback's row padding, and deciding
//! when a readback shows the finished bake.
//!
//! A bake renders its parts with ordinary Bevy cameras and meshes and reads the target back every
//! frame. A readback can show an unfinished image in two ways: a pipeline was still compiling
//! when it was rendered (the meshes that need it are not drawn), or a part was never specialised
//! for its camera (Bevy 0.19 specialises a mesh for a view when it becomes visible there; a mesh
//! skipped then, for example because one of its render assets was not ready that frame, is only
//! tried again when its `Mesh3d` or material changes). Both can leave a stable, incomplete image,
//! so "two readbacks agree" alone is not enough: [`ReadbackSettling`] marks every part changed
//! once the parts have drawn and no pipeline is compiling, and takes only an image read after
//! that change took effect, with pipelines idle for long enough to cover a readback's latency.

use bevy::prelude::*;
use bevy::render::render_resource::PipelineCache;
use bevy::render::{Render, RenderApp, RenderSystems};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Whether the render world had no pipeline compiling in its last frame.
#[derive(Resource, Clone, Default)]
pub struct BakePipelinesIdle(pub Arc<AtomicBool>);

impl BakePipelinesIdle {
    /// Whether no pipeline was compiling in the render world's last frame.
    pub fn get(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// Keeps [`BakePipelinesIdle`] up to date (once, whichever bake registers it first).
pub(crate) fn track_pipelines_idle(app: &mut App) {
    if app.world().contains_resource::<BakePipelinesIdle>() {
        return;
    }
    let idle = BakePipelinesIdle::default();
    app.insert_resource(idle.clone());
    if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
        render_app
            .insert_resource(idle)
            .add_systems(Render, note_pipelines_idle.in_set(RenderSystems::Cleanup));
    }
}

fn note_pipelines_idle(cache: Res<PipelineCache>, idle: Res<BakePipelinesIdle>) {
    idle.0.store(
        cache.waiting_pipelines().next().is_none(),
        Ordering::Relaxed,
    );
}

/// Removes the 256-byte row padding of a texture readback of `bytes_per_texel`.
pub(crate) fn unpad_rows(
    padded: &[u8],
    width: u32,
    height: u32,
    bytes_per_texel: usize,
) -> Option<Vec<u8>> {
    let row = width as usize * bytes_per_texel;
    let stride = row.div_ceil(256) * 256;
    if height == 0 || padded.len() < stride * (height as usize - 1) + row {
        return None;
    }
    Some(
        (0..height as usize)
            .flat_map(|y| padded[y * stride..y * stride + row].iter().copied())
            .collect(),
    )
}

/// Frames after which a bake that never settles is given up.
pub(crate) const MAX_BAKE_FRAMES: u32 = 600;

/// Frames in a row without a pipeline compiling before a readback is trusted. A readback reaches
/// the main world two frames or more after the frame it shows, so "idle now" alone could accept
/// an image rendered while a pipeline was still missing.
pub(crate) const IDLE_FRAMES: u32 = 4;

/// Frames after the parts were marked changed before a readback is taken to show them
/// re-specialised (a frame for the change to be extracted, and the readback's latency).
pub(crate) const TOUCH_LATENCY: u32 = 4;

/// What a bake does after one frame of [`ReadbackSettling::step`].
#[derive(Debug, PartialEq)]
pub(crate) enum SettleStep {
    /// Keep rendering.
    Wait,
    /// The parts have drawn and no pipeline is compiling: mark every part's `Mesh3d` changed, so
    /// that a part Bevy skipped is specialised again, and keep rendering.
    Touch,
    /// The finished bake's pixels.
    Done(Vec<u8>),
}

/// Decides, frame by frame, when a bake's readback shows the finished bake (see the module docs).
#[derive(Debug, Default)]
pub(crate) struct ReadbackSettling {
    frames: u32,
    idle_frames: u32,
    touched_at: Option<u32>,
    previous: Option<Vec<u8>>,
    any_readback: bool,
}

impl ReadbackSettling {
    /// Frames stepped so far.
    #[cfg(test)]
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Why a bake that never finished did not, for its error message.
    pub fn failure(&self) -> &'static str {
        if self.any_readback {
            "the bake never settled"
        } else {
            "no readback arrived"
        }
    }

    /// One frame: `idle` whether no pipeline compiled in the render world's last frame, `pixels`
    /// the readback that arrived this frame (if any), `has_content` whether an image holds
    /// anything (an empty image is what a bake shows before its first draw).
    pub fn step(
        &mut self,
        idle: bool,
        pixels: Option<Vec<u8>>,
        has_content: impl Fn(&[u8]) -> bool,
    ) -> SettleStep {
        self.frames += 1;
        self.idle_frames = if idle { self.idle_frames + 1 } else { 0 };
        let Some(pixels) = pixels else {
            return SettleStep::Wait;
        };
        self.any_readback = true;
        let Some(touched_at) = self.touched_at else {
            // The first image with content shows the parts' assets prepared.
            if idle && has_content(&pixels) {
                self.touched_at = Some(self.frames);
                return SettleStep::Touch;
            }
            return SettleStep::Wait;
        };
        // A readback still in flight when the parts were touched shows them as they were.
        if self.frames < touched_at + TOUCH_LATENCY {
            return SettleStep::Wait;
        }
        if self.idle_frames >= IDLE_FRAMES
            && self.previous.as_ref() == Some(&pixels)
            && has_content(&pixels)
        {
            return SettleStep::Done(pixels);
        }
        self.previous = Some(pixels);
        SettleStep::Wait
    }
}

impl ReadbackSettling {
    /// One frame of a bake whose parts are `parts`: [`Self::step`], marking the parts changed
    /// when it says so. `None` while the bake goes on; the finished pixels, or why the bake was
    /// given up after [`MAX_BAKE_FRAMES`] frames.
    pub fn advance(
        &mut self,
        idle: bool,
        pixels: Option<Vec<u8>>,
        has_content: impl Fn(&[u8]) -> bool,
        parts: &[Entity],
        meshes: &mut Query<&mut Mesh3d>,
    ) -> Option<Result<Vec<u8>, String>> {
        match self.step(idle, pixels, has_content) {
            SettleStep::Done(pixels) => Some(Ok(pixels)),
            SettleStep::Touch => {
                touch_parts(parts, meshes);
                None
            }
            SettleStep::Wait => (self.frames > MAX_BAKE_FRAMES)
                .then(|| Err(format!("{} in {MAX_BAKE_FRAMES} frames", self.failure()))),
        }
    }
}

/// Marks every part's `Mesh3d` changed, so that Bevy specialises each again for its camera.
fn touch_parts(parts: &[Entity], meshes: &mut Query<&mut Mesh3d>) {
    for &part in parts {
        if let Ok(mut mesh) = meshes.get_mut(part) {
            mesh.set_changed();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(v: u8) -> Option<Vec<u8>> {
        Some(vec![v; 8])
    }

    fn any(p: &[u8]) -> bool {
        p.iter().any(|&b| b > 0)
    }

    /// Steps a settling with a readback every frame; returns the frame of each `Touch` and of
    /// `Done`, and the pixels taken.
    fn run(
        settling: &mut ReadbackSettling,
        frames: impl IntoIterator<Item = (bool, Option<Vec<u8>>)>,
    ) -> (Vec<u32>, Option<(u32, Vec<u8>)>) {
        let mut touches = Vec::new();
        for (idle, pixels) in frames {
            match settling.step(idle, pixels, any) {
                SettleStep::Wait => {}
                SettleStep::Touch => touches.push(settling.frames()),
                SettleStep::Done(p) => return (touches, Some((settling.frames(), p))),
            }
        }
        (touches, None)
    }

    #[test]
    fn a_steady_image_is_touched_once_then_taken() {
        let mut s = ReadbackSettling::default();
        let (touches, done) = run(&mut s, (0..20).map(|_| (true, image(7))));
        assert_eq!(touches, vec![1]);
        // Readbacks before the touch's latency are ignored; then two equal ones.
        let (frame, pixels) = done.expect("taken");
        assert_eq!(frame, 1 + TOUCH_LATENCY + 1);
        assert_eq!(pixels, vec![7; 8]);
    }

    #[test]
    fn an_image_read_while_a_pipeline_compiled_is_not_taken() {
        // The parts drew and the bake touched them at frame 1; then a pipeline compiles in
        // frames 3 to 6, and the readbacks until frame 8 show the image without it (1).
        let mut s = ReadbackSettling::default();
        let frames = (1..=30).map(|f| (!(3..=6).contains(&f), image(if f <= 8 { 1 } else { 2 })));
        let (touches, done) = run(&mut s, frames);
        assert_eq!(touches, vec![1]);
        // "Idle now and two equal readbacks" would have taken image 1 at frame 7.
        let (frame, pixels) = done.expect("taken");
        assert_eq!(pixels, vec![2; 8]);
        assert_eq!(frame, 6 + IDLE_FRAMES);
    }

    #[test]
    fn no_touch_before_the_parts_drew_and_pipelines_are_idle() {
        let mut s = ReadbackSettling::default();
        let frames = (1..=30).map(|f| (f > 5, image(if f <= 3 { 0 } else { 4 })));
        let (touches, done) = run(&mut s, frames);
        assert_eq!(touches, vec![6]);
        assert_eq!(done.expect("taken").0, 6 + TOUCH_LATENCY + 1);
    }

    #[test]
    fn a_part_restored_by_the_touch_is_in_the_image_taken() {
        // The image is stable but misses a part (1) until the touch shows in a readback, three
        // frames after it.
        let mut s = ReadbackSettling::default();
        let mut touched = None;
        let mut taken = None;
        for _ in 0..40 {
            let f = s.frames() + 1;
            let v = if touched.is_some_and(|t| f > t + 3) {
                2
            } else {
                1
            };
            match s.step(true, image(v), any) {
                SettleStep::Wait => {}
                SettleStep::Touch => touched = Some(s.frames()),
                SettleStep::Done(p) => {
                    taken = Some(p);
                    break;
                }
            }
        }
        assert_eq!(touched, Some(1));
        assert_eq!(taken.expect("taken"), vec![2; 8]);
    }

    #[test]
    fn compiling_again_restarts_the_wait_and_empty_images_are_never_taken() {
        let mut s = ReadbackSettling::default();
        // A pipeline compiles every third frame: never IDLE_FRAMES idle frames in a row.
        let (_, done) = run(&mut s, (1..=40).map(|f| (f % 3 != 0, image(3))));
        assert!(done.is_none());
        let mut s = ReadbackSettling::default();
        let (touches, done) = run(&mut s, (0..40).map(|_| (true, image(0))));
        assert!(touches.is_empty() && done.is_none());
        assert_eq!(s.failure(), "the bake never settled");
        let mut s = ReadbackSettling::default();
        let (_, done) = run(&mut s, (0..10).map(|_| (true, None)));
        assert!(done.is_none());
        assert_eq!(s.failure(), "no readback arrived");
    }

    #[test]
    fn unpadding_keeps_each_row() {
        // 3 texels of 4 bytes: 12 bytes a row, padded to 256.
        let mut padded = vec![0u8; 256 + 12];
        padded[..12].copy_from_slice(&[1; 12]);
        padded[256..].copy_from_slice(&[2; 12]);
        let rows = unpad_rows(&padded, 3, 2, 4).unwrap();
        assert_eq!(rows, [[1u8; 12], [2; 12]].concat());
        assert_eq!(unpad_rows(&padded[..200], 3, 2, 4), None);
        assert_eq!(unpad_rows(&padded, 3, 0, 4), None);
    }
}
