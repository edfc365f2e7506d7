//! Every `unsafe` of rovib: loading a shared library, looking up its functions, and calling
//! foreign functions (loaded, or compiled in by the build script).
//!
//! What makes each call sound, besides the library keeping to `include/rovib_surface.h` (which
//! nothing can check): the pointers passed are to slices whose lengths are checked against the
//! coordinate count the library declared, and a loaded library outlives its function pointers
//! (they are only reachable through a borrow of [`Loaded`]).
#![allow(unsafe_code)]

use std::ffi::c_int;
use std::path::Path;

use crate::SurfaceError;

type CountFn = unsafe extern "C" fn() -> c_int;
type EnergyFn = unsafe extern "C" fn(*const f64) -> f64;
type GradientFn = unsafe extern "C" fn(*const f64, *mut f64) -> f64;
type DipoleFn = unsafe extern "C" fn(*const f64, *mut f64);

/// A surface's functions, for `coordinates` input values: the internal coordinates, or the
/// 3·NA Cartesian components of NA atoms' positions (atom `i`'s x, y, z at `3i`, `3i + 1`,
/// `3i + 2`).
#[derive(Copy, Clone, Debug)]
pub(crate) struct Functions {
    pub coordinates: usize,
    energy: EnergyFn,
    /// `None`: the library has no gradient function (central differences of the energy).
    gradient: Option<GradientFn>,
    dipole: Option<(DipoleFn, DipoleFn)>,
}

impl Functions {
    pub fn has_dipole(&self) -> bool {
        self.dipole.is_some()
    }

    /// U(q).
    pub fn energy(&self, q: &[f64]) -> f64 {
        assert_eq!(q.len(), self.coordinates, "a surface is called with its own number of coordinates");
        // SAFETY: q holds the `coordinates` values the function reads.
        unsafe { (self.energy)(q.as_ptr()) }
    }

    pub fn has_gradient(&self) -> bool {
        self.gradient.is_some()
    }

    /// ∂U/∂q into `grad` and `Some(U)`; `None` without a gradient function.
    pub fn gradient(&self, q: &[f64], grad: &mut [f64]) -> Option<f64> {
        assert!(q.len() == self.coordinates && grad.len() == self.coordinates, "one value per coordinate");
        let f = self.gradient?;
        // SAFETY: q and grad hold the `coordinates` values the function reads and writes.
        Some(unsafe { f(q.as_ptr(), grad.as_mut_ptr()) })
    }

    /// μ(q) into `mu` (3 values); `false` without a dipole surface.
    pub fn dipole(&self, q: &[f64], mu: &mut [f64; 3]) -> bool {
        assert_eq!(q.len(), self.coordinates, "one value per coordinate");
        let Some((f, _)) = self.dipole else { return false };
        // SAFETY: q holds `coordinates` values, mu the 3 the function writes.
        unsafe { f(q.as_ptr(), mu.as_mut_ptr()) };
        true
    }

    /// ∂μ/∂q into `dmu` (3 × coordinates, column k = ∂μ/∂q_k; over positions, column 3i + c
    /// is ∂μ/∂x_ic); `false` without a dipole.
    pub fn dipole_jacobian(&self, q: &[f64], dmu: &mut [f64]) -> bool {
        assert!(q.len() == self.coordinates && dmu.len() == 3 * self.coordinates, "3 values per coordinate");
        let Some((_, f)) = self.dipole else { return false };
        // SAFETY: q holds `coordinates` values, dmu the 3 × coordinates the function writes.
        unsafe { f(q.as_ptr(), dmu.as_mut_ptr()) };
        true
    }
}

/// A loaded shared library and its functions (valid while the library is loaded).
#[derive(Debug)]
pub(crate) struct Loaded {
    functions: Functions,
    /// `Some(NA)`: the functions take the positions of NA atoms (`functions.coordinates` is
    /// 3·NA); `None`: they take the internal coordinates.
    atoms: Option<usize>,
    // Dropped last: unloads the library.
    _library: libloading::Library,
}

/// The function names of one form of the ABI: over internal coordinates, or over positions.
struct Names {
    count: &'static str,
    energy: &'static str,
    gradient: &'static str,
    dipole: &'static str,
    dipole_jacobian: &'static str,
}

const COORDINATE_NAMES: Names = Names {
    count: "rovib_surface_coordinates",
    energy: "rovib_surface_energy",
    gradient: "rovib_surface_gradient",
    dipole: "rovib_surface_dipole",
    dipole_jacobian: "rovib_surface_dipole_jacobian",
};

const POSITION_NAMES: Names = Names {
    count: "rovib_surface_atoms",
    energy: "rovib_surface_positions_energy",
    gradient: "rovib_surface_positions_gradient",
    dipole: "rovib_surface_positions_dipole",
    dipole_jacobian: "rovib_surface_positions_dipole_jacobian",
};

impl Loaded {
    pub fn functions(&self) -> &Functions {
        &self.functions
    }

    /// The number of atoms of a surface over positions; `None` for one over coordinates.
    pub fn atoms(&self) -> Option<usize> {
        self.atoms
    }

