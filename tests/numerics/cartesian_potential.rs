//! Coordinates by kind at run time: the generated closed forms q(x), the Cartesian potential
//! U(x) and its gradient, for every shipped molecule that declares its coordinates by kind
//! (molecules with explicit positions only are skipped and named).
//!
//! Independent checks: q(x) of the lab positions `S R(q) + X` (generated positions, a random
//! rotation and translation) gives `q` back; `U(x) = U(q)`; `∂U/∂x` against Richardson central
//! differences of `U(x)`, against the chain rule through the tests' own dual-number `q(x)`
//! (tests/common/internal_coordinates.rs, written by hand), and the conservation laws it must
//! obey (no net force, no net torque: U is invariant under translation and rotation); and the
//! lab fit of such molecules needs no iteration.

use crate::common;

use common::internal_coordinates::{self as ic, jacobian};
use common::{Rng, for_each_molecule, random_q};
use rovib::runtime::frames::{FitOptions, LabState, from_lab};
use rovib::runtime::nalgebra::{Matrix3, Rotation3, SMatrix, SVector, Vector3};
use rovib::runtime::units::CoordinateUnit;
use rovib::runtime::{Molecule, MoleculeVisitor};

const POINTS: usize = 6;

fn random_rotation(rng: &mut Rng) -> Matrix3<f64> {
    let axis = Vector3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
    Rotation3::new(axis.normalize() * rng.uniform(0.0, 3.1)).into_inner()
}

/// Lab positions `S R(q) + X` for a random rotation and translation.
fn lab_positions<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    q: &SVector<f64, N>,
    rng: &mut Rng,
) -> SMatrix<f64, 3, NA> {
    let mut r = SMatrix::<f64, 3, NA>::zeros();
    m.positions(q, &mut r);
    let s = random_rotation(rng);
    let shift = Vector3::new(rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0));
    let mut x = s * r;
    for i in 0..NA {
        x.set_column(i, &(x.column(i) + shift));
    }
    x
}

/// The hand-written q(x) of the tests (tests/common/internal_coordinates.rs), if there is one.
type Hand = fn(&[ic::V3<ic::Dual>]) -> Vec<ic::Dual>;
fn hand_written(name: &str) -> Option<Hand> {
    Some(match name {
        "h2o" => ic::h2o,
        "co2" => ic::co2,
        "h2o2" => ic::h2o2,
        "nh3" => ic::nh3,
        "hcn" => ic::hcn,
        _ => return None,
    })
}

