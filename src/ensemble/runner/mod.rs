//! The unit of work of an ensemble: a block of consecutive trajectory indices → its
//! accumulators, failures and counts ([`super::run_block`]), and how block outcomes merge.
//!
//! Trajectory `i` draws its initial state from the sampler (its own random stream, a function
//! of `(seed, i)` only), is integrated with the production system, observed at the output
//! times into a fixed-size buffer and folded into the block's accumulators; no history is kept.
//! Blocks have a fixed size ([`BLOCK`]) and are merged in index order, so the statistics are
//! bit-identical whatever the number of threads (or, later, processes) and whatever order the
//! blocks finish in.

mod merge_error;
mod scalar;

use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use serde::{Deserialize, Serialize};

use super::quantity::Quantity;
use crate::output::TrajectoryCsv;
use crate::runtime::HamiltonianError;
use crate::runtime::Molecule;
use crate::runtime::cartesian_system::{CartesianError, CartesianSystem};
use crate::runtime::charts::{ChartError, ChartIntegrator, ChartObserver, ChartReport, ChartState};
use crate::runtime::ensemble::{CorrelationWorkspace, Histogram, Lifetimes, Moments, Side};
use crate::runtime::frames::body_of_lab_exact;
use crate::runtime::hamiltonian::fast::BodyState;
use crate::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use crate::runtime::integrate::{InvalidInput, Method, Observer, SolveError, Stats};
use crate::runtime::nalgebra::Vector3;
use crate::runtime::rigid_system::RigidError;
use crate::runtime::surface::Dipole;

pub use self::merge_error::{HistogramShape, MergeError, StatisticsShape};
pub(super) use self::scalar::run_block_scalar;

/// Trajectories per block: the grain of parallel work and of the fixed merge order.
pub const BLOCK: u64 = 64;

/// How many failures an outcome lists individually (the first, by index); all are counted.
pub const LISTED_FAILURES: usize = 10;

/// Everything one ensemble run needs to integrate and observe a trajectory.
pub struct Plan<'m, M, const N: usize, const NA: usize> {
    /// The molecule.
    pub molecule: &'m M,
    /// Frozen coordinates; the rotation is always free (the reduction does not depend on the
    /// sampled state).
    pub reduction: Reduction<N>,
    /// The integrator.
    pub method: Method,
    /// End time, a.u.
    pub t_end: f64,
    /// Output interval, a.u.
    pub interval: f64,
    /// The output times, a.u. (the grid `solve` observes).
    pub times: Vec<f64>,
    /// Every quantity observed; the first `n_means` have their means accumulated.
    pub quantities: Vec<Quantity>,
    /// See `quantities`.
    pub n_means: usize,
    /// Histograms: quantity index, bins, range, output-time indices.
    pub histograms: Vec<(usize, usize, [f64; 2], Vec<usize>)>,
    /// Correlated quantities (indices into `quantities`).
    pub correlations: Vec<usize>,
    /// The largest energy change at an output time, relative to max(|H(0)|,
    /// `output::ENERGY_SCALE_FLOOR`), before a trajectory fails.
    pub max_energy_error: f64,
    /// The smallest relative pivot of the metric.
    pub min_pivot: f64,
    /// `run.cartesian_fallback`: trajectories that reach a singular geometry of the internal
    /// chart continue in the Cartesian chart (`runtime::charts`) where that is possible
    /// ([`Plan::switches_charts`]), instead of failing as "ill-conditioned metric".
    pub cartesian_fallback: bool,
    /// `run.chart`: the chart the trajectories are integrated in. In the Cartesian chart
    /// (checked to exist, nothing frozen) every trajectory starts from its sampled state
    /// converted to positions and velocities, and is observed through the internal state
    /// converted at each output time; it never switches charts.
    pub chart: crate::scene::chart::RunChart,
    /// Keep the trajectory of every k-th index in `dir/trajectories/INDEX/trajectory.csv`.
    pub keep: Option<(u64, PathBuf)>,
    /// Scale from a.u. of time to the scene's time unit, for kept trajectories.
    pub time_scale: f64,
    /// Run the trajectories on SIMD lanes where the plan allows it (DOP853, nothing frozen, no
    /// kept trajectories): the same results to round-off, faster (see `super::lanes`).
    pub lanes: bool,
    /// The `[spectrum]` settings; the pair estimator runs every trajectory backward in time too.
    pub spectrum: super::spectrum_scene::SpectrumSettings,
    /// `run.stop_outside`: a trajectory stops at the first output time at which one of these
    /// coordinates (index, name, bounds in a.u.) is outside its bounds; that output is its last.
    pub stops: Vec<StopCondition>,
    /// `[pairs]`: the pair states of the sampled states (`super::pair_states`).
    pub pairs: Option<super::pair_states::PairStates>,
}

