//! SIMD lanes (`runtime::lanes`, `hamiltonian::lanes`, `integrate::Dop853Lanes`) against the
//! one-trajectory code:
//!
//! * the generated lane-generic functions at 2, 4 and 8 lanes equal one another bit for bit, and
//!   the generated `f64` functions called lane by lane (the trait's default) to round-off, on
//!   varied states of every shipped molecule (the lanes' `sin_cos` and `exp` are vector
//!   polynomials within 2 ulp of libm's, `runtime/src/transcendental.rs`);
//! * the production right-hand side likewise, and against the general (reduction-aware) path of
//!   `ReducedSystem` to round-off;
//! * the batched DOP853 against the scalar DOP853, trajectory by trajectory, bit for bit (every
//!   output, the step counts, failures at the same time) when both integrate the same numbers
//!   (the scalar solver on the lane right-hand side, one trajectory in every lane), and against
//!   the scalar production system (`ReducedSystem`, libm) to round-off.

use crate::common;

use std::ops::ControlFlow;

use common::{Rng, for_each_molecule, random_q};
use rovib::molecules::H2o;
use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::hamiltonian::fast::{self, BodyState, ReducedSystem, Reduction};
use rovib::runtime::hamiltonian::lanes::{self, ProductionLanes, production_rhs};
use rovib::runtime::integrate::{
    Dop853, Dop853Lanes, Dop853Options, LaneFailure, LaneFeeder, OdeSystem, SolveError, Stats,
};
use rovib::runtime::lanes::{F64x2, F64x4, F64x8, KineticLanes, Real};
use rovib::runtime::nalgebra::{Quaternion, SMatrix, SVector, UnitQuaternion, Vector3};
use rovib::runtime::{Atom, Coordinate, Kinematics, KineticMatrices, Molecule, MoleculeVisitor};

/// A molecule that forwards only the `f64` methods, so that its lane methods are the trait's
/// defaults (the `f64` functions lane by lane).
struct ScalarOnly<'a, M>(&'a M);

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Kinematics<N, NA> for ScalarOnly<'_, M> {
    fn name(&self) -> &'static str {
        self.0.name()
    }
    fn source(&self) -> &'static str {
        self.0.source()
    }
    fn atoms(&self) -> [Atom; NA] {
        self.0.atoms()
    }
    fn coordinates(&self) -> [Coordinate; N] {
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

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Molecule<N, NA> for ScalarOnly<'_, M> {
    fn potential(&self, q: &SVector<f64, N>) -> f64 {
        self.0.potential(q)
    }
    fn potential_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        self.0.potential_gradient(q, grad)
    }
}

fn same_bits(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits()
}

/// A random body state near the reference geometry: momenta of a few ħ/bohr, a random unit
/// quaternion, |J| up to ~17 ħ.
fn random_body<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, rng: &mut Rng) -> BodyState<N> {
    let axis = Vector3::from_fn(|_, _| rng.uniform(-1.0, 1.0));
    BodyState {
        q: random_q(m, rng),
        p: SVector::from_fn(|_, _| rng.uniform(-5.0, 5.0)),
        orientation: UnitQuaternion::from_scaled_axis(axis * 3.0),
        j: Vector3::from_fn(|_, _| rng.uniform(-10.0, 10.0)),
    }
}

fn flat_body<const N: usize>(b: &BodyState<N>) -> Vec<f64> {
    let q = b.orientation.quaternion();
    b.q.iter().chain(b.p.iter()).copied().chain([q.w, q.i, q.j, q.k]).chain(b.j.iter().copied()).collect()
}

/// Lane vectors of four flat states.
fn pack4(states: &[Vec<f64>]) -> Vec<F64x4> {
    (0..states[0].len()).map(|i| F64x4::from_array([0, 1, 2, 3].map(|l| states[l][i]))).collect()
}

