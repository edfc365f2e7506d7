// The two triangular solves of runtime/src/hamiltonian/factor_large.rs's `ldl_solve` for 54 rows
// (hexane), with `L` in the lower triangle and a transposed copy in the upper one, in four
// orders (docs/src/history/benchmarks.md, "Large molecules, fourth step"): thread CPU time per solve, and each
// result's largest difference from the first. Self-contained:
//
//   rustc --edition 2024 -C opt-level=3 benches/size/ldl_solve_variants.rs -o /tmp/ldl_solve_variants
//   /tmp/ldl_solve_variants
//
// `a`: forward by columns (x ← x − x_k L_·k), backward by inner products over columns (the
// version before `b`); `b`: both by inner products; `c`: forward by columns, backward by rows
// (x ← x − x_k L_k·, kept); `dd`: forward by inner products over rows, backward by rows.
use std::hint::black_box;
const D: usize = 54;
fn thread_cpu() -> f64 {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap();
    text.split_whitespace().next().unwrap().parse::<f64>().unwrap() * 1e-9
}
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) { for i in 0..4 { acc[i] += x[i] * y[i]; } }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ra.iter().zip(rb) { s += x * y; }
    s
}
// m: L lower (column k contiguous below diagonal) and upper copy (row j contiguous at m[j*D..j*D+j])
#[inline(never)]
fn solve_a(m: &[f64; D * D], d: &[f64; D], x: &mut [f64; D]) {
    for k in 0..D {
        let (head, tail) = x.split_at_mut(k + 1);
        let xk = head[k];
        for (xi, l) in tail.iter_mut().zip(&m[k * D + k + 1..(k + 1) * D]) { *xi -= l * xk; }
    }
    for (xi, r) in x.iter_mut().zip(d) { *xi *= r; }
    for i in (0..D).rev() {
        let t = dot(&m[i * D + i + 1..(i + 1) * D], &x[i + 1..]);
        x[i] -= t;
    }
}
#[inline(never)]
fn solve_b(m: &[f64; D * D], d: &[f64; D], x: &mut [f64; D]) {
    // forward by rows (dot), backward by columns (dot)
    for i in 1..D {
        let t = dot(&m[i * D..i * D + i], &x[..i]);
        x[i] -= t;
    }
    for (xi, r) in x.iter_mut().zip(d) { *xi *= r; }
    for i in (0..D).rev() {
        let t = dot(&m[i * D + i + 1..(i + 1) * D], &x[i + 1..]);
        x[i] -= t;
    }
}
#[inline(never)]
fn solve_c(m: &[f64; D * D], d: &[f64; D], x: &mut [f64; D]) {
    // forward axpy by columns, backward axpy by rows
    for k in 0..D {
        let (head, tail) = x.split_at_mut(k + 1);
        let xk = head[k];
        for (xi, l) in tail.iter_mut().zip(&m[k * D + k + 1..(k + 1) * D]) { *xi -= l * xk; }
    }
    for (xi, r) in x.iter_mut().zip(d) { *xi *= r; }
    for k in (1..D).rev() {
        let (head, tail) = x.split_at_mut(k);
        let xk = tail[0];
        for (xi, l) in head.iter_mut().zip(&m[k * D..k * D + k]) { *xi -= l * xk; }
    }
}
#[inline(never)]
fn solve_d(m: &[f64; D * D], d: &[f64; D], x: &mut [f64; D]) {
    // forward dot by rows, backward axpy by rows
    for i in 1..D {
        let t = dot(&m[i * D..i * D + i], &x[..i]);
        x[i] -= t;
    }
    for (xi, r) in x.iter_mut().zip(d) { *xi *= r; }
    for k in (1..D).rev() {
        let (head, tail) = x.split_at_mut(k);
        let xk = tail[0];
        for (xi, l) in head.iter_mut().zip(&m[k * D..k * D + k]) { *xi -= l * xk; }
    }
}
fn main() {
    let mut m = [0.0; D * D];
    for i in 0..D { for j in 0..D { let v = if i == j { 1.0 } else { (((i * 7 + j * 13) % 11) as f64 / 11.0 - 0.45) * 0.1 }; m[j * D + i] = v; m[i * D + j] = v; } }
    // make upper a copy of lower transposed
    for j in 0..D { for i in j + 1..D { m[i * D + j] = m[j * D + i]; } }
    let d = [0.7; D];
    let b: [f64; D] = std::array::from_fn(|i| (i as f64 * 0.37).sin());
    let fs: [(&str, fn(&[f64; D * D], &[f64; D], &mut [f64; D])); 4] = [("a", solve_a), ("b", solve_b), ("c", solve_c), ("dd", solve_d)];
    let mut r0 = b; solve_a(&m, &d, &mut r0);
    for (n, f) in fs { let mut x = b; f(&m, &d, &mut x); let e = x.iter().zip(&r0).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max); println!("{n} diff {e:e}"); }
    let n = 200000;
    for _ in 0..3 {
        for (name, f) in fs {
            let t0 = thread_cpu();
            for _ in 0..n { let mut x = black_box(b); f(black_box(&m), &d, &mut x); black_box(&x); }
            print!("{name} {:.0}  ", (thread_cpu() - t0) / n as f64 * 1e9);
        }
        println!();
    }
}
