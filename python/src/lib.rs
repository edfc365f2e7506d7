//! `rovib._rovib`: the Python extension module, a thin layer over the rovib library.
//!
//! Every function calls the same library code as the `rovib` command (`Simulation`,
//! `ensemble::run_ensemble_with`, `runtime::hamiltonian::evaluate`, `runtime::frames`), so
//! results from Python equal the CLI's by construction. Runs take a stop flag that their
//! progress callback raises when Python has a pending signal: Ctrl-C ends a run cleanly and
//! raises `KeyboardInterrupt`, and no signal handler is installed. Errors become
//! `rovib.RovibError` (a `ValueError`) with the CLI's message text. The pure-Python package
//! `rovib` (python/rovib/) wraps these functions: reading the outputs into NumPy arrays, dict
//! scenes, ASE.

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1};
use pyo3::create_exception;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

use rovib::ensemble::draw::draw_states;
use rovib::ensemble::tables::Table;
use rovib::ensemble::{EnsembleOptions, EnsembleReport};
use rovib::memory::{ExternalPotential, Record, RecordSink, run_in_memory};
use rovib::runtime::frames::{from_lab_body, to_lab_body};
use rovib::runtime::hamiltonian::fast::BodyState;
use rovib::runtime::hamiltonian::{PhaseState, evaluate as evaluate_state};
use rovib::runtime::nalgebra::{DMatrix, Quaternion, SMatrix, SVector, UnitQuaternion, Vector3};
use rovib::runtime::sample::{Region, Spec, energy as sample_energy, sampler};
use rovib::runtime::units::{AU_TIME_IN_FS, BOHR_IN_ANGSTROM};
use rovib::runtime::{CentreOfMass, FitOptions, LabState, Molecule, MoleculeVisitor, to_lab};
use rovib::{Error, Progress, Simulation, molecules};

create_exception!(
    _rovib,
    RovibError,
    PyValueError,
    "An error of rovib, with the same message as the `rovib` command prints."
);

/// A `RovibError` with the CLI's text for `e` (a located file error is already `error: ...`).
fn lib_error(e: Error) -> PyErr {
    match e {
        Error::File(f) => RovibError::new_err(f.to_string()),
        e => RovibError::new_err(format!("error: {e}")),
    }
}

/// Runs `f` without the GIL, with a stop flag and a progress callback that checks Python's
/// signals (on the calling thread, which is where Python runs its signal handlers). The first
/// failed check (Ctrl-C: `KeyboardInterrupt`) raises the flag, so the run ends cleanly at its
/// next output record, and is returned instead of the run's result.
fn with_signals<T: Send>(
    py: Python<'_>,
    f: impl FnOnce(&AtomicBool, &mut dyn FnMut(Progress)) -> Result<T, Error> + Send,
) -> PyResult<T> {
    let stop = AtomicBool::new(false);
    let mut pending: Option<PyErr> = None;
    let result = py.detach(|| {
        let mut check = |_: Progress| {
            if pending.is_none()
                && let Err(e) = Python::attach(|py| py.check_signals())
            {
                pending = Some(e);
                stop.store(true, Ordering::SeqCst);
            }
        };
        f(&stop, &mut check)
    });
    match pending {
        Some(e) => Err(e),
        None => result.map_err(lib_error),
    }
}

/// A `RovibError` from a one-line message, formatted as the CLI prints it.
fn message(m: impl std::fmt::Display) -> PyErr {
    RovibError::new_err(format!("error: {m}"))
}

/// The CLI's text for a molecule name that is not compiled in.
fn unknown_molecule(name: &str) -> PyErr {
    message(format!(
        "unknown molecule `{name}`; the compiled-in molecules are {} (add molecules/{name}.toml and rebuild to add it)",
        molecules::NAMES.join(", ")
    ))
}

/// Lab-frame velocity conversion: 1 Å/fs in bohr per ħ/E_h.
fn angstrom_per_fs_in_au() -> f64 {
    AU_TIME_IN_FS / BOHR_IN_ANGSTROM
}

/// A dense matrix as a list of rows.
fn rows(m: DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows()).map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect()).collect()
}

fn dense<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Vec<Vec<f64>> {
    rows(DMatrix::from_column_slice(R, C, m.as_slice()))
}

/// One state array given from Python, checked for length and finiteness (as `rovib eval` does).
fn vector<const K: usize>(
    name: &str,
    field: &str,
    meaning: &str,
    values: &Option<Vec<f64>>,
    default: SVector<f64, K>,
) -> Result<SVector<f64, K>, String> {
    let Some(values) = values else { return Ok(default) };
    if values.len() != K {
        return Err(format!("{name}: `{field}` has {} entries, expected {K} ({meaning})", values.len()));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(format!("{name}: `{field}[{i}]` is not a finite number ({meaning})"));
    }
    Ok(SVector::from_column_slice(values))
}

/// A phase state as four optional arrays (atomic units).
#[derive(Clone, Default)]
struct StateArgs {
    q: Option<Vec<f64>>,
    p: Option<Vec<f64>>,
    euler: Option<Vec<f64>>,
    pe: Option<Vec<f64>>,
}

