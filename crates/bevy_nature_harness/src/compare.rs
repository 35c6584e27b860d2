//! Comparing renders by numbers.
//!
//! All metrics work on 8-bit sRGB-encoded RGBA images, as read back from the render target.
//! Colour channels are compared as values in `[0, 1]`; alpha is ignored (render targets are opaque).
//!
//! - [`rmse`]: root-mean-square error over the RGB channels.
//! - [`psnr`]: peak signal-to-noise ratio in dB, `10 log10(1 / mse)` (infinite for equal images).
//! - [`ssim`]: mean structural similarity of the luma channel over 8×8 windows
//!   (Wang et al. 2004, constants `C1 = (0.01)^2`, `C2 = (0.03)^2`, stride 4).
//! - [`coverage`]: the fraction of pixels selected by a mask — e.g. "pixels that differ from the
//!   background colour by more than a threshold", which is how crown coverage is measured.
//!
//! [`Comparison`] bundles the figures for a pair of images and, when a test's assertion on it
//! fails, writes both images and an amplified difference image under [`artifacts_dir`].

use std::path::{Path, PathBuf};

/// An 8-bit RGBA image, row-major, top row first, sRGB-encoded colour.
#[derive(Clone, PartialEq, Eq)]
pub struct RgbaImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height * 4` bytes.
    pub data: Vec<u8>,
}

impl std::fmt::Debug for RgbaImage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "RgbaImage({}x{})", self.width, self.height)
    }
}

impl RgbaImage {
    /// Wraps raw RGBA bytes.
    ///
    /// # Panics
    /// If `data.len() != width * height * 4`.
    pub fn new(width: u32, height: u32, data: Vec<u8>) -> Self {
        assert_eq!(
            data.len(),
            width as usize * height as usize * 4,
            "RGBA data does not match {width}x{height}"
        );
        Self {
            width,
            height,
            data,
        }
    }

    /// An image filled with one colour.
    pub fn filled(width: u32, height: u32, rgba: [u8; 4]) -> Self {
        let data = rgba
            .iter()
            .copied()
            .cycle()
            .take(width as usize * height as usize * 4)
            .collect();
        Self::new(width, height, data)
    }

    /// The pixel at `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = (y as usize * self.width as usize + x as usize) * 4;
        [
            self.data[i],
            self.data[i + 1],
            self.data[i + 2],
            self.data[i + 3],
        ]
    }

    /// Sets the pixel at `(x, y)`.
    pub fn set_pixel(&mut self, x: u32, y: u32, rgba: [u8; 4]) {
        let i = (y as usize * self.width as usize + x as usize) * 4;
        self.data[i..i + 4].copy_from_slice(&rgba);
    }

    /// The image box-filtered by `k × k` (means of the encoded values, rounded; partial blocks
    /// at the right and bottom edges dropped): how a crown or forest looks from farther away,
    /// where single leaves no longer matter but their density does.
    pub fn box_downsample(&self, k: u32) -> RgbaImage {
        let k = k.max(1);
        let (w, h) = (self.width / k, self.height / k);
        let mut out = RgbaImage::filled(w, h, [0, 0, 0, 255]);
        let n = k * k;
        for y in 0..h {
            for x in 0..w {
                let mut sum = [0u32; 4];
                for dy in 0..k {
                    for dx in 0..k {
                        let p = self.pixel(x * k + dx, y * k + dy);
                        for c in 0..4 {
                            sum[c] += p[c] as u32;
                        }
                    }
                }
                out.set_pixel(x, y, sum.map(|s| ((s + n / 2) / n) as u8));
            }
        }
        out
    }

    /// Rec. 709 luma of the sRGB-encoded values at `(x, y)`, in `[0, 1]`.
    pub fn luma(&self, x: u32, y: u32) -> f64 {
        let [r, g, b, _] = self.pixel(x, y);
        (0.2126 * r as f64 + 0.7152 * g as f64 + 0.0722 * b as f64) / 255.0
    }

    /// Mean luma over a rectangle `[x0, x1) × [y0, y1)` (clamped to the image).
    pub fn mean_luma(&self, x0: u32, y0: u32, x1: u32, y1: u32) -> f64 {
        let (x1, y1) = (x1.min(self.width), y1.min(self.height));
        let mut sum = 0.0;
        let mut n = 0usize;
        for y in y0..y1 {
            for x in x0..x1 {
                sum += self.luma(x, y);
                n += 1;
            }
        }
        if n == 0 { 0.0 } else { sum / n as f64 }
    }

    /// Converts a Bevy [`Image`](bevy::image::Image) (any format `image` can decode, e.g. the
    /// `Rgba8UnormSrgb` or `Bgra8UnormSrgb` a screenshot returns) into RGBA8.
    pub fn from_bevy(image: bevy::image::Image) -> Result<Self, String> {
        let dynamic = image
            .try_into_dynamic()
            .map_err(|e| format!("cannot convert the read-back image: {e}"))?;
        let rgba = dynamic.to_rgba8();
        Ok(Self::new(rgba.width(), rgba.height(), rgba.into_raw()))
    }

    /// Writes the image as PNG, creating parent folders. Written to a temporary file first and
    /// renamed, so a reader never sees half a file.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), String> {
        let path = path.as_ref();
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .map_err(|e| format!("cannot create {}: {e}", parent.display()))?;
        }
        let tmp = path.with_extension("png.tmp");
        let buffer = image::RgbaImage::from_raw(self.width, self.height, self.data.clone())
            .ok_or("image buffer size mismatch")?;
        buffer
            .save_with_format(&tmp, image::ImageFormat::Png)
            .map_err(|e| format!("cannot write {}: {e}", tmp.display()))?;
        std::fs::rename(&tmp, path).map_err(|e| format!("cannot rename to {}: {e}", path.display()))
    }

    /// Reads a PNG (or any format the `image` crate was built with).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, String> {
        let path = path.as_ref();
        let img = image::open(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        let rgba = img.to_rgba8();
        Ok(Self::new(rgba.width(), rgba.height(), rgba.into_raw()))
    }
}

