//! How `rovib run` ends a run that cannot go on, tested through the binary as a user runs it:
//! at once, with one line on stderr naming the time and the last state, the output written so
//! far kept (complete rows, no NaN), and `summary.json` saying `"status": "failed"` with the
//! error. Every scene here is written to a temporary directory.
//!
//! * a bend closer to linear than the conditioning threshold (CO2; default and scene threshold);
//! * a non-finite right-hand side (a fixed step beyond the stability limit drives a Morse
//!   exponential into overflow);
//! * a collapsing step size (DOP853 `min_step`);
//! * a non-finite energy found at an output time (the one path that does not print the state);
//! * too many steps: covered by `a_failed_run_keeps_its_output_and_says_where_it_stopped` in
//!   `tests/scenes.rs`, not repeated here.
//!
//! And the case that must NOT stop: CO2 with J = 0 bends through linear and completes.
//! `STABILITY.md` records the figures.

use crate::common;

use common::cli::temp_dir;
use std::path::Path;
use std::process::{Command, Output};

/// Writes `scene` into `dir` and runs it, with the output in `dir/out`.
fn run_scene(dir: &Path, scene: &str) -> Output {
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene).unwrap();
    Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", path.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap(), "--quiet"])
        .output()
        .unwrap()
}

/// The one-line error of a failed run.
fn error_line(out: &Output) -> String {
    assert!(!out.status.success(), "the run should fail: {}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8(out.stderr.clone()).unwrap();
    assert_eq!(err.trim_end().lines().count(), 1, "one line on stderr:\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains("; output so far is in "), "{err}");
    err.trim_end().to_owned()
}

/// The rows of `trajectory.csv`: each as complete as the header, every number finite, the file
/// ending with a newline (no cut-off row).
fn trajectory(dir: &Path) -> Vec<Vec<f64>> {
    let csv = std::fs::read_to_string(dir.join("out/trajectory.csv")).unwrap();
    assert!(csv.ends_with('\n'), "the last row is complete");
    let mut lines = csv.lines();
    let columns = lines.next().unwrap().split(',').count();
    lines
        .map(|line| {
            let row: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
            assert_eq!(row.len(), columns, "a complete row: {line}");
            assert!(row.iter().all(|x| x.is_finite()), "no NaN or infinity in the output: {line}");
            row
        })
        .collect()
}

/// `lab.xyz` holds as many complete frames as the trajectory has rows.
fn check_lab_frames(dir: &Path, atoms: usize, rows: usize) {
    let xyz = std::fs::read_to_string(dir.join("out/lab.xyz")).unwrap();
    assert!(xyz.ends_with('\n'));
    assert_eq!(xyz.lines().count(), rows * (atoms + 2), "{rows} complete frames");
    assert!(!xyz.to_lowercase().contains("nan") && !xyz.contains("inf"), "no NaN in lab.xyz");
}

fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("out/summary.json")).unwrap()).unwrap()
}

/// The scene time (fs) in `(at t = T fs)` of an error line.
fn time_fs(err: &str) -> f64 {
    assert_eq!(err.matches("t = ").count(), 1, "the time is given once: {err}");
    let start = err.find("t = ").expect("the time in the scene's unit") + "t = ".len();
    let rest = &err[start..];
    rest[..rest.find(" fs").expect("with its unit")].parse().unwrap()
}

/// The vector after `marker` in an error line, e.g. `q = [..]`.
fn vector_after(err: &str, marker: &str) -> Vec<f64> {
    let start = err.find(marker).unwrap_or_else(|| panic!("`{marker}` in {err}")) + marker.len();
    let rest = &err[start..];
    rest[..rest.find(']').unwrap()].split(", ").map(|x| x.parse().unwrap()).collect()
}

/// CO2 from 150° at rest internally, rotating about its O–C–O axis with `J_X` ħ; `EXTRA_RUN`
/// and `EXTRA_INTEGRATOR` add keys.
const CO2: &str = r#"molecule = "co2"

[units]
length = "angstrom"
angle = "deg"
time = "fs"

[initial]
q = { r1 = 1.17, r2 = 1.16, alpha = 150.0 }
j = [J_X, 0.0, 0.0]

[integrator]
method = "dop853"
rtol = 1e-10
atol = 1e-10
EXTRA_INTEGRATOR

[run]
end = END
output_interval = 0.5
EXTRA_RUN
"#;

fn co2(j_x: &str, end: &str, extra_integrator: &str, extra_run: &str) -> String {
    CO2.replace("J_X", j_x)
        .replace("END", end)
        .replace("EXTRA_INTEGRATOR", extra_integrator)
        .replace("EXTRA_RUN", extra_run)
}