impl StateArgs {
    /// The phase state for `m`: `q` defaults to the reference geometry, `p` and `pe` to zero,
    /// `euler` to (0, π/2, 0) rad, as in `rovib eval`.
    fn phase<M: Molecule<N, NA>, const N: usize, const NA: usize>(&self, m: &M) -> Result<PhaseState<N>, String> {
        let reference = m.reference_geometry();
        if self.q.is_none() && reference.is_none() {
            return Err(format!(
                "state: `q` is missing and {} has no reference geometry to default to (give q)",
                m.name()
            ));
        }
        let names: Vec<&str> = m.coordinates().iter().map(|c| c.name).collect();
        let coordinates = format!("one per coordinate of {}: {}, in bohr or rad", m.name(), names.join(", "));
        let momenta = format!("one momentum per coordinate of {}: {}", m.name(), names.join(", "));
        Ok(PhaseState {
            q: vector("state", "q", &coordinates, &self.q, reference.unwrap_or_else(SVector::zeros))?,
            p: vector("state", "p", &momenta, &self.p, SVector::zeros())?,
            euler: vector(
                "state",
                "euler",
                "phi, theta, psi in rad",
                &self.euler,
                Vector3::new(0.0, std::f64::consts::FRAC_PI_2, 0.0),
            )?,
            pe: vector("state", "pe", "p_phi, p_theta, p_psi in hbar", &self.pe, Vector3::zeros())?,
        })
    }
}

/// What `molecule_info` returns, in plain Rust data.
struct Info {
    labels: Vec<&'static str>,
    elements: Vec<&'static str>,
    masses_da: Vec<f64>,
    coordinates: Vec<&'static str>,
    units: Vec<&'static str>,
    reference: Vec<Option<f64>>,
}

struct InfoVisitor;

impl MoleculeVisitor for InfoVisitor {
    type Output = Info;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Info {
        Info {
            labels: m.atoms().iter().map(|a| a.label).collect(),
            elements: m.atoms().iter().map(|a| a.element).collect(),
            masses_da: m.atoms().iter().map(|a| a.mass_da).collect(),
            coordinates: m.coordinates().iter().map(|c| c.name).collect(),
            units: m.coordinates().iter().map(|c| c.unit.atomic().name()).collect(),
            reference: m.coordinates().iter().map(|c| c.reference).collect(),
        }
    }
}

/// What `evaluate` returns, in plain Rust data.
struct Evaluated {
    h: f64,
    u: f64,
    t: f64,
    positions: Vec<Vec<f64>>,
    a: Vec<Vec<f64>>,
    coriolis: Vec<Vec<f64>>,
    inertia: Vec<Vec<f64>>,
    g11: Vec<Vec<f64>>,
    g12: Vec<Vec<f64>>,
    g22: Vec<Vec<f64>>,
    j: Vec<f64>,
    rhs: [Vec<f64>; 4],
}

struct EvalVisitor(StateArgs);

impl MoleculeVisitor for EvalVisitor {
    type Output = Result<Evaluated, String>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Self::Output {
        let state = self.0.phase(&m)?;
        let e = evaluate_state(&m, &state).map_err(|e| format!("cannot evaluate {}: {e}", m.name()))?;
        Ok(Evaluated {
            h: e.hamiltonian,
            u: e.potential,
            t: e.kinetic_energy,
            positions: dense(&e.positions.transpose()),
            a: dense(&e.kinetic.a),
            coriolis: dense(&e.kinetic.coriolis),
            inertia: dense(&e.kinetic.inertia),
            g11: dense(&e.g.g11),
            g12: dense(&e.g.g12),
            g22: dense(&e.g.g22),
            j: e.angular_momentum.as_slice().to_vec(),
            rhs: [
                e.rhs.q.as_slice().to_vec(),
                e.rhs.p.as_slice().to_vec(),
                e.rhs.euler.as_slice().to_vec(),
                e.rhs.pe.as_slice().to_vec(),
            ],
        })
    }
}

/// A state converted from the lab frame: q, p, Euler angles, their momenta, the orientation
/// quaternion (w, x, y, z) and the body-frame J.
struct FromLab {
    state: [Vec<f64>; 6],
    com: [Vec<f64>; 2],
    report: [f64; 3],
    iterations: usize,
}

struct FromLabVisitor {
    /// Positions, bohr, one row per atom.
    positions: Vec<[f64; 3]>,
    /// Velocities, bohr per ħ/E_h, one row per atom.
    velocities: Vec<[f64; 3]>,
    initial_q: Option<Vec<f64>>,
}

/// A 3 × NA matrix from rows per atom, or the message for a wrong atom count.
fn columns<const NA: usize>(name: &str, what: &str, rows: &[[f64; 3]]) -> Result<SMatrix<f64, 3, NA>, String> {
    if rows.len() != NA {
        return Err(format!("{what} have {} rows, expected one per atom of {name} ({NA})", rows.len()));
    }
    Ok(SMatrix::from_fn(|i, j| rows[j][i]))
}

