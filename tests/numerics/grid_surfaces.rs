//! Tabulated surfaces in scenes (`[potential] grid`, `src/surfaces/grid.rs`): molecules/arn2.toml's
//! surface sampled on a grid gives the definition's trajectory to a tolerance that shrinks with
//! the grid step; the policy outside the grid is honoured (a located stop, or the edge cubic
//! continued); every key and every binding mistake is a located error; ensembles run on a grid one
//! trajectory at a time and say so.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use rovib::Error;
use rovib::molecules::Arn2;
use rovib::runtime::diagnostic::Source;
use rovib::runtime::grid::{GridPotential, Outside, parse};
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::integrate::{Dop853Options, Method, OdeSystem, solve};
use rovib::runtime::nalgebra::{SVector, Vector3};
use rovib::runtime::surface::{Dipole, WithPotential};
use rovib::runtime::{Kinematics, Molecule, PhaseState};

use crate::surfaces::file_error;

fn tmp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-grids-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// arn2's surface (and dipole) on a grid over R ∈ [r_low, r_high] bohr (`nr` points) and
/// θ ∈ [0, 180] degrees (`nt` points), energies in cm-1, in the grid file format.
fn arn2_grid(r_low: f64, r_high: f64, nr: usize, nt: usize) -> String {
    let mut text = String::from(
        "# arn2 (molecules/arn2.toml) sampled\nR[bohr], theta[deg], energy[cm-1], mu_x[e*bohr], mu_y[e*bohr], mu_z[e*bohr]\n",
    );
    let cm = rovib::runtime::units::HARTREE_IN_WAVENUMBERS;
    for i in 0..nr {
        let r = r_low + (r_high - r_low) * i as f64 / (nr - 1) as f64;
        for j in 0..nt {
            let deg = 180.0 * j as f64 / (nt - 1) as f64;
            let q = SVector::from([r, deg.to_radians()]);
            let mut mu = Vector3::zeros();
            Arn2.moment(&q, &mut mu);
            text.push_str(&format!(
                "{r:.12}, {deg:.12}, {:.17e}, {:.17e}, {:.17e}, {:.17e}\n",
                Arn2.potential(&q) * cm,
                mu[0],
                mu[1],
                mu[2]
            ));
        }
    }
    text
}

fn arn2_potential(text: &str, outside: Outside) -> GridPotential<2> {
    let grid = parse(&Source { path: "arn2.csv", text }).unwrap();
    GridPotential::new(&grid, &Arn2.coordinates(), outside).unwrap()
}

/// The start of tests/numerics/surfaces.rs: off the minimum, turning (J = 4 ħ).
fn start() -> PhaseState<2> {
    PhaseState {
        q: SVector::from([6.9, 80f64.to_radians()]),
        p: SVector::from([0.0, 1.5]),
        euler: Vector3::new(0.3, 1.2, -0.4),
        pe: Vector3::new(0.5, -1.0, 4.0),
    }
}

/// The states at 21 output times over 10 000 a.u. (0.24 ps), DOP853 at tolerance 1e-12.
fn trajectory<M: Molecule<2, 3>>(m: &M) -> Vec<Vec<f64>> {
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
    solve(&mut system, &method, 0.0, &y0, 10_000.0, 500.0, &mut observe).unwrap();
    states
}

fn max_q_difference(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).flat_map(|(x, y)| (0..2).map(move |k| (x[k] - y[k]).abs())).fold(0.0, f64::max)
}

#[test]
fn a_trajectory_on_the_grid_approaches_the_definitions_as_the_grid_is_refined() {
    let exact = trajectory(&Arn2);
    let (first, last) = (&exact[0], &exact[exact.len() - 1]);
    assert!((first[0] - last[0]).abs() > 0.05 && (first[1] - last[1]).abs() > 0.05, "{first:?} {last:?}");
    let mut differences = Vec::new();
    // Steps 0.1 bohr × 3° and half that.
    for (nr, nt) in [(66, 61), (131, 121)] {
        let p = arn2_potential(&arn2_grid(4.5, 11.0, nr, nt), Outside::Error);
        differences.push(max_q_difference(&trajectory(&WithPotential { molecule: Arn2, potential: p }), &exact));
    }
    eprintln!(
        "max |Δq| over 10 000 a.u., grid vs definition: h = 0.1 bohr × 3°: {:e}; h/2: {:e}",
        differences[0], differences[1]
    );
    assert!(differences[0] < 2e-3, "{differences:?}");
    assert!(differences[1] < differences[0] / 6.0, "{differences:?}");
}

