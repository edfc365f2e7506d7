//! A block of an ensemble on SIMD lanes: the block's trajectories run [`LANES`] at a time through
//! the batched DOP853 ([`Dop853Lanes`]) and the lane-generic production right-hand side
//! ([`ProductionLanes`]), each lane taking the next trajectory as soon as its own ends.
//!
//! Every lane computes its trajectory as the one-trajectory path does, with the same steps, to
//! round-off: the arithmetic is the same IEEE operations in the same order, but the lanes'
//! `sin_cos` and `exp` are vector polynomials within 2 ulp of libm's
//! ([`crate::runtime::transcendental`]), which is what makes wide vectors pay (BENCHMARKS.md,
//! "Many trajectories per core"). Lanes of every width compute the same bits, so a block's
//! outcome does not depend on the build's vector width. The observations are kept per
//! trajectory and folded into the accumulators in index order at the end of the block, so the
//! outcome is the scalar [`super::run_block`]'s to round-off (`tests/ensembles/ensemble.rs`
//! compares the two block outcomes). A trajectory whose lane fails is run again by the scalar
//! path, which reports its failure with the full error.
//!
//! The lane width is the build's: [`Lanes`] is [`runtime::lanes::F64x8`](crate::runtime::lanes::F64x8)
//! when the build has AVX-512 (`RUSTFLAGS="-C target-cpu=native"` on such a CPU), `F64x4` with
//! AVX2, else `F64x2` (one SSE2 register: the default, baseline x86-64 build).
//!
//! Used by [`super::run_block`] when the plan asks for lanes and the run allows them:
//! DOP853, no frozen coordinate, no kept trajectory files.
//!
//! With the pair estimator ([`super::pair`]) each trajectory is two lane jobs: the forward run
//! of the sampled state and, in the next free lane, the forward run of its time-reversed state
//! (the backward run). When both have ended, the two buffers are folded as the scalar path folds
//! them (`runner::fold`, `pair::fold_pair`, `pair_states::fold`), in index order.

use std::ops::{ControlFlow, Range};
use std::sync::atomic::{AtomicBool, Ordering};

use super::runner::{Accumulators, CartesianWatch, Failure, Outcome, Plan, Stop, Tally, Watch, fold, run_block_scalar};
use crate::runtime::Molecule;
use crate::runtime::cartesian_system::CartesianSystem;
use crate::runtime::hamiltonian::BodyState;
use crate::runtime::hamiltonian::fast::ReducedSystem;
use crate::runtime::hamiltonian::lanes::ProductionLanes;
use crate::runtime::integrate::{Dop853Lanes, LaneFailure, LaneFeeder, Method, Stats};
#[cfg(not(target_feature = "avx2"))]
use crate::runtime::lanes::F64x2;
#[cfg(all(target_feature = "avx2", not(target_feature = "avx512f")))]
use crate::runtime::lanes::F64x4;
#[cfg(target_feature = "avx512f")]
use crate::runtime::lanes::F64x8;
use crate::runtime::lanes::Real;
use crate::runtime::sample::Sampler;

/// The lane type of ensembles on a build without AVX2 (the default, baseline x86-64 with SSE2):
/// two `f64` lanes, one 128-bit register (1.48× the one-trajectory throughput for water, against
/// 1.37× with four lanes in two registers; docs/src/history/benchmarks.md, "Many trajectories per core (SIMD lanes)").
#[cfg(not(target_feature = "avx2"))]
pub type Lanes = F64x2;
/// The lane type of ensembles on an AVX2 build without AVX-512: four `f64` lanes, one 256-bit
/// register.
#[cfg(all(target_feature = "avx2", not(target_feature = "avx512f")))]
pub type Lanes = F64x4;
/// The lane type of ensembles on an AVX-512 build: eight `f64` lanes, one 512-bit register
/// (BENCHMARKS.md, the figures: the lanes' gain at each width).
#[cfg(target_feature = "avx512f")]
pub type Lanes = F64x8;
/// Trajectories per vector.
pub const LANES: usize = <Lanes as Real>::LANES;

