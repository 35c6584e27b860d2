//! A bake killed at random points (`foliage_bake`, SIGKILL, 10 trials spread over the run) leaves
//! no damaged `.foliage` file — every file where a finished one belongs loads — and running it
//! again to the end writes byte-identical files to an uninterrupted bake.

use bevy_foliage::pruning::format::decode;
use bevy_nature_harness::interrupt::{
    Interrupted, files_of, kill_delays, run_killed_after, run_to_completion,
};
use std::path::Path;
use std::process::Command;

fn bake_into(out: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_foliage_bake"));
    command
        // Two rays a bin and two points a leaf for the seen-part gains and the open maps: the
        // determinism of each is checked too, at a fraction of the default bake's cost.
        .args([
            "--resolution",
            "64",
            "--depth",
            "7",
            "--rays-per-bin",
            "2",
            "--seen-points",
            "2",
            "--open-map-points",
            "2",
            "--out",
        ])
        .arg(out)
        .args(["olea", "fraxinus"]);
    command
}

#[test]
fn a_killed_bake_rerun_gives_the_same_bytes() {
    let root = std::env::temp_dir().join(format!("interrupted_bake_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let reference_dir = root.join("reference");
    std::fs::create_dir_all(&reference_dir).unwrap();
    let length = run_to_completion(&mut bake_into(&reference_dir)).unwrap();
    let reference = files_of(&reference_dir).unwrap();
    assert_eq!(
        reference
            .keys()
            .map(|p| p.to_string_lossy().into_owned())
            .collect::<Vec<_>>(),
        ["fraxinus.foliage", "olea.foliage"]
    );
    let mut killed = 0;
    for (trial, delay) in kill_delays(length, 10, 0xBA4E).into_iter().enumerate() {
        let dir = root.join(format!("trial{trial}"));
        std::fs::create_dir_all(&dir).unwrap();
        let how = run_killed_after(&mut bake_into(&dir), delay).unwrap();
        killed += (how == Interrupted::Killed) as u32;
        // What the kill left: only whole files where finished ones belong.
        for (path, bytes) in files_of(&dir).unwrap() {
            assert!(
                decode(&bytes).is_ok(),
                "trial {trial} (killed after {delay:?}): {} is damaged",
                path.display()
            );
            assert_eq!(
                Some(&bytes),
                reference.get(&path),
                "trial {trial}: {} differs",
                path.display()
            );
        }
        run_to_completion(&mut bake_into(&dir)).unwrap();
        assert_eq!(
            files_of(&dir).unwrap(),
            reference,
            "trial {trial}: the rerun after a kill at {delay:?} wrote other bytes"
        );
    }
    eprintln!("bake of {length:?}: {killed} of 10 trials killed part way, all reruns identical");
    assert!(
        killed >= 5,
        "the kills should land inside the run: {killed}"
    );
    let _ = std::fs::remove_dir_all(&root);
}
