//! Checks that the integrators allocate nothing while they run: workspaces are allocated when a
//! solver is created, never in a step or at an output time.
//!
//! Allocations are counted with the `allocation-counter` crate, which installs a counting
//! global allocator for this test binary. (Writing that allocator here would need
//! `unsafe impl GlobalAlloc`, and the workspace forbids unsafe code: `forbid` cannot be
//! lifted with `#![allow(unsafe_code)]`.) It counts the current thread only, so tests running
//! in parallel do not disturb each other.

use core::ops::ControlFlow;

use rovib_runtime::integrate::{Dop853, Dop853Options, GaussLegendre, GaussLegendreOptions, Observer, Rk4, Rk4Options};

use rovib_runtime::integrate::problems::Kepler;

/// Kepler with eccentricity 0.5 (period 2π).
const Y0: [f64; 4] = [0.5, 0.0, 0.0, 1.732_050_807_568_877_2];

/// Sums the first component over all outputs, without allocating.
struct Sum {
    count: usize,
    sum: f64,
}

impl Observer for Sum {
    fn observe(&mut self, _t: f64, y: &[f64]) -> ControlFlow<()> {
        self.count += 1;
        self.sum += y[0];
        ControlFlow::Continue(())
    }
}

/// Runs `run` once to warm up anything lazily initialised, then counts the allocations of a
/// second run; returns the count and the number of outputs of that run.
fn allocations(mut run: impl FnMut(&mut Sum)) -> (u64, usize) {
    run(&mut Sum { count: 0, sum: 0.0 });
    let mut observer = Sum { count: 0, sum: 0.0 };
    let info = allocation_counter::measure(|| run(&mut observer));
    (info.count_total, observer.count)
}

#[test]
fn dop853_does_not_allocate_while_running() {
    let mut solver = Dop853::new(4, Dop853Options::default()).unwrap();
    let (count, outputs) = allocations(|obs| {
        let stats = solver.integrate(&mut Kepler, 0.0, &Y0, 20.0, 0.01, obs).unwrap();
        assert!(stats.accepted > 100);
    });
    assert_eq!(outputs, 2001);
    assert_eq!(count, 0, "DOP853 allocated {count} times");
}

#[test]
fn gauss_legendre_does_not_allocate_while_running() {
    for stages in [2, 3] {
        for compensated in [true, false] {
            let options = GaussLegendreOptions { stages, step: 0.01, compensated, ..Default::default() };
            let mut solver = GaussLegendre::new(4, options).unwrap();
            let (count, outputs) = allocations(|obs| {
                let stats = solver.integrate(&mut Kepler, 0.0, &Y0, 20.0, 0.1, obs).unwrap();
                assert_eq!(stats.steps, 2000);
            });
            assert_eq!(outputs, 201);
            assert_eq!(count, 0, "GL{stages} allocated {count} times");
        }
    }
}

#[test]
fn rk4_does_not_allocate_while_running() {
    let mut solver = Rk4::new(4, Rk4Options { step: 0.01, ..Default::default() }).unwrap();
    let (count, outputs) = allocations(|obs| {
        let stats = solver.integrate(&mut Kepler, 0.0, &Y0, 20.0, 0.1, obs).unwrap();
        assert_eq!(stats.steps, 2000);
    });
    assert_eq!(outputs, 201);
    assert_eq!(count, 0, "RK4 allocated {count} times");
}

/// The counter works: creating a solver does allocate.
#[test]
fn creating_a_solver_allocates() {
    let info = allocation_counter::measure(|| {
        let solver = Rk4::new(4, Rk4Options::default()).unwrap();
        assert_eq!(solver.dim(), 4);
    });
    assert!(info.count_total > 0);
}
