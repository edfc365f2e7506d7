//! `rovib run` as a careless or hostile user drives it: stale files of an earlier run, two runs
//! into one directory, SIGINT/SIGTERM, a full disk, an energy guard at H(0) ≈ 0.

use crate::common;

use common::cli::rovib;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn dir(name: &str) -> PathBuf {
    common::cli::temp_dir("run-safety", name)
}

/// A vibrating, rotating water scene with the given end time (fs) and outputs.
fn scene(d: &Path, name: &str, end: f64, outputs: &str) -> PathBuf {
    let text = format!(
        "molecule = \"h2o\"\n[units]\nlength = \"angstrom\"\nangle = \"deg\"\ntime = \"fs\"\n\
         [initial]\nq = {{ r1 = 1.0078, r2 = 0.95785, alpha = 104.5 }}\neuler = [0.0, 90.0, 0.0]\nj = [3.0, 8.0, 2.0]\n\
         [run]\nend = {end}\noutput_interval = 0.5\noutputs = [{outputs}]\n"
    );
    let path = d.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn a_run_leaves_no_file_of_an_earlier_run() {
    let d = dir("stale");
    let out = d.join("out");
    let first = scene(&d, "first.toml", 5.0, "\"trajectory\", \"lab\", \"summary\"");
    let o = rovib(&["run", first.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("trajectory.csv").exists() && out.join("lab.xyz").exists());
    let second = scene(&d, "second.toml", 5.0, "\"summary\"");
    let o = rovib(&["run", second.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!out.join("trajectory.csv").exists(), "a trajectory.csv of the earlier run remains");
    assert!(!out.join("lab.xyz").exists(), "a lab.xyz of the earlier run remains");
    assert_eq!(summary(&out)["scene"], second.display().to_string());
    // No temporary or lock file is left behind.
    let mut names: Vec<String> =
        std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    names.sort();
    assert_eq!(names, ["summary.json"]);
}

/// Waits until `path` has more than `lines` lines (or 60 s).
fn wait_for_lines(path: &Path, lines: usize) {
    let begin = Instant::now();
    while std::fs::read_to_string(path).map_or(0, |t| t.lines().count()) <= lines {
        assert!(begin.elapsed() < Duration::from_secs(60), "{} never grew", path.display());
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// How long an interrupted run may take to finish its record and write its summary (a record
/// takes microseconds; the margin is for a loaded machine).
const STOP_LIMIT: Duration = Duration::from_secs(30);

/// Spawns a long run, checks that a second run into the same directory fails at once, sends
/// `signal`, and checks the outputs: whole rows and frames, summary "interrupted" at the last row.
fn interrupt_with(signal: &str) {
    let d = dir(signal);
    let out = d.join("out");
    let path = scene(&d, "long.toml", 4e5, "\"trajectory\", \"lab\", \"summary\"");
    let mut child = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // More than one 8 KB buffer of rows: the run is well under way.
    wait_for_lines(&out.join("trajectory.csv"), 100);

    let second = rovib(&["run", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]);
    let err = String::from_utf8(second.stderr).unwrap();
    assert!(!second.status.success());
    assert!(err.contains("in use by another run") && err.contains(&format!("process {}", child.id())), "{err}");

    let killed = Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status().unwrap();
    assert!(killed.success());
    // The run has about 8e5 records left: without the interrupt handling it would go on for
    // minutes, so a run that has not stopped within the limit has ignored the signal.
    let sent = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if sent.elapsed() > STOP_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the run did not stop within {STOP_LIMIT:?} of SIG{signal}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success(), "an interrupted run exits non-zero");
    assert!(err.contains("interrupted at t = "), "{err}");

    let s = summary(&out);
    assert_eq!(s["status"], "interrupted", "{s}");
    assert!(s["error"].is_null(), "{s}");
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    assert!(csv.ends_with('\n'), "trajectory.csv ends inside a row");
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    let columns = csv.lines().next().unwrap().split(',').count();
    assert!(rows.iter().all(|r| r.split(',').count() == columns));
    let last_t: f64 = rows.last().unwrap().split(',').next().unwrap().parse().unwrap();
    assert_eq!(s["t_reached"].as_f64().unwrap(), last_t, "{s}");
    assert_eq!(s["conservation"]["samples"].as_u64().unwrap(), rows.len() as u64);
    // lab.xyz: whole frames of 3 atoms (2 header lines + 3), as many as rows.
    let xyz = std::fs::read_to_string(out.join("lab.xyz")).unwrap();
    assert!(xyz.ends_with('\n'));
    assert_eq!(xyz.lines().count(), 5 * rows.len(), "lab.xyz has a partial frame or lost frames");
    assert!(!out.join(".rovib.lock").exists(), "the lock outlived the run");
    // The run writes hundreds of MB before the signal on a loaded machine: do not leave it.
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn sigint_finishes_the_record_and_writes_an_interrupted_summary() {
    interrupt_with("INT");
}

#[test]
fn sigterm_finishes_the_record_and_writes_an_interrupted_summary() {
    interrupt_with("TERM");
}

#[test]
fn a_full_disk_is_the_error_reported_and_the_summary_says_failed() {
    if !Path::new("/dev/full").exists() {
        return;
    }
    let d = dir("full");
    let out = d.join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::os::unix::fs::symlink("/dev/full", out.join("trajectory.csv")).unwrap();
    let path = scene(&d, "scene.toml", 200.0, "\"trajectory\", \"summary\"");
    let o = rovib(&["run", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success());
    assert!(err.contains("cannot write") && err.contains("trajectory.csv"), "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "failed", "{s}");
    let e = s["error"].as_str().unwrap();
    assert!(e.contains("trajectory.csv") && e.contains(&err_of_enospc()), "{s}");

    // summary.json cannot be written either: stderr has the first error and says so.
    std::fs::remove_file(out.join("summary.json")).unwrap();
    std::fs::create_dir(out.join("summary.json.tmp")).unwrap();
    let o = rovib(&["run", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success());
    assert!(err.contains("trajectory.csv") && err.contains(&err_of_enospc()), "{err}");
    assert!(err.contains("summary.json.tmp") && err.contains("no summary.json"), "{err}");
    assert!(!out.join("summary.json").exists());
}

/// How the OS words ENOSPC.
fn err_of_enospc() -> String {
    std::io::Error::from_raw_os_error(28).to_string()
}

#[test]
fn the_energy_guard_near_zero_energy_uses_the_absolute_floor_and_agrees_with_the_summary() {
    let d = dir("energy");
    let out = d.join("out");
    // Water at its minimum, almost at rest: H(0) ≈ 3e-22 hartree, round-off ≈ 5e-22 hartree.
    let path = d.join("near0.toml");
    std::fs::write(
        &path,
        "molecule = \"h2o\"\n[units]\ntime = \"fs\"\n[initial]\np = { r1 = 1e-9 }\n\
         [run]\nend = 50.0\noutput_interval = 1.0\noutputs = [\"summary\"]\n",
    )
    .unwrap();
    let o = rovib(&["run", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let c = &summary(&out)["conservation"];
    let abs = c["max_abs_energy_error_hartree"].as_f64().unwrap();
    assert_eq!(c["relative_to_hartree"].as_f64().unwrap(), 1e-3);
    assert_eq!(c["max_relative_energy_error"].as_f64().unwrap(), abs / 1e-3);

    // A guard that trips: the message's change is the summary's absolute error.
    let path = d.join("loose.toml");
    std::fs::write(
        &path,
        "molecule = \"h2o\"\n[units]\ntime = \"fs\"\n[initial]\np = { r1 = 1.0 }\n[integrator]\nmethod = \"rk4\"\nstep = 2.0\n\
         [run]\nend = 500.0\noutput_interval = 2.0\noutputs = [\"summary\"]\nmax_energy_error = 1e-6\n",
    )
    .unwrap();
    let o = rovib(&["run", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success(), "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
    let abs = s["conservation"]["max_abs_energy_error_hartree"].as_f64().unwrap();
    assert!(abs > 0.0, "{s}");
    assert!(err.contains(&format!("the energy changed by {abs:.3e} hartree")), "{abs:.3e} not in {err}");
}

/// The numbers of a CSV file's data rows.
fn rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

/// The atom positions (Å) of every frame of lab.xyz.
fn frames(path: &Path) -> Vec<Vec<[f64; 3]>> {
    let text = std::fs::read_to_string(path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let n: usize = lines[0].trim().parse().unwrap();
    lines
        .chunks(n + 2)
        .map(|f| {
            f[2..]
                .iter()
                .map(|l| {
                    let v: Vec<f64> = l.split_whitespace().skip(1).map(|x| x.parse().unwrap()).collect();
                    assert!(v.iter().all(|x| x.is_finite()), "{l}");
                    [v[0], v[1], v[2]]
                })
                .collect()
        })
        .collect()
}

/// `euler = [0, 0, 0]` (θ = 0, gimbal lock of the Euler angles) is a valid start: the run
/// integrates a quaternion. It runs, and it is the same motion as the start turned by 90° about
/// the lab x axis (rotational invariance, independent of how the orientation is stored): the
/// same q(t) and H(t), and lab positions turned by the same rotation.
#[test]
fn a_start_at_theta_zero_runs_and_is_the_turned_motion_of_a_start_at_ninety_degrees() {
    let d = dir("theta0");
    let run = |euler: &str| {
        let path = d.join(format!("e{}.toml", euler.len()));
        std::fs::write(
            &path,
            format!(
                "molecule = \"h2o\"\n[units]\nangle = \"deg\"\ntime = \"fs\"\n[initial]\nq = {{ r1 = 1.95, r2 = 1.8, alpha = 1.9 }}\n\
                 euler = {euler}\nj = [3.0, -2.0, 6.0]\n[integrator]\nmethod = \"dop853\"\nrtol = 1e-12\natol = 1e-12\n\
                 [run]\nend = 50.0\noutput_interval = 5.0\n"
            )
            .replace("angle = \"deg\"\n", ""),
        )
        .unwrap();
        let out = d.join(format!("out{}", euler.len()));
        let o = rovib(&["run", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]);
        assert!(o.status.success(), "{euler}: {}", String::from_utf8_lossy(&o.stderr));
        (rows(&out.join("trajectory.csv")), frames(&out.join("lab.xyz")))
    };
    let (a, lab_a) = run("[0, 0, 0]");
    let (b, lab_b) = run("[0, 1.5707963267948966, 0]");
    assert_eq!(a.len(), 11);
    // t, r1, r2, alpha, p_r1, p_r2, p_alpha, then the Euler angles and momenta (which differ), H.
    for (ra, rb) in a.iter().zip(&b) {
        for c in (0..7).chain([ra.len() - 1]) {
            assert!((ra[c] - rb[c]).abs() < 1e-9 * (1.0 + rb[c].abs()), "column {c}: {} vs {}", ra[c], rb[c]);
        }
    }
    // R(b) = Rx(90°) R(a) with R(a) = 1: (x, y, z) → (x, −z, y).
    for (fa, fb) in lab_a.iter().zip(&lab_b) {
        for (xa, xb) in fa.iter().zip(fb) {
            let turned = [xa[0], -xa[2], xa[1]];
            assert!(turned.iter().zip(xb).all(|(u, v)| (u - v).abs() < 1e-8), "{turned:?} vs {xb:?}");
        }
    }
}

/// A rigid molecule at rest with only a summary, and everything frozen with J = 0, have nothing
/// to integrate (a system of dimension 0): they run, and the
/// summary says the energy stayed H(0) = U(q) exactly.
#[test]
fn nothing_to_integrate_is_a_valid_run() {
    let d = dir("empty");
    for (name, text) in [
        ("rigid", "molecule = \"h2o_rigid\"\n[initial]\n[run]\nend = 100.0\noutputs = [\"summary\"]\n"),
        (
            "frozen",
            "molecule = \"h2o\"\n[initial]\n[run]\nend = 100.0\nfrozen = [\"r1\", \"r2\", \"alpha\"]\noutputs = [\"summary\"]\n",
        ),
        ("frozen-lab", "molecule = \"h2o\"\n[initial]\n[run]\nend = 100.0\nfrozen = [\"r1\", \"r2\", \"alpha\"]\n"),
    ] {
        let path = d.join(format!("{name}.toml"));
        std::fs::write(&path, text).unwrap();
        let out = d.join(name);
        let o = rovib(&["run", path.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"]);
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        let s = summary(&out);
        assert_eq!(s["status"], "completed", "{s}");
        assert_eq!(s["conservation"]["samples"], 101, "{s}");
        assert_eq!(s["conservation"]["max_abs_energy_error_hartree"], 0.0, "{s}");
        if name == "frozen-lab" {
            // At rest the lab positions never move.
            let f = frames(&out.join("lab.xyz"));
            assert!(f.iter().all(|frame| frame == &f[0]));
        }
    }
}

/// A scene read from /dev/zero would grow memory without bound: input files are read up to a
/// stated size.
#[test]
fn an_endless_input_file_is_refused_with_its_size_limit() {
    if !Path::new("/dev/zero").exists() {
        return;
    }
    let d = dir("zero");
    let o = rovib(&["run", "/dev/zero", "--out", d.join("out").to_str().unwrap(), "-q"]);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success());
    assert!(err.contains("cannot read /dev/zero: it is larger than 16777216 bytes (16 MiB)"), "{err}");
    let o = rovib(&["eval", "--molecule", "h2o", "--state", "/dev/zero"]);
    assert!(String::from_utf8(o.stderr).unwrap().contains("larger than 16777216 bytes"));
}

/// `rovib bench` with many output times would need 10¹⁵ bytes: it refuses with the numbers
/// before allocating.
#[test]
fn bench_refuses_a_scene_whose_states_would_not_fit_its_buffers() {
    let d = dir("bench");
    let path = d.join("many.toml");
    std::fs::write(
        &path,
        "molecule = \"h2o\"\n[initial]\nj = [1.0, 2.0, 3.0]\n[run]\nend = 1e9\noutput_interval = 1.0\nmax_outputs = 2000000000\n",
    )
    .unwrap();
    let o = rovib(&["bench", path.to_str().unwrap(), "--out", d.join("out").to_str().unwrap()]);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!o.status.success());
    assert!(!err.contains("panicked") && !err.contains("memory allocation"), "{err}");
    assert!(err.contains("1000000001 output times × 13 numbers × 8 bytes") && err.contains("limit of 64 MiB"), "{err}");
}

/// A molecule named `""` in a scene is refused as an empty name, not told to "add molecules/.toml".
#[test]
fn an_empty_molecule_name_is_not_told_to_add_molecules_dot_toml() {
    let d = dir("noname");
    let path = d.join("s.toml");
    std::fs::write(&path, "molecule = \"\"\n[initial]\n[run]\nend = 1.0\n").unwrap();
    let o = rovib(&["run", path.to_str().unwrap(), "--out", d.join("out").to_str().unwrap(), "-q"]);
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(err.contains("unknown molecule ``") && !err.contains("molecules/.toml"), "{err}");
    assert!(err.contains("s.toml:1:12"), "{err}");
}

/// Runs `rovib` with `args`, at most `limit`: its exit status and stderr (a hang fails).
fn rovib_within(args: &[&str], limit: Duration) -> (std::process::ExitStatus, String) {
    use std::io::Read as _;
    let mut child = Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let begin = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if begin.elapsed() > limit {
            let _ = child.kill();
            panic!("rovib {args:?} did not end within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    (status, err)
}

/// `run --resume` reads restart.json, and the trajectory.csv and lab.xyz it appends to, with a
/// bound: a link to /dev/zero in their place is refused at once, naming the file and the limit.
#[test]
fn a_resume_from_endless_files_is_refused_with_the_file_and_its_limit() {
    if !Path::new("/dev/zero").exists() {
        return;
    }
    let d = dir("resume-zero");
    let first = scene(&d, "first.toml", 2.0, "\"trajectory\", \"lab\", \"summary\", \"restart\"");
    let longer = scene(&d, "longer.toml", 4.0, "\"trajectory\", \"lab\", \"summary\", \"restart\"");
    let limit = Duration::from_secs(20);
    for (file, expected) in [
        ("restart.json", format!("it is larger than {} bytes", rovib::restart::MAX_RESTART_BYTES)),
        ("trajectory.csv", format!("line 1 is longer than {} bytes", rovib::output::MAX_LINE_BYTES)),
        ("lab.xyz", format!("line 1 is longer than {} bytes", rovib::output::MAX_LINE_BYTES)),
    ] {
        let out = d.join(file);
        let (s, err) = rovib_within(&["run", first.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"], limit);
        assert!(s.success(), "{err}");
        std::fs::remove_file(out.join(file)).unwrap();
        std::os::unix::fs::symlink("/dev/zero", out.join(file)).unwrap();
        let (s, err) = rovib_within(&["run", "--resume", out.to_str().unwrap(), longer.to_str().unwrap(), "-q"], limit);
        assert!(!s.success(), "a resume from /dev/zero as {file} succeeded");
        assert!(err.contains(&out.join(file).display().to_string()) && err.contains(&expected), "{file}: {err}");
    }
}
