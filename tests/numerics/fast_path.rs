//! The fast right-hand side (`runtime::hamiltonian::fast`) on every shipped molecule, against
//! independent references: the G-matrix path path (the reference implementation), the G-matrix path restricted to
//! `p_e = 0` for J = 0, finite differences of an independently built reduced Hamiltonian for
//! frozen coordinates, a trajectory of the G-matrix path system; and no allocation.

use crate::common;

use common::for_each_molecule;

use std::ops::ControlFlow;

use common::{Rng, random_state, richardson_derivative};
use rovib::molecules::H2o;
use rovib::runtime::hamiltonian::fast::{self, FastSystem, ReducedSystem, Reduction, ReductionError, RotationPart};
use rovib::runtime::hamiltonian::{
    self as gmatrix, HamiltonianError, HamiltonianSystem, MetricBlock, PhaseState, WMatrices, Workspace,
    rotation_matrix,
};
use rovib::runtime::integrate::{Dop853, Dop853Options, OdeSystem};
use rovib::runtime::nalgebra::{DMatrix, DVector, Quaternion, SVector, UnitQuaternion, Vector3};
use rovib::runtime::{KineticMatrices, Molecule, MoleculeVisitor};

const STATES: usize = 40;

/// `max |a − b| / max |b|` over one block (0 for an empty block; an all-zero `b` compares
/// absolutely).
fn block_rel(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(0f64, |m, v| m.max(v.abs()));
    let diff = a.iter().zip(b).fold(0f64, |m, (x, y)| m.max((x - y).abs()));
    if scale > 0.0 { diff / scale } else { diff }
}

/// The worst block-relative difference of two full states, block by block (q̇, ṗ, Ω̇, ṗ_e).
fn state_rel<const N: usize>(a: &PhaseState<N>, b: &PhaseState<N>) -> [f64; 4] {
    [
        block_rel(a.q.as_slice(), b.q.as_slice()),
        block_rel(a.p.as_slice(), b.p.as_slice()),
        block_rel(a.euler.as_slice(), b.euler.as_slice()),
        block_rel(a.pe.as_slice(), b.pe.as_slice()),
    ]
}

fn flat<const N: usize>(s: &PhaseState<N>) -> Vec<f64> {
    let mut y = vec![0.0; PhaseState::<N>::DIM];
    s.write_to(&mut y).unwrap();
    y
}

/// The body-formulation rates `(J̇, ς̇)` implied by a G-matrix right-hand side `ds` at `s`, by the
/// chain rule through the Euler angles: `J̇ = (∂W/∂θ θ̇ + ∂W/∂ψ ψ̇) p_e + W ṗ_e` and
/// `ς̇ = Σ ∂ς/∂Ω_i Ω̇_i` with `ς = exp(φ ẑ/2) exp(θ x̂/2) exp(ψ ẑ/2)`. Independent of the
/// reduced system's own formulas (`J × ω`, `½ ς ⊗ (0, ω)`).
fn body_rates<const N: usize>(s: &PhaseState<N>, ds: &PhaseState<N>) -> (Vector3<f64>, Quaternion<f64>) {
    let w = WMatrices::new(&s.euler).unwrap();
    let jdot = (w.dw_dtheta * ds.euler[1] + w.dw_dpsi * ds.euler[2]) * s.pe + w.w * ds.pe;
    let half = |axis: Vector3<f64>| Quaternion::from_imag(axis * 0.5);
    let qz = |a: f64| *UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a).quaternion();
    let qx = |a: f64| *UnitQuaternion::from_axis_angle(&Vector3::x_axis(), a).quaternion();
    let (a, b, c) = (qz(s.euler[0]), qx(s.euler[1]), qz(s.euler[2]));
    let qdot = a * half(Vector3::z()) * b * c * ds.euler[0]
        + a * b * half(Vector3::x()) * c * ds.euler[1]
        + a * b * c * half(Vector3::z()) * ds.euler[2];
    (jdot, qdot)
}