#[test]
fn the_grid_dipole_is_the_definitions_dipole_between_points() {
    let p = arn2_potential(&arn2_grid(4.5, 11.0, 66, 61), Outside::Error);
    let m = WithPotential { molecule: Arn2, potential: p };
    let q = SVector::from([6.93, 1.234]);
    let (mut a, mut b) = (Vector3::zeros(), Vector3::zeros());
    m.dipole().expect("the grid's dipole").moment(&q, &mut a);
    Arn2.moment(&q, &mut b);
    assert!((a - b).norm() < 1e-6 * b.norm(), "{a:?} {b:?}");
}

const SCENE: &str = "molecule = \"arn2\"\n\
[units]\nangle = \"deg\"\n\
[initial]\nq = { R = 6.9, theta = 80 }\np = { R = 3, theta = 1.5 }\n\
[integrator]\nmethod = \"dop853\"\nrtol = 1e-10\natol = 1e-10\n\
[run]\nend = 2000\noutput_interval = 100\n";

/// Writes `grid` as dir/pes.csv, then the scene with its `[potential]` table, and runs it.
fn run_scene(dir: &Path, grid: &str, scene: &str, potential: &str) -> Result<rovib::RunReport, Error> {
    std::fs::write(dir.join("pes.csv"), grid).unwrap();
    crate::surfaces::run_scene(dir, scene, potential)
}

