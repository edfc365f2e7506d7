//! Lab-frame conversions on the hand-written test molecules: round trips in both directions, the
//! centre-of-mass split, angular momentum and kinetic energy in both frames, the least-squares
//! velocity projection, and every error.

mod common;

use common::{RigidTop, Rng, Water, random_euler, random_vector, random_water_q};
use rovib_runtime::frames::{
    CentreOfMass, FitOptions, FrameError, LabState, euler_angles, from_lab, lab_angular_momentum, to_lab,
};
use rovib_runtime::hamiltonian::{PhaseState, body_angular_momentum, hamiltonian, rotation_matrix};
use rovib_runtime::nalgebra::{Matrix3, SMatrix, Vector3};
use rovib_runtime::{Kinematics, Molecule};

const STATES: usize = 20;

fn random_water_state(rng: &mut Rng) -> PhaseState<3> {
    PhaseState {
        q: random_water_q(rng),
        p: random_vector(rng, 5.0),
        euler: random_euler(rng),
        pe: random_vector(rng, 10.0),
    }
}

fn random_com(rng: &mut Rng) -> CentreOfMass {
    CentreOfMass { position: random_vector(rng, 10.0), velocity: random_vector(rng, 1e-3) }
}

/// `a − b` with each angle difference wrapped into (−π, π].
fn wrapped(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    if d > std::f64::consts::PI { d - std::f64::consts::TAU } else { d }
}

/// max |a − b| / max(max |b|, floor).
fn rel<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>, b: &SMatrix<f64, R, C>, floor: f64) -> f64 {
    (a - b).amax() / b.amax().max(floor)
}

#[test]
fn internal_to_lab_to_internal_round_trip() {
    let mut rng = Rng::new(1);
    let (mut worst_q, mut worst_p, mut worst_angle, mut worst_pe) = (0f64, 0f64, 0f64, 0f64);
    let mut worst_com = 0f64;
    for _ in 0..STATES {
        let state = random_water_state(&mut rng);
        let com = random_com(&mut rng);
        let lab = to_lab(&Water, &state, &com).unwrap();
        let (back, com_back, report) = from_lab(&Water, &lab, &FitOptions::default()).unwrap();
        worst_q = worst_q.max(rel(&back.q, &state.q, 1.0));
        worst_p = worst_p.max(rel(&back.p, &state.p, 1.0));
        worst_pe = worst_pe.max(rel(&back.pe, &state.pe, 1.0));
        for a in 0..3 {
            worst_angle = worst_angle.max(wrapped(back.euler[a], state.euler[a]).abs());
        }
        worst_com = worst_com.max(rel(&com_back.position, &com.position, 1.0)).max(rel(
            &com_back.velocity,
            &com.velocity,
            1e-3,
        ));
        assert!(report.position_residual < 1e-13, "{report:?}");
        assert!(report.velocity_residual < 1e-12 && report.discarded_kinetic_energy < 1e-24, "{report:?}");
        assert!(report.iterations <= 10, "{report:?}");
    }
    eprintln!(
        "water-test internal → lab → internal: q {worst_q:.1e}, p {worst_p:.1e}, angles {worst_angle:.1e} rad, \
         p_e {worst_pe:.1e}, centre of mass {worst_com:.1e}"
    );
    for (what, err) in [("q", worst_q), ("p", worst_p), ("angles", worst_angle), ("p_e", worst_pe), ("com", worst_com)]
    {
        assert!(err < 1e-10, "{what}: {err:e}");
    }
}

