//! The classical canonical distribution at a temperature T over internal and rotational phase
//! space (centre of mass at rest).
//!
//! # Measure
//!
//! In (q, p, Ω_e, p_e) the Liouville measure is flat. With `J = W p_e` and the orientation as a
//! rotation, `dΩ_e dp_e = d(Haar) dJ`, and `H = ½ (J, p)ᵀ M⁻¹ (J, p) + U(q)` with
//! `M = [[I, A], [Aᵀ, a]]`. Integrating the Gaussian over (J, p) leaves
//!
//! ```text
//! ρ(q) ∝ exp(−U(q)/kT) · √det M(q)        in the region,
//! ```
//!
//! times the Haar measure of the orientation, which is drawn uniformly (a normalised vector of
//! four standard normals as a unit quaternion). Given q, `(J, p)` is Gaussian with covariance
//! `kT·M(q)`: `(J, p) = √(kT) · L z`, `M = L Lᵀ` (block Cholesky), z standard normal. Leaving out
//! `√det M` (drawing q from `exp(−U/kT)` alone) is wrong: [`Thermal::without_metric_factor`]
//! does so on purpose, for the tests that show the difference.
//!
//! q is drawn by exact rejection sampling ([`super::configuration`]); `k_B T` uses
//! [`super::BOLTZMANN`] (hartree per kelvin).
//!
//! # Region
//!
//! The classical Boltzmann density of a Morse bond grows like `r²` at large r (the well is not
//! normalisable), so every length needs an upper limit or the region an energy cap; otherwise
//! building the sampler fails and says so.

use nalgebra::{SVector, Vector3};
use rand::RngExt as _;
use rand_distr::StandardNormal;

use super::configuration::{self, Configuration, Target};
use super::{BOLTZMANN, Region, SampleError, Sampler, haar, stream};
use crate::hamiltonian::fast::BodyState;
use crate::molecule::Molecule;

/// The thermal sampler.
pub struct Thermal<'m, M: ?Sized, const N: usize, const NA: usize> {
    configuration: Configuration<'m, M, N, NA>,
    molecule: &'m M,
    kt: f64,
    seed: u64,
}

impl<'m, M, const N: usize, const NA: usize> Thermal<'m, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The sampler at `temperature` (kelvin) in `region`.
    pub fn new(molecule: &'m M, temperature: f64, region: &Region<N>, seed: u64) -> Result<Self, SampleError> {
        Self::build(molecule, temperature, region, seed, true)
    }

    /// WRONG ON PURPOSE: the configuration drawn from `exp(−U/kT)` without `√det M`. Exists
    /// only so that tests can show that the configuration marginals detect the missing factor.
    pub fn without_metric_factor(
        molecule: &'m M,
        temperature: f64,
        region: &Region<N>,
        seed: u64,
    ) -> Result<Self, SampleError> {
        Self::build(molecule, temperature, region, seed, false)
    }

    fn build(
        molecule: &'m M,
        temperature: f64,
        region: &Region<N>,
        seed: u64,
        metric: bool,
    ) -> Result<Self, SampleError> {
        if !(temperature > 0.0 && temperature.is_finite()) {
            return Err(SampleError::Invalid(format!(
                "the temperature must be positive and finite (got {temperature} K): give it in kelvin"
            )));
        }
        let kt = BOLTZMANN * temperature;
        let (centre, hessian) = configuration::centre(molecule)?;
        let bounds = configuration::bounds(molecule, region, &centre)?;
        if bounds.u_cap.is_none() {
            let coords = molecule.coordinates();
            if let Some(k) = (0..N).find(|&k| !bounds.high[k].is_finite() || !bounds.low[k].is_finite()) {
                return Err(SampleError::Invalid(format!(
                    "the thermal distribution is not normalisable: coordinate {} has no upper limit; give it limits or \
                     give the region an energy cap",
                    coords[k].name
                )));
            }
        }
        let configuration =
            Configuration::new(molecule, Target::Boltzmann { kt, metric }, bounds, centre, hessian, kt)?;
        Ok(Self { configuration, molecule, kt, seed })
    }

    /// The configurational integral of the region with the centre of mass fixed, in Cartesian
    /// measure: `Z = ∫ e^{−U/kT} Π d³x_i δ³(X_cm)` (bohr^(3·atoms − 3); U from the potential's own
    /// zero), as `(ln Z, relative standard error)`. From `Π d³x_i = (M^{3/2} / Π m_i^{3/2}) √det M(q)
    /// sin β d³X dφ dβ dψ dq` (the kinetic metric is the mass-weighted Cartesian one in these
    /// coordinates) and `∫ sin β = 8π²`: `Z = 8π² (M^{3/2} / Π m_i^{3/2}) ∫ e^{−U/kT} √det M dq`,
    /// the integral by importance sampling (`Configuration::log_integral`) with `points`
    /// proposals from a stream of its own (the ensemble's seed, the last stream index).
    /// None for [`Self::without_metric_factor`].
    pub fn configurational_integral_with(&self, points: usize) -> Option<(f64, f64)> {
        let mut rng = stream(self.seed, u64::MAX);
        let (log, relative) = self.configuration.log_integral(&mut rng, points)?;
        let masses = self.molecule.masses();
        let total: f64 = masses.iter().sum();
        let log_mass = 1.5 * total.ln() - 1.5 * masses.iter().map(|m| m.ln()).sum::<f64>();
        Some(((8.0 * std::f64::consts::PI.powi(2)).ln() + log_mass + log, relative))
    }

    /// The estimated acceptance rate of the configuration's rejection sampling.
    pub fn acceptance(&self) -> f64 {
        self.configuration.acceptance
    }
}

impl<M, const N: usize, const NA: usize> Sampler<N> for Thermal<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized + Sync,
{
    fn draw(&self, index: u64) -> Result<BodyState<N>, SampleError> {
        let mut rng = stream(self.seed, index);
        let point = self.configuration.draw(&mut rng)?;
        let orientation = haar(&mut rng);
        let s = self.kt.sqrt();
        let z1 = Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal) * s);
        let z2 = SVector::<f64, N>::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal) * s);
        let (j, p) = point.chol.apply(&z1, &z2);
        Ok(BodyState { q: point.q, p, orientation, j })
    }

    fn configurational_integral(&self) -> Option<(f64, f64)> {
        self.configurational_integral_with(super::INTEGRAL_POINTS)
    }
}