/// The outputs of the generated lane functions for the geometries `qs` (one per lane of `T`) and
/// random velocities: per lane, the families (kinetic matrices, ∂T/∂q, ∂U/∂q, T and U) as flat
/// lists. `scalar` evaluates the `f64` functions lane by lane (the trait's defaults) instead.
fn generated_outputs<M, T, const N: usize, const NA: usize>(
    m: &M,
    qs: &[SVector<f64, N>],
    velocities: &[([f64; 3], [f64; N])],
    scalar: bool,
) -> Vec<[Vec<f64>; 4]>
where
    M: Molecule<N, NA>,
    T: Real,
{
    let lanes = |f: &dyn Fn(usize) -> f64| {
        let mut v = T::splat(0.0);
        for l in 0..T::LANES {
            v.set_lane(l, f(l));
        }
        v
    };
    let q: [T; N] = std::array::from_fn(|i| lanes(&|l| qs[l][i]));
    let omega: [T; 3] = std::array::from_fn(|i| lanes(&|l| velocities[l].0[i]));
    let qdot: [T; N] = std::array::from_fn(|i| lanes(&|l| velocities[l].1[i]));
    let (mut k, mut g, mut du) = (KineticLanes::<T, N>::zeros(), [T::splat(0.0); N], [T::splat(0.0); N]);
    let (t, u) = if scalar {
        let reference = ScalarOnly(m);
        let (_, _, t) = reference.kinetic_and_gradient_lanes(&q, &mut k, |_| (omega, qdot), &mut g);
        (t, reference.potential_gradient_lanes(&q, &mut du))
    } else {
        let (_, _, t) = m.kinetic_and_gradient_lanes(&q, &mut k, |_| (omega, qdot), &mut g);
        (t, m.potential_gradient_lanes(&q, &mut du))
    };
    (0..T::LANES)
        .map(|l| {
            let kl = k.lane(l);
            let matrices = kl.a.iter().chain(kl.coriolis.iter()).chain(kl.inertia.iter()).copied().collect();
            [
                matrices,
                g.iter().map(|x| x.lane(l)).collect(),
                du.iter().map(|x| x.lane(l)).collect(),
                vec![t.lane(l), u.lane(l)],
            ]
        })
        .collect()
}

#[derive(Copy, Clone)]
struct GeneratedLanesMatchF64;

impl MoleculeVisitor for GeneratedLanesMatchF64 {
    type Output = ();

    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        let mut rng = Rng::new(17);
        let mut worst: f64 = 0.0;
        for _ in 0..20 {
            let qs: Vec<SVector<f64, N>> = (0..8).map(|_| random_q(&m, &mut rng)).collect();
            let velocities: Vec<([f64; 3], [f64; N])> = (0..8)
                .map(|_| {
                    (
                        std::array::from_fn(|_| rng.uniform(-0.01, 0.01)),
                        std::array::from_fn(|_| rng.uniform(-0.01, 0.01)),
                    )
                })
                .collect();
            let x8 = generated_outputs::<M, F64x8, N, NA>(&m, &qs, &velocities, false);
            let x4: Vec<_> = [0, 4]
                .iter()
                .flat_map(|&o| generated_outputs::<M, F64x4, N, NA>(&m, &qs[o..], &velocities[o..], false))
                .collect();
            let x2: Vec<_> = [0, 2, 4, 6]
                .iter()
                .flat_map(|&o| generated_outputs::<M, F64x2, N, NA>(&m, &qs[o..], &velocities[o..], false))
                .collect();
            let libm: Vec<_> = [0, 4]
                .iter()
                .flat_map(|&o| generated_outputs::<M, F64x4, N, NA>(&m, &qs[o..], &velocities[o..], true))
                .collect();
            for lane in 0..8 {
                for family in 0..4 {
                    let (a, b, c, r) = (&x8[lane][family], &x4[lane][family], &x2[lane][family], &libm[lane][family]);
                    for i in 0..a.len() {
                        assert!(
                            same_bits(a[i], b[i]) && same_bits(a[i], c[i]),
                            "{}: lanes of different widths differ: {} / {} / {}",
                            m.name(),
                            a[i],
                            b[i],
                            c[i]
                        );
                    }
                    // To round-off against libm, relative to the family's largest entry.
                    let scale = r.iter().fold(1e-300_f64, |s, x| s.max(x.abs()));
                    for i in 0..a.len() {
                        let d = (a[i] - r[i]).abs() / scale;
                        assert!(d <= 1e-13, "{}: family {family} entry {i}: {} vs {} (libm)", m.name(), a[i], r[i]);
                        worst = worst.max(d);
                    }
                }
            }
        }
        eprintln!("{}: generated lanes against libm lane by lane, largest relative difference {worst:.1e}", m.name());
    }
}

