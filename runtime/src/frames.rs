//! Lab-frame Cartesian states and their conversion to and from the Hamiltonian's phase space.
//!
//! A trajectory is integrated in internal coordinates and Euler angles ([`PhaseState`]), but
//! initial conditions usually come as atom positions and velocities in a laboratory frame, and
//! diagnostics (the space-fixed angular momentum, a comparison with a plain Cartesian
//! propagation) need the same. This module converts in both directions:
//!
//! * [`to_lab`]: `x_i = X + R(Ω) R_i(q)`, `v_i = V + R(Ω) (ω × R_i + Σ_j ∂R_i/∂q_j q̇_j)`, with
//!   `(ω, q̇)` from the Hamiltonian's [`velocities`];
//! * [`from_lab`]: the inverse, by a least-squares fit (below).
//!
//! # Conventions
//!
//! * Atomic units: positions in bohr, velocities in bohr per ħ/E_h (the atomic unit of time,
//!   ≈ 0.024 188 fs), masses in electron masses, angular momenta in ħ, energies in hartree.
//! * A [`LabState`] holds one column per atom, in the molecule's atom order.
//! * `R(Ω) = Rz(φ) Rx(θ) Rz(ψ)` rotates body-frame vectors into the lab frame
//!   ([`rotation_matrix`]); `ω` is the body-frame angular velocity and `J = W p_e` the
//!   body-frame angular momentum, as in [`crate::hamiltonian`].
//!
//! # The centre of mass is split off
//!
//! The Hamiltonian has no translational degrees of freedom: the body-frame positions `R_i(q)`
//! have their centre of mass at the origin. A lab state therefore carries six more numbers than
//! a phase state, the centre-of-mass position `X` and velocity `V` ([`CentreOfMass`]):
//! [`from_lab`] returns them next to the phase state and [`to_lab`] takes them back. Because
//! `Σ m_i R_i = 0` and `Σ m_i ∂R_i/∂q_j = 0`, the translation is exactly orthogonal (in the
//! mass-weighted inner product) to every rotation and vibration, so the kinetic energy splits as
//! `½ M_total |V|² + T_rot-vib` and the split loses nothing.
//!
//! # Positions: a mass-weighted least-squares fit
//!
//! [`from_lab`] finds the orientation `R` and the internal coordinates `q` that minimise
//!
//! ```text
//! S(R, q) = Σ_i m_i |x_i − X − R R_i(q)|²
//! ```
//!
//! 1. Start from `q₀` ([`FitOptions::initial_q`], else the molecule's reference geometry) and
//!    the rotation that best superimposes `R_i(q₀)` on the input: the mass-weighted Kabsch
//!    method, i.e. the proper (det = +1) orthogonal polar factor of
//!    `C = Σ m_i (x_i − X) R_i(q₀)ᵀ` by a singular value decomposition. This is the global
//!    minimum over `R` at fixed `q₀`, so the iteration below starts from a good orientation even
//!    when the input is rotated far from the identity.
//! 2. Gauss–Newton on a small body-frame rotation `δθ` (`R ← R exp([δθ]×)`) and `δq` jointly.
//!    With the body-frame residuals `e_i = Rᵀ (x_i − X − R R_i)`, linearising
//!    `R exp([δθ]×) R_i(q + δq) ≈ R (R_i + δθ × R_i + Σ_j ∂R_i/∂q_j δq_j)` gives the normal
//!    equations
//!
//!    ```text
//!    [[I, A], [Aᵀ, a]] (δθ, δq) = (Σ m_i R_i × e_i,  Σ m_i ∂R_i/∂q_j · e_i)
//!    ```
//!
//!    whose matrix is *exactly* the kinetic metric of the Hamiltonian (the mass-weighted Gram
//!    matrix of the rotational and vibrational displacement fields). So the molecule's own
//!    [`Kinematics::kinetic`](crate::molecule::Kinematics::kinetic) and [`Kinematics::positions_jacobian`](crate::molecule::Kinematics::positions_jacobian) give every ingredient, and the
//!    solve is `(δθ, δq) = [[G11, G12], [G12ᵀ, G22]] · rhs` with the Hamiltonian's
//!    [`InverseMetric`] (which also detects a singular metric). A step that would increase `S`
//!    is halved (backtracking), so `S` never increases. After each step `R` is re-orthonormalised
//!    (its nearest rotation by SVD), so that rounding cannot accumulate into a non-rotation.
//! 3. Converged when the step's mass-weighted RMS displacement
//!    `sqrt((δθ, δq)ᵀ M (δθ, δq) / Σ m_i)` is at most [`FitOptions::step_tolerance`] (bohr). For
//!    representable positions the residual is zero at the solution and Gauss–Newton converges
//!    quadratically (typically 3–6 steps from the reference geometry).
//! 4. The fit is accepted if the mass-weighted RMS residual `sqrt(S / Σ m_i)` is at most
//!    [`FitOptions::residual_tolerance`]; otherwise the positions are not representable by this
//!    molecule's parametrization ([`FrameError::NotRepresentable`]): the atoms are in the wrong
//!    order, the molecule is rigid or has frozen coordinates, or the geometry is simply another
//!    molecule's. Setting the tolerance to `f64::INFINITY` accepts the least-squares fit.
//!
//! For a molecule whose coordinates are declared by kind (distances, angles, dihedrals) steps
//! 1–3 are replaced by the closed form `q = q(x)` ([`Kinematics::internal_coordinates`](crate::molecule::Kinematics::internal_coordinates)) and one
//! Kabsch rotation: no iteration and no metric, so the fit also works where the metric is
//! singular (a linear geometry). Angles are taken on the branch nearest the starting `q`.
//!
//! Euler angles are read off the fitted `R` with `θ ∈ [0, π]` and `φ, ψ ∈ (−π, π]`; at
//! `|sin θ| <` [`MIN_SIN_THETA`] the z-x-z angles are degenerate (gimbal lock) and the fit fails
//! with [`FrameError::EulerSingular`]. That is a property of the coordinates, not of the
//! molecule: rotating the whole input (positions and velocities) by a fixed rotation, e.g. 90°
//! about the lab x axis, moves it away from the singularity.
//!
//! # Velocities: the mass-weighted projection
//!
//! With the body-frame velocities `u_i = Rᵀ (v_i − V)` the momenta are
//!
//! ```text
//! J = Σ_i m_i R_i × u_i,      p_j = Σ_i m_i ∂R_i/∂q_j · u_i,      p_e = W⁻¹ J = Mᵀ J.
//! ```
//!
//! For velocities the parametrization can produce, `u_i = ω × R_i + Σ_j ∂R_i/∂q_j q̇_j`, these
//! are exactly `J = I ω + A q̇` and `p = Aᵀ ω + a q̇`, the Hamiltonian's momenta, and [`to_lab`]
//! gives the input back. For any other velocities (a rigid or partly frozen molecule, or
//! arbitrary Cartesian velocities of a molecule with fewer than `3·NA − 6` coordinates) they are
//! the momenta of the *mass-weighted least-squares projection*: the `(ω, q̇)` that minimise
//! `Σ m_i |u_i − ω × R_i − Σ_j ∂R_i/∂q_j q̇_j|²` (whose normal equations are `M (ω, q̇) = (J, p)`).
//! The discarded part is orthogonal to the kept one, so the kinetic energy it carried is simply
//! lost; [`FitReport`] reports its RMS size and energy, and this is not an error.
//!
//! # Round trips
//!
//! Internal → lab → internal and lab → internal → lab (for representable lab states) agree to
//! about 1e-13 relative at generic orientations (tested to 1e-10), with angles compared modulo
//! 2π.

