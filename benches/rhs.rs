//! Criterion benchmarks of one right-hand-side evaluation per shipped molecule, through the
//! `OdeSystem` interface the integrators use:
//!
//! * `rhs/NAME/seed`: the seed path (`HamiltonianSystem`, eqs. 9–16 with ∂G);
//! * `rhs/NAME/fast`: the fast path (`FastSystem`, one block Cholesky + ∂T/∂q at fixed v);
//! * `rhs/NAME/fast_unfused`: the same with the generated `kinetic_and_gradient` replaced by the
//!   trait's default (separate `kinetic` and `kinetic_energy_gradient`): what the generator's
//!   fusion of the two saves;
//! * `rhs/NAME/production`: what `rovib run` integrates (`ReducedSystem`, body-frame J and a
//!   unit quaternion, nothing reduced);
//! * `rhs/NAME/zero_j`, `rhs/NAME/zero_j_orientation`: J = 0 (`ReducedSystem`), without and
//!   with the orientation;
//! * `rhs/NAME/frozen1`: the first internal coordinate frozen (molecules with N ≥ 2).
//!
//! For water only, the parts of the fast path one by one (`parts/h2o/...`).

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group};
use rovib::molecules;
use rovib::runtime::hamiltonian::fast::{self, FastSystem, MetricFactor, ReducedSystem, Reduction};
use rovib::runtime::hamiltonian::{HamiltonianSystem, PhaseState};
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::nalgebra::{SMatrix, SVector, Vector3};
use rovib::runtime::units::CoordinateUnit;
use rovib::runtime::{Kinematics, KineticMatrices, Molecule, MoleculeVisitor};

/// A fixed, generic state: the reference geometry with lengths stretched 3 % and angles opened
/// by 0.05 rad, momenta of a few ħ, orientation away from gimbal lock.
fn bench_state<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M) -> PhaseState<N> {
    let reference = m.reference_geometry().unwrap_or_else(SVector::zeros);
    let coords = m.coordinates();
    PhaseState {
        q: SVector::from_fn(|k, _| match coords[k].unit {
            CoordinateUnit::Length(_) => reference[k] * 1.03,
            CoordinateUnit::Angle(_) => reference[k] + 0.05,
        }),
        p: SVector::from_fn(|k, _| if k % 2 == 0 { 2.0 } else { -1.5 }),
        euler: Vector3::new(0.3, 1.1, -0.7),
        pe: Vector3::new(2.0, -3.0, 1.5),
    }
}

/// Benchmarks `system.rhs` at the flat state `y`.
fn bench_system<S: OdeSystem>(c: &mut Criterion, id: &str, system: &mut S, y: &[f64]) {
    let mut dy = vec![0.0; y.len()];
    system.rhs(0.0, y, &mut dy).expect("the benchmark state is valid");
    c.bench_function(id, |b| {
        b.iter(|| {
            system.rhs(0.0, black_box(y), &mut dy).unwrap();
            black_box(&dy);
        })
    });
}

/// A molecule with every generated method but `kinetic_and_gradient`, which falls back to the
/// trait's default: two separate generated calls. Measures the generator's fusion.
#[derive(Copy, Clone)]
struct Unfused<M>(M);

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Kinematics<N, NA> for Unfused<M> {
    fn name(&self) -> &'static str {
        self.0.name()
    }
    fn source(&self) -> &'static str {
        self.0.source()
    }
    fn atoms(&self) -> [rovib::runtime::Atom; NA] {
        self.0.atoms()
    }
    fn coordinates(&self) -> [rovib::runtime::Coordinate; N] {
        self.0.coordinates()
    }
    fn positions(&self, q: &SVector<f64, N>, r: &mut SMatrix<f64, 3, NA>) {
        self.0.positions(q, r)
    }
    fn positions_jacobian(&self, q: &SVector<f64, N>, dr: &mut [SMatrix<f64, 3, NA>; N]) {
        self.0.positions_jacobian(q, dr)
    }
    fn kinetic(&self, q: &SVector<f64, N>, k: &mut KineticMatrices<N>) {
        self.0.kinetic(q, k)
    }
    fn kinetic_jacobian(&self, q: &SVector<f64, N>, dk: &mut [KineticMatrices<N>; N]) {
        self.0.kinetic_jacobian(q, dk)
    }
    fn kinetic_energy_gradient(
        &self,
        q: &SVector<f64, N>,
        omega: &Vector3<f64>,
        qdot: &SVector<f64, N>,
        grad: &mut SVector<f64, N>,
    ) -> f64 {
        self.0.kinetic_energy_gradient(q, omega, qdot, grad)
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Molecule<N, NA> for Unfused<M> {
    fn potential(&self, q: &SVector<f64, N>) -> f64 {
        self.0.potential(q)
    }
    fn potential_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        self.0.potential_gradient(q, grad)
    }
}

