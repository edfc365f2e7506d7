//! DOP853 continued from where a run stopped ([`Dop853::integrate_resumable`], then
//! [`Dop853::resume`]) repeats the uninterrupted run's steps: every later output is bit for bit
//! the uninterrupted run's. Checked on Kepler (eccentricity 0.6, tight and loose tolerances,
//! Lund stabilization on, so the controller's memory matters) and on the non-autonomous ExpSin.

use std::ops::ControlFlow;

use rovib_runtime::integrate::problems::{ExpSin, Kepler};
use rovib_runtime::integrate::{Dop853, Dop853Options, OdeSystem};

/// Every output (t, y) of a run.
type Outputs = Vec<(f64, Vec<f64>)>;

fn uninterrupted<S: OdeSystem>(s: &mut S, o: Dop853Options, y0: &[f64], t_end: f64, dt: f64) -> Outputs {
    let mut out = Vec::new();
    let mut observer = |t: f64, y: &[f64]| {
        out.push((t, y.to_vec()));
        ControlFlow::Continue(())
    };
    Dop853::new(s.dim(), o).unwrap().integrate(s, 0.0, y0, t_end, dt, &mut observer).unwrap();
    out
}

/// A run to `t_first` that stops itself after `stop_after` outputs (if given), continued to
/// `t_end`: the outputs of both parts.
fn split<S: OdeSystem>(
    s: &mut S,
    o: Dop853Options,
    y0: &[f64],
    t_first: f64,
    stop_after: Option<usize>,
    t_end: f64,
    dt: f64,
) -> Outputs {
    let mut out = Vec::new();
    let mut first = |t: f64, y: &[f64]| {
        out.push((t, y.to_vec()));
        if stop_after.is_some_and(|n| out.len() > n) { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
    };
    let mut solver = Dop853::new(s.dim(), o).unwrap();
    let (_, point) = solver.integrate_resumable(s, 0.0, y0, t_first, dt, &mut first).unwrap();
    let point = point.expect("a continuation point");
    assert_eq!(point.outputs_done as usize + 1, out.len(), "the point counts the outputs served");
    let mut rest = |t: f64, y: &[f64]| {
        out.push((t, y.to_vec()));
        ControlFlow::Continue(())
    };
    // A new solver, as a new process would have.
    let mut solver = Dop853::new(s.dim(), o).unwrap();
    solver.resume(s, 0.0, &point, t_end, dt, &mut rest).unwrap();
    out
}

/// The outputs after number `from` are identical; the earlier ones agree to `tol`.
fn same_after(full: &Outputs, split: &Outputs, from: usize, tol: f64) {
    assert_eq!(full.len(), split.len(), "as many outputs");
    for (k, ((ta, ya), (tb, yb))) in full.iter().zip(split).enumerate() {
        assert_eq!(ta, tb, "output time {k}");
        if k > from {
            assert_eq!(ya, yb, "output {k} after the continuation point");
        } else {
            for (a, b) in ya.iter().zip(yb) {
                assert!((a - b).abs() <= tol, "output {k}: {a} vs {b}");
            }
        }
    }
}

#[test]
fn kepler_continued_after_its_end_time_equals_one_run() {
    for (rtol, beta) in [(1e-12, 0.0), (1e-6, 0.04)] {
        let o = Dop853Options { rtol, atol: rtol, beta, ..Default::default() };
        let y0 = Kepler::initial(0.6);
        let full = uninterrupted(&mut Kepler, o, &y0, 20.0, 0.1);
        let parts = split(&mut Kepler, o, &y0, 10.0, None, 20.0, 0.1);
        // Outputs up to t = 10 came from the first run (its last step shortened).
        same_after(&full, &parts, 100, 1e3 * rtol);
    }
}

#[test]
fn kepler_stopped_by_its_observer_and_continued_equals_one_run_bit_for_bit() {
    for stop_after in [1, 37, 150] {
        let o = Dop853Options { rtol: 1e-9, atol: 1e-9, beta: 0.04, ..Default::default() };
        let y0 = Kepler::initial(0.6);
        let full = uninterrupted(&mut Kepler, o, &y0, 20.0, 0.1);
        let parts = split(&mut Kepler, o, &y0, 20.0, Some(stop_after), 20.0, 0.1);
        // Stopped inside a step: the continuation redoes that step, so nothing differs at all.
        same_after(&full, &parts, 0, 0.0);
    }
}

#[test]
fn a_non_autonomous_problem_continues_exactly_too() {
    let o = Dop853Options { rtol: 1e-10, atol: 1e-10, ..Default::default() };
    let full = uninterrupted(&mut ExpSin, o, &[1.0], 30.0, 0.25);
    let parts = split(&mut ExpSin, o, &[1.0], 12.5, None, 30.0, 0.25);
    same_after(&full, &parts, 50, 1e-8);
    // And against the exact solution, for scale.
    let (t, y) = parts.last().unwrap();
    assert!((y[0] - ExpSin::exact(*t)).abs() < 1e-8);
}
