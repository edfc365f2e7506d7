//! Criterion benchmarks of one right-hand-side evaluation per shipped molecule, through the
//! `OdeSystem` interface the integrators use:
//!
//! * `rhs/NAME/seed`: the seed path (`HamiltonianSystem`, eqs. 9–16 with ∂G);
//! * `rhs/NAME/fast`: the fast path (`FastSystem`, one block Cholesky + ∂T/∂q at fixed v);
//! * `rhs/NAME/zero_j`, `rhs/NAME/zero_j_orientation`: J = 0 (`ReducedSystem`), without and
//!   with the Euler angles;
//! * `rhs/NAME/frozen1`: the first internal coordinate frozen (molecules with N ≥ 2).
//!
//! For water only, the parts of the fast path one by one (`parts/h2o/...`) and a hand-fused
//! prototype of the generated code (`rhs/h2o/fast_fused_prototype`, see [`fused`]) that measures
//! what a generator change would save.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group};
use rovib::molecules;
use rovib::runtime::hamiltonian::fast::{self, FastSystem, MetricFactor, ReducedSystem, Reduction};
use rovib::runtime::hamiltonian::{HamiltonianSystem, PhaseState};
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::nalgebra::{SVector, Vector3};
use rovib::runtime::units::CoordinateUnit;
use rovib::runtime::{KineticMatrices, Molecule, MoleculeVisitor};

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

    // The fused prototype must give the fast path's numbers before its time means anything.
    let reference = fast::rhs(&m, &s).unwrap();
    let fused = fused::rhs(&s).unwrap();
    let scale = |v: &[f64]| v.iter().fold(1e-300_f64, |a, x| a.max(x.abs()));
    for (a, b) in [
        (fused.q.as_slice(), reference.q.as_slice()),
        (fused.p.as_slice(), reference.p.as_slice()),
        (fused.euler.as_slice(), reference.euler.as_slice()),
        (fused.pe.as_slice(), reference.pe.as_slice()),
    ] {
        let d = a.iter().zip(b).fold(0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(d <= 1e-13 * scale(b), "fused prototype differs from the fast path: {d:e}");
    }
    c.bench_function("rhs/h2o/fast_fused_prototype", |b| b.iter(|| fused::rhs(black_box(&s)).unwrap()));
    c.bench_function("rhs/h2o/fast_unfused_prototype", |b| b.iter(|| fused::rhs_unfused(black_box(&s)).unwrap()));
    c.bench_function("parts/h2o/kinetic_fused_prototype", |b| {
        b.iter(|| {
            let cache = fused::kinetic(black_box(&s.q), &mut k);
            black_box((&k, &cache));
        })
    });
}

/// A hand-written prototype for water of the generated code the fast path would like: `a`, `A`,
/// `I` and a cache of the position terms (the shared common subexpressions of `R_i` and
/// `∂R_i/∂q`, including the one `sin_cos`) in one call, then `∂T/∂q` at fixed `(ω, q̇)` from
/// the cache. The bodies are the generated `H2o::kinetic` and `H2o::kinetic_energy_gradient`
/// (rovib-codegen's output for `molecules/h2o.toml`) with the common prefix computed once.
///
/// The signature to generate (one more pair of methods on `Molecule`, or an associated type):
///
/// ```text
/// type KineticCache: Copy;
/// fn kinetic_cached(&self, q: &SVector<f64, N>, k: &mut KineticMatrices<N>) -> Self::KineticCache;
/// fn kinetic_energy_gradient_cached(&self, cache: &Self::KineticCache, omega: &Vector3<f64>,
///     qdot: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64;
/// ```
#[allow(clippy::excessive_precision, clippy::neg_multiply, clippy::approx_constant, clippy::unreadable_literal)]
mod fused {
    use rovib::runtime::hamiltonian::fast::MetricFactor;
    use rovib::runtime::hamiltonian::{HamiltonianError, MIN_SIN_THETA, PhaseState};
    use rovib::runtime::nalgebra::{SVector, Vector3};
    use rovib::runtime::{KineticMatrices, Molecule};

