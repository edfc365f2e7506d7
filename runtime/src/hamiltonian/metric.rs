//! The G matrices of the seed's eq. (3) (blocks of the inverse kinetic metric) and their
//! q-derivatives, eqs. (9)–(14).
//!
//! The full kinetic metric is `M = [[I, A], [Aᵀ, a]]` and `M⁻¹ = [[G11, G12], [G12ᵀ, G22]]`.
//! Every product with `a⁻¹` or `I⁻¹` is done with a Cholesky factorization (a solve, not an
//! explicit inverse): it is cheaper, more accurate, and its pivots tell whether a block is
//! positive definite. Only `G11` and `G22` themselves are formed as inverses, because they are
//! outputs.

use nalgebra::{Cholesky, Const, Matrix3, SMatrix, SVector};

use super::HamiltonianError;
use crate::molecule::KineticMatrices;

/// A Cholesky pivot (the square of a diagonal element of the factor) below this fraction of its
/// reference scale counts as zero: the block is reported singular.
///
/// An exactly singular block (a linear molecule's inertia tensor, coinciding atoms) comes out of
/// the arithmetic with a pivot of a few ε times the scale, often positive, so testing for `> 0`
/// alone would let it through with a meaningless ~1e16 inverse. Since every pivot is at least
/// the smallest eigenvalue, this is a cheap guard against such blocks, not a full
/// condition-number estimate. The reference scale is `trace I` for `I` and `G11⁻¹` (all in one
/// unit, and a vanishing moment of inertia must be seen relative to the others), and the matching
/// diagonal element of `a` for `a` and `G22⁻¹` (internal coordinates may mix bohr and rad, so
/// they are compared one by one).
pub const PIVOT_TOLERANCE: f64 = 1e-12;

/// Which block of the kinetic metric is singular or not positive definite.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum MetricBlock {
    /// The inertia tensor `I` (singular when the atoms are collinear or coincide).
    Inertia,
    /// The vibrational kinetic matrix `a` (singular when the coordinates are redundant or one
    /// of them moves no atom).
    Vibrational,
    /// `G11⁻¹ = I − A a⁻¹ Aᵀ`, the Schur complement of `a` in the full metric.
    G11Inverse,
    /// `G22⁻¹ = a − Aᵀ I⁻¹ A`, the Schur complement of `I` in the full metric (the inverse of
    /// Wilson's G matrix).
    G22Inverse,
}

impl core::fmt::Display for MetricBlock {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            MetricBlock::Inertia => "inertia tensor I",
            MetricBlock::Vibrational => "vibrational kinetic matrix a",
            MetricBlock::G11Inverse => "matrix G11⁻¹ = I − A a⁻¹ Aᵀ",
            MetricBlock::G22Inverse => "matrix G22⁻¹ = a − Aᵀ I⁻¹ A (inverse Wilson G matrix)",
        })
    }
}

/// The blocks `G11` (3 × 3), `G12` (3 × N), `G22` (N × N) of the inverse kinetic metric, or one
/// q-derivative of them.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct GMatrices<const N: usize> {
    /// `G11 = (I − A a⁻¹ Aᵀ)⁻¹` (symmetric): rotational block.
    pub g11: Matrix3<f64>,
    /// `G12 = −G11 A a⁻¹ = −I⁻¹ A G22`: rotation–vibration coupling block.
    pub g12: SMatrix<f64, 3, N>,
    /// `G22 = (a − Aᵀ I⁻¹ A)⁻¹` (symmetric): vibrational block, Wilson's G matrix.
    pub g22: SMatrix<f64, N, N>,
}

/// The G matrices at one q together with the factorizations that their q-derivatives reuse.
#[derive(Copy, Clone, Debug)]
pub struct InverseMetric<const N: usize> {
    /// `G11`, `G12`, `G22`.
    pub g: GMatrices<N>,
    /// Cholesky factor of `a`, for the products with `a⁻¹` in eq. (14).
    chol_a: Cholesky<f64, Const<N>>,
    /// `X = a⁻¹ Aᵀ` (N × 3).
    a_inv_at: SMatrix<f64, N, 3>,
    /// `Y = I⁻¹ A` (3 × N).
    i_inv_a: SMatrix<f64, 3, N>,
}

impl<const N: usize> InverseMetric<N> {
    /// Computes `G11`, `G12`, `G22` from `a`, `A`, `I` (eq. 3).
    ///
    /// `q` is only used to report where a block is singular or not positive definite
    /// ([`HamiltonianError::SingularMetric`]); the blocks are checked in the order `I`, `a`,
    /// `G11⁻¹`, `G22⁻¹`. Non-finite input gives [`HamiltonianError::NonFinite`].
    pub fn new(k: &KineticMatrices<N>, q: &SVector<f64, N>) -> Result<Self, HamiltonianError> {
        if !(all_finite(k.a.as_slice()) && all_finite(k.coriolis.as_slice()) && all_finite(k.inertia.as_slice())) {
            return Err(HamiltonianError::NonFinite { quantity: "kinetic matrices a, A, I" });
        }
        let inertia_scale = k.inertia.trace();
        let chol_i = factor(k.inertia, |_| inertia_scale, MetricBlock::Inertia, q)?;
        let chol_a = factor(k.a, |j| k.a[(j, j)], MetricBlock::Vibrational, q)?;

        let a_inv_at = chol_a.solve(&k.coriolis.transpose());
        let i_inv_a = chol_i.solve(&k.coriolis);

        // G11 = (I − A a⁻¹ Aᵀ)⁻¹. Symmetrized so that rounding does not make it asymmetric.
        let g11_inv = symmetric_part(&(k.inertia - k.coriolis * a_inv_at));
        let g11 = symmetric_part(&factor(g11_inv, |_| inertia_scale, MetricBlock::G11Inverse, q)?.inverse());
        // G22 = (a − Aᵀ I⁻¹ A)⁻¹.
        let g22_inv = symmetric_part(&(k.a - k.coriolis.transpose() * i_inv_a));
        let g22 = symmetric_part(&factor(g22_inv, |j| k.a[(j, j)], MetricBlock::G22Inverse, q)?.inverse());
        // G12 = −G11 A a⁻¹ = −G11 Xᵀ.
        let g12 = -(g11 * a_inv_at.transpose());

        Ok(Self { g: GMatrices { g11, g12, g22 }, chol_a, a_inv_at, i_inv_a })
    }

