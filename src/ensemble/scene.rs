//! The `[ensemble]` and `[statistics]` tables of a scene: parsed with their places, checked,
//! converted to atomic units, and bound to the molecule (names to indices, the sampling
//! [`BoundMethod`]). Every error names the file, the line and what to change.
//!
//! `crate::scene` parses the rest of the scene and only lets these two tables through.

use std::ops::Range;

use toml::Spanned;

use super::method::{self, Binding, BoundMethod};
pub use super::method::{METHODS, MethodSpec, RegionSpec};
use super::quantity::Quantity;
use crate::runtime::Molecule;
use crate::runtime::diagnostic::{FileError, Source};
use crate::scene::Scene;
use crate::scene::raw::{EnsembleRunKeys, RawEnsemble, RawHistogram, RawStatistics};

/// The seed of an ensemble whose scene gives none.
pub const DEFAULT_SEED: u64 = 0;

/// The most bins a histogram may have.
pub const MAX_BINS: usize = 1_000_000;

/// The most output times an ensemble may have (each trajectory buffers its observations at
/// every output time: 10⁶ times × a few quantities is tens of MB per thread).
pub const MAX_OUTPUT_TIMES: usize = 1_000_000;

/// A parsed `[ensemble]` (with `[statistics]`), in atomic units, names not yet bound.
#[derive(Clone, Debug)]
pub struct EnsembleScene {
    /// Number of trajectories.
    pub trajectories: u64,
    /// The seed of every trajectory's random stream.
    pub seed: u64,
    /// Whether the seed was given (else [`DEFAULT_SEED`]).
    pub seed_given: bool,
    /// What to sample.
    pub method: MethodSpec,
    /// Worker threads (`None`: every core).
    pub threads: Option<usize>,
    /// Write the trajectory of every k-th trajectory (index divisible by k).
    pub keep_trajectories: Option<u64>,
    /// What to reduce the ensemble to.
    pub statistics: StatisticsSpec,
    /// The cap on the estimated memory, GB (`ensemble.max_memory_gb`), and where it is written.
    pub max_memory_gb: (f64, Option<Range<usize>>),
    /// The cap on the estimated disk use, GB (`ensemble.max_disk_gb`), and where it is written.
    pub max_disk_gb: (f64, Option<Range<usize>>),
    /// The `[spectrum]` table ([`super::spectrum_scene`]).
    pub spectrum: super::spectrum_scene::SpectrumScene,
    /// The `[pairs]` table ([`super::pair_states`]).
    pub pairs: Option<super::pair_states::PairScene>,
    method_span: Range<usize>,
    trajectories_span: Range<usize>,
}

/// The `[statistics]` table, names not yet bound.
#[derive(Clone, Debug)]
pub struct StatisticsSpec {
    /// Quantities whose ensemble means are written (`None`: the default set).
    pub means: Option<Vec<Spanned<String>>>,
    /// Histograms.
    pub histograms: Vec<HistogramSpec>,
    /// Quantities whose autocorrelation functions are written.
    pub correlations: Vec<Spanned<String>>,
}

/// One histogram: a quantity over a range, at some output times.
#[derive(Clone, Debug)]
pub struct HistogramSpec {
    /// The quantity.
    pub quantity: Spanned<String>,
    /// Number of bins.
    pub bins: usize,
    /// The range, in the quantity's atomic unit.
    pub range: [f64; 2],
    /// Times, a.u. (each taken at the nearest output time).
    pub times: Vec<f64>,
}

/// The ensemble bound to a molecule: what to sample and what to compute.
pub struct Bound<const N: usize> {
    /// The sampling method bound to the molecule (its sampler: [`BoundMethod::sampler`]).
    pub spec: BoundMethod<N>,
    /// One line saying how the states are drawn, for summary.json.
    pub description: String,
    /// Every quantity observed, means first.
    pub quantities: Vec<Quantity>,
    /// How many of `quantities` have their means written.
    pub n_means: usize,
    /// Histograms: index into `quantities`, bins, range, output-time indices.
    pub histograms: Vec<(usize, usize, [f64; 2], Vec<usize>)>,
    /// Correlations: indices into `quantities`.
    pub correlations: Vec<usize>,
}

