//! Ensembles: sample initial states, run many trajectories on every core, reduce them to
//! statistics (means with standard errors, histograms, time-correlation functions).
//!
//! A scene with an `[ensemble]` table (and optionally `[statistics]`) describes the ensemble;
//! the guide's ensemble reference (docs/src/reference/ensemble.md) documents every key. [`run_ensemble`] is the library entry
//! point (the `rovib ensemble` command calls it); [`run_with_sampler`] runs the same ensemble
//! from any [`Sampler`], for tests and for callers with their own distribution.
//!
//! # Reproducibility
//!
//! Trajectory `i` draws from its own random stream of `(seed, i)`; trajectories are grouped in
//! blocks of [`runner::BLOCK`] consecutive indices, each block's accumulators are built in index
//! order and blocks are merged in index order. The statistics (and so `ensemble.csv`,
//! `histograms.csv`, `correlations.csv` and the plots) are therefore bit-identical whatever the
//! number of threads or MPI ranks ([`schedule`] hands out the blocks and merges them in order);
//! only the wall time, throughput, thread and rank counts in `summary.json` differ.
//!
//! # Checkpoints
//!
//! Every finished block is recorded in `OUT/checkpoint.jsonl` ([`checkpoint`]); a run killed at
//! any point continues with [`EnsembleOptions::resume`] (`rovib ensemble --resume`) from the
//! blocks already recorded, with the same final outputs as an uninterrupted run. The checkpoint
//! is removed when the ensemble completes.

pub mod checkpoint;
pub mod collision_final;
pub mod collision_output;
pub mod collision_run;
pub mod collision_scene;
pub mod draw;
pub mod lanes;
pub mod lifetimes;
pub mod method;
#[cfg(feature = "mpi")]
pub mod mpi;
pub mod output;
pub mod pair;
pub mod pair_states;
mod plot;
pub mod quantity;
pub mod resources;
pub mod runner;
pub mod scene;
pub mod schedule;
pub mod spectrum;
pub mod spectrum_scene;
pub mod states_file;
pub mod states_xyz;
pub mod tables;

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use self::checkpoint::{Checkpoint, Header, Identity, Layout, Resumed};
use self::runner::{Accumulators, BLOCK, Outcome, Plan, Tally, run_block_scalar};
use self::scene::{Bound, EnsembleScene, MethodSpec, parse_ensemble};
use self::schedule::{BlockResult, Collector, Remote, Work, block_range, caught, coordinate};
use crate::Progress;
use crate::error::Error;
use crate::molecules;
use crate::runtime::sample::Sampler;
use crate::runtime::{Molecule, MoleculeVisitor};
use crate::scene::chart::RunChart;
use crate::scene::{Scene, parse_scene};

pub use self::runner::Failure;

/// How to run an ensemble, besides the scene.
#[derive(Clone, Debug)]
pub struct EnsembleOptions {
    /// Where the outputs go (created if missing).
    pub out_dir: PathBuf,
    /// Worker threads, overriding the scene's `threads` (`None`: the scene's, else every core).
    pub threads: Option<usize>,
    /// When set, no new trajectory starts and running ones stop at their next output time;
    /// the outputs then cover the trajectories that finished (status "interrupted").
    pub stop: Arc<AtomicBool>,
    /// Run trajectories on SIMD lanes where possible (default; the results agree with one
    /// trajectory at a time to round-off, see `lanes`); `false` runs one trajectory at a time.
    pub lanes: bool,
    /// Record finished blocks in `out_dir/checkpoint.jsonl` (removed when the ensemble
    /// completes). A run without `resume` refuses to start over an existing checkpoint.
    pub checkpoint: bool,
    /// Continue from `out_dir/checkpoint.jsonl` (a run that was killed or interrupted): only the
    /// blocks not recorded there run, and the outputs are those of an uninterrupted run.
    pub resume: bool,
    /// Write nothing ([`EnsembleOptions::in_memory`]): no folder, lock, checkpoint or file; the
    /// results come back in [`EnsembleReport::tables`] (`out_dir` is not used).
    pub in_memory: bool,
}