impl MoleculeVisitor for FromLabVisitor {
    type Output = Result<FromLab, String>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Self::Output {
        let lab = LabState {
            positions: columns::<NA>(m.name(), "positions", &self.positions)?,
            velocities: columns::<NA>(m.name(), "velocities", &self.velocities)?,
        };
        let mut options = FitOptions::<N>::default();
        if let Some(q) = &self.initial_q {
            options.initial_q = Some(vector(
                "from_lab",
                "initial_q",
                "one per coordinate, bohr or rad",
                &Some(q.clone()),
                SVector::zeros(),
            )?);
        }
        // The body formulation holds every orientation, θ = 0 included (a molecule along the lab
        // z axis); its Euler angles there are one of the equivalent choices and p_e = Mᵀ J.
        let (body, com, report) = from_lab_body(&m, &lab, &options)
            .map_err(|e| format!("cannot convert the lab state of {}: {e}", m.name()))?;
        let s = body.to_phase();
        let o = body.orientation.quaternion();
        Ok(FromLab {
            state: [
                s.q.as_slice().to_vec(),
                s.p.as_slice().to_vec(),
                s.euler.as_slice().to_vec(),
                s.pe.as_slice().to_vec(),
                vec![o.w, o.i, o.j, o.k],
                body.j.as_slice().to_vec(),
            ],
            com: [com.position.as_slice().to_vec(), com.velocity.as_slice().to_vec()],
            report: [report.position_residual, report.velocity_residual, report.discarded_kinetic_energy],
            iterations: report.iterations,
        })
    }
}

struct ToLabVisitor {
    state: StateArgs,
    /// The orientation quaternion (w, x, y, z) and body-frame J, which replace `euler` and `pe`
    /// when given (defined at every orientation).
    body: Option<([f64; 4], [f64; 3])>,
    com: [[f64; 3]; 2],
}

impl MoleculeVisitor for ToLabVisitor {
    /// Positions (bohr) and velocities (bohr per ħ/E_h), one row per atom.
    type Output = Result<(Vec<Vec<f64>>, Vec<Vec<f64>>), String>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Self::Output {
        let state = self.state.phase(&m)?;
        let com = CentreOfMass { position: Vector3::from(self.com[0]), velocity: Vector3::from(self.com[1]) };
        let lab: LabState<NA> = match self.body {
            None => to_lab(&m, &state, &com),
            Some(([w, x, y, z], j)) => {
                let orientation = UnitQuaternion::try_new(Quaternion::new(w, x, y, z), 0.0)
                    .ok_or_else(|| "state: `orientation` is zero or not finite".to_owned())?;
                let body = BodyState { q: state.q, p: state.p, orientation, j: Vector3::from(j) };
                to_lab_body(&m, &body, &com)
            }
        }
        .map_err(|e| format!("cannot convert the state of {} to the lab frame: {e}", m.name()))?;
        Ok((dense(&lab.positions.transpose()), dense(&lab.velocities.transpose())))
    }
}

/// The names of the compiled-in molecules, sorted.
#[pyfunction]
fn molecules_list() -> Vec<&'static str> {
    molecules::NAMES.to_vec()
}

/// Atoms and coordinates of molecule `name`: atom labels, elements and masses (Da); coordinate
/// names, their atomic units (bohr or rad) and reference values in those units (None if the
/// definition gives none).
#[pyfunction]
fn molecule_info<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyDict>> {
    let info = molecules::visit(name, InfoVisitor).ok_or_else(|| unknown_molecule(name))?;
    let d = PyDict::new(py);
    d.set_item("name", name)?;
    let atoms = PyDict::new(py);
    atoms.set_item("labels", info.labels)?;
    atoms.set_item("elements", info.elements)?;
    atoms.set_item("masses_da", PyArray1::from_vec(py, info.masses_da))?;
    d.set_item("atoms", atoms)?;
    let coordinates = PyDict::new(py);
    coordinates.set_item("names", info.coordinates)?;
    coordinates.set_item("units", info.units)?;
    coordinates.set_item("reference", info.reference)?;
    d.set_item("coordinates", coordinates)?;
    Ok(d)
}

fn matrix<'py>(py: Python<'py>, rows: &[Vec<f64>]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    Ok(PyArray2::from_vec2(py, rows)?)
}

/// H, U, T, the kinetic and G matrices, J and the right-hand side at a state (atomic units).
#[pyfunction]
#[pyo3(signature = (name, q=None, p=None, euler=None, pe=None))]
fn evaluate<'py>(
    py: Python<'py>,
    name: &str,
    q: Option<Vec<f64>>,
    p: Option<Vec<f64>>,
    euler: Option<Vec<f64>>,
    pe: Option<Vec<f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let e = molecules::visit(name, EvalVisitor(StateArgs { q, p, euler, pe }))
        .ok_or_else(|| unknown_molecule(name))?
        .map_err(message)?;
    let d = PyDict::new(py);
    d.set_item("H", e.h)?;
    d.set_item("U", e.u)?;
    d.set_item("T", e.t)?;
    d.set_item("positions", matrix(py, &e.positions)?)?;
    d.set_item("a", matrix(py, &e.a)?)?;
    d.set_item("A", matrix(py, &e.coriolis)?)?;
    d.set_item("I", matrix(py, &e.inertia)?)?;
    d.set_item("G11", matrix(py, &e.g11)?)?;
    d.set_item("G12", matrix(py, &e.g12)?)?;
    d.set_item("G22", matrix(py, &e.g22)?)?;
    d.set_item("J", PyArray1::from_slice(py, &e.j))?;
    let rhs = PyDict::new(py);
    for (key, v) in ["q", "p", "euler", "pe"].iter().zip(&e.rhs) {
        rhs.set_item(*key, PyArray1::from_slice(py, v))?;
    }
    d.set_item("rhs", rhs)?;
    Ok(d)
}