pub use crate::scene::did_you_mean;

/// Parses the `[ensemble]` and `[statistics]` tables of `scene` (which must have `[ensemble]`).
pub fn parse_ensemble(scene: &Scene) -> Result<EnsembleScene, FileError> {
    let src = scene.source();
    let raw = scene.tables.ensemble.clone().map_err(|e| crate::scene::toml_error(&src, &e, method::KEYS_HELP))?;
    let Some(table) = raw.ensemble else {
        return Err(src.whole_file(
            "the scene has no [ensemble] table",
            "add [ensemble] with trajectories, seed and method (see docs/src/reference/ensemble.md), or use `rovib run`",
        ));
    };
    // The keys every method takes; a key that neither they nor some method take is unknown.
    let e: RawEnsemble = crate::scene::spanned::deserialize(&table)
        .map_err(|e| crate::scene::spanned_error(&src, &e, method::KEYS_HELP))?;
    method::refuse_unknown_keys(&src, &table)?;

    refuse_single_run_keys(&src, &raw.initial, raw.run.as_ref())?;

    let trajectories = *e.trajectories.get_ref();
    if trajectories < 1 {
        return Err(src.error(
            e.trajectories.span(),
            format!("`ensemble.trajectories` must be at least 1, got {trajectories}"),
            "write the number of trajectories to run, e.g. trajectories = 1000",
        ));
    }
    let seed = parse_seed(&src, e.seed.as_ref())?;
    let threads =
        parse_count(&src, &e.threads, "threads", "remove it to use every core, or give the number of worker threads")?
            .map(|t| t as usize);
    let keep_trajectories = parse_count(
        &src,
        &e.keep_trajectories,
        "keep_trajectories",
        "write k to keep the trajectory of every k-th trajectory",
    )?;
    let max_memory_gb = parse_cap(&src, &e.max_memory_gb, "max_memory_gb", super::resources::DEFAULT_MAX_MEMORY_GB)?;
    let max_disk_gb = parse_cap(&src, &e.max_disk_gb, "max_disk_gb", super::resources::DEFAULT_MAX_DISK_GB)?;
    check_output_times(scene, &src)?;
    let method = method::read(scene, &src, &e, &table)?;
    let statistics = match raw.statistics {
        None => StatisticsSpec { means: None, histograms: Vec::new(), correlations: Vec::new() },
        Some(s) => parse_statistics(scene, &src, s.into_inner())?,
    };
    Ok(EnsembleScene {
        trajectories: trajectories as u64,
        seed,
        seed_given: e.seed.is_some(),
        method,
        threads,
        keep_trajectories,
        statistics,
        max_memory_gb,
        max_disk_gb,
        spectrum: super::spectrum_scene::parse_spectrum(scene)?,
        pairs: super::pair_states::parse_pairs(scene)?,
        method_span: e.method.span(),
        trajectories_span: e.trajectories.span(),
    })
}

/// `ensemble.seed`: a non-negative integer, [`DEFAULT_SEED`] if not given.
fn parse_seed(src: &Source<'_>, seed: Option<&Spanned<i64>>) -> Result<u64, FileError> {
    match seed {
        Some(s) if *s.get_ref() < 0 => Err(src.error(
            s.span(),
            format!("`ensemble.seed` must be a non-negative integer, got {}", s.get_ref()),
            "write a seed from 0 to 9223372036854775807",
        )),
        Some(s) => Ok(*s.get_ref() as u64),
        None => Ok(DEFAULT_SEED),
    }
}

/// An optional count of at least 1 (`ensemble.{what}`), `help` saying what to write instead.
fn parse_count(src: &Source<'_>, x: &Option<Spanned<i64>>, what: &str, help: &str) -> Result<Option<u64>, FileError> {
    match x {
        Some(v) if *v.get_ref() < 1 => {
            Err(src.error(v.span(), format!("`ensemble.{what}` must be at least 1, got {}", v.get_ref()), help))
        }
        Some(v) => Ok(Some(*v.get_ref() as u64)),
        None => Ok(None),
    }
}

