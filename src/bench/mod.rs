//! `rovib bench SCENE.toml`: a work-precision diagram. Every integrator runs the scene over a
//! range of tolerances or steps; each run's wall time is set against its error relative to a
//! much tighter reference solution, for the final state and for the energy along the run.
//!
//! * Final-state error: the largest difference of any lab-frame atomic position (centre of mass
//!   removed) at the end time, in bohr. Positions are what the physics sees and, unlike q or the
//!   Euler angles, do not depend on the coordinates chosen.
//! * Energy error: max |H(t) − H(0)| / max(|H(0)|, 1e-3 hartree) over the output times (the
//!   scale of `rovib run`'s energy guard, `output::energy_scale`).
//! * Reference: DOP853 at rtol = atol = 1e-14; its own error is estimated by its difference from
//!   DOP853 at 1e-13 and reported, so that errors below it are read as "at most this".
//! * Fixed steps start at twice DOP853's mean step at rtol = 1e-6, rounded down to a whole
//!   fraction of the output interval, and halve from there.
//! * Wall time: the best of repeated runs (repeated until 0.2 s have been spent, at most 10),
//!   with an observer that only copies the state at output times; energies are computed
//!   afterwards, outside the timing.

pub mod ensemble;

use std::fmt::Write as _;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::Error;
use crate::molecules;
use crate::output::{OutputFile, energy_scale};
#[cfg(feature = "svg")]
use crate::plot::{Panel, Series, svg};
use crate::runtime::diagnostic::Compact;
use crate::runtime::hamiltonian::fast::ReducedSystem;
use crate::runtime::integrate::{Dop853Options, GaussLegendreOptions, Method, Rk4Options, SolveError, Stats, solve};
use crate::runtime::nalgebra::SMatrix;
use crate::runtime::{Molecule, MoleculeVisitor};
use crate::scene::Scene;
use crate::start::{initial_state, load_scene, production_system};

/// One run of the diagram.
#[derive(Clone, Debug)]
pub struct Trial {
    /// Method family, e.g. `dop853`, `gauss-legendre-3`.
    pub method: &'static str,
    /// The tolerance (DOP853) or the step in a.u. (fixed-step methods).
    pub parameter: f64,
    /// `Ok` or the reason the run failed.
    pub status: Result<(), TrialError>,
    /// Best wall time, s.
    pub wall_time: f64,
    /// Work counters of one run.
    pub stats: Stats,
    /// Largest lab-frame position difference from the reference at the end, bohr.
    pub final_error: f64,
    /// max |H(t) − H(0)| / max(|H(0)|, 1e-3 hartree) at output times.
    pub energy_error: f64,
}

/// Why a run of the diagram failed: what the integrator said, and when.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{detail}")]
pub struct TrialError {
    /// When the run stopped, a.u., if the integrator says.
    pub time: Option<f64>,
    /// The integrator's message.
    pub detail: String,
}

impl<E: std::error::Error> From<SolveError<E>> for TrialError {
    fn from(e: SolveError<E>) -> Self {
        TrialError { time: e.time(), detail: e.to_string() }
    }
}

/// The result of a benchmark.
pub struct BenchReport {
    /// The runs, in order.
    pub trials: Vec<Trial>,
    /// The reference's estimated final-state error, bohr.
    pub reference_error: f64,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// Runs the work-precision benchmark of the scene at `path` into `out_dir`
/// (default `out/SCENE_NAME/bench`). `quick` uses fewer tolerances and steps.
pub fn bench(path: &Path, out_dir: Option<&Path>, quick: bool) -> Result<BenchReport, Error> {
    let (scene, out_dir) = load_scene(path, out_dir, "bench")?;
    let name = scene.molecule.get_ref().clone();
    molecules::visit(&name, Bench { scene: &scene, out_dir: &out_dir, quick })
        .ok_or_else(|| Error::unknown_molecule(&name))?
}

struct Bench<'a> {
    scene: &'a Scene,
    out_dir: &'a Path,
    quick: bool,
}

/// The most bytes one run's states may take: the benchmark keeps every output state of the
/// reference, its check and the run being measured (three such buffers at once).
pub const MAX_STATE_BYTES: u64 = 64 << 20;

