//! The `rovib` binary: `list` and `eval` output and errors, run as a user runs them.

use std::io::Write as _;
use std::process::{Command, Output, Stdio};

use crate::common;

fn rovib(args: &[&str], stdin: Option<&str>) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("rovib runs");
    if let Some(input) = stdin {
        child.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
    }
    child.wait_with_output().unwrap()
}

fn stderr_line(out: &Output) -> String {
    assert!(!out.status.success(), "expected failure");
    let err = String::from_utf8(out.stderr.clone()).unwrap();
    assert_eq!(err.trim_end().lines().count(), 1, "one-line error, got:\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    err.trim_end().to_owned()
}

#[test]
fn list_names_every_molecule_with_atoms_and_coordinates() {
    let out = rovib(&["list"], None);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    // `molecules/NAME.toml`, or the file under ROVIB_MOLECULES_DIR.
    for name in rovib::molecules::NAMES {
        assert!(text.contains(&format!("{name} ({})", common::source_of(name))), "{text}");
    }
    let h2o = common::source_of("h2o");
    assert!(text.contains(&format!("h2o ({h2o}): 3 atoms, 3 internal coordinates\n  atoms:       O (O, 15.99491461957 Da), H1 (H, 1.00782503223 Da), H2 (H, 1.00782503223 Da)\n  coordinates: r1 [angstrom], r2 [angstrom], alpha [rad]")), "{text}");
    // The unit note once, not per coordinate.
    assert_eq!(text.matches("at run time").count(), 1, "{text}");
}

/// That the shipped linear molecules (CO2, HCN) have a linear reference geometry is a note of
/// `rovib list` (not a build warning), once, under the molecule; a bent molecule has none.
#[test]
fn list_notes_that_a_reference_geometry_is_linear_under_the_molecule() {
    let text = String::from_utf8(rovib(&["list"], None).stdout).unwrap();
    for name in ["co2", "hcn"] {
        let note = format!(
            "  note:        the reference geometry of molecule `{name}` ({}) is linear",
            common::source_of(name)
        );
        assert_eq!(text.matches(&note).count(), 1, "{text}");
        let block = text.split("\n\n").find(|b| b.starts_with(&format!("{name} ("))).unwrap();
        assert!(block.contains(&note), "the note is under its molecule: {block}");
        assert_eq!(rovib::molecules::notes(name).count(), 1);
    }
    assert_eq!(rovib::molecules::notes("h2o").count(), 0);
    let h2o = text.split("\n\n").find(|b| b.starts_with("h2o (")).unwrap();
    assert!(!h2o.contains("note:"), "{h2o}");
}

#[test]
fn eval_prints_every_quantity_consistent_with_the_library() {
    let state = r#"{"q": [1.85, 1.75, 1.9], "p": [0.3, -0.2, 0.5], "euler": [0.4, 1.2, -0.7], "pe": [2.0, -1.0, 3.0]}"#;
    let out = rovib(&["eval", "--molecule", "h2o", "--state", "-"], Some(state));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("valid JSON");
    for key in ["masses", "positions", "H", "a", "A", "I", "G11", "G12", "G22", "rhs"] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    for key in ["q", "p", "euler", "pe"] {
        assert_eq!(v["rhs"][key].as_array().unwrap().len(), 3);
    }
    assert_eq!(v["masses"][0].as_f64(), Some(15.99491461957));
    assert_eq!(v["G12"].as_array().unwrap().len(), 3, "G12 has 3 rows");
    assert_eq!(v["positions"].as_array().unwrap().len(), 3, "one row per atom");

    // The printed H and rhs are the library's, to the last digit (JSON round-trips f64).
    use rovib::runtime::hamiltonian::{PhaseState, Workspace, hamiltonian, rhs};
    let s = PhaseState::<3> {
        q: [1.85, 1.75, 1.9].into(),
        p: [0.3, -0.2, 0.5].into(),
        euler: [0.4, 1.2, -0.7].into(),
        pe: [2.0, -1.0, 3.0].into(),
    };
    let m = rovib::molecules::H2o;
    assert_eq!(v["H"].as_f64(), Some(hamiltonian(&m, &s).unwrap()));
    let d = rhs(&m, &s, &mut Workspace::default()).unwrap();
    assert_eq!(v["rhs"]["p"][2].as_f64(), Some(d.p[2]));
    assert_eq!(v["rhs"]["pe"][0].as_f64(), Some(0.0));
}

#[test]
fn eval_of_a_rigid_molecule_has_empty_vibrational_blocks() {
    let out =
        rovib(&["eval", "--molecule", "h2o_rigid", "--state", "-"], Some(r#"{"euler": [0, 1, 0], "pe": [1, 2, 3]}"#));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["a"].as_array().unwrap().len(), 0);
    assert_eq!(v["G12"][0].as_array().unwrap().len(), 0);
    assert!(v["H"].as_f64().unwrap() > 0.0);
}

#[test]
fn eval_errors_are_one_line() {
    let err = stderr_line(&rovib(&["eval", "--molecule", "h2o", "--state", "-"], Some(r#"{"q": [1.8, 1.8]}"#)));
    assert_eq!(
        err,
        "error: state on stdin: `q` has 2 entries, expected 3 (one per coordinate of h2o: r1, r2, alpha, in bohr or rad)"
    );
    let err = stderr_line(&rovib(
        &["eval", "--molecule", "h2o", "--state", "-"],
        Some(r#"{"q": [1.8, 1.8, 1.8], "pe": [0, 1]}"#),
    ));
    assert_eq!(err, "error: state on stdin: `pe` has 2 entries, expected 3 (p_phi, p_theta, p_psi in hbar)");
    let err = stderr_line(&rovib(&["eval", "--molecule", "h2o", "--state", "-"], Some(r#"{"q": [1.8, 1.8, 1e999]}"#)));
    assert!(err.contains("number out of range"), "{err}");
    let err = stderr_line(&rovib(&["eval", "--molecule", "h2O", "--state", "-"], Some("{}")));
    assert!(err.starts_with("error: unknown molecule `h2O`; the compiled-in molecules are "), "{err}");
    assert!(err.contains(&rovib::molecules::NAMES.join(", ")), "{err}");
    let err = stderr_line(&rovib(
        &["eval", "--molecule", "h2o", "--state", "-"],
        Some(r#"{"q": [1.8, 1.8, 1.8], "eular": [0, 1, 0]}"#),
    ));
    assert!(err.contains("unknown field `eular`"), "{err}");
    let err = stderr_line(&rovib(
        &["eval", "--molecule", "h2o", "--state", "-"],
        Some(r#"{"q": [1.8, 1.8, 1.8], "euler": [0, 0, 0]}"#),
    ));
    assert!(err.contains("too close to 0 or π"), "{err}");
    let err = stderr_line(&rovib(&["eval", "--molecule", "h2o", "--state", "/nonexistent/state.json"], None));
    assert!(err.starts_with("error: cannot read /nonexistent/state.json"), "{err}");
}

#[test]
fn a_closed_pipe_ends_output_quietly() {
    // `rovib list | head -1`: the reader goes away; rovib must not panic.
    let mut child = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["eval", "--molecule", "h2o"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.status.success(), "{err}");
}

/// `rovib eval` at a linear reference (HCN and CO2 ship their linear equilibria): exit 0, the
/// chart named singular with a note on what to do, H, G and rhs left out (they do not exist
/// there), and what exists printed and consistent: U = U(q) of the library, the Cartesian block's
/// U the same, the positions on a line, the Cartesian gradient zero at this minimum.
#[test]
fn eval_at_a_linear_reference_says_the_chart_is_singular_and_prints_what_exists() {
    use rovib::runtime::{Kinematics, Molecule};
    for (name, u_ref) in [
        ("hcn", rovib::molecules::Hcn.potential(&rovib::molecules::Hcn.reference_geometry().unwrap())),
        ("co2", rovib::molecules::Co2.potential(&rovib::molecules::Co2.reference_geometry().unwrap())),
    ] {
        let out = rovib(&["eval", "--molecule", name], None);
        assert!(out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("valid JSON");
        assert_eq!(v["euler_chart"], "singular", "{name}: {v}");
        let note = v["note"].as_str().unwrap_or_else(|| panic!("{name}: no note"));
        for promise in ["singular", "linear", "rovib run", "Cartesian", "bent geometry"] {
            assert!(note.contains(promise), "{name}: the note does not say `{promise}`: {note}");
        }
        for absent in ["H", "G11", "G12", "G22", "rhs"] {
            assert!(v.get(absent).is_none(), "{name}: `{absent}` printed where it does not exist");
        }
        assert_eq!(v["U"].as_f64(), Some(u_ref), "{name}");
        let c = &v["cartesian"];
        assert!((c["U"].as_f64().unwrap() - u_ref).abs() < 1e-12, "{name}: {c}");
        assert_eq!(c["H"].as_f64(), c["U"].as_f64(), "{name}: at rest H = U");
        let grad: Vec<f64> = c["gradient_U"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|r| r.as_array().unwrap().clone())
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert!(grad.iter().all(|g| g.abs() < 1e-10), "{name}: the gradient at the linear minimum: {grad:?}");
        let x: Vec<[f64; 3]> =
            c["positions"].as_array().unwrap().iter().map(|r| serde_json::from_value(r.clone()).unwrap()).collect();
        let d1 = [x[1][0] - x[0][0], x[1][1] - x[0][1], x[1][2] - x[0][2]];
        let d2 = [x[2][0] - x[0][0], x[2][1] - x[0][1], x[2][2] - x[0][2]];
        let cross = [d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]];
        assert!(cross.iter().all(|c| c.abs() < 1e-12), "{name}: positions not on a line: {x:?}");
    }
}

/// `rovib eval` at linear with momenta: the lab velocities by the pseudo-inverse; the Cartesian
/// block's T is ½ Σ m v² of its own velocities, J_lab is Σ m x × v of its own positions and
/// velocities and has the length of the body-frame J (a rotation does not change it).
#[test]
fn eval_at_linear_with_momenta_gives_consistent_cartesian_quantities() {
    use rovib::runtime::hamiltonian::euler_momenta_from_angular_momentum;
    use rovib::runtime::nalgebra::Vector3;
    // HCN's molecular axis is body z at linear: J perpendicular to it.
    let euler = Vector3::new(0.4, 1.2, -0.7);
    let pe = euler_momenta_from_angular_momentum(&euler, &Vector3::new(3.0, -4.0, 0.0));
    let state =
        format!(r#"{{"p": [0.2, -0.1, 1.5], "euler": [0.4, 1.2, -0.7], "pe": [{}, {}, {}]}}"#, pe[0], pe[1], pe[2]);
    let out = rovib(&["eval", "--molecule", "hcn", "--state", "-"], Some(&state));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["euler_chart"], "singular");
    let c = &v["cartesian"];
    let rows = |key: &str| -> Vec<[f64; 3]> { serde_json::from_value(c[key].clone()).unwrap() };
    let (x, u) = (rows("positions"), rows("velocities"));
    let masses: Vec<f64> = serde_json::from_value(v["masses"].clone()).unwrap();
    let me = masses.iter().map(|m| m * rovib::runtime::units::DALTON_IN_ELECTRON_MASSES).collect::<Vec<_>>();
    let t: f64 = (0..3).map(|i| 0.5 * me[i] * (u[i][0].powi(2) + u[i][1].powi(2) + u[i][2].powi(2))).sum();
    assert!(t > 0.0 && (c["T"].as_f64().unwrap() - t).abs() < 1e-12 * t, "T {} vs {t}", c["T"]);
    assert!((c["H"].as_f64().unwrap() - c["T"].as_f64().unwrap() - c["U"].as_f64().unwrap()).abs() < 1e-15);
    let mut l = [0.0; 3];
    for i in 0..3 {
        l[0] += me[i] * (x[i][1] * u[i][2] - x[i][2] * u[i][1]);
        l[1] += me[i] * (x[i][2] * u[i][0] - x[i][0] * u[i][2]);
        l[2] += me[i] * (x[i][0] * u[i][1] - x[i][1] * u[i][0]);
    }
    let j_lab: Vec<f64> = serde_json::from_value(c["J_lab"].clone()).unwrap();
    let j_body: Vec<f64> = serde_json::from_value(v["J"].clone()).unwrap();
    let norm = |a: &[f64]| a.iter().map(|x| x * x).sum::<f64>().sqrt();
    for k in 0..3 {
        assert!((j_lab[k] - l[k]).abs() < 1e-10 * norm(&l), "J_lab {j_lab:?} vs Σ m x × v {l:?}");
    }
    assert!((norm(&j_lab) - norm(&j_body)).abs() < 1e-9 * norm(&j_body), "|J_lab| {j_lab:?} vs |J| {j_body:?}");
    // Momenta with angular momentum along the axis cannot be carried at linear: a one-line error.
    let pe = euler_momenta_from_angular_momentum(&euler, &Vector3::new(0.0, 0.0, 3.0));
    let along_axis = format!(r#"{{"euler": [0.4, 1.2, -0.7], "pe": [{}, {}, {}]}}"#, pe[0], pe[1], pe[2]);
    let err = stderr_line(&rovib(&["eval", "--molecule", "hcn", "--state", "-"], Some(&along_axis)));
    assert!(err.contains("lab-frame Cartesian"), "{err}");
}

/// At a bent state the Cartesian block is the same state: its H equals the internal H, and
/// |J_lab| = |J|.
#[test]
fn eval_cartesian_block_agrees_with_the_hamiltonian_where_both_exist() {
    let state = r#"{"q": [2.0, 2.2, 2.6], "p": [0.3, -0.2, 0.5], "euler": [0.4, 1.2, -0.7], "pe": [2.0, -1.0, 3.0]}"#;
    let out = rovib(&["eval", "--molecule", "hcn", "--state", "-"], Some(state));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["euler_chart"], "regular");
    assert!(v.get("note").is_none());
    let (h, hc) = (v["H"].as_f64().unwrap(), v["cartesian"]["H"].as_f64().unwrap());
    assert!((h - hc).abs() < 1e-12 * h.abs(), "H {h} vs Cartesian {hc}");
    let j: Vec<f64> = serde_json::from_value(v["J"].clone()).unwrap();
    let jl: Vec<f64> = serde_json::from_value(v["cartesian"]["J_lab"].clone()).unwrap();
    let norm = |a: &[f64]| a.iter().map(|x| x * x).sum::<f64>().sqrt();
    assert!((norm(&j) - norm(&jl)).abs() < 1e-10 * norm(&j), "{j:?} vs {jl:?}");
}
