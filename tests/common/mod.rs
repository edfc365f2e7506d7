//! Helpers shared by the workspace's integration tests: random states near a molecule's
//! reference geometry, finite differences, and matrix comparisons.
#![allow(dead_code)]

pub mod cli;
pub mod ensemble;

use rovib::runtime::nalgebra::{SMatrix, SVector};
use rovib::runtime::units::CoordinateUnit;
use rovib::runtime::{Molecule, MoleculeVisitor};

/// Runs `check` on every shipped molecule (there must be at least one).
pub fn for_each_molecule(check: impl MoleculeVisitor<Output = ()> + Copy) {
    assert!(!rovib::molecules::NAMES.is_empty());
    for name in rovib::molecules::NAMES {
        rovib::molecules::visit(name, check).expect("every listed molecule can be visited");
    }
}

#[allow(unused_imports)]
pub use rovib_testkit::Rng;

/// A random geometry near the reference: lengths within ±8 %, angles within ±0.15 rad, reflected
/// back into the coordinate's range at its ends (a linear reference, α = π, gives α in
/// [π − 0.15, π]).
pub fn random_q<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, rng: &mut Rng) -> SVector<f64, N> {
    let reference = m.reference_geometry().unwrap_or_else(|| panic!("{} has no reference geometry", m.name()));
    let coords = m.coordinates();
    SVector::from_fn(|k, _| match coords[k].unit {
        CoordinateUnit::Length(_) => reference[k] * rng.uniform(0.92, 1.08),
        CoordinateUnit::Angle(_) => {
            let (low, high) = coords[k].range;
            let x = reference[k] + rng.uniform(-0.15, 0.15);
            if x > high {
                2.0 * high - x
            } else if x < low {
                2.0 * low - x
            } else {
                x
            }
        }
    })
}

/// The step for central differences along coordinate k.
pub fn fd_step<const N: usize>(q: &SVector<f64, N>, k: usize) -> f64 {
    1e-3 * q[k].abs().max(1.0)
}

/// Fourth-order central difference of a vector-valued function along q_k.
pub fn central_difference<const N: usize, const R: usize, const C: usize>(
    q: &SVector<f64, N>,
    k: usize,
    mut f: impl FnMut(&SVector<f64, N>) -> SMatrix<f64, R, C>,
) -> SMatrix<f64, R, C> {
    let h = fd_step(q, k);
    let at = |t: f64, f: &mut dyn FnMut(&SVector<f64, N>) -> SMatrix<f64, R, C>| {
        let mut x = *q;
        x[k] += t;
        f(&x)
    };
    let (m2, m1, p1, p2) = (at(-2.0 * h, &mut f), at(-h, &mut f), at(h, &mut f), at(2.0 * h, &mut f));
    (m2 - 8.0 * m1 + 8.0 * p1 - p2) / (12.0 * h)
}

/// max |a − b| / max(max |b|, floor): a norm-wise relative difference.
pub fn rel_diff<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>, b: &SMatrix<f64, R, C>, floor: f64) -> f64 {
    if R * C == 0 {
        return 0.0;
    }
    (a - b).amax() / b.amax().max(floor)
}

use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::nalgebra::Vector3;

/// A random phase-space state near the reference geometry: momenta of a few ħ/bohr or ħ (a
/// kinetic energy of order 0.01 hartree for water), Euler angles away from gimbal lock.
pub fn random_state<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, rng: &mut Rng) -> PhaseState<N> {
    PhaseState {
        q: random_q(m, rng),
        p: SVector::from_fn(|_, _| rng.uniform(-5.0, 5.0)),
        euler: Vector3::new(rng.uniform(-3.0, 3.0), rng.uniform(0.3, 2.8), rng.uniform(-3.0, 3.0)),
        pe: Vector3::from_fn(|_, _| rng.uniform(-10.0, 10.0)),
    }
}

/// `∂f/∂y_i` at `y` by a 5-point central difference with one Richardson extrapolation
/// (error O(h⁶)), for a scalar function of a flat state.
pub fn richardson_derivative(y: &[f64], i: usize, h: f64, f: &mut dyn FnMut(&[f64]) -> f64) -> f64 {
    let mut d = |h: f64| {
        let mut x = y.to_vec();
        let mut at = |t: f64, x: &mut Vec<f64>| {
            x[i] = y[i] + t;
            f(x)
        };
        let (m2, m1, p1, p2) = (at(-2.0 * h, &mut x), at(-h, &mut x), at(h, &mut x), at(2.0 * h, &mut x));
        (m2 - 8.0 * m1 + 8.0 * p1 - p2) / (12.0 * h)
    };
    let (d1, d2) = (d(h), d(h / 2.0));
    d2 + (d2 - d1) / 15.0
}
pub mod cartesian;
pub mod internal_coordinates;
