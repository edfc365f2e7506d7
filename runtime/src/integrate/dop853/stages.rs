//! The stage combinations of DOP853, `Σ_j a_j k_j` over a sparse row of the Butcher tableau,
//! written once over [`Real`] for the scalar solver (`f64`) and the batched one (a lane vector).
//!
//! The components are taken four at a time with the four sums kept in registers over the whole
//! row, instead of one pass over all components per stage that loads and stores the partial
//! sums each time (what the first version did; docs/src/history/benchmarks.md, "Many trajectories per core",
//! measures both). Each component's sum is still `((0 + a₀k₀) + a₁k₁) + …` in the row's order,
//! so the numbers are the same bits as before.

use crate::lanes::Real;

/// Components per block of sums kept in registers.
const BLOCK: usize = 4;

/// `out[i] = finish(i, Σ_j w_j k_j[i])` over the sparse row `row` of `(stage, w_j)`, where stage
/// `j`'s vector is `k[j·n..(j + 1)·n]`.
#[inline(always)]
fn sums<T: Real>(out: &mut [T], k: &[T], n: usize, row: &[(usize, f64)], finish: impl Fn(usize, T) -> T) {
    let out = &mut out[..n];
    let mut start = 0;
    while start + BLOCK <= n {
        let mut acc = [T::splat(0.0); BLOCK];
        for &(stage, w) in row {
            let w = T::splat(w);
            let ks = &k[stage * n + start..][..BLOCK];
            for (a, &v) in acc.iter_mut().zip(ks) {
                *a = *a + w * v;
            }
        }
        for (l, (o, a)) in out[start..start + BLOCK].iter_mut().zip(acc).enumerate() {
            *o = finish(start + l, a);
        }
        start += BLOCK;
    }
    for (i, o) in out.iter_mut().enumerate().skip(start) {
        let mut acc = T::splat(0.0);
        for &(stage, w) in row {
            acc = acc + T::splat(w) * k[stage * n + i];
        }
        *o = finish(i, acc);
    }
}

/// `out = Σ_j w_j k_j` over the sparse row `row` (stage vectors of length `n` in `k`).
#[inline]
pub(super) fn weights<T: Real>(out: &mut [T], k: &[T], n: usize, row: &[(usize, f64)]) {
    sums(out, k, n, row, |_, s| s);
}

/// `out = y + h·Σ_j a_j k_j`: the argument of a stage (`h` per lane).
#[inline]
pub(super) fn combine<T: Real>(out: &mut [T], y: &[T], k: &[T], n: usize, h: T, row: &[(usize, f64)]) {
    let y = &y[..n];
    sums(out, k, n, row, |i, s| y[i] + h * s);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blocked sums equal the plain per-stage passes (the first version) bit for bit, for
    /// dimensions that are and are not multiples of the block, and rows of every length.
    #[test]
    fn blocked_sums_equal_per_stage_passes() {
        let rows: [&[(usize, f64)]; 4] =
            [&[], &[(0, 0.3)], &[(0, 1.0 / 3.0), (2, -0.7), (1, 1e-3)], &[(3, 2.5), (0, -1.25), (1, 0.1), (2, 7.0)]];
        for n in [1, 3, 4, 5, 13, 16, 17] {
            let k: Vec<f64> = (0..4 * n).map(|i| ((i * 7919) % 1000) as f64 / 37.0 - 13.0).collect();
            let y: Vec<f64> = (0..n).map(|i| 1.0 / (i as f64 + 0.7)).collect();
            let h = 0.173;
            for row in rows {
                let mut plain = vec![0.0; n];
                for &(stage, w) in row {
                    for (o, v) in plain.iter_mut().zip(&k[stage * n..(stage + 1) * n]) {
                        *o += w * v;
                    }
                }
                let mut got = vec![f64::NAN; n];
                weights(&mut got, &k, n, row);
                assert!(got.iter().zip(&plain).all(|(a, b)| a.to_bits() == b.to_bits()), "n = {n}");
                combine(&mut got, &y, &k, n, h, row);
                for i in 0..n {
                    assert_eq!(got[i].to_bits(), (y[i] + h * plain[i]).to_bits(), "n = {n}, i = {i}");
                }
            }
        }
    }
}