struct BenchMolecule<'c> {
    c: &'c mut Criterion,
}

impl MoleculeVisitor for BenchMolecule<'_> {
    type Output = ();

    fn visit<M, const N: usize, const NA: usize>(self, m: M)
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        let c = self.c;
        let name = m.name();
        let s = bench_state(&m);
        let mut y = vec![0.0; PhaseState::<N>::DIM];
        s.write_to(&mut y).unwrap();

        bench_system(c, &format!("rhs/{name}/seed"), &mut HamiltonianSystem::new(&m), &y);
        bench_system(c, &format!("rhs/{name}/fast"), &mut FastSystem::new(&m), &y);
        bench_system(c, &format!("rhs/{name}/fast_unfused"), &mut FastSystem::new(&Unfused(m)), &y);
        let mut production = ReducedSystem::new(&m, Reduction::none(), &s);
        let mut yp = vec![0.0; production.dim()];
        production.reduce(&s, &mut yp).unwrap();
        bench_system(c, &format!("rhs/{name}/production"), &mut production, &yp);

        let mut s0 = s;
        s0.pe = Vector3::zeros();
        for (id, orientation) in [("zero_j", false), ("zero_j_orientation", true)] {
            let mut system = ReducedSystem::new(&m, Reduction::zero_angular_momentum(orientation), &s0);
            let mut y0 = vec![0.0; system.dim()];
            system.reduce(&s0, &mut y0).unwrap();
            if !y0.is_empty() {
                bench_system(c, &format!("rhs/{name}/{id}"), &mut system, &y0);
            }
        }
        if N >= 2 {
            let mut active = [true; N];
            active[0] = false;
            let mut system = ReducedSystem::new(&m, Reduction::frozen(active), &s);
            let mut y1 = vec![0.0; system.dim()];
            system.reduce(&s, &mut y1).unwrap();
            bench_system(c, &format!("rhs/{name}/frozen1"), &mut system, &y1);
        }
    }
}

fn rhs_per_molecule(c: &mut Criterion) {
    for name in molecules::NAMES {
        molecules::visit(name, BenchMolecule { c }).expect("listed");
    }
}

