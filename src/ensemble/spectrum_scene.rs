//! The `[spectrum]` table of an ensemble scene: which estimator of the dipole correlation the
//! spectrum is computed from, the wavenumber range written, and the pair volume that puts a pair
//! ensemble's spectral function into the binary absorption coefficient's units. Every key is
//! checked with its place; a `[spectrum]` table whose ensemble does not correlate the lab-frame
//! dipole is refused ([`SpectrumScene::check`]).

use std::ops::Range;

use super::quantity::Quantity;
use crate::runtime::diagnostic::{FileError, Source};
use crate::scene::Scene;

/// The highest wavenumber written by default, cm⁻¹ (also limited by the output interval's
/// Nyquist limit).
pub const DEFAULT_MAX_WAVENUMBER: f64 = 5000.0;

/// The estimators, as spelt in scenes.
pub const ESTIMATORS: [&str; 2] = ["stationary", "pair"];

/// How the dipole correlation of the ensemble is estimated.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub enum Estimator {
    /// Each trajectory's Hann-tapered fluctuation about its time mean, over all time origins: for
    /// a stationary ensemble (bound molecules).
    #[default]
    Stationary,
    /// `⟨μ(0)·μ(τ)⟩` from the sampled phase point only, no mean subtracted, each trajectory
    /// integrated forward and backward in time (τ from −T to T): for pairs, whose trajectories
    /// leave the sampled region (`super::pair`).
    Pair,
}

impl Estimator {
    /// The name in scenes and summary.json.
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Stationary => "stationary",
            Estimator::Pair => "pair",
        }
    }
}

/// The spectrum settings, in atomic units except the wavenumber.
#[derive(Clone, Debug, PartialEq)]
pub struct SpectrumSettings {
    /// The estimator.
    pub estimator: Estimator,
    /// The highest wavenumber written, cm⁻¹.
    pub max_wavenumber: f64,
    /// The pair volume V = Z_pair / (Z_A Z_B), bohr³: with it, spectrum.csv has the binary
    /// absorption coefficient α/ρ² (pair estimator only).
    pub pair_volume: Option<f64>,
}

impl Default for SpectrumSettings {
    fn default() -> Self {
        Self { estimator: Estimator::Stationary, max_wavenumber: DEFAULT_MAX_WAVENUMBER, pair_volume: None }
    }
}

impl SpectrumSettings {
    /// Whether the pair estimator is chosen.
    pub fn pair(&self) -> bool {
        self.estimator == Estimator::Pair
    }
}

/// The parsed table and where it is written (None: no `[spectrum]` table, the defaults).
#[derive(Clone, Debug, Default)]
pub struct SpectrumScene {
    /// The settings.
    pub settings: SpectrumSettings,
    /// Where `[spectrum]` is written.
    pub span: Option<Range<usize>>,
}

/// Parses `[spectrum]` of the scene.
pub fn parse_spectrum(scene: &Scene) -> Result<SpectrumScene, FileError> {
    let src = &scene.source();
    let raw = scene.tables.spectrum.clone().map_err(|e| {
        let help = "[spectrum] takes estimator (\"stationary\" or \"pair\"), max_wavenumber (cm-1) and pair_volume \
                    (bohr^3); see the README's \"Ensembles\"";
        crate::scene::toml_error(src, &e, help)
    })?;
    let Some(table) = raw.spectrum else { return Ok(SpectrumScene::default()) };
    let span = table.span();
    let t = table.into_inner();
    let mut settings = SpectrumSettings::default();
    if let Some(e) = &t.estimator {
        settings.estimator = match e.get_ref().as_str() {
            "stationary" => Estimator::Stationary,
            "pair" => Estimator::Pair,
            other => {
                return Err(src.error(
                    e.span(),
                    format!("unknown spectrum estimator `{other}`"),
                    "use \"stationary\" (bound molecules: tapered fluctuation over all time origins) or \"pair\" \
                     (pairs that leave the region: <mu(0).mu(t)> from the sampled point, forward and backward)",
                ));
            }
        };
    }
    if let Some(w) = &t.max_wavenumber {
        let v = *w.get_ref();
        if !(v.is_finite() && v > 0.0) {
            return Err(src.error(
                w.span(),
                format!("`spectrum.max_wavenumber` must be a positive finite number of cm-1, got {v}"),
                "write the highest wavenumber to write, e.g. max_wavenumber = 300 for a far-infrared band",
            ));
        }
        settings.max_wavenumber = v;
    }
    if let Some(p) = &t.pair_volume {
        let v = *p.get_ref();
        if !(v.is_finite() && v > 0.0) {
            return Err(src.error(
                p.span(),
                format!("`spectrum.pair_volume` must be a positive finite volume in bohr^3, got {v}"),
                "give V = Z_pair / (Z_A Z_B) in bohr^3 (for an atom-atom pair the summary's configurational_integral)",
            ));
        }
        if !settings.pair() {
            return Err(src.error(
                p.span(),
                "`spectrum.pair_volume` applies to the pair estimator only",
                "add estimator = \"pair\" to [spectrum], or remove pair_volume",
            ));
        }
        settings.pair_volume = Some(v);
    }
    Ok(SpectrumScene { settings, span: Some(span) })
}

impl SpectrumScene {
    /// Refuses a `[spectrum]` table (at its place) when the ensemble's correlations do not
    /// include the three lab-frame dipole components, from which alone the spectrum is computed.
    pub fn check(&self, src: &Source<'_>, quantities: &[Quantity], correlations: &[usize]) -> Result<(), FileError> {
        let Some(span) = &self.span else { return Ok(()) };
        let all = (0..3).all(|axis| correlations.iter().any(|&qi| quantities[qi] == Quantity::LabDipole(axis)));
        if all {
            return Ok(());
        }
        Err(src.error(
            span.clone(),
            "[spectrum] needs the lab-frame dipole's correlations, which [statistics] does not ask for",
            "add correlations = [\"mu_x\", \"mu_y\", \"mu_z\"] to [statistics] (a molecule with a [dipole]), or remove \
             [spectrum]",
        ))
    }
}
