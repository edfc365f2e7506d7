//! Surfaces from outside (`rovib-ffi`, `runtime::surface`): the spline × Legendre surface of
//! `ffi/surfaces/arn2_spline.c` compiled in at build time, the same source compiled here into a
//! shared library (`gcc -shared -fPIC`) and loaded at run time, and the same surface written in
//! the definition language (`molecules/arn2.toml`) give the same trajectories to 1e-12 bohr; a
//! scene's `[potential] library` is honoured, and a wrong gradient, a wrong coordinate count and
//! bad keys are refused with located errors.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::Command;

use rovib::Error;
use rovib::molecules::Arn2;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::integrate::{Dop853Options, Method, OdeSystem, solve};
use rovib::runtime::nalgebra::{SMatrix, SVector, Vector3};
use rovib::runtime::surface::{Dipole, Potential, PotentialOf, WithPotential};
use rovib::runtime::{Molecule, PhaseState};
use rovib_ffi::{SharedLibrary, SurfaceError, builtin};

const SOURCE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/ffi/surfaces/arn2_spline.c");
const INCLUDE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/ffi/include");

fn tmp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-surfaces-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Compiles `arn2_spline.c` with `defines` into `dir/libarn2.so` with gcc.
fn shared_library(dir: &Path, defines: &[&str]) -> PathBuf {
    let out = dir.join("libarn2.so");
    let status = Command::new("gcc")
        .args(["-O2", "-shared", "-fPIC", "-I", INCLUDE, "-o"])
        .arg(&out)
        .arg(SOURCE)
        .args(defines)
        .arg("-lm")
        .status()
        .expect("these tests need gcc");
    assert!(status.success(), "gcc failed");
    out
}

/// The state every trajectory starts from: off the minimum, turning (J = 4 ħ).
fn start() -> PhaseState<2> {
    PhaseState {
        q: SVector::from([6.9, 80f64.to_radians()]),
        p: SVector::from([0.0, 1.5]),
        euler: Vector3::new(0.3, 1.2, -0.4),
        pe: Vector3::new(0.5, -1.0, 4.0),
    }
}

/// The states at 40 output times over 20 000 a.u. (0.48 ps), DOP853 at tolerance 1e-12.
pub(crate) fn trajectory<M: Molecule<2, NA>, const NA: usize>(m: &M) -> Vec<Vec<f64>> {
    let s = start();
    let mut system = ReducedSystem::new(m, Reduction::none(), &s);
    let mut y0 = vec![0.0; system.dim()];
    system.reduce(&s, &mut y0).unwrap();
    let method = Method::Dop853(Dop853Options { rtol: 1e-12, atol: 1e-12, ..Dop853Options::default() });
    let mut states = Vec::new();
    let mut observe = |_t: f64, y: &[f64]| {
        states.push(y.to_vec());
        ControlFlow::Continue(())
    };
    solve(&mut system, &method, 0.0, &y0, 20_000.0, 500.0, &mut observe).unwrap();
    assert_eq!(states.len(), 41);
    states
}

/// The largest difference in R (bohr) and θ (rad) between two trajectories.
pub(crate) fn max_q_difference(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    a.iter().zip(b).flat_map(|(x, y)| (0..2).map(move |k| (x[k] - y[k]).abs())).fold(0.0, f64::max)
}

#[test]
fn the_c_surface_is_the_definitions_surface_pointwise() {
    let c = builtin::arn2_spline();
    let dsl = PotentialOf::<_, 3>(Arn2);
    // Every spline interval, the tail, both sides of each knot, and angles across [0, π].
    for r in [4.5, 5.0, 5.5, 6.0, 6.54, 6.999, 7.0, 7.5, 8.2, 9.7, 10.5, 11.9, 12.0, 14.0] {
        for theta in [0.0, 0.3, 1.0, std::f64::consts::FRAC_PI_2, 2.2, 3.0, std::f64::consts::PI] {
            let q = SVector::from([r, theta]);
            let (mut g1, mut g2) = (SVector::zeros(), SVector::zeros());
            let (u1, u2) = (c.energy_gradient(&q, &mut g1), dsl.energy_gradient(&q, &mut g2));
            assert!((u1 - u2).abs() <= 1e-13 * u2.abs().max(1e-6), "U at {q:?}: C {u1:e}, definition {u2:e}");
            assert!((u1 - c.energy(&q)).abs() == 0.0);
            for k in 0..2 {
                assert!((g1[k] - g2[k]).abs() <= 1e-12 * g2.norm().max(1e-6), "dU/dq{k} at {q:?}: {g1:?} {g2:?}");
            }
            let (mut m1, mut m2) = (Vector3::zeros(), Vector3::zeros());
            let composed = WithPotential { molecule: Arn2, potential: c };
            let dipole = composed.dipole().expect("the library's dipole");
            dipole.moment(&q, &mut m1);
            Arn2.moment(&q, &mut m2);
            assert!((m1 - m2).norm() <= 1e-13 * m2.norm().max(1e-12), "mu at {q:?}: {m1:?} {m2:?}");
            let (mut d1, mut d2) = (SMatrix::<f64, 3, 2>::zeros(), SMatrix::<f64, 3, 2>::zeros());
            dipole.moment_jacobian(&q, &mut d1);
            Arn2.moment_jacobian(&q, &mut d2);
            assert!((d1 - d2).norm() <= 1e-12 * d2.norm().max(1e-12), "dmu at {q:?}: {d1:?} {d2:?}");
        }
    }
}

