//! The contract between generated code and the runtime: the [`Molecule`] trait.
//!
//! `rovib-codegen` turns each `molecules/NAME.toml` into a unit struct that implements
//! [`Molecule<N, NA>`] with `N` internal coordinates and `NA` atoms. Everything else in the
//! runtime (G matrices, Hamilton's equations, integrators, frames) is generic over this trait,
//! so a hand-written implementation works just as well as a generated one.
//!
//! The potential and the dipole are also parts of their own ([`crate::surface`]): a
//! [`crate::surface::Potential`] from outside (a shared library, C compiled at build time)
//! composed with a generated molecule's kinematics by [`crate::surface::WithPotential`] is a
//! full `Molecule`, with no method written by hand.
//!
//! # Conventions
//!
//! * Atomic units: q in bohr or radians, positions in bohr, masses in electron masses,
//!   energies in hartree.
//! * Positions are body-frame Cartesian positions `R_i(q)` with the centre of mass at the origin:
//!   `Σ m_i R_i = 0` for every q. Column `i` of a `3 × NA` matrix is atom `i`.
//! * The kinetic matrices follow `docs/src/reference/equations.md`, section 2:
//!   `a_jk = Σ m_i ∂R_i/∂q_j · ∂R_i/∂q_k`, `A_jk = Σ m_i [R_i × ∂R_i/∂q_k]_j`,
//!   `I = Σ m_i (|R_i|² 1 − R_i R_iᵀ)`, so that the kinetic energy is
//!   `T = ½ (ω, q̇)ᵀ [[I, A], [Aᵀ, a]] (ω, q̇)` with ω the body-frame angular velocity.
//! * Every method overwrites its outputs completely; callers need not clear them.
//! * Value and derivative entry points are separate so a caller pays only for what it uses.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use crate::lanes::{KineticLanes, Real};
use crate::units::CoordinateUnit;

/// One atom of a molecule.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Atom {
    /// The label from the definition file (unique within the molecule), e.g. `"H1"`.
    pub label: &'static str,
    /// The chemical element symbol, e.g. `"H"`.
    pub element: &'static str,
    /// The mass in daltons.
    pub mass_da: f64,
    /// The mass in electron masses (atomic units), used by all numerics.
    pub mass: f64,
}

/// One internal coordinate of a molecule.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Coordinate {
    /// The name from the definition file, e.g. `"r1"`.
    pub name: &'static str,
    /// The unit the definition file writes this coordinate in. Values passed to and returned by
    /// the runtime are always in the matching atomic unit (bohr or rad).
    pub unit: CoordinateUnit,
    /// The reference geometry from the definition file, in atomic units, if it gave one.
    pub reference: Option<f64>,
    /// The valid values, a closed interval `(low, high)` in atomic units: the definition's
    /// `range`, else `(0, ∞)` for lengths and `(−∞, ∞)` for angles. Bond angles declare
    /// `(0, π)`; outside its range a coordinate describes a mirror image or no geometry at all.
    pub range: (f64, f64),
}

impl Coordinate {
    /// Whether `value` (atomic units) lies in [`Coordinate::range`], ends included; NaN does not.
    pub fn contains(&self, value: f64) -> bool {
        self.range.0 <= value && value <= self.range.1
    }
}

/// The kinetic matrices `a` (n × n), `A` (3 × n) and `I` (3 × 3) of the seed's eq. (3), or one
/// q-derivative of all three.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct KineticMatrices<const N: usize> {
    /// The vibrational kinetic matrix `a` (symmetric).
    pub a: SMatrix<f64, N, N>,
    /// The Coriolis matrix `A`.
    pub coriolis: SMatrix<f64, 3, N>,
    /// The inertia tensor `I` (symmetric).
    pub inertia: Matrix3<f64>,
}

impl<const N: usize> Default for KineticMatrices<N> {
    fn default() -> Self {
        Self { a: SMatrix::zeros(), coriolis: SMatrix::zeros(), inertia: Matrix3::zeros() }
    }
}

/// A molecule: atoms, internal coordinates, body-frame positions, kinetic matrices and
/// potential, with `N` internal coordinates and `NA` atoms.
///
/// Implemented by the types that `rovib-codegen` generates from `molecules/*.toml`.
pub trait Molecule<const N: usize, const NA: usize> {
    /// The molecule's name, as in its definition file.
    fn name(&self) -> &'static str;