/// A scene parsed from `text` (named `path` in messages; relative paths in it resolve from
/// `path`'s folder), or read from the file `path` when no text is given.
fn load_scene(path: &str, text: Option<&str>) -> PyResult<rovib::scene::Scene> {
    match text {
        Some(text) => rovib::scene::parse_scene(path, text).map_err(|e| lib_error(e.into())),
        None => rovib::ensemble::load_scene(path.as_ref()).map_err(lib_error),
    }
}

/// Runs the scene `text` (named `path`; the file `path` without text) into `out_dir` exactly as
/// `rovib run` does; returns the files written. Ctrl-C stops the run at its next output record
/// and raises `KeyboardInterrupt`.
#[pyfunction]
#[pyo3(signature = (path, out_dir, text=None))]
fn run_scene(py: Python<'_>, path: &str, out_dir: PathBuf, text: Option<&str>) -> PyResult<Vec<PathBuf>> {
    let sim = match text {
        Some(_) => Simulation::from_scene(load_scene(path, text)?, out_dir),
        None => Simulation::load(path.as_ref(), Some(&out_dir)).map_err(lib_error)?,
    };
    Ok(with_signals(py, |stop, progress| sim.run(stop, progress))?.files)
}

/// Continues the run in `out_dir` from its restart.json exactly as `rovib run --resume OUT_DIR
/// [SCENE]` does, with the scene `text` (named `path`), the file `path`, or neither (the stored
/// scene); returns the files written.
#[pyfunction]
#[pyo3(signature = (out_dir, path=None, text=None))]
fn resume_scene(py: Python<'_>, out_dir: PathBuf, path: Option<&str>, text: Option<&str>) -> PyResult<Vec<PathBuf>> {
    let sim = match (path, text) {
        (Some(path), Some(_)) => Simulation::resume_with_scene(&out_dir, load_scene(path, text)?),
        (path, _) => Simulation::resume(&out_dir, path.map(std::path::Path::new)),
    }
    .map_err(lib_error)?;
    Ok(with_signals(py, |stop, progress| sim.run(stop, progress))?.files)
}

/// A table of named columns as a dict of NumPy arrays, in column order.
fn table<'py>(py: Python<'py>, t: &Table) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (name, column) in t.names.iter().zip(&t.columns) {
        d.set_item(name, PyArray1::from_slice(py, column))?;
    }
    Ok(d)
}

/// Runs the ensemble of the scene `text` (named `path`; the file `path` without text) as
/// `rovib ensemble` does: into `out_dir`, or in memory without one (nothing written; the
/// correlations and spectrum come back as `correlations` and `spectrum`, dicts of arrays). The
/// output times in the scene's time unit (`time_unit`). Ctrl-C stops it (the trajectories that
/// finished are in `out_dir`) and raises `KeyboardInterrupt`.
#[pyfunction]
#[pyo3(signature = (path, out_dir=None, threads=None, text=None))]
fn run_ensemble_scene<'py>(
    py: Python<'py>,
    path: &str,
    out_dir: Option<PathBuf>,
    threads: Option<usize>,
    text: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let scene = load_scene(path, text)?;
    let mut options = match out_dir {
        Some(dir) => EnsembleOptions::new(dir),
        None => EnsembleOptions::in_memory(),
    };
    options.threads = threads;
    let report: EnsembleReport = with_signals(py, |stop, progress| {
        // The ensemble polls its own flag; the callback's is forwarded to it.
        let forward = |p: Progress| {
            progress(p);
            if stop.load(Ordering::SeqCst) {
                options.stop.store(true, Ordering::SeqCst);
            }
        };
        let mut forward = forward;
        rovib::ensemble::run_ensemble_with(&scene, &options, &mut forward)
    })?;
    let time_scale = scene.time_unit.in_au();
    let (k, nq) = (report.times.len(), report.quantities.len());
    let mut means = vec![vec![f64::NAN; nq]; k];
    let mut stderr = vec![vec![f64::NAN; nq]; k];
    for (i, row) in means.iter_mut().enumerate() {
        for (j, q) in report.quantities.iter().enumerate() {
            if let Some((m, s)) = report.mean(q, i) {
                row[j] = m;
                stderr[i][j] = s;
            }
        }
    }
    let d = PyDict::new(py);
    d.set_item("status", report.status.name())?;
    d.set_item("requested", report.requested)?;
    d.set_item("completed", report.outcome.completed)?;
    d.set_item("failed", report.outcome.failed.clone())?;
    let times: Vec<f64> = report.times.iter().map(|t| t / time_scale).collect();
    d.set_item("times", PyArray1::from_vec(py, times))?;
    d.set_item("time_unit", scene.time_unit.name())?;
    d.set_item("quantities", report.quantities.clone())?;
    d.set_item("units", report.units.clone())?;
    d.set_item("means", matrix(py, &means)?)?;
    d.set_item("stderr", matrix(py, &stderr)?)?;
    d.set_item("seed", report.seed)?;
    d.set_item("threads", report.threads)?;
    d.set_item("sampler", report.sampler.clone())?;
    d.set_item("wall_time_s", report.wall_time)?;
    d.set_item("files", report.files.clone())?;
    d.set_item("failed_count", report.outcome.failed_count())?;
    d.set_item("interrupted_or_not_run", report.outcome.interrupted)?;
    if let Some(tables) = &report.tables {
        d.set_item("correlations", table(py, &tables.correlations)?)?;
        match &tables.spectrum {
            Some(s) => d.set_item("spectrum", table(py, s)?)?,
            None => d.set_item("spectrum", PyDict::new(py))?,
        }
    }
    Ok(d)
}

