//! Checks that evaluating the seed right-hand side never allocates.
//!
//! Allocations are counted with the `allocation-counter` dev-dependency, which installs a
//! counting global allocator in this test binary. (A hand-written one would need
//! `unsafe impl GlobalAlloc`, and the workspace's `unsafe_code = "forbid"` cannot be relaxed
//! per file.) It counts the current thread only, so the test harness's threads cannot disturb
//! the count.

mod common;

use common::{RigidTop, Rng, Water, random_euler, random_vector, random_water_q};
use rovib_runtime::hamiltonian::{self, HamiltonianSystem, PhaseState, Workspace};
use rovib_runtime::integrate::OdeSystem;

#[test]
fn rhs_evaluations_do_not_allocate() {
    let mut rng = Rng::new(42);
    let states: Vec<PhaseState<3>> = (0..200)
        .map(|_| PhaseState {
            q: random_water_q(&mut rng),
            p: random_vector(&mut rng, 5.0),
            euler: random_euler(&mut rng),
            pe: random_vector(&mut rng, 10.0),
        })
        .collect();
    let flat: Vec<Vec<f64>> = states
        .iter()
        .map(|s| {
            let mut y = vec![0.0; PhaseState::<3>::DIM];
            s.write_to(&mut y).unwrap();
            y
        })
        .collect();
    // Everything that may allocate is created before the counted region.
    let mut workspace = Workspace::default();
    let mut system = HamiltonianSystem::new(&Water);
    let mut rigid = HamiltonianSystem::new(&RigidTop);
    let mut dydt = vec![0.0; PhaseState::<3>::DIM];
    let mut dydt_rigid = [0.0; 6];
    let mut sum = 0.0;

    let info = allocation_counter::measure(|| {
        for _ in 0..5 {
            for (s, y) in states.iter().zip(&flat) {
                let d = hamiltonian::rhs(&Water, s, &mut workspace).unwrap();
                sum += d.p[0];
                system.rhs(0.0, y, &mut dydt).unwrap();
                sum += dydt[0];
                sum += system.energy(y).unwrap();
                let (omega, _) = hamiltonian::velocities(&Water, s).unwrap();
                sum += omega[0];
                // The rigid top reads the last six components (Euler angles and momenta).
                rigid.rhs(0.0, &y[6..], &mut dydt_rigid).unwrap();
                sum += dydt_rigid[2];
            }
        }
    });
    assert!(sum.is_finite());
    assert_eq!(info.count_total, 0, "{} allocations in 2000 right-hand-side evaluations", info.count_total);

    // The counter does see this code's allocations: building an error allocates (its q).
    let mut linear = states[0];
    linear.q[2] = core::f64::consts::PI;
    let info = allocation_counter::measure(|| {
        assert!(hamiltonian::rhs(&Water, &linear, &mut workspace).is_err());
    });
    assert!(info.count_total > 0);
}
