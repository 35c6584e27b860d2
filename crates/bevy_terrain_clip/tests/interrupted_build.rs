//! A pyramid build killed at random points (`pyramid_build`, SIGKILL, 10 trials spread over the
//! run) leaves no damaged tile and no manifest before the last tile — every file present equals
//! the uninterrupted build's — and running it again resumes to byte-identical output.

use bevy_nature_harness::interrupt::{
    Interrupted, files_of, kill_delays, run_killed_after, run_to_completion,
};
use std::path::Path;
use std::process::Command;

fn build(image: &Path, out: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_pyramid_build"));
    command.arg(image).arg(out).args(["--tile", "64"]);
    command
}

#[test]
fn a_killed_build_rerun_gives_the_same_bytes() {
    let root = std::env::temp_dir().join(format!("interrupted_build_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    // 2048² of texture-like imagery: 1024 + 256 + 64 + 16 + 4 + 1 tiles of 64².
    let image = root.join("imagery.png");
    image::RgbImage::from_fn(2048, 2048, |x, y| {
        let v = |k: u32| ((x * k + y * (k + 3)) ^ (x / 7 + y / 5)) as u8;
        image::Rgb([v(3), v(5), v(11)])
    })
    .save(&image)
    .unwrap();
    let reference_dir = root.join("reference");
    let first = run_to_completion(&mut build(&image, &reference_dir)).unwrap();
    let reference = files_of(&reference_dir).unwrap();
    assert_eq!(reference.len(), 1365 + 1, "every tile and the manifest");
    // The run's length once the image is in the page cache (as in the trials).
    std::fs::remove_dir_all(&reference_dir).unwrap();
    let length = run_to_completion(&mut build(&image, &reference_dir))
        .unwrap()
        .min(first);
    assert_eq!(
        files_of(&reference_dir).unwrap(),
        reference,
        "the build is deterministic"
    );
    let mut killed = 0;
    let mut partial = Vec::new();
    for (trial, delay) in kill_delays(length, 10, 0x7E44).into_iter().enumerate() {
        let dir = root.join(format!("trial{trial}"));
        let how = run_killed_after(&mut build(&image, &dir), delay).unwrap();
        killed += (how == Interrupted::Killed) as u32;
        let left = if dir.exists() {
            files_of(&dir).unwrap()
        } else {
            Default::default()
        };
        for (path, bytes) in &left {
            assert_eq!(
                Some(bytes),
                reference.get(path),
                "trial {trial} (killed after {delay:?}): {} is not the finished file",
                path.display()
            );
        }
        if how == Interrupted::Killed {
            assert!(
                !left.contains_key(Path::new("pyramid.json")) || left.len() == reference.len(),
                "trial {trial}: a manifest before the last tile"
            );
        }
        partial.push(left.len());
        run_to_completion(&mut build(&image, &dir)).unwrap();
        assert_eq!(
            files_of(&dir).unwrap(),
            reference,
            "trial {trial}: the rerun after a kill at {delay:?} wrote other bytes"
        );
    }
    eprintln!(
        "build of {length:?}: {killed} of 10 trials killed part way, files left {partial:?} of {}, all reruns identical",
        reference.len()
    );
    // Kills late in the run may miss it (a run's length varies); enough land mid-build.
    let mid_build = partial
        .iter()
        .filter(|&&n| n > 0 && n < reference.len())
        .count();
    assert!(
        killed >= 5 && mid_build >= 3,
        "the kills should land inside the run: {killed} killed, {mid_build} mid-build"
    );
    let _ = std::fs::remove_dir_all(&root);
}