/// The initial states `0..count` of the ensemble of the scene `text` (named `path`; the file
/// `path` without text), drawn by its `[ensemble]` method as the ensemble draws them: arrays
/// `q`, `p` (count × N), `orientation` (count × 4, w x y z), `J` (count × 3, body frame), `H`,
/// `U` (hartree), the `molecule` and the sampler's `description`.
#[pyfunction]
#[pyo3(signature = (path, count, text=None))]
fn sample_scene<'py>(py: Python<'py>, path: &str, count: u64, text: Option<&str>) -> PyResult<Bound<'py, PyDict>> {
    let scene = load_scene(path, text)?;
    let drawn = py.detach(|| draw_states(&scene, count)).map_err(lib_error)?;
    let (k, n) = (count as usize, drawn.coordinates);
    let d = PyDict::new(py);
    d.set_item("q", PyArray1::from_vec(py, drawn.q).reshape([k, n])?)?;
    d.set_item("p", PyArray1::from_vec(py, drawn.p).reshape([k, n])?)?;
    d.set_item("orientation", PyArray1::from_vec(py, drawn.orientation).reshape([k, 4])?)?;
    d.set_item("J", PyArray1::from_vec(py, drawn.j).reshape([k, 3])?)?;
    d.set_item("H", PyArray1::from_vec(py, drawn.h))?;
    d.set_item("U", PyArray1::from_vec(py, drawn.u))?;
    d.set_item("molecule", drawn.molecule)?;
    d.set_item("description", drawn.description)?;
    Ok(d)
}

/// The definition's atom positions at `q` and their Jacobian.
struct PositionsVisitor(Vec<f64>);

impl MoleculeVisitor for PositionsVisitor {
    /// Positions (x, y, z atom by atom) and per coordinate their derivative, bohr per unit of q.
    type Output = Result<(usize, Vec<f64>, Vec<f64>), String>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Self::Output {
        let names: Vec<&str> = m.coordinates().iter().map(|c| c.name).collect();
        let meaning = format!("one per coordinate of {}: {}, in bohr or rad", m.name(), names.join(", "));
        let q = vector::<N>("positions", "q", &meaning, &Some(self.0), SVector::zeros())?;
        let mut r = SMatrix::<f64, 3, NA>::zeros();
        let mut dr = [SMatrix::<f64, 3, NA>::zeros(); N];
        m.positions(&q, &mut r);
        m.positions_jacobian(&q, &mut dr);
        Ok((NA, r.as_slice().to_vec(), dr.iter().flat_map(|d| d.as_slice().iter().copied()).collect()))
    }
}

/// The positions of molecule `name`'s atoms at `q` in its definition's frame (bohr, shape
/// (atoms, 3)) and their derivatives by each coordinate (shape (coordinates, atoms, 3)), as the
/// generated kinematics computes them.
#[pyfunction]
fn positions<'py>(py: Python<'py>, name: &str, q: Vec<f64>) -> PyResult<Bound<'py, PyTuple>> {
    let (atoms, r, dr) =
        molecules::visit(name, PositionsVisitor(q)).ok_or_else(|| unknown_molecule(name))?.map_err(message)?;
    let n = dr.len() / (3 * atoms);
    let r = PyArray1::from_vec(py, r).reshape([atoms, 3])?;
    let dr = PyArray1::from_vec(py, dr).reshape([n, atoms, 3])?;
    PyTuple::new(py, [r.into_any(), dr.into_any()])
}

/// What `sample` asks for.
struct SampleVisitor {
    method: String,
    count: u64,
    seed: u64,
    temperature: Option<f64>,
    energy: Option<f64>,
    angular_momentum: Option<f64>,
    energy_cap: Option<f64>,
}

/// States drawn by a sampler, flattened draw by draw: q, p (N each), orientation (w, x, y, z),
/// J (3), and H, U per draw.
struct Drawn {
    n: usize,
    state: [Vec<f64>; 4],
    h: Vec<f64>,
    u: Vec<f64>,
}

impl MoleculeVisitor for SampleVisitor {
    type Output = Result<Drawn, String>;

    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        let region = Region { energy_cap: self.energy_cap, limits: [None; N] };
        let need =
            |v: Option<f64>, key: &str| v.ok_or_else(|| format!("sample: method \"{}\" needs `{key}`", self.method));
        let spec = match self.method.as_str() {
            "thermal" => Spec::Thermal { temperature: need(self.temperature, "temperature")?, region },
            "microcanonical" => Spec::Microcanonical {
                energy: need(self.energy, "energy")?,
                angular_momentum: self.angular_momentum,
                region,
            },
            other => {
                return Err(format!("sample: unknown method `{other}` (use \"thermal\" or \"microcanonical\")"));
            }
        };
        let draws = sampler(&m, &spec, self.seed).map_err(|e| format!("cannot sample {}: {e}", m.name()))?;
        let mut out = Drawn { n: N, state: Default::default(), h: Vec::new(), u: Vec::new() };
        for i in 0..self.count {
            let b = draws.draw(i).map_err(|e| format!("cannot draw state {i} of {}: {e}", m.name()))?;
            let o = b.orientation.quaternion();
            out.state[0].extend_from_slice(b.q.as_slice());
            out.state[1].extend_from_slice(b.p.as_slice());
            out.state[2].extend_from_slice(&[o.w, o.i, o.j, o.k]);
            out.state[3].extend_from_slice(b.j.as_slice());
            out.h.push(sample_energy(&m, &b).map_err(|e| format!("state {i} of {}: {e}", m.name()))?);
            out.u.push(m.potential(&b.q));
        }
        Ok(out)
    }
}