impl EnsembleOptions {
    /// Outputs into `out_dir`, threads from the scene, a stop flag of its own,
    /// a checkpoint, no resume.
    pub fn new(out_dir: impl Into<PathBuf>) -> Self {
        Self {
            out_dir: out_dir.into(),
            threads: None,
            stop: Arc::new(AtomicBool::new(false)),
            lanes: true,
            checkpoint: true,
            resume: false,
            in_memory: false,
        }
    }

    /// An ensemble run in memory: nothing is written (no output folder, lock, checkpoint or
    /// file), the statistics come back in the report, correlations and spectrum in
    /// [`EnsembleReport::tables`]. Threads from the scene, a stop flag of its own. A collision
    /// ensemble and `ensemble.keep_trajectories` need a folder and are refused.
    pub fn in_memory() -> Self {
        Self { checkpoint: false, in_memory: true, ..Self::new(PathBuf::new()) }
    }
}

/// The checkpoint file's name in the output folder.
pub const CHECKPOINT_FILE: &str = "checkpoint.jsonl";

/// How this process takes part in the run.
pub enum Link<'a> {
    /// Alone: it runs every block and writes the outputs.
    Alone,
    /// MPI rank 0: it hands out the blocks, runs some, merges all and writes the outputs.
    Root(&'a mut dyn Remote),
    /// Another MPI rank: it runs the blocks rank 0 gives it and writes nothing.
    Worker(&'a mut dyn Serve),
}

/// A process that runs blocks for rank 0 (see [`mpi`](self)).
pub trait Serve {
    /// Asks rank 0 for blocks, runs them with `work` and sends their outcomes back, until rank 0
    /// has no more; every message carries `identity` (this run), which rank 0 checks against its
    /// own before it accepts any block.
    fn serve(&mut self, work: &Work<'_>, identity: &Identity) -> Result<(), Error>;

    /// Processes in all.
    fn ranks(&self) -> usize;
}

impl Link<'_> {
    fn ranks(&self) -> usize {
        match self {
            Link::Alone => 1,
            Link::Root(r) => r.ranks(),
            Link::Worker(w) => w.ranks(),
        }
    }
}

/// Whether the ensemble ran to the end.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Status {
    /// Every trajectory was run, and at least one completed (the statistics cover the completed
    /// ones; the failed ones are counted by reason in summary.json).
    Completed,
    /// Stopped by the stop flag (Ctrl-C): the statistics cover the trajectories that finished.
    Interrupted,
    /// Every trajectory was run and every one failed: there are no statistics
    /// (`rovib ensemble` exits with an error).
    Failed,
}

impl Status {
    /// As written in summary.json.
    pub fn name(self) -> &'static str {
        match self {
            Status::Completed => "completed",
            Status::Interrupted => "interrupted",
            Status::Failed => "failed",
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
    /// Worker threads used (by each process).
    pub threads: usize,
    /// Why fewer threads run than were asked for, if so (also in summary.json; the command prints it).
    pub threads_note: Option<String>,
    /// Why trajectories run one at a time although lanes were asked for, if so (also in
    /// summary.json; the command prints it).
    pub lanes_note: Option<String>,
    /// Processes (MPI ranks; 1 without MPI).
    pub ranks: usize,
    /// Blocks each process ran in this run (rank 0 first).
    pub blocks_by_rank: Vec<u64>,
    /// Trajectories (completed or failed) taken from the checkpoint of an earlier run.
    pub resumed: u64,
    /// The seed.
    pub seed: u64,
    /// How the initial states were drawn.
    pub sampler: String,
    /// The dipole's moments over the sampled states and the sampler's configurational integral,
    /// for an ensemble with a spectrum (`pair`).
    pub phase_space: Option<pair::PhaseSpace>,
    /// The pair states of the sampled states (`[pairs]`).
    pub pair_states: Option<pair_states::Census>,
    /// Files written.
    pub files: Vec<PathBuf>,
    /// The correlations and spectrum of an ensemble run in memory ([`EnsembleOptions::in_memory`]);
    /// `None` when they were written to files.
    pub tables: Option<tables::Tables>,
}

impl EnsembleReport {
    /// The ensemble mean and its standard error of `quantity` at output time `k`, if that
    /// quantity's means were accumulated.
    pub fn mean(&self, quantity: &str, k: usize) -> Option<(f64, f64)> {
        let j = self.quantities.iter().position(|q| q == quantity)?;
        let m = self.outcome.statistics.means.get(k * self.quantities.len() + j)?;
        Some((m.mean(), m.standard_error()))
    }