/// The generated lane functions at 2, 4 and 8 lanes compute the same numbers bit for bit, and
/// the generated `f64` functions' numbers (called lane by lane, libm's `sin_cos` and `exp`) to
/// round-off (10⁻¹³ of each family's largest entry), for every shipped molecule on varied
/// geometries and velocities.
#[test]
fn generated_lane_functions_equal_the_f64_functions_to_round_off() {
    for_each_molecule(GeneratedLanesMatchF64);
}

#[derive(Copy, Clone)]
struct ProductionLanesMatch;

impl MoleculeVisitor for ProductionLanesMatch {
    type Output = ();

    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        let mut rng = Rng::new(29);
        let dim = 2 * N + 7;
        for _ in 0..20 {
            let states: Vec<Vec<f64>> = (0..4).map(|_| flat_body(&random_body(&m, &mut rng))).collect();
            let y4 = pack4(&states);
            let mut d4 = vec![F64x4::splat(0.0); dim];
            assert_eq!(production_rhs::<M, F64x4, N, NA>(&m, &y4, &mut d4, 1e-12), 0b1111, "{}", m.name());
            let y2: Vec<F64x2> = (0..dim).map(|i| F64x2::from_array([states[2][i], states[3][i]])).collect();
            let mut d2 = vec![F64x2::splat(0.0); dim];
            assert_eq!(production_rhs::<M, F64x2, N, NA>(&m, &y2, &mut d2, 1e-12), 0b11);
            let y8: Vec<F64x8> =
                (0..dim).map(|i| F64x8::from_array(std::array::from_fn(|l| states[l % 4][i]))).collect();
            let mut d8 = vec![F64x8::splat(0.0); dim];
            assert_eq!(production_rhs::<M, F64x8, N, NA>(&m, &y8, &mut d8, 1e-12), 0xff);
            for (lane, y) in states.iter().enumerate() {
                let mut d = vec![0.0; dim];
                assert_eq!(production_rhs::<M, f64, N, NA>(&m, y, &mut d, 1e-12), 1);
                let scale = d.iter().fold(0f64, |a, v| a.max(v.abs()));
                for i in 0..dim {
                    let x = d4[i].lane(lane);
                    assert!(same_bits(d8[i].lane(lane), x) && same_bits(d8[i].lane(lane + 4), x), "{}", m.name());
                    if lane >= 2 {
                        assert!(same_bits(d2[i].lane(lane - 2), x), "{} lane {lane} component {i}", m.name());
                    }
                    assert!(
                        (x - d[i]).abs() <= 1e-12 * scale,
                        "{} lane {lane} component {i}: {x} vs {} (f64)",
                        m.name(),
                        d[i]
                    );
                }
                // Against the general path (a reduction that keeps everything but is not
                // recognised as "nothing reduced": the same system through the index maps).
                let template = PhaseState::<N> {
                    q: SVector::from_fn(|i, _| y[i]),
                    p: SVector::zeros(),
                    euler: Vector3::new(0.1, 1.0, 0.2),
                    pe: Vector3::zeros(),
                };
                let mut general = GeneralOnly(ReducedSystem::new(&m, Reduction::none(), &template));
                let mut dg = vec![0.0; dim];
                general.rhs(0.0, y, &mut dg).unwrap();
                let scale = dg.iter().fold(0f64, |a, v| a.max(v.abs()));
                for i in 0..dim {
                    assert!((d[i] - dg[i]).abs() <= 1e-12 * scale, "{} component {i}: {} vs {}", m.name(), d[i], dg[i]);
                }
            }
            // A lane with a non-finite state, or a singular metric, fails alone.
            let mut bad = states.clone();
            bad[1][0] = f64::NAN;
            let y4 = pack4(&bad);
            assert_eq!(production_rhs::<M, F64x4, N, NA>(&m, &y4, &mut d4, 1e-12), 0b1101, "{}", m.name());
            assert_eq!(production_rhs::<M, F64x4, N, NA>(&m, &pack4(&states), &mut d4, 2.0), 0, "{}", m.name());
        }
    }
}

