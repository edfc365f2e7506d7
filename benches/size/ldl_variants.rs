// The `L D Lᵀ` of a 54 × 54 symmetric positive definite matrix (hexane's Schur complement) in
// the variants measured for runtime/src/hamiltonian/factor_large.rs (docs/src/history/benchmarks.md, "Large
// molecules, fourth step"): thread CPU time per factorization (a 23 kB copy of the matrix
// included, timed alone as `copy`), interleaved rounds, and the residual of a solve with each
// factor as a check that every variant computes the factorization. Self-contained:
//
//   rustc --edition 2024 -C opt-level=3 benches/size/ldl_variants.rs -o /tmp/ldl_variants
//   /tmp/ldl_variants 50000 3
//
// `row`: the previous factor_large (L transposed, row by row, every entry an inner product with
// four partial sums that needs the entry before it). `dots2`: left-looking, each entry of a
// column an independent inner product over rows of L, two rows at a time. `colR`: left-looking,
// R entries of a column accumulated at once over contiguous columns (`col8` is what
// factor_large does). `rows8`, `rows12`: `col8`, `col12` plus a transposed copy of L, so that the pivot's
// inner product is contiguous. `two6`: two columns at a time (each column of L read once for
// both). `split8`: `col8` with two sets of accumulators (even and odd k). `ahead8`: `col8` with
// the entry the next pivot waits for computed first, with four partial sums.
use std::hint::black_box;

const D: usize = 54;
type Factor = fn(&mut [f64; D * D], f64) -> Option<[f64; D]>;

fn thread_cpu() -> f64 {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").expect("Linux");
    text.split_whitespace().next().and_then(|t| t.parse::<f64>().ok()).expect("nanoseconds") * 1e-9
}

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

#[inline(never)]
fn copy(m: &mut [f64; D * D], _tol: f64) -> Option<[f64; D]> {
    Some([m[0]; D])
}

/// The previous factor_large: L_jk at (k, j), i.e. m[j·D + k] (upper triangle).
#[inline(never)]
fn row(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    let mut d_inv = [0.0; D];
    let mut v = [0.0f64; D];
    for j in 0..D {
        let mut d = m[j * D + j];
        for k in 0..j {
            let vk = m[k * D + j] - dot(&m[k * D..k * D + k], &v[..k]);
            v[k] = vk;
            let ljk = vk * d_inv[k];
            m[j * D + k] = ljk;
            d -= ljk * vk;
        }
        if d.is_nan() || d <= tol {
            return None;
        }
        d_inv[j] = 1.0 / d;
    }
    Some(d_inv)
}

/// Left-looking by independent inner products over rows of L (L in the upper triangle).
#[inline(never)]
fn dots2(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    let (mut d_inv, mut pivots, mut c) = ([0.0; D], [0.0; D], [0.0f64; D]);
    for j in 0..D {
        for k in 0..j {
            c[k] = m[j * D + k] * pivots[k];
        }
        let d = m[j * D + j] - dot(&m[j * D..j * D + j], &c[..j]);
        if d.is_nan() || d <= tol {
            return None;
        }
        let r = 1.0 / d;
        (d_inv[j], pivots[j]) = (r, d);
        let mut i = j + 1;
        while i < D {
            let rows = if i + 1 < D { 2 } else { 1 };
            for t in 0..rows {
                let s = dot(&m[(i + t) * D..(i + t) * D + j], &c[..j]);
                m[(i + t) * D + j] = (m[j * D + i + t] - s) * r;
            }
            i += rows;
        }
    }
    Some(d_inv)
}

/// R entries of column j from row i, over the contiguous columns k < j (L in the lower triangle);
/// with `transposed`, also written to the upper triangle.
#[inline(always)]
fn block<const R: usize>(m: &mut [f64; D * D], c: &[f64; D], j: usize, i: usize, r: f64, transposed: bool) {
    let mut acc: [f64; R] = m[j * D + i..j * D + i + R].try_into().unwrap();
    for k in 0..j {
        let col: &[f64; R] = m[k * D + i..k * D + i + R].try_into().unwrap();
        for t in 0..R {
            acc[t] -= col[t] * c[k];
        }
    }
    for a in &mut acc {
        *a *= r;
    }
    m[j * D + i..j * D + i + R].copy_from_slice(&acc);
    if transposed {
        for t in 0..R {
            m[(i + t) * D + j] = acc[t];
        }
    }
}

