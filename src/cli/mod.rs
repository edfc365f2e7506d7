//! The `rovib` commands: `list`, `eval`, `run`, `ensemble`, `bench`.
//!
//! The commands call the library ([`rovib::Simulation`], [`rovib::ensemble`], [`rovib::freq`],
//! [`rovib::bench`]); this module owns what only a command line needs: arguments, progress bars
//! on a terminal, Ctrl-C, and the report on stdout.

use std::path::PathBuf;

use clap::{Parser, Subcommand};
use rovib::Error;

mod ensemble;
mod eval;
mod interrupt;
mod list;
mod progress;
mod run;

/// Classical rotation-vibration dynamics of polyatomic molecules.
#[derive(Debug, Parser)]
#[command(name = "rovib", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// A `rovib` subcommand.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// List the compiled-in molecules with their atoms and internal coordinates.
    List,
    /// Evaluate H, the kinetic and G matrices and Hamilton's equations at one state; print JSON.
    Eval {
        /// The molecule's name, as in `rovib list`.
        #[arg(long)]
        molecule: String,
        /// A JSON state `{"q": [...], "p": [...], "euler": [phi, theta, psi], "pe": [...]}` in
        /// atomic units; `-` reads standard input. Without it: the reference geometry at rest,
        /// with euler = [0, pi/2, 0].
        #[arg(long)]
        state: Option<PathBuf>,
    },
    /// Harmonic normal modes and rotational constants at the stationary point near the
    /// reference geometry (cm-1, MHz; says whether it is a minimum).
    Freq {
        /// The molecule's name, as in `rovib list`.
        #[arg(long)]
        molecule: String,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Integrate a scene: write trajectory.csv (with trajectory.units.json), lab.xyz,
    /// summary.json and restart.json.
    Run {
        /// The scene file (see scenes/ and docs/src/reference/scene.md). With --resume: optional, a scene that
        /// differs from the stored one only in run.end (to continue further).
        #[arg(required_unless_present = "resume")]
        scene: Option<PathBuf>,
        /// Output directory [default: out/SCENE_NAME].
        #[arg(long, conflicts_with = "resume")]
        out: Option<PathBuf>,
        /// Continue the run in this directory from its restart.json, appending to its files.
        #[arg(long, value_name = "DIR")]
        resume: Option<PathBuf>,
        /// No progress bar and no report on stdout.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Run an ensemble: sample initial states, integrate every trajectory on every core, write
    /// ensemble.csv, histograms.csv, correlations.csv, summary.json and SVG plots.
    Ensemble {
        /// A scene with an `[ensemble]` table (see docs/src/reference/ensemble.md).
        scene: PathBuf,
        /// Output directory [default: out/SCENE_NAME].
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (per MPI rank) [default: the scene's `threads`, else every core].
        #[arg(long)]
        threads: Option<usize>,
        /// No progress bar and no report on stdout.
        #[arg(long, short)]
        quiet: bool,
        /// One trajectory at a time instead of several per SIMD vector (the results agree to
        /// round-off; lanes are used only with DOP853, no frozen coordinate and no kept
        /// trajectories).
        #[arg(long)]
        no_lanes: bool,
        /// Continue a run that was killed or interrupted from OUT/checkpoint.jsonl: only the
        /// trajectories not finished there run; the outputs equal an uninterrupted run's.
        #[arg(long)]
        resume: bool,
    },
    /// Work-precision diagram: every integrator over a range of tolerances or steps, wall time
    /// against error; writes bench.csv, bench.md and bench.svg.
    Bench {
        /// The scene file.
        scene: PathBuf,
        /// Output directory [default: out/SCENE_NAME/bench].
        #[arg(long)]
        out: Option<PathBuf>,
        /// Fewer tolerances and steps (a smoke test of the diagram).
        #[arg(long)]
        quick: bool,
        /// Ensemble throughput instead (1 and 2 threads, with and without statistics; a scene
        /// with `[ensemble]`, e.g. scenes/h2o_ensemble_bench.toml).
        #[arg(long)]
        ensemble: bool,
        /// With --ensemble: the number of trajectories [default: the scene's].
        #[arg(long, requires = "ensemble")]
        trajectories: Option<u64>,
    },
}

/// Runs one command.
pub fn execute(cli: Cli) -> Result<(), Error> {
    match cli.command {
        Command::List => say(&list::list()),
        Command::Eval { molecule, state } => {
            let json = eval::eval(&molecule, state.as_deref())?;
            say(&format!("{json}\n"))
        }
        Command::Run { scene: Some(scene), out, resume: None, quiet }
            if rovib::ensemble::load_scene(&scene).is_ok_and(|s| s.ensemble) =>
        {
            run_ensemble(&scene, out.as_deref(), None, quiet, false, true)
        }
        Command::Freq { molecule, json } => say(&rovib::freq::freq(&molecule, json)?),
        Command::Ensemble { scene, out, threads, quiet, resume, no_lanes } => {
            run_ensemble(&scene, out.as_deref(), threads, quiet, resume, !no_lanes)
        }
        Command::Run { scene, out, resume, quiet } => {
            let report = match (&resume, &scene) {
                (Some(dir), scene) => run::run(rovib::Simulation::resume(dir, scene.as_deref())?, quiet)?,
                (None, Some(scene)) => run::run(rovib::Simulation::load(scene, out.as_deref())?, quiet)?,
                (None, None) => return Err(Error::Message("give a scene file, or --resume DIR".into())),
            };
            if !quiet {
                let c = &report.conservation;
                let mut text = format!(
                    "{} steps ({} rejected), {} right-hand sides, {:.3} s; max relative energy error {:.2e}, max |J| change {:.2e} hbar\n",
                    report.stats.steps,
                    report.stats.rejected,
                    report.stats.rhs_evals,
                    report.wall_time,
                    c.max_relative_energy_error(),
                    c.max_j_change
                );
                if let Some(stop) = &report.stopped {
                    text.push_str(&format!(
                        "stopped at t = {}: {} = {} (atomic units) left run.stop_outside {}\n",
                        stop["t"], stop["coordinate"], stop["value_au"], stop["bounds_au"]
                    ));
                }
                for f in &report.files {
                    text.push_str(&format!("wrote {}\n", f.display()));
                }
                say(&text)?;
            }
            Ok(())
        }
        Command::Bench { scene, out, ensemble: true, trajectories, .. } => {
            let report = rovib::bench::ensemble::bench(&scene, out.as_deref(), trajectories)?;
            let mut text = report.table.clone();
            for f in &report.files {
                text.push_str(&format!("wrote {}\n", f.display()));
            }
            say(&text)
        }
        Command::Bench { scene, out, quick, .. } => {
            let report = rovib::bench::bench(&scene, out.as_deref(), quick)?;
            let mut text = format!(
                "{} runs; reference final-state error ~{:.1e} bohr\n",
                report.trials.len(),
                report.reference_error
            );
            for f in &report.files {
                text.push_str(&format!("wrote {}\n", f.display()));
            }
            say(&text)
        }
    }
}

/// `rovib ensemble` (and `rovib run` on a scene with `[ensemble]`).
fn run_ensemble(
    scene: &std::path::Path,
    out: Option<&std::path::Path>,
    threads: Option<usize>,
    quiet: bool,
    resume: bool,
    lanes: bool,
) -> Result<(), Error> {
    // Under `mpirun` (with the `mpi` feature) only rank 0 has a report to print.
    let Some(report) = ensemble::ensemble(scene, out, threads, quiet, resume, lanes)? else {
        return Ok(());
    };
    if !quiet {
        say(&ensemble::describe(&report))?;
    }
    if report.status == rovib::ensemble::Status::Failed {
        let dir = report.files.first().and_then(|f| f.parent()).map_or(String::new(), |d| d.display().to_string());
        let reasons: Vec<String> = report.outcome.failed.iter().map(|(r, n)| format!("{n} {r}")).collect();
        return Err(Error::Message(format!(
            "every one of the {} trajectories failed ({}): there are no statistics; the first failures are in \
             {dir}/summary.json",
            report.requested,
            reasons.join(", ")
        )));
    }
    if report.status == rovib::ensemble::Status::Interrupted {
        let dir = report.files.first().and_then(|f| f.parent()).map_or(String::new(), |d| d.display().to_string());
        return Err(Error::Message(format!(
            "interrupted: {} of {} trajectories completed ({} failed); consistent outputs for them are in {dir}",
            report.outcome.completed,
            report.requested,
            report.outcome.failed_count()
        )));
    }
    Ok(())
}

/// Writes to stdout. A closed pipe (`rovib list | head -1`) ends the output quietly instead of
/// panicking as `println!` would.
fn say(text: &str) -> Result<(), Error> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(Error::context("cannot write to stdout", e)),
        _ => Ok(()),
    }
}
