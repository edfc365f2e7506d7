//! The Cartesian chart: Newton's equations for the atoms in a lab frame that moves with the
//! centre of mass, with the potential `U(x)` and its gradient `∂U/∂x` that the generator emits
//! for definitions whose coordinates are declared by kind ([`Molecule::cartesian_potential`]).
//!
//! It has no singular configuration: what `rovib run` integrates while the chart of internal
//! coordinates and orientation is singular or close to it (a linear geometry), see
//! [`crate::charts`].
//!
//! # State layout
//!
//! `[x_0, y_0, z_0, x_1, …, z_{NA−1} | v_0x, …, v_{NA−1}z]`: positions (bohr) and velocities
//! (bohr per ħ/E_h) atom by atom in the molecule's atom order, relative to the centre of mass
//! (which the Hamiltonian splits off and `rovib run` carries separately). `dx/dt = v`,
//! `dv/dt = −(1/m_i) ∂U/∂x_i`. Total momentum and the angular momentum about the centre of
//! mass are conserved by these equations (U depends only on distances and angles).

use nalgebra::{SMatrix, Vector3};

use crate::frames::LabState;
use crate::hamiltonian::MetricFactor;
use crate::integrate::OdeSystem;
use crate::molecule::{KineticMatrices, Molecule};
use nalgebra::SVector;

/// Why the Cartesian right-hand side stopped.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CartesianError {
    /// Not an error: the chart of internal coordinates is regular (every relative pivot of the
    /// kinetic metric above the threshold) at this state, so the run switches back to it.
    #[error("the internal-coordinate chart is regular again (relative pivots above {threshold:e})")]
    Regular {
        /// The threshold.
        threshold: f64,
    },
    /// The molecule has no Cartesian potential: its definition gives explicit positions rather
    /// than coordinates by kind.
    #[error(
        "molecule {molecule} has no Cartesian potential U(x): its definition gives atom positions rather than \
         coordinates by kind (distance, angle, dihedral), so there is no chart to continue in at a singular geometry"
    )]
    NoCartesianPotential {
        /// The molecule.
        molecule: &'static str,
    },
    /// The potential or its gradient is not finite here (even after averaging across a point
    /// where a coordinate's closed form is not differentiable).
    #[error("the Cartesian potential gradient ∂U/∂x is not finite at x = {x:?} bohr")]
    NonFinite {
        /// The positions, atom by atom.
        x: Vec<[f64; 3]>,
    },
}

/// Half-width (bohr) of the symmetric average that replaces `∂U/∂x` at a point where the
/// generated gradient is not finite (an angle at exactly π: `acos` is not differentiable there,
/// although a potential even in `α − π` is smooth): `½ (∇U(x + δd) + ∇U(x − δd))` equals
/// `∇U(x)` to `O(δ²)` wherever U is smooth.
pub const KINK_AVERAGE: f64 = 1e-6;

/// Newton's equations of a molecule in the Cartesian chart (module documentation).
#[derive(Clone, Copy, Debug)]
pub struct CartesianSystem<'a, M: ?Sized, const N: usize, const NA: usize> {
    molecule: &'a M,
    inverse_masses: [f64; NA],
    masses: [f64; NA],
    /// If set, every evaluation at a time after `check_after` first checks the internal chart
    /// at this state and fails with [`CartesianError::Regular`] when its metric's relative
    /// pivots all exceed this.
    return_pivot: Option<f64>,
    check_after: f64,
}

