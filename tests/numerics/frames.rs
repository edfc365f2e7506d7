//! Lab-frame conversions on every generated molecule: round trips in both directions, the
//! angular momentum in both frames, the least-squares velocity projection, and the errors
//! (non-representable positions, gimbal lock, non-finite input).

use crate::common;

use common::for_each_molecule;

use common::{Rng, random_state};
use rovib::molecules::{Ch4, H2o, H2oRigid, Nh3};
use rovib::runtime::frames::{CentreOfMass, FitOptions, FrameError, LabState, from_lab, lab_angular_momentum, to_lab};
use rovib::runtime::hamiltonian::{PhaseState, body_angular_momentum, hamiltonian, rotation_matrix};
use rovib::runtime::nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rovib::runtime::{Kinematics, Molecule, MoleculeVisitor};

const STATES: usize = 12;

fn random_com(rng: &mut Rng) -> CentreOfMass {
    CentreOfMass {
        position: Vector3::from_fn(|_, _| rng.uniform(-10.0, 10.0)),
        velocity: Vector3::from_fn(|_, _| rng.uniform(-1e-3, 1e-3)),
    }
}

/// `a − b` wrapped into (−π, π].
fn wrapped(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    if d > std::f64::consts::PI { d - std::f64::consts::TAU } else { d }
}

/// max |a − b| / max(max |b|, floor).
fn rel<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>, b: &SMatrix<f64, R, C>, floor: f64) -> f64 {
    if R * C == 0 {
        return 0.0;
    }
    (a - b).amax() / b.amax().max(floor)
}

/// internal → lab → internal and lab → internal → lab, to 1e-10 relative, at random states.
#[derive(Copy, Clone)]
struct RoundTrips;
impl MoleculeVisitor for RoundTrips {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(21);
        let (mut worst_state, mut worst_lab, mut worst_residual) = (0f64, 0f64, 0f64);
        let mut most_iterations = 0;
        for _ in 0..STATES {
            let state = random_state(&m, &mut rng);
            let com = random_com(&mut rng);
            let lab = to_lab(&m, &state, &com).unwrap();
            let (back, com_back, report) =
                from_lab(&m, &lab, &FitOptions::default()).unwrap_or_else(|e| panic!("{}: {e}", m.name()));
            // Coordinates that are angles could come back shifted by 2π; none of the shipped
            // ones do near the reference, so q is compared directly.
            let angles = (0..3).map(|a| wrapped(back.euler[a], state.euler[a]).abs()).fold(0.0, f64::max);
            worst_state = worst_state
                .max(rel(&back.q, &state.q, 1.0))
                .max(rel(&back.p, &state.p, 1.0))
                .max(rel(&back.pe, &state.pe, 1.0))
                .max(angles)
                .max(rel(&com_back.position, &com.position, 1.0))
                .max(rel(&com_back.velocity, &com.velocity, 1e-3));
            worst_residual = worst_residual.max(report.position_residual).max(report.velocity_residual);
            most_iterations = most_iterations.max(report.iterations);
            let again = to_lab(&m, &back, &com_back).unwrap();
            worst_lab = worst_lab.max(rel(&again.positions, &lab.positions, 1.0)).max(rel(
                &again.velocities,
                &lab.velocities,
                1e-3,
            ));
        }
        eprintln!(
            "{}: internal → lab → internal {worst_state:.1e}, lab → internal → lab {worst_lab:.1e}, \
             fit residuals ≤ {worst_residual:.1e}, ≤ {most_iterations} Gauss–Newton steps",
            m.name()
        );
        assert!(worst_state < 1e-10, "{}: internal → lab → internal {worst_state:e}", m.name());
        assert!(worst_lab < 1e-10, "{}: lab → internal → lab {worst_lab:e}", m.name());
        assert!(worst_residual < 1e-12, "{}: fit residual {worst_residual:e}", m.name());
    }
}

#[test]
fn round_trips_at_random_states() {
    for_each_molecule(RoundTrips);
}