fn quaternion_slice(q: &Quaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// The fast rhs equals the G-matrix path rhs block by block to 1e-12 relative; so does H; ṗ_φ is +0.
#[derive(Copy, Clone)]
struct FastEqualsGMatrix;
impl MoleculeVisitor for FastEqualsGMatrix {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(101);
        let mut ws = Workspace::<N>::default();
        let mut system = FastSystem::new(&m);
        let mut worst = [0f64; 4];
        let mut worst_h = 0f64;
        for _ in 0..STATES {
            let s = random_state(&m, &mut rng);
            let reference = gmatrix::rhs(&m, &s, &mut ws).unwrap();
            let d = fast::rhs(&m, &s).unwrap();
            assert_eq!(d.pe[0].to_bits(), 0f64.to_bits(), "{}: ṗ_φ must be exactly +0", m.name());
            for (w, e) in worst.iter_mut().zip(state_rel(&d, &reference)) {
                *w = w.max(e);
            }
            // The OdeSystem gives the same numbers as the function, to the bit.
            let y = flat(&s);
            let mut dy = vec![0.0; y.len()];
            system.rhs(0.0, &y, &mut dy).unwrap();
            assert_eq!(dy, flat(&d));
            let h = gmatrix::hamiltonian(&m, &s).unwrap();
            // Relative to |H|, or to 1 mEh when H is smaller (a van der Waals complex, where T and U
            // nearly cancel).
            worst_h = worst_h.max((system.energy(&y).unwrap() - h).abs() / h.abs().max(1e-3));
        }
        eprintln!(
            "{}: fast vs G-matrix path rhs, worst block-relative difference q̇ {:.1e}, ṗ {:.1e}, Ω̇ {:.1e}, ṗ_e {:.1e}; H {:.1e}",
            m.name(),
            worst[0],
            worst[1],
            worst[2],
            worst[3],
            worst_h
        );
        for (block, w) in ["q̇", "ṗ", "Ω̇", "ṗ_e"].iter().zip(worst) {
            assert!(w < 1e-12, "{}: fast vs G-matrix path {block}: {w:e}", m.name());
        }
        assert!(worst_h < 1e-13, "{}: fast vs G-matrix path H: {worst_h:e}", m.name());
    }
}

#[test]
fn fast_rhs_equals_the_gmatrix_rhs() {
    common::for_each_well_conditioned_molecule(FastEqualsGMatrix);
}

/// Invalid states give the G-matrix path's errors: non-finite components, gimbal lock.
#[derive(Copy, Clone)]
struct SameErrors;
impl MoleculeVisitor for SameErrors {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(102);
        let mut ws = Workspace::<N>::default();
        let s = random_state(&m, &mut rng);
        let mut bad = vec![];
        let mut gimbal = s;
        gimbal.euler[1] = 0.0;
        bad.push(gimbal);
        let mut gimbal = s;
        gimbal.euler[1] = core::f64::consts::PI;
        bad.push(gimbal);
        let mut nan = s;
        nan.pe[2] = f64::NAN;
        bad.push(nan);
        let mut inf = s;
        inf.euler[0] = f64::INFINITY;
        bad.push(inf);
        if N > 0 {
            let mut nan = s;
            nan.q[N - 1] = f64::NAN;
            bad.push(nan);
            let mut nan = s;
            nan.p[0] = f64::NAN;
            bad.push(nan);
        }
        for b in &bad {
            let expected = gmatrix::rhs(&m, b, &mut ws).unwrap_err();
            assert_eq!(fast::rhs(&m, b).unwrap_err(), expected, "{}", m.name());
            assert_eq!(fast::hamiltonian(&m, b).unwrap_err(), gmatrix::hamiltonian(&m, b).unwrap_err());
        }
    }
}

#[test]
fn invalid_states_give_the_gmatrix_errors() {
    for_each_molecule(SameErrors);
}

#[test]
fn singular_metrics_give_the_gmatrix_errors() {
    let m = H2o;
    let mut rng = Rng::new(103);
    let mut ws = Workspace::<3>::default();
    let s = random_state(&m, &mut rng);
    // Linear (α = π): the inertia tensor is singular. Coinciding hydrogens (α = 0, r1 = r2):
    // singular as well. r1 = 0: the bend no longer moves H1, but H2 still moves.
    for (r1, r2, alpha) in [(1.8, 1.9, core::f64::consts::PI), (1.8, 1.8, 0.0), (0.0, 1.8, 1.8), (0.0, 0.0, 1.8)] {
        let mut b = s;
        b.q = SVector::<f64, 3>::new(r1, r2, alpha);
        match gmatrix::rhs(&m, &b, &mut ws) {
            Err(expected) => {
                assert!(matches!(expected, HamiltonianError::SingularMetric { .. }), "{expected}");
                eprintln!("h2o at (r1, r2, α) = ({r1}, {r2}, {alpha:.4}): {expected}");
                assert_eq!(fast::rhs(&m, &b).unwrap_err(), expected);
                let mut reduced = ReducedSystem::new(&m, Reduction::zero_angular_momentum(true), &b);
                let mut y = vec![0.0; reduced.dim()];
                let mut zero_j = b;
                zero_j.pe = Vector3::zeros();
                reduced.reduce(&zero_j, &mut y).unwrap();
                let mut dy = vec![0.0; y.len()];
                assert_eq!(reduced.rhs(0.0, &y, &mut dy).unwrap_err(), expected);
            }
            Ok(_) => {
                let (d, reference) = (fast::rhs(&m, &b).unwrap(), gmatrix::rhs(&m, &b, &mut ws).unwrap());
                assert!(state_rel(&d, &reference).iter().all(|&e| e < 1e-12));
            }
        }
    }
    let mut linear = s;
    linear.q[2] = core::f64::consts::PI;
    assert!(matches!(
        fast::rhs(&m, &linear),
        Err(HamiltonianError::SingularMetric { matrix: MetricBlock::Inertia, .. })
    ));
}

