//! `method = "microcanonical"`: uniform on the energy shell, optionally at fixed |J|, in a region
//! ([`crate::runtime::sample::Microcanonical`]).

use std::ops::Range;

use serde::Deserialize;
use toml::Spanned;

use super::{Binding, Context, Method, RegionKeys, RegionSpec};
use crate::runtime::Molecule;
use crate::runtime::diagnostic::FileError;
use crate::runtime::sample::Spec;

/// The microcanonical method's keys.
#[derive(Deserialize)]
pub struct Keys {
    energy: Option<Spanned<f64>>,
    energy_unit: Option<Spanned<String>>,
    angular_momentum: Option<Spanned<f64>>,
    region: Option<Spanned<RegionKeys>>,
}

/// On the energy shell.
#[derive(Clone, Debug)]
pub struct Microcanonical {
    /// Total energy, hartree, and where it is written.
    pub energy: (f64, Range<usize>),
    /// Fixed |J|, ħ.
    pub angular_momentum: Option<f64>,
    /// The bounded region.
    pub region: RegionSpec,
}

impl Method for Microcanonical {
    const NAME: &'static str = "microcanonical";
    type Keys = Keys;
    type Bound<const N: usize> = Spec<N>;

    fn read(keys: Keys, cx: &Context<'_>) -> Result<Self, FileError> {
        let eh = cx.hartree(&keys.energy_unit)?;
        let energy =
            keys.energy.as_ref().ok_or_else(|| cx.needs("energy", "in ensemble.energy_unit, default hartree"))?;
        let angular_momentum = match &keys.angular_momentum {
            Some(j) if !(j.get_ref().is_finite() && *j.get_ref() >= 0.0) => {
                return Err(cx.src().error(
                    j.span(),
                    format!("`ensemble.angular_momentum` must be a non-negative |J| in hbar, got {}", j.get_ref()),
                    "write |J| in units of hbar, or remove it to sample J too",
                ));
            }
            Some(j) => Some(*j.get_ref()),
            None => None,
        };
        Ok(Microcanonical {
            energy: (cx.finite_energy(energy, "energy", eh)?, energy.span()),
            angular_momentum,
            region: cx.region(&keys.region, eh)?,
        })
    }

    fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        cx: &Binding<'_>,
    ) -> Result<(Spec<N>, String), FileError> {
        let (energy, r) = (&self.energy, &self.region);
        let u0 = cx.reference_energy(m)?;
        if energy.0 < u0 {
            return Err(cx.src().error(
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
            return Err(cx.src().error(
                at.clone(),
                format!(
                    "the energy cap {cap} hartree is below the energy above the reference, E − U(reference) = {} hartree",
                    energy.0 - u0
                ),
                "raise region.energy_cap above E − U(reference), or lower the energy",
            ));
        }
        let d = match self.angular_momentum {
            Some(j) => format!("microcanonical at E = {} hartree, |J| = {j} hbar", energy.0),
            None => format!("microcanonical at E = {} hartree", energy.0),
        };
        let spec = Spec::Microcanonical {
            energy: energy.0,
            angular_momentum: self.angular_momentum,
            region: cx.region(m, r)?,
        };
        Ok((spec, d))
    }
}
