//! [`ExampleRunner`]: the one way every example starts.
//!
//! ```text
//! cargo run --example nature                       # a window with a statistics panel
//! cargo run --example nature -- --headless --frames 120 --size 640x360 \
//!     --screenshot target/nature.png --stats target/nature.json
//! ```
//!
//! Flags:
//! - `--headless`: render offscreen (no window), then exit.
//! - `--frames N`: measured frames to run (headless default 60, or
//!   [`SOFTWARE_DEFAULT_FRAMES`] on a software rasteriser, where a frame of the main scene takes
//!   seconds to tens of seconds); windowed runs exit after N. A headless run reports its progress
//!   every [`PROGRESS_SECONDS`].
//! - `--size WxH`: render size (default 1280x720 windowed, 640x360 headless).
//! - `--screenshot PATH`: save the last frame as PNG.
//! - `--stats PATH`: write one JSON object (frame time median and p95, GPU pass times where
//!   supported, and every counter the plugins publish as Bevy diagnostics). Headless runs also
//!   print it on stdout.
//! - `--soak N`: run N frames headless, sampling resident and GPU memory every 500 frames
//!   ([`crate::soak`]); the samples and their growth are the JSON (printed, and written to
//!   `--stats`).
//!
//! With no display (`DISPLAY` and `WAYLAND_DISPLAY` unset) an example says so and runs
//! headless instead of failing to open a window.

use crate::headless::{HarnessConfig, RenderHarness};
use crate::stats::write_atomically;
use bevy::prelude::*;
use std::path::PathBuf;

/// Measured frames a headless run takes by default on a software rasteriser (an adapter of
/// device type `Cpu`, such as lavapipe or llvmpipe), where the default of 60 would keep a first
/// run of the main scene going for most of an hour; `--frames N` asks for more.
pub const SOFTWARE_DEFAULT_FRAMES: u32 = 5;

/// Seconds between two progress lines of a headless run (while it warms up and while it
/// measures).
pub const PROGRESS_SECONDS: f32 = 10.0;

/// When a headless run's next progress line is due: at most one every [`PROGRESS_SECONDS`]
/// from its start, so a slow software frame reports and a fast one does not flood stderr.
struct ProgressThrottle {
    started: std::time::Instant,
    reported: f32,
}

impl Default for ProgressThrottle {
    fn default() -> Self {
        Self {
            started: std::time::Instant::now(),
            reported: 0.0,
        }
    }
}

impl ProgressThrottle {
    /// The seconds since the start where a line is due now (and counted as written), else
    /// `None`.
    fn due(&mut self) -> Option<f32> {
        self.due_at(self.started.elapsed().as_secs_f32())
    }

    fn due_at(&mut self, elapsed: f32) -> Option<f32> {
        (elapsed - self.reported >= PROGRESS_SECONDS).then(|| {
            self.reported = elapsed;
            elapsed
        })
    }
}

/// The measured frames a headless run takes: `asked` where given, else
/// [`SOFTWARE_DEFAULT_FRAMES`] on a software adapter and 60 on any other.
pub fn headless_frames(asked: Option<u32>, software: bool) -> u32 {
    asked.unwrap_or(if software {
        SOFTWARE_DEFAULT_FRAMES
    } else {
        60
    })
}

/// Parsed command-line flags of an example.
#[derive(Clone, Debug, PartialEq)]
pub struct ExampleArgs {
    /// Render offscreen.
    pub headless: bool,
    /// Frames to run (measured frames when headless).
    pub frames: Option<u32>,
    /// Render size; `None` means the mode's default.
    pub size: Option<UVec2>,
    /// Where to save the last frame.
    pub screenshot: Option<PathBuf>,
    /// Where to write the JSON statistics.
    pub stats: Option<PathBuf>,
    /// Frames of a soak run (implies headless).
    pub soak: Option<u32>,
}

/// Usage text printed for `--help` and bad flags.
pub const USAGE: &str =
    "flags: [--headless] [--frames N] [--size WxH] [--screenshot PATH] [--stats PATH] [--soak N]";

