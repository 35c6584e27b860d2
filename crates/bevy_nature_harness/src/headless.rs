//! [`RenderHarness`]: a windowless Bevy app that renders into an offscreen image and reads it back.
//!
//! How a frame is known to have truly rendered: Bevy compiles pipelines asynchronously and
//! specialises new ones when meshes first become visible, so the first frames draw nothing or
//! only part of the scene. The harness steps the app until the render world's
//! [`PipelineCache`] has had no waiting pipelines, and an unchanged pipeline count, for a few
//! consecutive frames (plus any extra condition the test gives, such as "the glTF is loaded"),
//! and only then captures a screenshot of the target image. A pipeline that fails to compile is
//! an error with the shader message, not a black image.
//!
//! The app is not pipelined (the render world runs inside `App::update`), so the wall time of
//! one update is the time of a whole frame, CPU and GPU, and readbacks see the frame just drawn.
//!
//! Every camera spawned in the harness that targets a window is redirected to the harness'
//! target image, so example scenes run unchanged with and without a window.

use crate::adapter::{AdapterSummary, probe_adapter, require_adapter};
use crate::compare::RgbaImage;
use crate::stats::{FrameStats, RunStats, collect_diagnostics};
use bevy::app::PluginsState;
use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::diagnostic::DiagnosticsStore;
use bevy::prelude::*;
use bevy::render::error_handler::{RenderError, RenderErrorHandler, RenderErrorPolicy};
use bevy::render::gpu_readback::{Readback, ReadbackComplete};
use bevy::render::pipelined_rendering::PipelinedRenderingPlugin;
use bevy::render::render_resource::{
    Buffer, BufferDescriptor, BufferUsages, CachedPipeline, CachedPipelineState,
    CommandEncoderDescriptor, Extent3d, Origin3d, PipelineCache, PipelineDescriptor,
    TexelCopyBufferInfo, TexelCopyBufferLayout, TexelCopyTextureInfo, Texture, TextureAspect,
    TextureDimension, TextureFormat, TextureUsages,
};
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy::render::storage::ShaderBuffer;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use bevy::render::{RenderApp, RenderPlugin};
use bevy::shader::ShaderCacheError;
use bevy::window::ExitCondition;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Why the harness could not produce what was asked.
#[derive(Debug)]
pub enum HarnessError {
    /// No GPU adapter (see [`crate::adapter`]).
    NoAdapter,
    /// A render pipeline failed to compile; the shader errors are listed.
    Pipeline(Vec<String>),
    /// Pipelines were still compiling (or the extra readiness condition was false) after the
    /// given number of frames.
    NotReady {
        /// Frames stepped.
        frames: u32,
        /// Pipelines still waiting.
        waiting: usize,
    },
    /// A readback did not complete within the given number of frames.
    ReadbackTimeout(u32),
    /// The read-back data could not be interpreted.
    Readback(String),
    /// The renderer stopped on an error wgpu reported (a validation error, out of memory, a
    /// lost device): its kind and description. Rendering does not resume in this harness.
    Render(String),
}

impl std::fmt::Display for HarnessError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoAdapter => write!(f, "no GPU adapter found"),
            Self::Pipeline(errors) => {
                write!(f, "{} pipeline(s) failed to compile:", errors.len())?;
                for e in errors {
                    write!(f, "\n  {e}")?;
                }
                Ok(())
            }
            Self::NotReady { frames, waiting } => write!(
                f,
                "scene not ready after {frames} frames ({waiting} pipelines still compiling)"
            ),
            Self::ReadbackTimeout(frames) => {
                write!(f, "readback did not complete within {frames} frames")
            }
            Self::Readback(msg) => write!(f, "readback failed: {msg}"),
            Self::Render(msg) => write!(f, "the renderer stopped on an error: {msg}"),
        }
    }
}

impl std::error::Error for HarnessError {}

/// How the harness app is built.
#[derive(Clone, Debug)]
pub struct HarnessConfig {
    /// Size of the offscreen target in pixels.
    pub size: UVec2,
    /// Record GPU pass times with Bevy's `RenderDiagnosticsPlugin` (timestamp queries, where
    /// the adapter supports them; CPU span times otherwise).
    pub gpu_timing: bool,
    /// Keep Bevy's `LogPlugin` (warnings and errors only unless `RUST_LOG` says otherwise).
    pub log: bool,
    /// Give up waiting for pipelines after this many frames.
    pub max_warmup_frames: u32,
    /// Consecutive frames with no pipeline waiting before the scene counts as ready.
    pub stable_frames: u32,
    /// Compile pipelines on the render thread as they are queued instead of asynchronously.
    pub synchronous_pipeline_compilation: bool,
}

