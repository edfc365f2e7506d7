//! Checks that the integrators allocate nothing while they run: workspaces are allocated when a
//! solver is created, never in a step or at an output time.
//!
//! Allocations are counted with the `allocation-counter` crate, which installs a counting
//! global allocator for this test binary. (Writing that allocator here would need
//! `unsafe impl GlobalAlloc`, and the workspace forbids unsafe code: `forbid` cannot be
//! lifted with `#![allow(unsafe_code)]`.) It counts the current thread only, so tests running
//! in parallel do not disturb each other.

use core::ops::ControlFlow;

use rovib_runtime::integrate::{
    Dop853, Dop853Lanes, Dop853Options, GaussLegendre, GaussLegendreOptions, LaneFailure, LaneFeeder, LaneSystem,
    Observer, Rk4, Rk4Options, Stats,
};
use rovib_runtime::lanes::{F64x4, Real};

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

/// Kepler on lanes, each lane its own orbit.
struct KeplerLanes;

impl<T: Real> LaneSystem<T> for KeplerLanes {
    fn dim(&self) -> usize {
        4
    }
    fn rhs(&mut self, _t: T, y: &[T], dydt: &mut [T]) -> u32 {
        let r = (y[0] * y[0] + y[1] * y[1]).sqrt();
        let r3 = r * r * r;
        dydt[0] = y[2];
        dydt[1] = y[3];
        dydt[2] = -y[0] / r3;
        dydt[3] = -y[1] / r3;
        T::ALL
    }
}

/// Ten orbits of eccentricities 0.1 … 0.55, fed to the lanes without allocating.
struct Orbits {
    next: usize,
    outputs: usize,
    finished: usize,
}

impl LaneFeeder for Orbits {
    fn next(&mut self, _lane: usize, y0: &mut [f64]) -> bool {
        if self.next == 10 {
            return false;
        }
        y0.copy_from_slice(&Kepler::initial(0.1 + 0.05 * self.next as f64));
        self.next += 1;
        true
    }
    fn observe(&mut self, _lane: usize, _t: f64, _y: &[f64]) -> ControlFlow<()> {
        self.outputs += 1;
        ControlFlow::Continue(())
    }
    fn finish(&mut self, _lane: usize, result: Result<Stats, LaneFailure>) {
        assert!(result.is_ok());
        self.finished += 1;
    }
}

/// The batched DOP853 allocates nothing while it runs, including when a lane takes its next
/// trajectory (the starting-step estimate of each new trajectory included).
#[test]
fn batched_dop853_does_not_allocate_while_running() {
    let mut solver = Dop853Lanes::<F64x4>::new(4, Dop853Options::default()).unwrap();
    let mut run = || {
        let mut feeder = Orbits { next: 0, outputs: 0, finished: 0 };
        solver.integrate(&mut KeplerLanes, 0.0, 20.0, 0.1, &mut feeder).unwrap();
        feeder
    };
    run();
    let mut feeder = None;
    let info = allocation_counter::measure(|| feeder = Some(run()));
    let feeder = feeder.unwrap();
    assert_eq!((feeder.finished, feeder.outputs), (10, 10 * 201));
    assert_eq!(info.count_total, 0, "the batched DOP853 allocated {} times", info.count_total);
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

#[test]
fn the_integrator_of_every_method_does_not_allocate_while_running_and_equals_solve() {
    use rovib_runtime::integrate::{Integrator, Method, solve};
    let methods = [
        Method::Dop853(Dop853Options::default()),
        Method::GaussLegendre(GaussLegendreOptions { stages: 3, step: 0.01, ..Default::default() }),
        Method::Rk4(Rk4Options { step: 0.01, ..Default::default() }),
    ];
    for method in methods {
        let mut integrator = Integrator::new(&method, 4).unwrap();
        let (count, outputs) = allocations(|obs| {
            integrator.integrate(&mut Kepler, 0.0, &Y0, 20.0, 0.1, obs).unwrap();
        });
        assert_eq!(outputs, 201);
        assert_eq!(count, 0, "{method:?} allocated {count} times");
        // The same numbers as the one-shot `solve`, bit for bit.
        let (mut a, mut b) = (Sum { count: 0, sum: 0.0 }, Sum { count: 0, sum: 0.0 });
        integrator.integrate(&mut Kepler, 0.0, &Y0, 20.0, 0.1, &mut a).unwrap();
        solve(&mut Kepler, &method, 0.0, &Y0, 20.0, 0.1, &mut b).unwrap();
        assert_eq!(a.sum.to_bits(), b.sum.to_bits(), "{method:?}");
    }
}
