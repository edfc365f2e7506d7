//! A scene's `[potential] grid`: a tabulated surface (`rovib_runtime::grid`) read from a grid
//! file beside the scene and interpolated by cubic splines, with the declared policy `outside`
//! for points beyond the grid. It replaces the molecule's potential (and, with dipole columns,
//! its dipole) for the run through `WithPotential`, as a `[potential] library` does.

use std::ops::Range;
use std::path::{Path, PathBuf};

use toml::Spanned;

use crate::runtime::diagnostic::{FileError, MAX_INPUT_BYTES, Source, read_text_capped};
use crate::runtime::grid::{BindError, GridFile, GridPotential, Outside, parse};
use crate::runtime::integrate::SolveError;
use crate::runtime::molecule::Molecule;
use crate::runtime::nalgebra::SVector;
use crate::runtime::surface::{GradientCheck, check_gradient};
use crate::scene::Scene;

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
