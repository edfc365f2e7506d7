//! Potential energy surfaces over the atoms' Cartesian positions (what machine-learned
//! potentials and ASE calculators are), composed with the generated positions `R(q)`.
//!
//! A [`CartesianPotential<NA>`] is `U(x)` over the 3 × NA positions (column `i` is atom `i`, in
//! the molecule's atom order, bohr → hartree). [`FromPositions`] makes it a [`Potential<N>`] over
//! the internal coordinates: `U(q) = U(R(q))` and, by the chain rule through the generated
//! positions Jacobian ([`Kinematics::positions_jacobian`](crate::molecule::Kinematics::positions_jacobian)),
//! `∂U/∂q_k = Σ_i ∂U/∂x_i · ∂R_i/∂q_k`.
//!
//! `R(q)` is the body frame with the centre of mass at the origin, so the surface must not
//! depend on where the molecule is or how it is turned: it must be invariant under translations
//! and rotations of all atoms together (every isolated-molecule surface is).
//! [`check_rotation_invariance`] tests this at given positions before a run.

use nalgebra::{Rotation3, SMatrix, SVector, Vector3};

use crate::molecule::Molecule;
use crate::surface::Potential;

/// A potential over the atoms' positions: `U(x)` and `∂U/∂x`, hartree and bohr.
pub trait CartesianPotential<const NA: usize> {
    /// `U(x)`; column `i` of `x` is atom `i`.
    fn energy(&self, x: &SMatrix<f64, 3, NA>) -> f64;

    /// `∂U/∂x` into `grad` (overwritten; column `i` is `∂U/∂x_i`); returns `U(x)`.
    fn energy_gradient(&self, x: &SMatrix<f64, 3, NA>, grad: &mut SMatrix<f64, 3, NA>) -> f64;
}

/// A [`CartesianPotential`] composed with molecule `M`'s positions: a [`Potential`] over `M`'s
/// internal coordinates (`NA` is `M`'s number of atoms: `FromPositions::<_, _, 3> { .. }`). It costs one `positions_jacobian` (which also gives nothing else
/// the right-hand side needs) and one surface call per gradient; no lane form (ensembles run
/// one trajectory at a time).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FromPositions<M, C, const NA: usize> {
    /// The molecule whose positions `R(q)` the surface is evaluated at.
    pub molecule: M,
    /// The surface over the positions.
    pub surface: C,
}

impl<M, C, const N: usize, const NA: usize> Potential<N> for FromPositions<M, C, NA>
where
    M: Molecule<N, NA>,
    C: CartesianPotential<NA>,
{
    fn energy(&self, q: &SVector<f64, N>) -> f64 {
        let mut x = SMatrix::<f64, 3, NA>::zeros();
        self.molecule.positions(q, &mut x);
        self.surface.energy(&x)
    }

    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        let mut x = SMatrix::<f64, 3, NA>::zeros();
        let mut gx = SMatrix::<f64, 3, NA>::zeros();
        let mut dr = [SMatrix::<f64, 3, NA>::zeros(); N];
        self.molecule.positions(q, &mut x);
        self.molecule.positions_jacobian(q, &mut dr);
        let u = self.surface.energy_gradient(&x, &mut gx);
        for k in 0..N {
            grad[k] = gx.dot(&dr[k]);
        }
        u
    }
}

/// Σ v(r_ij) over `pairs` of atoms `(i, j)`, with r_ij = |x_i − x_j|, and its gradient added
/// to `grad` (which the caller zeroes first): the building block of a site–site surface's
/// [`CartesianPotential::energy_gradient`]. `v` returns the pair term and its derivative dv/dr.
pub fn add_pair_terms<const NA: usize>(
    x: &SMatrix<f64, 3, NA>,
    pairs: impl IntoIterator<Item = (usize, usize)>,
    v: impl Fn(f64) -> (f64, f64),
    grad: &mut SMatrix<f64, 3, NA>,
) -> f64 {
    let mut u = 0.0;
    for (i, j) in pairs {
        let d = x.column(i) - x.column(j);
        let r = d.norm();
        let (e, de) = v(r);
        u += e;
        let f = de / r * d;
        let mut gi = grad.column_mut(i);
        gi += f;
        let mut gj = grad.column_mut(j);
        gj -= f;
    }
    u
}

