//! Seeded mutation fuzzing on stable Rust, for the suite's loaders: each case takes a valid
//! input from a target's seeds, applies one to four random mutations (bit flips, interesting
//! bytes and integers, inserted, deleted, duplicated and spliced runs, truncation, numbers in
//! text grown to extremes) and runs the target on it; a panic or a case slower than
//! [`SLOW_CASE`] fails the run, naming the case and saving its input under
//! `$CARGO_TARGET_DIR/fuzz-crashes/<target>/` (the system's temporary folder without it) so it
//! can be kept as a regression case.
//!
//! `cargo test` runs each target's fixed number of cases; set `NATURE_FUZZ_CASES` for more, e.g.
//! `NATURE_FUZZ_CASES=200000 cargo test --release -p bevy_terrain_clip fuzz_` (and
//! `NATURE_FUZZ_SEED` for another sequence).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// A case slower than this fails the run (a hang, or work out of proportion to the input).
pub const SLOW_CASE: Duration = Duration::from_secs(5);

/// A deterministic random stream (SplitMix64).
#[derive(Clone, Debug)]
pub struct Mutator(u64);

impl Mutator {
    /// The stream from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A uniform integer in `0..n` (0 for `n = 0`).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next_u64() % n as u64) as usize
        }
    }

    /// `input` changed by one to four mutations; `others` are spliced from.
    pub fn mutate(&mut self, input: &[u8], others: &[Vec<u8>]) -> Vec<u8> {
        let mut out = input.to_vec();
        for _ in 0..1 + self.below(4) {
            self.mutate_once(&mut out, others);
        }
        out
    }

    fn mutate_once(&mut self, out: &mut Vec<u8>, others: &[Vec<u8>]) {
        const BYTES: [u8; 8] = [0, 1, 0x7f, 0x80, 0xff, b'0', b'-', b'9'];
        const WORDS: [u32; 8] = [
            0,
            1,
            0xffff_ffff,
            0x7fff_ffff,
            0x8000_0000,
            0xffff,
            0x1_0000,
            1 << 24,
        ];
        let len = out.len();
        match self.below(10) {
            0 if len > 0 => {
                let i = self.below(len);
                out[i] ^= 1 << self.below(8);
            }
            1 if len > 0 => {
                let i = self.below(len);
                out[i] = BYTES[self.below(BYTES.len())];
            }
            2 if len >= 4 => {
                let i = self.below(len - 3);
                let w = WORDS[self.below(WORDS.len())];
                let bytes = if self.below(2) == 0 {
                    w.to_le_bytes()
                } else {
                    w.to_be_bytes()
                };
                out[i..i + 4].copy_from_slice(&bytes);
            }
            3 => {
                let i = self.below(len + 1);
                let n = 1 + self.below(16);
                let fill: Vec<u8> = (0..n).map(|_| self.next_u64() as u8).collect();
                out.splice(i..i, fill);
            }
            4 if len > 0 => {
                let i = self.below(len);
                let n = 1 + self.below((len - i).min(64));
                out.drain(i..i + n);
            }
            5 if len > 0 => {
                let i = self.below(len);
                let n = 1 + self.below((len - i).min(64));
                let run = out[i..i + n].to_vec();
                let at = self.below(len + 1);
                out.splice(at..at, run);
            }
            6 if len > 0 => {
                out.truncate(self.below(len));
            }
            7 if !others.is_empty() => {
                let other = &others[self.below(others.len())];
                if !other.is_empty() {
                    let from = self.below(other.len());
                    let n = 1 + self.below((other.len() - from).min(256));
                    let at = self.below(len + 1);
                    let end = (at + n).min(len);
                    out.splice(at..end, other[from..from + n].iter().copied());
                }
            }
            _ => {
                // A number in text grown to an extreme: the digits of one run replaced.
                let digits: Vec<usize> = (0..len).filter(|&i| out[i].is_ascii_digit()).collect();
                if digits.is_empty() {
                    if len > 0 {
                        let i = self.below(len);
                        out[i] = out[i].wrapping_add(1);
                    }
                    return;
                }
                let mut start = digits[self.below(digits.len())];
                while start > 0 && out[start - 1].is_ascii_digit() {
                    start -= 1;
                }
                let mut end = start;
                while end < len && out[end].is_ascii_digit() {
                    end += 1;
                }
                const NUMBERS: [&str; 7] = [
                    "0",
                    "4294967296",
                    "18446744073709551616",
                    "99999999999999999999999999",
                    "-1",
                    "1e39",
                    "65535",
                ];
                let with = NUMBERS[self.below(NUMBERS.len())].as_bytes().to_vec();
                out.splice(start..end, with);
            }
        }
    }
}

