//! What a run writes besides its reporters' files (`crate::report`: `trajectory.csv`, `lab.xyz`,
//! `dipole.csv`): the buffered [`OutputFile`] they write through, `summary.json`, and the energy
//! guard.
//!
//! Files are written as the run goes, through buffers that are flushed when the run ends, also
//! when it ends with an error or an interrupt, so that everything up to that point is kept.
//!
//! Stale files: before a run writes anything it removes every file of [`crate::report::run_files`] that it will
//! not write itself, and `summary.json` always (see [`remove_stale_outputs`]); the files it does
//! write are truncated when created. `summary.json` is written last, under a temporary name that
//! is renamed over the final one, so it is either absent or complete and always this run's.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::error::Error;
use crate::runtime::integrate::Stats;
use crate::runtime::nalgebra::Vector3;
use crate::scene::Scene;

pub use crate::report::{
    ASE_TIME_IN_FS, DipoleCsv, LAB_XYZ_PROPERTIES, LabXyz, TRAJECTORY_UNITS_FILE, TrajectoryCsv, trajectory_columns,
};

/// The longest line [`OutputFile::append`] reads from a file it continues: 1 MiB, far above a
/// trajectory.csv row (tens of columns of at most 25 characters) or a lab.xyz line.
pub const MAX_LINE_BYTES: u64 = 1 << 20;

/// A writer that remembers its path for error messages.
pub struct OutputFile {
    path: PathBuf,
    out: BufWriter<File>,
}

impl OutputFile {
    /// Creates (truncates) `dir/name`.
    pub fn create(dir: &Path, name: &str) -> Result<Self, Error> {
        let path = dir.join(name);
        let file = File::create(&path).map_err(|e| Error::io("cannot create", &path, e))?;
        Ok(OutputFile { path, out: BufWriter::new(file) })
    }

    /// Opens `dir/name` to append to it (a resumed run), after checking that its first line is
    /// `first_line` (the header this run would write), that it ends with a whole line and that
    /// it has `lines` lines (what the run being continued wrote, no more and no less).
    pub fn append(dir: &Path, name: &str, first_line: &str, lines: usize) -> Result<Self, Error> {
        use std::io::{BufRead as _, Read as _};
        let path = dir.join(name);
        // Read a line at a time, each of at most MAX_LINE_BYTES, and stop past `lines`: memory
        // stays bounded whatever the file is (a link to /dev/zero, a huge file).
        let file = File::open(&path).map_err(|e| Error::io("cannot read (to continue it)", &path, e))?;
        let mut reader = std::io::BufReader::new(file);
        let mut line = Vec::new();
        let mut found_lines = 0;
        loop {
            line.clear();
            let read = (&mut reader)
                .take(MAX_LINE_BYTES + 1)
                .read_until(b'\n', &mut line)
                .map_err(|e| Error::io("cannot read (to continue it)", &path, e))?;
            if read == 0 {
                break;
            }
            if !line.ends_with(b"\n") {
                if line.len() as u64 > MAX_LINE_BYTES {
                    return Err(Error::unusable(
                        path,
                        format!(
                            ": line {} is longer than {MAX_LINE_BYTES} bytes, the most a line of this output can be: \
                             it is not this run's file (resume into the directory of the run that wrote the restart \
                             file)",
                            found_lines + 1
                        ),
                    ));
                }
                return Err(Error::unusable(path, " ends inside a line; it was cut and cannot be continued"));
            }
            if found_lines == 0 {
                let found = String::from_utf8_lossy(&line);
                let found = found.trim_end_matches('\n').trim_end_matches('\r');
                if found != first_line {
                    return Err(Error::unusable(
                        &path,
                        format!(
                            " starts with `{found}`, not `{first_line}` as this run writes it: it is not this run's \
                             (resume into the directory of the run that wrote the restart file)"
                        ),
                    ));
                }
            }
            found_lines += 1;
            if found_lines > lines {
                return Err(Error::unusable(
                    path,
                    format!(
                        " has more than the {lines} lines the run that wrote the restart file left: it was changed \
                         or already continued"
                    ),
                ));
            }
        }
        if found_lines != lines {
            return Err(Error::unusable(
                path,
                format!(
                    " has {found_lines} lines, but the run that wrote the restart file left {lines}: it was changed \
                     or already continued"
                ),
            ));
        }
        let file = std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .map_err(|e| Error::io("cannot open (to continue it)", &path, e))?;
        Ok(OutputFile { path, out: BufWriter::new(file) })
    }

    /// Writes one line (a newline is added).
    pub fn line(&mut self, text: &str) -> Result<(), Error> {
        writeln!(self.out, "{text}").map_err(|e| Error::io("cannot write", &self.path, e))
    }

