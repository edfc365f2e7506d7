//! `rovib ensemble SCENE.toml`: sample, run and reduce an ensemble (see [`crate::ensemble`]).

use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};

use super::CliError;
use crate::ensemble::{EnsembleOptions, EnsembleReport, load_scene, run_ensemble};

/// Runs the ensemble of the scene at `path` into `out_dir` (default `out/SCENE_NAME`), with
/// `threads` worker threads (default: the scene's, else every core). Ctrl-C stops it cleanly.
pub fn ensemble(
    path: &Path,
    out_dir: Option<&Path>,
    threads: Option<usize>,
    quiet: bool,
    lanes: bool,
) -> Result<EnsembleReport, CliError> {
    let scene = load_scene(path)?;
    let out_dir = match out_dir {
        Some(d) => d.to_owned(),
        None => PathBuf::from("out").join(path.file_stem().unwrap_or_default()),
    };
    let options = EnsembleOptions {
        out_dir,
        threads,
        progress: !quiet && std::io::stderr().is_terminal(),
        stop: crate::interrupt::flag(),
        lanes,
    };
    run_ensemble(&scene, &options)
}

/// The report printed on stdout.
pub fn describe(report: &EnsembleReport) -> String {
    let o = &report.outcome;
    let mut text = format!(
        "{}: {} of {} trajectories completed, {} failed; {:.3} s on {} threads, {:.1} trajectories/s\n",
        report.status.name(),
        o.completed,
        report.requested,
        o.failed_count(),
        report.wall_time,
        report.threads,
        report.throughput()
    );
    for (reason, n) in &o.failed {
        text.push_str(&format!("  {n} failed: {reason}\n"));
    }
    for f in &report.files {
        text.push_str(&format!("wrote {}\n", f.display()));
    }
    text
}