    /// The position terms `kinetic` and `kinetic_energy_gradient` share (named as in the
    /// generated gradient: `t[i]` is its `t_i`).
    #[derive(Copy, Clone, Debug)]
    pub struct Cache {
        t: [f64; 26],
    }

    /// `a`, `A`, `I` at q, and the cache.
    pub fn kinetic(q: &SVector<f64, 3>, k: &mut KineticMatrices<3>) -> Cache {
        let r1 = q[0];
        let r2 = q[1];
        let alpha = q[2];
        let t0 = 0.5 * alpha;
        let (t1, t2) = t0.sin_cos();
        let t3 = r1 * t1;
        let t4 = r1 * t2;
        let t5 = r2 * t1;
        let t6 = r2 * t2;
        let t7 = 0.05595743664404038 * t3;
        let t8 = 0.05595743664404038 * t5;
        let t9 = t7 - t8;
        let t10 = 0.05595743664404038 * t4 + 0.05595743664404038 * t6;
        let t11 = t8 - t7;
        let t12 = t3 - t9;
        let t13 = t4 - t10;
        let t14 = -t5 - t9;
        let t15 = t6 - t10;
        let t16 = 0.02797871832202019 * t4;
        let t17 = 0.02797871832202019 * t6;
        let t18 = t17 - t16;
        let t19 = 0.02797871832202019 * t5;
        let t20 = -0.02797871832202019 * t3 - t19;
        let t21 = t19 + 0.02797871832202019 * t3;
        let t22 = t16 - t17;
        let t23 = 0.5 * t4 - t22;
        let t24 = -0.5 * t3 - t20;
        let t25 = -0.5 * t6 - t22;
        let t26 = -0.5 * t5 - t20;
        let t27 = t1 * t1;
        let t28 = 0.0031312347157717935 * t27;
        let t29 = t2 * t2;
        let t30 = 0.0031312347157717935 * t29;
        let t31 = t28 + t30;
        let t32 = 1837.1526473652812 * (0.891216361427691 * t27 + 0.891216361427691 * t29);
        let t33 = 1837.1526473652812 * (0.05282620192826859 * t27 - 0.05282620192826859 * t29);
        let t34 = t33 + (29156.94569791016 * (t30 - t28) + t33);
        let t35 = t1 * t18;
        let t36 = 0.05595743664404038 * (t2 * t21);
        let t37 = t1 * t23;
        let t38 = t2 * t24;
        let t39 = 29156.94569791016 * (-0.05595743664404038 * t35 - t36)
            + 1837.1526473652812 * (0.9440425633559596 * t37 + 0.9440425633559596 * t38);
        let t40 = t1 * t25;
        let t41 = t2 * t26;
        let t42 = t39 + 1837.1526473652812 * (-0.05595743664404038 * t40 - 0.05595743664404038 * t41);
        let t43 = 29156.94569791016 * (0.05595743664404038 * t35 - t36)
            + 1837.1526473652812 * (0.05595743664404038 * t37 - 0.05595743664404038 * t38);
        let t44 = t43 + 1837.1526473652812 * (0.9440425633559596 * t41 - 0.9440425633559596 * t40);
        let t45 = 29156.94569791016 * (t18 * t18 + t21 * t21) + 1837.1526473652812 * (t23 * t23 + t24 * t24);
        let t46 = 0.05595743664404038 * (t1 * t10);
        let t47 = 0.05595743664404038 * (t2 * t11);
        let t48 = t1 * t13;
        let t49 = t2 * t12;
        let t50 = 29156.94569791016 * (t46 + t47)
            + 1837.1526473652812 * (0.9440425633559596 * t48 - 0.9440425633559596 * t49);
        let t51 = t1 * t15;
        let t52 = t2 * t14;
        let t53 = 29156.94569791016 * (t47 - t46)
            + 1837.1526473652812 * (0.05595743664404038 * t48 + 0.05595743664404038 * t49);
        let t54 = 29156.94569791016 * (-(t10 * t18) - t11 * t21) + 1837.1526473652812 * (t13 * t23 - t12 * t24);
        let t55 = t10 * t10;
        let t56 = t13 * t13;
        let t57 = t15 * t15;
        let t58 = 29156.94569791016 * (t10 * t11) - 1837.1526473652812 * (t12 * t13) - 1837.1526473652812 * (t14 * t15);
        let t59 = t11 * t11;
        let t60 = t12 * t12;
        let t61 = t14 * t14;
        let t62 = 29156.94569791016 * (t55 + t59) + 1837.1526473652812 * (t56 + t60) + 1837.1526473652812 * (t57 + t61);
        k.a[(0, 0)] = 29156.94569791016 * t31 + t32 + 1837.1526473652812 * t31;
        k.a[(0, 1)] = t34;
        k.a[(0, 2)] = t42;
        k.a[(1, 0)] = t34;
        k.a[(1, 1)] = t32 + 30994.09834527544 * t31;
        k.a[(1, 2)] = t44;
        k.a[(2, 0)] = t42;
        k.a[(2, 1)] = t44;
        k.a[(2, 2)] = t45 + 1837.1526473652812 * (t25 * t25 + t26 * t26);
        k.coriolis.fill(0.0);
        k.coriolis[(1, 0)] = t50 + 1837.1526473652812 * (0.05595743664404038 * t52 - 0.05595743664404038 * t51);
        k.coriolis[(1, 1)] = t53 + 1837.1526473652812 * (-0.9440425633559596 * t51 - 0.9440425633559596 * t52);
        k.coriolis[(1, 2)] = t54 + 1837.1526473652812 * (t15 * t25 - t14 * t26);
        k.inertia.fill(0.0);
        k.inertia[(0, 0)] = 29156.94569791016 * t55 + 1837.1526473652812 * t56 + 1837.1526473652812 * t57;
        k.inertia[(0, 2)] = t58;
        k.inertia[(1, 1)] = t62;
        k.inertia[(2, 0)] = t58;
        k.inertia[(2, 2)] = 29156.94569791016 * t59 + 1837.1526473652812 * t60 + 1837.1526473652812 * t61;
        // The gradient's t16..t25 are this function's t16..t20, t22..t26.
        Cache {
            t: [
                t0, t1, t2, t3, t4, t5, t6, t7, t8, t9, t10, t11, t12, t13, t14, t15, t16, t17, t18, t19, t20, t22,
                t23, t24, t25, t26,
            ],
        }
    }

