//! The molecule contract in its parts: generated [`Kinematics`], a potential, an optional dipole.
//!
//! A potential written outside (here: two methods of [`Potential`], U and ∂U/∂q) composes with a
//! generated molecule's kinematics by [`WithPotential`] without any kinematic method written:
//! the composition's kinematics are the generated ones bit for bit, its dynamics conserve the
//! energy, and the generated potential taken out and put back gives the generated molecule's
//! trajectory exactly. A molecule without a dipole surface has no dipole to evaluate
//! (`Molecule::dipole` is `None`), and a scene that asks for its dipole is refused.

use crate::common;

use std::path::Path;

use common::ensemble::options;
use rovib::ensemble::run_ensemble;
use rovib::molecules::{Arn2, H2o, Hcn};
use rovib::parameters::WithParameters;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::integrate::{Dop853Options, Method, OdeSystem, solve};
use rovib::runtime::nalgebra::{SMatrix, SVector, Vector3};
use rovib::runtime::surface::{Dipole, GradientCheck, Potential, PotentialOf, WithPotential, check_gradient};
use rovib::runtime::{Kinematics, KineticMatrices, Molecule, PhaseState};
use rovib::scene::parse_scene;

use crate::surfaces::{max_q_difference, trajectory};

/// An isotropic Morse well in R for Ar–N₂ (hartree, bohr): U and ∂U/∂q, nothing else.
struct Morse;

const DEPTH: f64 = 4.0e-4;
const STIFFNESS: f64 = 0.9;
const R_MIN: f64 = 7.0;

impl Potential<2> for Morse {
    fn energy(&self, q: &SVector<f64, 2>) -> f64 {
        let x = (-STIFFNESS * (q[0] - R_MIN)).exp();
        DEPTH * (1.0 - x) * (1.0 - x)
    }
    fn energy_gradient(&self, q: &SVector<f64, 2>, grad: &mut SVector<f64, 2>) -> f64 {
        let x = (-STIFFNESS * (q[0] - R_MIN)).exp();
        grad[0] = 2.0 * DEPTH * STIFFNESS * x * (1.0 - x);
        grad[1] = 0.0;
        DEPTH * (1.0 - x) * (1.0 - x)
    }
}

/// Points inside Ar–N₂'s ranges.
fn points() -> Vec<SVector<f64, 2>> {
    (0..7).map(|i| SVector::from([6.0 + 0.4 * i as f64, 0.2 + 0.4 * i as f64])).collect()
}

/// Only a molecule passes.
fn as_molecule<M: Molecule<2, 3>>(m: M) -> M {
    m
}

#[test]
fn an_outside_potential_takes_the_generated_kinematics_unchanged() {
    let composed = as_molecule(WithPotential { molecule: Arn2, potential: Morse });
    assert_eq!((composed.name(), composed.source(), composed.atoms()), (Arn2.name(), Arn2.source(), Arn2.atoms()));
    assert_eq!(composed.coordinates(), Arn2.coordinates());
    assert_eq!(composed.reference_geometry(), Arn2.reference_geometry());
    let centre = Arn2.reference_geometry().unwrap();
    assert_eq!(check_gradient(&Morse, &composed.coordinates(), &centre, &GradientCheck::default()), Ok(()));
    for q in points() {
        let (mut r1, mut r2) = (SMatrix::<f64, 3, 3>::zeros(), SMatrix::<f64, 3, 3>::zeros());
        composed.positions(&q, &mut r1);
        Arn2.positions(&q, &mut r2);
        assert_eq!(r1, r2);
        let (mut d1, mut d2) = ([SMatrix::<f64, 3, 3>::zeros(); 2], [SMatrix::<f64, 3, 3>::zeros(); 2]);
        composed.positions_jacobian(&q, &mut d1);
        Arn2.positions_jacobian(&q, &mut d2);
        assert_eq!(d1, d2);
        let (mut k1, mut k2) = (KineticMatrices::default(), KineticMatrices::default());
        composed.kinetic(&q, &mut k1);
        Arn2.kinetic(&q, &mut k2);
        assert_eq!(k1, k2);
        let (omega, qdot) = (Vector3::new(1e-4, -2e-4, 3e-4), SVector::from([1e-3, -2e-3]));
        let (mut g1, mut g2) = (SVector::zeros(), SVector::zeros());
        let t1 = composed.kinetic_energy_gradient(&q, &omega, &qdot, &mut g1);
        let t2 = Arn2.kinetic_energy_gradient(&q, &omega, &qdot, &mut g2);
        assert_eq!((t1, g1), (t2, g2));
        // The potential is the outside one, the dipole the molecule's.
        let mut g = SVector::zeros();
        assert_eq!(composed.potential_gradient(&q, &mut g), Morse.energy(&q));
        assert_eq!(composed.potential(&q), Morse.energy(&q));
        let (mut mu1, mut mu2) = (Vector3::zeros(), Vector3::zeros());
        composed.dipole().expect("Ar–N₂'s dipole").moment(&q, &mut mu1);
        Arn2.moment(&q, &mut mu2);
        assert_eq!(mu1, mu2);
    }
    // Morse has no lane form, so ensembles of the composition run one trajectory at a time.
    assert!(Arn2.has_lane_forms() && !composed.has_lane_forms());
}

