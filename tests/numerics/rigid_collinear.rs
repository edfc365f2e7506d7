//! Trajectories of a rigid atom + linear-molecule complex through its collinear geometries.
//!
//! molecules/hclar.toml (a MODEL rigid HCl-like rotor and Ar, coordinates R and θ) has its
//! minimum at the linear geometry θ = 0, where the whole complex is linear: the body frame is
//! undefined there and the kinetic metric singular (its moment about the rotor axis goes as
//! sin²θ). A rigid complex has fewer than 3N − 6 coordinates, so it has no Cartesian chart to
//! switch to; the body-frame chart runs until a relative pivot of the metric falls below the
//! run's `min_metric_pivot` (1e-12 by default, θ ≈ 1e-6 rad).
//!
//! Bound states near the linear minimum (thermal, thermal with J = 0 and thermal with the body
//! angular momentum about the rotor axis zero) are run the way a single scene or an ensemble
//! member runs (`ReducedSystem` with the scene's default pivot threshold, DOP853) and compared,
//! in lab positions, with an independent propagation of the same rigid rotor and atom in the lab
//! frame (tests/common/rigid_rotor.rs: no coordinates, body frame or metric; the site–site
//! potential written again by hand), started from the same lab state.

use crate::common;

use common::rigid_rotor::{AtomRotor, Site};
use rovib::molecules::Hclar;
use rovib::runtime::Kinematics;
use rovib::runtime::frames::{CentreOfMass, lab_of_body_any, to_lab_body};
use rovib::runtime::hamiltonian::fast::{BodyState, ReducedSystem, Reduction};
use rovib::runtime::integrate::{Dop853, Dop853Options, OdeSystem};
use rovib::runtime::nalgebra::{SMatrix, Vector3};
use rovib::runtime::sample::{Region, Sampler, Thermal};
use std::ops::ControlFlow;

/// Hartree per cm⁻¹.
const CM: f64 = 1.0 / 219_474.631_363_2;
const T_END: f64 = 20_000.0;
const INTERVAL: f64 = 100.0;
/// The scene-like tolerances of the rovib runs.
const RTOL: f64 = 1e-10;
const ATOL: f64 = 1e-12;
/// The reference's.
const REF_RTOL: f64 = 1e-13;
const REF_ATOL: f64 = 1e-15;

/// The model of molecules/hclar.toml written again: Ar (atom 2) and the rotor H (0) – Cl (1),
/// bond 2.409 bohr, sites on the atoms.
fn model() -> AtomRotor<3> {
    let mut m = AtomRotor {
        masses: Hclar.masses(),
        atom: 2,
        rotor: [0, 1],
        bond: 2.409,
        sites: [Site { offset: 0.0, eps: 120.0 * CM, sigma: 4.6 }, Site { offset: 0.0, eps: 50.0 * CM, sigma: 7.3 }],
    };
    let [h, cl] = m.atom_offsets();
    m.sites[0].offset = h;
    m.sites[1].offset = cl;
    m
}

#[derive(Debug, Default)]
struct Case {
    failure: Option<String>,
    max_dx: f64,
    outputs: usize,
    rhs: u64,
    min_angle: f64,
    ref_energy: f64,
    ref_l: f64,
    ref_constraint: f64,
}

/// Runs `body` in rovib and in `reference` and compares the lab positions at every output time.
fn run_against(body: &BodyState<2>, reference: AtomRotor<3>) -> Case {
    let lab0 = to_lab_body(&Hclar, body, &CentreOfMass::default()).expect("lab state");
    let y0 = reference.state_of_lab(&lab0);
    let options = Dop853Options { rtol: REF_RTOL, atol: REF_ATOL, ..Dop853Options::default() };
    let mut ref_rows = Vec::new();
    let mut case = Case { min_angle: f64::INFINITY, ..Case::default() };
    let (e0, l0) = (reference.energy(&y0), reference.angular_momentum(&y0));
    let mut propagated = reference.clone();
    Dop853::new(12, options)
        .unwrap()
        .integrate(&mut propagated, 0.0, &y0, T_END, INTERVAL, &mut |_t: f64, y: &[f64]| {
            case.ref_energy = case.ref_energy.max((reference.energy(y) - e0).abs());
            case.ref_l = case.ref_l.max((reference.angular_momentum(y) - l0).amax());
            let (lu, norm) = reference.constraint_residuals(y);
            case.ref_constraint = case.ref_constraint.max(lu.abs()).max(norm.abs());
            case.min_angle = case.min_angle.min(reference.angle_from_collinear(y));
            ref_rows.push(reference.positions(y));
            ControlFlow::Continue(())
        })
        .unwrap();

    // rovib: the body-frame chart, as a scene runs it (default pivot threshold).
    let system = ReducedSystem::from_body(&Hclar, Reduction::none(), body);
    let mut y = vec![0.0; system.dim()];
    system.reduce_body(body, &mut y).unwrap();
    let mut rows: Vec<SMatrix<f64, 3, 3>> = Vec::new();
    let mut failure = None;
    let mut integrated = system;
    let options = Dop853Options { rtol: RTOL, atol: ATOL, ..Dop853Options::default() };
    let result = Dop853::new(system.dim(), options).unwrap().integrate(
        &mut integrated,
        0.0,
        &y,
        T_END,
        INTERVAL,
        &mut |t: f64, y: &[f64]| match system
            .expand_body_and_energy(y)
            .map_err(|e| e.to_string())
            .and_then(|(b, _)| lab_of_body_any(&Hclar, &b, &CentreOfMass::default()).map_err(|e| e.to_string()))
        {
            Ok(lab) => {
                rows.push(lab.positions);
                ControlFlow::Continue(())
            }
            Err(e) => {
                failure = Some(format!("output at t = {t}: {e}"));
                ControlFlow::Break(())
            }
        },
    );
    match result {
        Ok(stats) => case.rhs = stats.rhs_evals,
        Err(e) => {
            let source = std::error::Error::source(&e).map_or(String::new(), |s| format!(": {s}"));
            failure = failure.or(Some(format!("{e}{source}")));
        }
    }
    case.failure = failure;
    case.outputs = rows.len();
    for (x, r) in rows.iter().zip(&ref_rows) {
        case.max_dx = case.max_dx.max((x - r).amax());
    }
    case
}