fn check_same_size(a: &RgbaImage, b: &RgbaImage) {
    assert!(
        a.width == b.width && a.height == b.height,
        "images differ in size: {}x{} vs {}x{}",
        a.width,
        a.height,
        b.width,
        b.height
    );
}

/// Mean squared error over the RGB channels, values in `[0, 1]`.
pub fn mse(a: &RgbaImage, b: &RgbaImage) -> f64 {
    check_same_size(a, b);
    let mut sum = 0.0;
    for (pa, pb) in a.data.chunks_exact(4).zip(b.data.chunks_exact(4)) {
        for c in 0..3 {
            let d = (pa[c] as f64 - pb[c] as f64) / 255.0;
            sum += d * d;
        }
    }
    sum / (a.data.len() / 4 * 3).max(1) as f64
}

/// Root-mean-square error over the RGB channels, in `[0, 1]`.
pub fn rmse(a: &RgbaImage, b: &RgbaImage) -> f64 {
    mse(a, b).sqrt()
}

/// Peak signal-to-noise ratio in dB (peak 1.0). `f64::INFINITY` for identical images.
pub fn psnr(a: &RgbaImage, b: &RgbaImage) -> f64 {
    let m = mse(a, b);
    if m == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (1.0 / m).log10()
    }
}

/// Mean SSIM of the luma channel over 8×8 windows with stride 4 (1.0 for identical images).
///
/// Images smaller than a window are compared as one window.
pub fn ssim(a: &RgbaImage, b: &RgbaImage) -> f64 {
    check_same_size(a, b);
    const C1: f64 = 0.01 * 0.01;
    const C2: f64 = 0.03 * 0.03;
    let win = 8.min(a.width).min(a.height).max(1);
    let stride = (win / 2).max(1);
    let mut total = 0.0;
    let mut windows = 0usize;
    let mut y0 = 0;
    while y0 + win <= a.height {
        let mut x0 = 0;
        while x0 + win <= a.width {
            let n = (win * win) as f64;
            let (mut ma, mut mb) = (0.0, 0.0);
            for y in y0..y0 + win {
                for x in x0..x0 + win {
                    ma += a.luma(x, y);
                    mb += b.luma(x, y);
                }
            }
            ma /= n;
            mb /= n;
            let (mut va, mut vb, mut cov) = (0.0, 0.0, 0.0);
            for y in y0..y0 + win {
                for x in x0..x0 + win {
                    let da = a.luma(x, y) - ma;
                    let db = b.luma(x, y) - mb;
                    va += da * da;
                    vb += db * db;
                    cov += da * db;
                }
            }
            let denom = n - 1.0;
            if denom > 0.0 {
                va /= denom;
                vb /= denom;
                cov /= denom;
            }
            total += ((2.0 * ma * mb + C1) * (2.0 * cov + C2))
                / ((ma * ma + mb * mb + C1) * (va + vb + C2));
            windows += 1;
            x0 += stride;
        }
        y0 += stride;
    }
    if windows == 0 {
        1.0
    } else {
        total / windows as f64
    }
}