#[derive(Copy, Clone)]
struct ClosedForms;
impl MoleculeVisitor for ClosedForms {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let name = m.name();
        let mut probe = SVector::<f64, N>::zeros();
        if !m.internal_coordinates(&SMatrix::zeros(), &mut probe) {
            assert!(m.cartesian_potential(&SMatrix::zeros()).is_none(), "{name}");
            eprintln!("{name}: explicit positions only, no closed forms (skipped)");
            return;
        }
        let mut rng = Rng::new(31);
        // At the reference geometry itself, linear ones included (hcn, co2: α = π exactly, where
        // the Euler chart is singular but q(x) and U(x) are not): q comes back, U(x) = U(q).
        let reference = m.reference_geometry().expect("a reference geometry");
        let x = lab_positions(&m, &reference, &mut rng);
        let mut back = SVector::<f64, N>::zeros();
        assert!(m.internal_coordinates(&x, &mut back));
        for k in 0..N {
            let d = (back[k] - reference[k]).abs();
            assert!(d < 1e-11 * reference[k].abs().max(1.0), "{name}: at the reference q{k} = {} from x", back[k]);
        }
        let (u, uq) = (m.cartesian_potential(&x).expect("closed forms"), m.potential(&reference));
        assert!((u - uq).abs() <= 1e-12 * uq.abs().max(1e-3), "{name}: at the reference U(x) = {u}, U(q) = {uq}");
        for _ in 0..POINTS {
            let q = random_q(&m, &mut rng);
            let x = lab_positions(&m, &q, &mut rng);
            // q(x) gives q back (angles modulo 2π).
            let mut back = SVector::<f64, N>::zeros();
            assert!(m.internal_coordinates(&x, &mut back));
            for (k, c) in m.coordinates().iter().enumerate() {
                let mut d = back[k] - q[k];
                if matches!(c.unit, CoordinateUnit::Angle(_)) {
                    d -= (d / std::f64::consts::TAU).round() * std::f64::consts::TAU;
                }
                assert!(d.abs() < 1e-11 * q[k].abs().max(1.0), "{name}: q{k} = {} from x, {} given", back[k], q[k]);
            }
            // U(x) = U(q).
            let u = m.cartesian_potential(&x).expect("closed forms");
            let uq = m.potential(&q);
            assert!((u - uq).abs() <= 1e-12 * uq.abs().max(1e-3), "{name}: U(x) = {u}, U(q) = {uq}");
            // ∂U/∂x against Richardson differences of U(x).
            let mut grad = SMatrix::<f64, 3, NA>::zeros();
            let u2 = m.cartesian_potential_gradient(&x, &mut grad).expect("closed forms");
            assert_eq!(u2, u, "{name}: the gradient function returns U");
            let scale = grad.amax().max(1e-8);
            for i in 0..NA {
                for a in 0..3 {
                    let f = |h: f64| {
                        let mut y = x;
                        y[(a, i)] += h;
                        m.cartesian_potential(&y).unwrap()
                    };
                    let d = |h: f64| (f(h) - f(-h)) / (2.0 * h);
                    let h = 1e-3;
                    let fd = (4.0 * d(h / 2.0) - d(h)) / 3.0;
                    let err = (grad[(a, i)] - fd).abs() / scale;
                    assert!(err < 1e-8, "{name}: ∂U/∂x[{a},{i}] = {} vs {fd} (relative {err:e})", grad[(a, i)]);
                }
            }
            // No net force, no net torque about any point.
            let force: Vector3<f64> = (0..NA).map(|i| grad.column(i).into_owned()).sum();
            let torque: Vector3<f64> =
                (0..NA).map(|i| x.column(i).into_owned().cross(&grad.column(i).into_owned())).sum();
            let size = x.amax();
            assert!(force.amax() < 1e-12 * scale, "{name}: net force {force:?}");
            assert!(torque.amax() < 1e-11 * scale * size, "{name}: net torque {torque:?}");
            // The chain rule through the hand-written dual-number q(x).
            if let Some(h) = hand_written(name) {
                let atoms: Vec<[f64; 3]> = (0..NA).map(|i| [x[(0, i)], x[(1, i)], x[(2, i)]]).collect();
                let (qh, dq) = jacobian(&atoms, h);
                let mut du = SVector::<f64, N>::zeros();
                m.potential_gradient(&SVector::from_column_slice(&qh), &mut du);
                for i in 0..NA {
                    for a in 0..3 {
                        let want: f64 = (0..N).map(|k| du[k] * dq[k][i][a]).sum();
                        let err = (grad[(a, i)] - want).abs() / scale;
                        assert!(err < 1e-11, "{name}: ∂U/∂x[{a},{i}] = {} vs chain rule {want}", grad[(a, i)]);
                    }
                }
            }
            // The lab fit takes the closed form: no Gauss–Newton step.
            let lab = LabState { positions: x, velocities: SMatrix::zeros() };
            let (state, _, report) =
                from_lab(&m, &lab, &FitOptions::default()).unwrap_or_else(|e| panic!("{name}: lab fit failed: {e}"));
            assert_eq!(report.iterations, 0, "{name}");
            assert!(report.position_residual < 1e-12, "{name}: residual {}", report.position_residual);
            assert!((state.q - q).amax() < 1e-11 * q.amax(), "{name}: fitted {} vs {q}", state.q);
        }
    }
}

#[test]
fn closed_forms_and_the_cartesian_gradient_match_independent_evaluations() {
    for_each_molecule(ClosedForms);
}