/// The number of output states a run keeps (`t0`, the grid, `t_end`), or the error when they
/// would take more than [`MAX_STATE_BYTES`]: a scene with many output times is refused with the
/// numbers instead of aborting on an allocation.
fn check_buffer(scene: &Scene, dim: usize) -> Result<usize, Error> {
    let outputs = (scene.t_end / scene.output_interval).ceil() + 2.0;
    let bytes = outputs * dim as f64 * 8.0;
    if bytes.is_nan() || bytes > MAX_STATE_BYTES as f64 {
        return Err(Error::Message(format!(
            "rovib bench keeps every output state of a run: {} output times × {dim} numbers × 8 bytes = {} MiB, \
             more than its limit of {} MiB; lengthen run.output_interval (the diagram uses the final state and \
             the energy at output times, which a few hundred outputs sample well)",
            outputs - 1.0,
            Compact(bytes / f64::from(1 << 20)),
            MAX_STATE_BYTES >> 20
        )));
    }
    Ok(outputs as usize)
}

/// Lab-frame positions (centre of mass at the origin) of a flat state, bohr.
fn lab_positions<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    system: &ReducedSystem<'_, M, N, NA>,
    y: &[f64],
) -> Option<SMatrix<f64, 3, NA>> {
    let body = system.expand_body(y).ok()?;
    let mut r = SMatrix::<f64, 3, NA>::zeros();
    system.molecule().positions(&body.q, &mut r);
    Some(body.rotation() * r)
}

impl MoleculeVisitor for Bench<'_> {
    type Output = Result<BenchReport, Error>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Self::Output {
        let scene = self.scene;
        let start = initial_state(&m, scene)?;
        let (system, y0) = production_system(&m, scene, &start.body)?;
        let h0 = system.energy(&y0).map_err(|e| Error::context("the initial state", e))?;
        let outputs = check_buffer(scene, y0.len())?;

        // One timed run: the states at output times, the work counters, the best wall time.
        let run = |method: &Method| -> (Result<Vec<f64>, TrialError>, Stats, f64) {
            let mut best = f64::INFINITY;
            let mut spent = 0.0;
            let mut repeats = 0;
            loop {
                let mut states: Vec<f64> = Vec::with_capacity(y0.len() * outputs);
                let mut observer = |_t: f64, y: &[f64]| {
                    states.extend_from_slice(y);
                    ControlFlow::Continue(())
                };
                let mut system = system;
                let begin = Instant::now();
                let result = solve(&mut system, method, 0.0, &y0, scene.t_end, scene.output_interval, &mut observer);
                let wall = begin.elapsed().as_secs_f64();
                best = best.min(wall);
                spent += wall;
                repeats += 1;
                match result {
                    Err(e) => return (Err(e.into()), Stats::default(), wall),
                    Ok(stats) if spent >= 0.2 || repeats >= 10 => return (Ok(states), stats, best),
                    Ok(_) => {}
                }
            }
        };

        let tight = |rtol: f64| Method::Dop853(Dop853Options { rtol, atol: rtol, ..Default::default() });
        let (reference, ref_stats, _) = run(&tight(1e-14));
        let reference = reference.map_err(|e| Error::context("the reference run (DOP853 at 1e-14) failed", e))?;
        let (check, _, _) = run(&tight(1e-13));
        let check = check.map_err(|e| Error::context("the reference check (DOP853 at 1e-13) failed", e))?;
        let dim = y0.len();
        let last = |states: &[f64]| states[states.len() - dim..].to_vec();
        let ref_final =
            lab_positions(&system, &last(&reference)).ok_or_else(|| Error::Message("bad reference state".into()))?;
        let final_error =
            |states: &[f64]| lab_positions(&system, &last(states)).map_or(f64::INFINITY, |x| (x - ref_final).amax());
        let reference_error = final_error(&check);

        // Fixed steps: from twice DOP853's mean step at a loose tolerance, halving. Fixed-step
        // methods land on every output time, so the largest step is a whole fraction of the
        // output interval (a larger one would be shortened to it anyway).
        let loose_steps = run(&tight(1e-6)).1.accepted.max(1);
        let h_loose = 2.0 * scene.t_end / loose_steps as f64;
        let h_max = scene.output_interval / (scene.output_interval / h_loose).ceil().max(1.0);
        let (tolerances, halvings): (Vec<f64>, u32) = if self.quick {
            ((2..=6).map(|k| 10f64.powi(-2 * k + 1)).collect(), 5)
        } else {
            ((4..=13).map(|k| 10f64.powi(-k)).collect(), 8)
        };
        let mut methods: Vec<(&'static str, f64, Method)> =
            tolerances.iter().map(|&tol| ("dop853", tol, tight(tol))).collect();
        for k in 0..halvings {
            let h = h_max / 2f64.powi(k as i32);
            methods.push((
                "gauss-legendre-2",
                h,
                Method::GaussLegendre(GaussLegendreOptions { stages: 2, step: h, ..Default::default() }),
            ));
            methods.push((
                "gauss-legendre-3",
                h,
                Method::GaussLegendre(GaussLegendreOptions { stages: 3, step: h, ..Default::default() }),
            ));
            methods.push(("rk4", h, Method::Rk4(Rk4Options { step: h, ..Default::default() })));
        }

        let mut trials = Vec::new();
        for (name, parameter, method) in methods {
            let (states, stats, wall_time) = run(&method);
            let trial = match states {
                Err(e) => Trial {
                    method: name,
                    parameter,
                    status: Err(e),
                    wall_time,
                    stats,
                    final_error: f64::NAN,
                    energy_error: f64::NAN,
                },
                Ok(states) => {
                    let energy_error = states
                        .chunks(dim)
                        .map(|y| match system.energy(y) {
                            Ok(h) => (h - h0).abs() / energy_scale(h0),
                            Err(_) => f64::INFINITY,
                        })
                        .fold(0.0, f64::max);
                    Trial {
                        method: name,
                        parameter,
                        status: Ok(()),
                        wall_time,
                        stats,
                        final_error: final_error(&states),
                        energy_error,
                    }
                }
            };
            trials.push(trial);
        }

        let mut files = vec![write_csv(self.out_dir, &trials)?];
        // bench.svg needs the `svg` feature (plotters); without it bench.csv and bench.md hold the same figures.
        #[cfg(feature = "svg")]
        files.push(write_svg(self.out_dir, scene, &trials, reference_error)?);
        files.push(write_markdown(self.out_dir, scene, m.name(), &trials, reference_error, &ref_stats)?);
        Ok(BenchReport { trials, reference_error, files })
    }
}