#[test]
fn compiled_in_loaded_and_generated_surfaces_give_the_same_trajectory() {
    let dir = tmp("trajectory");
    let library = SharedLibrary::load(&shared_library(&dir, &[])).unwrap();
    assert_eq!((library.coordinates(), library.has_dipole()), (Some(2), true));
    let loaded = library.surface::<2>().unwrap();
    let generated = trajectory(&Arn2);
    let compiled_in = trajectory(&WithPotential { molecule: Arn2, potential: builtin::arn2_spline() });
    let from_library = trajectory(&WithPotential { molecule: Arn2, potential: loaded });
    // The trajectory goes somewhere: R and θ move by more than round-off.
    let (first, last) = (&generated[0], &generated[40]);
    assert!((first[0] - last[0]).abs() > 0.05 && (first[1] - last[1]).abs() > 0.05, "{first:?} {last:?}");
    let (a, b) = (max_q_difference(&compiled_in, &generated), max_q_difference(&from_library, &compiled_in));
    eprintln!("max |Δq|: compiled-in vs definition {a:e}, library vs compiled-in {b:e}");
    assert!(a <= 1e-12 && b <= 1e-12, "{a:e} {b:e}");
}

#[test]
fn a_library_takes_the_molecules_number_of_coordinates() {
    let dir = tmp("count");
    let library = SharedLibrary::load(&shared_library(&dir, &[])).unwrap();
    match library.surface::<3>() {
        Err(SurfaceError::Coordinates { found: 2, expected: 3, .. }) => {}
        other => panic!("{other:?}"),
    }
    match SharedLibrary::load(&dir.join("missing.so")) {
        Err(SurfaceError::Load { .. }) => {}
        other => panic!("{other:?}"),
    }
}

const SCENE: &str = "molecule = \"arn2\"\n\
[units]\nangle = \"deg\"\n\
[initial]\nq = { R = 6.9, theta = 80 }\np = { R = 0, theta = 1.5 }\n\
[integrator]\nmethod = \"dop853\"\nrtol = 1e-12\natol = 1e-12\n\
[run]\nend = 2000\noutput_interval = 100\n";

/// Writes `scene` (with a `[potential]` table `potential`) as dir/scene.toml and runs it.
pub(crate) fn run_scene(dir: &Path, scene: &str, potential: &str) -> Result<rovib::RunReport, Error> {
    let path = dir.join("scene.toml");
    std::fs::write(&path, format!("{scene}[potential]\n{potential}\n")).unwrap();
    rovib::simulation::run(&path, Some(&dir.join("out")))
}

/// Runs `scene` as written (the definition's own potential) in `plain`, and asserts that its
/// trajectory.csv has the rows of `dir/out/trajectory.csv` (a run of the same scene on an outside
/// surface) to the digits written: the same header, the same number of rows, each value within
/// 1e-9 relative (1e-9 absolute below 1). Returns the number of rows.
pub(crate) fn assert_same_trajectory_as_the_definition(dir: &Path, plain: &Path, scene: &str) -> usize {
    let with_library = std::fs::read_to_string(dir.join("out/trajectory.csv")).unwrap();
    let path = plain.join("scene.toml");
    std::fs::write(&path, scene).unwrap();
    rovib::simulation::run(&path, Some(&plain.join("out"))).unwrap();
    let generated = std::fs::read_to_string(plain.join("out/trajectory.csv")).unwrap();
    let rows = |s: &str| s.lines().map(|l| l.split(',').map(str::to_owned).collect::<Vec<_>>()).collect::<Vec<_>>();
    let (a, b) = (rows(&with_library), rows(&generated));
    assert_eq!(a.len(), b.len());
    assert_eq!(a[0], b[0]);
    for (x, y) in a.iter().zip(&b).skip(1) {
        for (u, v) in x.iter().zip(y) {
            let (u, v): (f64, f64) = (u.parse().unwrap(), v.parse().unwrap());
            assert!((u - v).abs() <= 1e-9 * v.abs().max(1.0), "{x:?}\n{y:?}");
        }
    }
    a.len()
}

