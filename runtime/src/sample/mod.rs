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
//!
//! # Samplers (one file each)
//!
//! * [`thermal`]: canonical at T; configuration `exp(−U/kT)·√det M(q)`, `(J, p)` Gaussian with
//!   covariance `kT·M(q)`, orientation uniform.
//! * [`microcanonical`]: uniform on `H = E`, optionally at fixed |J|.
//! * [`normal_modes`]: harmonic normal modes about the minimum ([`crate::modes`]), random
//!   phases, energies per mode random, fixed or `(v + ½)ħω`, rotation thermal or fixed.
//! * [`Spec::States`]: states given explicitly; the `rovib` crate reads them from a CSV file of
//!   internal coordinates or an extended XYZ file (`method = "file"` in an ensemble scene).
//!
//! The configuration of the first two is drawn by exact rejection sampling
//! ([`configuration`]), so every state is an independent draw from its trajectory's own stream.
//!
//! # Adding a sampler
//!
//! An `[ensemble] method` of `rovib ensemble` is one file of the `rovib` crate,
//! `src/ensemble/method/NAME.rs`: its keys, their checks, its binding to the molecule and the
//! [`Sampler`] it builds, either one of these or its own type in that file (measured with a toy
//! `rest` method, every trajectory at the reference geometry at rest, run end to end: one file
//! changed; the recipe is in that folder's `mod.rs` and in the guide's architecture page). A
//! sampler meant for this crate's users too goes here, in its own file with its `mod` line
//! below (and a [`Spec`] variant with its arm in [`sampler`] if `sampler` should build it), and
//! the method file calls it.
//!
//! # Units
//!
//! Atomic units: q in bohr and rad, p in ħ/bohr or ħ, J in ħ, energies in hartree; temperatures
//! in kelvin, converted with [`BOLTZMANN`]. The orientation is the body → lab rotation as a
//! unit quaternion; the centre of mass is at rest at the origin.

use nalgebra::{Quaternion, SVector, UnitQuaternion, Vector3};
use rand::RngExt as _;
use rand::SeedableRng as _;
use rand_distr::StandardNormal;

use crate::hamiltonian::HamiltonianError;
use crate::hamiltonian::fast::{BodyState, MetricFactor};
use crate::molecule::{KineticMatrices, Molecule};

pub mod collision;
pub mod configuration;
pub mod microcanonical;
pub mod normal_modes;
pub mod thermal;

pub use microcanonical::Microcanonical;
pub use normal_modes::NormalModeSampler;
pub use thermal::Thermal;

/// The Boltzmann constant in hartree per kelvin (CODATA 2018: k_B = 1.380 649 × 10⁻²³ J/K exact,
/// E_h = 4.359 744 722 2071 × 10⁻¹⁸ J).
pub const BOLTZMANN: f64 = 3.166_811_563_455_6e-6;

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

    /// The configurational integral of the sampled region, `(ln Z, relative standard error)`,
    /// where the sampler knows it (the thermal one: [`Thermal::configurational_integral_with`] with
    /// [`INTEGRAL_POINTS`] points); None otherwise.
    fn configurational_integral(&self) -> Option<(f64, f64)> {
        None
    }
}

/// The proposals of the importance-sampling estimate of a thermal sampler's configurational
/// integral (relative standard error ~ 1/√(acceptance · points)).
pub const INTEGRAL_POINTS: usize = 1 << 16;

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
    Fixed(Vector3<f64>),
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
    match spec {
        Spec::Thermal { temperature, region } => Ok(Box::new(Thermal::new(molecule, *temperature, region, seed)?)),
        Spec::Microcanonical { energy, angular_momentum, region } => {
            Ok(Box::new(Microcanonical::new(molecule, *energy, *angular_momentum, region, seed)?))
        }
        Spec::NormalModes { energies, rotation } => {
            Ok(Box::new(NormalModeSampler::new(molecule, energies, rotation, seed)?))
        }
        Spec::States(states) => {
            if states.is_empty() {
                return Err(SampleError::Invalid("no states given: the file holds no state".into()));
            }
            Ok(Box::new(Given(states.clone())))
        }
    }
}

impl<const N: usize> Region<N> {
    /// No cap, every coordinate over its valid range.
    pub fn unbounded() -> Self {
        Self { energy_cap: None, limits: [None; N] }
    }

    /// Only an energy cap (hartree above U at the reference geometry).
    pub fn capped(energy_cap: f64) -> Self {
        Self { energy_cap: Some(energy_cap), limits: [None; N] }
    }
}

/// A uniformly distributed rotation (Haar measure): four standard normals, normalised, as a unit
/// quaternion.
pub fn haar(rng: &mut TrajectoryRng) -> UnitQuaternion<f64> {
    loop {
        let v: [f64; 4] = std::array::from_fn(|_| rng.sample(StandardNormal));
        let q = Quaternion::new(v[0], v[1], v[2], v[3]);
        if q.norm() > 1e-150 {
            return UnitQuaternion::from_quaternion(q);
        }
    }
}

/// A direction uniform on the unit sphere.
pub fn uniform_direction(rng: &mut TrajectoryRng) -> Vector3<f64> {
    loop {
        let v = Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal));
        let n = v.norm();
        if n > 1e-150 {
            return v / n;
        }
    }
}

/// The kinetic energy `½ (ω·J + q̇·p)`, `(ω, q̇) = M⁻¹ (J, p)`, as the runtime's fast path
/// computes it, in hartree.
pub fn kinetic_energy<const N: usize>(
    k: &KineticMatrices<N>,
    q: &SVector<f64, N>,
    j: &Vector3<f64>,
    p: &SVector<f64, N>,
) -> Result<f64, SampleError> {
    let (omega, qdot) =
        MetricFactor::new(k, q).map_err(|e: HamiltonianError| SampleError::Invalid(e.to_string()))?.solve(j, p);
    Ok(0.5 * (omega.dot(j) + qdot.dot(p)))
}

/// The total energy `H = T + U` of a body state, in hartree, by the fast path's formula.
pub fn energy<M, const N: usize, const NA: usize>(molecule: &M, state: &BodyState<N>) -> Result<f64, SampleError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let mut k = KineticMatrices::default();
    molecule.kinetic(&state.q, &mut k);
    Ok(kinetic_energy(&k, &state.q, &state.j, &state.p)? + molecule.potential(&state.q))
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
