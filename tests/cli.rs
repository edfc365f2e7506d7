//! The `rovib` binary: `list` and `eval` output and errors, run as a user runs them.

use std::io::Write as _;
use std::process::{Command, Output, Stdio};

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
    for name in rovib::molecules::NAMES {
        assert!(text.contains(&format!("{name} (molecules/{name}.toml)")), "{text}");
    }
    assert!(text.contains("h2o (molecules/h2o.toml): 3 atoms, 3 internal coordinates\n  atoms:       O (O, 15.99491461957 Da), H1 (H, 1.00782503223 Da), H2 (H, 1.00782503223 Da)\n  coordinates: r1 [angstrom], r2 [angstrom], alpha [rad]"), "{text}");
    // The unit note once, not per coordinate.
    assert_eq!(text.matches("at run time").count(), 1, "{text}");
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
