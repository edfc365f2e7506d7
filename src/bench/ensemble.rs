//! `rovib bench --ensemble SCENE.toml`: ensemble throughput (trajectories per second) on 1 and
//! 2 threads, the parallel efficiency, and the cost of the statistics against the integration.
//!
//! Initial states come from the scene's own sampler when it can be built; otherwise (a scene
//! whose method cannot be sampled) from a Gaussian spread about the molecule's reference geometry at rest (an ensemble
//! scene has no `[initial]`): q ± 0.02
//! (bohr, rad), p ± 0.5 (ħ/bohr, ħ), J ± 2 ħ per component, uniform orientation, drawn from
//! trajectory i's own stream. The report says which was used.
//!
//! Each configuration runs [`REPEATS`] times, interleaved, and its best wall time is kept;
//! "statistics" means the
//! bench's full set (means of every coordinate, T, U, H, |J|, Lz; a 50-bin histogram of every
//! coordinate at the start and the end; the autocorrelation of every coordinate), "none" means
//! no quantity at all. Both check the energy at every output time (the guard), which is counted
//! as integration.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use rand_distr::{Distribution as _, StandardNormal};

use crate::ensemble::{EnsembleOptions, EnsembleReport, run_with_sampler};
use crate::error::Error;
use crate::molecules;
use crate::runtime::hamiltonian::fast::BodyState;
use crate::runtime::nalgebra::{Quaternion, SVector, UnitQuaternion, Vector3};
use crate::runtime::sample::{self, SampleError, Sampler};
use crate::runtime::{Molecule, MoleculeVisitor};
use crate::scene::{Scene, parse_scene};
use crate::simulation::initial_state;

/// How often each configuration runs (the best wall time is kept).
pub const REPEATS: usize = 3;

/// One measured configuration.
#[derive(Clone, Debug)]
pub struct EnsembleTrial {
    /// Worker threads.
    pub threads: usize,
    /// Whether the full statistics were accumulated.
    pub statistics: bool,
    /// Trajectories run.
    pub trajectories: u64,
    /// Failed ones.
    pub failed: u64,
    /// Best wall time, s.
    pub wall_time: f64,
    /// Right-hand-side evaluations per completed trajectory.
    pub rhs_per_trajectory: f64,
}

/// What `rovib bench --ensemble` measured.
pub struct EnsembleBenchReport {
    /// The runs.
    pub trials: Vec<EnsembleTrial>,
    /// Where the states came from.
    pub sampler: String,
    /// The text table (also written to ensemble_bench.md).
    pub table: String,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// A standard normal variate from trajectory `index`'s stream.
fn normal(rng: &mut sample::TrajectoryRng) -> f64 {
    StandardNormal.sample(rng)
}

/// The fallback sampler: a Gaussian spread about one state.
struct Spread<const N: usize> {
    centre: BodyState<N>,
    seed: u64,
}

impl<const N: usize> Sampler<N> for Spread<N> {
    fn draw(&self, index: u64) -> Result<BodyState<N>, SampleError> {
        let mut rng = sample::stream(self.seed, index);
        let mut s = self.centre;
        s.q += SVector::<f64, N>::from_fn(|_, _| 0.02 * normal(&mut rng));
        s.p += SVector::<f64, N>::from_fn(|_, _| 0.5 * normal(&mut rng));
        s.j += Vector3::from_fn(|_, _| 2.0 * normal(&mut rng));
        let (w, x, y, z) = (normal(&mut rng), normal(&mut rng), normal(&mut rng), normal(&mut rng));
        s.orientation = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
        Ok(s)
    }
}

/// Runs the ensemble benchmark of the scene at `path` (which has `[ensemble]`
/// and no `[statistics]`) with `trajectories` trajectories (default the scene's).
pub fn bench(path: &Path, out_dir: Option<&Path>, trajectories: Option<u64>) -> Result<EnsembleBenchReport, Error> {
    let text = crate::runtime::diagnostic::read_text_capped(path, crate::runtime::diagnostic::MAX_INPUT_BYTES)?;
    let name = path.display().to_string();
    let scene = parse_scene(&name, &text)?;
    if !scene.ensemble || text.lines().any(|l| l.trim_start().starts_with("[statistics]")) {
        return Err(Error::Message(format!(
            "{name}: `rovib bench --ensemble` needs a scene with [ensemble] and without [statistics] \
             (it sets its own), e.g. scenes/h2o_ensemble_bench.toml"
        )));
    }
    let out_dir = match out_dir {
        Some(d) => d.to_owned(),
        None => Path::new("out").join(path.file_stem().unwrap_or_default()).join("bench-ensemble"),
    };
    let molecule = scene.molecule.get_ref().clone();
    molecules::visit(&molecule, Visit { scene: &scene, text: &text, out_dir: &out_dir, trajectories })
        .ok_or_else(|| Error::unknown_molecule(&molecule))?
}

struct Visit<'a> {
    scene: &'a Scene,
    text: &'a str,
    out_dir: &'a Path,
    trajectories: Option<u64>,
}