use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, UnitQuaternion, Vector3};

pub use crate::hamiltonian::euler_angles;
use crate::hamiltonian::fast::{BodyState, MetricFactor};
use crate::hamiltonian::{
    HamiltonianError, InverseMetric, MIN_SIN_THETA, MetricBlock, PhaseState, body_angular_momentum,
    euler_momenta_from_angular_momentum, rotation_matrix, velocities,
};
use crate::molecule::{KineticMatrices, Molecule};

/// Positions and velocities of every atom in a laboratory (space-fixed) frame.
///
/// Column `i` is atom `i`, in the molecule's atom order. Positions in bohr, velocities in bohr
/// per atomic unit of time (ħ/E_h).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LabState<const NA: usize> {
    /// Atom positions `x_i`, bohr.
    pub positions: SMatrix<f64, 3, NA>,
    /// Atom velocities `v_i = ẋ_i`, bohr per ħ/E_h.
    pub velocities: SMatrix<f64, 3, NA>,
}

impl<const NA: usize> Default for LabState<NA> {
    fn default() -> Self {
        Self { positions: SMatrix::zeros(), velocities: SMatrix::zeros() }
    }
}

/// The position and velocity of the centre of mass, split off by [`from_lab`] and put back by
/// [`to_lab`].
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct CentreOfMass {
    /// `X = Σ m_i x_i / Σ m_i`, bohr.
    pub position: Vector3<f64>,
    /// `V = Σ m_i v_i / Σ m_i`, bohr per ħ/E_h.
    pub velocity: Vector3<f64>,
}

impl CentreOfMass {
    /// At rest at the origin.
    pub const AT_REST: Self = Self { position: Vector3::new(0.0, 0.0, 0.0), velocity: Vector3::new(0.0, 0.0, 0.0) };
}

impl<const NA: usize> LabState<NA> {
    /// Length of the flat layout: `6·NA`.
    pub const DIM: usize = 6 * NA;

    /// Writes the state as `[x_1, y_1, z_1, x_2, …, z_NA, vx_1, …, vz_NA]` (positions, then
    /// velocities, atom by atom), the layout of a Cartesian [`crate::integrate::OdeSystem`].
    ///
    /// # Panics
    ///
    /// If `y.len() != 6·NA`.
    pub fn write_to(&self, y: &mut [f64]) {
        assert_eq!(y.len(), Self::DIM, "a lab state of {NA} atoms has 6·NA = {} components", Self::DIM);
        let (x, v) = y.split_at_mut(3 * NA);
        x.copy_from_slice(self.positions.as_slice());
        v.copy_from_slice(self.velocities.as_slice());
    }

    /// Reads a state from the layout of [`LabState::write_to`].
    ///
    /// # Panics
    ///
    /// If `y.len() != 6·NA`.
    pub fn read_from(y: &[f64]) -> Self {
        assert_eq!(y.len(), Self::DIM, "a lab state of {NA} atoms has 6·NA = {} components", Self::DIM);
        Self {
            positions: SMatrix::from_column_slice(&y[..3 * NA]),
            velocities: SMatrix::from_column_slice(&y[3 * NA..]),
        }
    }

    /// The centre of mass (position and velocity) for the given masses (electron masses).
    pub fn centre_of_mass(&self, masses: &[f64; NA]) -> CentreOfMass {
        let total: f64 = masses.iter().sum();
        let (mut position, mut velocity) = (Vector3::zeros(), Vector3::zeros());
        for i in 0..NA {
            position += self.positions.column(i) * masses[i];
            velocity += self.velocities.column(i) * masses[i];
        }
        CentreOfMass { position: position / total, velocity: velocity / total }
    }

    /// The total angular momentum about the centre of mass, `L = Σ m_i (x_i − X) × (v_i − V)`,
    /// in ħ, lab-frame components.
    ///
    /// For a state from [`to_lab`] this is `R(Ω) J` with `J = W p_e` the Hamiltonian's
    /// body-frame angular momentum ([`lab_angular_momentum`]), so `|L| = |J|`; along a
    /// trajectory the vector `L` is conserved.
    pub fn angular_momentum(&self, masses: &[f64; NA]) -> Vector3<f64> {
        let com = self.centre_of_mass(masses);
        let mut l = Vector3::zeros();
        for i in 0..NA {
            let x = self.positions.column(i) - com.position;
            let v = self.velocities.column(i) - com.velocity;
            l += x.cross(&v) * masses[i];
        }
        l
    }

    /// The total kinetic energy `½ Σ m_i |v_i|²`, hartree (including the centre-of-mass motion).
    pub fn kinetic_energy(&self, masses: &[f64; NA]) -> f64 {
        (0..NA).map(|i| 0.5 * masses[i] * self.velocities.column(i).norm_squared()).sum()
    }

