//! trajectory.csv's columns: names that cannot collide with any coordinate's,
//! their units in trajectory.units.json, and the unwrapped Euler angles against a closed form.

use std::path::PathBuf;
use std::process::Command;

use rovib::molecules::H2oRigid;
use rovib::output::trajectory_columns;
use rovib::runtime::Coordinate;
use rovib::runtime::Kinematics;
use rovib::runtime::nalgebra::SMatrix;
use rovib::runtime::units::{AU_TIME_IN_FS, AngleUnit, CoordinateUnit, LengthUnit};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-columns-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn coordinate(name: &'static str, angle: bool) -> Coordinate {
    let unit = if angle { CoordinateUnit::Angle(AngleUnit::Deg) } else { CoordinateUnit::Length(LengthUnit::Angstrom) };
    Coordinate { name, unit, reference: None, range: (f64::NEG_INFINITY, f64::INFINITY) }
}

#[test]
fn coordinates_named_like_output_columns_give_distinct_columns_with_units() {
    // Every name that collided with the old header (t, theta, phi, psi, H, p_r2, p_phi), and r2.
    let names = [
        ("t", false),
        ("theta", true),
        ("phi", true),
        ("psi", true),
        ("H", false),
        ("p_r2", false),
        ("r2", false),
        ("p_phi", true),
        ("pe_phi", true),
        ("euler_phi", true),
    ];
    let coords: Vec<Coordinate> = names.iter().map(|&(n, a)| coordinate(n, a)).collect();
    let columns = trajectory_columns(&coords, "fs", true);
    let mut seen = std::collections::BTreeSet::new();
    for (name, _) in &columns {
        assert!(seen.insert(name.clone()), "column `{name}` appears twice in {columns:?}");
    }
    assert_eq!(columns.len(), 1 + 2 * names.len() + 10 + 2);
    let unit = |n: &str| columns.iter().find(|(c, _)| c == n).unwrap().1;
    assert_eq!(unit("t"), "fs");
    assert_eq!(unit("q_t"), "bohr");
    assert_eq!(unit("p_t"), "hbar/bohr");
    assert_eq!(unit("q_theta"), "rad");
    assert_eq!(unit("p_theta"), "hbar");
    assert_eq!(unit("euler_theta"), "rad");
    assert_eq!(unit("pe_theta"), "hbar");
    assert_eq!(unit("Jy"), "hbar");
    assert_eq!(unit("H"), "hartree");
    assert_eq!(unit("q_H"), "bohr");
    assert_eq!(unit("euler_psi_unwrapped"), "rad");
}

/// Rigid water turning about its out-of-plane principal axis (body y), which points along lab z:
/// the motion is φ(t) = φ(0) + ω t with ω = J / I_yy, θ and ψ constant. Over 5 turns the
/// unwrapped φ must follow that line, the raw one stays in (−π, π], and the units file says so.
#[test]
fn unwrapped_phi_of_a_free_rotation_about_lab_z_is_omega_t() {
    let dir = temp_dir("unwrap");
    let scene = dir.join("s.toml");
    std::fs::write(
        &scene,
        r#"molecule = "h2o_rigid"
[units]
angle = "deg"
time = "fs"
[initial]
euler = [30, 90, 0]
j = [0, 20, 0]
[run]
end = 500.0
output_interval = 1.0
euler_unwrapped = true
"#,
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", scene.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    // I_yy = Σ m (x² + z²) from the body-frame positions (bohr) and masses (m_e).
    let m = H2oRigid;
    let mut r = SMatrix::<f64, 3, 3>::zeros();
    m.positions(&Default::default(), &mut r);
    let masses = m.masses();
    let i_yy: f64 = (0..3).map(|i| masses[i] * (r[(0, i)].powi(2) + r[(2, i)].powi(2))).sum();
    let omega = 20.0 / i_yy; // rad per ħ/E_h

    let csv = std::fs::read_to_string(dir.join("out/trajectory.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header,
        [
            "t",
            "euler_phi",
            "euler_theta",
            "euler_psi",
            "pe_phi",
            "pe_theta",
            "pe_psi",
            "Jx",
            "Jy",
            "Jz",
            "H",
            "euler_phi_unwrapped",
            "euler_psi_unwrapped"
        ]
    );
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    let phi0 = 30f64.to_radians();
    let mut worst: f64 = 0.0;
    for row in &rows {
        let t_au = row[0] / AU_TIME_IN_FS;
        let (phi, phi_u, psi_u) = (row[1], row[11], row[12]);
        worst = worst.max((phi_u - (phi0 + omega * t_au)).abs());
        assert!(phi > -std::f64::consts::PI && phi <= std::f64::consts::PI, "raw φ = {phi}");
        let turns = (phi_u - phi) / std::f64::consts::TAU;
        assert!((turns - turns.round()).abs() < 1e-9, "unwrapped φ − φ = {turns} turns");
        assert!(psi_u.abs() < 1e-9, "ψ stays 0: {psi_u}");
    }
    assert!(worst < 1e-7, "unwrapped φ is φ(0) + ω t to {worst:e} rad");
    let last = rows.last().unwrap()[11];
    assert!(last > phi0 + 5.0 * std::f64::consts::TAU, "more than 5 turns: {last}");

    let units: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/trajectory.units.json")).unwrap()).unwrap();
    assert_eq!(units["time_unit"], "fs");
    assert_eq!(units["columns"]["t"], "fs");
    assert_eq!(units["columns"]["euler_phi_unwrapped"], "rad");
    assert_eq!(units["columns"]["pe_phi"], "hbar");
    assert_eq!(units["order"].as_array().unwrap().len(), header.len());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A trajectory.csv written by `rovib run` (prefixed columns, Euler momenta) is a states file:
/// ensemble trajectory i starts from its row i.
#[test]
fn a_trajectory_csv_is_read_back_as_a_states_file() {
    let dir = temp_dir("states");
    let run_scene = dir.join("run.toml");
    std::fs::write(
        &run_scene,
        "molecule = \"h2o\"\n[units]\ntime = \"fs\"\n[initial]\nq = { r1 = 1.0 }\neuler = [0.3, 1.1, -0.4]\n\
         j = [3.0, 8.0, 2.0]\n[run]\nend = 3.0\noutput_interval = 1.0\neuler_unwrapped = true\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", run_scene.to_str().unwrap(), "--out", dir.join("run").to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let ensemble = dir.join("ensemble.toml");
    std::fs::write(
        &ensemble,
        "molecule = \"h2o\"\n[ensemble]\ntrajectories = 4\nmethod = \"file\"\nfile = \"run/trajectory.csv\"\n\
         keep_trajectories = 1\n[statistics]\nmeans = [\"H\"]\n[run]\nend = 1.0\noutput_interval = 1.0\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["ensemble", ensemble.to_str().unwrap(), "--out", dir.join("ens").to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = |path: PathBuf| -> Vec<Vec<f64>> {
        let text = std::fs::read_to_string(path).unwrap();
        text.lines().skip(1).map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect()
    };
    let source = rows(dir.join("run/trajectory.csv"));
    for i in 0..4 {
        let first = &rows(dir.join(format!("ens/trajectories/{i}/trajectory.csv")))[0];
        // q and p exactly; Euler angles, their momenta and H through the quaternion to round-off.
        assert_eq!(first[1..7], source[i][1..7], "trajectory {i}");
        for c in 7..14 {
            assert!(
                (first[c] - source[i][c]).abs() < 1e-12 * source[i][c].abs().max(1.0),
                "trajectory {i}, column {c}"
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
