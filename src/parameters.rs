//! Potential parameters at run time: a scene's `[potential.parameters]` overrides the values a
//! molecule was compiled with, without rebuilding. [`WithParameters`] is the molecule with its
//! potential evaluated by the generated `potential_with`/`potential_gradient_with` (the
//! parameters as inputs); everything else is the molecule's own code. Runs without overrides
//! keep the compiled-in constants (folded into the generated code), see BENCHMARKS.md for what
//! the run-time path costs.

use crate::runtime::diagnostic::FileError;
use crate::runtime::nalgebra::{SMatrix, SVector};
use crate::runtime::surface::Dipole;
use crate::runtime::{HasKinematics, Molecule};
use crate::scene::Scene;
use crate::scene::did_you_mean;

/// Molecule `M` with its potential's parameters set to `values` (one per
/// `M::parameters()`, in that order).
#[derive(Clone, Debug, PartialEq)]
pub struct WithParameters<M> {
    /// The molecule.
    pub molecule: M,
    /// The parameters' values, in the units the definition writes them in.
    pub values: Vec<f64>,
}

/// The parameter values of `m` with the scene's overrides, or `None` if the scene overrides
/// none; an unknown name is an error at its place with the closest known name.
pub fn scene_parameters<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
) -> Result<Option<Vec<f64>>, FileError> {
    if scene.parameters.is_empty() {
        return Ok(None);
    }
    let known = m.parameters();
    let mut values: Vec<f64> = known.iter().map(|(_, v)| *v).collect();
    for (name, value) in &scene.parameters {
        let Some(i) = known.iter().position(|(k, _)| k == name.get_ref()) else {
            let names: Vec<&str> = known.iter().map(|(k, _)| *k).collect();
            let help = match (did_you_mean(name.get_ref(), names.iter().copied()), names.is_empty()) {
                (_, true) => format!("{}'s potential has no parameters", m.name()),
                (Some(s), false) => format!("did you mean `{s}`? the parameters are {}", names.join(", ")),
                (None, false) => format!("the parameters of {} are {}", m.name(), names.join(", ")),
            };
            return Err(scene.source().error(
                name.span(),
                format!("{} has no potential parameter `{}`", m.name(), name.get_ref()),
                help,
            ));
        };
        values[i] = *value;
    }
    Ok(Some(values))
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> HasKinematics<N, NA> for WithParameters<M> {
    type Kinematics = M;
    fn kinematics(&self) -> &M {
        &self.molecule
    }
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Molecule<N, NA> for WithParameters<M> {
    // `potential_gradient_lanes` is deliberately not forwarded: the molecule's lane-generic
    // potential has the compiled-in parameters folded in, so the trait's default (lane by lane
    // through `potential_gradient` above, i.e. `potential_gradient_with`) is the right one.

    fn potential(&self, q: &SVector<f64, N>) -> f64 {
        self.molecule.potential_with(q, &self.values)
    }

    fn potential_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        self.molecule.potential_gradient_with(q, &self.values, grad)
    }

    fn parameters(&self) -> &'static [(&'static str, f64)] {
        self.molecule.parameters()
    }

    fn potential_with(&self, q: &SVector<f64, N>, params: &[f64]) -> f64 {
        self.molecule.potential_with(q, params)
    }

    fn potential_gradient_with(&self, q: &SVector<f64, N>, params: &[f64], grad: &mut SVector<f64, N>) -> f64 {
        self.molecule.potential_gradient_with(q, params, grad)
    }

    // The Cartesian chart (`runtime::charts`) with the same parameters: U(q(x), values).

    fn cartesian_potential(&self, x: &SMatrix<f64, 3, NA>) -> Option<f64> {
        self.molecule.cartesian_potential_with(x, &self.values)
    }

    fn cartesian_potential_gradient(&self, x: &SMatrix<f64, 3, NA>, grad: &mut SMatrix<f64, 3, NA>) -> Option<f64> {
        self.molecule.cartesian_potential_gradient_with(x, &self.values, grad)
    }

    fn cartesian_potential_with(&self, x: &SMatrix<f64, 3, NA>, params: &[f64]) -> Option<f64> {
        self.molecule.cartesian_potential_with(x, params)
    }

    fn cartesian_potential_gradient_with(
        &self,
        x: &SMatrix<f64, 3, NA>,
        params: &[f64],
        grad: &mut SMatrix<f64, 3, NA>,
    ) -> Option<f64> {
        self.molecule.cartesian_potential_gradient_with(x, params, grad)
    }

    fn dipole(&self) -> Option<impl Dipole<N>> {
        self.molecule.dipole()
    }
}