    /// The definition file this molecule was generated from, relative to the workspace root.
    fn source(&self) -> &'static str;

    /// The atoms, in definition order.
    fn atoms(&self) -> [Atom; NA];

    /// The internal coordinates, in definition order (the order of q and p).
    fn coordinates(&self) -> [Coordinate; N];

    /// Body-frame positions `R_i(q)` (column `i` is atom `i`), centre of mass at the origin.
    fn positions(&self, q: &SVector<f64, N>, r: &mut SMatrix<f64, 3, NA>);

    /// `∂R_i/∂q_k`: element `k` of `dr` is the 3 × NA matrix of derivatives along `q_k`.
    fn positions_jacobian(&self, q: &SVector<f64, N>, dr: &mut [SMatrix<f64, 3, NA>; N]);

    /// The kinetic matrices `a`, `A`, `I` at `q`.
    fn kinetic(&self, q: &SVector<f64, N>, k: &mut KineticMatrices<N>);

    /// Their q-derivatives: element `k` of `dk` holds `∂a/∂q_k`, `∂A/∂q_k`, `∂I/∂q_k`.
    ///
    /// Only the G-matrix reference path needs them. The default assembles them from
    /// [`Molecule::kinetic_energy_gradient`] by polarization ([`crate::polarization`]: exact up
    /// to rounding, `(N + 3)(N + 4)/2` gradient calls); the generator emits a symbolic version
    /// only on request (`ROVIB_KINETIC_JACOBIAN=generated`), since it grows like `N³`.
    fn kinetic_jacobian(&self, q: &SVector<f64, N>, dk: &mut [KineticMatrices<N>; N]) {
        crate::polarization::kinetic_jacobian(self, q, dk);
    }

    /// The gradient in q of the kinetic energy `T = ½ Σ m_i |ω × R_i + Σ_j ∂R_i/∂q_j q̇_j|²`
    /// at fixed body-frame angular velocity `omega` and fixed `qdot`; returns `T` as well.
    ///
    /// This equals `½ vᵀ (∂M/∂q_k) v` with `v = (ω, q̇)` and `M = [[I, A], [Aᵀ, a]]`, computed
    /// directly from the positions and their first and second derivatives.
    fn kinetic_energy_gradient(
        &self,
        q: &SVector<f64, N>,
        omega: &Vector3<f64>,
        qdot: &SVector<f64, N>,
        grad: &mut SVector<f64, N>,
    ) -> f64;

    /// [`Molecule::kinetic`] and [`Molecule::kinetic_energy_gradient`] in one call, with the
    /// velocities supplied in between: computes `a`, `A`, `I` into `k`, calls `velocities(k)`
    /// for `(ω, q̇)` (typically `M⁻¹ (J, p)` from a factorization of `k`), then the gradient of
    /// `T` at those velocities into `grad`, and returns `(ω, q̇, T)`.
    ///
    /// Generated molecules override this with one function in which both halves share every
    /// position term and every `sin`/`cos`, which the two separate calls compute twice; the
    /// default just makes the two calls.
    fn kinetic_and_gradient<E>(
        &self,
        q: &SVector<f64, N>,
        k: &mut KineticMatrices<N>,
        velocities: impl FnOnce(&KineticMatrices<N>) -> Result<(Vector3<f64>, SVector<f64, N>), E>,
        grad: &mut SVector<f64, N>,
    ) -> Result<(Vector3<f64>, SVector<f64, N>, f64), E> {
        self.kinetic(q, k);
        let (omega, qdot) = velocities(k)?;
        let t = self.kinetic_energy_gradient(q, &omega, &qdot, grad);
        Ok((omega, qdot, t))
    }

    /// The potential energy `U(q)` in hartree.
    fn potential(&self, q: &SVector<f64, N>) -> f64;

    /// `∂U/∂q` into `grad`; returns `U(q)` as well.
    fn potential_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64;