/// Any triangle with any velocities is a water state (3 atoms: 3 rotations + 3 vibrations), so
/// random Cartesian states must come back exactly.
#[test]
fn lab_to_internal_to_lab_round_trip_for_arbitrary_triangles() {
    let mut rng = Rng::new(2);
    let (mut worst_x, mut worst_v) = (0f64, 0f64);
    for _ in 0..STATES {
        // A water-like triangle (not the parametrization's own output), randomly rotated.
        let q = random_water_q(&mut rng);
        let mut body = SMatrix::<f64, 3, 3>::zeros();
        Water.positions(&q, &mut body);
        let rotation = rotation_matrix(&random_euler(&mut rng));
        let lab = LabState {
            positions: rotation * body + SMatrix::from_fn(|_, _| rng.uniform(-0.2, 0.2)),
            velocities: SMatrix::from_fn(|_, _| rng.uniform(-2e-3, 2e-3)),
        };
        let (state, com, report) = from_lab(&Water, &lab, &FitOptions::default()).unwrap();
        assert!(report.position_residual < 1e-13 && report.velocity_residual < 1e-14, "{report:?}");
        let again = to_lab(&Water, &state, &com).unwrap();
        worst_x = worst_x.max(rel(&again.positions, &lab.positions, 1.0));
        worst_v = worst_v.max(rel(&again.velocities, &lab.velocities, 1e-3));
    }
    eprintln!("water-test lab → internal → lab: positions {worst_x:.1e}, velocities {worst_v:.1e}");
    assert!(worst_x < 1e-10 && worst_v < 1e-10, "positions {worst_x:e}, velocities {worst_v:e}");
}

#[test]
fn centre_of_mass_is_split_off_and_restored() {
    let mut rng = Rng::new(3);
    let masses = Water.masses();
    let state = random_water_state(&mut rng);
    let com = random_com(&mut rng);
    let lab = to_lab(&Water, &state, &com).unwrap();
    let measured = lab.centre_of_mass(&masses);
    assert!((measured.position - com.position).amax() < 1e-13);
    assert!((measured.velocity - com.velocity).amax() < 1e-17);
    // The translation carries ½ M V² and nothing else.
    let total_mass: f64 = masses.iter().sum();
    let split = lab.kinetic_energy(&masses) - lab.internal_kinetic_energy(&masses);
    assert!((split - 0.5 * total_mass * com.velocity.norm_squared()).abs() < 1e-15);
}

#[test]
fn angular_momentum_and_kinetic_energy_agree_between_frames() {
    let mut rng = Rng::new(4);
    let masses = Water.masses();
    for _ in 0..STATES {
        let state = random_water_state(&mut rng);
        let lab = to_lab(&Water, &state, &random_com(&mut rng)).unwrap();
        let j = body_angular_momentum(&state).unwrap();
        let l = lab.angular_momentum(&masses);
        assert!((l.norm() - j.norm()).abs() < 1e-11 * j.norm(), "|L| = {}, |J| = {}", l.norm(), j.norm());
        assert!(rel(&l, &(rotation_matrix(&state.euler) * j), 1.0) < 1e-11);
        assert!(rel(&lab_angular_momentum(&state).unwrap(), &l, 1.0) < 1e-11);
        let t = hamiltonian(&Water, &state).unwrap() - Water.potential(&state.q);
        let t_lab = lab.internal_kinetic_energy(&masses);
        assert!((t - t_lab).abs() < 1e-11 * t, "T = {t}, lab {t_lab}");
    }
}

#[test]
fn flat_layout_round_trips() {
    let mut rng = Rng::new(5);
    let lab = to_lab(&Water, &random_water_state(&mut rng), &random_com(&mut rng)).unwrap();
    let mut y = vec![0.0; LabState::<3>::DIM];
    lab.write_to(&mut y);
    assert_eq!(&y[3..6], lab.positions.column(1).as_slice());
    assert_eq!(&y[9..12], lab.velocities.column(0).as_slice());
    assert_eq!(LabState::<3>::read_from(&y), lab);
}

