//! The microcanonical distribution: uniform on the energy shell `H = E`, optionally at fixed
//! `|J|`, centre of mass at rest.
//!
//! # Measure
//!
//! The Liouville measure in (q, Haar, J, p) is flat and `H = ½ xᵀ M⁻¹ x + U(q)` with
//! `x = (J, p)` of dimension `d = n + 3` (n internal coordinates). Uniform on the shell means
//! the density `δ(H − E)`. Integrating over x at fixed q: with `x = √(2K) L u`, `M = L Lᵀ`,
//! `K = E − U`, the shell `{½ xᵀ M⁻¹ x = K}` has area `∝ √det M · K^{(d−1)/2}` and
//! `δ(H − E) = δ(½ρ² − K)`, so
//!
//! ```text
//! ρ(q) ∝ √det M(q) · (E − U(q))^{(d−2)/2}            (U < E, in the region)
//! ```
//!
//! and given q the direction u is uniform on the unit sphere `S^{d−1}` (normalised standard
//! normals): `(J, p) = √(2(E − U)) · L u`.
//!
//! **Fixed |J| = j.** The measure gets `δ(|J| − j)`, i.e. `j² dĴ` with Ĵ on the unit sphere.
//! Completing the square in p, `T = ½ (p − p₀)ᵀ G22 (p − p₀) + ½ Jᵀ I⁻¹ J` with
//! `p₀ = Aᵀ I⁻¹ J` and `G22⁻¹ = S = a − Aᵀ I⁻¹ A`. Integrating δ(H − E) over p ∈ ℝⁿ gives
//!
//! ```text
//! ρ(q, Ĵ) ∝ √det S(q) · (E − U(q) − ½ j² Ĵᵀ I⁻¹(q) Ĵ)^{(n−2)/2}
//! ```
//!
//! (no `√det I`: J is not integrated over), with the Haar orientation uniform. Given (q, Ĵ),
//! `p = p₀ + √(2K') · L2 u`, `K' = E − U − ½ Jᵀ I⁻¹ J`, `S = L2 L2ᵀ`, u uniform on `S^{n−1}`.
//! This needs n ≥ 2 (for n = 1 the density is unbounded at the turning points).
//!
//! # Exactness
//!
//! The configuration (and Ĵ) is drawn by exact rejection sampling
//! ([`super::configuration`]). The momenta are then rescaled once so that the kinetic energy
//! computed by the runtime's fast path (`T = ½ (ω·J + q̇·p)`, `(ω, q̇) = M⁻¹(J, p)`) is
//! exactly `E − U` to rounding: a factor `1 + O(10⁻¹⁵)` that moves no state off the
//! distribution but makes `H = E` to about 1e-15 relative. At fixed |J| only `p − p₀` is
//! rescaled, so `|J|` stays exactly j.
//!
//! # Region
//!
//! `U < E` bounds the configuration when E is below every dissociation limit; above one, give
//! the lengths limits.

use nalgebra::{SVector, Vector3};
use rand::RngExt as _;
use rand_distr::StandardNormal;

use super::configuration::{self, Configuration, Point, Target};
use super::{Region, SampleError, Sampler, haar, kinetic_energy, stream};
use crate::hamiltonian::fast::BodyState;
use crate::molecule::Molecule;

/// The microcanonical sampler.
pub struct Microcanonical<'m, M: ?Sized, const N: usize, const NA: usize> {
    configuration: Configuration<'m, M, N, NA>,
    energy: f64,
    angular_momentum: Option<f64>,
    seed: u64,
}