    /// Trajectories that finished (completed or failed) in this run, per second of wall time
    /// (those taken from a checkpoint are not counted).
    pub fn throughput(&self) -> f64 {
        (self.outcome.completed + self.outcome.failed_count()).saturating_sub(self.resumed) as f64 / self.wall_time
    }

    /// The accumulated statistics.
    pub fn statistics(&self) -> &Accumulators {
        &self.outcome.statistics
    }
}

/// Reads and parses a scene file (which may have `[ensemble]`).
pub fn load_scene(path: &Path) -> Result<Scene, Error> {
    let text = crate::runtime::diagnostic::read_text_capped(path, crate::runtime::diagnostic::MAX_INPUT_BYTES)?;
    Ok(parse_scene(&path.display().to_string(), &text)?)
}

/// Runs the ensemble of `scene` (which must have `[ensemble]`) with its own sampler and writes
/// ensemble.csv, histograms.csv, correlations.csv, summary.json, ensemble.svg and
/// histograms.svg into `options.out_dir`.
pub fn run_ensemble(scene: &Scene, options: &EnsembleOptions) -> Result<EnsembleReport, Error> {
    run_ensemble_with(scene, options, &mut |_| {})
}

/// [`run_ensemble`] with a progress callback: called on this thread as trajectories finish (and
/// at least every 0.1 s), with the trajectories done and failed so far. Setting
/// `options.stop` (from the callback or another thread) ends the run cleanly: no trajectory
/// starts, running ones stop at their next output time, and the outputs cover those that
/// finished (status "interrupted"; continue with [`EnsembleOptions::resume`]). No signal handler
/// is installed.
///
/// ```no_run
/// use rovib::ensemble::{EnsembleOptions, load_scene, run_ensemble_with};
///
/// let scene = load_scene("scenes/h2o_ensemble.toml".as_ref())?;
/// let options = EnsembleOptions::new("out/h2o_ensemble");
/// let report = run_ensemble_with(&scene, &options, &mut |p| eprintln!("{}/{}", p.done, p.total))?;
/// println!("{} completed", report.outcome.completed);
/// # Ok::<(), rovib::Error>(())
/// ```
pub fn run_ensemble_with(
    scene: &Scene,
    options: &EnsembleOptions,
    progress: &mut dyn FnMut(Progress),
) -> Result<EnsembleReport, Error> {
    run_linked(scene, options, Link::Alone, progress).map(|r| r.expect("a process alone writes a report"))
}

/// [`run_ensemble`] as one process of several: the report on rank 0 (and alone), `None` on the
/// other ranks.
pub fn run_linked(
    scene: &Scene,
    options: &EnsembleOptions,
    link: Link<'_>,
    progress: &mut dyn FnMut(Progress),
) -> Result<Option<EnsembleReport>, Error> {
    let ensemble = parse_ensemble(scene)?;
    let name = scene.molecule.get_ref().clone();
    molecules::visit(&name, Visit { scene, ensemble: &ensemble, options, link, progress }).ok_or_else(|| {
        let e = Error::unknown_molecule(&name);
        Error::File(scene.source().error(scene.molecule.span(), e.to_string(), "use a name from `rovib list`"))
    })?
}

struct Visit<'a, 'l> {
    scene: &'a Scene,
    ensemble: &'a EnsembleScene,
    options: &'a EnsembleOptions,
    link: Link<'l>,
    progress: &'a mut dyn FnMut(Progress),
}

impl MoleculeVisitor for Visit<'_, '_> {
    type Output = Result<Option<EnsembleReport>, Error>;

    /// With the scene's `[potential] library` every trajectory, the sampler and the statistics
    /// use that potential; with its `[potential.parameters]` the molecule's own with them (as
    /// `rovib run` does), else the compiled-in one.
    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        crate::scene_molecule::with_scene_molecule(self.scene, m, self)
    }
}

impl crate::scene_molecule::SceneMoleculeUser for Visit<'_, '_> {
    type Output = Option<EnsembleReport>;

