//! ∂U/∂q by central differences, for a surface that gives only U.
//!
//! Step rule: `h_k = ε^(1/3) · max(1, |q_k|)` (ε = 2⁻⁵², so h ≈ 6.1e-6 bohr or rad near 1),
//! which balances the truncation error `h² |U'''| / 6` against the round-off `ε |U| / h`: the
//! gradient is good to about `ε^(2/3) ≈ 4e-11` relative to the size of U and its third
//! derivatives. Each gradient costs `2N + 1` energy calls (N the number of coordinates).

use nalgebra::SVector;

use crate::surface::{Dipole, Potential};

/// The relative step `ε^(1/3)`.
pub const RELATIVE_STEP: f64 = 6.055_454_452_393_343e-6;

/// The central-difference step for a coordinate at `x`.
pub fn step(x: f64) -> f64 {
    RELATIVE_STEP * x.abs().max(1.0)
}

/// ∂U/∂q of `energy` at `q` by central differences into `grad`; returns `U(q)` (2N + 1 calls).
pub fn central_gradient<const N: usize>(
    energy: impl Fn(&SVector<f64, N>) -> f64,
    q: &SVector<f64, N>,
    grad: &mut SVector<f64, N>,
) -> f64 {
    for k in 0..N {
        let h = step(q[k]);
        let (mut plus, mut minus) = (*q, *q);
        plus[k] += h;
        minus[k] -= h;
        // The steps actually taken (q ± h rounded), so that the quotient is exact in them.
        grad[k] = (energy(&plus) - energy(&minus)) / (plus[k] - minus[k]);
    }
    energy(q)
}

/// What a run states about a gradient by central differences, for `n` coordinates.
pub fn note(n: usize) -> String {
    format!(
        "∂U/∂q by central differences (step ε^(1/3)·max(1, |q_k|) ≈ 6e-6): {} energy calls per gradient, \
         relative accuracy about 4e-11 of the surface's scale",
        2 * n + 1
    )
}

/// Potential `P` with its gradient replaced by central differences of its energy
/// ([`central_gradient`]); its dipole, if any, is `P`'s.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CentralDifferences<P>(pub P);

impl<P: Potential<N>, const N: usize> Potential<N> for CentralDifferences<P> {
    fn energy(&self, q: &SVector<f64, N>) -> f64 {
        self.0.energy(q)
    }

    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        central_gradient(|q| self.0.energy(q), q, grad)
    }

    fn dipole_part(&self) -> Option<&dyn Dipole<N>> {
        self.0.dipole_part()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_step_is_the_cube_root_of_epsilon() {
        assert!((RELATIVE_STEP - f64::EPSILON.cbrt()).abs() < 1e-20);
    }

    #[test]
    fn central_differences_of_a_known_function_are_within_the_stated_accuracy() {
        // U = exp(q0) sin(q1) + q0² q1, at a few points.
        let u = |q: &SVector<f64, 2>| q[0].exp() * q[1].sin() + q[0] * q[0] * q[1];
        for q in [SVector::from([0.3, 1.2]), SVector::from([-2.0, 7.5]), SVector::from([1.5, -0.1])] {
            let mut g = SVector::zeros();
            assert_eq!(central_gradient(u, &q, &mut g), u(&q));
            let exact =
                SVector::from([q[0].exp() * q[1].sin() + 2.0 * q[0] * q[1], q[0].exp() * q[1].cos() + q[0] * q[0]]);
            let scale = 1.0 + q[0].exp() + q[0] * q[0] + q[1].abs();
            assert!((g - exact).norm() <= 1e-9 * scale, "{g:?} {exact:?}");
        }
    }
}
