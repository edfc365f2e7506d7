//! The `[ensemble]` and `[statistics]` tables of a scene: parsed with their places, checked,
//! converted to atomic units, and bound to the molecule (names to indices, the sampling
//! [`Spec`]). Every error names the file, the line and what to change.
//!
//! `crate::scene` parses the rest of the scene and only lets these two tables through.

use std::ops::Range;
use std::path::PathBuf;

use toml::Spanned;

use super::quantity::Quantity;
use super::states_file::read_states;
use crate::runtime::Molecule;
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::sample::{ModeEnergies, Region, RotationSampling, Spec};
use crate::runtime::units::EnergyUnit;
use crate::scene::Scene;

mod method;
use crate::scene::raw::EnsembleRunKeys;

/// The seed of an ensemble whose scene gives none.
pub const DEFAULT_SEED: u64 = 0;

/// The most bins a histogram may have.
pub const MAX_BINS: usize = 1_000_000;

/// The most output times an ensemble may have (each trajectory buffers its observations at
/// every output time: 10⁶ times × a few quantities is tens of MB per thread).
pub const MAX_OUTPUT_TIMES: usize = 1_000_000;

/// The sampling methods, as spelt in scenes (one entry each in `method::VARIANTS`).
pub const METHODS: [&str; method::VARIANTS.len()] = {
    let mut names = [""; method::VARIANTS.len()];
    let mut i = 0;
    while i < names.len() {
        names[i] = method::VARIANTS[i].name;
        i += 1;
    }
    names
};

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

/// A sampling method with its parameters (energies in hartree, temperatures in kelvin, J in ħ).
#[derive(Clone, Debug)]
pub enum MethodSpec {
    /// Canonical at `temperature` kelvin.
    Thermal {
        /// Kelvin.
        temperature: f64,
        /// The bounded region.
        region: RegionSpec,
    },
    /// On the energy shell.
    Microcanonical {
        /// Total energy, hartree, and where it is written.
        energy: (f64, Range<usize>),
        /// Fixed |J|, ħ.
        angular_momentum: Option<f64>,
        /// The bounded region.
        region: RegionSpec,
    },
    /// Normal-mode sampling.
    NormalModes {
        /// Energies per mode.
        energies: ModeEnergies,
        /// Rotation.
        rotation: RotationSampling,
    },
    /// States read from a file (path resolved against the scene's folder).
    File {
        /// The file.
        path: PathBuf,
        /// Where `file = ...` is written.
        span: Range<usize>,
    },
    /// Collisions of two fragments (`[collision]`, run by `super::collision_run`).
    Collision(Box<super::collision_scene::CollisionScene>),
}

/// `region = { energy_cap = ..., limits = { name = [lo, hi] } }`, cap in hartree, limits in the
/// scene's units until bound.
#[derive(Clone, Debug, Default)]
pub struct RegionSpec {
    /// The cap on `U(q) − U(q_ref)`, hartree, and where it is written.
    pub energy_cap: Option<(f64, Range<usize>)>,
    /// Limits by coordinate name, in the scene's length or angle unit.
    pub limits: Vec<(Spanned<String>, [f64; 2])>,
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
    /// The sampling specification.
    pub spec: Spec<N>,
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
    let raw = scene.tables.ensemble.clone().map_err(|e| {
        let help = "docs/src/reference/ensemble.md (the guide's ensemble reference) lists every key of [ensemble] and [statistics]";
        crate::scene::toml_error(&src, &e, help)
    })?;
    let Some(ensemble) = raw.ensemble else {
        return Err(src.whole_file(
            "the scene has no [ensemble] table",
            "add [ensemble] with trajectories, seed and method (see docs/src/reference/ensemble.md), or use `rovib run`",
        ));
    };

    refuse_single_run_keys(&src, &raw.initial, raw.run.as_ref())?;
    let e = ensemble.into_inner();

