//! The fast right-hand side: the same Hamilton's equations as the seed path ([`super::rhs`]),
//! evaluated from one block factorization of the kinetic metric and one generated
//! kinetic-energy gradient, with no G matrices, no derivative of any inverse and no
//! `kinetic_jacobian`; plus reduced systems that skip what a scene does not need (J = 0,
//! frozen internal coordinates).
//!
//! # What it computes
//!
//! Per evaluation, at `(q, p, Ω_e, p_e)`:
//!
//! 1. `J = W p_e` (eq. 2), from `sin`/`cos` of θ and ψ directly (no `∂W/∂Ω_e` matrices);
//! 2. `a`, `A`, `I` ([`Molecule::kinetic`]) and the block factorization of the full metric
//!    `M = [[I, A], [Aᵀ, a]]` ([`MetricFactor`]): `I⁻¹` (3 × 3, closed form), `Y = I⁻¹A`, and the
//!    Schur complement `S = a − Aᵀ I⁻¹ A = a − AᵀY = G22⁻¹ = L D Lᵀ` (Cholesky without square
//!    roots);
//! 3. the velocities `v = (ω, q̇) = M⁻¹ (J, p)`: `q̇ = S⁻¹ (p − YᵀJ)`, `ω = I⁻¹J − Y q̇`;
//! 4. `∂T/∂q` at fixed `(ω, q̇)` ([`Molecule::kinetic_energy_gradient`]) and `∂U/∂q`
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
//! which is exactly what Molecule::kinetic_energy_gradient returns. Hence
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
//! Compared with the seed path: the N `kinetic_jacobian` matrices (O(N³) numbers), the
//! factorization of `a` and of `G11⁻¹`, the explicit inverses G11 and G22, and the N
//! derivative products of eqs. (10)–(14), each O(N³). What remains is O(N³/3) for the one
//! factorization of S and generated straight-line code for `kinetic`, `kinetic_energy_gradient`
//! and `potential_gradient`.
//!
//! The [`ReducedSystem`]s skip further, by scene:
//!
//! * **J = 0** ([`Rotation::ZeroAngularMomentum`]): `ṗ_e` is linear in `p_e`, so `p_e = 0` stays
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
//! [`rhs`] returns the seed's numbers to rounding (tests: 1e-12 relative per block). It fails
//! with the same [`HamiltonianError`]s as the seed, checked in the same order: non-finite state,
//! gimbal lock ([`HamiltonianError::EulerSingular`]), non-finite kinetic matrices, a singular or
//! not positive definite metric ([`HamiltonianError::SingularMetric`]), non-finite potential
//! gradient, non-finite result. (Where the seed reports non-finite `∂a/∂q, ∂A/∂q, ∂I/∂q`, which
//! the fast path never computes, it reports a non-finite `∂T/∂q` instead.) For a metric that fails, the factorization only sees `I` and `S`;
//! on that (cold) path the seed's [`InverseMetric::new`] is run to name the block exactly as
//! the seed would (`I`, `a`, `G11⁻¹`, `G22⁻¹`). `M` is positive definite iff `I` and `S` are,
//! and then `a` and `G11⁻¹` are too, so the two paths can disagree only for a metric within
//! [`PIVOT_TOLERANCE`] of singular in `a` or `G11⁻¹` but not in `I` or `S`, where the fast path
//! returns numbers and the seed an error.
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
//! load): seed 10 325 instructions, fast path 2 117, production [`ReducedSystem`] 2 046, J = 0
//! 1 838; in time on the development machine (a shared 2-core AMD EPYC VM at 2.6 GHz) seed
//! ≈ 1.37 µs against ≈ 0.2 µs. The generated code is about half of the fast path, the
//! factorization and solve a fifth. The generated [`Molecule::kinetic_and_gradient`] computes
//! the position terms (and every `sin_cos`) once for `a, A, I` and for `∂T/∂q`: 2 117
//! instructions against 2 394 with the two separate generated calls (`rhs/NAME/fast_unfused`).
//!
//! # Tests
//!
//! `tests/fast_path.rs` (for every shipped molecule): [`rhs`] against the seed's [`super::rhs`]
//! at random states; the J = 0 system against the seed restricted to `p_e = 0`; the frozen
//! system against central finite differences of its own Hamiltonian built independently (the
//! reduced metric with `DMatrix` and a general inverse); no allocation; and a DOP853 trajectory
//! of [`FastSystem`] against one of the seed's [`super::HamiltonianSystem`].

use nalgebra::{Matrix3, Quaternion, SMatrix, SVector, UnitQuaternion, Vector3};

use super::metric::{InverseMetric, MetricBlock, PIVOT_TOLERANCE};
use super::{HamiltonianError, MIN_SIN_THETA, PhaseState, angular_velocity_matrix, euler_angles};
use crate::integrate::OdeSystem;
use crate::molecule::{KineticMatrices, Molecule};