fn write_csv(dir: &Path, trials: &[Trial]) -> Result<PathBuf, Error> {
    let mut f = OutputFile::create(dir, "bench.csv")?;
    f.line("method,parameter,parameter_unit,status,wall_time_s,rhs_evals,steps,rejected_steps,final_position_error_bohr,max_relative_energy_error")?;
    for t in trials {
        let unit = if t.method == "dop853" { "rtol=atol" } else { "step_au" };
        let status = match &t.status {
            Ok(()) => "ok".to_owned(),
            Err(e) => format!("\"failed: {}\"", e.to_string().replace('"', "'")),
        };
        f.line(&format!(
            "{},{:e},{unit},{status},{:e},{},{},{},{:e},{:e}",
            t.method,
            t.parameter,
            t.wall_time,
            t.stats.rhs_evals,
            t.stats.steps,
            t.stats.rejected,
            t.final_error,
            t.energy_error
        ))?;
    }
    f.flush()?;
    Ok(f.path().to_owned())
}

#[cfg(feature = "svg")]
fn families(trials: &[Trial]) -> Vec<&'static str> {
    let mut names: Vec<&'static str> = Vec::new();
    for t in trials {
        if !names.contains(&t.method) {
            names.push(t.method);
        }
    }
    names
}

#[cfg(feature = "svg")]
fn write_svg(dir: &Path, scene: &Scene, trials: &[Trial], reference_error: f64) -> Result<PathBuf, Error> {
    let series = |error: fn(&Trial) -> f64| -> Vec<Series> {
        families(trials)
            .into_iter()
            .map(|name| Series {
                name: name.to_owned(),
                points: trials
                    .iter()
                    .filter(|t| t.method == name && t.status.is_ok())
                    .map(|t| (t.wall_time, error(t)))
                    .collect(),
            })
            .collect()
    };
    let panels = [
        Panel {
            title: format!("{}: final-state error", scene.molecule.get_ref()),
            x_label: "wall time (s)".into(),
            y_label: format!("max lab position error (bohr); reference ~{reference_error:.0e}"),
            series: series(|t| t.final_error),
        },
        Panel {
            title: format!("{}: energy error along the run", scene.molecule.get_ref()),
            x_label: "wall time (s)".into(),
            y_label: "max |H(t) − H(0)| / max(|H(0)|, 1e-3 Eh)".into(),
            series: series(|t| t.energy_error),
        },
    ];
    let mut f = OutputFile::create(dir, "bench.svg")?;
    f.line(&svg(&panels))?;
    f.flush()?;
    Ok(f.path().to_owned())
}

