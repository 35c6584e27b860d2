//! The frame-rate feedback exponent of Gumbau 2011, eq. 4.3: `d_lod = lod^n`, n rising above 1
//! (less detail) while frames are slower than the target and falling below 1 while they are
//! faster.
//!
//! The thesis does not give the controller. This one is an integral controller in the log
//! domain: `ln n ← ln n + k · ln(t̄ / T)`, with t̄ the frame time smoothed over a few frames, T the
//! target, a dead band around T where n is left alone, and each step limited. Why it settles
//! without oscillating: near the set point the scene responds as `ln t ≈ ln T + s·(ln n − ln n*)`
//! with a slope s ∈ (−1, 0) (more exponent, fewer leaves, shorter frames; the per-frame base cost
//! keeps |s| under 1), so the error evolves as `e ← (1 + k·s)·e`: for 0 < k ≤ 1 the factor lies
//! in [0, 1) and the error shrinks without changing sign. The smoothing adds a little lag, so k
//! defaults to 0.35, well inside that range; the dead band stops the controller from chasing
//! frame-time noise.

use bevy::reflect::Reflect;

/// Settings of the feedback exponent.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub struct FeedbackSettings {
    /// Target frame time (ms).
    pub target_frame_ms: f32,
    /// Integral gain k in the log domain, in (0, 1].
    pub gain: f32,
    /// Relative dead band around the target (0.05: ±5 %).
    pub dead_band: f32,
    /// Smallest exponent (most detail).
    pub min_exponent: f32,
    /// Largest exponent (least detail).
    pub max_exponent: f32,
    /// Largest change of `ln n` per frame.
    pub max_step: f32,
    /// Weight of the newest frame in the smoothed frame time, in (0, 1].
    pub smoothing: f32,
}

impl Default for FeedbackSettings {
    fn default() -> Self {
        Self {
            target_frame_ms: 1000.0 / 60.0,
            gain: 0.35,
            dead_band: 0.05,
            min_exponent: 0.25,
            max_exponent: 8.0,
            max_step: 0.15,
            smoothing: 0.5,
        }
    }
}

impl FeedbackSettings {
    /// These settings with every value made usable (and what was changed).
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let d = Self::default();
        let mut s = *self;
        let mut fixes = Vec::new();
        let mut fix = |name: &str, v: &mut f32, ok: bool, default: f32| {
            if !ok {
                fixes.push(format!("{name} = {v} is out of range: using {default}"));
                *v = default;
            }
        };
        let t = s.target_frame_ms;
        fix(
            "target_frame_ms",
            &mut s.target_frame_ms,
            t.is_finite() && t > 0.0,
            d.target_frame_ms,
        );
        let g = s.gain;
        fix("gain", &mut s.gain, g > 0.0 && g <= 1.0, d.gain);
        let b = s.dead_band;
        fix(
            "dead_band",
            &mut s.dead_band,
            (0.0..1.0).contains(&b),
            d.dead_band,
        );
        let m = s.smoothing;
        fix(
            "smoothing",
            &mut s.smoothing,
            m > 0.0 && m <= 1.0,
            d.smoothing,
        );
        let st = s.max_step;
        fix(
            "max_step",
            &mut s.max_step,
            st > 0.0 && st.is_finite(),
            d.max_step,
        );
        let (lo, hi) = (s.min_exponent, s.max_exponent);
        if !(lo > 0.0 && hi.is_finite() && lo <= 1.0 && hi >= 1.0) {
            fixes.push(format!(
                "exponent range [{lo}, {hi}] must contain 1 and be positive: using [{}, {}]",
                d.min_exponent, d.max_exponent
            ));
            s.min_exponent = d.min_exponent;
            s.max_exponent = d.max_exponent;
        }
        (s, fixes)
    }
}

/// The controller's state.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub struct ExponentController {
    /// Current exponent n.
    pub exponent: f32,
    /// Smoothed frame time (ms), once a frame was seen.
    pub smoothed_ms: Option<f32>,
}

impl Default for ExponentController {
    fn default() -> Self {
        Self {
            exponent: 1.0,
            smoothed_ms: None,
        }
    }
}