/// `ReducedSystem` through its general (reduction-aware) path: the quaternion block is
/// recomputed with nalgebra's quaternion product, so this is an independent evaluation of the
/// same equations.
struct GeneralOnly<'a, M, const N: usize, const NA: usize>(ReducedSystem<'a, M, N, NA>);

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> OdeSystem for GeneralOnly<'_, M, N, NA> {
    type Error = rovib::runtime::HamiltonianError;
    fn dim(&self) -> usize {
        self.0.dim()
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Self::Error> {
        // The general path: expand the flat state to a body state and evaluate by the fast
        // Euler-free formulas of ReducedSystem::energy's neighbours (velocities by the solve,
        // then the rates), here through `expand_body_and_energy` for ω and the molecule's
        // gradient functions.
        let n = N;
        let body = self.0.expand_body(y)?;
        let mut k = KineticMatrices::default();
        let m = self.0.molecule();
        m.kinetic(&body.q, &mut k);
        let factor = fast::MetricFactor::new(&k, &body.q)?;
        let (omega, qdot) = factor.solve(&body.j, &body.p);
        let mut dt = SVector::zeros();
        m.kinetic_energy_gradient(&body.q, &omega, &qdot, &mut dt);
        let mut du = SVector::zeros();
        m.potential_gradient(&body.q, &mut du);
        let quat = Quaternion::new(y[2 * n], y[2 * n + 1], y[2 * n + 2], y[2 * n + 3]);
        let dq = quat * Quaternion::from_imag(omega) * 0.5;
        let dj = body.j.cross(&omega);
        for i in 0..n {
            dydt[i] = qdot[i];
            dydt[n + i] = dt[i] - du[i];
        }
        dydt[2 * n..2 * n + 4].copy_from_slice(&[dq.w, dq.i, dq.j, dq.k]);
        dydt[2 * n + 4..].copy_from_slice(dj.as_slice());
        Ok(())
    }
}

/// The lane-generic production right-hand side at 2, 4 and 8 lanes gives the same numbers bit for
/// bit, and its `f64` instance's (libm's `sin_cos` and `exp`) to 10⁻¹² of the largest component;
/// the `f64` instance equals an evaluation through nalgebra's metric
/// factorization and quaternion product to round-off; a non-finite lane or a failed pivot test
/// clears only its own bit.
#[test]
fn production_rhs_lanes_equal_f64_and_the_general_path() {
    common::for_each_well_conditioned_molecule(ProductionLanesMatch);
}

/// Which molecules take the lane code: every shipped molecule has exact lane forms (so the
/// tests above run the generated lane code, not the lane-by-lane defaults), a molecule without
/// them does not; its nothing-reduced `ReducedSystem` then takes the general path, which gives
/// the fast path's q̇ and ṗ bit for bit (as the lane path does for molecules with lane forms,
/// `tests/fast_path.rs`).
#[derive(Copy, Clone)]
struct LaneAvailability;

impl MoleculeVisitor for LaneAvailability {
    type Output = ();

    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        // Every molecule below 24 coordinates has exact lane forms; larger ones (hexane, added
        // through ROVIB_MOLECULES_DIR) run one trajectory at a time on the general path.
        assert_eq!(lanes::available(&m), N < 24, "{}: lane forms exactly below 24 coordinates", m.name());
        let scalar = ScalarOnly(&m);
        assert!(!lanes::available(&scalar), "{}: the trait's defaults are not lane forms", m.name());
        let mut rng = Rng::new(31);
        for _ in 0..10 {
            let s = common::random_state(&m, &mut rng);
            let mut system = ReducedSystem::new(&scalar, Reduction::none(), &s);
            let mut y = vec![0.0; system.dim()];
            system.reduce(&s, &mut y).unwrap();
            let mut dy = vec![0.0; y.len()];
            system.rhs(0.0, &y, &mut dy).unwrap();
            let reference = fast::rhs(&scalar, &s).unwrap();
            assert_eq!(&dy[..N], reference.q.as_slice(), "{}", m.name());
            assert_eq!(&dy[N..2 * N], reference.p.as_slice(), "{}", m.name());
        }
    }
}

