//! Two charts of phase space and the switch between them: internal coordinates with the
//! orientation ([`ReducedSystem`], fast, singular at linear geometries) and lab-frame Cartesian
//! positions and velocities ([`CartesianSystem`], never singular).
//!
//! A run integrates in the internal chart while its kinetic metric is well conditioned. When
//! an evaluation finds a relative pivot below [`SWITCH_PIVOT`], the integrator stops at its last
//! accepted state, which is converted exactly (`x = R R(q)`, `v = R (ω × R + ∂R/∂q q̇)`) to the
//! Cartesian chart, and DOP853 continues there from the same time, on the same output grid.
//! While in the Cartesian chart every evaluation checks the internal chart at the current
//! positions; when all its relative pivots exceed [`RETURN_PIVOT`] (ten times the switch
//! threshold, so the run does not chatter between charts), the last accepted Cartesian state is
//! converted back (closed-form `q(x)`, Kabsch orientation, `J = Σ m R × u`,
//! `p = Σ m ∂R/∂q · u`) and the run continues in the internal chart. The conversions are exact
//! up to rounding in both directions, so the trajectory is that of one Hamiltonian; only the
//! integrator's step history restarts at a switch (docs/src/reference/equations.md, "Chart switch").
//!
//! A molecule without a Cartesian potential that is a complex of rigid linear fragments and
//! single atoms ([`RigidLayout::detect`](crate::rigid_system::RigidLayout::detect)) switches
//! the same way to the lab-frame rigid chart
//! ([`RigidSystem`]: each fragment's centre of mass, momentum, axis and angular momentum, each
//! atom's position and momentum), with the same thresholds; the conversion back fits `q` and the
//! orientation to the positions (Kabsch, then Gauss–Newton from the last `q`) and projects the
//! velocities as above. While a run is in the rigid chart its outputs are handed to the observer
//! as internal-chart states (the same conversion), so observers need no third kind of state.
//!
//! Only DOP853 switches (an adaptive method can restart at any time); frozen coordinates have
//! no Cartesian counterpart, so a reduction with frozen coordinates does not switch (the run
//! stops at the singular geometry as before).

use core::ops::ControlFlow;

use crate::cartesian_system::{CartesianError, CartesianSystem};
use crate::frames::{CentreOfMass, body_of_lab_exact, lab_of_body_any};
use crate::hamiltonian::BodyState;
use crate::hamiltonian::{HamiltonianError, ReducedSystem, RotationPart};
use crate::integrate::{Dop853, Dop853Options, Dop853Resume, InvalidInput, OdeSystem, SolveError, Stats};
use crate::molecule::Molecule;
use crate::rigid_system::{RigidError, RigidSystem};
use nalgebra::{SVector, Vector3};

/// The relative pivot of the kinetic metric below which the run leaves the internal chart.
pub const SWITCH_PIVOT: f64 = 1e-4;

/// The relative pivot above which the run returns to the internal chart.
pub const RETURN_PIVOT: f64 = 1e-3;

/// Which chart a state is in.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Chart {
    /// Internal coordinates and orientation: a [`ReducedSystem`] flat state.
    Internal,
    /// Lab-frame Cartesian positions and velocities about the centre of mass: a
    /// [`CartesianSystem`] flat state.
    Cartesian,
    /// Lab-frame rigid fragments and atoms: a [`RigidSystem`] flat state (outputs are handed on
    /// as [`ChartState::Internal`]).
    Rigid,
}