/// An optional cap in GB (`ensemble.{what}`, positive and finite) with its place, else `default`.
fn parse_cap(
    src: &Source<'_>,
    x: &Option<Spanned<f64>>,
    what: &str,
    default: f64,
) -> Result<(f64, Option<Range<usize>>), FileError> {
    match x {
        Some(v) if !(v.get_ref().is_finite() && *v.get_ref() > 0.0) => Err(src.error(
            v.span(),
            format!("`ensemble.{what}` must be a positive finite number of GB, got {}", v.get_ref()),
            format!("leave it out for the default {default} GB, or give the most the ensemble may use"),
        )),
        Some(v) => Ok((*v.get_ref(), Some(v.span()))),
        None => Ok((default, None)),
    }
}

/// Refuses more than [`MAX_OUTPUT_TIMES`] output times: every trajectory keeps its observations
/// at all of them until it ends.
fn check_output_times(scene: &Scene, src: &Source<'_>) -> Result<(), FileError> {
    let n_times = scene.t_end / scene.output_interval;
    if n_times.is_nan() || n_times > MAX_OUTPUT_TIMES as f64 {
        return Err(src.whole_file(
            format!("run.end / run.output_interval = {n_times:.3e} output times, more than the {MAX_OUTPUT_TIMES} an ensemble allows"),
            "raise run.output_interval (the statistics' time grid) or shorten run.end",
        ));
    }
    Ok(())
}

/// The `[statistics]` table: its histograms checked and their times in atomic units.
fn parse_statistics(scene: &Scene, src: &Source<'_>, s: RawStatistics) -> Result<StatisticsSpec, FileError> {
    let histograms = s.histograms.iter().map(|h| parse_histogram(scene, src, h.get_ref())).collect::<Result<_, _>>()?;
    Ok(StatisticsSpec { means: s.means, histograms, correlations: s.correlations })
}

/// One `[[statistics.histograms]]`: its bins, range and times checked.
fn parse_histogram(scene: &Scene, src: &Source<'_>, h: &RawHistogram) -> Result<HistogramSpec, FileError> {
    let bins = *h.bins.get_ref();
    if bins > MAX_BINS as i64 {
        return Err(src.error(
            h.bins.span(),
            format!("a histogram of {bins} bins is more than the {MAX_BINS} allowed"),
            "use fewer bins",
        ));
    }
    if bins < 1 {
        return Err(src.error(
            h.bins.span(),
            format!("a histogram needs at least one bin, got {bins}"),
            "write bins = 50, for example",
        ));
    }
    let r = h.range.get_ref();
    if r.len() != 2 || !r.iter().all(|x| x.is_finite()) || r[0] >= r[1] {
        return Err(src.error(
            h.range.span(),
            "a histogram's range must be two finite numbers [low, high] with low < high",
            "write range = [low, high] in the quantity's atomic unit (bohr, rad, hartree, hbar)",
        ));
    }
    if !histogram_range_is_representable([r[0], r[1]], bins as usize) {
        return Err(src.error(
            h.range.span(),
            format!(
                "the histogram range [{}, {}] in {bins} bins has a width or bin width that is not a \
                 finite, resolvable number",
                r[0], r[1]
            ),
            "give a range whose width (high − low) is finite and whose bins are wider than the rounding \
             of numbers of its size, e.g. range = [0, 10]",
        ));
    }
    let times = match &h.times {
        None => vec![0.0],
        Some(t) => histogram_times(scene, src, t)?,
    };
    Ok(HistogramSpec { quantity: h.quantity.clone(), bins: bins as usize, range: [r[0], r[1]], times })
}

