//! The `L D Lᵀ` factorization and solve of [`super::factor`] for large blocks (molecules with
//! at least [`LARGE_BLOCK`] internal coordinates), laid out for throughput rather than latency.
//!
//! The small-block version stores `L` in the strict lower triangle and reads its rows, which
//! in nalgebra's column-major storage are strided: for water's 3 × 3 block that costs nothing,
//! but for hexane's 54 × 54 Schur complement (`N³/6 ≈ 26 000` multiply-adds) the inner
//! products ran as one long dependent chain of strided loads. Here `L_jk` is stored
//! transposed, at `(k, j)` in the strict upper triangle, so that row `k` of `L` is the
//! contiguous column `k`; each inner product runs over two contiguous slices with four
//! independent partial sums, and the back substitution is a sequence of contiguous
//! `x ← x − x_k L_k·` updates. Same algorithm (row-by-row `L D Lᵀ`, the same pivots and tests),
//! different summation order: results agree with the small-block version to rounding (unit
//! test against nalgebra's Cholesky below). Measured: about 3 % of hexane's right-hand side
//! gained, while ethane (18 coordinates) was slower with it than with the unrolled small-block
//! version, hence the threshold; no shipped molecule reaches it.

use nalgebra::{SMatrix, SVector};

/// From this block size on, [`super::factor`] uses this module.
pub const LARGE_BLOCK: usize = 24;

/// `Σ a_i b_i` with four partial sums.
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..4 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// [`super::factor`]'s `ldl_in_place` with `L` written transposed into the strict upper
/// triangle (reads the lower triangle of `m` only); returns `1 / D`, or `None` unless every
/// pivot `D_jj` exceeds `tol · scale(j)` (NaN fails too).
#[inline]
pub(super) fn ldl_in_place<const D: usize>(
    m: &mut SMatrix<f64, D, D>,
    scale: impl Fn(usize) -> f64,
    tol: f64,
) -> Option<SVector<f64, D>> {
    let mut d_inv = SVector::<f64, D>::zeros();
    let mut v = [0.0f64; D];
    for j in 0..D {
        let mut d = m[(j, j)];
        for k in 0..j {
            // v_k = L_jk D_k = m_jk − Σ_{l<k} L_kl v_l; row k of L is column k above the diagonal.
            let column = &m.as_slice()[k * D..k * D + k];
            let vk = m[(j, k)] - dot(column, &v[..k]);
            v[k] = vk;
            let ljk = vk * d_inv[k];
            m[(k, j)] = ljk;
            d -= ljk * vk;
        }
        if d.is_nan() || d <= tol * scale(j) {
            return None;
        }
        d_inv[j] = 1.0 / d;
    }
    Some(d_inv)
}

/// `x = L⁻ᵀ D⁻¹ L⁻¹ b` for a factor from [`ldl_in_place`] (`L` in the strict upper triangle).
#[inline]
pub(super) fn ldl_solve<const D: usize>(
    l: &SMatrix<f64, D, D>,
    d_inv: &SVector<f64, D>,
    mut x: SVector<f64, D>,
) -> SVector<f64, D> {
    let s = l.as_slice();
    for i in 1..D {
        let xs = x.as_slice();
        let t = dot(&s[i * D..i * D + i], &xs[..i]);
        x[i] -= t;
    }
    for i in 0..D {
        x[i] *= d_inv[i];
    }
    for k in (1..D).rev() {
        let xk = x[k];
        let column = &s[k * D..k * D + k];
        for (xi, lki) in x.as_mut_slice()[..k].iter_mut().zip(column) {
            *xi -= lki * xk;
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against nalgebra's Cholesky of the same matrix: the solve, and `D` (the squared
    /// Cholesky diagonal), for a 20 × 20 symmetric positive definite matrix.
    #[test]
    fn matches_cholesky() {
        const D: usize = 20;
        let b = SMatrix::<f64, D, D>::from_fn(|i, j| ((i * 7 + j * 13) % 11) as f64 / 11.0 - 0.45);
        let m = b * b.transpose() + SMatrix::<f64, D, D>::identity() * 0.5;
        let rhs = SVector::<f64, D>::from_fn(|i, _| (i as f64 * 0.37).sin());
        let mut f = m;
        let d_inv = ldl_in_place(&mut f, |_| 1.0, 1e-14).expect("positive definite");
        let chol = m.cholesky().expect("positive definite");
        let expected = chol.solve(&rhs);
        let x = ldl_solve(&f, &d_inv, rhs);
        assert!((x - expected).amax() < 1e-10 * expected.amax(), "{x} vs {expected}");
        let l = chol.l();
        for j in 0..D {
            assert!((1.0 / d_inv[j] - l[(j, j)] * l[(j, j)]).abs() < 1e-12 * m[(j, j)]);
        }
        // A matrix that is not positive definite fails.
        let mut bad = m;
        bad[(D - 1, D - 1)] = -1.0;
        assert!(ldl_in_place(&mut bad, |_| 1.0, 1e-14).is_none());
    }
}
