//! Tabulated surfaces: a potential (and optionally a dipole) read from a grid file and
//! interpolated by tensor-product cubic splines ([`spline`]), composed with a molecule's
//! kinematics through [`crate::surface::WithPotential`].
//!
//! The grid's axes are named by the molecule's coordinates, in any order, and must cover all of
//! them: a coordinate not on the grid is refused when the grid is bound ([`GridPotential::new`]),
//! never taken to contribute nothing. Outside the grid's box the policy [`Outside`] applies.

pub mod file;
pub mod spline;

use nalgebra::{SMatrix, SVector, Vector3};

pub use file::{GridAxis, GridFile, parse};
pub use spline::{MAX_AXES, Outside, SplineError, TensorSpline};

use crate::molecule::Coordinate;
use crate::surface::{Dipole, Potential};

/// Why a grid cannot be the potential of a molecule.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BindError {
    /// An axis that is not one of the molecule's coordinates.
    #[error("the grid's axis `{axis}` is not a coordinate of the molecule (its coordinates: {coordinates})")]
    UnknownAxis {
        /// The axis's index in the file.
        index: usize,
        /// Its name.
        axis: String,
        /// The molecule's coordinates, comma-separated.
        coordinates: String,
    },
    /// A length axis for an angle coordinate or the reverse.
    #[error("the grid's axis `{axis}` is in {unit}, but coordinate `{axis}` is {kind}")]
    Kind {
        /// The axis's index in the file.
        index: usize,
        /// Its name.
        axis: String,
        /// The axis's unit.
        unit: &'static str,
        /// "a length" or "an angle".
        kind: &'static str,
    },
    /// A coordinate the grid does not cover.
    #[error("coordinate `{coordinate}` is not an axis of the grid; a grid potential must cover every coordinate")]
    Missing {
        /// The coordinate's name.
        coordinate: &'static str,
    },
}

/// A grid file's spline as the potential (and, with dipole columns, the dipole) of a molecule
/// with `N` coordinates.
#[derive(Clone, Debug)]
pub struct GridPotential<const N: usize> {
    spline: TensorSpline,
    /// The coordinate of each grid axis.
    coordinate_of: [usize; MAX_AXES],
    outside: Outside,
    dipole: bool,
}

impl<const N: usize> GridPotential<N> {
    /// Binds `grid` to the coordinates `coordinates` (by name) with policy `outside`.
    pub fn new(grid: &GridFile, coordinates: &[Coordinate; N], outside: Outside) -> Result<Self, BindError> {
        let mut coordinate_of = [0; MAX_AXES];
        for (index, axis) in grid.axes.iter().enumerate() {
            let Some(k) = coordinates.iter().position(|c| c.name == axis.name) else {
                return Err(BindError::UnknownAxis {
                    index,
                    axis: axis.name.clone(),
                    coordinates: coordinates.iter().map(|c| c.name).collect::<Vec<_>>().join(", "),
                });
            };
            let length = |u: crate::units::CoordinateUnit| matches!(u, crate::units::CoordinateUnit::Length(_));
            if length(axis.unit) != length(coordinates[k].unit) {
                return Err(BindError::Kind {
                    index,
                    axis: axis.name.clone(),
                    unit: axis.unit.name(),
                    kind: if length(coordinates[k].unit) { "a length" } else { "an angle" },
                });
            }
            coordinate_of[index] = k;
        }
        if let Some(c) = coordinates.iter().find(|c| !grid.axes.iter().any(|a| a.name == c.name)) {
            return Err(BindError::Missing { coordinate: c.name });
        }
        Ok(Self { spline: grid.spline.clone(), coordinate_of, outside, dipole: grid.dipole })
    }

    /// The spline.
    pub fn spline(&self) -> &TensorSpline {
        &self.spline
    }

    /// The coordinate index of grid axis `a`.
    pub fn coordinate_of(&self, a: usize) -> usize {
        self.coordinate_of[a]
    }

    /// The policy outside the box.
    pub fn outside(&self) -> Outside {
        self.outside
    }

    /// Whether `q` is inside the grid's box.
    pub fn contains(&self, q: &SVector<f64, N>) -> bool {
        self.spline.contains(&self.point(q))
    }

    fn point(&self, q: &SVector<f64, N>) -> [f64; MAX_AXES] {
        let mut x = [0.0; MAX_AXES];
        for (a, v) in x.iter_mut().enumerate().take(self.spline.axes()) {
            *v = q[self.coordinate_of[a]];
        }
        x
    }

    fn column(&self, column: usize, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        let mut g = [0.0; MAX_AXES];
        let v = self.spline.evaluate(column, &self.point(q), self.outside, &mut g);
        grad.fill(0.0);
        for (a, ga) in g.iter().enumerate().take(self.spline.axes()) {
            grad[self.coordinate_of[a]] = *ga;
        }
        v
    }
}

impl<const N: usize> Potential<N> for GridPotential<N> {
    fn energy(&self, q: &SVector<f64, N>) -> f64 {
        self.column(0, q, &mut SVector::zeros())
    }

    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        self.column(0, q, grad)
    }

    fn dipole_part(&self) -> Option<&dyn Dipole<N>> {
        if self.dipole { Some(self) } else { None }
    }
}

impl<const N: usize> Dipole<N> for GridPotential<N> {
    fn moment(&self, q: &SVector<f64, N>, mu: &mut Vector3<f64>) {
        let mut g = SVector::zeros();
        for c in 0..3 {
            mu[c] = self.column(c + 1, q, &mut g);
        }
    }

    fn moment_jacobian(&self, q: &SVector<f64, N>, dmu: &mut SMatrix<f64, 3, N>) {
        let mut g = SVector::zeros();
        for c in 0..3 {
            self.column(c + 1, q, &mut g);
            dmu.set_row(c, &g.transpose());
        }
    }
}
