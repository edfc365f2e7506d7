//! Scene files: every kind of initial condition reproduces what it asked for, scene errors point
//! at their place, and `rovib run` writes complete outputs, or keeps what it wrote when a run
//! fails.

use std::path::PathBuf;
use std::process::Command;

use rovib::molecules::H2o;
use rovib::runtime::hamiltonian::{velocities, w_matrix};
use rovib::runtime::units::{AU_TIME_IN_FS, BOHR_IN_ANGSTROM};
use rovib::scene::parse_scene;
use rovib::start::initial_state;

const BASE: &str = r#"molecule = "h2o"

[units]
length = "angstrom"
angle = "deg"
time = "fs"

[initial]
INITIAL

[integrator]
method = "dop853"
rtol = 1e-10
atol = 1e-10

[run]
end = 20.0
output_interval = 1.0
"#;

fn scene(initial: &str) -> String {
    BASE.replace("INITIAL", initial)
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-scenes-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn internal_coordinates_with_momenta_and_body_angular_momentum() {
    let s = parse_scene(
        "s.toml",
        &scene("q = { r1 = 1.0, alpha = 100.0 }\np = { r2 = 0.5 }\neuler = [10, 80, 20]\nj = [1, 2, 3]"),
    )
    .unwrap();
    let start = initial_state(&H2o, &s).unwrap().state;
    assert!((start.q[0] - 1.0 / BOHR_IN_ANGSTROM).abs() < 1e-15);
    assert!((start.q[1] - 0.95785 / BOHR_IN_ANGSTROM).abs() < 1e-15, "r2 from the reference geometry");
    assert!((start.q[2] - 100f64.to_radians()).abs() < 1e-15);
    assert_eq!(start.p.as_slice(), &[0.0, 0.5, 0.0]);
    let j = w_matrix(&start.euler).unwrap() * start.pe;
    assert!((j - rovib::runtime::nalgebra::Vector3::new(1.0, 2.0, 3.0)).amax() < 1e-14, "J = W p_e = {j:?}");
}

#[test]
fn internal_coordinates_with_velocities_and_euler_momenta() {
    // q̇ in Å/fs and deg/fs; the state must move at exactly these velocities.
    let s = parse_scene("s.toml", &scene("q = { r1 = 0.96, r2 = 0.97, alpha = 104.0 }\nqdot = { r1 = 0.01, alpha = -0.5 }\neuler = [0, 70, 0]\npe = [1, 0.5, -2]"))
        .unwrap();
    let start = initial_state(&H2o, &s).unwrap().state;
    // p_e → J → p_e again (the start is kept as J): equal up to round-off.
    for (a, b) in start.pe.iter().zip([1.0, 0.5, -2.0]) {
        assert!((a - b).abs() < 1e-14, "{:?}", start.pe);
    }
    let (_, qdot) = velocities(&H2o, &start).unwrap();
    let to_au_length = AU_TIME_IN_FS / BOHR_IN_ANGSTROM;
    let expected = [0.01 * to_au_length, 0.0, (-0.5f64).to_radians() * AU_TIME_IN_FS];
    for k in 0..3 {
        assert!((qdot[k] - expected[k]).abs() < 1e-12 * expected[0].abs(), "q̇[{k}] = {} vs {}", qdot[k], expected[k]);
    }
}

fn scene_error(text: &str) -> rovib::runtime::diagnostic::FileError {
    match parse_scene("scenes/bad.toml", text) {
        Ok(s) => initial_state(&H2o, &s).err().expect("an error"),
        Err(e) => e,
    }
}

#[test]
fn scene_errors_name_the_place_and_the_fix() {
    let e = scene_error(&scene("q = { r1 = 1.0, alpah = 100.0 }"));
    assert_eq!(e.message, "h2o has no coordinate `alpah` (in q)");
    assert_eq!((e.line, e.column), (9, 17));
    assert!(e.help.contains("r1, r2, alpha"), "{}", e.help);

    let e = scene_error(&scene("q = { r1 = 1.0 }\np = { r1 = 0.1 }\nqdot = { r1 = 0.1 }"));
    assert_eq!(e.message, "both p and qdot are given");
    assert_eq!(e.line, 11);

    let e = scene_error(&scene("euler = [0, 90]"));
    assert_eq!(e.message, "`euler` has 2 entries, expected 3");

    let e = scene_error(&BASE.replace("INITIAL", "").replace("\"dop853\"", "\"euler\""));
    assert_eq!(e.message, "unknown integrator `euler`");
    assert!(e.help.contains("gauss-legendre"));

    let e = scene_error(&BASE.replace("INITIAL", "").replace("\"dop853\"", "\"rk4\""));
    assert_eq!(e.message, "`rtol` does not apply to the fixed-step rk4 method");

    let e = scene_error(&BASE.replace("INITIAL", "").replace("end = 20.0", "end = -1.0"));
    assert_eq!(e.message, "`run.end` must be a positive finite number, got -1");
    assert_eq!((e.line, e.column), (17, 7));

    let e = scene_error(&BASE.replace("INITIAL", "").replace("time = \"fs\"", "time = \"ns\""));
    assert_eq!(e.message, "unknown time unit `ns`");

    let e = scene_error(&BASE.replace("INITIAL", "").replace("output_interval", "output_intervall"));
    assert!(e.message.starts_with("unknown field `output_intervall`"), "{}", e.message);
}

fn rovib(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rovib")).args(args).output().unwrap()
}

#[test]
fn run_writes_the_three_outputs_consistently() {
    let dir = temp_dir("run");
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene("q = { r1 = 1.0 }\nj = [2, 5, 1]")).unwrap();
    let out = rovib(&["run", path.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    let csv = std::fs::read_to_string(dir.join("out/trajectory.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "t,q_r1,q_r2,q_alpha,p_r1,p_r2,p_alpha,euler_phi,euler_theta,euler_psi,pe_phi,pe_theta,pe_psi,Jx,Jy,Jz,H"
    );
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 21, "t = 0, 1, ..., 20 fs");
    assert_eq!(rows[20][0], 20.0);
    let h0 = rows[0][16];
    assert!(rows.iter().all(|r| (r[16] - h0).abs() < 1e-8 * h0.abs()), "H conserved");

    let xyz = std::fs::read_to_string(dir.join("out/lab.xyz")).unwrap();
    let frames: Vec<&str> = xyz.lines().collect();
    assert_eq!(frames.len(), 21 * 5, "5 lines per frame");
    assert_eq!(frames[0], "3");
    assert!(
        frames[1]
            .starts_with("Properties=species:S:1:pos:R:3:masses:R:1:momenta:R:3:vel:R:3 Time=0.0 time_unit=fs energy="),
        "{}",
        frames[1]
    );
    assert!(frames[2].starts_with("O "));
    // The O–H distance in the file (Å) is r1 of the same output time.
    let atom = |line: &str| -> [f64; 3] {
        let v: Vec<f64> = line.split_whitespace().skip(1).map(|x| x.parse().unwrap()).collect();
        [v[0], v[1], v[2]]
    };
    for f in [0, 7, 20] {
        let (o, h1) = (atom(frames[5 * f + 2]), atom(frames[5 * f + 3]));
        let d = ((o[0] - h1[0]).powi(2) + (o[1] - h1[1]).powi(2) + (o[2] - h1[2]).powi(2)).sqrt();
        // Full round-trip precision: round-off only (12 decimals in Å would be ~1e-12 off).
        assert!(
            (d / BOHR_IN_ANGSTROM - rows[f][1]).abs() < 1e-14,
            "frame {f}: |O–H1| = {d} Å vs r1 = {} bohr",
            rows[f][1]
        );
    }

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["status"], "completed");
    assert!(summary["rhs_evaluations"].as_u64().unwrap() > 100);
    let c = &summary["conservation"];
    assert!(c["max_relative_energy_error"].as_f64().unwrap() < 1e-8);
    assert!(c["max_abs_j_change_hbar"].as_f64().unwrap() < 1e-9);
    // The body formulation integrates J, not p_e: p_φ = L_z is conserved to the tolerance.
    assert!(c["max_p_phi_change_hbar"].as_f64().unwrap() < 1e-9);
    assert!(c["max_lab_angular_momentum_change_hbar"].as_f64().unwrap() < 1e-9);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_failed_run_keeps_its_output_and_says_where_it_stopped() {
    let dir = temp_dir("fail");
    let path = dir.join("scene.toml");
    // Too few steps allowed: the run must stop, report the time and keep what it wrote.
    std::fs::write(&path, scene("q = { r1 = 1.0 }").replace("atol = 1e-10", "atol = 1e-10\nmax_steps = 40")).unwrap();
    let out = rovib(&["run", path.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap(), "--quiet"]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.starts_with("error: the run stopped: "), "{err}");
    // What, when (in the scene's unit, once) and where.
    assert!(err.contains("integrator.max_steps = 40 steps were taken by t = "), "{err}");
    assert_eq!(err.matches("t = ").count(), 1, "{err}");
    assert!(err.contains(" fs; last accepted state [r1, r2, alpha, p_r1, p_r2, p_alpha"), "{err}");
    let csv = std::fs::read_to_string(dir.join("out/trajectory.csv")).unwrap();
    let rows = csv.lines().count() - 1;
    assert!((1..21).contains(&rows), "{rows} rows kept");
    assert!(csv.ends_with('\n'), "the last row is complete");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["status"], "failed");
    assert!(summary["error"].as_str().unwrap().contains("steps"));
    // The work done before the stop is still reported.
    assert!(summary["rhs_evaluations"].as_u64().unwrap() > 40);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn every_shipped_scene_parses_and_binds_to_its_molecule() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes");
    let mut count = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let text = std::fs::read_to_string(&path).unwrap();
            let s = parse_scene(&path.display().to_string(), &text).unwrap_or_else(|e| panic!("{e}"));
            assert!(rovib::molecules::NAMES.contains(&s.molecule.get_ref().as_str()), "{}", path.display());
            count += 1;
        }
    }
    assert!(count >= 1);
}

