//! One trajectory of a scene, integrated into an output folder (`rovib run SCENE.toml`): the
//! start or a continuation from `restart.json`, the folder's lock, the output writers, the energy
//! guard, the stop conditions and summary.json. [`Simulation`] is the entry point; it takes a
//! stop flag and a progress callback and installs no signal handler.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::Progress;
use crate::dir_lock::DirLock;
use crate::error::Error;
use crate::external_potential::{External, ExternalPotential};
use crate::molecules;
use crate::output::{Conservation, RunSummary, energy_guard, remove_stale_outputs, write_summary};
use crate::report::{Frame, LabFrame, Needs, Open, Reporter};
use crate::restart::{Dop853Point, FinalState, Restart};
use crate::runtime::cartesian_system::CartesianSystem;
use crate::runtime::charts::{self, ChartError, ChartObserver, ChartReport, ChartStart, ChartState};
use crate::runtime::frames::body_of_lab_exact;
use crate::runtime::frames::{CentreOfMass, LabState, to_lab_body};
use crate::runtime::hamiltonian::fast::BodyState;
use crate::runtime::hamiltonian::{ReducedSystem, Reduction, RotationPart};
use crate::runtime::integrate::{Dop853, Dop853Resume, Method, Observer, OdeSystem, SolveError, Stats, solve};
use crate::runtime::nalgebra::{Quaternion, SVector, UnitQuaternion, Vector3};
use crate::runtime::surface::Dipole;
use crate::runtime::{Molecule, MoleculeVisitor};
use crate::scene::{Scene, parse_scene};
use crate::start::{StopCondition, frozen_reduction, stop_conditions};
use std::sync::atomic::{AtomicBool, Ordering};
// The initial state and the production system live in `crate::start`; re-exported here for
// callers that used these paths.
use crate::start::production_system_unchecked;
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
    /// Warnings about the scene (also in summary.json), e.g. a start far above the reference
    /// energy.
    pub warnings: Vec<String>,
    /// The stop condition that ended the run (`run.stop_outside`), as in summary.json.
    pub stopped: Option<serde_json::Value>,
}

/// One trajectory of a scene, ready to run into its output folder.
///
/// ```no_run
/// use std::sync::atomic::AtomicBool;
/// use rovib::Simulation;
///
/// let stop = AtomicBool::new(false);
/// let sim = Simulation::load("scenes/h2o.toml".as_ref(), Some("out/h2o".as_ref()))?;
/// let report = sim.run(&stop, &mut |p| eprintln!("{}/{} outputs", p.done, p.total))?;
/// // Later, with a later `run.end` in the scene: continue from restart.json.
/// let more = Simulation::resume("out/h2o".as_ref(), Some("scenes/h2o_longer.toml".as_ref()))?;
/// more.run(&stop, &mut |_| {})?;
/// # Ok::<(), rovib::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct Simulation {
    scene: Scene,
    out_dir: PathBuf,
    restart: Option<Restart>,
}

impl Simulation {
    /// The scene at `path`, to run into `out_dir` (default `out/SCENE_NAME`, created).
    pub fn load(path: &Path, out_dir: Option<&Path>) -> Result<Self, Error> {
        let (scene, out_dir) = load_scene(path, out_dir, "")?;
        Ok(Self { scene, out_dir, restart: None })
    }

    /// A parsed scene (see [`crate::scene::parse_scene`]), to run into `out_dir` (created when
    /// the run starts).
    pub fn from_scene(scene: Scene, out_dir: impl Into<PathBuf>) -> Self {
        Self { scene, out_dir: out_dir.into(), restart: None }
    }

    /// The continuation of the run in `dir` from its `restart.json` (`rovib run --resume DIR
    /// [SCENE]`): with the scene stored there, or with `scene`, which may change `run.end` (to
    /// continue further) but nothing that would make the continuation a different run. The run
    /// appends to trajectory.csv and lab.xyz and rewrites summary.json (this part's work,
    /// `resumed_from`) and restart.json.
    pub fn resume(dir: &Path, scene: Option<&Path>) -> Result<Self, Error> {
        let restart = Restart::read(dir)?;
        let stored = parse_scene(&restart.scene_path, &restart.scene_text)?;
        let scene = match scene {
            Some(path) => load_scene(path, Some(dir), "")?.0,
            None => stored.clone(),
        };
        compatible(&scene, &stored, &restart)?;
        Ok(Self { scene, out_dir: dir.to_owned(), restart: Some(restart) })
    }

