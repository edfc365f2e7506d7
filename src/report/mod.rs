//! A run's outputs at each output time, as reporters: each declares what it [`Needs`] beyond the
//! phase-space state (the lab frame, the lab dipole), gets one [`Frame`] per output time, and is
//! flushed when the run ends. The recorder of [`crate::Simulation`] computes the union of the
//! needs, builds the frame once and hands it to every reporter; it knows no file by name.
//!
//! [`OUTPUTS`] is the registry: the `run.outputs` names of the files written as the run goes,
//! with their files and constructors. The scene accepts these names (and "summary", "restart",
//! which the run writes at its end).
//!
//! Adding an output is adding one file here, `src/report/NAME.rs`, that declares
//! `pub(super) const OUTPUT: Output`: the build script makes every file of this folder a module and
//! lists their `OUTPUT`s in [`OUTPUTS`] in the order of the files' names (it refuses, with the
//! file and what to change, a file that declares no `OUTPUT` or whose name is not a module name).

use std::path::Path;

include!(concat!(env!("OUT_DIR"), "/reporters.rs"));

pub use dipole_csv::DipoleCsv;
pub use lab_xyz::{ASE_TIME_IN_FS, LAB_XYZ_PROPERTIES, LabXyz};
pub use trajectory_csv::{TRAJECTORY_UNITS_FILE, TrajectoryCsv, trajectory_columns};

use crate::error::Error;
use crate::restart::Restart;
use crate::runtime::{Atom, Coordinate};

/// What a reporter needs at an output time beyond the phase-space state, which every frame has.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    /// The lab-frame positions and velocities, and the potential energy ([`Frame::lab`]).
    pub lab: bool,
    /// The lab-frame dipole moment ([`Frame::dipole`]); a molecule without a dipole surface
    /// cannot run with a reporter that needs it.
    pub dipole: bool,
    /// The orientation (the Euler angles and their momenta): without it a run at zero angular
    /// momentum may integrate the internal motion alone. Implied by `lab` and `dipole`.
    pub orientation: bool,
}

impl Needs {
    /// Nothing beyond the internal state, J and H.
    pub const NOTHING: Needs = Needs { lab: false, dipole: false, orientation: false };

    /// What either needs.
    pub fn union(self, other: Needs) -> Needs {
        Needs {
            lab: self.lab || other.lab,
            dipole: self.dipole || other.dipole,
            orientation: self.orientation || other.orientation,
        }
    }

    /// Whether the orientation must be integrated.
    pub fn orientation(self) -> bool {
        self.orientation || self.lab || self.dipole
    }
}

/// The state at one output time, in the units of trajectory.csv: the time in the scene's time
/// unit, everything else in atomic units.
#[derive(Clone, Copy)]
pub struct Frame<'a> {
    /// Time, in the scene's time unit (`units.time`).
    pub t: f64,
    /// The internal coordinates (bohr or rad), in the molecule's order.
    pub q: &'a [f64],
    /// Their momenta (ħ/bohr or ħ).
    pub p: &'a [f64],
    /// Euler angles φ, θ, ψ (rad, z-x-z).
    pub euler: [f64; 3],
    /// Their conjugate momenta (ħ).
    pub pe: [f64; 3],
    /// The body-frame angular momentum (ħ).
    pub j: [f64; 3],
    /// H (hartree).
    pub energy: f64,
    /// The lab frame (the rows of lab.xyz), when a reporter needs it.
    pub lab: Option<LabFrame<'a>>,
    /// The lab-frame dipole moment (e·bohr, the row of dipole.csv), when a reporter needs it.
    pub dipole: Option<[f64; 3]>,
}

/// The lab frame at one output time.
#[derive(Clone, Copy)]
pub struct LabFrame<'a> {
    /// Positions, bohr: x, y, z of each atom in the molecule's order (3 × atoms values).
    pub positions: &'a [f64],
    /// Velocities, bohr per ħ/E_h, in the same layout.
    pub velocities: &'a [f64],
    /// U at this state, hartree.
    pub potential: f64,
}

