//! Helpers of the ensemble tests: run options and reading the CSV outputs.

use std::path::{Path, PathBuf};

use rovib::ensemble::EnsembleOptions;

/// Options writing into `dir` with `threads` worker threads.
pub fn options(dir: PathBuf, threads: usize) -> EnsembleOptions {
    let mut o = EnsembleOptions::new(dir);
    o.threads = Some(threads);
    o
}

/// A CSV file as its header and rows of numbers.
pub fn csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(str::to_owned).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse().unwrap_or(f64::NAN)).collect()).collect();
    (header, rows)
}

/// The index of column `name`.
pub fn column(header: &[String], name: &str) -> usize {
    header.iter().position(|h| h == name).unwrap_or_else(|| panic!("no column {name} in {header:?}"))
}

/// The files of an ensemble run that must be byte-identical between runs of one scene and seed
/// (summary.json differs: wall time, threads, ranks).
pub const STATISTICS_FILES: [&str; 5] =
    ["ensemble.csv", "histograms.csv", "correlations.csv", "ensemble.svg", "histograms.svg"];

/// Writes `dir/scene.toml`: `n` thermal water trajectories (300 K) of `end` a.u., means,
/// histograms and correlation functions, so every kind of accumulator is merged.
pub fn thermal_scene(dir: &Path, n: u64, end: f64) -> PathBuf {
    let text = format!(
        "molecule = \"h2o\"\n[ensemble]\ntrajectories = {n}\nseed = 77\nmethod = \"thermal\"\ntemperature = 300.0\n\
         region = {{ energy_cap = 0.1 }}\n[statistics]\nmeans = [\"r1\", \"alpha\", \"H\", \"J\"]\n\
         histograms = [{{ quantity = \"alpha\", bins = 20, range = [1.5, 2.2], times = [0, {end}] }}]\n\
         correlations = [\"r1\"]\n[integrator]\nmethod = \"dop853\"\nrtol = 1e-8\natol = 1e-8\n\
         [run]\nend = {end}\noutput_interval = {}\n",
        end / 20.0
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Asserts that the statistics files of two output folders are byte-identical.
pub fn assert_same_statistics(expected: &Path, found: &Path) {
    for f in STATISTICS_FILES {
        let (a, b) = (std::fs::read(expected.join(f)).unwrap(), std::fs::read(found.join(f)).unwrap());
        assert!(a == b, "{f} differs between {} and {}", expected.display(), found.display());
    }
}

/// The summary.json of an output folder.
pub fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

/// Lines in a file (0 if it does not exist).
pub fn lines(path: &Path) -> usize {
    std::fs::read_to_string(path).map_or(0, |t| t.lines().count())
}

/// Waits for `child` at most `limit`; kills it and fails if it takes longer (a hang).
pub fn wait_at_most(child: &mut std::process::Child, limit: std::time::Duration) -> std::process::ExitStatus {
    let begin = std::time::Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if begin.elapsed() > limit {
            let _ = child.kill();
            panic!("the process did not end within {limit:?}: it hangs");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Waits until `path` has at least `n` lines (a checkpoint filling up), at most `limit`.
pub fn wait_for_lines(path: &Path, n: usize, limit: std::time::Duration) {
    let begin = std::time::Instant::now();
    while lines(path) < n {
        assert!(begin.elapsed() < limit, "{} did not reach {n} lines within {limit:?}", path.display());
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}
