//! SIMD lanes against one trajectory at a time, for water, measured as BENCHMARKS.md reports it
//! ("Many trajectories per core"): thread CPU time, the contenders interleaved round by round in
//! one process, on varied states.
//!
//! 1. Cost per trajectory-evaluation of the production right-hand side: `ReducedSystem::rhs`
//!    (`f64`, what `rovib run` integrates), and `production_rhs` at `F64x2` and `F64x4`
//!    (divided by the lanes). Chained as in an integrator: each input is the previous input plus
//!    `1e-3` times the previous output, from 64 different starting states.
//! 2. Ensemble throughput: 64 water trajectories over 10⁴ a.u. at rtol = atol = 1e-8 with 101
//!    output times (the ensemble bench's settings), by the scalar `Dop853` one after the other and
//!    by `Dop853Lanes` at 2 and 4 lanes.
//! 3. One trajectory: `scenes/h2o_1e4au.toml`'s start (BENCHMARKS.md's benchmark trajectory)
//!    over 10⁴ a.u. at rtol = atol = 1e-10 with 101 output times, by the scalar `Dop853` with
//!    the production system (what `rovib run` integrates, without its file output), CPU ms
//!    per trajectory (mean of 8 runs in each round).
//!
//! ```sh
//! cargo run --release --features examples --example lanes_bench            # 7 rounds
//! cargo run --release --features examples --example lanes_bench -- 15      # more rounds
//! ```
//!
//! `lanes_bench profile-scalar` and `lanes_bench profile-x2` run only one ensemble pass of that
//! contender (64 trajectories), to be profiled (`valgrind --tool=callgrind`). `lanes_bench
//! checksum` prints the bits of a checksum of the lanes' outputs at 2, 4 and 8 lanes, to compare
//! builds (baseline against `-C target-cpu=native`).
//!
//! Built for the default target (baseline x86-64: SSE2, no AVX, no FMA) unless RUSTFLAGS say
//! otherwise; the program prints which vector features the build has.

mod common;
use common::thread_cpu;

use std::hint::black_box;
use std::ops::ControlFlow;

use rovib::molecules::H2o;
use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::hamiltonian::lanes::{ProductionLanes, production_rhs};
use rovib::runtime::integrate::{Dop853, Dop853Lanes, Dop853Options, LaneFailure, LaneFeeder, OdeSystem, Stats};
use rovib::runtime::lanes::{F64x2, F64x4, F64x8, Real};
use rovib::runtime::nalgebra::{SVector, UnitQuaternion, Vector3};
use rovib::scene::parse_scene;
use rovib::start::initial_state;
use rovib_testkit::Rng;

const DIM: usize = 13;

/// Water near equilibrium with thermal-sized momenta, a random orientation and |J| of a few ħ.
fn states(count: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = Rng::new(seed);
    (0..count)
        .map(|_| {
            let q = [1.81 * rng.uniform(0.97, 1.03), 1.81 * rng.uniform(0.97, 1.03), 1.824 + rng.uniform(-0.08, 0.08)];
            let p = [rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0), rng.uniform(-1.0, 1.0)];
            let axis = Vector3::from_fn(|_, _| rng.uniform(-1.0, 1.0));
            let o = *UnitQuaternion::from_scaled_axis(axis * 3.0).quaternion();
            let j = [rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0)];
            q.into_iter().chain(p).chain([o.w, o.i, o.j, o.k]).chain(j).collect()
        })
        .collect()
}

fn template() -> PhaseState<3> {
    PhaseState {
        q: SVector::from([1.81, 1.81, 1.824]),
        p: SVector::zeros(),
        euler: Vector3::zeros(),
        pe: Vector3::zeros(),
    }
}

/// ns per evaluation of the f64 production system, chained.
fn rhs_f64(starts: &[Vec<f64>], iters: usize) -> f64 {
    let m = H2o;
    let mut system = ReducedSystem::new(&m, Reduction::none(), &template());
    let mut d = vec![0.0; DIM];
    let t0 = thread_cpu();
    for s in starts {
        let mut y = s.clone();
        for _ in 0..iters {
            system.rhs(0.0, &y, &mut d).expect("a valid state");
            for i in 0..DIM {
                y[i] += 1e-3 * d[i];
            }
        }
        black_box(&y);
    }
    (thread_cpu() - t0) * 1e9 / (starts.len() * iters) as f64
}

/// ns per trajectory-evaluation of the production right-hand side at `T`, chained.
fn rhs_lanes<T: Real>(starts: &[Vec<f64>], iters: usize) -> f64 {
    let m = H2o;
    let mut d = vec![T::splat(0.0); DIM];
    let t0 = thread_cpu();
    for group in starts.chunks_exact(T::LANES) {
        let mut y: Vec<T> = (0..DIM)
            .map(|i| {
                let mut v = T::splat(0.0);
                for (l, s) in group.iter().enumerate() {
                    v.set_lane(l, s[i]);
                }
                v
            })
            .collect();
        for _ in 0..iters {
            let ok = production_rhs::<_, T, 3, 3>(&m, &y, &mut d, 1e-12);
            assert_eq!(ok, T::ALL);
            for i in 0..DIM {
                y[i] = y[i] + T::splat(1e-3) * d[i];
            }
        }
        black_box(&y);
    }
    (thread_cpu() - t0) * 1e9 / (starts.len() * iters) as f64
}

