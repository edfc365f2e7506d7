//! The `[collision]` table of a scene whose `[ensemble]` has `method = "collision"`: the two
//! fragments, the impact parameter (plain or stratified), the relative energy (fixed or
//! flux-weighted thermal), each fragment's rotation and vibration, the initial separation, the
//! separation that ends a trajectory after the encounter and the radius of the lifetime. Parsed
//! with places and converted to atomic units; atom labels are bound to the molecule by
//! [`CollisionScene::bind`]. Every key is honoured or refused at its place.

use std::ops::Range;

use toml::Spanned;

use crate::runtime::Molecule;
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::sample::collision::{CollisionSpec, FragmentRotation, FragmentVibration, RelativeEnergy, Stratum};
use crate::runtime::units::EnergyUnit;
use crate::scene::Scene;

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

/// Parses `[collision]` (required by `method = "collision"`, whose place is `method`) and refuses
/// the tables and keys a collision ensemble does not use.
pub fn parse_collision(scene: &Scene, method: Range<usize>) -> Result<CollisionScene, FileError> {
    let src = scene.source();
    let raw = scene.tables.collision.clone().map_err(|e| crate::scene::toml_error(&src, &e, HELP))?;
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
    let eh = match &c.energy_unit {
        None => 1.0,
        Some(u) => EnergyUnit::parse(u.get_ref())
            .ok_or_else(|| {
                let names: Vec<String> = EnergyUnit::SPELLINGS.iter().map(|s| format!("\"{}\"", s.0)).collect();
                src.error(
                    u.span(),
                    format!("unknown energy unit `{}`", u.get_ref()),
                    format!("use one of {}", names.join(", ")),
                )
            })?
            .in_hartree(),
    };
    let length = scene.units.length.unwrap_or(1.0);
    let positive = |x: &Spanned<f64>, what: &str, unit: &str| -> Result<f64, FileError> {
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
    };
    let length_unit = "the scene's units.length (bohr if not given)";
    let r0 = positive(&c.r0, "r0", length_unit)? * length;
    let r_stop = positive(&c.r_stop, "r_stop", length_unit)? * length;
    let lifetime_radius = match &c.lifetime_radius {
        Some(x) => positive(x, "lifetime_radius", length_unit)? * length,
        None => r0,
    };
    let bins = match &c.bins {
        None => 40,
        Some(b) if (1..=MAX_BINS).contains(b.get_ref()) => *b.get_ref() as usize,
        Some(b) => {
            return Err(src.error(
                b.span(),
                format!("`collision.bins` must be from 1 to {MAX_BINS}, got {}", b.get_ref()),
                "write the number of bins of the final-state histograms, e.g. bins = 40",
            ));
        }
    };

    let (strata, stratified) = match (&c.b_max, &c.strata) {
        (Some(b), None) => {
            let b_max = positive(b, "b_max", length_unit)? * length;
            (vec![Stratum { low: 0.0, high: b_max, weight: 1.0 }], false)
        }
        (None, Some(list)) => {
            if list.get_ref().is_empty() {
                return Err(src.error(list.span(), "`collision.strata` is empty", "give at least one stratum"));
            }
            let mut strata = Vec::new();
            let mut last = 0.0;
            for s in list.get_ref() {
                let s = s.get_ref();
                let b = s.b.get_ref();
                if b.len() != 2 || !b.iter().all(|x| x.is_finite()) || b[0] < 0.0 || b[0] >= b[1] || b[0] != last {
                    return Err(src.error(
                        s.b.span(),
                        format!("a stratum's b must be [low, high] with 0 ≤ low < high, starting where the previous ends ({last})"),
                        "write contiguous strata from 0, e.g. strata = [{ b = [0, 4], weight = 1 }, { b = [4, 10], weight = 2 }]",
                    ));
                }
                last = b[1];
                let w = *s.weight.get_ref();
                if !(w.is_finite() && w > 0.0) {
                    return Err(src.error(
                        s.weight.span(),
                        format!("a stratum's weight must be positive, got {w}"),
                        "write the stratum's relative share of the trajectories",
                    ));
                }
                strata.push(Stratum { low: b[0] * length, high: b[1] * length, weight: w });
            }
            (strata, true)
        }
        (Some(b), Some(_)) => {
            return Err(src.error(
                b.span(),
                "both collision.b_max and collision.strata are given",
                "give b_max (b² uniform on [0, b_max²]) or strata, not both",
            ));
        }
        (None, None) => {
            return Err(src.error(
                span.clone(),
                "[collision] needs b_max or strata",
                "add b_max = ... (scene length unit), or strata = [{ b = [low, high], weight = w }, ...]",
            ));
        }
    };
    if let Some(last) = strata.last()
        && last.high >= r0
    {
        return Err(src.error(
            c.r0.span(),
            format!("r0 must be above the largest impact parameter, {} (scene units)", last.high / length),
            "raise r0 (the initial separation) above b_max",
        ));
    }
    let energy = match (&c.energy, &c.temperature) {
        (Some(e), None) => {
            RelativeEnergy::Fixed(positive(e, "energy", "collision.energy_unit (hartree if not given)")? * eh)
        }
        (None, Some(t)) => RelativeEnergy::Thermal(positive(t, "temperature", "kelvin")?),
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

    let Some(fragments) = &c.fragment else {
        return Err(src.error(
            span,
            "[collision] needs its two fragments",
            "add two [[collision.fragment]] tables, each with atoms = [\"label\", ...]",
        ));
    };
    if fragments.get_ref().len() != 2 {
        return Err(src.error(
            fragments.span(),
            format!("a collision has two fragments, {} are given", fragments.get_ref().len()),
            "give exactly two [[collision.fragment]] tables",
        ));
    }
    let mut labels: [Vec<Spanned<String>>; 2] = [Vec::new(), Vec::new()];
    let mut rotation = [FragmentRotation::None, FragmentRotation::None];
    let mut vibration = [FragmentVibration::None, FragmentVibration::None];
    for (k, f) in fragments.get_ref().iter().enumerate() {
        let f = f.get_ref();
        labels[k] = f.atoms.get_ref().clone();
        if labels[k].is_empty() {
            return Err(src.error(f.atoms.span(), "a fragment has no atoms", "list the fragment's atom labels"));
        }
        rotation[k] = match (&f.rotation_temperature, &f.j) {
            (Some(t), None) => FragmentRotation::Thermal(positive(t, "fragment.rotation_temperature", "kelvin")?),
            (None, Some(j)) if (0..=i64::from(u32::MAX)).contains(j.get_ref()) => {
                FragmentRotation::Quantum(*j.get_ref() as u32)
            }
            (None, Some(j)) => {
                return Err(src.error(
                    j.span(),
                    format!("j = {} is not a rotational quantum number", j.get_ref()),
                    "write J ≥ 0",
                ));
            }
            (Some(t), Some(_)) => {
                return Err(src.error(
                    t.span(),
                    "both rotation_temperature and j are given",
                    "give rotation_temperature (thermal) or j (quasi-classical), not both",
                ));
            }
            (None, None) => FragmentRotation::None,
        };
        vibration[k] = match (&f.vibration_temperature, &f.v) {
            (Some(t), None) => FragmentVibration::Thermal(positive(t, "fragment.vibration_temperature", "kelvin")?),
            (None, Some(v)) if (0..=i64::from(u32::MAX)).contains(v.get_ref()) => {
                FragmentVibration::Quantum(*v.get_ref() as u32)
            }
            (None, Some(v)) => {
                return Err(src.error(
                    v.span(),
                    format!("v = {} is not a vibrational quantum number", v.get_ref()),
                    "write v ≥ 0",
                ));
            }
            (Some(t), Some(_)) => {
                return Err(src.error(
                    t.span(),
                    "both vibration_temperature and v are given",
                    "give vibration_temperature (thermal) or v (quasi-classical), not both",
                ));
            }
            (None, None) => FragmentVibration::None,
        };
    }
    Ok(CollisionScene {
        fragments: labels,
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

impl CollisionScene {
    /// The sampler's spec for molecule `m`: atom labels bound to indices (an unknown or repeated
    /// label, or an atom in no fragment, is an error at its place).
    pub fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        src: &Source<'_>,
        trajectories: u64,
    ) -> Result<CollisionSpec, FileError> {
        let atoms = m.atoms();
        let names: Vec<&str> = atoms.iter().map(|a| a.label).collect();
        let mut used = vec![false; NA];
        let mut fragments: [Vec<usize>; 2] = [Vec::new(), Vec::new()];
        for k in 0..2 {
            for l in &self.fragments[k] {
                let i = names.iter().position(|n| *n == l.get_ref()).ok_or_else(|| {
                    src.error(
                        l.span(),
                        format!("{} has no atom `{}`", m.name(), l.get_ref()),
                        format!("the atoms are {}", names.join(", ")),
                    )
                })?;
                if used[i] {
                    return Err(src.error(
                        l.span(),
                        format!("atom `{}` is listed twice", l.get_ref()),
                        "list each atom in one fragment once",
                    ));
                }
                used[i] = true;
                fragments[k].push(i);
            }
        }
        if let Some(i) = used.iter().position(|u| !u) {
            return Err(src.error(
                self.span.clone(),
                format!("atom `{}` is in neither fragment", names[i]),
                "every atom of the molecule belongs to one of the two fragments",
            ));
        }
        Ok(CollisionSpec {
            fragments,
            strata: self.strata.clone(),
            energy: self.energy.clone(),
            rotation: self.rotation.clone(),
            vibration: self.vibration.clone(),
            r0: self.r0,
            trajectories,
        })
    }
}
