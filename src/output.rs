//! What a run writes: `trajectory.csv`, `lab.xyz` (extended XYZ) and `summary.json`.
//!
//! Files are written as the run goes, through buffers that are flushed when the run ends, also
//! when it ends with an error or an interrupt, so that everything up to that point is kept.
//!
//! Stale files: before a run writes anything it removes every file of [`RUN_FILES`] that it will
//! not write itself, and `summary.json` always (see [`remove_stale_outputs`]); the files it does
//! write are truncated when created. `summary.json` is written last, under a temporary name that
//! is renamed over the final one, so it is either absent or complete and always this run's.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::runtime::integrate::{Method, Stats};
use crate::runtime::nalgebra::Vector3;
use crate::runtime::units::BOHR_IN_ANGSTROM;
use crate::scene::Scene;

/// A writer that remembers its path for error messages.
pub struct OutputFile {
    path: PathBuf,
    out: BufWriter<File>,
}

impl OutputFile {
    /// Creates (truncates) `dir/name`.
    pub fn create(dir: &Path, name: &str) -> Result<Self, String> {
        let path = dir.join(name);
        let file = File::create(&path).map_err(|e| format!("cannot create {}: {e}", path.display()))?;
        Ok(OutputFile { path, out: BufWriter::new(file) })
    }

    /// Writes one line (a newline is added).
    pub fn line(&mut self, text: &str) -> Result<(), String> {
        writeln!(self.out, "{text}").map_err(|e| format!("cannot write {}: {e}", self.path.display()))
    }