/// States of molecule `name` drawn by the thermal (`temperature`, kelvin) or microcanonical
/// (`energy`, hartree; optional `angular_momentum`, ħ) sampler with `seed`, draws 0 to `count` −
/// 1 as an ensemble with that seed would start its trajectories: arrays `q`, `p` (count × N),
/// `orientation` (count × 4, w x y z), `J` (count × 3, body frame), `H`, `U` (hartree).
#[pyfunction]
#[pyo3(signature = (name, method, count, seed, temperature=None, energy=None, angular_momentum=None, energy_cap=None))]
fn sample<'py>(
    py: Python<'py>,
    name: &str,
    method: String,
    count: u64,
    seed: u64,
    temperature: Option<f64>,
    energy: Option<f64>,
    angular_momentum: Option<f64>,
    energy_cap: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let visitor = SampleVisitor { method, count, seed, temperature, energy, angular_momentum, energy_cap };
    let drawn =
        py.detach(|| molecules::visit(name, visitor)).ok_or_else(|| unknown_molecule(name))?.map_err(message)?;
    let k = count as usize;
    let d = PyDict::new(py);
    let [q, p, o, j] = drawn.state;
    d.set_item("q", PyArray1::from_vec(py, q).reshape([k, drawn.n])?)?;
    d.set_item("p", PyArray1::from_vec(py, p).reshape([k, drawn.n])?)?;
    d.set_item("orientation", PyArray1::from_vec(py, o).reshape([k, 4])?)?;
    d.set_item("J", PyArray1::from_vec(py, j).reshape([k, 3])?)?;
    d.set_item("H", PyArray1::from_vec(py, drawn.h))?;
    d.set_item("U", PyArray1::from_vec(py, drawn.u))?;
    Ok(d)
}

/// The records of a run in memory, row by row.
#[derive(Default)]
struct Records {
    /// Rows of trajectory.csv's columns: t, q, p, Euler angles, their momenta, J, H.
    rows: Vec<f64>,
    /// Lab positions and velocities (bohr, bohr per ħ/E_h; 3 × atoms per record) and U.
    lab: [Vec<f64>; 2],
    lab_potential: Vec<f64>,
    /// Lab-frame dipole, 3 per record.
    dipole: Vec<f64>,
    count: usize,
    summary: Option<String>,
}

impl RecordSink for Records {
    fn record(&mut self, r: &Record<'_>) {
        self.count += 1;
        self.rows.push(r.t);
        self.rows.extend_from_slice(r.q);
        self.rows.extend_from_slice(r.p);
        for part in [r.euler, r.pe, r.j] {
            self.rows.extend_from_slice(&part);
        }
        self.rows.push(r.energy);
        if let Some(lab) = &r.lab {
            self.lab[0].extend_from_slice(lab.positions);
            self.lab[1].extend_from_slice(lab.velocities);
            self.lab_potential.push(lab.potential);
        }
        if let Some(mu) = r.dipole {
            self.dipole.extend_from_slice(&mu);
        }
    }

    fn summary(&mut self, summary: &serde_json::Value) {
        self.summary = Some(summary.to_string());
    }
}

/// A Python callable `f(q) -> (U, dU/dq)` (NumPy arrays, atomic units) as a potential. The GIL
/// is taken for each call. The first exception (or a wrong return value) is kept and makes this
/// and every later call return NaN, which stops the run; the caller then raises the exception.
struct PyPotential {
    f: Py<PyAny>,
    error: Mutex<Option<PyErr>>,
}

impl PyPotential {
    fn call(&self, q: &[f64], grad: &mut [f64]) -> PyResult<f64> {
        Python::attach(|py| {
            let out = self.f.bind(py).call1((PyArray1::from_slice(py, q),))?;
            let n = grad.len();
            let shape = || {
                PyTypeError::new_err(format!(
                    "the potential must return (U, dU/dq): a float and {n} floats, got {}",
                    out.repr().map(|r| r.to_string()).unwrap_or_default()
                ))
            };
            let (u, g): (f64, Bound<'_, PyAny>) = out.extract().map_err(|_| shape())?;
            match g.extract::<PyReadonlyArray1<'_, f64>>() {
                Ok(a) => {
                    let values = a.as_slice()?;
                    if values.len() != n {
                        return Err(shape());
                    }
                    grad.copy_from_slice(values);
                }
                Err(_) => {
                    let v: Vec<f64> = g.extract().map_err(|_| shape())?;
                    if v.len() != n {
                        return Err(shape());
                    }
                    grad.copy_from_slice(&v);
                }
            }
            Ok(u)
        })
    }

    /// The exception the potential raised, if any (taken).
    fn take_error(&self) -> Option<PyErr> {
        self.error.lock().ok()?.take()
    }
}

impl ExternalPotential for PyPotential {
    fn energy_gradient(&self, q: &[f64], grad: &mut [f64]) -> f64 {
        let failed = self.error.lock().map(|e| e.is_some()).unwrap_or(true);
        let result = if failed { Ok(f64::NAN) } else { self.call(q, grad) };
        match result {
            Ok(u) if !failed => u,
            other => {
                if let (Err(e), Ok(mut slot)) = (other, self.error.lock()) {
                    *slot = Some(e);
                }
                grad.fill(f64::NAN);
                f64::NAN
            }
        }
    }

