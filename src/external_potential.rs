//! A potential given at run time ([`ExternalPotential`], e.g. a Python function) over a
//! molecule's internal coordinates, as the [`Potential`] a run composes with the molecule's
//! kinematics, and the gradient check it passes before the first step.

use crate::error::Error;
use crate::runtime::molecule::Molecule;
use crate::runtime::nalgebra::SVector;
use crate::runtime::surface::{GradientCheck, GradientError, Potential, check_gradient};

/// A potential given at run time over the molecule's internal coordinates (atomic units, the
/// molecule's coordinate order).
pub trait ExternalPotential: Sync {
    /// U(q), with ∂U/∂q written into `grad` (one entry per coordinate). A potential that fails
    /// returns NaN (the run then stops on a non-finite value) and keeps its own error for the
    /// caller.
    fn energy_gradient(&self, q: &[f64], grad: &mut [f64]) -> f64;
    /// What to call it in messages, e.g. "the Python potential".
    fn describe(&self) -> String;
}

/// An [`ExternalPotential`] as the [`Potential`] of a molecule with `N` coordinates.
pub(crate) struct External<'a>(pub &'a dyn ExternalPotential);

impl<const N: usize> Potential<N> for External<'_> {
    fn energy(&self, q: &SVector<f64, N>) -> f64 {
        let mut grad = [0.0; N];
        self.0.energy_gradient(q.as_slice(), &mut grad)
    }
    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        self.0.energy_gradient(q.as_slice(), grad.as_mut_slice())
    }
}

/// Checks an external potential's gradient against central differences of its energy at the
/// reference geometry and around it, before the first step (as a scene's `[potential] library`
/// is checked); the error names the coordinate to fix.
pub(crate) fn check_external<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    potential: &dyn ExternalPotential,
) -> Result<(), Error> {
    let coordinates = m.coordinates();
    let centre = m.reference_geometry().unwrap_or_else(|| {
        SVector::from_fn(|k, _| {
            let (low, high) = coordinates[k].range;
            if low.is_finite() && high.is_finite() { 0.5 * (low + high) } else { low.max(1.0).min(high) }
        })
    });
    let what = potential.describe();
    check_gradient(&External(potential), &coordinates, &centre, &GradientCheck::default()).map_err(|e| match &e {
        GradientError::Mismatch { coordinate, .. } => Error::Message(format!(
            "the gradient of {what} disagrees with its energy: {e}; fix ∂U/∂{coordinate} (coordinate `{coordinate}` of \
             {}, in the order {})",
            m.source(),
            coordinates.map(|c| c.name).join(", ")
        )),
        GradientError::NotFinite { .. } => Error::Message(format!(
            "{what}: {e}; it must be finite inside the coordinates' ranges around the reference geometry"
        )),
    })
}