    /// Flushes the buffer to disk.
    pub fn flush(&mut self) -> Result<(), String> {
        self.out.flush().map_err(|e| format!("cannot write {}: {e}", self.path.display()))
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// `trajectory.csv`: one row per output time.
///
/// Columns: `t` (in the scene's time unit), each q by name (bohr or rad), each p as `p_NAME`
/// (ħ/bohr or ħ), `phi`, `theta`, `psi` (rad), `p_phi`, `p_theta`, `p_psi` (ħ), `H` (hartree).
pub struct TrajectoryCsv {
    file: OutputFile,
    row: String,
}

impl TrajectoryCsv {
    /// Creates the file and writes the header.
    pub fn create(dir: &Path, coordinates: &[&str]) -> Result<Self, String> {
        let mut file = OutputFile::create(dir, "trajectory.csv")?;
        let mut header = vec!["t".to_owned()];
        header.extend(coordinates.iter().map(|c| (*c).to_owned()));
        header.extend(coordinates.iter().map(|c| format!("p_{c}")));
        header.extend(["phi", "theta", "psi", "p_phi", "p_theta", "p_psi", "H"].map(str::to_owned));
        file.line(&header.join(","))?;
        Ok(TrajectoryCsv { file, row: String::new() })
    }

    /// Writes one row: time, then the values in column order. Numbers are written with full
    /// round-trip precision.
    pub fn row(&mut self, t: f64, values: impl IntoIterator<Item = f64>) -> Result<(), String> {
        use std::fmt::Write as _;
        self.row.clear();
        let _ = write!(self.row, "{t:?}");
        for v in values {
            let _ = write!(self.row, ",{v:?}");
        }
        let row = std::mem::take(&mut self.row);
        let result = self.file.line(&row);
        self.row = row;
        result
    }

    /// Flushes to disk.
    pub fn flush(&mut self) -> Result<(), String> {
        self.file.flush()
    }
}

/// `dipole.csv`: the lab-frame dipole moment μ_lab = S μ(q), one row per output time.
///
/// Columns: `t` (in the scene's time unit), `mu_x`, `mu_y`, `mu_z` (e·bohr, in the lab frame
/// of `lab.xyz`; the centre of mass's motion does not change it for a neutral molecule).
pub struct DipoleCsv {
    csv: TrajectoryCsv,
}

impl DipoleCsv {
    /// Creates the file and writes the header.
    pub fn create(dir: &Path) -> Result<Self, String> {
        let mut file = OutputFile::create(dir, "dipole.csv")?;
        file.line("t,mu_x,mu_y,mu_z")?;
        Ok(DipoleCsv { csv: TrajectoryCsv { file, row: String::new() } })
    }

    /// Writes one row: time and μ_lab in e·bohr.
    pub fn row(&mut self, t: f64, mu: &Vector3<f64>) -> Result<(), String> {
        self.csv.row(t, mu.iter().copied())
    }

    /// Flushes to disk.
    pub fn flush(&mut self) -> Result<(), String> {
        self.csv.flush()
    }
}

/// `lab.xyz`: extended XYZ, one frame per output time, positions in Å, readable by ASE, VMD
/// and OVITO. The comment line carries `Properties=species:S:1:pos:R:3`, the time and the
/// energy.
pub struct LabXyz {
    file: OutputFile,
    elements: Vec<&'static str>,
    time_unit: &'static str,
}

impl LabXyz {
    /// Creates the file for atoms of the given elements.
    pub fn create(dir: &Path, elements: Vec<&'static str>, time_unit: &'static str) -> Result<Self, String> {
        Ok(LabXyz { file: OutputFile::create(dir, "lab.xyz")?, elements, time_unit })
    }

    /// Writes one frame; `positions` are in bohr, one `[x, y, z]` per atom.
    pub fn frame(&mut self, t: f64, energy: f64, positions: impl IntoIterator<Item = [f64; 3]>) -> Result<(), String> {
        self.file.line(&self.elements.len().to_string())?;
        self.file.line(&format!(
            "Properties=species:S:1:pos:R:3 Time={t:?} time_unit={} energy_hartree={energy:?} pbc=\"F F F\"",
            self.time_unit
        ))?;
        for (element, x) in self.elements.iter().zip(positions) {
            let [a, b, c] = x.map(|v| v * BOHR_IN_ANGSTROM);
            self.file.line(&format!("{element} {a:.12} {b:.12} {c:.12}"))?;
        }
        Ok(())
    }

    /// Flushes to disk.
    pub fn flush(&mut self) -> Result<(), String> {
        self.file.flush()
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

/// Conservation diagnostics accumulated over the output times.
#[derive(Clone, Debug, Default)]
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

/// Every file `rovib run` may write into its output directory.
pub const RUN_FILES: [&str; 4] = ["trajectory.csv", "lab.xyz", "dipole.csv", "summary.json"];

/// Removes the files of [`RUN_FILES`] in `dir` that this run will not write (not in `keep`),
/// and `summary.json` in any case (it is written at the end, atomically), so that no file of an
/// earlier run remains looking like this run's. Missing files are fine.
pub fn remove_stale_outputs(dir: &Path, keep: &[&str]) -> Result<(), String> {
    for name in RUN_FILES {
        if name != "summary.json" && keep.contains(&name) {
            continue;
        }
        let path = dir.join(name);
        match std::fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(format!("cannot remove {} left by an earlier run: {e}", path.display())),
        }
    }
    Ok(())
}

/// Writes `summary.json` (pretty-printed) atomically: to `summary.json.tmp`, flushed and synced,
/// then renamed over `summary.json`, so a reader never sees a half-written summary.
pub fn write_summary(dir: &Path, summary: &Value) -> Result<PathBuf, String> {
    let tmp = dir.join("summary.json.tmp");
    let path = dir.join("summary.json");
    let write = || -> std::io::Result<()> {
        let mut file = File::create(&tmp)?;
        writeln!(file, "{}", serde_json::to_string_pretty(summary).expect("a JSON value serialises"))?;
        file.sync_all()
    };
    write().map_err(|e| format!("cannot write {}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, &path).map_err(|e| format!("cannot rename {} to {}: {e}", tmp.display(), path.display()))?;
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
}

impl RunSummary<'_> {
    /// The JSON value written to `summary.json`.
    pub fn to_json(&self) -> Value {
        let scene = self.scene;
        let stats = self.stats;
        json!({
            "scene": scene.path,
            "molecule": self.molecule,
            "status": match (self.failure, self.interrupted) {
                (Some(_), _) => "failed",
                (None, true) => "interrupted",
                (None, false) => "completed",
            },
            "error": self.failure,
            "t_reached": self.t_reached,
            "method": method_json(&scene.method),
            "formulation": "body-frame angular momentum J and unit quaternion, fast right-hand side",
            "state_layout": self.state_layout,
            "frozen": scene.frozen.iter().map(|s| s.get_ref().as_str()).collect::<Vec<_>>(),
            "zero_angular_momentum": self.zero_angular_momentum,
            "min_metric_pivot": scene.min_metric_pivot,
            "max_energy_error": scene.max_energy_error,
            "t_end": scene.t_end / scene.time_unit.in_au(),
            "output_interval": scene.output_interval / scene.time_unit.in_au(),
            "time_unit": scene.time_unit.name(),
            "units": "q in bohr or rad, p in hbar/bohr or hbar, angles in rad, p_e and J in hbar, H in hartree; lab.xyz in angstrom",
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

/// The integrator and its settings, as `summary.json` names them.
fn method_json(method: &Method) -> Value {
    match method {
        Method::Dop853(o) => json!({"name": "dop853", "rtol": o.rtol, "atol": o.atol}),
        Method::GaussLegendre(o) => {
            json!({"name": "gauss-legendre", "stages": o.stages, "step_au": o.step, "compensated": o.compensated})
        }
        Method::Rk4(o) => json!({"name": "rk4", "step_au": o.step}),
    }
}
