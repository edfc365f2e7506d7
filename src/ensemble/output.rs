//! What an ensemble writes: ensemble.csv (means and standard errors against time),
//! histograms.csv, correlations.csv, summary.json, ensemble.svg and histograms.svg.
//!
//! Numbers are written with full round-trip precision (`{:?}`); a statistic that does not
//! exist (the standard error of fewer than two values) is written `NaN`. All values are in
//! atomic units, named in the column headers; times are in the scene's time unit.

use std::path::{Path, PathBuf};

use serde_json::json;

use super::EnsembleReport;
use super::plot::{Content, Panel, svg};
use super::runner::Plan;
use super::scene::EnsembleScene;
use crate::cli::CliError;
use crate::output::{OutputFile, write_summary};
use crate::runtime::Molecule;
use crate::scene::Scene;

/// Writes every output of `report` into `dir` and returns the files' paths.
pub fn write_all<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    ensemble: &EnsembleScene,
    plan: &Plan<'_, M, N, NA>,
    report: &EnsembleReport,
    dir: &Path,
) -> Result<Vec<PathBuf>, CliError> {
    let tu = scene.time_unit.name();
    let ts = scene.time_unit.in_au();
    let acc = &report.outcome.statistics;
    let mut files = Vec::new();
    let mut csv = |name: &str, lines: Vec<String>| -> Result<(), CliError> {
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
        let mut row = format!("{:?},{}", t / ts, acc.means.get(k * nm).map_or(0, |m| m.count()));
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
    let mut header = vec![format!("tau_{tu}")];
    for &qi in &plan.correlations {
        let (name, unit) = (plan.quantities[qi].name(m), plan.quantities[qi].unit(m));
        header.push(format!("{name}_C_{unit}^2"));
        header.push(format!("{name}_C_stderr_{unit}^2"));
        header.push(format!("{name}_C_normalised"));
    }
    let mut lines = vec![header.join(",")];
    for (lag, t) in plan.times.iter().enumerate() {
        let mut row = format!("{:?}", t / ts);
        for c in &acc.correlations {
            let (mean, c0) = (c[lag].mean(), c[0].mean());
            row.push_str(&format!(",{mean:?},{:?},{:?}", c[lag].standard_error(), mean / c0));
        }
        lines.push(row);
    }
    csv("correlations.csv", lines)?;
    let temperature = match &ensemble.method {
        super::scene::MethodSpec::Thermal { temperature, .. } => Some(*temperature),
        _ => None,
    };
    files.extend(super::spectrum::write(plan, acc, temperature, dir)?);

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
    for (name, panels) in [("ensemble.svg", panels), ("histograms.svg", hist_panels)] {
        let path = dir.join(name);
        std::fs::write(&path, svg(&panels))
            .map_err(|e| CliError::context(format!("cannot write {}", path.display()), e))?;
        files.push(path);
    }

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
        "charts": charts_json(plan, &o.charts, ts),
        "correlation": "C(tau) = sum_t dx(t) dx(t+tau) / (n - tau), dx = x - (time mean of x along the trajectory), averaged over trajectories",
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
        let why = if !plan.cartesian_fallback {
            "run.cartesian_fallback = false"
        } else if !matches!(plan.method, crate::runtime::integrate::Method::Dop853(_)) {
            "only dop853 switches charts (the fixed-step methods stop at a singular geometry)"
        } else if !plan.reduction.active.iter().all(|&a| a) {
            "frozen coordinates have no Cartesian counterpart"
        } else {
            "the molecule has no Cartesian potential (its definition gives positions, not coordinates by kind)"
        };
        return json!({ "switching": false, "why": why });
    }
    json!({
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
    })
}

fn tick_time(t: f64) -> String {
    let s = format!("{t:.6}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}