    /// [`Simulation::resume`] with a parsed scene (see [`crate::scene::parse_scene`]) in place
    /// of a scene file: the same checks, the same continuation.
    pub fn resume_with_scene(dir: &Path, scene: Scene) -> Result<Self, Error> {
        let restart = Restart::read(dir)?;
        let stored = parse_scene(&restart.scene_path, &restart.scene_text)?;
        compatible(&scene, &stored, &restart)?;
        Ok(Self { scene, out_dir: dir.to_owned(), restart: Some(restart) })
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The output folder.
    pub fn out_dir(&self) -> &Path {
        &self.out_dir
    }

    /// Runs to the scene's end (or its stop condition) on this thread, writing the outputs the
    /// scene asks for. `progress` is called after each output record; when `stop` is set (by the
    /// callback or another thread) the run ends after the current record, the files ending on a
    /// whole row and frame, summary.json and restart.json written, and returns
    /// [`Error::Interrupted`]. A run that fails keeps what it wrote and says where.
    pub fn run(&self, stop: &AtomicBool, progress: &mut dyn FnMut(Progress)) -> Result<RunReport, Error> {
        self.run_with_reporters(stop, progress, Vec::new())
    }

    /// [`Simulation::run`], with `reporters` called at every output time after the scene's own
    /// outputs (each gets what its [`Reporter::needs`] asks for).
    pub fn run_with_reporters(
        &self,
        stop: &AtomicBool,
        progress: &mut dyn FnMut(Progress),
        reporters: Vec<Box<dyn Reporter + '_>>,
    ) -> Result<RunReport, Error> {
        std::fs::create_dir_all(&self.out_dir).map_err(|e| Error::io("cannot create", &self.out_dir, e))?;
        self.run_with(stop, progress, reporters, false, None)
    }

    /// [`Simulation::run`] with `extra` reporters, and `in_memory` when nothing is to be written
    /// (`crate::memory`: no folder, no lock; the summary goes to the reporters), and the
    /// molecule on `potential` if given.
    pub(crate) fn run_with<'a>(
        &'a self,
        stop: &'a AtomicBool,
        progress: &'a mut dyn FnMut(Progress),
        extra: Vec<Box<dyn Reporter + 'a>>,
        in_memory: bool,
        potential: Option<&'a dyn ExternalPotential>,
    ) -> Result<RunReport, Error> {
        let name = self.scene.molecule.get_ref().clone();
        let resume = self.restart.as_ref();
        let visitor =
            Run { scene: &self.scene, out_dir: &self.out_dir, stop, progress, resume, extra, in_memory, potential };
        molecules::visit(&name, visitor).ok_or_else(|| {
            let e = Error::unknown_molecule(&name);
            Error::File(self.scene.source().error(
                self.scene.molecule.span(),
                e.to_string(),
                "use a name from `rovib list`",
            ))
        })?
    }
}

/// Runs the scene at `path` into `out_dir` (default `out/SCENE_NAME`) to its end, without a
/// stop flag or progress: [`Simulation::load`] then [`Simulation::run`].
pub fn run(path: &Path, out_dir: Option<&Path>) -> Result<RunReport, Error> {
    Simulation::load(path, out_dir)?.run(&AtomicBool::new(false), &mut |_| {})
}

/// Continues the run in `dir` (see [`Simulation::resume`]) to its end.
pub fn resume(dir: &Path, scene: Option<&Path>) -> Result<RunReport, Error> {
    Simulation::resume(dir, scene)?.run(&AtomicBool::new(false), &mut |_| {})
}

/// Whether `scene` continues the run that wrote `restart` (with scene `stored`): the same
/// molecule, integrator, output times, units, outputs and frozen coordinates, and a later end.
fn compatible(scene: &Scene, stored: &Scene, restart: &Restart) -> Result<(), Error> {
    let frozen = |s: &Scene| s.frozen.iter().map(|f| f.get_ref().clone()).collect::<Vec<_>>();
    let parameters =
        |s: &Scene| s.parameters.iter().map(|(n, v)| (n.get_ref().clone(), v.to_bits())).collect::<Vec<_>>();
    let differences: Vec<&str> = [
        (scene.molecule.get_ref() != stored.molecule.get_ref(), "molecule"),
        (scene.method != stored.method, "[integrator]"),
        (scene.output_interval.to_bits() != stored.output_interval.to_bits(), "run.output_interval"),
        (scene.time_unit != stored.time_unit, "units.time"),
        (scene.outputs != stored.outputs, "run.outputs"),
        (frozen(scene) != frozen(stored), "run.frozen"),
        (scene.euler_unwrapped != stored.euler_unwrapped, "run.euler_unwrapped"),
        (scene.cartesian_fallback != stored.cartesian_fallback, "run.cartesian_fallback"),
        (scene.min_metric_pivot != stored.min_metric_pivot, "run.min_metric_pivot"),
        (parameters(scene) != parameters(stored), "potential.parameters"),
    ]
    .into_iter()
    .filter_map(|(differs, what)| differs.then_some(what))
    .collect();
    if !differences.is_empty() {
        return Err(Error::Message(format!(
            "{} differs from the run being continued ({}) in {}: a continuation may change only run.end (and \
             run.max_energy_error, run.max_outputs)",
            scene.path,
            restart.scene_path,
            differences.join(", ")
        )));
    }
    if scene.t_end <= restart.t_au {
        return Err(Error::Message(format!(
            "the run already reached t = {} {}, and the scene ends at {} {}: give a later run.end to continue",
            restart.t,
            restart.time_unit,
            scene.t_end / scene.time_unit.in_au(),
            scene.time_unit.name()
        )));
    }
    Ok(())
}

struct Run<'a> {
    scene: &'a Scene,
    out_dir: &'a Path,
    stop: &'a AtomicBool,
    progress: &'a mut dyn FnMut(Progress),
    resume: Option<&'a Restart>,
    /// Reporters beyond the scene's outputs (a run in memory's sink).
    extra: Vec<Box<dyn Reporter + 'a>>,
    /// Whether the run writes nothing (a run in memory).
    in_memory: bool,
    /// A potential given at run time, replacing the molecule's.
    potential: Option<&'a dyn ExternalPotential>,
}

/// H(0) − U(reference) above which a run warns that it starts far above the reference energy,
/// hartree (0.1 hartree = 2.7 eV, about half the dissociation energy of a single bond and 100
/// times kT at 300 K; a length given in the wrong unit typically lands at or above it: water's
/// r1 = 1.81 meant in bohr but read in Å starts 0.14 hartree up).
pub const HIGH_START_ENERGY: f64 = 0.1;