/// A stop condition bound to the molecule: coordinate index, name, bounds in atomic units.
pub type StopCondition = (usize, &'static str, [f64; 2]);

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Plan<'_, M, N, NA> {
    /// Whether the trajectories switch charts: `cartesian_fallback`, DOP853 (an adaptive method
    /// restarts at any time), no frozen coordinates (they have no Cartesian counterpart) and a
    /// molecule with a Cartesian potential (coordinates declared by kind) or made of rigid linear
    /// fragments and atoms (the rigid chart).
    pub fn switches_charts(&self) -> bool {
        self.cartesian_fallback
            && !self.in_cartesian_chart()
            && matches!(self.method, Method::Dop853(_))
            && self.reduction.active.iter().all(|&a| a)
            && (CartesianSystem::new(self.molecule).is_ok() || self.uses_rigid_chart())
    }

    /// Whether every trajectory is integrated in the Cartesian chart (`run.chart = "cartesian"`).
    pub fn in_cartesian_chart(&self) -> bool {
        self.chart == crate::scene::chart::RunChart::Cartesian
    }

    /// Whether the fallback chart is the rigid one (no Cartesian potential, a rigid layout).
    pub fn uses_rigid_chart(&self) -> bool {
        CartesianSystem::new(self.molecule).is_err()
            && crate::runtime::rigid_system::RigidLayout::detect(self.molecule).is_some()
    }
}

impl<M, const N: usize, const NA: usize> Plan<'_, M, N, NA> {
    /// The lags of the correlations: the output times on the uniform grid `k · interval`. When
    /// `t_end` is not a multiple of the interval (within 1e-9 of one), the last output closes a
    /// shorter interval and is left out: a correlation (and its FFT spectrum) needs equal lags.
    pub fn correlation_lags(&self) -> usize {
        let n = self.times.len();
        match n {
            0 | 1 => n,
            _ if self.times[n - 1] - self.times[n - 2] < self.interval * (1.0 - 1e-9) => n - 1,
            _ => n,
        }
    }

    /// The correlation values kept per quantity: one per lag, or for the pair estimator one per
    /// lag on each side of τ = 0 (`2·lags − 1`, τ from −T to T).
    pub fn correlation_span(&self) -> usize {
        let lags = self.correlation_lags();
        if self.spectrum.pair() && lags > 0 { 2 * lags - 1 } else { lags }
    }

    /// The first stop condition `q` meets (outside its bounds): its index, the side and the
    /// coordinate's value.
    fn stop_met(&self, q: &[f64]) -> Option<Stop> {
        self.stops.iter().enumerate().find_map(|(c, &(i, _, [low, high]))| {
            let v = q[i];
            let side = if v < low {
                Side::Below
            } else if v > high {
                Side::Above
            } else if v.is_nan() {
                // Not inside: as `rovib run` treats it, outside (reported on the upper side).
                Side::Above
            } else {
                return None;
            };
            Some(Stop { condition: c, side, value: v })
        })
    }
}

/// The stop condition a trajectory met at its last output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stop {
    /// Index into [`Plan::stops`].
    pub condition: usize,
    /// Which side of the interval.
    pub side: Side,
    /// The coordinate's value, a.u.
    pub value: f64,
}

/// How many stopped trajectories an outcome lists individually (the first, by index); all are
/// counted in [`Outcome::lifetimes`].
pub const LISTED_STOPS: usize = 10_000;

/// One stopped trajectory.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoppedTrajectory {
    /// Trajectory index.
    pub index: u64,
    /// The output time at which it stopped, a.u.
    pub time: f64,
    /// The stop condition (index into the plan's stop conditions).
    pub condition: usize,
    /// Which side of the interval.
    pub side: Side,
    /// The coordinate's value there, a.u.
    pub value: f64,
}