    /// The kinetic energy relative to the centre of mass, `½ Σ m_i |v_i − V|²`, hartree: the
    /// kinetic energy of the rotation–vibration Hamiltonian for a state from [`to_lab`].
    pub fn internal_kinetic_energy(&self, masses: &[f64; NA]) -> f64 {
        let v_com = self.centre_of_mass(masses).velocity;
        (0..NA).map(|i| 0.5 * masses[i] * (self.velocities.column(i) - v_com).norm_squared()).sum()
    }

    fn is_finite(&self) -> (bool, bool) {
        let finite = |m: &SMatrix<f64, 3, NA>| m.iter().all(|x| x.is_finite());
        (finite(&self.positions), finite(&self.velocities))
    }
}

/// Options of the position fit in [`from_lab`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FitOptions<const N: usize> {
    /// Internal coordinates to start the fit from (atomic units); `None` (the default) starts from
    /// the molecule's reference geometry. Give a guess near the answer when the geometry is far
    /// from the reference or when the parametrization has several equivalent solutions (e.g. a
    /// dihedral modulo 2π) and a particular branch is wanted.
    pub initial_q: Option<SVector<f64, N>>,
    /// Largest accepted mass-weighted RMS residual `sqrt(Σ m_i |x_i − X − R R_i(q)|² / Σ m_i)`,
    /// bohr. Default 1e-5 bohr (≈ 5e-6 Å): above the rounding of coordinates printed with 6
    /// decimals, far below the residual of a wrong atom order or a distorted rigid geometry
    /// (≳ 0.01 bohr). `f64::INFINITY` accepts any least-squares fit.
    pub residual_tolerance: f64,
    /// The fit has converged when a Gauss–Newton step moves the atoms by at most this
    /// mass-weighted RMS distance, bohr. Default 1e-12 bohr.
    pub step_tolerance: f64,
    /// Most Gauss–Newton steps before [`FrameError::NotConverged`]. Default 100.
    pub max_iterations: usize,
}

impl<const N: usize> Default for FitOptions<N> {
    fn default() -> Self {
        Self { initial_q: None, residual_tolerance: 1e-5, step_tolerance: 1e-12, max_iterations: 100 }
    }
}

/// How well a lab state matched the molecule's parametrization in [`from_lab`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FitReport {
    /// Gauss–Newton steps taken (after the Kabsch start).
    pub iterations: usize,
    /// Mass-weighted RMS position residual `sqrt(Σ m_i |x_i − X − R R_i(q)|² / Σ m_i)`, bohr:
    /// rounding level (≲ 1e-14) for representable positions.
    pub position_residual: f64,
    /// Mass-weighted RMS of the velocity part that the parametrization cannot represent,
    /// `sqrt(Σ m_i |u_i − ω × R_i − Σ_j ∂R_i/∂q_j q̇_j|² / Σ m_i)`, bohr per ħ/E_h (see the
    /// module documentation; zero up to rounding for representable velocities).
    pub velocity_residual: f64,
    /// The kinetic energy of that discarded part, `½ Σ m_i |…|²`, hartree: the input's kinetic
    /// energy minus the centre-of-mass and rotation–vibration kinetic energies.
    pub discarded_kinetic_energy: f64,
}