impl Default for HarnessConfig {
    fn default() -> Self {
        Self {
            size: UVec2::new(160, 120),
            gpu_timing: true,
            log: true,
            max_warmup_frames: 600,
            stable_frames: 3,
            synchronous_pipeline_compilation: false,
        }
    }
}

impl HarnessConfig {
    /// The default configuration with a target of `width × height`.
    pub fn sized(width: u32, height: u32) -> Self {
        Self {
            size: UVec2::new(width, height),
            ..default()
        }
    }
}

/// The offscreen image every window-targeting camera of the harness renders into.
#[derive(Resource, Clone, Debug)]
pub struct HeadlessTarget(pub Handle<Image>);

/// Creates the RGBA8 sRGB offscreen target image: renderable, copyable (screenshots and
/// readbacks) and sampleable.
pub fn create_target_image(images: &mut Assets<Image>, size: UVec2) -> Handle<Image> {
    let mut image = Image::new_target_texture(size.x, size.y, TextureFormat::Rgba8UnormSrgb, None);
    image.texture_descriptor.usage = TextureUsages::RENDER_ATTACHMENT
        | TextureUsages::COPY_SRC
        | TextureUsages::COPY_DST
        | TextureUsages::TEXTURE_BINDING;
    image.asset_usage = RenderAssetUsages::RENDER_WORLD;
    images.add(image)
}

/// Redirects cameras that target a window to the headless target image.
fn redirect_window_cameras(
    add: On<Add, Camera>,
    target: Res<HeadlessTarget>,
    targets: Query<&RenderTarget>,
    mut commands: Commands,
) {
    let redirect = match targets.get(add.entity) {
        Ok(RenderTarget::Window(_)) | Err(_) => true,
        Ok(_) => false,
    };
    if redirect {
        commands
            .entity(add.entity)
            .insert(RenderTarget::Image(target.0.clone().into()));
    }
}

/// Adds Bevy's default plugins configured for offscreen rendering: no window, no winit, the
/// render world run inside `App::update`.
pub fn add_headless_plugins(app: &mut App, config: &HarnessConfig) {
    let mut plugins = DefaultPlugins
        .build()
        .set(WindowPlugin {
            primary_window: None,
            exit_condition: ExitCondition::DontExit,
            close_when_requested: false,
            ..default()
        })
        .set(RenderPlugin {
            synchronous_pipeline_compilation: config.synchronous_pipeline_compilation,
            ..default()
        });
    if plugins.contains::<PipelinedRenderingPlugin>() {
        plugins = plugins.disable::<PipelinedRenderingPlugin>();
    }
    #[cfg(feature = "windowed")]
    if plugins.contains::<bevy::winit::WinitPlugin>() {
        plugins = plugins.disable::<bevy::winit::WinitPlugin>();
    }
    if config.log {
        plugins = plugins.set(bevy::log::LogPlugin {
            filter: "warn,wgpu_hal=error,wgpu_core=error,naga=warn".into(),
            ..default()
        });
    } else {
        plugins = plugins.disable::<bevy::log::LogPlugin>();
    }
    app.add_plugins(plugins);
    if config.gpu_timing {
        app.add_plugins((
            bevy::render::diagnostic::RenderDiagnosticsPlugin,
            crate::frame_timer::FrameTimerPlugin,
        ));
    }
}

/// The first error the renderer stopped on (main world), recorded by [`record_render_error`].
#[derive(Resource, Clone, Debug)]
struct HarnessRenderError(String);

/// The harness's render-error policy: Bevy's default asks the app to exit, which a harness
/// stepping frames by hand never sees — its readbacks then time out with no hint of the cause.
/// This records the error for the harness to return, and stops rendering as Bevy would.
fn record_render_error(
    error: &RenderError,
    main_world: &mut World,
    _render_world: &mut World,
) -> RenderErrorPolicy {
    if !main_world.contains_resource::<HarnessRenderError>() {
        main_world.insert_resource(HarnessRenderError(format!(
            "{:?}: {}",
            error.ty, error.description
        )));
    }
    RenderErrorPolicy::StopRendering
}