/// The warning for a start at `h0` when the potential at the reference geometry is `u_ref`
/// (hartree), if it is far above.
pub fn start_energy_warning(name: &str, h0: f64, u_ref: f64) -> Option<String> {
    use crate::runtime::units::{HARTREE_IN_EV, HARTREE_IN_WAVENUMBERS};
    let above = h0 - u_ref;
    (above > HIGH_START_ENERGY).then(|| {
        format!(
            "the start is {:.3} eV ({:.0} cm-1) above the potential at {name}'s reference geometry, more than {:.1} eV: \
             the molecule may dissociate or leave the potential's valid region (check the scene's units: q values \
             are in each coordinate's declared unit unless [units] says otherwise)",
            above * HARTREE_IN_EV,
            above * HARTREE_IN_WAVENUMBERS,
            HIGH_START_ENERGY * HARTREE_IN_EV
        )
    })
}

impl MoleculeVisitor for Run<'_> {
    type Output = Result<RunReport, Error>;

    /// With the scene's `[potential] library` the molecule runs on that potential; with its
    /// `[potential.parameters]` on its own with them (the run-time path), else with its
    /// compiled-in constants.
    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        if let Some(p) = self.potential {
            crate::external_potential::check_external(&m, p)?;
            return self.go(crate::runtime::surface::WithPotential { molecule: m, potential: External(p) });
        }
        crate::scene_molecule::with_scene_molecule(self.scene, m, self)
    }
}

impl crate::scene_molecule::SceneMoleculeUser for Run<'_> {
    type Output = RunReport;

    fn with_molecule<M: Molecule<N, NA> + Sync, const N: usize, const NA: usize>(
        self,
        m: M,
    ) -> Result<RunReport, Error> {
        self.go(m)
    }
}

/// Where a run starts: the integrated system and its flat state, the centre of mass, the
/// time (a.u.) and body state, and a lab-frame start at a linear geometry (which begins in the
/// Cartesian chart as given).
struct Begin<'m, M, const N: usize, const NA: usize> {
    system: ReducedSystem<'m, M, N, NA>,
    y0: Vec<f64>,
    com: (Vector3<f64>, Vector3<f64>),
    t0: f64,
    body: BodyState<N>,
    lab: Option<Vec<f64>>,
}

/// What the integration gave: its statistics and DOP853 continuation point, or its error; the
/// time it took; the chart switches (if the run could switch); right-hand sides evaluated.
struct Integrated {
    result: Result<(Stats, Option<Dop853Resume>), SolveError<ChartError>>,
    wall_time: f64,
    charts: Option<ChartReport>,
    evaluations: u64,
}