const T_END: f64 = 1e4;
const INTERVAL: f64 = 100.0;

fn options() -> Dop853Options {
    Dop853Options { rtol: 1e-8, atol: 1e-8, ..Default::default() }
}

/// CPU ms per trajectory of the scalar DOP853, and right-hand sides per trajectory.
fn ensemble_scalar(starts: &[Vec<f64>]) -> (f64, f64) {
    let m = H2o;
    let mut system = ReducedSystem::new(&m, Reduction::none(), &template());
    let mut solver = Dop853::new(DIM, options()).unwrap();
    let mut evals = 0;
    let t0 = thread_cpu();
    for y0 in starts {
        let mut sink = 0.0;
        let mut observer = |_t: f64, y: &[f64]| {
            sink += y[0];
            ControlFlow::Continue(())
        };
        let stats = solver.integrate(&mut system, 0.0, y0, T_END, INTERVAL, &mut observer).expect("a valid run");
        black_box(sink);
        evals += stats.rhs_evals;
    }
    ((thread_cpu() - t0) * 1e3 / starts.len() as f64, evals as f64 / starts.len() as f64)
}

struct Feed<'a> {
    starts: &'a [Vec<f64>],
    next: usize,
    sink: f64,
    checksum: bool,
    /// XOR of the bits of every output's state and time: a checksum independent of the order in
    /// which the lanes deliver their outputs.
    xor: u64,
    evals: u64,
}

impl LaneFeeder for Feed<'_> {
    fn next(&mut self, _lane: usize, y0: &mut [f64]) -> bool {
        let Some(s) = self.starts.get(self.next) else { return false };
        y0.copy_from_slice(s);
        self.next += 1;
        true
    }
    fn observe(&mut self, _lane: usize, t: f64, y: &[f64]) -> ControlFlow<()> {
        self.sink += y[0];
        if self.checksum {
            // Each value's bits rotated by its component, so equal values do not cancel.
            let mut h = t.to_bits();
            for (i, v) in y.iter().enumerate() {
                h ^= v.to_bits().rotate_left(i as u32 * 5 + 1);
            }
            self.xor ^= h.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
        ControlFlow::Continue(())
    }
    fn finish(&mut self, _lane: usize, result: Result<Stats, LaneFailure>) {
        self.evals += result.expect("a valid run").rhs_evals;
    }
}

/// CPU ms per trajectory of the batched DOP853 at `T`.
fn ensemble_lanes<T: Real>(starts: &[Vec<f64>]) -> f64 {
    ensemble_lanes_run::<T>(starts, false).0
}

/// CPU ms per trajectory of the batched DOP853 at `T`, and (with `checksum`) a checksum of every
/// output of every trajectory that does not depend on the order of the outputs.
fn ensemble_lanes_run<T: Real>(starts: &[Vec<f64>], checksum: bool) -> (f64, u64) {
    let m = H2o;
    let mut solver = Dop853Lanes::<T>::new(DIM, options()).unwrap();
    let mut feed = Feed { starts, next: 0, sink: 0.0, checksum, xor: 0, evals: 0 };
    let t0 = thread_cpu();
    solver.integrate(&mut ProductionLanes::new(&m, 1e-12), 0.0, T_END, INTERVAL, &mut feed).unwrap();
    black_box(feed.sink);
    ((thread_cpu() - t0) * 1e3 / starts.len() as f64, feed.xor)
}

/// `scenes/h2o_1e4au.toml`'s initial state in the production layout.
fn scene_start() -> Vec<f64> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/h2o_1e4au.toml");
    let text = std::fs::read_to_string(path).expect("scenes/h2o_1e4au.toml");
    let scene = parse_scene(path, &text).expect("a valid scene");
    let start = initial_state(&H2o, &scene).expect("a valid start");
    let system = ReducedSystem::from_body(&H2o, Reduction::none(), &start.body);
    let mut y = vec![0.0; DIM];
    system.reduce_body(&start.body, &mut y).expect("a regular start");
    y
}