    fn with_molecule<M, const N: usize, const NA: usize>(self, m: M) -> Result<Option<EnsembleReport>, Error>
    where
        M: Molecule<N, NA> + Sync,
    {
        if let MethodSpec::Collision(c) = &self.ensemble.method {
            if self.options.in_memory {
                let why = "a collision ensemble writes its outputs into a folder: it cannot run in memory";
                return Err(self
                    .scene
                    .source()
                    .error(self.ensemble.method_span(), why, "give it an output folder")
                    .into());
            }
            if !matches!(self.link, Link::Alone) {
                let why = "a collision ensemble runs in one process: it cannot run under MPI";
                let help = "run it without mpirun (its threads use the cores of one machine), or split the \
                            trajectories over several scenes with different seeds";
                return Err(self.scene.source().error(self.ensemble.method_span(), why, help).into());
            }
            if let (RunChart::Cartesian, Some(span)) = &self.scene.chart {
                let why = "`run.chart = \"cartesian\"` is not available for a collision ensemble";
                let help = "remove it: a collision runs in internal coordinates (with the Cartesian chart near linear \
                            geometries)";
                return Err(self.scene.source().error(span.clone(), why, help).into());
            }
            return collision_output::run_and_write(&m, self.scene, self.ensemble, &c.0, self.options)
                .map(|r| Some(r.0));
        }
        let times = output_times(self.scene.t_end, self.scene.output_interval);
        let bound = self.ensemble.bind(&m, self.scene, &times)?;
        let sampler = bound.spec.sampler(&m, self.ensemble.seed).map_err(|e| {
            self.scene.source().error(
                self.ensemble.method_span(),
                format!("cannot sample this ensemble: {e}"),
                "change the method or its parameters in [ensemble] (see docs/src/reference/ensemble.md)",
            )
        })?;
        let description = bound.description.clone();
        execute(&m, self.scene, self.ensemble, bound, &*sampler, &description, self.options, self.link, self.progress)
    }
}

/// Runs the ensemble of `scene` for molecule `m` with initial states from `sampler` instead of
/// the scene's method (the method's parameters are still checked); `description` says how the
/// states are drawn, for summary.json. The scene's `[potential] library` or
/// `[potential.parameters]` apply to the trajectories and statistics (the sampler is the caller's).
pub fn run_with_sampler<M, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    sampler: &dyn Sampler<N>,
    description: &str,
    options: &EnsembleOptions,
) -> Result<EnsembleReport, Error>
where
    M: Molecule<N, NA> + Sync + Clone,
{
    // The sampler is over this molecule's coordinates (`N`), so the three cases are written
    // out here rather than through `scene_molecule::with_scene_molecule`, whose user is
    // generic in `N`.
    if let Some(surface) = crate::surfaces::scene_surface(m, scene)? {
        let m = crate::runtime::surface::WithPotential { molecule: m.clone(), potential: surface };
        return run_with_sampler_as_given(&m, scene, sampler, description, options);
    }
    if let Some(values) = crate::parameters::scene_parameters(m, scene)? {
        let m = crate::parameters::WithParameters { molecule: m.clone(), values };
        return run_with_sampler_as_given(&m, scene, sampler, description, options);
    }
    run_with_sampler_as_given(m, scene, sampler, description, options)
}

fn run_with_sampler_as_given<M, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    sampler: &dyn Sampler<N>,
    description: &str,
    options: &EnsembleOptions,
) -> Result<EnsembleReport, Error>
where
    M: Molecule<N, NA> + Sync,
{
    let ensemble = parse_ensemble(scene)?;
    let times = output_times(scene.t_end, scene.output_interval);
    let bound = ensemble.bind(m, scene, &times)?;
    execute(m, scene, &ensemble, bound, sampler, description, options, Link::Alone, &mut |_| {})
        .map(|r| r.expect("a process alone writes a report"))
}

/// Runs trajectories `indices` (a block) and returns their outcome. Never panics on a bad
/// trajectory: each failure is recorded and the block goes on. Stops starting trajectories
/// (and cuts running ones short at their next output time) once `stop` is set.
///
/// On SIMD lanes ([`lanes`]) when `plan.lanes` is set and the plan allows it, else one
/// trajectory at a time; the outcome is the same.
pub fn run_block<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    sampler: &dyn Sampler<N>,
    indices: Range<u64>,
    stop: &AtomicBool,
    progress: &Tally,
) -> Outcome
where
    M: Molecule<N, NA> + Sync,
{
    if lanes::applies(plan) {
        return lanes::run_block_lanes(plan, sampler, indices, stop, progress);
    }
    run_block_scalar(plan, sampler, indices, stop, progress)
}

