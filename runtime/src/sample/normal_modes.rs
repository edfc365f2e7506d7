//! Normal-mode sampling about a minimum of the potential: random phases, energies per mode
//! (microcanonical normal-mode sampling as in VENUS, fixed, or quasiclassical `(v + ½)ħω`),
//! and the overall rotation thermal or fixed.
//!
//! # Method
//!
//! The minimum q₀ is found by Newton's method from the reference geometry and checked
//! ([`crate::modes`]: a reference that is not a minimum, e.g. a saddle, is an error that names
//! the mode of negative curvature). With the harmonic frequencies `ω_k` (hartree, ħ = 1) and
//! mode vectors `L` (`Lᵀ G⁻¹ L = 1`), each mode k gets its energy `E_k` and a phase φ_k uniform
//! in [0, 2π):
//!
//! ```text
//! Q_k = √(2E_k)/ω_k · cos φ_k,    P_k = −√(2E_k) · sin φ_k        (mass-weighted normal coordinates)
//! q = q₀ + L Q,   q̇ = L P,
//! ω = I⁻¹ (J − A q̇),   p = Aᵀ ω + a q̇                         (Legendre map at the given J)
//! ```
//!
//! Mode energies: **Random** `{ total }`: `E_k = total · x_k` with x uniform on the simplex
//! Σx_k = 1 (normalised exponential variates), the VENUS microcanonical normal-mode scheme;
//! **Fixed**: as given; **Quantum**: `E_k = (v_k + ½) ħω_k` (zero-point energy ½Σħω_k at v = 0).
//! Modes are ordered by increasing ω.
//!
//! Rotation: **Thermal** at T: J Gaussian with covariance kT·I(q) at the sampled q
//! (`J = √(kT) L1 z`, `I = L1 L1ᵀ`), which is the canonical distribution of J at fixed q and
//! q̇; **Fixed**: the given body-frame J. The orientation is uniform (Haar) in both.
//!
//! # Limits
//!
//! The harmonic vibrational energy `Σ E_k` may be at most [`MAX_MODE_ENERGY`] (1 hartree,
//! 27.2 eV: above the dissociation energy of every chemical bond, far beyond where harmonic
//! modes mean anything); more is refused when the sampler is built. A drawn geometry with a
//! coordinate outside its valid range (a bond angle beyond π) is a failed draw that names the
//! coordinate, never a state to integrate.
//!
//! # Harmonic limit
//!
//! With J = 0 the kinetic energy is exactly `½ q̇ᵀ G22⁻¹(q) q̇`, so mode k carries exactly E_k
//! only in the harmonic limit: the state's vibrational energy `H − U(q₀)` is
//! `Σ E_k + O(E^{3/2})` (cubic anharmonicity and the q-dependence of G22 and of the
//! rotational coupling). At J ≠ 0 the rotational energy `½ Jᵀ I⁻¹ J` comes on top.

use nalgebra::{SVector, Vector3};
use rand::RngExt as _;
use rand_distr::{Exp1, StandardNormal};

use super::configuration::MetricCholesky;
use super::{BOLTZMANN, ModeEnergies, RotationSampling, SampleError, Sampler, haar, stream};
use crate::hamiltonian::fast::BodyState;
use crate::modes::{self, NormalModes};
use crate::molecule::{KineticMatrices, Molecule};

/// The largest harmonic vibrational energy `Σ E_k` (hartree) the sampler accepts.
pub const MAX_MODE_ENERGY: f64 = 1.0;

/// The normal-mode sampler.
pub struct NormalModeSampler<'m, M: ?Sized, const N: usize, const NA: usize> {
    molecule: &'m M,
    modes: NormalModes<N>,
    energies: ModeEnergies,
    rotation: RotationSampling,
    seed: u64,
}

