//! Potential energy (and dipole) surfaces written in C, as [`rovib_runtime::surface::Potential`]
//! parts: a shared library loaded at run time ([`SharedLibrary`], the ABI of
//! `include/rovib_surface.h`), or C compiled into this crate at build time ([`builtin`]). A
//! library may instead give the surface over the atoms' Cartesian positions
//! ([`PositionSurface`], composed with the molecule's positions by [`OnPositions`]).
//!
//! A [`Surface`] composed with a generated molecule's kinematics by
//! [`rovib_runtime::surface::WithPotential`] is a full molecule. The surface has no lane form:
//! ensembles integrate one trajectory at a time. All of rovib's `unsafe` is in the private
//! module `raw`.

use std::marker::PhantomData;
use std::path::Path;

use rovib_runtime::finite_differences::central_gradient;
use rovib_runtime::nalgebra::{SMatrix, SVector, Vector3};
use rovib_runtime::surface::{Dipole, Potential};

mod positions;
mod raw;

pub use positions::{OnPositions, PositionSurface};

/// The version of the C ABI this crate reads (`ROVIB_SURFACE_ABI` of `rovib_surface.h`).
pub const ABI_VERSION: i32 = 1;

/// Why a surface cannot be used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SurfaceError {
    /// The operating system could not load the library.
    #[error("cannot load the surface library {source_name}: {message}")]
    Load {
        /// The library's path.
        source_name: String,
        /// The loader's message.
        message: String,
    },
    /// A required function is missing.
    #[error("the surface library {source_name} has no function `{symbol}`, which rovib_surface.h requires")]
    Missing {
        /// The library's path.
        source_name: String,
        /// The function's name.
        symbol: &'static str,
    },
    /// Built against another version of the header.
    #[error("the surface library {source_name} was built for surface ABI {found}; this rovib reads ABI {ABI_VERSION}")]
    Abi {
        /// The library's path.
        source_name: String,
        /// What `rovib_surface_abi()` returned.
        found: i32,
    },
    /// `rovib_surface_coordinates()` or `rovib_surface_atoms()` is not positive.
    #[error("the surface library {source_name}: {function}() returned {found}, not a positive count")]
    BadCount {
        /// The library's path.
        source_name: String,
        /// The function.
        function: &'static str,
        /// What it returned.
        found: i32,
    },
    /// Neither `rovib_surface_energy` nor `rovib_surface_positions_energy`.
    #[error(
        "the surface library {source_name} has neither `rovib_surface_energy` (a surface over internal coordinates) \
         nor `rovib_surface_positions_energy` (over atom positions)"
    )]
    NoForm {
        /// The library's path.
        source_name: String,
    },
    /// Both `rovib_surface_energy` and `rovib_surface_positions_energy`.
    #[error(
        "the surface library {source_name} has both `rovib_surface_energy` and `rovib_surface_positions_energy`: \
         rovib would not know which one is the surface"
    )]
    BothForms {
        /// The library's path.
        source_name: String,
    },
    /// A function of the other form than the library's energy (it would go unused).
    #[error("the surface library {source_name} has `{symbol}`, which does not go with its energy `{energy}`")]
    Mixed {
        /// The library's path.
        source_name: String,
        /// The function of the other form.
        symbol: &'static str,
        /// The energy function it has.
        energy: &'static str,
    },
    /// A surface over positions used as one over coordinates, or the other way round.
    #[error("the surface library {source_name} is a surface over {found}, not over {wanted}")]
    Form {
        /// The library's path.
        source_name: String,
        /// What it is over: "internal coordinates" or "atom positions".
        found: &'static str,
        /// What was asked for.
        wanted: &'static str,
    },
    /// The surface takes the positions of another number of atoms than the molecule has.
    #[error("the surface {source_name} takes the positions of {found} atoms, but the molecule has {expected}")]
    Atoms {
        /// The library's path.
        source_name: String,
        /// The surface's count.
        found: usize,
        /// The molecule's.
        expected: usize,
    },
    /// The surface takes another number of coordinates than the molecule has.
    #[error("the surface {source_name} takes {found} coordinates, but the molecule has {expected}")]
    Coordinates {
        /// The library's path.
        source_name: String,
        /// The surface's count.
        found: usize,
        /// The molecule's.
        expected: usize,
    },
    /// `rovib_surface_init()` returned non-zero.
    #[error("the surface library {source_name} did not start: rovib_surface_init() returned {code}")]
    Init {
        /// The library's path.
        source_name: String,
        /// The code it returned.
        code: i32,
    },
    /// One of the two dipole functions without the other.
    #[error("the surface library {source_name} has `{present}` but not `{missing}`: a dipole surface needs both")]
    HalfDipole {
        /// The library's path.
        source_name: String,
        /// The function it has.
        present: &'static str,
        /// The one it lacks.
        missing: &'static str,
    },
}