/// The lab form of a scene: positions (Å) and velocities (Å/fs) of a state made with `to_lab`
/// bind back to that state, with the centre-of-mass motion split off.
#[test]
fn lab_frame_positions_and_velocities_bind_back_to_the_same_state() {
    use rovib::runtime::frames::{CentreOfMass, to_lab};
    use rovib::runtime::hamiltonian::PhaseState;
    use rovib::runtime::nalgebra::Vector3;
    let state = PhaseState::<3> {
        q: [1.9, 1.75, 1.7].into(),
        p: [0.4, -0.3, 1.5].into(),
        euler: [0.3, 1.1, -0.6].into(),
        pe: [4.0, -2.0, 3.0].into(),
    };
    let com = CentreOfMass { position: Vector3::new(1.0, -2.0, 0.5), velocity: Vector3::new(1e-4, 0.0, -2e-4) };
    let lab = to_lab(&H2o, &state, &com).unwrap();
    let (l, v) = (BOHR_IN_ANGSTROM, BOHR_IN_ANGSTROM / AU_TIME_IN_FS);
    let mut table = String::new();
    for (key, m, scale) in [("positions", &lab.positions, l), ("velocities", &lab.velocities, v)] {
        let entries: Vec<String> = ["O", "H1", "H2"]
            .iter()
            .enumerate()
            .map(|(i, label)| {
                format!("{label} = [{:?}, {:?}, {:?}]", m[(0, i)] * scale, m[(1, i)] * scale, m[(2, i)] * scale)
            })
            .collect();
        table.push_str(&format!("{key} = {{ {} }}\n", entries.join(", ")));
    }
    let s = parse_scene("lab.toml", &scene(&table)).unwrap();
    let start = initial_state(&H2o, &s).unwrap();
    let back = start.state;
    assert!((back.q - state.q).amax() < 1e-12, "{:?}", back.q);
    assert!((back.p - state.p).amax() < 1e-10, "{:?}", back.p);
    assert!((back.euler - state.euler).amax() < 1e-12, "{:?}", back.euler);
    assert!((back.pe - state.pe).amax() < 1e-10, "{:?}", back.pe);
    assert!((start.com_position - com.position).amax() < 1e-12);
    assert!((start.com_velocity - com.velocity).amax() < 1e-15);
}

