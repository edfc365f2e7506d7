//! The scene file parsed once: its text into TOML's spanned tables ([`DeTable`], a place at
//! every depth), and those into the raw structs below, one per reader of the scene (the single
//! run's [`RawScene`]; the ensemble's, the collision's, the spectrum's and the pairs' tables).
//! Each reader validates its struct with its own messages; a serde error of an ensemble-side
//! table is kept until its reader asks for it, so that it is reported with that reader's help
//! and in the order in which the tables are read.

use std::collections::BTreeMap;

use serde::Deserialize;
use serde::de::DeserializeOwned;
use toml::Spanned;
use toml::de::{DeTable, Deserializer};

use super::variant::RawVariantTable;

/// A table of values by name, every key and value with its place.
pub(crate) type RawTable<T> = Spanned<BTreeMap<Spanned<String>, Spanned<T>>>;

/// A table read from the one parse, or serde's error about it.
pub(crate) type Read<T> = Result<T, toml::de::Error>;

/// The tables of a scene as the readers after the single run's take them.
#[derive(Clone, Debug)]
pub(crate) struct Tables {
    /// `[ensemble]`, `[statistics]` and the single-run keys an ensemble refuses.
    pub(crate) ensemble: Read<EnsembleFile>,
    /// `[collision]` and the tables and keys a collision ensemble refuses.
    pub(crate) collision: Read<CollisionFile>,
    /// `[spectrum]`.
    pub(crate) spectrum: Read<SpectrumFile>,
    /// `[pairs]`.
    pub(crate) pairs: Read<PairsFile>,
    /// `run.outputs` as written, each name with its place (for a run in memory, which refuses
    /// `"restart"` at its place).
    pub(crate) outputs: Vec<Spanned<String>>,
}

/// Parses `text` once and reads every reader's tables from it.
///
/// # Errors
///
/// A TOML syntax error, or serde's error about the single run's tables.
pub(crate) fn parse(text: &str) -> Result<(RawScene, Tables), toml::de::Error> {
    let doc = DeTable::parse(text)?;
    let scene: RawScene = read(&doc)?;
    let outputs = scene.run.get_ref().outputs.as_ref().map(|o| o.get_ref().clone()).unwrap_or_default();
    let tables =
        Tables { ensemble: read(&doc), collision: read(&doc), spectrum: read(&doc), pairs: read(&doc), outputs };
    Ok((scene, tables))
}

/// One reader's struct from the parsed document (a copy of the tree, not a second parse).
fn read<T: DeserializeOwned>(doc: &Spanned<DeTable<'_>>) -> Read<T> {
    T::deserialize(Deserializer::from(doc.clone()))
}

