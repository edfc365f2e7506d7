//! Outputs as reporters (`rovib::report`): a reporter gets the lab frame and the dipole only
//! when some reporter of the run needs them, its frames are the rows trajectory.csv writes, and
//! a continuation integrates the orientation whenever the scene's outputs need it.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use rovib::Simulation;
use rovib::error::Error;
use rovib::report::{Frame, Needs, Reporter};

fn temp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-reporters-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Water for `end` fs, an output every fs, with `initial` and `outputs`.
fn scene(dir: &Path, name: &str, end: f64, initial: &str, outputs: &str) -> PathBuf {
    let text = format!(
        "molecule = \"h2o\"\n[units]\nlength = \"angstrom\"\nangle = \"deg\"\ntime = \"fs\"\n\
         [initial]\nq = {{ r1 = 1.0078, r2 = 0.95785, alpha = 104.5 }}\n{initial}\n\
         [integrator]\nmethod = \"dop853\"\nrtol = 1e-10\natol = 1e-10\n\
         [run]\nend = {end:?}\noutput_interval = 1.0\noutputs = [{outputs}]\n"
    );
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Counts what it is given, and keeps the rows as trajectory.csv writes them.
struct Counter<'a> {
    needs: Needs,
    seen: &'a mut Seen,
}

#[derive(Default)]
struct Seen {
    frames: usize,
    lab: usize,
    dipole: usize,
    rows: Vec<String>,
}

impl Reporter for Counter<'_> {
    fn needs(&self) -> Needs {
        self.needs
    }

    fn report(&mut self, f: &Frame<'_>) -> Result<(), Error> {
        self.seen.frames += 1;
        self.seen.lab += usize::from(f.lab.is_some());
        self.seen.dipole += usize::from(f.dipole.is_some());
        let mut row = format!("{:?}", f.t);
        for v in f.q.iter().chain(f.p).chain(&f.euler).chain(&f.pe).chain(&f.j).chain([&f.energy]) {
            row.push_str(&format!(",{v:?}"));
        }
        self.seen.rows.push(row);
        Ok(())
    }
}

const TURNING: &str = "p = { r1 = 0.0, r2 = 0.0, alpha = 0.0 }\neuler = [0.0, 90.0, 0.0]\nj = [3.0, 8.0, 2.0]";

/// Runs `path` into `out` with a counter needing `needs`.
fn run_counted(path: &Path, out: &Path, needs: Needs) -> Seen {
    let mut seen = Seen::default();
    let sim = Simulation::load(path, Some(out)).unwrap();
    let counter = Counter { needs, seen: &mut seen };
    sim.run_with_reporters(&AtomicBool::new(false), &mut |_| {}, vec![Box::new(counter)]).unwrap();
    seen
}

#[test]
fn the_lab_frame_and_the_dipole_are_computed_only_when_a_reporter_needs_them() {
    let dir = temp_dir("needs");
    let only_trajectory = scene(&dir, "trajectory.toml", 10.0, TURNING, "\"trajectory\"");
    let out = dir.join("out");
    let seen = run_counted(&only_trajectory, &out, Needs::NOTHING);
    assert_eq!((seen.frames, seen.lab, seen.dipole), (11, 0, 0));
    // Its frames are the rows of trajectory.csv, bit for bit.
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    assert_eq!(seen.rows, csv.lines().skip(1).collect::<Vec<_>>());

    // A reporter's own needs are met: the lab frame and the dipole with no file asking.
    let both = Needs { lab: true, dipole: true, orientation: true };
    let seen = run_counted(&only_trajectory, &dir.join("out_needs"), both);
    assert_eq!((seen.frames, seen.lab, seen.dipole), (11, 11, 11));
    // And the scene's: lab.xyz makes the lab frame, which every reporter then sees.
    let with_lab = scene(&dir, "lab.toml", 10.0, TURNING, "\"trajectory\", \"lab\"");
    let seen = run_counted(&with_lab, &dir.join("out_lab"), Needs::NOTHING);
    assert_eq!((seen.frames, seen.lab, seen.dipole), (11, 11, 0));
}

#[test]
fn a_run_at_zero_angular_momentum_writing_only_the_dipole_continues_bit_for_bit() {
    let dir = temp_dir("dipole-resume");
    let still = "p = { r1 = 2.0, r2 = -1.0, alpha = 0.5 }\neuler = [10.0, 70.0, 30.0]";
    let outputs = "\"dipole\", \"summary\", \"restart\"";
    let (half, full) = (scene(&dir, "half.toml", 5.0, still, outputs), scene(&dir, "full.toml", 10.0, still, outputs));
    let whole = dir.join("whole");
    rovib::simulation::run(&full, Some(&whole)).unwrap();
    let split = dir.join("split");
    rovib::simulation::run(&half, Some(&split)).unwrap();
    rovib::simulation::resume(&split, Some(&full)).unwrap();
    let read = |d: &Path| std::fs::read_to_string(d.join("dipole.csv")).unwrap();
    let (whole, split) = (read(&whole), read(&split));
    let (whole, split): (Vec<&str>, Vec<&str>) = (whole.lines().collect(), split.lines().collect());
    assert_eq!((whole.len(), split.len()), (12, 12), "header + t = 0, 1, ..., 10 fs");
    // After the continuation point (t = 5 fs, row 6) the rows are the uninterrupted run's; up to
    // it they come from the first run, whose last step was shortened to end there.
    assert_eq!(whole[7..], split[7..]);
    for (a, b) in whole[1..7].iter().zip(&split[1..7]) {
        let numbers = |row: &str| row.split(',').map(|x| x.parse::<f64>().unwrap()).collect::<Vec<_>>();
        for (x, y) in numbers(a).iter().zip(numbers(b)) {
            assert!((x - y).abs() <= 1e-8 * x.abs().max(1.0), "{a} vs {b}");
        }
    }
}

#[test]
fn an_unknown_output_is_refused_at_its_place_with_the_closest_name() {
    let dir = temp_dir("unknown");
    let path = scene(&dir, "typo.toml", 1.0, TURNING, "\"trajectory\", \"dipol\"");
    let e = Simulation::load(&path, Some(&dir.join("out"))).err().unwrap().to_string();
    assert!(e.contains("typo.toml") && e.contains("unknown output `dipol`"), "{e}");
    assert!(e.contains("did you mean \"dipole\"?"), "{e}");
}
