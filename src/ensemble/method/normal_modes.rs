//! `method = "normal-modes"`: harmonic normal modes about the reference geometry, energies per
//! mode random, fixed or quantised, rotation thermal or fixed
//! ([`crate::runtime::sample::NormalModeSampler`]).

use serde::Deserialize;
use toml::Spanned;

use super::{Binding, Context, Method};
use crate::runtime::Molecule;
use crate::runtime::diagnostic::FileError;
use crate::runtime::nalgebra::Vector3;
use crate::runtime::sample::{ModeEnergies, RotationSampling, Spec};

/// The normal-modes method's keys.
#[derive(Deserialize)]
pub struct Keys {
    energy: Option<Spanned<f64>>,
    energy_unit: Option<Spanned<String>>,
    quanta: Option<Spanned<Vec<i64>>>,
    mode_energies: Option<Spanned<Vec<f64>>>,
    temperature: Option<Spanned<f64>>,
    j: Option<Spanned<Vec<f64>>>,
}

/// Normal-mode sampling.
#[derive(Clone, Debug)]
pub struct NormalModes {
    /// Energies per mode.
    pub energies: ModeEnergies,
    /// Rotation.
    pub rotation: RotationSampling,
}

impl Method for NormalModes {
    const NAME: &'static str = "normal-modes";
    type Keys = Keys;
    type Bound<const N: usize> = Spec<N>;

    fn read(keys: Keys, cx: &Context<'_>) -> Result<Self, FileError> {
        let eh = cx.hartree(&keys.energy_unit)?;
        let src = cx.src();
        let energies = match (&keys.quanta, &keys.mode_energies, &keys.energy) {
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
                ModeEnergies::Fixed(m.get_ref().iter().map(|v| v * eh).collect())
            }
            (None, None, Some(total)) => ModeEnergies::Random { total: cx.finite_energy(total, "energy", eh)? },
            (None, None, None) => {
                return Err(src.error(
                    cx.method_span(),
                    "the normal-modes method needs the mode energies",
                    "add quanta = [v1, v2, ...] (quasiclassical), mode_energies = [...] or energy = ... (random over the modes)",
                ));
            }
            _ => {
                return Err(src.error(
                    cx.method_span(),
                    "more than one of quanta, mode_energies and energy is given",
                    "give exactly one of quanta, mode_energies and energy",
                ));
            }
        };
        let rotation = match (&keys.temperature, &keys.j) {
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
        Ok(NormalModes { energies, rotation })
    }

    fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        _m: &M,
        _cx: &Binding<'_>,
    ) -> Result<(Spec<N>, String), FileError> {
        let (energies, rotation) = (&self.energies, &self.rotation);
        Ok((
            Spec::NormalModes { energies: energies.clone(), rotation: rotation.clone() },
            format!("normal modes, energies {energies:?}, rotation {rotation:?}"),
        ))
    }
}
