//! [`crate::ensemble::run_block`] one trajectory at a time: each trajectory of the block is
//! drawn, checked, integrated (forward, and for the pair estimator also backward in time) while
//! a [`Watch`] observes it into reused buffers, and folded into the block's outcome.
//!
//! Nothing here allocates per step: the buffers are made once per block ([`Scratch`]) and the
//! observation is [`Watch`]'s.

use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};

use super::{
    Accumulators, Failure, Integrator, Outcome, PANIC_HOOK, Plan, Stop, Tally, Watch, chart_reason, fold,
    hamiltonian_reason, in_cartesian_chart, panic_hook, solve_reason, write_chart_report,
};
use crate::output::{DipoleCsv, TrajectoryCsv};
use crate::runtime::Molecule;
use crate::runtime::cartesian_system::CartesianSystem;
use crate::runtime::charts::{ChartReport, ChartStart};
use crate::runtime::ensemble::CorrelationWorkspace;
use crate::runtime::hamiltonian::fast::{BodyState, ReducedSystem};
use crate::runtime::integrate::{SolveError, Stats};
use crate::runtime::sample::Sampler;

/// Why a pass of a trajectory failed: the failure's category, time (a.u.) and detail.
type PassFailure = (&'static str, Option<f64>, String);

/// [`crate::ensemble::run_block`] one trajectory at a time.
pub(in crate::ensemble) fn run_block_scalar<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    sampler: &dyn Sampler<N>,
    indices: Range<u64>,
    stop: &AtomicBool,
    progress: &Tally,
) -> Outcome
where
    M: Molecule<N, NA> + Sync,
{
    let mut outcome = Outcome::new(Accumulators::new(plan));
    let block = Block::new(plan, stop, progress);
    let integrated_dim = if block.in_cartesian { 6 * NA } else { plan.reduction.dim() };
    let mut integrator = match Integrator::new(&plan.method, integrated_dim, NA, block.switching) {
        Ok(i) => i,
        Err(e) => {
            for index in indices {
                let f =
                    Failure { index, reason: "invalid integrator settings".into(), time: None, detail: e.to_string() };
                outcome.fail(f, progress);
            }
            return outcome;
        }
    };
    let mut scratch = Scratch::new(plan);
    let panic_at = panic_hook();
    for index in indices {
        if stop.load(Ordering::Relaxed) {
            outcome.interrupted += 1;
            continue;
        }
        if panic_at == Some(index) {
            panic!("{PANIC_HOOK}={index}: a deliberate panic (test hook)");
        }
        match draw(sampler, index) {
            Ok(drawn) => block.run_trajectory(&mut integrator, &mut scratch, &mut outcome, index, &drawn),
            Err((reason, time, detail)) => {
                outcome.fail(Failure { index, reason: reason.into(), time, detail }, progress);
                progress.done();
            }
        }
    }
    outcome
}

/// Trajectory `index`'s initial state from the sampler, which must be finite.
#[inline]
fn draw<const N: usize>(sampler: &dyn Sampler<N>, index: u64) -> Result<BodyState<N>, PassFailure> {
    let drawn = sampler.draw(index).map_err(|e| ("sampler", None, e.to_string()))?;
    let finite = drawn.q.iter().chain(drawn.p.iter()).chain(drawn.j.iter()).all(|v| v.is_finite())
        && drawn.orientation.coords.iter().all(|v| v.is_finite());
    if !finite {
        return Err(("invalid initial state", Some(0.0), format!("the drawn state is not finite: {drawn:?}")));
    }
    Ok(drawn)
}

/// The buffers reused by every trajectory of a block.
struct Scratch {
    /// The observations of the forward run, `[time][quantity]`.
    buffer: Vec<f64>,
    /// The pair estimator's backward run (`crate::ensemble::pair`), else empty.
    backward: Vec<f64>,
    /// The reduced initial state.
    y0: Vec<f64>,
    /// The correlation functions' workspace, if any are computed.
    workspace: Option<CorrelationWorkspace>,
    /// One quantity's series and its correlation, for `fold`.
    series: Vec<f64>,
    correlation: Vec<f64>,
}

impl Scratch {
    fn new<M, const N: usize, const NA: usize>(plan: &Plan<'_, M, N, NA>) -> Self {
        let size = plan.times.len() * plan.quantities.len();
        let lags = plan.correlation_lags();
        Scratch {
            buffer: vec![0.0; size],
            backward: if plan.spectrum.pair() { vec![0.0; size] } else { Vec::new() },
            y0: vec![0.0; plan.reduction.dim()],
            workspace: (!plan.correlations.is_empty()).then(|| CorrelationWorkspace::new(lags)),
            series: vec![0.0; lags],
            correlation: vec![0.0; lags],
        }
    }
}

/// What the trajectories of a block share: the plan and what follows from it.
struct Block<'p, 'm, M, const N: usize, const NA: usize> {
    plan: &'p Plan<'m, M, N, NA>,
    stop: &'p AtomicBool,
    progress: &'p Tally,
    /// Whether the plan switches charts.
    switching: bool,
    /// Whether every trajectory is integrated in the Cartesian chart.
    in_cartesian: bool,
    /// 2 for the pair estimator (forward and backward in time), else 1.
    passes: usize,
    needs_potential: bool,
    needs_dipole: bool,
}

