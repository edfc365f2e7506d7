//! `restart.json` and `rovib run --resume`: a run to T/2 continued to T equals one run to T.
//!
//! With DOP853 "equals" is bit for bit after T/2: the continuation repeats the uninterrupted
//! run's steps from the start of the step the first run shortened to land on T/2. The rows up
//! to T/2 were written by the first run; the last of them (served by the shortened step) differ
//! from the uninterrupted run's by the local error, within the tolerances.

use crate::common;

use common::cli::{rovib, temp_dir};
use std::path::{Path, PathBuf};
use std::process::Command;

const SCENE: &str = r#"molecule = "h2o"

[units]
length = "angstrom"
angle = "deg"
time = "fs"

[initial]
q = { r1 = 1.0078, r2 = 0.95785, alpha = 104.5 }
euler = [10.0, 70.0, 20.0]
j = [3.0, 8.0, 2.0]

[integrator]
INTEGRATOR

[run]
end = END
output_interval = 1.0
euler_unwrapped = true
"#;

const DOP853: &str = "method = \"dop853\"\nrtol = 1e-10\natol = 1e-10";

fn scene(integrator: &str, end: f64) -> String {
    SCENE.replace("INTEGRATOR", integrator).replace("END", &format!("{end:?}"))
}

fn run_ok(args: &[&str]) {
    let out = rovib(args);
    assert!(out.status.success(), "rovib {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

fn lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path).unwrap().lines().map(str::to_owned).collect()
}

fn numbers(line: &str) -> Vec<f64> {
    line.split(',').map(|x| x.parse().unwrap()).collect()
}

/// Runs `integrator` to `end` in one go and to `end / 2` then `--resume` to `end`; returns the
/// two trajectory.csv and lab.xyz as lines, and the directory of the split run.
fn full_and_split(name: &str, integrator: &str, end: f64) -> ([Vec<String>; 2], [Vec<String>; 2], PathBuf) {
    let dir = temp_dir("restart", name);
    let (full, half) = (dir.join("full.toml"), dir.join("half.toml"));
    std::fs::write(&full, scene(integrator, end)).unwrap();
    std::fs::write(&half, scene(integrator, end / 2.0)).unwrap();
    let (a, b) = (dir.join("a"), dir.join("b"));
    run_ok(&["run", full.to_str().unwrap(), "--out", a.to_str().unwrap(), "--quiet"]);
    run_ok(&["run", half.to_str().unwrap(), "--out", b.to_str().unwrap(), "--quiet"]);
    assert!(b.join("restart.json").exists());
    run_ok(&["run", "--resume", b.to_str().unwrap(), full.to_str().unwrap(), "--quiet"]);
    let csv = [lines(&a.join("trajectory.csv")), lines(&b.join("trajectory.csv"))];
    let xyz = [lines(&a.join("lab.xyz")), lines(&b.join("lab.xyz"))];
    (csv, xyz, dir)
}