/// How many listed trajectories [`ChartCounts`] keeps (the first, by index).
pub const LISTED_SWITCHING: usize = 10;

/// One trajectory that switched charts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SwitchingTrajectory {
    /// Trajectory index.
    pub index: u64,
    /// Chart switches (each way counts one).
    pub switches: u64,
    /// Time in the Cartesian chart, a.u.
    pub cartesian_time: f64,
}

/// The chart switches of the completed trajectories (`runtime::charts`), mergeable in block
/// order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ChartCounts {
    /// Completed trajectories that switched at least once.
    pub trajectories_switched: u64,
    /// Switches in all.
    pub switches: u64,
    /// Time spent in the Cartesian chart, summed over trajectories, a.u.
    pub cartesian_time: f64,
    /// Time spent in the rigid chart, summed over trajectories, a.u.
    #[serde(default)]
    pub rigid_time: f64,
    /// Completed trajectories by their number of switches (0 included): `[switches, count]`
    /// pairs in increasing order of switches (a list, not a map: the checkpoint's untagged
    /// records cannot read integer map keys back).
    pub by_switches: Vec<[u64; 2]>,
    /// The first [`LISTED_SWITCHING`] trajectories that switched, by index.
    pub first: Vec<SwitchingTrajectory>,
}

impl ChartCounts {
    /// Adds `count` trajectories with `switches` switches to `by_switches`.
    fn count(&mut self, switches: u64, count: u64) {
        match self.by_switches.binary_search_by_key(&switches, |p| p[0]) {
            Ok(i) => self.by_switches[i][1] += count,
            Err(i) => self.by_switches.insert(i, [switches, count]),
        }
    }

    pub(super) fn add(&mut self, index: u64, report: &ChartReport) {
        self.count(report.switches, 1);
        if report.switches == 0 {
            return;
        }
        self.trajectories_switched += 1;
        self.switches += report.switches;
        self.cartesian_time += report.cartesian_time;
        self.rigid_time += report.rigid_time;
        if self.first.len() < LISTED_SWITCHING {
            self.first.push(SwitchingTrajectory {
                index,
                switches: report.switches,
                cartesian_time: report.cartesian_time,
            });
        }
    }

    fn merge(&mut self, other: &ChartCounts) {
        self.trajectories_switched += other.trajectories_switched;
        self.switches += other.switches;
        self.cartesian_time += other.cartesian_time;
        self.rigid_time += other.rigid_time;
        for &[k, v] in &other.by_switches {
            self.count(k, v);
        }
        for t in &other.first {
            if self.first.len() < LISTED_SWITCHING {
                self.first.push(t.clone());
            }
        }
    }
}

/// Sums over the trajectories of a block (or of the whole ensemble), mergeable.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Accumulators {
    /// Output times.
    pub n_times: usize,
    /// Quantities with means.
    pub n_means: usize,
    /// Means: `[time][quantity]`, flattened (`k · n_means + j`).
    pub means: Vec<Moments>,
    /// One histogram per (histogram, time), in scene order.
    pub histograms: Vec<Histogram>,
    /// Per correlated quantity, the moments of `C(τ)` over the trajectories spanning the lag,
    /// per lag ([`Plan::correlation_lags`] of them).
    pub correlations: Vec<Vec<Moments>>,
}

impl Accumulators {
    /// Empty accumulators of `plan`'s shape.
    pub fn new<M, const N: usize, const NA: usize>(plan: &Plan<'_, M, N, NA>) -> Self {
        let mut histograms = Vec::new();
        for (_, bins, range, at) in &plan.histograms {
            for _ in at {
                // The range was checked when the scene was parsed.
                histograms.push(Histogram::new(*bins, range[0], range[1]).expect("a checked histogram range"));
            }
        }
        Self {
            n_times: plan.times.len(),
            n_means: plan.n_means,
            means: vec![Moments::new(); plan.times.len() * plan.n_means],
            histograms,
            correlations: vec![vec![Moments::new(); plan.correlation_span()]; plan.correlations.len()],
        }
    }

