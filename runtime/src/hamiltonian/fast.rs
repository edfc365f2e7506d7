//! The fast right-hand side: the same Hamilton's equations as the G-matrix path ([`super::rhs`]),
//! evaluated from one block factorization of the kinetic metric and one generated
//! kinetic-energy gradient, with no G matrices, no derivative of any inverse and no
//! `kinetic_jacobian`. The reduced systems that skip what a scene does not need (J = 0, frozen
//! internal coordinates) build on it in [`super::reduced`]; the factorization is in
//! [`super::factor`]. This module re-exports both, and the body state, under their old paths
//! (`hamiltonian::fast::{ReducedSystem, MetricFactor, BodyState, ...}`).
//!
//! # What it computes
//!
//! Per evaluation, at `(q, p, Ω_e, p_e)`:
//!
//! 1. `J = W p_e` (eq. 2), from `sin`/`cos` of θ and ψ directly (no `∂W/∂Ω_e` matrices);
//! 2. `a`, `A`, `I` ([`Kinematics::kinetic`](crate::molecule::Kinematics::kinetic)) and the block factorization of the full metric
//!    `M = [[I, A], [Aᵀ, a]]` ([`MetricFactor`]): `I⁻¹` (3 × 3, closed form), `Y = I⁻¹A`, and the
//!    Schur complement `S = a − Aᵀ I⁻¹ A = a − AᵀY = G22⁻¹ = L D Lᵀ` (Cholesky without square
//!    roots);
//! 3. the velocities `v = (ω, q̇) = M⁻¹ (J, p)`: `q̇ = S⁻¹ (p − YᵀJ)`, `ω = I⁻¹J − Y q̇`;
//! 4. `∂T/∂q` at fixed `(ω, q̇)` ([`Kinematics::kinetic_energy_gradient`](crate::molecule::Kinematics::kinetic_energy_gradient)) and `∂U/∂q`
//!    ([`Molecule::potential_gradient`]).
//!
//! Then
//!
//! ```text
//! q̇   = the solve above                      (= G12ᵀ J + G22 p, eq. 8)
//! ṗ   = ∂T/∂q|_(ω, q̇) − ∂U/∂q                (= −∂H/∂q, eq. 16; derivation below)
//! Ω̇_e = Wᵀ ω                                 (eq. 6)
//! ṗ_e = −((∂W/∂Ω_e) p_e) · ω,  ṗ_φ = +0.0     (eq. 5)
//! ```
//!
//! # Why `∂H/∂q_k = −½ vᵀ (∂M/∂q_k) v + ∂U/∂q_k`
//!
//! ```text
//! Eq. (1) with M⁻¹ = [[G11, G12], [G12ᵀ, G22]] (eq. 3) is
//!
//!     H(q, p, Ω_e, p_e) = ½ bᵀ M(q)⁻¹ b + U(q),    b = (J, p),  J = W(Ω_e) p_e.
//!
//! b does not depend on q (W depends on the Euler angles only, and q and p are independent
//! phase-space coordinates), so only M⁻¹ is differentiated, and by eq. (9)
//!
//!     ∂H/∂q_k = ½ bᵀ (∂M⁻¹/∂q_k) b + ∂U/∂q_k
//!             = −½ bᵀ M⁻¹ (∂M/∂q_k) M⁻¹ b + ∂U/∂q_k          (M symmetric: (M⁻¹b)ᵀ = bᵀM⁻¹)
//!             = −½ vᵀ (∂M/∂q_k) v + ∂U/∂q_k,                  v = M⁻¹ b.
//!
//! v = M⁻¹ b is (ω, q̇): its blocks are G11 J + G12 p = ω and G12ᵀ J + G22 p = ∂H/∂p = q̇
//! (eqs. 6, 8). And with T(q, v) = ½ vᵀ M(q) v = ½ Σ m_i |ω × R_i + Σ_j ∂R_i/∂q_j q̇_j|², the
//! kinetic energy as a function of the velocities,
//!
//!     ½ vᵀ (∂M/∂q_k) v = ∂T/∂q_k |_(ω, q̇ fixed),
//!
//! which is exactly what Kinematics::kinetic_energy_gradient returns. Hence
//!
//!     ṗ_k = −∂H/∂q_k = ∂T/∂q_k|_(ω, q̇) − ∂U/∂q_k.
//!
//! (This is the Legendre-transform identity ∂H/∂q|_p = −∂L/∂q|_q̇ for L = T − U.) Eqs. (10)–(16)
//! compute the same number as −½ vᵀ ∂M v by expanding ∂M⁻¹ block by block; the fast path
//! never forms M⁻¹, so it needs neither ∂G nor the N matrices ∂a/∂q_k, ∂A/∂q_k, ∂I/∂q_k.
//! Likewise ∂H/∂Ω_e = (∂b/∂Ω_e)ᵀ M⁻¹ b = ((∂W/∂Ω_e) p_e) · ω, which in closed form is
//!
//!     ∂H/∂φ = 0,
//!     ∂H/∂θ = (p_ψ − cos θ p_φ) / sin²θ · (sin ψ ω_x + cos ψ ω_y),
//!     ∂H/∂ψ = J_y ω_x − J_x ω_y               ((∂W/∂ψ) p_e = (J_y, −J_x, 0)).
//! ```
//!
//! # What it skips
//!
//! Compared with the G-matrix path: the N `kinetic_jacobian` matrices (O(N³) numbers), the
//! factorization of `a` and of `G11⁻¹`, the explicit inverses G11 and G22, and the N
//! derivative products of eqs. (10)–(14), each O(N³). What remains is O(N³/3) for the one
//! factorization of S and generated straight-line code for `kinetic`, `kinetic_energy_gradient`
//! and `potential_gradient`.
//!
//! The [`ReducedSystem`]s skip further, by scene:
//!
//! * **J = 0** ([`RotationPart::ZeroAngularMomentum`]): `ṗ_e` is linear in `p_e`, so `p_e = 0` stays
//!   exactly 0 and need not be integrated; `v = M⁻¹ (0, p)` skips the `I⁻¹J` and `YᵀJ`
//!   products, and there is no `∂W` work at all (no Euler-angle work either unless the
//!   orientation is integrated). The orientation is integrated only when asked for (lab-frame
//!   output): with `J = 0` the molecule still turns as it vibrates (`ω = −I⁻¹ A q̇ ≠ 0`), by
//!   `Ω̇_e = Wᵀ ω`.
//! * **Frozen internal coordinates** (a run-time mask): the kinetic metric is reduced on the
//!   *Lagrangian* side, i.e. the frozen rows and columns of `M` are dropped (a frozen
//!   coordinate has `q̇ = 0`, so it contributes nothing to `T = ½ vᵀ M v`). Inside the fixed-size
//!   N block this is done by replacing those rows and columns of `a` and those columns of `A`
//!   with identity/zero, so the same factorization gives `q̇_frozen = 0` exactly and the active
//!   block is `M_red⁻¹ (J, p_active)`. (Dropping rows and columns of `M⁻¹` instead would be a
//!   different and wrong model: it would keep the frozen coordinates moving.) The gradients
//!   come from the same generated functions (they evaluate every coordinate; the unused ones
//!   cost little because the generated code shares its subexpressions).
//!
//! # Equivalence and errors
//!
//! [`rhs`] returns the G-matrix path's numbers to rounding (tests: 1e-12 relative per block). It fails
//! with the same [`HamiltonianError`]s as the G-matrix path, checked in the same order: non-finite state,
//! gimbal lock ([`HamiltonianError::EulerSingular`]), non-finite kinetic matrices, a singular or
//! not positive definite metric ([`HamiltonianError::SingularMetric`]), non-finite potential
//! gradient, non-finite result. (Where the G-matrix path reports non-finite `∂a/∂q, ∂A/∂q, ∂I/∂q`, which
//! the fast path never computes, it reports a non-finite `∂T/∂q` instead.) For a metric that fails, the factorization only sees `I` and `S`;
//! on that (cold) path the G-matrix path's [`super::InverseMetric::new`] is run to name the block exactly as
//! the G-matrix path would (`I`, `a`, `G11⁻¹`, `G22⁻¹`). `M` is positive definite iff `I` and `S` are,
//! and then `a` and `G11⁻¹` are too, so the two paths can disagree only for a metric within
//! [`super::PIVOT_TOLERANCE`] of singular in `a` or `G11⁻¹` but not in `I` or `S`, where the fast path
//! returns numbers and the G-matrix path an error.
//!
//! # Allocation
//!
//! None: everything is fixed-size and on the stack (about `8 (2N² + 9N + 20)` bytes for the
//! kinetic matrices and the factor), so the systems need no workspace; only building an error
//! allocates. `N = 0` (a rigid molecule) works: every N-sized block is empty.
//!
//! # Cost
//!
//! Water (N = 3), one evaluation through [`OdeSystem::rhs`], counted by callgrind
//! (`ROVIB_RHS_PROFILE=PART` in `benches/rhs.rs`; instructions do not depend on the machine's
//! load): G-matrix path 10 325 instructions, fast path 2 117, production [`ReducedSystem`] 2 046, J = 0
//! 1 838; in time on the development machine (a shared 2-core AMD EPYC VM at 2.6 GHz) G-matrix path
//! ≈ 1.37 µs against ≈ 0.2 µs. The generated code is about half of the fast path, the
//! factorization and solve a fifth. The generated [`Kinematics::kinetic_and_gradient`](crate::molecule::Kinematics::kinetic_and_gradient) computes
//! the position terms (and every `sin_cos`) once for `a, A, I` and for `∂T/∂q`: 2 117
//! instructions against 2 394 with the two separate generated calls (`rhs/NAME/fast_unfused`).
//!
//! # Tests
//!
//! `tests/numerics/fast_path.rs` (for every shipped molecule): [`rhs`] against the G-matrix path's [`super::rhs`]
//! at random states; the J = 0 system against the G-matrix path restricted to `p_e = 0`; the frozen
//! system against central finite differences of its own Hamiltonian built independently (the
//! reduced metric with `DMatrix` and a general inverse); no allocation; and a DOP853 trajectory
//! of [`FastSystem`] against one of the G-matrix path's [`super::HamiltonianSystem`].