/// The block factorization of the full kinetic metric `M = [[I, A], [Aᵀ, a]]`:
///
/// ```text
/// M = [[1, 0], [Yᵀ, 1]] · [[I, 0], [0, S]] · [[1, Y], [0, 1]],   Y = I⁻¹ A,
/// S = a − Aᵀ I⁻¹ A = a − Aᵀ Y = G22⁻¹,
/// ```
///
/// with `I⁻¹` in closed form (adjugate over determinant) and `S` factored as `L D Lᵀ` (unit
/// lower-triangular `L`, diagonal `D`: the square-root-free form of Cholesky, with the same
/// pivots `D_jj = L_jj²`). Then
///
/// ```text
/// M⁻¹ (J, p):   q̇ = S⁻¹ (p − Yᵀ J),   ω = I⁻¹ J − Y q̇.
/// ```
///
/// `M` is positive definite iff `I` and `S` are, so these two are the whole
/// positive-definiteness check. Pivots are tested against [`PIVOT_TOLERANCE`] with the seed's
/// scales (`trace I` for `I`, `a_jj` for `S`); `I`'s Cholesky pivots are ratios of its leading
/// principal minors, `D₁ = m₁`, `D₂ = m₂/m₁`, `D₃ = m₃/m₂`, so they are tested as
/// `m_j > tol · scale · m_{j−1}` without dividing.
///
/// Why this form: on these tiny blocks the cost is latency, not flops, and a division or square
/// root costs ~15–20 cycles of latency against ~4 for a multiplication. A textbook Cholesky
/// with triangular solves put some 25 dependent divisions and square roots on water's critical
/// path (measured: ~180 ns of a ~400 ns evaluation); here `I` costs one division, `S` one per
/// pivot, and the solves none. (For a 3 × 3 symmetric positive definite `I` the adjugate
/// formula's error grows with the condition number like that of any inverse, and its
/// cofactors do not cancel catastrophically unless `I` is close to singular, which the pivot
/// test rejects; the tests compare the result with the seed's Cholesky-based path to 1e-12
/// for every shipped molecule.)
#[derive(Copy, Clone, Debug)]
pub struct MetricFactor<const N: usize> {
    /// `I⁻¹`.
    i_inv: Matrix3<f64>,
    /// `Y = I⁻¹ A` (3 × N).
    y: SMatrix<f64, 3, N>,
    /// `S = L₂ D₂ L₂ᵀ`: `L₂` in the strict lower triangle (the rest is never read).
    l2: SMatrix<f64, N, N>,
    /// `1 / D₂`.
    d2_inv: SVector<f64, N>,
}

impl<const N: usize> MetricFactor<N> {
    /// Factors the metric of `k`; `q` only goes into the error.
    ///
    /// Fails with [`HamiltonianError::NonFinite`] for non-finite matrices and
    /// [`HamiltonianError::SingularMetric`] (naming the block as the seed's
    /// [`InverseMetric::new`] does) when `M` is singular or not positive definite.
    // Always inlined: called once per evaluation, and inlining lets the factor live in
    // registers instead of being copied out through the `Result` (measured ~5 % of water's rhs).
    #[inline(always)]
    pub fn new(k: &KineticMatrices<N>, q: &SVector<f64, N>) -> Result<Self, HamiltonianError> {
        Self::with_tolerance(k, q, PIVOT_TOLERANCE)
    }

    /// [`MetricFactor::new`] with a stricter test of the pivots: every relative pivot (pivot
    /// over `trace I` for `I`, over `a_jj` for `S`) must exceed `min_pivot`. A metric that
    /// passes [`PIVOT_TOLERANCE`] but not `min_pivot` fails with
    /// [`HamiltonianError::IllConditionedMetric`], which names the block and its smallest
    /// relative pivot: how a run stops when a molecule approaches a singular geometry (a
    /// triatomic bending to linear) before the equations lose accuracy.
    #[inline(always)]
    pub fn with_tolerance(
        k: &KineticMatrices<N>,
        q: &SVector<f64, N>,
        min_pivot: f64,
    ) -> Result<Self, HamiltonianError> {
        let tol = min_pivot.max(PIVOT_TOLERANCE);
        if !(all_finite(k.a.as_slice()) & all_finite(k.coriolis.as_slice()) & all_finite(k.inertia.as_slice())) {
            return Err(HamiltonianError::NonFinite { quantity: "kinetic matrices a, A, I" });
        }
        let Some(i_inv) = inverse_spd3(&k.inertia, tol) else {
            return Err(metric_failure(k, q, MetricBlock::Inertia, tol));
        };
        let y = i_inv * k.coriolis;
        // S = a − Aᵀ Y, lower triangle only (the factorization reads nothing else).
        let mut l2 = k.a;
        let a = &k.coriolis;
        for j in 0..N {
            for i in j..N {
                l2[(i, j)] -= a[(0, i)] * y[(0, j)] + a[(1, i)] * y[(1, j)] + a[(2, i)] * y[(2, j)];
            }
        }
        let Some(d2_inv) = ldl_in_place(&mut l2, |j| k.a[(j, j)], tol) else {
            return Err(metric_failure(k, q, MetricBlock::G22Inverse, tol));
        };
        Ok(Self { i_inv, y, l2, d2_inv })
    }

    /// `v = (ω, q̇) = M⁻¹ (j, p)`.
    #[inline]
    pub fn solve(&self, j: &Vector3<f64>, p: &SVector<f64, N>) -> (Vector3<f64>, SVector<f64, N>) {
        let i_inv_j = self.i_inv * j;
        let qdot = ldl_solve(&self.l2, &self.d2_inv, p - self.y.transpose() * j);
        (i_inv_j - self.y * qdot, qdot)
    }

    /// `v = (ω, q̇) = M⁻¹ (0, p)`: [`MetricFactor::solve`] for `J = 0`, without the `I⁻¹ J`
    /// and `Yᵀ J` terms.
    #[inline]
    pub fn solve_zero_j(&self, p: &SVector<f64, N>) -> (Vector3<f64>, SVector<f64, N>) {
        let qdot = ldl_solve(&self.l2, &self.d2_inv, *p);
        (-(self.y * qdot), qdot)
    }
}

