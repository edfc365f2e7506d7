//! The keys of a scene's `[potential]` that replace the molecule's potential: `library` (a
//! shared library, loaded by [`crate::surfaces`]) and `grid` with `outside` (a grid file, read by
//! [`crate::surfaces::grid`]), checked where the scene is read, with their places.

use std::ops::Range;
use std::path::{Path, PathBuf};

use toml::Spanned;

use super::Named;
use super::raw::RawScenePotential;
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::grid::Outside;

/// A scene's `[potential]`, checked: what `parse_scene` puts in the scene.
pub(super) struct ScenePotential {
    /// `[potential.parameters]`.
    pub(super) parameters: Vec<Named<f64>>,
    /// `library`, resolved ([`scene_library`]).
    pub(super) library: Option<(Spanned<String>, PathBuf)>,
    /// `grid` and `outside` ([`scene_grid`]).
    pub(super) grid: Option<SceneGrid>,
    /// `gradient = "central-differences"` ([`crate::surface_gradient::scene_gradient`]).
    pub(super) central_differences: bool,
}

/// Checks every key of `[potential]` (none without the table).
pub(super) fn scene_potential(src: &Source<'_>, raw: Option<&RawScenePotential>) -> Result<ScenePotential, FileError> {
    let Some(raw) = raw else {
        return Ok(ScenePotential { parameters: Vec::new(), library: None, grid: None, central_differences: false });
    };
    let parameters_span = raw.parameters.as_ref().map(|t| t.span());
    Ok(ScenePotential {
        parameters: match &raw.parameters {
            Some(table) => super::named_numbers(src, table, "potential.parameters")?,
            None => Vec::new(),
        },
        library: scene_library(src, raw.library.as_ref(), parameters_span.clone())?,
        grid: scene_grid(
            src,
            raw.grid.as_ref(),
            raw.outside.as_ref(),
            raw.library.as_ref().map(|l| l.span()),
            parameters_span,
        )?,
        central_differences: crate::surface_gradient::scene_gradient(src, raw.gradient.as_ref(), raw.library.as_ref())?,
    })
}

/// The checked `library` key of a scene's `[potential]` (its place, and the path resolved
/// against the scene file's directory); `parameters` is the place of `[potential.parameters]`,
/// which a library potential does not take.
pub fn scene_library(
    src: &Source<'_>,
    library: Option<&Spanned<String>>,
    parameters: Option<Range<usize>>,
) -> Result<Option<(Spanned<String>, PathBuf)>, FileError> {
    let Some(library) = library else { return Ok(None) };
    if library.get_ref().trim().is_empty() {
        return Err(src.error(
            library.span(),
            "`potential.library` is empty",
            "give the path of a shared library with the functions of rovib_surface.h, e.g. \"libsurf.so\"",
        ));
    }
    if let Some(span) = parameters {
        return Err(src.error(
            span,
            "`[potential.parameters]` sets the definition's parameters, but `potential.library` replaces that potential",
            "remove [potential.parameters], or remove `library` to run on the definition's potential",
        ));
    }
    let dir = Path::new(src.path).parent().unwrap_or(Path::new(""));
    Ok(Some((library.clone(), dir.join(library.get_ref()))))
}

/// The checked `grid` and `outside` keys of a scene's `[potential]`.
#[derive(Clone, Debug)]
pub struct SceneGrid {
    /// `grid` as written (its place for errors).
    pub written: Spanned<String>,
    /// The grid file, resolved against the scene file's directory.
    pub path: PathBuf,
    /// The policy outside the grid.
    pub outside: Outside,
    /// `outside`'s place.
    pub outside_span: Range<usize>,
}

const OUTSIDE_HELP: &str = "write outside = \"error\" (a trajectory that leaves the grid stops, with a message) or \
                            outside = \"extrapolate\" (the edge cell's cubic continued beyond the grid)";

/// Checks `[potential] grid` and `outside`; `library` and `parameters` are the places of the
/// keys that cannot go with a grid.
pub fn scene_grid(
    src: &Source<'_>,
    grid: Option<&Spanned<String>>,
    outside: Option<&Spanned<String>>,
    library: Option<Range<usize>>,
    parameters: Option<Range<usize>>,
) -> Result<Option<SceneGrid>, FileError> {
    let Some(grid) = grid else {
        if let Some(outside) = outside {
            return Err(src.error(
                outside.span(),
                "`potential.outside` is the policy of a grid potential, but the scene has no `potential.grid`",
                "remove `outside`, or add grid = \"pes.csv\" (docs/src/howto/outside-surfaces.md)",
            ));
        }
        return Ok(None);
    };
    if grid.get_ref().trim().is_empty() {
        return Err(src.error(
            grid.span(),
            "`potential.grid` is empty",
            "give the path of a grid file, e.g. \"pes.csv\"",
        ));
    }
    if let Some(span) = library {
        return Err(src.error(
            span,
            "`potential.library` and `potential.grid` both replace the potential",
            "keep one of them",
        ));
    }
    if let Some(span) = parameters {
        return Err(src.error(
            span,
            "`[potential.parameters]` sets the definition's parameters, but `potential.grid` replaces that potential",
            "remove [potential.parameters], or remove `grid` to run on the definition's potential",
        ));
    }
    let Some(outside_key) = outside else {
        return Err(src.error(
            grid.span(),
            "`potential.grid` needs `outside`: what the surface is beyond the grid",
            OUTSIDE_HELP,
        ));
    };
    let policy = match outside_key.get_ref().as_str() {
        "error" => Outside::Error,
        "extrapolate" => Outside::Extrapolate,
        other => return Err(src.error(outside_key.span(), format!("unknown `outside = \"{other}\"`"), OUTSIDE_HELP)),
    };
    let dir = Path::new(src.path).parent().unwrap_or(Path::new(""));
    Ok(Some(SceneGrid {
        written: grid.clone(),
        path: dir.join(grid.get_ref()),
        outside: policy,
        outside_span: outside_key.span(),
    }))
}