    /// Flushes the buffer to disk.
    pub fn flush(&mut self) -> Result<(), Error> {
        self.out.flush().map_err(|e| Error::io("cannot write", &self.path, e))
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// The smallest energy that relative energy errors are measured against, hartree: about kT at
/// 300 K (9.5e-4 hartree), a thermal energy scale below which H(0) (which can be 0 at a minimum
/// at rest) is no meaningful yardstick for a change. With the default `run.max_energy_error` =
/// 1e-2 a run starting at H(0) = 0 stops when |ΔH| exceeds 1e-5 hartree (2 cm⁻¹).
pub const ENERGY_SCALE_FLOOR: f64 = 1e-3;

/// What an energy change is relative to: max(|H(0)|, [`ENERGY_SCALE_FLOOR`]), hartree.
pub fn energy_scale(h0: f64) -> f64 {
    h0.abs().max(ENERGY_SCALE_FLOOR)
}

/// The energy guard of `rovib run` and `rovib ensemble`: `Err` with the message when
/// `|H − H(0)| / max(|H(0)|, ENERGY_SCALE_FLOOR)` exceeds `max_energy_error` or is NaN (a
/// non-finite energy is a runaway too). The message gives the absolute change, which is what
/// `summary.json` reports as `max_abs_energy_error_hartree`, and the scale it was divided by.
pub fn energy_guard(h0: f64, h: f64, max_energy_error: f64) -> Result<(), EnergyDrift> {
    let drift = (h - h0).abs() / energy_scale(h0);
    if drift.is_nan() || drift > max_energy_error {
        return Err(EnergyDrift { h0, h, max_energy_error });
    }
    Ok(())
}

/// An energy that moved more than `run.max_energy_error` allows ([`energy_guard`]); its message
/// gives the absolute change and the scale it was divided by.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error(
    "the energy changed by {:.3e} hartree from H(0) = {h0} hartree, {:.1e} relative to max(|H(0)|, \
     {ENERGY_SCALE_FLOOR:e} hartree) = {:e} hartree, more than run.max_energy_error = {max_energy_error:e} (the \
     step is too large or the tolerances too loose for this motion; reduce them)",
    (h - h0).abs(),
    (h - h0).abs() / energy_scale(*h0),
    energy_scale(*h0)
)]
pub struct EnergyDrift {
    /// H at the start, hartree.
    pub h0: f64,
    /// H when the guard tripped, hartree.
    pub h: f64,
    /// The allowed relative change.
    pub max_energy_error: f64,
}

/// Conservation diagnostics accumulated over the output times.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Conservation {
    /// H at the first output, hartree.
    pub initial_energy: Option<f64>,
    /// max |H(t) − H(0)| over output times, hartree.
    pub max_energy_error: f64,
    /// |J| at the first output, ħ.
    pub initial_j: f64,
    /// max | |J(t)| − |J(0)| |, ħ.
    pub max_j_change: f64,
    /// p_φ at the first output, ħ.
    pub initial_p_phi: f64,
    /// max |p_φ(t) − p_φ(0)|, ħ.
    pub max_p_phi_change: f64,
    /// The lab-frame angular momentum about the centre of mass at the first output, ħ.
    pub initial_lab_l: [f64; 3],
    /// max |L(t) − L(0)| (vector difference), ħ.
    pub max_lab_l_change: f64,
    /// How many output times contributed.
    pub samples: u64,
}

impl Conservation {
    /// Records one output time.
    pub fn record(&mut self, energy: f64, j_abs: f64, p_phi: f64, lab_l: [f64; 3]) {
        match self.initial_energy {
            None => {
                self.initial_energy = Some(energy);
                self.initial_j = j_abs;
                self.initial_p_phi = p_phi;
                self.initial_lab_l = lab_l;
            }
            Some(h0) => {
                self.max_energy_error = self.max_energy_error.max((energy - h0).abs());
                self.max_j_change = self.max_j_change.max((j_abs - self.initial_j).abs());
                self.max_p_phi_change = self.max_p_phi_change.max((p_phi - self.initial_p_phi).abs());
                let d: f64 = lab_l.iter().zip(&self.initial_lab_l).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();
                self.max_lab_l_change = self.max_lab_l_change.max(d);
            }
        }
        self.samples += 1;
    }

    /// max |H(t) − H(0)| / [`energy_scale`]`(H(0))`: the quantity the run's energy guard
    /// (`run.max_energy_error`) compares.
    pub fn max_relative_energy_error(&self) -> f64 {
        self.max_energy_error / energy_scale(self.initial_energy.unwrap_or(0.0))
    }