/// A windowless Bevy app rendering into an offscreen image. See the module docs.
pub struct RenderHarness {
    app: App,
    config: HarnessConfig,
    target: Handle<Image>,
    adapter: Option<AdapterSummary>,
    frame_times: Vec<Duration>,
    warmup_frames: u32,
    ready: bool,
    recaptures: u32,
}

impl RenderHarness {
    /// For render tests: a harness of `width × height`, or `None` when there is no adapter and
    /// the test should skip (never under `CI=true`: see [`require_adapter`]).
    pub fn for_test(test: &str, width: u32, height: u32) -> Option<Self> {
        require_adapter(test)?;
        Some(
            Self::new(HarnessConfig {
                log: true,
                ..HarnessConfig::sized(width, height)
            })
            .unwrap_or_else(|e| panic!("{test}: {e}")),
        )
    }

    /// A harness with a fresh app built from `config`.
    pub fn new(config: HarnessConfig) -> Result<Self, HarnessError> {
        let mut app = App::new();
        add_headless_plugins(&mut app, &config);
        Self::from_app(app, config)
    }

    /// Wraps an app that already has its plugins (e.g. from [`add_headless_plugins`] plus the
    /// crate under test). Creates the target image and the camera redirection.
    pub fn from_app(mut app: App, config: HarnessConfig) -> Result<Self, HarnessError> {
        let adapter = probe_adapter();
        if adapter.is_none() {
            return Err(HarnessError::NoAdapter);
        }
        let target = {
            let mut images = app.world_mut().resource_mut::<Assets<Image>>();
            create_target_image(&mut images, config.size)
        };
        app.insert_resource(HeadlessTarget(target.clone()))
            .insert_resource(RenderErrorHandler(record_render_error));
        app.add_observer(redirect_window_cameras);
        Ok(Self {
            app,
            config,
            target,
            adapter,
            frame_times: Vec::new(),
            warmup_frames: 0,
            recaptures: 0,
            ready: false,
        })
    }

    /// The app, to add plugins, systems and entities before the first frame.
    pub fn app_mut(&mut self) -> &mut App {
        &mut self.app
    }

    /// The app, to read state.
    pub fn app(&self) -> &App {
        &self.app
    }

    /// The main world.
    pub fn world_mut(&mut self) -> &mut World {
        self.app.world_mut()
    }

    /// The offscreen target image.
    pub fn target(&self) -> Handle<Image> {
        self.target.clone()
    }

    /// Target size in pixels.
    pub fn size(&self) -> UVec2 {
        self.config.size
    }

    /// The adapter in use.
    pub fn adapter(&self) -> Option<&AdapterSummary> {
        self.adapter.as_ref()
    }

    /// Finishes plugin setup the way `App::run` would (waiting for the renderer to initialise).
    fn finish_setup(&mut self) {
        if self.app.plugins_state() == PluginsState::Cleaned {
            return;
        }
        while self.app.plugins_state() == PluginsState::Adding {
            bevy::tasks::tick_global_task_pools_on_main_thread();
            std::thread::yield_now();
        }
        self.app.finish();
        self.app.cleanup();
    }

    /// Runs one frame and returns its wall time.
    pub fn step(&mut self) -> Duration {
        self.finish_setup();
        let start = Instant::now();
        self.app.update();
        start.elapsed()
    }

    /// The error the renderer stopped on, if it did: every frame after it renders nothing.
    pub fn render_error(&self) -> Option<HarnessError> {
        self.app
            .world()
            .get_resource::<HarnessRenderError>()
            .map(|e| HarnessError::Render(e.0.clone()))
    }

    /// [`Self::step`], failing once the renderer has stopped on an error.
    fn step_checked(&mut self) -> Result<Duration, HarnessError> {
        let dt = self.step();
        match self.render_error() {
            Some(e) => Err(e),
            None => Ok(dt),
        }
    }

    /// Pipelines still compiling, total pipelines, and the errors of failed ones.
    fn pipeline_status(&self) -> (usize, usize, Vec<String>) {
        let Some(cache) = self.pipeline_cache() else {
            return (0, 0, Vec::new());
        };
        let (mut waiting, mut total) = (0, 0);
        let mut errors = Vec::new();
        for pipeline in cache.pipelines() {
            total += 1;
            if is_compiling(pipeline) {
                waiting += 1;
            } else if let CachedPipelineState::Err(err) = &pipeline.state {
                errors.push(format!(
                    "{}: {err}",
                    pipeline_label(pipeline).unwrap_or("<unnamed>")
                ));
            }
        }
        (waiting, total, errors)
    }

