//! The block factorization of the kinetic metric `M = [[I, A], [Aᵀ, a]]` that the fast paths
//! solve with: `I⁻¹` in closed form and the Schur complement `S = a − Aᵀ I⁻¹ A` as `L D Lᵀ`
//! ([`MetricFactor`]), with the pivot tests that make a singular or ill-conditioned metric an
//! error naming its block.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use super::HamiltonianError;
use super::factor_large;
use super::finite::all_finite;
use super::metric::{InverseMetric, MetricBlock, PIVOT_TOLERANCE};
use crate::molecule::KineticMatrices;

/// The block factorization of the full kinetic metric `M = [[I, A], [Aᵀ, a]]`:
///
/// ```text
/// M = [[1, 0], [Yᵀ, 1]] · [[I, 0], [0, S]] · [[1, Y], [0, 1]],   Y = I⁻¹ A,
/// S = a − Aᵀ I⁻¹ A = a − Aᵀ Y = G22⁻¹,
/// ```
///
/// with `I⁻¹` in closed form (adjugate over determinant) and `S` factored as `L D Lᵀ` (unit
/// lower-triangular `L`, diagonal `D`: the square-root-free form of Cholesky, with the same
/// pivots `D_jj = L_jj²`). Then
///
/// ```text
/// M⁻¹ (J, p):   q̇ = S⁻¹ (p − Yᵀ J),   ω = I⁻¹ J − Y q̇.
/// ```
///
/// `M` is positive definite iff `I` and `S` are, so these two are the whole
/// positive-definiteness check. Pivots are tested against [`PIVOT_TOLERANCE`] with the G-matrix
/// path's scales (`trace I` for `I`, `a_jj` for `S`); `I`'s Cholesky pivots are ratios of its leading
/// principal minors, `D₁ = m₁`, `D₂ = m₂/m₁`, `D₃ = m₃/m₂`, so they are tested as
/// `m_j > tol · scale · m_{j−1}` without dividing.
///
/// Why this form: on these tiny blocks the cost is latency, not flops, and a division or square
/// root costs ~15–20 cycles of latency against ~4 for a multiplication. A textbook Cholesky
/// with triangular solves put some 25 dependent divisions and square roots on water's critical
/// path (measured: ~180 ns of a ~400 ns evaluation); here `I` costs one division, `S` one per
/// pivot, and the solves none. (For a 3 × 3 symmetric positive definite `I` the adjugate
/// formula's error grows with the condition number like that of any inverse, and its
/// cofactors do not cancel catastrophically unless `I` is close to singular, which the pivot
/// test rejects; the tests compare the result with the G-matrix path's Cholesky-based inverse to 1e-12
/// for every shipped molecule.)
#[derive(Copy, Clone, Debug)]
pub struct MetricFactor<const N: usize> {
    /// `I⁻¹`.
    i_inv: Matrix3<f64>,
    /// `Y = I⁻¹ A` (3 × N).
    y: SMatrix<f64, 3, N>,
    /// `S = L₂ D₂ L₂ᵀ`: `L₂` in the strict lower triangle (for `N ≥ LARGE_BLOCK` computed by
    /// columns, with a transposed copy in the strict upper triangle, `factor_large`).
    l2: SMatrix<f64, N, N>,
    /// `1 / D₂`.
    d2_inv: SVector<f64, N>,
}

impl<const N: usize> MetricFactor<N> {
    /// Factors the metric of `k`; `q` only goes into the error.
    ///
    /// Fails with [`HamiltonianError::NonFinite`] for non-finite matrices and
    /// [`HamiltonianError::SingularMetric`] (naming the block as the G-matrix path's
    /// [`InverseMetric::new`] does) when `M` is singular or not positive definite.
    // Always inlined: called once per evaluation, and inlining lets the factor live in
    // registers instead of being copied out through the `Result` (measured ~5 % of water's rhs).
    #[inline(always)]
    pub fn new(k: &KineticMatrices<N>, q: &SVector<f64, N>) -> Result<Self, HamiltonianError> {
        Self::with_tolerance(k, q, PIVOT_TOLERANCE)
    }

