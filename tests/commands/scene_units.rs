//! Scene numbers without `[units]`: q in each coordinate's declared unit (not bohr and rad
//! whatever the definition declares), and the warning for a start far above the reference energy.

use std::path::PathBuf;
use std::process::Command;

use rovib::molecules::H2o;
use rovib::runtime::hamiltonian::hamiltonian;
use rovib::runtime::units::{BOHR_IN_ANGSTROM, HARTREE_IN_EV};
use rovib::runtime::{Kinematics, Molecule};
use rovib::scene::parse_scene;
use rovib::start::initial_state;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-scene-units-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn scene(q: &str) -> String {
    format!(
        "molecule = \"h2o\"\n[initial]\nq = {{ {q} }}\nqdot = {{ r2 = 0.001 }}\n[run]\nend = 20.0\noutput_interval = 10.0\n"
    )
}

#[test]
fn q_without_units_is_in_each_coordinates_declared_unit() {
    // h2o.toml declares r1, r2 in Å and alpha in rad.
    let s = parse_scene("s.toml", &scene("r1 = 1.2, alpha = 1.9")).unwrap();
    let start = initial_state(&H2o, &s).unwrap().state;
    assert_eq!(start.q[0], 1.2 / BOHR_IN_ANGSTROM);
    assert_eq!(start.q[2], 1.9);
    // qdot in the declared unit per a.u. of time: Å per ħ/E_h here, so p_r2 = a_22 · q̇ in bohr.
    // The same geometry with explicit bohr: q̇ = 0.001 bohr per a.u. instead of Å per a.u.
    let r1_bohr = 1.2 / BOHR_IN_ANGSTROM;
    let with_units = parse_scene(
        "u.toml",
        &scene(&format!("r1 = {r1_bohr:?}, alpha = 1.9")).replace("[initial]", "[units]\nlength = \"bohr\"\n[initial]"),
    )
    .unwrap();
    let start_bohr = initial_state(&H2o, &with_units).unwrap().state;
    assert_eq!(start_bohr.q[0], r1_bohr, "an explicit [units] length still applies");
    let ratio = start.p[1] / start_bohr.p[1];
    assert!((ratio - 1.0 / BOHR_IN_ANGSTROM).abs() < 1e-12, "qdot scaled by the declared unit: {ratio}");
}

fn run(dir: &std::path::Path, text: &str) -> (bool, String, serde_json::Value) {
    let path = dir.join("s.toml");
    std::fs::write(&path, text).unwrap();
    let out_dir = dir.join("out");
    let out = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", path.to_str().unwrap(), "--out", out_dir.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    let summary = serde_json::from_str(&std::fs::read_to_string(out_dir.join("summary.json")).unwrap()).unwrap();
    (out.status.success(), String::from_utf8(out.stderr).unwrap(), summary)
}

#[test]
fn a_start_far_above_the_reference_energy_is_warned_about_with_its_figure() {
    let dir = temp_dir("warn");
    // r1 = 1.81 meant in bohr, read in Å (the declared unit): 0.85 Å stretched.
    let (ok, stderr, summary) = run(&dir, &scene("r1 = 1.81"));
    assert!(ok, "a warning, not an error: {stderr}");
    let s = parse_scene("s.toml", &scene("r1 = 1.81")).unwrap();
    let h0 = hamiltonian(&H2o, &initial_state(&H2o, &s).unwrap().state).unwrap();
    let above_ev = (h0 - H2o.potential(&H2o.reference_geometry().unwrap())) * HARTREE_IN_EV;
    assert!(above_ev > 2.72, "{above_ev}");
    let figure = format!("{above_ev:.3} eV");
    assert!(stderr.starts_with("warning: the start is ") && stderr.contains(&figure), "{figure}: {stderr}");
    let warnings = summary["warnings"].as_array().unwrap();
    assert_eq!(warnings.len(), 1);
    assert!(warnings[0].as_str().unwrap().contains(&figure));

    // Near the reference: no warning.
    let (ok, stderr, summary) = run(&dir, &scene("r1 = 1.0"));
    assert!(ok && stderr.is_empty(), "{stderr}");
    assert_eq!(summary["warnings"], serde_json::json!([]));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_stop_condition_ends_the_run_at_the_first_output_outside_and_the_summary_says_so() {
    let dir = temp_dir("stop");
    // Stretched to 1.25 Å at rest, the bond swings in below 0.9 Å within half a period.
    let text = "molecule = \"h2o\"\n[units]\ntime = \"fs\"\n[initial]\nq = { r1 = 1.25 }\n\
                [run]\nend = 100.0\noutput_interval = 0.1\nstop_outside = { r1 = [0.9, 2.0] }\n";
    let (ok, stderr, summary) = run(&dir, text);
    assert!(ok, "{stderr}");
    assert_eq!(summary["status"], "stopped");
    assert_eq!(summary["stop"]["coordinate"], "r1");
    let csv = std::fs::read_to_string(dir.join("out/trajectory.csv")).unwrap();
    let rows: Vec<Vec<f64>> = csv.lines().skip(1).map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    let low = 0.9 / BOHR_IN_ANGSTROM;
    let (last, before) = (&rows[rows.len() - 1], &rows[rows.len() - 2]);
    assert!(last[1] < low && before[1] >= low, "stopped at the first row below: {} then {}", before[1], last[1]);
    assert!(rows.iter().rev().skip(1).all(|r| r[1] >= low), "no earlier row outside");
    assert_eq!(summary["stop"]["t"].as_f64(), Some(last[0]));
    assert_eq!(summary["stop"]["value_au"].as_f64(), Some(last[1]));
    assert!(last[0] < 20.0, "well before the end: t = {}", last[0]);

    // An unknown coordinate is an error at its place.
    let (ok, stderr, _) = {
        let path = dir.join("bad.toml");
        std::fs::write(&path, text.replace("{ r1 = [0.9", "{ r3 = [0.9")).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_rovib"))
            .args(["run", path.to_str().unwrap(), "--out", dir.join("bad").to_str().unwrap(), "--quiet"])
            .output()
            .unwrap();
        (out.status.success(), String::from_utf8(out.stderr).unwrap(), ())
    };
    assert!(!ok && stderr.contains("h2o has no coordinate `r3` (in run.stop_outside)"), "{stderr}");
    assert!(stderr.contains("bad.toml:"), "{stderr}");
    std::fs::remove_dir_all(&dir).unwrap();
}
