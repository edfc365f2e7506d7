//! The kinetic matrices of a molecule at one geometry ([`KineticMatrices`]): what the
//! generated kinematics fill, the lanes carry and the Hamiltonian reads.

use nalgebra::{Matrix3, SMatrix};

/// The kinetic matrices `a` (n × n), `A` (3 × n) and `I` (3 × 3) of the seed's eq. (3), or one
/// q-derivative of all three.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct KineticMatrices<const N: usize> {
    /// The vibrational kinetic matrix `a` (symmetric).
    pub a: SMatrix<f64, N, N>,
    /// The Coriolis matrix `A`.
    pub coriolis: SMatrix<f64, 3, N>,
    /// The inertia tensor `I` (symmetric).
    pub inertia: Matrix3<f64>,
}

impl<const N: usize> Default for KineticMatrices<N> {
    fn default() -> Self {
        Self { a: SMatrix::zeros(), coriolis: SMatrix::zeros(), inertia: Matrix3::zeros() }
    }
}