    /// [`MetricFactor::new`] with a stricter test of the pivots: every relative pivot (pivot
    /// over `trace I` for `I`, over `a_jj` for `S`) must exceed `min_pivot`. A metric that
    /// passes [`PIVOT_TOLERANCE`] but not `min_pivot` fails with
    /// [`HamiltonianError::IllConditionedMetric`], which names the block and its smallest
    /// relative pivot: how a run stops when a molecule approaches a singular geometry (a
    /// triatomic bending to linear) before the equations lose accuracy.
    #[inline(always)]
    pub fn with_tolerance(
        k: &KineticMatrices<N>,
        q: &SVector<f64, N>,
        min_pivot: f64,
    ) -> Result<Self, HamiltonianError> {
        let tol = min_pivot.max(PIVOT_TOLERANCE);
        if !(all_finite(k.a.as_slice()) & all_finite(k.coriolis.as_slice()) & all_finite(k.inertia.as_slice())) {
            return Err(HamiltonianError::NonFinite { quantity: "kinetic matrices a, A, I" });
        }
        let Some(i_inv) = inverse_spd3(&k.inertia, tol) else {
            return Err(metric_failure(k, q, MetricBlock::Inertia, tol));
        };
        let y = i_inv * k.coriolis;
        // S = a − Aᵀ Y, lower triangle only (the factorization reads nothing else).
        let mut l2 = k.a;
        let a = &k.coriolis;
        for j in 0..N {
            for i in j..N {
                l2[(i, j)] -= a[(0, i)] * y[(0, j)] + a[(1, i)] * y[(1, j)] + a[(2, i)] * y[(2, j)];
            }
        }
        let Some(d2_inv) = ldl_in_place(&mut l2, |j| k.a[(j, j)], tol) else {
            return Err(metric_failure(k, q, MetricBlock::G22Inverse, tol));
        };
        Ok(Self { i_inv, y, l2, d2_inv })
    }

    /// Whether [`MetricFactor::with_tolerance`] would succeed with `min_pivot`, without building
    /// an error (so without allocating): the test the Cartesian chart of `crate::charts` makes at
    /// every evaluation to know when the internal chart is regular again.
    pub fn is_regular(k: &KineticMatrices<N>, min_pivot: f64) -> bool {
        let tol = min_pivot.max(PIVOT_TOLERANCE);
        if !(all_finite(k.a.as_slice()) & all_finite(k.coriolis.as_slice()) & all_finite(k.inertia.as_slice())) {
            return false;
        }
        let Some(i_inv) = inverse_spd3(&k.inertia, tol) else {
            return false;
        };
        let mut schur = k.a - k.coriolis.transpose() * (i_inv * k.coriolis);
        ldl_in_place(&mut schur, |j| k.a[(j, j)], tol).is_some()
    }

    /// `v = (ω, q̇) = M⁻¹ (j, p)`.
    #[inline]
    pub fn solve(&self, j: &Vector3<f64>, p: &SVector<f64, N>) -> (Vector3<f64>, SVector<f64, N>) {
        let i_inv_j = self.i_inv * j;
        let qdot = ldl_solve(&self.l2, &self.d2_inv, p - self.y.transpose() * j);
        (i_inv_j - self.y * qdot, qdot)
    }

    /// `v = (ω, q̇) = M⁻¹ (0, p)`: [`MetricFactor::solve`] for `J = 0`, without the `I⁻¹ J`
    /// and `Yᵀ J` terms.
    #[inline]
    pub fn solve_zero_j(&self, p: &SVector<f64, N>) -> (Vector3<f64>, SVector<f64, N>) {
        let qdot = ldl_solve(&self.l2, &self.d2_inv, *p);
        (-(self.y * qdot), qdot)
    }
}

