//! Long runs with bounded memory: `--soak N` on an example runs N frames headless and samples,
//! every [`SOAK_INTERVAL`] frames, the process's resident memory and the GPU memory wgpu's
//! allocator holds, so that a leak — a cache that never evicts, buffers made every frame —
//! shows as a series that keeps climbing.

use crate::headless::RenderHarness;
use bevy::render::RenderApp;
use bevy::render::renderer::RenderDevice;
use serde::Serialize;

/// Frames between two samples.
pub const SOAK_INTERVAL: u32 = 500;

/// One sample of a soak run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SoakSample {
    /// Frames run when it was taken.
    pub frame: u32,
    /// Resident set size of the process (bytes; `None` where `/proc` is not there).
    pub rss_bytes: Option<u64>,
    /// Bytes of live GPU allocations (buffers and textures) wgpu's allocator reports (`None`
    /// on backends without a report).
    pub gpu_allocated_bytes: Option<u64>,
    /// Bytes of GPU memory blocks the allocator holds, free parts included.
    pub gpu_reserved_bytes: Option<u64>,
}

/// `VmRSS` of a `/proc/<pid>/status` text, in bytes.
pub fn rss_from_status(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let mut words = line.split_whitespace().skip(1);
    let value: u64 = words.next()?.parse().ok()?;
    match words.next() {
        Some("kB") | None => Some(value * 1024),
        Some(_) => None,
    }
}

/// The process's resident set size (Linux).
pub fn resident_bytes() -> Option<u64> {
    rss_from_status(&std::fs::read_to_string("/proc/self/status").ok()?)
}

/// Takes a sample of `harness` after `frame` frames.
pub fn sample(harness: &RenderHarness, frame: u32) -> SoakSample {
    let report = harness
        .app()
        .get_sub_app(RenderApp)
        .and_then(|app| app.world().get_resource::<RenderDevice>())
        .and_then(|device| device.wgpu_device().generate_allocator_report());
    SoakSample {
        frame,
        rss_bytes: resident_bytes(),
        gpu_allocated_bytes: report.as_ref().map(|r| r.total_allocated_bytes),
        gpu_reserved_bytes: report.as_ref().map(|r| r.total_reserved_bytes),
    }
}

/// How a series grew after its warm-up: from the sample at a fifth of the run (caches filled,
/// pipelines made) to the last, and the peak of the later samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Growth {
    /// The value after the warm-up.
    pub after_warmup: u64,
    /// The last value.
    pub last: u64,
    /// The highest value after the warm-up.
    pub peak: u64,
}

impl Growth {
    /// The growth of `values` (one per sample), or `None` for fewer than two.
    pub fn of(values: &[u64]) -> Option<Self> {
        if values.len() < 2 {
            return None;
        }
        let warm = values.len() / 5;
        let later = &values[warm..];
        Some(Self {
            after_warmup: later[0],
            last: *later.last()?,
            peak: *later.iter().max()?,
        })
    }

    /// Growth from after the warm-up to the peak, as a fraction of the value after the warm-up.
    pub fn fraction(&self) -> f64 {
        (self.peak as f64 - self.after_warmup as f64) / self.after_warmup.max(1) as f64
    }
}

/// The JSON of a soak run: every sample, and the growth of each series.
pub fn report_json(name: &str, frames: u32, samples: &[SoakSample]) -> String {
    let series =
        |f: fn(&SoakSample) -> Option<u64>| -> Vec<u64> { samples.iter().filter_map(f).collect() };
    serde_json::json!({
        "name": name,
        "soak_frames": frames,
        "interval": SOAK_INTERVAL,
        "samples": samples,
        "rss_growth": Growth::of(&series(|s| s.rss_bytes)),
        "gpu_allocated_growth": Growth::of(&series(|s| s.gpu_allocated_bytes)),
    })
    .to_string()
}

/// Runs `frames` frames of `harness`, sampling before the first and every [`SOAK_INTERVAL`]
/// frames, with a line per sample on stderr.
pub fn soak(
    harness: &mut RenderHarness,
    name: &str,
    frames: u32,
) -> Result<Vec<SoakSample>, String> {
    soak_sampling_every(harness, name, frames, SOAK_INTERVAL)
}

/// [`soak`], sampling every `interval` frames.
pub fn soak_sampling_every(
    harness: &mut RenderHarness,
    name: &str,
    frames: u32,
    interval: u32,
) -> Result<Vec<SoakSample>, String> {
    let interval = interval.max(1);
    let mib =
        |b: Option<u64>| b.map_or("n/a".into(), |b| format!("{:.1} MiB", b as f64 / 1048576.0));
    let mut samples = vec![sample(harness, 0)];
    let mut done = 0;
    let started = std::time::Instant::now();
    while done < frames {
        let n = interval.min(frames - done);
        harness.run_frames(n).map_err(|e| e.to_string())?;
        done += n;
        let s = sample(harness, done);
        eprintln!(
            "{name}: soak frame {done}/{frames} ({:.0} s): resident {}, GPU allocated {} (reserved {})",
            started.elapsed().as_secs_f64(),
            mib(s.rss_bytes),
            mib(s.gpu_allocated_bytes),
            mib(s.gpu_reserved_bytes)
        );
        samples.push(s);
    }
    Ok(samples)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rss_is_read_from_proc_status() {
        let status = "Name:\tnature\nVmPeak:\t  900 kB\nVmRSS:\t  123456 kB\nThreads:\t9\n";
        assert_eq!(rss_from_status(status), Some(123_456 * 1024));
        assert_eq!(rss_from_status("Name: x\n"), None);
        assert!(resident_bytes().is_none_or(|b| b > 1 << 20));
    }

    #[test]
    fn growth_is_measured_after_the_warm_up() {
        // Warm-up climbs, then a plateau with noise.
        let values = [10, 50, 100, 100, 101, 100, 102, 100, 101, 100];
        let g = Growth::of(&values).unwrap();
        assert_eq!((g.after_warmup, g.last, g.peak), (100, 100, 102));
        assert!((g.fraction() - 0.02).abs() < 1e-9);
        // A leak keeps climbing.
        let leak: Vec<u64> = (0..10).map(|i| 100 + 10 * i).collect();
        assert!(Growth::of(&leak).unwrap().fraction() > 0.5);
        assert!(Growth::of(&[1]).is_none());
    }
}