#[test]
fn lane_code_only_for_molecules_with_lane_forms() {
    for_each_molecule(LaneAvailability);
}

/// What one trajectory produced: every output, then the end.
#[derive(Clone, Debug, PartialEq)]
struct Record {
    outputs: Vec<(f64, Vec<f64>)>,
    end: Option<Result<Stats, LaneFailure>>,
}

/// Feeds trajectories `0..states.len()` to the lanes and records them; trajectory `stop_at`
/// (if any) breaks at its third output.
struct Feeder {
    states: Vec<Vec<f64>>,
    next: usize,
    lane_job: Vec<usize>,
    records: Vec<Record>,
    stop_at: Option<usize>,
}

impl LaneFeeder for Feeder {
    fn next(&mut self, lane: usize, y0: &mut [f64]) -> bool {
        if self.next == self.states.len() {
            return false;
        }
        y0.copy_from_slice(&self.states[self.next]);
        self.lane_job[lane] = self.next;
        self.next += 1;
        true
    }
    fn observe(&mut self, lane: usize, t: f64, y: &[f64]) -> ControlFlow<()> {
        let job = self.lane_job[lane];
        let r = &mut self.records[job];
        r.outputs.push((t, y.to_vec()));
        if Some(job) == self.stop_at && r.outputs.len() == 3 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }
    fn finish(&mut self, lane: usize, result: Result<Stats, LaneFailure>) {
        let job = self.lane_job[lane];
        assert!(self.records[job].end.is_none(), "trajectory {job} finished twice");
        self.records[job].end = Some(result);
    }
}

/// The lane right-hand side as a one-trajectory system: the state in every lane of `T`, lane 0
/// read back, so that the scalar DOP853 integrates exactly the numbers a lane integrates.
struct OneLane<'a, M, T> {
    molecule: &'a M,
    min_pivot: f64,
    y: Vec<T>,
    d: Vec<T>,
}

impl<M: Molecule<3, 3>, T: Real> OdeSystem for OneLane<'_, M, T> {
    type Error = Failed;
    fn dim(&self) -> usize {
        13
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Self::Error> {
        for (v, &x) in self.y.iter_mut().zip(y) {
            *v = T::splat(x);
        }
        if production_rhs::<M, T, 3, 3>(self.molecule, &self.y, &mut self.d, self.min_pivot) & 1 == 0 {
            return Err(Failed("the lane failed".into()));
        }
        for (o, v) in dydt.iter_mut().zip(&self.d) {
            *o = v.lane(0);
        }
        Ok(())
    }
}