/// A pass that ran to its end: outputs observed, the stop condition met, its work and charts.
struct Ran {
    k: usize,
    stopped: Option<Stop>,
    stats: Stats,
    chart_report: ChartReport,
}

/// How one pass of a trajectory ended.
enum Pass {
    Failed(PassFailure),
    Interrupted,
    Ran(Ran),
}

impl<'p, 'm, M, const N: usize, const NA: usize> Block<'p, 'm, M, N, NA>
where
    M: Molecule<N, NA> + Sync,
{
    fn new(plan: &'p Plan<'m, M, N, NA>, stop: &'p AtomicBool, progress: &'p Tally) -> Self {
        Block {
            plan,
            stop,
            progress,
            switching: plan.switches_charts(),
            in_cartesian: plan.in_cartesian_chart(),
            passes: if plan.spectrum.pair() { 2 } else { 1 },
            needs_potential: plan.quantities.iter().any(|q| q.needs_potential()),
            needs_dipole: plan.quantities.iter().any(|q| q.needs_dipole()),
        }
    }

    /// Runs trajectory `index` from `drawn` (both passes for the pair estimator) and counts it
    /// in `outcome`: completed and folded, failed, or interrupted (not counted as done).
    #[inline]
    fn run_trajectory(
        &self,
        integrator: &mut Integrator,
        scratch: &mut Scratch,
        outcome: &mut Outcome,
        index: u64,
        drawn: &BodyState<N>,
    ) {
        // The pair estimator's forward run, kept while the backward one runs.
        let mut forward: Option<Ran> = None;
        for pass in 0..self.passes {
            // Pass 1 (pair estimator only) runs backward in time: the state with its momenta reversed.
            let state = if pass == 0 { *drawn } else { crate::ensemble::pair::reversed(drawn) };
            match self.run_pass(integrator, scratch, index, pass, &state) {
                Pass::Failed((reason, time, detail)) => {
                    let detail = if pass == 0 { detail } else { format!("backward in time (t is -t): {detail}") };
                    outcome.fail(Failure { index, reason: reason.into(), time, detail }, self.progress);
                    break;
                }
                Pass::Interrupted => {
                    outcome.interrupted += 1;
                    return;
                }
                Pass::Ran(ran) if pass + 1 < self.passes => forward = Some(ran),
                Pass::Ran(ran) => self.complete(scratch, outcome, index, drawn, forward.take(), ran),
            }
        }
        self.progress.done();
    }

    /// One pass of trajectory `index` from `state`, observed into the forward (pass 0) or the
    /// backward buffer.
    #[inline]
    fn run_pass(
        &self,
        integrator: &mut Integrator,
        scratch: &mut Scratch,
        index: u64,
        pass: usize,
        state: &BodyState<N>,
    ) -> Pass {
        let plan = self.plan;
        // The sampled state is the template: frozen coordinates stay at its values.
        let mut system = ReducedSystem::from_body(plan.molecule, plan.reduction, state).with_min_pivot(plan.min_pivot);
        // A state at a singular geometry starts in the Cartesian chart when the plan switches
        // (the chart integrator checks it: an `InvalidInput` there is an invalid initial state).
        if let Err(e) = system.reduce_body(state, &mut scratch.y0)
            && !self.switching
            && !self.in_cartesian
        {
            return Pass::Failed(("invalid initial state", Some(0.0), e.to_string()));
        }
        let (csv, dipole) = match open_kept(plan, index, pass) {
            Ok(files) => files,
            Err(e) => return Pass::Failed(("output", Some(0.0), e)),
        };
        let out = if pass == 0 { &mut scratch.buffer } else { &mut scratch.backward };
        let mut watch = Watch {
            system,
            plan,
            buffer: out,
            needs_potential: self.needs_potential,
            needs_dipole: self.needs_dipole || dipole.is_some(),
            k: 0,
            initial_energy: 0.0,
            stop: self.stop,
            failure: None,
            interrupted: false,
            csv,
            dipole,
            cartesian: if self.switching || self.in_cartesian {
                CartesianSystem::new(plan.molecule).ok()
            } else {
                None
            },
            last_q: state.q,
            stopped: None,
        };
        let mut chart_report = ChartReport::default();
        let result = match integrator {
            Integrator::Charts(charts) => charts
                .integrate(
                    &system,
                    0.0,
                    ChartStart::Fresh(state),
                    plan.t_end,
                    plan.interval,
                    &mut watch,
                    &mut chart_report,
                )
                .map(|()| chart_report.stats)
                .map_err(|e| match e {
                    // The settings were checked when the integrators were made: what is left is
                    // a start that neither chart can hold.
                    SolveError::InvalidInput(why) => ("invalid initial state", why, Some(0.0)),
                    e => solve_reason(&e, chart_reason),
                }),
            other if self.in_cartesian => in_cartesian_chart(other, plan, state, &mut watch),
            other => other
                .integrate(&mut system, &scratch.y0, plan.t_end, plan.interval, &mut watch)
                .map_err(|e| solve_reason(&e, hamiltonian_reason)),
        };
        self.close_kept(&mut watch, index, &chart_report);
        let (k, interrupted, observed, stopped) = (watch.k, watch.interrupted, watch.failure.take(), watch.stopped);
        let n_times = plan.times.len();
        match (result, observed) {
            (Err((reason, detail, time)), _) => Pass::Failed((reason, time, detail)),
            (Ok(_), Some((reason, t, detail))) => Pass::Failed((reason, Some(t), detail)),
            (Ok(_), None) if interrupted => Pass::Interrupted,
            (Ok(_), None) if k != n_times && stopped.is_none() => {
                Pass::Failed(("output", Some(plan.t_end), format!("{k} output times observed, {n_times} expected")))
            }
            (Ok(stats), None) => Pass::Ran(Ran { k, stopped, stats, chart_report }),
        }
    }

    /// Flushes a kept trajectory's files and writes its chart switches beside them; an error
    /// fails the trajectory unless it failed already.
    #[inline]
    fn close_kept(&self, watch: &mut Watch<'_, '_, M, N, NA>, index: u64, chart_report: &ChartReport) {
        let plan = self.plan;
        if let Some(csv) = &mut watch.csv
            && let Err(e) = csv.flush()
        {
            watch.failure.get_or_insert(("output", plan.t_end, e.to_string()));
        }
        if let Some(d) = &mut watch.dipole
            && let Err(e) = d.flush()
        {
            watch.failure.get_or_insert(("output", plan.t_end, e.to_string()));
        }
        // A kept trajectory's chart switches beside its trajectory.csv.
        if self.switching
            && watch.csv.is_some()
            && let Some((_, dir)) = &plan.keep
            && let Err(e) = write_chart_report(&dir.join(index.to_string()), chart_report, plan.time_scale)
        {
            watch.failure.get_or_insert(("output", plan.t_end, e.to_string()));
        }
    }

    /// Counts a completed trajectory (its last pass `last`, after `forward` for the pair
    /// estimator) and folds its observations into the block's statistics.
    #[inline]
    fn complete(
        &self,
        scratch: &mut Scratch,
        outcome: &mut Outcome,
        index: u64,
        drawn: &BodyState<N>,
        forward: Option<Ran>,
        last: Ran,
    ) {
        let plan = self.plan;
        // The backward run's work and chart switches count with the forward run's.
        let (run, back) = match forward {
            Some(mut f) => {
                f.stats.steps += last.stats.steps;
                f.stats.rhs_evals += last.stats.rhs_evals;
                f.chart_report.switches += last.chart_report.switches;
                f.chart_report.cartesian_time += last.chart_report.cartesian_time;
                f.chart_report.rigid_time += last.chart_report.rigid_time;
                (f, Some(last.k))
            }
            None => (last, None),
        };
        outcome.completed += 1;
        outcome.steps += run.stats.steps;
        outcome.rhs_evaluations += run.stats.rhs_evals;
        if self.switching {
            outcome.charts.add(index, &run.chart_report);
        }
        outcome.count_lifetime(plan, index, run.k, run.stopped);
        let Scratch { buffer, backward, workspace, series, correlation, .. } = scratch;
        match back {
            Some(kb) => {
                fold(plan, &mut outcome.statistics, buffer, run.k, None, series, correlation);
                crate::ensemble::pair::fold_pair(plan, &mut outcome.statistics, buffer, run.k, backward, kb);
                let classes = &mut outcome.pair_states;
                crate::ensemble::pair_states::fold(plan, drawn, classes, buffer, run.k, backward, kb);
            }
            None => fold(plan, &mut outcome.statistics, buffer, run.k, workspace.as_mut(), series, correlation),
        }
    }
}