use nalgebra::{SVector, Vector3};

pub use super::body::{BodyState, momenta_from_velocities, quaternion_of_euler};
use super::euler::EulerTrig;
pub use super::factor::MetricFactor;
use super::finite::{all_finite, check_rhs, check_state, finite};
pub use super::reduced::{ReducedSystem, Reduction, ReductionError, RotationPart};
use super::{HamiltonianError, PhaseState};
use crate::integrate::OdeSystem;
use crate::molecule::{KineticMatrices, Molecule};

/// `(ω, q̇, ṗ)`.
type VelocitiesAndForce<const N: usize> = (Vector3<f64>, SVector<f64, N>, SVector<f64, N>);

/// The kinetic matrices, the velocities `(ω, q̇)` from `factor` (the caller's metric solve),
/// and the internal force `ṗ = ∂T/∂q|_(ω, q̇) − ∂U/∂q`, through the generated
/// [`Kinematics::kinetic_and_gradient`](crate::molecule::Kinematics::kinetic_and_gradient), which computes the position terms once for both halves.
/// Returns `(ω, q̇, ṗ)`.
#[inline(always)]
pub(super) fn velocities_and_force<M, const N: usize, const NA: usize>(
    molecule: &M,
    q: &SVector<f64, N>,
    factor: impl FnOnce(&KineticMatrices<N>) -> Result<(Vector3<f64>, SVector<f64, N>), HamiltonianError>,
) -> Result<VelocitiesAndForce<N>, HamiltonianError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let mut k = KineticMatrices::default();
    let mut dt = SVector::zeros();
    let (omega, qdot, _) = molecule.kinetic_and_gradient(q, &mut k, factor, &mut dt)?;
    if !all_finite(dt.as_slice()) {
        return Err(HamiltonianError::NonFinite { quantity: "kinetic energy gradient ∂T/∂q" });
    }
    let mut du = SVector::zeros();
    molecule.potential_gradient(q, &mut du);
    if !all_finite(du.as_slice()) {
        return Err(HamiltonianError::NonFinite { quantity: "potential gradient ∂U/∂q" });
    }
    Ok((omega, qdot, dt - du))
}

