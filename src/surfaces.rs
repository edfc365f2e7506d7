//! A scene's `[potential] library`: a shared library with the C ABI of
//! `ffi/include/rovib_surface.h` whose potential (and dipole, if it has one) replaces the
//! molecule's for the run, composed with the generated kinematics by
//! [`crate::runtime::surface::WithPotential`]. It is loaded when the run starts, its coordinate
//! count checked against the molecule's, and its gradient checked against central differences
//! of its energy before the first trajectory ([`crate::runtime::surface::check_gradient`]).

use std::ops::Range;
use std::path::{Path, PathBuf};

use rovib_ffi::SharedLibrary;

use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::molecule::Molecule;
use crate::runtime::nalgebra::SVector;
use crate::runtime::surface::{GradientCheck, GradientError, check_gradient};
use crate::scene::Scene;
use toml::Spanned;

pub mod grid;

pub use grid::ScenePotential;

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

/// The scene's library surface for molecule `m`, loaded (once per process and library: it
/// stays loaded until the process ends), counted and gradient-checked, or its grid surface
/// (`grid::scene_grid_potential`); `None` without either.
pub fn scene_surface<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
) -> Result<Option<ScenePotential<N>>, FileError> {
    if let Some(grid) = grid::scene_grid_potential(m, scene)? {
        return Ok(Some(ScenePotential::Grid(grid)));
    }
    let Some((written, path)) = &scene.library else { return Ok(None) };
    let at = |message: String, help: &str| scene.source().error(written.span(), message, help);
    let library = SharedLibrary::load(path).map_err(|e| {
        at(
            e.to_string(),
            "build it with `gcc -O2 -shared -fPIC -o libsurf.so surf.c -lm` (docs/src/howto/outside-surfaces.md)",
        )
    })?;
    if !library.has_gradient() && !scene.central_differences {
        return Err(at(
            format!("the surface library {} has no `rovib_surface_gradient`", path.display()),
            "add `gradient = \"central-differences\"` to [potential] (2N + 1 energy calls per gradient), or export \
             rovib_surface_gradient",
        ));
    }
    let library: &'static SharedLibrary = Box::leak(Box::new(library));
    let surface = library.surface::<N>().map_err(|e| {
        at(
            format!("{e} ({})", m.name()),
            &format!(
                "the surface must take the coordinates of {} in its order: {}",
                m.source(),
                m.coordinates().map(|c| c.name).join(", ")
            ),
        )
    })?;
    let surface = if scene.central_differences { surface.with_central_differences() } else { surface };
    let coordinates = m.coordinates();
    let centre = m.reference_geometry().unwrap_or_else(|| {
        SVector::from_fn(|k, _| {
            let (low, high) = coordinates[k].range;
            if low.is_finite() && high.is_finite() { 0.5 * (low + high) } else { low.max(1.0).min(high) }
        })
    });
    check_gradient(&surface, &coordinates, &centre, &GradientCheck::default()).map_err(|e| match &e {
        GradientError::Mismatch { coordinate, .. } => at(
            format!("the gradient of {} disagrees with its energy: {e}", path.display()),
            &format!("fix ∂U/∂{coordinate} in rovib_surface_gradient (coordinate `{coordinate}` of {})", m.source()),
        ),
        GradientError::NotFinite { .. } => at(
            format!("{}: {e}", path.display()),
            "the surface must be finite inside the coordinates' ranges around the reference geometry",
        ),
    })?;
    Ok(Some(ScenePotential::Library(surface)))
}
