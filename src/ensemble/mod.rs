//! Ensembles: sample initial states, run many trajectories on every core, reduce them to
//! statistics (means with standard errors, histograms, time-correlation functions).
//!
//! A scene with an `[ensemble]` table (and optionally `[statistics]`) describes the ensemble;
//! the README's "Ensembles" section documents every key. [`run_ensemble`] is the library entry
//! point (the `rovib ensemble` command calls it); [`run_with_sampler`] runs the same ensemble
//! from any [`Sampler`], for tests and for callers with their own distribution.
//!
//! # Reproducibility
//!
//! Trajectory `i` draws from its own random stream of `(seed, i)`; trajectories are grouped in
//! blocks of [`runner::BLOCK`] consecutive indices, each block's accumulators are built in index
//! order and blocks are merged in index order. The statistics (and so `ensemble.csv`,
//! `histograms.csv`, `correlations.csv` and the plots) are therefore bit-identical whatever the
//! number of threads; only the wall time, throughput and thread count in `summary.json` differ.

pub mod checkpoint;
pub mod lanes;
pub mod output;
mod plot;
pub mod quantity;
pub mod runner;
pub mod scene;
mod states_file;
pub mod states_xyz;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use self::runner::{Accumulators, BLOCK, Outcome, Plan, Progress, run_block};
use self::scene::{Bound, EnsembleScene, parse_ensemble};
use crate::cli::{CliError, unknown_molecule};
use crate::molecules;
use crate::runtime::sample::{self, Sampler};
use crate::runtime::{Molecule, MoleculeVisitor};
use crate::scene::{Scene, parse_scene};

pub use self::runner::Failure;

/// How to run an ensemble, besides the scene.
#[derive(Clone, Debug)]
pub struct EnsembleOptions {
    /// Where the outputs go (created if missing).
    pub out_dir: PathBuf,
    /// Worker threads, overriding the scene's `threads` (`None`: the scene's, else every core).
    pub threads: Option<usize>,
    /// Show a progress bar (the caller decides: a terminal and not `--quiet`).
    pub progress: bool,
    /// When set, no new trajectory starts and running ones stop at their next output time;
    /// the outputs then cover the trajectories that finished (status "interrupted").
    pub stop: Arc<AtomicBool>,
    /// Run trajectories on SIMD lanes where possible (default; the results are the same bit
    /// for bit, see `lanes`); `false` runs one trajectory at a time.
    pub lanes: bool,
}

impl EnsembleOptions {
    /// Outputs into `out_dir`, threads from the scene, no progress bar, a stop flag of its own.
    pub fn new(out_dir: impl Into<PathBuf>) -> Self {
        Self {
            out_dir: out_dir.into(),
            threads: None,
            progress: false,
            stop: Arc::new(AtomicBool::new(false)),
            lanes: true,
        }
    }
}

/// Whether the ensemble ran to the end.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Status {
    /// Every trajectory was run (completed or failed).
    Completed,
    /// Stopped by the stop flag (Ctrl-C): the statistics cover the trajectories that finished.
    Interrupted,
}

impl Status {
    /// As written in summary.json.
    pub fn name(self) -> &'static str {
        match self {
            Status::Completed => "completed",
            Status::Interrupted => "interrupted",
        }
    }
}

/// What an ensemble produced.
#[derive(Clone, Debug)]
pub struct EnsembleReport {
    /// Completed or interrupted.
    pub status: Status,
    /// Trajectories asked for.
    pub requested: u64,
    /// Statistics, counts and failures.
    pub outcome: Outcome,
    /// Output times, a.u.
    pub times: Vec<f64>,
    /// Names of the quantities with means, in column order.
    pub quantities: Vec<String>,
    /// Their units.
    pub units: Vec<&'static str>,
    /// Wall time of the trajectories (sampling, integration, statistics), s.
    pub wall_time: f64,
    /// Worker threads used.
    pub threads: usize,
    /// The seed.
    pub seed: u64,
    /// How the initial states were drawn.
    pub sampler: String,
    /// Files written.
    pub files: Vec<PathBuf>,
}

impl EnsembleReport {
    /// The ensemble mean and its standard error of `quantity` at output time `k`, if that
    /// quantity's means were accumulated.
    pub fn mean(&self, quantity: &str, k: usize) -> Option<(f64, f64)> {
        let j = self.quantities.iter().position(|q| q == quantity)?;
        let m = self.outcome.statistics.means.get(k * self.quantities.len() + j)?;
        Some((m.mean(), m.standard_error()))
    }

    /// Trajectories that finished (completed or failed) per second of wall time.
    pub fn throughput(&self) -> f64 {
        (self.outcome.completed + self.outcome.failed_count()) as f64 / self.wall_time
    }

    /// The accumulated statistics.
    pub fn statistics(&self) -> &Accumulators {
        &self.outcome.statistics
    }
}

/// Reads and parses a scene file (which may have `[ensemble]`).
pub fn load_scene(path: &Path) -> Result<Scene, CliError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| CliError::context(format!("cannot read {}", path.display()), e))?;
    Ok(parse_scene(&path.display().to_string(), &text)?)
}

/// Runs the ensemble of `scene` (which must have `[ensemble]`) with its own sampler and writes
/// ensemble.csv, histograms.csv, correlations.csv, summary.json, ensemble.svg and
/// histograms.svg into `options.out_dir`.
pub fn run_ensemble(scene: &Scene, options: &EnsembleOptions) -> Result<EnsembleReport, CliError> {
    let ensemble = parse_ensemble(scene)?;
    let name = scene.molecule.get_ref().clone();
    molecules::visit(&name, Visit { scene, ensemble: &ensemble, options }).ok_or_else(|| {
        let e = unknown_molecule(&name);
        CliError::File(scene.source().error(scene.molecule.span(), e.to_string(), "use a name from `rovib list`"))
    })?
}