/// The right-hand side of Hamilton's equations, `(q̇, ṗ, Ω̇_e, ṗ_e)`, by the fast path (see the
/// module docs): the G-matrix path's [`super::rhs`] to rounding, with the same errors, no workspace and
/// no allocation unless it fails. `ṗ_φ` is exactly `+0.0`.
pub fn rhs<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
) -> Result<PhaseState<N>, HamiltonianError>
where
    M: Molecule<N, NA> + ?Sized,
{
    rhs_inline(molecule, state)
}

/// [`rhs`], always inlined so that [`FastSystem`] stores the results straight into the caller's
/// slice (returned through memory and copied with 16-byte loads, they stalled on
/// store-to-load forwarding: ~10 % of water's evaluation).
#[inline(always)]
fn rhs_inline<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
) -> Result<PhaseState<N>, HamiltonianError>
where
    M: Molecule<N, NA> + ?Sized,
{
    check_state(state)?;
    let e = EulerTrig::new(&state.euler)?;
    let j = e.j(&state.pe);
    let (omega, qdot, pdot) =
        velocities_and_force(molecule, &state.q, |k| Ok(MetricFactor::new(k, &state.q)?.solve(&j, &state.p)))?;
    let out =
        PhaseState { q: qdot, p: pdot, euler: e.euler_rates(&omega), pe: e.euler_momenta_rates(&state.pe, &j, &omega) };
    check_rhs(&out)?;
    Ok(out)
}