/// A histogram's times (scene's time unit) in atomic units, each within the run.
fn histogram_times(scene: &Scene, src: &Source<'_>, t: &Spanned<Vec<f64>>) -> Result<Vec<f64>, FileError> {
    let end = scene.t_end / scene.units.time;
    let mut times = Vec::new();
    for &x in t.get_ref() {
        if !(x.is_finite() && (0.0..=end * (1.0 + 1e-12)).contains(&x)) {
            return Err(src.error(
                t.span(),
                format!("histogram time {x} is outside the run, 0 to run.end = {end}"),
                "write times between 0 and run.end, in the scene's time unit",
            ));
        }
        times.push(x * scene.units.time);
    }
    Ok(times)
}

/// `[initial]`, `run.outputs` and `run.euler_unwrapped` describe one trajectory and its files;
/// an ensemble draws its own states and writes its own files, so each is an error at its place.
fn refuse_single_run_keys(
    src: &Source<'_>,
    initial: &Option<Spanned<toml::Value>>,
    run: Option<&EnsembleRunKeys>,
) -> Result<(), FileError> {
    if let Some(i) = initial {
        return Err(src.error(
            i.span(),
            "an ensemble does not use [initial]: every trajectory starts from a state drawn by ensemble.method",
            "remove [initial]; to start the trajectories from given states use method = \"file\" with a states file, \
             or run this one state with `rovib run` on a scene without [ensemble]",
        ));
    }
    let Some(run) = run else { return Ok(()) };
    if let Some(o) = &run.outputs {
        return Err(src.error(
            o.span(),
            "`run.outputs` does not apply to an ensemble: it always writes ensemble.csv, histograms.csv, \
             correlations.csv, summary.json and the plots",
            "remove run.outputs; to keep the trajectory files of some members use ensemble.keep_trajectories = k",
        ));
    }
    if let Some(u) = &run.euler_unwrapped {
        return Err(src.error(
            u.span(),
            "`run.euler_unwrapped` does not apply to an ensemble (its kept trajectory files have no unwrapped columns)",
            "remove it; for unwrapped Euler angles run one trajectory with `rovib run`",
        ));
    }
    Ok(())
}

/// A histogram range whose width, and each bin's width, are finite and resolvable in f64 at the
/// range's magnitude (else the bin edges are NaN, infinite or coincide).
fn histogram_range_is_representable(range: [f64; 2], bins: usize) -> bool {
    let width = range[1] - range[0];
    let bin = width / bins as f64;
    let scale = range[0].abs().max(range[1].abs());
    width.is_finite() && bin.is_normal() && bin > 4.0 * f64::EPSILON * scale
}

