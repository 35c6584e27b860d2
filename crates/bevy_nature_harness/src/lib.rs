//! Headless render harness shared by the `bevy_nature` tests, benchmarks and examples.
//!
//! Everything the suite claims is checked by rendering for real on whatever adapter the machine
//! has (a software Vulkan driver such as llvmpipe/lavapipe in CI) and comparing by numbers.
//! This crate is the one place that knows how to do that:
//!
//! - [`adapter`]: find out whether a GPU adapter exists, and what a test must do when it does not
//!   (fail under `CI=true`, skip with a message otherwise).
//! - [`headless`]: [`RenderHarness`], a Bevy [`App`](bevy::app::App) with no window that renders
//!   every camera into an offscreen image, waits until pipelines are compiled and a frame truly
//!   rendered, reads back RGBA pixels and GPU buffers, and records per-frame CPU time and, where
//!   the adapter supports timestamp queries, GPU time of named passes.
//! - [`compare`]: [`RgbaImage`] and the image metrics the tests assert on (RMSE, PSNR, SSIM,
//!   masked coverage); a failed comparison writes both images and a difference image under
//!   `target/nature-artifacts/` so a person can look.
//! - [`interrupt`]: killing a bake or a build at random points and comparing what a rerun writes.
//! - [`soak`]: `--soak N`, a long run sampling resident and GPU memory.
//! - [`stats`]: frame-time statistics (median, p95) and the JSON the example runner prints.
//! - [`runner`]: [`ExampleRunner`], used by every example: windowed by default, `--headless`,
//!   `--frames N`, `--size WxH`, `--screenshot PATH`, `--stats PATH`, with a `bevy_egui` panel of
//!   the plugins' live diagnostics and settings in windowed runs (feature `windowed`).

pub mod adapter;
pub mod compare;
pub mod frame_timer;
pub mod fuzz;
pub mod headless;
pub mod interrupt;
#[cfg(feature = "windowed")]
pub mod panel;
pub mod runner;
pub mod soak;
pub mod stats;

pub use adapter::{AdapterSummary, probe_adapter, require_adapter};
pub use compare::{Comparison, RgbaImage, artifacts_dir};
pub use headless::{HarnessError, RenderHarness};
pub use runner::{ExampleArgs, ExampleRunner};
pub use stats::{FrameStats, RunStats};