#[test]
fn dop853_continued_from_half_time_is_the_uninterrupted_run_bit_for_bit() {
    let end = 200.0;
    let ([full, split], [full_xyz, split_xyz], dir) = full_and_split("dop853", DOP853, end);
    assert_eq!(full.len(), 202, "header + t = 0, 1, ..., 200 fs");
    assert_eq!(split.len(), full.len(), "the continuation appends exactly the missing rows");
    assert_eq!(full[0], split[0]);
    let half = 1 + 100; // the row of t = 100 fs
    for k in half + 1..full.len() {
        assert_eq!(full[k], split[k], "row {k} after the continuation point differs");
    }
    // Rows up to T/2 come from the first run; the last ones were served by its shortened step.
    for k in 1..=half {
        let (a, b) = (numbers(&full[k]), numbers(&split[k]));
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-8 * x.abs().max(1.0), "row {k}: {x} vs {y}");
        }
    }
    // lab.xyz: 5 lines per frame, frames after T/2 identical.
    assert_eq!(split_xyz.len(), full_xyz.len());
    assert_eq!(full_xyz[5 * half..], split_xyz[5 * half..]);

    // The summary says where the continuation started; H(0) is still the first run's.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("b/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["status"], "completed");
    assert!((summary["resumed_from"].as_f64().unwrap() - 100.0).abs() < 1e-12, "{}", summary["resumed_from"]);
    assert_eq!(summary["conservation"]["initial_energy_hartree"].as_f64(), Some(numbers(&full[1])[16]));
    assert_eq!(summary["conservation"]["samples"], 201);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_restart_file_holds_the_last_row_and_refuses_a_second_or_changed_continuation() {
    let dir = temp_dir("restart", "refuse");
    let path = dir.join("s.toml");
    std::fs::write(&path, scene(DOP853, 20.0)).unwrap();
    let out = dir.join("out");
    run_ok(&["run", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
    let restart: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("restart.json")).unwrap()).unwrap();
    let csv = lines(&out.join("trajectory.csv"));
    let last = numbers(csv.last().unwrap());
    assert!((restart["t"].as_f64().unwrap() - 20.0).abs() < 1e-12);
    assert_eq!(restart["outputs_done"], 20);
    let state = &restart["state"];
    let got: Vec<f64> = ["q", "p", "euler", "pe"]
        .iter()
        .flat_map(|k| state[k].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()))
        .collect();
    assert_eq!(got, last[1..13], "the restart state is the last row, bit for bit");
    assert!(restart["dop853"]["step_au"].as_f64().unwrap() > 0.0);

    // Nothing to continue to: the scene ends where the run did.
    let o = rovib(&["run", "--resume", out.to_str().unwrap(), "--quiet"]);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success() && err.contains("already reached t = 20"), "{err}");

    // Another integrator is another run.
    let other = dir.join("other.toml");
    std::fs::write(&other, scene(DOP853, 40.0).replace("rtol = 1e-10", "rtol = 1e-9")).unwrap();
    let o = rovib(&["run", "--resume", out.to_str().unwrap(), other.to_str().unwrap(), "--quiet"]);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(
        !o.status.success() && err.contains("differs from the run being continued") && err.contains("[integrator]")
    );

    // Continue once; the restart file is replaced, so continuing the old one twice is refused
    // by the row count of the files.
    let longer = dir.join("longer.toml");
    std::fs::write(&longer, scene(DOP853, 40.0)).unwrap();
    let saved = std::fs::read(out.join("restart.json")).unwrap();
    run_ok(&["run", "--resume", out.to_str().unwrap(), longer.to_str().unwrap(), "--quiet"]);
    assert_eq!(lines(&out.join("trajectory.csv")).len(), 42);
    std::fs::write(out.join("restart.json"), saved).unwrap();
    let o = rovib(&["run", "--resume", out.to_str().unwrap(), longer.to_str().unwrap(), "--quiet"]);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success() && err.contains("already continued"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn gauss_legendre_continued_from_half_time_follows_the_uninterrupted_run() {
    // Fixed step: the continuation restarts the step grid at T/2 from the state written there;
    // with a step that divides the output interval it takes the same steps (the implicit
    // stages converge from another first guess, so agreement is to round-off, not bits).
    let integrator = "method = \"gauss-legendre\"\nstep = 0.25";
    let ([full, split], _, dir) = full_and_split("gl", integrator, 40.0);
    assert_eq!(split.len(), full.len());
    for k in 1..full.len() {
        let (a, b) = (numbers(&full[k]), numbers(&split[k]));
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "row {k}: {x} vs {y}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Interrupted with SIGINT in the middle of a long run, then continued to a nearby end: every
/// row of the two parts is bit for bit the row of one uninterrupted run to that end (the
/// continuation redoes the step in which the run stopped).
#[test]
fn an_interrupted_run_continues_bit_for_bit() {
    let dir = temp_dir("restart", "sigint");
    let long = dir.join("long.toml");
    std::fs::write(&long, scene(DOP853, 4e5)).unwrap();
    let out = dir.join("out");
    let child = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", long.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let begin = std::time::Instant::now();
    while std::fs::read_to_string(out.join("trajectory.csv")).map_or(0, |t| t.lines().count()) < 300 {
        assert!(begin.elapsed().as_secs() < 60, "the run never got going");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert!(Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap().success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success() && err.contains("rovib run --resume"), "{err}");

    let restart: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("restart.json")).unwrap()).unwrap();
    let t = restart["t"].as_f64().unwrap();
    let end = t.ceil() + 20.0;
    let near = dir.join("near.toml");
    std::fs::write(&near, scene(DOP853, end)).unwrap();
    run_ok(&["run", "--resume", out.to_str().unwrap(), near.to_str().unwrap(), "--quiet"]);
    let once = dir.join("once");
    run_ok(&["run", near.to_str().unwrap(), "--out", once.to_str().unwrap(), "--quiet"]);

    let (split, whole) = (lines(&out.join("trajectory.csv")), lines(&once.join("trajectory.csv")));
    assert_eq!(split.len(), whole.len(), "interrupted at t = {t} fs, continued to {end} fs");
    assert_eq!(split, whole, "interrupted at t = {t} fs");
    assert_eq!(lines(&out.join("lab.xyz")), lines(&once.join("lab.xyz")));
    std::fs::remove_dir_all(&dir).unwrap();
}