/// The batched DOP853 runs eleven water trajectories on four lanes (so lanes take new
/// trajectories as others finish, at different times) and each one equals the scalar DOP853's
/// run of the same trajectory on the same numbers (the lane right-hand side, [`OneLane`]) bit
/// for bit: every output time and state, the numbers of steps, rejections and right-hand sides.
/// One trajectory stops at its third output (its observer's break) and one fails (a state whose
/// stretch flies apart until the metric test fails): the scalar solver stops at the same time.
/// Against the scalar production system (`ReducedSystem`, libm's `sin_cos` and `exp`), the
/// completed trajectories agree to round-off (10⁻¹¹ of the largest |y| over 2000 a.u.; 3·10⁻¹⁴
/// measured), and the dissociating one fails too.
#[test]
fn batched_dop853_equals_scalar_dop853_trajectory_by_trajectory() {
    let m = H2o;
    let mut rng = Rng::new(5);
    let mut states: Vec<Vec<f64>> = (0..11).map(|_| flat_body(&random_body(&m, &mut rng))).collect();
    // Trajectory 6 dissociates: a huge stretch momentum drives r1 out until the strict pivot test fails.
    states[6][3] = 60.0;
    let options = Dop853Options { rtol: 1e-9, atol: 1e-9, ..Default::default() };
    let (t_end, interval) = (2000.0, 150.0);
    let min_pivot = 1e-3;

    let dim = 13;
    let mut feeder = Feeder {
        states: states.clone(),
        next: 0,
        lane_job: vec![0; 4],
        records: vec![Record { outputs: vec![], end: None }; 11],
        stop_at: Some(2),
    };
    let mut lanes = Dop853Lanes::<F64x4>::new(dim, options).unwrap();
    lanes.integrate(&mut ProductionLanes::new(&m, min_pivot), 0.0, t_end, interval, &mut feeder).unwrap();

    let mut failures = 0;
    let mut worst: f64 = 0.0;
    for (j, y0) in states.iter().enumerate() {
        let run = |system: &mut dyn OdeSystem<Error = Failed>| {
            let mut scalar = Dop853::new(dim, options).unwrap();
            let mut outputs = Vec::new();
            let mut observer = |t: f64, y: &[f64]| {
                outputs.push((t, y.to_vec()));
                if j == 2 && outputs.len() == 3 { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
            };
            let result = scalar.integrate(system, 0.0, y0, t_end, interval, &mut observer);
            (outputs, result)
        };
        let one_lane = OneLane::<_, F64x2> {
            molecule: &m,
            min_pivot,
            y: vec![F64x2::splat(0.0); dim],
            d: vec![F64x2::splat(0.0); dim],
        };
        let (outputs, result) = run(&mut Stringly(one_lane));
        let batched = &feeder.records[j];
        assert_eq!(batched.outputs.len(), outputs.len(), "trajectory {j}: output count");
        for ((tb, yb), (ts, ys)) in batched.outputs.iter().zip(&outputs) {
            assert!(same_bits(*tb, *ts), "trajectory {j}: time {tb} vs {ts}");
            for (a, b) in yb.iter().zip(ys) {
                assert!(same_bits(*a, *b), "trajectory {j} at t = {ts}: {a} vs {b}");
            }
        }
        match (batched.end.expect("every trajectory finishes"), &result) {
            (Ok(a), Ok(b)) => assert_eq!(a, *b, "trajectory {j}: statistics"),
            (Err(LaneFailure::Rhs { t }), Err(SolveError::Rhs { t: ts, .. })) => {
                assert!(same_bits(t, *ts), "trajectory {j}: failed at {t} vs {ts}");
                failures += 1;
            }
            (a, b) => panic!("trajectory {j}: batched {a:?}, scalar {b:?}"),
        }
        // The scalar production system (libm): the same trajectory to round-off.
        let template = PhaseState::<3> {
            q: SVector::from_fn(|i, _| y0[i]),
            p: SVector::zeros(),
            euler: Vector3::zeros(),
            pe: Vector3::zeros(),
        };
        let system = ReducedSystem::new(&m, Reduction::none(), &template).with_min_pivot(min_pivot);
        let (libm_outputs, libm_result) = run(&mut Stringly(system));
        assert_eq!(libm_result.is_ok(), result.is_ok(), "trajectory {j}: {libm_result:?}");
        if result.is_ok() {
            assert_eq!(libm_outputs.len(), outputs.len());
            let scale = outputs.iter().flat_map(|(_, y)| y).fold(0f64, |s, v| s.max(v.abs()));
            for ((tl, yl), (ts, ys)) in libm_outputs.iter().zip(&outputs) {
                assert_eq!(tl, ts);
                for (a, b) in yl.iter().zip(ys) {
                    let d = (a - b).abs() / scale;
                    assert!(d <= 1e-11, "trajectory {j} at t = {ts}: {a} (libm) vs {b}");
                    worst = worst.max(d);
                }
            }
        }
    }
    eprintln!("lanes against the scalar production system: largest relative difference {worst:.1e}");
    assert_eq!(failures, 1, "trajectory 6 fails in both");
    assert_eq!(feeder.records[2].outputs.len(), 3);
}

/// A system with its error as [`Failed`], so that systems of different error types run through
/// one closure.
struct Stringly<S>(S);

impl<S: OdeSystem> OdeSystem for Stringly<S>
where
    S::Error: std::fmt::Debug,
{
    type Error = Failed;
    fn dim(&self) -> usize {
        self.0.dim()
    }
    fn rhs(&mut self, t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Self::Error> {
        self.0.rhs(t, y, dydt).map_err(|e| Failed(format!("{e:?}")))
    }
}

/// A failed evaluation, with what the system said.
#[derive(Debug)]
struct Failed(String);

impl std::fmt::Display for Failed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Failed {}