/// Cold path of [`MetricFactor::with_tolerance`]. A metric singular within
/// [`PIVOT_TOLERANCE`] is named as the seed would name it (it checks `I`, `a`, `G11⁻¹`, `G22⁻¹`
/// in that order), falling back to the block this factorization tripped on when the seed's
/// tests happen to pass; a metric that only fails the stricter `tol` is ill-conditioned.
#[cold]
#[inline(never)]
fn metric_failure<const N: usize>(
    k: &KineticMatrices<N>,
    q: &SVector<f64, N>,
    found: MetricBlock,
    tol: f64,
) -> HamiltonianError {
    let singular = match InverseMetric::new(k, q) {
        Err(e) => return e,
        Ok(_) => HamiltonianError::SingularMetric { matrix: found, q: q.as_slice().to_vec() },
    };
    if tol <= PIVOT_TOLERANCE {
        return singular;
    }
    // Positive definite within PIVOT_TOLERANCE: report the smallest relative pivot of the block.
    let inertia = inverse_spd3(&k.inertia, tol).is_none();
    let pivot = if inertia {
        let m = &k.inertia;
        let trace = m.trace();
        let minor2 = m[(0, 0)] * m[(1, 1)] - m[(1, 0)] * m[(1, 0)];
        let pivots = [m[(0, 0)], minor2 / m[(0, 0)], m.determinant() / minor2];
        pivots.iter().fold(f64::INFINITY, |acc, p| acc.min(p / trace))
    } else {
        let y = k.inertia.try_inverse().unwrap_or_else(Matrix3::zeros) * k.coriolis;
        let mut schur = k.a - k.coriolis.transpose() * y;
        match ldl_in_place(&mut schur, |j| k.a[(j, j)], f64::NEG_INFINITY) {
            Some(d_inv) => (0..N).fold(f64::INFINITY, |acc, j| acc.min(1.0 / (d_inv[j] * k.a[(j, j)]))),
            None => return singular,
        }
    };
    let matrix = if inertia { MetricBlock::Inertia } else { MetricBlock::G22Inverse };
    HamiltonianError::IllConditionedMetric { matrix, q: q.as_slice().to_vec(), pivot, threshold: tol }
}

/// The inverse of a symmetric 3 × 3 matrix by adjugate and determinant, or `None` unless it
/// is positive definite with every Cholesky pivot above `tol` times its trace (the seed's test
/// for `I` with `tol` = [`PIVOT_TOLERANCE`]). Reads the lower triangle only.
#[inline]
fn inverse_spd3(m: &Matrix3<f64>, tol: f64) -> Option<Matrix3<f64>> {
    let (m00, m10, m20, m11, m21, m22) = (m[(0, 0)], m[(1, 0)], m[(2, 0)], m[(1, 1)], m[(2, 1)], m[(2, 2)]);
    let c00 = m11 * m22 - m21 * m21;
    let c10 = m20 * m21 - m10 * m22;
    let c20 = m10 * m21 - m20 * m11;
    let c11 = m00 * m22 - m20 * m20;
    let c21 = m10 * m20 - m00 * m21;
    let c22 = m00 * m11 - m10 * m10;
    let det = m00 * c00 + m10 * c10 + m20 * c20;
    // Leading principal minors m00, c22, det; pivot_j = minor_j / minor_{j−1} > tol · trace.
    // Written as `a > b` so that NaN fails.
    let tol = tol * (m00 + m11 + m22);
    let positive = (m00 > tol) & (c22 > tol * m00) & (det > tol * c22);
    if !positive {
        return None;
    }
    let r = 1.0 / det;
    #[rustfmt::skip]
    let inv = Matrix3::new(
        c00 * r, c10 * r, c20 * r,
        c10 * r, c11 * r, c21 * r,
        c20 * r, c21 * r, c22 * r,
    );
    Some(inv)
}

/// In-place `m = L D Lᵀ` of a symmetric matrix, reading the lower triangle only and writing
/// `L` (unit diagonal, not stored) into the strict lower triangle; returns `1 / D`, or `None`
/// unless every pivot `D_jj` exceeds `tol` times `scale(j)` (NaN fails too).
///
/// Row by row: with `v_k = L_jk D_k`, `v_k = m_jk − Σ_{l<k} L_kl v_l`, `L_jk = v_k / D_k`,
/// `D_j = m_jj − Σ_{k<j} L_jk v_k`. Hand-written rather than `nalgebra::Cholesky` because with
/// constant bounds it unrolls into straight-line code, and for the reciprocal pivots.
#[inline]
fn ldl_in_place<const D: usize>(
    m: &mut SMatrix<f64, D, D>,
    scale: impl Fn(usize) -> f64,
    tol: f64,
) -> Option<SVector<f64, D>> {
    let mut d_inv = SVector::<f64, D>::zeros();
    let mut v = SVector::<f64, D>::zeros();
    for j in 0..D {
        let mut d = m[(j, j)];
        for k in 0..j {
            let mut vk = m[(j, k)];
            for l in 0..k {
                vk -= m[(k, l)] * v[l];
            }
            v[k] = vk;
            let ljk = vk * d_inv[k];
            m[(j, k)] = ljk;
            d -= ljk * vk;
        }
        if d.is_nan() || d <= tol * scale(j) {
            return None;
        }
        d_inv[j] = 1.0 / d;
    }
    Some(d_inv)
}

/// `x = L⁻ᵀ D⁻¹ L⁻¹ b` for a factor from [`ldl_in_place`]: multiplications only.
#[inline]
fn ldl_solve<const D: usize>(
    l: &SMatrix<f64, D, D>,
    d_inv: &SVector<f64, D>,
    mut x: SVector<f64, D>,
) -> SVector<f64, D> {
    for i in 0..D {
        for k in 0..i {
            x[i] -= l[(i, k)] * x[k];
        }
    }
    for i in 0..D {
        x[i] *= d_inv[i];
    }
    for i in (0..D).rev() {
        for k in i + 1..D {
            x[i] -= l[(k, i)] * x[k];
        }
    }
    x
}

