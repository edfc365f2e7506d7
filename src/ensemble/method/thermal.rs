//! `method = "thermal"`: the classical canonical distribution at a temperature, in a region
//! ([`crate::runtime::sample::Thermal`]).

use serde::Deserialize;
use toml::Spanned;

use super::{Binding, Context, Method, RegionKeys, RegionSpec};
use crate::runtime::Molecule;
use crate::runtime::diagnostic::FileError;
use crate::runtime::sample::Spec;

/// The thermal method's keys.
#[derive(Deserialize)]
pub struct Keys {
    temperature: Option<Spanned<f64>>,
    energy_unit: Option<Spanned<String>>,
    region: Option<Spanned<RegionKeys>>,
}

/// Canonical at `temperature` kelvin.
#[derive(Clone, Debug)]
pub struct Thermal {
    /// Kelvin.
    pub temperature: f64,
    /// The bounded region.
    pub region: RegionSpec,
}

impl Method for Thermal {
    const NAME: &'static str = "thermal";
    type Keys = Keys;
    type Bound<const N: usize> = Spec<N>;

    fn read(keys: Keys, cx: &Context<'_>) -> Result<Self, FileError> {
        let eh = cx.hartree(&keys.energy_unit)?;
        let t = keys.temperature.as_ref().ok_or_else(|| cx.needs("temperature", "kelvin"))?;
        Ok(Thermal { temperature: cx.temperature(t)?, region: cx.region(&keys.region, eh)? })
    }

    fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        cx: &Binding<'_>,
    ) -> Result<(Spec<N>, String), FileError> {
        let temperature = self.temperature;
        Ok((
            Spec::Thermal { temperature, region: cx.region(m, &self.region)? },
            format!("thermal (canonical) at {temperature} K"),
        ))
    }

    fn temperature(&self) -> Option<f64> {
        Some(self.temperature)
    }
}