/// A rigid top keeps only the rotational part of arbitrary velocities: the mass-weighted
/// least-squares projection, whose discarded part carries the missing kinetic energy.
#[test]
fn rigid_top_projects_velocities_by_mass_weighted_least_squares() {
    let mut rng = Rng::new(6);
    let masses = RigidTop.masses();
    let mut body = SMatrix::<f64, 3, 3>::zeros();
    RigidTop.positions(&SMatrix::zeros(), &mut body);
    let rotation = rotation_matrix(&random_euler(&mut rng));
    let lab = LabState { positions: rotation * body, velocities: SMatrix::from_fn(|_, _| rng.uniform(-1e-3, 1e-3)) };
    let (state, com, report) = from_lab(&RigidTop, &lab, &FitOptions::default()).unwrap();
    assert!(report.position_residual < 1e-13);
    // J is the lab angular momentum about the centre of mass, in body components.
    let l = lab.angular_momentum(&masses);
    assert!(rel(&lab_angular_momentum(&state).unwrap(), &l, 1.0) < 1e-12);
    // Energy: total = translation + rotation + discarded.
    let back = to_lab(&RigidTop, &state, &com).unwrap();
    let total_mass: f64 = masses.iter().sum();
    let e_in = lab.kinetic_energy(&masses);
    let e_parts = 0.5 * total_mass * com.velocity.norm_squared()
        + back.internal_kinetic_energy(&masses)
        + report.discarded_kinetic_energy;
    assert!((e_in - e_parts).abs() < 1e-12 * e_in, "{e_in} vs {e_parts}");
    assert!(report.discarded_kinetic_energy > 1e-3 * e_in, "random velocities are not rigid: {report:?}");
    // The discarded part is orthogonal to every rigid motion: projecting the kept velocities
    // again changes nothing.
    let (again, _, report2) = from_lab(&RigidTop, &back, &FitOptions::default()).unwrap();
    assert!(rel(&again.pe, &state.pe, 1.0) < 1e-11 && report2.discarded_kinetic_energy < 1e-12 * e_in);
}

#[test]
fn distorted_rigid_geometry_is_not_representable() {
    let mut body = SMatrix::<f64, 3, 3>::zeros();
    RigidTop.positions(&SMatrix::zeros(), &mut body);
    let mut positions = rotation_matrix(&Vector3::new(0.3, 1.0, -0.5)) * body;
    positions[(0, 2)] += 0.05;
    let lab = LabState { positions, velocities: SMatrix::zeros() };
    match from_lab(&RigidTop, &lab, &FitOptions::default()) {
        Err(FrameError::NotRepresentable { residual, tolerance, worst_atom, .. }) => {
            assert!(residual > 1e-3 && tolerance == 1e-5, "{residual} {tolerance}");
            assert!(worst_atom < 3);
        }
        other => panic!("expected NotRepresentable, got {other:?}"),
    }
    // Accepting the least-squares fit is the caller's choice.
    let loose = FitOptions { residual_tolerance: f64::INFINITY, ..FitOptions::default() };
    let (_, _, report) = from_lab(&RigidTop, &lab, &loose).unwrap();
    assert!(report.position_residual > 1e-3);
}