/// The chart the ensemble's trajectories are integrated in (`run.chart`): `cartesian` only for
/// a molecule with a Cartesian potential (coordinates declared by kind) and nothing frozen,
/// else an error at the key; `auto` by the rule of [`crate::scene::chart`].
fn chart_of<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    reduction: &crate::runtime::hamiltonian::fast::Reduction<N>,
) -> Result<RunChart, Error> {
    let (chart, span) = &scene.chart;
    let unavailable = if !reduction.active.iter().all(|&a| a) {
        Some("the scene freezes coordinates (run.frozen), which have no Cartesian counterpart")
    } else if crate::runtime::cartesian_system::CartesianSystem::new(m).is_err() {
        Some(
            "the molecule has no Cartesian potential U(x) (its definition gives positions rather than coordinates \
             by kind, or the potential comes from a shared library or a grid file)",
        )
    } else {
        None
    };
    match (chart, unavailable) {
        (RunChart::Internal, _) => Ok(RunChart::Internal),
        (RunChart::Auto, Some(_)) => Ok(RunChart::Internal),
        (RunChart::Auto, None) => Ok(if scene.cartesian_fallback && linear_at_reference(m) {
            RunChart::Cartesian
        } else {
            RunChart::Internal
        }),
        (RunChart::Cartesian, None) => Ok(RunChart::Cartesian),
        (RunChart::Cartesian, Some(why)) => {
            let at = span.clone().unwrap_or(0..0);
            Err(scene
                .source()
                .error(
                    at,
                    format!("`run.chart = \"cartesian\"` is not available for {}: {why}", m.name()),
                    "remove it (the default, \"auto\", chooses the internal chart for this molecule)",
                )
                .into())
        }
    }
}