impl<'m, M, const N: usize, const NA: usize> NormalModeSampler<'m, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The sampler; fails when the reference geometry does not lead to a minimum or the
    /// energies or rotation are invalid.
    pub fn new(
        molecule: &'m M,
        energies: &ModeEnergies,
        rotation: &RotationSampling,
        seed: u64,
    ) -> Result<Self, SampleError> {
        let reference = molecule.reference_geometry().ok_or_else(|| {
            SampleError::Invalid(format!(
                "{} has no reference geometry (every coordinate needs a `reference` in {})",
                molecule.name(),
                molecule.source()
            ))
        })?;
        let q0 = modes::stationary_point(molecule, &reference)
            .map_err(|e| SampleError::Invalid(format!("normal-mode sampling needs a minimum: {e}")))?;
        let mut x0 = nalgebra::SMatrix::<f64, 3, NA>::zeros();
        molecule.positions(&q0, &mut x0);
        if crate::cartesian_modes::is_linear(&x0) {
            return Err(SampleError::Invalid(format!(
                "the minimum of {} found from its reference geometry is linear: it has 3N - 5 normal modes with a \
                 doubly degenerate bend (`rovib freq --molecule {}` lists them), and normal-mode sampling works in the \
                 3N - 6 internal coordinates, whose chart is singular there; not available yet for linear molecules, \
                 use thermal or microcanonical sampling",
                molecule.name(),
                molecule.name()
            )));
        }
        let modes = NormalModes::at(molecule, &q0).map_err(|e| {
            SampleError::Invalid(format!(
                "normal-mode sampling needs a minimum, but the stationary point found from the reference geometry of {} \
                 is not one: {e}; use thermal or microcanonical sampling",
                molecule.name()
            ))
        })?;
        Self::with_modes(molecule, modes, energies, rotation, seed)
    }

    /// The sampler about given normal modes.
    pub fn with_modes(
        molecule: &'m M,
        modes: NormalModes<N>,
        energies: &ModeEnergies,
        rotation: &RotationSampling,
        seed: u64,
    ) -> Result<Self, SampleError> {
        match energies {
            ModeEnergies::Random { total } if !(*total >= 0.0 && total.is_finite()) => {
                return Err(SampleError::Invalid(format!(
                    "the vibrational energy must be zero or positive (got {total} hartree)"
                )));
            }
            ModeEnergies::Fixed(e) if e.len() != N || e.iter().any(|x| !(*x >= 0.0 && x.is_finite())) => {
                return Err(SampleError::Invalid(format!(
                    "give {N} mode energies, each zero or positive, in hartree (got {e:?})"
                )));
            }
            ModeEnergies::Quantum(v) if v.len() != N => {
                return Err(SampleError::Invalid(format!("give {N} quantum numbers, one per mode (got {})", v.len())));
            }
            _ => {}
        }
        let (total, what) = match energies {
            ModeEnergies::Random { total } => (*total, "the vibrational energy"),
            ModeEnergies::Fixed(e) => (e.iter().sum(), "the sum of the mode energies"),
            ModeEnergies::Quantum(v) => (
                v.iter().zip(modes.omega.iter()).map(|(&v, &w)| (f64::from(v) + 0.5) * w).sum(),
                "the harmonic energy Σ (v_k + ½) ħω_k of the quanta",
            ),
        };
        if total > MAX_MODE_ENERGY {
            return Err(SampleError::Invalid(format!(
                "{what} is {total:.4e} hartree ({:.4e} cm⁻¹), above the {MAX_MODE_ENERGY} hartree (27.2 eV) that \
                 normal-mode sampling accepts (harmonic modes mean nothing there, far above every bond's dissociation \
                 energy): give fewer quanta or less energy",
                total * crate::units::HARTREE_IN_WAVENUMBERS
            )));
        }
        match rotation {
            RotationSampling::Thermal { temperature } if !(*temperature > 0.0 && temperature.is_finite()) => {
                return Err(SampleError::Invalid(format!(
                    "the rotational temperature must be positive (got {temperature} K)"
                )));
            }
            RotationSampling::Fixed(j) if j.iter().any(|x| !x.is_finite()) => {
                return Err(SampleError::Invalid(format!("the angular momentum must be finite (got {j:?})")));
            }
            _ => {}
        }
        Ok(Self { molecule, modes, energies: energies.clone(), rotation: rotation.clone(), seed })
    }

    /// The normal modes used.
    pub fn modes(&self) -> &NormalModes<N> {
        &self.modes
    }
}

impl<M, const N: usize, const NA: usize> Sampler<N> for NormalModeSampler<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized + Sync,
{
    fn draw(&self, index: u64) -> Result<BodyState<N>, SampleError> {
        let mut rng = stream(self.seed, index);
        let omega = &self.modes.omega;
        let e: SVector<f64, N> = match &self.energies {
            ModeEnergies::Random { total } => {
                let x = SVector::<f64, N>::from_fn(|_, _| rng.sample::<f64, _>(Exp1));
                let sum = x.sum();
                if sum > 0.0 { x * (total / sum) } else { SVector::from_element(total / N as f64) }
            }
            ModeEnergies::Fixed(e) => SVector::from_fn(|k, _| e[k]),
            ModeEnergies::Quantum(v) => SVector::from_fn(|k, _| (f64::from(v[k]) + 0.5) * omega[k]),
        };
        let mut big_q = SVector::<f64, N>::zeros();
        let mut big_p = SVector::<f64, N>::zeros();
        for k in 0..N {
            let phi = std::f64::consts::TAU * rng.random::<f64>();
            let a = (2.0 * e[k]).sqrt();
            big_q[k] = a / omega[k] * phi.cos();
            big_p[k] = -a * phi.sin();
        }
        let q = self.modes.q0 + self.modes.vectors * big_q;
        if let Some((c, x)) = self.molecule.coordinates().iter().zip(q.iter()).find(|(c, x)| !c.contains(**x)) {
            return Err(SampleError::Invalid(format!(
                "the displaced geometry puts {} = {x} outside its valid range [{}, {}] (atomic units): the harmonic \
                 amplitude of the modes is too large there; lower the mode energies or quanta",
                c.name, c.range.0, c.range.1
            )));
        }
        let qdot = self.modes.vectors * big_p;
        let mut k = KineticMatrices::default();
        self.molecule.kinetic(&q, &mut k);
        let j = match &self.rotation {
            RotationSampling::Thermal { temperature } => {
                let chol = MetricCholesky::new(&k).ok_or_else(|| singular(&q))?;
                let s = (BOLTZMANN * temperature).sqrt();
                chol.l1 * Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal) * s)
            }
            RotationSampling::Fixed(j) => *j,
        };
        let orientation = haar(&mut rng);
        let i_inv = k.inertia.try_inverse().ok_or_else(|| singular(&q))?;
        let w = i_inv * (j - k.coriolis * qdot);
        let p = k.coriolis.transpose() * w + k.a * qdot;
        if p.iter().chain(w.iter()).any(|x| !x.is_finite()) {
            return Err(singular(&q));
        }
        Ok(BodyState { q, p, orientation, j })
    }
}

fn singular<const N: usize>(q: &SVector<f64, N>) -> SampleError {
    SampleError::Invalid(format!(
        "the kinetic metric is singular at the displaced geometry q = {:?}: lower the mode energies",
        q.as_slice()
    ))
}
