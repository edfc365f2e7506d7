//! A scene's `[potential] library`: a shared library with the C ABI of
//! `ffi/include/rovib_surface.h` whose potential (and dipole, if it has one) replaces the
//! molecule's for the run, composed with the generated kinematics by
//! [`crate::runtime::surface::WithPotential`]. The library's surface is over the internal
//! coordinates or over the atoms' positions (then composed with R(q) by
//! [`rovib_ffi::OnPositions`]). It is loaded when the run starts, its coordinate (or atom)
//! count checked against the molecule's, a surface over positions checked for invariance under
//! rotations and translations, and its gradient checked against central differences of its
//! energy before the first trajectory ([`crate::runtime::surface::check_gradient`]).

use rovib_ffi::{OnPositions, SharedLibrary};

use crate::runtime::diagnostic::FileError;
use crate::runtime::grid::GridPotential;
use crate::runtime::molecule::Molecule;
use crate::runtime::nalgebra::{SMatrix, SVector};
use crate::runtime::position_surface::check_rotation_invariance;
use crate::runtime::surface::{Dipole, GradientCheck, GradientError, Potential, check_gradient};
use crate::scene::Scene;

pub mod grid;

/// The potential a scene puts in place of the molecule's: a shared library's (over internal
/// coordinates or over the atoms' positions) or a grid's.
pub enum ScenePotential<M, const N: usize, const NA: usize> {
    /// `[potential] library` with the functions over internal coordinates.
    Library(rovib_ffi::Surface<'static, N>),
    /// `[potential] library` with the functions over positions, composed with `M`'s R(q).
    Positions(OnPositions<'static, M, NA>),
    /// `[potential] grid`.
    Grid(GridPotential<N>),
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Potential<N> for ScenePotential<M, N, NA> {
    fn energy(&self, q: &SVector<f64, N>) -> f64 {
        match self {
            Self::Library(s) => s.energy(q),
            Self::Positions(s) => s.energy(q),
            Self::Grid(g) => g.energy(q),
        }
    }
    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        match self {
            Self::Library(s) => s.energy_gradient(q, grad),
            Self::Positions(s) => s.energy_gradient(q, grad),
            Self::Grid(g) => g.energy_gradient(q, grad),
        }
    }
    fn dipole_part(&self) -> Option<&dyn Dipole<N>> {
        match self {
            Self::Library(s) => s.dipole_part(),
            Self::Positions(s) => s.dipole_part(),
            Self::Grid(g) => g.dipole_part(),
        }
    }
}

/// The relative tolerance of the rotation-invariance check of a surface over positions: far
/// above round-off, far below any external field or frame dependence worth the name.
const INVARIANCE_TOLERANCE: f64 = 1e-10;

/// The scene's library surface for molecule `m`, loaded (once per process and library: it
/// stays loaded until the process ends), counted and gradient-checked (a surface over
/// positions also checked for invariance under rotations and translations), or its grid
/// surface (`grid::scene_grid_potential`); `None` without either.
pub fn scene_surface<M: Molecule<N, NA> + Clone, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
) -> Result<Option<ScenePotential<M, N, NA>>, FileError> {
    if let Some(grid) = grid::scene_grid_potential(m, scene)? {
        return Ok(Some(ScenePotential::Grid(grid)));
    }
    let Some((written, path)) = &scene.library else { return Ok(None) };
    let at = |message: String, help: &str| scene.source().error(written.span(), message, help);
    let library = SharedLibrary::load(path).map_err(|e| at(e.to_string(), &e.help()))?;
    let (gradient, form) = match library.atoms() {
        None => ("rovib_surface_gradient", "coordinates"),
        Some(_) => ("rovib_surface_positions_gradient", "positions"),
    };
    if !library.has_gradient() && !scene.central_differences {
        return Err(at(
            format!("the surface library {} has no `{gradient}`", path.display()),
            &format!(
                "add `gradient = \"central-differences\"` to [potential] (2N + 1 energy calls per gradient), or export \
                 `{}`",
                rovib_ffi::prototype(gradient).unwrap_or(gradient)
            ),
        ));
    }
    let library: &'static SharedLibrary = Box::leak(Box::new(library));
    let order = |what: &str| match form {
        "positions" => format!(
            "the surface must take the positions of the {what} of {} in its order: {}",
            m.source(),
            m.atoms().map(|a| a.label).join(", ")
        ),
        _ => format!(
            "the surface must take the {what} of {} in its order: {}",
            m.source(),
            m.coordinates().map(|c| c.name).join(", ")
        ),
    };
    let mismatch = |e: rovib_ffi::SurfaceError, what: &str| at(format!("{e} ({})", m.name()), &order(what));
    let surface = if form == "positions" {
        let surface = library.positions_surface::<NA>().map_err(|e| mismatch(e, "atoms"))?;
        let mut x = SMatrix::<f64, 3, NA>::zeros();
        m.positions(&reference(m), &mut x);
        check_rotation_invariance(&surface, &x, INVARIANCE_TOLERANCE).map_err(|e| {
            at(
                format!("{}: {e}", path.display()),
                "the surface over positions must give the same energy wherever the molecule is and however it is \
                 turned (no external field, no fixed frame): rovib evaluates it in the body frame",
            )
        })?;
        let on = surface.on(m.clone());
        ScenePotential::Positions(if scene.central_differences { on.with_central_differences() } else { on })
    } else {
        let surface = library.surface::<N>().map_err(|e| mismatch(e, "coordinates"))?;
        ScenePotential::Library(if scene.central_differences { surface.with_central_differences() } else { surface })
    };
    let coordinates = m.coordinates();
    check_gradient(&surface, &coordinates, &reference(m), &GradientCheck::default()).map_err(|e| match &e {
        GradientError::Mismatch { coordinate, .. } => at(
            format!("the gradient of {} disagrees with its energy: {e}", path.display()),
            &format!("fix ∂U/∂{coordinate} in {gradient} (coordinate `{coordinate}` of {})", m.source()),
        ),
        GradientError::NotFinite { .. } => at(
            format!("{}: {e}", path.display()),
            "the surface must be finite inside the coordinates' ranges around the reference geometry",
        ),
    })?;
    Ok(Some(surface))
}

/// The molecule's reference geometry, or the middle of the coordinates' ranges.
fn reference<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M) -> SVector<f64, N> {
    let coordinates = m.coordinates();
    m.reference_geometry().unwrap_or_else(|| {
        SVector::from_fn(|k, _| {
            let (low, high) = coordinates[k].range;
            if low.is_finite() && high.is_finite() { 0.5 * (low + high) } else { low.max(1.0).min(high) }
        })
    })
}
