//! summary.json of a finished ensemble: what ran, how it ended, and how to read the outputs.

use serde_json::json;

use crate::ensemble::EnsembleReport;
use crate::ensemble::runner::{Accumulators, Plan};
use crate::ensemble::scene::EnsembleScene;
use crate::runtime::Molecule;
use crate::runtime::spectrum::Spectrum;
use crate::scene::Scene;

/// The summary of a finished ensemble (status completed, interrupted or failed).
pub(super) fn summary_json<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    ensemble: &EnsembleScene,
    plan: &Plan<'_, M, N, NA>,
    report: &EnsembleReport,
    spectrum: Option<&Spectrum>,
) -> serde_json::Value {
    let ts = scene.time_unit.in_au();
    let tu = scene.time_unit.name();
    let acc = &report.outcome.statistics;
    let o = &report.outcome;
    json!({
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
        "block_size": crate::ensemble::runner::BLOCK,
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
        "histograms_outside_range": histograms_outside_range(m, plan, acc),
        "chart": plan.chart.name(),
        "chart_requested": scene.chart.0.name(),
        "charts": charts_json(plan, &o.charts, ts),
        "stops": crate::ensemble::lifetimes::summary(m, plan, o, ts),
        "spectrum": crate::ensemble::pair::summary(plan, report.phase_space.as_ref(), spectrum),
        "pair_states": plan.pairs.as_ref().zip(report.pair_states.as_ref())
            .map(|(p, c)| crate::ensemble::pair_states::summary(p, c, &report.outcome.pair_states)),
        "correlation": if plan.spectrum.pair() {
            "C(tau) = x(0) x(tau) for tau from -T to T (negative tau: the trajectory run backward in time from its sampled state, momenta reversed), no mean subtracted, averaged over every completed trajectory (0 after a stop); lags on the uniform grid k * output_interval only"
        } else {
            "C(tau) = sum_t dx(t) dx(t+tau) / (n - tau), dx = x - (time mean of x along the trajectory), n its outputs, averaged over the trajectories whose outputs span the lag (count per lag: column n of correlations.csv); lags on the uniform grid k * output_interval only"
        },
    })
}

/// For each histogrammed quantity, the values below, above and outside (NaN) its range at each
/// of its times.
fn histograms_outside_range<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    plan: &Plan<'_, M, N, NA>,
    acc: &Accumulators,
) -> Vec<serde_json::Value> {
    plan.histograms.iter().enumerate().map(|(i, (qi, _, _, _))| {
        let first: usize = plan.histograms[..i].iter().map(|h| h.3.len()).sum();
        json!({
            "quantity": plan.quantities[*qi].name(m),
            "below": (0..plan.histograms[i].3.len()).map(|t| acc.histograms[first + t].below()).collect::<Vec<_>>(),
            "above": (0..plan.histograms[i].3.len()).map(|t| acc.histograms[first + t].above()).collect::<Vec<_>>(),
            "not_a_number": (0..plan.histograms[i].3.len()).map(|t| acc.histograms[first + t].not_a_number()).collect::<Vec<_>>(),
        })
    }).collect::<Vec<_>>()
}

/// The chart switches of the completed trajectories (times in the scene's unit, `ts` a.u. per
/// unit), or why the trajectories do not switch.
fn charts_json<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    c: &crate::ensemble::runner::ChartCounts,
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