/// The prototype of each function of `rovib_surface.h`, as a library must define it.
pub fn prototype(symbol: &str) -> Option<&'static str> {
    Some(match symbol {
        "rovib_surface_abi" => "int rovib_surface_abi(void) { return ROVIB_SURFACE_ABI; }",
        "rovib_surface_coordinates" => "int rovib_surface_coordinates(void)",
        "rovib_surface_atoms" => "int rovib_surface_atoms(void)",
        "rovib_surface_energy" => "double rovib_surface_energy(const double *q)",
        "rovib_surface_gradient" => "double rovib_surface_gradient(const double *q, double *grad)",
        "rovib_surface_positions_energy" => "double rovib_surface_positions_energy(const double *x)",
        "rovib_surface_positions_gradient" => "double rovib_surface_positions_gradient(const double *x, double *grad)",
        "rovib_surface_dipole" => "void rovib_surface_dipole(const double *q, double *mu)",
        "rovib_surface_dipole_jacobian" => "void rovib_surface_dipole_jacobian(const double *q, double *dmu)",
        "rovib_surface_positions_dipole" => "void rovib_surface_positions_dipole(const double *x, double *mu)",
        "rovib_surface_positions_dipole_jacobian" => {
            "void rovib_surface_positions_dipole_jacobian(const double *x, double *dmu)"
        }
        _ => return None,
    })
}

impl SurfaceError {
    /// What to change in the library (for the help line of a located error).
    pub fn help(&self) -> String {
        const HEADER: &str = "ffi/include/rovib_surface.h";
        match self {
            Self::Load { .. } => format!(
                "check the path (relative to the scene file); build a library with \
                 `gcc -O2 -shared -fPIC -I ffi/include -o libsurf.so surf.c -lm` ({HEADER}, docs/src/howto/outside-surfaces.md)"
            ),
            Self::Missing { symbol, .. } => format!(
                "add `{}` to the library, with C linkage (`extern \"C\"` in C++), and build it again ({HEADER})",
                prototype(symbol).unwrap_or(symbol)
            ),
            Self::Abi { .. } => format!(
                "build the library again against this rovib's {HEADER} and return ROVIB_SURFACE_ABI ({ABI_VERSION}) \
                 from rovib_surface_abi()"
            ),
            Self::BadCount { function, .. } => format!("return the number from {function}() ({HEADER})"),
            Self::NoForm { .. } => format!(
                "add `{}` (with rovib_surface_coordinates) or `{}` (with rovib_surface_atoms) ({HEADER})",
                prototype("rovib_surface_energy").unwrap_or_default(),
                prototype("rovib_surface_positions_energy").unwrap_or_default()
            ),
            Self::BothForms { .. } => {
                format!("keep one: the rovib_surface_* functions over coordinates or the positions ones ({HEADER})")
            }
            Self::Mixed { symbol, energy, .. } => {
                format!("remove `{symbol}`, or give the surface in its form instead of `{energy}` ({HEADER})")
            }
            Self::Form { found, .. } => format!("use the library as a surface over {found}"),
            Self::Coordinates { expected, .. } => {
                format!("rovib_surface_coordinates() must return the molecule's {expected}, in its coordinate order")
            }
            Self::Atoms { expected, .. } => {
                format!("rovib_surface_atoms() must return the molecule's {expected}, in its atom order")
            }
            Self::Init { .. } => "see the library's own documentation for what its init code means".to_owned(),
            Self::HalfDipole { missing, .. } => format!(
                "add `{}`, or remove the other dipole function ({HEADER})",
                prototype(missing).unwrap_or(missing)
            ),
        }
    }
}

/// A shared library with the functions of `rovib_surface.h`, loaded (and its init function, if
/// any, called). Unloaded when dropped; the [`Surface`]s it hands out borrow it.
#[derive(Debug)]
pub struct SharedLibrary {
    path: String,
    loaded: raw::Loaded,
}

impl SharedLibrary {
    /// Loads the library at `path` and checks its ABI version.
    pub fn load(path: &Path) -> Result<Self, SurfaceError> {
        Ok(Self { path: path.display().to_string(), loaded: raw::Loaded::load(path)? })
    }

    /// The path it was loaded from, as shown in messages.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The number of internal coordinates a surface over coordinates takes; `None` for a
    /// surface over positions.
    pub fn coordinates(&self) -> Option<usize> {
        self.loaded.atoms().is_none().then_some(self.loaded.functions().coordinates)
    }

    /// The number of atoms a surface over positions takes; `None` for one over coordinates.
    pub fn atoms(&self) -> Option<usize> {
        self.loaded.atoms()
    }

    /// Whether it has a gradient function (without one, [`Surface`] takes central differences).
    pub fn has_gradient(&self) -> bool {
        self.loaded.functions().has_gradient()
    }