/// A state handed to a [`ChartObserver`], in the chart it is in.
#[derive(Copy, Clone, Debug)]
pub enum ChartState<'y> {
    /// A [`ReducedSystem`] flat state.
    Internal(&'y [f64]),
    /// A [`CartesianSystem`] flat state.
    Cartesian(&'y [f64]),
}

/// Receives the solution at the output times, in whichever chart it is.
pub trait ChartObserver {
    /// As [`crate::integrate::Observer::observe`].
    fn observe(&mut self, t: f64, state: ChartState<'_>) -> ControlFlow<()>;
}

/// Why a run with chart switching stopped.
#[derive(Debug, thiserror::Error)]
pub enum ChartError {
    /// In the internal chart.
    #[error(transparent)]
    Internal(#[from] HamiltonianError),
    /// In the Cartesian chart.
    #[error(transparent)]
    Cartesian(#[from] CartesianError),
    /// In the rigid chart.
    #[error(transparent)]
    Rigid(#[from] RigidError),
    /// A state could not be converted between the charts.
    #[error("switching from the {from:?} chart to the other at t = {t}: {reason}")]
    Switch {
        /// The chart the run was in.
        from: Chart,
        /// When.
        t: f64,
        /// Why the conversion failed.
        reason: String,
    },
}

/// What a run with chart switching did.
#[derive(Clone, Debug, Default)]
pub struct ChartReport {
    /// The work of all segments.
    pub stats: Stats,
    /// Chart switches (each way counts one).
    pub switches: u64,
    /// Time spent in the Cartesian chart, a.u.
    pub cartesian_time: f64,
    /// Time spent in the rigid chart, a.u.
    pub rigid_time: f64,
    /// Where the run stood at its end, for `rovib run --resume`, if it ended in the internal
    /// chart (a continuation then repeats the internal segment's steps).
    pub resume: Option<Dop853Resume>,
    /// The chart of the last state.
    pub last_chart: Option<Chart>,
}

fn add(total: &mut Stats, s: &Stats) {
    total.steps += s.steps;
    total.accepted += s.accepted;
    total.rejected += s.rejected;
    total.rhs_evals += s.rhs_evals;
}

/// An internal-chart system that reports a singular or ill-conditioned metric as a switch.
fn is_switch(e: &HamiltonianError) -> bool {
    matches!(e, HamiltonianError::IllConditionedMetric { .. } | HamiltonianError::SingularMetric { .. })
}

/// Whether a reduction can switch: every coordinate active (the Cartesian and rigid charts
/// have no constraints) and a Cartesian potential or a rigid layout ([`RigidSystem::new`]).
pub fn can_switch<M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize>(
    system: &ReducedSystem<'_, M, N, NA>,
) -> bool {
    system.reduction().active.iter().all(|&a| a)
        && (CartesianSystem::new(system.molecule()).is_ok() || RigidSystem::new(system.molecule()).is_some())
}

/// The internal flat state of `system` for a body state, with `J` set to exactly zero for a
/// system that integrates `J = 0`.
fn reduce<M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize>(
    system: &ReducedSystem<'_, M, N, NA>,
    mut body: BodyState<N>,
    out: &mut [f64],
) -> Result<(), String> {
    if system.reduction().rotation != RotationPart::Free {
        body.j = Vector3::zeros();
    }
    system.reduce_body(&body, out).map_err(|e| e.to_string())
}

/// The Cartesian flat state of a body-formulation state (centre of mass at rest at the origin;
/// also at a singular geometry, through the metric's pseudo-inverse).
pub fn to_cartesian<M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize>(
    m: &M,
    body: &BodyState<N>,
) -> Result<Vec<f64>, String> {
    let lab = lab_of_body_any(m, body, &CentreOfMass::default()).map_err(|e| e.to_string())?;
    let mut y = vec![0.0; 6 * NA];
    CartesianSystem::<M, N, NA>::flat(&lab, &mut y);
    Ok(y)
}

/// The body-formulation state of a Cartesian flat state (closed-form q nearest `near`), with
/// `J` set to exactly zero for a system that integrates `J = 0` (the Cartesian chart conserves
/// `J = 0` to rounding); and the internal flat state of `system`.
pub fn to_internal<M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize>(
    system: &ReducedSystem<'_, M, N, NA>,
    y: &[f64],
    near: &SVector<f64, N>,
) -> Result<(BodyState<N>, Vec<f64>), String> {
    let lab = CartesianSystem::<M, N, NA>::lab(y);
    let (mut body, _) = body_of_lab_exact(system.molecule(), &lab, near).map_err(|e| e.to_string())?;
    if system.reduction().rotation != RotationPart::Free {
        body.j = Vector3::zeros();
    }
    let mut out = vec![0.0; system.dim()];
    system.reduce_body(&body, &mut out).map_err(|e| e.to_string())?;
    Ok((body, out))
}

/// Where a run with chart switching starts.
pub enum ChartStart<'s, const N: usize> {
    /// Fresh at the grid origin `t0`, from this body state (in the internal chart if it is
    /// regular there, else in the Cartesian chart).
    Fresh(&'s BodyState<N>),
    /// Fresh at the grid origin `t0` in the Cartesian chart, from this [`CartesianSystem`] flat
    /// state (a start at a singular geometry given by positions and velocities: taken as it is).
    FreshCartesian(&'s [f64]),
    /// Continuing an internal-chart DOP853 run.
    Resume(&'s Dop853Resume),
}

/// The next segment's start.
enum Next {
    /// A fresh internal-chart run at `t0` (observes `t0`).
    Fresh(Vec<f64>),
    /// A continuation point in the chart of the segment.
    Point(Dop853Resume),
}

/// Counts the outputs served and hands them on in the segment's chart.
struct Served<'o, O: ?Sized> {
    observer: &'o mut O,
    served: &'o mut Option<u64>,
    chart: Chart,
}

impl<O: ChartObserver + ?Sized> crate::integrate::Observer for Served<'_, O> {
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()> {
        *self.served = Some(self.served.map_or(0, |s| s + 1));
        let state = match self.chart {
            Chart::Internal => ChartState::Internal(y),
            Chart::Cartesian | Chart::Rigid => ChartState::Cartesian(y),
        };
        self.observer.observe(t, state)
    }
}

/// `e` with its system error mapped into a [`ChartError`].
pub fn map_error<E>(e: SolveError<E>, f: impl FnOnce(E) -> ChartError) -> SolveError<ChartError> {
    match e {
        SolveError::Rhs { t, y, source } => SolveError::Rhs { t, y, source: f(source) },
        SolveError::NonFinite { t, y } => SolveError::NonFinite { t, y },
        SolveError::StepSizeTooSmall { t, h, y } => SolveError::StepSizeTooSmall { t, h, y },
        SolveError::TooManySteps { t, max_steps, y } => SolveError::TooManySteps { t, max_steps, y },
        SolveError::NotConverged { t, y } => SolveError::NotConverged { t, y },
        SolveError::InvalidInput(s) => SolveError::InvalidInput(s),
    }
}

/// Integrates from `start` to `t_end` with DOP853, outputs at `t0 + k·interval` (the grid of
/// [`crate::integrate::solve`]), switching charts as the module documentation describes.
/// `system` must be able to switch ([`can_switch`]); its `min_pivot` is replaced by
/// [`SWITCH_PIVOT`]. `report` collects the work of every segment, also when the run fails (so
/// that a failed run still reports its evaluations).
#[allow(clippy::too_many_arguments)]
pub fn integrate<M, O, const N: usize, const NA: usize>(
    system: &ReducedSystem<'_, M, N, NA>,
    options: Dop853Options,
    t0: f64,
    start: ChartStart<'_, N>,
    t_end: f64,
    interval: f64,
    observer: &mut O,
    report: &mut ChartReport,
) -> Result<(), SolveError<ChartError>>
where
    M: Molecule<N, NA> + ?Sized,
    O: ChartObserver + ?Sized,
{
    ChartIntegrator::new(system.dim(), NA, options)?.integrate(system, t0, start, t_end, interval, observer, report)
}

/// The DOP853 integrators of a run with chart switching (one per chart; the rigid chart's made
/// at its first use), made once and reused for many runs (an ensemble's trajectories), so that
/// a run allocates nothing but the states it hands over at a switch.
pub struct ChartIntegrator {
    internal: Dop853,
    cartesian: Dop853,
    rigid: Option<Dop853>,
}

impl ChartIntegrator {
    /// For systems of `internal_dim` internal-chart components and `atoms` atoms.
    pub fn new(internal_dim: usize, atoms: usize, options: Dop853Options) -> Result<Self, InvalidInput> {
        Ok(Self {
            internal: Dop853::new(internal_dim, options)?,
            cartesian: Dop853::new(6 * atoms, options)?,
            rigid: None,
        })
    }

    /// [`integrate`] with these integrators (`system.dim()` and the atom count as made).
    #[allow(clippy::too_many_arguments)]
    pub fn integrate<M, O, const N: usize, const NA: usize>(
        &mut self,
        system: &ReducedSystem<'_, M, N, NA>,
        t0: f64,
        start: ChartStart<'_, N>,
        t_end: f64,
        interval: f64,
        observer: &mut O,
        report: &mut ChartReport,
    ) -> Result<(), SolveError<ChartError>>
    where
        M: Molecule<N, NA> + ?Sized,
        O: ChartObserver + ?Sized,
    {
        if self.internal.dim() != system.dim() || self.cartesian.dim() != 6 * NA {
            return Err(SolveError::InvalidInput(format!(
                "chart integrators made for {} and {} components, the system has {} and {}",
                self.internal.dim(),
                self.cartesian.dim(),
                system.dim(),
                6 * NA
            )));
        }
        let dops = Integrators { internal: &mut self.internal, cartesian: &mut self.cartesian, rigid: &mut self.rigid };
        run(dops, system, t0, start, t_end, interval, observer, report)
    }
}

/// The integrators of [`run`].
struct Integrators<'d> {
    internal: &'d mut Dop853,
    cartesian: &'d mut Dop853,
    rigid: &'d mut Option<Dop853>,
}

/// Serves the outputs of a rigid-chart segment as internal-chart states of `internal`.
struct RigidServed<'o, 'm, O: ?Sized, M: ?Sized, const N: usize, const NA: usize> {
    observer: &'o mut O,
    served: &'o mut Option<u64>,
    /// A copy of the segment's system for the conversions (its position fit has its own start).
    rigid: RigidSystem<'m, M, N, NA>,
    internal: &'o ReducedSystem<'m, M, N, NA>,
    buffer: &'o mut [f64],
    /// An output that could not be converted: when and why.
    failure: Option<(f64, String)>,
}

impl<O, M, const N: usize, const NA: usize> crate::integrate::Observer for RigidServed<'_, '_, O, M, N, NA>
where
    O: ChartObserver + ?Sized,
    M: Molecule<N, NA> + ?Sized,
{
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()> {
        *self.served = Some(self.served.map_or(0, |s| s + 1));
        let converted =
            self.rigid.body_of_flat(y).map_err(|e| e.to_string()).and_then(|b| reduce(self.internal, b, self.buffer));
        match converted {
            Ok(()) => self.observer.observe(t, ChartState::Internal(self.buffer)),
            Err(reason) => {
                self.failure = Some((t, reason));
                ControlFlow::Break(())
            }
        }
    }
}

/// The run of [`ChartIntegrator::integrate`]: a first segment in the chart the start is regular
/// in, then segment after segment, each ending at a switch of chart or at the run's end.
#[allow(clippy::too_many_arguments)]
fn run<M, O, const N: usize, const NA: usize>(
    dops: Integrators<'_>,
    system: &ReducedSystem<'_, M, N, NA>,
    t0: f64,
    start: ChartStart<'_, N>,
    t_end: f64,
    interval: f64,
    observer: &mut O,
    report: &mut ChartReport,
) -> Result<(), SolveError<ChartError>>
where
    M: Molecule<N, NA> + ?Sized,
    O: ChartObserver + ?Sized,
{
    let Integrators { internal: dop_i, cartesian: dop_c, rigid: dop_r } = dops;
    let mut run = Switching::new(system, t0, t_end, interval)?;
    let Some((mut chart, mut next)) = run.first_segment(start, observer, report)? else { return Ok(()) };
    loop {
        report.last_chart = Some(chart);
        let after = match chart {
            Chart::Internal => run.internal_segment(dop_i, &next, observer, report)?,
            Chart::Cartesian => run.cartesian_segment(dop_c, &next, observer, report)?,
            Chart::Rigid => run.rigid_segment(dop_r, *dop_i.options(), &next, observer, report)?,
        };
        match after {
            None => return Ok(()),
            Some((c, n)) => (chart, next) = (c, n),
        }
    }
}

/// A run with chart switching ([`run`]): the systems of the charts, the run's times, and what
/// carries over from segment to segment.
struct Switching<'m, M: ?Sized, const N: usize, const NA: usize> {
    /// The internal chart, with the switch threshold as its smallest pivot.
    internal: ReducedSystem<'m, M, N, NA>,
    /// The Cartesian chart, where the molecule has one.
    cartesian: Option<CartesianSystem<'m, M, N, NA>>,
    /// The rigid chart, where the molecule has no Cartesian one.
    rigid: Option<RigidSystem<'m, M, N, NA>>,
    /// Which of the two it has: the chart near singular geometries of the internal one.
    fallback: Chart,
    t0: f64,
    t_end: f64,
    interval: f64,
    /// An internal-chart state: the rigid chart's start converted.
    buffer: Vec<f64>,
    /// The number of the last output served (`None` before the one at `t0`).
    served: Option<u64>,
    /// The last internal configuration known, where a conversion to the internal chart starts.
    last_q: SVector<f64, N>,
    /// When the run last entered the fallback chart.
    entered: f64,
}

impl<'m, M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize> Switching<'m, M, N, NA> {
    /// The charts of `system`'s molecule: the internal one, and the Cartesian chart where the
    /// molecule has one, else the rigid chart (neither is an error).
    fn new(
        system: &ReducedSystem<'m, M, N, NA>,
        t0: f64,
        t_end: f64,
        interval: f64,
    ) -> Result<Self, SolveError<ChartError>> {
        let m = system.molecule();
        let internal = system.with_min_pivot(SWITCH_PIVOT);
        let (cartesian, rigid) = match CartesianSystem::new(m) {
            Ok(c) => (Some(c.with_return_pivot(RETURN_PIVOT)), None),
            Err(e) => match RigidSystem::new(m) {
                Some(r) => (None, Some(r.with_return_pivot(RETURN_PIVOT))),
                None => return Err(SolveError::InvalidInput(e.to_string())),
            },
        };
        let fallback = if rigid.is_some() { Chart::Rigid } else { Chart::Cartesian };
        let buffer = vec![0.0; internal.dim()];
        Ok(Self {
            internal,
            cartesian,
            rigid,
            fallback,
            t0,
            t_end,
            interval,
            buffer,
            served: None,
            last_q: SVector::zeros(),
            entered: t0,
        })
    }

    /// The first segment's chart and start; `None` when the run ends at its start (a fallback
    /// start serves the output at `t0` here).
    fn first_segment<O: ChartObserver + ?Sized>(
        &mut self,
        start: ChartStart<'_, N>,
        observer: &mut O,
        report: &mut ChartReport,
    ) -> Result<Option<(Chart, Next)>, SolveError<ChartError>> {
        let y = match start {
            ChartStart::Resume(r) => {
                self.served = Some(r.outputs_done);
                return Ok(Some((Chart::Internal, Next::Point(r.clone()))));
            }
            ChartStart::Fresh(body) => match self.fresh(body)? {
                (true, y) => return Ok(Some((Chart::Internal, Next::Fresh(y)))),
                (false, y) => y,
            },
            ChartStart::FreshCartesian(y) => self.fresh_cartesian(y)?,
        };
        report.last_chart = Some(self.fallback);
        self.served = Some(0);
        let first = match &self.rigid {
            None => ChartState::Cartesian(&y),
            Some(r) => {
                let body = r
                    .clone()
                    .body_of_flat(&y)
                    .map_err(|e| SolveError::InvalidInput(format!("the start in the rigid chart does not fit: {e}")))?;
                self.last_q = body.q;
                reduce(&self.internal, body, &mut self.buffer).map_err(SolveError::InvalidInput)?;
                ChartState::Internal(&self.buffer)
            }
        };
        if observer.observe(self.t0, first).is_break() || self.t_end <= self.t0 {
            return Ok(None);
        }
        let h = self.interval.min(self.t_end - self.t0) * 1e-3;
        let point = Dop853Resume { t: self.t0, y, h, fac_old: 1e-4, reject: false, outputs_done: 0 };
        Ok(Some((self.fallback, Next::Point(point))))
    }

    /// A fresh start from `body`: whether the internal chart is regular there, and the start
    /// in the internal chart if it is, else in the fallback chart.
    fn fresh(&mut self, body: &BodyState<N>) -> Result<(bool, Vec<f64>), SolveError<ChartError>> {
        self.last_q = body.q;
        let internal = &mut self.internal;
        let mut y = vec![0.0; internal.dim()];
        let mut dy = vec![0.0; internal.dim()];
        if internal.reduce_body(body, &mut y).is_ok() && internal.rhs(self.t0, &y, &mut dy).is_ok() {
            return Ok((true, y));
        }
        let y = if let Some(r) = &mut self.rigid {
            let mut yr = vec![0.0; r.dim()];
            r.flat_of_body(body, &mut yr).map_err(|reason| {
                SolveError::InvalidInput(format!(
                    "the start is singular for internal coordinates and cannot be put in the rigid chart: {reason}"
                ))
            })?;
            r.set_near(&body.q);
            yr
        } else {
            to_cartesian(self.internal.molecule(), body).map_err(|reason| {
                SolveError::InvalidInput(format!(
                    "the start is singular for internal coordinates and cannot be put in the Cartesian chart: {reason}"
                ))
            })?
        };
        Ok((false, y))
    }

    /// A fresh start from the Cartesian flat state `y`, in the fallback chart.
    fn fresh_cartesian(&mut self, y: &[f64]) -> Result<Vec<f64>, SolveError<ChartError>> {
        if y.len() != 6 * NA {
            return Err(SolveError::InvalidInput(format!(
                "a Cartesian start of {} components, expected {}",
                y.len(),
                6 * NA
            )));
        }
        let lab = CartesianSystem::<M, N, NA>::lab(y);
        if let Some(r) = &self.rigid {
            let mut yr = vec![0.0; r.dim()];
            r.layout().flat(r.masses(), &lab, &mut yr);
            return Ok(yr);
        }
        if let Ok((body, _)) = body_of_lab_exact(self.internal.molecule(), &lab, &self.last_q) {
            self.last_q = body.q;
        }
        Ok(y.to_vec())
    }

    /// A segment in the internal chart from `next`: the run's end (`None`), or the switch to the
    /// fallback chart at the last accepted state when the metric's pivot fell below
    /// [`SWITCH_PIVOT`].
    fn internal_segment<O: ChartObserver + ?Sized>(
        &mut self,
        dop: &mut Dop853,
        next: &Next,
        observer: &mut O,
        report: &mut ChartReport,
    ) -> Result<Option<(Chart, Next)>, SolveError<ChartError>> {
        let (t0, t_end, interval) = (self.t0, self.t_end, self.interval);
        let mut out = Served { observer, served: &mut self.served, chart: Chart::Internal };
        let result = match next {
            Next::Fresh(y) => dop.integrate_resumable(&mut self.internal, t0, y, t_end, interval, &mut out),
            Next::Point(p) => dop.resume(&mut self.internal, t0, p, t_end, interval, &mut out),
        };
        match result {
            Ok((stats, resume)) => {
                add(&mut report.stats, &stats);
                report.resume = resume;
                Ok(None)
            }
            Err(SolveError::Rhs { source, .. }) if is_switch(&source) => self.leave_internal(dop, report).map(Some),
            Err(e) => {
                add(&mut report.stats, &dop.last_accepted().3);
                Err(map_error(e, ChartError::Internal))
            }
        }
    }

    /// The switch from the internal chart to the fallback chart at `dop`'s last accepted state.
    fn leave_internal(
        &mut self,
        dop: &Dop853,
        report: &mut ChartReport,
    ) -> Result<(Chart, Next), SolveError<ChartError>> {
        let (t, y, h, stats) = dop.last_accepted();
        add(&mut report.stats, &stats);
        // A failure before the internal segment chose a step (at its start).
        let h = if h.is_finite() && h > 0.0 { h } else { self.interval.min(self.t_end - t) * 1e-3 };
        let fail = |reason: String| SolveError::Rhs {
            t,
            y: y.to_vec(),
            source: ChartError::Switch { from: Chart::Internal, t, reason },
        };
        let body = self.internal.expand_body(y).map_err(|e| fail(e.to_string()))?;
        self.last_q = body.q;
        let yc = match (&mut self.cartesian, &mut self.rigid) {
            (Some(cartesian), _) => {
                let yc = to_cartesian(self.internal.molecule(), &body).map_err(fail)?;
                // The Cartesian segment takes at least the step the internal one failed in.
                cartesian.check_after(t + h);
                yc
            }
            (None, Some(r)) => {
                let mut yr = vec![0.0; r.dim()];
                r.flat_of_body(&body, &mut yr).map_err(|e| fail(e.to_string()))?;
                r.set_near(&body.q);
                r.check_after(t + h);
                yr
            }
            (None, None) => unreachable!("a fallback chart was made above"),
        };
        let outputs_done = self.served.unwrap_or(0);
        report.switches += 1;
        self.entered = t;
        let point = Dop853Resume { t, y: yc, h, fac_old: 1e-4, reject: false, outputs_done };
        Ok((self.fallback, Next::Point(point)))
    }

    /// A segment in the Cartesian chart from `next`, to what [`conclude`] decides.
    fn cartesian_segment<O: ChartObserver + ?Sized>(
        &mut self,
        dop: &mut Dop853,
        next: &Next,
        observer: &mut O,
        report: &mut ChartReport,
    ) -> Result<Option<(Chart, Next)>, SolveError<ChartError>> {
        let Next::Point(p) = next else { unreachable!("a Cartesian segment starts from a point") };
        let Some(cartesian) = &mut self.cartesian else { unreachable!("the Cartesian chart is the fallback") };
        let mut out = Served { observer, served: &mut self.served, chart: Chart::Cartesian };
        let result = dop.resume(cartesian, self.t0, p, self.t_end, self.interval, &mut out);
        let at = Segment { internal: &self.internal, served: self.served, entered: self.entered, t_end: self.t_end };
        conclude(result, dop, cartesian, at, &mut self.last_q, report)
    }

    /// A segment in the rigid chart from `next` (its integrator made with `options` at its first
    /// use), its outputs served as internal-chart states, to what [`conclude`] decides.
    fn rigid_segment<O: ChartObserver + ?Sized>(
        &mut self,
        dop: &mut Option<Dop853>,
        options: Dop853Options,
        next: &Next,
        observer: &mut O,
        report: &mut ChartReport,
    ) -> Result<Option<(Chart, Next)>, SolveError<ChartError>> {
        let Next::Point(p) = next else { unreachable!("a rigid segment starts from a point") };
        let Some(rigid) = &mut self.rigid else { unreachable!("the rigid chart is the fallback") };
        if dop.as_ref().is_none_or(|d| d.dim() != rigid.dim()) {
            *dop = Some(Dop853::new(rigid.dim(), options).map_err(|e| SolveError::InvalidInput(e.to_string()))?);
        }
        let Some(dop) = dop.as_mut() else { unreachable!("made above") };
        let mut out = RigidServed {
            observer,
            served: &mut self.served,
            rigid: rigid.clone(),
            internal: &self.internal,
            buffer: &mut self.buffer,
            failure: None,
        };
        out.rigid.set_near(&self.last_q);
        let result = dop.resume(rigid, self.t0, p, self.t_end, self.interval, &mut out);
        if let Some((t, reason)) = out.failure.take() {
            add(&mut report.stats, &dop.last_accepted().3);
            let y = dop.last_accepted().1.to_vec();
            return Err(SolveError::Rhs { t, y, source: ChartError::Switch { from: Chart::Rigid, t, reason } });
        }
        let at = Segment { internal: &self.internal, served: self.served, entered: self.entered, t_end: self.t_end };
        conclude(result, dop, rigid, at, &mut self.last_q, report)
    }
}

/// A chart a run falls back to near singular geometries of the internal chart (the Cartesian or
/// the rigid chart), as [`conclude`] needs it.
trait Fallback<const N: usize>: OdeSystem {
    /// Which chart it is.
    const CHART: Chart;
    /// Whether a segment stopped because the internal chart may be regular again.
    fn returning(e: &Self::Error) -> bool;
    /// This chart's error as a [`ChartError`].
    fn chart_error(e: Self::Error) -> ChartError;
    /// The body state at the flat state `y` if the internal chart is regular there (every
    /// relative pivot above [`SWITCH_PIVOT`]), else `None`; `near` is the internal
    /// configuration the conversion starts from, updated to the one found when there is one.
    fn regular_body(&mut self, y: &[f64], near: &mut SVector<f64, N>) -> Result<Option<BodyState<N>>, String>;
    /// Makes the return test apply only to evaluations at times after `t`.
    fn check_after(&mut self, t: f64);
}

impl<M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize> Fallback<N> for CartesianSystem<'_, M, N, NA> {
    const CHART: Chart = Chart::Cartesian;

    fn returning(e: &CartesianError) -> bool {
        matches!(e, CartesianError::Regular { .. })
    }

    fn chart_error(e: CartesianError) -> ChartError {
        ChartError::Cartesian(e)
    }

    fn regular_body(&mut self, y: &[f64], near: &mut SVector<f64, N>) -> Result<Option<BodyState<N>>, String> {
        if !self.internal_chart_regular(&Self::positions(y), SWITCH_PIVOT) {
            return Ok(None);
        }
        let (body, _) = body_of_lab_exact(self.molecule(), &Self::lab(y), near).map_err(|e| e.to_string())?;
        *near = body.q;
        Ok(Some(body))
    }

    fn check_after(&mut self, t: f64) {
        CartesianSystem::check_after(self, t);
    }
}

impl<M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize> Fallback<N> for RigidSystem<'_, M, N, NA> {
    const CHART: Chart = Chart::Rigid;

    fn returning(e: &RigidError) -> bool {
        matches!(e, RigidError::Regular { .. })
    }

    fn chart_error(e: RigidError) -> ChartError {
        ChartError::Rigid(e)
    }

    fn regular_body(&mut self, y: &[f64], near: &mut SVector<f64, N>) -> Result<Option<BodyState<N>>, String> {
        self.set_near(near);
        let body = self.body_of_flat(y).map_err(|e| e.to_string())?;
        *near = body.q;
        let mut k = crate::molecule::KineticMatrices::<N>::default();
        self.molecule().kinetic(&body.q, &mut k);
        Ok(crate::hamiltonian::MetricFactor::is_regular(&k, SWITCH_PIVOT).then_some(body))
    }

    fn check_after(&mut self, t: f64) {
        RigidSystem::check_after(self, t);
    }
}

/// Where a fallback segment of [`run`] stands: the internal system to return to, the outputs
/// served before the segment, when the run entered the fallback chart, and the run's end.
struct Segment<'a, 'm, M: ?Sized, const N: usize, const NA: usize> {
    internal: &'a ReducedSystem<'m, M, N, NA>,
    served: Option<u64>,
    entered: f64,
    t_end: f64,
}

/// The end of a fallback segment: `None` when the run is finished, else the next segment's
/// chart and start (the internal chart if it is regular at the segment's last accepted state,
/// else one more step in the fallback chart before testing again). Adds the segment's work and
/// time to `report`.
fn conclude<S, M, const N: usize, const NA: usize>(
    result: Result<(Stats, Option<Dop853Resume>), SolveError<S::Error>>,
    dop: &Dop853,
    system: &mut S,
    at: Segment<'_, '_, M, N, NA>,
    last_q: &mut SVector<f64, N>,
    report: &mut ChartReport,
) -> Result<Option<(Chart, Next)>, SolveError<ChartError>>
where
    S: Fallback<N>,
    M: Molecule<N, NA> + ?Sized,
{
    let time = match S::CHART {
        Chart::Rigid => &mut report.rigid_time,
        Chart::Cartesian | Chart::Internal => &mut report.cartesian_time,
    };
    match result {
        Ok((stats, _)) => {
            add(&mut report.stats, &stats);
            *time += at.t_end - at.entered;
            Ok(None)
        }
        Err(SolveError::Rhs { source, .. }) if S::returning(&source) => {
            let (t, y, h, stats) = dop.last_accepted();
            add(&mut report.stats, &stats);
            let outputs_done = at.served.unwrap_or(0);
            let fail = |reason: String| SolveError::Rhs {
                t,
                y: y.to_vec(),
                source: ChartError::Switch { from: S::CHART, t, reason },
            };
            match system.regular_body(y, last_q).map_err(fail)? {
                Some(body) => {
                    let mut yi = vec![0.0; at.internal.dim()];
                    reduce(at.internal, body, &mut yi).map_err(fail)?;
                    *time += t - at.entered;
                    report.switches += 1;
                    let point = Dop853Resume { t, y: yi, h, fac_old: 1e-4, reject: false, outputs_done };
                    Ok(Some((Chart::Internal, Next::Point(point))))
                }
                None => {
                    system.check_after(t + h);
                    let point = Dop853Resume { t, y: y.to_vec(), h, fac_old: 1e-4, reject: false, outputs_done };
                    Ok(Some((S::CHART, Next::Point(point))))
                }
            }
        }
        Err(e) => {
            add(&mut report.stats, &dop.last_accepted().3);
            Err(map_error(e, S::chart_error))
        }
    }
}