    /// Pipelines still compiling, leaving out the screenshot's own: Bevy specialises
    /// `screenshot-to-screen` with the first capture, and it only draws a capture onto a window's
    /// surface — never into the image read back.
    fn scene_pipelines_compiling(&self) -> usize {
        self.pipeline_cache().map_or(0, |cache| {
            cache
                .pipelines()
                .filter(|&pipeline| {
                    is_compiling(pipeline)
                        && pipeline_label(pipeline) != Some("screenshot-to-screen")
                })
                .count()
        })
    }

    fn pipeline_cache(&self) -> Option<&PipelineCache> {
        self.app
            .get_sub_app(RenderApp)?
            .world()
            .get_resource::<PipelineCache>()
    }

    /// Steps frames until no pipeline is compiling for [`HarnessConfig::stable_frames`]
    /// consecutive frames. Returns the number of frames stepped.
    pub fn wait_until_ready(&mut self) -> Result<u32, HarnessError> {
        self.wait_until(|_| true)
    }

    /// Like [`wait_until_ready`](Self::wait_until_ready), with an extra condition on the main
    /// world (e.g. an asset finished loading, a bake completed).
    pub fn wait_until(
        &mut self,
        condition: impl FnMut(&mut World) -> bool,
    ) -> Result<u32, HarnessError> {
        self.wait_until_reporting(condition, |_, _| {})
    }

    /// [`Self::wait_until`], calling `report` after each frame with the frames stepped so far
    /// and the pipelines still compiling (for progress output on a slow adapter).
    pub fn wait_until_reporting(
        &mut self,
        mut condition: impl FnMut(&mut World) -> bool,
        mut report: impl FnMut(u32, usize),
    ) -> Result<u32, HarnessError> {
        let mut stable = 0;
        let mut last_total = usize::MAX;
        for frame in 1..=self.config.max_warmup_frames {
            self.step_checked()?;
            self.warmup_frames += 1;
            let (waiting, total, errors) = self.pipeline_status();
            if !errors.is_empty() {
                return Err(HarnessError::Pipeline(errors));
            }
            report(frame, waiting);
            let settled = waiting == 0 && total == last_total && condition(self.app.world_mut());
            last_total = total;
            stable = if settled { stable + 1 } else { 0 };
            if stable >= self.config.stable_frames {
                self.ready = true;
                return Ok(frame);
            }
        }
        let (waiting, _, _) = self.pipeline_status();
        Err(HarnessError::NotReady {
            frames: self.config.max_warmup_frames,
            waiting,
        })
    }

    fn ensure_ready(&mut self) -> Result<(), HarnessError> {
        if !self.ready {
            self.wait_until_ready()?;
        }
        Ok(())
    }