    /// Whether the generator emitted lane-generic [`Molecule::kinetic_and_gradient_lanes`] and
    /// [`Molecule::potential_gradient_lanes`] (the same operations as the `f64` functions).
    /// `false` for the trait's lane-by-lane defaults, and for molecules whose `a` gets its
    /// centre-of-mass term at run time (large molecules, `rovib_codegen::Options`): those are
    /// integrated one trajectory at a time ([`crate::hamiltonian::lanes::available`]).
    fn has_lane_forms(&self) -> bool {
        false
    }

    /// [`Molecule::kinetic_and_gradient`] for `T::LANES` states at once, one per lane of `T`
    /// ([`crate::lanes`]), with no error path: `velocities` returns `(ω, q̇)` for every lane.
    ///
    /// Generated molecules override this with lane-generic straight-line code (the same
    /// operations as their `kinetic_and_gradient`, with `T`'s `sin_cos` and `exp`: the vector
    /// polynomials of [`crate::transcendental`], so a lane's numbers are the `f64` function's to
    /// round-off); the default calls the `f64` methods lane by lane.
    fn kinetic_and_gradient_lanes<T: Real>(
        &self,
        q: &[T; N],
        k: &mut KineticLanes<T, N>,
        velocities: impl FnOnce(&KineticLanes<T, N>) -> ([T; 3], [T; N]),
        grad: &mut [T; N],
    ) -> ([T; 3], [T; N], T) {
        for lane in 0..T::LANES {
            let mut kl = KineticMatrices::default();
            self.kinetic(&SVector::from_fn(|i, _| q[i].lane(lane)), &mut kl);
            k.set_lane(lane, &kl);
        }
        let (omega, qdot) = velocities(k);
        let mut t = T::splat(0.0);
        for lane in 0..T::LANES {
            let mut g = SVector::zeros();
            let tl = self.kinetic_energy_gradient(
                &SVector::from_fn(|i, _| q[i].lane(lane)),
                &Vector3::from_fn(|i, _| omega[i].lane(lane)),
                &SVector::from_fn(|i, _| qdot[i].lane(lane)),
                &mut g,
            );
            t.set_lane(lane, tl);
            for i in 0..N {
                grad[i].set_lane(lane, g[i]);
            }
        }
        (omega, qdot, t)
    }

    /// [`Molecule::potential_gradient`] for `T::LANES` states at once (generated molecules
    /// override it with lane-generic code; the default calls the `f64` method lane by lane).
    fn potential_gradient_lanes<T: Real>(&self, q: &[T; N], grad: &mut [T; N]) -> T {
        let mut u = T::splat(0.0);
        for lane in 0..T::LANES {
            let mut g = SVector::zeros();
            u.set_lane(lane, self.potential_gradient(&SVector::from_fn(|i, _| q[i].lane(lane)), &mut g));
            for i in 0..N {
                grad[i].set_lane(lane, g[i]);
            }
        }
        u
    }