/// A Cartesian surface that changes when all atoms are turned or moved together.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error(
    "the surface is not invariant under {motion}: U = {energy:e} hartree at the given positions, {moved:e} after \
     (difference {difference:e}, more than {tolerance:e}); a surface over positions must not depend on the \
     molecule's place or orientation, because rovib evaluates it in the body frame"
)]
pub struct InvarianceError {
    /// What was done to the positions.
    pub motion: String,
    /// U at the given positions.
    pub energy: f64,
    /// U after.
    pub moved: f64,
    /// |difference|.
    pub difference: f64,
    /// What was accepted.
    pub tolerance: f64,
}

/// Checks that `c` gives the same U (to `relative · max(|U|, 1e-6)`, hartree) at `x` turned
/// by three fixed rotations and moved by a fixed translation, and that its gradient turns with
/// the positions (`∂U/∂x` at `Rx` is `R ∂U/∂x`, to the same relative tolerance of its norm).
pub fn check_rotation_invariance<C: CartesianPotential<NA> + ?Sized, const NA: usize>(
    c: &C,
    x: &SMatrix<f64, 3, NA>,
    relative: f64,
) -> Result<(), InvarianceError> {
    let mut g0 = SMatrix::<f64, 3, NA>::zeros();
    let u0 = c.energy_gradient(x, &mut g0);
    let tolerance = relative * u0.abs().max(1e-6);
    let gradient_tolerance = relative * g0.norm().max(1e-6);
    let rotations = [
        ("a rotation by 0.7 rad about x", Rotation3::from_axis_angle(&Vector3::x_axis(), 0.7)),
        ("a rotation by 1.9 rad about y", Rotation3::from_axis_angle(&Vector3::y_axis(), 1.9)),
        ("a rotation by (0.4, -1.1, 2.3) Euler angles", Rotation3::from_euler_angles(0.4, -1.1, 2.3)),
    ];
    let shift = Vector3::new(0.37, -1.3, 2.1);
    let mut g = SMatrix::<f64, 3, NA>::zeros();
    for (motion, r) in rotations
        .iter()
        .map(|(m, r)| (m.to_string(), *r))
        .chain(std::iter::once((format!("a translation by {shift:?} bohr"), Rotation3::identity())))
    {
        let mut moved = r.matrix() * x;
        if motion.starts_with("a translation") {
            for mut column in moved.column_iter_mut() {
                column += shift;
            }
        }
        let u = c.energy_gradient(&moved, &mut g);
        let turned = r.matrix() * g0;
        let difference = (u - u0).abs();
        let gradient_difference = (g - turned).norm();
        if difference.is_nan()
            || difference > tolerance
            || gradient_difference.is_nan()
            || gradient_difference > gradient_tolerance
        {
            return Err(InvarianceError {
                motion: if difference <= tolerance {
                    format!("{motion} (its gradient does not turn with it)")
                } else {
                    motion
                },
                energy: u0,
                moved: u,
                difference: difference.max(gradient_difference),
                tolerance,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Σ_{i<j} (r_ij − 1)², invariant; and the same plus an external field along z, not.
    struct Springs {
        field: f64,
    }

    impl CartesianPotential<3> for Springs {
        fn energy(&self, x: &SMatrix<f64, 3, 3>) -> f64 {
            let mut g = SMatrix::zeros();
            self.energy_gradient(x, &mut g)
        }
        fn energy_gradient(&self, x: &SMatrix<f64, 3, 3>, grad: &mut SMatrix<f64, 3, 3>) -> f64 {
            grad.fill(0.0);
            let pairs = [(0, 1), (0, 2), (1, 2)];
            let mut u = add_pair_terms(x, pairs, |r| ((r - 1.0).powi(2), 2.0 * (r - 1.0)), grad);
            for i in 0..3 {
                u += self.field * x[(2, i)];
                grad[(2, i)] += self.field;
            }
            u
        }
    }

    #[test]
    fn an_invariant_surface_passes_and_an_external_field_is_caught() {
        let x = SMatrix::<f64, 3, 3>::from_column_slice(&[0.0, 0.0, 0.0, 1.2, 0.0, 0.1, -0.3, 0.9, 0.2]);
        assert_eq!(check_rotation_invariance(&Springs { field: 0.0 }, &x, 1e-12), Ok(()));
        let e = check_rotation_invariance(&Springs { field: 0.01 }, &x, 1e-12).unwrap_err();
        assert!(e.motion.contains("rotation"), "{e}");
    }
}
