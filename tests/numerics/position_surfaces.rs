//! Surfaces over Cartesian positions (`runtime::position_surface`) and gradients by central
//! differences (`runtime::finite_differences`, a scene's `[potential] gradient`).
//!
//! A site–site Ar–N Lennard-Jones surface on the arn2 kinematics written over the atoms'
//! positions and composed with R(q) equals the same surface written in (R, θ) by hand (U and
//! ∂U/∂q to round-off, trajectories to 1e-12 bohr). The arn2 spline surface with ∂U/∂q by
//! central differences gives trajectories close to the analytic gradient's (the error is
//! measured and bounded); a library without a gradient function is refused unless the scene
//! asks for central differences, and then runs and says so.
//!
//! A shared library over positions (`tests/surfaces/co2ar_sites.c`, compiled here with gcc):
//! molecules/co2ar.toml's site–site surface and dipole over the atoms' positions, composed with
//! R(q), equals the definition's pointwise and gives its trajectories to 1e-12 bohr, directly
//! and from a scene; a surface that is not rotation-invariant, a wrong gradient and a wrong
//! atom count are refused with located errors.

use std::path::Path;
use std::process::Command;

use rovib::molecules::{Arn2, Co2ar};
use rovib::runtime::finite_differences::CentralDifferences;
use rovib::runtime::nalgebra::{SMatrix, SVector, Vector3};
use rovib::runtime::position_surface::{CartesianPotential, FromPositions, add_pair_terms, check_rotation_invariance};
use rovib::runtime::surface::{Dipole, Potential, WithPotential};
use rovib::runtime::{Kinematics, Molecule};
use rovib_ffi::{SharedLibrary, builtin};

use crate::surfaces::{assert_same_trajectory_as_the_definition, file_error, max_q_difference, run_scene, trajectory};

/// The N–N bond of molecules/arn2.toml, bohr.
const RNN: f64 = 2.0744;
const EPSILON: f64 = 2e-4;
const SIGMA: f64 = 6.0;

/// 4ε((σ/r)¹² − (σ/r)⁶) and its derivative.
fn lj(r: f64) -> (f64, f64) {
    let s6 = (SIGMA / r).powi(6);
    (4.0 * EPSILON * (s6 * s6 - s6), 4.0 * EPSILON * (-12.0 * s6 * s6 + 6.0 * s6) / r)
}

/// Ar–N1 + Ar–N2 over the positions (atoms N1, N2, Ar).
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

/// The same surface in (R, θ): d₁² = R² − R r cos θ + r²/4, d₂² = R² + R r cos θ + r²/4.
struct SiteSiteInternal;

impl Potential<2> for SiteSiteInternal {
    fn energy(&self, q: &SVector<f64, 2>) -> f64 {
        let mut g = SVector::zeros();
        self.energy_gradient(q, &mut g)
    }
    fn energy_gradient(&self, q: &SVector<f64, 2>, grad: &mut SVector<f64, 2>) -> f64 {
        let (r, theta) = (q[0], q[1]);
        let (s, c) = theta.sin_cos();
        let mut u = 0.0;
        grad.fill(0.0);
        for sign in [-1.0, 1.0] {
            let d = (r * r + sign * r * RNN * c + RNN * RNN / 4.0).sqrt();
            let (v, dv) = lj(d);
            u += v;
            grad[0] += dv * (r + sign * RNN / 2.0 * c) / d;
            grad[1] += dv * (-sign * r * RNN * s) / (2.0 * d);
        }
        u
    }
}

#[test]
fn a_surface_over_positions_is_the_same_surface_over_internal_coordinates() {
    let cartesian = FromPositions::<_, _, 3> { molecule: Arn2, surface: SiteSite };
    for r in [5.5, 6.9, 8.0, 11.0] {
        for theta in [0.0, 0.4, 1.3, std::f64::consts::FRAC_PI_2, 2.5, std::f64::consts::PI] {
            let q = SVector::from([r, theta]);
            let (mut g1, mut g2) = (SVector::zeros(), SVector::zeros());
            let (u1, u2) = (cartesian.energy_gradient(&q, &mut g1), SiteSiteInternal.energy_gradient(&q, &mut g2));
            // Round-off of the terms (4ε(σ/r)¹² ~ 1e-3 hartree), which cancel in U.
            assert!((u1 - u2).abs() <= 1e-15, "U at {q:?}: {u1:e} vs {u2:e}");
            assert_eq!(cartesian.energy(&q), u1);
            assert!((g1 - g2).norm() <= 1e-15, "∂U/∂q at {q:?}: {g1:?} vs {g2:?}");
            let mut x = SMatrix::zeros();
            Arn2.positions(&q, &mut x);
            assert_eq!(check_rotation_invariance(&SiteSite, &x, 1e-12), Ok(()));
        }
    }
    let a = trajectory(&WithPotential { molecule: Arn2, potential: cartesian });
    let b = trajectory(&WithPotential { molecule: Arn2, potential: SiteSiteInternal });
    let (first, last) = (&b[0], &b[40]);
    assert!((first[0] - last[0]).abs() > 0.05, "the trajectory moves: {first:?} {last:?}");
    let d = max_q_difference(&a, &b);
    eprintln!("max |Δq| Cartesian surface vs internal: {d:e}");
    assert!(d <= 1e-12, "{d:e}");
}