/// Metrics that are singular or indefinite in a block the factorization never forms (`a`,
/// `G11⁻¹`) are still reported as the G-matrix path reports them.
#[test]
fn metric_factor_names_the_block_the_gmatrix_path_names() {
    use rovib::runtime::hamiltonian::{InverseMetric, MetricFactor};
    use rovib::runtime::nalgebra::{Matrix2, Matrix3, SMatrix};
    let inertia = Matrix3::from_diagonal(&Vector3::new(3.0, 4.0, 5.0));
    // Redundant coordinates: a singular, I fine.
    let redundant = KineticMatrices::<2> { a: Matrix2::new(1e3, 1e3, 1e3, 1e3), coriolis: SMatrix::zeros(), inertia };
    // A coordinate that only rotates the molecule: a and I fine, M singular (G11⁻¹ and S too).
    let rotation = KineticMatrices::<1> {
        a: SMatrix::from_element(3.0),
        coriolis: SMatrix::<f64, 3, 1>::new(3.0, 0.0, 0.0),
        inertia,
    };
    // Indefinite: a and I positive definite, M not.
    let indefinite = KineticMatrices::<1> { coriolis: SMatrix::<f64, 3, 1>::new(5.0, 0.0, 0.0), ..rotation };
    let q2 = SVector::<f64, 2>::new(0.1, 0.2);
    let q1 = SVector::<f64, 1>::new(0.3);
    let expected = InverseMetric::new(&redundant, &q2).unwrap_err();
    assert!(matches!(expected, HamiltonianError::SingularMetric { matrix: MetricBlock::Vibrational, .. }));
    assert_eq!(MetricFactor::new(&redundant, &q2).unwrap_err(), expected);
    for k in [rotation, indefinite] {
        let expected = InverseMetric::new(&k, &q1).unwrap_err();
        assert!(matches!(expected, HamiltonianError::SingularMetric { matrix: MetricBlock::G11Inverse, .. }));
        assert_eq!(MetricFactor::new(&k, &q1).unwrap_err(), expected);
    }
    let mut nan = rotation;
    nan.a[(0, 0)] = f64::NAN;
    assert_eq!(MetricFactor::new(&nan, &q1).unwrap_err(), InverseMetric::new(&nan, &q1).unwrap_err());
}

/// The J = 0 systems equal the G-matrix path at `p_e = 0`, where the G-matrix path's ṗ_e is exactly zero.
#[derive(Copy, Clone)]
struct ZeroJEqualsGMatrix;
impl MoleculeVisitor for ZeroJEqualsGMatrix {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(104);
        let mut ws = Workspace::<N>::default();
        let mut worst = [0f64; 3];
        for _ in 0..STATES {
            let mut s = random_state(&m, &mut rng);
            s.pe = Vector3::zeros();
            let reference = gmatrix::rhs(&m, &s, &mut ws).unwrap();
            // ṗ_e is linear in p_e: at p_e = 0 it vanishes identically, so p_e stays 0.
            assert!(
                reference.pe.iter().all(|&v| v == 0.0),
                "{}: G-matrix ṗ_e at p_e = 0: {:?}",
                m.name(),
                reference.pe
            );
            for orientation in [true, false] {
                let mut system = ReducedSystem::new(&m, Reduction::zero_angular_momentum(orientation), &s);
                let dim = system.dim();
                assert_eq!(dim, 2 * N + if orientation { 4 } else { 0 });
                let mut y = vec![0.0; dim];
                system.reduce(&s, &mut y).unwrap();
                let mut dy = vec![0.0; dim];
                system.rhs(0.0, &y, &mut dy).unwrap();
                worst[0] = worst[0].max(block_rel(&dy[..N], reference.q.as_slice()));
                worst[1] = worst[1].max(block_rel(&dy[N..2 * N], reference.p.as_slice()));
                if orientation {
                    let (_, qdot) = body_rates(&s, &reference);
                    worst[2] = worst[2].max(block_rel(&dy[2 * N..], &quaternion_slice(&qdot)));
                }
                let e = system.expand(&y).unwrap();
                assert_eq!(e.pe, Vector3::zeros());
                assert_eq!((e.q, e.p), (s.q, s.p));
                assert!((rotation_matrix(&e.euler) - rotation_matrix(&s.euler)).amax() < 1e-14);
                let h = gmatrix::hamiltonian(&m, &s).unwrap();
                assert!((system.energy(&y).unwrap() - h).abs() <= 1e-13 * h.abs(), "{}", m.name());
            }
        }
        eprintln!(
            "{}: J = 0 system vs G-matrix path at p_e = 0, worst block-relative difference q̇ {:.1e}, ṗ {:.1e}, ς̇ {:.1e}",
            m.name(),
            worst[0],
            worst[1],
            worst[2]
        );
        assert!(worst.iter().all(|&w| w < 1e-12), "{}: J = 0 vs G-matrix path: {worst:?}", m.name());
    }
}