/// Bound thermal states near the linear minimum (20 K, θ ≤ 0.6 rad, U at most 60 cm⁻¹ above
/// the reference geometry's), draw `i` of `seed`.
fn thermal(seed: u64, count: u64) -> Vec<BodyState<2>> {
    let region = Region { energy_cap: Some(60.0 * CM), limits: [Some((6.9, 8.8)), Some((0.0, 0.6))] };
    let sampler = Thermal::new(&Hclar, 20.0, &region, seed).unwrap();
    (0..count).map(|i| sampler.draw(i).unwrap()).collect()
}

fn measure(label: &str, states: &[BodyState<2>]) -> Vec<Case> {
    let cases: Vec<Case> = states.iter().map(|s| run_against(s, model())).collect();
    for (i, c) in cases.iter().enumerate() {
        eprintln!(
            "{label} {i}: J = {:.2?}, closest to collinear {:.1e} rad, max |Δx| = {:.2e} bohr over {} outputs, {} rhs; \
             reference |ΔE| {:.1e} Eh, |ΔJ| {:.1e} ħ, constraints {:.1e}; {}",
            states[i].j.as_slice(),
            c.min_angle,
            c.max_dx,
            c.outputs,
            c.rhs,
            c.ref_energy,
            c.ref_l,
            c.ref_constraint,
            c.failure.as_deref().unwrap_or("completed")
        );
    }
    cases
}

fn check(cases: &[Case]) {
    for c in cases {
        assert!(c.ref_energy < 1e-10 && c.ref_l < 1e-10 && c.ref_constraint < 1e-10, "the reference drifts: {c:?}");
        assert!(c.failure.is_none(), "{c:?}");
        assert!(c.max_dx < 1e-8, "rovib is {:e} bohr from the lab-frame reference: {c:?}", c.max_dx);
    }
}

#[test]
fn thermal_states_near_the_linear_minimum_agree_with_the_lab_frame_rotor() {
    let states = thermal(28, 6);
    check(&measure("thermal", &states));
}

/// With J = 0 the motion is planar and θ passes through 0 itself. The body-frame chart runs
/// through unless an integrator stage lands so close to θ = 0 that a relative pivot of the
/// metric falls below 1e-12 (θ ≲ 1e-6 rad): then the run stops with an error naming the
/// ill-conditioned or singular block, q and t (one of these six, at t = 9477 ħ/E_h), never
/// with a wrong number. Up to the stop, and for the runs that complete, the positions agree with
/// the reference.
#[test]
fn states_with_zero_angular_momentum_pass_through_collinear_or_stop_loudly() {
    let states: Vec<BodyState<2>> =
        thermal(29, 6).into_iter().map(|s| BodyState { j: Vector3::zeros(), ..s }).collect();
    let cases = measure("J = 0", &states);
    for c in &cases {
        assert!(c.ref_energy < 1e-10 && c.ref_l < 1e-10 && c.ref_constraint < 1e-10, "the reference drifts: {c:?}");
        assert!(c.max_dx < 1e-8, "rovib is {:e} bohr from the lab-frame reference: {c:?}", c.max_dx);
        if let Some(f) = &c.failure {
            assert!(f.contains("ill-conditioned") || f.contains("singular"), "{f}");
        }
    }
    let completed = cases.iter().filter(|c| c.failure.is_none()).count();
    assert!(completed >= 4, "{completed} of 6 completed");
}

/// The comparison can fail: with the reference's Ar–H σ larger by 1e-6 (relative), the same
/// thermal state is more than 1e-8 bohr from rovib's run.
#[test]
fn a_reference_perturbed_by_1e_6_is_told_apart() {
    let mut perturbed = model();
    perturbed.sites[0].sigma *= 1.0 + 1e-6;
    let state = thermal(28, 1)[0];
    let c = run_against(&state, perturbed);
    eprintln!("perturbed reference: max |Δx| = {:.2e} bohr", c.max_dx);
    assert!(c.failure.is_none() && c.max_dx > 1e-8, "{c:?}");
}

#[test]
fn states_with_no_angular_momentum_about_the_axis_agree_with_the_lab_frame_rotor() {
    let states: Vec<BodyState<2>> =
        thermal(30, 6).into_iter().map(|s| BodyState { j: Vector3::new(s.j.x, s.j.y, 0.0), ..s }).collect();
    check(&measure("J_z = 0", &states));
}