/// Whether the internal chart is singular or ill-conditioned at the molecule's reference geometry
/// (a linear molecule at its linear equilibrium): some relative pivot of the kinetic metric there
/// is below the chart switch's return threshold. False for a molecule without a reference.
fn linear_at_reference<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M) -> bool {
    let Some(q) = m.reference_geometry() else { return false };
    let mut k = crate::runtime::molecule::KineticMatrices::<N>::default();
    m.kinetic(&q, &mut k);
    !crate::runtime::hamiltonian::MetricFactor::is_regular(&k, crate::runtime::charts::RETURN_PIVOT)
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
    link: Link<'_>,
    progress: &mut dyn FnMut(Progress),
) -> Result<Option<EnsembleReport>, Error>
where
    M: Molecule<N, NA> + Sync,
{
    let reduction = crate::start::frozen_reduction(m, scene)?;
    let chart = chart_of(m, scene, &reduction)?;
    let ranks = link.ranks();
    if ranks > 1 && ensemble.keep_trajectories.is_some() {
        return Err(Error::Message(
            "`ensemble.keep_trajectories` is not available with more than one MPI rank (only rank 0 writes files); \
             remove it, or run the ensemble in one process"
                .into(),
        ));
    }
    if options.in_memory {
        refuse_in_memory(ensemble, options)?;
    }
    let worker = matches!(link, Link::Worker(_));
    // One run per folder, held until the last output is written (the other ranks, and a run in
    // memory, write nothing).
    let _lock = if worker || options.in_memory { None } else { Some(lock_out_dir(&options.out_dir)?) };
    let plan = make_plan(m, scene, ensemble, &bound, options, reduction, chart)?;
    // `[pairs] max_energy`: the scene's sampler restricted to H_rel < E_max.
    let restricted = plan.pairs.as_ref().and_then(|p| {
        p.max_energy.map(|e| pair_states::RestrictedSampler(pair_states::Restricted::new(sampler, m, p, e)))
    });
    let sampler: &dyn Sampler<N> = match &restricted {
        Some(r) => r,
        None => sampler,
    };
    let threads = Threads::of(m, ensemble, options);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.threads)
        .build()
        .map_err(|e| Error::context("cannot start the worker threads", e))?;
    let n = ensemble.trajectories;
    let tally = Tally::default();
    let run = |b: u64| -> BlockResult {
        caught(b, n, || run_block(&plan, sampler, block_range(b, n), &options.stop, &tally))
    };
    let work = Work { threads: threads.threads, pool: &pool, run: &run, stop: &options.stop, progress: &tally };

    let empty = Outcome::new(Accumulators::new(&plan));
    let identity = Identity { header: run_header(scene, ensemble, options), layout: Layout::of(&empty.statistics) };
    let remote = match link {
        Link::Worker(w) => {
            w.serve(&work, &identity)?;
            return Ok(None);
        }
        Link::Root(r) => {
            r.expect(identity);
            Some(r)
        }
        Link::Alone => None,
    };
    let (checkpoint, resumed) =
        if options.in_memory { (None, Default::default()) } else { open_checkpoint(scene, ensemble, options, &empty)? };
    // From here on the folder is this run's: nothing of an earlier run stays, and the summary
    // says "running" until it says how the run ended.
    let failed = |error: &str| fail_run(options, scene, m.name(), n, error);
    if !options.in_memory {
        output::remove_stale_outputs(&options.out_dir, options.resume)?;
        output::write_running(&options.out_dir, scene, m.name(), n, options.resume)?;
    }
    let mut collector = Collector::new(n, empty, resumed, checkpoint, ranks);
    tally.done.fetch_add(collector.resumed(), Ordering::Relaxed);
    let begin = Instant::now();
    let result = coordinate(&work, &mut collector, remote, &mut || progress(tally.progress(n)));
    let wall_time = begin.elapsed().as_secs_f64();
    if let Err(e) = result {
        return Err(failed(&stopped_message(options, &e)));
    }
    let resumed = collector.resumed();
    let (total, blocks_by_rank, checkpoint) =
        collector.finish().map_err(|e| failed(&format!("the ensemble stopped: {e}")))?;
    let ran = Ran { total, blocks_by_rank, resumed, wall_time, ranks };
    let census = (sampler, restricted.as_ref().map(|r| &r.0));
    let mut report = assemble_report(m, &plan, ensemble, options, census, description, threads, ran);
    if options.in_memory {
        report.tables = Some(tables::tables(m, scene, ensemble, &plan, &report.outcome.statistics));
        return Ok(Some(report));
    }
    report.files = output::write_all(m, scene, ensemble, &plan, &report, &options.out_dir)
        .map_err(|e| failed(&format!("the ensemble ran, but its outputs could not be written: {e}")))?;
    if let Some(c) = checkpoint
        && report.status != Status::Interrupted
    {
        // Every trajectory ran and the outputs are written: the checkpoint has served.
        std::fs::remove_file(c.path())
            .map_err(|e| Error::context(format!("cannot remove {}", c.path().display()), e))?;
    }
    Ok(Some(report))
}

/// What a run in memory cannot do: keep trajectories (files) or resume (a checkpoint file).
fn refuse_in_memory(ensemble: &EnsembleScene, options: &EnsembleOptions) -> Result<(), Error> {
    if ensemble.keep_trajectories.is_some() {
        return Err(Error::Message(
            "`ensemble.keep_trajectories` writes trajectories into a folder: an ensemble run in memory cannot keep \
             them; remove it, or give the ensemble an output folder"
                .into(),
        ));
    }
    if options.resume {
        return Err(Error::Message("an ensemble run in memory has no checkpoint to resume from".into()));
    }
    Ok(())
}

/// Creates the output folder and takes its lock: one run per folder.
fn lock_out_dir(dir: &Path) -> Result<crate::dir_lock::DirLock, Error> {
    std::fs::create_dir_all(dir).map_err(|e| Error::context(format!("cannot create {}", dir.display()), e))?;
    crate::dir_lock::DirLock::acquire(dir)
}

