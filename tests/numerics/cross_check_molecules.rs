//! Every shipped molecule with internal coordinates against the independent Cartesian
//! molecular-dynamics propagation (`tests/common/cartesian.rs`): the same checks `tests/cartesian.rs`
//! makes of water, on a shorter trajectory of each, rotating, from a random state near its
//! reference geometry, integrated by the production path (`rovib run`'s system).
//!
//! The rigid molecule has no internal coordinates and cannot be propagated as free atoms
//! (that needs constraint forces); its rotation is checked against the seed path in
//! `tests/fast_path.rs` and by its conserved H, |J| and L in `tests/scenes.rs`.

use crate::common;

use common::cartesian::{CrossCheck, cross_check};
use common::internal_coordinates::{self, Dual, V3};
use common::{Rng, random_state};
use rovib::molecules::{Ch4, Co2, Ethane, H2o2, Nh3};
use rovib::runtime::Molecule;
use rovib::runtime::frames::CentreOfMass;
use rovib::runtime::nalgebra::Vector3;

fn check<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, q_of_x: fn(&[V3<Dual>]) -> Vec<Dual>, seed: u64) {
    let mut rng = Rng::new(seed);
    let mut initial = random_state(m, &mut rng);
    // Moderate momenta: a few hundred cm⁻¹ of kinetic energy per mode for these masses.
    initial.p *= 0.5;
    let com = CentreOfMass { position: Vector3::new(0.5, -0.3, 0.2), velocity: Vector3::new(2e-5, -1e-5, 3e-5) };
    // 10⁴ a.u. ≈ 242 fs: four periods of CO2's bend (672 cm⁻¹), two of H2O2's torsion.
    let t_end = 10_000.0;
    let settings = CrossCheck::dop853(t_end, 10.0, 1e-13, 1e-14).production();
    let r = cross_check(m, q_of_x, &initial, &com, &settings);
    eprintln!(
        "{}: {t_end} a.u., |L| = {:.2} ħ: max |Δx| = {:.2e} bohr, max |Δv| = {:.2e}, q(x(0)) − q = {:.1e}, \
         Hamiltonian |ΔH| = {:.1e} Eh, Cartesian |ΔE| = {:.1e} Eh, |ΔL| = {:.1e} ħ, {} right-hand sides",
        m.name(),
        r.angular_momentum,
        r.max_position_difference,
        r.max_velocity_difference,
        r.initial_q_mismatch,
        r.hamiltonian_energy_drift,
        r.cartesian_energy_drift,
        r.cartesian_angular_momentum_drift,
        r.hamiltonian_stats.rhs_evals
    );
    assert!(r.initial_q_mismatch < 1e-12, "{}: q(x) does not invert the parametrization", m.name());
    assert!(r.angular_momentum > 1.0, "{}: the molecule should rotate", m.name());
    assert!(r.max_position_difference < 1e-8, "{}: positions differ by {:e} bohr", m.name(), r.max_position_difference);
    assert!(r.hamiltonian_energy_drift < 1e-10, "{}: H drifts by {:e}", m.name(), r.hamiltonian_energy_drift);
    assert!(r.cartesian_angular_momentum_drift < 1e-8, "{}: L drifts", m.name());
}

#[test]
fn co2_agrees_with_cartesian_dynamics() {
    check(&Co2, internal_coordinates::co2, 21);
}

#[test]
fn h2o2_agrees_with_cartesian_dynamics() {
    check(&H2o2, internal_coordinates::h2o2, 22);
}

#[test]
fn nh3_agrees_with_cartesian_dynamics() {
    check(&Nh3, internal_coordinates::nh3, 23);
}

#[test]
fn ch4_agrees_with_cartesian_dynamics() {
    check(&Ch4, internal_coordinates::ch4, 24);
}

/// The largest shipped molecule (18 coordinates): its sparse generated kinetic code and the
/// production path against free atoms.
#[test]
fn ethane_agrees_with_cartesian_dynamics() {
    check(&Ethane, internal_coordinates::ethane, 25);
}