    /// As JSON, for `summary.json`.
    pub fn to_json(&self) -> Value {
        json!({
            "sampled_at": "output times",
            "samples": self.samples,
            "initial_energy_hartree": self.initial_energy,
            "max_abs_energy_error_hartree": self.max_energy_error,
            "max_relative_energy_error": self.max_relative_energy_error(),
            "relative_to_hartree": energy_scale(self.initial_energy.unwrap_or(0.0)),
            "initial_abs_j_hbar": self.initial_j,
            "max_abs_j_change_hbar": self.max_j_change,
            "initial_p_phi_hbar": self.initial_p_phi,
            "max_p_phi_change_hbar": self.max_p_phi_change,
            "initial_lab_angular_momentum_hbar": self.initial_lab_l,
            "max_lab_angular_momentum_change_hbar": self.max_lab_l_change,
        })
    }
}

/// The restart file's name in a run's output directory (written by [`crate::restart`]).
pub const RESTART_FILE: &str = "restart.json";

/// Removes the files of [`crate::report::run_files`] in `dir` that this run will not write (not in `keep`),
/// and `summary.json` and `restart.json` in any case (they are written at the end, atomically,
/// and only a run that ends well writes `restart.json`), so that no file of an earlier run
/// remains looking like this run's. Missing files are fine.
pub fn remove_stale_outputs(dir: &Path, keep: &[&str]) -> Result<(), Error> {
    for name in crate::report::run_files() {
        if name != "summary.json" && name != RESTART_FILE && keep.contains(&name) {
            continue;
        }
        let path = dir.join(name);
        match std::fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(Error::io("cannot remove (left by an earlier run)", path, e)),
        }
    }
    Ok(())
}

/// Writes `summary.json` (pretty-printed) atomically: to `summary.json.tmp`, flushed and synced,
/// then renamed over `summary.json`, so a reader never sees a half-written summary.
pub fn write_summary(dir: &Path, summary: &Value) -> Result<PathBuf, Error> {
    write_atomically(dir, "summary.json", summary)
}

/// Writes `value` (pretty-printed JSON) to `dir/name` atomically: to `name.tmp`, flushed and
/// synced, then renamed over `name`.
pub fn write_atomically(dir: &Path, name: &str, value: &Value) -> Result<PathBuf, Error> {
    let tmp = dir.join(format!("{name}.tmp"));
    let path = dir.join(name);
    let write = || -> std::io::Result<()> {
        let mut file = File::create(&tmp)?;
        writeln!(file, "{}", serde_json::to_string_pretty(value).expect("a JSON value serialises"))?;
        file.sync_all()
    };
    write().map_err(|e| Error::io("cannot write", &tmp, e))?;
    std::fs::rename(&tmp, &path).map_err(|e| Error::io(format!("cannot rename {} to", tmp.display()), &path, e))?;
    Ok(path)
}

/// Everything `summary.json` reports about one run; [`RunSummary::to_json`] is the file's schema.
pub struct RunSummary<'a> {
    /// The scene that was run (its path, method, end time, units, outputs, limits).
    pub scene: &'a Scene,
    /// The molecule's name.
    pub molecule: &'a str,
    /// Why the run stopped, if it failed.
    pub failure: Option<&'a str>,
    /// Whether SIGINT or SIGTERM stopped the run (status "interrupted" unless it also failed).
    pub interrupted: bool,
    /// The stop condition (`run.stop_outside`) that ended the run, if one did (status "stopped").
    pub stopped: Option<&'a Value>,
    /// The last output time written, in the scene's time unit (`None` if none was).
    pub t_reached: Option<f64>,
    /// The flat layout of the integrated state, e.g. `[r1, p_r1, quaternion w, x, y, z, J_x, J_y, J_z]`.
    pub state_layout: &'a str,
    /// Whether the run integrated the `J = 0` system.
    pub zero_angular_momentum: bool,
    /// The solver's work counters (`None` if it stopped with an error before reporting them).
    pub stats: Option<Stats>,
    /// Right-hand-side evaluations, counted as they happen.
    pub rhs_evaluations: u64,
    /// Wall time of the integration, s.
    pub wall_time: f64,
    /// The conservation diagnostics at output times.
    pub conservation: &'a Conservation,
    /// Centre-of-mass position, bohr.
    pub com_position: Vector3<f64>,
    /// Centre-of-mass velocity, bohr per ħ/E_h.
    pub com_velocity: Vector3<f64>,
    /// The time (scene unit) a resumed run continued from (`None` for a run from t = 0).
    pub resumed_from: Option<f64>,
    /// Warnings about the scene (e.g. a start far above the reference energy).
    pub warnings: &'a [String],
    /// The chart switch at linear geometries, if the run could switch (`runtime::charts`):
    /// thresholds, switches, time in the Cartesian chart.
    pub charts: Option<Value>,
}