    /// Merges `other` (the trajectories after this one's) in. Accumulators of another layout
    /// (another number of times or quantities, another histogram's bins or range: another
    /// scene's) are an error naming the difference, and nothing is merged.
    pub fn merge(&mut self, other: &Accumulators) -> Result<(), MergeError> {
        self.same_layout(other)?;
        for (a, b) in self.means.iter_mut().zip(&other.means) {
            a.merge(b);
        }
        for (a, b) in self.histograms.iter_mut().zip(&other.histograms) {
            a.merge(b)?;
        }
        for (a, b) in self.correlations.iter_mut().zip(&other.correlations) {
            for (x, y) in a.iter_mut().zip(b) {
                x.merge(y);
            }
        }
        Ok(())
    }

    /// Whether `other` has this layout; if not, what differs.
    pub fn same_layout(&self, other: &Accumulators) -> Result<(), MergeError> {
        let shape = |a: &Accumulators| -> StatisticsShape {
            (a.n_times, a.n_means, a.means.len(), a.correlations.iter().map(Vec::len).collect::<Vec<_>>())
        };
        let (mine, theirs) = (shape(self), shape(other));
        if mine != theirs {
            return Err(MergeError::Shape { theirs, mine });
        }
        if self.histograms.len() != other.histograms.len() {
            return Err(MergeError::HistogramCount { theirs: other.histograms.len(), mine: self.histograms.len() });
        }
        for (i, (a, b)) in self.histograms.iter().zip(&other.histograms).enumerate() {
            let (x, y) = ((a.counts().len(), a.low(), a.high()), (b.counts().len(), b.low(), b.high()));
            if x.0 != y.0 || x.1.to_bits() != y.1.to_bits() || x.2.to_bits() != y.2.to_bits() {
                return Err(MergeError::Histogram { index: i, theirs: y, mine: x });
            }
        }
        Ok(())
    }
}

/// A trajectory that did not finish: its index, a short category, the time (a.u.) and details.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    /// Trajectory index.
    pub index: u64,
    /// Category: "sampler", "invalid initial state" (not finite, or not representable by the
    /// system), "ill-conditioned metric", "singular metric", "non-finite", "energy guard", "too many steps", "step size too small",
    /// "not converged", "invalid integrator settings", "output".
    pub reason: String,
    /// When it happened, a.u. (none for the sampler).
    pub time: Option<f64>,
    /// The full message.
    pub detail: String,
}

/// What a block (or the ensemble so far) produced.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// Statistics of the completed trajectories.
    pub statistics: Accumulators,
    /// Trajectories completed (in the statistics).
    pub completed: u64,
    /// Failed trajectories by category.
    pub failed: BTreeMap<String, u64>,
    /// The first [`LISTED_FAILURES`] failures by index.
    pub first_failures: Vec<Failure>,
    /// Trajectories not run or cut short because of an interrupt.
    pub interrupted: u64,
    /// Integrator work of the completed trajectories.
    pub steps: u64,
    /// Right-hand-side evaluations of the completed trajectories.
    pub rhs_evaluations: u64,
    /// Chart switches of the completed trajectories (all zero for a plan that does not switch).
    #[serde(default)]
    pub charts: ChartCounts,
    /// Completed trajectories observed per output time and stopped by `run.stop_outside`
    /// (a trajectory that stops is completed: its outputs up to the stop are in the statistics).
    #[serde(default)]
    pub lifetimes: Lifetimes,
    /// The first [`LISTED_STOPS`] stopped trajectories by index.
    #[serde(default)]
    pub first_stops: Vec<StoppedTrajectory>,
    /// The dipole correlation per pair state (`[pairs]` with the pair estimator).
    #[serde(default)]
    pub pair_states: super::pair_states::ClassCorrelations,
}

impl Outcome {
    /// Nothing yet.
    pub fn new(statistics: Accumulators) -> Self {
        Self {
            statistics,
            completed: 0,
            failed: BTreeMap::new(),
            first_failures: Vec::new(),
            interrupted: 0,
            steps: 0,
            rhs_evaluations: 0,
            charts: ChartCounts::default(),
            lifetimes: Lifetimes::default(),
            first_stops: Vec::new(),
            pair_states: Default::default(),
        }
    }

