//! The `L D Lᵀ` factorization and solve of [`super::factor`] for large blocks (molecules with
//! at least [`LARGE_BLOCK`] internal coordinates), laid out for throughput rather than latency.
//!
//! The small-block version goes row by row: row `j` of `L` is a forward substitution with the
//! rows above, each entry an inner product that needs the entry before it. For water's 3 × 3
//! block that costs nothing, but for hexane's 54 × 54 Schur complement (`N³/6 ≈ 26 000`
//! multiply-adds) it is one long dependent chain. Here `L` is computed column by column
//! (left-looking): the entries of column `j` below the diagonal, `L_ij = (m_ij − Σ_{k<j} L_ik
//! L_jk D_k) / D_j`, are independent of each other, so [`ROWS`] consecutive ones are
//! accumulated at once in registers while the columns to their left are read as contiguous
//! slices of nalgebra's column-major storage (`L` in the strict lower triangle, as in the
//! small-block version, plus a transposed copy in the strict upper triangle for the pivots).
//! The solve runs over contiguous columns and rows. Same pivots and tests, different summation
//! order: results agree with the small-block version to rounding (unit tests against
//! nalgebra's Cholesky below).
//!
//! Measured (`benches/size/ldl_variants.rs`, docs/src/history/benchmarks.md "Large molecules, fourth step"): a
//! 54 × 54 factorization 7.1 µs with `L` transposed, row by row with four partial sums per inner
//! product, 3.4 µs with this layout. The transposed layout was itself
//! about 3 % faster than the small-block version on hexane, but ethane (18 coordinates) was
//! slower with it than with the unrolled small-block one, hence the threshold; no shipped
//! molecule reaches it.

use nalgebra::{SMatrix, SVector};

/// From this block size on, [`super::factor`] uses this module.
pub const LARGE_BLOCK: usize = 24;

/// Rows of a column of `L` computed together in registers by [`ldl_in_place`].
const ROWS: usize = 8;

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

/// `acc_t ← (m_{i+t, j} − Σ_{k<j} L_{i+t, k} c_k) / D_j` for `t < R`, written to `L_{i+t, j}`: `R`
/// consecutive entries of column `j` of `L`, each a contiguous slice of the columns to its left,
/// accumulated in `R` independent registers (vectorised by LLVM over `t`).
#[inline(always)]
fn column_block<const D: usize, const R: usize>(m: &mut [f64], c: &[f64; D], j: usize, i: usize, d_inv: f64) {
    let mut acc: [f64; R] = m[j * D + i..j * D + i + R].try_into().expect("R rows");
    for (k, &ck) in c[..j].iter().enumerate() {
        let column: &[f64; R] = m[k * D + i..k * D + i + R].try_into().expect("R rows");
        for t in 0..R {
            acc[t] -= column[t] * ck;
        }
    }
    for a in &mut acc {
        *a *= d_inv;
    }
    m[j * D + i..j * D + i + R].copy_from_slice(&acc);
    // And transposed, into row j of the strict upper triangle, where the pivot of column i + t
    // reads it as part of a contiguous row.
    for (t, &a) in acc.iter().enumerate() {
        m[(i + t) * D + j] = a;
    }
}

/// [`super::factor`]'s `ldl_in_place` by columns (left-looking): `L` in the strict lower
/// triangle as there, and a copy of it transposed in the strict upper triangle (reads the lower
/// triangle of `m` only); returns `1 / D`, or `None` unless every pivot `D_jj` exceeds
/// `tol · scale(j)` (NaN fails too).
///
/// Column `j`: `c_k = L_jk D_k` (`k < j`), `D_j = m_jj − Σ_k L_jk c_k`, and for `i > j`
/// `L_ij = (m_ij − Σ_{k<j} L_ik c_k) / D_j`; the entries of a column are independent of each
/// other, so they are computed [`ROWS`] at a time by [`column_block`]. The transposed copy
/// makes row `j` of `L`, which the pivot needs, contiguous (measured: 3.66 → 3.35 µs for 54
/// rows).
#[inline]
pub(super) fn ldl_in_place<const D: usize>(
    m: &mut SMatrix<f64, D, D>,
    scale: impl Fn(usize) -> f64,
    tol: f64,
) -> Option<SVector<f64, D>> {
    let mut d_inv = SVector::<f64, D>::zeros();
    let mut pivots = [0.0f64; D];
    let mut c = [0.0f64; D];
    let m = m.as_mut_slice();
    for j in 0..D {
        // Row j of L, contiguous in the upper triangle (column j of the storage).
        let row = &m[j * D..j * D + j];
        for ((ck, &ljk), &dk) in c.iter_mut().zip(row).zip(&pivots) {
            *ck = ljk * dk;
        }
        let d = m[j * D + j] - dot(row, &c[..j]);
        if d.is_nan() || d <= tol * scale(j) {
            return None;
        }
        let r = 1.0 / d;
        d_inv[j] = r;
        pivots[j] = d;
        let mut i = j + 1;
        while i + ROWS <= D {
            column_block::<D, ROWS>(m, &c, j, i, r);
            i += ROWS;
        }
        while i + 2 <= D {
            column_block::<D, 2>(m, &c, j, i, r);
            i += 2;
        }
        if i < D {
            column_block::<D, 1>(m, &c, j, i, r);
        }
    }
    Some(d_inv)
}

