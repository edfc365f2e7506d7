//! What run-time potential parameters cost: one production right-hand side (`ReducedSystem`,
//! what `rovib run` integrates) of each molecule with compiled-in parameters against the same
//! molecule through `WithParameters` (the generated `potential_gradient_with`, parameters read
//! from a slice) at the compiled values. Interleaved rounds, thread CPU time, 8 states per
//! molecule (reference geometry stretched and bent by varying amounts, varied momenta and J).
//!
//! ```sh
//! cargo run --release --features examples --example parameters_cost            # or: -- ROUNDS EVALS_PER_ROUND
//! ```

mod common;
use common::thread_cpu;

use std::hint::black_box;

use rovib::molecules;
use rovib::parameters::WithParameters;
use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::nalgebra::{SVector, Vector3};
use rovib::runtime::units::CoordinateUnit;
use rovib::runtime::{Molecule, MoleculeVisitor};

fn states<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M) -> Vec<PhaseState<N>> {
    let reference = m.reference_geometry().unwrap_or_else(SVector::zeros);
    let coords = m.coordinates();
    (0..8)
        .map(|s| {
            let f = s as f64 / 8.0;
            PhaseState {
                q: SVector::from_fn(|k, _| match coords[k].unit {
                    CoordinateUnit::Length(_) => reference[k] * (0.97 + 0.08 * f),
                    CoordinateUnit::Angle(_) => reference[k] + 0.1 * (f - 0.5),
                }),
                p: SVector::from_fn(|k, _| (k as f64 + 1.0) * (f - 0.4)),
                euler: Vector3::new(0.3 + f, 1.1 - 0.2 * f, -0.7),
                pe: Vector3::new(2.0 * f, -1.0, 3.0 - f),
            }
        })
        .collect()
}

/// CPU time of `evals` right-hand sides over the states, s per evaluation.
fn time<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, states: &[PhaseState<N>], evals: usize) -> f64 {
    let mut total = 0.0;
    for s in states {
        let mut system = ReducedSystem::new(m, Reduction::none(), s);
        let mut y = vec![0.0; system.dim()];
        system.reduce(s, &mut y).expect("a regular state");
        let mut dy = vec![0.0; y.len()];
        let begin = thread_cpu();
        for _ in 0..evals {
            system.rhs(0.0, black_box(&y), &mut dy).expect("finite");
            black_box(&dy);
        }
        total += thread_cpu() - begin;
    }
    total / (evals * states.len()) as f64
}

struct Cost {
    rounds: usize,
    evals: usize,
}

impl MoleculeVisitor for Cost {
    type Output = Option<String>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Option<String> {
        if m.parameters().is_empty() {
            return None;
        }
        let values = m.parameters().iter().map(|(_, v)| *v).collect();
        let states = states(&m);
        let with = WithParameters { molecule: m, values };
        let m = &with.molecule;
        let (mut compiled, mut runtime) = (Vec::new(), Vec::new());
        for round in 0..self.rounds {
            // Alternate which goes first.
            if round % 2 == 0 {
                compiled.push(time(m, &states, self.evals));
                runtime.push(time(&with, &states, self.evals));
            } else {
                runtime.push(time(&with, &states, self.evals));
                compiled.push(time(m, &states, self.evals));
            }
        }
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let ratios: Vec<f64> = runtime.iter().zip(&compiled).map(|(r, c)| r / c).collect();
        let (lo, hi) = ratios.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), r| (lo.min(*r), hi.max(*r)));
        let (c, r) = (median(&mut compiled), median(&mut runtime));
        Some(format!(
            "| {} | {} | {:.1} | {:.1} | {:.3} | {lo:.3}–{hi:.3} |",
            m.name(),
            m.parameters().len(),
            c * 1e9,
            r * 1e9,
            r / c
        ))
    }
}

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let (rounds, evals) = (args.first().copied().unwrap_or(11), args.get(1).copied().unwrap_or(20_000));
    println!("{rounds} interleaved rounds of {evals} evaluations × 8 states; thread CPU time, median per evaluation");
    println!("| molecule | parameters | compiled (ns) | run-time (ns) | ratio | ratio range |");
    println!("| --- | ---: | ---: | ---: | ---: | --- |");
    for name in molecules::NAMES {
        if let Some(Some(line)) = molecules::visit(name, Cost { rounds, evals }) {
            println!("{line}");
        }
    }
}