/// The fast path of water taken apart: what each step costs on its own.
fn water_parts(c: &mut Criterion) {
    let m = molecules::H2o;
    let s = bench_state(&m);
    let mut k = KineticMatrices::<3>::default();
    m.kinetic(&s.q, &mut k);
    let j = rovib::runtime::hamiltonian::w_matrix(&s.euler).unwrap() * s.pe;
    let (omega, qdot) = MetricFactor::new(&k, &s.q).unwrap().solve(&j, &s.p);
    let mut grad = SVector::<f64, 3>::zeros();

    c.bench_function("parts/h2o/fast_rhs_fn", |b| b.iter(|| fast::rhs(&m, black_box(&s)).unwrap()));
    c.bench_function("parts/h2o/kinetic", |b| {
        b.iter(|| {
            m.kinetic(black_box(&s.q), &mut k);
            black_box(&k);
        })
    });
    c.bench_function("parts/h2o/kinetic_energy_gradient", |b| {
        b.iter(|| m.kinetic_energy_gradient(black_box(&s.q), black_box(&omega), black_box(&qdot), &mut grad))
    });
    c.bench_function("parts/h2o/potential_gradient", |b| b.iter(|| m.potential_gradient(black_box(&s.q), &mut grad)));
    c.bench_function("parts/h2o/factor_and_solve", |b| {
        b.iter(|| MetricFactor::new(black_box(&k), &s.q).unwrap().solve(black_box(&j), black_box(&s.p)))
    });
    c.bench_function("parts/h2o/euler_sin_cos", |b| {
        b.iter(|| {
            let e = black_box(&s.euler);
            (e[1].sin_cos(), e[2].sin_cos())
        })
    });
    c.bench_function("parts/h2o/kinetic_jacobian", |b| {
        let mut dk = [KineticMatrices::<3>::default(); 3];
        b.iter(|| {
            m.kinetic_jacobian(black_box(&s.q), &mut dk);
            black_box(&dk);
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(30)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    targets = rhs_per_molecule, water_parts
}

/// Runs the benchmarks, or with `ROVIB_RHS_PROFILE=PART` set, only a plain loop over one part
/// of water's right-hand side (`seed`, `fast`, `fast_fn`, `zero_j`, `production`, `unfused`, `kinetic`, `keg` for
/// `kinetic_energy_gradient`, `potential_gradient`, `factor`, `euler`), `ROVIB_RHS_ITERS` times
/// (default 10⁷), for `perf stat -e cycles:u` or `valgrind --tool=callgrind`: counts that a
/// machine shared with compilers does not blur.
fn main() {
    match std::env::var("ROVIB_RHS_PROFILE") {
        Ok(part) => profile_loop(&part),
        Err(_) => {
            benches();
            Criterion::default().configure_from_args().final_summary();
        }
    }
}

fn profile_loop(part: &str) {
    let iters: u64 = std::env::var("ROVIB_RHS_ITERS").ok().and_then(|v| v.parse().ok()).unwrap_or(10_000_000);
    let m = molecules::H2o;
    let s = bench_state(&m);
    let mut y = vec![0.0; PhaseState::<3>::DIM];
    s.write_to(&mut y).unwrap();
    let mut dy = vec![0.0; y.len()];
    let mut s0 = s;
    s0.pe = Vector3::zeros();
    let mut k = KineticMatrices::<3>::default();
    m.kinetic(&s.q, &mut k);
    let j = rovib::runtime::hamiltonian::w_matrix(&s.euler).unwrap() * s.pe;
    let (omega, qdot) = MetricFactor::new(&k, &s.q).unwrap().solve(&j, &s.p);
    let mut grad = SVector::<f64, 3>::zeros();
    let mut seed_system = HamiltonianSystem::new(&m);
    let mut fast_system = FastSystem::new(&m);
    let mut zero_j = ReducedSystem::new(&m, Reduction::zero_angular_momentum(false), &s0);
    let mut y0 = vec![0.0; zero_j.dim()];
    zero_j.reduce(&s0, &mut y0).unwrap();
    let mut production = ReducedSystem::new(&m, Reduction::none(), &s);
    let mut yp = vec![0.0; production.dim()];
    production.reduce(&s, &mut yp).unwrap();
    let mut dyp = yp.clone();
    // A macro rather than a closure argument, so that each loop body is inlined.
    macro_rules! run {
        ($body:expr) => {
            for _ in 0..iters {
                black_box($body);
            }
        };
    }
    match part {
        "seed" => run!(seed_system.rhs(0.0, black_box(&y), &mut dy).unwrap()),
        "fast" => run!(fast_system.rhs(0.0, black_box(&y), &mut dy).unwrap()),
        "fast_fn" => run!(fast::rhs(&m, black_box(&s)).unwrap()),
        "zero_j" => run!(zero_j.rhs(0.0, black_box(&y0), &mut dy[..6]).unwrap()),
        "production" => run!(production.rhs(0.0, black_box(&yp), &mut dyp).unwrap()),
        "unfused" => run!(FastSystem::new(&Unfused(m)).rhs(0.0, black_box(&y), &mut dy).unwrap()),
        "kinetic" => run!(m.kinetic(black_box(&s.q), &mut k)),
        "keg" => run!(m.kinetic_energy_gradient(black_box(&s.q), black_box(&omega), black_box(&qdot), &mut grad)),
        "potential_gradient" => run!(m.potential_gradient(black_box(&s.q), &mut grad)),
        "factor" => run!(MetricFactor::new(black_box(&k), &s.q).unwrap().solve(black_box(&j), black_box(&s.p))),
        "euler" => run!({
            let e = black_box(&s.euler);
            (e[1].sin_cos(), e[2].sin_cos())
        }),
        other => panic!("unknown ROVIB_RHS_PROFILE part {other:?}"),
    }
    black_box((&dy, &grad, &k));
}