/// The fastest successful run whose error is at most `target`.
fn fastest(trials: &[Trial], target: f64, error: fn(&Trial) -> f64) -> Option<&Trial> {
    trials.iter().filter(|t| t.status.is_ok() && error(t) <= target).min_by(|a, b| a.wall_time.total_cmp(&b.wall_time))
}

/// A trial's tolerance, or its step in the scene's time unit (and in a.u.).
fn parameter_text(t: &Trial, scene: &Scene) -> String {
    if t.method == "dop853" {
        format!("rtol = atol = {:.0e}", t.parameter)
    } else if scene.time_unit.name() == "au" {
        format!("step = {:.4} a.u.", t.parameter)
    } else {
        format!(
            "step = {:.4e} {} ({:.4} a.u.)",
            t.parameter / scene.time_unit.in_au(),
            scene.time_unit.name(),
            t.parameter
        )
    }
}

fn write_markdown(
    dir: &Path,
    scene: &Scene,
    molecule: &str,
    trials: &[Trial],
    reference_error: f64,
    ref_stats: &Stats,
) -> Result<PathBuf, Error> {
    let mut s = String::new();
    let t_end = scene.t_end / scene.time_unit.in_au();
    let _ = writeln!(s, "# Work-precision: {molecule}, {} (`{}`)\n", scene.description, scene.path);
    let _ = writeln!(
        s,
        "End time {t_end} {}; energy sampled every {} {}. Reference: DOP853 at rtol = atol = 1e-14 ({} right-hand sides); its \
         final-state error, estimated against DOP853 at 1e-13, is {reference_error:.1e} bohr, so smaller errors below read as \
         \"at most that\".\n",
        scene.time_unit.name(),
        scene.output_interval / scene.time_unit.in_au(),
        scene.time_unit.name(),
        ref_stats.rhs_evals
    );
    let _ = writeln!(
        s,
        "| method | parameter | wall time (s) | rhs evaluations | final position error (bohr) | max relative energy error |"
    );
    let _ = writeln!(s, "| --- | --- | ---: | ---: | ---: | ---: |");
    for t in trials {
        match &t.status {
            Ok(()) => {
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.3e} | {} | {:.1e} | {:.1e} |",
                    t.method,
                    parameter_text(t, scene),
                    t.wall_time,
                    t.stats.rhs_evals,
                    t.final_error,
                    t.energy_error
                );
            }
            Err(e) => {
                let _ = writeln!(s, "| {} | {} | – | – | failed: {} | – |", t.method, parameter_text(t, scene), e);
            }
        }
    }
    let _ = writeln!(s, "\n## Which method at which accuracy\n");
    let _ = writeln!(s, "The fastest run in this table that reaches each target:\n");
    let _ = writeln!(s, "| target | final position error ≤ target | energy error ≤ target |");
    let _ = writeln!(s, "| --- | --- | --- |");
    for target in [1e-3, 1e-5, 1e-7, 1e-9, 1e-11] {
        let pick = |error: fn(&Trial) -> f64| match fastest(trials, target, error) {
            Some(t) => format!("{} ({}), {:.2e} s", t.method, parameter_text(t, scene), t.wall_time),
            None => "none of these runs".into(),
        };
        let _ = writeln!(s, "| {target:.0e} | {} | {} |", pick(|t| t.final_error), pick(|t| t.energy_error));
    }
    let mut f = OutputFile::create(dir, "bench.md")?;
    f.line(&s)?;
    f.flush()?;
    Ok(f.path().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_trial_says_what_the_integrator_said() {
        let e = TrialError::from(SolveError::<std::fmt::Error>::TooManySteps { t: 2.5, y: vec![0.0], max_steps: 10 });
        assert_eq!(e.time, Some(2.5));
        assert_eq!(
            e.to_string(),
            SolveError::<std::fmt::Error>::TooManySteps { t: 2.5, y: vec![0.0], max_steps: 10 }.to_string()
        );
    }
}