impl ExampleArgs {
    /// Parses flags (without the program name).
    pub fn parse_from<I, S>(args: I) -> Result<Self, String>
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        let mut parsed = Self {
            headless: false,
            frames: None,
            size: None,
            screenshot: None,
            stats: None,
            soak: None,
        };
        let mut args = args.into_iter().map(Into::into);
        while let Some(arg) = args.next() {
            let (flag, inline) = match arg.split_once('=') {
                Some((f, v)) => (f.to_string(), Some(v.to_string())),
                None => (arg.clone(), None),
            };
            let mut value = |name: &str| {
                inline
                    .clone()
                    .or_else(|| args.next())
                    .ok_or_else(|| format!("{name} needs a value; {USAGE}"))
            };
            match flag.as_str() {
                "--headless" => parsed.headless = true,
                "--frames" => {
                    let v = value("--frames")?;
                    let n: u32 = v
                        .parse()
                        .map_err(|_| format!("--frames: '{v}' is not a whole number"))?;
                    if n == 0 {
                        return Err("--frames must be at least 1".into());
                    }
                    parsed.frames = Some(n);
                }
                "--size" => parsed.size = Some(parse_size(&value("--size")?)?),
                "--screenshot" => parsed.screenshot = Some(value("--screenshot")?.into()),
                "--stats" => parsed.stats = Some(value("--stats")?.into()),
                "--soak" => {
                    let v = value("--soak")?;
                    let n: u32 = v
                        .parse()
                        .ok()
                        .filter(|&n| n > 0)
                        .ok_or_else(|| format!("--soak: '{v}' is not a number of frames"))?;
                    parsed.soak = Some(n);
                    parsed.headless = true;
                }
                "--help" | "-h" => return Err(USAGE.into()),
                other => return Err(format!("unknown flag '{other}'; {USAGE}")),
            }
        }
        Ok(parsed)
    }

    /// Parses the process arguments; prints the problem and exits with status 2 on bad flags.
    pub fn from_env() -> Self {
        match Self::parse_from(std::env::args().skip(1)) {
            Ok(args) => args,
            Err(message) => {
                eprintln!("{message}");
                std::process::exit(2);
            }
        }
    }
}

/// Parses `WxH` (e.g. `640x360`).
pub fn parse_size(text: &str) -> Result<UVec2, String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("--size: '{text}' is not WxH"))?;
    let parse = |s: &str| {
        s.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=16384).contains(v))
            .ok_or_else(|| format!("--size: '{text}' needs two whole numbers in 1..=16384"))
    };
    Ok(UVec2::new(parse(w)?, parse(h)?))
}

/// Whether a window could be opened: an X11 or Wayland display is named in the environment.
pub fn display_available() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|var| std::env::var(var).is_ok_and(|v| !v.is_empty()))
}

/// Runs an example scene windowed or headless. See the module docs.
pub struct ExampleRunner {
    name: String,
    args: ExampleArgs,
    #[cfg_attr(not(feature = "windowed"), allow(dead_code))]
    inspected: Vec<fn(&mut App)>,
    ready_when: Option<fn(&mut World) -> bool>,
}

impl ExampleRunner {
    /// A runner for the example `name`, with flags from the command line.
    pub fn new(name: impl Into<String>) -> Self {
        Self::with_args(name, ExampleArgs::from_env())
    }

    /// A runner with explicit flags (tests use this).
    pub fn with_args(name: impl Into<String>, args: ExampleArgs) -> Self {
        Self {
            name: name.into(),
            args,
            inspected: Vec::new(),
            ready_when: None,
        }
    }

    /// Headless runs wait, besides the pipelines, until `condition` holds (a bake finished, an
    /// asset loaded) before measuring and taking the screenshot.
    pub fn ready_when(mut self, condition: fn(&mut World) -> bool) -> Self {
        self.ready_when = Some(condition);
        self
    }

    /// The parsed flags.
    pub fn args(&self) -> &ExampleArgs {
        &self.args
    }

    /// Shows and edits the reflected resource `R` (a plugin's settings) in the windowed panel.
    pub fn inspect_resource<R>(mut self) -> Self
    where
        R: Resource + Component<Mutability = bevy::ecs::component::Mutable> + Reflect,
    {
        #[cfg(feature = "windowed")]
        self.inspected.push(crate::panel::inspect_resource::<R>);
        #[cfg(not(feature = "windowed"))]
        let _ = &mut self;
        self
    }

