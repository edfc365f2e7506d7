//! `rovib run SCENE.toml`: integrate a scene and write its trajectory and diagnostics.

use std::io::IsTerminal as _;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use super::{CliError, unknown_molecule};
use crate::dir_lock::DirLock;
use crate::molecules;
use crate::output::{
    Conservation, DipoleCsv, ENERGY_SCALE_FLOOR, LabXyz, RunSummary, TrajectoryCsv, energy_scale, remove_stale_outputs,
    write_summary,
};
use crate::runtime::hamiltonian::hamiltonian;
use crate::runtime::hamiltonian::{ReducedSystem, Reduction, RotationPart};
use crate::runtime::integrate::{Observer, OdeSystem, SolveError, Stats, solve};
use crate::runtime::nalgebra::{SMatrix, Vector3};
use crate::runtime::{Molecule, MoleculeVisitor};
use crate::scene::Scene;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
// The initial state and the production system live in `crate::start`; re-exported here for
// callers that used these paths.
pub use crate::start::{Start, initial_state, load_scene, production_system};

/// What a finished run reports on the terminal.
pub struct RunReport {
    /// The output directory.
    pub out_dir: PathBuf,
    /// Files written.
    pub files: Vec<PathBuf>,
    /// Work counters.
    pub stats: Stats,
    /// Diagnostics.
    pub conservation: Conservation,
    /// Wall time of the integration, s.
    pub wall_time: f64,
}

/// Runs the scene at `path`, writing into `out_dir` (default `out/SCENE_NAME`).
pub fn run(path: &Path, out_dir: Option<&Path>, quiet: bool) -> Result<RunReport, CliError> {
    let (scene, out_dir) = load_scene(path, out_dir, "")?;
    let name = scene.molecule.get_ref().clone();
    let visitor = Run { scene: &scene, out_dir: &out_dir, progress: !quiet && std::io::stderr().is_terminal() };
    molecules::visit(&name, visitor).ok_or_else(|| {
        let e = unknown_molecule(&name);
        CliError::File(scene.source().error(scene.molecule.span(), e.to_string(), "use a name from `rovib list`"))
    })?
}

struct Run<'a> {
    scene: &'a Scene,
    out_dir: &'a Path,
    progress: bool,
}

impl MoleculeVisitor for Run<'_> {
    type Output = Result<RunReport, CliError>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Self::Output {
        let scene = self.scene;
        let start = initial_state(&m, scene)?;
        // Fail before writing anything if the initial state is not valid.
        hamiltonian(&m, &start.state).map_err(|e| CliError::context("the initial state", e))?;
        if scene.outputs.dipole && !m.has_dipole() {
            return Err(CliError::File(scene.source().error(
                scene.molecule.span(),
                format!("the scene asks for the \"dipole\" output, but molecule `{}` has no dipole surface", m.name()),
                format!(
                    "add a [dipole] table to {} (see the README), or remove \"dipole\" from run.outputs",
                    m.source()
                ),
            )));
        }
        let (system, y0) = production_system(&m, scene, &start.state)?;
        let layout = layout(system.reduction(), &m);

        // One run per directory, then no file of an earlier run may remain looking like this one's.
        let _lock = DirLock::acquire(self.out_dir)?;
        let mut keep = Vec::new();
        if scene.outputs.trajectory {
            keep.push("trajectory.csv");
        }
        if scene.outputs.lab {
            keep.push("lab.xyz");
        }
        if scene.outputs.dipole {
            keep.push("dipole.csv");
        }
        remove_stale_outputs(self.out_dir, &keep)?;

        let names: Vec<&str> = m.coordinates().iter().map(|c| c.name).collect();
        let mut recorder = Recorder::<M, N, NA> {
            system,
            trajectory: if scene.outputs.trajectory {
                Some(TrajectoryCsv::create(self.out_dir, &names)?)
            } else {
                None
            },
            lab: if scene.outputs.lab {
                Some(LabXyz::create(
                    self.out_dir,
                    m.atoms().iter().map(|a| a.element).collect(),
                    scene.time_unit.name(),
                )?)
            } else {
                None
            },
            dipole: if scene.outputs.dipole { Some(DipoleCsv::create(self.out_dir)?) } else { None },
            diagnostics: scene.outputs.summary,
            conservation: Conservation::default(),
            initial_energy: None,
            max_energy_error: scene.max_energy_error,
            layout: layout.clone(),
            time_scale: scene.time_unit.in_au(),
            time_unit: scene.time_unit.name(),
            com: (start.com_position, start.com_velocity),
            progress: self.progress.then(|| progress_bar(scene)),
            stop: crate::interrupt::flag(),
            interrupted: false,
            t_reached: None,
            error: None,
        };
        let mut counted = Counted { inner: system, evaluations: 0 };
        let begin = Instant::now();
        let result = solve(&mut counted, &scene.method, 0.0, &y0, scene.t_end, scene.output_interval, &mut recorder);
        let wall_time = begin.elapsed().as_secs_f64();
        if let Some(bar) = &recorder.progress {
            bar.finish_and_clear();
        }
        // Keep everything written so far, whatever happened.
        let flushed = recorder.flush();

        // The first error is the one reported: a failed record (which stops the solver) comes
        // before the solver's own error, and both before a failure to flush at the end.
        let (stats, failure) = match result {
            Ok(stats) => (Some(stats), recorder.error.take().map(|e| format!("the run stopped: {e}"))),
            Err(e) => (None, Some(format!("the run stopped: {}", describe_failure(&e, scene, &layout)))),
        };
        let failure = failure.or_else(|| flushed.err().map(|e| format!("the run stopped: {e}")));
        let interrupted = recorder.interrupted && failure.is_none();
        let t_reached = recorder.t_reached.map(|t| t / scene.time_unit.in_au());
        let mut files: Vec<PathBuf> = Vec::new();
        if scene.outputs.trajectory {
            files.push(self.out_dir.join("trajectory.csv"));
        }
        if scene.outputs.lab {
            files.push(self.out_dir.join("lab.xyz"));
        }
        if scene.outputs.dipole {
            files.push(self.out_dir.join("dipole.csv"));
        }
        let mut summary_error = None;
        if scene.outputs.summary {
            let summary = RunSummary {
                scene,
                molecule: m.name(),
                failure: failure.as_deref(),
                interrupted,
                t_reached,
                state_layout: &layout,
                zero_angular_momentum: system.reduction().rotation != RotationPart::Free,
                stats,
                rhs_evaluations: counted.evaluations,
                wall_time,
                conservation: &recorder.conservation,
                com_position: start.com_position,
                com_velocity: start.com_velocity,
            };
            match write_summary(self.out_dir, &summary.to_json()) {
                Ok(path) => files.push(path),
                Err(e) => summary_error = Some(e),
            }
        }
        let where_ = format!("output so far is in {}", self.out_dir.display());
        let message = match (failure, interrupted, summary_error) {
            (Some(f), _, Some(s)) => Some(format!("{f}; also {s} (no summary.json); {where_}")),
            (Some(f), _, None) => Some(format!("{f}; {where_}")),
            (None, true, s) => Some(format!(
                "interrupted at t = {} {}{}; {where_}",
                t_reached.unwrap_or(0.0),
                scene.time_unit.name(),
                s.map(|s| format!("; {s} (no summary.json)")).unwrap_or_default()
            )),
            (None, false, Some(s)) => Some(s),
            (None, false, None) => None,
        };
        if let Some(message) = message {
            return Err(CliError::Message(message));
        }
        let stats = stats.unwrap_or_default();
        Ok(RunReport { out_dir: self.out_dir.to_owned(), files, stats, conservation: recorder.conservation, wall_time })
    }
}