#[test]
fn lab_frame_errors_name_the_atoms() {
    let e = scene_error(&scene("positions = { O = [0, 0, 0], H1 = [0.9, 0, 0] }"));
    assert_eq!(e.message, "the lab-frame positions do not give atom H2");
    assert_eq!(e.line, 9);
    let e = scene_error(&scene("positions = { O = [0, 0, 0], H1 = [0.9, 0, 0], H3 = [0, 0.9, 0] }"));
    assert_eq!(e.message, "h2o has no atom `H3` (in positions)");
    assert!(e.help.contains("O, H1, H2"));
    let e = scene_error(&scene("positions = { O = [0, 0, 0], H1 = [0.9, 0, 0], H2 = [0, 0.9, 0] }\nq = { r1 = 1.0 }"));
    assert!(e.message.starts_with("the initial condition mixes the lab form"), "{}", e.message);
    // Collinear atoms: the metric is singular there, but water's coordinates have closed forms,
    // so this is a start in the Cartesian chart, taken as given, not an error.
    let linear = parse_scene("s.toml", &scene("positions = { O = [0, 0, 0], H1 = [0.9, 0, 0], H2 = [-0.9, 0, 0] }"));
    let start = initial_state(&H2o, &linear.unwrap()).expect("a linear start");
    assert!(start.lab_start.is_some() && (start.body.q[2] - std::f64::consts::PI).abs() < 1e-12);
}

