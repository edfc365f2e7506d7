//! Parts of the kinetic matrices that generated code for large molecules leaves to the runtime.
//!
//! With the centre of mass `c = Σ_i m_i r_i / M` applied numerically (`docs/src/reference/equations.md`,
//! "Sparse assembly"), the vibrational matrix is
//!
//! ```text
//! a_jk = Σ_i m_i ∂r_i/∂q_j · ∂r_i/∂q_k − M ∂c/∂q_j · ∂c/∂q_k,
//! ```
//!
//! a structurally sparse sum over atoms (each atom depends on a few coordinates for local,
//! Z-matrix-like coordinates) minus a dense rank-3 term. Expanded, the dense term is
//! `n(n + 1)/2` expressions of 7 operations each, a fifth of hexane's generated production
//! code; as the loop below it is `3n²` multiply-adds over contiguous columns. The generator
//! emits the sparse sum and `∂c/∂q` and calls [`remove_centre_of_mass`] from `Kinematics::kinetic`
//! and `Kinematics::kinetic_and_gradient` for molecules with at least
//! `rovib_codegen::kinetic::RUN_TIME_CENTRE_OF_MASS_FROM` coordinates; smaller ones keep the
//! expanded form.

use nalgebra::{SMatrix, SVector, Vector3};

use crate::molecule::KineticMatrices;

/// The velocities callback of a large molecule's generated `kinetic_and_gradient_sparse`:
/// `(ω, q̇)` from the finished kinetic matrices, or `None` (the generic
/// `Kinematics::kinetic_and_gradient` wrapper keeps the error). `dyn`, so that the large
/// generated body is compiled once rather than once per caller.
pub type Velocities<'a, const N: usize> =
    dyn FnMut(&KineticMatrices<N>) -> Option<(Vector3<f64>, SVector<f64, N>)> + 'a;

/// `a_jk −= total · dc_·j · dc_·k` for every entry: the centre-of-mass term of `a`, with `dc`
/// column `k` = `∂c/∂q_k` and `total` the total mass: the arithmetic of the expanded expression
/// it replaces (`a − M (x₀y₀ + x₁y₁ + x₂y₂)`), on the lower triangle, mirrored to the upper
/// (`a` must be symmetric on entry; it stays exactly symmetric).
#[inline]
pub fn remove_centre_of_mass<const N: usize>(a: &mut SMatrix<f64, N, N>, dc: &SMatrix<f64, 3, N>, total: f64) {
    // The three rows of dc as contiguous arrays, so that the inner loop runs over contiguous
    // memory; the lower triangle is computed and mirrored.
    let mut rows = [[0.0f64; N]; 3];
    for j in 0..N {
        for axis in 0..3 {
            rows[axis][j] = dc[(axis, j)];
        }
    }
    for k in 0..N {
        let (x0, x1, x2) = (rows[0][k], rows[1][k], rows[2][k]);
        for j in k..N {
            a[(j, k)] -= total * (rows[0][j] * x0 + rows[1][j] * x1 + rows[2][j] * x2);
        }
        for j in k + 1..N {
            a[(k, j)] = a[(j, k)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the same term written out with nalgebra's products: `a − M dcᵀ dc`.
    #[test]
    fn the_update_is_a_minus_m_dct_dc() {
        let dc = SMatrix::<f64, 3, 4>::from_fn(|i, j| (i as f64 + 1.0) * 0.3 - j as f64 * 0.7 + 0.11);
        let a0 = SMatrix::<f64, 4, 4>::from_fn(|i, j| 5.0 + (i + j) as f64 + if i == j { 10.0 } else { 0.0 });
        let mut a = a0;
        remove_centre_of_mass(&mut a, &dc, 2.5);
        let expected = a0 - 2.5 * dc.transpose() * dc;
        assert!((a - expected).amax() < 1e-12, "{a} vs {expected}");
        assert_eq!(a, a.transpose());
    }
}
