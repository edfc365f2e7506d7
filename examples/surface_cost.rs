//! The cost of one production right-hand side of `arn2` (rigid atom–diatom, 2 coordinates, 3
//! atoms) with its potential from each route: the generated expressions of
//! `molecules/arn2.toml` (scalar, and lane-generic at `F64x4` per trajectory-evaluation), the
//! same surface in C compiled into rovib-ffi (`builtin::arn2_spline`), loaded from a shared
//! library (given its path), named by a definition as a Rust file, as Fortran and as C (with
//! `--features surface-demos`; the Rust file also on lanes: kinematics lane-generic, potential
//! one lane at a time), with ∂U/∂q by central differences of the compiled-in C, and a surface
//! over Cartesian positions (a site–site Ar–N Lennard-Jones, `FromPositions`) against the same
//! surface hand-written in (R, θ). With a second path, `tests/surfaces/co2ar_sites.c` loaded as a
//! shared library over positions (`OnPositions`) on `co2ar` (2 coordinates, 4 atoms) against
//! co2ar's generated expressions. Thread CPU time per evaluation, the contenders interleaved
//! round by round; the median of 7 rounds of 8 states × 100 000 evaluations each (a round lasts tens of milliseconds: the thread CPU clock of /proc advances by scheduler ticks).
//!
//! ```sh
//! gcc -O2 -shared -fPIC -I ffi/include -o /tmp/libarn2.so ffi/surfaces/arn2_spline.c -lm
//! gcc -O2 -shared -fPIC -I ffi/include -o /tmp/libco2ar.so tests/surfaces/co2ar_sites.c -lm
//! cargo run --release --features examples,surface-demos --example surface_cost -- /tmp/libarn2.so /tmp/libco2ar.so
//! ```

mod common;
use common::thread_cpu;

use std::hint::black_box;
use std::path::Path;

use rovib::molecules::{Arn2, Co2ar};
use rovib::runtime::Molecule;
use rovib::runtime::finite_differences::CentralDifferences;
use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::hamiltonian::lanes::production_rhs;
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::lanes::{F64x4, Real};
use rovib::runtime::nalgebra::{SMatrix, SVector, Vector3};
use rovib::runtime::position_surface::{CartesianPotential, FromPositions, add_pair_terms};
use rovib::runtime::surface::{Potential, WithPotential};
use rovib_ffi::{SharedLibrary, builtin};

const EVALUATIONS: usize = 100_000;

/// A route's name and one measured round (ns per right-hand side).
type Contender<'a> = (&'static str, Box<dyn Fn() -> f64 + 'a>);

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

/// Thread CPU time per scalar right-hand side, ns, over the states.
fn scalar<M: Molecule<2, NA>, const NA: usize>(m: &M) -> f64 {
    let mut total = 0.0;
    for s in &states() {
        let mut system = ReducedSystem::new(m, Reduction::none(), s);
        let mut y = vec![0.0; system.dim()];
        system.reduce(s, &mut y).expect("a regular state");
        let mut dy = vec![0.0; y.len()];
        let begin = thread_cpu();
        for _ in 0..EVALUATIONS {
            system.rhs(0.0, black_box(&y), &mut dy).expect("finite");
            black_box(&dy);
        }
        total += thread_cpu() - begin;
    }
    total / (EVALUATIONS * 8) as f64 * 1e9
}

/// Thread CPU time per trajectory-evaluation of the lane-generic right-hand side at `F64x4`, ns.
fn lanes<M: Molecule<2, 3>>(m: &M) -> f64 {
    let flat: Vec<Vec<f64>> = states()
        .iter()
        .map(|s| {
            let system = ReducedSystem::new(m, Reduction::none(), s);
            let mut y = vec![0.0; system.dim()];
            system.reduce(s, &mut y).expect("a regular state");
            y
        })
        .collect();
    let dim = flat[0].len();
    let mut total = 0.0;
    for group in flat.chunks_exact(F64x4::LANES) {
        let y: Vec<F64x4> = (0..dim)
            .map(|i| {
                let mut v = F64x4::splat(0.0);
                for (l, s) in group.iter().enumerate() {
                    v.set_lane(l, s[i]);
                }
                v
            })
            .collect();
        let mut d = vec![F64x4::splat(0.0); dim];
        let begin = thread_cpu();
        for _ in 0..EVALUATIONS {
            let ok = production_rhs::<_, F64x4, 2, 3>(m, black_box(&y), &mut d, 1e-12);
            assert_eq!(ok, F64x4::ALL);
            black_box(&d);
        }
        total += thread_cpu() - begin;
    }
    total / (EVALUATIONS * flat.len()) as f64 * 1e9
}