    fn describe(&self) -> String {
        let name = Python::attach(|py| {
            self.f.bind(py).getattr("__name__").and_then(|n| n.extract::<String>()).unwrap_or_else(|_| "f".into())
        });
        format!("the Python potential `{name}`")
    }
}

/// Runs the scene `text` (named `path` in messages) in memory, optionally on the Python
/// potential `potential(q) -> (U, dU/dq)`: nothing is written. Returns the records as arrays
/// (`rows`: the columns of trajectory.csv; `lab_positions`, `lab_velocities` in bohr and bohr
/// per ħ/E_h, shape (records, atoms, 3), and `lab_potential`, when the scene asks for "lab";
/// `dipole`, shape (records, 3), for "dipole"), the summary's JSON text, the molecule, the
/// scene's time unit. A scene naming "restart" in `run.outputs` is refused (a continuation
/// needs a folder). An exception of the potential is raised as it is.
#[pyfunction]
#[pyo3(signature = (path, text, potential=None))]
fn run_memory<'py>(
    py: Python<'py>,
    path: &str,
    text: &str,
    potential: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let scene = rovib::scene::parse_scene(path, text).map_err(|e| lib_error(e.into()))?;
    let potential = potential.map(|f| PyPotential { f, error: Mutex::new(None) });
    let mut records = Records::default();
    let result = with_signals(py, |stop, progress| {
        run_in_memory(path, text, potential.as_ref().map(|p| p as &dyn ExternalPotential), stop, progress, &mut records)
    });
    if let Some(e) = potential.as_ref().and_then(PyPotential::take_error) {
        return Err(e);
    }
    result?;
    let k = records.count;
    let width = records.rows.len().checked_div(k).unwrap_or(0);
    let d = PyDict::new(py);
    d.set_item("rows", PyArray1::from_vec(py, records.rows).reshape([k, width])?)?;
    if records.lab_potential.len() == k && k > 0 {
        let atoms = records.lab[0].len() / (3 * k);
        let [x, v] = records.lab;
        d.set_item("lab_positions", PyArray1::from_vec(py, x).reshape([k, atoms, 3])?)?;
        d.set_item("lab_velocities", PyArray1::from_vec(py, v).reshape([k, atoms, 3])?)?;
        d.set_item("lab_potential", PyArray1::from_vec(py, records.lab_potential))?;
    }
    if records.dipole.len() == 3 * k && k > 0 {
        d.set_item("dipole", PyArray1::from_vec(py, records.dipole).reshape([k, 3])?)?;
    }
    d.set_item("summary", records.summary)?;
    d.set_item("molecule", scene.molecule.get_ref())?;
    d.set_item("time_unit", scene.time_unit.name())?;
    d.set_item("euler_unwrapped", scene.euler_unwrapped)?;
    Ok(d)
}

/// The phase state (atomic units), centre of mass (bohr, bohr per ħ/E_h) and fit report of
/// lab-frame positions (Å, one row per atom) and velocities (Å/fs).
#[pyfunction]
#[pyo3(signature = (name, positions, velocities=None, initial_q=None))]
fn from_lab_frame<'py>(
    py: Python<'py>,
    name: &str,
    positions: Vec<[f64; 3]>,
    velocities: Option<Vec<[f64; 3]>>,
    initial_q: Option<Vec<f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let to_bohr = 1.0 / BOHR_IN_ANGSTROM;
    let v = angstrom_per_fs_in_au();
    let velocities = velocities.unwrap_or_else(|| vec![[0.0; 3]; positions.len()]);
    let visitor = FromLabVisitor {
        positions: positions.iter().map(|r| r.map(|x| x * to_bohr)).collect(),
        velocities: velocities.iter().map(|r| r.map(|x| x * v)).collect(),
        initial_q,
    };
    let out = molecules::visit(name, visitor).ok_or_else(|| unknown_molecule(name))?.map_err(message)?;
    let d = PyDict::new(py);
    for (key, values) in ["q", "p", "euler", "pe", "orientation", "J"].iter().zip(&out.state) {
        d.set_item(*key, PyArray1::from_slice(py, values))?;
    }
    let com = PyDict::new(py);
    com.set_item("position", PyArray1::from_slice(py, &out.com[0]))?;
    com.set_item("velocity", PyArray1::from_slice(py, &out.com[1]))?;
    d.set_item("com", com)?;
    let fit = PyDict::new(py);
    fit.set_item("iterations", out.iterations)?;
    fit.set_item("position_residual_bohr", out.report[0])?;
    fit.set_item("velocity_residual_au", out.report[1])?;
    fit.set_item("discarded_kinetic_energy_hartree", out.report[2])?;
    d.set_item("fit", fit)?;
    Ok(d)
}

