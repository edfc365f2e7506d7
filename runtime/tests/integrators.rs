//! Convergence, conservation and failure behaviour of the integrators in
//! `rovib_runtime::integrate`, on problems with known solutions.
//!
//! Run with `--nocapture` to see the measured orders and energy errors.

use core::convert::Infallible;
use core::ops::ControlFlow;
use std::f64::consts::PI;

use rovib_runtime::integrate::{
    Dop853, Dop853Options, GaussLegendre, GaussLegendreOptions, Method, Observer, OdeSystem, Rk4, Rk4Options,
    SolveError, Stats, fixed_step_count, solve,
};

// ---------------------------------------------------------------------------------------------
// Test problems (Kepler and ExpSin are the runtime's own, in `integrate::problems`)
// ---------------------------------------------------------------------------------------------

use rovib_runtime::integrate::problems::{ExpSin, Kepler};

/// The harmonic oscillator `q' = p, p' = −q`: its energy is a quadratic invariant, which
/// Gauss methods conserve exactly, so any energy error they show is round-off.
struct Oscillator;

impl OdeSystem for Oscillator {
    type Error = Infallible;
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Infallible> {
        dydt[0] = y[1];
        dydt[1] = -y[0];
        Ok(())
    }
}

/// `y' = y²`, `y(0) = 1`: `y = 1/(1 − t)` blows up at `t = 1`.
struct BlowUp;

impl OdeSystem for BlowUp {
    type Error = Infallible;
    fn dim(&self) -> usize {
        1
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Infallible> {
        dydt[0] = y[0] * y[0];
        Ok(())
    }
}

/// A system whose right-hand side fails from `t_fail` on.
struct FailsLate {
    t_fail: f64,
}

#[derive(Debug)]
struct Singular(f64);

impl std::fmt::Display for Singular {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "singular metric at t = {}", self.0)
    }
}

impl std::error::Error for Singular {}