/// `L = Σ m_i (x_i − X) × (v_i − V)` equals `R(Ω) J`, so `|L| = |J|`; the lab kinetic energy
/// about the centre of mass equals `H − U`.
#[derive(Copy, Clone)]
struct AngularMomentum;
impl MoleculeVisitor for AngularMomentum {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(22);
        let masses = m.masses();
        for _ in 0..STATES {
            let state = random_state(&m, &mut rng);
            let lab = to_lab(&m, &state, &random_com(&mut rng)).unwrap();
            let j = body_angular_momentum(&state).unwrap();
            let l = lab.angular_momentum(&masses);
            assert!((l.norm() - j.norm()).abs() < 1e-11 * j.norm(), "{}: |L| {} |J| {}", m.name(), l.norm(), j.norm());
            assert!(rel(&l, &(rotation_matrix(&state.euler) * j), 1.0) < 1e-11, "{}: L ≠ R J", m.name());
            assert!(rel(&lab_angular_momentum(&state).unwrap(), &l, 1.0) < 1e-11);
            let t = hamiltonian(&m, &state).unwrap() - m.potential(&state.q);
            let t_lab = lab.internal_kinetic_energy(&masses);
            assert!((t - t_lab).abs() < 1e-11 * t, "{}: T = {t}, lab {t_lab}", m.name());
        }
    }
}

#[test]
fn lab_angular_momentum_is_r_times_j() {
    for_each_molecule(AngularMomentum);
}

/// Arbitrary Cartesian velocities on a representable geometry: J is still the lab angular
/// momentum (a rigid rotation is always representable), and the kinetic energy splits exactly
/// into centre of mass + kept + discarded (the projection is orthogonal). Molecules with a full
/// set of 3·NA − 6 coordinates discard nothing.
#[derive(Copy, Clone)]
struct VelocityProjection;
impl MoleculeVisitor for VelocityProjection {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(23);
        let masses = m.masses();
        let total_mass: f64 = masses.iter().sum();
        for _ in 0..STATES {
            let state = random_state(&m, &mut rng);
            let mut lab = to_lab(&m, &state, &CentreOfMass::AT_REST).unwrap();
            lab.velocities = SMatrix::from_fn(|_, _| rng.uniform(-1e-3, 1e-3));
            let (fit, com, report) = from_lab(&m, &lab, &FitOptions::default()).unwrap();
            let l = lab.angular_momentum(&masses);
            assert!(rel(&lab_angular_momentum(&fit).unwrap(), &l, 1e-6) < 1e-10, "{}", m.name());
            let kept = to_lab(&m, &fit, &com).unwrap();
            let e_in = lab.kinetic_energy(&masses);
            let e_parts = 0.5 * total_mass * com.velocity.norm_squared()
                + kept.internal_kinetic_energy(&masses)
                + report.discarded_kinetic_energy;
            assert!((e_in - e_parts).abs() < 1e-11 * e_in, "{}: {e_in} vs {e_parts}", m.name());
            if N == 3 * NA - 6 {
                assert!(report.discarded_kinetic_energy < 1e-12 * e_in, "{}: {report:?}", m.name());
            } else {
                assert!(report.discarded_kinetic_energy > 1e-6 * e_in, "{}: {report:?}", m.name());
            }
        }
    }
}

#[test]
fn arbitrary_velocities_are_projected_by_mass_weighted_least_squares() {
    for_each_molecule(VelocityProjection);
}

