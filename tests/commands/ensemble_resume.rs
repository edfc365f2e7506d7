//! Checkpoint and resume of `rovib ensemble`, and the integrity of its output folder (one run at
//! a time, no file of an earlier run left, a summary that says how the run ended), in one process: a run killed with SIGKILL part way,
//! or stopped by a panicking trajectory, continues with `--resume` to outputs byte-identical to
//! an uninterrupted run's. (The same under MPI: tests/mpi.rs, with `--features mpi`.)
//! Shown able to fail (docs/src/history/benchmarks.md, "Ensembles over MPI"): a resume that skips a block, and
//! blocks merged in arrival order, both fail the byte comparison here.

use crate::common;

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
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 35 s unoptimised on a loaded 2-core machine"]
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
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 12 s unoptimised on a loaded 2-core machine"]
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
    assert!(!out.join("ensemble.csv").exists());
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
    assert!(s["error"].as_str().unwrap().contains("panicked"), "{s}");
    // The blocks that finished (at least 0-3, handed out before block 5 on two threads) are in
    // the checkpoint, the panicking one is not; the resume runs the rest.
    let recorded = lines(&out.join("checkpoint.jsonl")) - 1;
    assert!((4..10).contains(&recorded), "{recorded} blocks recorded");
    // The blocks ran on lanes: a resume one trajectory at a time would differ by round-off.
    let o = ensemble(&scene, &out, &["--resume", "--no-lanes"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("checkpoint.jsonl:1:") && err.contains("resume on lanes (without `--no-lanes`)"), "{err}");
    ok(&ensemble(&scene, &out, &["--resume"]));
    assert_same_statistics(&reference, &out);
    assert_eq!(summary(&out)["resumed_trajectories"].as_u64().unwrap(), 64 * recorded as u64);
}

/// A small run scene for `rovib run` into an ensemble's folder.
fn run_scene(d: &Path) -> PathBuf {
    let path = d.join("run.toml");
    std::fs::write(
        &path,
        "molecule = \"h2o\"\n[units]\nlength = \"angstrom\"\nangle = \"deg\"\ntime = \"fs\"\n\
         [initial]\nq = { r1 = 1.0078, r2 = 0.95785, alpha = 104.5 }\nj = [3.0, 8.0, 2.0]\n\
         [run]\nend = 2.0\noutput_interval = 0.5\noutputs = [\"trajectory\", \"lab\", \"summary\", \"restart\"]\n",
    )
    .unwrap();
    path
}

fn names(d: &Path) -> Vec<String> {
    let mut n: Vec<String> =
        std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    n.sort();
    n
}

#[test]
fn every_trajectory_failing_is_status_failed_with_a_non_zero_exit_and_no_stale_file() {
    let d = dir("failed");
    let scene = thermal_scene(&d, 128, 100.0);
    let out = d.join("out");
    ok(&ensemble(&scene, &out, &["--threads", "2"]));
    assert_eq!(summary(&out)["status"], "completed");
    // Files an earlier run of another kind (or with a spectrum, or kept trajectories) left.
    for f in
        ["spectrum.csv", "spectrum.svg", "trajectory.csv", "lab.xyz", "restart.json", "trajectories/64/trajectory.csv"]
    {
        std::fs::create_dir_all(out.join(f).parent().unwrap()).unwrap();
        std::fs::write(out.join(f), "stale\n").unwrap();
    }
    // Every trajectory fails: one step is not enough for any.
    let text = std::fs::read_to_string(&scene).unwrap().replace("atol = 1e-8\n", "atol = 1e-8\nmax_steps = 1\n");
    let failing = d.join("failing.toml");
    std::fs::write(&failing, text).unwrap();
    let o = ensemble(&failing, &out, &["--threads", "2"]);
    assert!(!o.status.success(), "an ensemble whose every trajectory failed exited 0");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("every one of the 128 trajectories failed (128 too many steps)"), "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
    assert_eq!(s["trajectories"]["failed"], 128);
    assert_eq!(s["scene"], failing.display().to_string());
    assert!(!out.join("checkpoint.jsonl").exists(), "every trajectory ran: nothing to resume");
    assert_eq!(
        names(&out),
        ["correlations.csv", "ensemble.csv", "ensemble.svg", "histograms.csv", "histograms.svg", "summary.json"]
    );
}

