//! A body-frame dipole surface ([`Dipole`]): the optional part of a molecule that gives μ(q)
//! and ∂μ/∂q, generated or given from outside.

use nalgebra::{SMatrix, SVector, Vector3};

/// A body-frame dipole surface over `N` internal coordinates (e·bohr).
pub trait Dipole<const N: usize> {
    /// μ(q) into `mu` (overwritten).
    fn moment(&self, q: &SVector<f64, N>, mu: &mut Vector3<f64>);

    /// `∂μ/∂q` into `dmu` (overwritten): column `k` is `∂μ/∂q_k`.
    fn moment_jacobian(&self, q: &SVector<f64, N>, dmu: &mut SMatrix<f64, 3, N>);
}

impl<D: Dipole<N> + ?Sized, const N: usize> Dipole<N> for &D {
    fn moment(&self, q: &SVector<f64, N>, mu: &mut Vector3<f64>) {
        (**self).moment(q, mu)
    }
    fn moment_jacobian(&self, q: &SVector<f64, N>, dmu: &mut SMatrix<f64, 3, N>) {
        (**self).moment_jacobian(q, dmu)
    }
}