/// Why a state could not be converted between the lab frame and the Hamiltonian's phase space.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// The best fit of the parametrization leaves a mass-weighted RMS residual above
    /// [`FitOptions::residual_tolerance`]. Check the atom order (it must be the molecule's), that
    /// the geometry belongs to this molecule, and for a rigid or partly frozen molecule that the
    /// frozen distances and angles match; or raise the tolerance to accept the least-squares
    /// fit.
    #[error(
        "the positions are not representable by the internal coordinates of {molecule}: the \
         mass-weighted rms residual of the best fit is {residual:e} bohr, above the tolerance \
         {tolerance:e} bohr (largest misfit at atom {worst_atom}: {worst_atom_residual:e} bohr; \
         check the atom order and the geometry)"
    )]
    NotRepresentable {
        /// The molecule's name.
        molecule: &'static str,
        /// The fitted mass-weighted RMS residual, bohr.
        residual: f64,
        /// [`FitOptions::residual_tolerance`], bohr.
        tolerance: f64,
        /// The index of the atom with the largest residual.
        worst_atom: usize,
        /// That atom's residual distance, bohr.
        worst_atom_residual: f64,
        /// The fitted internal coordinates, atomic units.
        q: Vec<f64>,
    },
    /// The positions fit only with an improper rotation (a reflection): the labels' handedness is
    /// opposite to the definition's, so that, e.g. for CH4 or NH3, any proper fit needs negative
    /// bond lengths or angles outside [0, π]. Swap the labels of two equivalent atoms.
    #[error(
        "the positions are not representable with this labelling: mirror image (the labels' \
         handedness is opposite to the definition's of {molecule}); swap two equivalent labels"
    )]
    MirrorImage {
        /// The molecule's name.
        molecule: &'static str,
    },
    /// The best fit reproduces the positions only with a coordinate outside its valid range
    /// ([`crate::molecule::Coordinate::range`]).
    #[error(
        "the positions of {molecule} fit only with {coordinate} = {value} outside its valid range \
         [{low}, {high}] (atomic units); check the atom labels and the geometry"
    )]
    OutOfRange {
        /// The molecule's name.
        molecule: &'static str,
        /// The coordinate out of its range.
        coordinate: &'static str,
        /// Its fitted value, atomic units.
        value: f64,
        /// The range's lower end, atomic units.
        low: f64,
        /// The range's upper end, atomic units.
        high: f64,
    },
    /// The orientation is at the gimbal lock of the z-x-z Euler angles: `|sin θ| <`
    /// [`MIN_SIN_THETA`]. Rotate the input (positions and velocities) as a whole, e.g. by 90°
    /// about the lab x axis, to move away from it.
    #[error(
        "the orientation has euler angle θ = {theta} rad, too close to 0 or π (|sin θ| < \
         {MIN_SIN_THETA:e}): the z-x-z angles are degenerate there (gimbal lock); rotate the \
         input as a whole, e.g. by 90° about the lab x axis"
    )]
    EulerSingular {
        /// The Euler angle θ, rad.
        theta: f64,
    },
    /// Gauss–Newton did not converge within [`FitOptions::max_iterations`] steps, or no
    /// step along its direction decreased the residual. Give a starting geometry closer to the
    /// answer in [`FitOptions::initial_q`], or allow more iterations.
    #[error(
        "the position fit did not converge in {iterations} gauss-newton steps (mass-weighted rms \
         residual {residual:e} bohr, last step {step:e} bohr); start from a closer \
         FitOptions::initial_q or allow more iterations"
    )]
    NotConverged {
        /// Steps taken.
        iterations: usize,
        /// The mass-weighted RMS residual reached, bohr.
        residual: f64,
        /// The mass-weighted RMS displacement of the last full step, bohr.
        step: f64,
    },
    /// The kinetic metric `[[I, A], [Aᵀ, a]]` (the normal matrix of the fit, and the metric of
    /// the velocities) is singular at `q`: the molecule is linear there, atoms coincide, or the
    /// coordinates are redundant.
    #[error("the {matrix} is singular or not positive definite at q = {q:?}")]
    SingularMetric {
        /// Which block.
        matrix: MetricBlock,
        /// The internal coordinates, atomic units.
        q: Vec<f64>,
    },
    /// An input or an intermediate result is NaN or infinite.
    #[error("non-finite {quantity}")]
    NonFinite {
        /// What was not finite, e.g. `"lab positions"`.
        quantity: &'static str,
    },
    /// No starting geometry: the molecule's definition has no reference for every coordinate
    /// and [`FitOptions::initial_q`] is `None`. Give one.
    #[error("{molecule} has no reference geometry to start the fit from; set FitOptions::initial_q")]
    NoInitialGeometry {
        /// The molecule's name.
        molecule: &'static str,
    },
    /// A [`FitOptions`] value cannot be used (a tolerance that is NaN or negative, …).
    #[error("invalid fit options: {reason}")]
    InvalidOptions {
        /// What is wrong.
        reason: &'static str,
    },
    /// The molecule's coordinates have no closed forms q(x) (its definition gives positions
    /// rather than coordinates by kind).
    #[error("{molecule} has no closed-form internal coordinates q(x) (declare its coordinates by kind)")]
    NoClosedForms {
        /// The molecule's name.
        molecule: &'static str,
    },
    /// At a singular geometry, the momenta `(J, p)` are not in the range of the kinetic metric:
    /// angular momentum about the axis of a linear molecule, which no motion of the atoms carries.
    #[error(
        "the momenta (J, p) are not those of any motion of the atoms at this singular geometry (residual \
         {residual:e} of {momentum:e}): a linear molecule carries no angular momentum about its axis"
    )]
    NotInRange {
        /// `|M v − (J, p)|` of the least-squares solution.
        residual: f64,
        /// `|(J, p)|`.
        momentum: f64,
    },
    /// Any other failure to evaluate the Hamiltonian's quantities at a phase state.
    #[error(transparent)]
    Hamiltonian(HamiltonianError),
}

impl From<HamiltonianError> for FrameError {
    fn from(e: HamiltonianError) -> Self {
        match e {
            HamiltonianError::EulerSingular { theta } => Self::EulerSingular { theta },
            HamiltonianError::SingularMetric { matrix, q } => Self::SingularMetric { matrix, q },
            HamiltonianError::NonFinite { quantity } => Self::NonFinite { quantity },
            other => Self::Hamiltonian(other),
        }
    }
}

/// The lab-frame positions and velocities of a phase state with its centre of mass `com`:
///
/// ```text
/// x_i = X + R(Ω) R_i(q),     v_i = V + R(Ω) (ω × R_i + Σ_j ∂R_i/∂q_j q̇_j),
/// ```
///
/// with `(ω, q̇)` from [`velocities`] (`ω = G11 J + G12 p`, `q̇ = G12ᵀ J + G22 p`).
///
/// # Errors
///
/// Those of [`velocities`]: [`FrameError::EulerSingular`] at gimbal lock (J = W p_e is
/// undefined there), [`FrameError::SingularMetric`], [`FrameError::NonFinite`] (also for a
/// non-finite `com` or molecule output).
pub fn to_lab<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
    com: &CentreOfMass,
) -> Result<LabState<NA>, FrameError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let (omega, qdot) = velocities(molecule, state)?;
    lab_state(molecule, &state.q, &rotation_matrix(&state.euler), &omega, &qdot, com)
}

/// [`to_lab`] for a state of the body formulation ([`BodyState`]: orientation as a quaternion,
/// body-frame `J`), which has no singular orientation: works through gimbal lock.
pub fn to_lab_body<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &BodyState<N>,
    com: &CentreOfMass,
) -> Result<LabState<NA>, FrameError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let mut k = KineticMatrices::default();
    molecule.kinetic(&state.q, &mut k);
    let (omega, qdot) = MetricFactor::new(&k, &state.q)?.solve(&state.j, &state.p);
    lab_state(molecule, &state.q, &state.rotation(), &omega, &qdot, com)
}

/// `x_i = X + R R_i(q)`, `v_i = V + R (ω × R_i + Σ_j ∂R_i/∂q_j q̇_j)`.
fn lab_state<M, const N: usize, const NA: usize>(
    molecule: &M,
    q: &SVector<f64, N>,
    rotation: &Matrix3<f64>,
    omega: &Vector3<f64>,
    qdot: &SVector<f64, N>,
    com: &CentreOfMass,
) -> Result<LabState<NA>, FrameError>
where
    M: Molecule<N, NA> + ?Sized,
{
    if !(com.position.iter().chain(com.velocity.iter()).all(|x| x.is_finite())) {
        return Err(FrameError::NonFinite { quantity: "centre-of-mass position or velocity" });
    }
    let mut r = SMatrix::<f64, 3, NA>::zeros();
    molecule.positions(q, &mut r);
    let mut dr = [SMatrix::<f64, 3, NA>::zeros(); N];
    molecule.positions_jacobian(q, &mut dr);

    let mut lab = LabState::<NA>::default();
    for i in 0..NA {
        let ri: Vector3<f64> = r.column(i).into();
        let mut u = omega.cross(&ri);
        for (j, drj) in dr.iter().enumerate() {
            u += drj.column(i) * qdot[j];
        }
        lab.positions.set_column(i, &(com.position + rotation * ri));
        lab.velocities.set_column(i, &(com.velocity + rotation * u));
    }
    match lab.is_finite() {
        (true, true) => Ok(lab),
        _ => Err(FrameError::NonFinite { quantity: "body-frame positions R_i(q) or their jacobian" }),
    }
}