impl Run<'_> {
    /// The run: its start, its output folder (locked, cleared of an earlier run's files), the
    /// integration with its recorder, then the restart file, the summary and the report.
    fn go<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Result<RunReport, Error> {
        let scene = self.scene;
        let in_memory = self.in_memory;
        let needs = self.extra.iter().fold(scene.outputs.files.needs(), |n, r| n.union(r.needs()));
        if needs.dipole && !m.has_dipole() {
            let output = scene.outputs.files.iter().find(|o| o.needs.dipole).map_or("dipole", |o| o.name);
            return Err(Error::File(scene.source().error(
                scene.molecule.span(),
                format!(
                    "the scene asks for the \"{output}\" output, but molecule `{}` has no dipole surface",
                    m.name()
                ),
                format!(
                    "add a [dipole] table to {} (see docs/src/reference/definition.md), or remove \"{output}\" from \
                     run.outputs",
                    m.source()
                ),
            )));
        }
        if let (crate::scene::chart::RunChart::Cartesian, Some(span)) = &scene.chart {
            return Err(Error::File(scene.source().error(
                span.clone(),
                "`run.chart = \"cartesian\"` applies to ensembles ([ensemble]) only",
                "remove it: `rovib run` integrates in internal coordinates and continues in the Cartesian chart \
                 near linear geometries (run.cartesian_fallback)",
            )));
        }
        let mut warnings = Vec::new();
        if scene.central_differences {
            warnings.push(crate::surface_gradient::note(N));
        }
        let begin = self.begin(&m, &mut warnings)?;
        let layout = layout(begin.system.reduction(), &m);
        let stops = stop_conditions(&m, scene)?;

        // One run per directory, then no file of an earlier run may remain looking like this one's.
        let _lock = if in_memory { None } else { Some(DirLock::acquire(self.out_dir)?) };
        let mut reporters = if in_memory {
            Vec::new()
        } else {
            crate::ensemble::output::clear_for_run(self.out_dir)?;
            self.open_reporters(&m)?
        };
        let records = self.resume.map_or(0, |r| r.outputs_done + 1);
        let Run { scene, out_dir, stop, progress, resume, extra, .. } = self;
        reporters.extend(extra);
        let mut recorder = Recorder::<M, N, NA> {
            system: begin.system,
            layout: layout.clone(),
            time_scale: scene.time_unit.in_au(),
            time_unit: scene.time_unit.name(),
            com: begin.com,
            reporters,
            in_memory,
            guard: EnergyGuard {
                diagnostics: scene.outputs.summary || scene.outputs.restart || in_memory,
                conservation: resume.map_or_else(Conservation::default, |r| r.conservation.clone()),
                initial_energy: resume.and_then(|r| r.conservation.initial_energy),
                max_energy_error: scene.max_energy_error,
            },
            stops: Stops { flag: stop, interrupted: false, outside: stops, met: None },
            count: Count {
                progress,
                total: (scene.t_end / scene.output_interval).ceil() as u64 + 1,
                records,
                // A fixed-step continuation starts the solver at the last output time, which the
                // first run already wrote.
                skip_first: resume.is_some() && !dop853_continues(scene, resume),
            },
            last: LastOutput {
                y: begin.y0.clone(),
                y_valid: true,
                q: begin.body.q,
                cartesian: CartesianSystem::new(&m).ok(),
            },
            t_reached: None,
            error: None,
        };
        let integrated = integrate_run(scene, resume, &begin, &mut recorder);
        Finish { scene, out_dir, resume }.finish(&m, begin, recorder, integrated, &layout, warnings)
    }

    /// The start: the scene's initial state (checked before anything is written, unless it is
    /// a linear start the Cartesian chart can take) or the restart file's state; a warning if
    /// it lies far above the reference geometry's energy.
    fn begin<'m, M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &'m M,
        warnings: &mut Vec<String>,
    ) -> Result<Begin<'m, M, N, NA>, Error> {
        let scene = self.scene;
        let Some(r) = self.resume else {
            let start = initial_state(m, scene)?;
            let lab = start.lab_start.clone();
            let (system, y0) = match production_system(m, scene, &start.body) {
                Ok(s) => s,
                Err(e) => match production_system_unchecked(m, scene, &start.body) {
                    Ok(s) if uses_charts(scene, &s.0) => s,
                    _ => return Err(e.into()),
                },
            };
            if let Some(q_ref) = m.reference_geometry() {
                let h0 = match system.energy(&y0) {
                    Ok(h) => h,
                    Err(_) if uses_charts(scene, &system) => lab
                        .clone()
                        .or_else(|| charts::to_cartesian(m, &start.body).ok())
                        .and_then(|y| CartesianSystem::new(m).ok()?.energy(&y).ok())
                        .ok_or_else(|| Error::Message("the initial state: no finite energy".into()))?,
                    Err(e) => return Err(Error::context("the initial state", e)),
                };
                warnings.extend(start_energy_warning(m.name(), h0, m.potential(&q_ref)));
            }
            let com = (start.com_position, start.com_velocity);
            return Ok(Begin { system, y0, com, t0: 0.0, body: start.body, lab });
        };
        let (system, y0) = resumed_system(m, scene, r)?;
        let com = (Vector3::from(r.com_position_bohr), Vector3::from(r.com_velocity_bohr_per_au));
        Ok(Begin { system, y0, com, t0: r.t_au, body: restart_body(r)?, lab: None })
    }

    /// Removes the files of an earlier run this one will not write, then creates (or, when
    /// resuming, checks and opens for appending) the ones it writes as it goes.
    fn open_reporters<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
    ) -> Result<Vec<Box<dyn Reporter + 'static>>, Error> {
        let (scene, dir) = (self.scene, self.out_dir);
        let keep: Vec<&str> = scene.outputs.files.files().collect();
        remove_stale_outputs(dir, &keep)?;
        let (coordinates, atoms) = (m.coordinates(), m.atoms());
        let open = Open {
            dir,
            coordinates: &coordinates,
            atoms: &atoms,
            time_unit: scene.time_unit.name(),
            euler_unwrapped: scene.euler_unwrapped,
            resume: self.resume,
        };
        scene.outputs.files.iter().map(|o| (o.open)(&open)).collect()
    }
}

/// The part of a run that writes its ending: the scene, the output folder, the restart file it continues.
struct Finish<'a> {
    scene: &'a Scene,
    out_dir: &'a Path,
    resume: Option<&'a Restart>,
}