/// Whether `plan` can run on lanes: lanes asked for, DOP853, nothing reduced, no kept
/// trajectories, and a molecule with exact lane forms (not a large molecule whose kinetic
/// matrix is completed at run time, see [`crate::runtime::hamiltonian::lanes::available`]).
pub fn applies<M: Molecule<N, NA>, const N: usize, const NA: usize>(plan: &Plan<'_, M, N, NA>) -> bool {
    plan.lanes
        && if plan.in_cartesian_chart() {
            crate::runtime::cartesian_lanes::available(plan.molecule)
        } else {
            crate::runtime::hamiltonian::lanes::available(plan.molecule)
        }
        && matches!(plan.method, Method::Dop853(_))
        && plan.reduction.active.iter().all(|&a| a)
        && plan.reduction.rotation == crate::runtime::hamiltonian::fast::RotationPart::Free
        && plan.keep.is_none()
}

/// What became of one trajectory of the block.
enum Fate {
    /// Completed: its observations, the outputs observed (all, or up to a stop condition met),
    /// the stop condition and its statistics.
    Completed(Vec<f64>, usize, Option<Stop>, Stats),
    /// Failed before integration (sampler, initial state).
    Failed(Failure),
    /// Stopped by the stop flag (or never started).
    Interrupted,
    /// To be run again by the scalar path (its lane failed, or its observer reported a failure).
    Redo,
}

/// One lane's running trajectory.
struct Slot<'m, M, const N: usize, const NA: usize> {
    index: u64,
    /// The backward run of the pair estimator (the reversed state's forward run).
    backward: bool,
    system: ReducedSystem<'m, M, N, NA>,
    buffer: Vec<f64>,
    k: usize,
    initial_energy: f64,
    failure: Option<(&'static str, f64, String)>,
    interrupted: bool,
    stopped: Option<Stop>,
    /// q at the last output (the branch of the closed-form q of a Cartesian-chart state).
    last_q: crate::runtime::nalgebra::SVector<f64, N>,
}

struct Feeder<'a, 'm, M, const N: usize, const NA: usize> {
    plan: &'a Plan<'m, M, N, NA>,
    sampler: &'a dyn Sampler<N>,
    next: u64,
    end: u64,
    stop: &'a AtomicBool,
    needs_potential: bool,
    needs_dipole: bool,
    slots: Vec<Option<Slot<'m, M, N, NA>>>,
    results: Vec<Option<Fate>>,
    /// The pair estimator: whether each trajectory also runs backward, the backward runs'
    /// fates, the sampled states (for the pair-state classes), and the backward run next due.
    pair: bool,
    backward: Vec<Option<Fate>>,
    drawn: Vec<Option<BodyState<N>>>,
    pending: Option<(u64, BodyState<N>)>,
    first: u64,
    /// [`super::runner::PANIC_HOOK`], as the scalar path honours it.
    panic_at: Option<u64>,
    /// The Cartesian chart, when the trajectories run in it (`run.chart`).
    cartesian: Option<CartesianSystem<'m, M, N, NA>>,
}