/// The located error of a scene that must be refused.
pub(crate) fn file_error(r: Result<rovib::RunReport, Error>) -> rovib::runtime::diagnostic::FileError {
    match r {
        Err(Error::File(e)) => e,
        Err(e) => panic!("not located: {e}"),
        Ok(_) => panic!("accepted"),
    }
}

#[test]
fn a_scene_runs_on_a_library_named_relative_to_it() {
    let dir = tmp("scene");
    shared_library(&dir, &[]);
    run_scene(&dir, SCENE, "library = \"libarn2.so\"").unwrap();
    assert_same_trajectory_as_the_definition(&dir, &tmp("scene-plain"), SCENE);
}

#[test]
fn a_wrong_gradient_is_refused_before_the_first_trajectory() {
    let dir = tmp("wrong-gradient");
    shared_library(&dir, &["-DARN2_THETA_SIGN_BUG"]);
    let e = file_error(run_scene(&dir, SCENE, "library = \"libarn2.so\""));
    // The `library` line (the scene's last), the coordinate, and both values.
    assert_eq!(e.line, SCENE.lines().count() + 2, "{e}");
    assert!(e.message.contains("∂U/∂theta = ") && e.message.contains("central differences give"), "{e}");
    assert!(e.help.contains("theta"), "{e}");
    assert!(!dir.join("out/trajectory.csv").exists());
    // Both values: opposite signs of the same size.
    let numbers: Vec<f64> = e
        .message
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter_map(|w| w.parse::<f64>().ok())
        .filter(|x| x.abs() > 1e-8)
        .collect();
    assert!(numbers.len() >= 2 && (numbers[0] + numbers[1]).abs() < 1e-6 * numbers[0].abs(), "{e}");
}

#[test]
fn library_keys_are_refused_at_their_place() {
    let dir = tmp("keys");
    shared_library(&dir, &[]);
    let line = SCENE.lines().count() + 2;
    let e = file_error(run_scene(&dir, SCENE, "library = \"\""));
    assert!(e.line == line && e.message.contains("empty"), "{e}");
    let e = file_error(run_scene(&dir, SCENE, "library = \"nowhere.so\""));
    assert!(e.line == line && e.message.contains("cannot load") && e.message.contains("nowhere.so"), "{e}");
    let e = file_error(run_scene(&dir, SCENE, "libary = \"libarn2.so\""));
    assert!(e.line == line && e.message.contains("libary"), "{e}");
    let e = file_error(run_scene(&dir, SCENE, "library = \"libarn2.so\"\nparameters = { a = 1 }"));
    assert!(e.line == line + 1 && e.message.contains("replaces"), "{e}");
    // Another molecule's coordinates: water has three.
    let water = SCENE.replace("arn2", "h2o").replace("q = { R = 6.9, theta = 80 }\np = { R = 0, theta = 1.5 }\n", "");
    let e = file_error(run_scene(&dir, &water, "library = \"libarn2.so\""));
    assert!(e.message.contains("takes 2 coordinates, but the molecule has 3"), "{e}");
}

#[test]
fn an_ensemble_on_a_library_runs_one_trajectory_at_a_time_and_says_so() {
    let dir = tmp("ensemble");
    shared_library(&dir, &[]);
    let text = format!(
        "molecule = \"arn2\"\n[ensemble]\ntrajectories = 8\nseed = 4\nmethod = \"thermal\"\ntemperature = 10\nregion = {{ energy_cap = 0.0002 }}\n\
         [statistics]\nmeans = [\"R\"]\n[run]\nend = 400\noutput_interval = 100\n[potential]\nlibrary = \"{}\"\n",
        dir.join("libarn2.so").display()
    );
    let scene = rovib::scene::parse_scene("ensemble.toml", &text).unwrap();
    let mut options = rovib::ensemble::EnsembleOptions::new(dir.join("out"));
    options.threads = Some(2);
    let with_library = rovib::ensemble::run_ensemble(&scene, &options).unwrap();
    assert_eq!(with_library.outcome.completed, 8);
    assert!(with_library.lanes_note.as_deref().is_some_and(|n| n.contains("one trajectory at a time")));
    let summary = std::fs::read_to_string(dir.join("out/summary.json")).unwrap();
    assert!(summary.contains("\"lanes_note\": \"arn2 has no lane form"), "{summary}");
    // The same ensemble on the definition's potential (on lanes): the same means to round-off.
    let plain = rovib::scene::parse_scene("ensemble.toml", text.split("[potential]").next().unwrap()).unwrap();
    let generated = rovib::ensemble::run_ensemble(&plain, &{
        let mut o = rovib::ensemble::EnsembleOptions::new(dir.join("out-plain"));
        o.threads = Some(2);
        o
    })
    .unwrap();
    for k in 0..5 {
        let (a, b) = (with_library.mean("R", k).unwrap().0, generated.mean("R", k).unwrap().0);
        assert!((a - b).abs() < 1e-9, "mean R at output {k}: {a} vs {b}");
    }
}

