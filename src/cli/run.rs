//! `rovib run SCENE.toml`: integrate a scene and write its trajectory and diagnostics.

use std::io::IsTerminal as _;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

use super::{CliError, unknown_molecule};
use crate::molecules;
use crate::output::{Conservation, LabXyz, TrajectoryCsv, write_summary};
use crate::runtime::diagnostic::FileError;
use crate::runtime::frames::{FitOptions, LabState, from_lab};
use crate::runtime::hamiltonian::fast::{ReducedSystem, Reduction, ReductionError, RotationPart};
use crate::runtime::hamiltonian::{PhaseState, euler_momenta_from_angular_momentum, hamiltonian, w_matrix};
use crate::runtime::integrate::{Method, Observer, OdeSystem, SolveError, Stats, solve};
use crate::runtime::nalgebra::{SMatrix, SVector, Vector3};
use crate::runtime::units::CoordinateUnit;
use crate::runtime::{KineticMatrices, Molecule, MoleculeVisitor};
use crate::scene::{Initial, Momenta, Rotation as InitialRotation, Scene, parse_scene};

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

/// Reads and parses the scene at `path` and creates its output directory: `out_dir`, or by
/// default `out/SCENE_NAME` followed by `default_subdir` (for `rovib run` and `rovib bench`).
pub(crate) fn load_scene(
    path: &Path,
    out_dir: Option<&Path>,
    default_subdir: &str,
) -> Result<(Scene, PathBuf), CliError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| CliError::context(format!("cannot read {}", path.display()), e))?;
    let scene = parse_scene(&path.display().to_string(), &text)?;
    let out_dir = match out_dir {
        Some(d) => d.to_owned(),
        None => Path::new("out").join(path.file_stem().unwrap_or_default()).join(default_subdir),
    };
    std::fs::create_dir_all(&out_dir)
        .map_err(|e| CliError::context(format!("cannot create {}", out_dir.display()), e))?;
    Ok((scene, out_dir))
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

/// Where a run starts: the phase-space state and the centre-of-mass motion (bohr, bohr/a.u.).
pub struct Start<const N: usize> {
    /// The internal state.
    pub state: PhaseState<N>,
    /// Centre-of-mass position.
    pub com_position: Vector3<f64>,
    /// Centre-of-mass velocity.
    pub com_velocity: Vector3<f64>,
}