/// `H` by the fast path: `T = ½ v · (J, p) = ½ (ω · J + q̇ · p)` plus `U`, in hartree.
pub fn hamiltonian<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
) -> Result<f64, HamiltonianError>
where
    M: Molecule<N, NA> + ?Sized,
{
    check_state(state)?;
    let j = EulerTrig::new(&state.euler)?.j(&state.pe);
    let mut k = KineticMatrices::default();
    molecule.kinetic(&state.q, &mut k);
    let (omega, qdot) = MetricFactor::new(&k, &state.q)?.solve(&j, &state.p);
    let t = 0.5 * (omega.dot(&j) + qdot.dot(&state.p));
    let u = finite(molecule.potential(&state.q), "potential U(q)")?;
    finite(t + u, "Hamiltonian H")
}

/// The fast path as an [`OdeSystem`] on the phase-space flat layout
/// `[q, p, φ, θ, ψ, p_φ, p_θ, p_ψ]` (dimension `2N + 6`): a drop-in replacement for
/// [`super::HamiltonianSystem`] that needs no workspace.
pub struct FastSystem<'a, M: ?Sized, const N: usize, const NA: usize> {
    molecule: &'a M,
}

impl<'a, M, const N: usize, const NA: usize> FastSystem<'a, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The system of `molecule` (allocates nothing).
    pub fn new(molecule: &'a M) -> Self {
        Self { molecule }
    }

    /// The molecule.
    pub fn molecule(&self) -> &'a M {
        self.molecule
    }

    /// `H` of the flat state `y`, in hartree.
    pub fn energy(&self, y: &[f64]) -> Result<f64, HamiltonianError> {
        hamiltonian(self.molecule, &PhaseState::read_from(y)?)
    }
}

impl<M, const N: usize, const NA: usize> OdeSystem for FastSystem<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    type Error = HamiltonianError;

    fn dim(&self) -> usize {
        PhaseState::<N>::DIM
    }

    /// `dydt = (q̇, ṗ, Ω̇_e, ṗ_e)` by [`rhs`]; `t` is unused.
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), HamiltonianError> {
        let d = rhs_inline(self.molecule, &PhaseState::read_from(y)?)?;
        write_state(&d, dydt)
    }
}

/// [`PhaseState::write_to`] element by element (see [`rhs_inline`] for why).
#[inline(always)]
fn write_state<const N: usize>(s: &PhaseState<N>, y: &mut [f64]) -> Result<(), HamiltonianError> {
    if y.len() != PhaseState::<N>::DIM {
        return Err(HamiltonianError::DimensionMismatch { expected: PhaseState::<N>::DIM, found: y.len() });
    }
    for i in 0..N {
        y[i] = s.q[i];
        y[N + i] = s.p[i];
    }
    for i in 0..3 {
        y[2 * N + i] = s.euler[i];
        y[2 * N + 3 + i] = s.pe[i];
    }
    Ok(())
}
