//! `[ensemble] method`: a variant table. Each method is a [`Variant`]: its name, the keys it
//! takes and the function that reads and checks them into its [`MethodSpec`]. Every value is read
//! with its place, inside nested tables too (`region.limits`), because the table is read by serde
//! into typed, spanned fields from the scene's one parse. A key of another method is refused at
//! the key's place, a missing required key at the method's place, an unknown method at its place
//! with a did-you-mean.

use std::ops::Range;
use std::path::Path;

use toml::Spanned;

use super::{MethodSpec, RegionSpec, did_you_mean, quoted};
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::nalgebra::Vector3;
use crate::runtime::sample::{ModeEnergies, RotationSampling};
use crate::scene::Scene;
use crate::scene::raw::{RawEnsemble, RawRegion};

/// What a method's reader is given: the scene, its `[ensemble]` table, and the factor from the
/// table's energy unit to hartree.
pub(super) struct Context<'a> {
    pub(super) scene: &'a Scene,
    pub(super) src: &'a Source<'a>,
    pub(super) e: &'a RawEnsemble,
    pub(super) eh: f64,
}

/// One sampling method as spelt in scenes.
pub(super) struct Variant {
    /// Its `method = "..."`.
    pub(super) name: &'static str,
    /// The method-specific keys it takes (of [`METHOD_KEYS`]).
    keys: &'static [&'static str],
    /// Reads its keys.
    read: fn(&Context<'_>) -> Result<MethodSpec, FileError>,
}

/// The methods, in the order in which messages list them.
pub(super) const VARIANTS: &[Variant] = &[
    Variant { name: "thermal", keys: &["temperature", "energy_unit", "region"], read: thermal },
    Variant {
        name: "microcanonical",
        keys: &["energy", "energy_unit", "angular_momentum", "region"],
        read: microcanonical,
    },
    Variant {
        name: "normal-modes",
        keys: &["energy", "energy_unit", "quanta", "mode_energies", "temperature", "j"],
        read: normal_modes,
    },
    Variant { name: "file", keys: &["file"], read: file },
    Variant { name: "collision", keys: &[], read: collision },
];

/// The keys of `[ensemble]` that belong to some methods and not others.
const METHOD_KEYS: [&str; 9] =
    ["temperature", "energy", "energy_unit", "angular_momentum", "region", "quanta", "mode_energies", "j", "file"];

/// Reads the method of `[ensemble]`.
pub(super) fn read(cx: &Context<'_>) -> Result<MethodSpec, FileError> {
    let (src, e) = (cx.src, cx.e);
    let name = e.method.get_ref().as_str();
    let Some(variant) = VARIANTS.iter().find(|v| v.name == name) else {
        let methods = super::METHODS;
        let help = match did_you_mean(name, methods) {
            Some(m) => format!("did you mean \"{m}\"? the methods are {}", quoted(&methods)),
            None => format!("the methods are {}", quoted(&methods)),
        };
        return Err(src.error(e.method.span(), format!("unknown ensemble method `{name}`"), help));
    };
    for (key, at) in METHOD_KEYS.iter().zip(written(e)) {
        if let Some(at) = at
            && !variant.keys.contains(key)
        {
            return Err(src.error(
                at,
                format!("`{key}` does not apply to the {name} method"),
                format!("the {name} method takes {}; remove `{key}` or choose another method", variant.keys.join(", ")),
            ));
        }
    }
    (variant.read)(cx)
}

/// Where each of [`METHOD_KEYS`] is written, if it is.
fn written(e: &RawEnsemble) -> [Option<Range<usize>>; 9] {
    fn at<T>(x: &Option<Spanned<T>>) -> Option<Range<usize>> {
        x.as_ref().map(Spanned::span)
    }
    [
        at(&e.temperature),
        at(&e.energy),
        at(&e.energy_unit),
        at(&e.angular_momentum),
        at(&e.region),
        at(&e.quanta),
        at(&e.mode_energies),
        at(&e.j),
        at(&e.file),
    ]
}

impl Context<'_> {
    /// A required key missing, at the method's place.
    fn needs(&self, what: &str, unit: &str) -> FileError {
        let name = self.e.method.get_ref();
        self.src.error(
            self.e.method.span(),
            format!("the {name} method needs `{what}`"),
            format!("add {what} = ... ({unit}) to [ensemble]"),
        )
    }

    fn temperature(&self, t: &Spanned<f64>) -> Result<f64, FileError> {
        let v = *t.get_ref();
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.src.error(
                t.span(),
                format!("`ensemble.temperature` must be a positive finite number of kelvin, got {v}"),
                "write a temperature above 0 K, e.g. temperature = 300",
            ))
        }
    }

    fn region(&self, r: &Option<Spanned<RawRegion>>) -> Result<RegionSpec, FileError> {
        let Some(r) = r else { return Ok(RegionSpec::default()) };
        let r = r.get_ref();
        let energy_cap = match &r.energy_cap {
            Some(c) if !(c.get_ref().is_finite() && *c.get_ref() > 0.0) => {
                return Err(self.src.error(
                    c.span(),
                    format!("`region.energy_cap` must be a positive finite energy, got {}", c.get_ref()),
                    "give the largest U(q) − U(reference) to sample, in ensemble.energy_unit",
                ));
            }
            Some(c) => Some((c.get_ref() * self.eh, c.span())),
            None => None,
        };
        let mut limits = Vec::new();
        for (name, v) in &r.limits {
            let x = v.get_ref();
            if x.len() != 2 || !x.iter().all(|x| x.is_finite()) || x[0] >= x[1] {
                return Err(self.src.error(
                    v.span(),
                    format!(
                        "the limits of `{}` must be two finite numbers [low, high] with low < high",
                        name.get_ref()
                    ),
                    format!("write {} = [low, high] in the scene's length or angle unit", name.get_ref()),
                ));
            }
            limits.push((name.clone(), [x[0], x[1]]));
        }
        Ok(RegionSpec { energy_cap, limits })
    }

    fn finite_energy(&self, x: &Spanned<f64>, what: &str) -> Result<f64, FileError> {
        if x.get_ref().is_finite() {
            Ok(x.get_ref() * self.eh)
        } else {
            Err(self.src.error(x.span(), format!("`ensemble.{what}` is not a finite number"), "write a finite energy"))
        }
    }
}

