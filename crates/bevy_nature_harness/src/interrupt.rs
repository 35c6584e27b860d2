//! Interrupting long work at random points: the tests that kill a bake or a pyramid build part
//! way and check that running it again gives byte-identical output, with no damaged file left
//! where a finished one belongs.
//!
//! [`run_killed_after`] starts a command and kills it (SIGKILL: no chance to clean up) after a
//! delay, [`kill_delays`] spreads seeded random delays over a run's length, and [`files_of`]
//! reads a folder's files for comparison, leaving out temporary files (`*.tmp*`) — what an
//! interrupted atomic write leaves behind, never read by the loaders.

use std::collections::BTreeMap;
use std::io;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How an interrupted run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interrupted {
    /// Killed after the delay.
    Killed,
    /// It finished before the delay, with this success.
    Finished(bool),
}

/// Runs `command` (its output discarded) and kills it after `delay` unless it finished.
pub fn run_killed_after(command: &mut Command, delay: Duration) -> io::Result<Interrupted> {
    let mut child = command
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()?;
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(Interrupted::Finished(status.success()));
        }
        if start.elapsed() >= delay {
            child.kill()?;
            child.wait()?;
            return Ok(Interrupted::Killed);
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Runs `command` to completion (its output discarded); returns how long it took, or an error
/// if it failed.
pub fn run_to_completion(command: &mut Command) -> io::Result<Duration> {
    let start = Instant::now();
    let output = command
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()?;
    if !output.status.success() {
        return Err(io::Error::other(format!(
            "{command:?} failed: {}",
            String::from_utf8_lossy(&output.stderr)
        )));
    }
    Ok(start.elapsed())
}

/// `trials` delays spread over `0..length` at seeded random points (one per equal slice of
/// the run, so early, middle and late interruptions are all tried).
pub fn kill_delays(length: Duration, trials: u32, seed: u64) -> Vec<Duration> {
    let mut state = seed;
    (0..trials)
        .map(|i| {
            // SplitMix64.
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            let u = ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64;
            length.mul_f64((i as f64 + u) / trials as f64)
        })
        .collect()
}

/// Whether `path` is a temporary file of an atomic write (`name.tmp`, `name.tmp1234`).
pub fn is_temporary(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.starts_with("tmp"))
}

/// Every file under `dir` (recursively) but temporary ones, by path relative to `dir`, with
/// its bytes.
pub fn files_of(dir: &Path) -> io::Result<BTreeMap<PathBuf, Vec<u8>>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        for entry in std::fs::read_dir(&folder)? {
            let path = entry?.path();
            if path.is_dir() {
                stack.push(path);
            } else if !is_temporary(&path) {
                let relative = path.strip_prefix(dir).unwrap_or(&path).to_path_buf();
                out.insert(relative, std::fs::read(&path)?);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delays_cover_the_run_in_order() {
        let delays = kill_delays(Duration::from_secs(10), 10, 7);
        assert_eq!(delays.len(), 10);
        for (i, d) in delays.iter().enumerate() {
            assert!(*d >= Duration::from_secs(i as u64) && *d < Duration::from_secs(i as u64 + 1));
        }
        assert_ne!(delays, kill_delays(Duration::from_secs(10), 10, 8));
    }

    #[test]
    fn temporary_files_are_recognised() {
        assert!(is_temporary(Path::new("a/olea.tmp")));
        assert!(is_temporary(Path::new("olea.tmp4242")));
        assert!(!is_temporary(Path::new("olea.foliage")));
        assert!(!is_temporary(Path::new("2/0/0.png")));
    }
}
