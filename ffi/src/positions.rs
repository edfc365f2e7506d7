//! A shared library's surface over the atoms' Cartesian positions (the `rovib_surface_positions_*`
//! functions of `rovib_surface.h`): [`PositionSurface`] is its [`CartesianPotential`], and
//! [`OnPositions`] composes it with a molecule's positions `R(q)` into a [`Potential`] over the
//! internal coordinates (with the library's dipole over positions, if it has one, as a
//! [`Dipole`]).

use std::marker::PhantomData;

use rovib_runtime::finite_differences::{central_gradient, step};
use rovib_runtime::molecule::Molecule;
use rovib_runtime::nalgebra::{SMatrix, SVector, Vector3};
use rovib_runtime::position_surface::{CartesianPotential, FromPositions};
use rovib_runtime::surface::{Dipole, Potential};

use crate::{SharedLibrary, raw};

/// A C surface over the positions of `NA` atoms (bohr, the molecule's atom order): U(x), and
/// ∂U/∂x from the library's gradient function or, without one, central differences over the
/// 3·NA components. `'a` is the library it came from.
#[derive(Copy, Clone, Debug)]
pub struct PositionSurface<'a, const NA: usize> {
    functions: raw::Functions,
    library: PhantomData<&'a SharedLibrary>,
}

impl<'a, const NA: usize> PositionSurface<'a, NA> {
    pub(crate) fn new(functions: raw::Functions) -> Self {
        debug_assert_eq!(functions.coordinates, 3 * NA);
        Self { functions, library: PhantomData }
    }

    /// Whether the library has `rovib_surface_positions_gradient`.
    pub fn has_gradient(&self) -> bool {
        self.functions.has_gradient()
    }

    /// Whether the library has a dipole surface over positions.
    pub fn has_dipole(&self) -> bool {
        self.functions.has_dipole()
    }

    /// The surface over the internal coordinates of `molecule` (whose atoms these are), with
    /// ∂U/∂q through the positions Jacobian, or by central differences in q if the library has
    /// no gradient function.
    pub fn on<M>(self, molecule: M) -> OnPositions<'a, M, NA> {
        let differences = !self.has_gradient();
        OnPositions { inner: FromPositions { molecule, surface: self }, differences }
    }
}

impl<const NA: usize> CartesianPotential<NA> for PositionSurface<'_, NA> {
    fn energy(&self, x: &SMatrix<f64, 3, NA>) -> f64 {
        // Column-major: atom i's x, y, z at 3i, 3i + 1, 3i + 2, the layout of rovib_surface.h.
        self.functions.energy(x.as_slice())
    }

    fn energy_gradient(&self, x: &SMatrix<f64, 3, NA>, grad: &mut SMatrix<f64, 3, NA>) -> f64 {
        if let Some(u) = self.functions.gradient(x.as_slice(), grad.as_mut_slice()) {
            return u;
        }
        for j in 0..3 * NA {
            let h = step(x[j]);
            let (mut plus, mut minus) = (*x, *x);
            plus[j] += h;
            minus[j] -= h;
            grad[j] = (self.energy(&plus) - self.energy(&minus)) / (plus[j] - minus[j]);
        }
        self.energy(x)
    }
}

/// A library surface over positions composed with molecule `M`'s positions: a [`Potential`]
/// over `M`'s internal coordinates (`U(q) = U(R(q))`) and, if the library has one, a [`Dipole`]
/// (`μ(q) = μ(R(q))`, in the body frame because `R(q)` is). No lane form.
#[derive(Copy, Clone, Debug)]
pub struct OnPositions<'a, M, const NA: usize> {
    inner: FromPositions<M, PositionSurface<'a, NA>, NA>,
    /// ∂U/∂q by central differences of U(q) (2N + 1 surface calls per gradient).
    differences: bool,
}

impl<M, const NA: usize> OnPositions<'_, M, NA> {
    /// The same surface with ∂U/∂q by central differences of U(q)
    /// ([`rovib_runtime::finite_differences`]: 2N + 1 surface calls per gradient).
    pub fn with_central_differences(self) -> Self {
        Self { differences: true, ..self }
    }

    /// Whether ∂U/∂q is taken by central differences.
    pub fn central_differences(&self) -> bool {
        self.differences
    }

    /// The surface over positions.
    pub fn surface(&self) -> &PositionSurface<'_, NA> {
        &self.inner.surface
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Potential<N> for OnPositions<'_, M, NA> {
    fn energy(&self, q: &SVector<f64, N>) -> f64 {
        self.inner.energy(q)
    }

    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        if self.differences {
            return central_gradient(|q| self.inner.energy(q), q, grad);
        }
        self.inner.energy_gradient(q, grad)
    }

    fn dipole_part(&self) -> Option<&dyn Dipole<N>> {
        self.inner.surface.has_dipole().then_some(self as &dyn Dipole<N>)
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Dipole<N> for OnPositions<'_, M, NA> {
    fn moment(&self, q: &SVector<f64, N>, mu: &mut Vector3<f64>) {
        let mut x = SMatrix::<f64, 3, NA>::zeros();
        self.inner.molecule.positions(q, &mut x);
        let mut m = [f64::NAN; 3];
        self.inner.surface.functions.dipole(x.as_slice(), &mut m);
        *mu = Vector3::from(m);
    }

    fn moment_jacobian(&self, q: &SVector<f64, N>, dmu: &mut SMatrix<f64, 3, N>) {
        let mut x = SMatrix::<f64, 3, NA>::zeros();
        let mut dr = [SMatrix::<f64, 3, NA>::zeros(); N];
        self.inner.molecule.positions(q, &mut x);
        self.inner.molecule.positions_jacobian(q, &mut dr);
        // Atom i's block: ∂μ_a/∂x_ic at 3c + a (column-major 3 × 3, as rovib_surface.h lays out).
        let mut blocks = [[f64::NAN; 9]; NA];
        if !self.inner.surface.functions.dipole_jacobian(x.as_slice(), blocks.as_flattened_mut()) {
            dmu.fill(f64::NAN);
            return;
        }
        for k in 0..N {
            for a in 0..3 {
                let mut s = 0.0;
                for (i, block) in blocks.iter().enumerate() {
                    for c in 0..3 {
                        s += block[3 * c + a] * dr[k][(c, i)];
                    }
                }
                dmu[(a, k)] = s;
            }
        }
    }
}
