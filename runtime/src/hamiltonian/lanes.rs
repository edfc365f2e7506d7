//! The production right-hand side with nothing reduced, written once over [`Real`]: with
//! `T = f64` it is what [`super::ReducedSystem`] evaluates when every coordinate is active and
//! the rotation is free (no index maps, one finiteness test per evaluation); with a vector
//! type it evaluates `T::LANES` independent trajectories at once ([`ProductionLanes`]), each lane
//! the `f64` evaluation of that lane's state to round-off (the lanes' `sin_cos` and `exp` are
//! vector polynomials, [`crate::lanes`]).
//!
//! The equations are [`super::ReducedSystem`]'s (see there): on the flat layout
//! `[q (N), p (N), ς_w ς_x ς_y ς_z, J_x J_y J_z]` (dimension `2N + 7`),
//!
//! ```text
//! (ω, q̇) = M(q)⁻¹ (J, p)              block factorization, as in super::factor
//! ṗ      = ∂T/∂q|_(ω, q̇) − ∂U/∂q
//! ς̇      = ½ ς ⊗ (0, ω)
//! J̇      = J × ω
//! ```
//!
//! The code has no branch on the numbers: the metric's pivot tests (those of
//! [`super::MetricFactor::with_tolerance`]) and the finiteness of the state, the kinetic
//! matrices and the result are collected into a lane mask that the caller tests once. A lane
//! that fails has meaningless numbers; [`super::ReducedSystem`] then re-evaluates the state with
//! the general path, which names the error.

use crate::lanes::{KineticLanes, Real};
use crate::molecule::Molecule;

/// Whether `molecule`'s production system runs on this module's lane-generic code with the
/// `f64` path's operations: the molecule has generated lane forms
/// ([`Molecule::has_lane_forms`]: not a large molecule with the centre-of-mass term of `a` at run
/// time) and its vibrational block is factorized by [`super::factor`]'s small-block `L D Lᵀ`
/// (fewer than `factor_large::LARGE_BLOCK` = 24 coordinates), which this module's `solve` repeats
/// operation for operation. Otherwise [`super::ReducedSystem`] takes its general path and the
/// ensemble runner runs one trajectory at a time.
pub fn available<M, const N: usize, const NA: usize>(molecule: &M) -> bool
where
    M: Molecule<N, NA> + ?Sized,
{
    molecule.has_lane_forms() && N < super::factor_large::LARGE_BLOCK
}

/// `(ω, q̇) = M⁻¹ (J, p)` by the block factorization of [`super::MetricFactor`] (closed-form
/// `I⁻¹`, `Y = I⁻¹ A`, `S = a − AᵀY = L D Lᵀ`), lane-generic. Clears the bits of `ok` whose
/// pivots are not above `tol` times their scale (`trace I` for `I`, `a_jj` for `S`); NaN fails.
#[inline(always)]
fn solve<T: Real, const N: usize>(
    k: &KineticLanes<T, N>,
    j: &[T; 3],
    p: &[T; N],
    tol: f64,
    ok: &mut u32,
) -> ([T; 3], [T; N]) {
    let m = &k.inertia;
    let (m00, m10, m20, m11, m21, m22) = (m[0][0], m[1][0], m[2][0], m[1][1], m[2][1], m[2][2]);
    let c00 = m11 * m22 - m21 * m21;
    let c10 = m20 * m21 - m10 * m22;
    let c20 = m10 * m21 - m20 * m11;
    let c11 = m00 * m22 - m20 * m20;
    let c21 = m10 * m20 - m00 * m21;
    let c22 = m00 * m11 - m10 * m10;
    let det = m00 * c00 + m10 * c10 + m20 * c20;
    let tol_i = T::splat(tol) * (m00 + m11 + m22);
    *ok &= m00.gt_mask(tol_i) & c22.gt_mask(tol_i * m00) & det.gt_mask(tol_i * c22);
    let r = T::splat(1.0) / det;
    let i_inv = [[c00 * r, c10 * r, c20 * r], [c10 * r, c11 * r, c21 * r], [c20 * r, c21 * r, c22 * r]];
    let a = &k.coriolis;
    // Y = I⁻¹ A.
    let y: [[T; N]; 3] = core::array::from_fn(|r| {
        core::array::from_fn(|c| i_inv[r][0] * a[0][c] + i_inv[r][1] * a[1][c] + i_inv[r][2] * a[2][c])
    });
    // S = a − Aᵀ Y (lower triangle), then L D Lᵀ in place (as factor.rs's ldl_in_place).
    let mut l = k.a;
    for c in 0..N {
        for r in c..N {
            l[r][c] = l[r][c] - (a[0][r] * y[0][c] + a[1][r] * y[1][c] + a[2][r] * y[2][c]);
        }
    }
    let mut d_inv = [T::splat(0.0); N];
    let mut v = [T::splat(0.0); N];
    for r in 0..N {
        let mut d = l[r][r];
        for c in 0..r {
            let mut vc = l[r][c];
            for s in 0..c {
                vc = vc - l[c][s] * v[s];
            }
            v[c] = vc;
            let lrc = vc * d_inv[c];
            l[r][c] = lrc;
            d = d - lrc * vc;
        }
        *ok &= d.gt_mask(T::splat(tol) * k.a[r][r]);
        d_inv[r] = T::splat(1.0) / d;
    }
    // q̇ = S⁻¹ (p − Yᵀ J), ω = I⁻¹ J − Y q̇.
    let mut x: [T; N] = core::array::from_fn(|i| p[i] - (y[0][i] * j[0] + y[1][i] * j[1] + y[2][i] * j[2]));
    for r in 0..N {
        for c in 0..r {
            x[r] = x[r] - l[r][c] * x[c];
        }
    }
    for r in 0..N {
        x[r] = x[r] * d_inv[r];
    }
    for r in (0..N).rev() {
        for c in r + 1..N {
            x[r] = x[r] - l[c][r] * x[c];
        }
    }
    let omega = core::array::from_fn(|r| {
        let mut y_qdot = T::splat(0.0);
        for c in 0..N {
            y_qdot = y_qdot + y[r][c] * x[c];
        }
        (i_inv[r][0] * j[0] + i_inv[r][1] * j[1] + i_inv[r][2] * j[2]) - y_qdot
    });
    (omega, x)
}