/// Cold path of [`MetricFactor::with_tolerance`]. A metric singular within
/// [`PIVOT_TOLERANCE`] is named as the G-matrix path would name it (it checks `I`, `a`, `G11⁻¹`, `G22⁻¹`
/// in that order), falling back to the block this factorization tripped on when the G-matrix path's
/// tests happen to pass; a metric that only fails the stricter `tol` is ill-conditioned.
#[cold]
#[inline(never)]
fn metric_failure<const N: usize>(
    k: &KineticMatrices<N>,
    q: &SVector<f64, N>,
    found: MetricBlock,
    tol: f64,
) -> HamiltonianError {
    let singular = match InverseMetric::new(k, q) {
        Err(e) => return e,
        Ok(_) => HamiltonianError::SingularMetric { matrix: found, q: q.as_slice().to_vec() },
    };
    if tol <= PIVOT_TOLERANCE {
        return singular;
    }
    // Positive definite within PIVOT_TOLERANCE: report the smallest relative pivot of the block.
    let inertia = inverse_spd3(&k.inertia, tol).is_none();
    let pivot = if inertia {
        let m = &k.inertia;
        let trace = m.trace();
        let minor2 = m[(0, 0)] * m[(1, 1)] - m[(1, 0)] * m[(1, 0)];
        let pivots = [m[(0, 0)], minor2 / m[(0, 0)], m.determinant() / minor2];
        pivots.iter().fold(f64::INFINITY, |acc, p| acc.min(p / trace))
    } else {
        let y = k.inertia.try_inverse().unwrap_or_else(Matrix3::zeros) * k.coriolis;
        let mut schur = k.a - k.coriolis.transpose() * y;
        match ldl_in_place(&mut schur, |j| k.a[(j, j)], f64::NEG_INFINITY) {
            Some(d_inv) => (0..N).fold(f64::INFINITY, |acc, j| acc.min(1.0 / (d_inv[j] * k.a[(j, j)]))),
            None => return singular,
        }
    };
    let matrix = if inertia { MetricBlock::Inertia } else { MetricBlock::G22Inverse };
    HamiltonianError::IllConditionedMetric { matrix, q: q.as_slice().to_vec(), pivot, threshold: tol }
}

/// The inverse of a symmetric 3 × 3 matrix by adjugate and determinant, or `None` unless it
/// is positive definite with every Cholesky pivot above `tol` times its trace (the G-matrix path's test
/// for `I` with `tol` = [`PIVOT_TOLERANCE`]). Reads the lower triangle only.
#[inline]
fn inverse_spd3(m: &Matrix3<f64>, tol: f64) -> Option<Matrix3<f64>> {
    let (m00, m10, m20, m11, m21, m22) = (m[(0, 0)], m[(1, 0)], m[(2, 0)], m[(1, 1)], m[(2, 1)], m[(2, 2)]);
    let c00 = m11 * m22 - m21 * m21;
    let c10 = m20 * m21 - m10 * m22;
    let c20 = m10 * m21 - m20 * m11;
    let c11 = m00 * m22 - m20 * m20;
    let c21 = m10 * m20 - m00 * m21;
    let c22 = m00 * m11 - m10 * m10;
    let det = m00 * c00 + m10 * c10 + m20 * c20;
    // Leading principal minors m00, c22, det; pivot_j = minor_j / minor_{j−1} > tol · trace.
    // Written as `a > b` so that NaN fails.
    let tol = tol * (m00 + m11 + m22);
    let positive = (m00 > tol) & (c22 > tol * m00) & (det > tol * c22);
    if !positive {
        return None;
    }
    let r = 1.0 / det;
    #[rustfmt::skip]
    let inv = Matrix3::new(
        c00 * r, c10 * r, c20 * r,
        c10 * r, c11 * r, c21 * r,
        c20 * r, c21 * r, c22 * r,
    );
    Some(inv)
}