impl EnsembleScene {
    /// Binds the ensemble to molecule `m`: coordinate names, units, the sampling method
    /// ([`BoundMethod`], reading a states file), the quantities and the output-time indices of
    /// histograms.
    pub fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        scene: &Scene,
        times: &[f64],
    ) -> Result<Bound<N>, FileError> {
        let src = scene.source();
        let cx = Binding::new(scene, self.method_span.clone(), (self.trajectories, self.trajectories_span.clone()));
        let (spec, description) = self.method.bind::<M, N, NA>(m, &cx)?;

        // Quantities: means (or the default set), then those only histogrammed or correlated.
        let lookup = |name: &Spanned<String>| -> Result<Quantity, FileError> {
            Quantity::parse(name.get_ref(), m).ok_or_else(|| {
                unknown_name(&src, name, "no quantity is called", Quantity::names(m).iter().map(String::as_str))
            })
        };
        let mut quantities: Vec<Quantity> = match &self.statistics.means {
            Some(list) => list.iter().map(lookup).collect::<Result<_, _>>()?,
            None => Quantity::default_set::<M, N, NA>(),
        };
        quantities.dedup();
        let n_means = quantities.len();
        let mut index_of = |q: Quantity| match quantities.iter().position(|x| *x == q) {
            Some(i) => i,
            None => {
                quantities.push(q);
                quantities.len() - 1
            }
        };
        let mut histograms = Vec::new();
        for h in &self.statistics.histograms {
            let qi = index_of(lookup(&h.quantity)?);
            let at: Vec<usize> = h.times.iter().map(|&t| nearest(times, t)).collect();
            histograms.push((qi, h.bins, h.range, at));
        }
        let mut correlations = Vec::new();
        for c in &self.statistics.correlations {
            correlations.push(index_of(lookup(c)?));
        }
        self.spectrum.check(&src, &quantities, &correlations)?;
        let bound = Bound { spec, description, quantities, n_means, histograms, correlations };
        self.check_resources(&bound, scene, times.len(), 2 * N + 8)?;
        Ok(bound)
    }

    /// Refuses an ensemble whose estimated memory or disk use (see [`super::resources`]) is above
    /// `ensemble.max_memory_gb` or `ensemble.max_disk_gb`, before any trajectory runs.
    fn check_resources<const N: usize>(
        &self,
        bound: &Bound<N>,
        scene: &Scene,
        times: usize,
        row_numbers: usize,
    ) -> Result<(), FileError> {
        use super::resources::{Shape, gb};
        let src = scene.source();
        let blocks = self.trajectories.div_ceil(super::runner::BLOCK);
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let shape = Shape {
            trajectories: self.trajectories,
            blocks,
            threads: super::worker_threads(self.threads, cores, blocks).0,
            times,
            quantities: bound.quantities.len(),
            means: bound.n_means,
            correlations: bound.correlations.len(),
            histogram_bins: bound.histograms.iter().map(|h| h.1 as u64 * h.3.len() as u64).sum(),
            row_numbers,
            keep: self.keep_trajectories,
        };
        let e = shape.estimate();
        let at = |given: &Option<Range<usize>>| given.clone().unwrap_or_else(|| self.trajectories_span.clone());
        if e.memory > self.max_memory_gb.0 * 1e9 {
            return Err(src.error(
                at(&self.max_memory_gb.1),
                format!(
                    "the ensemble's statistics would need about {} of memory ({} output times, {} histogram bins \
                     over their times, {} threads), more than ensemble.max_memory_gb = {}",
                    gb(e.memory),
                    times,
                    shape.histogram_bins,
                    shape.threads,
                    self.max_memory_gb.0
                ),
                "use fewer histogram bins or times, a longer run.output_interval or fewer threads, \
                 or raise ensemble.max_memory_gb if the machine has the memory",
            ));
        }
        if e.disk > self.max_disk_gb.0 * 1e9 {
            let kept =
                if e.kept > 0.0 { format!(", of which {} kept trajectories", gb(e.kept)) } else { String::new() };
            return Err(src.error(
                at(&self.max_disk_gb.1),
                format!(
                    "the ensemble would write about {} (checkpoint, tables{kept}), more than ensemble.max_disk_gb = {}",
                    gb(e.disk),
                    self.max_disk_gb.0
                ),
                "keep fewer trajectories (a larger keep_trajectories), use fewer histogram bins or times, \
                 or raise ensemble.max_disk_gb if the disk has the room",
            ));
        }
        Ok(())
    }

    /// Where `method = ...` is written, for errors of the sampler.
    pub fn method_span(&self) -> Range<usize> {
        self.method_span.clone()
    }
}

/// The index of the output time nearest to `t`.
fn nearest(times: &[f64], t: f64) -> usize {
    let mut best = 0;
    for (i, &x) in times.iter().enumerate() {
        if (x - t).abs() < (times[best] - t).abs() {
            best = i;
        }
    }
    best
}

pub(crate) fn unknown_name<'a>(
    src: &Source<'_>,
    name: &Spanned<String>,
    what: &str,
    known: impl Iterator<Item = &'a str> + Clone,
) -> FileError {
    let list: Vec<&str> = known.clone().collect();
    let help = match did_you_mean(name.get_ref(), known) {
        Some(s) => format!("did you mean `{s}`? the names are {}", list.join(", ")),
        None => format!("the names are {}", list.join(", ")),
    };
    src.error(name.span(), format!("{what} `{}`", name.get_ref()), help)
}