/// Whether every element is finite: `x · 0` is `±0` for finite `x` and NaN for ±∞ and NaN, so
/// the sum is NaN iff some element is not finite.
///
/// Why not `iter().all(is_finite)`: short-circuiting costs ~16 instructions per element
/// (callgrind: a third of the factorization's instructions went to this check), and the
/// branch-free `fold(true, |ok, x| ok & x.is_finite())` is vectorized into 16-byte loads of
/// values just written by 8-byte stores, which stalls on store-to-load forwarding (perf: half
/// the cycles of the output check). A scalar sum has neither problem, and nothing waits for
/// it but a well-predicted branch.
#[inline]
fn all_finite(v: &[f64]) -> bool {
    !v.iter().fold(0.0, |acc, &x| acc + x * 0.0).is_nan()
}

/// Whether every component of a state is finite; inlined so that the values are checked where
/// they are computed instead of being reloaded from memory.
#[inline(always)]
fn state_is_finite<const N: usize>(s: &PhaseState<N>) -> bool {
    all_finite(s.q.as_slice())
        & all_finite(s.p.as_slice())
        & all_finite(s.euler.as_slice())
        & all_finite(s.pe.as_slice())
}

/// [`PhaseState::check_finite`] with the fast check first; the seed's check (which names the
/// block) only runs when something is not finite.
#[inline(always)]
fn check_state<const N: usize>(s: &PhaseState<N>) -> Result<(), HamiltonianError> {
    if state_is_finite(s) { Ok(()) } else { cold_check_state(s) }
}

#[cold]
#[inline(never)]
fn cold_check_state<const N: usize>(s: &PhaseState<N>) -> Result<(), HamiltonianError> {
    s.check_finite()
}

/// `sin`/`cos` of θ and ψ: everything W, Wᵀ and ∂W need (W does not depend on φ), with
/// `1 / sin θ` computed once (one division instead of three).
#[derive(Copy, Clone, Debug)]
struct Euler {
    inv_st: f64,
    ct: f64,
    sp: f64,
    cp: f64,
}

impl Euler {
    /// Fails like [`super::WMatrices::new`]: non-finite angles, then `|sin θ| <` [`MIN_SIN_THETA`].
    #[inline]
    fn new(euler: &Vector3<f64>) -> Result<Self, HamiltonianError> {
        if !all_finite(euler.as_slice()) {
            return Err(HamiltonianError::NonFinite { quantity: "Euler angles (φ, θ, ψ)" });
        }
        let theta = euler[1];
        let (st, ct) = theta.sin_cos();
        if st.abs() < MIN_SIN_THETA {
            return Err(HamiltonianError::EulerSingular { theta });
        }
        let (sp, cp) = euler[2].sin_cos();
        Ok(Self { inv_st: 1.0 / st, ct, sp, cp })
    }

    /// `J = W p_e` (eq. 2).
    #[inline]
    fn j(&self, pe: &Vector3<f64>) -> Vector3<f64> {
        let g = (pe[0] - self.ct * pe[2]) * self.inv_st;
        Vector3::new(self.sp * g + self.cp * pe[1], self.cp * g - self.sp * pe[1], pe[2])
    }

    /// `Ω̇_e = Wᵀ ω` (eq. 6).
    #[inline]
    fn euler_rates(&self, omega: &Vector3<f64>) -> Vector3<f64> {
        let phi_dot = (self.sp * omega[0] + self.cp * omega[1]) * self.inv_st;
        Vector3::new(phi_dot, self.cp * omega[0] - self.sp * omega[1], omega[2] - self.ct * phi_dot)
    }

    /// `ṗ_e = −((∂W/∂Ω_e) p_e) · ω` (eqs. 5, 7) with `ṗ_φ` a literal `+0.0` (H does not depend
    /// on φ; negating a computed zero could give −0.0), given `J = W p_e`.
    #[inline]
    fn euler_momenta_rates(&self, pe: &Vector3<f64>, j: &Vector3<f64>, omega: &Vector3<f64>) -> Vector3<f64> {
        let dh_dtheta =
            (pe[2] - self.ct * pe[0]) * (self.inv_st * self.inv_st) * (self.sp * omega[0] + self.cp * omega[1]);
        let dh_dpsi = j[1] * omega[0] - j[0] * omega[1];
        Vector3::new(0.0, -dh_dtheta, -dh_dpsi)
    }
}

/// `(ω, q̇, ṗ)`.
type VelocitiesAndForce<const N: usize> = (Vector3<f64>, SVector<f64, N>, SVector<f64, N>);

/// The kinetic matrices, the velocities `(ω, q̇)` from `factor` (the caller's metric solve),
/// and the internal force `ṗ = ∂T/∂q|_(ω, q̇) − ∂U/∂q`, through the generated
/// [`Molecule::kinetic_and_gradient`], which computes the position terms once for both halves.
/// Returns `(ω, q̇, ṗ)`.
#[inline(always)]
fn velocities_and_force<M, const N: usize, const NA: usize>(
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

fn finite(x: f64, quantity: &'static str) -> Result<f64, HamiltonianError> {
    if x.is_finite() { Ok(x) } else { Err(HamiltonianError::NonFinite { quantity }) }
}

#[inline(always)]
fn check_rhs<const N: usize>(out: &PhaseState<N>) -> Result<(), HamiltonianError> {
    if state_is_finite(out) { Ok(()) } else { Err(non_finite_rhs()) }
}

#[cold]
#[inline(never)]
fn non_finite_rhs() -> HamiltonianError {
    HamiltonianError::NonFinite { quantity: "right-hand side of Hamilton's equations" }
}

/// The right-hand side of Hamilton's equations, `(q̇, ṗ, Ω̇_e, ṗ_e)`, by the fast path (see the
/// module docs): the seed's [`super::rhs`] to rounding, with the same errors, no workspace and
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
    let e = Euler::new(&state.euler)?;
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
    let j = Euler::new(&state.euler)?.j(&state.pe);
    let mut k = KineticMatrices::default();
    molecule.kinetic(&state.q, &mut k);
    let (omega, qdot) = MetricFactor::new(&k, &state.q)?.solve(&j, &state.p);
    let t = 0.5 * (omega.dot(&j) + qdot.dot(&state.p));
    let u = finite(molecule.potential(&state.q), "potential U(q)")?;
    finite(t + u, "Hamiltonian H")
}

