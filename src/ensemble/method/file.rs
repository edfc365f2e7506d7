//! `method = "file"`: trajectory `i` starts from the `i`-th state of a CSV file of internal
//! coordinates or an extended XYZ file ([`crate::ensemble::states_file`]).

use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use super::{Binding, Context, Method};
use crate::ensemble::states_file::read_states;
use crate::runtime::Molecule;
use crate::runtime::diagnostic::FileError;
use crate::runtime::sample::Spec;

/// The file method's keys.
#[derive(Deserialize)]
pub struct Keys {
    file: Option<Spanned<String>>,
}

/// States read from a file.
#[derive(Clone, Debug)]
pub struct File {
    /// The file (resolved against the scene's folder).
    pub path: PathBuf,
    /// Where `file = ...` is written.
    pub span: Range<usize>,
}

impl Method for File {
    const NAME: &'static str = "file";
    type Keys = Keys;
    type Bound<const N: usize> = Spec<N>;

    fn read(keys: Keys, cx: &Context<'_>) -> Result<Self, FileError> {
        let file = keys.file.as_ref().ok_or_else(|| cx.needs("file", "a path relative to the scene"))?;
        let base = Path::new(&cx.scene().path).parent().unwrap_or(Path::new(""));
        Ok(File { path: base.join(file.get_ref()), span: file.span() })
    }

    fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        cx: &Binding<'_>,
    ) -> Result<(Spec<N>, String), FileError> {
        let (path, src) = (&self.path, cx.src());
        let states = read_states(m, path, cx.scene()).map_err(|e| match e {
            Ok(located) => located,
            Err(message) => src.error(
                self.span.clone(),
                message,
                "give a readable CSV or extended XYZ file of states (see docs/src/reference/ensemble.md)",
            ),
        })?;
        let (trajectories, at) = cx.trajectories();
        if (states.len() as u64) < trajectories {
            return Err(src.error(
                at,
                format!("{} has {} states but trajectories = {}", path.display(), states.len(), trajectories),
                format!("lower trajectories to at most {}, or add states to the file", states.len()),
            ));
        }
        Ok((Spec::States(states), format!("{trajectories} states from {}", path.display())))
    }

    fn input_file(&self) -> Option<&Path> {
        Some(&self.path)
    }
}
