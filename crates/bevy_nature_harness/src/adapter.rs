//! Does this machine have a GPU adapter, and what does a render test do if it has none?
//!
//! Render tests must never pass silently on a machine that cannot render. The rule:
//! with `CI=true` (or `CI=1`) in the environment a missing adapter is a test **failure**;
//! otherwise (a developer laptop without drivers) the test prints why and skips.

use bevy::tasks::block_on;
use std::sync::OnceLock;

/// What the probe found: enough to put in a note or a benchmark's JSON.
#[derive(Clone, Debug, serde::Serialize)]
pub struct AdapterSummary {
    /// Adapter name as the driver reports it (e.g. `llvmpipe (LLVM 15.0.6, 256 bits)`).
    pub name: String,
    /// Backend (Vulkan, Gl, ...).
    pub backend: String,
    /// Device type (Cpu for software rasterisers, DiscreteGpu, ...).
    pub device_type: String,
    /// Driver name and version string.
    pub driver: String,
    /// Whether GPU timestamp queries are supported (GPU pass times are then recorded).
    pub timestamp_queries: bool,
}

/// `true` when running under CI (`CI=true` or `CI=1`), where render tests must not skip.
pub fn in_ci() -> bool {
    matches!(
        std::env::var("CI").map(|v| v.to_ascii_lowercase()),
        Ok(v) if v == "true" || v == "1" || v == "yes"
    )
}

/// Asks wgpu for an adapter the same way Bevy's renderer will (same backends, honouring
/// `WGPU_BACKEND`). The answer is computed once per process.
pub fn probe_adapter() -> Option<AdapterSummary> {
    static PROBE: OnceLock<Option<AdapterSummary>> = OnceLock::new();
    PROBE
        .get_or_init(|| {
            let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
            let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
                backends,
                ..wgpu::InstanceDescriptor::new_without_display_handle()
            });
            let adapter = block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: None,
            }))
            .ok()?;
            let info = adapter.get_info();
            Some(AdapterSummary {
                name: info.name,
                backend: format!("{:?}", info.backend),
                device_type: format!("{:?}", info.device_type),
                driver: format!("{} {}", info.driver, info.driver_info),
                timestamp_queries: adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY),
            })
        })
        .clone()
}

/// For render tests: returns the adapter, or `None` when the test should skip.
///
/// # Panics
/// Under CI (see [`in_ci`]) when no adapter is found: a render test there fails, never skips.
pub fn require_adapter(test: &str) -> Option<AdapterSummary> {
    match probe_adapter() {
        Some(adapter) => Some(adapter),
        None if in_ci() => panic!(
            "{test}: no GPU adapter found and CI=true: render tests must not skip in CI. \
             Install a Vulkan driver (Debian: mesa-vulkan-drivers libvulkan1) — `.ci/run` does."
        ),
        None => {
            eprintln!(
                "{test}: SKIPPED — no GPU adapter on this machine (install mesa-vulkan-drivers; \
                 with CI=true this is a failure)"
            );
            None
        }
    }
}
