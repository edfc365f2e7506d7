//! What `sin_cos` and `exp` cost: libm (one number per call; what the one-trajectory `f64`
//! path calls) against `runtime::transcendental` (the polynomial written once over `Real`) at
//! `f64` and per lane of `F64x2`, `F64x4`, `F64x8` (what the lanes call). Thread CPU time per evaluation, the contenders interleaved round by round in one
//! process; chained (each argument depends on the previous result), over arguments in
//! `[−3, 3]` (angles, Morse exponents). docs/src/history/benchmarks.md, "Many trajectories per core".
//!
//! ```sh
//! cargo run --release --features examples --example transcendental_cost -- 7
//! ```

mod common;
use common::thread_cpu;

use std::hint::black_box;

use rovib::runtime::lanes::{F64x2, F64x4, F64x8, Real};
use rovib::runtime::transcendental;

const ITERS: usize = 2_000_000;

/// ns per evaluation of `f` on `T`, divided by the lanes; the argument stays in [−3, 3].
fn chained<T: Real>(f: impl Fn(T) -> T) -> f64 {
    let mut x = T::splat(0.3);
    for l in 0..T::LANES {
        x.set_lane(l, 0.3 + 0.1 * l as f64);
    }
    let t0 = thread_cpu();
    for _ in 0..ITERS {
        let y = f(x);
        // Keeps the chain (x depends on y) and the argument bounded.
        x = T::splat(0.5) * x + T::splat(1e-3) * y;
    }
    black_box(x);
    (thread_cpu() - t0) * 1e9 / (ITERS * T::LANES) as f64
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let rounds: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(7);
    println!(
        "target features: avx2 {}, fma {}, avx512f {}",
        cfg!(target_feature = "avx2"),
        cfg!(target_feature = "fma"),
        cfg!(target_feature = "avx512f")
    );
    let names = ["libm f64", "poly f64", "poly F64x2", "poly F64x4", "poly F64x8"];
    let mut sc: Vec<Vec<f64>> = vec![vec![]; 5];
    let mut ex: Vec<Vec<f64>> = vec![vec![]; 5];
    for _ in 0..rounds {
        sc[0].push(chained::<f64>(|x| {
            let (s, c) = x.sin_cos();
            s + c
        }));
        sc[1].push(chained::<f64>(|x| {
            let (s, c) = transcendental::sin_cos(x);
            s + c
        }));
        sc[2].push(chained::<F64x2>(|x| {
            let (s, c) = x.sin_cos();
            s + c
        }));
        sc[3].push(chained::<F64x4>(|x| {
            let (s, c) = x.sin_cos();
            s + c
        }));
        sc[4].push(chained::<F64x8>(|x| {
            let (s, c) = x.sin_cos();
            s + c
        }));
        ex[0].push(chained::<f64>(f64::exp));
        ex[1].push(chained::<f64>(transcendental::exp));
        ex[2].push(chained::<F64x2>(Real::exp));
        ex[3].push(chained::<F64x4>(Real::exp));
        ex[4].push(chained::<F64x8>(Real::exp));
    }
    println!("ns per evaluation (per lane), medians of {rounds} interleaved rounds:");
    for (i, name) in names.iter().enumerate() {
        println!("{name:>11}: sin_cos {:6.2}   exp {:6.2}", median(&mut sc[i]), median(&mut ex[i]));
    }
}
