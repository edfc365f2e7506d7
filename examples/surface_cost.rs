//! The cost of one production right-hand side of `arn2` (rigid atom–diatom, 2 coordinates) with
//! its potential from each route: the generated expressions of `molecules/arn2.toml`, the same
//! surface in C compiled in (`rovib_ffi::builtin::arn2_spline`), and, given a path, the same C
//! built as a shared library and loaded at run time. Thread CPU time per evaluation over 8
//! states, the median of 7 rounds of 20 000 evaluations.
//!
//! ```sh
//! gcc -O2 -shared -fPIC -I ffi/include -o /tmp/libarn2.so ffi/surfaces/arn2_spline.c -lm
//! cargo run --release --example surface_cost -- /tmp/libarn2.so
//! ```

mod common;
use common::thread_cpu;

use std::hint::black_box;
use std::path::Path;

use rovib::molecules::Arn2;
use rovib::runtime::Molecule;
use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::nalgebra::{SVector, Vector3};
use rovib::runtime::surface::WithPotential;
use rovib_ffi::{SharedLibrary, builtin};

fn states() -> Vec<PhaseState<2>> {
    (0..8)
        .map(|s| {
            let f = s as f64 / 8.0;
            PhaseState {
                q: SVector::from([6.0 + 2.0 * f, 1.2 + 0.6 * f]),
                p: SVector::from([0.3 - f, 1.0 + f]),
                euler: Vector3::new(0.3 + f, 1.1 - 0.2 * f, -0.7),
                pe: Vector3::new(2.0 * f, -1.0, 3.0 - f),
            }
        })
        .collect()
}

/// Median thread CPU time per right-hand side, ns.
fn cost<M: Molecule<2, 3>>(m: &M) -> f64 {
    let states = states();
    let mut rounds: Vec<f64> = (0..7)
        .map(|_| {
            let mut total = 0.0;
            for s in &states {
                let mut system = ReducedSystem::new(m, Reduction::none(), s);
                let mut y = vec![0.0; system.dim()];
                system.reduce(s, &mut y).expect("a regular state");
                let mut dy = vec![0.0; y.len()];
                let begin = thread_cpu();
                for _ in 0..2500 {
                    system.rhs(0.0, black_box(&y), &mut dy).expect("finite");
                    black_box(&dy);
                }
                total += thread_cpu() - begin;
            }
            total / (2500 * states.len()) as f64 * 1e9
        })
        .collect();
    rounds.sort_by(f64::total_cmp);
    rounds[rounds.len() / 2]
}

fn main() {
    println!("generated expressions   {:.1} ns", cost(&Arn2));
    println!(
        "C compiled in           {:.1} ns",
        cost(&WithPotential { molecule: Arn2, potential: builtin::arn2_spline() })
    );
    if let Some(path) = std::env::args().nth(1) {
        let library = SharedLibrary::load(Path::new(&path)).unwrap_or_else(|e| panic!("{e}"));
        let surface = library.surface::<2>().unwrap_or_else(|e| panic!("{e}"));
        println!("shared library          {:.1} ns", cost(&WithPotential { molecule: Arn2, potential: surface }));
    }
}
