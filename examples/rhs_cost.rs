//! The cost of one production right-hand side (`ReducedSystem` with nothing reduced: what
//! `rovib run` integrates) per compiled-in molecule: thread CPU time per evaluation over 8
//! varied states, the median of several rounds. Meant for comparing two builds (before/after a
//! generator change) by running their binaries alternately, and for large molecules built with
//! `ROVIB_MOLECULES_DIR` (docs/src/history/benchmarks.md, "Large molecules").
//!
//! ```sh
//! cargo run --release --features examples --example rhs_cost -- [ROUNDS [EVALS]] [NAME...]
//! ```
//!
//! Prints one line per molecule: `name N median_ns min_ns max_ns` (per evaluation, over the
//! rounds). With `ROUNDS = 0` it runs `EVALS` evaluations of the first named molecule and
//! prints nothing else, for `valgrind --tool=callgrind` (instructions per evaluation from two
//! runs with different `EVALS`).

mod common;
use common::thread_cpu;

use std::hint::black_box;

use rovib::molecules;
use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::nalgebra::{SVector, Vector3};
use rovib::runtime::units::CoordinateUnit;
use rovib::runtime::{Molecule, MoleculeVisitor};

/// Eight states about the reference geometry: lengths scaled by 0.97–1.04, angles moved by
/// ±0.05 rad, varied momenta and angular momentum.
fn states<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M) -> Vec<PhaseState<N>> {
    let reference = m.reference_geometry().unwrap_or_else(SVector::zeros);
    let coords = m.coordinates();
    (0..8)
        .map(|s| {
            let f = s as f64 / 8.0;
            PhaseState {
                q: SVector::from_fn(|k, _| match coords[k].unit {
                    CoordinateUnit::Length(_) => reference[k] * (0.97 + 0.08 * f),
                    CoordinateUnit::Angle(_) => reference[k] + 0.1 * (f - 0.5) * if k % 2 == 0 { 1.0 } else { -1.0 },
                }),
                p: SVector::from_fn(|k, _| ((k % 7) as f64 - 3.0) * (f - 0.4)),
                euler: Vector3::new(0.3 + f, 1.1 - 0.2 * f, -0.7),
                pe: Vector3::new(2.0 * f, -1.0, 3.0 - f),
            }
        })
        .collect()
}

/// CPU time of `evals` right-hand sides spread over the states, s per evaluation. A state where
/// the right-hand side is not defined (a linear molecule's straight geometry, where the inertia
/// tensor is singular) is left out; `None` when every state is.
fn time<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    states: &[PhaseState<N>],
    evals: usize,
) -> Option<f64> {
    let (mut total, mut count) = (0.0, 0);
    let per_state = evals.div_ceil(states.len());
    for s in states {
        let mut system = ReducedSystem::new(m, Reduction::none(), s);
        let mut y = vec![0.0; system.dim()];
        let mut dy = vec![0.0; y.len()];
        if system.reduce(s, &mut y).is_err() || system.rhs(0.0, &y, &mut dy).is_err() {
            continue;
        }
        let begin = thread_cpu();
        for _ in 0..per_state {
            // Finite at this state (checked above): the result is only kept from being optimised out.
            let _ = system.rhs(0.0, black_box(&y), &mut dy);
            black_box(&dy);
        }
        total += thread_cpu() - begin;
        count += per_state;
    }
    (count > 0).then(|| total / count as f64)
}

struct Cost {
    rounds: usize,
    evals: usize,
}

impl MoleculeVisitor for Cost {
    type Output = String;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> String {
        let states = states(&m);
        if self.rounds == 0 {
            time(&m, &states, self.evals);
            return String::new();
        }
        let Some(mut t) = (0..self.rounds).map(|_| time(&m, &states, self.evals)).collect::<Option<Vec<f64>>>() else {
            return format!("{} {N} skipped: the right-hand side is undefined at every test state", m.name());
        };
        t.sort_by(f64::total_cmp);
        format!("{} {N} {:.1} {:.1} {:.1}", m.name(), t[t.len() / 2] * 1e9, t[0] * 1e9, t[t.len() - 1] * 1e9)
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let numbers: Vec<usize> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let mut names: Vec<&str> = args.iter().filter(|a| a.parse::<usize>().is_err()).map(String::as_str).collect();
    if names.is_empty() {
        names = molecules::NAMES.to_vec();
    }
    let (rounds, evals) = (numbers.first().copied().unwrap_or(5), numbers.get(1).copied().unwrap_or(2000));
    for name in names {
        match molecules::visit(name, Cost { rounds, evals }) {
            Some(line) if !line.is_empty() => println!("{line}"),
            Some(_) => return,
            None => {
                eprintln!("no molecule {name:?}; compiled in: {}", molecules::NAMES.join(", "));
                std::process::exit(2);
            }
        }
    }
}
