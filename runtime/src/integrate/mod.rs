//! Integrators for Hamilton's equations: DOP853 (adaptive), Gauss–Legendre (implicit,
//! symplectic) and classical RK4, behind one small interface.
//!
//! A problem is an [`OdeSystem`]: a right-hand side `dy/dt = f(t, y)` on a flat `&[f64]` state.
//! A method writes the state at each output time to an [`Observer`]. Every method allocates its
//! workspace once, when it is created; a step never allocates.

use core::ops::ControlFlow;

/// A system of ordinary differential equations `dy/dt = f(t, y)` of fixed dimension.
pub trait OdeSystem {
    /// Why the right-hand side could not be evaluated (e.g. a singular metric).
    type Error: std::error::Error + 'static;

    /// The dimension of `y`.
    fn dim(&self) -> usize;

    /// Writes `f(t, y)` into `dydt` (both of length [`OdeSystem::dim`]).
    fn rhs(&mut self, t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Self::Error>;
}

/// Receives the solution at the output times (and at the initial time).
pub trait Observer {
    /// Called with the time and the state; return `ControlFlow::Break(())` to stop the run early
    /// (the solver then returns `Ok` with the statistics so far).
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()>;
}

impl<F: FnMut(f64, &[f64]) -> ControlFlow<()>> Observer for F {
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()> {
        self(t, y)
    }
}

/// Work counters of one run.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Steps attempted (accepted + rejected).
    pub steps: u64,
    /// Steps accepted.
    pub accepted: u64,
    /// Steps rejected by the error control (always 0 for fixed-step methods).
    pub rejected: u64,
    /// Right-hand-side evaluations.
    pub rhs_evals: u64,
}

/// Why a run ended before its end time. Each variant carries the time and the last accepted
/// state so that the caller can report where it happened.
#[derive(Debug)]
pub enum SolveError<E> {
    /// The right-hand side failed.
    Rhs {
        /// Time of the failing evaluation.
        t: f64,
        /// Last accepted state.
        y: Vec<f64>,
        /// The system's error.
        source: E,
    },
    /// The right-hand side or the new state contained NaN or infinity.
    NonFinite {
        /// Time at which it was detected.
        t: f64,
        /// Last accepted (finite) state.
        y: Vec<f64>,
    },
    /// The adaptive step size fell below the minimum.
    StepSizeTooSmall {
        /// Time reached.
        t: f64,
        /// The step size that was too small.
        h: f64,
        /// Last accepted state.
        y: Vec<f64>,
    },
    /// The maximum number of steps was reached before the end time.
    TooManySteps {
        /// Time reached.
        t: f64,
        /// The limit.
        max_steps: u64,
        /// Last accepted state.
        y: Vec<f64>,
    },
    /// The implicit stage equations did not converge.
    NotConverged {
        /// Time of the step.
        t: f64,
        /// Last accepted state.
        y: Vec<f64>,
    },
    /// The arguments were inconsistent (wrong dimension, non-positive step, ...).
    InvalidInput(String),
}