#[test]
fn zero_angular_momentum_system_equals_the_gmatrix_path_at_zero_euler_momenta() {
    common::for_each_well_conditioned_molecule(ZeroJEqualsGMatrix);
}

/// A J = 0 trajectory keeps p_e = 0 in the G-matrix path system to the bit, and the reduced system with
/// orientation follows it.
#[derive(Copy, Clone)]
struct ZeroJTrajectory;
impl MoleculeVisitor for ZeroJTrajectory {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        if N == 0 {
            return; // A rigid molecule with J = 0 does not move.
        }
        let mut rng = Rng::new(105);
        let mut s = random_state(&m, &mut rng);
        s.pe = Vector3::zeros();
        let opts = Dop853Options { rtol: 1e-12, atol: 1e-12, ..Dop853Options::default() };
        let (t_end, dt) = (200.0, 50.0);
        let mut reference_out = vec![];
        let mut gmatrix_system = HamiltonianSystem::new(&m);
        Dop853::new(gmatrix_system.dim(), opts)
            .unwrap()
            .integrate(&mut gmatrix_system, 0.0, &flat(&s), t_end, dt, &mut |_t: f64, y: &[f64]| {
                reference_out.push(PhaseState::<N>::read_from(y).unwrap());
                ControlFlow::Continue(())
            })
            .unwrap();
        let mut system = ReducedSystem::new(&m, Reduction::zero_angular_momentum(true), &s);
        let mut y0 = vec![0.0; system.dim()];
        system.reduce(&s, &mut y0).unwrap();
        let mut out = vec![];
        Dop853::new(system.dim(), opts)
            .unwrap()
            .integrate(&mut system, 0.0, &y0, t_end, dt, &mut |_t: f64, y: &[f64]| {
                out.push(y.to_vec());
                ControlFlow::Continue(())
            })
            .unwrap();
        assert_eq!(out.len(), reference_out.len());
        let mut worst = 0f64;
        for (y, reference) in out.iter().zip(&reference_out) {
            assert!(reference.pe.iter().all(|&v| v == 0.0), "{}: p_e left 0: {:?}", m.name(), reference.pe);
            let e = system.expand(y).unwrap();
            assert_eq!(e.pe, Vector3::zeros());
            let d = state_rel(&e, reference);
            let rotation = (rotation_matrix(&e.euler) - rotation_matrix(&reference.euler)).amax();
            worst = worst.max(d[0]).max(d[1]).max(rotation);
        }
        eprintln!(
            "{}: J = 0 trajectory vs G-matrix path (p_e = 0): worst block-relative difference {worst:.1e}",
            m.name()
        );
        assert!(worst < 1e-9, "{}: J = 0 trajectory vs G-matrix path: {worst:e}", m.name());
    }
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 11 s unoptimised on a loaded 2-core machine"]
fn zero_angular_momentum_trajectory_follows_the_gmatrix_path() {
    for_each_molecule(ZeroJTrajectory);
}

/// The reduced Hamiltonian built independently of the code under test: the full metric from
/// `kinetic` as a `DMatrix`, the frozen rows and columns deleted, nalgebra's general inverse.
/// Returns `(H, ω)`.
fn reduced_hamiltonian<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    active: &[bool; N],
    template: &PhaseState<N>,
    free: bool,
    orientation: bool,
    y: &[f64],
) -> (f64, Vector3<f64>) {
    let idx: Vec<usize> = (0..N).filter(|&k| active[k]).collect();
    let na = idx.len();
    let mut q = template.q;
    let mut p_a = DVector::zeros(na);
    for (s, &k) in idx.iter().enumerate() {
        q[k] = y[s];
        p_a[s] = y[na + s];
    }
    // Body layout: [q_a, p_a, quaternion (4) if the orientation is integrated, J (3) if free].
    let j = if free {
        let at = 2 * na + 4;
        Vector3::new(y[at], y[at + 1], y[at + 2])
    } else {
        assert_eq!(y.len(), 2 * na + if orientation { 4 } else { 0 });
        Vector3::zeros()
    };
    let mut k = KineticMatrices::<N>::default();
    m.kinetic(&q, &mut k);
    let mut full = DMatrix::zeros(3 + N, 3 + N);
    full.view_mut((0, 0), (3, 3)).copy_from(&k.inertia);
    full.view_mut((0, 3), (3, N)).copy_from(&k.coriolis);
    full.view_mut((3, 0), (N, 3)).copy_from(&k.coriolis.transpose());
    full.view_mut((3, 3), (N, N)).copy_from(&k.a);
    let keep: Vec<usize> = (0..3).chain(idx.iter().map(|k| k + 3)).collect();
    let reduced = DMatrix::from_fn(keep.len(), keep.len(), |r, c| full[(keep[r], keep[c])]);
    let inverse = reduced.try_inverse().expect("reduced metric invertible");
    let b = DVector::from_iterator(3 + na, j.iter().copied().chain(p_a.iter().copied()));
    let v = &inverse * &b;
    (0.5 * b.dot(&v) + m.potential(&q), Vector3::new(v[0], v[1], v[2]))
}