/// The files of a kept trajectory (`ensemble.keep_trajectories`, forward pass only):
/// trajectory.csv, and dipole.csv for a molecule with a dipole surface; none for the others.
fn open_kept<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    index: u64,
    pass: usize,
) -> Result<(Option<TrajectoryCsv>, Option<DipoleCsv>), String> {
    let csv = match &plan.keep {
        Some((k, dir)) if index.is_multiple_of(*k) && pass == 0 => {
            let dir = dir.join(index.to_string());
            let unit = crate::scene::TimeUnit::of_scale(plan.time_scale).map_or("au", |u| u.name());
            let csv = std::fs::create_dir_all(&dir)
                .map_err(|e| crate::Error::io("cannot create", &dir, e))
                .and_then(|()| TrajectoryCsv::create(&dir, &plan.molecule.coordinates(), unit, false))
                .map_err(|e| e.to_string())?;
            Some(csv)
        }
        _ => None,
    };
    // A kept trajectory of a molecule with a dipole surface also writes dipole.csv.
    let dipole = match (&csv, &plan.keep) {
        (Some(_), Some((_, dir))) if plan.molecule.has_dipole() => {
            Some(DipoleCsv::create(&dir.join(index.to_string())).map_err(|e| e.to_string())?)
        }
        _ => None,
    };
    Ok((csv, dipole))
}