impl Finish<'_> {
    /// After the integration: flushes the files, writes the restart file and the summary, and
    /// reports the run, or the first thing that went wrong (a failed record, the solver's error,
    /// a failed flush, in that order), or the interruption.
    fn finish<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        self,
        m: &M,
        begin: Begin<'_, M, N, NA>,
        mut recorder: Recorder<'_, M, N, NA>,
        integrated: Integrated,
        layout: &str,
        warnings: Vec<String>,
    ) -> Result<RunReport, Error> {
        let scene = self.scene;
        let Integrated { result, wall_time, charts: chart_report, evaluations } = integrated;
        // Keep everything written so far, whatever happened.
        let flushed = recorder.flush();
        let (stats, point, failure) = match result {
            Ok((stats, point)) => (Some(stats), point, recorder.error.take().map(|e| format!("the run stopped: {e}"))),
            Err(e) => {
                let note = crate::surfaces::grid::failure_note(&e, scene);
                (None, None, Some(format!("the run stopped: {}{note}", describe_failure(&e, scene, layout))))
            }
        };
        let failure = failure.or_else(|| flushed.err().map(|e| format!("the run stopped: {e}")));
        let interrupted = recorder.stops.interrupted && failure.is_none();
        let stopped = recorder.stops.met.take().filter(|_| failure.is_none());
        let t_reached = recorder.t_reached.map(|t| t / scene.time_unit.in_au());
        let mut files: Vec<PathBuf> = scene.outputs.files.files().map(|f| self.out_dir.join(f)).collect();
        let mut summary_error = None;
        if scene.outputs.restart
            && failure.is_none()
            && let Some(t) = recorder.t_reached
        {
            let restart = recorder.restart(scene, t, point.as_ref(), layout);
            match restart.and_then(|r| r.write(self.out_dir)) {
                Ok(path) => files.push(path),
                Err(e) => summary_error = Some(e.to_string()),
            }
        }
        let in_memory = recorder.in_memory;
        if scene.outputs.summary || in_memory {
            let summary = RunSummary {
                scene,
                molecule: m.name(),
                failure: failure.as_deref(),
                interrupted,
                stopped: stopped.as_ref(),
                t_reached,
                state_layout: layout,
                zero_angular_momentum: begin.system.reduction().rotation != RotationPart::Free,
                stats,
                rhs_evaluations: evaluations,
                wall_time,
                conservation: &recorder.guard.conservation,
                com_position: begin.com.0,
                com_velocity: begin.com.1,
                resumed_from: self.resume.map(|r| r.t),
                warnings: &warnings,
                charts: chart_report.is_some().then(|| charts_json(chart_report.as_ref(), scene)),
            };
            let json = summary.to_json();
            if !in_memory {
                match write_summary(self.out_dir, &json) {
                    Ok(path) => files.push(path),
                    Err(e) => summary_error = summary_error.or(Some(e.to_string())),
                }
            }
            if failure.is_none() {
                recorder.reporters.iter_mut().for_each(|r| r.summary(&json));
            }
        }
        let where_ = if in_memory {
            "the records so far were returned".to_owned()
        } else {
            format!("output so far is in {}", self.out_dir.display())
        };
        // The warnings about the scene, which a failed run has no report to carry.
        let notes: String = warnings.iter().map(|w| format!("; warning: {w}")).collect();
        let message = match (failure, interrupted, summary_error) {
            (Some(f), _, Some(s)) => Some(format!("{f}; also {s} (no summary.json); {where_}{notes}")),
            (Some(f), _, None) => Some(format!("{f}; {where_}{notes}")),
            (None, true, s) => {
                return Err(Error::Interrupted {
                    message: format!(
                        "interrupted at t = {} {}{}; {where_}{}",
                        t_reached.unwrap_or(0.0),
                        scene.time_unit.name(),
                        s.map(|s| format!("; {s} (no summary.json)")).unwrap_or_default(),
                        if scene.outputs.restart {
                            format!(
                                "; continue it with `rovib run --resume {}` or `Simulation::resume`",
                                self.out_dir.display()
                            )
                        } else {
                            String::new()
                        }
                    ),
                    out_dir: self.out_dir.to_owned(),
                });
            }
            (None, false, Some(s)) => Some(s),
            (None, false, None) => None,
        };
        if let Some(message) = message {
            return Err(Error::Message(message));
        }
        let stats = stats.unwrap_or_default();
        Ok(RunReport {
            out_dir: self.out_dir.to_owned(),
            files,
            stats,
            conservation: recorder.guard.conservation,
            wall_time,
            warnings,
            stopped,
        })
    }
}

/// Integrates from `begin` with the chart switch where the run can switch
/// ([`uses_charts`]), else in the internal chart, handing each output time to `recorder`.
fn integrate_run<M: Molecule<N, NA>, O: ChartObserver + Observer, const N: usize, const NA: usize>(
    scene: &Scene,
    resume: Option<&Restart>,
    begin: &Begin<'_, M, N, NA>,
    recorder: &mut O,
) -> Integrated {
    let clock = Instant::now();
    if uses_charts(scene, &begin.system) {
        let mut report = ChartReport::default();
        let r = integrate_charts(
            &begin.system,
            scene,
            begin.t0,
            &begin.body,
            begin.lab.as_deref(),
            resume,
            recorder,
            &mut report,
        );
        let result = r.map(|()| (report.stats, report.resume.clone()));
        let evaluations = report.stats.rhs_evals;
        return Integrated { result, wall_time: clock.elapsed().as_secs_f64(), charts: Some(report), evaluations };
    }
    let mut counted = Counted { inner: begin.system, evaluations: 0 };
    let result = integrate(&mut counted, scene, begin.t0, &begin.y0, resume, recorder)
        .map_err(|e| charts::map_error(e, ChartError::Internal));
    Integrated { result, wall_time: clock.elapsed().as_secs_f64(), charts: None, evaluations: counted.evaluations }
}

/// Whether the run switches to the Cartesian chart at singular geometries: DOP853, a molecule
/// with a Cartesian potential (coordinates by kind, compiled parameters) and no frozen
/// coordinates (`crate::runtime::charts`).
fn uses_charts<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    scene: &Scene,
    system: &ReducedSystem<'_, M, N, NA>,
) -> bool {
    scene.cartesian_fallback && matches!(scene.method, Method::Dop853(_)) && charts::can_switch(system)
}

/// The chart switches of a run, for summary.json.
fn charts_json(report: Option<&ChartReport>, scene: &Scene) -> serde_json::Value {
    let per_unit = 1.0 / scene.time_unit.in_au();
    match report {
        Some(r) => {
            // The time spent in the fallback chart the run used: the rigid chart for rigid
            // complexes, the Cartesian chart otherwise.
            let rigid = r.rigid_time > 0.0 || r.last_chart == Some(charts::Chart::Rigid);
            let (key, time) = if rigid { ("rigid_time", r.rigid_time) } else { ("cartesian_time", r.cartesian_time) };
            let mut value = serde_json::json!({
                "switch_pivot": charts::SWITCH_PIVOT,
                "return_pivot": charts::RETURN_PIVOT,
                "switches": r.switches,
                "last_chart": r.last_chart.map(|c| match c {
                    charts::Chart::Internal => "internal",
                    charts::Chart::Cartesian => "cartesian",
                    charts::Chart::Rigid => "rigid",
                }),
            });
            value[key] = (time * per_unit).into();
            value
        }
        None => serde_json::json!({
            "switch_pivot": charts::SWITCH_PIVOT,
            "return_pivot": charts::RETURN_PIVOT,
        }),
    }
}

