//! What a collision ensemble (`method = "collision"`) writes when it is interrupted, and its
//! refusals, located at the scene's `[ensemble] method` line: `--resume` (a collision run keeps
//! no checkpoint) and MPI (it runs in one process).

use std::path::PathBuf;

use rovib::ensemble::collision_output::run_collisions;
use rovib::ensemble::{Link, Serve, run_linked};
use rovib::scene::parse_scene;

use crate::common;

fn dir(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-collision-interrupt-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Six collisions on n2ar_iso; `method = "collision"` is on line 5 of scene.toml.
fn scene(dir: &std::path::Path) -> rovib::scene::Scene {
    let text = "molecule = \"n2ar_iso\"\n[ensemble]\ntrajectories = 6\nseed = 3\nmethod = \"collision\"\n\
                [collision]\nb_max = 8.0\nenergy = 1e-3\nr0 = 30.0\nr_stop = 31.0\n[[collision.fragment]]\n\
                atoms = [\"N1\", \"N2\"]\n[[collision.fragment]]\natoms = [\"Ar\"]\n[integrator]\n\
                method = \"dop853\"\nrtol = 1e-9\natol = 1e-9\n[run]\nend = 400000.0\noutput_interval = 2000.0\n";
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    parse_scene(&path.display().to_string(), text).unwrap()
}

fn summary(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn an_interrupted_collision_run_says_so_and_presents_no_final_statistics() {
    let d = dir("stopped");
    let s = scene(&d);
    let out = d.join("out");
    // A complete run first: its statistics are final.
    let o = common::ensemble::options(out.clone(), 1);
    let (report, _) = run_collisions(&s, &o).unwrap();
    assert_eq!(report.outcome.completed, 6);
    let whole = summary(&out);
    assert_eq!(whole["status"], "completed");
    assert_eq!(whole["final"], true);
    assert!(whole["cross_sections"].is_object() && out.join("collision_histograms.csv").exists());
    // The same folder, interrupted before any trajectory completes.
    let o = common::ensemble::options(out.clone(), 1);
    o.stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let (report, collisions) = run_collisions(&s, &o).unwrap();
    assert_eq!(report.status.name(), "interrupted");
    assert_eq!((report.outcome.completed, report.outcome.interrupted), (0, 6));
    assert!(collisions.records.is_empty());
    let cut = summary(&out);
    assert_eq!(cut["status"], "interrupted");
    assert_eq!(cut["final"], false);
    assert_eq!((cut["completed"].as_u64(), cut["interrupted_or_not_run"].as_u64()), (Some(0), Some(6)));
    for key in ["outcomes", "cross_sections", "energy_transfer"] {
        assert!(cut.get(key).is_none(), "an interrupted run presents {key} as final: {cut}");
        assert!(cut["partial_statistics"].get(key).is_some(), "partial {key} missing: {cut}");
    }
    let note = cut["partial_statistics"]["note"].as_str().unwrap();
    assert!(note.contains("not final"), "{note}");
    // No histograms of the ensemble, and none left from the complete run.
    assert!(!out.join("collision_histograms.csv").exists(), "stale or partial collision_histograms.csv");
    let rows = std::fs::read_to_string(out.join("final_states.csv")).unwrap().lines().count();
    assert_eq!(rows, 1, "final_states.csv holds the completed trajectories only (here none)");
}

#[test]
fn resume_is_refused_for_collision_runs_at_the_method_line() {
    let d = dir("resume");
    let s = scene(&d);
    let mut o = common::ensemble::options(d.join("out"), 1);
    o.resume = true;
    let e = run_collisions(&s, &o).unwrap_err().to_string();
    assert!(e.contains("cannot be resumed") && e.contains("scene.toml:5"), "{e}");
    assert!(!d.join("out").join("summary.json").exists(), "a refused run wrote outputs");
}

/// A worker rank that must never be asked for work.
struct NoWorker;

impl Serve for NoWorker {
    fn serve(
        &mut self,
        _: &rovib::ensemble::schedule::Work<'_>,
        _: &rovib::ensemble::checkpoint::Identity,
    ) -> Result<(), rovib::Error> {
        panic!("a collision ensemble served blocks under MPI")
    }

    fn ranks(&self) -> usize {
        2
    }
}

#[test]
fn mpi_is_refused_for_collision_runs_at_the_method_line() {
    let d = dir("mpi");
    let s = scene(&d);
    let o = common::ensemble::options(d.join("out"), 1);
    let mut worker = NoWorker;
    let e = run_linked(&s, &o, Link::Worker(&mut worker), &mut |_| {}).err().unwrap().to_string();
    assert!(e.contains("cannot run under MPI") && e.contains("scene.toml:5"), "{e}");
    assert!(e.contains("without mpirun"), "{e}");
}