    /// Loads `path`, checks its ABI version, which form it has (coordinates or positions) and
    /// its count, and calls its init function.
    pub fn load(path: &Path) -> Result<Self, SurfaceError> {
        let shown = path.display().to_string();
        // SAFETY: loading runs the library's initialisers; the user named this library as a
        // surface, and rovib_surface.h asks it to do nothing else on load.
        let library = unsafe { libloading::Library::new(path) }
            .map_err(|e| SurfaceError::Load { source_name: shown.clone(), message: e.to_string() })?;
        let missing = |symbol: &'static str| SurfaceError::Missing { source_name: shown.clone(), symbol };
        // SAFETY (each `get`): the types are the prototypes of rovib_surface.h.
        let has = |name: &str| unsafe { library.get::<CountFn>(name.as_bytes()) }.is_ok();
        let count = |name: &'static str| -> Result<c_int, SurfaceError> {
            let f = unsafe { library.get::<CountFn>(name.as_bytes()) }.map_err(|_| missing(name))?;
            // SAFETY: takes no arguments.
            Ok(unsafe { f() })
        };
        let abi = count("rovib_surface_abi")?;
        if abi != crate::ABI_VERSION {
            return Err(SurfaceError::Abi { source_name: shown, found: abi });
        }
        let (names, other) = match (has(COORDINATE_NAMES.energy), has(POSITION_NAMES.energy)) {
            (true, false) => (&COORDINATE_NAMES, &POSITION_NAMES),
            (false, true) => (&POSITION_NAMES, &COORDINATE_NAMES),
            (true, true) => return Err(SurfaceError::BothForms { source_name: shown }),
            (false, false) => return Err(SurfaceError::NoForm { source_name: shown }),
        };
        // A function of the other form would be silently unused: refused.
        for symbol in [other.count, other.gradient, other.dipole, other.dipole_jacobian] {
            if has(symbol) {
                return Err(SurfaceError::Mixed { source_name: shown, symbol, energy: names.energy });
            }
        }
        let found = count(names.count)?;
        let count = usize::try_from(found).ok().filter(|&n| n > 0).ok_or_else(|| SurfaceError::BadCount {
            source_name: shown.clone(),
            function: names.count,
            found,
        })?;
        let (coordinates, atoms) =
            if names.count == POSITION_NAMES.count { (3 * count, Some(count)) } else { (count, None) };
        let energy = *unsafe { library.get::<EnergyFn>(names.energy.as_bytes()) }.map_err(|_| missing(names.energy))?;
        // Optional: without it, ∂U/∂q is taken by central differences of the energy.
        let gradient = unsafe { library.get::<GradientFn>(names.gradient.as_bytes()) }.ok().map(|s| *s);
        let mu = unsafe { library.get::<DipoleFn>(names.dipole.as_bytes()) }.ok().map(|s| *s);
        let dmu = unsafe { library.get::<DipoleFn>(names.dipole_jacobian.as_bytes()) }.ok().map(|s| *s);
        let dipole = match (mu, dmu) {
            (Some(a), Some(b)) => Some((a, b)),
            (None, None) => None,
            (Some(_), None) => {
                return Err(SurfaceError::HalfDipole {
                    source_name: shown,
                    present: names.dipole,
                    missing: names.dipole_jacobian,
                });
            }
            (None, Some(_)) => {
                return Err(SurfaceError::HalfDipole {
                    source_name: shown,
                    present: names.dipole_jacobian,
                    missing: names.dipole,
                });
            }
        };
        if let Ok(init) = unsafe { library.get::<CountFn>(b"rovib_surface_init") } {
            // SAFETY: takes no arguments; called once, before any other surface function.
            let code = unsafe { init() };
            if code != 0 {
                return Err(SurfaceError::Init { source_name: shown, code });
            }
        }
        Ok(Self { functions: Functions { coordinates, energy, gradient, dipole }, atoms, _library: library })
    }
}

// The surfaces the build script compiles in (ffi/surfaces/*.c, each with its own prefix).
unsafe extern "C" {
    fn arn2_spline_coordinates() -> c_int;
    fn arn2_spline_energy(q: *const f64) -> f64;
    fn arn2_spline_gradient(q: *const f64, grad: *mut f64) -> f64;
    fn arn2_spline_dipole(q: *const f64, mu: *mut f64);
    fn arn2_spline_dipole_jacobian(q: *const f64, dmu: *mut f64);
}

/// The compiled-in `ffi/surfaces/arn2_spline.c`.
pub(crate) fn arn2_spline() -> Functions {
    // SAFETY: takes no arguments.
    let coordinates = unsafe { arn2_spline_coordinates() } as usize;
    Functions {
        coordinates,
        energy: arn2_spline_energy,
        gradient: Some(arn2_spline_gradient),
        dipole: Some((arn2_spline_dipole, arn2_spline_dipole_jacobian)),
    }
}

/// The potentials of molecule definitions that name C, C++ or Fortran sources, compiled in by
/// the build script: per molecule `NAME`, its `NAME_energy` and `NAME_gradient` and safe calls
/// `energy_NAME` and `gradient_NAME` over arrays of the molecule's coordinate count.
pub(crate) mod compiled {
    #![allow(dead_code)]
    include!(concat!(env!("OUT_DIR"), "/compiled_raw.rs"));
}