    /// `∂T/∂q` at fixed `(ω, q̇)` from the cache; returns `T`.
    pub fn kinetic_energy_gradient(
        c: &Cache,
        omega: &Vector3<f64>,
        qdot: &SVector<f64, 3>,
        grad: &mut SVector<f64, 3>,
    ) -> f64 {
        let [
            _,
            t1,
            t2,
            t3,
            t4,
            t5,
            t6,
            _,
            _,
            _,
            t10,
            t11,
            t12,
            t13,
            t14,
            t15,
            _,
            _,
            t18,
            t19,
            t20,
            _,
            t22,
            t23,
            t24,
            t25,
        ] = c.t;
        let omega_x = omega[0];
        let omega_y = omega[1];
        let omega_z = omega[2];
        let qdot_r1 = qdot[0];
        let qdot_r2 = qdot[1];
        let qdot_alpha = qdot[2];
        let t26 = 0.013989359161010096 * t6;
        let t27 = -0.013989359161010096 * t4 - t26;
        let t28 = 0.013989359161010096 * t5;
        let t29 = 0.013989359161010096 * t3;
        let t30 = t28 - t29;
        let t31 = t11 * omega_z + t10 * omega_x;
        let t32 = t1 * qdot_r1;
        let t33 = 0.05595743664404038 * t32;
        let t34 = t2 * qdot_r1;
        let t35 = 0.05595743664404038 * t34;
        let t36 = t1 * qdot_r2;
        let t37 = 0.05595743664404038 * t36;
        let t38 = t2 * qdot_r2;
        let t39 = 0.05595743664404038 * t38;
        let t40 = -(t10 * omega_y) - t33 + t37 + t18 * qdot_alpha;
        let t41 = -(t11 * omega_y) - t35 - t39 + (t19 + 0.02797871832202019 * t3) * qdot_alpha;
        let t42 = t12 * omega_z - t13 * omega_x;
        let t43 = t37 + (t13 * omega_y + 0.9440425633559596 * t32) + t22 * qdot_alpha;
        let t44 = 0.9440425633559596 * t34 - t12 * omega_y - t39 + t23 * qdot_alpha;
        let t45 = 14578.47284895508 * (t40 * t40 + t31 * t31 + t41 * t41)
            + 918.5763236826406 * (t43 * t43 + t42 * t42 + t44 * t44);
        let t46 = t14 * omega_z - t15 * omega_x;
        let t47 = t15 * omega_y - t33 - 0.9440425633559596 * t36 + t24 * qdot_alpha;
        let t48 = -(t14 * omega_y) - t35 + 0.9440425633559596 * t38 + t25 * qdot_alpha;
        let t49 = t45 + 918.5763236826406 * (t47 * t47 + t46 * t46 + t48 * t48);
        let t50 = t1 * qdot_alpha;
        let t51 = 0.02797871832202019 * t50;
        let t52 = t1 * omega_y;
        let t53 = 0.05595743664404038 * t52;
        let t54 = t51 + t53;
        let t55 = t2 * omega_x;
        let t56 = t1 * omega_z;
        let t57 = 0.05595743664404038 * t55;
        let t58 = 0.05595743664404038 * t56;
        let t59 = t57 - t58;
        let t60 = t2 * qdot_alpha;
        let t61 = t2 * omega_y;
        let t62 = 0.02797871832202019 * t60;
        let t63 = -0.05595743664404038 * t61 - t62;
        let t64 = 2.0 * (t48 * t54) + (2.0 * (t46 * t59) + 2.0 * (t47 * t63));
        let t65 = 0.4720212816779798 * t50;
        let t66 = 0.9440425633559596 * t55;
        let t67 = 0.4720212816779798 * t60;
        let t68 = 0.9440425633559596 * t61;
        let t69 = 2.0 * (t42 * (0.9440425633559596 * t56 - t66)) + 2.0 * (t43 * (t67 + t68));
        let t70 = 2.0 * (t41 * t54) + (2.0 * (t31 * t59) + 2.0 * (t40 * t63));
        let t71 = 918.5763236826406 * (2.0 * (t44 * (-0.9440425633559596 * t52 - t65)) + t69) + 14578.47284895508 * t70;
        let t72 = 2.0 * (t46 * (-0.9440425633559596 * t56 - t66)) + 2.0 * (t47 * (t68 - t67));
        let t73 = t51 - t53;
        let t74 = t57 + t58;
        let t75 = t62 - 0.05595743664404038 * t61;
        let t76 = 2.0 * (t44 * t73) + (2.0 * (t42 * t74) + 2.0 * (t43 * t75));
        let t77 = 2.0 * (t41 * t73) + (2.0 * (t31 * t74) + 2.0 * (t40 * t75));
        let t78 = 918.5763236826406 * (2.0 * (t48 * (0.9440425633559596 * t52 - t65)) + t72)
            + (918.5763236826406 * t76 + 14578.47284895508 * t77);
        let t79 = 0.02797871832202019 * t32;
        let t80 = (-0.25 * t6 - t27) * qdot_alpha + (t79 - t24 * omega_y - 0.4720212816779798 * t36);
        let t81 = 0.02797871832202019 * t34;
        let t82 = (0.25 * t5 - t30) * qdot_alpha + (t25 * omega_y - t81 - 0.4720212816779798 * t38);
        let t83 = 2.0 * (t46 * (t24 * omega_z - t25 * omega_x)) + 2.0 * (t47 * t82);
        let t84 = 0.02797871832202019 * t36;
        let t85 = (-0.25 * t4 - t27) * qdot_alpha + (-0.4720212816779798 * t32 - t22 * omega_y + t84);
        let t86 = 0.02797871832202019 * t38;
        let t87 = (-0.25 * t3 - t30) * qdot_alpha + (0.4720212816779798 * t34 + t23 * omega_y + t86);
        let t88 = 2.0 * (t42 * (t22 * omega_z - t23 * omega_x)) + 2.0 * (t43 * t87);
        let t89 = (t26 + 0.013989359161010096 * t4) * qdot_alpha + (t84 + (t79 - t18 * omega_y));
        let t90 = (t29 - t28) * qdot_alpha + (t86 + (-(t20 * omega_y) - t81));
        let t91 = 2.0 * (t31 * (t20 * omega_x + t18 * omega_z)) + 2.0 * (t40 * t90);
        let t92 = 918.5763236826406 * (2.0 * (t44 * t85) + t88) + 14578.47284895508 * (2.0 * (t41 * t89) + t91);
        grad[0] = 918.5763236826406 * t64 + t71;
        grad[1] = t78;
        grad[2] = 918.5763236826406 * (2.0 * (t48 * t80) + t83) + t92;
        t49
    }

