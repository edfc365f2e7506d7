//! Checkpoint and resume of `rovib ensemble`, in one process: a run killed with SIGKILL part way,
//! or stopped by a panicking trajectory, continues with `--resume` to outputs byte-identical to
//! an uninterrupted run's. (The same under MPI: tests/mpi.rs, with `--features mpi`.)
//! Shown able to fail (BENCHMARKS.md, "Ensembles over MPI"): a resume that skips a block, and
//! blocks merged in arrival order, both fail the byte comparison here.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::Duration;

use common::ensemble::{assert_same_statistics, lines, summary, thermal_scene, wait_at_most, wait_for_lines};

/// Trajectories of the test scene: 40 blocks of 64 (with 10 blocks, the lane integrator
/// sometimes finished them all before the test's SIGKILL arrived).
const N: u64 = 2560;
/// The checkpoint's lines when every block is recorded: a header and one line per block.
const ALL_LINES: usize = 1 + (N / 64) as usize;
/// Their length, a.u.
const END: f64 = 500.0;

fn dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-ensemble-resume-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn rovib(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rovib"));
    c.args(args).env_remove(rovib::ensemble::runner::PANIC_HOOK);
    c
}

fn ensemble(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["ensemble", scene.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"];
    args.extend_from_slice(extra);
    rovib(&args).output().unwrap()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_run_killed_part_way_resumes_to_the_same_bytes() {
    let d = dir("kill");
    let scene = thermal_scene(&d, N, END);
    let reference = d.join("reference");
    ok(&ensemble(&scene, &reference, &["--threads", "2"]));
    assert!(!reference.join("checkpoint.jsonl").exists(), "a completed run removes its checkpoint");

    let out = d.join("killed");
    let checkpoint = out.join("checkpoint.jsonl");
    let mut child = rovib(&["ensemble", scene.to_str().unwrap(), "--out", out.to_str().unwrap(), "--threads", "2"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The header and three blocks, then SIGKILL: no chance to clean up.
    wait_for_lines(&checkpoint, 4, Duration::from_secs(120));
    child.kill().unwrap();
    wait_at_most(&mut child, Duration::from_secs(10));
    let recorded = lines(&checkpoint);
    assert!(!out.join("ensemble.csv").exists(), "the killed run must not have finished");
    assert!(recorded < ALL_LINES, "the killed run recorded every block ({recorded} lines)");

    // Starting again without --resume would throw the finished blocks away: refused.
    let o = ensemble(&scene, &out, &[]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("checkpoint.jsonl") && err.contains("--resume"), "{err}");
    // A resume of another scene (another seed) is refused at the checkpoint's header.
    let other = d.join("other");
    std::fs::create_dir_all(&other).unwrap();
    let text = std::fs::read_to_string(&scene).unwrap().replace("seed = 77", "seed = 78");
    std::fs::write(other.join("scene.toml"), text).unwrap();
    let o = ensemble(&other.join("scene.toml"), &out, &["--resume"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("checkpoint.jsonl:1:") && err.contains("another run"), "{err}");

    // On one thread this time: the blocks, not the threads, fix the result.
    ok(&ensemble(&scene, &out, &["--resume", "--threads", "1"]));
    assert_same_statistics(&reference, &out);
    let s = summary(&out);
    let resumed = s["resumed_trajectories"].as_u64().unwrap();
    assert!((3 * 64..N).contains(&resumed), "resumed {resumed} of {N}");
    assert_eq!(s["trajectories"]["completed"].as_u64().unwrap(), summary(&reference)["trajectories"]["completed"]);
    assert!(!checkpoint.exists());
}

#[test]
fn a_panicking_trajectory_stops_the_run_with_its_block_and_the_checkpoint_intact() {
    let d = dir("panic");
    let scene = thermal_scene(&d, 640, 300.0);
    let reference = d.join("reference");
    ok(&ensemble(&scene, &reference, &["--threads", "2"]));

    let out = d.join("out");
    let o = rovib(&["ensemble", scene.to_str().unwrap(), "--out", out.to_str().unwrap(), "--threads", "2"])
        .env(rovib::ensemble::runner::PANIC_HOOK, "330")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("error: the ensemble stopped: a trajectory of block 5 (trajectories 320..384) panicked")
            && err.contains("ROVIB_TEST_PANIC_AT=330")
            && err.contains("--resume"),
        "{err}"
    );
    assert!(!out.join("ensemble.csv").exists() && !out.join("summary.json").exists());
    // The blocks that finished (at least 0-3, handed out before block 5 on two threads) are in
    // the checkpoint, the panicking one is not; the resume runs the rest.
    let recorded = lines(&out.join("checkpoint.jsonl")) - 1;
    assert!((4..10).contains(&recorded), "{recorded} blocks recorded");
    // The blocks ran on lanes: a resume one trajectory at a time would differ by round-off.
    let o = ensemble(&scene, &out, &["--resume", "--no-lanes"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("checkpoint.jsonl:1:") && err.contains("resume without --no-lanes"), "{err}");
    ok(&ensemble(&scene, &out, &["--resume"]));
    assert_same_statistics(&reference, &out);
    assert_eq!(summary(&out)["resumed_trajectories"].as_u64().unwrap(), 64 * recorded as u64);
}