#[test]
fn central_differences_follow_the_analytic_trajectory_closely() {
    let analytic = trajectory(&WithPotential { molecule: Arn2, potential: builtin::arn2_spline() });
    let differences =
        trajectory(&WithPotential { molecule: Arn2, potential: CentralDifferences(builtin::arn2_spline()) });
    let d = max_q_difference(&differences, &analytic);
    eprintln!("max |Δq| central differences vs analytic gradient, 20 000 a.u. at tolerance 1e-12: {d:e}");
    // The gradient is good to ~1e-10 relative; the trajectory error stays far below 1e-6 bohr,
    // and is not round-off (it is the differences' error, not zero).
    assert!(d < 1e-6 && d > 0.0, "{d:e}");
}

const SCENE: &str = "molecule = \"arn2\"\n\
[units]\nangle = \"deg\"\n\
[initial]\nq = { R = 6.9, theta = 80 }\np = { R = 0, theta = 1.5 }\n\
[integrator]\nmethod = \"dop853\"\nrtol = 1e-12\natol = 1e-12\n\
[run]\nend = 2000\noutput_interval = 100\n";

#[test]
fn a_library_without_a_gradient_runs_on_central_differences_only_when_asked() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-position-surfaces-fd");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let status = Command::new("gcc")
        .args(["-O2", "-shared", "-fPIC", "-DARN2_NO_GRADIENT", "-I"])
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/ffi/include"))
        .arg("-o")
        .arg(dir.join("libarn2.so"))
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/ffi/surfaces/arn2_spline.c"))
        .arg("-lm")
        .status()
        .expect("this test needs gcc");
    assert!(status.success());
    let run = |potential: &str| {
        let path = dir.join("scene.toml");
        std::fs::write(&path, format!("{SCENE}[potential]\n{potential}\n")).unwrap();
        rovib::simulation::run(&path, Some(&dir.join("out")))
    };
    let line = SCENE.lines().count() + 2;
    let located = |r: Result<rovib::RunReport, rovib::Error>| match r {
        Err(rovib::Error::File(e)) => e,
        other => panic!("not a located error: {:?}", other.map(|_| ())),
    };
    let e = located(run("library = \"libarn2.so\""));
    assert!(e.line == line && e.message.contains("no `rovib_surface_gradient`"), "{e}");
    assert!(e.help.contains("central-differences"), "{e}");
    let e = located(run("library = \"libarn2.so\"\ngradient = \"finite\""));
    assert!(e.line == line + 1 && e.message.contains("finite"), "{e}");
    let e = located(run("gradient = \"central-differences\""));
    assert!(e.line == line && e.message.contains("library"), "{e}");
    let report = run("library = \"libarn2.so\"\ngradient = \"central-differences\"").unwrap();
    assert!(
        report.warnings.iter().any(|w| w.contains("central differences") && w.contains("5 energy calls")),
        "{:?}",
        report.warnings
    );
    let summary = std::fs::read_to_string(dir.join("out/summary.json")).unwrap();
    assert!(summary.contains("central differences"), "{summary}");
}

const SITES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/surfaces/co2ar_sites.c");

/// Compiles `co2ar_sites.c` with `defines` into `dir/libco2ar.so` with gcc (a fresh directory
/// per test: `dir` is emptied first).
fn sites_library(name: &str, defines: &[&str]) -> std::path::PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-position-library-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let status = Command::new("gcc")
        .args(["-O2", "-shared", "-fPIC", "-I"])
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/ffi/include"))
        .arg("-o")
        .arg(dir.join("libco2ar.so"))
        .arg(SITES)
        .args(defines)
        .arg("-lm")
        .status()
        .expect("this test needs gcc");
    assert!(status.success(), "gcc failed on {SITES}");
    dir
}

