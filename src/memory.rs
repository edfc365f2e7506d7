//! One trajectory run in memory: the scene given as text, the output records handed to a
//! [`RecordSink`] instead of files, and optionally a potential given at run time
//! ([`ExternalPotential`], e.g. a Python function) composed with the molecule's generated
//! kinematics by [`crate::runtime::surface::WithPotential`].
//!
//! [`run_in_memory`] writes nothing: no output folder, no lock, no trajectory.csv, lab.xyz or
//! dipole.csv (their rows go to the sink), no summary.json (its JSON goes to the sink) and no
//! restart.json (a scene whose `run.outputs` names "restart" is refused: continuing a run
//! needs a folder, [`crate::Simulation`]).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use crate::Progress;
use crate::error::Error;
use crate::report::{Frame, Needs, Reporter};
use crate::scene::{Outputs, parse_scene};
use crate::simulation::{RunReport, Simulation};

pub use crate::external_potential::ExternalPotential;

/// One output record of a run in memory, in the units of trajectory.csv: the time in the
/// scene's time unit, everything else in atomic units; `lab` when the scene's `run.outputs`
/// names "lab", `dipole` when it names "dipole".
pub use crate::report::Frame as Record;
/// The lab frame at one output time.
pub use crate::report::LabFrame as LabRecord;

/// Where a run in memory puts its output.
pub trait RecordSink: Send {
    /// One output record (called in time order, after the energy guard accepted it).
    fn record(&mut self, record: &Record<'_>);
    /// The run's summary: the JSON summary.json would hold (called once, at the end of a run
    /// that did not fail).
    fn summary(&mut self, summary: &serde_json::Value);
}

/// The sink of a run in memory and what the scene asked of it: the reporter of a run in memory.
struct Tap<'a> {
    sink: &'a mut dyn RecordSink,
    /// Lab-frame records ("lab" in `run.outputs`).
    lab: bool,
    /// Dipole records ("dipole" in `run.outputs`).
    dipole: bool,
}

impl Reporter for Tap<'_> {
    fn needs(&self) -> Needs {
        Needs { lab: self.lab, dipole: self.dipole, orientation: false }
    }

    fn report(&mut self, frame: &Frame<'_>) -> Result<(), Error> {
        let record =
            Frame { lab: frame.lab.filter(|_| self.lab), dipole: frame.dipole.filter(|_| self.dipole), ..*frame };
        self.sink.record(&record);
        Ok(())
    }

    fn summary(&mut self, summary: &serde_json::Value) {
        self.sink.summary(summary);
    }
}

/// Runs the scene `text` (named `path` in messages, and relative paths in it resolve from
/// `path`'s folder) to its end in memory: every output record goes to `sink`, and with
/// `potential` the molecule runs on it instead of its own (its gradient checked first). `stop`
/// and `progress` work as in [`Simulation::run`]. Nothing is written to disk.
pub fn run_in_memory(
    path: &str,
    text: &str,
    potential: Option<&dyn ExternalPotential>,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(Progress),
    sink: &mut dyn RecordSink,
) -> Result<RunReport, Error> {
    let mut scene = parse_scene(path, text)?;
    let src = scene.source();
    let outputs = scene.tables.outputs.clone();
    if let Some(restart) = outputs.iter().find(|o| o.get_ref() == "restart") {
        return Err(src
            .error(
                restart.span(),
                "a run in memory writes no restart.json",
                "remove \"restart\" from run.outputs, or run into a folder (`out_dir`) to continue the run later",
            )
            .into());
    }
    if potential.is_some() {
        let what = potential.map(|p| p.describe()).unwrap_or_default();
        if let Some((library, _)) = &scene.library {
            return Err(src
                .error(
                    library.span(),
                    format!("the scene names `potential.library`, and {what} is given too"),
                    "remove `library` from [potential], or give no potential to the call",
                )
                .into());
        }
        if let Some((name, _)) = scene.parameters.first() {
            return Err(src
                .error(
                    name.span(),
                    format!(
                        "`[potential.parameters]` sets the definition's parameters, but {what} replaces that potential"
                    ),
                    "remove [potential.parameters], or give no potential to the call",
                )
                .into());
        }
    }
    let wanted = scene.outputs.files.needs();
    scene.outputs = Outputs::NONE;
    let tap = Tap { sink, lab: wanted.lab, dipole: wanted.dipole };
    Simulation::from_scene(scene, PathBuf::new()).run_with(stop, progress, vec![Box::new(tap)], true, potential)
}