/// `x = L⁻ᵀ D⁻¹ L⁻¹ b` for a factor from [`ldl_in_place`], as two sequences of contiguous updates:
/// `x ← x − x_k L_·k` forward over the columns of `L` (lower triangle), `x ← x − x_k L_k·`
/// backward over its rows (the transposed copy in the upper triangle). Measured against
/// inner products for the back substitution: 0.85 → 0.60 µs for 54 rows.
#[inline]
pub(super) fn ldl_solve<const D: usize>(
    l: &SMatrix<f64, D, D>,
    d_inv: &SVector<f64, D>,
    mut x: SVector<f64, D>,
) -> SVector<f64, D> {
    let s = l.as_slice();
    let xs = x.as_mut_slice();
    for k in 0..D {
        let (head, tail) = xs.split_at_mut(k + 1);
        let xk = head[k];
        for (xi, lik) in tail.iter_mut().zip(&s[k * D + k + 1..(k + 1) * D]) {
            *xi -= lik * xk;
        }
    }
    for (xi, r) in xs.iter_mut().zip(d_inv.iter()) {
        *xi *= r;
    }
    for k in (1..D).rev() {
        let (head, tail) = xs.split_at_mut(k);
        let xk = tail[0];
        for (xi, lki) in head.iter_mut().zip(&s[k * D..k * D + k]) {
            *xi -= lki * xk;
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against nalgebra's Cholesky `C Cᵀ` of the same matrix: the solve, `D` (the squared
    /// diagonal of `C`) and `L` (`C` with its columns divided by their diagonal), for symmetric
    /// positive definite matrices of 20, 27 and 54 rows (every path of the column blocks:
    /// [`ROWS`] at a time, pairs, single rows). The strict upper triangle of the input is NaN,
    /// so reading it anywhere would show.
    fn matches_cholesky<const D: usize>() {
        let b = SMatrix::<f64, D, D>::from_fn(|i, j| ((i * 7 + j * 13) % 11) as f64 / 11.0 - 0.45);
        let m = b * b.transpose() + SMatrix::<f64, D, D>::identity() * 0.5;
        let rhs = SVector::<f64, D>::from_fn(|i, _| (i as f64 * 0.37).sin());
        let mut f = SMatrix::<f64, D, D>::from_fn(|i, j| if i >= j { m[(i, j)] } else { f64::NAN });
        let d_inv = ldl_in_place(&mut f, |_| 1.0, 1e-14).expect("positive definite");
        let chol = m.cholesky().expect("positive definite");
        let expected = chol.solve(&rhs);
        let x = ldl_solve(&f, &d_inv, rhs);
        assert!((x - expected).amax() < 1e-10 * expected.amax(), "{D}: {x} vs {expected}");
        let l = chol.l();
        for j in 0..D {
            assert!((1.0 / d_inv[j] - l[(j, j)] * l[(j, j)]).abs() < 1e-12 * m[(j, j)], "{D}: D_{j}");
            for i in j + 1..D {
                assert!((f[(i, j)] - l[(i, j)] / l[(j, j)]).abs() < 1e-12, "{D}: L_{i}{j}");
            }
        }
        // A matrix that is not positive definite fails, at its first or its last pivot.
        for p in [0, D - 1] {
            let mut bad = m;
            bad[(p, p)] = -1.0;
            assert!(ldl_in_place(&mut bad, |_| 1.0, 1e-14).is_none(), "{D}: pivot {p}");
        }
    }

    #[test]
    fn matches_cholesky_20_27_54() {
        matches_cholesky::<20>();
        matches_cholesky::<27>();
        matches_cholesky::<54>();
    }
}