/// The N–N bond of arn2 (bohr) and a Lennard-Jones Ar–N site–site model.
const RNN: f64 = 2.0744;
fn lj(r: f64) -> (f64, f64) {
    let s6 = (6.0 / r).powi(6);
    (8e-4 * (s6 * s6 - s6), 8e-4 * (-12.0 * s6 * s6 + 6.0 * s6) / r)
}

/// Ar–N1 + Ar–N2 over the positions.
struct SiteSite;
impl CartesianPotential<3> for SiteSite {
    fn energy(&self, x: &SMatrix<f64, 3, 3>) -> f64 {
        let mut g = SMatrix::zeros();
        self.energy_gradient(x, &mut g)
    }
    fn energy_gradient(&self, x: &SMatrix<f64, 3, 3>, grad: &mut SMatrix<f64, 3, 3>) -> f64 {
        grad.fill(0.0);
        add_pair_terms(x, [(2, 0), (2, 1)], lj, grad)
    }
}

/// The same in (R, θ), by hand.
struct SiteSiteInternal;
impl Potential<2> for SiteSiteInternal {
    fn energy(&self, q: &SVector<f64, 2>) -> f64 {
        let mut g = SVector::zeros();
        self.energy_gradient(q, &mut g)
    }
    fn energy_gradient(&self, q: &SVector<f64, 2>, grad: &mut SVector<f64, 2>) -> f64 {
        let (s, c) = q[1].sin_cos();
        let mut u = 0.0;
        grad.fill(0.0);
        for sign in [-1.0, 1.0] {
            let d = (q[0] * q[0] + sign * q[0] * RNN * c + RNN * RNN / 4.0).sqrt();
            let (v, dv) = lj(d);
            u += v;
            grad[0] += dv * (q[0] + sign * RNN / 2.0 * c) / d;
            grad[1] += dv * (-sign * q[0] * RNN * s) / (2.0 * d);
        }
        u
    }
}

fn main() {
    let load =
        |k| std::env::args().nth(k).map(|path| SharedLibrary::load(Path::new(&path)).unwrap_or_else(|e| panic!("{e}")));
    let library = load(1);
    let positions_library = load(2);
    let mut contenders: Vec<Contender<'_>> = vec![
        ("generated expressions (f64)", Box::new(|| scalar(&Arn2))),
        ("generated expressions (F64x4, per trajectory)", Box::new(|| lanes(&Arn2))),
        (
            "C compiled into rovib-ffi",
            Box::new(|| scalar(&WithPotential { molecule: Arn2, potential: builtin::arn2_spline() })),
        ),
        (
            "C compiled in, ∂U/∂q by central differences",
            Box::new(|| {
                scalar(&WithPotential { molecule: Arn2, potential: CentralDifferences(builtin::arn2_spline()) })
            }),
        ),
        (
            "site–site LJ over positions (FromPositions)",
            Box::new(|| {
                scalar(&WithPotential {
                    molecule: Arn2,
                    potential: FromPositions::<_, _, 3> { molecule: Arn2, surface: SiteSite },
                })
            }),
        ),
        (
            "site–site LJ in (R, θ) by hand",
            Box::new(|| scalar(&WithPotential { molecule: Arn2, potential: SiteSiteInternal })),
        ),
    ];
    #[cfg(feature = "surface-demos")]
    {
        use rovib::molecules::{Arn2C, Arn2Fortran, Arn2Rust};
        contenders.push(("definition: Rust file (f64)", Box::new(|| scalar(&Arn2Rust))));
        contenders.push(("definition: Rust file (F64x4, per trajectory)", Box::new(|| lanes(&Arn2Rust))));
        contenders.push(("definition: Fortran (f64)", Box::new(|| scalar(&Arn2Fortran))));
        contenders.push(("definition: C (f64)", Box::new(|| scalar(&Arn2C))));
    }
    if let Some(library) = &library {
        let surface = library.surface::<2>().unwrap_or_else(|e| panic!("{e}"));
        contenders.push((
            "shared library (dlopen)",
            Box::new(move || scalar(&WithPotential { molecule: Arn2, potential: surface })),
        ));
    }
    if let Some(library) = &positions_library {
        let surface = library.positions_surface::<4>().unwrap_or_else(|e| panic!("{e}")).on(Co2ar);
        contenders.push(("co2ar: generated expressions (f64)", Box::new(|| scalar(&Co2ar))));
        contenders.push((
            "co2ar: shared library over positions (dlopen, OnPositions)",
            Box::new(move || scalar(&WithPotential { molecule: Co2ar, potential: surface })),
        ));
    }
    let mut rounds: Vec<Vec<f64>> = vec![Vec::new(); contenders.len()];
    for _ in 0..7 {
        for (i, (_, f)) in contenders.iter().enumerate() {
            rounds[i].push(f());
        }
    }
    for ((name, _), mut r) in contenders.iter().zip(rounds) {
        r.sort_by(f64::total_cmp);
        println!("{name:<48} {:>7.1} ns", r[r.len() / 2]);
    }
}
