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

use std::path::{Path, PathBuf};

use serde_json::json;

use super::EnsembleReport;
#[cfg(feature = "svg")]
use super::plot::svg;
use super::plot::{Content, Panel};
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
    remove_files(dir, &ENSEMBLE_FILES)?;
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
    let files: Vec<&str> = ENSEMBLE_FILES.iter().copied().filter(|&f| f != "summary.json").collect();
    remove_files(dir, &files)?;
    remove_kept(dir)
}

fn remove_files(dir: &Path, names: &[&str]) -> Result<(), Error> {
    for name in names {
        let path = dir.join(name);
        match std::fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(Error::io("cannot remove (left by an earlier run)", path, e)),
        }
    }
    Ok(())
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
    let tu = scene.time_unit.name();
    let ts = scene.time_unit.in_au();
    let acc = &report.outcome.statistics;
    let mut files = Vec::new();
    let mut csv = |name: &str, lines: Vec<String>| -> Result<(), Error> {
        let mut f = OutputFile::create(dir, name)?;
        for l in &lines {
            f.line(l)?;
        }
        f.flush()?;
        files.push(f.path().to_owned());
        Ok(())
    };

    // ensemble.csv
    let nm = plan.n_means;
    let mut lines = Vec::with_capacity(plan.times.len() + 1);
    let mut header = vec![format!("t_{tu}"), "n".to_owned()];
    for (name, unit) in report.quantities.iter().zip(&report.units) {
        header.push(format!("{name}_mean_{unit}"));
        header.push(format!("{name}_stderr_{unit}"));
    }
    lines.push(header.join(","));
    for (k, t) in plan.times.iter().enumerate() {
        // The trajectories observed at this time: all completed ones, less those stopped earlier.
        let mut row = format!("{:?},{}", t / ts, report.outcome.lifetimes.observed(k));
        for j in 0..nm {
            let m = &acc.means[k * nm + j];
            row.push_str(&format!(",{:?},{:?}", m.mean(), m.standard_error()));
        }
        lines.push(row);
    }
    csv("ensemble.csv", lines)?;

    // histograms.csv
    let mut lines = vec![format!("quantity,unit,t_{tu},bin_low,bin_high,count,density")];
    let mut h = 0;
    let mut hist_panels = Vec::new();
    for (qi, _, _, at) in &plan.histograms {
        let (name, unit) = (plan.quantities[*qi].name(m), plan.quantities[*qi].unit(m));
        for &k in at {
            let hist = &acc.histograms[h];
            let mut bars = Vec::new();
            for (i, &c) in hist.counts().iter().enumerate() {
                let lo = hist.low() + i as f64 * hist.width();
                let hi = if i + 1 == hist.counts().len() { hist.high() } else { lo + hist.width() };
                let density = if hist.total() == 0 { 0.0 } else { hist.density(i) };
                lines.push(format!("{name},{unit},{:?},{lo:?},{hi:?},{c},{density:?}", plan.times[k] / ts));
                bars.push((lo, hi, density));
            }
            hist_panels.push(Panel {
                title: format!("{name} at t = {} {tu}", tick_time(plan.times[k] / ts)),
                x_label: format!("{name} ({unit})"),
                y_label: format!("probability density (1/{unit})"),
                content: Content::Bars(bars),
            });
            h += 1;
        }
    }
    csv("histograms.csv", lines)?;

    // correlations.csv
    let mut header = vec![format!("tau_{tu}"), "n".to_owned()];
    for &qi in &plan.correlations {
        let (name, unit) = (plan.quantities[qi].name(m), plan.quantities[qi].unit(m));
        // A compound unit is squared as a whole: (e*bohr)^2.
        let unit = if unit.contains(['*', '/']) { format!("({unit})") } else { unit.to_owned() };
        header.push(format!("{name}_C_{unit}^2"));
        header.push(format!("{name}_C_stderr_{unit}^2"));
        header.push(format!("{name}_C_normalised"));
    }
    let mut lines = vec![header.join(",")];
    // Lags on the uniform grid only (`Plan::correlation_lags`); `n`: the trajectories whose
    // span covers the lag, which every correlated quantity shares.
    // The pair estimator keeps τ from −T to T: row i is lag i − (lags − 1), C(0) at lags − 1.
    let zero = plan.correlation_span() - plan.correlation_lags();
    for lag in 0..plan.correlation_span() {
        let t = if lag >= zero { plan.times[lag - zero] } else { -plan.times[zero - lag] };
        let n = acc.correlations.first().map_or(0, |c| c[lag].count());
        let mut row = format!("{:?},{n}", t / ts);
        for c in &acc.correlations {
            let (mean, c0) = (c[lag].mean(), c[zero].mean());
            row.push_str(&format!(",{mean:?},{:?},{:?}", c[lag].standard_error(), mean / c0));
        }
        lines.push(row);
    }
    csv("correlations.csv", lines)?;
    if !plan.stops.is_empty() {
        csv("lifetimes.csv", super::lifetimes::lifetimes_csv(m, plan, &report.outcome, tu, ts))?;
        csv("stops.csv", super::lifetimes::stops_csv(m, plan, &report.outcome, tu, ts))?;
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

    // Plots.
    let panels: Vec<Panel> = (0..nm)
        .map(|j| Panel {
            title: format!("⟨{}⟩ ± standard error", report.quantities[j]),
            x_label: format!("t ({tu})"),
            y_label: format!("{} ({})", report.quantities[j], report.units[j]),
            content: Content::Band(
                plan.times
                    .iter()
                    .enumerate()
                    .map(|(k, t)| {
                        let m = &acc.means[k * nm + j];
                        (t / ts, m.mean(), m.standard_error())
                    })
                    .collect(),
            ),
        })
        .collect();
    // The plots need the `svg` feature; the CSV files above hold the same figures.
    #[cfg(feature = "svg")]
    for (name, panels) in [("ensemble.svg", panels), ("histograms.svg", hist_panels)] {
        let path = dir.join(name);
        std::fs::write(&path, svg(&panels)).map_err(|e| Error::io("cannot write", &path, e))?;
        files.push(path);
    }
    #[cfg(not(feature = "svg"))]
    let _ = (panels, hist_panels);

    // summary.json
    let o = &report.outcome;
    let summary = json!({
        "scene": scene.path,
        "molecule": m.name(),
        "status": report.status.name(),
        "trajectories": {
            "requested": report.requested,
            "completed": o.completed,
            "failed": o.failed_count(),
            "interrupted_or_not_run": o.interrupted,
        },
        "failures_by_reason": o.failed,
        "first_failures": o.first_failures.iter().map(|f| json!({
            "index": f.index,
            "reason": f.reason,
            "time": f.time.map(|t| t / ts),
            "detail": f.detail,
        })).collect::<Vec<_>>(),
        "statistics_cover": "completed trajectories only: failed and interrupted ones are left out",
        "description": scene.description,
        "seed": report.seed,
        "seed_given": ensemble.seed_given,
        "sampler": report.sampler,
        "threads": report.threads,
        "threads_note": report.threads_note,
        "lanes_note": report.lanes_note,
        "ranks": report.ranks,
        "blocks_by_rank": report.blocks_by_rank,
        "resumed_trajectories": report.resumed,
        "block_size": super::runner::BLOCK,
        "wall_time_s": report.wall_time,
        "throughput_trajectories_per_s": report.throughput(),
        "steps": o.steps,
        "rhs_evaluations": o.rhs_evaluations,
        "method": scene.method.name(),
        "t_end": scene.t_end / ts,
        "output_interval": scene.output_interval / ts,
        "output_times": plan.times.len(),
        "time_unit": tu,
        "frozen": scene.frozen.iter().map(|s| s.get_ref().as_str()).collect::<Vec<_>>(),
        "max_energy_error": scene.max_energy_error,
        "max_energy_error_relative_to": format!(
            "max(|H(0)|, {:e} hartree) of each trajectory",
            crate::output::ENERGY_SCALE_FLOOR
        ),
        "kept_trajectories_every": ensemble.keep_trajectories,
        "means": report.quantities.iter().zip(&report.units).map(|(q, u)| json!({"quantity": q, "unit": u})).collect::<Vec<_>>(),
        "histograms_outside_range": plan.histograms.iter().enumerate().map(|(i, (qi, _, _, _))| {
            let first: usize = plan.histograms[..i].iter().map(|h| h.3.len()).sum();
            json!({
                "quantity": plan.quantities[*qi].name(m),
                "below": (0..plan.histograms[i].3.len()).map(|t| acc.histograms[first + t].below()).collect::<Vec<_>>(),
                "above": (0..plan.histograms[i].3.len()).map(|t| acc.histograms[first + t].above()).collect::<Vec<_>>(),
                "not_a_number": (0..plan.histograms[i].3.len()).map(|t| acc.histograms[first + t].not_a_number()).collect::<Vec<_>>(),
            })
        }).collect::<Vec<_>>(),
        "chart": plan.chart.name(),
        "chart_requested": scene.chart.0.name(),
        "charts": charts_json(plan, &o.charts, ts),
        "stops": super::lifetimes::summary(m, plan, o, ts),
        "spectrum": super::pair::summary(plan, report.phase_space.as_ref(), spectrum.as_ref()),
        "pair_states": plan.pairs.as_ref().zip(report.pair_states.as_ref())
            .map(|(p, c)| super::pair_states::summary(p, c, &report.outcome.pair_states)),
        "correlation": if plan.spectrum.pair() {
            "C(tau) = x(0) x(tau) for tau from -T to T (negative tau: the trajectory run backward in time from its sampled state, momenta reversed), no mean subtracted, averaged over every completed trajectory (0 after a stop); lags on the uniform grid k * output_interval only"
        } else {
            "C(tau) = sum_t dx(t) dx(t+tau) / (n - tau), dx = x - (time mean of x along the trajectory), n its outputs, averaged over the trajectories whose outputs span the lag (count per lag: column n of correlations.csv); lags on the uniform grid k * output_interval only"
        },
    });
    files.push(write_summary(dir, &summary)?);
    Ok(files)
}