/// In-place `m = L D Lᵀ` of a symmetric matrix, reading the lower triangle only and writing
/// `L` (unit diagonal, not stored) into the strict lower triangle; returns `1 / D`, or `None`
/// unless every pivot `D_jj` exceeds `tol` times `scale(j)` (NaN fails too).
///
/// Row by row: with `v_k = L_jk D_k`, `v_k = m_jk − Σ_{l<k} L_kl v_l`, `L_jk = v_k / D_k`,
/// `D_j = m_jj − Σ_{k<j} L_jk v_k`. Hand-written rather than `nalgebra::Cholesky` because with
/// constant bounds it unrolls into straight-line code, and for the reciprocal pivots. Blocks of
/// [`factor_large::LARGE_BLOCK`] and more go to [`factor_large::ldl_in_place`] instead, which
/// computes the same `L` (same storage) column by column.
#[inline]
fn ldl_in_place<const D: usize>(
    m: &mut SMatrix<f64, D, D>,
    scale: impl Fn(usize) -> f64,
    tol: f64,
) -> Option<SVector<f64, D>> {
    if D >= factor_large::LARGE_BLOCK {
        return factor_large::ldl_in_place(m, scale, tol);
    }
    let mut d_inv = SVector::<f64, D>::zeros();
    let mut v = SVector::<f64, D>::zeros();
    for j in 0..D {
        let mut d = m[(j, j)];
        for k in 0..j {
            let mut vk = m[(j, k)];
            for l in 0..k {
                vk -= m[(k, l)] * v[l];
            }
            v[k] = vk;
            let ljk = vk * d_inv[k];
            m[(j, k)] = ljk;
            d -= ljk * vk;
        }
        if d.is_nan() || d <= tol * scale(j) {
            return None;
        }
        d_inv[j] = 1.0 / d;
    }
    Some(d_inv)
}