/// Binds the scene's initial condition to molecule `m`: names to indices, units to atomic units.
pub fn initial_state<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
) -> Result<Start<N>, FileError> {
    let src = scene.source();
    let coords = m.coordinates();
    let index = |name: &toml::Spanned<String>, what: &str| -> Result<usize, FileError> {
        coords.iter().position(|c| c.name == name.get_ref()).ok_or_else(|| {
            let known: Vec<&str> = coords.iter().map(|c| c.name).collect();
            src.error(
                name.span(),
                format!("{} has no coordinate `{}` (in {what})", m.name(), name.get_ref()),
                if known.is_empty() {
                    format!("{} is rigid: remove {what}", m.name())
                } else {
                    format!("the coordinates of {} are {}", m.name(), known.join(", "))
                },
            )
        })
    };
    // Per-coordinate factor from the scene's units to atomic units.
    let scale = |k: usize| match coords[k].unit {
        CoordinateUnit::Length(_) => scene.units.length,
        CoordinateUnit::Angle(_) => scene.units.angle,
    };
    match &scene.initial {
        Initial::Internal { q, momenta, euler, rotation } => {
            let mut qv = SVector::<f64, N>::zeros();
            let mut given = [false; N];
            for (name, value) in q {
                let k = index(name, "q")?;
                qv[k] = value * scale(k);
                given[k] = true;
            }
            if let Some(k) = (0..N).find(|&k| !given[k]) {
                let reference = m.reference_geometry().ok_or_else(|| {
                    src.error(
                        scene.molecule.span(),
                        format!(
                            "the initial q does not give `{}` and {} has no reference geometry",
                            coords[k].name,
                            m.name()
                        ),
                        format!("give every coordinate in q = {{ ... }}, or add `reference` values to {}", m.source()),
                    )
                })?;
                for k in (0..N).filter(|&k| !given[k]) {
                    qv[k] = reference[k];
                }
            }
            let euler = Vector3::from(*euler);
            let (pv, pe) = match (momenta, rotation) {
                (Momenta::P(p), rot) => {
                    let mut pv = SVector::<f64, N>::zeros();
                    for (name, value) in p {
                        pv[index(name, "p")?] = *value;
                    }
                    let pe = match rot {
                        InitialRotation::Pe(pe) => Vector3::from(*pe),
                        InitialRotation::J(j) => euler_momenta_from_angular_momentum(&euler, &Vector3::from(*j)),
                    };
                    (pv, pe)
                }
                (Momenta::Qdot(qd), rot) => {
                    let mut qdot = SVector::<f64, N>::zeros();
                    for (name, value) in qd {
                        let k = index(name, "qdot")?;
                        qdot[k] = value * scale(k) / scene.units.time;
                    }
                    // J is given (or follows from p_e); then ω = I⁻¹(J − A q̇) and p = Aᵀω + a q̇.
                    let j = match rot {
                        InitialRotation::J(j) => Vector3::from(*j),
                        InitialRotation::Pe(pe) => {
                            w_matrix(&euler).map_err(|e| {
                                src.whole_file(format!("the initial orientation: {e}"), "choose θ away from 0 and π")
                            })? * Vector3::from(*pe)
                        }
                    };
                    let mut k = KineticMatrices::<N>::default();
                    m.kinetic(&qv, &mut k);
                    let inertia = k.inertia.cholesky().ok_or_else(|| {
                        src.whole_file(
                            format!(
                                "the inertia tensor of {} is singular at the initial geometry q = {:?}",
                                m.name(),
                                qv.as_slice()
                            ),
                            "start from a geometry where the molecule is not linear",
                        )
                    })?;
                    let omega = inertia.solve(&(j - k.coriolis * qdot));
                    let pv = k.coriolis.transpose() * omega + k.a * qdot;
                    let pe = match rot {
                        InitialRotation::Pe(pe) => Vector3::from(*pe),
                        InitialRotation::J(_) => euler_momenta_from_angular_momentum(&euler, &j),
                    };
                    (pv, pe)
                }
            };
            Ok(Start {
                state: PhaseState { q: qv, p: pv, euler, pe },
                com_position: Vector3::zeros(),
                com_velocity: Vector3::zeros(),
            })
        }
        Initial::Lab { positions, velocities, span } => {
            let atoms = m.atoms();
            let atom_index = |label: &toml::Spanned<String>, what: &str| -> Result<usize, FileError> {
                atoms.iter().position(|a| a.label == label.get_ref()).ok_or_else(|| {
                    let known: Vec<&str> = atoms.iter().map(|a| a.label).collect();
                    src.error(
                        label.span(),
                        format!("{} has no atom `{}` (in {what})", m.name(), label.get_ref()),
                        format!("the atoms of {} are {}", m.name(), known.join(", ")),
                    )
                })
            };
            let mut lab = LabState::<NA> { positions: SMatrix::zeros(), velocities: SMatrix::zeros() };
            let mut given = [false; NA];
            for (label, x) in positions {
                let i = atom_index(label, "positions")?;
                lab.positions.set_column(i, &Vector3::from(*x));
                given[i] = true;
            }
            let missing: Vec<&str> = (0..NA).filter(|&i| !given[i]).map(|i| atoms[i].label).collect();
            if !missing.is_empty() {
                return Err(src.error(
                    span.clone(),
                    format!(
                        "the lab-frame positions do not give atom{} {}",
                        if missing.len() == 1 { "" } else { "s" },
                        missing.join(", ")
                    ),
                    "give the position of every atom, keyed by its label",
                ));
            }
            for (label, v) in velocities {
                lab.velocities.set_column(atom_index(label, "velocities")?, &Vector3::from(*v));
            }
            let (state, com, _) = from_lab(m, &lab, &FitOptions::default()).map_err(|e| {
                src.error(
                    span.clone(),
                    format!("the lab-frame positions cannot start a run of {}: {e}", m.name()),
                    "check the atom positions and their units; rotate the input if θ is at 0 or π",
                )
            })?;
            Ok(Start { state, com_position: com.position, com_velocity: com.velocity })
        }
    }
}