impl RunSummary<'_> {
    /// The JSON value written to `summary.json`.
    pub fn to_json(&self) -> Value {
        let scene = self.scene;
        let stats = self.stats;
        json!({
            "scene": scene.path,
            "molecule": self.molecule,
            "status": match (self.failure, self.interrupted, self.stopped) {
                (Some(_), _, _) => "failed",
                (None, true, _) => "interrupted",
                (None, false, Some(_)) => "stopped",
                (None, false, None) => "completed",
            },
            "stop": self.stopped,
            "error": self.failure,
            "t_reached": self.t_reached,
            "resumed_from": self.resumed_from,
            "warnings": self.warnings,
            "charts": self.charts,
            "method": scene.method,
            "formulation": "body-frame angular momentum J and unit quaternion, fast right-hand side",
            "state_layout": self.state_layout,
            "frozen": scene.frozen.iter().map(|s| s.get_ref().as_str()).collect::<Vec<_>>(),
            "potential_parameters": scene
                .parameters
                .iter()
                .map(|(n, v)| (n.get_ref().clone(), Value::from(*v)))
                .collect::<serde_json::Map<_, _>>(),
            "zero_angular_momentum": self.zero_angular_momentum,
            "min_metric_pivot": scene.min_metric_pivot,
            "max_energy_error": scene.max_energy_error,
            "t_end": scene.t_end / scene.time_unit.in_au(),
            "output_interval": scene.output_interval / scene.time_unit.in_au(),
            "time_unit": scene.time_unit.name(),
            "units": "q in bohr or rad, p in hbar/bohr or hbar, angles in rad, p_e and J in hbar, H in hartree \
                      (trajectory.csv: see trajectory.units.json); lab.xyz in angstrom, u, angstrom/fs and eV",
            // The solver reports its steps only when it finishes; evaluations are counted by the caller.
            "steps": stats.map(|s| s.steps),
            "accepted_steps": stats.map(|s| s.accepted),
            "rejected_steps": stats.map(|s| s.rejected),
            "rhs_evaluations": self.rhs_evaluations,
            "wall_time_s": self.wall_time,
            "conservation": self.conservation.to_json(),
            "centre_of_mass": {
                "position_bohr": self.com_position.as_slice(),
                "velocity_bohr_per_au": self.com_velocity.as_slice(),
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folder(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("rovib-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A file to continue that is cut, foreign, longer or shorter than the restart file says is
    /// refused with `Error::Unusable` naming it; the right one is continued.
    #[test]
    fn an_output_that_cannot_be_continued_is_a_typed_error_naming_the_file() {
        let d = folder("append");
        let cases = [
            ("t,x\n1,2\n1,", "ends inside a line"),
            ("s,y\n1,2\n", "starts with `s,y`"),
            ("t,x\n1,2\n3,4\n", "more than the 2 lines"),
            ("t,x\n", "has 1 lines"),
        ];
        for (text, why) in cases {
            std::fs::write(d.join("f.csv"), text).unwrap();
            match OutputFile::append(&d, "f.csv", "t,x", 2) {
                Err(e @ Error::Unusable { .. }) => {
                    let m = e.to_string();
                    assert!(m.starts_with(&d.join("f.csv").display().to_string()) && m.contains(why), "{m}");
                }
                Err(e) => panic!("{text:?}: {e:?}"),
                Ok(_) => panic!("{text:?} was continued"),
            }
        }
        std::fs::write(d.join("f.csv"), "t,x\n1,2\n").unwrap();
        let mut f = OutputFile::append(&d, "f.csv", "t,x", 2).unwrap();
        f.line("3,4").unwrap();
        f.flush().unwrap();
        assert_eq!(std::fs::read_to_string(d.join("f.csv")).unwrap(), "t,x\n1,2\n3,4\n");
        match OutputFile::append(&d, "missing.csv", "t,x", 2) {
            Err(Error::Io { path, .. }) => assert_eq!(path, d.join("missing.csv")),
            other => panic!("{:?}", other.err()),
        }
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// The guard trips past the allowed change (and on NaN), and its message gives the change.
    #[test]
    fn the_energy_guard_reports_the_change_and_its_scale() {
        assert!(energy_guard(-1.0, -1.0 + 0.9e-6, 1e-6).is_ok());
        let e = energy_guard(-1.0, -1.0 + 2e-6, 1e-6).unwrap_err();
        assert_eq!(e, EnergyDrift { h0: -1.0, h: -1.0 + 2e-6, max_energy_error: 1e-6 });
        assert!(e.to_string().contains("changed by 2.000e-6 hartree"), "{e}");
        assert!(energy_guard(-1.0, f64::NAN, 1e-6).is_err());
    }
}