    /// The derivatives `∂G11/∂q_k`, `∂G12/∂q_k`, `∂G22/∂q_k` of eqs. (10)–(14), given
    /// `dk = (∂a/∂q_k, ∂A/∂q_k, ∂I/∂q_k)` at the same q.
    ///
    /// With `X = a⁻¹ Aᵀ` and `Y = I⁻¹ A` the seed's brackets read
    ///
    /// ```text
    /// ∂G11 = −G11 [∂I − ∂A X − (∂A X)ᵀ + Xᵀ ∂a X] G11                      (10)–(12)
    /// ∂G22 = −G22 [∂a − ∂Aᵀ Y − (∂Aᵀ Y)ᵀ + Yᵀ ∂I Y] G22                    (13)
    /// ∂G12 = −∂G11 Xᵀ − G11 (a⁻¹ (∂Aᵀ − ∂a X))ᵀ                            (14)
    /// ```
    ///
    /// (in (14), `G11 ∂A a⁻¹ = G11 (a⁻¹ ∂Aᵀ)ᵀ` and `G11 A a⁻¹ ∂a a⁻¹ = G11 (a⁻¹ ∂a X)ᵀ`, using
    /// that `a` is symmetric). The seed's eq. (15) is not used: it is dimensionally wrong.
    pub fn derivative(&self, dk: &KineticMatrices<N>) -> GMatrices<N> {
        let GMatrices { g11, g22, .. } = self.g;
        let x = &self.a_inv_at;
        let y = &self.i_inv_a;

        let da_x = dk.coriolis * x; // ∂A a⁻¹ Aᵀ (3 × 3)
        let bracket11 = dk.inertia - da_x - da_x.transpose() + x.transpose() * dk.a * x;
        let dg11 = symmetric_part(&(-(g11 * bracket11 * g11)));

        let dat_y = dk.coriolis.transpose() * y; // ∂Aᵀ I⁻¹ A (N × N)
        let bracket22 = dk.a - dat_y - dat_y.transpose() + y.transpose() * dk.inertia * y;
        let dg22 = symmetric_part(&(-(g22 * bracket22 * g22)));

        let inner = self.chol_a.solve(&(dk.coriolis.transpose() - dk.a * x)); // N × 3
        let dg12 = -(dg11 * x.transpose()) - g11 * inner.transpose();

        GMatrices { g11: dg11, g12: dg12, g22: dg22 }
    }
}

fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn symmetric_part<const D: usize>(m: &SMatrix<f64, D, D>) -> SMatrix<f64, D, D> {
    (m + m.transpose()) * 0.5
}

/// Cholesky-factors the symmetric `m`, failing unless every pivot `L_jj²` exceeds
/// [`PIVOT_TOLERANCE`] times `scale(j)`; `q` only goes into the error.
fn factor<const D: usize, const N: usize>(
    m: SMatrix<f64, D, D>,
    scale: impl Fn(usize) -> f64,
    matrix: MetricBlock,
    q: &SVector<f64, N>,
) -> Result<Cholesky<f64, Const<D>>, HamiltonianError> {
    let singular = || HamiltonianError::SingularMetric { matrix, q: q.as_slice().to_vec() };
    // `Cholesky::new` only fails on a non-positive pivot; the tolerance catches the
    // numerically singular case too (see PIVOT_TOLERANCE).
    let chol = Cholesky::new(m).ok_or_else(singular)?;
    let l = chol.l_dirty();
    for j in 0..D {
        let pivot = l[(j, j)] * l[(j, j)];
        if pivot <= PIVOT_TOLERANCE * scale(j) {
            return Err(singular());
        }
    }
    Ok(chol)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rigid_molecule_has_g11_equal_to_the_inverse_inertia() {
        let k = KineticMatrices::<0> {
            inertia: Matrix3::new(4.0, 1.0, 0.0, 1.0, 3.0, 0.5, 0.0, 0.5, 2.0),
            ..KineticMatrices::default()
        };
        let g = InverseMetric::new(&k, &SVector::zeros()).unwrap().g;
        let i_inv = k.inertia.try_inverse().unwrap();
        assert!((g.g11 - i_inv).abs().max() < 1e-15);
    }

    #[test]
    fn numerically_singular_inertia_is_rejected() {
        // Positive definite in floating point (Cholesky succeeds), singular in substance.
        let k = KineticMatrices::<0> {
            inertia: Matrix3::from_diagonal(&nalgebra::Vector3::new(1e4, 1e4, 1e-10)),
            ..KineticMatrices::default()
        };
        assert!(Cholesky::new(k.inertia).is_some());
        assert_eq!(
            InverseMetric::new(&k, &SVector::zeros()).unwrap_err(),
            HamiltonianError::SingularMetric { matrix: MetricBlock::Inertia, q: vec![] }
        );
    }
}