    /// Runs one frame and waits until the GPU has finished all the work it submitted, returning
    /// the wall time of both together: a frame time that includes the GPU, not just the CPU's
    /// submission (the renderer runs inside `App::update` here, unpipelined).
    pub fn step_gpu_synchronised(&mut self) -> Result<Duration, HarnessError> {
        self.finish_setup();
        let start = Instant::now();
        self.app.update();
        if let Some(e) = self.render_error() {
            return Err(e);
        }
        let device = self
            .app
            .get_sub_app(RenderApp)
            .and_then(|r| r.world().get_resource::<RenderDevice>())
            .ok_or_else(|| HarnessError::Readback("no render device".into()))?
            .clone();
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| HarnessError::Readback(e.to_string()))?;
        Ok(start.elapsed())
    }

    /// Runs `frames` measured frames like [`Self::run_frames`], each timed with
    /// [`Self::step_gpu_synchronised`].
    pub fn run_frames_gpu_synchronised(&mut self, frames: u32) -> Result<(), HarnessError> {
        self.ensure_ready()?;
        for _ in 0..frames {
            let dt = self.step_gpu_synchronised()?;
            self.frame_times.push(dt);
        }
        Ok(())
    }

    /// Runs `frames` measured frames (after the scene is ready), recording each frame's time.
    pub fn run_frames(&mut self, frames: u32) -> Result<(), HarnessError> {
        self.ensure_ready()?;
        for _ in 0..frames {
            let dt = self.step_checked()?;
            self.frame_times.push(dt);
        }
        Ok(())
    }

    /// Forgets the measured frame times (e.g. between two configurations measured in one run).
    pub fn reset_timing(&mut self) {
        self.frame_times.clear();
        if let Some(times) = self
            .app
            .world()
            .get_resource::<crate::frame_timer::GpuFrameTimes>()
        {
            times.0.lock().unwrap().clear();
        }
        if let Some(mut store) = self.app.world_mut().get_resource_mut::<DiagnosticsStore>() {
            for diagnostic in store.iter_mut() {
                diagnostic.clear_history();
            }
        }
    }

    /// Statistics of the measured frames.
    pub fn frame_stats(&self) -> FrameStats {
        FrameStats::from_durations(&self.frame_times)
    }

    /// A full report: frame time, GPU pass times, every published diagnostic.
    pub fn run_stats(&self, name: &str) -> RunStats {
        let (gpu_pass_ms, diagnostics) = self
            .app
            .world()
            .get_resource::<DiagnosticsStore>()
            .map(collect_diagnostics)
            .unwrap_or_default();
        RunStats {
            name: name.to_string(),
            size: [self.config.size.x, self.config.size.y],
            mode: "headless".into(),
            adapter: self.adapter.clone(),
            warmup_frames: self.warmup_frames,
            frame_time: self.frame_stats(),
            gpu_pass_ms,
            diagnostics,
        }
    }

    /// The latest value of a Bevy diagnostic (a plugin counter such as `foliage/triangles_drawn`).
    pub fn diagnostic(&self, path: &bevy::diagnostic::DiagnosticPath) -> Option<f64> {
        self.app
            .world()
            .get_resource::<DiagnosticsStore>()?
            .get(path)?
            .value()
    }

    /// Whether GPU pass times come from timestamp queries (the adapter supports them and
    /// [`HarnessConfig::gpu_timing`] is on).
    pub fn has_gpu_timestamps(&self) -> bool {
        self.config.gpu_timing && self.adapter.as_ref().is_some_and(|a| a.timestamp_queries)
    }

    /// Median GPU time in ms of a named render pass from timestamp queries, over the frames since
    /// the last [`reset_timing`](Self::reset_timing) — an error, never a fallback, when the
    /// adapter has no timestamp queries or the pass recorded no span.
    pub fn gpu_pass_time_ms(&self, pass: &str) -> Result<f64, String> {
        if !self.has_gpu_timestamps() {
            return Err("no GPU timestamp queries on this adapter".into());
        }
        let store = self
            .app
            .world()
            .get_resource::<DiagnosticsStore>()
            .ok_or("no diagnostics store")?;
        collect_diagnostics(store)
            .0
            .get(pass)
            .copied()
            .ok_or_else(|| format!("no GPU timestamp span '{pass}' was recorded"))
    }

    /// Median over the frames since the last [`reset_timing`](Self::reset_timing) of the GPU
    /// time of the whole frame: timestamps written before and after everything the frame submits
    /// ([`frame_timer`](crate::frame_timer): shadow maps, prepasses, main passes,
    /// post-processing, any plugin's passes). Results arrive a frame or two late: step a few
    /// frames after the measured ones. An error without timestamp queries or without results.
    pub fn gpu_frame_time_ms(&self) -> Result<f64, String> {
        if !self.has_gpu_timestamps() {
            return Err("no GPU timestamp queries on this adapter".into());
        }
        let times = self
            .app
            .world()
            .get_resource::<crate::frame_timer::GpuFrameTimes>()
            .ok_or("the frame timer is not installed")?
            .0
            .lock()
            .unwrap()
            .clone();
        if times.is_empty() {
            return Err("no whole-frame GPU timestamps were read back".into());
        }
        Ok(FrameStats::from_millis(&times).median_ms)
    }

    /// Median GPU (or, without timestamp queries, CPU span) time in ms of a named render pass,
    /// e.g. `"main_opaque_pass_3d"`, over the frames since the last [`reset_timing`](Self::reset_timing).
    pub fn pass_time_ms(&self, pass: &str) -> Option<f64> {
        let store = self.app.world().get_resource::<DiagnosticsStore>()?;
        let (gpu, other) = collect_diagnostics(store);
        gpu.get(pass)
            .copied()
            .or_else(|| other.get(&format!("render/{pass}/elapsed_cpu")).copied())
    }

    /// Steps frames until `slot` is filled, at most `max_frames`, each waiting for the GPU: a
    /// readback completes a frame or two after its copy is submitted, and frames that queue GPU
    /// work faster than a heavy scene executes it would run out the count first.
    fn step_until<T>(
        &mut self,
        slot: &Arc<Mutex<Option<T>>>,
        max_frames: u32,
    ) -> Result<T, HarnessError> {
        for _ in 0..max_frames {
            self.step_gpu_synchronised()?;
            if let Some(value) = slot.lock().unwrap().take() {
                return Ok(value);
            }
        }
        Err(HarnessError::ReadbackTimeout(max_frames))
    }

    /// Waits until the scene is ready, renders a frame and returns its pixels.
    ///
    /// A capture whose frame still had pipelines compiling is taken again once they are ready:
    /// an entity spawned (or a setting changed) after the scene first became ready needs new
    /// pipeline variants, compiled asynchronously, and the frame drawn before they are ready
    /// simply leaves those draws out — on a software adapter shared with other tests' threads
    /// that can outlast any fixed number of frames stepped before the capture.
    pub fn render(&mut self) -> Result<RgbaImage, HarnessError> {
        self.ensure_ready()?;
        for _ in 0..3 {
            let (image, complete) = self.capture()?;
            if complete {
                return RgbaImage::from_bevy(image).map_err(HarnessError::Readback);
            }
            self.recaptures += 1;
            bevy::log::warn!(
                "render: the captured frame still had scene pipelines compiling; \
                 capturing again once they are ready"
            );
            self.wait_until_ready()?;
        }
        let (waiting, _, _) = self.pipeline_status();
        Err(HarnessError::NotReady {
            frames: self.config.max_warmup_frames,
            waiting,
        })
    }

    /// How many captures [`render`](Self::render) took again because their frame still had
    /// pipelines compiling.
    pub fn recaptures(&self) -> u32 {
        self.recaptures
    }

    /// Captures the next frame; `true` with it when no pipeline was still compiling after that
    /// frame, i.e. every draw it queued had its pipeline.
    fn capture(&mut self) -> Result<(Image, bool), HarnessError> {
        let slot: Arc<Mutex<Option<Image>>> = Arc::default();
        let sink = slot.clone();
        self.app
            .world_mut()
            .spawn(Screenshot::image(self.target.clone()))
            .observe(move |captured: On<ScreenshotCaptured>| {
                *sink.lock().unwrap() = Some(captured.image.clone());
            });
        // The screenshot copies the frame it is extracted in: the first one stepped.
        self.step_gpu_synchronised()?;
        let waiting = self.scene_pipelines_compiling();
        if let Some(image) = slot.lock().unwrap().take() {
            return Ok((image, waiting == 0));
        }
        // Up to 120 frames: after a settings change the next frame may wait on a new pipeline
        // variant, compiled asynchronously, which on a software adapter shared with other
        // tests' threads has outlasted 30 frames. Frames after the capture are not stepped.
        let image = self.step_until(&slot, 119)?;
        Ok((image, waiting == 0))
    }

    /// Reads back the contents of a [`ShaderBuffer`] asset after the next frame.
    pub fn read_shader_buffer(
        &mut self,
        buffer: Handle<ShaderBuffer>,
    ) -> Result<Vec<u8>, HarnessError> {
        self.read_back(Readback::buffer(buffer))
    }

    /// Spawns `readback`, steps until its data arrives (30 frames at most) and despawns it.
    fn read_back(&mut self, readback: Readback) -> Result<Vec<u8>, HarnessError> {
        self.finish_setup();
        let slot: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();
        let sink = slot.clone();
        let entity = self
            .app
            .world_mut()
            .spawn(readback)
            .observe(move |done: On<ReadbackComplete>| {
                *sink.lock().unwrap() = Some(done.data.clone());
            })
            .id();
        let result = self.step_until(&slot, 30);
        self.app.world_mut().despawn(entity);
        result
    }

    /// Reads back a 2D [`Image`] asset's texture after the next frame: `height` rows of
    /// `width · bytes_per_texel` bytes (the copy's 256-byte row padding removed).
    pub fn read_image(
        &mut self,
        image: Handle<Image>,
        width: u32,
        height: u32,
        bytes_per_texel: u32,
    ) -> Result<Vec<u8>, HarnessError> {
        let padded = self.read_back(Readback::texture(image))?;
        let row = (width * bytes_per_texel) as usize;
        let stride = row.div_ceil(256) * 256;
        if height > 1 && padded.len() < stride * (height as usize - 1) + row {
            return Err(HarnessError::Readback(format!(
                "image readback of {} bytes is too short for {width}×{height}",
                padded.len()
            )));
        }
        let stride = if height > 1 { stride } else { row };
        Ok((0..height as usize)
            .flat_map(|y| padded[y * stride..y * stride + row].iter().copied())
            .collect())
    }

    /// Reads back a buffer that lives in the render world (e.g. one a render system created).
    /// `find` picks the buffer from the render world; `None` means "not created yet" and the
    /// harness steps another frame. Copies it into a mappable staging buffer and waits.
    pub fn read_render_buffer(
        &mut self,
        mut find: impl FnMut(&World) -> Option<Buffer>,
    ) -> Result<Vec<u8>, HarnessError> {
        self.finish_setup();
        for _ in 0..30 {
            let render_world = self
                .app
                .get_sub_app(RenderApp)
                .ok_or(HarnessError::NoAdapter)?
                .world();
            if let Some(buffer) = find(render_world) {
                let device = render_world.resource::<RenderDevice>();
                let queue = render_world.resource::<RenderQueue>();
                return read_buffer_now(device, queue, &buffer);
            }
            self.step_checked()?;
        }
        Err(HarnessError::ReadbackTimeout(30))
    }
}

