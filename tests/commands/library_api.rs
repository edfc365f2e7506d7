//! The library's `Simulation` and `run_ensemble_with`: a progress callback on the calling
//! thread, and a stop flag that ends the run cleanly (no signal handler involved); an interrupted
//! simulation continues with `Simulation::resume` to the same trajectory as a run without a stop.

use crate::common;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use rovib::ensemble::{Status, load_scene, run_ensemble_with};
use rovib::{Error, Simulation};

fn temp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-library-api-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Water for 20 fs, an output every fs (21 records).
fn scene(dir: &Path) -> PathBuf {
    let text = "molecule = \"h2o\"\n[units]\nlength = \"angstrom\"\nangle = \"deg\"\ntime = \"fs\"\n\
                [initial]\nq = { r1 = 1.0078, r2 = 0.95785, alpha = 104.5 }\np = { r1 = 0.0, r2 = 0.0, alpha = 0.0 }\n\
                euler = [0.0, 90.0, 0.0]\nj = [3.0, 8.0, 2.0]\n[integrator]\nmethod = \"dop853\"\nrtol = 1e-10\n\
                atol = 1e-10\n[run]\nend = 20.0\noutput_interval = 1.0\n\
                outputs = [\"trajectory\", \"summary\", \"restart\"]\n";
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn rows(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join("trajectory.csv")).unwrap().lines().skip(1).map(str::to_owned).collect()
}

#[test]
fn progress_counts_every_output_record() {
    let dir = temp_dir("progress");
    let sim = Simulation::load(&scene(&dir), Some(&dir.join("out"))).unwrap();
    let mut seen = Vec::new();
    let report = sim.run(&AtomicBool::new(false), &mut |p| seen.push(p)).unwrap();
    assert_eq!(seen.len(), 21);
    assert!(seen.iter().enumerate().all(|(k, p)| p.done == k as u64 + 1 && p.total == 21 && p.failed == 0), "{seen:?}");
    assert!(report.stats.steps > 0);
    assert_eq!(rows(&dir.join("out")).len(), 21);
}

#[test]
fn the_stop_flag_interrupts_and_resume_continues_to_the_uninterrupted_run() {
    let dir = temp_dir("stop");
    let path = scene(&dir);
    let whole = dir.join("whole");
    rovib::simulation::run(&path, Some(&whole)).unwrap();

    let split = dir.join("split");
    let stop = AtomicBool::new(false);
    let sim = Simulation::load(&path, Some(&split)).unwrap();
    // The callback raises the flag at the fifth record: the run ends right after it.
    let result = sim.run(&stop, &mut |p| {
        if p.done == 5 {
            stop.store(true, Ordering::SeqCst);
        }
    });
    let e = match result {
        Err(e) => e,
        Ok(_) => panic!("the run was not interrupted"),
    };
    assert!(matches!(e, Error::Interrupted { .. }) && e.is_interrupted(), "{e}");
    assert!(e.to_string().contains("Simulation::resume"), "{e}");
    assert_eq!(rows(&split).len(), 5);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(split.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["status"], "interrupted", "{summary}");

    Simulation::resume(&split, None).unwrap().run(&AtomicBool::new(false), &mut |_| {}).unwrap();
    assert_eq!(rows(&split), rows(&whole));
}

#[test]
fn an_ensemble_reports_progress_and_stops_on_the_flag() {
    let dir = temp_dir("ensemble");
    let scene = load_scene(&common::ensemble::thermal_scene(&dir, 64, 200.0)).unwrap();
    let mut options = common::ensemble::options(dir.join("all"), 2);
    let mut last = None;
    let report = run_ensemble_with(&scene, &options, &mut |p| last = Some(p)).unwrap();
    assert_eq!(report.status, Status::Completed);
    let last = last.expect("the callback ran");
    assert_eq!((last.done, last.total, last.failed), (64, 64, 0));

    // Ten blocks on one thread; the callback raises the flag as soon as it runs (after the first
    // block at the latest): no block starts after that.
    let scene = load_scene(&common::ensemble::thermal_scene(&dir, 640, 200.0)).unwrap();
    options.threads = Some(1);
    options.out_dir = dir.join("stopped");
    let stop = std::sync::Arc::clone(&options.stop);
    let report = run_ensemble_with(&scene, &options, &mut |_| stop.store(true, Ordering::SeqCst)).unwrap();
    assert_eq!(report.status, Status::Interrupted);
    assert!(report.outcome.completed < 640, "{}", report.outcome.completed);
}