#[test]
fn outside_error_stops_the_run_with_the_grids_edge_and_extrapolate_continues() {
    let dir = tmp("outside");
    // R up to 7.0 bohr: the start (6.9 bohr, moving out) leaves the grid near t = 1000 a.u.
    let grid = arn2_grid(4.5, 7.0, 26, 37);
    let e = match run_scene(&dir, &grid, SCENE, "grid = \"pes.csv\"\noutside = \"error\"") {
        Err(e) => e.to_string(),
        Ok(_) => panic!("the run left the grid and went on"),
    };
    let line = SCENE.lines().count() + 3;
    assert!(e.contains("the run stopped") && e.contains("potential gradient"), "{e}");
    assert!(e.contains("pes.csv (R in [4.5, 7] bohr, theta in [0, 180] deg) with outside = \"error\""), "{e}");
    assert!(e.contains(&format!("scene.toml:{line}")), "{e}");
    // The edge cubic continued: the run goes on, past R = 7.0 bohr.
    run_scene(&dir, &grid, SCENE, "grid = \"pes.csv\"\noutside = \"extrapolate\"").unwrap();
    let csv = std::fs::read_to_string(dir.join("out/trajectory.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let r = header.iter().position(|h| *h == "q_R").unwrap();
    let rows: Vec<f64> = csv.lines().skip(1).map(|l| l.split(',').nth(r).unwrap().parse().unwrap()).collect();
    assert_eq!(rows.len(), 21);
    assert!(rows.iter().any(|&x| x > 7.05), "{rows:?}");
}

#[test]
fn a_scene_on_a_grid_follows_the_definitions_trajectory() {
    let dir = tmp("scene");
    run_scene(&dir, &arn2_grid(4.5, 11.0, 66, 61), SCENE, "grid = \"pes.csv\"\noutside = \"error\"").unwrap();
    let on_grid = std::fs::read_to_string(dir.join("out/trajectory.csv")).unwrap();
    let plain = tmp("scene-plain");
    std::fs::write(plain.join("scene.toml"), SCENE).unwrap();
    rovib::simulation::run(&plain.join("scene.toml"), Some(&plain.join("out"))).unwrap();
    let exact = std::fs::read_to_string(plain.join("out/trajectory.csv")).unwrap();
    let header: Vec<&str> = exact.lines().next().unwrap().split(',').collect();
    let r = header.iter().position(|h| *h == "q_R").unwrap();
    let column =
        |s: &str| -> Vec<f64> { s.lines().skip(1).map(|l| l.split(',').nth(r).unwrap().parse().unwrap()).collect() };
    let (a, b) = (column(&on_grid), column(&exact));
    assert_eq!(a.len(), b.len());
    let d = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    assert!(d < 1e-4, "max |ΔR| = {d:e}");
}

#[test]
fn grid_keys_and_bindings_are_refused_at_their_place() {
    let dir = tmp("keys");
    let grid = arn2_grid(4.5, 11.0, 14, 13);
    let line = SCENE.lines().count() + 2;
    let e = file_error(run_scene(&dir, &grid, SCENE, "grid = \"pes.csv\""));
    assert!(e.line == line && e.message.contains("needs `outside`"), "{e}");
    let e = file_error(run_scene(&dir, &grid, SCENE, "grid = \"pes.csv\"\noutside = \"clamp\""));
    assert!(e.line == line + 1 && e.message.contains("clamp") && e.help.contains("extrapolate"), "{e}");
    let e = file_error(run_scene(&dir, &grid, SCENE, "outside = \"error\""));
    assert!(e.line == line && e.message.contains("no `potential.grid`"), "{e}");
    let e = file_error(run_scene(&dir, &grid, SCENE, "grid = \"\"\noutside = \"error\""));
    assert!(e.line == line && e.message.contains("empty"), "{e}");
    let e = file_error(run_scene(&dir, &grid, SCENE, "grid = \"pes.csv\"\noutside = \"error\"\nlibrary = \"lib.so\""));
    assert!(e.line == line + 2 && e.message.contains("both replace"), "{e}");
    let e =
        file_error(run_scene(&dir, &grid, SCENE, "grid = \"pes.csv\"\noutside = \"error\"\nparameters = { a = 1 }"));
    assert!(e.line == line + 2 && e.message.contains("replaces"), "{e}");
    let e = file_error(run_scene(&dir, &grid, SCENE, "grid = \"nowhere.csv\"\noutside = \"error\""));
    assert!(e.line == line && e.message.contains("cannot read the grid file"), "{e}");
    let e = file_error(run_scene(&dir, &grid, SCENE, "grid = \"pes.csv\"\noutside = \"error\"\noutisde = 1"));
    assert!(e.line == line + 2 && e.message.contains("outisde"), "{e}");
    // In the grid file: an axis that is not a coordinate, a length in degrees.
    let e = file_error(run_scene(
        &dir,
        &grid.replace("theta[deg]", "phi[deg]"),
        SCENE,
        "grid = \"pes.csv\"\noutside = \"error\"",
    ));
    assert!(e.path.ends_with("pes.csv") && (e.line, e.column) == (2, 10) && e.message.contains("`phi`"), "{e}");
    assert!(e.help.contains("R, theta"), "{e}");
    let e = file_error(run_scene(
        &dir,
        &grid.replace("R[bohr]", "R[deg]"),
        SCENE,
        "grid = \"pes.csv\"\noutside = \"error\"",
    ));
    assert!(e.path.ends_with("pes.csv") && (e.line, e.column) == (2, 1) && e.message.contains("a length"), "{e}");
    // A grid that misses a coordinate: refused, never taken as constant along it.
    let one = "R[bohr] energy[hartree]\n5 0\n6 0\n7 0\n8 0\n";
    let e = file_error(run_scene(&dir, one, SCENE, "grid = \"pes.csv\"\noutside = \"error\""));
    assert!(e.line == line && e.message.contains("coordinate `theta` is not an axis of the grid"), "{e}");
    // A grid error is located in the grid file.
    let mut lines: Vec<String> = grid.lines().map(str::to_owned).collect();
    let mut fields: Vec<&str> = lines[2].split(", ").collect();
    fields[2] = "NaN";
    lines[2] = fields.join(", ");
    let e = file_error(run_scene(&dir, &lines.join("\n"), SCENE, "grid = \"pes.csv\"\noutside = \"error\""));
    assert!(e.path.ends_with("pes.csv") && e.line == 3, "{e}");
}

#[test]
fn an_ensemble_on_a_grid_runs_one_trajectory_at_a_time_and_says_so() {
    let dir = tmp("ensemble");
    std::fs::write(dir.join("pes.csv"), arn2_grid(4.5, 11.0, 66, 61)).unwrap();
    let text = "molecule = \"arn2\"\n[ensemble]\ntrajectories = 8\nseed = 4\nmethod = \"thermal\"\ntemperature = 10\n\
                region = { energy_cap = 0.0002 }\n[statistics]\nmeans = [\"R\"]\n[run]\nend = 400\noutput_interval = 100\n\
                [potential]\ngrid = \"pes.csv\"\noutside = \"error\"\n";
    let scene = rovib::scene::parse_scene(dir.join("ensemble.toml").to_str().unwrap(), text).unwrap();
    let mut options = rovib::ensemble::EnsembleOptions::new(dir.join("out"));
    options.threads = Some(2);
    let report = rovib::ensemble::run_ensemble(&scene, &options).unwrap();
    assert_eq!(report.outcome.completed, 8);
    assert!(
        report.lanes_note.as_deref().is_some_and(|n| n.contains("grid file") && n.contains("one trajectory at a time"))
    );
}
