//! The `[collision]` table of a scene whose `[ensemble]` has `method = "collision"`: the two
//! fragments, the impact parameter (plain or stratified), the relative energy (fixed or
//! flux-weighted thermal), each fragment's rotation and vibration, the initial separation, the
//! separation that ends a trajectory after the encounter and the radius of the lifetime. Parsed
//! with places and converted to atomic units; atom labels are bound to the molecule by
//! [`CollisionScene::bind`]. Every key is honoured or refused at its place.
//!
//! This module reads the scalar keys and refuses the tables a collision does not use; the
//! impact parameter is read in `impact`, the fragments in `fragments`, and the labels are bound
//! in `bind`.

mod bind;
mod fragments;
mod impact;

use std::ops::Range;

use toml::Spanned;

use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::sample::collision::{FragmentRotation, FragmentVibration, RelativeEnergy, Stratum};
use crate::runtime::units::EnergyUnit;
use crate::scene::Scene;
use crate::scene::raw::{CollisionFile, RawCollision};

const HELP: &str = "docs/src/howto/collisions.md and docs/src/reference/ensemble.md list the keys of [collision]";

/// A parsed `[collision]`, lengths in bohr, energies in hartree, labels not yet bound.
#[derive(Clone, Debug)]
pub struct CollisionScene {
    /// Atom labels of the two fragments, with their places.
    pub fragments: [Vec<Spanned<String>>; 2],
    /// Impact-parameter strata, bohr.
    pub strata: Vec<Stratum>,
    /// Whether the strata were given (`strata`) rather than `b_max`.
    pub stratified: bool,
    /// The relative energy.
    pub energy: RelativeEnergy,
    /// Rotation of each fragment.
    pub rotation: [FragmentRotation; 2],
    /// Vibration of each fragment.
    pub vibration: [FragmentVibration; 2],
    /// Initial separation, bohr.
    pub r0: f64,
    /// The separation past which a trajectory ends after its encounter, bohr.
    pub r_stop: f64,
    /// Lifetime: time with R below this, bohr.
    pub lifetime_radius: f64,
    /// Bins of the histograms in histograms of final states.
    pub bins: usize,
    /// Where `[collision]` is written.
    pub span: Range<usize>,
}

/// The most histogram bins of final states.
pub const MAX_BINS: i64 = 100_000;

/// The unit of the lengths of `[collision]`, as the errors name it.
const LENGTH_UNIT: &str = "the scene's units.length (bohr if not given)";

/// Parses `[collision]` (required by `method = "collision"`, whose place is `method`) and refuses
/// the tables and keys a collision ensemble does not use.
pub fn parse_collision(scene: &Scene, method: Range<usize>) -> Result<CollisionScene, FileError> {
    let src = scene.source();
    let raw = scene.tables.collision.clone().map_err(|e| crate::scene::toml_error(&src, &e, HELP))?;
    refuse_other_tables(&src, &raw)?;
    let Some(c) = raw.collision else {
        return Err(src.error(
            method,
            "the collision method needs a [collision] table",
            "add [collision] with the fragments, b_max (or strata), energy (or temperature), r0 and r_stop \
             (docs/src/howto/collisions.md)",
        ));
    };
    let span = c.span();
    let c = c.into_inner();
    let eh = energy_unit_in_hartree(&src, c.energy_unit.as_ref())?;
    let length = scene.units.length.unwrap_or(1.0);
    let r0 = positive(&src, &c.r0, "r0", LENGTH_UNIT)? * length;
    let r_stop = positive(&src, &c.r_stop, "r_stop", LENGTH_UNIT)? * length;
    let lifetime_radius = match &c.lifetime_radius {
        Some(x) => positive(&src, x, "lifetime_radius", LENGTH_UNIT)? * length,
        None => r0,
    };
    let bins = histogram_bins(&src, c.bins.as_ref())?;
    let (strata, stratified) = impact::strata(&src, &c, length, &span)?;
    impact::check_r0_beyond_strata(&src, &c, &strata, r0, length)?;
    let energy = relative_energy(&src, &c, eh, &span)?;
    let (fragments, rotation, vibration) = fragments::parse(&src, &c, span.clone())?;
    Ok(CollisionScene {
        fragments,
        strata,
        stratified,
        energy,
        rotation,
        vibration,
        r0,
        r_stop,
        lifetime_radius,
        bins,
        span,
    })
}

