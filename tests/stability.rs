//! Stress tests of numerical stability (the fast versions; `STABILITY.md` has the long ones and
//! the figures). This file: gimbal lock.
//!
//! The production path integrates the orientation as a unit quaternion and the body-frame
//! angular momentum J, so θ = 0 is an ordinary orientation. The proof: a trajectory that passes
//! within 1e-6 rad of θ = 0 agrees with the independent Cartesian propagation to 1e-8 bohr.

mod common;

use std::ops::ControlFlow;

use common::cartesian::{CrossCheck, cross_check};
use common::internal_coordinates;
use rovib::molecules::H2o;
use rovib::runtime::frames::CentreOfMass;
use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::hamiltonian::fast::{BodyState, ReducedSystem, Reduction, quaternion_of_euler};
use rovib::runtime::integrate::{Dop853Options, Method, OdeSystem, solve};
use rovib::runtime::nalgebra::{SVector, Vector3};

/// The state a body-formulation trajectory is in after `t`, integrated tightly.
fn evolve(state: &BodyState<3>, t: f64) -> BodyState<3> {
    let template = state.to_phase();
    let mut system = ReducedSystem::new(&H2o, Reduction::none(), &template);
    let mut y = vec![0.0; system.dim()];
    system.reduce_body(state, &mut y).unwrap();
    let copy = system;
    let mut last = None;
    let method = Method::Dop853(Dop853Options { rtol: 1e-14, atol: 1e-14, ..Default::default() });
    solve(&mut system, &method, 0.0, &y.clone(), t, t, &mut |_t: f64, y: &[f64]| {
        last = Some(copy.expand_body(y).unwrap());
        ControlFlow::Continue(())
    })
    .unwrap();
    last.unwrap()
}

/// Momenta reversed: the same path run backwards in time.
fn reversed(s: &BodyState<3>) -> BodyState<3> {
    BodyState { p: -s.p, j: -s.j, ..*s }
}

/// The trajectory of the gimbal-lock test: a state `T` before the close pass, and `T`.
fn near_pass() -> (PhaseState<3>, f64) {
    // S*: water vibrating and rotating, with its body z axis 5e-7 rad from the lab z axis.
    let star = BodyState::<3> {
        q: SVector::<f64, 3>::new(1.86, 1.79, 1.80),
        p: SVector::<f64, 3>::new(0.8, -1.1, 2.5),
        orientation: quaternion_of_euler(&Vector3::new(0.4, 5e-7, -0.9)),
        j: Vector3::new(6.0, -3.0, 2.0),
    };
    // Start T earlier on the same trajectory: reverse the momenta, run forward, reverse again.
    let t_half = 2500.0;
    (reversed(&evolve(&reversed(&star), t_half)).to_phase(), t_half)
}

#[test]
fn a_trajectory_through_gimbal_lock_agrees_with_the_cartesian_propagation() {
    let (initial, t_half) = near_pass();
    assert!(initial.euler[1].sin() > 0.1, "the run starts far from gimbal lock: θ = {}", initial.euler[1]);
    let settings = CrossCheck::dop853(2.0 * t_half, 2.5, 1e-13, 1e-14);
    let production =
        cross_check(&H2o, internal_coordinates::h2o, &initial, &CentreOfMass::AT_REST, &settings.production());
    // The seed path (Euler angles) on the same trajectory, for comparison: it survives this pass
    // (H does not depend on φ), but resolving the spin of φ and ψ near θ = 0 costs it steps.
    let seed = cross_check(&H2o, internal_coordinates::h2o, &initial, &CentreOfMass::AT_REST, &settings);
    for (name, r) in [("production", &production), ("seed", &seed)] {
        eprintln!(
            "gimbal lock, {name}: closest approach θ = {:.2e} rad, max |Δx| = {:.2e} bohr, max |Δv| = {:.2e}, \
             |ΔH| = {:.1e}, Cartesian |ΔE| = {:.1e}, {} right-hand sides over {} a.u.",
            r.min_theta,
            r.max_position_difference,
            r.max_velocity_difference,
            r.hamiltonian_energy_drift,
            r.cartesian_energy_drift,
            r.hamiltonian_stats.rhs_evals,
            2.0 * t_half
        );
    }
    assert!(production.min_theta < 1e-6, "closest approach to θ = 0 is {:e} rad", production.min_theta);
    assert!(
        production.max_position_difference < 1e-8,
        "positions differ by {:e} bohr",
        production.max_position_difference
    );
    assert!(production.hamiltonian_energy_drift < 1e-10);
    assert!(
        seed.hamiltonian_stats.rhs_evals > production.hamiltonian_stats.rhs_evals,
        "the Euler-angle path should need more work near gimbal lock"
    );
}