/// The quaternion of a state's Euler angles.
fn reference_quaternion<const N: usize>(s: &PhaseState<N>) -> Quaternion<f64> {
    *fast::quaternion_of_euler(&s.euler).quaternion()
}

/// Up to this many coordinates (every shipped molecule), [`FrozenIsHamiltonian`] freezes every
/// coordinate alone and tries 4 states per mask; above it (hexane's 54, added through
/// `ROVIB_MOLECULES_DIR`) every `⌈N / 12⌉`-th coordinate alone and one state per mask. Its work
/// grows as `N⁵` otherwise (a mask per coordinate, a finite difference per coordinate, a dense
/// inverse of the reduced metric per difference): 118 s for hexane in the test profile in full,
/// about a tenth of that scaled.
const FREEZE_EACH_UP_TO: usize = 18;

/// Masks to try: each coordinate frozen alone (every `⌈N / 12⌉`-th above
/// [`FREEZE_EACH_UP_TO`] coordinates), everything frozen, and a few mixed ones.
fn masks<const N: usize>(rng: &mut Rng) -> Vec<[bool; N]> {
    let mut out = vec![];
    let stride = if N > FREEZE_EACH_UP_TO { N.div_ceil(12) } else { 1 };
    for f in (0..N).step_by(stride) {
        let mut a = [true; N];
        a[f] = false;
        out.push(a);
    }
    if N > 0 {
        out.push([false; N]);
    }
    if N > 2 {
        for _ in 0..3 {
            out.push(core::array::from_fn(|_| rng.next_u64() & 1 == 1));
        }
    }
    out
}

