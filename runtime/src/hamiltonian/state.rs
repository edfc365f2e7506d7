//! The phase-space state `(q, p, Ω_e, p_e)` and its flat layout for the integrators.

use nalgebra::{SVector, Vector3};

use super::HamiltonianError;

/// A point of phase space: internal coordinates and momenta, Euler angles and their momenta.
///
/// The same type also holds a time derivative of a state (what [`super::rhs`] returns), with
/// every field replaced by its rate of change.
///
/// # Flat layout
///
/// Integrators see the state as one `&[f64]` of length [`PhaseState::DIM`] `= 2N + 6`:
///
/// ```text
/// [ q_1 … q_N | p_1 … p_N | φ θ ψ | p_φ p_θ p_ψ ]
/// ```
///
/// All in atomic units: q in bohr or rad, p in ħ/bohr or ħ (ħ = 1), angles in rad, `p_e` in ħ.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PhaseState<const N: usize> {
    /// Internal coordinates `q`, in the molecule's coordinate order.
    pub q: SVector<f64, N>,
    /// Momenta `p` conjugate to `q`.
    pub p: SVector<f64, N>,
    /// Euler angles `(φ, θ, ψ)` of the z-x-z convention (see [`super::euler`]).
    pub euler: Vector3<f64>,
    /// Momenta `(p_φ, p_θ, p_ψ)` conjugate to the Euler angles.
    pub pe: Vector3<f64>,
}

impl<const N: usize> Default for PhaseState<N> {
    fn default() -> Self {
        Self::zeros()
    }
}

impl<const N: usize> PhaseState<N> {
    /// Length of the flat layout: `2N + 6`.
    pub const DIM: usize = 2 * N + 6;

    /// The state with every component zero.
    pub fn zeros() -> Self {
        Self { q: SVector::zeros(), p: SVector::zeros(), euler: Vector3::zeros(), pe: Vector3::zeros() }
    }

    /// Writes the state into `y` in the flat layout `[q, p, φ, θ, ψ, p_φ, p_θ, p_ψ]`.
    ///
    /// Fails (without writing) if `y.len() != 2N + 6`.
    pub fn write_to(&self, y: &mut [f64]) -> Result<(), HamiltonianError> {
        check_len::<N>(y.len())?;
        let (q, rest) = y.split_at_mut(N);
        let (p, rest) = rest.split_at_mut(N);
        let (euler, pe) = rest.split_at_mut(3);
        q.copy_from_slice(self.q.as_slice());
        p.copy_from_slice(self.p.as_slice());
        euler.copy_from_slice(self.euler.as_slice());
        pe.copy_from_slice(self.pe.as_slice());
        Ok(())
    }

    /// Reads a state from the flat layout `[q, p, φ, θ, ψ, p_φ, p_θ, p_ψ]`.
    ///
    /// Fails if `y.len() != 2N + 6`. The values are not checked here: non-finite entries are
    /// reported by the functions that evaluate the Hamiltonian.
    pub fn read_from(y: &[f64]) -> Result<Self, HamiltonianError> {
        check_len::<N>(y.len())?;
        Ok(Self {
            q: SVector::from_column_slice(&y[..N]),
            p: SVector::from_column_slice(&y[N..2 * N]),
            euler: Vector3::from_column_slice(&y[2 * N..2 * N + 3]),
            pe: Vector3::from_column_slice(&y[2 * N + 3..2 * N + 6]),
        })
    }

    /// Fails with [`HamiltonianError::NonFinite`] naming the first block that holds NaN or ±∞.
    pub fn check_finite(&self) -> Result<(), HamiltonianError> {
        let blocks: [(&'static str, &[f64]); 4] = [
            ("internal coordinates q", self.q.as_slice()),
            ("internal momenta p", self.p.as_slice()),
            ("Euler angles (φ, θ, ψ)", self.euler.as_slice()),
            ("Euler momenta (p_φ, p_θ, p_ψ)", self.pe.as_slice()),
        ];
        for (quantity, values) in blocks {
            if !values.iter().all(|v| v.is_finite()) {
                return Err(HamiltonianError::NonFinite { quantity });
            }
        }
        Ok(())
    }
}

fn check_len<const N: usize>(found: usize) -> Result<(), HamiltonianError> {
    if found == PhaseState::<N>::DIM {
        Ok(())
    } else {
        Err(HamiltonianError::DimensionMismatch { expected: PhaseState::<N>::DIM, found })
    }
}
