//! What an ensemble writes: ensemble.csv (means and standard errors against time),
//! histograms.csv, correlations.csv, summary.json, ensemble.svg and histograms.svg (and, with
//! stop conditions, lifetimes.csv and stops.csv: `super::lifetimes`).
//!
//! Numbers are written with full round-trip precision (`{:?}`); a statistic that does not
//! exist (the standard error of fewer than two values) is written `NaN`. All values are in
//! atomic units, named in the column headers; times are in the scene's time unit.
//!
//! Integrity of the folder: the run holds the directory lock (`crate::dir_lock`) from before it
//! touches anything to after its last write; at the start it removes every output an earlier run
//! (an ensemble, or a `rovib run`) left there ([`remove_stale_outputs`]) and writes `summary.json`
//! with status "running" ([`write_running`]); it ends by writing it again with the true status:
//! "completed", "interrupted", or "failed" (every trajectory failed, or the run stopped on an
//! error, [`write_failed`]). A summary that still says "running" is a run that was killed.
//!
//! The CSV tables and their plots are made in `tables`, the final summary.json in `summary`.

use std::path::{Path, PathBuf};

use serde_json::json;

mod summary;
mod tables;

use super::EnsembleReport;
#[cfg(feature = "svg")]
use super::plot::{Panel, svg};
use super::runner::Plan;
use super::scene::EnsembleScene;
use crate::error::Error;
use crate::output::{OutputFile, write_summary};
use crate::runtime::Molecule;
use crate::scene::Scene;

/// Every file `rovib ensemble` writes into its output folder, besides `checkpoint.jsonl` and the
/// kept trajectories (`trajectories/INDEX/`).
pub const ENSEMBLE_FILES: [&str; 12] = [
    "ensemble.csv",
    "histograms.csv",
    "correlations.csv",
    "moments.csv",
    "spectrum.csv",
    "spectrum.svg",
    "ensemble.svg",
    "histograms.svg",
    "summary.json",
    "pair_states.csv",
    "correlations_by_state.csv",
    "spectrum_by_state.csv",
];

/// The folder of the kept trajectories (`ensemble.keep_trajectories`) in the output folder.
pub const KEPT_FOLDER: &str = "trajectories";

/// Removes what an earlier run left in `dir` that this ensemble would not rewrite at once: its
/// outputs ([`ENSEMBLE_FILES`]), a `rovib run`'s (trajectory.csv, lab.xyz, dipole.csv,
/// restart.json, …) and, unless `resume` (whose resumed blocks' kept trajectories stay), the
/// kept trajectories (the numbered folders in `trajectories/`). Missing files are fine.
pub fn remove_stale_outputs(dir: &Path, resume: bool) -> Result<(), Error> {
    crate::output::remove_earlier_files(dir, ENSEMBLE_FILES)?;
    crate::output::remove_stale_outputs(dir, &[])?;
    if !resume {
        remove_kept(dir)?;
    }
    Ok(())
}

/// For `rovib run` into `dir`: refuses a folder with an unfinished ensemble's checkpoint (its
/// finished blocks would be lost), else removes an ensemble's outputs and kept trajectories.
pub fn clear_for_run(dir: &Path) -> Result<(), Error> {
    let checkpoint = dir.join(super::CHECKPOINT_FILE);
    if checkpoint.exists() {
        return Err(Error::unusable(
            checkpoint,
            " holds the finished blocks of an ensemble that did not complete: resume that ensemble into this folder \
             (`rovib ensemble SCENE --out DIR --resume`), delete the file, or choose another output folder",
        ));
    }
    crate::output::remove_earlier_files(dir, ENSEMBLE_FILES.into_iter().filter(|&f| f != "summary.json"))?;
    remove_kept(dir)
}

/// Removes the numbered folders in `dir/trajectories` (what `keep_trajectories` writes), then
/// the folder if it is left empty; anything else in it is left alone.
fn remove_kept(dir: &Path) -> Result<(), Error> {
    let kept = dir.join(KEPT_FOLDER);
    let Ok(entries) = std::fs::read_dir(&kept) else { return Ok(()) };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let numbered = name.to_str().is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
        if numbered && entry.file_type().is_ok_and(|t| t.is_dir()) {
            std::fs::remove_dir_all(entry.path())
                .map_err(|e| Error::io("cannot remove (left by an earlier run)", entry.path(), e))?;
        }
    }
    let _ = std::fs::remove_dir(&kept);
    Ok(())
}

