//! The Hamiltonian of a molecule in internal coordinates plus Euler angles, and Hamilton's
//! equations, along three paths that compute the same numbers:
//!
//! | room | what it holds |
//! | --- | --- |
//! | [`gmatrix`] | the reference: W, the G matrices `G = M⁻¹` and their derivatives, formula by formula |
//! | [`fast`] | the fast right-hand side: one block factorization, one generated `∂T/∂q`, no G matrices |
//! | [`reduced`] | the production system: body formulation (quaternion, J), reduced to what a scene needs |
//! | [`body`] | the body formulation's state and the Legendre map `(J, p) = M (ω, q̇)` |
//! | [`lanes`] | the production right-hand side over lane types: one trajectory (`f64`) or several per SIMD vector |
//! | [`factor`] | the block factorization of the kinetic metric the fast paths solve with |
//! | [`metric`] | the inverse metric (G11, G12, G22) and its q-derivatives |
//! | [`euler`] | z-x-z Euler angles: rotation matrix, W and its derivatives |
//! | `state` | the phase-space state and its flat layout |
//! | `finite` | the finiteness checks all paths share |
//!
//! The face of the module re-exports what callers use: the G-matrix path's functions and
//! [`HamiltonianSystem`], the Euler-angle helpers, and the fast and reduced systems. All of them compute, in atomic units,
//!
//! ```text
//! H = ½ pᵀ G22(q) p + Jᵀ G12(q) p + ½ Jᵀ G11(q) J + U(q),   J = W(Ω_e) p_e        (1), (2)
//! ```
//!
//! # State layout
//!
//! A state is a [`PhaseState<N>`]; integrators see it flat, as `2N + 6` numbers
//! `[q_1 … q_N, p_1 … p_N, φ, θ, ψ, p_φ, p_θ, p_ψ]` ([`PhaseState::write_to`],
//! [`PhaseState::read_from`]). The right-hand side [`rhs`] returns the time derivative in the
//! same layout.
//!
//! # Units
//!
//! Atomic units throughout: q in bohr or rad, positions in bohr, masses in electron masses,
//! energies in hartree, time in ħ/E_h, angles in rad; momenta in ħ/bohr (for a length
//! coordinate) or ħ (for an angle and for `p_e`, `J`), with ħ = 1.
//!
//! # Euler angles
//!
//! `Ω_e = (φ, θ, ψ)` are z-x-z Euler angles: the body-to-lab rotation is
//! `R = Rz(φ) Rx(θ) Rz(ψ)` ([`euler::rotation_matrix`]), the body-frame angular velocity is
//! `ω = M Ω̇` ([`euler::angular_velocity_matrix`]) and `J = W p_e` with `W = M⁻ᵀ` (eq. 2,
//! [`euler::WMatrices`]). W is undefined where `sin θ = 0`; there every function fails with
//! [`HamiltonianError::EulerSingular`] rather than return infinities.
//!
//! # Errors and allocation
//!
//! Nothing here returns NaN silently: a state or a molecule result that is not finite, an
//! orientation at gimbal lock and a kinetic metric that is singular or not positive definite
//! are all [`HamiltonianError`]s. Evaluating the right-hand side does not allocate (fixed-size
//! matrices on the stack, the q-derivatives of the kinetic matrices in a [`Workspace`]); only
//! building an error does.

pub mod body;
pub mod euler;
pub mod factor;
mod factor_large;
pub mod fast;
mod finite;
pub mod gmatrix;
pub mod lanes;
pub mod metric;
pub mod reduced;
mod state;

pub use body::{BodyState, momenta_from_velocities, quaternion_of_euler};
pub use euler::{
    MIN_SIN_THETA, WMatrices, angular_momentum_from_euler_momenta, angular_velocity_matrix, euler_angles,
    euler_momenta_from_angular_momentum, rotation_matrix, w_matrix,
};
pub use factor::MetricFactor;
pub use fast::FastSystem;
pub use gmatrix::{
    Evaluation, HamiltonianSystem, Workspace, body_angular_momentum, evaluate, hamiltonian, rhs, velocities,
};
pub use metric::{GMatrices, InverseMetric, MetricBlock, PIVOT_TOLERANCE};
pub use reduced::{ReducedSystem, Reduction, ReductionError, RotationPart};
pub use state::PhaseState;

/// Why the Hamiltonian or its derivatives could not be evaluated.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HamiltonianError {
    /// `|sin θ| <` [`MIN_SIN_THETA`]: W of eq. (2) is undefined (gimbal lock).
    #[error(
        "the Euler angle θ = {theta} rad is too close to 0 or π (|sin θ| < {MIN_SIN_THETA:e}), \
         where W of eq. (2) is undefined (gimbal lock of the z-x-z angles)"
    )]
    EulerSingular {
        /// The offending θ, in rad.
        theta: f64,
    },
    /// A block of the kinetic metric is singular (within [`PIVOT_TOLERANCE`]) or not positive
    /// definite at this geometry.
    #[error("the {matrix} is singular or not positive definite at q = {q:?}")]
    SingularMetric {
        /// Which block.
        matrix: MetricBlock,
        /// The internal coordinates, in atomic units.
        q: Vec<f64>,
    },
    /// A block of the kinetic metric is positive definite but close enough to singular that the
    /// equations of motion lose accuracy: one of its relative Cholesky pivots (pivot over the
    /// block's scale, see [`PIVOT_TOLERANCE`]) is below the threshold a system was given (for
    /// example a triatomic bending to a linear geometry).
    #[error(
        "the {matrix} is ill-conditioned at q = {q:?}: a relative pivot is {pivot:.2e}, below the threshold \
         {threshold:.0e} (a near-linear or otherwise degenerate geometry)"
    )]
    IllConditionedMetric {
        /// Which block.
        matrix: MetricBlock,
        /// The internal coordinates, in atomic units.
        q: Vec<f64>,
        /// The smallest relative pivot of that block.
        pivot: f64,
        /// The threshold it fell below.
        threshold: f64,
    },
    /// An input or an intermediate result is NaN or infinite.
    #[error("non-finite {quantity}")]
    NonFinite {
        /// What was not finite, e.g. `"internal momenta p"` or `"potential gradient ∂U/∂q"`.
        quantity: &'static str,
    },
    /// A flat state slice has the wrong length.
    #[error("state has {found} components, expected {expected}")]
    DimensionMismatch {
        /// `2N + 6`.
        expected: usize,
        /// The length that was passed.
        found: usize,
    },
}