/// One output of a run, called at every output time.
pub trait Reporter {
    /// What it needs in the frames it gets.
    fn needs(&self) -> Needs;
    /// One output time (in time order, after the energy guard accepted it).
    fn report(&mut self, frame: &Frame<'_>) -> Result<(), Error>;
    /// Writes what is buffered (at the end of the run, also one that failed or was interrupted).
    fn flush(&mut self) -> Result<(), Error> {
        Ok(())
    }
    /// Records in the restart file what a continuation needs to carry on this output.
    fn continuation(&self, _restart: &mut Restart) {}
    /// The run's summary (the JSON of summary.json), once at the end of a run that did not fail.
    fn summary(&mut self, _summary: &serde_json::Value) {}
}

/// What a reporter of [`OUTPUTS`] is opened with.
pub struct Open<'a> {
    /// The output folder.
    pub dir: &'a Path,
    /// The molecule's coordinates.
    pub coordinates: &'a [Coordinate],
    /// The molecule's atoms.
    pub atoms: &'a [Atom],
    /// The scene's time unit (the `t` column).
    pub time_unit: &'static str,
    /// `run.euler_unwrapped`.
    pub euler_unwrapped: bool,
    /// The run being continued (`rovib run --resume`): its files are checked and appended to.
    pub resume: Option<&'a Restart>,
}

impl Open<'_> {
    /// The records of the run being continued (in its files: the output times 0 to
    /// `outputs_done`), if it is one.
    pub fn records(&self) -> Option<usize> {
        self.resume.map(|r| (r.outputs_done + 1) as usize)
    }
}

/// An output written as the run goes, selectable in `run.outputs`.
pub struct Output {
    /// Its name in `run.outputs`.
    pub name: &'static str,
    /// The files it writes into the output folder (kept from removal when it is selected).
    pub files: &'static [&'static str],
    /// Whether a scene without `run.outputs` writes it.
    pub by_default: bool,
    /// What it needs, known before it is opened (checked against the molecule).
    pub needs: Needs,
    /// Creates its files, or when continuing a run checks and opens them for appending.
    pub open: fn(&Open<'_>) -> Result<Box<dyn Reporter>, Error>,
}

/// The outputs a run writes at its end (not reporters): `summary.json` and `restart.json`.
pub const END_OUTPUTS: [(&str, &str); 2] = [("summary", "summary.json"), ("restart", crate::restart::RESTART_FILE)];

/// Every name `run.outputs` accepts.
pub fn output_names() -> impl Iterator<Item = &'static str> + Clone {
    OUTPUTS.iter().map(|o| o.name).chain(END_OUTPUTS.iter().map(|(n, _)| *n))
}

/// The accepted names with their files, for messages: `"trajectory" (trajectory.csv), …`.
pub fn describe_outputs() -> String {
    let files = OUTPUTS.iter().map(|o| (o.name, o.files[0])).chain(END_OUTPUTS);
    files.map(|(name, file)| format!("\"{name}\" ({file})")).collect::<Vec<_>>().join(", ")
}

/// Every file `rovib run` may write into its output directory.
pub fn run_files() -> impl Iterator<Item = &'static str> {
    OUTPUTS.iter().flat_map(|o| o.files.iter().copied()).chain(END_OUTPUTS.iter().map(|(_, f)| *f))
}

/// A set of [`OUTPUTS`] (by their place in the registry).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Selection(u64);

impl Selection {
    /// No output.
    pub const EMPTY: Selection = Selection(0);

    /// The outputs a scene without `run.outputs` writes.
    pub fn defaults() -> Selection {
        Selection(OUTPUTS.iter().enumerate().filter(|(_, o)| o.by_default).fold(0, |s, (i, _)| s | 1 << i))
    }

    /// Adds the output called `name`; false if [`OUTPUTS`] has none of that name.
    pub fn insert(&mut self, name: &str) -> bool {
        match OUTPUTS.iter().position(|o| o.name == name) {
            Some(i) => {
                self.0 |= 1 << i;
                true
            }
            None => false,
        }
    }

    /// Whether the output called `name` is selected.
    pub fn contains(&self, name: &str) -> bool {
        self.iter().any(|o| o.name == name)
    }

    /// The selected outputs, in registry order.
    pub fn iter(self) -> impl Iterator<Item = &'static Output> {
        OUTPUTS.iter().enumerate().filter(move |(i, _)| self.0 & (1 << i) != 0).map(|(_, o)| o)
    }

    /// What the selected outputs need.
    pub fn needs(self) -> Needs {
        self.iter().fold(Needs::NOTHING, |n, o| n.union(o.needs))
    }

    /// The files the selected outputs write.
    pub fn files(self) -> impl Iterator<Item = &'static str> {
        self.iter().flat_map(|o| o.files.iter().copied())
    }
}