    /// Merges the outcome of the next block in.
    /// Merges `other` (the trajectories after this one's) in; statistics of another layout are
    /// an error and nothing is merged (see [`Accumulators::merge`]).
    pub fn merge(&mut self, other: &Outcome) -> Result<(), MergeError> {
        self.statistics.merge(&other.statistics)?;
        self.completed += other.completed;
        for (k, v) in &other.failed {
            *self.failed.entry(k.clone()).or_default() += v;
        }
        for f in &other.first_failures {
            if self.first_failures.len() < LISTED_FAILURES {
                self.first_failures.push(f.clone());
            }
        }
        self.interrupted += other.interrupted;
        self.steps += other.steps;
        self.rhs_evaluations += other.rhs_evaluations;
        self.charts.merge(&other.charts);
        self.lifetimes.merge(&other.lifetimes)?;
        let room = LISTED_STOPS.saturating_sub(self.first_stops.len());
        self.first_stops.extend(other.first_stops.iter().take(room).cloned());
        self.pair_states.merge(&other.pair_states);
        Ok(())
    }

    /// Counts a completed trajectory observed at `observed` output times, stopped by `stop` at
    /// the last of them (or run to the end).
    pub(super) fn count_lifetime<M, const N: usize, const NA: usize>(
        &mut self,
        plan: &Plan<'_, M, N, NA>,
        index: u64,
        observed: usize,
        stop: Option<Stop>,
    ) {
        self.lifetimes.add(plan.times.len(), plan.stops.len(), observed, stop.map(|s| (s.condition, s.side)));
        if let Some(s) = stop
            && self.first_stops.len() < LISTED_STOPS
        {
            self.first_stops.push(StoppedTrajectory {
                index,
                time: plan.times[observed - 1],
                condition: s.condition,
                side: s.side,
                value: s.value,
            });
        }
    }

    /// Failed trajectories in all.
    pub fn failed_count(&self) -> u64 {
        self.failed.values().sum()
    }

    pub(super) fn fail(&mut self, f: Failure, progress: &Tally) {
        *self.failed.entry(f.reason.clone()).or_default() += 1;
        if self.first_failures.len() < LISTED_FAILURES {
            self.first_failures.push(f);
        }
        progress.failed();
    }
}

/// The live counts of finished and failed trajectories, shared by the worker threads; the
/// coordinating thread reads them for the progress callback.
#[derive(Debug, Default)]
pub struct Tally {
    /// Trajectories finished (completed, failed or cut short) so far.
    pub done: AtomicU64,
    /// Failures so far.
    pub failures: AtomicU64,
}

impl Tally {
    pub(super) fn done(&self) {
        self.done.fetch_add(1, Ordering::Relaxed);
    }

    fn failed(&self) {
        self.failures.fetch_add(1, Ordering::Relaxed);
    }

    /// A block another process ran: its trajectories and failures.
    pub fn remote_block(&self, o: &Outcome) {
        let failed = o.failed_count();
        self.failures.fetch_add(failed, Ordering::Relaxed);
        self.done.fetch_add(o.completed + failed + o.interrupted, Ordering::Relaxed);
    }

    /// The counts as a [`crate::Progress`] out of `total` trajectories.
    pub fn progress(&self, total: u64) -> crate::Progress {
        crate::Progress {
            done: self.done.load(Ordering::Relaxed),
            total,
            failed: self.failures.load(Ordering::Relaxed),
        }
    }
}

/// Test hook: with `ROVIB_TEST_PANIC_AT=i` in the environment, trajectory `i` panics, so the
/// tests can show that a panicking trajectory ends the run with a clear error, its checkpoint
/// intact, in one process and under MPI. Never set it otherwise.
pub const PANIC_HOOK: &str = "ROVIB_TEST_PANIC_AT";

pub(super) fn panic_hook() -> Option<u64> {
    std::env::var(PANIC_HOOK).ok()?.trim().parse().ok()
}

/// One integrator, created once per block and reused for its trajectories.
// One value per block: its size does not matter, and the workspace stays inline.
#[allow(clippy::large_enum_variant)]
enum Integrator {
    /// The scene's method ([`crate::runtime::integrate::Integrator`]).
    Plain(crate::runtime::integrate::Integrator),
    /// DOP853 with the chart switch.
    Charts(Box<ChartIntegrator>),
}