/// The chart switches of the completed trajectories (times in the scene's unit, `ts` a.u. per
/// unit), or why the trajectories do not switch.
fn charts_json<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    c: &super::runner::ChartCounts,
    ts: f64,
) -> serde_json::Value {
    use crate::runtime::charts::{RETURN_PIVOT, SWITCH_PIVOT};
    if !plan.switches_charts() {
        let why = if plan.in_cartesian_chart() {
            "every trajectory is integrated in the Cartesian chart (run.chart: see chart and chart_requested)"
        } else if !plan.cartesian_fallback {
            "run.cartesian_fallback = false"
        } else if !matches!(plan.method, crate::runtime::integrate::Method::Dop853(_)) {
            "only dop853 switches charts (the fixed-step methods stop at a singular geometry)"
        } else if !plan.reduction.active.iter().all(|&a| a) {
            "frozen coordinates have no Cartesian counterpart"
        } else {
            "the molecule has no Cartesian potential (its definition gives positions, not coordinates by kind) and \
             is not a complex of rigid linear fragments and atoms"
        };
        return json!({ "switching": false, "why": why });
    }
    let mut out = json!({
        "switching": true,
        "switch_pivot": SWITCH_PIVOT,
        "return_pivot": RETURN_PIVOT,
        "counted": "completed trajectories",
        "trajectories_switched": c.trajectories_switched,
        "switches": c.switches,
        "cartesian_time": c.cartesian_time / ts,
        "trajectories_by_switches": c.by_switches.iter().map(|[k, v]| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
        "first_switching": c.first.iter().map(|t| json!({
            "index": t.index,
            "switches": t.switches,
            "cartesian_time": t.cartesian_time / ts,
        })).collect::<Vec<_>>(),
    });
    if plan.uses_rigid_chart() {
        out["chart"] = json!("rigid");
        out["rigid_time"] = json!(c.rigid_time / ts);
    }
    out
}

fn tick_time(t: f64) -> String {
    let s = format!("{t:.6}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}
