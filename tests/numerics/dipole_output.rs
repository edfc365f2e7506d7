//! `dipole.csv`, the lab-frame dipole μ_lab(t) = S(t) μ(q(t)) of `rovib run`, checked
//! independently: for water's point charges, against Σ q_i (x_i − X) from the lab-frame positions
//! of `lab.xyz` (which go through positions and orientation, not through the dipole code); its
//! length against |μ(q)| in the body frame (a rotation keeps lengths); for rigid water, the
//! constant measured dipole. A molecule without a dipole surface is a located error.

use std::path::{Path, PathBuf};

use rovib::molecules::H2o;
use rovib::runtime::Kinematics;
use rovib::runtime::nalgebra::{SVector, Vector3};
use rovib::runtime::surface::Dipole;
use rovib::runtime::units::{BOHR_IN_ANGSTROM, DEBYE_IN_E_BOHR};
use rovib::simulation::run;

/// Water's charges from molecules/h2o.toml: +q_H on each H, −2 q_H on O (e).
const Q_H: f64 = 0.32922;

fn temp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-dipole-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write_scene(dir: &Path, molecule: &str, initial: &str, outputs: &str) -> PathBuf {
    let text = format!(
        "molecule = \"{molecule}\"\n[units]\nlength = \"angstrom\"\nangle = \"deg\"\ntime = \"fs\"\n\
         [initial]\n{initial}\n[integrator]\nmethod = \"dop853\"\nrtol = 1e-11\natol = 1e-11\n\
         [run]\nend = 30.0\noutput_interval = 0.5\noutputs = [{outputs}]\n"
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn csv_rows(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(str::to_owned).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    (header, rows)
}

/// Frames of lab.xyz: per frame, per atom, (element, position in bohr).
fn xyz_frames(path: &Path) -> Vec<Vec<(String, Vector3<f64>)>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let mut frames = Vec::new();
    while let Some(n) = lines.next() {
        let n: usize = n.trim().parse().unwrap();
        lines.next();
        let frame = (0..n)
            .map(|_| {
                let parts: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
                let x: Vec<f64> = parts[1..4].iter().map(|v| v.parse::<f64>().unwrap() / BOHR_IN_ANGSTROM).collect();
                (parts[0].to_owned(), Vector3::new(x[0], x[1], x[2]))
            })
            .collect();
        frames.push(frame);
    }
    frames
}

#[test]
fn water_dipole_matches_the_charges_on_the_lab_frame_positions() {
    let dir = temp_dir("water");
    // Vibrating (bend and stretch displaced), rotating about all three axes, with a drift.
    let initial = "positions = { O = [0.1, 0.2, -0.1], H1 = [1.0, 0.1, 0.0], H2 = [-0.2, 0.95, 0.05] }\n\
                   velocities = { O = [0.0001, 0.0, 0.0002], H1 = [0.0, 0.01, 0.003], H2 = [0.004, 0.0, -0.008] }";
    let scene = write_scene(&dir, "h2o", initial, "\"trajectory\", \"lab\", \"dipole\"");
    run(&scene, Some(&dir)).unwrap();
    let (header, dipole) = csv_rows(&dir.join("dipole.csv"));
    assert_eq!(header, ["t", "mu_x", "mu_y", "mu_z"]);
    let frames = xyz_frames(&dir.join("lab.xyz"));
    let (_, trajectory) = csv_rows(&dir.join("trajectory.csv"));
    assert_eq!(frames.len(), dipole.len());
    assert_eq!(trajectory.len(), dipole.len());
    assert_eq!(dipole.len(), 61);
    let masses = H2o.masses();
    let (mut worst, mut worst_norm, mut spread) = (0.0f64, 0.0f64, (f64::INFINITY, 0.0f64));
    for ((row, frame), traj) in dipole.iter().zip(&frames).zip(&trajectory) {
        let mu = Vector3::new(row[1], row[2], row[3]);
        // Independent: Σ q_i (x_i − X) with X the centre of mass of the lab positions.
        let total: f64 = masses.iter().sum();
        let com = frame.iter().zip(masses).map(|((_, x), m)| x * m).sum::<Vector3<f64>>() / total;
        let charges = [-2.0 * Q_H, Q_H, Q_H];
        assert_eq!(frame.iter().map(|(e, _)| e.as_str()).collect::<Vec<_>>(), ["O", "H", "H"]);
        let want: Vector3<f64> = frame.iter().zip(charges).map(|((_, x), q)| (x - com) * q).sum();
        // lab.xyz has 12 decimals in Å: 1e-12 Å ≈ 2e-12 bohr per coordinate.
        worst = worst.max((mu - want).amax());
        // |μ_lab| = |μ(q)|: the rotation keeps the length.
        let q = SVector::<f64, 3>::new(traj[1], traj[2], traj[3]);
        let mut body = Vector3::zeros();
        H2o.moment(&q, &mut body);
        worst_norm = worst_norm.max((mu.norm() - body.norm()).abs());
        spread = (spread.0.min(mu.norm()), spread.1.max(mu.norm()));
    }
    assert!(worst < 1e-10, "μ_lab against Σ q_i (x_i − X): {worst:e} e·bohr");
    assert!(worst_norm < 1e-12, "|μ_lab| against |μ(q)|: {worst_norm:e} e·bohr");
    // The check is not vacuous: |μ| changes as the molecule vibrates, μ_lab turns.
    assert!(spread.1 - spread.0 > 1e-3, "|μ| between {} and {}", spread.0, spread.1);
    let turned = (Vector3::new(dipole[0][1], dipole[0][2], dipole[0][3])
        - Vector3::new(dipole[60][1], dipole[60][2], dipole[60][3]))
    .norm();
    assert!(turned > 0.1, "μ_lab turned by {turned} e·bohr");
}

#[test]
fn rigid_water_keeps_its_measured_dipole_length_as_it_turns() {
    let dir = temp_dir("rigid");
    let scene = write_scene(&dir, "h2o_rigid", "euler = [10, 70, 30]\nj = [3, 7, 2]", "\"dipole\"");
    run(&scene, Some(&dir)).unwrap();
    assert!(!dir.join("trajectory.csv").exists() && !dir.join("lab.xyz").exists());
    let (_, rows) = csv_rows(&dir.join("dipole.csv"));
    for row in &rows {
        let norm = Vector3::new(row[1], row[2], row[3]).norm();
        assert!((norm / DEBYE_IN_E_BOHR - 1.8546).abs() < 1e-12, "|μ| = {} D", norm / DEBYE_IN_E_BOHR);
    }
    let first = Vector3::new(rows[0][1], rows[0][2], rows[0][3]);
    let last = Vector3::new(rows[60][1], rows[60][2], rows[60][3]);
    assert!((first - last).norm() > 0.1, "it turns");
}

#[test]
fn asking_a_molecule_without_a_dipole_is_a_located_error() {
    let dir = temp_dir("none");
    let scene = write_scene(&dir, "ch4", "", "\"dipole\"");
    let Err(e) = run(&scene, Some(&dir)) else { panic!("ch4 has no dipole") };
    let e = e.to_string();
    assert!(e.contains("molecule `ch4` has no dipole surface") && e.contains("scene.toml:1:"), "{e}");
    // `molecules/ch4.toml`, or the file under ROVIB_MOLECULES_DIR.
    assert!(e.contains(&format!("add a [dipole] table to {}", rovib::molecules::Ch4.source())), "{e}");
}