/// `block` with two sets of accumulators, for even and odd k.
#[inline(always)]
fn block_split<const R: usize>(m: &mut [f64; D * D], c: &[f64; D], j: usize, i: usize, r: f64) {
    let mut acc: [f64; R] = m[j * D + i..j * D + i + R].try_into().unwrap();
    let mut odd = [0.0f64; R];
    let mut k = 0;
    while k + 2 <= j {
        let col: &[f64; R] = m[k * D + i..k * D + i + R].try_into().unwrap();
        let next: &[f64; R] = m[(k + 1) * D + i..(k + 1) * D + i + R].try_into().unwrap();
        for t in 0..R {
            acc[t] -= col[t] * c[k];
            odd[t] += next[t] * c[k + 1];
        }
        k += 2;
    }
    if k < j {
        let col: &[f64; R] = m[k * D + i..k * D + i + R].try_into().unwrap();
        for t in 0..R {
            acc[t] -= col[t] * c[k];
        }
    }
    for t in 0..R {
        acc[t] = (acc[t] - odd[t]) * r;
    }
    m[j * D + i..j * D + i + R].copy_from_slice(&acc);
}

#[derive(Clone, Copy, PartialEq)]
enum Column {
    Plain,
    Transposed,
    Split,
    Ahead,
}

/// Left-looking by columns (L in the lower triangle), R rows at a time.
#[inline(always)]
fn col<const R: usize>(m: &mut [f64; D * D], tol: f64, how: Column) -> Option<[f64; D]> {
    let (mut d_inv, mut pivots, mut c) = ([0.0; D], [0.0; D], [0.0f64; D]);
    let transposed = how == Column::Transposed;
    for j in 0..D {
        let d = if transposed {
            let row = &m[j * D..j * D + j];
            for k in 0..j {
                c[k] = row[k] * pivots[k];
            }
            m[j * D + j] - dot(row, &c[..j])
        } else {
            let mut p = [0.0f64; 4];
            for k in 0..j {
                let l = m[k * D + j];
                c[k] = l * pivots[k];
                p[k % 4] += l * c[k];
            }
            m[j * D + j] - ((p[0] + p[1]) + (p[2] + p[3]))
        };
        if d.is_nan() || d <= tol {
            return None;
        }
        let r = 1.0 / d;
        (d_inv[j], pivots[j]) = (r, d);
        let mut i = j + 1;
        if how == Column::Ahead && i < D {
            let mut s = [0.0f64; 4];
            for k in 0..j {
                s[k % 4] += m[k * D + i] * c[k];
            }
            m[j * D + i] = (m[j * D + i] - ((s[0] + s[1]) + (s[2] + s[3]))) * r;
            i += 1;
        }
        while i + R <= D {
            if how == Column::Split {
                block_split::<R>(m, &c, j, i, r);
            } else {
                block::<R>(m, &c, j, i, r, transposed);
            }
            i += R;
        }
        while i + 2 <= D {
            block::<2>(m, &c, j, i, r, transposed);
            i += 2;
        }
        if i < D {
            block::<1>(m, &c, j, i, r, transposed);
        }
    }
    Some(d_inv)
}

/// Two columns j, j + 1 at a time, R rows at a time (L in the lower triangle).
#[inline(never)]
fn two6(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    const R: usize = 6;
    let (mut d_inv, mut pivots, mut ca, mut cb) = ([0.0; D], [0.0; D], [0.0f64; D], [0.0f64; D]);
    let mut j = 0;
    while j < D {
        let mut p = [0.0f64; 4];
        for k in 0..j {
            let l = m[k * D + j];
            ca[k] = l * pivots[k];
            p[k % 4] += l * ca[k];
        }
        let d = m[j * D + j] - ((p[0] + p[1]) + (p[2] + p[3]));
        if d.is_nan() || d <= tol {
            return None;
        }
        let ra = 1.0 / d;
        (d_inv[j], pivots[j]) = (ra, d);
        if j + 1 == D {
            break;
        }
        let mut s = [0.0f64; 4];
        for k in 0..j {
            s[k % 4] += m[k * D + j + 1] * ca[k];
        }
        m[j * D + j + 1] = (m[j * D + j + 1] - ((s[0] + s[1]) + (s[2] + s[3]))) * ra;
        let mut p = [0.0f64; 4];
        for k in 0..=j {
            let l = m[k * D + j + 1];
            cb[k] = l * pivots[k];
            p[k % 4] += l * cb[k];
        }
        let d1 = m[(j + 1) * D + j + 1] - ((p[0] + p[1]) + (p[2] + p[3]));
        if d1.is_nan() || d1 <= tol {
            return None;
        }
        let rb = 1.0 / d1;
        (d_inv[j + 1], pivots[j + 1]) = (rb, d1);
        let mut i = j + 2;
        while i < D {
            let rows = (D - i).min(R);
            let mut a = [0.0f64; R];
            let mut b = [0.0f64; R];
            a[..rows].copy_from_slice(&m[j * D + i..j * D + i + rows]);
            b[..rows].copy_from_slice(&m[(j + 1) * D + i..(j + 1) * D + i + rows]);
            if rows == R {
                for k in 0..j {
                    let col: &[f64; R] = m[k * D + i..k * D + i + R].try_into().unwrap();
                    for t in 0..R {
                        a[t] -= col[t] * ca[k];
                        b[t] -= col[t] * cb[k];
                    }
                }
            } else {
                for k in 0..j {
                    for t in 0..rows {
                        a[t] -= m[k * D + i + t] * ca[k];
                        b[t] -= m[k * D + i + t] * cb[k];
                    }
                }
            }
            for t in 0..rows {
                a[t] *= ra;
                b[t] = (b[t] - a[t] * cb[j]) * rb;
            }
            m[j * D + i..j * D + i + rows].copy_from_slice(&a[..rows]);
            m[(j + 1) * D + i..(j + 1) * D + i + rows].copy_from_slice(&b[..rows]);
            i += rows;
        }
        j += 2;
    }
    Some(d_inv)
}

