//! Binds the fragments' atom labels of a parsed `[collision]` to the molecule's atoms.

use super::CollisionScene;
use crate::runtime::Molecule;
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::sample::collision::CollisionSpec;

impl CollisionScene {
    /// The sampler's spec for molecule `m`: atom labels bound to indices (an unknown or repeated
    /// label, or an atom in no fragment, is an error at its place).
    pub fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        src: &Source<'_>,
        trajectories: u64,
    ) -> Result<CollisionSpec, FileError> {
        let atoms = m.atoms();
        let names: Vec<&str> = atoms.iter().map(|a| a.label).collect();
        let mut used = vec![false; NA];
        let mut fragments: [Vec<usize>; 2] = [Vec::new(), Vec::new()];
        for k in 0..2 {
            for l in &self.fragments[k] {
                let i = names.iter().position(|n| *n == l.get_ref()).ok_or_else(|| {
                    src.error(
                        l.span(),
                        format!("{} has no atom `{}`", m.name(), l.get_ref()),
                        format!("the atoms are {}", names.join(", ")),
                    )
                })?;
                if used[i] {
                    return Err(src.error(
                        l.span(),
                        format!("atom `{}` is listed twice", l.get_ref()),
                        "list each atom in one fragment once",
                    ));
                }
                used[i] = true;
                fragments[k].push(i);
            }
        }
        if let Some(i) = used.iter().position(|u| !u) {
            return Err(src.error(
                self.span.clone(),
                format!("atom `{}` is in neither fragment", names[i]),
                "every atom of the molecule belongs to one of the two fragments",
            ));
        }
        Ok(CollisionSpec {
            fragments,
            strata: self.strata.clone(),
            energy: self.energy.clone(),
            rotation: self.rotation.clone(),
            vibration: self.vibration.clone(),
            r0: self.r0,
            trajectories,
        })
    }
}