/// The summary of an ensemble that has started: status "running", replaced when it ends.
pub fn write_running(
    dir: &Path,
    scene: &Scene,
    molecule: &str,
    requested: u64,
    resume: bool,
) -> Result<PathBuf, Error> {
    write_summary(
        dir,
        &json!({
            "scene": scene.path,
            "molecule": molecule,
            "status": "running",
            "process": std::process::id(),
            "resume": resume,
            "trajectories": { "requested": requested },
            "note": "written when the ensemble started and replaced when it ends; a run that still says \"running\" \
                     while no process holds the folder's lock was killed (continue it with `rovib ensemble --resume` or `EnsembleOptions::resume`)",
        }),
    )
}

/// The summary of an ensemble that stopped on an error (no statistics were written).
pub fn write_failed(
    dir: &Path,
    scene: &Scene,
    molecule: &str,
    requested: u64,
    error: &str,
    checkpoint: Option<&Path>,
) -> Result<PathBuf, Error> {
    write_summary(
        dir,
        &json!({
            "scene": scene.path,
            "molecule": molecule,
            "status": "failed",
            "error": error,
            "trajectories": { "requested": requested },
            "checkpoint": checkpoint.filter(|c| c.exists()),
        }),
    )
}

/// Writes every output of `report` into `dir` and returns the files' paths.
pub fn write_all<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    ensemble: &EnsembleScene,
    plan: &Plan<'_, M, N, NA>,
    report: &EnsembleReport,
    dir: &Path,
) -> Result<Vec<PathBuf>, Error> {
    let time = (scene.time_unit.name(), scene.time_unit.in_au());
    let (tu, ts) = time;
    let acc = &report.outcome.statistics;
    let mut files = Vec::new();
    write_lines(dir, "ensemble.csv", &tables::means_csv(plan, report, time), &mut files)?;
    let (lines, hist_panels) = tables::histograms(m, plan, acc, time);
    write_lines(dir, "histograms.csv", &lines, &mut files)?;
    write_lines(dir, "correlations.csv", &tables::correlations_csv(m, plan, acc, time), &mut files)?;
    if !plan.stops.is_empty() {
        let lifetimes = super::lifetimes::lifetimes_csv(m, plan, &report.outcome, tu, ts);
        write_lines(dir, "lifetimes.csv", &lifetimes, &mut files)?;
        write_lines(dir, "stops.csv", &super::lifetimes::stops_csv(m, plan, &report.outcome, tu, ts), &mut files)?;
    }
    let temperature = ensemble.method.temperature();
    files.extend(super::spectrum::write(plan, acc, temperature, dir)?);
    let spectrum = super::spectrum::spectrum(plan, acc);
    if let Some(phase) = &report.phase_space {
        files.push(super::pair::write_moments(phase, spectrum.as_ref(), dir)?);
    }
    if let Some(census) = &report.pair_states {
        files.extend(super::pair_states::write(plan, census, &report.outcome.pair_states, (tu, ts), dir)?);
    }
    // The plots need the `svg` feature; the CSV files above hold the same figures.
    #[cfg(feature = "svg")]
    write_plots(dir, tables::mean_panels(plan, report, time), hist_panels, &mut files)?;
    #[cfg(not(feature = "svg"))]
    let _ = hist_panels;
    let summary = summary::summary_json(m, scene, ensemble, plan, report, spectrum.as_ref());
    files.push(write_summary(dir, &summary)?);
    Ok(files)
}

/// Writes `lines` into the file `name` in `dir` and adds its path to `files`.
fn write_lines(dir: &Path, name: &str, lines: &[String], files: &mut Vec<PathBuf>) -> Result<(), Error> {
    let mut f = OutputFile::create(dir, name)?;
    for l in lines {
        f.line(l)?;
    }
    f.flush()?;
    files.push(f.path().to_owned());
    Ok(())
}

/// Writes ensemble.svg (the means) and histograms.svg and adds their paths to `files`.
#[cfg(feature = "svg")]
fn write_plots(dir: &Path, means: Vec<Panel>, histograms: Vec<Panel>, files: &mut Vec<PathBuf>) -> Result<(), Error> {
    for (name, panels) in [("ensemble.svg", means), ("histograms.svg", histograms)] {
        let path = dir.join(name);
        std::fs::write(&path, svg(&panels)).map_err(|e| Error::io("cannot write", &path, e))?;
        files.push(path);
    }
    Ok(())
}