#[test]
fn a_library_over_positions_is_the_definitions_surface_and_gives_its_trajectory() {
    let dir = sites_library("pointwise", &[]);
    let library = SharedLibrary::load(&dir.join("libco2ar.so")).unwrap();
    assert_eq!((library.atoms(), library.coordinates(), library.has_dipole()), (Some(4), None, true));
    let surface = library.positions_surface::<4>().unwrap().on(Co2ar);
    assert!(!surface.central_differences());
    for r in [5.0, 6.6, 8.0, 11.0] {
        for theta in [0.0, 0.4, 1.3, std::f64::consts::FRAC_PI_2, 2.5, std::f64::consts::PI] {
            let q = SVector::from([r, theta]);
            let (mut g1, mut g2) = (SVector::zeros(), SVector::zeros());
            let (u1, u2) = (surface.energy_gradient(&q, &mut g1), Co2ar.potential_gradient(&q, &mut g2));
            assert!((u1 - u2).abs() <= 1e-14 * u2.abs().max(1e-6), "U at {q:?}: {u1:e} vs {u2:e}");
            assert!((g1 - g2).norm() <= 1e-13 * g2.norm().max(1e-6), "∂U/∂q at {q:?}: {g1:?} vs {g2:?}");
            let composed = WithPotential { molecule: Co2ar, potential: surface };
            let (mut m1, mut m2) = (Vector3::zeros(), Vector3::zeros());
            composed.dipole().unwrap().moment(&q, &mut m1);
            Co2ar.dipole().unwrap().moment(&q, &mut m2);
            assert!((m1 - m2).norm() <= 1e-13 * m2.norm().max(1e-9), "μ at {q:?}: {m1:?} vs {m2:?}");
            let (mut d1, mut d2) = (SMatrix::<f64, 3, 2>::zeros(), SMatrix::<f64, 3, 2>::zeros());
            composed.dipole().unwrap().moment_jacobian(&q, &mut d1);
            Co2ar.dipole().unwrap().moment_jacobian(&q, &mut d2);
            assert!((d1 - d2).norm() <= 1e-12 * d2.norm().max(1e-9), "∂μ/∂q at {q:?}: {d1:?} vs {d2:?}");
        }
    }
    let a = trajectory(&WithPotential { molecule: Co2ar, potential: surface });
    let b = trajectory(&Co2ar);
    let (first, last) = (&b[0], &b[40]);
    assert!((first[0] - last[0]).abs() > 0.05, "the trajectory moves: {first:?} {last:?}");
    let d = max_q_difference(&a, &b);
    eprintln!("max |Δq| library over positions vs definition (co2ar): {d:e}");
    assert!(d <= 1e-12, "{d:e}");
}

const CO2AR_SCENE: &str = "molecule = \"co2ar\"\n\
[units]\nangle = \"deg\"\n\
[initial]\nq = { R = 6.9, theta = 80 }\np = { R = 0, theta = 1.5 }\n\
[integrator]\nmethod = \"dop853\"\nrtol = 1e-12\natol = 1e-12\n\
[run]\nend = 2000\noutput_interval = 100\n";

#[test]
fn a_scene_runs_on_a_library_over_positions() {
    let dir = sites_library("scene", &[]);
    run_scene(&dir, CO2AR_SCENE, "library = \"libco2ar.so\"").unwrap();
    let rows = assert_same_trajectory_as_the_definition(&dir, &sites_library("scene-plain", &[]), CO2AR_SCENE);
    assert!(rows > 10, "{rows} rows");
}

#[test]
fn a_library_over_positions_is_checked_at_load() {
    let line = CO2AR_SCENE.lines().count() + 2;
    // An external field along z: U changes when the atoms are turned.
    let dir = sites_library("field", &["-DCO2AR_FIELD"]);
    let e = file_error(run_scene(&dir, CO2AR_SCENE, "library = \"libco2ar.so\""));
    assert!(e.line == line && e.message.contains("not invariant under a rotation"), "{e}");
    assert!(e.message.contains("libco2ar.so") && e.help.contains("turned"), "{e}");
    // A gradient off by one part in 10⁴ (the check's tolerance is 1e-5 relative).
    let dir = sites_library("gradient", &["-DCO2AR_GRADIENT_SCALE=1.0001"]);
    let e = file_error(run_scene(&dir, CO2AR_SCENE, "library = \"libco2ar.so\""));
    assert!(e.line == line && e.message.contains("disagrees with its energy"), "{e}");
    assert!(e.help.contains("rovib_surface_positions_gradient"), "{e}");
    // Four atoms for a molecule of three, and a surface over positions asked for over coordinates.
    let dir = sites_library("atoms", &[]);
    let arn2 = CO2AR_SCENE.replace("co2ar", "arn2");
    let e = file_error(run_scene(&dir, &arn2, "library = \"libco2ar.so\""));
    assert!(e.line == line && e.message.contains("positions of 4 atoms, but the molecule has 3"), "{e}");
    assert!(e.help.contains("N1, N2, Ar"), "{e}");
    let library = SharedLibrary::load(&dir.join("libco2ar.so")).unwrap();
    assert!(matches!(library.surface::<2>(), Err(rovib_ffi::SurfaceError::Form { .. })));
}