    /// Shows and edits the reflected component `C` (e.g. a light's shadow settings) on every
    /// entity that has it, in the windowed panel.
    pub fn inspect_component<C>(mut self) -> Self
    where
        C: Component<Mutability = bevy::ecs::component::Mutable> + Reflect,
    {
        #[cfg(feature = "windowed")]
        self.inspected.push(crate::panel::inspect_component::<C>);
        #[cfg(not(feature = "windowed"))]
        let _ = &mut self;
        self
    }

    /// Whether this run will be headless (asked for, or no display, or no windowed support).
    pub fn is_headless(&self) -> bool {
        if self.args.headless {
            return true;
        }
        if !cfg!(feature = "windowed") {
            eprintln!(
                "{}: built without the `windowed` feature: running headless",
                self.name
            );
            return true;
        }
        if !display_available() {
            eprintln!(
                "{}: no display available (DISPLAY and WAYLAND_DISPLAY are unset): running headless",
                self.name
            );
            return true;
        }
        false
    }

    /// Builds the app with `scene` (which adds the plugins and spawns the scene, camera
    /// included) and runs it.
    pub fn run(self, scene: impl FnOnce(&mut App)) -> AppExit {
        if self.is_headless() {
            let name = self.name.clone();
            match self.run_headless(scene) {
                Ok(()) => AppExit::Success,
                Err(message) => {
                    eprintln!("{name}: {message}");
                    AppExit::error()
                }
            }
        } else {
            self.run_windowed(scene)
        }
    }

    fn run_headless(self, scene: impl FnOnce(&mut App)) -> Result<(), String> {
        let size = self.args.size.unwrap_or(UVec2::new(640, 360));
        let adapter = crate::adapter::require_adapter(&self.name).ok_or("no GPU adapter")?;
        let software = adapter.device_type == "Cpu";
        let frames = headless_frames(self.args.frames, software);
        if software && self.args.frames.is_none() && self.args.soak.is_none() {
            eprintln!(
                "{}: software rasteriser ({}): measuring {frames} frames rather than 60 (--frames N for more)",
                self.name, adapter.name
            );
        }
        let mut harness =
            RenderHarness::new(HarnessConfig::sized(size.x, size.y)).map_err(|e| e.to_string())?;
        scene(harness.app_mut());
        let condition = self.ready_when.unwrap_or(|_| true);
        let mut progress = ProgressThrottle::default();
        let warmup = harness
            .wait_until_reporting(condition, |frame, compiling| {
                if let Some(elapsed) = progress.due() {
                    eprintln!(
                        "{}: warming up, frame {frame} ({compiling} pipelines compiling, {elapsed:.0} s)",
                        self.name
                    );
                }
            })
            .map_err(|e| e.to_string())?;
        match self.args.soak {
            Some(soak) => eprintln!(
                "{}: scene ready after {warmup} frames; soaking {soak} frames",
                self.name
            ),
            None => eprintln!(
                "{}: scene ready after {warmup} frames; measuring {frames} frames",
                self.name
            ),
        }
        if let Some(frames) = self.args.soak {
            let samples = crate::soak::soak(&mut harness, &self.name, frames)?;
            let json = crate::soak::report_json(&self.name, frames, &samples);
            println!("{json}");
            if let Some(path) = &self.args.stats {
                write_atomically(path, &json)?;
                eprintln!("{}: soak samples written to {}", self.name, path.display());
            }
            return Ok(());
        }
        harness.reset_timing();
        let mut progress = ProgressThrottle::default();
        for frame in 1..=frames {
            harness.run_frames(1).map_err(|e| e.to_string())?;
            if let Some(elapsed) = progress.due().filter(|_| frame < frames) {
                eprintln!(
                    "{}: frame {frame} of {frames} measured ({elapsed:.0} s)",
                    self.name
                );
            }
        }
        let stats = harness.run_stats(&self.name);
        if let Some(path) = &self.args.screenshot {
            let image = harness.render().map_err(|e| e.to_string())?;
            image.save_png(path)?;
            eprintln!("{}: screenshot written to {}", self.name, path.display());
        }
        let json = stats.to_json();
        println!("{json}");
        if let Some(path) = &self.args.stats {
            write_atomically(path, &json)?;
            eprintln!("{}: stats written to {}", self.name, path.display());
        }
        Ok(())
    }