impl<'m, M: Molecule<N, NA>, const N: usize, const NA: usize> Feeder<'_, 'm, M, N, NA> {
    fn set(&mut self, index: u64, r: Fate) {
        self.results[(index - self.first) as usize] = Some(r);
    }

    fn set_backward(&mut self, index: u64, r: Fate) {
        self.backward[(index - self.first) as usize] = Some(r);
    }

    fn slot(&self, index: u64, backward: bool, system: ReducedSystem<'m, M, N, NA>, q: &[f64]) -> Slot<'m, M, N, NA> {
        Slot {
            last_q: crate::runtime::nalgebra::SVector::from_column_slice(q),
            index,
            backward,
            system,
            buffer: vec![0.0; self.plan.times.len() * self.plan.quantities.len()],
            k: 0,
            initial_energy: 0.0,
            failure: None,
            interrupted: false,
            stopped: None,
        }
    }

    /// A lane's start: the internal flat state, or in the Cartesian chart (`run.chart`) the
    /// positions and velocities.
    fn lane_start(
        &self,
        system: &ReducedSystem<'m, M, N, NA>,
        state: &BodyState<N>,
        y0: &mut [f64],
    ) -> Result<(), String> {
        if !self.plan.in_cartesian_chart() {
            return system.reduce_body(state, y0).map_err(|e| e.to_string());
        }
        let y = crate::runtime::charts::to_cartesian(self.plan.molecule, state)
            .map_err(|e| format!("the state in the Cartesian chart: {e}"))?;
        y0.copy_from_slice(&y);
        Ok(())
    }

    /// Starts the backward run of `index` from the reversed `drawn` in `lane`, if it can start:
    /// under the stop flag it is interrupted, and a state the lanes cannot take is left to the
    /// scalar path.
    fn start_backward(&mut self, lane: usize, index: u64, drawn: &BodyState<N>, y0: &mut [f64]) -> bool {
        if self.stop.load(Ordering::Relaxed) {
            self.set_backward(index, Fate::Interrupted);
            return false;
        }
        let state = super::pair::reversed(drawn);
        let system = ReducedSystem::from_body(self.plan.molecule, self.plan.reduction, &state)
            .with_min_pivot(self.plan.min_pivot);
        if self.lane_start(&system, &state, y0).is_err() {
            self.set_backward(index, Fate::Redo);
            return false;
        }
        self.slots[lane] = Some(self.slot(index, true, system, state.q.as_slice()));
        true
    }
}

impl<'m, M: Molecule<N, NA>, const N: usize, const NA: usize> LaneFeeder for Feeder<'_, 'm, M, N, NA> {
    fn next(&mut self, lane: usize, y0: &mut [f64]) -> bool {
        loop {
            if let Some((index, drawn)) = self.pending.take()
                && self.start_backward(lane, index, &drawn, y0)
            {
                return true;
            }
            if self.next >= self.end {
                return false;
            }
            let index = self.next;
            self.next += 1;
            if self.stop.load(Ordering::Relaxed) {
                self.set(index, Fate::Interrupted);
                continue;
            }
            if self.panic_at == Some(index) {
                panic!("{}={index}: a deliberate panic (test hook)", super::runner::PANIC_HOOK);
            }
            let failure = |reason: &str, time: Option<f64>, detail: String| Failure {
                index,
                reason: reason.into(),
                time,
                detail,
            };
            let state = match self.sampler.draw(index) {
                Ok(s) => s,
                Err(e) => {
                    self.set(index, Fate::Failed(failure("sampler", None, e.to_string())));
                    continue;
                }
            };
            let finite = state.q.iter().chain(state.p.iter()).chain(state.j.iter()).all(|v| v.is_finite())
                && state.orientation.coords.iter().all(|v| v.is_finite());
            if !finite {
                let detail = format!("the drawn state is not finite: {state:?}");
                self.set(index, Fate::Failed(failure("invalid initial state", Some(0.0), detail)));
                continue;
            }
            let system = ReducedSystem::from_body(self.plan.molecule, self.plan.reduction, &state)
                .with_min_pivot(self.plan.min_pivot);
            if let Err(e) = self.lane_start(&system, &state, y0) {
                self.set(index, Fate::Failed(failure("invalid initial state", Some(0.0), e)));
                continue;
            }
            if self.pair {
                self.drawn[(index - self.first) as usize] = Some(state);
                self.pending = Some((index, state));
            }
            self.slots[lane] = Some(self.slot(index, false, system, state.q.as_slice()));
            return true;
        }
    }

    fn observe(&mut self, lane: usize, t: f64, y: &[f64]) -> ControlFlow<()> {
        let Some(slot) = self.slots[lane].as_mut() else { return ControlFlow::Break(()) };
        let mut watch = Watch {
            system: slot.system,
            plan: self.plan,
            buffer: &mut slot.buffer,
            needs_potential: self.needs_potential,
            needs_dipole: self.needs_dipole,
            k: slot.k,
            initial_energy: slot.initial_energy,
            stop: self.stop,
            failure: None,
            interrupted: false,
            csv: None,
            dipole: None,
            // Lent to the observer for this output, and taken back below.
            cartesian: self.cartesian.take(),
            last_q: slot.last_q,
            stopped: None,
        };
        let flow = match watch.cartesian {
            Some(_) => crate::runtime::integrate::Observer::observe(&mut CartesianWatch(&mut watch), t, y),
            None => crate::runtime::integrate::Observer::observe(&mut watch, t, y),
        };
        (slot.k, slot.initial_energy, slot.interrupted) = (watch.k, watch.initial_energy, watch.interrupted);
        slot.last_q = watch.last_q;
        self.cartesian = watch.cartesian.take();
        slot.stopped = watch.stopped;
        slot.failure = watch.failure.take();
        flow
    }

    fn finish(&mut self, lane: usize, result: Result<Stats, LaneFailure>) {
        let Some(slot) = self.slots[lane].take() else { return };
        let n_times = self.plan.times.len();
        let r = match (result, slot.failure) {
            (Ok(_), None) if slot.interrupted => Fate::Interrupted,
            // A stop condition ends the lane's trajectory as `Break` does, successfully.
            (Ok(stats), None) if slot.k == n_times || slot.stopped.is_some() => {
                Fate::Completed(slot.buffer, slot.k, slot.stopped, stats)
            }
            // A failed lane, an observer's failure or a short run: the scalar path reports it.
            _ => Fate::Redo,
        };
        if slot.backward { self.set_backward(slot.index, r) } else { self.set(slot.index, r) }
    }
}