const CO2_LAYOUT: &str =
    "last accepted state [r1, r2, alpha, p_r1, p_r2, p_alpha, quaternion w, x, y, z, J_x, J_y, J_z] = [";

/// Checks what every failed run must leave behind and returns the rows kept.
fn failed_run(dir: &Path, err: &str, atoms: usize) -> Vec<Vec<f64>> {
    let rows = trajectory(dir);
    assert!(!rows.is_empty(), "at least the initial row is kept");
    check_lab_frames(dir, atoms, rows.len());
    let s = summary(dir);
    assert_eq!(s["status"], "failed");
    let recorded = s["error"].as_str().unwrap();
    assert!(err.starts_with("error: ") && err[7..].starts_with(recorded), "summary error {recorded:?} vs {err:?}");
    rows
}

#[test]
fn a_bend_closer_to_linear_than_the_threshold_stops_naming_time_q_and_the_inertia_tensor() {
    let dir = temp_dir("stress", "linear");
    // J_x = 1e-5 ħ would bring the bend to δ = π − α ≈ 3e-7 rad; the default threshold (relative
    // pivot of I 1e-12) is reached at δ ≈ 5.4e-6 rad.
    let err = error_line(&run_scene(&dir, &co2("1e-5", "60.0", "", "cartesian_fallback = false")));
    assert!(
        err.starts_with("error: the run stopped: the inertia tensor I is singular or not positive definite at q = ["),
        "{err}"
    );
    let q = vector_after(&err, "at q = [");
    assert!((std::f64::consts::PI - q[2]).abs() < 6e-6, "stopped at the closest approach, q = {q:?}");
    // Measured: t = 12.753 fs (527.24 ħ/E_h), α = π − 5.3e-6.
    let t = time_fs(&err);
    assert!((12.0..13.5).contains(&t), "t = {t} fs");
    let state = vector_after(&err, CO2_LAYOUT);
    assert_eq!(state.len(), 13);
    let rows = failed_run(&dir, &err, 3);
    let last = rows.last().unwrap()[0];
    assert!(last <= t && last + 0.5 > t, "rows up to the last output before t: {last}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_stricter_scene_threshold_stops_the_bend_earlier_as_ill_conditioned() {
    let dir = temp_dir("stress", "threshold");
    // J_x = 0.1 ħ reaches δ ≈ 3.4e-3 rad (relative pivot 4e-7): fine by default, below 1e-6.
    let err =
        error_line(&run_scene(&dir, &co2("0.1", "60.0", "", "min_metric_pivot = 1e-6\ncartesian_fallback = false")));
    assert!(err.contains("the inertia tensor I is ill-conditioned at q = ["), "{err}");
    assert!(err.contains("below the threshold 1e-6"), "{err}");
    // Measured: t = 12.687 fs, relative pivot 9.8e-7, α = π − 5.4e-3.
    let t = time_fs(&err);
    assert!((12.0..13.5).contains(&t), "t = {t} fs");
    assert_eq!(vector_after(&err, CO2_LAYOUT).len(), 13);
    failed_run(&dir, &err, 3);
    assert_eq!(summary(&dir)["min_metric_pivot"], 1e-6);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn zero_angular_momentum_co2_bends_through_linear_and_completes() {
    let dir = temp_dir("stress", "zero");
    let out = run_scene(&dir, &co2("0.0", "100.0", "", "cartesian_fallback = false"));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = trajectory(&dir);
    assert_eq!(rows.len(), 201);
    let pi = std::f64::consts::PI;
    let crossings = rows.windows(2).filter(|w| (w[0][3] - pi) * (w[1][3] - pi) < 0.0).count();
    // Measured: 4 crossings, α up to π + 0.428, relative energy error 2.2e-10 (rtol 1e-10).
    assert!(crossings >= 4, "{crossings} passes through α = π");
    let s = summary(&dir);
    assert_eq!(s["status"], "completed");
    assert!(s["conservation"]["max_relative_energy_error"].as_f64().unwrap() < 1e-9);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Water as in `scenes/h2o.toml`, integrated by RK4 at `STEP` fs with outputs every `OUTPUT` fs.
const H2O_RK4: &str = r#"molecule = "h2o"

[units]
length = "angstrom"
angle = "deg"
time = "fs"

[initial]
q = { r1 = 1.0078, r2 = 0.95785, alpha = 104.5 }
j = [3.0, 8.0, 2.0]

[integrator]
method = "rk4"
step = STEP

[run]
end = 200.0
output_interval = OUTPUT
"#;

#[test]
fn a_step_beyond_the_stability_limit_overflows_the_morse_potential_and_stops() {
    let dir = temp_dir("stress", "nonfinite");
    // RK4 is stable for ω h < 2.8: for the O–H stretch (3830 cm⁻¹) h < 3.9 fs. At 4.2 fs the
    // stretch amplitude grows each step until a stage pushes a bond deep into the repulsive wall
    // and exp(−a (r − re)) overflows.
    // The energy guard would stop it earlier (see below): raised out of the way here.
    let scene =
        H2O_RK4.replace("STEP", "4.2").replace("OUTPUT", "4.2").replace("[run]", "[run]\nmax_energy_error = 1e300");
    let err = error_line(&run_scene(&dir, &scene));
    assert!(err.starts_with("error: the run stopped: non-finite potential gradient ∂U/∂q at t = "), "{err}");
    // Measured: t = 79.8 fs; 19 rows kept (t = 0 … 75.6 fs).
    let t = time_fs(&err);
    assert!((70.0..90.0).contains(&t), "t = {t} fs");
    let state = vector_after(
        &err,
        "last accepted state [r1, r2, alpha, p_r1, p_r2, p_alpha, quaternion w, x, y, z, J_x, J_y, J_z] = [",
    );
    assert!(state.len() == 13 && state.iter().all(|x| x.is_finite()), "{state:?}");
    let rows = failed_run(&dir, &err, 3);
    assert!(rows.len() >= 10, "{} rows", rows.len());
    let last = rows.last().unwrap()[0];
    assert!(last < t && last + 4.2 + 1e-9 >= t, "rows up to the last step before t: {last}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_collapsing_step_size_stops_the_run() {
    let dir = temp_dir("stress", "minstep");
    // J_x = 1e-3 ħ: near the closest approach to linear (δ ≈ 3.4e-5 rad) the molecule spins about
    // its axis at ω_x ≈ 44 rad per ħ/E_h and DOP853's steps fall to about 3e-3 ħ/E_h; elsewhere
    // they are 0.04 ħ/E_h (the first) to several ħ/E_h. min_step = 0.0005 fs = 0.021 ħ/E_h.
    let err = error_line(&run_scene(&dir, &co2("1e-3", "60.0", "min_step = 0.0005", "cartesian_fallback = false")));
    assert!(err.starts_with("error: the run stopped: the step size fell to "), "{err}");
    // In the scene's unit, like min_step itself.
    assert!(err.contains(" fs, below integrator.min_step, at t = "), "{err}");
    // Measured: t = 12.751 fs, step 1.7e-2 ħ/E_h.
    let t = time_fs(&err);
    assert!((12.0..13.5).contains(&t), "t = {t} fs");
    assert_eq!(vector_after(&err, CO2_LAYOUT).len(), 13);
    let rows = failed_run(&dir, &err, 3);
    let last = rows.last().unwrap()[0];
    assert!(last <= t && last + 0.5 > t, "rows up to the last output before t: {last}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_non_finite_energy_at_an_output_time_stops_the_run() {
    let dir = temp_dir("stress", "output");
    // RK4 at 20 fs: the first step lands where U(q) overflows; the right-hand side was finite at
    // every stage, so the failure is found when the output time records H.
    let scene =
        H2O_RK4.replace("STEP", "20.0").replace("OUTPUT", "20.0").replace("[run]", "[run]\nmax_energy_error = 1e300");
    let err = error_line(&run_scene(&dir, &scene));
    assert!(err.starts_with("error: the run stopped: non-finite potential U(q) at t = 20 fs; state ["), "{err}");
    assert_eq!(time_fs(&err), 20.0);
    let rows = failed_run(&dir, &err, 3);
    assert_eq!(rows.len(), 1, "only the initial row");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_run_whose_energy_runs_away_stops_instead_of_completing() {
    let dir = temp_dir("stress", "guard");
    // RK4 at 4.2 fs, just past its stability limit for the O–H stretch: the energy grows each
    // step. Without the guard the run would overflow only at 79.8 fs, and at 5 fs it would
    // "complete" with a relative energy error of 4e58; the guard stops it at the first output
    // time where |ΔH|/|H(0)| exceeds run.max_energy_error (default 1 %).
    let err = error_line(&run_scene(&dir, &H2O_RK4.replace("STEP", "4.2").replace("OUTPUT", "4.2")));
    assert!(err.starts_with("error: the run stopped: the energy changed by "), "{err}");
    assert!(err.contains("more than run.max_energy_error = 1e-2"), "{err}");
    let t = time_fs(&err);
    assert!(t < 10.0, "stopped at t = {t} fs");
    let rows = failed_run(&dir, &err, 3);
    assert!(rows.iter().all(|r| r.iter().all(|x| x.is_finite())));
    std::fs::remove_dir_all(&dir).unwrap();
}