/// The fast path as an [`OdeSystem`] on the seed's flat layout
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

/// The state of the body formulation that [`ReducedSystem`] integrates: internal coordinates and
/// momenta, the orientation as a unit quaternion (body → lab, `R = Rz(φ) Rx(θ) Rz(ψ)` of the
/// Euler angles) and the body-frame angular momentum `J = W p_e`.
///
/// Unlike `(Ω_e, p_e)` it has no singular orientation: Euler angles are derived only for output
/// ([`BodyState::to_phase`]), where `p_e = Mᵀ J` is defined even at `θ = 0`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BodyState<const N: usize> {
    /// Internal coordinates (bohr, rad).
    pub q: SVector<f64, N>,
    /// Their conjugate momenta.
    pub p: SVector<f64, N>,
    /// Body → lab rotation.
    pub orientation: UnitQuaternion<f64>,
    /// Body-frame angular momentum, ħ.
    pub j: Vector3<f64>,
}

impl<const N: usize> BodyState<N> {
    /// From a phase-space state: the quaternion of the Euler angles and `J = W p_e`; fails at
    /// gimbal lock, where `p_e` does not determine `J`.
    pub fn from_phase(s: &PhaseState<N>) -> Result<Self, HamiltonianError> {
        let j = Euler::new(&s.euler)?.j(&s.pe);
        Ok(Self { q: s.q, p: s.p, orientation: quaternion_of_euler(&s.euler), j })
    }

    /// To a phase-space state, for output: Euler angles of the rotation (`θ ∈ [0, π]`; at
    /// `sin θ = 0` the split of `φ ± ψ` is arbitrary) and `p_e = Mᵀ J`, which needs no division.
    pub fn to_phase(&self) -> PhaseState<N> {
        let euler = euler_angles(self.orientation.to_rotation_matrix().matrix());
        PhaseState { q: self.q, p: self.p, euler, pe: angular_velocity_matrix(&euler).transpose() * self.j }
    }

    /// The body → lab rotation matrix.
    pub fn rotation(&self) -> Matrix3<f64> {
        *self.orientation.to_rotation_matrix().matrix()
    }
}

/// The unit quaternion of `R = Rz(φ) Rx(θ) Rz(ψ)`.
pub fn quaternion_of_euler(euler: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), euler[0])
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), euler[1])
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), euler[2])
}

/// What a [`ReducedSystem`] integrates of the overall rotation.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Rotation {
    /// Everything: the orientation (a quaternion) and the body-frame angular momentum `J`.
    Free,
    /// Zero angular momentum: `J = 0` exactly for all time (`J̇ = J × ω`), so `J` is not stored;
    /// the orientation is integrated only if `orientation` is true, for lab-frame output (a
    /// molecule with `J = 0` still turns as it vibrates).
    ZeroAngularMomentum {
        /// Whether to integrate the orientation.
        orientation: bool,
    },
}

/// Which parts of phase space a [`ReducedSystem`] integrates, chosen at run time.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Reduction<const N: usize> {
    /// `active[k]` is false for an internal coordinate frozen at its value (zero velocity).
    pub active: [bool; N],
    /// What is integrated of the overall rotation.
    pub rotation: Rotation,
}

impl<const N: usize> Reduction<N> {
    /// Nothing reduced: the same motion as [`FastSystem`], in the body formulation.
    pub fn none() -> Self {
        Self { active: [true; N], rotation: Rotation::Free }
    }

    /// `J = 0`, all internal coordinates active; the orientation integrated if asked for.
    pub fn zero_angular_momentum(orientation: bool) -> Self {
        Self { active: [true; N], rotation: Rotation::ZeroAngularMomentum { orientation } }
    }

    /// The coordinates with `active[k] == false` frozen, rotation free.
    pub fn frozen(active: [bool; N]) -> Self {
        Self { active, rotation: Rotation::Free }
    }

    /// The coordinates called `frozen` (names as in [`Molecule::coordinates`]) frozen, rotation
    /// free: how a scene that names coordinates picks them at run time.
    pub fn freezing<M, const NA: usize>(molecule: &M, frozen: &[&str]) -> Result<Self, ReductionError>
    where
        M: Molecule<N, NA> + ?Sized,
    {
        let coords = molecule.coordinates();
        let mut active = [true; N];
        for name in frozen {
            let k = coords.iter().position(|c| c.name == *name).ok_or_else(|| ReductionError::UnknownCoordinate {
                name: (*name).to_owned(),
                known: coords.iter().map(|c| c.name).collect(),
            })?;
            active[k] = false;
        }
        Ok(Self::frozen(active))
    }

    /// The number of active internal coordinates.
    pub fn active_count(&self) -> usize {
        self.active.iter().filter(|&&a| a).count()
    }

    /// Whether the orientation is integrated.
    pub fn orientation(&self) -> bool {
        matches!(self.rotation, Rotation::Free | Rotation::ZeroAngularMomentum { orientation: true })
    }

    /// The dimension of the flat state: `2 n_active + 4 (orientation) + 3 (J)`.
    pub fn dim(&self) -> usize {
        2 * self.active_count()
            + if self.orientation() { 4 } else { 0 }
            + if self.rotation == Rotation::Free { 3 } else { 0 }
    }
}