/// The plan every block runs: the scene's run settings, the bound quantities, the stop
/// conditions and the pair states bound to `m`.
fn make_plan<'m, M, const N: usize, const NA: usize>(
    m: &'m M,
    scene: &Scene,
    ensemble: &EnsembleScene,
    bound: &Bound<N>,
    options: &EnsembleOptions,
    reduction: crate::runtime::hamiltonian::Reduction<N>,
    chart: RunChart,
) -> Result<Plan<'m, M, N, NA>, Error>
where
    M: Molecule<N, NA> + Sync,
{
    Ok(Plan {
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
        cartesian_fallback: scene.cartesian_fallback,
        chart,
        keep: ensemble.keep_trajectories.map(|k| (k, options.out_dir.join("trajectories"))),
        time_scale: scene.time_unit.in_au(),
        lanes: options.lanes,
        stops: crate::start::stop_conditions(m, scene)?,
        spectrum: ensemble.spectrum.settings.clone(),
        pairs: ensemble.pairs.as_ref().map(|p| p.bind(m, scene, bound.spec.spec())).transpose()?,
    })
}

/// The worker threads of a run, and why fewer run than were asked for or why trajectories run
/// one at a time although lanes were asked for, if so.
struct Threads {
    threads: usize,
    threads_note: Option<String>,
    lanes_note: Option<String>,
}

impl Threads {
    fn of<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        m: &M,
        ensemble: &EnsembleScene,
        options: &EnsembleOptions,
    ) -> Self {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let asked = options.threads.or(ensemble.threads);
        let (threads, threads_note) = worker_threads(asked, cores, ensemble.trajectories.div_ceil(BLOCK));
        let lanes_note = (options.lanes && !crate::runtime::hamiltonian::lanes::available(m)).then(|| {
            format!(
                "{} has no lane form here (a potential from a shared library or a grid file, or a large molecule): one trajectory \
                 at a time on each thread",
                m.name()
            )
        });
        Threads { threads, threads_note, lanes_note }
    }
}

/// The error of a run that stopped after it took the folder: `error`, with summary.json saying
/// "failed" (or, if that cannot be written, the error says so). In memory, only `error`.
fn fail_run(options: &EnsembleOptions, scene: &Scene, molecule: &str, n: u64, error: &str) -> Error {
    if options.in_memory {
        return Error::Message(error.to_owned());
    }
    let dir = &options.out_dir;
    let checkpoint = options.checkpoint.then(|| dir.join(CHECKPOINT_FILE));
    // The error itself is what matters; a summary that cannot be written is mentioned.
    match output::write_failed(dir, scene, molecule, n, error, checkpoint.as_deref()) {
        Ok(_) => Error::Message(error.to_owned()),
        Err(e) => Error::Message(format!("{error}; also {e} (summary.json may still say \"running\")")),
    }
}

/// Why the blocks stopped, and where the finished ones are kept if there is a checkpoint.
fn stopped_message(options: &EnsembleOptions, e: &impl std::fmt::Display) -> String {
    let kept = if options.checkpoint {
        format!(
            "; the blocks that finished are in {} (fix the cause, then continue it: `rovib ensemble --resume` or `EnsembleOptions::resume`)",
            options.out_dir.join(CHECKPOINT_FILE).display()
        )
    } else {
        String::new()
    };
    format!("the ensemble stopped: {e}{kept}")
}

/// What the blocks of a run added up to.
struct Ran {
    total: Outcome,
    blocks_by_rank: Vec<u64>,
    resumed: u64,
    wall_time: f64,
    ranks: usize,
}

