//! `rovib::memory::run_in_memory`: a scene given as text runs without touching the disk, its
//! records equal the rows `rovib run` writes, and a potential given at run time is
//! gradient-checked and replaces the molecule's.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use rovib::Error;
use rovib::memory::{ExternalPotential, Record, RecordSink, run_in_memory};

fn temp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-memory-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Water for 10 fs, an output every fs, with the outputs a run in memory gives back.
const SCENE: &str = "molecule = \"h2o\"\n[units]\nlength = \"angstrom\"\nangle = \"deg\"\ntime = \"fs\"\n\
    [initial]\nq = { r1 = 1.0078, r2 = 0.95785, alpha = 104.5 }\np = { r1 = 0.0, r2 = 0.0, alpha = 0.0 }\n\
    euler = [0.0, 90.0, 0.0]\nj = [3.0, 8.0, 2.0]\n[integrator]\nmethod = \"dop853\"\nrtol = 1e-10\n\
    atol = 1e-10\n[run]\nend = 10.0\noutput_interval = 1.0\n\
    outputs = [\"trajectory\", \"lab\", \"summary\"]\n";

#[derive(Default)]
struct Rows {
    rows: Vec<String>,
    lab_frames: usize,
    summary: Option<serde_json::Value>,
}

impl RecordSink for Rows {
    fn record(&mut self, r: &Record<'_>) {
        // As trajectory.csv writes them: every number with round-trip precision.
        let mut row = format!("{:?}", r.t);
        for v in r.q.iter().chain(r.p).chain(&r.euler).chain(&r.pe).chain(&r.j).chain([&r.energy]) {
            row.push_str(&format!(",{v:?}"));
        }
        self.rows.push(row);
        self.lab_frames += usize::from(r.lab.as_ref().is_some_and(|l| l.positions.len() == 9));
    }
    fn summary(&mut self, summary: &serde_json::Value) {
        self.summary = Some(summary.clone());
    }
}

#[test]
fn records_in_memory_are_the_rows_of_the_run_into_a_folder() {
    let dir = temp_dir("rows");
    let path = dir.join("scene.toml");
    std::fs::write(&path, SCENE).unwrap();
    let out = dir.join("out");
    rovib::simulation::run(&path, Some(&out)).unwrap();
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let written: Vec<&str> = csv.lines().skip(1).collect();

    let mut sink = Rows::default();
    let report = run_in_memory("scene.toml", SCENE, None, &AtomicBool::new(false), &mut |_| {}, &mut sink).unwrap();
    assert_eq!(sink.rows, written);
    assert_eq!((sink.lab_frames, report.files.len()), (11, 0));
    let summary = sink.summary.unwrap();
    let on_disk: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["rhs_evaluations"], on_disk["rhs_evaluations"]);
    // Nothing new next to the scene: only the file run's folder.
    let mut entries: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
    entries.sort();
    assert_eq!(entries, ["out", "scene.toml"]);
}

/// Water's potential as a sum of harmonic terms, with the gradient of coordinate `wrong`
/// scaled by 1.01 (none when out of range), failing (NaN) after `fail_after` calls.
struct Harmonic {
    wrong: usize,
    fail_after: usize,
    calls: std::sync::atomic::AtomicUsize,
}

impl ExternalPotential for Harmonic {
    fn energy_gradient(&self, q: &[f64], grad: &mut [f64]) -> f64 {
        let n = self.calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut u = 0.0;
        for (i, (centre, k)) in [1.81, 1.81, 1.82].into_iter().zip([0.5, 0.5, 0.16]).enumerate() {
            u += 0.5 * k * (q[i] - centre).powi(2);
            grad[i] = k * (q[i] - centre) * if i == self.wrong { 1.01 } else { 1.0 };
        }
        if n >= self.fail_after { f64::NAN } else { u }
    }
    fn describe(&self) -> String {
        "the test's harmonic potential".into()
    }
}

#[test]
fn an_external_potential_is_checked_then_used() {
    let run = |p: &Harmonic| {
        let mut sink = Rows::default();
        run_in_memory("scene.toml", SCENE, Some(p), &AtomicBool::new(false), &mut |_| {}, &mut sink).map(|_| sink)
    };
    let good = Harmonic { wrong: 9, fail_after: usize::MAX, calls: Default::default() };
    let sink = run(&good).unwrap();
    assert_eq!(sink.rows.len(), 11);
    let h: Vec<f64> = sink.rows.iter().map(|r| r.rsplit(',').next().unwrap().parse().unwrap()).collect();
    assert!(h.iter().all(|e| (e - h[0]).abs() <= 1e-8 * h[0].abs()), "{h:?}");
    let wrong = Harmonic { wrong: 2, fail_after: usize::MAX, calls: Default::default() };
    let e = run(&wrong).err().unwrap().to_string();
    assert!(e.contains("gradient of the test's harmonic potential") && e.contains("fix ∂U/∂alpha"), "{e}");
    let failing = Harmonic { wrong: 9, fail_after: 200, calls: Default::default() };
    let e = run(&failing).err().unwrap().to_string();
    assert!(e.contains("the run stopped") && e.contains("non-finite potential"), "{e}");
}

#[test]
fn a_run_in_memory_refuses_restart_at_its_line() {
    let text = SCENE.replace("\"summary\"]", "\"summary\", \"restart\"]");
    let mut sink = Rows::default();
    match run_in_memory("scene.toml", &text, None, &AtomicBool::new(false), &mut |_| {}, &mut sink) {
        Err(Error::File(e)) => {
            let shown = e.to_string();
            assert!(shown.contains("writes no restart.json") && shown.contains("scene.toml:18:"), "{shown}");
        }
        other => panic!("{:?}", other.err()),
    }
    assert!(sink.rows.is_empty());
}