#[inline(never)]
fn col8(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    col::<8>(m, tol, Column::Plain)
}
#[inline(never)]
fn col12(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    col::<12>(m, tol, Column::Plain)
}
#[inline(never)]
fn col16(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    col::<16>(m, tol, Column::Plain)
}
#[inline(never)]
fn rows8(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    col::<8>(m, tol, Column::Transposed)
}
#[inline(never)]
fn rows12(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    col::<12>(m, tol, Column::Transposed)
}
#[inline(never)]
fn split8(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    col::<8>(m, tol, Column::Split)
}
#[inline(never)]
fn ahead8(m: &mut [f64; D * D], tol: f64) -> Option<[f64; D]> {
    col::<8>(m, tol, Column::Ahead)
}

/// `B Bᵀ + 0.5·1` with a fixed pattern `B`.
fn spd() -> [f64; D * D] {
    let mut b = [0.0; D * D];
    for i in 0..D {
        for j in 0..D {
            b[j * D + i] = ((i * 7 + j * 13) % 11) as f64 / 11.0 - 0.45;
        }
    }
    let mut m = [0.0; D * D];
    for i in 0..D {
        for j in 0..D {
            let s: f64 = (0..D).map(|k| b[k * D + i] * b[k * D + j]).sum();
            m[j * D + i] = s + if i == j { 0.5 } else { 0.0 };
        }
    }
    m
}

/// max |M x − b| for the solve with the factor (`upper`: L stored transposed).
fn residual(f: Factor, upper: bool, m0: &[f64; D * D]) -> f64 {
    let mut m = *m0;
    let d_inv = f(&mut m, 1e-14).expect("positive definite");
    let l = |i: usize, k: usize| if upper { m[i * D + k] } else { m[k * D + i] };
    let b: Vec<f64> = (0..D).map(|i| (i as f64 * 0.37).sin()).collect();
    let mut x = b.clone();
    for i in 0..D {
        for k in 0..i {
            x[i] -= l(i, k) * x[k];
        }
    }
    for i in 0..D {
        x[i] *= d_inv[i];
    }
    for i in (0..D).rev() {
        for k in i + 1..D {
            x[i] -= l(k, i) * x[k];
        }
    }
    (0..D)
        .map(|i| {
            let mx: f64 = (0..D).map(|j| m0[i.min(j) * D + i.max(j)] * x[j]).sum();
            (mx - b[i]).abs()
        })
        .fold(0.0, f64::max)
}

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
    let (n, rounds) = (args.first().copied().unwrap_or(50000), args.get(1).copied().unwrap_or(3));
    let m0 = spd();
    let variants: [(&str, Factor, bool); 11] = [
        ("copy", copy, false),
        ("row", row, true),
        ("dots2", dots2, true),
        ("col8", col8, false),
        ("col12", col12, false),
        ("col16", col16, false),
        ("rows8", rows8, false),
        ("rows12", rows12, false),
        ("two6", two6, false),
        ("split8", split8, false),
        ("ahead8", ahead8, false),
    ];
    for &(name, f, upper) in &variants[1..] {
        println!("{name}: residual {:.1e}", residual(f, upper, &m0));
    }
    for _ in 0..rounds {
        for &(name, f, _) in &variants {
            let begin = thread_cpu();
            for _ in 0..n {
                let mut m = black_box(m0);
                black_box(f(&mut m, 1e-14));
            }
            print!("{name} {:.0}  ", (thread_cpu() - begin) / n as f64 * 1e9);
        }
        println!("(ns)");
    }
}
