//! `rovib ensemble SCENE.toml`: sample, run and reduce an ensemble (see [`rovib::ensemble`]).

use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};

use rovib::Error;
use rovib::ensemble::{EnsembleOptions, EnsembleReport, load_scene, run_ensemble_with};

use super::progress::Bar;

/// Runs the ensemble of the scene at `path` into `out_dir` (default `out/SCENE_NAME`), with
/// `threads` worker threads (default: the scene's, else every core), continuing its checkpoint
/// with `resume`. Ctrl-C stops it cleanly. Started by an MPI launcher (and built with the `mpi`
/// feature) it runs as one rank of several: the report is then on rank 0 only (`None` on the
/// others).
pub fn ensemble(
    path: &Path,
    out_dir: Option<&Path>,
    threads: Option<usize>,
    quiet: bool,
    resume: bool,
    lanes: bool,
) -> Result<Option<EnsembleReport>, Error> {
    let out_dir = match out_dir {
        Some(d) => d.to_owned(),
        None => PathBuf::from("out").join(path.file_stem().unwrap_or_default()),
    };
    let mut options = EnsembleOptions::new(out_dir);
    options.threads = threads;
    options.stop = super::interrupt::flag();
    options.resume = resume;
    options.lanes = lanes;
    let mut bar = Bar::new(!quiet && std::io::stderr().is_terminal(), "trajectories", true);
    #[cfg(feature = "mpi")]
    if rovib::ensemble::mpi::launched() {
        return rovib::ensemble::mpi::run(path, &options, &mut |p| bar.update(p));
    }
    let scene = load_scene(path)?;
    run_ensemble_with(&scene, &options, &mut |p| bar.update(p)).map(Some)
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
    for note in report.threads_note.iter().chain(&report.lanes_note) {
        text.push_str(&format!("note: {note}\n"));
    }
    for (reason, n) in &o.failed {
        text.push_str(&format!("  {n} failed: {reason}\n"));
    }
    for f in &report.files {
        text.push_str(&format!("wrote {}\n", f.display()));
    }
    text
}
