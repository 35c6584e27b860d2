//! Frame-time statistics and the one-JSON-object report of a run.
//!
//! Machines here are shared and noisy, so a run reports robust figures (median and 95th
//! percentile, not the mean alone), and performance claims are ratios of two runs measured
//! side by side in one process.

use bevy::diagnostic::DiagnosticsStore;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Duration;

/// Robust statistics of a set of frame times, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FrameStats {
    /// Number of frames measured.
    pub frames: usize,
    /// Median frame time (ms).
    pub median_ms: f64,
    /// 95th percentile frame time (ms), nearest-rank.
    pub p95_ms: f64,
    /// Mean frame time (ms).
    pub mean_ms: f64,
    /// Smallest frame time (ms).
    pub min_ms: f64,
    /// Largest frame time (ms).
    pub max_ms: f64,
}

impl FrameStats {
    /// Statistics of `samples`; all zero when empty.
    pub fn from_durations(samples: &[Duration]) -> Self {
        let ms: Vec<f64> = samples.iter().map(|d| d.as_secs_f64() * 1e3).collect();
        Self::from_millis(&ms)
    }

    /// Statistics of samples already in milliseconds; all zero when empty.
    pub fn from_millis(samples: &[f64]) -> Self {
        if samples.is_empty() {
            return Self::default();
        }
        let mut sorted = samples.to_vec();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let median = if n % 2 == 1 {
            sorted[n / 2]
        } else {
            0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
        };
        Self {
            frames: n,
            median_ms: median,
            p95_ms: percentile_nearest_rank(&sorted, 0.95),
            mean_ms: sorted.iter().sum::<f64>() / n as f64,
            min_ms: sorted[0],
            max_ms: sorted[n - 1],
        }
    }
}

/// Nearest-rank percentile of an ascending slice (`p` in `(0, 1]`).
pub fn percentile_nearest_rank(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = (p * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// Everything one headless run reports, serialised as a single JSON object.
#[derive(Clone, Debug, Default, Serialize)]
pub struct RunStats {
    /// Example or benchmark name.
    pub name: String,
    /// Render size `[width, height]`.
    pub size: [u32; 2],
    /// `"headless"` or `"windowed"`.
    pub mode: String,
    /// Adapter used, when known.
    pub adapter: Option<crate::AdapterSummary>,
    /// Frames rendered before measuring (pipeline compilation, asset loading).
    pub warmup_frames: u32,
    /// Frame time of the measured frames (CPU wall time of one `App::update`, which includes
    /// waiting for the GPU in a non-pipelined app).
    pub frame_time: FrameStats,
    /// Median GPU time (ms) of each render pass that recorded a timestamp span
    /// (`render/<pass>/elapsed_gpu`), when the adapter supports timestamp queries.
    pub gpu_pass_ms: BTreeMap<String, f64>,
    /// Latest smoothed value of every other Bevy diagnostic (the plugins' counters), by path.
    pub diagnostics: BTreeMap<String, f64>,
}

impl RunStats {
    /// The JSON text of this report.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("RunStats serialises")
    }
}

/// Splits the store into GPU pass times (`render/<pass>/elapsed_gpu`, median over the kept
/// history) and every other diagnostic (smoothed value).
pub fn collect_diagnostics(
    store: &DiagnosticsStore,
) -> (BTreeMap<String, f64>, BTreeMap<String, f64>) {
    let mut gpu = BTreeMap::new();
    let mut other = BTreeMap::new();
    for diagnostic in store.iter() {
        let path = diagnostic.path().as_str().to_string();
        if let Some(pass) = path
            .strip_prefix("render/")
            .and_then(|p| p.strip_suffix("/elapsed_gpu"))
        {
            let values: Vec<f64> = diagnostic.values().copied().collect();
            if !values.is_empty() {
                gpu.insert(pass.to_string(), FrameStats::from_millis(&values).median_ms);
            }
        } else if let Some(value) = diagnostic.smoothed().or_else(|| diagnostic.value()) {
            other.insert(path, value);
        }
    }
    (gpu, other)
}

/// Writes `text` to `path` through a temporary file and a rename.
pub fn write_atomically(path: &std::path::Path, text: &str) -> Result<(), String> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .map_err(|e| format!("cannot create {}: {e}", parent.display()))?;
    }
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text).map_err(|e| format!("cannot write {}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("cannot rename to {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_and_p95() {
        let ms: Vec<f64> = (1..=100).map(f64::from).collect();
        let s = FrameStats::from_millis(&ms);
        assert_eq!(s.frames, 100);
        assert_eq!(s.median_ms, 50.5);
        assert_eq!(s.p95_ms, 95.0);
        assert_eq!(s.min_ms, 1.0);
        assert_eq!(s.max_ms, 100.0);
        assert!((s.mean_ms - 50.5).abs() < 1e-12);
    }

    #[test]
    fn odd_count_median_is_middle_sample_and_outlier_does_not_move_it() {
        let s = FrameStats::from_millis(&[10.0, 11.0, 1000.0, 9.0, 10.5]);
        assert_eq!(s.median_ms, 10.5);
        assert_eq!(s.p95_ms, 1000.0);
    }

    #[test]
    fn empty_is_zero() {
        assert_eq!(FrameStats::from_millis(&[]), FrameStats::default());
    }
}
