//! The G-matrix path: W, the G matrices, H and Hamilton's equations, formula by formula.
//!
//! This is the reference implementation of the Hamiltonian (`docs/src/reference/equations.md`): it
//! forms the inverse metric `G = M⁻¹` and its q-derivatives and follows the derivation's
//! formulas one by one, for readability; the faster paths ([`super::fast`]) are tested against
//! it.
//!
//! ```text
//! H = ½ pᵀ G22(q) p + Jᵀ G12(q) p + ½ Jᵀ G11(q) J + U(q),   J = W(Ω_e) p_e        (1), (2)
//! ```
//!
//! # Euler angles
//!
//! `Ω_e = (φ, θ, ψ)` are z-x-z Euler angles: the body-to-lab rotation is
//! `R = Rz(φ) Rx(θ) Rz(ψ)` ([`super::euler::rotation_matrix`]), the body-frame angular velocity is
//! `ω = M Ω̇` ([`super::euler::angular_velocity_matrix`]) and `J = W p_e` with `W = M⁻ᵀ` (eq. 2,
//! [`super::euler::WMatrices`]). W is undefined where `sin θ = 0`; there every function fails with
//! [`HamiltonianError::EulerSingular`] rather than return infinities.
//!
//! # Equations of motion (eqs. 4–8, 16)
//!
//! ```text
//! q̇   =  ∂H/∂p   = G22 p + G12ᵀ J
//! ṗ_k = −∂H/∂q_k = −(½ pᵀ ∂G22 p + Jᵀ ∂G12 p + ½ Jᵀ ∂G11 J + ∂U/∂q_k)
//! Ω̇_e =  ∂H/∂p_e = Wᵀ (G11 J + G12 p) = Wᵀ ω
//! ṗ_e = −∂H/∂Ω_e = −((∂W/∂Ω_e) p_e) · ω,   with ∂H/∂φ = 0 exactly
//! ```
//!
//! `∂G/∂q_k` come from eqs. (9)–(14) ([`super::metric::InverseMetric::derivative`]). The seed's
//! eq. (15), which rewrites (14), is **not used**: as printed it puts a `G22 […] G22` product
//! (N × N) where `∂G11/∂q` (3 × 3) belongs, next to `A a⁻¹` (3 × N), so it is dimensionally
//! inconsistent; eq. (14) is, and the tests check it against finite differences.
//!
//! # Errors and allocation
//!
//! Nothing here returns NaN silently: a state or a molecule result that is not finite, an
//! orientation at gimbal lock and a kinetic metric that is singular or not positive definite
//! are all [`HamiltonianError`]s. Evaluating the right-hand side does not allocate (fixed-size
//! matrices on the stack, the q-derivatives of the kinetic matrices in a [`Workspace`]); only
//! building an error does.

use nalgebra::{SMatrix, SVector, Vector3};

use super::finite::{all_finite, check_rhs, finite};
use super::{GMatrices, HamiltonianError, InverseMetric, PhaseState, WMatrices, angular_momentum_from_euler_momenta};
use crate::integrate::OdeSystem;
use crate::molecule::{KineticMatrices, Molecule};

/// Scratch space for [`rhs`]: the kinetic matrices and their N q-derivatives.
///
/// Kept out of the stack frame because `[KineticMatrices<N>; N]` grows like N³ (about 240 kB
/// at N = 30); [`HamiltonianSystem`] allocates one when it is created.
#[derive(Clone, Debug)]
pub struct Workspace<const N: usize> {
    kinetic: KineticMatrices<N>,
    dkinetic: [KineticMatrices<N>; N],
}

impl<const N: usize> Default for Workspace<N> {
    fn default() -> Self {
        Self { kinetic: KineticMatrices::default(), dkinetic: [KineticMatrices::default(); N] }
    }
}

impl<const N: usize> Workspace<N> {
    /// A zeroed workspace on the heap (the one allocation a [`HamiltonianSystem`] makes).
    pub fn boxed() -> Box<Self> {
        Box::new(Self::default())
    }
}

/// What every quantity of the Hamiltonian needs: W, J, the G matrices, ω and q̇.
struct Kinematics<const N: usize> {
    w: WMatrices,
    j: Vector3<f64>,
    metric: InverseMetric<N>,
    omega: Vector3<f64>,
    qdot: SVector<f64, N>,
}