    /// The potential's parameters (`[potential.parameters]` of the definition, sorted by name)
    /// with their compiled-in values as written there; empty for a potential without any.
    fn parameters(&self) -> &'static [(&'static str, f64)] {
        &[]
    }

    /// `U(q)` in hartree with the parameters `params` (one per [`Molecule::parameters`], in
    /// that order; a shorter slice panics) instead of the compiled-in values. Generated
    /// molecules with parameters override this; the default ignores `params`.
    fn potential_with(&self, q: &SVector<f64, N>, params: &[f64]) -> f64 {
        let _ = params;
        self.potential(q)
    }

    /// [`Molecule::potential_gradient`] with the parameters `params` (see
    /// [`Molecule::potential_with`]).
    fn potential_gradient_with(&self, q: &SVector<f64, N>, params: &[f64], grad: &mut SVector<f64, N>) -> f64 {
        let _ = params;
        self.potential_gradient(q, grad)
    }

    /// Whether the definition has a `[dipole]` table (and [`Molecule::dipole`] computes it).
    fn has_dipole(&self) -> bool {
        false
    }

    /// The body-frame dipole moment μ(q) in e·bohr. Generated only for a definition with a
    /// `[dipole]` table; without one (see [`Molecule::has_dipole`]) this writes NaN.
    fn dipole(&self, q: &SVector<f64, N>, mu: &mut Vector3<f64>) {
        let _ = q;
        *mu = Vector3::from_element(f64::NAN);
    }

    /// `∂μ/∂q`: column `k` is `∂μ/∂q_k` in e·bohr per unit of q_k; NaN without a dipole.
    fn dipole_jacobian(&self, q: &SVector<f64, N>, dmu: &mut SMatrix<f64, 3, N>) {
        let _ = q;
        dmu.fill(f64::NAN);
    }

    /// The reference geometry in atomic units, or `None` if the definition gave none for some
    /// coordinate.
    fn reference_geometry(&self) -> Option<SVector<f64, N>> {
        let coords = self.coordinates();
        let mut q = SVector::zeros();
        for (k, c) in coords.iter().enumerate() {
            q[k] = c.reference?;
        }
        Some(q)
    }

    /// `Ok` if every coordinate of `q` lies in its [`Coordinate::range`], else the index of the
    /// first that does not (NaN counts as outside).
    fn in_range(&self, q: &SVector<f64, N>) -> Result<(), usize> {
        match self.coordinates().iter().zip(q.iter()).position(|(c, &x)| !c.contains(x)) {
            Some(k) => Err(k),
            None => Ok(()),
        }
    }

    /// The atomic masses in electron masses, in atom order.
    fn masses(&self) -> [f64; NA] {
        self.atoms().map(|a| a.mass)
    }

    // Coordinates declared by kind (distance, angle, dihedral): closed forms in Cartesian
    // positions. Generated for such definitions; the defaults say "not available".

    /// The internal coordinates of Cartesian positions `x` (bohr, column `i` is atom `i`, any
    /// frame and origin) in closed form, into `q`: distances, angles in `[0, π]`, dihedrals in
    /// `(−π, π]`. Returns `false` (and leaves `q` alone) for a molecule whose definition gives
    /// explicit positions without kinds; then only the iterative fit of `crate::frames` applies.
    fn internal_coordinates(&self, x: &SMatrix<f64, 3, NA>, q: &mut SVector<f64, N>) -> bool {
        let _ = (x, q);
        false
    }

    /// The potential `U(q(x))` in hartree at Cartesian positions `x` (bohr), or `None` when the
    /// coordinates have no closed form ([`Molecule::internal_coordinates`]).
    fn cartesian_potential(&self, x: &SMatrix<f64, 3, NA>) -> Option<f64> {
        let _ = x;
        None
    }

    /// `∂U/∂x` (hartree per bohr, column `i` is atom `i`) into `grad` and `U` (hartree), or
    /// `None` when the coordinates have no closed form. Not finite where a coordinate's closed
    /// form is not differentiable (an angle at exactly 0 or π, a dihedral about collinear atoms).
    fn cartesian_potential_gradient(&self, x: &SMatrix<f64, 3, NA>, grad: &mut SMatrix<f64, 3, NA>) -> Option<f64> {
        let _ = (x, grad);
        None
    }

    /// [`Molecule::cartesian_potential`] with the parameters `params` (see
    /// [`Molecule::potential_with`]). Generated for definitions with coordinates by kind and
    /// parameters; the default (no parameters, or no closed form) ignores `params`.
    fn cartesian_potential_with(&self, x: &SMatrix<f64, 3, NA>, params: &[f64]) -> Option<f64> {
        let _ = params;
        self.cartesian_potential(x)
    }

    /// [`Molecule::cartesian_potential_gradient`] with the parameters `params`.
    fn cartesian_potential_gradient_with(
        &self,
        x: &SMatrix<f64, 3, NA>,
        params: &[f64],
        grad: &mut SMatrix<f64, 3, NA>,
    ) -> Option<f64> {
        let _ = params;
        self.cartesian_potential_gradient(x, grad)
    }
}

/// Something to do with a molecule chosen at run time by name, for code that is generic over
/// [`Molecule<N, NA>`]: the generated `molecules::visit(name, visitor)` calls
/// [`MoleculeVisitor::visit`] with the matching generated type, so each molecule gets its own
/// monomorphised, fixed-size code path.
pub trait MoleculeVisitor {
    /// The result of the visit.
    type Output;