#[test]
fn a_run_and_an_ensemble_into_one_folder_leave_only_the_last_ones_files() {
    let d = dir("mixed");
    let scene = thermal_scene(&d, 64, 100.0);
    let run = run_scene(&d);
    let out = d.join("out");
    ok(&ensemble(&scene, &out, &["--threads", "2"]));
    ok(&rovib(&["run", run.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]).output().unwrap());
    assert_eq!(names(&out), ["lab.xyz", "restart.json", "summary.json", "trajectory.csv", "trajectory.units.json"]);
    ok(&ensemble(&scene, &out, &["--threads", "2"]));
    assert_eq!(
        names(&out),
        ["correlations.csv", "ensemble.csv", "ensemble.svg", "histograms.csv", "histograms.svg", "summary.json"]
    );
    // An unfinished ensemble's checkpoint is not thrown away by a `rovib run`.
    std::fs::write(out.join("checkpoint.jsonl"), "{}\n").unwrap();
    let o = rovib(&["run", run.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]).output().unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("checkpoint.jsonl") && err.contains("--resume"), "{err}");
    assert!(out.join("ensemble.csv").exists() && out.join("checkpoint.jsonl").exists());
}

/// Waits (at most 60 s) until summary.json says "running" for process `pid`.
fn wait_for_running(out: &Path, pid: u32) {
    let begin = std::time::Instant::now();
    loop {
        let s: Option<serde_json::Value> =
            std::fs::read_to_string(out.join("summary.json")).ok().and_then(|t| serde_json::from_str(&t).ok());
        if s.as_ref().is_some_and(|s| s["status"] == "running" && s["process"] == pid) {
            return;
        }
        assert!(begin.elapsed() < Duration::from_secs(60), "no \"running\" summary of process {pid}: {s:?}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Sends `signal` (e.g. "STOP", "CONT") to process `pid`.
fn signal(pid: u32, signal: &str) {
    let s = Command::new("kill").arg(format!("-{signal}")).arg(pid.to_string()).status().unwrap();
    assert!(s.success(), "kill -{signal} {pid} failed");
}

/// Each process in turn is frozen (SIGSTOP) while it holds the folder, so the checks do not
/// depend on how fast it runs.
#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 68 s unoptimised on a loaded 2-core machine"]
fn one_process_at_a_time_in_an_ensembles_folder_and_a_killed_run_resumes() {
    let d = dir("lock");
    let scene = thermal_scene(&d, 4 * N, END);
    let run = run_scene(&d);
    let out = d.join("out");
    let spawn = |extra: &[&str]| {
        let mut args = vec!["ensemble", scene.to_str().unwrap(), "--out", out.to_str().unwrap(), "--threads", "1"];
        args.extend_from_slice(extra);
        rovib(&args).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap()
    };
    let refused = |o: Output, pid: u32| {
        assert!(!o.status.success(), "a second process ran in a locked folder");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("in use by another run") && err.contains(&format!("process {pid}")), "{err}");
    };
    let mut first = spawn(&[]);
    wait_for_running(&out, first.id());
    wait_for_lines(&out.join("checkpoint.jsonl"), 2, Duration::from_secs(120));
    signal(first.id(), "STOP");
    // While it runs: a resume, a fresh ensemble and a `rovib run` are refused, and touch nothing.
    refused(ensemble(&scene, &out, &["--resume"]), first.id());
    refused(ensemble(&scene, &out, &[]), first.id());
    refused(rovib(&["run", run.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]).output().unwrap(), first.id());
    assert_eq!(summary(&out)["status"], "running");
    // Killed: the summary still says "running" (what happened), and the lock died with it.
    first.kill().unwrap();
    wait_at_most(&mut first, Duration::from_secs(10));
    assert_eq!(summary(&out)["status"], "running");
    // Two resumes at once: the second is refused while the first runs.
    let mut resume = spawn(&["--resume"]);
    wait_for_running(&out, resume.id());
    signal(resume.id(), "STOP");
    refused(ensemble(&scene, &out, &["--resume"]), resume.id());
    signal(resume.id(), "CONT");
    assert!(wait_at_most(&mut resume, Duration::from_secs(300)).success());
    assert_eq!(summary(&out)["status"], "completed");
    assert!(!out.join("checkpoint.jsonl").exists() && !out.join(".rovib.lock").exists());
}