/// Largest per-channel difference between `pixel` and `reference`, in `[0, 255]`.
pub fn channel_distance(pixel: [u8; 4], reference: [u8; 4]) -> u8 {
    (0..3)
        .map(|c| pixel[c].abs_diff(reference[c]))
        .max()
        .unwrap_or(0)
}

/// Fraction of pixels for which `mask(x, y, pixel)` holds.
pub fn coverage(image: &RgbaImage, mut mask: impl FnMut(u32, u32, [u8; 4]) -> bool) -> f64 {
    let mut hits = 0usize;
    for y in 0..image.height {
        for x in 0..image.width {
            if mask(x, y, image.pixel(x, y)) {
                hits += 1;
            }
        }
    }
    hits as f64 / (image.width as usize * image.height as usize).max(1) as f64
}

/// Fraction of pixels that differ from `background` by more than `threshold` in some channel:
/// the screen coverage of whatever was drawn over a plain background.
pub fn coverage_against_background(image: &RgbaImage, background: [u8; 4], threshold: u8) -> f64 {
    coverage(image, |_, _, p| channel_distance(p, background) > threshold)
}

/// A difference image: per-channel `|a - b|` amplified by `gain`, opaque.
pub fn difference_image(a: &RgbaImage, b: &RgbaImage, gain: f64) -> RgbaImage {
    check_same_size(a, b);
    let data = a
        .data
        .chunks_exact(4)
        .zip(b.data.chunks_exact(4))
        .flat_map(|(pa, pb)| {
            let d = |c: usize| ((pa[c].abs_diff(pb[c]) as f64 * gain).min(255.0)) as u8;
            [d(0), d(1), d(2), 255]
        })
        .collect();
    RgbaImage::new(a.width, a.height, data)
}