/// The frozen-coordinate system's rhs is the symplectic gradient of its own Hamiltonian, built
/// independently and differentiated numerically; its energy is that Hamiltonian; expanding a
/// state gives a full state where the G-matrix path has q̇_frozen = 0 and the same velocities.
#[derive(Copy, Clone)]
struct FrozenIsHamiltonian;
impl MoleculeVisitor for FrozenIsHamiltonian {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(106);
        let mut ws = Workspace::<N>::default();
        let mut worst_fd = 0f64;
        let mut worst_reference = 0f64;
        let mut cases = 0;
        for active in masks::<N>(&mut rng) {
            for rotation in [RotationPart::Free, RotationPart::ZeroAngularMomentum { orientation: true }] {
                let free = rotation == RotationPart::Free;
                for _ in 0..if N > FREEZE_EACH_UP_TO { 1 } else { 4 } {
                    let mut s = random_state(&m, &mut rng);
                    if !free {
                        s.pe = Vector3::zeros();
                    }
                    let mut system = ReducedSystem::new(&m, Reduction { active, rotation }, &s);
                    let dim = system.dim();
                    let na = active.iter().filter(|&&a| a).count();
                    assert_eq!(dim, 2 * na + if free { 7 } else { 4 });
                    let mut y = vec![0.0; dim];
                    system.reduce(&s, &mut y).unwrap();
                    let mut dy = vec![0.0; dim];
                    system.rhs(0.0, &y, &mut dy).unwrap();
                    cases += 1;

                    let mut h_of = |x: &[f64]| reduced_hamiltonian(&m, &active, &s, free, true, x).0;
                    let (h, omega) = reduced_hamiltonian(&m, &active, &s, free, true, &y);
                    let e = system.energy(&y).unwrap();
                    assert!((e - h).abs() <= 1e-12 * h.abs(), "{}: energy {e} vs {h}", m.name());

                    // Conjugate pairs (q_a, p_a); the rotation (quaternion, J) is not a canonical pair
                    // and is checked below against ω of the independent reduced metric.
                    let pairs: Vec<(usize, usize)> = (0..na).map(|s| (s, na + s)).collect();
                    let coord_blocks: Vec<usize> = pairs.iter().map(|&(x, _)| x).collect();
                    let momentum_blocks: Vec<usize> = pairs.iter().map(|&(_, p)| p).collect();
                    let scale = |idx: &[usize]| idx.iter().fold(1e-12_f64, |acc, &i| acc.max(dy[i].abs()));
                    let (scale_x, scale_p) = (scale(&coord_blocks), scale(&momentum_blocks));
                    for &(x, p) in &pairs {
                        let hx = 1e-3 * y[x].abs().max(1.0);
                        let hp = 1e-3 * y[p].abs().max(1.0);
                        let dh_dp = richardson_derivative(&y, p, hp, &mut h_of);
                        let dh_dx = richardson_derivative(&y, x, hx, &mut h_of);
                        // Differences below the differences' own round-off (ε·|H|/h, with margin)
                        // are not errors: a rate that is exactly zero (an isotropic potential's
                        // torque with only the angle active) has only round-off to compare.
                        let noise = |h_step: f64| 1e3 * f64::EPSILON * h.abs() / h_step;
                        let off = |d: f64, n: f64| (d.abs() - n).max(0.0);
                        worst_fd = worst_fd
                            .max(off(dy[x] - dh_dp, noise(hp)) / scale_x)
                            .max(off(dy[p] + dh_dx, noise(hx)) / scale_p);
                    }
                    // ς̇ = ½ ς ⊗ (0, ω) and J̇ = J × ω, with ω from the independent reduced metric.
                    let at = 2 * na;
                    let quaternion = Quaternion::new(y[at], y[at + 1], y[at + 2], y[at + 3]);
                    let qdot = quaternion * Quaternion::from_imag(omega) * 0.5;
                    worst_fd = worst_fd.max(block_rel(&dy[at..at + 4], &quaternion_slice(&qdot)));
                    if free {
                        let j = Vector3::new(y[at + 4], y[at + 5], y[at + 6]);
                        worst_fd = worst_fd.max(block_rel(&dy[at + 4..], j.cross(&omega).as_slice()));
                    }

                    // The expanded full state: the G-matrix path sees the same motion, with q̇_f = 0.
                    let full = system.expand(&y).unwrap();
                    let reference = gmatrix::rhs(&m, &full, &mut ws).unwrap();
                    let hf = gmatrix::hamiltonian(&m, &full).unwrap();
                    assert!((hf - e).abs() <= 1e-12 * e.abs(), "{}: G-matrix H of the expanded state", m.name());
                    // Judged against the velocities the state's momenta give unconstrained (with
                    // everything frozen, the G-matrix path's q̇ is all rounding).
                    let qdot_scale = reference.q.amax().max(fast::rhs(&m, &s).unwrap().q.amax());
                    for k in 0..N {
                        let expected = if active[k] { dy[active[..k].iter().filter(|&&a| a).count()] } else { 0.0 };
                        worst_reference = worst_reference.max((reference.q[k] - expected).abs() / qdot_scale);
                    }
                    // The seed's rotation rates, carried into the body formulation by the chain
                    // rule (the expanded Euler angles give ±ς: the same rotation).
                    let (jdot, qdot) = body_rates(&full, &reference);
                    let sign = quaternion.dot(&reference_quaternion(&full)).signum();
                    worst_reference =
                        worst_reference.max(block_rel(&dy[at..at + 4], &quaternion_slice(&(qdot * sign))));
                    if free {
                        worst_reference = worst_reference.max(block_rel(&dy[at + 4..], jdot.as_slice()));
                    }
                }
            }
        }
        eprintln!(
            "{}: frozen systems ({cases} cases): rhs vs finite differences of H_red {worst_fd:.1e}; \
             expanded state vs G-matrix path velocities {worst_reference:.1e}",
            m.name()
        );
        assert!(worst_fd < 1e-7, "{}: frozen rhs vs finite differences: {worst_fd:e}", m.name());
        assert!(
            worst_reference < 1e-11,
            "{}: frozen vs G-matrix path at the expanded state: {worst_reference:e}",
            m.name()
        );
    }
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 41 s unoptimised on a loaded 2-core machine"]
fn frozen_coordinate_system_is_hamiltonian_in_its_own_reduced_metric() {
    common::for_each_well_conditioned_molecule(FrozenIsHamiltonian);
}