/// Whether a pipeline is still being compiled: queued, being created, or waiting on a shader
/// that is still loading (Bevy retries those; they are not failures).
fn is_compiling(pipeline: &CachedPipeline) -> bool {
    match &pipeline.state {
        CachedPipelineState::Queued | CachedPipelineState::Creating(_) => true,
        CachedPipelineState::Err(err) => matches!(
            err,
            ShaderCacheError::ShaderNotLoaded(_) | ShaderCacheError::ShaderImportNotYetAvailable
        ),
        CachedPipelineState::Ok(_) => false,
    }
}

/// A pipeline's label, render or compute.
fn pipeline_label(pipeline: &CachedPipeline) -> Option<&str> {
    match &pipeline.descriptor {
        PipelineDescriptor::RenderPipelineDescriptor(d) => d.label.as_deref(),
        PipelineDescriptor::ComputePipelineDescriptor(d) => d.label.as_deref(),
    }
}

/// Reads back layers `0..layers` of mip `mip` of a 2D (array) `texture` whose texels are
/// `texel_bytes` long: copies them into a buffer, submits, blocks until it is mapped, and returns
/// the texels tightly packed — row after row, layer after layer, without the copy's 256-byte row
/// padding.
pub fn read_texture_now(
    device: &RenderDevice,
    queue: &RenderQueue,
    texture: &Texture,
    mip: u32,
    layers: u32,
    texel_bytes: u32,
) -> Result<Vec<u8>, HarnessError> {
    let size = texture.size().mip_level_size(mip, TextureDimension::D2);
    let tight = size.width * texel_bytes;
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let padded = tight.div_ceil(align) * align;
    let buffer = device.create_buffer(&BufferDescriptor {
        label: Some("harness_texture_readback"),
        size: (padded * size.height * layers) as u64,
        usage: BufferUsages::COPY_DST | BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor {
        label: Some("harness_texture_readback"),
    });
    encoder.copy_texture_to_buffer(
        TexelCopyTextureInfo {
            texture,
            mip_level: mip,
            origin: Origin3d::ZERO,
            aspect: TextureAspect::All,
        },
        TexelCopyBufferInfo {
            buffer: &buffer,
            layout: TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(size.height),
            },
        },
        Extent3d {
            width: size.width,
            height: size.height,
            depth_or_array_layers: layers,
        },
    );
    queue.submit([encoder.finish()]);
    let bytes = read_buffer_now(device, queue, &buffer)?;
    Ok(bytes
        .chunks_exact(padded as usize)
        .flat_map(|row| &row[..tight as usize])
        .copied()
        .collect())
}