/// How many cases a target runs: `NATURE_FUZZ_CASES` if set, else `default`.
pub fn cases(default: u32) -> u32 {
    std::env::var("NATURE_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// What a fuzzing run did.
#[derive(Clone, Debug, Default)]
pub struct FuzzReport {
    /// Cases run.
    pub cases: u32,
    /// Cases the target accepted (`check` returned `true`) — how deep mutations got.
    pub accepted: u32,
    /// The slowest case.
    pub slowest: Duration,
}

/// Runs `target` on `cases` mutations of `seeds` (and on the seeds themselves first), with
/// `check` returning whether the input was accepted (for the report). Panics — naming the case,
/// the seed (`NATURE_FUZZ_SEED`, default 1) and where its input was saved — if `check` panics or
/// takes longer than [`SLOW_CASE`].
pub fn fuzz(
    target: &str,
    seeds: &[Vec<u8>],
    cases: u32,
    check: impl FnMut(&[u8]) -> bool,
) -> FuzzReport {
    fuzz_with(target, seeds, cases, |_| {}, check)
}

/// [`fuzz`] with `fixup` applied to every mutated input before the target sees it — e.g.
/// [`fix_png_crcs`], so that mutations get past a format's checksums into its decoder.
pub fn fuzz_with(
    target: &str,
    seeds: &[Vec<u8>],
    cases: u32,
    mut fixup: impl FnMut(&mut Vec<u8>),
    mut check: impl FnMut(&[u8]) -> bool,
) -> FuzzReport {
    assert!(!seeds.is_empty(), "{target}: no seeds");
    let seed: u64 = std::env::var("NATURE_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let mut mutator = Mutator::new(seed ^ fnv(target.as_bytes()));
    let mut report = FuzzReport::default();
    let inputs = seeds
        .iter()
        .cloned()
        .chain((0..cases).map(|_| {
            let base = &seeds[mutator.below(seeds.len())];
            let mut input = mutator.mutate(base, seeds);
            fixup(&mut input);
            input
        }))
        .collect::<Vec<_>>();
    for (case, input) in inputs.iter().enumerate() {
        let start = Instant::now();
        let outcome = catch_unwind(AssertUnwindSafe(|| check(input)));
        let took = start.elapsed();
        report.slowest = report.slowest.max(took);
        let failure = match outcome {
            Err(panic) => Some(format!(
                "panicked: {}",
                panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default()
            )),
            Ok(_) if took > SLOW_CASE => Some(format!("took {took:?}")),
            Ok(accepted) => {
                report.accepted += accepted as u32;
                None
            }
        };
        if let Some(failure) = failure {
            let path = save_crash(target, case, input);
            panic!(
                "fuzz target {target}, case {case} (NATURE_FUZZ_SEED={seed}): {failure}; input \
                 saved to {}",
                path.display()
            );
        }
        report.cases += 1;
    }
    report
}

/// The CRC-32 of PNG chunks and zlib's gzip (ISO 3309).
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// Rewrites the CRC of every whole chunk of a PNG file (after the 8-byte signature: length,
/// type, data, CRC), so a mutated file fails on what was mutated, not on its checksum. Stops at
/// the first chunk that does not fit.
pub fn fix_png_crcs(png: &mut [u8]) {
    let mut at = 8usize;
    while at + 12 <= png.len() {
        let len = u32::from_be_bytes(png[at..at + 4].try_into().unwrap()) as usize;
        let Some(end) = (at + 8).checked_add(len).filter(|&e| e + 4 <= png.len()) else {
            return;
        };
        let crc = crc32(&png[at + 4..end]);
        png[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        at = end + 4;
    }
}

fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x100_0000_01b3)
    })
}

fn save_crash(target: &str, case: usize, input: &[u8]) -> PathBuf {
    let dir = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(std::env::temp_dir)
        .join("fuzz-crashes")
        .join(target);
    let path = dir.join(format!("case-{case}.bin"));
    let _ = std::fs::create_dir_all(&dir).and_then(|_| std::fs::write(&path, input));
    path
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_are_deterministic_and_varied() {
        let seed = b"{\"levels\": 12, \"tile_size\": 256}".to_vec();
        let run = |s| {
            let mut m = Mutator::new(s);
            (0..200)
                .map(|_| m.mutate(&seed, std::slice::from_ref(&seed)))
                .collect::<Vec<_>>()
        };
        assert_eq!(run(7), run(7));
        let cases = run(7);
        let distinct: std::collections::HashSet<_> = cases.iter().collect();
        assert!(distinct.len() > 150, "{}", distinct.len());
        assert!(cases.iter().any(|c| c.len() < seed.len()));
        assert!(cases.iter().any(|c| c.len() > seed.len()));
        assert!(
            cases
                .iter()
                .any(|c| String::from_utf8_lossy(c).contains("4294967296"))
        );
    }

    #[test]
    fn a_panicking_target_fails_the_run_and_keeps_its_input() {
        let result = catch_unwind(|| {
            fuzz("fuzz_self_test", &[b"ok".to_vec()], 200, |bytes| {
                assert!(bytes.len() <= 2, "grew");
                true
            })
        });
        let message = result
            .expect_err("an input longer than the seed panics")
            .downcast_ref::<String>()
            .cloned()
            .unwrap_or_default();
        assert!(
            message.contains("fuzz_self_test") && message.contains("grew"),
            "{message}"
        );
        let report = fuzz("fuzz_self_test_ok", &[b"ok".to_vec()], 50, |_| true);
        assert_eq!((report.cases, report.accepted), (51, 51));
    }

    /// The CRC of "IEND" is PNG's well-known AE 42 60 82; a chunk's CRC is rewritten.
    #[test]
    fn png_crcs_are_recomputed() {
        assert_eq!(crc32(b"IEND"), 0xAE42_6082);
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        png.extend_from_slice(&[0, 0, 0, 0]);
        png.extend_from_slice(b"IEND");
        png.extend_from_slice(&[0, 0, 0, 0]);
        fix_png_crcs(&mut png);
        assert_eq!(&png[16..20], &[0xAE, 0x42, 0x60, 0x82]);
        // A chunk claiming more data than the file has is left alone.
        let mut short = png.clone();
        short[8..12].copy_from_slice(&1000u32.to_be_bytes());
        let before = short.clone();
        fix_png_crcs(&mut short);
        assert_eq!(short, before);
    }
}