/// The system every command integrates, chosen from the scene: the body formulation (no
/// gimbal lock) on the fast path, reduced to what the scene needs: frozen coordinates as it
/// names them, `J = 0` when the initial angular momentum is exactly zero (then `J` stays
/// zero), and the orientation only when an output needs it. Returns the system and the
/// initial flat state.
pub fn production_system<'m, M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &'m M,
    scene: &Scene,
    start: &PhaseState<N>,
) -> Result<(ReducedSystem<'m, M, N, NA>, Vec<f64>), CliError> {
    let names: Vec<&str> = scene.frozen.iter().map(|s| s.get_ref().as_str()).collect();
    let mut reduction = Reduction::freezing(m, &names).map_err(|e| {
        let at = match &e {
            ReductionError::UnknownCoordinate { name, .. } => {
                scene.frozen.iter().find(|s| s.get_ref() == name).map_or(0..0, |s| s.span())
            }
            _ => 0..0,
        };
        scene.source().error(at, e.to_string(), "name coordinates from `rovib list` in run.frozen")
    })?;
    if start.pe == Vector3::zeros() {
        reduction.rotation =
            RotationPart::ZeroAngularMomentum { orientation: scene.outputs.lab || scene.outputs.trajectory };
    }
    let system = ReducedSystem::new(m, reduction, start).with_min_pivot(scene.min_metric_pivot);
    let mut y0 = vec![0.0; system.dim()];
    system.reduce(start, &mut y0).map_err(|e| CliError::context("the initial state", e))?;
    Ok((system, y0))
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
        let (system, y0) = production_system(&m, scene, &start.state)?;
        let layout = layout(system.reduction(), &m);

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
            diagnostics: scene.outputs.summary,
            conservation: Conservation::default(),
            initial_energy: None,
            max_energy_error: scene.max_energy_error,
            layout: layout.clone(),
            time_scale: scene.time_unit.in_au(),
            time_unit: scene.time_unit.name(),
            com: (start.com_position, start.com_velocity),
            progress: self.progress.then(|| progress_bar(scene)),
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

        let (stats, failure) = match result {
            Ok(stats) => (Some(stats), recorder.error.take().map(|e| format!("the run stopped: {e}"))),
            Err(e) => (None, Some(format!("the run stopped: {}", describe_failure(&e, scene, &layout)))),
        };
        let mut files: Vec<PathBuf> = Vec::new();
        if scene.outputs.trajectory {
            files.push(self.out_dir.join("trajectory.csv"));
        }
        if scene.outputs.lab {
            files.push(self.out_dir.join("lab.xyz"));
        }
        if scene.outputs.summary {
            let summary = json!({
                "scene": scene.path,
                "molecule": m.name(),
                "status": if failure.is_some() { "failed" } else { "completed" },
                "error": failure,
                "method": method_json(&scene.method),
                "formulation": "body-frame angular momentum J and unit quaternion, fast right-hand side",
                "state_layout": layout,
                "frozen": scene.frozen.iter().map(|s| s.get_ref().as_str()).collect::<Vec<_>>(),
                "zero_angular_momentum": system.reduction().rotation != RotationPart::Free,
                "min_metric_pivot": scene.min_metric_pivot,
                "max_energy_error": scene.max_energy_error,
                "t_end": scene.t_end / scene.time_unit.in_au(),
                "output_interval": scene.output_interval / scene.time_unit.in_au(),
                "time_unit": scene.time_unit.name(),
                "units": "q in bohr or rad, p in hbar/bohr or hbar, angles in rad, p_e and J in hbar, H in hartree; lab.xyz in angstrom",
                // The solver reports its steps only when it finishes; evaluations are counted here.
                "steps": stats.map(|s| s.steps),
                "accepted_steps": stats.map(|s| s.accepted),
                "rejected_steps": stats.map(|s| s.rejected),
                "rhs_evaluations": counted.evaluations,
                "wall_time_s": wall_time,
                "conservation": recorder.conservation.to_json(),
                "centre_of_mass": {
                    "position_bohr": start.com_position.as_slice(),
                    "velocity_bohr_per_au": start.com_velocity.as_slice(),
                },
            });
            files.push(write_summary(self.out_dir, &summary)?);
        }
        flushed?;
        if let Some(message) = failure {
            return Err(CliError::Message(format!("{message}; output so far is in {}", self.out_dir.display())));
        }
        let stats = stats.unwrap_or_default();
        Ok(RunReport { out_dir: self.out_dir.to_owned(), files, stats, conservation: recorder.conservation, wall_time })
    }
}

fn method_json(method: &Method) -> serde_json::Value {
    match method {
        Method::Dop853(o) => json!({"name": "dop853", "rtol": o.rtol, "atol": o.atol}),
        Method::GaussLegendre(o) => {
            json!({"name": "gauss-legendre", "stages": o.stages, "step_au": o.step, "compensated": o.compensated})
        }
        Method::Rk4(o) => json!({"name": "rk4", "step_au": o.step}),
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
        let drift = if h0 == 0.0 { (energy - h0).abs() } else { ((energy - h0) / h0).abs() };
        // NaN fails too: a non-finite energy is a runaway as well.
        if drift.is_nan() || drift > self.max_energy_error {
            let e = format!(
                "the energy changed by {drift:.1e} relative to H(0) = {h0} hartree, more than run.max_energy_error = \
                 {:e} (the step is too large or the tolerances too loose for this motion; reduce them)",
                self.max_energy_error
            );
            return Err(at(&e, y, &self.layout));
        }
        let rotation = body.rotation();
        let phase = body.to_phase();
        if self.diagnostics {
            self.conservation.record(energy, body.j.norm(), phase.pe[0], (rotation * body.j).into());
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
        Ok(())
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Observer for Recorder<'_, M, N, NA> {
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()> {
        match self.record(t, y) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                self.error = Some(e);
                ControlFlow::Break(())
            }
        }
    }
}