/// The lab-frame angular momentum `L = R(Ω) J` of a phase state (`J = W p_e`), in ħ.
///
/// Equal to [`LabState::angular_momentum`] of the state's [`to_lab`] image; conserved along a
/// trajectory. Fails like [`body_angular_momentum`] (gimbal lock, non-finite input).
pub fn lab_angular_momentum<const N: usize>(state: &PhaseState<N>) -> Result<Vector3<f64>, FrameError> {
    Ok(rotation_matrix(&state.euler) * body_angular_momentum(state)?)
}

/// The proper rotation nearest to `c` in the Frobenius norm: `U diag(1, 1, det(U Vᵀ)) Vᵀ` from
/// the SVD `c = U Σ Vᵀ`. For `c = Σ m_i y_i R_iᵀ` this is the mass-weighted Kabsch rotation (it
/// maximises `tr(Rᵀ c) = Σ m_i y_i · R R_i`); for a nearly orthogonal `c` it re-orthonormalises.
/// The det correction flips the axis of the smallest singular value, which is what keeps the
/// result proper for a planar molecule (one singular value zero).
pub(crate) fn nearest_rotation(c: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let svd = c.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    // nalgebra does not sort singular values; find the smallest to flip.
    let smallest = svd.singular_values.imin();
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(smallest, smallest)] = -1.0;
    }
    Some(u * d * v_t)
}

/// `S = Σ m_i |y_i − R R_i(q)|²` and the body-frame residuals `e_i = Rᵀ y_i − R_i(q)`.
fn residuals<M, const N: usize, const NA: usize>(
    molecule: &M,
    masses: &[f64; NA],
    y: &SMatrix<f64, 3, NA>,
    rotation: &Matrix3<f64>,
    q: &SVector<f64, N>,
    r: &mut SMatrix<f64, 3, NA>,
) -> (f64, SMatrix<f64, 3, NA>)
where
    M: Molecule<N, NA> + ?Sized,
{
    molecule.positions(q, r);
    // Rᵀ y_i − R_i has the same length as y_i − R R_i (R is orthogonal).
    let e = rotation.transpose() * y - *r;
    let s = (0..NA).map(|i| masses[i] * e.column(i).norm_squared()).sum();
    (s, e)
}

/// The phase state, centre of mass and fit report of a lab-frame state: the inverse of
/// [`to_lab`], by the mass-weighted least-squares fit and velocity projection described in the
/// [module documentation](self).
///
/// # Errors
///
/// * [`FrameError::NonFinite`]: NaN or ±∞ in the input (or in the molecule's output);
/// * [`FrameError::InvalidOptions`], [`FrameError::NoInitialGeometry`];
/// * [`FrameError::SingularMetric`]: the kinetic metric is singular at a geometry of the fit;
/// * [`FrameError::NotConverged`]: Gauss–Newton did not converge;
/// * [`FrameError::NotRepresentable`]: the fitted residual is above the tolerance;
/// * [`FrameError::EulerSingular`]: the fitted orientation is at gimbal lock.
pub fn from_lab<M, const N: usize, const NA: usize>(
    molecule: &M,
    lab: &LabState<NA>,
    options: &FitOptions<N>,
) -> Result<(PhaseState<N>, CentreOfMass, FitReport), FrameError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let (body, com, report) = from_lab_body(molecule, lab, options)?;
    let euler = euler_angles(&body.rotation());
    if euler[1].sin().abs() < MIN_SIN_THETA {
        return Err(FrameError::EulerSingular { theta: euler[1] });
    }
    let state = PhaseState { q: body.q, p: body.p, euler, pe: euler_momenta_from_angular_momentum(&euler, &body.j) };
    if state.check_finite().is_err() {
        return Err(FrameError::NonFinite { quantity: "fitted phase state" });
    }
    Ok((state, com, report))
}

