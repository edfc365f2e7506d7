//! The q-derivatives of the kinetic matrices from the kinetic-energy gradient, by polarization:
//! the default [`Kinematics::kinetic_jacobian`](crate::molecule::Kinematics::kinetic_jacobian) that the G-matrix reference path uses when the
//! generator did not emit the symbolic one (it does not by default; see `rovib-codegen`'s
//! `Options`).
//!
//! With `v = (ω, q̇)` and `M = [[I, A], [Aᵀ, a]]`, the kinetic-energy gradient returns
//! `g_l(v) = ½ vᵀ (∂M/∂q_l) v` for every `l` at once. A symmetric matrix is determined by its
//! quadratic form (polarization identity): with unit vectors `e_a`,
//!
//! ```text
//! (∂_l M)_aa = 2 g_l(e_a),        (∂_l M)_ab = g_l(e_a + e_b) − g_l(e_a) − g_l(e_b)   (a ≠ b)
//! ```
//!
//! so `(N + 3)(N + 4)/2` gradient evaluations give every `∂a/∂q_l`, `∂A/∂q_l`, `∂I/∂q_l`, exact
//! up to rounding (an off-diagonal entry carries an absolute error of a few ulps of the two
//! diagonal entries it is taken from). The cost is `O(N²)` gradient evaluations, each
//! `O(Σ_i n_i² + N²)` for local coordinates: fine for the reference path, which already costs
//! `O(N⁴)` per evaluation, and independent of the molecule's size at build time.
//!
//! Checked against a hand-written `kinetic_jacobian` (`runtime/tests/hamiltonian.rs`) and
//! against finite differences of `kinetic` for every shipped molecule (`tests/numerics/generated_code.rs`).

use nalgebra::{SVector, Vector3};

use crate::kinetic_matrices::KineticMatrices;

/// `dk[l]` = `∂a/∂q_l`, `∂A/∂q_l`, `∂I/∂q_l` from a molecule's kinetic-energy gradient at one
/// geometry: `kinetic_energy_gradient(omega, qdot, out)` is
/// [`Kinematics::kinetic_energy_gradient`] at that q.
///
/// [`Kinematics::kinetic_energy_gradient`]: crate::molecule::Kinematics::kinetic_energy_gradient
pub fn kinetic_jacobian<const N: usize>(
    kinetic_energy_gradient: impl Fn(&Vector3<f64>, &SVector<f64, N>, &mut SVector<f64, N>) -> f64,
    dk: &mut [KineticMatrices<N>; N],
) {
    // g(v) into `out`, for v = e_a (+ e_b).
    let gradient = |a: usize, b: Option<usize>, out: &mut SVector<f64, N>| {
        let mut omega = Vector3::zeros();
        let mut qdot = SVector::<f64, N>::zeros();
        for x in std::iter::once(a).chain(b) {
            if x < 3 {
                omega[x] = 1.0;
            } else {
                qdot[x - 3] = 1.0;
            }
        }
        kinetic_energy_gradient(&omega, &qdot, out);
    };
    // Stores (∂_l M)_ab = (∂_l M)_ba = value[l] for every l.
    let store = |dk: &mut [KineticMatrices<N>; N], a: usize, b: usize, value: &SVector<f64, N>| {
        for (l, d) in dk.iter_mut().enumerate() {
            let x = value[l];
            match (a < 3, b < 3) {
                (true, true) => {
                    d.inertia[(a, b)] = x;
                    d.inertia[(b, a)] = x;
                }
                (true, false) => d.coriolis[(a, b - 3)] = x,
                (false, true) => d.coriolis[(b, a - 3)] = x,
                (false, false) => {
                    d.a[(a - 3, b - 3)] = x;
                    d.a[(b - 3, a - 3)] = x;
                }
            }
        }
    };
    let dim = N + 3;
    let mut g = SVector::<f64, N>::zeros();
    for a in 0..dim {
        gradient(a, None, &mut g);
        store(dk, a, a, &(2.0 * g));
    }
    // g_l(e_a) is half the diagonal just stored (halving is exact), so nothing else is kept.
    let half_diagonal =
        |d: &KineticMatrices<N>, a: usize| 0.5 * if a < 3 { d.inertia[(a, a)] } else { d.a[(a - 3, a - 3)] };
    for a in 0..dim {
        for b in a + 1..dim {
            gradient(a, Some(b), &mut g);
            for (l, x) in g.iter_mut().enumerate() {
                *x -= half_diagonal(&dk[l], a) + half_diagonal(&dk[l], b);
            }
            store(dk, a, b, &g);
        }
    }
}
