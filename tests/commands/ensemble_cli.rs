//! `rovib ensemble` (and `rovib run` on an ensemble scene) as a user runs them, including
//! Ctrl-C.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-ensemble-cli-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A scene of `n` trajectories from a states file of `n` copies of a vibrating, rotating water.
fn scene(d: &Path, n: usize, end: f64) -> PathBuf {
    let mut states = String::from("r1,r2,alpha,p_r1,Jx,Jy,Jz\n");
    for i in 0..n {
        states.push_str(&format!("{},1.81,1.82,0.3,3,8,2\n", 1.85 + 1e-4 * (i % 10) as f64));
    }
    std::fs::write(d.join("states.csv"), states).unwrap();
    let text = format!(
        "molecule = \"h2o\"\n[ensemble]\ntrajectories = {n}\nmethod = \"file\"\nfile = \"states.csv\"\n\
         [statistics]\nmeans = [\"r1\", \"H\"]\n[run]\nend = {end}\noutput_interval = {}\n",
        end / 10.0
    );
    let path = d.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn ensemble_and_run_write_the_outputs_and_report() {
    let d = dir("ok");
    let path = scene(&d, 20, 200.0);
    let out = d.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["ensemble", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "--threads", "2"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8(o.stdout).unwrap();
    assert!(stdout.starts_with("completed: 20 of 20 trajectories completed, 0 failed"), "{stdout}");
    for f in ["ensemble.csv", "histograms.csv", "correlations.csv", "summary.json", "ensemble.svg", "histograms.svg"] {
        assert!(out.join(f).exists(), "{f}");
        assert!(stdout.contains(f), "{stdout}");
    }
    // 20 trajectories are one block: one thread runs it, and summary.json says why.
    assert_eq!(summary(&out)["threads"], 1);
    assert!(summary(&out)["threads_note"].as_str().unwrap().contains("2 threads were asked for, 1 run"));
    // `rovib run` on a scene with [ensemble] runs the ensemble; --quiet prints nothing.
    let out2 = d.join("out2");
    let o = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", path.to_str().unwrap(), "--out", out2.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(o.stdout.is_empty() && o.stderr.is_empty());
    assert_eq!(std::fs::read(out.join("ensemble.csv")).unwrap(), std::fs::read(out2.join("ensemble.csv")).unwrap());
}

#[test]
fn a_bad_scene_fails_with_a_located_error_and_writes_nothing() {
    let d = dir("bad");
    let path = d.join("scene.toml");
    std::fs::write(&path, "molecule = \"h2o\"\n[ensemble]\ntrajectories = 0\nmethod = \"thermal\"\n[run]\nend = 1\n")
        .unwrap();
    let out = d.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["ensemble", path.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(err.contains("`ensemble.trajectories` must be at least 1, got 0"), "{err}");
    assert!(err.contains(&format!("{}:3:16", path.display())), "{err}");
    assert!(!out.exists());
}

#[test]
fn ctrl_c_stops_cleanly_with_consistent_outputs() {
    let d = dir("sigint");
    // About 2000 trajectories of 10⁵ a.u.: far longer than the test waits.
    let path = scene(&d, 2000, 1e5);
    let out = d.join("out");
    let child = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["ensemble", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "--threads", "2"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let killed = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(killed.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success(), "an interrupted ensemble exits non-zero");
    assert!(err.contains("interrupted: ") && err.contains("of 2000 trajectories completed"), "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "interrupted");
    let completed = s["trajectories"]["completed"].as_u64().unwrap();
    assert!(completed < 2000, "{s}");
    assert_eq!(
        completed
            + s["trajectories"]["failed"].as_u64().unwrap()
            + s["trajectories"]["interrupted_or_not_run"].as_u64().unwrap(),
        2000
    );
    // ensemble.csv counts exactly the completed trajectories at every time.
    let text = std::fs::read_to_string(out.join("ensemble.csv")).unwrap();
    for line in text.lines().skip(1) {
        assert_eq!(line.split(',').nth(1).unwrap(), completed.to_string(), "{line}");
    }
}