/// Why a [`Reduction`] cannot be built, or a full state cannot be mapped onto a
/// [`ReducedSystem`]'s flat state.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ReductionError {
    /// The flat slice has the wrong length.
    #[error("the reduced state has {found} components, expected {expected}")]
    DimensionMismatch {
        /// The system's dimension.
        expected: usize,
        /// The length that was passed.
        found: usize,
    },
    /// A J = 0 system was given a state with non-zero angular momentum.
    #[error("the state has angular momentum J = {j:?}, but this system has zero angular momentum")]
    NonzeroAngularMomentum {
        /// The state's body-frame `J`.
        j: [f64; 3],
    },
    /// [`Reduction::freezing`] was given a name the molecule has no coordinate of.
    #[error("no internal coordinate is called {name:?} (the coordinates are {known:?})")]
    UnknownCoordinate {
        /// The name that was given.
        name: String,
        /// The molecule's coordinate names.
        known: Vec<&'static str>,
    },
    /// A frozen coordinate of the state differs from the value the system holds it at.
    #[error("frozen coordinate q[{index}] is {found} in the state but held at {held}")]
    FrozenCoordinateMoved {
        /// Its index in q.
        index: usize,
        /// Its value in the state.
        found: f64,
        /// The value the system holds.
        held: f64,
    },
    /// A phase-space state at gimbal lock, whose `p_e` does not determine `J`.
    #[error(transparent)]
    Hamiltonian(#[from] HamiltonianError),
}

/// Hamilton's equations in the body formulation, restricted by a [`Reduction`], as an
/// [`OdeSystem`]: the production path, free of the Euler-angle singularity.
///
/// # Equations
///
/// With `J` the body-frame angular momentum and `ς` the unit quaternion of the orientation,
///
/// ```text
/// (ω, q̇) = M(q)⁻¹ (J, p)                 the fast path's factorization
/// ṗ      = ∂T/∂q|_(ω, q̇) − ∂U/∂q          as in the fast path (J does not depend on q)
/// J̇      = J × ω                          L = R J is constant in the lab: 0 = Ṙ J + R J̇, Ṙ = R [ω]×
/// ς̇      = ½ ς ⊗ (0, ω)                   the same Ṙ = R [ω]× for quaternions
/// ```
///
/// These are the seed's equations with `(Ω_e, p_e)` replaced by `(ς, J = W p_e)`: the
/// Hamiltonian `H = ½ (J, p)ᵀ M⁻¹ (J, p) + U` is the same function, and the tests compare both
/// the right-hand side (through the chain rule) and trajectories with the seed path. The
/// quaternion never feeds back into `q`, `p` or `J`, so its norm (conserved by the exact flow,
/// to the tolerance by DOP853, to rounding by Gauss–Legendre, for which `|ς|²` and `|J|²` are
/// quadratic invariants) only affects the orientation, which is always normalised before use.
///
/// # Flat layout
///
/// ```text
/// [ q_a … | p_a … | ς_w ς_x ς_y ς_z (if the orientation is integrated) | J_x J_y J_z (if Rotation::Free) ]
/// ```
///
/// where `q_a`, `p_a` are the active coordinates and their momenta in coordinate order
/// (dimension [`Reduction::dim`]). Frozen coordinates stay at the values of the `template`
/// state given to [`ReducedSystem::new`] with zero velocity; when the orientation is not
/// integrated, [`ReducedSystem::expand`] reports the template's.
///
/// # The reduced Hamiltonian
///
/// `H_red = ½ bᵀ M_red⁻¹ b + U(q)` with `b = (J, p_a)` (`J = 0` for a J = 0 system) and `M_red`
/// the full metric with the frozen rows and columns deleted: the Legendre transform of the
/// Lagrangian with the frozen velocities set to zero. Its `p_a` and `J` are the full system's
/// momenta at those velocities.
///
/// # Conditioning
///
/// [`ReducedSystem::with_min_pivot`] sets the smallest relative pivot of the metric the system
/// accepts (default [`PIVOT_TOLERANCE`]); below it every evaluation fails with
/// [`HamiltonianError::IllConditionedMetric`] naming the block and q, so a run stops, with the
/// time, before a near-singular geometry degrades the numbers.
#[derive(Debug)]
pub struct ReducedSystem<'a, M: ?Sized, const N: usize, const NA: usize> {
    molecule: &'a M,
    reduction: Reduction<N>,
    /// Frozen q values, and the orientation when it is not integrated.
    template: BodyState<N>,
    /// `index[s]` for `s < n_active`: the coordinate stored in slot `s`.
    index: [usize; N],
    n_active: usize,
    all_active: bool,
    min_pivot: f64,
}

// By hand: a derive would require `M: Clone`, but only a reference to the molecule is held.
impl<M: ?Sized, const N: usize, const NA: usize> Clone for ReducedSystem<'_, M, N, NA> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M: ?Sized, const N: usize, const NA: usize> Copy for ReducedSystem<'_, M, N, NA> {}

/// Where the blocks of a reduced flat state start.
#[derive(Copy, Clone)]
struct Offsets {
    p: usize,
    quaternion: Option<usize>,
    j: Option<usize>,
    dim: usize,
}

/// An unpacked reduced state: full-length q and p, the (not necessarily unit) quaternion, J.
struct Unpacked<const N: usize> {
    q: SVector<f64, N>,
    p: SVector<f64, N>,
    quaternion: Quaternion<f64>,
    j: Vector3<f64>,
}