    #[cfg(not(feature = "windowed"))]
    fn run_windowed(self, _scene: impl FnOnce(&mut App)) -> AppExit {
        unreachable!("is_headless() is always true without the windowed feature")
    }

    #[cfg(feature = "windowed")]
    fn run_windowed(self, scene: impl FnOnce(&mut App)) -> AppExit {
        let size = self.args.size.unwrap_or(UVec2::new(1280, 720));
        let mut app = App::new();
        app.add_plugins(DefaultPlugins.set(WindowPlugin {
            primary_window: Some(Window {
                title: format!("bevy_nature — {}", self.name),
                resolution: bevy::window::WindowResolution::new(size.x, size.y),
                ..default()
            }),
            ..default()
        }));
        app.add_plugins(bevy::render::diagnostic::RenderDiagnosticsPlugin);
        crate::panel::add_panel(
            &mut app,
            crate::panel::PanelRun {
                name: self.name.clone(),
                frames: self.args.frames,
                screenshot: self.args.screenshot.clone(),
                stats: self.args.stats.clone(),
                size,
            },
        );
        for inspect in &self.inspected {
            inspect(&mut app);
        }
        scene(&mut app);
        app.run()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_all_flags() {
        let args = ExampleArgs::parse_from([
            "--headless",
            "--frames",
            "12",
            "--size=320x200",
            "--screenshot",
            "a.png",
            "--stats",
            "s.json",
        ])
        .unwrap();
        assert!(args.headless);
        assert_eq!(args.frames, Some(12));
        assert_eq!(args.size, Some(UVec2::new(320, 200)));
        assert_eq!(args.screenshot, Some(PathBuf::from("a.png")));
        assert_eq!(args.stats, Some(PathBuf::from("s.json")));
        let soak = ExampleArgs::parse_from(["--soak", "10000"]).unwrap();
        assert_eq!(soak.soak, Some(10_000));
        assert!(soak.headless, "a soak runs headless");
        assert!(ExampleArgs::parse_from(["--soak", "0"]).is_err());
    }

    #[test]
    fn progress_lines_come_at_most_once_a_period() {
        let mut progress = ProgressThrottle::default();
        assert_eq!(progress.due_at(0.5), None);
        assert_eq!(progress.due_at(PROGRESS_SECONDS), Some(PROGRESS_SECONDS));
        // Counted from the last line written, not from the start.
        assert_eq!(progress.due_at(PROGRESS_SECONDS + 9.0), None);
        let next = 2.0 * PROGRESS_SECONDS + 1.0;
        assert_eq!(progress.due_at(next), Some(next));
        assert_eq!(progress.due_at(next + 0.1), None);
    }

    #[test]
    fn defaults_are_windowed_and_unset() {
        let args = ExampleArgs::parse_from(Vec::<String>::new()).unwrap();
        assert!(!args.headless);
        assert_eq!(args.frames, None);
        assert_eq!(args.size, None);
    }

    /// A headless run measures what it is asked for; unasked, 60 frames on a GPU and a few on
    /// a software rasteriser.
    #[test]
    fn a_software_rasteriser_measures_fewer_frames_unless_asked() {
        assert_eq!(headless_frames(None, false), 60);
        assert_eq!(headless_frames(None, true), SOFTWARE_DEFAULT_FRAMES);
        assert_eq!(headless_frames(Some(120), true), 120);
        assert_eq!(headless_frames(Some(7), false), 7);
    }

    #[test]
    fn rejects_bad_flags() {
        assert!(ExampleArgs::parse_from(["--size", "640"]).is_err());
        assert!(ExampleArgs::parse_from(["--size", "0x10"]).is_err());
        assert!(ExampleArgs::parse_from(["--frames", "-3"]).is_err());
        assert!(ExampleArgs::parse_from(["--frames", "0"]).is_err());
        assert!(ExampleArgs::parse_from(["--frames"]).is_err());
        assert!(ExampleArgs::parse_from(["--fast"]).is_err());
    }
}