/// With nothing frozen the reduced system moves as the fast path: q̇ and ṗ to the bit, the
/// rotation through the chain rule to rounding.
#[derive(Copy, Clone)]
struct NothingFrozen;
impl MoleculeVisitor for NothingFrozen {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(107);
        for _ in 0..STATES {
            let s = random_state(&m, &mut rng);
            let mut system = ReducedSystem::new(&m, Reduction::none(), &s);
            let mut explicit = ReducedSystem::new(&m, Reduction::frozen([true; N]), &s);
            let mut y = vec![0.0; system.dim()];
            system.reduce(&s, &mut y).unwrap();
            assert_eq!(y.len(), 2 * N + 7);
            let mut dy = vec![0.0; y.len()];
            system.rhs(0.0, &y, &mut dy).unwrap();
            // J = W p_e comes from the same code as the fast path's, so q̇ and ṗ are the same bits.
            let reference = fast::rhs(&m, &s).unwrap();
            assert_eq!(&dy[..N], reference.q.as_slice(), "{}", m.name());
            assert_eq!(&dy[N..2 * N], reference.p.as_slice(), "{}", m.name());
            let (jdot, qdot) = body_rates(&s, &reference);
            assert!(block_rel(&dy[2 * N..2 * N + 4], &quaternion_slice(&qdot)) < 1e-12, "{}: ς̇", m.name());
            assert!(block_rel(&dy[2 * N + 4..], jdot.as_slice()) < 1e-12, "{}: J̇", m.name());
            let mut dy2 = vec![0.0; y.len()];
            explicit.rhs(0.0, &y, &mut dy2).unwrap();
            assert_eq!(dy2, dy);
            assert_eq!(system.energy(&y).unwrap(), fast::hamiltonian(&m, &s).unwrap());
            let e = system.expand(&y).unwrap();
            assert_eq!((e.q, e.p), (s.q, s.p));
            assert!((rotation_matrix(&e.euler) - rotation_matrix(&s.euler)).amax() < 1e-14);
            assert!(block_rel(e.pe.as_slice(), s.pe.as_slice()) < 1e-13, "{}: p_e {:?} vs {:?}", m.name(), e.pe, s.pe);
        }
    }
}

#[test]
fn nothing_frozen_is_the_fast_path_exactly() {
    for_each_molecule(NothingFrozen);
}

#[test]
fn reduce_rejects_states_the_system_cannot_hold() {
    let m = H2o;
    let s = random_state(&m, &mut Rng::new(108));
    let zero_j = ReducedSystem::new(&m, Reduction::zero_angular_momentum(false), &s);
    let mut y = vec![0.0; zero_j.dim()];
    let j = fast::BodyState::from_phase(&s).unwrap().j;
    assert_eq!(zero_j.reduce(&s, &mut y), Err(ReductionError::NonzeroAngularMomentum { j: j.into() }));
    assert_eq!(zero_j.reduce(&s, &mut [0.0; 3]), Err(ReductionError::DimensionMismatch { expected: 6, found: 3 }));
    let by_name = Reduction::freezing(&m, &["alpha"]).unwrap();
    assert_eq!(by_name, Reduction::frozen([true, true, false]));
    assert_eq!(
        Reduction::<3>::freezing(&m, &["theta"]),
        Err(ReductionError::UnknownCoordinate { name: "theta".into(), known: vec!["r1", "r2", "alpha"] })
    );
    let frozen = ReducedSystem::new(&m, by_name, &s);
    let mut moved = s;
    moved.q[2] += 0.1;
    let mut y = vec![0.0; frozen.dim()];
    assert_eq!(frozen.dim(), 2 * 2 + 4 + 3, "active q and p, quaternion, J");
    assert_eq!(
        frozen.reduce(&moved, &mut y),
        Err(ReductionError::FrozenCoordinateMoved { index: 2, found: moved.q[2], held: s.q[2] })
    );
    // The frozen coordinate's momentum is not part of the reduced state.
    let mut other_p = s;
    other_p.p[2] += 3.0;
    let mut y2 = vec![0.0; frozen.dim()];
    frozen.reduce(&s, &mut y).unwrap();
    frozen.reduce(&other_p, &mut y2).unwrap();
    assert_eq!(y, y2);
}