/// Where failed comparisons and example screenshots are written: `<workspace>/target/nature-artifacts`.
///
/// The workspace is found by walking up from `CARGO_MANIFEST_DIR` (set by cargo for tests and
/// `cargo run`) or the current directory to the folder holding `Cargo.lock`. `NATURE_ARTIFACTS_DIR`
/// overrides it.
pub fn artifacts_dir() -> PathBuf {
    if let Ok(dir) = std::env::var("NATURE_ARTIFACTS_DIR") {
        return PathBuf::from(dir);
    }
    let start = std::env::var("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .or_else(|_| std::env::current_dir())
        .unwrap_or_else(|_| PathBuf::from("."));
    let root = start
        .ancestors()
        .find(|dir| dir.join("Cargo.lock").exists())
        .unwrap_or(&start)
        .to_path_buf();
    root.join("target").join("nature-artifacts")
}

/// The figures of one image comparison, plus the images to save if a test's assertion fails.
#[derive(Clone, Debug)]
pub struct Comparison {
    /// A name for artifacts (`target/nature-artifacts/<name>/`).
    pub name: String,
    /// RMSE over RGB in `[0, 1]`.
    pub rmse: f64,
    /// PSNR in dB.
    pub psnr: f64,
    /// Mean luma SSIM.
    pub ssim: f64,
    /// The image under test.
    pub actual: RgbaImage,
    /// The reference.
    pub reference: RgbaImage,
    /// Where artifacts go; `None` means [`artifacts_dir`].
    pub artifacts_root: Option<PathBuf>,
}

impl Comparison {
    /// Compares `actual` against `reference`.
    pub fn new(name: impl Into<String>, actual: &RgbaImage, reference: &RgbaImage) -> Self {
        Self {
            name: name.into(),
            rmse: rmse(actual, reference),
            psnr: psnr(actual, reference),
            ssim: ssim(actual, reference),
            actual: actual.clone(),
            reference: reference.clone(),
            artifacts_root: None,
        }
    }

    /// Writes artifacts under `root` instead of [`artifacts_dir`].
    pub fn with_artifacts_root(mut self, root: impl Into<PathBuf>) -> Self {
        self.artifacts_root = Some(root.into());
        self
    }

    /// Writes `actual.png`, `reference.png` and `difference.png` (×8) under
    /// `artifacts_dir()/<name>/` and returns that folder.
    pub fn save_artifacts(&self) -> PathBuf {
        let root = self.artifacts_root.clone().unwrap_or_else(artifacts_dir);
        let dir = root.join(sanitize(&self.name));
        let write = |file: &str, image: &RgbaImage| {
            if let Err(e) = image.save_png(dir.join(file)) {
                eprintln!("could not save comparison artifact {file}: {e}");
            }
        };
        write("actual.png", &self.actual);
        write("reference.png", &self.reference);
        write(
            "difference.png",
            &difference_image(&self.actual, &self.reference, 8.0),
        );
        dir
    }

    /// Asserts a condition on this comparison; on failure saves the artifacts and panics with
    /// the figures, the reason and where the images are.
    #[track_caller]
    pub fn assert(&self, condition: bool, what: &str) {
        if !condition {
            let dir = self.save_artifacts();
            panic!(
                "comparison '{}' failed: {what}\n  rmse {:.5}, psnr {:.2} dB, ssim {:.4}\n  images: {}",
                self.name,
                self.rmse,
                self.psnr,
                self.ssim,
                dir.display()
            );
        }
    }

    /// Asserts that the images are close: `rmse <= max_rmse`.
    #[track_caller]
    pub fn assert_rmse_at_most(&self, max_rmse: f64) {
        self.assert(
            self.rmse <= max_rmse,
            &format!("expected rmse <= {max_rmse}"),
        );
    }

    /// Asserts that the images clearly differ: `rmse >= min_rmse`.
    #[track_caller]
    pub fn assert_rmse_at_least(&self, min_rmse: f64) {
        self.assert(
            self.rmse >= min_rmse,
            &format!("expected rmse >= {min_rmse} (images should differ)"),
        );
    }
}

fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_downsample_averages_blocks() {
        let mut img = RgbaImage::filled(4, 2, [0, 0, 0, 255]);
        img.set_pixel(0, 0, [255, 100, 0, 255]);
        img.set_pixel(1, 1, [255, 0, 0, 255]);
        let small = img.box_downsample(2);
        assert_eq!((small.width, small.height), (2, 1));
        assert_eq!(small.pixel(0, 0), [128, 25, 0, 255]);
        assert_eq!(small.pixel(1, 0), [0, 0, 0, 255]);
    }

    fn gradient(w: u32, h: u32) -> RgbaImage {
        let mut img = RgbaImage::filled(w, h, [0, 0, 0, 255]);
        for y in 0..h {
            for x in 0..w {
                let v = ((x + y) * 255 / (w + h - 2)) as u8;
                img.set_pixel(x, y, [v, v / 2, 255 - v, 255]);
            }
        }
        img
    }

    #[test]
    fn identical_images_are_perfect() {
        let a = gradient(32, 24);
        assert_eq!(rmse(&a, &a), 0.0);
        assert!(psnr(&a, &a).is_infinite());
        assert!((ssim(&a, &a) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rmse_matches_hand_computation() {
        // One channel of one pixel off by 255 in a 2x1 image: mse = 1 / 6.
        let a = RgbaImage::filled(2, 1, [0, 0, 0, 255]);
        let mut b = a.clone();
        b.set_pixel(1, 0, [255, 0, 0, 255]);
        assert!((mse(&a, &b) - 1.0 / 6.0).abs() < 1e-12);
        assert!((rmse(&a, &b) - (1.0f64 / 6.0).sqrt()).abs() < 1e-12);
        assert!((psnr(&a, &b) - 10.0 * 6f64.log10()).abs() < 1e-9);
    }

    #[test]
    fn ssim_drops_for_structural_change_more_than_for_brightness_shift() {
        let a = gradient(64, 64);
        let mut noisy = a.clone();
        let mut state = 12345u32;
        for y in 0..64 {
            for x in 0..64 {
                state = state.wrapping_mul(1664525).wrapping_add(1013904223);
                let n = (state >> 24) as u8;
                let p = a.pixel(x, y);
                noisy.set_pixel(x, y, [p[0] ^ n, p[1] ^ n, p[2] ^ n, 255]);
            }
        }
        let structural = ssim(&a, &noisy);
        assert!(structural < 0.5, "ssim of noise {structural}");
        let mut brighter = a.clone();
        for px in brighter.data.chunks_exact_mut(4) {
            for c in &mut px[..3] {
                *c = c.saturating_add(10);
            }
        }
        let shifted = ssim(&a, &brighter);
        assert!(
            shifted > structural && shifted > 0.9,
            "ssim of shift {shifted}"
        );
    }

    #[test]
    fn coverage_counts_pixels_off_background() {
        let mut img = RgbaImage::filled(10, 10, [20, 30, 40, 255]);
        for x in 0..5 {
            img.set_pixel(x, 0, [200, 30, 40, 255]);
        }
        img.set_pixel(9, 9, [22, 30, 40, 255]); // within threshold
        let c = coverage_against_background(&img, [20, 30, 40, 255], 8);
        assert!((c - 0.05).abs() < 1e-12, "coverage {c}");
    }

    #[test]
    fn failed_assertion_writes_artifacts() {
        let dir =
            std::env::temp_dir().join(format!("nature-artifacts-test-{}", std::process::id()));
        let a = RgbaImage::filled(4, 4, [0, 0, 0, 255]);
        let b = RgbaImage::filled(4, 4, [255, 255, 255, 255]);
        let cmp = Comparison::new("unit/failing", &a, &b).with_artifacts_root(&dir);
        let result = std::panic::catch_unwind(|| cmp.assert_rmse_at_most(0.1));
        assert!(
            result.is_err(),
            "a large difference must fail the assertion"
        );
        let out = dir.join("unit_failing");
        for f in ["actual.png", "reference.png", "difference.png"] {
            let img = RgbaImage::load(out.join(f)).expect(f);
            assert_eq!((img.width, img.height), (4, 4));
        }
        let diff = RgbaImage::load(out.join("difference.png")).unwrap();
        assert_eq!(diff.pixel(0, 0), [255, 255, 255, 255]);
        let _ = std::fs::remove_dir_all(dir);
    }
}