impl MoleculeVisitor for Visit<'_> {
    type Output = Result<EnsembleBenchReport, Error>;

    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        let names: Vec<&str> = m.coordinates().iter().map(|c| c.name).collect();
        let quoted = |v: &[&str]| v.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ");
        let mut means = names.clone();
        means.extend(["T", "U", "H", "J", "Lz"]);
        let histograms: Vec<String> = names
            .iter()
            .map(|n| {
                let range = if m
                    .coordinates()
                    .iter()
                    .any(|c| c.name == *n && matches!(c.unit, crate::runtime::units::CoordinateUnit::Angle(_)))
                {
                    "[1.2, 2.4]"
                } else {
                    "[1.0, 3.0]"
                };
                format!(
                    "{{ quantity = \"{n}\", bins = 50, range = {range}, times = [0, {}] }}",
                    self.scene.t_end / self.scene.units.time
                )
            })
            .collect();
        let full = format!(
            "\n[statistics]\nmeans = [{}]\nhistograms = [{}]\ncorrelations = [{}]\n",
            quoted(&means),
            histograms.join(", "),
            quoted(&names)
        );
        let none = "\n[statistics]\nmeans = []\n".to_owned();
        let variant = |statistics: &str| -> Result<Scene, Error> {
            let mut text = self.text.to_owned();
            if let Some(n) = self.trajectories {
                text = replace_trajectories(&text, n);
            }
            text.push_str(statistics);
            Ok(parse_scene(&self.scene.path, &text)?)
        };
        let scenes = [(true, variant(&full)?), (false, variant(&none)?)];

        let ensemble = crate::ensemble::scene::parse_ensemble(&scenes[0].1)?;
        let start = initial_state(&m, self.scene)?;
        let centre = start.body;
        let spread = Spread { centre, seed: ensemble.seed };
        let times = crate::ensemble::output_times(self.scene.t_end, self.scene.output_interval);
        let bound = ensemble.bind(&m, &scenes[0].1, &times)?;
        let own = bound.spec.sampler(&m, ensemble.seed);
        let (sampler, description): (&dyn Sampler<N>, String) = match &own {
            Ok(s) => (&**s, bound.description.clone()),
            Err(e) => (
                &spread,
                format!(
                    "Gaussian spread about the reference geometry (q ± 0.02, p ± 0.5, J ± 2 hbar, uniform orientation), because the scene's sampler is not available: {e}"
                ),
            ),
        };

        // Configurations interleaved and repeated, the best wall time of each kept: on a shared
        // machine the best is the run least disturbed by other processes.
        let mut trials: Vec<EnsembleTrial> = Vec::new();
        for _ in 0..REPEATS {
            for threads in [1, 2] {
                for (statistics, scene) in &scenes {
                    let tag = if *statistics { "statistics" } else { "none" };
                    let mut options = EnsembleOptions::new(self.out_dir.join(format!("threads{threads}-{tag}")));
                    options.threads = Some(threads);
                    let r: EnsembleReport = run_with_sampler(&m, scene, sampler, &description, &options)?;
                    let trial = EnsembleTrial {
                        threads,
                        statistics: *statistics,
                        trajectories: r.requested,
                        failed: r.outcome.failed_count(),
                        wall_time: r.wall_time,
                        rhs_per_trajectory: r.outcome.rhs_evaluations as f64 / r.outcome.completed.max(1) as f64,
                    };
                    match trials.iter_mut().find(|t| t.threads == threads && t.statistics == *statistics) {
                        Some(t) => t.wall_time = t.wall_time.min(trial.wall_time),
                        None => trials.push(trial),
                    }
                }
            }
        }
        let table = table(&trials, &description, self.scene);
        std::fs::create_dir_all(self.out_dir)
            .map_err(|e| Error::context(format!("cannot create {}", self.out_dir.display()), e))?;
        let md = self.out_dir.join("ensemble_bench.md");
        std::fs::write(&md, &table).map_err(|e| Error::context(format!("cannot write {}", md.display()), e))?;
        Ok(EnsembleBenchReport { trials, sampler: description, table, files: vec![md] })
    }
}

/// The scene text with `trajectories = n` in `[ensemble]`.
fn replace_trajectories(text: &str, n: u64) -> String {
    let mut out = String::new();
    let mut in_ensemble = false;
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with('[') {
            in_ensemble = t.starts_with("[ensemble]");
        }
        if in_ensemble && t.starts_with("trajectories") {
            let _ = writeln!(out, "trajectories = {n}");
        } else {
            let _ = writeln!(out, "{line}");
        }
    }
    out
}

fn table(trials: &[EnsembleTrial], sampler: &str, scene: &Scene) -> String {
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let mut s = format!(
        "Ensemble benchmark: {} ({} to t = {} a.u.), states: {sampler}\nload average at the end (1, 5, 15 min): {}\n\n\
         | threads | statistics | trajectories | failed | best wall time (s) | trajectories/s | per trajectory (ms) | rhs per trajectory |\n\
         | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |\n",
        scene.path,
        scene.method.name(),
        scene.t_end,
        load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")
    );
    let rate = |t: &EnsembleTrial| t.trajectories as f64 / t.wall_time;
    for t in trials {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.3} | {:.0} | {:.3} | {:.0} |",
            t.threads,
            if t.statistics { "full" } else { "none" },
            t.trajectories,
            t.failed,
            t.wall_time,
            rate(t),
            1e3 * t.wall_time / t.trajectories as f64,
            t.rhs_per_trajectory
        );
    }
    let find =
        |threads: usize, statistics: bool| trials.iter().find(|t| t.threads == threads && t.statistics == statistics);
    if let (Some(a1), Some(a2), Some(n1)) = (find(1, true), find(2, true), find(1, false)) {
        let _ = writeln!(
            s,
            "\nparallel efficiency 1 → 2 threads (with statistics): {:.1} %; statistics cost on 1 thread: {:+.1} % of the run without\n\
             throughput on 2 threads: {:.0} trajectories per minute",
            100.0 * rate(a2) / (2.0 * rate(a1)),
            100.0 * (a1.wall_time - n1.wall_time) / n1.wall_time,
            60.0 * rate(a2)
        );
    }
    s
}
