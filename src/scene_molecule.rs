//! The molecule a scene runs: the compiled-in one, with the scene's `[potential]` library or
//! grid in place of its potential ([`crate::surfaces::scene_surface`]), or with its
//! `[potential.parameters]` ([`crate::parameters::scene_parameters`]), else as compiled. Every
//! command that visits a molecule by name (a run, an ensemble, a collision ensemble, drawing
//! states) goes through [`with_scene_molecule`], so they all run the same molecule.
//! (`ensemble::run_with_sampler`, whose caller's sampler is typed by the molecule's coordinate
//! count, writes the same three cases out.)

use crate::error::Error;
use crate::parameters::{WithParameters, scene_parameters};
use crate::runtime::Molecule;
use crate::runtime::surface::WithPotential;
use crate::scene::Scene;
use crate::surfaces::scene_surface;

/// What is done with the scene's molecule, whichever of the three it is.
pub trait SceneMoleculeUser {
    /// What the use gives.
    type Output;

    /// Uses the scene's molecule `m`.
    fn with_molecule<M, const N: usize, const NA: usize>(self, m: M) -> Result<Self::Output, Error>
    where
        M: Molecule<N, NA> + Sync;
}

/// Hands `user` the molecule `scene` runs, built from the compiled-in `m`.
pub fn with_scene_molecule<U, M, const N: usize, const NA: usize>(
    scene: &Scene,
    m: M,
    user: U,
) -> Result<U::Output, Error>
where
    U: SceneMoleculeUser,
    M: Molecule<N, NA> + Clone + Sync,
{
    if let Some(surface) = scene_surface(&m, scene)? {
        return user.with_molecule(WithPotential { molecule: m, potential: surface });
    }
    match scene_parameters(&m, scene)? {
        Some(values) => user.with_molecule(WithParameters { molecule: m, values }),
        None => user.with_molecule(m),
    }
}