    /// The fast path's rhs for water with the fused kinetic functions (errors as the fast
    /// path; the Euler-angle formulas are those of `fast.rs`).
    pub fn rhs(s: &PhaseState<3>) -> Result<PhaseState<3>, HamiltonianError> {
        rhs_with::<true>(s)
    }

    /// [`rhs`] with the generated, unfused `kinetic` and `kinetic_energy_gradient`: the same
    /// code otherwise, to tell the gain of the fusion from that of the inlining.
    pub fn rhs_unfused(s: &PhaseState<3>) -> Result<PhaseState<3>, HamiltonianError> {
        rhs_with::<false>(s)
    }

    #[inline(always)]
    fn rhs_with<const FUSED: bool>(s: &PhaseState<3>) -> Result<PhaseState<3>, HamiltonianError> {
        let m = rovib::molecules::H2o;
        s.check_finite()?;
        let (st, ct) = s.euler[1].sin_cos();
        if st.abs() < MIN_SIN_THETA {
            return Err(HamiltonianError::EulerSingular { theta: s.euler[1] });
        }
        let (sp, cp) = s.euler[2].sin_cos();
        let pe = &s.pe;
        let g = (pe[0] - ct * pe[2]) / st;
        let j = Vector3::new(sp * g + cp * pe[1], cp * g - sp * pe[1], pe[2]);
        let mut k = KineticMatrices::default();
        let cache = if FUSED {
            kinetic(&s.q, &mut k)
        } else {
            m.kinetic(&s.q, &mut k);
            Cache { t: [0.0; 26] }
        };
        let (omega, qdot) = MetricFactor::new(&k, &s.q)?.solve(&j, &s.p);
        let mut du = SVector::zeros();
        m.potential_gradient(&s.q, &mut du);
        if !du.iter().all(|x| x.is_finite()) {
            return Err(HamiltonianError::NonFinite { quantity: "potential gradient ∂U/∂q" });
        }
        let mut dt = SVector::zeros();
        if FUSED {
            kinetic_energy_gradient(&cache, &omega, &qdot, &mut dt);
        } else {
            m.kinetic_energy_gradient(&s.q, &omega, &qdot, &mut dt);
        }
        if !dt.iter().all(|x| x.is_finite()) {
            return Err(HamiltonianError::NonFinite { quantity: "kinetic energy gradient ∂T/∂q" });
        }
        let phi_dot = (sp * omega[0] + cp * omega[1]) / st;
        let euler = Vector3::new(phi_dot, cp * omega[0] - sp * omega[1], omega[2] - ct * phi_dot);
        let dh_dtheta = (pe[2] - ct * pe[0]) / (st * st) * (sp * omega[0] + cp * omega[1]);
        let dh_dpsi = j[1] * omega[0] - j[0] * omega[1];
        let out = PhaseState { q: qdot, p: dt - du, euler, pe: Vector3::new(0.0, -dh_dtheta, -dh_dpsi) };
        if out.check_finite().is_err() {
            return Err(HamiltonianError::NonFinite { quantity: "right-hand side of Hamilton's equations" });
        }
        Ok(out)
    }
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
/// of water's right-hand side (`seed`, `fast`, `fast_fn`, `zero_j`, `fused`, `unfused`, `kinetic`, `keg` for
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
        "fused" => run!(fused::rhs(black_box(&s)).unwrap()),
        "unfused" => run!(fused::rhs_unfused(black_box(&s)).unwrap()),
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