impl OdeSystem for FailsLate {
    type Error = Singular;
    fn dim(&self) -> usize {
        1
    }
    fn rhs(&mut self, t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Singular> {
        if t >= self.t_fail {
            return Err(Singular(t));
        }
        dydt[0] = -y[0];
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// Runs `method` and returns the final state and the statistics.
fn final_state<S: OdeSystem>(
    system: &mut S,
    method: &Method,
    y0: &[f64],
    t_end: f64,
    output_interval: f64,
) -> (Vec<f64>, Stats) {
    let mut last = Vec::new();
    let stats = solve(system, method, 0.0, y0, t_end, output_interval, &mut |_t: f64, y: &[f64]| {
        last.clear();
        last.extend_from_slice(y);
        ControlFlow::Continue(())
    })
    .unwrap();
    (last, stats)
}

/// Keeps the last observed state.
#[derive(Default)]
struct Last(Vec<f64>);

impl Observer for Last {
    fn observe(&mut self, _t: f64, y: &[f64]) -> ControlFlow<()> {
        self.0.clear();
        self.0.extend_from_slice(y);
        ControlFlow::Continue(())
    }
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// Global error after one Kepler period (e = 0.5) with `n` fixed steps of `make(h)`.
fn kepler_period_error(make: impl Fn(f64) -> Method, n: u32) -> f64 {
    let y0 = Kepler::initial(0.5);
    let period = 2.0 * PI;
    let method = make(period / f64::from(n));
    let (y, stats) = final_state(&mut Kepler, &method, &y0, period, period);
    assert_eq!(stats.steps, u64::from(n), "the step must not be shrunk");
    max_abs_diff(&y, &y0)
}

/// Observed orders `log2(err(n) / err(2n))` for the given step counts.
fn observed_orders(name: &str, make: impl Fn(f64) -> Method, steps: &[u32]) -> Vec<f64> {
    let errors: Vec<f64> = steps.iter().map(|&n| kepler_period_error(&make, n)).collect();
    let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
    let shown: Vec<String> = errors.iter().map(|e| format!("{e:.3e}")).collect();
    println!("{name}: steps {steps:?}, errors {shown:?}, observed orders {orders:.3?}");
    orders
}

fn assert_order(orders: &[f64], expected: f64) {
    for &p in orders {
        assert!((p - expected).abs() <= 0.3, "observed order {p:.3}, expected {expected} ± 0.3 (all: {orders:.3?})");
    }
}

fn gauss(stages: usize, step: f64, compensated: bool) -> Method {
    Method::GaussLegendre(GaussLegendreOptions { stages, step, compensated, ..Default::default() })
}

// ---------------------------------------------------------------------------------------------
// Orders of convergence
// ---------------------------------------------------------------------------------------------

#[test]
fn rk4_is_fourth_order_on_kepler() {
    let orders =
        observed_orders("RK4", |step| Method::Rk4(Rk4Options { step, ..Default::default() }), &[400, 800, 1600]);
    assert_order(&orders, 4.0);
}

#[test]
fn gauss_legendre_2_is_fourth_order_on_kepler() {
    let orders = observed_orders("GL2", |step| gauss(2, step, true), &[200, 400, 800]);
    assert_order(&orders, 4.0);
}

#[test]
fn gauss_legendre_3_is_sixth_order_on_kepler() {
    let orders = observed_orders("GL3", |step| gauss(3, step, true), &[100, 200, 400]);
    assert_order(&orders, 6.0);
}

/// DOP853's global error is proportional to the tolerance: on Kepler (e = 0.5, three periods)
/// the least-squares slope of log(error) against log(tolerance) over six decades is close to 1
/// and the error falls with every tighter tolerance. (Single decades are irregular on this
/// problem, because the controller alternates accepted and rejected steps on the way into
/// pericentre.)
#[test]
fn dop853_error_is_proportional_to_the_tolerance() {
    let y0 = Kepler::initial(0.5);
    let period = 2.0 * PI;
    let tolerances = [1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12];
    let mut points = Vec::new();
    for tol in tolerances {
        let method = Method::Dop853(Dop853Options { rtol: tol, atol: tol, ..Default::default() });
        let (y, stats) = final_state(&mut Kepler, &method, &y0, 3.0 * period, period);
        let err = max_abs_diff(&y, &y0);
        println!(
            "DOP853 Kepler tol {tol:.0e}: error {err:.3e} ({:.0}·tol), {} accepted, {} rejected, {} f-evals",
            err / tol,
            stats.accepted,
            stats.rejected,
            stats.rhs_evals
        );
        points.push((tol.log10(), err.log10()));
    }
    let n = points.len() as f64;
    let (mx, my) = (points.iter().map(|p| p.0).sum::<f64>() / n, points.iter().map(|p| p.1).sum::<f64>() / n);
    let slope = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>()
        / points.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
    println!("DOP853 Kepler: slope of log(error) vs log(tol) = {slope:.3}");
    assert!((0.8..=1.3).contains(&slope), "slope {slope}");
    for w in points.windows(2) {
        assert!(w[1].1 < w[0].1, "error did not fall: {points:?}");
    }
}

/// The dense output at every output time (almost all of them inside steps) agrees with the
/// exact solution to about the tolerance: within 20·tol on the harmonic oscillator, whose
/// global error the controller keeps near the tolerance. On y' = y·cos t the global error itself
/// accumulates to a few dozen tol over its 15–60 steps (scalar problems fool the error
/// estimator now and then), and the dense output stays within that.
/// (The interpolant's own order is checked in the unit tests of `dop853.rs`.)
#[test]
fn dop853_dense_output_matches_the_exact_solution() {
    for tol in [1e-7, 1e-10, 1e-13] {
        let options = Dop853Options { rtol: tol, atol: tol, ..Default::default() };
        // Harmonic oscillator, y = (cos t, −sin t).
        let mut worst: f64 = 0.0;
        let mut count = 0;
        let stats =
            solve(&mut Oscillator, &Method::Dop853(options), 0.0, &[1.0, 0.0], 30.0, 0.1, &mut |t: f64, y: &[f64]| {
                worst = worst.max(max_abs_diff(y, &[t.cos(), -t.sin()]));
                count += 1;
                ControlFlow::Continue(())
            })
            .unwrap();
        println!(
            "DOP853 dense oscillator, tol {tol:.0e}: max error {worst:.2e} ({:.1}·tol), {count} outputs, {stats:?}",
            worst / tol
        );
        assert_eq!(count, 301);
        assert!(stats.accepted < 250, "outputs must not force steps");
        assert!(worst < 20.0 * tol, "max error {worst} at tol {tol}");
    }
    for tol in [1e-6, 1e-8, 1e-10] {
        let options = Dop853Options { rtol: tol, atol: tol, ..Default::default() };
        // y' = y cos t, y = exp(sin t).
        let mut worst: f64 = 0.0;
        let stats = solve(&mut ExpSin, &Method::Dop853(options), 0.0, &[1.0], 10.0, 0.05, &mut |t: f64, y: &[f64]| {
            worst = worst.max((y[0] - ExpSin::exact(t)).abs() / ExpSin::exact(t));
            ControlFlow::Continue(())
        })
        .unwrap();
        println!(
            "DOP853 dense exp(sin t), tol {tol:.0e}: max relative error {worst:.2e} ({:.1}·tol), {stats:?}",
            worst / tol
        );
        assert!(worst < 200.0 * tol, "max error {worst} at tol {tol}");
    }
}

// ---------------------------------------------------------------------------------------------
// Output times
// ---------------------------------------------------------------------------------------------

fn output_times(method: &Method, t0: f64, t_end: f64, interval: f64) -> Vec<f64> {
    let mut times = Vec::new();
    solve(&mut ExpSin, method, t0, &[1.0], t_end, interval, &mut |t: f64, _y: &[f64]| {
        times.push(t);
        ControlFlow::Continue(())
    })
    .unwrap();
    times
}

#[test]
fn observer_sees_t0_the_grid_and_t_end() {
    let methods = [
        Method::Dop853(Dop853Options::default()),
        gauss(2, 0.07, true),
        gauss(3, 0.07, false),
        Method::Rk4(Rk4Options { step: 0.07, ..Default::default() }),
    ];
    for method in &methods {
        // t_end not on the grid: the last output is t_end itself.
        let times = output_times(method, 1.0, 2.25, 0.5);
        assert_eq!(times, [1.0, 1.5, 2.0, 2.25], "{}", method.name());
        // t_end on the grid up to rounding: no sliver interval, the last output is t_end.
        let times = output_times(method, 0.0, 0.3, 0.1);
        assert_eq!(times.len(), 4, "{}: {times:?}", method.name());
        assert_eq!(times[3], 0.3);
        // A run of zero length observes t0 only.
        assert_eq!(output_times(method, 2.0, 2.0, 0.1), [2.0]);
        // Output interval longer than the run.
        assert_eq!(output_times(method, 0.0, 1.0, 5.0), [0.0, 1.0]);
    }
}

#[test]
fn fixed_steps_are_shrunk_to_fit_the_output_interval() {
    // 0.5 / 0.07 = 7.14 → 8 steps of 0.0625 per interval; 0.25 / 0.07 → 4 steps.
    let method = Method::Rk4(Rk4Options { step: 0.07, ..Default::default() });
    let (_, stats) = final_state(&mut ExpSin, &method, &[1.0], 2.25, 0.5);
    assert_eq!(stats.steps, 4 * 8 + 4);
    assert_eq!(stats.rhs_evals, 4 * stats.steps);
}

#[test]
fn every_full_output_interval_gets_the_same_number_of_steps() {
    // A step that is not exact in binary (0.001 fs in atomic units), 100 per output interval,
    // over 10⁴ intervals: the grid's times carry rounding of order ε·t, which must not add
    // steps late in the run.
    let h = 0.001 / 0.024_188_843_265_857;
    let method = Method::Rk4(Rk4Options { step: h, ..Default::default() });
    let (_, stats) = final_state(&mut Oscillator, &method, &[1.0, 0.0], 1e6 * h, 100.0 * h);
    assert_eq!(stats.steps, 1_000_000);
}

/// `fixed_step_count` (what a scene is checked against `max_steps` with, before the run) is
/// the number of steps the fixed-step driver then takes, counted by running it: whole and
/// partial last intervals, steps exact and not exact in binary, step longer than the interval.
#[test]
fn the_fixed_step_count_known_in_advance_is_the_count_taken() {
    let h_fs = 0.001 / 0.024_188_843_265_857;
    for (t_end, interval, step) in [
        (2.25, 0.5, 0.07),
        (2.0, 0.5, 0.07),
        (1e4 * h_fs, 100.0 * h_fs, h_fs),
        (3.0, 0.3, 0.1),
        (1.0, 0.25, 5.0),
        (0.7, 1.0, 0.2),
        (10.0, 10.0 / 3.0, 1.0 / 7.0),
    ] {
        let predicted = fixed_step_count(0.0, t_end, interval, step);
        for method in [Method::Rk4(Rk4Options { step, ..Default::default() }), gauss(2, step, true)] {
            let (_, stats) = final_state(&mut Oscillator, &method, &[1.0, 0.0], t_end, interval);
            assert_eq!(stats.steps, predicted, "t_end {t_end}, interval {interval}, step {step}, {}", method.name());
        }
    }
    // Saturates instead of overflowing; nothing to do for invalid times.
    assert_eq!(fixed_step_count(0.0, 1e300, 1e290, 5e-324), u64::MAX);
    assert_eq!(fixed_step_count(0.0, 1.0, 0.5, f64::NAN), 0);
    assert_eq!(fixed_step_count(0.0, 0.0, 0.5, 0.1), 0);
}

#[test]
fn observer_can_stop_the_run() {
    for method in [
        Method::Dop853(Dop853Options::default()),
        gauss(3, 0.1, true),
        Method::Rk4(Rk4Options { step: 0.1, ..Default::default() }),
    ] {
        let mut times = Vec::new();
        let stats = solve(&mut ExpSin, &method, 0.0, &[1.0], 10.0, 1.0, &mut |t: f64, _y: &[f64]| {
            times.push(t);
            if t >= 3.0 { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
        })
        .unwrap();
        assert_eq!(times, [0.0, 1.0, 2.0, 3.0], "{}", method.name());
        assert!(stats.accepted > 0);
    }
}

// ---------------------------------------------------------------------------------------------
// Gauss–Legendre: long-time energy behaviour
// ---------------------------------------------------------------------------------------------

/// Max |H − H0| over the first and the second half of a run of `steps` steps.
fn energy_error_halves(method: &Method, steps: u64, step: f64, e: f64) -> (f64, f64) {
    let y0 = Kepler::initial(e);
    let h0 = Kepler::energy(&y0);
    let t_end = steps as f64 * step;
    let (mut first, mut second): (f64, f64) = (0.0, 0.0);
    solve(&mut Kepler, method, 0.0, &y0, t_end, step, &mut |t: f64, y: &[f64]| {
        let dh = (Kepler::energy(y) - h0).abs();
        if t <= 0.5 * t_end {
            first = first.max(dh);
        } else {
            second = second.max(dh);
        }
        ControlFlow::Continue(())
    })
    .unwrap();
    (first, second)
}

#[test]
fn gauss_legendre_energy_error_has_no_secular_drift_on_kepler() {
    let steps = 100_000;
    for (stages, per_period) in [(2, 200.0), (3, 100.0)] {
        let step = 2.0 * PI / per_period;
        let (first, second) = energy_error_halves(&gauss(stages, step, true), steps, step, 0.5);
        println!(
            "GL{stages} Kepler e = 0.5, h = 2π/{per_period}, {steps} steps: max |ΔH| first half {first:.3e}, second half {second:.3e}"
        );
        assert!(second <= 2.0 * first, "energy drifts: {first:e} → {second:e}");
        assert!(first > 0.0 && first < 1e-4);
    }
}

/// The harmonic oscillator's energy is a quadratic invariant that Gauss methods conserve
/// exactly, so its error is pure round-off. With a small step the increment is much smaller
/// than the state; adding it without compensation loses ε·|y| per step (a random walk that
/// grows like √n), while compensated summation keeps the error at the level of ε·|increment|.
#[test]
fn compensated_summation_keeps_energy_error_at_round_off() {
    let steps: u64 = 400_000;
    let step = 1e-3;
    let t_end = steps as f64 * step;
    let run = |compensated: bool| {
        let mut worst: f64 = 0.0;
        solve(
            &mut Oscillator,
            &gauss(2, step, compensated),
            0.0,
            &[1.0, 0.0],
            t_end,
            t_end / 100.0,
            &mut |_t: f64, y: &[f64]| {
                worst = worst.max((0.5 * (y[0] * y[0] + y[1] * y[1]) - 0.5).abs());
                ControlFlow::Continue(())
            },
        )
        .unwrap();
        worst
    };
    let with = run(true);
    let without = run(false);
    println!("GL2 oscillator, h = {step}, {steps} steps: max |ΔH| compensated {with:.3e}, uncompensated {without:.3e}");
    assert!(with < 1e-14, "compensated error {with:e}");
    assert!(without > 10.0 * with, "uncompensated {without:e} vs compensated {with:e}");
}

// ---------------------------------------------------------------------------------------------
// Failures
// ---------------------------------------------------------------------------------------------

#[test]
fn blow_up_is_reported_near_its_time() {
    let err = solve(
        &mut BlowUp,
        &Method::Dop853(Dop853Options::default()),
        0.0,
        &[1.0],
        2.0,
        0.5,
        &mut |_t: f64, _y: &[f64]| ControlFlow::Continue(()),
    )
    .unwrap_err();
    println!("DOP853 y' = y²: {err}");
    match &err {
        SolveError::StepSizeTooSmall { t, y, .. } | SolveError::NonFinite { t, y } => {
            assert!((t - 1.0).abs() < 1e-6, "t = {t}");
            assert!(y[0] > 1e6 && y[0].is_finite(), "y = {y:?}");
        }
        other => panic!("unexpected error {other:?}"),
    }

    for method in [gauss(3, 0.01, true), gauss(2, 0.01, false)] {
        let err =
            solve(&mut BlowUp, &method, 0.0, &[1.0], 2.0, 0.5, &mut |_t: f64, _y: &[f64]| ControlFlow::Continue(()))
                .unwrap_err();
        println!("{} y' = y²: {err}", method.name());
        match &err {
            SolveError::NotConverged { t, y } | SolveError::NonFinite { t, y } => {
                assert!((0.95..1.05).contains(t), "t = {t}");
                assert!(y[0].is_finite());
            }
            other => panic!("unexpected error {other:?}"),
        }
    }

    let rk4 = Method::Rk4(Rk4Options { step: 0.01, ..Default::default() });
    let err = solve(&mut BlowUp, &rk4, 0.0, &[1.0], 2.0, 0.5, &mut |_t: f64, _y: &[f64]| ControlFlow::Continue(()))
        .unwrap_err();
    println!("rk4 y' = y²: {err}");
    match &err {
        SolveError::NonFinite { t, y } => {
            assert!((0.95..1.2).contains(t), "t = {t}");
            assert!(y[0].is_finite());
        }
        other => panic!("unexpected error {other:?}"),
    }
}

#[test]
fn max_steps_gives_too_many_steps() {
    let methods = [
        Method::Dop853(Dop853Options { max_steps: 5, ..Default::default() }),
        Method::GaussLegendre(GaussLegendreOptions { step: 0.01, max_steps: 5, ..Default::default() }),
        Method::Rk4(Rk4Options { step: 0.01, max_steps: 5 }),
    ];
    for method in &methods {
        let err = solve(&mut Kepler, method, 0.0, &Kepler::initial(0.5), 100.0, 1.0, &mut |_t: f64, _y: &[f64]| {
            ControlFlow::Continue(())
        })
        .unwrap_err();
        match &err {
            SolveError::TooManySteps { t, max_steps, y } => {
                assert_eq!(*max_steps, 5);
                assert!(*t > 0.0 && *t < 100.0);
                assert_eq!(y.len(), 4);
            }
            other => panic!("{}: unexpected error {other:?}", method.name()),
        }
        assert!(err.to_string().starts_with("maximum number of steps (5) reached at t = "));
    }
}

#[test]
fn rhs_errors_are_reported_with_their_time() {
    let methods = [
        Method::Dop853(Dop853Options::default()),
        gauss(2, 0.01, true),
        gauss(3, 0.01, true),
        Method::Rk4(Rk4Options { step: 0.01, ..Default::default() }),
    ];
    for method in &methods {
        let mut system = FailsLate { t_fail: 0.5 };
        let mut last_observed = 0.0;
        let err = solve(&mut system, method, 0.0, &[1.0], 1.0, 0.1, &mut |t: f64, _y: &[f64]| {
            last_observed = t;
            ControlFlow::Continue(())
        })
        .unwrap_err();
        match &err {
            SolveError::Rhs { t, y, source } => {
                assert!(*t >= 0.5 && *t < 0.7, "{}: t = {t}", method.name());
                assert_eq!(source.0, *t);
                // The last accepted state is a point of y = exp(−t) before the failure.
                assert!(y[0] > (-0.5_f64).exp() * (1.0 - 1e-6) && y[0] < 1.0, "{y:?}");
            }
            other => panic!("{}: unexpected error {other:?}", method.name()),
        }
        assert!(last_observed < 0.5 + 1e-12);
        let message = err.to_string();
        assert!(message.starts_with("right-hand side failed at t = 0."), "{message}");
        let source = std::error::Error::source(&err).unwrap().to_string();
        assert!(source.starts_with("singular metric at t = "), "{source}");
    }
}

#[test]
fn invalid_input_is_rejected() {
    let observe = &mut |_t: f64, _y: &[f64]| ControlFlow::Continue(());
    let default = Method::default();
    let invalid = |r: Result<Stats, SolveError<Infallible>>| match r {
        Err(SolveError::InvalidInput(message)) => message,
        other => panic!("expected InvalidInput, got {other:?}"),
    };
    // Wrong dimension of y0.
    let m = invalid(solve(&mut Kepler, &default, 0.0, &[1.0, 0.0], 1.0, 0.1, observe));
    assert!(m.contains("length 2") && m.contains("dimension 4"), "{m}");
    // A held solver used with a system of another dimension.
    let mut solver = Dop853::new(2, Dop853Options::default()).unwrap();
    let r = solver.integrate(&mut Kepler, 0.0, &Kepler::initial(0.5), 1.0, 0.1, observe);
    assert!(invalid(r).contains("dimension 4"));
    let mut solver = GaussLegendre::new(1, GaussLegendreOptions::default()).unwrap();
    assert!(invalid(solver.integrate(&mut Oscillator, 0.0, &[1.0, 0.0], 1.0, 0.1, observe)).contains("dimension"));
    let mut solver = Rk4::new(3, Rk4Options::default()).unwrap();
    assert!(invalid(solver.integrate(&mut Oscillator, 0.0, &[1.0, 0.0], 1.0, 0.1, observe)).contains("dimension"));
    // Times and intervals.
    let y0 = [1.0];
    invalid(solve(&mut ExpSin, &default, 1.0, &y0, 0.5, 0.1, observe));
    invalid(solve(&mut ExpSin, &default, 0.0, &y0, 1.0, 0.0, observe));
    invalid(solve(&mut ExpSin, &default, 0.0, &y0, 1.0, f64::NAN, observe));
    invalid(solve(&mut ExpSin, &default, 0.0, &y0, f64::INFINITY, 0.1, observe));
    invalid(solve(&mut ExpSin, &default, 0.0, &[f64::NAN], 1.0, 0.1, observe));
    // Options.
    let bad_methods = [
        Method::Dop853(Dop853Options { rtol: 0.0, ..Default::default() }),
        Method::Dop853(Dop853Options { atol: -1.0, ..Default::default() }),
        Method::Dop853(Dop853Options { rtol: f64::NAN, ..Default::default() }),
        Method::Dop853(Dop853Options { initial_step: Some(0.0), ..Default::default() }),
        Method::Dop853(Dop853Options { max_step: 0.0, ..Default::default() }),
        Method::Dop853(Dop853Options { min_step: 2.0, max_step: 1.0, ..Default::default() }),
        Method::Dop853(Dop853Options { max_steps: 0, ..Default::default() }),
        Method::Dop853(Dop853Options { beta: 0.5, ..Default::default() }),
        gauss(4, 0.1, true),
        gauss(3, -0.1, true),
        gauss(3, f64::INFINITY, true),
        Method::GaussLegendre(GaussLegendreOptions { max_iterations: 0, ..Default::default() }),
        Method::Rk4(Rk4Options { step: 0.0, ..Default::default() }),
    ];
    for method in &bad_methods {
        assert!(method.validate().is_err(), "{method:?}");
        let m = invalid(solve(&mut ExpSin, method, 0.0, &y0, 1.0, 0.1, observe));
        assert!(!m.is_empty());
    }
    assert!(Method::default().validate().is_ok());
    // A zero-dimensional system cannot be integrated.
    assert!(Rk4::new(0, Rk4Options::default()).is_err());
}

#[test]
fn non_finite_derivative_is_reported() {
    struct NanAfter;
    impl OdeSystem for NanAfter {
        type Error = Infallible;
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, t: f64, _y: &[f64], dydt: &mut [f64]) -> Result<(), Infallible> {
            dydt[0] = if t < 0.3 { 1.0 } else { f64::NAN };
            Ok(())
        }
    }
    for method in [
        Method::Dop853(Dop853Options::default()),
        gauss(3, 0.01, true),
        Method::Rk4(Rk4Options { step: 0.01, ..Default::default() }),
    ] {
        let err =
            solve(&mut NanAfter, &method, 0.0, &[0.0], 1.0, 0.1, &mut |_t: f64, _y: &[f64]| ControlFlow::Continue(()))
                .unwrap_err();
        println!("{}: {err}", method.name());
        match &err {
            // DOP853 shrinks a non-finite trial step until the step is too small at t = 0.3.
            SolveError::NonFinite { t, y } | SolveError::StepSizeTooSmall { t, y, .. } => {
                assert!((0.29..=0.31).contains(t), "{}: t = {t}", method.name());
                assert!(y[0].is_finite());
            }
            other => panic!("{}: unexpected error {other:?}", method.name()),
        }
    }
}

#[test]
fn held_solvers_can_be_reused() {
    let y0 = Kepler::initial(0.5);
    let mut dop = Dop853::new(4, Dop853Options::default()).unwrap();
    let mut gl = GaussLegendre::new(4, GaussLegendreOptions { step: 0.01, ..Default::default() }).unwrap();
    let mut rk = Rk4::new(4, Rk4Options { step: 0.01, ..Default::default() }).unwrap();
    for _ in 0..2 {
        let mut last = Last::default();
        dop.integrate(&mut Kepler, 0.0, &y0, 2.0 * PI, 1.0, &mut last).unwrap();
        assert!(max_abs_diff(&last.0, &y0) < 1e-7);
        gl.integrate(&mut Kepler, 0.0, &y0, 2.0 * PI, 1.0, &mut last).unwrap();
        assert!(max_abs_diff(&last.0, &y0) < 1e-7);
        rk.integrate(&mut Kepler, 0.0, &y0, 2.0 * PI, 1.0, &mut last).unwrap();
        assert!(max_abs_diff(&last.0, &y0) < 1e-4);
    }
}

/// `y' = −1000·y` with a step of 0.1: the fixed-point iteration multiplies errors by about
/// h·λ·ρ(A) ≈ 29 per sweep, so it cannot converge; the first step fails at t0.
#[test]
fn too_large_a_gauss_step_does_not_converge() {
    struct Stiff;
    impl OdeSystem for Stiff {
        type Error = Infallible;
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Infallible> {
            dydt[0] = -1000.0 * y[0];
            Ok(())
        }
    }
    for stages in [2, 3] {
        let err = solve(&mut Stiff, &gauss(stages, 0.1, true), 0.5, &[1.0], 1.0, 0.1, &mut |_t: f64, _y: &[f64]| {
            ControlFlow::Continue(())
        })
        .unwrap_err();
        assert!(matches!(err, SolveError::NotConverged { .. }), "GL{stages}: {err:?}");
        assert_eq!(err.time(), Some(0.5));
        assert_eq!(err.state(), Some(&[1.0][..]));
        assert_eq!(err.to_string(), "implicit stage equations did not converge in the step at t = 0.5");
    }
}