#[test]
fn distorted_rigid_water_is_not_representable() {
    let m = H2oRigid;
    let mut body = SMatrix::<f64, 3, 3>::zeros();
    m.positions(&SVector::zeros(), &mut body);
    let rotation = rotation_matrix(&Vector3::new(0.4, 1.2, -2.0));
    // Stretch one O–H bond by 0.05 bohr: a geometry of water, but not of *rigid* water.
    let mut distorted = body;
    let oh = (body.column(1) - body.column(0)).normalize();
    distorted.set_column(1, &(body.column(1) + oh * 0.05));
    let lab = LabState { positions: rotation * distorted, velocities: SMatrix::zeros() };
    match from_lab(&m, &lab, &FitOptions::default()) {
        Err(FrameError::NotRepresentable { residual, tolerance, worst_atom, worst_atom_residual, q, .. }) => {
            assert!(residual > 1e-3 && residual < 0.05, "residual {residual}");
            assert_eq!(tolerance, FitOptions::<0>::default().residual_tolerance);
            assert_eq!(worst_atom, 1, "the stretched hydrogen misfits most");
            assert!(worst_atom_residual > residual && q.is_empty());
        }
        other => panic!("expected NotRepresentable, got {other:?}"),
    }
    let message = from_lab(&m, &lab, &FitOptions::default()).unwrap_err().to_string();
    assert!(message.contains("not representable") && message.contains("atom order"), "{message}");
    // The undistorted geometry is fine.
    let lab = LabState { positions: rotation * body, velocities: SMatrix::zeros() };
    assert!(from_lab(&m, &lab, &FitOptions::default()).is_ok());
}

#[test]
fn orientation_at_theta_zero_is_euler_singular() {
    let m = H2o;
    let q = m.reference_geometry().unwrap();
    let mut body = SMatrix::<f64, 3, 3>::zeros();
    m.positions(&q, &mut body);
    // A rotation about the lab z axis only: θ = 0.
    let rz = rotation_matrix(&Vector3::new(0.7, 0.0, 0.0));
    let lab = LabState { positions: rz * body, velocities: SMatrix::zeros() };
    match from_lab(&m, &lab, &FitOptions::default()) {
        Err(FrameError::EulerSingular { theta }) => assert!(theta.abs() < 1e-8, "θ = {theta}"),
        other => panic!("expected EulerSingular, got {other:?}"),
    }
    // Tilting it by 90° about x is the documented way out.
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
    let lab = LabState { positions: rx * rz * body, velocities: SMatrix::zeros() };
    assert!(from_lab(&m, &lab, &FitOptions::default()).is_ok());
    // And the forward map refuses θ = 0 too (J = W p_e is undefined there).
    let locked = PhaseState { q, euler: Vector3::new(0.7, 0.0, 0.0), ..PhaseState::zeros() };
    assert_eq!(to_lab(&m, &locked, &CentreOfMass::AT_REST), Err(FrameError::EulerSingular { theta: 0.0 }));
}

#[test]
fn non_finite_input_is_rejected() {
    let m = H2o;
    let mut rng = Rng::new(24);
    let lab = to_lab(&m, &random_state(&m, &mut rng), &CentreOfMass::AT_REST).unwrap();
    let mut bad = lab;
    bad.positions[(2, 1)] = f64::NAN;
    assert_eq!(from_lab(&m, &bad, &FitOptions::default()), Err(FrameError::NonFinite { quantity: "lab positions" }));
    let mut bad = lab;
    bad.velocities[(0, 2)] = f64::NEG_INFINITY;
    assert_eq!(from_lab(&m, &bad, &FitOptions::default()), Err(FrameError::NonFinite { quantity: "lab velocities" }));
    let mut state = random_state(&m, &mut rng);
    state.pe[0] = f64::NAN;
    assert!(matches!(to_lab(&m, &state, &CentreOfMass::AT_REST), Err(FrameError::NonFinite { .. })));
}

/// Every permutation of `0..n` (Heap's algorithm), for the labellings of equivalent atoms.
fn permutations(n: usize) -> Vec<Vec<usize>> {
    fn heap(k: usize, a: &mut Vec<usize>, out: &mut Vec<Vec<usize>>) {
        if k <= 1 {
            out.push(a.clone());
            return;
        }
        for i in 0..k {
            heap(k - 1, a, out);
            let j = if k.is_multiple_of(2) { i } else { 0 };
            a.swap(j, k - 1);
        }
    }
    let mut out = Vec::new();
    heap(n, &mut (0..n).collect(), &mut out);
    out
}