fn kinematics<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
    kinetic: &mut KineticMatrices<N>,
) -> Result<Kinematics<N>, HamiltonianError>
where
    M: Molecule<N, NA> + ?Sized,
{
    state.check_finite()?;
    let w = WMatrices::new(&state.euler)?;
    let j = w.w * state.pe;
    molecule.kinetic(&state.q, kinetic);
    let metric = InverseMetric::new(kinetic, &state.q)?;
    let g = &metric.g;
    let omega = g.g11 * j + g.g12 * state.p;
    let qdot = g.g12.transpose() * j + g.g22 * state.p;
    Ok(Kinematics { w, j, metric, omega, qdot })
}

/// The kinetic part of eq. (1), `T = ½ pᵀ G22 p + Jᵀ G12 p + ½ Jᵀ G11 J`; given `∂G/∂q_k`
/// instead of `G` it is the kinetic part of `∂H/∂q_k` in eq. (16).
fn kinetic_energy<const N: usize>(g: &GMatrices<N>, j: &Vector3<f64>, p: &SVector<f64, N>) -> f64 {
    0.5 * p.dot(&(g.g22 * p)) + j.dot(&(g.g12 * p)) + 0.5 * j.dot(&(g.g11 * j))
}

/// The Hamiltonian `H` of eq. (1), in hartree.
pub fn hamiltonian<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
) -> Result<f64, HamiltonianError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let mut kinetic = KineticMatrices::default();
    let kin = kinematics(molecule, state, &mut kinetic)?;
    let t = kinetic_energy(&kin.metric.g, &kin.j, &state.p);
    let u = finite(molecule.potential(&state.q), "potential U(q)")?;
    finite(t + u, "Hamiltonian H")
}

/// The right-hand side of Hamilton's equations (eqs. 4–8, 16): `(q̇, ṗ, Ω̇_e, ṗ_e)` as a
/// [`PhaseState`] of time derivatives. Does not allocate unless it fails.
///
/// `ṗ_φ` is exactly `0.0` (H does not depend on φ), so `p_φ` is conserved to the bit.
pub fn rhs<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
    workspace: &mut Workspace<N>,
) -> Result<PhaseState<N>, HamiltonianError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let kin = kinematics(molecule, state, &mut workspace.kinetic)?;
    let (j, p) = (&kin.j, &state.p);

    // ṗ = −∂H/∂q, eq. (16).
    let mut du = SVector::zeros();
    molecule.potential_gradient(&state.q, &mut du);
    if !all_finite(du.as_slice()) {
        return Err(HamiltonianError::NonFinite { quantity: "potential gradient ∂U/∂q" });
    }
    molecule.kinetic_jacobian(&state.q, &mut workspace.dkinetic);
    let dk_finite = workspace
        .dkinetic
        .iter()
        .all(|d| d.a.iter().chain(d.coriolis.iter()).chain(d.inertia.iter()).all(|x| x.is_finite()));
    if !dk_finite {
        return Err(HamiltonianError::NonFinite {
            quantity: "kinetic matrix derivatives ∂a/∂q, ∂A/∂q, ∂I/∂q"
        });
    }
    let mut pdot = SVector::zeros();
    for (k, dk) in workspace.dkinetic.iter().enumerate() {
        let dg = kin.metric.derivative(dk);
        pdot[k] = -(kinetic_energy(&dg, j, p) + du[k]);
    }

    // Ω̇_e = ∂H/∂p_e = Wᵀ (G11 J + G12 p) = Wᵀ ω, eq. (6).
    let euler_dot = kin.w.w.transpose() * kin.omega;
    // ∂H/∂Ω_e = ((∂W/∂Ω_e) p_e) · ω, eq. (5); ∂W/∂φ = 0, so ṗ_φ is a literal +0.0 (negating
    // a computed zero could give −0.0).
    let dh_dtheta = (kin.w.dw_dtheta * state.pe).dot(&kin.omega);
    let dh_dpsi = (kin.w.dw_dpsi * state.pe).dot(&kin.omega);
    let pe_dot = Vector3::new(0.0, -dh_dtheta, -dh_dpsi);

    let out = PhaseState { q: kin.qdot, p: pdot, euler: euler_dot, pe: pe_dot };
    check_rhs(&out)?;
    Ok(out)
}

/// The body-frame angular momentum `J = W p_e` of a state (eq. 2).
pub fn body_angular_momentum<const N: usize>(state: &PhaseState<N>) -> Result<Vector3<f64>, HamiltonianError> {
    let j = angular_momentum_from_euler_momenta(&state.euler, &state.pe)?;
    if all_finite(j.as_slice()) {
        Ok(j)
    } else {
        Err(HamiltonianError::NonFinite { quantity: "Euler momenta (p_φ, p_θ, p_ψ)" })
    }
}