#[test]
fn a_composed_molecule_conserves_its_energy() {
    let m = WithPotential { molecule: Arn2, potential: Morse };
    let s = PhaseState {
        q: SVector::from([7.4, 80f64.to_radians()]),
        p: SVector::from([0.0, 1.5]),
        euler: Vector3::new(0.3, 1.2, -0.4),
        pe: Vector3::new(0.5, -1.0, 4.0),
    };
    let system = ReducedSystem::new(&m, Reduction::none(), &s);
    let mut y0 = vec![0.0; system.dim()];
    system.reduce(&s, &mut y0).unwrap();
    let h0 = system.energy(&y0).unwrap();
    let method = Method::Dop853(Dop853Options { rtol: 1e-12, atol: 1e-12, ..Dop853Options::default() });
    let mut worst: f64 = 0.0;
    let mut r_values = Vec::new();
    let mut observe = |_t: f64, y: &[f64]| {
        worst = worst.max((system.energy(y).unwrap() - h0).abs());
        r_values.push(y[0]);
        std::ops::ControlFlow::Continue(())
    };
    solve(&mut ReducedSystem::new(&m, Reduction::none(), &s), &method, 0.0, &y0, 20_000.0, 500.0, &mut observe)
        .unwrap();
    // H0 is ~1e-4 hartree; DOP853 at 1e-12 keeps it to ~1e-12 relative over 0.5 ps.
    assert!(worst <= 1e-9 * h0.abs(), "energy drift {worst:e} of {h0:e}");
    // The well is felt: R moves.
    let spread = r_values.iter().fold(0.0_f64, |a, &r| a.max((r - 7.4).abs()));
    assert!(spread > 0.05, "R stays within {spread} bohr of its start");
}

#[test]
fn the_generated_potential_as_a_part_gives_the_generated_trajectory() {
    // Out of the molecule with `PotentialOf`, back in with `WithPotential`: the same functions,
    // so the same numbers, bit for bit.
    let composed = WithPotential { molecule: Arn2, potential: PotentialOf::<_, 3>(Arn2) };
    assert_eq!(max_q_difference(&trajectory(&composed), &trajectory(&Arn2)), 0.0);
}

#[test]
fn a_molecule_without_a_dipole_surface_has_no_dipole() {
    // molecules/hcn.toml has no [dipole] table.
    assert!(Hcn.dipole().is_none() && !Hcn.has_dipole());
    let composed = WithPotential { molecule: Hcn, potential: PotentialOf::<_, 3>(Hcn) };
    assert!(composed.dipole().is_none() && !composed.has_dipole());
    let parametrised = WithParameters { molecule: Hcn, values: Vec::new() };
    assert!(parametrised.dipole().is_none() && !parametrised.has_dipole());
    // Water has one, and keeps it through both compositions.
    let q = H2o.reference_geometry().unwrap();
    let mut want = Vector3::zeros();
    H2o.moment(&q, &mut want);
    assert!(want.norm() > 0.1, "{want:?}");
    for got in [
        WithPotential { molecule: H2o, potential: PotentialOf::<_, 3>(H2o) }.dipole().map(|d| {
            let mut mu = Vector3::zeros();
            d.moment(&q, &mut mu);
            mu
        }),
        WithParameters { molecule: H2o, values: Vec::new() }.dipole().map(|d| {
            let mut mu = Vector3::zeros();
            d.moment(&q, &mut mu);
            mu
        }),
    ] {
        assert_eq!(got, Some(want));
    }
}

#[test]
fn a_spectrum_of_a_molecule_without_a_dipole_surface_is_refused() {
    let text = "molecule = \"hcn\"\n[ensemble]\ntrajectories = 2\nseed = 7\nmethod = \"thermal\"\n\
                temperature = 10.0\n[statistics]\ncorrelations = [\"mu_x\", \"mu_y\", \"mu_z\"]\n\
                [run]\nend = 100.0\noutput_interval = 10.0\n";
    let scene = parse_scene("ir.toml", text).unwrap();
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-contract-no-dipole");
    let _ = std::fs::remove_dir_all(&dir);
    let e = run_ensemble(&scene, &options(dir.clone(), 1)).expect_err("hcn has no dipole surface").to_string();
    assert!(e.contains("ir.toml:") && e.contains("mu_x"), "{e}");
    assert!(!dir.join("spectrum.csv").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