    let trajectories = *e.trajectories.get_ref();
    if trajectories < 1 {
        return Err(src.error(
            e.trajectories.span(),
            format!("`ensemble.trajectories` must be at least 1, got {trajectories}"),
            "write the number of trajectories to run, e.g. trajectories = 1000",
        ));
    }
    let seed = match &e.seed {
        Some(s) if *s.get_ref() < 0 => {
            return Err(src.error(
                s.span(),
                format!("`ensemble.seed` must be a non-negative integer, got {}", s.get_ref()),
                "write a seed from 0 to 9223372036854775807",
            ));
        }
        Some(s) => *s.get_ref() as u64,
        None => DEFAULT_SEED,
    };
    let count = |x: &Option<Spanned<i64>>, what: &str, help: &str| -> Result<Option<u64>, FileError> {
        match x {
            Some(v) if *v.get_ref() < 1 => {
                Err(src.error(v.span(), format!("`ensemble.{what}` must be at least 1, got {}", v.get_ref()), help))
            }
            Some(v) => Ok(Some(*v.get_ref() as u64)),
            None => Ok(None),
        }
    };
    let threads = count(&e.threads, "threads", "remove it to use every core, or give the number of worker threads")?
        .map(|t| t as usize);
    let keep_trajectories =
        count(&e.keep_trajectories, "keep_trajectories", "write k to keep the trajectory of every k-th trajectory")?;

    let cap = |x: &Option<Spanned<f64>>, what: &str, default: f64| -> Result<(f64, Option<Range<usize>>), FileError> {
        match x {
            Some(v) if !(v.get_ref().is_finite() && *v.get_ref() > 0.0) => Err(src.error(
                v.span(),
                format!("`ensemble.{what}` must be a positive finite number of GB, got {}", v.get_ref()),
                format!("leave it out for the default {default} GB, or give the most the ensemble may use"),
            )),
            Some(v) => Ok((*v.get_ref(), Some(v.span()))),
            None => Ok((default, None)),
        }
    };
    let max_memory_gb = cap(&e.max_memory_gb, "max_memory_gb", super::resources::DEFAULT_MAX_MEMORY_GB)?;
    let max_disk_gb = cap(&e.max_disk_gb, "max_disk_gb", super::resources::DEFAULT_MAX_DISK_GB)?;

