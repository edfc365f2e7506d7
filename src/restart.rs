//! `restart.json`: where a run stood when it ended, so that `rovib run --resume DIR` continues it.
//!
//! Written (atomically, like `summary.json`) by every run that completed or was interrupted and
//! whose outputs include `"restart"` (the default). It holds the scene (path and text), the last
//! output time reached and its number on the output grid, the final state (readable: q, p, the
//! orientation quaternion, J, the Euler angles and p_e; and the integrated flat state), the
//! centre-of-mass motion, the conservation diagnostics so far, and for DOP853 the integrator's
//! own continuation point ([`Dop853Resume`]: the start of the step first shortened to land on
//! the end time, the step the controller proposed there and its memory). Numbers are written by
//! serde_json with `float_roundtrip`, so they read back bit for bit.
//!
//! **What "exactly" means.** With DOP853 a continued run takes the same steps as one run to the
//! later end time would have, so every output after the first run's last one is bit for bit
//! that run's (`tests/commands/restart.rs` checks it). With the fixed-step methods the continuation
//! restarts the step grid at the last output time from the state written there, which is the
//! uninterrupted run's own step sequence when the output interval is a whole number of steps.
//!
//! Ensembles (`rovib ensemble`) do not write this file. Their random state needs no saving:
//! trajectory `i` draws from its own stream of `(seed, i)` (`runtime::sample::stream`), so an
//! ensemble resumes from a record of which trajectories (blocks) finished, its checkpoint
//! (`src/ensemble/checkpoint.rs`), not from a stream position.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::energy_guard::Conservation;
use crate::error::Error;
use crate::runtime::integrate::Dop853Resume;

/// The restart file's name in a run's output directory (one of [`crate::report::run_files`]).
pub const RESTART_FILE: &str = "restart.json";

/// The largest `restart.json` read: the scene's text (at most
/// [`MAX_INPUT_BYTES`](crate::runtime::diagnostic::MAX_INPUT_BYTES), 16 MiB, and at most 6 bytes
/// per byte once escaped in JSON) and 1 MiB for the state and integrator memory. A larger file,
/// or an endless one (a link to `/dev/zero`), is refused with this figure instead of read.
pub const MAX_RESTART_BYTES: u64 = 6 * crate::runtime::diagnostic::MAX_INPUT_BYTES + (1 << 20);

/// What identifies the file's format; a different value is refused.
pub const FORMAT: &str = "rovib restart 1";

/// The contents of `restart.json`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Restart {
    /// [`FORMAT`].
    pub format: String,
    /// The scene file as the run named it.
    pub scene_path: String,
    /// The scene file's text (the run continues with these settings unless given a scene).
    pub scene_text: String,
    /// The molecule's name.
    pub molecule: String,
    /// The last output time written, atomic units.
    pub t_au: f64,
    /// The same in the scene's time unit.
    pub t: f64,
    /// The scene's time unit.
    pub time_unit: String,
    /// How many output times after t = 0 were written (the last one is number `outputs_done`
    /// of the grid k·output_interval; trajectory.csv has `outputs_done + 1` rows).
    pub outputs_done: u64,
    /// The state at `t_au`.
    pub state: FinalState,
    /// The integrated flat state at `t_au`, in the layout `state_layout`.
    pub y: Vec<f64>,
    /// The layout of `y`.
    pub state_layout: String,
    /// Whether the run integrated the `J = 0` system (the initial angular momentum was zero).
    pub zero_angular_momentum: bool,
    /// DOP853's continuation point (absent for the fixed-step methods).
    pub dop853: Option<Dop853Point>,
    /// Centre-of-mass position (bohr) and velocity (bohr per ħ/E_h).
    pub com_position_bohr: [f64; 3],
    /// See `com_position_bohr`.
    pub com_velocity_bohr_per_au: [f64; 3],
    /// The conservation diagnostics so far (H(0) stays the run's first).
    pub conservation: Conservation,
    /// The raw and unwrapped (φ, ψ) of the last row, when trajectory.csv has unwrapped columns.
    pub euler_unwrapped: Option<([f64; 2], [f64; 2])>,
}

/// The state at the last output time, in atomic units.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FinalState {
    /// Internal coordinates, bohr or rad.
    pub q: Vec<f64>,
    /// Their momenta, ħ/bohr or ħ.
    pub p: Vec<f64>,
    /// Body → lab rotation as a unit quaternion `[w, x, y, z]`.
    pub orientation: [f64; 4],
    /// Body-frame angular momentum, ħ.
    pub j: [f64; 3],
    /// Euler angles φ, θ, ψ (rad, z-x-z), for reading.
    pub euler: [f64; 3],
    /// Their momenta p_φ, p_θ, p_ψ (ħ), for reading.
    pub pe: [f64; 3],
}

/// [`Dop853Resume`] as stored.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Dop853Point {
    /// Where the next step starts, atomic units.
    pub t_au: f64,
    /// The flat state there.
    pub y: Vec<f64>,
    /// The step to try there, atomic units.
    pub step_au: f64,
    /// The step-size controller's memory.
    pub fac_old: f64,
    /// Whether the step before was rejected.
    pub reject: bool,
}

impl Dop853Point {
    /// From the integrator's continuation point.
    pub fn from_resume(r: &Dop853Resume) -> Self {
        Dop853Point { t_au: r.t, y: r.y.clone(), step_au: r.h, fac_old: r.fac_old, reject: r.reject }
    }

    /// The integrator's continuation point after `outputs_done` output times.
    pub fn to_resume(&self, outputs_done: u64) -> Dop853Resume {
        Dop853Resume {
            t: self.t_au,
            y: self.y.clone(),
            h: self.step_au,
            fac_old: self.fac_old,
            reject: self.reject,
            outputs_done,
        }
    }
}

impl Restart {
    /// Reads `dir/restart.json`.
    pub fn read(dir: &Path) -> Result<Self, Error> {
        let path = dir.join(RESTART_FILE);
        if !path.exists() {
            return Err(Error::unusable(
                path,
                " does not exist: only a run that completed or was interrupted, with \"restart\" in its outputs, can \
                 be continued",
            ));
        }
        let text = crate::runtime::diagnostic::read_text_capped(&path, MAX_RESTART_BYTES)?;
        let restart: Restart = serde_json::from_str(&text)
            .map_err(|e| Error::unusable(&path, format!(" is not a rovib restart file: {e}")))?;
        if restart.format != FORMAT {
            return Err(Error::unusable(
                path,
                format!(" has format `{}`, this rovib reads `{FORMAT}`", restart.format),
            ));
        }
        let finite = restart.y.iter().all(|v| v.is_finite()) && restart.t_au.is_finite();
        if !finite {
            return Err(Error::unusable(path, " holds a non-finite state"));
        }
        Ok(restart)
    }

    /// Writes `dir/restart.json` atomically.
    pub fn write(&self, dir: &Path) -> Result<std::path::PathBuf, Error> {
        let value = serde_json::to_value(self)
            .map_err(|e| Error::unusable(dir.join(RESTART_FILE), format!(" cannot be written: {e}")))?;
        crate::output_file::write_atomically(dir, RESTART_FILE, &value)
    }
}
