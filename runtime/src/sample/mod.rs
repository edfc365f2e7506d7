//! Initial conditions for ensembles: where trajectory `i` of an ensemble starts.
//!
//! This module is the contract between the samplers (thermal, microcanonical, normal modes,
//! from a file) and the ensemble runner, which knows nothing of how a state was drawn: it asks a
//! [`Sampler`] for the state of trajectory `index` and gets a [`BodyState`] in atomic units, with
//! the centre of mass at rest at the origin.
//!
//! # Reproducibility
//!
//! Trajectory `index` draws from its own random stream, derived from `(seed, index)` only
//! ([`stream`]), so an ensemble is the same whatever the number of threads, ranks or the order in
//! which trajectories finish.

use rand::SeedableRng as _;

use crate::hamiltonian::fast::BodyState;
use crate::molecule::Molecule;

/// The random generator of one trajectory: ChaCha8, a counter-based generator whose 2⁶⁴
/// independent streams are selected by the trajectory index.
pub type TrajectoryRng = rand_chacha::ChaCha8Rng;

/// The random stream of trajectory `index` of an ensemble seeded with `seed`.
pub fn stream(seed: u64, index: u64) -> TrajectoryRng {
    let mut rng = TrajectoryRng::seed_from_u64(seed);
    rng.set_stream(index);
    rng
}

/// Draws the initial state of trajectory `index`. Implementations are deterministic functions
/// of `(their configuration, seed, index)` and are shared between threads.
pub trait Sampler<const N: usize>: Sync {
    /// The initial state of trajectory `index`: q (bohr, rad), p (ħ/bohr, ħ), the orientation
    /// (body → lab) and the body-frame angular momentum J (ħ).
    fn draw(&self, index: u64) -> Result<BodyState<N>, SampleError>;
}

/// How the bounded region of configuration space is chosen for a distribution that is not
/// normalisable otherwise (a Morse well at a finite temperature).
#[derive(Clone, Debug, PartialEq)]
pub struct Region<const N: usize> {
    /// Accept only configurations with `U(q) − U(q_ref) ≤ energy_cap` (hartree); `None` for no cap.
    pub energy_cap: Option<f64>,
    /// Per coordinate, the closed interval `[low, high]` in atomic units (bohr, rad); `None` for
    /// the coordinate's valid range.
    pub limits: [Option<(f64, f64)>; N],
}

/// The energy put into each normal mode by [`Spec::NormalModes`].
#[derive(Clone, Debug, PartialEq)]
pub enum ModeEnergies {
    /// Microcanonical normal-mode sampling: the total vibrational energy (hartree) distributed
    /// uniformly at random over the modes (as VENUS does).
    Random {
        /// Total vibrational energy above the minimum, hartree.
        total: f64,
    },
    /// Fixed energies per mode, hartree, in the order of increasing harmonic wavenumber.
    Fixed(Vec<f64>),
    /// Quasiclassical: `E_k = (v_k + ½) ħ ω_k` with the given quantum numbers, in the order of
    /// increasing harmonic wavenumber.
    Quantum(Vec<u32>),
}

/// How the overall rotation is drawn by [`Spec::NormalModes`].
#[derive(Clone, Debug, PartialEq)]
pub enum RotationSampling {
    /// Thermal at this temperature (kelvin): J Gaussian with covariance kT·I at the sampled
    /// geometry, orientation uniform (Haar).
    Thermal {
        /// Kelvin.
        temperature: f64,
    },
    /// This body-frame J (ħ), orientation uniform (Haar).
    Fixed(nalgebra::Vector3<f64>),
}

/// What to sample, all in atomic units except temperatures (kelvin).
#[derive(Clone, Debug, PartialEq)]
pub enum Spec<const N: usize> {
    /// The classical canonical distribution at `temperature` over internal and rotational phase
    /// space: configuration density `exp(−U/kT)·√det M(q)` in the region, orientation uniform,
    /// `(J, p)` Gaussian with covariance `kT·M(q)`.
    Thermal {
        /// Kelvin.
        temperature: f64,
        /// The bounded region.
        region: Region<N>,
    },
    /// Uniform on the energy shell `H = energy` (hartree), optionally at fixed `|J|` (ħ).
    Microcanonical {
        /// Total energy, hartree (the same zero as the potential).
        energy: f64,
        /// Fixed |J|, ħ.
        angular_momentum: Option<f64>,
        /// The bounded region.
        region: Region<N>,
    },
    /// Normal-mode sampling about the reference geometry (a minimum): random phases, energies
    /// per mode as given, rotation as given.
    NormalModes {
        /// Energies per mode.
        energies: ModeEnergies,
        /// The overall rotation.
        rotation: RotationSampling,
    },
    /// States given explicitly (read from a file by the caller), trajectory `i` starts from
    /// `states[i]`.
    States(Vec<BodyState<N>>),
}

/// Why a state could not be drawn (or a sampler not built).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SampleError {
    /// The configuration is not usable for this sampler (the message says why and what to change).
    #[error("{0}")]
    Invalid(String),
}

/// Builds the sampler of `spec` for `molecule`, with the ensemble's `seed`.
///
/// Fails with a message that says what to change when the spec cannot be sampled (a
/// temperature that is not positive, an energy below the minimum of the potential, a reference
/// geometry that is not a minimum for normal-mode sampling, ...).
pub fn sampler<'m, M, const N: usize, const NA: usize>(
    molecule: &'m M,
    spec: &Spec<N>,
    seed: u64,
) -> Result<Box<dyn Sampler<N> + 'm>, SampleError>
where
    M: Molecule<N, NA> + Sync,
{
    let _ = (molecule, seed);
    match spec {
        Spec::States(states) => Ok(Box::new(Given(states.clone()))),
        _ => Err(SampleError::Invalid("this sampling method is not implemented yet".into())),
    }
}

/// Trajectory `i` starts from the `i`-th given state.
struct Given<const N: usize>(Vec<BodyState<N>>);

impl<const N: usize> Sampler<N> for Given<N> {
    fn draw(&self, index: u64) -> Result<BodyState<N>, SampleError> {
        usize::try_from(index).ok().and_then(|i| self.0.get(i)).copied().ok_or_else(|| {
            SampleError::Invalid(format!("trajectory {index} asks for a state beyond the {} given", self.0.len()))
        })
    }
}
