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

use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::error::Error;
use crate::runtime::integrate::Stats;
use crate::runtime::nalgebra::Vector3;
use crate::scene::Scene;

pub use crate::report::{
    ASE_TIME_IN_FS, DipoleCsv, LAB_XYZ_PROPERTIES, LabXyz, TRAJECTORY_UNITS_FILE, TrajectoryCsv, trajectory_columns,
};

pub use crate::energy_guard::{Conservation, ENERGY_SCALE_FLOOR, EnergyDrift, energy_guard, energy_scale};
pub use crate::output_file::{MAX_LINE_BYTES, OutputFile, write_atomically};
pub use crate::restart::RESTART_FILE;

/// Removes the files of [`crate::report::run_files`] in `dir` that this run will not write (not in `keep`),
/// and `summary.json` and `restart.json` in any case (they are written at the end, atomically,
/// and only a run that ends well writes `restart.json`), so that no file of an earlier run
/// remains looking like this run's. Missing files are fine.
pub fn remove_stale_outputs(dir: &Path, keep: &[&str]) -> Result<(), Error> {
    let stale = crate::report::run_files()
        .filter(|name| *name == "summary.json" || *name == RESTART_FILE || !keep.contains(name));
    remove_earlier_files(dir, stale)
}

/// Removes the files `names` in `dir` that an earlier run left; a missing file is fine.
pub fn remove_earlier_files<'a>(dir: &Path, names: impl IntoIterator<Item = &'a str>) -> Result<(), Error> {
    for name in names {
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