impl Integrator {
    fn new(method: &Method, dim: usize, atoms: usize, charts: bool) -> Result<Self, InvalidInput> {
        Ok(match method {
            Method::Dop853(o) if charts => Self::Charts(Box::new(ChartIntegrator::new(dim, atoms, *o)?)),
            method => Self::Plain(crate::runtime::integrate::Integrator::new(method, dim)?),
        })
    }

    fn integrate<S: crate::runtime::integrate::OdeSystem, O: Observer>(
        &mut self,
        system: &mut S,
        y0: &[f64],
        t_end: f64,
        interval: f64,
        observer: &mut O,
    ) -> Result<Stats, SolveError<S::Error>> {
        match self {
            Self::Plain(i) => i.integrate(system, 0.0, y0, t_end, interval, observer),
            Self::Charts(_) => Err(SolveError::InvalidInput("the chart integrator runs through `Charts`".into())),
        }
    }
}

fn hamiltonian_reason(e: &HamiltonianError) -> &'static str {
    match e {
        HamiltonianError::IllConditionedMetric { .. } => "ill-conditioned metric",
        HamiltonianError::SingularMetric { .. } => "singular metric",
        HamiltonianError::NonFinite { .. } => "non-finite",
        _ => "right-hand side",
    }
}

fn chart_reason(e: &ChartError) -> &'static str {
    match e {
        ChartError::Internal(h) => hamiltonian_reason(h),
        ChartError::Cartesian(CartesianError::NonFinite { .. }) => "non-finite",
        ChartError::Cartesian(_) => "right-hand side",
        ChartError::Rigid(RigidError::NonFinite { .. }) => "non-finite",
        ChartError::Rigid(_) => "right-hand side",
        ChartError::Switch { .. } => "chart switch",
    }
}

/// A failed solve's category, message and time.
fn solve_reason<E: std::error::Error>(
    e: &SolveError<E>,
    reason: impl Fn(&E) -> &'static str,
) -> (&'static str, String, Option<f64>) {
    let (category, detail) = match e {
        SolveError::Rhs { source, .. } => (reason(source), format!("{e}: {source}")),
        SolveError::NonFinite { .. } => ("non-finite", e.to_string()),
        SolveError::StepSizeTooSmall { .. } => ("step size too small", e.to_string()),
        SolveError::TooManySteps { .. } => ("too many steps", e.to_string()),
        SolveError::NotConverged { .. } => ("not converged", e.to_string()),
        SolveError::InvalidInput(_) => ("invalid integrator settings", e.to_string()),
    };
    (category, detail, e.time())
}