/// The velocities of a state: the body-frame angular velocity `ω = G11 J + G12 p` and
/// `q̇ = G12ᵀ J + G22 p`.
pub fn velocities<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
) -> Result<(Vector3<f64>, SVector<f64, N>), HamiltonianError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let mut kinetic = KineticMatrices::default();
    let kin = kinematics(molecule, state, &mut kinetic)?;
    Ok((kin.omega, kin.qdot))
}

/// Everything `rovib eval` prints about one state.
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluation<const N: usize, const NA: usize> {
    /// Body-frame positions `R_i(q)` in bohr (column `i` is atom `i`).
    pub positions: SMatrix<f64, 3, NA>,
    /// `H`, in hartree.
    pub hamiltonian: f64,
    /// The potential energy `U(q)`, in hartree.
    pub potential: f64,
    /// The kinetic energy `H − U`, in hartree.
    pub kinetic_energy: f64,
    /// `a`, `A`, `I` at q.
    pub kinetic: KineticMatrices<N>,
    /// `G11`, `G12`, `G22` at q.
    pub g: GMatrices<N>,
    /// The body-frame angular momentum `J = W p_e`.
    pub angular_momentum: Vector3<f64>,
    /// The body-frame angular velocity `ω`.
    pub omega: Vector3<f64>,
    /// `q̇`.
    pub qdot: SVector<f64, N>,
    /// The right-hand side of Hamilton's equations.
    pub rhs: PhaseState<N>,
}

/// Evaluates everything in [`Evaluation`] at one state.
pub fn evaluate<M, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
) -> Result<Evaluation<N, NA>, HamiltonianError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let mut workspace = Workspace::boxed();
    let rhs = rhs(molecule, state, &mut workspace)?;
    let mut kinetic = KineticMatrices::default();
    let kin = kinematics(molecule, state, &mut kinetic)?;
    let kinetic_energy = kinetic_energy(&kin.metric.g, &kin.j, &state.p);
    let potential = finite(molecule.potential(&state.q), "potential U(q)")?;
    let hamiltonian = finite(kinetic_energy + potential, "Hamiltonian H")?;
    let mut positions = SMatrix::zeros();
    molecule.positions(&state.q, &mut positions);
    Ok(Evaluation {
        positions,
        hamiltonian,
        potential,
        kinetic_energy,
        kinetic,
        g: kin.metric.g,
        angular_momentum: kin.j,
        omega: kin.omega,
        qdot: kin.qdot,
        rhs,
    })
}

/// A molecule's Hamilton's equations as an [`OdeSystem`] on the flat state of [`PhaseState`]
/// (dimension `2N + 6`).
pub struct HamiltonianSystem<'a, M: ?Sized, const N: usize, const NA: usize> {
    molecule: &'a M,
    workspace: Box<Workspace<N>>,
}

impl<'a, M, const N: usize, const NA: usize> HamiltonianSystem<'a, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The system of `molecule`; allocates its [`Workspace`] once, here.
    pub fn new(molecule: &'a M) -> Self {
        Self { molecule, workspace: Workspace::boxed() }
    }

    /// The molecule.
    pub fn molecule(&self) -> &'a M {
        self.molecule
    }

    /// `H` of the flat state `y`, in hartree.
    pub fn energy(&self, y: &[f64]) -> Result<f64, HamiltonianError> {
        hamiltonian(self.molecule, &PhaseState::read_from(y)?)
    }

    /// Everything in [`Evaluation`] at the flat state `y`.
    pub fn evaluate(&self, y: &[f64]) -> Result<Evaluation<N, NA>, HamiltonianError> {
        evaluate(self.molecule, &PhaseState::read_from(y)?)
    }
}

impl<M, const N: usize, const NA: usize> OdeSystem for HamiltonianSystem<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    type Error = HamiltonianError;

    fn dim(&self) -> usize {
        PhaseState::<N>::DIM
    }

    /// `dydt = (q̇, ṗ, Ω̇_e, ṗ_e)` by [`rhs`]; `t` is unused (H does not depend on time).
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), HamiltonianError> {
        let state = PhaseState::read_from(y)?;
        let derivative = rhs(self.molecule, &state, &mut self.workspace)?;
        derivative.write_to(dydt)
    }
}