    /// Called with the molecule.
    fn visit<M, const N: usize, const NA: usize>(self, molecule: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static;
}

/// The kinematic methods of a [`Molecule`] wrapper, forwarded to the wrapped molecule in field
/// `$field`: name, source, atoms, coordinates, positions and their Jacobian, the kinetic matrices
/// and their derivatives (also on lanes). For a type that replaces only the potential (or its
/// parameters) and keeps the generated kinematics; write it inside the `impl Molecule` block.
#[macro_export]
macro_rules! forward_kinematics {
    ($field:ident) => {
        fn name(&self) -> &'static str {
            self.$field.name()
        }
        fn source(&self) -> &'static str {
            self.$field.source()
        }
        fn atoms(&self) -> [$crate::molecule::Atom; NA] {
            self.$field.atoms()
        }
        fn coordinates(&self) -> [$crate::molecule::Coordinate; N] {
            self.$field.coordinates()
        }
        fn positions(&self, q: &$crate::nalgebra::SVector<f64, N>, r: &mut $crate::nalgebra::SMatrix<f64, 3, NA>) {
            self.$field.positions(q, r)
        }
        fn positions_jacobian(
            &self,
            q: &$crate::nalgebra::SVector<f64, N>,
            dr: &mut [$crate::nalgebra::SMatrix<f64, 3, NA>; N],
        ) {
            self.$field.positions_jacobian(q, dr)
        }
        fn kinetic(&self, q: &$crate::nalgebra::SVector<f64, N>, k: &mut $crate::molecule::KineticMatrices<N>) {
            self.$field.kinetic(q, k)
        }
        fn kinetic_jacobian(
            &self,
            q: &$crate::nalgebra::SVector<f64, N>,
            dk: &mut [$crate::molecule::KineticMatrices<N>; N],
        ) {
            self.$field.kinetic_jacobian(q, dk)
        }
        fn kinetic_energy_gradient(
            &self,
            q: &$crate::nalgebra::SVector<f64, N>,
            omega: &$crate::nalgebra::Vector3<f64>,
            qdot: &$crate::nalgebra::SVector<f64, N>,
            grad: &mut $crate::nalgebra::SVector<f64, N>,
        ) -> f64 {
            self.$field.kinetic_energy_gradient(q, omega, qdot, grad)
        }
        fn kinetic_and_gradient<E>(
            &self,
            q: &$crate::nalgebra::SVector<f64, N>,
            k: &mut $crate::molecule::KineticMatrices<N>,
            velocities: impl FnOnce(
                &$crate::molecule::KineticMatrices<N>,
            ) -> Result<($crate::nalgebra::Vector3<f64>, $crate::nalgebra::SVector<f64, N>), E>,
            grad: &mut $crate::nalgebra::SVector<f64, N>,
        ) -> Result<($crate::nalgebra::Vector3<f64>, $crate::nalgebra::SVector<f64, N>, f64), E> {
            self.$field.kinetic_and_gradient(q, k, velocities, grad)
        }
        fn kinetic_and_gradient_lanes<T: $crate::lanes::Real>(
            &self,
            q: &[T; N],
            k: &mut $crate::lanes::KineticLanes<T, N>,
            velocities: impl FnOnce(&$crate::lanes::KineticLanes<T, N>) -> ([T; 3], [T; N]),
            grad: &mut [T; N],
        ) -> ([T; 3], [T; N], T) {
            self.$field.kinetic_and_gradient_lanes(q, k, velocities, grad)
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{AngleUnit, LengthUnit};

    #[test]
    fn a_range_is_closed_and_rejects_nan() {
        let angle = Coordinate {
            name: "alpha",
            unit: CoordinateUnit::Angle(AngleUnit::Deg),
            reference: None,
            range: (0.0, core::f64::consts::PI),
        };
        assert!(angle.contains(0.0) && angle.contains(1.0) && angle.contains(core::f64::consts::PI));
        assert!(!angle.contains(-1e-12) && !angle.contains(3.2) && !angle.contains(f64::NAN));
        let length = Coordinate {
            name: "r",
            unit: CoordinateUnit::Length(LengthUnit::Bohr),
            reference: None,
            range: (0.0, f64::INFINITY),
        };
        assert!(length.contains(1e300) && !length.contains(-2.05));
    }
}