/// [`from_lab`] in the body formulation: the orientation as a unit quaternion and the
/// body-frame `J`, which are defined at every orientation, so that a fitted rotation with
/// θ = 0 or π (e.g. positions given in the molecule's own body frame) is not an error. The
/// errors are those of [`from_lab`] except [`FrameError::EulerSingular`].
pub fn from_lab_body<M, const N: usize, const NA: usize>(
    molecule: &M,
    lab: &LabState<NA>,
    options: &FitOptions<N>,
) -> Result<(BodyState<N>, CentreOfMass, FitReport), FrameError>
where
    M: Molecule<N, NA> + ?Sized,
{
    match lab.is_finite() {
        (false, _) => return Err(FrameError::NonFinite { quantity: "lab positions" }),
        (_, false) => return Err(FrameError::NonFinite { quantity: "lab velocities" }),
        _ => {}
    }
    if options.residual_tolerance.is_nan() || options.residual_tolerance < 0.0 {
        return Err(FrameError::InvalidOptions { reason: "residual_tolerance must be non-negative" });
    }
    if !(options.step_tolerance > 0.0 && options.step_tolerance.is_finite()) {
        return Err(FrameError::InvalidOptions { reason: "step_tolerance must be positive and finite" });
    }
    let q = match options.initial_q {
        Some(q) => q,
        None => molecule.reference_geometry().ok_or(FrameError::NoInitialGeometry { molecule: molecule.name() })?,
    };
    if !q.iter().all(|x| x.is_finite()) {
        return Err(FrameError::NonFinite { quantity: "initial internal coordinates" });
    }

    let masses = molecule.masses();
    let total_mass: f64 = masses.iter().sum();
    let com = lab.centre_of_mass(&masses);
    // Positions relative to the centre of mass: the parametrization's R_i(q) has Σ m_i R_i = 0,
    // so translation is already optimal here and never enters the fit.
    let mut y = lab.positions;
    for i in 0..NA {
        y.set_column(i, &(lab.positions.column(i) - com.position));
    }
    // Far from the origin, subtracting the centre of mass leaves rounding of about ε·|x| in
    // every position, and no step can be smaller than that: the step tolerance is relative to
    // the size of the input as well as absolute.
    let scale = lab.positions.amax();
    let step_tolerance = options.step_tolerance.max(64.0 * f64::EPSILON * scale);
    let rms = |s: f64| (s.max(0.0) / total_mass).sqrt();

    // Coordinates declared by kind have closed forms q(x): no iteration (and no metric, so this
    // works at a linear geometry too). Otherwise Gauss–Newton.
    let fit_at = |y: &SMatrix<f64, 3, NA>| match closed_form_fit(molecule, &masses, y, &q) {
        Some(f) => f,
        None => fit_positions(molecule, &masses, y, q, step_tolerance, options.max_iterations),
    };
    let fit = fit_at(&y);
    let good = |f: &PositionFit<N, NA>| rms(f.s) <= options.residual_tolerance && molecule.in_range(&f.q).is_ok();
    let fit = match fit {
        Ok(f) if good(&f) => f,
        other => {
            // The labels may describe the mirror image of what the definition can represent (a
            // chiral parametrization, e.g. CH4's or NH3's, with two equivalent atoms swapped):
            // then the best proper rotation either leaves a residual, meets a singular metric on
            // the way (the molecule flattening), or fits only with coordinates outside their
            // ranges (negative bond lengths), while the inverted input fits. Inversion is
            // improper, so fitting −y tests every improper superposition at once.
            let mirrored = fit_at(&(-y));
            if mirrored.as_ref().is_ok_and(good) {
                return Err(FrameError::MirrorImage { molecule: molecule.name() });
            }
            let f = other?;
            if let Err(k) = molecule.in_range(&f.q) {
                let c = &molecule.coordinates()[k];
                return Err(FrameError::OutOfRange {
                    molecule: molecule.name(),
                    coordinate: c.name,
                    value: f.q[k],
                    low: c.range.0,
                    high: c.range.1,
                });
            }
            f
        }
    };
    let PositionFit { rotation, q, s, e, iterations, r } = fit;

    // 4. Representable?
    let residual = rms(s);
    if residual > options.residual_tolerance {
        let (worst_atom, worst_atom_residual) = (0..NA)
            .map(|i| (i, e.column(i).norm()))
            .fold((0, 0.0), |best, cur| if cur.1 > best.1 { cur } else { best });
        return Err(FrameError::NotRepresentable {
            molecule: molecule.name(),
            residual,
            tolerance: options.residual_tolerance,
            worst_atom,
            worst_atom_residual,
            q: q.iter().copied().collect(),
        });
    }

    // Velocities: body frame, centre-of-mass motion removed, then projected onto (J, p).
    let mut dr = [SMatrix::<f64, 3, NA>::zeros(); N];
    molecule.positions_jacobian(&q, &mut dr);
    let mut u = lab.velocities;
    for i in 0..NA {
        u.set_column(i, &(rotation.transpose() * (lab.velocities.column(i) - com.velocity)));
    }
    let (j, p) = projections(&masses, &r, &dr, &u);
    let orientation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rotation));
    let state = BodyState { q, p, orientation, j };

    // What the projection discarded: u_i minus the velocity field of (ω, q̇) = M⁻¹ (J, p).
    let mut kinetic = KineticMatrices::<N>::default();
    molecule.kinetic(&q, &mut kinetic);
    let g = InverseMetric::new(&kinetic, &q)?.g;
    let omega = g.g11 * j + g.g12 * p;
    let qdot = g.g12.transpose() * j + g.g22 * p;
    let mut discarded = 0.0;
    for i in 0..NA {
        let ri: Vector3<f64> = r.column(i).into();
        let mut fitted = omega.cross(&ri);
        for (k, drk) in dr.iter().enumerate() {
            fitted += drk.column(i) * qdot[k];
        }
        discarded += masses[i] * (u.column(i) - fitted).norm_squared();
    }
    let report = FitReport {
        iterations,
        position_residual: residual,
        velocity_residual: rms(discarded),
        discarded_kinetic_energy: 0.5 * discarded,
    };
    let finite = state.q.iter().chain(state.p.iter()).chain(state.j.iter()).all(|x| x.is_finite());
    if !finite || !report.velocity_residual.is_finite() {
        return Err(FrameError::NonFinite { quantity: "fitted phase state" });
    }
    Ok((state, com, report))
}

/// The body-formulation state of a lab state for a molecule whose coordinates have closed forms,
/// with no metric: `q = q(x)` (each angle on the branch nearest `near`), the Kabsch orientation,
/// `J = Σ m_i R_i × u_i` and `p_j = Σ m_i ∂R_i/∂q_j · u_i` with `u_i` the body-frame velocities
/// about the centre of mass. Unlike [`from_lab_body`] it works at a singular geometry (a linear
/// molecule: the momenta are projections, defined everywhere); the Cartesian chart of
/// [`crate::charts`] converts back with it. Returns the state and the centre of mass.
///
/// # Errors
///
/// [`FrameError::NoClosedForms`] for a molecule without closed forms, [`FrameError::NonFinite`],
/// and [`FrameError::NotRepresentable`] if the positions do not fit (RMS above 1e-6 bohr).
pub fn body_of_lab_exact<M, const N: usize, const NA: usize>(
    molecule: &M,
    lab: &LabState<NA>,
    near: &SVector<f64, N>,
) -> Result<(BodyState<N>, CentreOfMass), FrameError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let masses = molecule.masses();
    let total_mass: f64 = masses.iter().sum();
    let com = lab.centre_of_mass(&masses);
    let mut y = lab.positions;
    for i in 0..NA {
        y.set_column(i, &(lab.positions.column(i) - com.position));
    }
    let fit = closed_form_fit(molecule, &masses, &y, near)
        .ok_or(FrameError::NoClosedForms { molecule: molecule.name() })??;
    let residual = (fit.s.max(0.0) / total_mass).sqrt();
    if residual.is_nan() || residual > 1e-6 {
        return Err(FrameError::NotRepresentable {
            molecule: molecule.name(),
            residual,
            tolerance: 1e-6,
            worst_atom: 0,
            worst_atom_residual: residual,
            q: fit.q.iter().copied().collect(),
        });
    }
    let mut dr = [SMatrix::<f64, 3, NA>::zeros(); N];
    molecule.positions_jacobian(&fit.q, &mut dr);
    let mut u = lab.velocities;
    for i in 0..NA {
        u.set_column(i, &(fit.rotation.transpose() * (lab.velocities.column(i) - com.velocity)));
    }
    let (j, p) = projections(&masses, &fit.r, &dr, &u);
    let orientation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(fit.rotation));
    let state = BodyState { q: fit.q, p, orientation, j };
    if !state.q.iter().chain(state.p.iter()).chain(state.j.iter()).all(|x| x.is_finite()) {
        return Err(FrameError::NonFinite { quantity: "body state of the lab state" });
    }
    Ok((state, com))
}