/// The body state stored in a restart file.
fn restart_body<const N: usize>(r: &Restart) -> Result<BodyState<N>, Error> {
    let [w, x, y, z] = r.state.orientation;
    let orientation = UnitQuaternion::try_new(Quaternion::new(w, x, y, z), 0.0)
        .ok_or_else(|| Error::Message("the restart file's orientation quaternion is zero".into()))?;
    if r.state.q.len() != N || r.state.p.len() != N {
        return Err(Error::Message(format!("the restart file has {} coordinates, expected {N}", r.state.q.len())));
    }
    Ok(BodyState {
        q: SVector::from_column_slice(&r.state.q),
        p: SVector::from_column_slice(&r.state.p),
        orientation,
        j: Vector3::from(r.state.j),
    })
}

/// [`integrate`] with the chart switch of `crate::runtime::charts` (DOP853 only): fresh from
/// `start`, or continuing `resume` (from its DOP853 point in the internal chart, else from its
/// last output state with the output grid restarted there, as [`integrate`] does).
#[allow(clippy::too_many_arguments)]
fn integrate_charts<M: Molecule<N, NA>, O: ChartObserver, const N: usize, const NA: usize>(
    system: &ReducedSystem<'_, M, N, NA>,
    scene: &Scene,
    t0: f64,
    start: &BodyState<N>,
    lab_start: Option<&[f64]>,
    resume: Option<&Restart>,
    observer: &mut O,
    report: &mut ChartReport,
) -> Result<(), SolveError<ChartError>> {
    let Method::Dop853(options) = scene.method else {
        return Err(SolveError::InvalidInput("the chart switch runs with dop853 only".into()));
    };
    let (t_end, interval) = (scene.t_end, scene.output_interval);
    match resume {
        Some(r) if dop853_continues(scene, resume) => {
            let point = r.dop853.as_ref().expect("checked by dop853_continues").to_resume(r.outputs_done);
            charts::integrate(system, options, 0.0, ChartStart::Resume(&point), t_end, interval, observer, report)
        }
        None if lab_start.is_some() => {
            let y = lab_start.expect("checked");
            charts::integrate(system, options, t0, ChartStart::FreshCartesian(y), t_end, interval, observer, report)
        }
        _ => charts::integrate(system, options, t0, ChartStart::Fresh(start), t_end, interval, observer, report),
    }
}

/// Whether a resumed run continues DOP853 from its own continuation point (else it restarts the
/// solver at the last output time).
fn dop853_continues(scene: &Scene, resume: Option<&Restart>) -> bool {
    matches!(scene.method, Method::Dop853(_)) && resume.is_some_and(|r| r.dop853.is_some())
}

/// Runs the solver: fresh from `(t0, y0)`, or continuing `resume`. Returns the work and, for
/// DOP853, where it stood at the end.
fn integrate<S: OdeSystem, O: Observer>(
    system: &mut S,
    scene: &Scene,
    t0: f64,
    y0: &[f64],
    resume: Option<&Restart>,
    observer: &mut O,
) -> Result<(Stats, Option<Dop853Resume>), SolveError<S::Error>> {
    let (t_end, interval) = (scene.t_end, scene.output_interval);
    match (&scene.method, resume) {
        (Method::Dop853(o), None) => {
            Dop853::new(system.dim(), *o)?.integrate_resumable(system, 0.0, y0, t_end, interval, observer)
        }
        (Method::Dop853(o), Some(r)) if dop853_continues(scene, resume) => {
            let point = r.dop853.as_ref().expect("checked by dop853_continues").to_resume(r.outputs_done);
            if point.y.len() != system.dim() {
                return Err(SolveError::InvalidInput(format!(
                    "the restart file's DOP853 state has {} components, the system {}",
                    point.y.len(),
                    system.dim()
                )));
            }
            Dop853::new(system.dim(), *o)?.resume(system, 0.0, &point, t_end, interval, observer)
        }
        (method, _) => Ok((solve(system, method, t0, y0, t_end, interval, observer)?, None)),
    }
}

/// The system and flat state a resumed run continues from: the scene's frozen coordinates, the
/// `J = 0` reduction if the first run had it, the restart file's state as the template.
fn resumed_system<'m, M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &'m M,
    scene: &Scene,
    r: &Restart,
) -> Result<(ReducedSystem<'m, M, N, NA>, Vec<f64>), Error> {
    let bad = |what: String| Error::Message(format!("the restart file does not fit {}: {what}", m.name()));
    if r.molecule != m.name() {
        return Err(bad(format!("it is of {}", r.molecule)));
    }
    if r.state.q.len() != N || r.state.p.len() != N {
        return Err(bad(format!("{} coordinates and {} momenta, expected {N}", r.state.q.len(), r.state.p.len())));
    }
    let [w, x, y, z] = r.state.orientation;
    let orientation = UnitQuaternion::try_new(Quaternion::new(w, x, y, z), 0.0)
        .ok_or_else(|| bad("the orientation quaternion is zero".into()))?;
    let body = BodyState {
        q: SVector::from_column_slice(&r.state.q),
        p: SVector::from_column_slice(&r.state.p),
        orientation,
        j: Vector3::from(r.state.j),
    };
    let mut reduction = frozen_reduction(m, scene)?;
    if r.zero_angular_momentum {
        reduction.rotation = RotationPart::ZeroAngularMomentum {
            orientation: scene.outputs.files.needs().orientation() || reduction.active_count() == 0,
        };
    }
    let system = ReducedSystem::from_body(m, reduction, &body).with_min_pivot(scene.min_metric_pivot);
    if system.dim() != r.y.len() {
        return Err(bad(format!("its state has {} components, the run's system {}", r.y.len(), system.dim())));
    }
    Ok((system, r.y.clone()))
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
    /// The flat layout, for messages.
    layout: String,
    time_scale: f64,
    time_unit: &'static str,
    com: (Vector3<f64>, Vector3<f64>),
    /// The outputs, called at every output time.
    reporters: Vec<Box<dyn Reporter + 'm>>,
    /// Whether the run writes nothing (a run in memory).
    in_memory: bool,
    guard: EnergyGuard,
    stops: Stops<'m>,
    count: Count<'m>,
    last: LastOutput<'m, M, N, NA>,
    /// The last output time recorded, a.u.
    t_reached: Option<f64>,
    error: Option<String>,
}