/// Lab-frame positions (Å) and velocities (Å/fs), one row per atom, of a phase state (atomic
/// units) with its centre of mass (bohr, bohr per ħ/E_h; default at rest at the origin).
#[pyfunction]
#[pyo3(signature = (name, q=None, p=None, euler=None, pe=None, com_position=None, com_velocity=None, orientation=None, j=None))]
fn to_lab_frame<'py>(
    py: Python<'py>,
    name: &str,
    q: Option<Vec<f64>>,
    p: Option<Vec<f64>>,
    euler: Option<Vec<f64>>,
    pe: Option<Vec<f64>>,
    com_position: Option<[f64; 3]>,
    com_velocity: Option<[f64; 3]>,
    orientation: Option<[f64; 4]>,
    j: Option<[f64; 3]>,
) -> PyResult<Bound<'py, PyTuple>> {
    let body = match (orientation, j) {
        (Some(o), Some(j)) => Some((o, j)),
        (None, None) => None,
        _ => {
            return Err(message("state: give both `orientation` and `J`, or neither (then `euler` and `pe` are used)"));
        }
    };
    let visitor = ToLabVisitor {
        body,
        state: StateArgs { q, p, euler, pe },
        com: [com_position.unwrap_or_default(), com_velocity.unwrap_or_default()],
    };
    let (x, v) = molecules::visit(name, visitor).ok_or_else(|| unknown_molecule(name))?.map_err(message)?;
    let x: Vec<Vec<f64>> = x.iter().map(|r| r.iter().map(|c| c * BOHR_IN_ANGSTROM).collect()).collect();
    let v: Vec<Vec<f64>> = v.iter().map(|r| r.iter().map(|c| c / angstrom_per_fs_in_au()).collect()).collect();
    PyTuple::new(py, [matrix(py, &x)?.into_any(), matrix(py, &v)?.into_any()])
}

/// How deeply a scene given as a dict may nest tables and lists. A scene file nests at most four
/// levels (`[ensemble]` → `region` → `limits` → `[lo, hi]`); the bound keeps a deeply nested or
/// self-referencing dict from exhausting the stack.
const MAX_SCENE_DEPTH: usize = 32;

/// A Python value of a scene (dict, list, str, int, float, bool) as TOML; `at` names it in
/// messages, `depth` is how many tables and lists enclose it.
fn toml_value(v: &Bound<'_, PyAny>, at: &str, depth: usize) -> PyResult<toml::Value> {
    if depth > MAX_SCENE_DEPTH {
        return Err(message(format!(
            "scene: `{at}` is nested more than {MAX_SCENE_DEPTH} tables or lists deep (a scene nests at most \
             four; does a dict or list contain itself?)"
        )));
    }
    // bool before int: Python's bool is an int.
    if v.is_instance_of::<PyBool>() {
        Ok(toml::Value::Boolean(v.extract()?))
    } else if v.is_instance_of::<PyInt>() {
        Ok(toml::Value::Integer(v.extract()?))
    } else if v.is_instance_of::<PyFloat>() {
        Ok(toml::Value::Float(v.extract()?))
    } else if v.is_instance_of::<PyString>() {
        Ok(toml::Value::String(v.extract()?))
    } else if let Ok(d) = v.cast::<PyDict>() {
        let mut table = toml::Table::new();
        for (k, item) in d.iter() {
            let key: String = k.extract().map_err(|_| message(format!("scene: the keys of `{at}` must be strings")))?;
            let path = if at.is_empty() { key.clone() } else { format!("{at}.{key}") };
            table.insert(key, toml_value(&item, &path, depth + 1)?);
        }
        Ok(toml::Value::Table(table))
    } else if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() || v.hasattr("tolist")? {
        let items: Vec<Bound<'_, PyAny>> =
            if v.hasattr("tolist")? { v.call_method0("tolist")?.extract()? } else { v.extract()? };
        let values: PyResult<Vec<toml::Value>> =
            items.iter().enumerate().map(|(i, x)| toml_value(x, &format!("{at}[{i}]"), depth + 1)).collect();
        Ok(toml::Value::Array(values?))
    } else {
        Err(message(format!(
            "scene: `{at}` is a {}, which a scene cannot hold (use a dict, list, str, int, float or bool)",
            v.get_type().name()?
        )))
    }
}

/// The TOML text of a scene given as a dict (the same keys as a scene file).
#[pyfunction]
fn scene_toml(scene: &Bound<'_, PyDict>) -> PyResult<String> {
    let value = toml_value(scene.as_any(), "", 0)?;
    toml::to_string(&value).map_err(|e| message(format!("scene: cannot write it as toml: {e}")))
}

/// The module.
#[pymodule]
fn _rovib(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("RovibError", m.py().get_type::<RovibError>())?;
    m.add_function(wrap_pyfunction!(molecules_list, m)?)?;
    m.add_function(wrap_pyfunction!(molecule_info, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(run_scene, m)?)?;
    m.add_function(wrap_pyfunction!(run_memory, m)?)?;
    m.add_function(wrap_pyfunction!(sample, m)?)?;
    m.add_function(wrap_pyfunction!(sample_scene, m)?)?;
    m.add_function(wrap_pyfunction!(positions, m)?)?;
    m.add_function(wrap_pyfunction!(resume_scene, m)?)?;
    m.add_function(wrap_pyfunction!(run_ensemble_scene, m)?)?;
    m.add_function(wrap_pyfunction!(from_lab_frame, m)?)?;
    m.add_function(wrap_pyfunction!(to_lab_frame, m)?)?;
    m.add_function(wrap_pyfunction!(scene_toml, m)?)?;
    m.add("BOHR_IN_ANGSTROM", BOHR_IN_ANGSTROM)?;
    m.add("AU_TIME_IN_FS", AU_TIME_IN_FS)?;
    Ok(())
}