/// CPU ms of one scalar DOP853 run from `y0` over 10⁴ a.u. at rtol = atol = 1e-10 (mean of
/// `reps`), and its right-hand sides.
fn one_trajectory(y0: &[f64], reps: usize) -> (f64, u64) {
    let m = H2o;
    let mut system = ReducedSystem::new(&m, Reduction::none(), &template());
    let options = Dop853Options { rtol: 1e-10, atol: 1e-10, ..Default::default() };
    let mut solver = Dop853::new(DIM, options).unwrap();
    let mut evals = 0;
    let t0 = thread_cpu();
    for _ in 0..reps {
        let mut sink = 0.0;
        let mut observer = |_t: f64, y: &[f64]| {
            sink += y[0];
            ControlFlow::Continue(())
        };
        evals = solver.integrate(&mut system, 0.0, y0, T_END, INTERVAL, &mut observer).expect("a valid run").rhs_evals;
        black_box(sink);
    }
    ((thread_cpu() - t0) * 1e3 / reps as f64, evals)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let arg = std::env::args().nth(1);
    match arg.as_deref() {
        Some("profile-scalar") => {
            let (ms, _) = ensemble_scalar(&states(64, 1));
            println!("scalar ensemble: {ms:.3} ms per trajectory");
            return;
        }
        Some("checksum") => {
            // The lanes' results do not depend on the vector width or the build's target
            // features: the same bits here for a baseline and a `-C target-cpu=native` build.
            let starts = states(64, 1);
            let sums = [
                ensemble_lanes_run::<F64x2>(&starts, true).1,
                ensemble_lanes_run::<F64x4>(&starts, true).1,
                ensemble_lanes_run::<F64x8>(&starts, true).1,
            ];
            println!(
                "checksum of the lanes' outputs (F64x2, F64x4, F64x8): {:016x} {:016x} {:016x}",
                sums[0], sums[1], sums[2]
            );
            return;
        }
        Some("profile-x2") => {
            println!("F64x2 ensemble: {:.3} ms per trajectory", ensemble_lanes::<F64x2>(&states(64, 1)));
            return;
        }
        _ => {}
    }
    let rounds: usize = arg.and_then(|a| a.parse().ok()).unwrap_or(7);
    println!(
        "target features: sse2 {}, avx {}, avx2 {}, fma {}, avx512f {}",
        cfg!(target_feature = "sse2"),
        cfg!(target_feature = "avx"),
        cfg!(target_feature = "avx2"),
        cfg!(target_feature = "fma"),
        cfg!(target_feature = "avx512f")
    );
    let starts = states(64, 1);
    let scene_y0 = scene_start();
    let (mut one, mut one_evals) = (vec![], 0);
    let (mut f, mut x2, mut x4, mut x8) = (vec![], vec![], vec![], vec![]);
    let (mut ef, mut ex2, mut ex4, mut ex8) = (vec![], vec![], vec![], vec![]);
    let mut evals = 0.0;
    for round in 0..rounds {
        f.push(rhs_f64(&starts, 2000));
        x2.push(rhs_lanes::<F64x2>(&starts, 2000));
        x4.push(rhs_lanes::<F64x4>(&starts, 2000));
        x8.push(rhs_lanes::<F64x8>(&starts, 2000));
        let (ms, e) = ensemble_scalar(&starts);
        evals = e;
        ef.push(ms);
        ex2.push(ensemble_lanes::<F64x2>(&starts));
        ex4.push(ensemble_lanes::<F64x4>(&starts));
        ex8.push(ensemble_lanes::<F64x8>(&starts));
        let (ms, e) = one_trajectory(&scene_y0, 8);
        one.push(ms);
        one_evals = e;
        println!(
            "round {round}: rhs ns/eval f64 {:.1}, x2 {:.1}, x4 {:.1}, x8 {:.1}; ensemble ms/trajectory f64 {:.3}, x2 {:.3}, \
             x4 {:.3}, x8 {:.3}; one trajectory at 1e-10 {:.3} ms",
            f[round], x2[round], x4[round], x8[round], ef[round], ex2[round], ex4[round], ex8[round], one[round]
        );
    }
    let ratio = |a: &[f64], b: &[f64]| {
        let mut r: Vec<f64> = a.iter().zip(b).map(|(x, y)| x / y).collect();
        median(&mut r)
    };
    println!("\nmedians over {rounds} interleaved rounds (thread CPU time):");
    println!(
        "rhs per trajectory-evaluation: f64 {:.1} ns, F64x2 {:.1} ns ({:.2}x), F64x4 {:.1} ns ({:.2}x), F64x8 {:.1} ns ({:.2}x)",
        median(&mut f.clone()),
        median(&mut x2.clone()),
        ratio(&f, &x2),
        median(&mut x4.clone()),
        ratio(&f, &x4),
        median(&mut x8.clone()),
        ratio(&f, &x8)
    );
    println!(
        "ensemble, water 1e4 a.u. rtol 1e-8 ({evals:.0} rhs per trajectory): f64 {:.3} ms, F64x2 {:.3} ms ({:.2}x), F64x4 {:.3} ms ({:.2}x), \
         F64x8 {:.3} ms ({:.2}x) per trajectory",
        median(&mut ef.clone()),
        median(&mut ex2.clone()),
        ratio(&ef, &ex2),
        median(&mut ex4.clone()),
        ratio(&ef, &ex4),
        median(&mut ex8.clone()),
        ratio(&ef, &ex8)
    );
    println!(
        "one trajectory, scenes/h2o_1e4au.toml at rtol 1e-10 ({one_evals} rhs): {:.3} ms ({:.1} ns per rhs, integrator included)",
        median(&mut one.clone()),
        median(&mut one.clone()) * 1e6 / one_evals as f64
    );
}