impl<'a, M, const N: usize, const NA: usize> CartesianSystem<'a, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The Cartesian chart of `molecule`; fails if it has no Cartesian potential.
    pub fn new(molecule: &'a M) -> Result<Self, CartesianError> {
        if molecule.cartesian_potential(&SMatrix::zeros()).is_none() {
            return Err(CartesianError::NoCartesianPotential { molecule: molecule.name() });
        }
        let masses = molecule.masses();
        Ok(Self {
            molecule,
            inverse_masses: masses.map(|m| 1.0 / m),
            masses,
            return_pivot: None,
            check_after: f64::NEG_INFINITY,
        })
    }

    /// The same system, failing with [`CartesianError::Regular`] wherever the internal chart's
    /// relative pivots all exceed `pivot` (how the switch back is detected).
    pub fn with_return_pivot(mut self, pivot: f64) -> Self {
        self.return_pivot = Some(pivot);
        self
    }

    /// Makes the return test apply only to evaluations at times after `t` (so that a segment
    /// entered at a state the test would accept still takes its first step).
    pub fn check_after(&mut self, t: f64) {
        self.check_after = t;
    }

    /// The molecule.
    pub fn molecule(&self) -> &'a M {
        self.molecule
    }

    /// `6·NA`.
    pub const DIM: usize = 6 * NA;

    /// The positions of a flat state (column i is atom i).
    pub fn positions(y: &[f64]) -> SMatrix<f64, 3, NA> {
        SMatrix::from_column_slice(&y[..3 * NA])
    }

    /// The flat state of a centre-of-mass lab state (positions and velocities relative to the
    /// centre of mass, which the caller has removed).
    pub fn flat(lab: &LabState<NA>, y: &mut [f64]) {
        y[..3 * NA].copy_from_slice(lab.positions.as_slice());
        y[3 * NA..6 * NA].copy_from_slice(lab.velocities.as_slice());
    }

    /// The lab state of a flat state (relative to the centre of mass).
    pub fn lab(y: &[f64]) -> LabState<NA> {
        LabState {
            positions: SMatrix::from_column_slice(&y[..3 * NA]),
            velocities: SMatrix::from_column_slice(&y[3 * NA..6 * NA]),
        }
    }

    /// `H = Σ ½ m_i |v_i|² + U(x)`, hartree.
    pub fn energy(&self, y: &[f64]) -> Result<f64, CartesianError> {
        let lab = Self::lab(y);
        let u = self
            .molecule
            .cartesian_potential(&lab.positions)
            .ok_or(CartesianError::NoCartesianPotential { molecule: self.molecule.name() })?;
        let t = lab.kinetic_energy(&self.masses);
        let h = t + u;
        if h.is_finite() { Ok(h) } else { Err(self.non_finite(&lab.positions)) }
    }

    /// Whether the internal chart's metric at positions `x` has every relative pivot above
    /// `pivot` (no allocation).
    pub fn internal_chart_regular(&self, x: &SMatrix<f64, 3, NA>, pivot: f64) -> bool {
        let mut q = SVector::<f64, N>::zeros();
        if !self.molecule.internal_coordinates(x, &mut q) {
            return false;
        }
        let mut k = KineticMatrices::<N>::default();
        self.molecule.kinetic(&q, &mut k);
        MetricFactor::is_regular(&k, pivot)
    }

    /// `∂U/∂x` into `grad`, averaged symmetrically across a point where the generated gradient
    /// is not finite ([`KINK_AVERAGE`]).
    pub(crate) fn gradient(
        &self,
        x: &SMatrix<f64, 3, NA>,
        grad: &mut SMatrix<f64, 3, NA>,
    ) -> Result<(), CartesianError> {
        let none = || CartesianError::NoCartesianPotential { molecule: self.molecule.name() };
        self.molecule.cartesian_potential_gradient(x, grad).ok_or_else(none)?;
        if grad.iter().all(|g| g.is_finite()) {
            return Ok(());
        }
        // A fixed direction that moves every atom off any line or plane the geometry lies in.
        let d = SMatrix::<f64, 3, NA>::from_fn(|a, i| ((1 + a + 3 * i) as f64 * 1.618_033_988_75).sin());
        let d = d / d.norm() * KINK_AVERAGE;
        let mut plus = SMatrix::<f64, 3, NA>::zeros();
        self.molecule.cartesian_potential_gradient(&(x + d), &mut plus).ok_or_else(none)?;
        self.molecule.cartesian_potential_gradient(&(x - d), grad).ok_or_else(none)?;
        *grad = (*grad + plus) * 0.5;
        if grad.iter().all(|g| g.is_finite()) { Ok(()) } else { Err(self.non_finite(x)) }
    }

    #[cold]
    fn non_finite(&self, x: &SMatrix<f64, 3, NA>) -> CartesianError {
        CartesianError::NonFinite { x: x.column_iter().map(|c| [c[0], c[1], c[2]]).collect() }
    }

    /// The lab-frame angular momentum `Σ m_i x_i × v_i` (about the centre of mass), ħ.
    pub fn angular_momentum(&self, y: &[f64]) -> Vector3<f64> {
        Self::lab(y).angular_momentum(&self.masses)
    }
}

impl<M, const N: usize, const NA: usize> OdeSystem for CartesianSystem<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    type Error = CartesianError;

    fn dim(&self) -> usize {
        6 * NA
    }

    fn rhs(&mut self, t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), CartesianError> {
        let x = Self::positions(y);
        if let Some(threshold) = self.return_pivot
            && t > self.check_after
            && self.internal_chart_regular(&x, threshold)
        {
            return Err(CartesianError::Regular { threshold });
        }
        let mut grad = SMatrix::<f64, 3, NA>::zeros();
        self.gradient(&x, &mut grad)?;
        dydt[..3 * NA].copy_from_slice(&y[3 * NA..6 * NA]);
        for i in 0..NA {
            for a in 0..3 {
                dydt[3 * NA + 3 * i + a] = -grad[(a, i)] * self.inverse_masses[i];
            }
        }
        Ok(())
    }
}