    /// Whether it has a dipole surface.
    pub fn has_dipole(&self) -> bool {
        self.loaded.functions().has_dipole()
    }

    /// The surface for a molecule with `N` coordinates; an error if it takes another number.
    pub fn surface<const N: usize>(&self) -> Result<Surface<'_, N>, SurfaceError> {
        if self.loaded.atoms().is_some() {
            return Err(SurfaceError::Form {
                source_name: self.path.clone(),
                found: "atom positions",
                wanted: "internal coordinates",
            });
        }
        Surface::new(*self.loaded.functions(), &self.path)
    }

    /// The surface over the positions of `NA` atoms; an error if it is a surface over
    /// coordinates or takes another number of atoms.
    pub fn positions_surface<const NA: usize>(&self) -> Result<PositionSurface<'_, NA>, SurfaceError> {
        match self.loaded.atoms() {
            None => Err(SurfaceError::Form {
                source_name: self.path.clone(),
                found: "internal coordinates",
                wanted: "atom positions",
            }),
            Some(found) if found != NA => {
                Err(SurfaceError::Atoms { source_name: self.path.clone(), found, expected: NA })
            }
            Some(_) => Ok(PositionSurface::new(*self.loaded.functions())),
        }
    }
}

/// A C surface over `N` coordinates: a [`Potential`] and, if the C code has one, a [`Dipole`]
/// ([`Potential::dipole_part`]). `'a` is the library it came from.
#[derive(Copy, Clone, Debug)]
pub struct Surface<'a, const N: usize> {
    functions: raw::Functions,
    /// ∂U/∂q by central differences of U (also without a gradient function).
    differences: bool,
    library: PhantomData<&'a SharedLibrary>,
}

impl<const N: usize> Surface<'_, N> {
    fn new(functions: raw::Functions, source_name: &str) -> Result<Self, SurfaceError> {
        if functions.coordinates != N {
            return Err(SurfaceError::Coordinates {
                source_name: source_name.to_owned(),
                found: functions.coordinates,
                expected: N,
            });
        }
        let differences = !functions.has_gradient();
        Ok(Self { functions, differences, library: PhantomData })
    }

    /// The same surface with ∂U/∂q by central differences of its energy
    /// ([`rovib_runtime::finite_differences`]: 2N + 1 energy calls per gradient).
    pub fn with_central_differences(self) -> Self {
        Self { differences: true, ..self }
    }

    /// Whether ∂U/∂q is taken by central differences.
    pub fn central_differences(&self) -> bool {
        self.differences
    }
}

impl<const N: usize> Potential<N> for Surface<'_, N> {
    fn energy(&self, q: &SVector<f64, N>) -> f64 {
        self.functions.energy(q.as_slice())
    }

    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        if !self.differences
            && let Some(u) = self.functions.gradient(q.as_slice(), grad.as_mut_slice())
        {
            return u;
        }
        central_gradient(|q| self.functions.energy(q.as_slice()), q, grad)
    }

    fn dipole_part(&self) -> Option<&dyn Dipole<N>> {
        self.functions.has_dipole().then_some(self as &dyn Dipole<N>)
    }
}

impl<const N: usize> Dipole<N> for Surface<'_, N> {
    fn moment(&self, q: &SVector<f64, N>, mu: &mut Vector3<f64>) {
        let mut m = [f64::NAN; 3];
        self.functions.dipole(q.as_slice(), &mut m);
        *mu = Vector3::from(m);
    }

    fn moment_jacobian(&self, q: &SVector<f64, N>, dmu: &mut SMatrix<f64, 3, N>) {
        // Column-major: element (a, k) is dmu[3 k + a], the layout of rovib_surface.h.
        if !self.functions.dipole_jacobian(q.as_slice(), dmu.as_mut_slice()) {
            dmu.fill(f64::NAN);
        }
    }
}

/// The potentials of molecule definitions that name C, C++ or Fortran sources (`[potential] c`,
/// `cpp`, `fortran`), compiled into this crate by its build script: per molecule `NAME`,
/// `NAME(q, grad) -> U` (∂U/∂q into `grad`) and `NAME_energy(q) -> U`, over the molecule's
/// coordinates in hartree. The generated molecule calls them; they are safe to call.
pub mod compiled {
    include!(concat!(env!("OUT_DIR"), "/compiled.rs"));
}

/// Surfaces compiled into this crate from `ffi/surfaces/*.c` by the build script.
pub mod builtin {
    use super::{Surface, raw};

    /// `ffi/surfaces/arn2_spline.c`: the spline × Legendre surface of `molecules/arn2.toml`
    /// (q = (R, θ)), with its induced dipole.
    pub fn arn2_spline() -> Surface<'static, 2> {
        Surface::new(raw::arn2_spline(), "built-in arn2_spline").expect("arn2_spline.c takes 2 coordinates")
    }
}
