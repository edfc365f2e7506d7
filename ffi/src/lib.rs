//! Potential energy (and dipole) surfaces written in C, as [`rovib_runtime::surface::Potential`]
//! parts: a shared library loaded at run time ([`SharedLibrary`], the ABI of
//! `include/rovib_surface.h`), or C compiled into this crate at build time ([`builtin`]).
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

mod raw;

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
    /// `rovib_surface_coordinates()` is negative.
    #[error("the surface library {source_name} says it takes {found} coordinates")]
    BadCount {
        /// The library's path.
        source_name: String,
        /// What it returned.
        found: i32,
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

    /// The number of coordinates the surface takes.
    pub fn coordinates(&self) -> usize {
        self.loaded.functions().coordinates
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
        Surface::new(*self.loaded.functions(), &self.path)
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