/// The conservation diagnostics and the guard against a run that has gone unstable.
struct EnergyGuard {
    /// Whether to accumulate the diagnostics (for the summary, the restart file or a run in memory).
    diagnostics: bool,
    conservation: Conservation,
    /// H at the first output time, for the guard.
    initial_energy: Option<f64>,
    /// The relative energy error at which the run stops.
    max_energy_error: f64,
}

/// What ends a run between output records: the caller's stop flag and `run.stop_outside`.
struct Stops<'m> {
    /// The caller's stop flag, polled after each output record, so the run stops between records.
    flag: &'m AtomicBool,
    /// Whether the run stopped on `flag`.
    interrupted: bool,
    /// `run.stop_outside`: coordinate index, name, bounds in atomic units.
    outside: Vec<StopCondition>,
    /// The stop condition met, for summary.json.
    met: Option<serde_json::Value>,
}

/// The output records: how many so far and in the whole run, reported to the progress callback.
struct Count<'m> {
    /// Called after each output record.
    progress: &'m mut dyn FnMut(Progress),
    /// Output records of the whole run (the progress total).
    total: u64,
    /// Output records in the files so far (the next one is number `records` of the grid).
    records: u64,
    /// Whether to pass over the first call (a continuation's start, already written).
    skip_first: bool,
}