/// Refuses `[statistics]`, `[spectrum]`, `[pairs]` and `run.stop_outside`, which a collision
/// ensemble does not use.
fn refuse_other_tables(src: &Source<'_>, raw: &CollisionFile) -> Result<(), FileError> {
    if let Some(s) = &raw.statistics {
        return Err(src.error(
            s.span(),
            "a collision ensemble does not use [statistics]: it writes final states, histograms and cross sections",
            "remove [statistics] (see docs/src/howto/collisions.md for what a collision ensemble writes)",
        ));
    }
    if let Some(s) = &raw.spectrum {
        return Err(src.error(
            s.span(),
            "a collision ensemble does not compute spectra",
            "remove [spectrum], or use a thermal pair ensemble for a spectrum",
        ));
    }
    if let Some(s) = &raw.pairs {
        return Err(src.error(
            s.span(),
            "a collision ensemble does not classify pair states: [pairs] is for thermal pair ensembles",
            "remove [pairs]; a collision ensemble writes each trajectory's outcome in final_states.csv",
        ));
    }
    if let Some(s) = raw.run.as_ref().and_then(|r| r.stop_outside.as_ref()) {
        return Err(src.error(
            s.span(),
            "`run.stop_outside` does not apply to a collision ensemble: a trajectory ends when the fragments' \
             separation passes collision.r_stop after the encounter",
            "remove run.stop_outside and set collision.r_stop",
        ));
    }
    Ok(())
}

/// Hartree per unit of `collision.energy_unit` (1 if not given).
fn energy_unit_in_hartree(src: &Source<'_>, unit: Option<&Spanned<String>>) -> Result<f64, FileError> {
    let Some(u) = unit else { return Ok(1.0) };
    let unit = EnergyUnit::parse(u.get_ref()).ok_or_else(|| {
        let names: Vec<String> = EnergyUnit::SPELLINGS.iter().map(|s| format!("\"{}\"", s.0)).collect();
        src.error(
            u.span(),
            format!("unknown energy unit `{}`", u.get_ref()),
            format!("use one of {}", names.join(", ")),
        )
    })?;
    Ok(unit.in_hartree())
}

/// The value of `collision.{what}`, which must be positive and finite (written in `unit`).
fn positive(src: &Source<'_>, x: &Spanned<f64>, what: &str, unit: &str) -> Result<f64, FileError> {
    let v = *x.get_ref();
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(src.error(
            x.span(),
            format!("`collision.{what}` must be a positive finite number, got {v}"),
            format!("write {what} in {unit}"),
        ))
    }
}

/// `collision.bins`: from 1 to [`MAX_BINS`], 40 if not given.
fn histogram_bins(src: &Source<'_>, bins: Option<&Spanned<i64>>) -> Result<usize, FileError> {
    match bins {
        None => Ok(40),
        Some(b) if (1..=MAX_BINS).contains(b.get_ref()) => Ok(*b.get_ref() as usize),
        Some(b) => Err(src.error(
            b.span(),
            format!("`collision.bins` must be from 1 to {MAX_BINS}, got {}", b.get_ref()),
            "write the number of bins of the final-state histograms, e.g. bins = 40",
        )),
    }
}

/// The relative energy: `energy` (fixed, `eh` hartree per its unit) or `temperature`
/// (flux-weighted thermal), exactly one; `energy_unit` only with `energy`.
fn relative_energy(
    src: &Source<'_>,
    c: &RawCollision,
    eh: f64,
    span: &Range<usize>,
) -> Result<RelativeEnergy, FileError> {
    let energy = match (&c.energy, &c.temperature) {
        (Some(e), None) => {
            RelativeEnergy::Fixed(positive(src, e, "energy", "collision.energy_unit (hartree if not given)")? * eh)
        }
        (None, Some(t)) => RelativeEnergy::Thermal(positive(src, t, "temperature", "kelvin")?),
        (Some(e), Some(_)) => {
            return Err(src.error(
                e.span(),
                "both collision.energy and collision.temperature are given",
                "give energy (fixed relative energy) or temperature (flux-weighted Maxwell–Boltzmann), not both",
            ));
        }
        (None, None) => {
            return Err(src.error(
                span.clone(),
                "[collision] needs energy or temperature",
                "add energy = ... (fixed, in energy_unit) or temperature = ... (kelvin, P(E) ∝ E exp(−E/kT))",
            ));
        }
    };
    if let (Some(u), RelativeEnergy::Thermal(_)) = (&c.energy_unit, &energy) {
        return Err(src.error(
            u.span(),
            "`collision.energy_unit` applies to collision.energy only, which is not given",
            "remove energy_unit, or give the relative energy as energy = ...",
        ));
    }
    Ok(energy)
}
