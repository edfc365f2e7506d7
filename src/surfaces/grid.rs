//! A scene's `[potential] grid`: a tabulated surface (`rovib_runtime::grid`) read from a grid
//! file beside the scene and interpolated by cubic splines, with the declared policy `outside`
//! for points beyond the grid. It replaces the molecule's potential (and, with dipole columns,
//! its dipole) for the run through `WithPotential`, as a `[potential] library` does.

use crate::runtime::diagnostic::{FileError, MAX_INPUT_BYTES, Source, read_text_capped};
use crate::runtime::grid::{BindError, GridFile, GridPotential, Outside, parse};
use crate::runtime::integrate::SolveError;
use crate::runtime::molecule::Molecule;
use crate::runtime::nalgebra::SVector;
use crate::runtime::surface::{GradientCheck, check_gradient};
use crate::scene::Scene;
pub use crate::scene::potential::SceneGrid;

/// Reads the scene's grid file: its text and the parsed grid.
fn load(scene: &Scene, grid: &SceneGrid) -> Result<(String, GridFile), FileError> {
    let text = read_text_capped(&grid.path, MAX_INPUT_BYTES).map_err(|e| {
        scene.source().error(
            grid.written.span(),
            format!("cannot read the grid file: {e}"),
            "give the path of a grid file, relative to the scene",
        )
    })?;
    let path = grid.path.display().to_string();
    let file = parse(&Source { path: &path, text: &text })?;
    Ok((text, file))
}

/// The scene's grid potential for molecule `m`: read, bound to `m`'s coordinates and
/// gradient-checked; `None` without `[potential] grid`.
pub fn scene_grid_potential<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
) -> Result<Option<GridPotential<N>>, FileError> {
    let Some(grid) = &scene.grid else { return Ok(None) };
    let (text, file) = load(scene, grid)?;
    let path = grid.path.display().to_string();
    let coordinates = m.coordinates();
    let names = coordinates.map(|c| c.name).join(", ");
    let potential = GridPotential::new(&file, &coordinates, grid.outside).map_err(|e| match &e {
        BindError::UnknownAxis { index, .. } | BindError::Kind { index, .. } => Source { path: &path, text: &text }
            .error(
                file.axes[*index].span.clone(),
                e.to_string(),
                format!("name the axes by the coordinates of {} ({names}), a length unit for a length", m.source()),
            ),
        BindError::Missing { .. } => scene.source().error(
            grid.written.span(),
            format!("{path}: {e}"),
            format!("give the grid an axis for every coordinate of {} ({names}); a grid has 1 to 3 axes", m.source()),
        ),
    })?;
    // The spline's gradient is its exact derivative; the check guards the binding (axis order
    // and units) as a library's gradient is checked, at points inside the grid.
    let mut inside = coordinates;
    let mut centre =
        m.reference_geometry().unwrap_or_else(|| SVector::from_fn(|k, _| coordinates[k].reference.unwrap_or(0.0)));
    for a in 0..potential.spline().axes() {
        let k = potential.coordinate_of(a);
        let knots = potential.spline().knots(a);
        let (low, high) = (knots[0], knots[knots.len() - 1]);
        let margin = 1e-3 * (high - low);
        inside[k].range = (low + margin, high - margin);
        centre[k] = centre[k].clamp(low + margin, high - margin);
    }
    check_gradient(&potential, &inside, &centre, &GradientCheck::default()).map_err(|e| {
        scene.source().error(
            grid.written.span(),
            format!("the spline of {path} fails the gradient check: {e}"),
            "check the grid's values: a spline this steep between neighbouring points is not a smooth surface",
        )
    })?;
    Ok(Some(potential))
}

/// What a failed run adds to its message when the scene's grid has `outside = "error"`: where
/// the grid ends, since leaving it makes the potential NaN and stops the trajectory at once.
pub fn failure_note<E>(e: &SolveError<E>, scene: &Scene) -> String {
    let Some(grid) = scene.grid.as_ref().filter(|g| g.outside == Outside::Error) else { return String::new() };
    if !matches!(e, SolveError::Rhs { .. } | SolveError::NonFinite { .. }) {
        return String::new();
    }
    let (line, _) = scene.source().place(grid.outside_span.start);
    let bounds = load(scene, grid)
        .map(|(_, f)| {
            let parts: Vec<String> = f
                .axes
                .iter()
                .enumerate()
                .map(|(a, axis)| {
                    let k = f.spline.knots(a);
                    let s = axis.unit.in_atomic_units();
                    format!("{} in [{}, {}] {}", axis.name, k[0] / s, k[k.len() - 1] / s, axis.unit.name())
                })
                .collect();
            format!(" ({})", parts.join(", "))
        })
        .unwrap_or_default();
    format!(
        ". The potential is the grid {}{bounds} with outside = \"error\" ({}:{line}): a trajectory that leaves it gets a \
         NaN potential and stops where it left; extend the grid, or set outside = \"extrapolate\"",
        grid.path.display(),
        scene.path
    )
}