/// CH4 at its tetrahedral equilibrium, at rest, under all 24 labellings of its hydrogens: half
/// are proper rotations of the definition's labelled geometry and must fit with every coordinate
/// in its range and H(0) = U(tetrahedral); the other half are mirror images, which a proper fit
/// could reproduce only with negative bond lengths, and must be refused as such. Nothing else.
#[test]
fn ch4_labellings_fit_or_are_mirror_images() {
    let m = Ch4;
    // The reference has the bonds at r_e and every angle but a12 tetrahedral.
    let mut q_tet = m.reference_geometry().unwrap();
    q_tet[4] = (-1.0f64 / 3.0).acos();
    let u_min = m.potential(&q_tet);
    let state = PhaseState { q: q_tet, p: SVector::zeros(), euler: Vector3::new(0.3, 1.1, -0.5), pe: Vector3::zeros() };
    let com = CentreOfMass { position: Vector3::new(1.0, -2.0, 0.5), velocity: Vector3::zeros() };
    let lab: LabState<5> = to_lab(&m, &state, &com).unwrap();
    let (mut fitted, mut mirrored) = (0, 0);
    for perm in permutations(4) {
        let mut relabelled = lab;
        for (k, &j) in perm.iter().enumerate() {
            relabelled.positions.set_column(1 + k, &lab.positions.column(1 + j));
        }
        match from_lab(&m, &relabelled, &FitOptions::default()) {
            Ok((fit, _, _)) => {
                assert!(m.in_range(&fit.q).is_ok(), "{perm:?}: q = {:?} outside its ranges", fit.q.as_slice());
                let h = hamiltonian(&m, &fit).unwrap();
                assert!((h - u_min).abs() < 1e-9, "{perm:?}: H(0) = {h}, U(tetrahedral) = {u_min}");
                let back = to_lab(&m, &fit, &com).unwrap();
                assert!((back.positions - relabelled.positions).amax() < 1e-9, "{perm:?}: positions not reproduced");
                fitted += 1;
            }
            Err(FrameError::MirrorImage { .. }) => mirrored += 1,
            Err(e) => panic!("{perm:?}: {e}"),
        }
    }
    assert_eq!((fitted, mirrored), (12, 12));
}

/// NH3 of the wrong handedness (the definition's positions inverted through the centre of mass)
/// is a mirror image, said as such (not as "a is singular").
#[test]
fn nh3_of_the_wrong_handedness_is_a_mirror_image() {
    let m = Nh3;
    let q = m.reference_geometry().unwrap();
    let state = PhaseState { q, p: SVector::zeros(), euler: Vector3::new(0.3, 1.1, -0.5), pe: Vector3::zeros() };
    let lab: LabState<4> = to_lab(&m, &state, &CentreOfMass::AT_REST).unwrap();
    assert!(from_lab(&m, &lab, &FitOptions::default()).is_ok());
    let inverted = LabState { positions: -lab.positions, velocities: lab.velocities };
    let err = from_lab(&m, &inverted, &FitOptions::default()).unwrap_err();
    assert!(matches!(err, FrameError::MirrorImage { .. }), "{err}");
    assert!(err.to_string().contains("mirror image"), "{err}");
}

/// Far from the origin (10⁵ Å and beyond) subtracting the centre of mass leaves rounding of ε·|x| ≈ 4e-11
/// bohr; the fit's step tolerance is relative, so it converges there.
#[test]
fn lab_fit_converges_far_from_the_origin() {
    let m = H2o;
    let q = m.reference_geometry().unwrap();
    let state = PhaseState { q, p: SVector::zeros(), euler: Vector3::new(0.3, 1.1, -0.5), pe: Vector3::zeros() };
    for x in [1.9e5, 1e6, 1e7] {
        let com = CentreOfMass { position: Vector3::new(x, -x, 0.7 * x), velocity: Vector3::zeros() };
        let lab: LabState<3> = to_lab(&m, &state, &com).unwrap();
        let (fit, _, report) = from_lab(&m, &lab, &FitOptions::default()).unwrap();
        assert!((fit.q - q).amax() < 1e-6, "{x}: {:?}", fit.q.as_slice());
        assert!(report.position_residual < 1e3 * f64::EPSILON * x, "{x}: {}", report.position_residual);
    }
}
