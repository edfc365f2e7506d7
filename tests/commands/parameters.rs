//! Potential parameters at run time (`[potential.parameters]` in a scene): the run-time path
//! against water's potential written out by hand, against finite differences, and through
//! `rovib run`.

use std::process::Command;

use rovib::molecules::H2o;
use rovib::parameters::WithParameters;
use rovib::runtime::Molecule;
use rovib::runtime::nalgebra::SVector;
use rovib::runtime::units::{BOHR_IN_ANGSTROM, HARTREE_IN_WAVENUMBERS};

/// molecules/h2o.toml's potential, transcribed: q in bohr and rad, the parameters by name.
fn water(q: &SVector<f64, 3>, p: &dyn Fn(&str) -> f64) -> f64 {
    let (r1, r2, alpha) = (q[0] * BOHR_IN_ANGSTROM, q[1] * BOHR_IN_ANGSTROM, q[2]);
    let (de, a, re, ae) = (p("De"), p("a"), p("re"), p("alpha_e"));
    let morse = |r: f64| de * (1.0 - (-a * (r - re)).exp()).powi(2);
    let cm = morse(r1)
        + morse(r2)
        + 0.5 * p("faa") * (alpha - ae).powi(2)
        + p("frr2") * (r1 - re) * (r2 - re)
        + p("fra") * (r1 - re + r2 - re) * (alpha - ae);
    cm / HARTREE_IN_WAVENUMBERS
}

fn with(overrides: &[(&str, f64)]) -> (WithParameters<H2o>, impl Fn(&str) -> f64) {
    let names = H2o.parameters();
    let values: Vec<f64> =
        names.iter().map(|(n, v)| overrides.iter().find(|(o, _)| o == n).map_or(*v, |(_, x)| *x)).collect();
    let lookup = values.clone();
    let get = move |name: &str| lookup[names.iter().position(|(n, _)| *n == name).unwrap()];
    (WithParameters { molecule: H2o, values }, get)
}

const GEOMETRIES: [[f64; 3]; 3] = [[1.9, 1.75, 1.7], [1.6, 2.3, 2.1], [2.8, 1.81, 1.3]];

#[test]
fn overridden_parameters_give_the_hand_written_potential() {
    assert_eq!(H2o.parameters().len(), 7);
    let (m, p) = with(&[("De", 50_000.0), ("a", 2.0), ("fra", -3000.0)]);
    let (compiled, p0) = with(&[]);
    for q in GEOMETRIES.map(SVector::from) {
        let expected = water(&q, &p);
        assert!((m.potential(&q) - expected).abs() <= 1e-14 * expected.abs(), "{} vs {expected}", m.potential(&q));
        // The compiled-in values through the run-time path equal the compiled constants.
        let u0 = H2o.potential(&q);
        assert!((compiled.potential(&q) - u0).abs() <= 1e-14 * u0.abs());
        assert!((u0 - water(&q, &p0)).abs() <= 1e-14 * u0.abs());
        assert!((m.potential(&q) - u0).abs() > 1e-3 * u0.abs(), "the override changes U");
    }
}

#[test]
fn the_run_time_gradient_is_the_derivative_of_the_run_time_potential() {
    let (m, _) = with(&[("De", 50_000.0), ("re", 1.0)]);
    for q in GEOMETRIES.map(SVector::from) {
        let mut g = SVector::<f64, 3>::zeros();
        let u = m.potential_gradient(&q, &mut g);
        assert_eq!(u, m.potential(&q));
        for k in 0..3 {
            let h = 1e-6;
            let (mut a, mut b) = (q, q);
            a[k] += h;
            b[k] -= h;
            let fd = (m.potential(&a) - m.potential(&b)) / (2.0 * h);
            assert!((g[k] - fd).abs() <= 1e-7 * g[k].abs().max(1e-3), "k = {k}: {} vs {fd}", g[k]);
        }
    }
}