/// The state at the last output recorded, in the internal chart (for the restart file), and the
/// Cartesian chart that states near a linear geometry arrive in.
struct LastOutput<'m, M, const N: usize, const NA: usize> {
    /// The flat state (internal chart) at the last output recorded.
    y: Vec<f64>,
    /// Whether `y` is the last output's state (not so after an output at an exactly linear
    /// geometry, which the internal chart cannot hold).
    y_valid: bool,
    /// q at the last output recorded (the branch for closed-form angles).
    q: SVector<f64, N>,
    /// The Cartesian chart, if the molecule has one (states the chart switch hands over).
    cartesian: Option<CartesianSystem<'m, M, N, NA>>,
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Recorder<'_, M, N, NA> {
    fn record(&mut self, t: f64, state: ChartState<'_>) -> Result<(), Error> {
        let t_out = t / self.time_scale;
        let at = |e: &dyn std::fmt::Display, y: &[f64], layout: &str| {
            format!("{e} at t = {t_out} {}; state {layout} = {y:?}", self.time_unit)
        };
        // H at every output time: for the outputs, and for the guard against a run that has
        // gone unstable (a too large fixed step) and would otherwise "complete" with garbage.
        // A Cartesian-chart state (near a linear geometry) gives the same quantities through
        // the closed-form q(x) and projections, and the Cartesian H.
        let (y, cartesian) = match state {
            ChartState::Internal(y) => (y, None),
            ChartState::Cartesian(y) => (y, Some(y)),
        };
        let cartesian_layout = "[positions about the centre of mass (bohr), velocities (bohr/au)], atom by atom";
        let (body, energy, internal_y) = match cartesian {
            None => {
                let (body, energy) = self.system.expand_body_and_energy(y).map_err(|e| at(&e, y, &self.layout))?;
                (body, energy, None)
            }
            Some(y) => {
                let chart = self.last.cartesian.as_ref().ok_or("a Cartesian state without a Cartesian chart")?;
                let lab = CartesianSystem::<M, N, NA>::lab(y);
                let (body, _) = body_of_lab_exact(self.system.molecule(), &lab, &self.last.q)
                    .map_err(|e| at(&e, y, cartesian_layout))?;
                let energy = chart.energy(y).map_err(|e| at(&e, y, cartesian_layout))?;
                let internal = charts::to_internal(&self.system, y, &self.last.q).ok().map(|(_, yi)| yi);
                (body, energy, Some(internal))
            }
        };
        let layout = if cartesian.is_some() { cartesian_layout } else { self.layout.as_str() };
        let h0 = *self.guard.initial_energy.get_or_insert(energy);
        let rotation = body.rotation();
        let phase = body.to_phase();
        // Recorded before the guard, so that the summary includes the output that tripped it.
        if self.guard.diagnostics {
            self.guard.conservation.record(energy, body.j.norm(), phase.pe[0], (rotation * body.j).into());
        }
        energy_guard(h0, energy, self.guard.max_energy_error).map_err(|e| at(&e, y, layout))?;
        // What the reporters need beyond the phase-space state is computed only if one needs it.
        let needs = self.reporters.iter().fold(Needs::NOTHING, |n, r| n.union(r.needs()));
        let lab = if needs.lab {
            let com = CentreOfMass { position: self.com.0 + self.com.1 * t, velocity: self.com.1 };
            let lab: LabState<NA> = match cartesian {
                None => to_lab_body(self.system.molecule(), &body, &com).map_err(|e| at(&e, y, layout))?,
                Some(y) => {
                    let mut lab = CartesianSystem::<M, N, NA>::lab(y);
                    for i in 0..NA {
                        lab.positions.set_column(i, &(lab.positions.column(i) + com.position));
                        lab.velocities.set_column(i, &(lab.velocities.column(i) + com.velocity));
                    }
                    lab
                }
            };
            Some((lab, self.system.molecule().potential(&body.q)))
        } else {
            None
        };
        let dipole = needs.dipole.then(|| {
            // A run whose reporters need the dipole is refused for a molecule without one (`Run::go`).
            let mut mu = Vector3::from_element(f64::NAN);
            if let Some(dipole) = self.system.molecule().dipole() {
                dipole.moment(&body.q, &mut mu);
            }
            (rotation * mu).into()
        });
        let frame = Frame {
            t: t_out,
            q: phase.q.as_slice(),
            p: phase.p.as_slice(),
            euler: phase.euler.into(),
            pe: phase.pe.into(),
            j: body.j.into(),
            energy,
            lab: lab.as_ref().map(|(lab, potential)| LabFrame {
                positions: lab.positions.as_slice(),
                velocities: lab.velocities.as_slice(),
                potential: *potential,
            }),
            dipole,
        };
        for reporter in &mut self.reporters {
            reporter.report(&frame)?;
        }
        // A state the internal chart cannot hold (exactly linear) leaves no restart point.
        self.last.y_valid = true;
        match &internal_y {
            None => self.last.y.copy_from_slice(y),
            Some(Some(yi)) => self.last.y.copy_from_slice(yi),
            Some(None) => self.last.y_valid = false,
        }
        self.last.q = body.q;
        self.count.records += 1;
        if let Some(&(k, name, [low, high])) =
            self.stops.outside.iter().find(|(k, _, [lo, hi])| !(*lo..=*hi).contains(&body.q[*k]))
        {
            self.stops.met = Some(serde_json::json!({
                "coordinate": name,
                "value_au": body.q[k],
                "bounds_au": [low, high],
                "t": t_out,
                "checked": "at output times",
            }));
        }
        (self.count.progress)(Progress { done: self.count.records, total: self.count.total, failed: 0 });
        Ok(())
    }

    /// The restart file for a run that reached output time `t` (a.u.), with DOP853's
    /// continuation point if it has one.
    fn restart(&self, scene: &Scene, t: f64, point: Option<&Dop853Resume>, layout: &str) -> Result<Restart, Error> {
        if !self.last.y_valid {
            return Err("cannot write the restart file: the last output is at a linear geometry, which internal \
                 coordinates cannot hold (continue from an earlier time or run longer)"
                .into());
        }
        let body = self.system.expand_body(&self.last.y).map_err(|e| format!("cannot write the restart file: {e}"))?;
        let phase = body.to_phase();
        let q = body.orientation.quaternion();
        let m = self.system.molecule();
        let mut restart = Restart {
            format: crate::restart::FORMAT.to_owned(),
            scene_path: scene.path.clone(),
            scene_text: scene.text.clone(),
            molecule: m.name().to_owned(),
            t_au: t,
            t: t / self.time_scale,
            time_unit: self.time_unit.to_owned(),
            outputs_done: self.count.records.saturating_sub(1),
            state: FinalState {
                q: body.q.as_slice().to_vec(),
                p: body.p.as_slice().to_vec(),
                orientation: [q.w, q.i, q.j, q.k],
                j: body.j.into(),
                euler: phase.euler.into(),
                pe: phase.pe.into(),
            },
            y: self.last.y.clone(),
            state_layout: layout.to_owned(),
            zero_angular_momentum: self.system.reduction().rotation != RotationPart::Free,
            dop853: point.map(Dop853Point::from_resume),
            com_position_bohr: self.com.0.into(),
            com_velocity_bohr_per_au: self.com.1.into(),
            conservation: self.guard.conservation.clone(),
            euler_unwrapped: None,
        };
        for reporter in &self.reporters {
            reporter.continuation(&mut restart);
        }
        Ok(restart)
    }

    /// Flushes every reporter (all of them, also after one fails); the first error.
    fn flush(&mut self) -> Result<(), Error> {
        self.reporters.iter_mut().map(|r| r.flush()).fold(Ok(()), Result::and)
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Observer for Recorder<'_, M, N, NA> {
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()> {
        ChartObserver::observe(self, t, ChartState::Internal(y))
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> ChartObserver for Recorder<'_, M, N, NA> {
    fn observe(&mut self, t: f64, y: ChartState<'_>) -> ControlFlow<()> {
        if std::mem::take(&mut self.count.skip_first) {
            return ControlFlow::Continue(());
        }
        match self.record(t, y) {
            Ok(()) => {
                self.t_reached = Some(t);
                if self.stops.met.is_some() {
                    return ControlFlow::Break(());
                }
                // After a complete record: the files end on a whole row and a whole frame.
                if self.stops.flag.load(Ordering::SeqCst) {
                    self.stops.interrupted = true;
                    return ControlFlow::Break(());
                }
                ControlFlow::Continue(())
            }
            Err(e) => {
                self.error = Some(e.to_string());
                ControlFlow::Break(())
            }
        }
    }
}