/// The production right-hand side, nothing reduced, for `T::LANES` states (flat layout in the
/// module docs, `y` and `dydt` of length `2N + 7`). Returns the mask of the lanes that
/// succeeded: finite state, kinetic matrices and result, and every pivot of the metric above
/// `min_pivot` times its scale. Returns 0 if a slice has the wrong length.
#[inline(always)]
pub fn production_rhs<M, T, const N: usize, const NA: usize>(
    molecule: &M,
    y: &[T],
    dydt: &mut [T],
    min_pivot: f64,
) -> u32
where
    M: Molecule<N, NA> + ?Sized,
    T: Real,
{
    if y.len() != 2 * N + 7 || dydt.len() != 2 * N + 7 {
        return 0;
    }
    let zero = T::splat(0.0);
    let q: [T; N] = core::array::from_fn(|i| y[i]);
    let p: [T; N] = core::array::from_fn(|i| y[N + i]);
    let s = [y[2 * N], y[2 * N + 1], y[2 * N + 2], y[2 * N + 3]];
    let j = [y[2 * N + 4], y[2 * N + 5], y[2 * N + 6]];
    let mut ok = T::ALL;
    // x · 0 is ±0 for finite x and NaN otherwise: one sum over the state, the kinetic matrices
    // and the result is NaN exactly in the lanes where something is not finite.
    let mut nan_probe = zero;
    for &v in y {
        nan_probe = nan_probe + v * zero;
    }
    let mut k = KineticLanes::zeros();
    let mut dt = [zero; N];
    let (omega, qdot, _) = molecule.kinetic_and_gradient_lanes(
        &q,
        &mut k,
        |k| {
            for row in k.a.iter().chain(&k.coriolis) {
                for &v in row {
                    nan_probe = nan_probe + v * zero;
                }
            }
            for row in &k.inertia {
                for &v in row {
                    nan_probe = nan_probe + v * zero;
                }
            }
            solve(k, &j, &p, min_pivot, &mut ok)
        },
        &mut dt,
    );
    let mut du = [zero; N];
    molecule.potential_gradient_lanes(&q, &mut du);
    for i in 0..N {
        dydt[i] = qdot[i];
        dydt[N + i] = dt[i] - du[i];
    }
    // ς̇ = ½ ς ⊗ (0, ω).
    let half = T::splat(0.5);
    let (w, qx, qy, qz) = (s[0], s[1], s[2], s[3]);
    let (ox, oy, oz) = (omega[0], omega[1], omega[2]);
    dydt[2 * N] = half * (-(qx * ox) - qy * oy - qz * oz);
    dydt[2 * N + 1] = half * (w * ox + qy * oz - qz * oy);
    dydt[2 * N + 2] = half * (w * oy + qz * ox - qx * oz);
    dydt[2 * N + 3] = half * (w * oz + qx * oy - qy * ox);
    // J̇ = J × ω.
    dydt[2 * N + 4] = j[1] * oz - j[2] * oy;
    dydt[2 * N + 5] = j[2] * ox - j[0] * oz;
    dydt[2 * N + 6] = j[0] * oy - j[1] * ox;
    for &v in dydt.iter() {
        nan_probe = nan_probe + v * zero;
    }
    ok & nan_probe.not_nan_mask()
}

/// `T::LANES` trajectories of a molecule's production system (nothing reduced) evaluated
/// together: the right-hand side of the batched integrator
/// ([`crate::integrate::Dop853Lanes`]).
pub struct ProductionLanes<'a, M: ?Sized, const N: usize, const NA: usize> {
    molecule: &'a M,
    min_pivot: f64,
}

impl<'a, M, const N: usize, const NA: usize> ProductionLanes<'a, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The system of `molecule`, failing a lane whose metric has a relative pivot at or below
    /// `min_pivot` (as [`super::ReducedSystem::with_min_pivot`]).
    pub fn new(molecule: &'a M, min_pivot: f64) -> Self {
        Self { molecule, min_pivot }
    }

    /// The flat dimension, `2N + 7`.
    pub const DIM: usize = 2 * N + 7;
}

impl<M, T, const N: usize, const NA: usize> crate::integrate::LaneSystem<T> for ProductionLanes<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
    T: Real,
{
    fn dim(&self) -> usize {
        2 * N + 7
    }

    #[inline]
    fn rhs(&mut self, _t: T, y: &[T], dydt: &mut [T]) -> u32 {
        production_rhs::<M, T, N, NA>(self.molecule, y, dydt, self.min_pivot)
    }
}