#[test]
fn a_scene_overrides_parameters_and_names_an_unknown_one() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-parameters");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let text = "molecule = \"h2o\"\n[initial]\nq = { r1 = 1.2, r2 = 0.9, alpha = 1.7 }\n\
                [potential.parameters]\nDe = 50000.0\nfra = -3000.0\n[run]\nend = 50.0\noutput_interval = 5.0\n";
    let path = dir.join("s.toml");
    std::fs::write(&path, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", path.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).unwrap()).unwrap();
    // At rest H(0) = U(q0) with the overridden parameters (q in Å: h2o declares Å).
    let q0 = SVector::from([1.2 / BOHR_IN_ANGSTROM, 0.9 / BOHR_IN_ANGSTROM, 1.7]);
    let (_, p) = with(&[("De", 50_000.0), ("fra", -3000.0)]);
    let h0 = summary["conservation"]["initial_energy_hartree"].as_f64().unwrap();
    assert!((h0 - water(&q0, &p)).abs() <= 1e-13 * h0.abs(), "{h0} vs {}", water(&q0, &p));
    assert!(summary["conservation"]["max_relative_energy_error"].as_f64().unwrap() < 1e-8);
    assert_eq!(summary["potential_parameters"]["De"], 50000.0);

    std::fs::write(&path, text.replace("De = 50000.0", "DE = 50000.0")).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", path.to_str().unwrap(), "--out", dir.join("bad").to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(!out.status.success());
    assert!(err.contains("h2o has no potential parameter `DE`") && err.contains("did you mean `De`?"), "{err}");
    assert!(err.contains("s.toml:5:"), "located: {err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The Cartesian chart with overridden parameters (`WithParameters::cartesian_potential`, the
/// generated `cartesian_potential_with`): U(x) equals the hand-written potential at the
/// distances and angle of x, computed here; ∂U/∂x equals central differences of U(x); and the
/// override changes U(x).
#[test]
fn the_cartesian_potential_runs_with_the_overridden_parameters() {
    use rovib::runtime::nalgebra::{SMatrix, Vector3};
    let (m, p) = with(&[("De", 50_000.0), ("re", 1.0), ("fra", -3000.0)]);
    let positions = [
        SMatrix::<f64, 3, 3>::from_column_slice(&[0.1, -0.2, 0.05, 1.7, 0.3, -0.4, -0.6, 1.6, 0.2]),
        SMatrix::<f64, 3, 3>::from_column_slice(&[0.0, 0.0, 0.0, 0.0, 0.0, 1.9, 1.2, 0.1, -1.3]),
    ];
    for x in positions {
        let (o, h1, h2): (Vector3<f64>, Vector3<f64>, Vector3<f64>) =
            (x.column(0).into(), x.column(1).into(), x.column(2).into());
        let q = SVector::<f64, 3>::new((h1 - o).norm(), (h2 - o).norm(), (h1 - o).angle(&(h2 - o)));
        let expected = water(&q, &p);
        let u = m.cartesian_potential(&x).expect("water has coordinates by kind");
        assert!((u - expected).abs() <= 1e-13 * expected.abs(), "U(x) = {u}, hand-written {expected}");
        assert!((u - H2o.cartesian_potential(&x).unwrap()).abs() > 1e-3 * u.abs(), "the override changes U(x)");
        let mut g = SMatrix::<f64, 3, 3>::zeros();
        let u2 = m.cartesian_potential_gradient(&x, &mut g).unwrap();
        assert_eq!(u, u2);
        for i in 0..3 {
            for a in 0..3 {
                let h = 1e-5;
                let (mut plus, mut minus) = (x, x);
                plus[(a, i)] += h;
                minus[(a, i)] -= h;
                let fd = (m.cartesian_potential(&plus).unwrap() - m.cartesian_potential(&minus).unwrap()) / (2.0 * h);
                assert!((g[(a, i)] - fd).abs() <= 1e-7 * (1.0 + fd.abs()), "∂U/∂x[{a},{i}] = {}, fd {fd}", g[(a, i)]);
            }
        }
    }
}

fn ensemble_dir(name: &str) -> std::path::PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-parameters-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A thermal water ensemble at 100 K whose potential moves its minimum (`re`, `alpha_e`): the
/// ensemble means of r1 and α sit at the moved minimum (closed form: the minimum of the
/// Morse-plus-quadratic potential is at r = re, α = alpha_e, and at 100 K the thermal
/// displacement of the mean is below 0.003 Å and 0.01 rad), at t = 0 (the sampler) and at every
/// later output time (the trajectories), not at the compiled-in minimum 0.958 Å, 1.824 rad.
#[test]
fn an_ensemble_runs_with_the_scene_parameters() {
    use rovib::ensemble::{EnsembleOptions, run_ensemble};
    let dir = ensemble_dir("ensemble");
    let (re, alpha_e) = (1.05, 1.65);
    let text = format!(
        "molecule = \"h2o\"\n[ensemble]\ntrajectories = 192\nseed = 4\nmethod = \"thermal\"\ntemperature = 100\n\
         region = {{ energy_cap = 0.05 }}\nthreads = 2\n[statistics]\nmeans = [\"r1\", \"alpha\"]\n\
         [potential.parameters]\nre = {re}\nalpha_e = {alpha_e}\n[run]\nend = 400\noutput_interval = 100\n"
    );
    let scene = rovib::scene::parse_scene("p.toml", &text).unwrap();
    let report = run_ensemble(&scene, &EnsembleOptions::new(dir.join("out"))).unwrap();
    assert_eq!(report.outcome.completed, 192);
    for k in 0..report.times.len() {
        let (r1, se_r) = report.mean("r1", k).unwrap();
        let (alpha, se_a) = report.mean("alpha", k).unwrap();
        let r1 = r1 * BOHR_IN_ANGSTROM;
        let se_r = se_r * BOHR_IN_ANGSTROM;
        assert!(
            (r1 - re).abs() < 0.003 + 4.0 * se_r,
            "t = {}: ⟨r1⟩ = {r1} ± {se_r} Å, minimum at {re}",
            report.times[k]
        );
        assert!((alpha - alpha_e).abs() < 0.01 + 4.0 * se_a, "t = {}: ⟨α⟩ = {alpha} ± {se_a}", report.times[k]);
        // The test sees the difference: the compiled-in minimum is far outside the tolerance.
        assert!((0.95785 - re).abs() > 10.0 * (0.003 + 4.0 * se_r));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An unknown parameter name in an ensemble scene is an error at its place, before any
/// trajectory, from the library (what the Python package calls) and from the command line.
#[test]
fn an_ensemble_refuses_an_unknown_parameter_at_its_place() {
    use rovib::Error;
    use rovib::ensemble::{EnsembleOptions, run_ensemble};
    let dir = ensemble_dir("unknown");
    let text = "molecule = \"h2o\"\n[ensemble]\ntrajectories = 4\nmethod = \"thermal\"\ntemperature = 300\n\
                region = { energy_cap = 0.1 }\n[potential.parameters]\nbogus = 1\nRE = 1.0\n[run]\nend = 10\n";
    let scene = rovib::scene::parse_scene("u.toml", text).unwrap();
    match run_ensemble(&scene, &EnsembleOptions::new(dir.join("lib"))) {
        Err(Error::File(e)) => {
            assert_eq!((e.path.as_str(), e.line), ("u.toml", 9), "{e}");
            assert!(e.message.contains("h2o has no potential parameter `RE`"), "{e}");
            assert!(e.help.contains("did you mean `re`?"), "{e}");
        }
        other => panic!("expected a located error, got {other:?}"),
    }
    assert!(!dir.join("lib/ensemble.csv").exists());
    let path = dir.join("u.toml");
    std::fs::write(&path, text.replace("RE = 1.0\n", "")).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["ensemble", path.to_str().unwrap(), "--out", dir.join("cli").to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(!out.status.success());
    assert!(err.contains("h2o has no potential parameter `bogus`") && err.contains("u.toml:8:"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