impl<'a, M, const N: usize, const NA: usize> ReducedSystem<'a, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The reduced system of `molecule`; `template` supplies the frozen coordinates' values and
    /// the orientation reported when it is not integrated (its momenta are not used, and its
    /// Euler angles may be at gimbal lock).
    pub fn new(molecule: &'a M, reduction: Reduction<N>, template: &PhaseState<N>) -> Self {
        let template = BodyState {
            q: template.q,
            p: SVector::zeros(),
            orientation: quaternion_of_euler(&template.euler),
            j: Vector3::zeros(),
        };
        Self::from_body(molecule, reduction, &template)
    }

    /// [`ReducedSystem::new`] with a body-formulation template.
    pub fn from_body(molecule: &'a M, reduction: Reduction<N>, template: &BodyState<N>) -> Self {
        let mut index = [0; N];
        let mut n_active = 0;
        for k in 0..N {
            if reduction.active[k] {
                index[n_active] = k;
                n_active += 1;
            }
        }
        Self {
            molecule,
            reduction,
            template: *template,
            index,
            n_active,
            all_active: n_active == N,
            min_pivot: PIVOT_TOLERANCE,
        }
    }

    /// The same system, failing with [`HamiltonianError::IllConditionedMetric`] wherever a
    /// relative pivot of the metric is below `min_pivot` (see [`MetricFactor::with_tolerance`]).
    pub fn with_min_pivot(mut self, min_pivot: f64) -> Self {
        self.min_pivot = min_pivot;
        self
    }

    /// The molecule.
    pub fn molecule(&self) -> &'a M {
        self.molecule
    }

    /// The reduction.
    pub fn reduction(&self) -> &Reduction<N> {
        &self.reduction
    }

    fn offsets(&self) -> Offsets {
        let p = self.n_active;
        let mut next = 2 * self.n_active;
        let quaternion = self.reduction.orientation().then(|| {
            next += 4;
            next - 4
        });
        let j = (self.reduction.rotation == Rotation::Free).then(|| {
            next += 3;
            next - 3
        });
        Offsets { p, quaternion, j, dim: next }
    }

    /// The full `q`, `p` (zero for frozen coordinates), quaternion and `J` of a flat state.
    #[inline]
    fn unpack(&self, y: &[f64], o: &Offsets) -> Unpacked<N> {
        let mut u = Unpacked {
            q: self.template.q,
            p: SVector::zeros(),
            quaternion: *self.template.orientation.quaternion(),
            j: Vector3::zeros(),
        };
        for (slot, &k) in self.index[..self.n_active].iter().enumerate() {
            u.q[k] = y[slot];
            u.p[k] = y[o.p + slot];
        }
        if let Some(i) = o.quaternion {
            u.quaternion = Quaternion::new(y[i], y[i + 1], y[i + 2], y[i + 3]);
        }
        if let Some(i) = o.j {
            u.j = Vector3::new(y[i], y[i + 1], y[i + 2]);
        }
        u
    }

    /// Kinetic matrices with the frozen rows and columns of `M` replaced by those of the
    /// identity: `a_fj = a_jf = δ_fj`, `A_·f = 0`. The metric is then block diagonal (after a
    /// permutation) as `M_red ⊕ 1`, so `M⁻¹ (J, p)` with `p_f = 0` gives `q̇_f = 0` exactly and
    /// the active block `M_red⁻¹ (J, p_a)`.
    #[inline]
    fn masked(&self, k: &KineticMatrices<N>) -> KineticMatrices<N> {
        let mut k = *k;
        for f in 0..N {
            if !self.reduction.active[f] {
                for j in 0..N {
                    k.a[(f, j)] = 0.0;
                    k.a[(j, f)] = 0.0;
                }
                k.a[(f, f)] = 1.0;
                for r in 0..3 {
                    k.coriolis[(r, f)] = 0.0;
                }
            }
        }
        k
    }

    /// The unpacked state, after checking the slice.
    #[inline]
    fn checked_unpack(&self, y: &[f64], o: &Offsets) -> Result<Unpacked<N>, HamiltonianError> {
        if y.len() != o.dim {
            return Err(HamiltonianError::DimensionMismatch { expected: o.dim, found: y.len() });
        }
        if !all_finite(y) {
            return Err(HamiltonianError::NonFinite { quantity: "state (q, p, orientation, J)" });
        }
        Ok(self.unpack(y, o))
    }

    /// `(ω, q̇) = M_red⁻¹ (J, p)` from the kinetic matrices at `u.q`.
    #[inline(always)]
    fn solve(
        &self,
        k: &KineticMatrices<N>,
        u: &Unpacked<N>,
        o: &Offsets,
    ) -> Result<(Vector3<f64>, SVector<f64, N>), HamiltonianError> {
        let masked;
        let k = if self.all_active {
            k
        } else {
            masked = self.masked(k);
            &masked
        };
        let factor = MetricFactor::with_tolerance(k, &u.q, self.min_pivot)?;
        Ok(match o.j {
            Some(_) => factor.solve(&u.j, &u.p),
            None => factor.solve_zero_j(&u.p),
        })
    }

    /// The unpacked state and the velocities `(ω, q̇)`.
    #[inline]
    fn kinematics(
        &self,
        y: &[f64],
        o: &Offsets,
    ) -> Result<(Unpacked<N>, Vector3<f64>, SVector<f64, N>), HamiltonianError> {
        let u = self.checked_unpack(y, o)?;
        let mut k = KineticMatrices::default();
        self.molecule.kinetic(&u.q, &mut k);
        let (omega, qdot) = self.solve(&k, &u, o)?;
        Ok((u, omega, qdot))
    }

    /// `H_red` of the flat state `y`, in hartree: `½ (ω · J + q̇_a · p_a) + U`.
    pub fn energy(&self, y: &[f64]) -> Result<f64, HamiltonianError> {
        let o = self.offsets();
        let (u, omega, qdot) = self.kinematics(y, &o)?;
        self.energy_at(&u, &omega, &qdot)
    }

    /// `½ (ω · J + q̇_a · p_a) + U` at an unpacked state and its velocities.
    fn energy_at(
        &self,
        u: &Unpacked<N>,
        omega: &Vector3<f64>,
        qdot: &SVector<f64, N>,
    ) -> Result<f64, HamiltonianError> {
        let t = 0.5 * (omega.dot(&u.j) + qdot.dot(&u.p));
        let v = finite(self.molecule.potential(&u.q), "potential U(q)")?;
        finite(t + v, "Hamiltonian H")
    }

    /// Writes the reduced flat state of a body-formulation state into `y`: active q and p, and
    /// (as the reduction keeps them) the orientation and `J`. The momenta of frozen coordinates
    /// are not used (the constraint determines them; see [`ReducedSystem::expand`]).
    ///
    /// Fails if `y` has the wrong length, if the state has `J ≠ 0` for a J = 0 system, or if a
    /// frozen coordinate differs from the value the system holds it at.
    pub fn reduce_body(&self, state: &BodyState<N>, y: &mut [f64]) -> Result<(), ReductionError> {
        let o = self.offsets();
        if y.len() != o.dim {
            return Err(ReductionError::DimensionMismatch { expected: o.dim, found: y.len() });
        }
        if o.j.is_none() && state.j != Vector3::zeros() {
            return Err(ReductionError::NonzeroAngularMomentum { j: state.j.into() });
        }
        for k in 0..N {
            let held = self.template.q[k];
            if !self.reduction.active[k] && state.q[k] != held {
                return Err(ReductionError::FrozenCoordinateMoved { index: k, found: state.q[k], held });
            }
        }
        for (slot, &k) in self.index[..self.n_active].iter().enumerate() {
            y[slot] = state.q[k];
            y[o.p + slot] = state.p[k];
        }
        if let Some(i) = o.quaternion {
            let q = state.orientation.quaternion();
            y[i..i + 4].copy_from_slice(&[q.w, q.i, q.j, q.k]);
        }
        if let Some(i) = o.j {
            y[i..i + 3].copy_from_slice(state.j.as_slice());
        }
        Ok(())
    }

    /// [`ReducedSystem::reduce_body`] of a phase-space state (`J = W p_e`: fails at gimbal lock).
    pub fn reduce(&self, state: &PhaseState<N>, y: &mut [f64]) -> Result<(), ReductionError> {
        // A J = 0 system needs no W, so a state at gimbal lock with p_e = 0 is fine.
        let body = if state.pe == Vector3::zeros() {
            BodyState { q: state.q, p: state.p, orientation: quaternion_of_euler(&state.euler), j: Vector3::zeros() }
        } else {
            BodyState::from_phase(state)?
        };
        self.reduce_body(&body, y)
    }

    /// The body-formulation state of a reduced flat state, for output: frozen coordinates at
    /// their held values, `J = 0` for a J = 0 system, the template's orientation if it is not
    /// integrated (the integrated quaternion normalised otherwise), and each frozen coordinate's
    /// momentum the full system's `p_f = ∂T/∂q̇_f = (Aᵀ ω + a q̇)_f` at the reduced velocities
    /// (so that the full system at the expanded state moves the same way, with `q̇_f = 0`).
    pub fn expand_body(&self, y: &[f64]) -> Result<BodyState<N>, HamiltonianError> {
        Ok(self.expand_body_and_energy(y)?.0)
    }

    /// [`ReducedSystem::expand_body`] and [`ReducedSystem::energy`] together, sharing the one
    /// evaluation of the kinetic matrices and the factorization (what output needs at every
    /// output time).
    pub fn expand_body_and_energy(&self, y: &[f64]) -> Result<(BodyState<N>, f64), HamiltonianError> {
        let o = self.offsets();
        let u = self.checked_unpack(y, &o)?;
        let mut k = KineticMatrices::default();
        self.molecule.kinetic(&u.q, &mut k);
        let (omega, qdot) = self.solve(&k, &u, &o)?;
        let energy = self.energy_at(&u, &omega, &qdot)?;
        let mut p = u.p;
        if !self.all_active {
            // `k` is unmasked here: the full system's momenta at the reduced velocities.
            let p_full = k.coriolis.transpose() * omega + k.a * qdot;
            for f in 0..N {
                if !self.reduction.active[f] {
                    p[f] = p_full[f];
                }
            }
        }
        let orientation = UnitQuaternion::try_new(u.quaternion, 0.0)
            .ok_or(HamiltonianError::NonFinite { quantity: "orientation quaternion (zero norm)" })?;
        Ok((BodyState { q: u.q, p, orientation, j: u.j }, energy))
    }

    /// [`ReducedSystem::expand_body`] as a phase-space state ([`BodyState::to_phase`]).
    pub fn expand(&self, y: &[f64]) -> Result<PhaseState<N>, HamiltonianError> {
        Ok(self.expand_body(y)?.to_phase())
    }
}