fn progress_bar(scene: &Scene) -> ProgressBar {
    let outputs = (scene.t_end / scene.output_interval).ceil() as u64 + 1;
    let bar = ProgressBar::new(outputs);
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {pos}/{len} outputs, eta {eta}")
            .expect("a valid template"),
    );
    bar
}

/// An [`OdeSystem`] that counts its right-hand-side evaluations, so that a run the solver stops
/// still reports its work.
struct Counted<S> {
    inner: S,
    evaluations: u64,
}

impl<S: OdeSystem> OdeSystem for Counted<S> {
    type Error = S::Error;

    fn dim(&self) -> usize {
        self.inner.dim()
    }

    fn rhs(&mut self, t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Self::Error> {
        self.evaluations += 1;
        self.inner.rhs(t, y, dydt)
    }
}

/// Why a run stopped, in the scene's units: what happened, when, and the last accepted state.
fn describe_failure<E: std::error::Error>(e: &SolveError<E>, scene: &Scene, layout: &str) -> String {
    let unit = scene.time_unit.name();
    let at = |t: f64| format!("t = {} {unit}", t / scene.time_unit.in_au());
    let what = match e {
        SolveError::Rhs { t, source, .. } => format!("{} at {}", source, at(*t)),
        SolveError::NonFinite { t, .. } => {
            format!(
                "the right-hand side became infinite or NaN at {} (the step may be too large for this motion)",
                at(*t)
            )
        }
        SolveError::StepSizeTooSmall { t, h, .. } => format!(
            "the step size fell to {} {unit}, below integrator.min_step, at {} (the motion has become too fast to resolve)",
            h / scene.time_unit.in_au(),
            at(*t)
        ),
        SolveError::TooManySteps { t, max_steps, .. } => {
            format!("integrator.max_steps = {max_steps} steps were taken by {}", at(*t))
        }
        SolveError::NotConverged { t, .. } => {
            format!("the implicit Gauss-Legendre stages did not converge at {} (reduce integrator.step)", at(*t))
        }
        SolveError::InvalidInput(reason) => format!("invalid integrator settings: {reason}"),
    };
    match e.state() {
        Some(y) => format!("{what}; last accepted state {layout} = {y:?}"),
        None => what,
    }
}

/// The flat layout of a system's state, for messages: `[q_a, p_a, quaternion, J]`.
fn layout<M: Molecule<N, NA>, const N: usize, const NA: usize>(r: &Reduction<N>, m: &M) -> String {
    let coords = m.coordinates();
    let active: Vec<&str> = (0..N).filter(|&k| r.active[k]).map(|k| coords[k].name).collect();
    let mut parts: Vec<String> = active.iter().map(|c| (*c).to_owned()).collect();
    parts.extend(active.iter().map(|c| format!("p_{c}")));
    if r.orientation() {
        parts.extend(["quaternion w", "x", "y", "z"].map(str::to_owned));
    }
    if r.rotation == RotationPart::Free {
        parts.extend(["J_x", "J_y", "J_z"].map(str::to_owned));
    }
    format!("[{}]", parts.join(", "))
}

/// Writes each output time and accumulates the diagnostics (only what the scene asks for);
/// remembers the first error and stops the run there.
struct Recorder<'m, M, const N: usize, const NA: usize> {
    /// A copy of the integrated system, to expand states and evaluate H at output times.
    system: ReducedSystem<'m, M, N, NA>,
    trajectory: Option<TrajectoryCsv>,
    lab: Option<LabXyz>,
    dipole: Option<DipoleCsv>,
    diagnostics: bool,
    conservation: Conservation,
    /// H at the first output time, for the energy guard.
    initial_energy: Option<f64>,
    /// The relative energy error at which the run stops.
    max_energy_error: f64,
    /// The flat layout, for messages.
    layout: String,
    time_scale: f64,
    time_unit: &'static str,
    com: (Vector3<f64>, Vector3<f64>),
    progress: Option<ProgressBar>,
    /// Set by SIGINT/SIGTERM; polled after each output record, so the run stops between records.
    stop: Arc<AtomicBool>,
    /// Whether the run stopped on `stop`.
    interrupted: bool,
    /// The last output time recorded, a.u.
    t_reached: Option<f64>,
    error: Option<String>,
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Recorder<'_, M, N, NA> {
    fn record(&mut self, t: f64, y: &[f64]) -> Result<(), String> {
        let t_out = t / self.time_scale;
        let at = |e: &dyn std::fmt::Display, y: &[f64], layout: &str| {
            format!("{e} at t = {t_out} {}; state {layout} = {y:?}", self.time_unit)
        };
        // H at every output time: for the outputs, and for the guard against a run that has
        // gone unstable (a too large fixed step) and would otherwise "complete" with garbage.
        let (body, energy) = self.system.expand_body_and_energy(y).map_err(|e| at(&e, y, &self.layout))?;
        let h0 = *self.initial_energy.get_or_insert(energy);
        let rotation = body.rotation();
        let phase = body.to_phase();
        // Recorded before the guard, so that the summary includes the output that tripped it.
        if self.diagnostics {
            self.conservation.record(energy, body.j.norm(), phase.pe[0], (rotation * body.j).into());
        }
        let change = (energy - h0).abs();
        let scale = energy_scale(h0);
        let drift = change / scale;
        // NaN fails too: a non-finite energy is a runaway as well.
        if drift.is_nan() || drift > self.max_energy_error {
            let e = format!(
                "the energy changed by {change:.3e} hartree from H(0) = {h0} hartree, {drift:.1e} relative to \
                 max(|H(0)|, {ENERGY_SCALE_FLOOR:e} hartree) = {scale:e} hartree, more than run.max_energy_error = \
                 {:e} (the step is too large or the tolerances too loose for this motion; reduce them)",
                self.max_energy_error
            );
            return Err(at(&e, y, &self.layout));
        }
        if let Some(csv) = &mut self.trajectory {
            let values = phase.q.iter().chain(phase.p.iter()).chain(phase.euler.iter()).chain(phase.pe.iter());
            csv.row(t_out, values.copied().chain([energy]))?;
        }
        if let Some(xyz) = &mut self.lab {
            let mut r = SMatrix::<f64, 3, NA>::zeros();
            self.system.molecule().positions(&body.q, &mut r);
            let com = self.com.0 + self.com.1 * t;
            let lab = rotation * r;
            xyz.frame(t_out, energy, (0..NA).map(|i| (lab.column(i) + com).into()))?;
        }
        if let Some(csv) = &mut self.dipole {
            let mut mu = Vector3::zeros();
            self.system.molecule().dipole(&body.q, &mut mu);
            csv.row(t_out, &(rotation * mu))?;
        }
        if let Some(bar) = &self.progress {
            bar.inc(1);
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), String> {
        if let Some(csv) = &mut self.trajectory {
            csv.flush()?;
        }
        if let Some(xyz) = &mut self.lab {
            xyz.flush()?;
        }
        if let Some(csv) = &mut self.dipole {
            csv.flush()?;
        }
        Ok(())
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Observer for Recorder<'_, M, N, NA> {
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()> {
        match self.record(t, y) {
            Ok(()) => {
                self.t_reached = Some(t);
                // After a complete record: the files end on a whole row and a whole frame.
                if self.stop.load(Ordering::SeqCst) {
                    self.interrupted = true;
                    return ControlFlow::Break(());
                }
                ControlFlow::Continue(())
            }
            Err(e) => {
                self.error = Some(e);
                ControlFlow::Break(())
            }
        }
    }
}