// ---------------------------------------------------------------------------------------------
// scene

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawScene {
    pub(crate) molecule: Spanned<String>,
    #[serde(default)]
    pub(crate) description: Option<String>,
    #[serde(default)]
    pub(crate) units: RawUnits,
    pub(crate) initial: Option<Spanned<RawInitial>>,
    // Parsed with their places by `crate::ensemble::scene`.
    pub(crate) ensemble: Option<toml::Value>,
    pub(crate) statistics: Option<toml::Value>,
    pub(crate) spectrum: Option<toml::Value>,
    pub(crate) collision: Option<toml::Value>,
    pub(crate) pairs: Option<toml::Value>,
    #[serde(default)]
    pub(crate) integrator: Option<RawVariantTable>,
    pub(crate) run: Spanned<RawRun>,
    pub(crate) potential: Option<RawScenePotential>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawScenePotential {
    pub(crate) parameters: Option<RawTable<f64>>,
    pub(crate) library: Option<Spanned<String>>,
    pub(crate) grid: Option<Spanned<String>>,
    pub(crate) outside: Option<Spanned<String>>,
    pub(crate) gradient: Option<Spanned<String>>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawUnits {
    pub(crate) length: Option<Spanned<String>>,
    pub(crate) angle: Option<Spanned<String>>,
    pub(crate) time: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawInitial {
    pub(crate) q: Option<RawTable<f64>>,
    pub(crate) p: Option<RawTable<f64>>,
    pub(crate) qdot: Option<RawTable<f64>>,
    pub(crate) euler: Option<Spanned<Vec<f64>>>,
    pub(crate) pe: Option<Spanned<Vec<f64>>>,
    pub(crate) j: Option<Spanned<Vec<f64>>>,
    pub(crate) positions: Option<RawTable<Vec<f64>>>,
    pub(crate) velocities: Option<RawTable<Vec<f64>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRun {
    pub(crate) end: Spanned<f64>,
    pub(crate) output_interval: Option<Spanned<f64>>,
    pub(crate) outputs: Option<Spanned<Vec<Spanned<String>>>>,
    #[serde(default)]
    pub(crate) frozen: Vec<Spanned<String>>,
    pub(crate) min_metric_pivot: Option<Spanned<f64>>,
    pub(crate) max_energy_error: Option<Spanned<f64>>,
    pub(crate) max_outputs: Option<Spanned<u64>>,
    #[serde(default)]
    pub(crate) euler_unwrapped: bool,
    pub(crate) cartesian_fallback: Option<bool>,
    pub(crate) chart: Option<Spanned<String>>,
    pub(crate) stop_outside: Option<RawTable<Vec<f64>>>,
}

// ---------------------------------------------------------------------------------------------
// ensemble

#[derive(Clone, Debug, Deserialize)]
pub(crate) struct EnsembleFile {
    /// Kept with every place: its common keys are read into [`RawEnsemble`] and the method's keys
    /// into the method's own struct (`crate::ensemble::method`).
    pub(crate) ensemble: Option<Spanned<super::spanned::Value>>,
    pub(crate) statistics: Option<Spanned<RawStatistics>>,
    pub(crate) initial: Option<Spanned<toml::Value>>,
    pub(crate) run: Option<EnsembleRunKeys>,
}

/// The keys of `[run]` that a single run honours and an ensemble refuses (the others are parsed
/// by `crate::scene`).
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct EnsembleRunKeys {
    pub(crate) outputs: Option<Spanned<toml::Value>>,
    pub(crate) euler_unwrapped: Option<Spanned<toml::Value>>,
}

/// The keys of `[ensemble]` every method takes (each method's own are in its file of
/// `src/ensemble/method/`).
#[derive(Clone, Debug, Deserialize)]
pub struct RawEnsemble {
    /// `trajectories = ...`.
    pub trajectories: Spanned<i64>,
    /// `seed = ...`.
    pub seed: Option<Spanned<i64>>,
    /// `method = "..."`.
    pub method: Spanned<String>,
    /// `threads = ...`.
    pub threads: Option<Spanned<i64>>,
    /// `keep_trajectories = k`.
    pub keep_trajectories: Option<Spanned<i64>>,
    /// `max_memory_gb = ...`.
    pub max_memory_gb: Option<Spanned<f64>>,
    /// `max_disk_gb = ...`.
    pub max_disk_gb: Option<Spanned<f64>>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawStatistics {
    pub(crate) means: Option<Vec<Spanned<String>>>,
    #[serde(default)]
    pub(crate) histograms: Vec<Spanned<RawHistogram>>,
    #[serde(default)]
    pub(crate) correlations: Vec<Spanned<String>>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawHistogram {
    pub(crate) quantity: Spanned<String>,
    pub(crate) bins: Spanned<i64>,
    pub(crate) range: Spanned<Vec<f64>>,
    pub(crate) times: Option<Spanned<Vec<f64>>>,
}

// ---------------------------------------------------------------------------------------------
// collision

#[derive(Clone, Debug, Deserialize)]
pub(crate) struct CollisionFile {
    pub(crate) collision: Option<Spanned<RawCollision>>,
    pub(crate) statistics: Option<Spanned<toml::Value>>,
    pub(crate) spectrum: Option<Spanned<toml::Value>>,
    pub(crate) pairs: Option<Spanned<toml::Value>>,
    pub(crate) run: Option<CollisionRunKeys>,
}

#[derive(Clone, Debug, Deserialize)]
pub(crate) struct CollisionRunKeys {
    pub(crate) stop_outside: Option<Spanned<toml::Value>>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCollision {
    pub(crate) fragment: Option<Spanned<Vec<Spanned<RawFragment>>>>,
    pub(crate) b_max: Option<Spanned<f64>>,
    pub(crate) strata: Option<Spanned<Vec<Spanned<RawStratum>>>>,
    pub(crate) energy: Option<Spanned<f64>>,
    pub(crate) energy_unit: Option<Spanned<String>>,
    pub(crate) temperature: Option<Spanned<f64>>,
    pub(crate) r0: Spanned<f64>,
    pub(crate) r_stop: Spanned<f64>,
    pub(crate) lifetime_radius: Option<Spanned<f64>>,
    pub(crate) bins: Option<Spanned<i64>>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFragment {
    pub(crate) atoms: Spanned<Vec<Spanned<String>>>,
    pub(crate) rotation_temperature: Option<Spanned<f64>>,
    pub(crate) j: Option<Spanned<i64>>,
    pub(crate) vibration_temperature: Option<Spanned<f64>>,
    pub(crate) v: Option<Spanned<i64>>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawStratum {
    pub(crate) b: Spanned<Vec<f64>>,
    pub(crate) weight: Spanned<f64>,
}

// ---------------------------------------------------------------------------------------------
// spectrum

#[derive(Clone, Debug, Deserialize)]
pub(crate) struct SpectrumFile {
    pub(crate) spectrum: Option<Spanned<RawSpectrum>>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSpectrum {
    pub(crate) estimator: Option<Spanned<String>>,
    pub(crate) max_wavenumber: Option<Spanned<f64>>,
    pub(crate) pair_volume: Option<Spanned<f64>>,
}

// ---------------------------------------------------------------------------------------------
// pairs

#[derive(Clone, Debug, Deserialize)]
pub(crate) struct PairsFile {
    pub(crate) pairs: Option<Spanned<RawPairs>>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPairs {
    pub(crate) monomers: Spanned<Vec<Vec<Spanned<String>>>>,
    pub(crate) distance: Spanned<String>,
    pub(crate) far: Option<Spanned<f64>>,
    pub(crate) max_energy: Option<Spanned<f64>>,
    pub(crate) monomer_integral: Option<Spanned<f64>>,
}