fn summary_of(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

/// `[run] frozen` holds a coordinate at its initial value; zero initial angular momentum drops
/// J from the integrated state; both show in summary.json and in the trajectory.
#[test]
fn frozen_coordinates_and_zero_angular_momentum_reduce_what_is_integrated() {
    let dir = temp_dir("reduced");
    let path = dir.join("scene.toml");
    let text = scene("q = { r1 = 1.0, alpha = 100.0 }\nj = [0, 0, 0]")
        .replace("output_interval = 1.0", "output_interval = 1.0\nfrozen = [\"r2\"]");
    std::fs::write(&path, text).unwrap();
    let out = rovib(&["run", path.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap(), "--quiet"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = summary_of(&dir.join("out"));
    assert_eq!(s["frozen"], serde_json::json!(["r2"]));
    assert_eq!(s["zero_angular_momentum"], true);
    assert_eq!(s["state_layout"], "[r1, alpha, p_r1, p_alpha, quaternion w, x, y, z]");
    assert!(s["conservation"]["max_relative_energy_error"].as_f64().unwrap() < 1e-8);
    assert_eq!(s["conservation"]["max_abs_j_change_hbar"].as_f64(), Some(0.0));
    let csv = std::fs::read_to_string(dir.join("out/trajectory.csv")).unwrap();
    let rows: Vec<Vec<f64>> = csv.lines().skip(1).map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    let r2 = 0.95785 / BOHR_IN_ANGSTROM;
    assert!(rows.iter().all(|r| (r[2] - r2).abs() < 1e-15), "r2 stays at its value");
    assert!(rows.iter().any(|r| (r[1] - rows[0][1]).abs() > 1e-3), "r1 moves");
    assert!(rows.iter().all(|r| r[10] == 0.0 && r[11] == 0.0 && r[12] == 0.0), "p_e stays exactly 0");

    // A frozen name the molecule does not have is an error at its place.
    let text = scene("q = { r1 = 1.0 }").replace("output_interval = 1.0", "output_interval = 1.0\nfrozen = [\"r3\"]");
    std::fs::write(&path, text).unwrap();
    let out = rovib(&["run", path.to_str().unwrap(), "--out", dir.join("out2").to_str().unwrap(), "--quiet"]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("no internal coordinate is called \"r3\""), "{err}");
    assert!(err.contains("--> ") && err.contains(":19:11"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An initial q outside a coordinate's valid range (a negative bond length, a bond angle above
/// 180°) is refused at its place, with the range in the scene's units.
#[test]
fn initial_q_outside_its_range_is_a_located_error() {
    for (q, name) in [("r1 = -0.96, r2 = 0.97, alpha = 104.0", "r1"), ("r1 = 0.96, r2 = 0.97, alpha = 250.0", "alpha")]
    {
        let s = parse_scene("s.toml", &scene(&format!("q = {{ {q} }}\np = {{}}\neuler = [0, 70, 0]\nj = [0, 0, 0]")))
            .unwrap();
        let e = initial_state(&H2o, &s).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains(&format!("{name} = ")) && e.contains("outside its valid range"), "{e}");
        assert!(e.contains("s.toml:"), "{e}");
    }
}

#[test]
fn a_velocity_for_a_frozen_coordinate_is_a_located_error() {
    // Before this check the velocity leaked into the other coordinates through the metric
    // (p_r2 = 1.3, p_alpha = 4.3 for qdot r1 = 1 with r1 frozen) and raised H(0).
    for (given, what) in [("qdot = { r2 = 0.1, r1 = 1.0 }", "qdot"), ("p = { r1 = 0.5 }", "p")] {
        let text = scene(&format!("q = {{ r1 = 1.0 }}\n{given}")).replace("[run]\n", "[run]\nfrozen = [\"r1\"]\n");
        let e = scene_error(&text);
        assert_eq!(e.message.split(" but").next(), Some("`r1` is frozen (run.frozen)"), "{}", e.message);
        assert!(e.message.contains(what), "{}", e.message);
        assert_eq!(e.line, 10);
        assert!(e.help.contains("zero velocity"), "{}", e.help);
    }
    // A zero velocity for a frozen coordinate is harmless and accepted.
    let text =
        scene("q = { r1 = 1.0 }\nqdot = { r1 = 0.0, r2 = 0.1 }").replace("[run]\n", "[run]\nfrozen = [\"r1\"]\n");
    assert!(parse_scene("ok.toml", &text).is_ok());
}

#[test]
fn picoseconds_are_a_thousand_femtoseconds() {
    let fs = parse_scene("fs.toml", &scene("").replace("end = 20.0", "end = 1500.0")).unwrap();
    let ps =
        parse_scene("ps.toml", &scene("").replace("time = \"fs\"", "time = \"ps\"").replace("end = 20.0", "end = 1.5"))
            .unwrap();
    assert_eq!(fs.time_unit.name(), "fs");
    assert_eq!(ps.time_unit.name(), "ps");
    // 1.5 ps = 1500 fs = 1500 / 0.024 188 843 265 857 a.u. (CODATA 2018), independently of TimeUnit.
    let expected = 1500.0 / 2.418_884_326_585_7e-2;
    assert!((ps.t_end - expected).abs() < 1e-9 * expected, "{} vs {expected}", ps.t_end);
    assert!((ps.t_end - fs.t_end).abs() < 1e-9 * expected);
}

#[test]
fn unbounded_output_counts_and_overflowing_times_are_refused_where_written() {
    // 5e-324 fs wrote 900 MB in 30 s before this check.
    let e = scene_error(&scene("").replace("output_interval = 1.0", "output_interval = 5e-324"));
    assert!(e.message.contains("output times"), "{}", e.message);
    assert!(e.message.contains("1000000"), "{}", e.message);
    assert_eq!(e.line, 18);
    let e = scene_error(&scene("").replace("end = 20.0", "end = 1e307"));
    assert!(e.message.contains("`run.end` is inf"), "{}", e.message);
    assert_eq!(e.line, 17);
    // The limit can be raised on purpose.
    let text = scene("")
        .replace("output_interval = 1.0", "output_interval = 1e-5")
        .replace("[run]\n", "[run]\nmax_outputs = 3000000\n");
    assert!(parse_scene("ok.toml", &text).is_ok());
    let text = scene("").replace("output_interval = 1.0", "output_interval = 1e-5");
    assert!(scene_error(&text).message.contains("more than 1000000"));
}