impl<M, const N: usize, const NA: usize> OdeSystem for ReducedSystem<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    type Error = HamiltonianError;

    fn dim(&self) -> usize {
        self.offsets().dim
    }

    /// `dydt` in the reduced layout: `(q̇_a, ṗ_a, ς̇, J̇)` as the reduction keeps them.
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), HamiltonianError> {
        let o = self.offsets();
        if dydt.len() != o.dim {
            return Err(HamiltonianError::DimensionMismatch { expected: o.dim, found: dydt.len() });
        }
        let u = self.checked_unpack(y, &o)?;
        let (omega, qdot, pdot) = velocities_and_force(self.molecule, &u.q, |k| self.solve(k, &u, &o))?;
        for (slot, &k) in self.index[..self.n_active].iter().enumerate() {
            dydt[slot] = qdot[k];
            dydt[o.p + slot] = pdot[k];
        }
        if let Some(i) = o.quaternion {
            // ς̇ = ½ ς ⊗ (0, ω).
            let d = u.quaternion * Quaternion::from_imag(omega) * 0.5;
            dydt[i..i + 4].copy_from_slice(&[d.w, d.i, d.j, d.k]);
        }
        if let Some(i) = o.j {
            dydt[i..i + 3].copy_from_slice(u.j.cross(&omega).as_slice());
        }
        if !all_finite(dydt) {
            return Err(HamiltonianError::NonFinite { quantity: "right-hand side of Hamilton's equations" });
        }
        Ok(())
    }
}