/// Observes one trajectory at the output times into `buffer` (`[time][quantity]`).
pub(super) struct Watch<'a, 'm, M, const N: usize, const NA: usize> {
    pub(super) system: ReducedSystem<'m, M, N, NA>,
    pub(super) plan: &'a Plan<'m, M, N, NA>,
    pub(super) buffer: &'a mut [f64],
    pub(super) needs_potential: bool,
    pub(super) needs_dipole: bool,
    pub(super) k: usize,
    pub(super) initial_energy: f64,
    pub(super) stop: &'a AtomicBool,
    pub(super) failure: Option<(&'static str, f64, String)>,
    pub(super) interrupted: bool,
    pub(super) csv: Option<TrajectoryCsv>,
    /// A kept trajectory's dipole.csv (molecules with a dipole surface).
    pub(super) dipole: Option<crate::output::DipoleCsv>,
    /// The Cartesian chart, for a plan that switches charts.
    pub(super) cartesian: Option<CartesianSystem<'m, M, N, NA>>,
    /// q at the last output (the branch for the closed-form coordinates of a Cartesian state).
    pub(super) last_q: crate::runtime::nalgebra::SVector<f64, N>,
    /// The stop condition met at the last output (`plan.stops`), which ended the trajectory.
    pub(super) stopped: Option<Stop>,
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Observer for Watch<'_, '_, M, N, NA> {
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()> {
        ChartObserver::observe(self, t, ChartState::Internal(y))
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> ChartObserver for Watch<'_, '_, M, N, NA> {
    fn observe(&mut self, t: f64, state: ChartState<'_>) -> ControlFlow<()> {
        if self.stop.load(Ordering::Relaxed) {
            self.interrupted = true;
            return ControlFlow::Break(());
        }
        if self.k >= self.plan.times.len() {
            self.failure =
                Some(("output", t, format!("an output at t = {t} beyond the {} expected", self.plan.times.len())));
            return ControlFlow::Break(());
        }
        // A Cartesian-chart state (near a linear geometry) gives the same quantities through the
        // closed-form q(x), the exact body frame and the Cartesian H (as `rovib run` records it).
        let expanded = match state {
            ChartState::Internal(y) => {
                self.system.expand_body_and_energy(y).map_err(|e| (hamiltonian_reason(&e), e.to_string()))
            }
            ChartState::Cartesian(y) => self.cartesian_body(y),
        };
        let (body, h) = match expanded {
            Ok(x) => x,
            Err((reason, detail)) => {
                self.failure = Some((reason, t, detail));
                return ControlFlow::Break(());
            }
        };
        self.last_q = body.q;
        self.record(t, &body, h)
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Watch<'_, '_, M, N, NA> {
    /// The body state and H of a Cartesian-chart state.
    fn cartesian_body(&self, y: &[f64]) -> Result<(BodyState<N>, f64), (&'static str, String)> {
        let chart =
            self.cartesian.as_ref().ok_or(("chart switch", "a Cartesian state without a Cartesian chart".into()))?;
        let lab = CartesianSystem::<M, N, NA>::lab(y);
        let (body, _) = body_of_lab_exact(self.plan.molecule, &lab, &self.last_q)
            .map_err(|e| ("chart switch", format!("the body frame of a Cartesian state: {e}")))?;
        let h = chart.energy(y).map_err(|e| ("non-finite", e.to_string()))?;
        Ok((body, h))
    }

    /// Records the quantities of output `self.k` (time `t`, a.u.) from the body state and H.
    fn record(&mut self, t: f64, body: &BodyState<N>, h: f64) -> ControlFlow<()> {
        let nq = self.plan.quantities.len();
        if self.k == 0 {
            self.initial_energy = h;
        }
        let h0 = self.initial_energy;
        // The same guard as `rovib run`'s, with the same absolute floor (`output::energy_guard`).
        if let Err(e) = crate::output::energy_guard(h0, h, self.plan.max_energy_error) {
            self.failure = Some(("energy guard", t, e.to_string()));
            return ControlFlow::Break(());
        }
        let u = if self.needs_potential { self.plan.molecule.potential(&body.q) } else { f64::NAN };
        let rotation = body.rotation();
        let mut mu = Vector3::from_element(f64::NAN);
        if self.needs_dipole
            && let Some(dipole) = self.plan.molecule.dipole()
        {
            dipole.moment(&body.q, &mut mu);
            mu = rotation * mu;
        }
        let row = &mut self.buffer[self.k * nq..(self.k + 1) * nq];
        for (v, q) in row.iter_mut().zip(&self.plan.quantities) {
            *v = q.value(body, h, u, &rotation, &mu);
        }
        if let Some(d) = &mut self.dipole
            && let Err(e) = d.row(t / self.plan.time_scale, &mu)
        {
            self.failure = Some(("output", t, e.to_string()));
            return ControlFlow::Break(());
        }
        if let Some(csv) = &mut self.csv {
            let phase = body.to_phase();
            let (euler, pe) = (phase.euler.into(), phase.pe.into());
            if let Err(e) = csv.state_row(
                t / self.plan.time_scale,
                phase.q.as_slice(),
                phase.p.as_slice(),
                euler,
                pe,
                body.j.into(),
                h,
            ) {
                self.failure = Some(("output", t, e.to_string()));
                return ControlFlow::Break(());
            }
        }
        self.k += 1;
        // Checked on q at output times, as `rovib run` does: the output where a coordinate is
        // outside is the trajectory's last.
        if let Some(stop) = self.plan.stop_met(body.q.as_slice()) {
            self.stopped = Some(stop);
            return ControlFlow::Break(());
        }
        ControlFlow::Continue(())
    }
}

/// One trajectory from `state` in the Cartesian chart (`run.chart = "cartesian"`), observed by
/// `watch` through the internal state at each output time.
fn in_cartesian_chart<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    integrator: &mut Integrator,
    plan: &Plan<'_, M, N, NA>,
    state: &BodyState<N>,
    watch: &mut Watch<'_, '_, M, N, NA>,
) -> Result<Stats, (&'static str, String, Option<f64>)> {
    let invalid = |why: String| ("invalid initial state", why, Some(0.0));
    let mut system = CartesianSystem::new(plan.molecule).map_err(|e| invalid(e.to_string()))?;
    let y0 = crate::runtime::charts::to_cartesian(plan.molecule, state)
        .map_err(|e| invalid(format!("the state in the Cartesian chart: {e}")))?;
    integrator
        .integrate(&mut system, &y0, plan.t_end, plan.interval, &mut CartesianWatch(watch))
        .map_err(|e| solve_reason(&e, |e| chart_reason(&ChartError::Cartesian(e.clone()))))
}

/// Hands the states of a Cartesian-chart run to a [`Watch`].
pub(super) struct CartesianWatch<'w, 'a, 'm, M, const N: usize, const NA: usize>(
    pub(super) &'w mut Watch<'a, 'm, M, N, NA>,
);

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Observer for CartesianWatch<'_, '_, '_, M, N, NA> {
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()> {
        ChartObserver::observe(self.0, t, ChartState::Cartesian(y))
    }
}

/// Writes `charts.json` (switches, time in the Cartesian chart in the scene's unit, the chart at
/// the end) of one kept trajectory into `dir`.
fn write_chart_report(dir: &std::path::Path, r: &ChartReport, time_scale: f64) -> Result<(), crate::Error> {
    let mut json = serde_json::json!({
        "switches": r.switches,
        "cartesian_time": r.cartesian_time / time_scale,
        "last_chart": r.last_chart.map(|c| match c {
            crate::runtime::charts::Chart::Internal => "internal",
            crate::runtime::charts::Chart::Cartesian => "cartesian",
            crate::runtime::charts::Chart::Rigid => "rigid",
        }),
    });
    if r.rigid_time > 0.0 {
        json["rigid_time"] = serde_json::json!(r.rigid_time / time_scale);
    }
    let mut f = crate::output::OutputFile::create(dir, "charts.json")?;
    f.line(&json.to_string())?;
    f.flush()
}

/// Folds one completed trajectory's observations at its first `observed` output times (all of
/// them, or up to the one where it stopped) into the accumulators: each output time's means and
/// histograms are over the trajectories observed there, and a trajectory's correlation is that
/// of its own series (`series` and `correlation` are [`Plan::correlation_lags`] long), added
/// at the lags it spans.
pub(super) fn fold<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    acc: &mut Accumulators,
    buffer: &[f64],
    observed: usize,
    workspace: Option<&mut CorrelationWorkspace>,
    series: &mut [f64],
    correlation: &mut [f64],
) {
    let nq = plan.quantities.len();
    let nm = plan.n_means;
    for k in 0..observed {
        for j in 0..nm {
            acc.means[k * nm + j].add(buffer[k * nq + j]);
        }
    }
    let mut h = 0;
    for (qi, _, _, at) in &plan.histograms {
        for &k in at {
            if k < observed {
                acc.histograms[h].add(buffer[k * nq + qi]);
            }
            h += 1;
        }
    }
    let span = observed.min(series.len());
    if let Some(ws) = workspace
        && span > 0
    {
        let (series, correlation) = (&mut series[..span], &mut correlation[..span]);
        for (ci, &qi) in plan.correlations.iter().enumerate() {
            for (k, s) in series.iter_mut().enumerate() {
                *s = buffer[k * nq + qi];
            }
            // The dipole's correlations feed the spectrum: tapered (see `runtime::spectrum`).
            if plan.quantities[qi].needs_dipole() {
                ws.tapered_autocorrelation(series, correlation);
            } else {
                ws.fluctuation_autocorrelation(series, correlation);
            }
            for (m, &c) in acc.correlations[ci].iter_mut().zip(correlation.iter()) {
                m.add(c);
            }
        }
    }
}