    let energy_unit = match &e.energy_unit {
        None => EnergyUnit::Hartree,
        Some(u) => EnergyUnit::parse(u.get_ref()).ok_or_else(|| {
            let names: Vec<&str> = EnergyUnit::SPELLINGS.iter().map(|s| s.0).collect();
            src.error(
                u.span(),
                format!("unknown energy unit `{}`", u.get_ref()),
                format!("use one of {}", names.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ")),
            )
        })?,
    };
    let eh = energy_unit.in_hartree();

    // Every trajectory keeps its observations at all output times until it ends.
    let n_times = scene.t_end / scene.output_interval;
    if n_times.is_nan() || n_times > MAX_OUTPUT_TIMES as f64 {
        return Err(src.whole_file(
            format!("run.end / run.output_interval = {n_times:.3e} output times, more than the {MAX_OUTPUT_TIMES} an ensemble allows"),
            "raise run.output_interval (the statistics' time grid) or shorten run.end",
        ));
    }
    let method = method::read(&method::Context { scene, src: &src, e: &e, eh })?;

    let statistics = match raw.statistics {
        None => StatisticsSpec { means: None, histograms: Vec::new(), correlations: Vec::new() },
        Some(s) => {
            let s = s.into_inner();
            let mut histograms = Vec::new();
            for h in &s.histograms {
                let h = h.get_ref();
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
                    Some(t) => {
                        let mut times = Vec::new();
                        for &x in t.get_ref() {
                            if !(x.is_finite() && (0.0..=scene.t_end / scene.units.time * (1.0 + 1e-12)).contains(&x)) {
                                return Err(src.error(
                                    t.span(),
                                    format!(
                                        "histogram time {x} is outside the run, 0 to run.end = {}",
                                        scene.t_end / scene.units.time
                                    ),
                                    "write times between 0 and run.end, in the scene's time unit",
                                ));
                            }
                            times.push(x * scene.units.time);
                        }
                        times
                    }
                };
                histograms.push(HistogramSpec {
                    quantity: h.quantity.clone(),
                    bins: bins as usize,
                    range: [r[0], r[1]],
                    times,
                });
            }
            StatisticsSpec { means: s.means, histograms, correlations: s.correlations }
        }
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

fn quoted(names: &[&str]) -> String {
    names.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ")
}

impl EnsembleScene {
    /// Binds the ensemble to molecule `m`: coordinate names, units, the sampling [`Spec`]
    /// (reading the states file), the quantities and the output-time indices of histograms.
    pub fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        scene: &Scene,
        times: &[f64],
    ) -> Result<Bound<N>, FileError> {
        let src = scene.source();
        let coords = m.coordinates();
        let reference_energy = || -> Result<f64, FileError> {
            let q = m.reference_geometry().ok_or_else(|| {
                src.error(
                    self.method_span.clone(),
                    format!("{} has no reference geometry to measure energies from", m.name()),
                    format!("add `reference` values to the coordinates in {}", m.source()),
                )
            })?;
            Ok(m.potential(&q))
        };
        let region = |r: &RegionSpec| -> Result<Region<N>, FileError> {
            let mut limits = [None; N];
            for (name, [lo, hi]) in &r.limits {
                let k = coords.iter().position(|c| c.name == name.get_ref()).ok_or_else(|| {
                    unknown_name(&src, name, &format!("{} has no coordinate", m.name()), coords.iter().map(|c| c.name))
                })?;
                let s = scene.units.coordinate_to_au(coords[k].unit, 1.0);
                let (rlo, rhi) = coords[k].range;
                let slack = |x: f64| 1e-12 * x.abs().max(1.0);
                if lo * s < rlo - slack(rlo) || hi * s > rhi + slack(rhi) {
                    return Err(src.error(
                        name.span(),
                        format!(
                            "the limits [{lo}, {hi}] of `{}` reach outside its valid range [{}, {}] (scene units)",
                            name.get_ref(),
                            rlo / s,
                            rhi / s
                        ),
                        "give limits within the coordinate's range (a bond angle within [0, π], a length above 0)",
                    ));
                }
                limits[k] = Some((lo * s, hi * s));
            }
            Ok(Region { energy_cap: r.energy_cap.as_ref().map(|c| c.0), limits })
        };
        let (spec, description) = match &self.method {
            MethodSpec::Thermal { temperature, region: r } => (
                Spec::Thermal { temperature: *temperature, region: region(r)? },
                format!("thermal (canonical) at {temperature} K"),
            ),
            MethodSpec::Microcanonical { energy, angular_momentum, region: r } => {
                let u0 = reference_energy()?;
                if energy.0 < u0 {
                    return Err(src.error(
                        energy.1.clone(),
                        format!(
                            "the energy {} hartree is below the potential at the reference geometry, {u0} hartree",
                            energy.0
                        ),
                        "give a total energy above the minimum of the potential (same zero as the potential)",
                    ));
                }
                if let Some((cap, at)) = &r.energy_cap
                    && *cap < energy.0 - u0
                {
                    return Err(src.error(
                        at.clone(),
                        format!(
                            "the energy cap {cap} hartree is below the energy above the reference, E − U(reference) = {} hartree",
                            energy.0 - u0
                        ),
                        "raise region.energy_cap above E − U(reference), or lower the energy",
                    ));
                }
                let d = match angular_momentum {
                    Some(j) => format!("microcanonical at E = {} hartree, |J| = {j} hbar", energy.0),
                    None => format!("microcanonical at E = {} hartree", energy.0),
                };
                (Spec::Microcanonical { energy: energy.0, angular_momentum: *angular_momentum, region: region(r)? }, d)
            }
            MethodSpec::NormalModes { energies, rotation } => (
                Spec::NormalModes { energies: energies.clone(), rotation: rotation.clone() },
                format!("normal modes, energies {energies:?}, rotation {rotation:?}"),
            ),
            MethodSpec::File { path, span } => {
                let states = read_states(m, path, scene).map_err(|e| match e {
                    Ok(located) => located,
                    Err(message) => src.error(
                        span.clone(),
                        message,
                        "give a readable CSV or extended XYZ file of states (see docs/src/reference/ensemble.md)",
                    ),
                })?;
                if (states.len() as u64) < self.trajectories {
                    return Err(src.error(
                        self.trajectories_span.clone(),
                        format!(
                            "{} has {} states but trajectories = {}",
                            path.display(),
                            states.len(),
                            self.trajectories
                        ),
                        format!("lower trajectories to at most {}, or add states to the file", states.len()),
                    ));
                }
                (Spec::States(states), format!("{} states from {}", self.trajectories, path.display()))
            }
            MethodSpec::Collision(_) => {
                return Err(src.error(
                    self.method_span.clone(),
                    "a collision ensemble runs through `rovib ensemble` (its own runner), not with another sampler",
                    "run the scene with `rovib ensemble`",
                ));
            }
        };

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

fn unknown_name<'a>(
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