/// `x = L⁻ᵀ D⁻¹ L⁻¹ b` for a factor from [`ldl_in_place`]: multiplications only.
#[inline]
fn ldl_solve<const D: usize>(
    l: &SMatrix<f64, D, D>,
    d_inv: &SVector<f64, D>,
    mut x: SVector<f64, D>,
) -> SVector<f64, D> {
    if D >= factor_large::LARGE_BLOCK {
        return factor_large::ldl_solve(l, d_inv, x);
    }
    for i in 0..D {
        for k in 0..i {
            x[i] -= l[(i, k)] * x[k];
        }
    }
    for i in 0..D {
        x[i] *= d_inv[i];
    }
    for i in (0..D).rev() {
        for k in i + 1..D {
            x[i] -= l[(k, i)] * x[k];
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use nalgebra::{SMatrix, SVector};
    use rand::{RngExt as _, SeedableRng as _};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// A random symmetric positive definite `D × D` matrix `B Bᵀ + 0.1·1` with `B` uniform in
    /// `[-1, 1)`: condition numbers of a few hundred at most.
    fn random_spd<const D: usize>(rng: &mut ChaCha8Rng) -> SMatrix<f64, D, D> {
        let b = SMatrix::<f64, D, D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
        b * b.transpose() + SMatrix::<f64, D, D>::identity() * 0.1
    }

    fn random_vector<const D: usize>(rng: &mut ChaCha8Rng) -> SVector<f64, D> {
        SVector::from_fn(|_, _| rng.random_range(-1.0..1.0))
    }

    /// The kinetic matrices of the full metric `m` = [[I, A], [Aᵀ, a]].
    fn blocks(m: &SMatrix<f64, 7, 7>) -> KineticMatrices<4> {
        const N: usize = 4;
        let mut k = KineticMatrices::<N> { inertia: m.fixed_view::<3, 3>(0, 0).into_owned(), ..Default::default() };
        for j in 0..N {
            for r in 0..3 {
                k.coriolis[(r, j)] = m[(r, 3 + j)];
            }
            for i in 0..N {
                k.a[(i, j)] = m[(3 + i, 3 + j)];
            }
        }
        k
    }

    /// `M⁻¹ (J, p)` by the block factorization equals nalgebra's Cholesky solve of the whole
    /// 7 × 7 metric, for random symmetric positive definite metrics; so does the `J = 0` solve.
    #[test]
    fn solve_matches_cholesky_of_the_whole_metric() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..200 {
            let m = random_spd::<7>(&mut rng);
            let k = blocks(&m);
            let (j, p) = (random_vector::<3>(&mut rng), random_vector::<4>(&mut rng));
            let factor = MetricFactor::new(&k, &SVector::zeros()).unwrap();
            let (omega, qdot) = factor.solve(&j, &p);
            let b = SVector::<f64, 7>::from_iterator(j.iter().chain(p.iter()).copied());
            let v = m.cholesky().unwrap().solve(&b);
            let scale = v.amax();
            assert!((omega - v.fixed_rows::<3>(0)).amax() < 1e-10 * scale, "ω {omega:?} vs {v:?}");
            assert!((qdot - v.fixed_rows::<4>(3)).amax() < 1e-10 * scale, "q̇ {qdot:?} vs {v:?}");

            let (omega0, qdot0) = factor.solve_zero_j(&p);
            let b0 = SVector::<f64, 7>::from_iterator([0.0; 3].iter().chain(p.iter()).copied());
            let v0 = m.cholesky().unwrap().solve(&b0);
            assert!((omega0 - v0.fixed_rows::<3>(0)).amax() < 1e-10 * v0.amax());
            assert!((qdot0 - v0.fixed_rows::<4>(3)).amax() < 1e-10 * v0.amax());
        }
    }

    /// The closed-form 3 × 3 inverse and the in-place `L D Lᵀ` solve against nalgebra's general
    /// inverse on random symmetric positive definite matrices.
    #[test]
    fn inverse_and_ldl_match_nalgebra() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..200 {
            let m3 = random_spd::<3>(&mut rng);
            let inv = inverse_spd3(&m3, PIVOT_TOLERANCE).unwrap();
            let reference = m3.try_inverse().unwrap();
            assert!((inv - reference).amax() < 1e-10 * reference.amax(), "{inv} vs {reference}");

            let m5 = random_spd::<5>(&mut rng);
            let b = random_vector::<5>(&mut rng);
            let mut l = m5;
            let d_inv = ldl_in_place(&mut l, |j| m5[(j, j)], PIVOT_TOLERANCE).unwrap();
            let x = ldl_solve(&l, &d_inv, b);
            let reference = m5.try_inverse().unwrap() * b;
            assert!((x - reference).amax() < 1e-10 * reference.amax(), "{x} vs {reference}");
        }
    }

    /// Matrices that are not positive definite are refused: a negative eigenvalue in `I` or in
    /// the Schur complement, and NaN.
    #[test]
    fn indefinite_and_nan_matrices_are_refused() {
        let minus = SMatrix::<f64, 3, 3>::from_diagonal(&SVector::from([1.0, -1.0, 1.0]));
        assert!(inverse_spd3(&minus, PIVOT_TOLERANCE).is_none());
        let mut nan = SMatrix::<f64, 3, 3>::identity();
        nan[(1, 1)] = f64::NAN;
        assert!(inverse_spd3(&nan, PIVOT_TOLERANCE).is_none());
        let mut m = minus;
        assert!(ldl_in_place(&mut m, |_| 1.0, PIVOT_TOLERANCE).is_none());

        // S = a − Aᵀ I⁻¹ A = 1 − 4 < 0.
        let k = KineticMatrices::<1> {
            inertia: SMatrix::identity(),
            coriolis: SMatrix::from([[2.0, 0.0, 0.0]]),
            a: SMatrix::from([[1.0]]),
        };
        let q = SVector::<f64, 1>::new(0.5);
        assert!(matches!(MetricFactor::new(&k, &q), Err(HamiltonianError::SingularMetric { .. })));
    }
}