fn thermal(cx: &Context<'_>) -> Result<MethodSpec, FileError> {
    let t = cx.e.temperature.as_ref().ok_or_else(|| cx.needs("temperature", "kelvin"))?;
    Ok(MethodSpec::Thermal { temperature: cx.temperature(t)?, region: cx.region(&cx.e.region)? })
}

fn microcanonical(cx: &Context<'_>) -> Result<MethodSpec, FileError> {
    let e = cx.e;
    let energy = e.energy.as_ref().ok_or_else(|| cx.needs("energy", "in ensemble.energy_unit, default hartree"))?;
    let angular_momentum = match &e.angular_momentum {
        Some(j) if !(j.get_ref().is_finite() && *j.get_ref() >= 0.0) => {
            return Err(cx.src.error(
                j.span(),
                format!("`ensemble.angular_momentum` must be a non-negative |J| in hbar, got {}", j.get_ref()),
                "write |J| in units of hbar, or remove it to sample J too",
            ));
        }
        Some(j) => Some(*j.get_ref()),
        None => None,
    };
    Ok(MethodSpec::Microcanonical {
        energy: (cx.finite_energy(energy, "energy")?, energy.span()),
        angular_momentum,
        region: cx.region(&e.region)?,
    })
}

fn normal_modes(cx: &Context<'_>) -> Result<MethodSpec, FileError> {
    let (src, e) = (cx.src, cx.e);
    let energies = match (&e.quanta, &e.mode_energies, &e.energy) {
        (Some(q), None, None) => {
            if let Some(bad) = q.get_ref().iter().find(|v| **v < 0 || **v > i64::from(u32::MAX)) {
                return Err(src.error(
                    q.span(),
                    format!("quantum number {bad} is not a non-negative integer"),
                    "write one vibrational quantum number v ≥ 0 per mode",
                ));
            }
            ModeEnergies::Quantum(q.get_ref().iter().map(|&v| v as u32).collect())
        }
        (None, Some(m), None) => {
            if m.get_ref().iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err(src.error(
                    m.span(),
                    "mode energies must be non-negative finite numbers",
                    "write one energy per mode in ensemble.energy_unit",
                ));
            }
            ModeEnergies::Fixed(m.get_ref().iter().map(|v| v * cx.eh).collect())
        }
        (None, None, Some(total)) => ModeEnergies::Random { total: cx.finite_energy(total, "energy")? },
        (None, None, None) => {
            return Err(src.error(
                e.method.span(),
                "the normal-modes method needs the mode energies",
                "add quanta = [v1, v2, ...] (quasiclassical), mode_energies = [...] or energy = ... (random over the modes)",
            ));
        }
        _ => {
            return Err(src.error(
                e.method.span(),
                "more than one of quanta, mode_energies and energy is given",
                "give exactly one of quanta, mode_energies and energy",
            ));
        }
    };
    let rotation = match (&e.temperature, &e.j) {
        (Some(t), None) => RotationSampling::Thermal { temperature: cx.temperature(t)? },
        (None, Some(j)) => {
            let v = j.get_ref();
            if v.len() != 3 || !v.iter().all(|x| x.is_finite()) {
                return Err(src.error(
                    j.span(),
                    "`ensemble.j` must be three finite numbers",
                    "write j = [Jx, Jy, Jz] in hbar",
                ));
            }
            RotationSampling::Fixed(Vector3::new(v[0], v[1], v[2]))
        }
        (None, None) => RotationSampling::Fixed(Vector3::zeros()),
        (Some(_), Some(j)) => {
            return Err(src.error(
                j.span(),
                "both a rotational temperature and a fixed j are given",
                "give temperature (thermal rotation) or j (fixed body-frame J), not both",
            ));
        }
    };
    Ok(MethodSpec::NormalModes { energies, rotation })
}

fn file(cx: &Context<'_>) -> Result<MethodSpec, FileError> {
    let file = cx.e.file.as_ref().ok_or_else(|| cx.needs("file", "a path relative to the scene"))?;
    let base = Path::new(&cx.scene.path).parent().unwrap_or(Path::new(""));
    Ok(MethodSpec::File { path: base.join(file.get_ref()), span: file.span() })
}

fn collision(cx: &Context<'_>) -> Result<MethodSpec, FileError> {
    if let Some(k) = &cx.e.keep_trajectories {
        return Err(cx.src.error(
            k.span(),
            "`keep_trajectories` does not apply to a collision ensemble (it writes final_states.csv)",
            "remove keep_trajectories; run one collision with `rovib run` and [initial] positions to see its path",
        ));
    }
    let c = super::super::collision_scene::parse_collision(cx.scene, cx.e.method.span())?;
    Ok(MethodSpec::Collision(Box::new(c)))
}