/// [`super::run_block`] on lanes (see the module docs); `plan` must satisfy [`applies`].
pub fn run_block_lanes<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    sampler: &dyn Sampler<N>,
    indices: Range<u64>,
    stop: &AtomicBool,
    progress: &Tally,
) -> Outcome
where
    M: Molecule<N, NA> + Sync,
{
    let Method::Dop853(options) = plan.method else { return run_block_scalar(plan, sampler, indices, stop, progress) };
    let dim = if plan.in_cartesian_chart() { 6 * NA } else { plan.reduction.dim() };
    let mut solver = match Dop853Lanes::<Lanes>::new(dim, options) {
        Ok(s) => s,
        Err(_) => return run_block_scalar(plan, sampler, indices, stop, progress),
    };
    let count = (indices.end - indices.start) as usize;
    let mut feeder = Feeder {
        plan,
        sampler,
        next: indices.start,
        end: indices.end,
        stop,
        needs_potential: plan.quantities.iter().any(super::quantity::Quantity::needs_potential),
        needs_dipole: plan.quantities.iter().any(super::quantity::Quantity::needs_dipole),
        slots: (0..LANES).map(|_| None).collect(),
        results: (0..count).map(|_| None).collect(),
        pair: plan.spectrum.pair(),
        backward: (0..count).map(|_| None).collect(),
        drawn: vec![None; count],
        pending: None,
        first: indices.start,
        panic_at: super::runner::panic_hook(),
        cartesian: if plan.in_cartesian_chart() { CartesianSystem::new(plan.molecule).ok() } else { None },
    };
    // A plan that switches charts: a lane stops where the scalar path would switch (its internal
    // chart's pivot threshold), and the scalar path runs that trajectory again with the switch,
    // so that trajectory is the scalar path's.
    let switching = plan.switches_charts();
    let min_pivot = if switching { plan.min_pivot.max(crate::runtime::charts::SWITCH_PIVOT) } else { plan.min_pivot };
    let run = if plan.in_cartesian_chart() {
        match crate::runtime::cartesian_lanes::CartesianLanes::new(plan.molecule) {
            Ok(mut system) => solver.integrate(&mut system, 0.0, plan.t_end, plan.interval, &mut feeder),
            Err(_) => return run_block_scalar(plan, sampler, indices, stop, progress),
        }
    } else {
        let mut system = ProductionLanes::new(plan.molecule, min_pivot);
        solver.integrate(&mut system, 0.0, plan.t_end, plan.interval, &mut feeder)
    };
    if run.is_err() {
        return run_block_scalar(plan, sampler, indices, stop, progress);
    }

    // In index order, as the scalar path folds them.
    let mut outcome = Outcome::new(Accumulators::new(plan));
    let lags = plan.correlation_lags();
    let mut workspace =
        (!plan.correlations.is_empty()).then(|| crate::runtime::ensemble::CorrelationWorkspace::new(lags));
    let mut series = vec![0.0; lags];
    let mut correlation = vec![0.0; lags];
    let pair = feeder.pair;
    let runs = feeder.results.into_iter().zip(feeder.backward).zip(feeder.drawn);
    for (offset, ((result, backward), drawn)) in runs.enumerate() {
        let index = indices.start + offset as u64;
        let result = result.unwrap_or(Fate::Interrupted);
        if pair {
            // Both runs of the pair estimator, combined as the scalar path combines them.
            match (result, backward.unwrap_or(Fate::Interrupted), drawn) {
                (
                    Fate::Completed(forward, kf, stop, stats),
                    Fate::Completed(backward, kb, _, back_stats),
                    Some(drawn),
                ) => {
                    outcome.completed += 1;
                    outcome.steps += stats.steps + back_stats.steps;
                    outcome.rhs_evaluations += stats.rhs_evals + back_stats.rhs_evals;
                    if switching {
                        outcome.charts.add(index, &crate::runtime::charts::ChartReport::default());
                    }
                    outcome.count_lifetime(plan, index, kf, stop);
                    fold(plan, &mut outcome.statistics, &forward, kf, None, &mut series, &mut correlation);
                    super::pair::fold_pair(plan, &mut outcome.statistics, &forward, kf, &backward, kb);
                    let classes = &mut outcome.pair_states;
                    super::pair_states::fold(plan, &drawn, classes, &forward, kf, &backward, kb);
                    progress.done();
                }
                (Fate::Failed(f), _, _) => {
                    outcome.fail(f, progress);
                    progress.done();
                }
                (Fate::Interrupted, _, _) | (Fate::Completed(..), Fate::Interrupted, _) => outcome.interrupted += 1,
                // A failed run of either direction: the scalar path runs both and reports it.
                _ => outcome
                    .merge(&run_block_scalar(plan, sampler, index..index + 1, stop, progress))
                    .expect("accumulators of one plan have one layout"),
            }
            continue;
        }
        match result {
            Fate::Completed(buffer, observed, stop, stats) => {
                outcome.completed += 1;
                outcome.steps += stats.steps;
                outcome.rhs_evaluations += stats.rhs_evals;
                if switching {
                    // Never below the switch threshold: no switch, as the scalar path counts it.
                    outcome.charts.add(index, &crate::runtime::charts::ChartReport::default());
                }
                outcome.count_lifetime(plan, index, observed, stop);
                fold(
                    plan,
                    &mut outcome.statistics,
                    &buffer,
                    observed,
                    workspace.as_mut(),
                    &mut series,
                    &mut correlation,
                );
                progress.done();
            }
            Fate::Failed(f) => {
                outcome.fail(f, progress);
                progress.done();
            }
            Fate::Interrupted => outcome.interrupted += 1,
            // Both are of this plan, so of one layout.
            Fate::Redo => outcome
                .merge(&run_block_scalar(plan, sampler, index..index + 1, stop, progress))
                .expect("accumulators of one plan have one layout"),
        }
    }
    outcome
}
