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