impl<'m, M, const N: usize, const NA: usize> Microcanonical<'m, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The sampler at total energy `energy` (hartree, the zero of U), optionally with `|J|`
    /// fixed (ħ), in `region`.
    pub fn new(
        molecule: &'m M,
        energy: f64,
        angular_momentum: Option<f64>,
        region: &Region<N>,
        seed: u64,
    ) -> Result<Self, SampleError> {
        if !energy.is_finite() {
            return Err(SampleError::Invalid(format!("the energy must be finite (got {energy})")));
        }
        if let Some(j) = angular_momentum {
            if !(j >= 0.0 && j.is_finite()) {
                return Err(SampleError::Invalid(format!("|J| must be zero or positive (got {j} ħ)")));
            }
            if N < 2 {
                return Err(SampleError::Invalid(format!(
                    "fixed |J| needs at least 2 internal coordinates ({} has {N}): leave |J| free",
                    molecule.name()
                )));
            }
        }
        let (centre, hessian) = configuration::centre(molecule)?;
        let bounds = configuration::bounds(molecule, region, &centre)?;
        if let Some(cap) = bounds.u_cap
            && cap < energy
        {
            return Err(SampleError::Invalid(format!(
                "the energy cap (U ≤ {cap} hartree) is below the energy E = {energy} hartree and would cut the energy \
                 shell: raise the cap above E − U(reference) or leave it out"
            )));
        }
        let u_centre = molecule.potential(&centre);
        if energy.partial_cmp(&u_centre) != Some(std::cmp::Ordering::Greater)
            && hessian.is_some_and(|f| f.cholesky().is_some())
        {
            return Err(SampleError::Invalid(format!(
                "the energy E = {energy} hartree is not above the minimum of the potential, U = {u_centre} hartree: \
                 raise E"
            )));
        }
        let d = N as f64 + if angular_momentum.is_some() { 0.0 } else { 3.0 };
        let power = 0.5 * (d - 2.0);
        let target = match angular_momentum {
            Some(j) => Target::ShellFixedJ { energy, j, power },
            None => Target::Shell { energy, power },
        };
        // The harmonic estimate of the configuration's spread: each of the N + d quadratic
        // terms holds (E − U_min)/(N + d) on average, like kT/2 in the canonical case.
        let kt_eff = 2.0 * (energy - u_centre).max(1e-12) / (N as f64 + d);
        let configuration = Configuration::new(molecule, target, bounds, centre, hessian, kt_eff).map_err(|e| {
            SampleError::Invalid(format!("{e} (is E = {energy} hartree above the minimum of U in the region?)"))
        })?;
        if energy.partial_cmp(&configuration.u_min) != Some(std::cmp::Ordering::Greater) {
            return Err(SampleError::Invalid(format!(
                "the energy E = {energy} hartree is below the lowest potential found in the region ({} hartree): raise E",
                configuration.u_min
            )));
        }
        Ok(Self { configuration, energy, angular_momentum, seed })
    }

    /// The estimated acceptance rate of the configuration's rejection sampling.
    pub fn acceptance(&self) -> f64 {
        self.configuration.acceptance
    }

    fn momenta(
        &self,
        point: &Point<N>,
        rng: &mut super::TrajectoryRng,
    ) -> Result<(Vector3<f64>, SVector<f64, N>), SampleError> {
        let kinetic = self.energy - point.u;
        match self.angular_momentum {
            None => {
                let (z1, z2) = sphere::<N>(rng, 3);
                let s = (2.0 * kinetic).sqrt();
                let (j, p) = point.chol.apply(&(z1 * s), &(z2 * s));
                let t = kinetic_energy(&point.kinetic, &point.q, &j, &p)?;
                let c = (kinetic / t).sqrt();
                Ok((j * c, p * c))
            }
            Some(jabs) => {
                let j = point.j_dir * jabs;
                let rotational = point.chol.rotational_energy(&j);
                let left = kinetic - rotational;
                let (_, u) = sphere::<N>(rng, 0);
                let p0 = point.chol.p_of_j(&j);
                let dp = point.chol.l2 * u * (2.0 * left).sqrt();
                // Rescale p − p₀ so that the fast path's T is E − U: T(c) = T(0) + c² K'.
                let t0 = kinetic_energy(&point.kinetic, &point.q, &j, &p0)?;
                let t1 = kinetic_energy(&point.kinetic, &point.q, &j, &(p0 + dp))?;
                let c = ((kinetic - t0) / (t1 - t0)).sqrt();
                Ok((j, p0 + dp * if c.is_finite() { c } else { 1.0 }))
            }
        }
    }
}

/// A uniform point on the unit sphere of dimension `extra + N − 1`, split into its first
/// `extra` (≤ 3, the rest of the 3-vector zero) and last N components.
fn sphere<const N: usize>(rng: &mut super::TrajectoryRng, extra: usize) -> (Vector3<f64>, SVector<f64, N>) {
    loop {
        let a = Vector3::from_fn(|i, _| if i < extra { rng.sample::<f64, _>(StandardNormal) } else { 0.0 });
        let b = SVector::<f64, N>::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal));
        let norm = (a.norm_squared() + b.norm_squared()).sqrt();
        if norm > 1e-150 {
            return (a / norm, b / norm);
        }
    }
}

impl<M, const N: usize, const NA: usize> Sampler<N> for Microcanonical<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized + Sync,
{
    fn draw(&self, index: u64) -> Result<BodyState<N>, SampleError> {
        let mut rng = stream(self.seed, index);
        let point = self.configuration.draw(&mut rng)?;
        let orientation = haar(&mut rng);
        let (j, p) = self.momenta(&point, &mut rng)?;
        Ok(BodyState { q: point.q, p, orientation, j })
    }
}