impl ExponentController {
    /// Feeds one frame time (ms) and returns the exponent for the next frame. Non-finite or
    /// non-positive frame times are ignored.
    pub fn update(&mut self, frame_ms: f32, settings: &FeedbackSettings) -> f32 {
        if !(frame_ms.is_finite() && frame_ms > 0.0) {
            return self.exponent;
        }
        let smoothed = match self.smoothed_ms {
            Some(s) => s + settings.smoothing * (frame_ms - s),
            None => frame_ms,
        };
        self.smoothed_ms = Some(smoothed);
        let error = (smoothed / settings.target_frame_ms).ln();
        if error.abs() > (1.0 + settings.dead_band).ln() {
            let step = (settings.gain * error).clamp(-settings.max_step, settings.max_step);
            self.exponent = (self.exponent.ln() + step)
                .exp()
                .clamp(settings.min_exponent, settings.max_exponent);
        }
        self.exponent
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::forest::lod::desired_lod;
    use crate::rng::SplitMix64;

    /// A forest whose frame time is a base cost plus a cost per leaf drawn, with noise.
    struct Scene {
        distances: Vec<f32>,
        base_ms: f32,
        ms_per_lod: f32,
        noise: f32,
        rng: SplitMix64,
    }

    impl Scene {
        fn new(seed: u64, noise: f32) -> Self {
            let mut rng = SplitMix64::new(seed);
            let distances = (0..500).map(|_| 10.0 + 240.0 * rng.next_f32()).collect();
            Self {
                distances,
                base_ms: 6.0,
                ms_per_lod: 0.25,
                noise,
                rng,
            }
        }

        fn frame_ms(&mut self, n: f32) -> f32 {
            let lods: f32 = self
                .distances
                .iter()
                .map(|&d| desired_lod(d, 10.0, 250.0, n))
                .sum();
            let jitter = 1.0 + self.noise * (2.0 * self.rng.next_f32() - 1.0);
            (self.base_ms + self.ms_per_lod * lods) * jitter
        }
    }

    fn run(scene: &mut Scene, settings: &FeedbackSettings, frames: usize) -> (Vec<f32>, Vec<f32>) {
        let mut c = ExponentController::default();
        let (mut times, mut ns) = (Vec::new(), Vec::new());
        for _ in 0..frames {
            let t = scene.frame_ms(c.exponent);
            times.push(t);
            ns.push(c.update(t, settings));
        }
        (times, ns)
    }

    #[test]
    fn settles_on_the_target_without_oscillating() {
        // Full detail (n = 1) costs 6 + 0.25 · 250 ≈ 68 ms; the target is 30 ms.
        let settings = FeedbackSettings {
            target_frame_ms: 30.0,
            ..Default::default()
        };
        let mut scene = Scene::new(3, 0.0);
        let (times, ns) = run(&mut scene, &settings, 200);
        assert!(times[0] > 60.0, "{}", times[0]);
        let settled = times[40..].iter().all(|t| (t / 30.0 - 1.0).abs() <= 0.08);
        assert!(settled, "{:?}", &times[40..60]);
        // Monotone approach: n only ever rises on the way from 68 ms down to 30 ms.
        let reversals = ns.windows(2).filter(|w| w[1] < w[0] - 1e-6).count();
        assert_eq!(reversals, 0, "{ns:?}");
        assert!(ns[199] > 1.0);
    }

    #[test]
    fn noise_inside_the_dead_band_does_not_make_it_hunt() {
        let settings = FeedbackSettings {
            target_frame_ms: 30.0,
            ..Default::default()
        };
        let mut scene = Scene::new(5, 0.03);
        let (times, ns) = run(&mut scene, &settings, 400);
        let late = &ns[100..];
        let reversals = late
            .windows(3)
            .filter(|w| (w[1] - w[0]) * (w[2] - w[1]) < 0.0)
            .count();
        let spread = late.iter().cloned().fold(f32::MIN, f32::max)
            / late.iter().cloned().fold(f32::MAX, f32::min);
        assert!(
            reversals <= 4,
            "n reversed {reversals} times after settling"
        );
        assert!(spread < 1.1, "n wandered by {spread}");
        let mean = times[100..].iter().sum::<f32>() / 300.0;
        assert!((mean / 30.0 - 1.0).abs() < 0.06, "mean frame {mean} ms");
    }

    #[test]
    fn raises_detail_when_frames_are_fast_and_saturates_when_the_target_is_unreachable() {
        let fast = FeedbackSettings {
            target_frame_ms: 200.0,
            ..Default::default()
        };
        let (_, ns) = run(&mut Scene::new(1, 0.0), &fast, 100);
        assert_eq!(ns[99], fast.min_exponent, "all detail affordable");
        let impossible = FeedbackSettings {
            target_frame_ms: 1.0,
            ..Default::default()
        };
        let (_, ns) = run(&mut Scene::new(1, 0.0), &impossible, 100);
        assert_eq!(ns[99], impossible.max_exponent);
        assert!(ns.windows(2).all(|w| w[1] >= w[0]));
    }

    #[test]
    fn bad_settings_are_corrected() {
        let (s, fixes) = FeedbackSettings {
            target_frame_ms: -1.0,
            gain: 5.0,
            min_exponent: 2.0,
            ..Default::default()
        }
        .sanitized();
        assert_eq!(fixes.len(), 3, "{fixes:?}");
        assert_eq!(s, FeedbackSettings::default());
        let mut c = ExponentController::default();
        assert_eq!(c.update(f32::NAN, &s), 1.0);
    }
}