/// Compiles the C `source` (with rovib_surface.h included first) into `dir/libbad.so`.
fn library_from(dir: &Path, source: &str) {
    let file = dir.join("bad.c");
    std::fs::write(&file, format!("#include \"rovib_surface.h\"\n{source}\n")).unwrap();
    let status = Command::new("gcc")
        .args(["-O2", "-shared", "-fPIC", "-I", INCLUDE, "-o"])
        .arg(dir.join("libbad.so"))
        .arg(&file)
        .status()
        .expect("these tests need gcc");
    assert!(status.success(), "gcc failed on {source}");
}

#[test]
fn every_load_failure_is_located_at_the_library_line_and_says_what_to_change() {
    const ABI: &str = "int rovib_surface_abi(void) { return ROVIB_SURFACE_ABI; }\n";
    const COUNT: &str = "int rovib_surface_coordinates(void) { return 2; }\n";
    const ENERGY: &str = "double rovib_surface_energy(const double *q) { return q[0]; }\n\
                          double rovib_surface_gradient(const double *q, double *g) { g[0] = 1; g[1] = 0; return q[0]; }\n";
    const POSITIONS: &str = "int rovib_surface_atoms(void) { return 3; }\n\
                             double rovib_surface_positions_energy(const double *x) { return 0; }\n";
    let line = SCENE.lines().count() + 2;
    // (library source, what the message must say, what the help must say)
    let cases: [(String, &str, &str); 9] = [
        (
            format!("{COUNT}{ENERGY}"),
            "no function `rovib_surface_abi`",
            "int rovib_surface_abi(void) { return ROVIB_SURFACE_ABI; }",
        ),
        (
            format!("int rovib_surface_abi(void) {{ return 7; }}\n{COUNT}{ENERGY}"),
            "built for surface ABI 7; this rovib reads ABI 1",
            "ROVIB_SURFACE_ABI (1)",
        ),
        (format!("{ABI}{ENERGY}"), "no function `rovib_surface_coordinates`", "int rovib_surface_coordinates(void)"),
        (
            format!("{ABI}int rovib_surface_coordinates(void) {{ return -2; }}\n{ENERGY}"),
            "rovib_surface_coordinates() returned -2",
            "return the number",
        ),
        (
            format!("{ABI}{COUNT}"),
            "has neither `rovib_surface_energy`",
            "double rovib_surface_positions_energy(const double *x)",
        ),
        (
            format!("{ABI}{COUNT}{ENERGY}{POSITIONS}"),
            "has both `rovib_surface_energy` and `rovib_surface_positions_energy`",
            "keep one",
        ),
        (
            format!("{ABI}{ENERGY}{POSITIONS}").replace("rovib_surface_energy", "e"),
            "has `rovib_surface_gradient`, which does not go with its energy `rovib_surface_positions_energy`",
            "remove `rovib_surface_gradient`",
        ),
        (
            format!("{ABI}{COUNT}{ENERGY}int rovib_surface_init(void) {{ return 3; }}\n"),
            "did not start: rovib_surface_init() returned 3",
            "what its init code means",
        ),
        (
            format!("{ABI}{COUNT}{ENERGY}void rovib_surface_dipole(const double *q, double *mu) {{}}\n"),
            "has `rovib_surface_dipole` but not `rovib_surface_dipole_jacobian`",
            "void rovib_surface_dipole_jacobian(const double *q, double *dmu)",
        ),
    ];
    for (k, (source, message, help)) in cases.iter().enumerate() {
        let dir = tmp(&format!("load-failure-{k}"));
        library_from(&dir, source);
        let e = file_error(run_scene(&dir, SCENE, "library = \"libbad.so\""));
        assert_eq!(e.line, line, "{e}");
        assert!(e.path.ends_with("scene.toml"), "{e}");
        assert!(e.message.contains(message) && e.message.contains("libbad.so"), "case {k}: {e}");
        assert!(e.help.contains(help), "case {k}: {e}");
        assert!(!dir.join("out/trajectory.csv").exists());
    }
}
