//! rovib's side of the interleaved CasADi comparison (`benches/casadi/interleaved.py`): the
//! production right-hand side of water (`ReducedSystem` with nothing reduced, what `rovib run`
//! integrates), chained as in an integrator (each input is the previous input plus `1e-3` times
//! the previous output) from each of the states in a file, timed with this thread's CPU time.
//!
//! ```sh
//! cargo run --release --features examples --example rhs_chain -- STATES ITERS
//! ```
//!
//! `STATES` holds one state a line, 12 numbers in atomic units in the seed's variables
//! `r1 r2 alpha p_r1 p_r2 p_alpha phi theta psi p_phi p_theta p_psi` (the CasADi model's `x`);
//! each is converted to the production variables (q, p, quaternion, body-frame J) before timing.
//! Prints `ns_per_evaluation checksum`.

mod common;
use common::thread_cpu;

use std::hint::black_box;

use rovib::molecules::H2o;
use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::nalgebra::{SVector, Vector3};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(path), Some(iters)) = (args.first(), args.get(1).and_then(|a| a.parse::<usize>().ok())) else {
        eprintln!("usage: rhs_chain STATES ITERS");
        std::process::exit(2);
    };
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(2);
    });
    let m = H2o;
    let mut starts = Vec::new();
    for (line_no, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let x: Vec<f64> = line.split_whitespace().filter_map(|v| v.parse().ok()).collect();
        if x.len() != 12 {
            eprintln!("{path}:{}: expected 12 numbers, found {}", line_no + 1, x.len());
            std::process::exit(2);
        }
        let s = PhaseState {
            q: SVector::from([x[0], x[1], x[2]]),
            p: SVector::from([x[3], x[4], x[5]]),
            euler: Vector3::new(x[6], x[7], x[8]),
            pe: Vector3::new(x[9], x[10], x[11]),
        };
        let system = ReducedSystem::new(&m, Reduction::none(), &s);
        let mut y = vec![0.0; system.dim()];
        if let Err(e) = system.reduce(&s, &mut y) {
            eprintln!("{path}:{}: {e}", line_no + 1);
            std::process::exit(2);
        }
        starts.push(y);
    }
    let template = PhaseState { q: SVector::from([1.81, 1.81, 1.824]), ..PhaseState::default() };
    let mut system = ReducedSystem::new(&m, Reduction::none(), &template);
    let mut d = vec![0.0; system.dim()];
    let mut checksum = 0.0;
    let begin = thread_cpu();
    for s in &starts {
        let mut y = s.clone();
        for _ in 0..iters {
            system.rhs(0.0, black_box(&y), &mut d).expect("a valid state");
            for (yi, di) in y.iter_mut().zip(&d) {
                *yi += 1e-3 * di;
            }
        }
        checksum += y[0];
    }
    let ns = (thread_cpu() - begin) * 1e9 / (starts.len() * iters) as f64;
    println!("{ns:.2} {checksum:.17e}");
}