/// No path allocates, over many evaluations.
#[derive(Copy, Clone)]
struct NoAllocation;
impl MoleculeVisitor for NoAllocation {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(109);
        let states: Vec<PhaseState<N>> = (0..100).map(|_| random_state(&m, &mut rng)).collect();
        let template = states[0];
        let mut fast_system = FastSystem::new(&m);
        let mut zero_j = ReducedSystem::new(&m, Reduction::zero_angular_momentum(false), &template);
        let mut zero_j_oriented = ReducedSystem::new(&m, Reduction::zero_angular_momentum(true), &template);
        let mut active = [true; N];
        if N > 0 {
            active[0] = false;
        }
        let mut frozen = ReducedSystem::new(&m, Reduction::frozen(active), &template);
        let flats: Vec<Vec<f64>> = states.iter().map(flat).collect();
        let reduced = |sys: &ReducedSystem<'_, M, N, NA>| -> Vec<Vec<f64>> {
            states
                .iter()
                .map(|s| {
                    let mut s = *s;
                    if sys.reduction().rotation != RotationPart::Free {
                        s.pe = Vector3::zeros();
                    }
                    for k in 0..N {
                        if !sys.reduction().active[k] {
                            s.q[k] = template.q[k];
                        }
                    }
                    let mut y = vec![0.0; sys.dim()];
                    sys.reduce(&s, &mut y).unwrap();
                    y
                })
                .collect()
        };
        let (y_zero_j, y_oriented, y_frozen) = (reduced(&zero_j), reduced(&zero_j_oriented), reduced(&frozen));
        // Large enough for every layout (the body layout of a free system has 2N + 7).
        let mut dy = vec![0.0; PhaseState::<N>::DIM + 1];
        let mut sum = 0.0;
        let info = allocation_counter::measure(|| {
            for _ in 0..10 {
                for (i, s) in states.iter().enumerate() {
                    sum += fast::rhs(&m, s).unwrap().pe[2];
                    sum += fast::hamiltonian(&m, s).unwrap();
                    fast_system.rhs(0.0, &flats[i], &mut dy[..PhaseState::<N>::DIM]).unwrap();
                    sum += dy[0] + fast_system.energy(&flats[i]).unwrap();
                    for (sys, y) in [
                        (&mut zero_j, &y_zero_j[i]),
                        (&mut zero_j_oriented, &y_oriented[i]),
                        (&mut frozen, &y_frozen[i]),
                    ] {
                        if y.is_empty() {
                            continue; // a rigid molecule at J = 0 without orientation
                        }
                        sys.rhs(0.0, y, &mut dy[..y.len()]).unwrap();
                        sum += dy[0] + sys.energy(y).unwrap() + sys.expand(y).unwrap().q.sum();
                    }
                }
            }
        });
        assert!(sum.is_finite());
        assert_eq!(info.count_total, 0, "{}: {} allocations", m.name(), info.count_total);
    }
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 8 s unoptimised on a loaded 2-core machine"]
fn no_path_allocates() {
    for_each_molecule(NoAllocation);
    // The counter does see allocations: building an error allocates (its q).
    let mut linear = random_state(&H2o, &mut Rng::new(110));
    linear.q[2] = core::f64::consts::PI;
    let info = allocation_counter::measure(|| {
        assert!(fast::rhs(&H2o, &linear).is_err());
    });
    assert!(info.count_total > 0);
}

/// A DOP853 trajectory of the fast system follows the G-matrix path system's.
#[derive(Copy, Clone)]
struct Trajectory;
impl MoleculeVisitor for Trajectory {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let s = random_state(&m, &mut Rng::new(111));
        let opts = Dop853Options { rtol: 1e-12, atol: 1e-12, ..Dop853Options::default() };
        let (t_end, dt) = (300.0, 25.0);
        let run = |system: &mut dyn FnMut(&mut Dop853, &mut Vec<Vec<f64>>)| {
            let mut out = vec![];
            let mut solver = Dop853::new(PhaseState::<N>::DIM, opts).unwrap();
            system(&mut solver, &mut out);
            out
        };
        let y0 = flat(&s);
        let reference_out = run(&mut |solver, out| {
            let mut sys = HamiltonianSystem::new(&m);
            solver
                .integrate(&mut sys, 0.0, &y0, t_end, dt, &mut |_t: f64, y: &[f64]| {
                    out.push(y.to_vec());
                    ControlFlow::Continue(())
                })
                .unwrap();
        });
        let fast_out = run(&mut |solver, out| {
            let mut sys = FastSystem::new(&m);
            solver
                .integrate(&mut sys, 0.0, &y0, t_end, dt, &mut |_t: f64, y: &[f64]| {
                    out.push(y.to_vec());
                    ControlFlow::Continue(())
                })
                .unwrap();
        });
        assert_eq!(reference_out.len(), fast_out.len());
        let mut worst = [0f64; 4];
        for (a, b) in fast_out.iter().zip(&reference_out) {
            let (a, b) = (PhaseState::<N>::read_from(a).unwrap(), PhaseState::<N>::read_from(b).unwrap());
            assert_eq!(a.pe[0], b.pe[0], "p_φ is conserved exactly in both");
            for (w, e) in worst.iter_mut().zip(state_rel(&a, &b)) {
                *w = w.max(e);
            }
        }
        eprintln!(
            "{}: fast vs G-matrix path DOP853 trajectory (t = {t_end}), worst block-relative difference q {:.1e}, p {:.1e}, Ω {:.1e}, p_e {:.1e}",
            m.name(),
            worst[0],
            worst[1],
            worst[2],
            worst[3]
        );
        assert!(worst.iter().all(|&w| w < 1e-9), "{}: trajectories differ: {worst:?}", m.name());
    }
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 11 s unoptimised on a loaded 2-core machine"]
fn fast_trajectory_follows_the_gmatrix_trajectory() {
    for_each_molecule(Trajectory);
}