struct Visit<'a> {
    scene: &'a Scene,
    ensemble: &'a EnsembleScene,
    options: &'a EnsembleOptions,
}

impl MoleculeVisitor for Visit<'_> {
    type Output = Result<EnsembleReport, CliError>;

    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        let times = output_times(self.scene.t_end, self.scene.output_interval);
        let bound = self.ensemble.bind(&m, self.scene, &times)?;
        let sampler = sample::sampler(&m, &bound.spec, self.ensemble.seed).map_err(|e| {
            self.scene.source().error(
                self.ensemble.method_span(),
                format!("cannot sample this ensemble: {e}"),
                "change the method or its parameters in [ensemble] (see the README's \"Ensembles\")",
            )
        })?;
        let description = bound.description.clone();
        execute(&m, self.scene, self.ensemble, bound, &*sampler, &description, self.options)
    }
}

/// Runs the ensemble of `scene` for molecule `m` with initial states from `sampler` instead of
/// the scene's method (the method's parameters are still checked); `description` says how the
/// states are drawn, for summary.json.
pub fn run_with_sampler<M, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    sampler: &dyn Sampler<N>,
    description: &str,
    options: &EnsembleOptions,
) -> Result<EnsembleReport, CliError>
where
    M: Molecule<N, NA> + Sync,
{
    let ensemble = parse_ensemble(scene)?;
    let times = output_times(scene.t_end, scene.output_interval);
    let bound = ensemble.bind(m, scene, &times)?;
    execute(m, scene, &ensemble, bound, sampler, description, options)
}

/// The output times of a run from 0 to `t_end` every `interval` (a.u.): the grid
/// `runtime::integrate::solve` observes (0, k·interval while before `t_end`, then `t_end`; a
/// ratio within 64 ε of an integer counts as that integer). The runner checks every trajectory
/// against it.
pub fn output_times(t_end: f64, interval: f64) -> Vec<f64> {
    let ratio = t_end / interval;
    let nearest = ratio.round();
    let count = if t_end > 0.0 {
        (if (ratio - nearest).abs() <= 64.0 * f64::EPSILON * ratio { nearest } else { ratio.ceil() }).max(1.0) as usize
    } else {
        0
    };
    (0..=count).map(|k| if k >= count { t_end } else { k as f64 * interval }).collect()
}

fn execute<M, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    ensemble: &EnsembleScene,
    bound: Bound<N>,
    sampler: &dyn Sampler<N>,
    description: &str,
    options: &EnsembleOptions,
) -> Result<EnsembleReport, CliError>
where
    M: Molecule<N, NA> + Sync,
{
    let reduction = crate::start::frozen_reduction(m, scene)?;
    std::fs::create_dir_all(&options.out_dir)
        .map_err(|e| CliError::context(format!("cannot create {}", options.out_dir.display()), e))?;
    let plan = Plan {
        molecule: m,
        reduction,
        method: scene.method,
        t_end: scene.t_end,
        interval: scene.output_interval,
        times: output_times(scene.t_end, scene.output_interval),
        quantities: bound.quantities.clone(),
        n_means: bound.n_means,
        histograms: bound.histograms.clone(),
        correlations: bound.correlations.clone(),
        max_energy_error: scene.max_energy_error,
        min_pivot: scene.min_metric_pivot,
        keep: ensemble.keep_trajectories.map(|k| (k, options.out_dir.join("trajectories"))),
        time_scale: scene.time_unit.in_au(),
        lanes: options.lanes,
    };
    let threads = options
        .threads
        .or(ensemble.threads)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| CliError::context("cannot start the worker threads", e))?;
    let n = ensemble.trajectories;
    let progress = Progress { bar: options.progress.then(|| progress_bar(n)), failures: AtomicU64::new(0) };

    let begin = Instant::now();
    let mut total = Outcome::new(Accumulators::new(&plan));
    let n_blocks = n.div_ceil(BLOCK);
    // Blocks run in chunks; each chunk's outcomes are merged in block order before the next
    // starts, which bounds memory (a few accumulators per thread) at any ensemble size.
    let chunk = 16 * threads as u64;
    pool.install(|| {
        let mut first = 0;
        while first < n_blocks {
            let last = (first + chunk).min(n_blocks);
            let outcomes: Vec<Outcome> = (first..last)
                .into_par_iter()
                .map(|b| run_block(&plan, sampler, b * BLOCK..((b + 1) * BLOCK).min(n), &options.stop, &progress))
                .collect();
            for o in &outcomes {
                total.merge(o);
            }
            first = last;
        }
    });
    let wall_time = begin.elapsed().as_secs_f64();
    if let Some(bar) = &progress.bar {
        bar.finish_and_clear();
    }
    let status = if options.stop.load(Ordering::Relaxed) && total.interrupted > 0 {
        Status::Interrupted
    } else {
        Status::Completed
    };
    let mut report = EnsembleReport {
        status,
        requested: n,
        outcome: total,
        times: plan.times.clone(),
        quantities: plan.quantities[..plan.n_means].iter().map(|q| q.name(m)).collect(),
        units: plan.quantities[..plan.n_means].iter().map(|q| q.unit(m)).collect(),
        wall_time,
        threads,
        seed: ensemble.seed,
        sampler: description.to_owned(),
        files: Vec::new(),
    };
    report.files = output::write_all(m, scene, ensemble, &plan, &report, &options.out_dir)?;
    Ok(report)
}

fn progress_bar(n: u64) -> ProgressBar {
    let bar = ProgressBar::new(n);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {pos}/{len} trajectories, {msg}, eta {eta}",
        )
        .expect("a valid template"),
    );
    bar.set_message("0 failed");
    bar
}