/// [`to_lab_body`], also at a singular geometry: there `(ω, q̇)` solves `M (ω, q̇) = (J, p)` by the
/// metric's pseudo-inverse (the null direction, the spin about a linear molecule's axis, moves no
/// atom, so the lab velocities are unique). Fails with [`FrameError::NotInRange`] if `(J, p)` is
/// not in the metric's range (angular momentum about the axis of a linear molecule).
pub fn lab_of_body_any<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &BodyState<N>,
    com: &CentreOfMass,
) -> Result<LabState<NA>, FrameError>
where
    M: Molecule<N, NA> + ?Sized,
{
    match to_lab_body(molecule, state, com) {
        Err(FrameError::SingularMetric { .. }) => {}
        other => return other,
    }
    let mut k = KineticMatrices::<N>::default();
    molecule.kinetic(&state.q, &mut k);
    let d = 3 + N;
    let metric = nalgebra::DMatrix::<f64>::from_fn(d, d, |r, c| match (r < 3, c < 3) {
        (true, true) => k.inertia[(r, c)],
        (true, false) => k.coriolis[(r, c - 3)],
        (false, true) => k.coriolis[(c, r - 3)],
        (false, false) => k.a[(r - 3, c - 3)],
    });
    let rhs = nalgebra::DVector::<f64>::from_iterator(d, state.j.iter().chain(state.p.iter()).copied());
    let scale = metric.amax();
    let svd = metric.clone().svd(true, true);
    let v = svd
        .solve(&rhs, 1e-10 * scale)
        .map_err(|_| FrameError::NonFinite { quantity: "pseudo-inverse of the metric" })?;
    let residual = (&metric * &v - &rhs).norm();
    if residual.is_nan() || residual > 1e-9 * rhs.norm().max(f64::MIN_POSITIVE) {
        return Err(FrameError::NotInRange { residual, momentum: rhs.norm() });
    }
    let omega = Vector3::new(v[0], v[1], v[2]);
    let qdot = SVector::<f64, N>::from_iterator(v.iter().skip(3).copied());
    lab_state(molecule, &state.q, &state.rotation(), &omega, &qdot, com)
}

/// The result of the Gauss–Newton position fit: the rotation, `q`, `S`, the body-frame residuals
/// `e_i`, the steps taken and `R_i(q)`.
struct PositionFit<const N: usize, const NA: usize> {
    rotation: Matrix3<f64>,
    q: SVector<f64, N>,
    s: f64,
    e: SMatrix<f64, 3, NA>,
    iterations: usize,
    r: SMatrix<f64, 3, NA>,
}

/// The fit of the centre-of-mass positions `y` for a molecule whose coordinates have closed
/// forms ([`Kinematics::internal_coordinates`](crate::molecule::Kinematics::internal_coordinates)): `q = q(y)`, each angle moved by a multiple of 2π
/// to the value nearest `start` (a dihedral keeps its branch), then the Kabsch rotation of
/// `R_i(q)` onto `y`. `None` for a molecule without closed forms.
fn closed_form_fit<M, const N: usize, const NA: usize>(
    molecule: &M,
    masses: &[f64; NA],
    y: &SMatrix<f64, 3, NA>,
    start: &SVector<f64, N>,
) -> Option<Result<PositionFit<N, NA>, FrameError>>
where
    M: Molecule<N, NA> + ?Sized,
{
    let mut q = SVector::<f64, N>::zeros();
    if !molecule.internal_coordinates(y, &mut q) {
        return None;
    }
    for (k, c) in molecule.coordinates().iter().enumerate() {
        if matches!(c.unit, crate::units::CoordinateUnit::Angle(_)) {
            let tau = std::f64::consts::TAU;
            let shifted = q[k] + tau * ((start[k] - q[k]) / tau).round();
            // Keep the shift only if it stays valid (a bond angle stays in [0, π]).
            if c.contains(shifted) {
                q[k] = shifted;
            }
        }
    }
    if !q.iter().all(|x| x.is_finite()) {
        return Some(Err(FrameError::NonFinite { quantity: "internal coordinates of the positions" }));
    }
    let mut r = SMatrix::<f64, 3, NA>::zeros();
    molecule.positions(&q, &mut r);
    let mut c = Matrix3::zeros();
    for i in 0..NA {
        c += y.column(i) * r.column(i).transpose() * masses[i];
    }
    let Some(rotation) = nearest_rotation(&c) else {
        return Some(Err(FrameError::NonFinite { quantity: "kabsch rotation" }));
    };
    let (s, e) = residuals(molecule, masses, y, &rotation, &q, &mut r);
    Some(Ok(PositionFit { rotation, q, s, e, iterations: 0, r }))
}

