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
use nalgebra::Vector3;

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

/// Whether a reduction can switch: every coordinate active (the Cartesian chart has no
/// constraints).
pub fn can_switch<M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize>(
    system: &ReducedSystem<'_, M, N, NA>,
) -> bool {
    system.reduction().active.iter().all(|&a| a) && CartesianSystem::new(system.molecule()).is_ok()
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
    near: &nalgebra::SVector<f64, N>,
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
            Chart::Cartesian => ChartState::Cartesian(y),
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

/// The two DOP853 integrators of a run with chart switching (one per chart), made once and
/// reused for many runs (an ensemble's trajectories), so that a run allocates nothing but the
/// states it hands over at a switch.
pub struct ChartIntegrator {
    internal: Dop853,
    cartesian: Dop853,
}

impl ChartIntegrator {
    /// For systems of `internal_dim` internal-chart components and `atoms` atoms.
    pub fn new(internal_dim: usize, atoms: usize, options: Dop853Options) -> Result<Self, InvalidInput> {
        Ok(Self { internal: Dop853::new(internal_dim, options)?, cartesian: Dop853::new(6 * atoms, options)? })
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
        run(&mut self.internal, &mut self.cartesian, system, t0, start, t_end, interval, observer, report)
    }
}

#[allow(clippy::too_many_arguments)]
fn run<M, O, const N: usize, const NA: usize>(
    dop_i: &mut Dop853,
    dop_c: &mut Dop853,
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
    let m = system.molecule();
    let mut internal = system.with_min_pivot(SWITCH_PIVOT);
    let mut cartesian =
        CartesianSystem::new(m).map_err(|e| SolveError::InvalidInput(e.to_string()))?.with_return_pivot(RETURN_PIVOT);
    let mut served: Option<u64> = None;
    let mut last_q = nalgebra::SVector::<f64, N>::zeros();
    let mut entered = t0;
    let (mut chart, mut next) = match start {
        ChartStart::Resume(r) => {
            served = Some(r.outputs_done);
            (Chart::Internal, Next::Point(r.clone()))
        }
        ChartStart::FreshCartesian(y) if y.len() != 6 * NA => {
            return Err(SolveError::InvalidInput(format!(
                "a Cartesian start of {} components, expected {}",
                y.len(),
                6 * NA
            )));
        }
        ChartStart::Fresh(_) | ChartStart::FreshCartesian(_) => {
            let (regular, y, cartesian_y) = match start {
                ChartStart::Fresh(body) => {
                    last_q = body.q;
                    let mut y = vec![0.0; internal.dim()];
                    let mut dy = vec![0.0; internal.dim()];
                    let regular = internal.reduce_body(body, &mut y).is_ok() && internal.rhs(t0, &y, &mut dy).is_ok();
                    let cartesian_y = if regular {
                        Vec::new()
                    } else {
                        to_cartesian(m, body).map_err(|reason| {
                            SolveError::InvalidInput(format!(
                                "the start is singular for internal coordinates and cannot be put in the Cartesian \
                                 chart: {reason}"
                            ))
                        })?
                    };
                    (regular, y, cartesian_y)
                }
                ChartStart::FreshCartesian(y) => {
                    let lab = CartesianSystem::<M, N, NA>::lab(y);
                    if let Ok((body, _)) = body_of_lab_exact(m, &lab, &last_q) {
                        last_q = body.q;
                    }
                    (false, Vec::new(), y.to_vec())
                }
                ChartStart::Resume(_) => unreachable!("matched above"),
            };
            if regular {
                (Chart::Internal, Next::Fresh(y))
            } else {
                let y = cartesian_y;
                report.last_chart = Some(Chart::Cartesian);
                served = Some(0);
                if observer.observe(t0, ChartState::Cartesian(&y)).is_break() || t_end <= t0 {
                    return Ok(());
                }
                let h = interval.min(t_end - t0) * 1e-3;
                (
                    Chart::Cartesian,
                    Next::Point(Dop853Resume { t: t0, y, h, fac_old: 1e-4, reject: false, outputs_done: 0 }),
                )
            }
        }
    };
    loop {
        report.last_chart = Some(chart);
        let mut out = Served { observer: &mut *observer, served: &mut served, chart };
        match chart {
            Chart::Internal => {
                let result = match &next {
                    Next::Fresh(y) => dop_i.integrate_resumable(&mut internal, t0, y, t_end, interval, &mut out),
                    Next::Point(p) => dop_i.resume(&mut internal, t0, p, t_end, interval, &mut out),
                };
                match result {
                    Ok((stats, resume)) => {
                        add(&mut report.stats, &stats);
                        report.resume = resume;
                        return Ok(());
                    }
                    Err(SolveError::Rhs { source, .. }) if is_switch(&source) => {
                        let (t, y, h, stats) = dop_i.last_accepted();
                        add(&mut report.stats, &stats);
                        // A failure before the internal segment chose a step (at its start).
                        let h = if h.is_finite() && h > 0.0 { h } else { interval.min(t_end - t) * 1e-3 };
                        let fail = |reason: String| SolveError::Rhs {
                            t,
                            y: y.to_vec(),
                            source: ChartError::Switch { from: Chart::Internal, t, reason },
                        };
                        let body = internal.expand_body(y).map_err(|e| fail(e.to_string()))?;
                        last_q = body.q;
                        let yc = to_cartesian(m, &body).map_err(fail)?;
                        // The Cartesian segment takes at least the step the internal one failed in.
                        cartesian.check_after(t + h);
                        let outputs_done = served.unwrap_or(0);
                        next = Next::Point(Dop853Resume { t, y: yc, h, fac_old: 1e-4, reject: false, outputs_done });
                        chart = Chart::Cartesian;
                        report.switches += 1;
                        entered = t;
                    }
                    Err(e) => {
                        add(&mut report.stats, &dop_i.last_accepted().3);
                        return Err(map_error(e, ChartError::Internal));
                    }
                }
            }
            Chart::Cartesian => {
                let Next::Point(p) = &next else { unreachable!("a Cartesian segment starts from a point") };
                match dop_c.resume(&mut cartesian, t0, p, t_end, interval, &mut out) {
                    Ok((stats, _)) => {
                        add(&mut report.stats, &stats);
                        report.cartesian_time += t_end - entered;
                        return Ok(());
                    }
                    Err(SolveError::Rhs { source: CartesianError::Regular { .. }, .. }) => {
                        let (t, y, h, stats) = dop_c.last_accepted();
                        add(&mut report.stats, &stats);
                        let outputs_done = served.unwrap_or(0);
                        let x = CartesianSystem::<M, N, NA>::positions(y);
                        if cartesian.internal_chart_regular(&x, SWITCH_PIVOT) {
                            let (body, yi) = to_internal(&internal, y, &last_q).map_err(|reason| SolveError::Rhs {
                                t,
                                y: y.to_vec(),
                                source: ChartError::Switch { from: Chart::Cartesian, t, reason },
                            })?;
                            last_q = body.q;
                            next =
                                Next::Point(Dop853Resume { t, y: yi, h, fac_old: 1e-4, reject: false, outputs_done });
                            chart = Chart::Internal;
                            report.switches += 1;
                            report.cartesian_time += t - entered;
                        } else {
                            // Regular at a stage but not yet at the last accepted state: one more
                            // step here before testing again.
                            cartesian.check_after(t + h);
                            next = Next::Point(Dop853Resume {
                                t,
                                y: y.to_vec(),
                                h,
                                fac_old: 1e-4,
                                reject: false,
                                outputs_done,
                            });
                        }
                    }
                    Err(e) => {
                        add(&mut report.stats, &dop_c.last_accepted().3);
                        return Err(map_error(e, ChartError::Cartesian));
                    }
                }
            }
        }
    }
}