/// The report of a finished run (its files not yet written). `census` is the sampler and, with
/// `[pairs] max_energy`, its restriction, for the census of the sampled states.
fn assemble_report<M, const N: usize, const NA: usize>(
    m: &M,
    plan: &Plan<'_, M, N, NA>,
    ensemble: &EnsembleScene,
    options: &EnsembleOptions,
    census: (&dyn Sampler<N>, Option<&pair_states::Restricted<'_, M, N>>),
    description: &str,
    threads: Threads,
    ran: Ran,
) -> EnsembleReport
where
    M: Molecule<N, NA> + Sync,
{
    let (sampler, restricted) = census;
    let n = ensemble.trajectories;
    let total = ran.total;
    let status = if options.stop.load(Ordering::Relaxed) && total.interrupted > 0 {
        Status::Interrupted
    } else if total.completed == 0 && total.failed_count() > 0 {
        Status::Failed
    } else {
        Status::Completed
    };
    EnsembleReport {
        status,
        requested: n,
        outcome: total,
        times: plan.times.clone(),
        quantities: plan.quantities[..plan.n_means].iter().map(|q| q.name(m)).collect(),
        units: plan.quantities[..plan.n_means].iter().map(|q| q.unit(m)).collect(),
        wall_time: ran.wall_time,
        threads: threads.threads,
        threads_note: threads.threads_note,
        lanes_note: threads.lanes_note,
        ranks: ran.ranks,
        blocks_by_rank: ran.blocks_by_rank,
        resumed: ran.resumed,
        seed: ensemble.seed,
        sampler: description.to_owned(),
        phase_space: spectrum::dipole_correlated(plan).then(|| pair::phase_space(m, sampler, n)),
        pair_states: plan.pairs.as_ref().map(|p| pair_states::census(m, p, sampler, restricted, n)),
        files: Vec::new(),
        tables: None,
    }
}

/// What identifies this run in its checkpoint and to the other MPI ranks: the hash of the
/// scene's bytes and, for a states file, the file's, the seed, N, the block size and the lane
/// setting.
fn run_header(scene: &Scene, ensemble: &EnsembleScene, options: &EnsembleOptions) -> Header {
    let mut bytes = scene.text.clone().into_bytes();
    if let Some(states) = ensemble.method.input_file()
        && let Ok(b) = std::fs::read(states)
    {
        bytes.push(0);
        bytes.extend_from_slice(&b);
    }
    Header::new(&bytes, ensemble.seed, ensemble.trajectories, BLOCK)
        .with_lanes(options.lanes)
        .with_chart(scene.chart.0.name())
}

/// The most worker threads per core an ensemble starts: the trajectories are compute-bound, so
/// more than a few per core only add switching (and thousands take minutes to start).
pub const MAX_THREADS_PER_CORE: usize = 4;

/// The worker threads to start when `asked` were asked for (`None`: one per core) on `cores`
/// cores for `blocks` blocks: at most one per block and [`MAX_THREADS_PER_CORE`] per core, at
/// least one; with a note saying why, when that is fewer than asked.
pub fn worker_threads(asked: Option<usize>, cores: usize, blocks: u64) -> (usize, Option<String>) {
    let wanted = asked.unwrap_or(cores).max(1);
    let per_cores = MAX_THREADS_PER_CORE.saturating_mul(cores.max(1));
    let by_blocks = usize::try_from(blocks).unwrap_or(usize::MAX).max(1);
    let used = wanted.min(per_cores).min(by_blocks);
    let note = (asked.is_some() && used < wanted).then(|| {
        let why = if used == by_blocks {
            format!("the ensemble has {blocks} block(s) of {BLOCK} trajectories, and a thread runs one block at a time")
        } else {
            format!("this machine has {cores} core(s) and more than {MAX_THREADS_PER_CORE} threads per core only add switching")
        };
        format!("{wanted} threads were asked for, {used} run: {why}")
    });
    (used, note)
}

/// The checkpoint of this run (new, or continued with `options.resume`) and what it held.
fn open_checkpoint(
    scene: &Scene,
    ensemble: &EnsembleScene,
    options: &EnsembleOptions,
    empty: &Outcome,
) -> Result<(Option<(Checkpoint, Header)>, Resumed), Error> {
    let path = options.out_dir.join(CHECKPOINT_FILE);
    if !options.checkpoint {
        if options.resume {
            return Err(Error::Message("resuming (`rovib ensemble --resume`, `EnsembleOptions::resume`) needs the checkpoint, which is turned off".into()));
        }
        return Ok((None, Resumed::default()));
    }
    let header = run_header(scene, ensemble, options);
    if options.resume {
        let (c, resumed) = Checkpoint::resume(&path, &header, checkpoint::size_limit(&header, empty))
            .map_err(|e| Error::Message(e.to_string()))?;
        return Ok((Some((c, header)), resumed));
    }
    if path.exists() {
        return Err(Error::Message(format!(
            "{} holds the finished blocks of an earlier run of this folder that did not complete; \
             continue it (`rovib ensemble --resume` or `EnsembleOptions::resume`), or delete the file to start again",
            path.display()
        )));
    }
    let c = Checkpoint::create(&path, &header).map_err(|e| Error::Message(e.to_string()))?;
    Ok((Some((c, header)), Resumed::default()))
}