/// Steps 1–3 of the fit (module documentation) of the centre-of-mass positions `y`, from `q`.
fn fit_positions<M, const N: usize, const NA: usize>(
    molecule: &M,
    masses: &[f64; NA],
    y: &SMatrix<f64, 3, NA>,
    mut q: SVector<f64, N>,
    step_tolerance: f64,
    max_iterations: usize,
) -> Result<PositionFit<N, NA>, FrameError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let total_mass: f64 = masses.iter().sum();
    // 1. Kabsch start: the best rotation for the starting geometry.
    let mut r = SMatrix::<f64, 3, NA>::zeros();
    molecule.positions(&q, &mut r);
    if !r.iter().all(|x| x.is_finite()) {
        return Err(FrameError::NonFinite { quantity: "body-frame positions R_i(q)" });
    }
    let mut c = Matrix3::zeros();
    for i in 0..NA {
        c += y.column(i) * r.column(i).transpose() * masses[i];
    }
    let mut rotation = nearest_rotation(&c).ok_or(FrameError::NonFinite { quantity: "kabsch rotation" })?;

    // 2. Gauss–Newton on (δθ, δq) with the kinetic metric as the normal matrix.
    let mut kinetic = KineticMatrices::<N>::default();
    let mut dr = [SMatrix::<f64, 3, NA>::zeros(); N];
    let (mut s, mut e) = residuals(molecule, masses, y, &rotation, &q, &mut r);
    let rms = |s: f64| (s.max(0.0) / total_mass).sqrt();
    let mut iterations = 0;
    loop {
        if !s.is_finite() {
            return Err(FrameError::NonFinite { quantity: "position residual of the fit" });
        }
        molecule.kinetic(&q, &mut kinetic);
        molecule.positions_jacobian(&q, &mut dr);
        let metric = InverseMetric::new(&kinetic, &q)?;
        let (b_rot, b_vib) = projections(masses, &r, &dr, &e);
        let g = &metric.g;
        let d_theta = g.g11 * b_rot + g.g12 * b_vib;
        let d_q = g.g12.transpose() * b_rot + g.g22 * b_vib;
        // δᵀ M δ = δᵀ b, since M δ = b: the squared mass-weighted displacement of the step.
        let last_step = rms(d_theta.dot(&b_rot) + d_q.dot(&b_vib));
        if !last_step.is_finite() {
            return Err(FrameError::NonFinite { quantity: "gauss-newton step of the fit" });
        }
        // A step this small means convergence; it is still applied (if it does not increase S),
        // so that the residual ends at rounding level rather than at the size of this step.
        let converged = last_step <= step_tolerance;
        if !converged && iterations == max_iterations {
            return Err(FrameError::NotConverged { iterations, residual: rms(s), step: last_step });
        }
        // Backtracking: the full step is right near the solution; far from it, or when the
        // residual is large, a shorter one may be needed for S to decrease.
        let mut factor = 1.0;
        let mut accepted = false;
        for _ in 0..if converged { 1 } else { 40 } {
            let step_rotation = Rotation3::new(d_theta * factor).into_inner();
            let trial_rotation = nearest_rotation(&(rotation * step_rotation))
                .ok_or(FrameError::NonFinite { quantity: "rotation of the fit" })?;
            let trial_q = q + d_q * factor;
            let (trial_s, trial_e) = residuals(molecule, masses, y, &trial_rotation, &trial_q, &mut r);
            if trial_s <= s {
                (rotation, q, s, e) = (trial_rotation, trial_q, trial_s, trial_e);
                accepted = true;
                break;
            }
            factor *= 0.5;
        }
        if accepted {
            // `r` holds R_i(q) of the accepted trial (the trials stop at the first accepted one).
            iterations += 1;
        } else {
            // `r` holds a rejected trial's positions; restore the current geometry's.
            molecule.positions(&q, &mut r);
        }
        if converged {
            break;
        }
        if !accepted {
            // No decrease at all along the Gauss–Newton direction, although the step is not
            // small: a saddle or a degenerate direction.
            return Err(FrameError::NotConverged { iterations, residual: rms(s), step: last_step });
        }
    }

    Ok(PositionFit { rotation, q, s, e, iterations, r })
}

/// `(Σ m_i R_i × w_i, Σ m_i ∂R_i/∂q_j · w_i)` of a body-frame field `w_i`: the projections of
/// `w` onto the rotational and vibrational displacement fields. For residuals they are the
/// right-hand side of the fit's normal equations; for velocities they are `(J, p)`.
pub(crate) fn projections<const N: usize, const NA: usize>(
    masses: &[f64; NA],
    r: &SMatrix<f64, 3, NA>,
    dr: &[SMatrix<f64, 3, NA>; N],
    w: &SMatrix<f64, 3, NA>,
) -> (Vector3<f64>, SVector<f64, N>) {
    let mut rot = Vector3::zeros();
    let mut vib = SVector::zeros();
    for i in 0..NA {
        let wi: Vector3<f64> = w.column(i) * masses[i];
        rot += r.column(i).cross(&wi);
        for (j, drj) in dr.iter().enumerate() {
            vib[j] += drj.column(i).dot(&wi);
        }
    }
    (rot, vib)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_angles_invert_rotation_matrix() {
        for euler in [
            Vector3::new(0.3, 1.1, -2.0),
            Vector3::new(-3.0, 0.01, 3.1),
            Vector3::new(2.5, 3.1, -0.4),
            Vector3::new(0.0, std::f64::consts::FRAC_PI_2, 0.0),
        ] {
            let back = euler_angles(&rotation_matrix(&euler));
            assert!((back - euler).amax() < 1e-13, "{euler} -> {back}");
        }
        // Gimbal lock: only φ + ψ is defined, and the rotation is still reproduced.
        let locked = Vector3::new(0.4, 0.0, 0.7);
        let back = euler_angles(&rotation_matrix(&locked));
        assert_eq!(back[1], 0.0);
        assert!((rotation_matrix(&back) - rotation_matrix(&locked)).amax() < 1e-15);
    }

    #[test]
    fn nearest_rotation_is_proper_for_planar_point_sets() {
        // A reflection-like input (det < 0) of rank 2 still gives a proper rotation.
        let c = Matrix3::new(1.0, 0.0, 0.0, 0.0, -2.0, 0.0, 0.0, 0.0, 0.0);
        let r = nearest_rotation(&c).unwrap();
        assert!((r.determinant() - 1.0).abs() < 1e-14);
        assert!((r * r.transpose() - Matrix3::identity()).amax() < 1e-14);
    }
}
