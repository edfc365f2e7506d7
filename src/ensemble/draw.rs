//! The initial states an ensemble would start its trajectories from, without running them:
//! [`draw_states`] binds the scene's `[ensemble]` method (any of [`super::method::METHODS`]:
//! thermal, microcanonical, normal modes, a states file, …) to its molecule exactly as
//! [`super::run_ensemble`] does, with the scene's `[potential]`, and the `[pairs] max_energy`
//! restriction, and draws states `0..count`.

use super::output_times;
use super::pair_states::{Restricted, RestrictedSampler};
use super::scene::parse_ensemble;
use crate::error::Error;
use crate::molecules;
use crate::runtime::sample::{Sampler, energy};
use crate::runtime::{Molecule, MoleculeVisitor};
use crate::scene::Scene;

/// States drawn by an ensemble's sampler, flattened state by state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DrawnStates {
    /// The molecule.
    pub molecule: String,
    /// Internal coordinates per state (N).
    pub coordinates: usize,
    /// q per state (bohr, rad), `count × coordinates`.
    pub q: Vec<f64>,
    /// p per state (ħ/bohr, ħ), `count × coordinates`.
    pub p: Vec<f64>,
    /// The orientation (body → lab) per state as a unit quaternion w, x, y, z, `count × 4`.
    pub orientation: Vec<f64>,
    /// The body-frame angular momentum per state (ħ), `count × 3`.
    pub j: Vec<f64>,
    /// H per state (hartree, the potential's zero).
    pub h: Vec<f64>,
    /// U per state (hartree).
    pub u: Vec<f64>,
    /// How the states are drawn (as summary.json's `sampler`).
    pub description: String,
}

/// At most this many states are drawn by one call (the arrays stay far below a gigabyte).
pub const MAX_DRAWN: u64 = 10_000_000;

/// Draws the initial states `0..count` of the ensemble of `scene` (which must have
/// `[ensemble]`), the states trajectories `0..count` of [`super::run_ensemble`] start from.
pub fn draw_states(scene: &Scene, count: u64) -> Result<DrawnStates, Error> {
    if count > MAX_DRAWN {
        return Err(Error::Message(format!("cannot draw {count} states: at most {MAX_DRAWN} at a time")));
    }
    let name = scene.molecule.get_ref().clone();
    molecules::visit(&name, Draw { scene, count }).ok_or_else(|| {
        let e = Error::unknown_molecule(&name);
        Error::File(scene.source().error(scene.molecule.span(), e.to_string(), "use a name from `rovib list`"))
    })?
}

struct Draw<'a> {
    scene: &'a Scene,
    count: u64,
}

impl MoleculeVisitor for Draw<'_> {
    type Output = Result<DrawnStates, Error>;

    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        crate::scene_molecule::with_scene_molecule(self.scene, m, self)
    }
}

impl crate::scene_molecule::SceneMoleculeUser for Draw<'_> {
    type Output = DrawnStates;

    fn with_molecule<M, const N: usize, const NA: usize>(self, m: M) -> Result<DrawnStates, Error>
    where
        M: Molecule<N, NA> + Sync,
    {
        let scene = self.scene;
        let ensemble = parse_ensemble(scene)?;
        if let super::scene::MethodSpec::Collision(_) = &ensemble.method {
            return Err(scene
                .source()
                .error(
                    ensemble.method_span(),
                    "a collision ensemble samples two molecules and their approach, not states of one molecule",
                    "draw the states of each molecule with its own thermal or microcanonical ensemble",
                )
                .into());
        }
        let times = output_times(scene.t_end, scene.output_interval);
        let bound = ensemble.bind(&m, scene, &times)?;
        let sampler = bound.spec.sampler(&m, ensemble.seed).map_err(|e| {
            scene.source().error(
                ensemble.method_span(),
                format!("cannot sample this ensemble: {e}"),
                "change the method or its parameters in [ensemble] (see docs/src/reference/ensemble.md)",
            )
        })?;
        let pairs = ensemble.pairs.as_ref().map(|p| p.bind(&m, scene, bound.spec.spec())).transpose()?;
        let restricted =
            pairs.as_ref().and_then(|p| p.max_energy.map(|e| RestrictedSampler(Restricted::new(&*sampler, &m, p, e))));
        let sampler: &dyn Sampler<N> = match &restricted {
            Some(r) => r,
            None => &*sampler,
        };
        let k = self.count as usize;
        let mut out = DrawnStates {
            molecule: m.name().to_owned(),
            coordinates: N,
            q: Vec::with_capacity(k * N),
            p: Vec::with_capacity(k * N),
            orientation: Vec::with_capacity(k * 4),
            j: Vec::with_capacity(k * 3),
            h: Vec::with_capacity(k),
            u: Vec::with_capacity(k),
            description: bound.description.clone(),
        };
        for i in 0..self.count {
            let b = sampler.draw(i).map_err(|e| Error::Message(format!("cannot draw state {i}: {e}")))?;
            let o = b.orientation.quaternion();
            out.q.extend_from_slice(b.q.as_slice());
            out.p.extend_from_slice(b.p.as_slice());
            out.orientation.extend_from_slice(&[o.w, o.i, o.j, o.k]);
            out.j.extend_from_slice(b.j.as_slice());
            out.h.push(energy(&m, &b).map_err(|e| Error::Message(format!("state {i}: {e}")))?);
            out.u.push(m.potential(&b.q));
        }
        Ok(out)
    }
}