#[test]
fn gimbal_lock_is_an_error_in_both_directions() {
    // The body frame itself (R = 1) has θ = 0.
    let q = SMatrix::<f64, 3, 1>::new(1.8, 1.9, 1.7);
    let mut body = SMatrix::<f64, 3, 3>::zeros();
    Water.positions(&q, &mut body);
    let lab = LabState { positions: body, velocities: SMatrix::zeros() };
    match from_lab(&Water, &lab, &FitOptions::default()) {
        Err(FrameError::EulerSingular { theta }) => assert!(theta.abs() < 1e-8, "θ = {theta}"),
        other => panic!("expected EulerSingular, got {other:?}"),
    }
    let err = FrameError::EulerSingular { theta: 0.0 }.to_string();
    assert!(err.contains("rotate the input"), "{err}");
    // Rotating it by 90° about x is the documented remedy.
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
    let turned = LabState { positions: rx * body, velocities: SMatrix::zeros() };
    let (state, _, _) = from_lab(&Water, &turned, &FitOptions::default()).unwrap();
    assert!((state.euler[1] - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert!(rel(&state.q, &q, 1.0) < 1e-12);

    let locked = PhaseState { q, p: Vector3::zeros(), euler: Vector3::new(0.2, 0.0, 0.1), pe: Vector3::zeros() };
    assert_eq!(to_lab(&Water, &locked, &CentreOfMass::AT_REST), Err(FrameError::EulerSingular { theta: 0.0 }));
}

#[test]
fn non_finite_input_is_an_error() {
    let mut rng = Rng::new(7);
    let lab = to_lab(&Water, &random_water_state(&mut rng), &CentreOfMass::AT_REST).unwrap();
    let mut bad = lab;
    bad.positions[(1, 2)] = f64::NAN;
    assert_eq!(
        from_lab(&Water, &bad, &FitOptions::default()),
        Err(FrameError::NonFinite { quantity: "lab positions" })
    );
    let mut bad = lab;
    bad.velocities[(0, 0)] = f64::INFINITY;
    assert_eq!(
        from_lab(&Water, &bad, &FitOptions::default()),
        Err(FrameError::NonFinite { quantity: "lab velocities" })
    );
    let mut state = random_water_state(&mut rng);
    state.p[1] = f64::NAN;
    assert!(matches!(to_lab(&Water, &state, &CentreOfMass::AT_REST), Err(FrameError::NonFinite { .. })));
    let com = CentreOfMass { position: Vector3::new(0.0, f64::NAN, 0.0), velocity: Vector3::zeros() };
    assert!(matches!(to_lab(&Water, &random_water_state(&mut rng), &com), Err(FrameError::NonFinite { .. })));
}

#[test]
fn fit_options_are_validated_and_used() {
    let mut rng = Rng::new(8);
    let state = random_water_state(&mut rng);
    let lab = to_lab(&Water, &state, &CentreOfMass::AT_REST).unwrap();
    let bad = FitOptions { residual_tolerance: f64::NAN, ..FitOptions::default() };
    assert!(matches!(from_lab(&Water, &lab, &bad), Err(FrameError::InvalidOptions { .. })));
    let bad = FitOptions { step_tolerance: 0.0, ..FitOptions::default() };
    assert!(matches!(from_lab(&Water, &lab, &bad), Err(FrameError::InvalidOptions { .. })));
    // Zero iterations allowed: the Kabsch start alone is not converged.
    let none = FitOptions { max_iterations: 0, ..FitOptions::default() };
    assert!(matches!(from_lab(&Water, &lab, &none), Err(FrameError::NotConverged { iterations: 0, .. })));
    // Starting at the answer converges at once.
    let exact = FitOptions { initial_q: Some(state.q), ..FitOptions::default() };
    let (_, _, report) = from_lab(&Water, &lab, &exact).unwrap();
    assert!(report.iterations <= 1, "{report:?}");
}

#[test]
fn collinear_atoms_give_a_singular_metric() {
    let q = SMatrix::<f64, 3, 1>::new(1.8, 1.8, std::f64::consts::PI);
    let mut body = SMatrix::<f64, 3, 3>::zeros();
    Water.positions(&q, &mut body);
    let rotation = rotation_matrix(&Vector3::new(0.1, 1.0, 0.2));
    let lab = LabState { positions: rotation * body, velocities: SMatrix::zeros() };
    let start = FitOptions { initial_q: Some(q), ..FitOptions::default() };
    assert!(matches!(from_lab(&Water, &lab, &start), Err(FrameError::SingularMetric { .. })));
}

#[test]
fn euler_angles_of_random_rotations() {
    let mut rng = Rng::new(9);
    for _ in 0..STATES {
        let euler = random_euler(&mut rng);
        let back = euler_angles(&rotation_matrix(&euler));
        assert!((back - euler).amax() < 1e-12, "{euler} → {back}");
    }
}