/// Copies `buffer` into a staging buffer, submits, and blocks until it is mapped.
pub fn read_buffer_now(
    device: &RenderDevice,
    queue: &RenderQueue,
    buffer: &Buffer,
) -> Result<Vec<u8>, HarnessError> {
    let size = buffer.size();
    let staging = device.create_buffer(&BufferDescriptor {
        label: Some("harness_readback_staging"),
        size,
        usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor {
        label: Some("harness_readback"),
    });
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    staging
        .slice(..)
        .map_async(bevy::render::render_resource::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| HarnessError::Readback(e.to_string()))?;
    rx.recv()
        .map_err(|e| HarnessError::Readback(e.to_string()))?
        .map_err(|e| HarnessError::Readback(e.to_string()))?;
    let data = staging.slice(..).get_mapped_range().to_vec();
    staging.unmap();
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy::render::render_resource::{BufferDescriptor, BufferUsages};
    use bevy::render::{Render, RenderSystems};

    /// Writes past the end of a 16-byte buffer once: a wgpu validation error.
    fn overrun(device: Res<RenderDevice>, queue: Res<RenderQueue>, mut done: Local<bool>) {
        if std::mem::replace(&mut *done, true) {
            return;
        }
        let buffer = device.create_buffer(&BufferDescriptor {
            label: Some("harness_overrun_test"),
            size: 16,
            usage: BufferUsages::COPY_DST | BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        queue.write_buffer(&buffer, 0, &[0u8; 64]);
    }

    /// An entity spawned after the scene became ready, captured with no frame stepped in
    /// between, is in the image: the capture waits for its pipelines rather than returning the
    /// frame drawn without it.
    #[test]
    fn a_capture_waits_for_the_pipelines_of_an_entity_spawned_after_ready() {
        let Some(mut harness) = RenderHarness::for_test("harness_late_entity", 16, 16) else {
            return;
        };
        harness.app_mut().world_mut().spawn((
            Camera3d::default(),
            Camera {
                clear_color: ClearColorConfig::Custom(Color::BLACK),
                ..default()
            },
            Msaa::Off,
            bevy::core_pipeline::tonemapping::Tonemapping::None,
            Transform::from_xyz(0.0, 0.0, 3.0).looking_at(Vec3::ZERO, Vec3::Y),
        ));
        let before = harness.render().expect("the empty scene renders");
        assert_eq!(before.pixel(8, 8)[..3], [0, 0, 0], "nothing is drawn yet");
        assert_eq!(
            harness.recaptures(),
            0,
            "the screenshot's own pipeline, compiled with the first capture, is not the scene's"
        );
        let world = harness.app_mut().world_mut();
        let mesh = world
            .resource_mut::<Assets<Mesh>>()
            .add(Cuboid::new(1.0, 1.0, 1.0));
        let material = world
            .resource_mut::<Assets<StandardMaterial>>()
            .add(StandardMaterial {
                base_color: Color::srgb(1.0, 0.0, 0.0),
                unlit: true,
                ..default()
            });
        world.spawn((Mesh3d(mesh), MeshMaterial3d(material)));
        let after = harness.render().expect("the cube renders");
        let centre = after.pixel(8, 8);
        assert!(
            centre[0] > 250 && centre[1] < 5 && centre[2] < 5,
            "the cube spawned just before the capture is drawn: centre {centre:?} \
             ({} captures taken again)",
            harness.recaptures()
        );
    }

    /// A renderer that stopped on an error is reported as that error, not as a readback that
    /// never arrived.
    #[test]
    fn a_render_error_is_returned_not_a_timeout() {
        let Some(mut harness) = RenderHarness::for_test("harness_render_error", 16, 16) else {
            return;
        };
        harness.app_mut().world_mut().spawn(Camera3d::default());
        assert!(harness.render().is_ok(), "a frame renders before the error");
        harness
            .app_mut()
            .sub_app_mut(RenderApp)
            .add_systems(Render, overrun.in_set(RenderSystems::PrepareResources));
        let err = harness
            .render()
            .expect_err("the overrun stops the renderer");
        let HarnessError::Render(message) = &err else {
            panic!("expected a render error, got {err}");
        };
        assert!(
            message.starts_with("Validation") && message.contains("write_buffer"),
            "{message}"
        );
        assert!(harness.render().is_err(), "it stays stopped");
    }
}
