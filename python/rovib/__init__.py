"""rovib from Python: classical rotation-vibration dynamics of polyatomic molecules.

A thin layer over the Rust library (the extension module ``rovib._rovib``): every function runs
the same code as the ``rovib`` command, so results equal the CLI's. Units are atomic unless
stated: bohr, rad, electron masses, hartree; masses of atoms in Da; lab-frame positions in Å and
velocities in Å/fs.

One time unit: every time this package returns (``Trajectory["t"]``, ``Ensemble.times``, the lag
column ``tau_UNIT`` of ``Ensemble.correlations``) is in the scene's time unit, ``units.time``:
"au" (ħ/E_h = ``AU_TIME_IN_FS`` fs ≈ 0.0242 fs) unless the scene says "fs" or "ps"; each result
names it as ``time_unit``. Times given to functions are read in that same unit.

Errors raise :class:`RovibError` (a ``ValueError``) with the CLI's message. Ctrl-C during a run
or an ensemble stops it cleanly and raises ``KeyboardInterrupt``; no signal handler is
installed. Without an ``out_dir`` nothing is written: the scene is passed to the library as text
and the results come back as NumPy arrays (:func:`run`, :func:`run_ensemble`).
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Tuple, Union

import numpy as np

from . import _rovib
from ._rovib import AU_TIME_IN_FS, BOHR_IN_ANGSTROM, RovibError

__all__ = [
    "RovibError",
    "Trajectory",
    "Ensemble",
    "molecules",
    "molecule_info",
    "evaluate",
    "run",
    "run_ensemble",
    "resume",
    "from_lab",
    "to_lab",
    "sample",
    "with_initial",
    "positions",
    "ensemble_states",
    "read_trajectory",
    "BOHR_IN_ANGSTROM",
    "AU_TIME_IN_FS",
]

PathLike = Union[str, "os.PathLike[str]"]


def molecules() -> List[str]:
    """The names of the compiled-in molecules, sorted (as ``rovib list``)."""
    return list(_rovib.molecules_list())


def molecule_info(name: str) -> Dict[str, Any]:
    """Atoms and internal coordinates of molecule ``name``.

    Returns ``{"name", "atoms": {"labels", "elements", "masses_da"}, "coordinates": {"names",
    "units", "reference"}}``: masses in Da; each coordinate's atomic unit ("bohr" or "rad") and
    its reference value in that unit (None if the definition gives none).
    """
    return _rovib.molecule_info(name)


def evaluate(name: str, q=None, p=None, euler=None, pe=None) -> Dict[str, Any]:
    """Everything about one state of molecule ``name``, as ``rovib eval`` prints it.

    ``q`` (bohr or rad, default the reference geometry), ``p`` (ħ/bohr or ħ, default 0),
    ``euler`` (φ, θ, ψ in rad, default (0, π/2, 0)), ``pe`` (p_φ, p_θ, p_ψ in ħ, default 0).
    Returns ``H``, ``U``, ``T`` (hartree), ``positions`` (body frame, bohr, one row per atom), the
    kinetic matrices ``a``, ``A``, ``I``, the G matrices ``G11``, ``G12``, ``G22``, the body-frame
    angular momentum ``J`` (ħ) and ``rhs`` (dq/dt, dp/dt, deuler/dt, dpe/dt per ħ/E_h).
    """
    return _rovib.evaluate(name, _vec(q), _vec(p), _vec(euler), _vec(pe))


def _vec(x) -> Optional[List[float]]:
    return None if x is None else [float(v) for v in np.asarray(x, dtype=float).ravel()]


def _rows(x) -> Optional[List[List[float]]]:
    if x is None:
        return None
    a = np.asarray(x, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise RovibError(f"error: expected an array of shape (atoms, 3), got shape {a.shape}")
    return a.tolist()


@dataclass
class Trajectory:
    """A finished run: the columns of ``trajectory.csv`` as NumPy arrays, and ``summary.json``.

    A run in memory (no ``out_dir``) has the same columns and summary, and, when the scene's
    ``run.outputs`` names "lab" (the default outputs do), ``lab_positions`` and
    ``lab_velocities`` (Å and Å/fs, shape (records, atoms, 3), as lab.xyz) and ``lab_potential``
    (hartree); for "dipole", ``dipole`` (e·bohr, shape (records, 3), as dipole.csv).

    ``columns`` maps each CSV header name to its array: ``t`` (the scene's time unit,
    ``time_unit``), ``q_NAME``
    (bohr or rad), ``p_NAME`` (ħ/bohr or ħ), ``euler_phi``, ``euler_theta``, ``euler_psi`` (rad),
    ``pe_phi``, ``pe_theta``, ``pe_psi`` (ħ), ``Jx``, ``Jy``, ``Jz`` (body frame, ħ), ``H`` (hartree), and with ``run.euler_unwrapped``
    ``euler_phi_unwrapped``, ``euler_psi_unwrapped``. ``units`` maps every column to its unit, in
    file order (from ``trajectory.units.json``). ``out_dir`` holds every file written (lab.xyz,
    restart.json ...); it is None for a run in memory.
    """

    out_dir: Optional[str]
    columns: Dict[str, np.ndarray]
    summary: Dict[str, Any]
    units: Dict[str, str] = field(default_factory=dict)
    files: List[str] = field(default_factory=list)
    lab_positions: Optional[np.ndarray] = None
    lab_velocities: Optional[np.ndarray] = None
    lab_potential: Optional[np.ndarray] = None
    dipole: Optional[np.ndarray] = None

    @property
    def time_unit(self) -> str:
        """The unit of ``self["t"]``: the scene's ``units.time`` ("au" for ħ/E_h, "fs" or "ps")."""
        return self.units.get("t", "au")

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0

    @property
    def names(self) -> List[str]:
        """The column names, in file order."""
        return list(self.columns)


@dataclass
class Ensemble:
    """A finished ensemble: means and standard errors per output time and quantity.

    ``means[k, j]`` and ``stderr[k, j]`` are quantity ``quantities[j]`` (unit ``units[j]``) at
    ``times[k]``, in the scene's time unit ``time_unit`` (as a trajectory's ``t``).

    ``correlations`` holds the columns of correlations.csv as NumPy arrays: ``tau_UNIT`` (the lag,
    in the scene's time unit), ``n`` (trajectories spanning the lag) and per correlated quantity
    ``NAME_C_UNIT^2`` (C(τ) in the square of the quantity's atomic unit, e.g. ``(e*bohr)^2``),
    ``NAME_C_stderr_UNIT^2`` (its standard error) and ``NAME_C_normalised`` (C(τ)/C(0)).
    ``spectrum`` holds those of spectrum.csv: ``wavenumber_cm-1`` (cm⁻¹),
    ``lineshape_e2bohr2_per_hartree`` (e²·bohr²/hartree) and, for a thermal ensemble,
    ``sigma_CORRECTION_cm2`` (the absorption cross section per molecule, cm², under each quantum
    correction), for a pair ensemble with a pair volume ``alpha_over_rho2_CORRECTION_cm-1_amagat-2``.
    Both are empty when the scene asks for none.

    Without ``out_dir`` (``out_dir`` None) nothing was written: the arrays come straight from the
    library, and ``summary`` holds the keys of summary.json that the run's report gives
    (``status``, ``trajectories``, ``seed``, ``sampler``, ``threads``, ``wall_time_s``,
    ``time_unit``). With ``out_dir`` every file is there and ``summary`` is summary.json.
    """

    out_dir: Optional[str]
    times: np.ndarray
    quantities: List[str]
    units: List[str]
    means: np.ndarray
    stderr: np.ndarray
    summary: Dict[str, Any]
    report: Dict[str, Any]
    time_unit: str = "au"
    correlations: Dict[str, np.ndarray] = field(default_factory=dict)
    spectrum: Dict[str, np.ndarray] = field(default_factory=dict)

    def mean(self, quantity: str) -> Tuple[np.ndarray, np.ndarray]:
        """The mean of ``quantity`` and its standard error at every output time."""
        j = self.quantities.index(quantity)
        return self.means[:, j], self.stderr[:, j]


def read_trajectory(out_dir: PathLike) -> Trajectory:
    """Reads the outputs of a finished run in ``out_dir`` (trajectory.csv, summary.json, and
    trajectory.units.json when present)."""
    out_dir = os.fspath(out_dir)
    path = os.path.join(out_dir, "trajectory.csv")
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = [[float(x) for x in row] for row in reader if row]
    data = np.array(rows, dtype=float).reshape(len(rows), len(header))
    columns = {name: data[:, j].copy() for j, name in enumerate(header)}
    summary = _read_json(os.path.join(out_dir, "summary.json")) or {}
    units = _read_json(os.path.join(out_dir, "trajectory.units.json")) or {}
    if "columns" in units and isinstance(units["columns"], dict):
        # JSON objects are unordered: "order" lists the columns in file order.
        order = units.get("order") or list(units["columns"])
        units = {name: units["columns"][name] for name in order if name in units["columns"]}
    return Trajectory(out_dir=out_dir, columns=columns, summary=summary, units=units)


def _read_columns(path: str) -> Dict[str, np.ndarray]:
    """The columns of a CSV file of numbers (lines starting with ``#`` skipped), by header name;
    empty if the file does not exist."""
    if not os.path.exists(path):
        return {}
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.reader(line for line in f if not line.startswith("#"))
        header = next(reader)
        rows = [[float(x) for x in row] for row in reader if row]
    data = np.array(rows, dtype=float).reshape(len(rows), len(header))
    return {name: data[:, j].copy() for j, name in enumerate(header)}


def _read_json(path: str):
    if not os.path.exists(path):
        return None
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def _scene_source(scene) -> Tuple[str, Optional[str]]:
    """The name and TOML text of a scene for the library: a dict (converted to TOML), a TOML text
    (a str with a line break), or the path of a scene file with no text (the library reads it, as
    the ``rovib`` command does; relative paths in it resolve from its folder)."""
    if isinstance(scene, dict):
        return "<scene dict>", _rovib.scene_toml(scene)
    if isinstance(scene, str) and "\n" in scene:
        return "<scene text>", scene
    return os.fspath(scene), None


def _scene_text(scene) -> Tuple[str, str]:
    """The TOML text of a scene and the name its messages use: a dict (written as TOML), a TOML
    text (a str with a line break), or the path of a scene file (read; its folder is where
    relative paths in it resolve from)."""
    if isinstance(scene, dict):
        return "<scene dict>", _rovib.scene_toml(scene)
    if isinstance(scene, str) and "\n" in scene:
        return "<scene text>", scene
    path = os.fspath(scene)
    with open(path, encoding="utf-8") as f:
        return path, f.read()


def _unwrapped(angle: np.ndarray) -> np.ndarray:
    """A continuous angle: each record adds the change since the previous one, taken in (−π, π]
    (as trajectory.csv's ``euler_*_unwrapped`` columns)."""
    if len(angle) == 0:
        return angle.copy()
    d = np.fmod(np.diff(angle), 2.0 * np.pi)
    d = np.where(d > np.pi, d - 2.0 * np.pi, np.where(d <= -np.pi, d + 2.0 * np.pi, d))
    return np.add.accumulate(np.concatenate([angle[:1], d]))


def _run_in_memory(scene, potential) -> Trajectory:
    path, text = _scene_text(scene)
    out = _rovib.run_memory(path, text, potential)
    info = molecule_info(out["molecule"])
    names = info["coordinates"]["names"]
    units = info["coordinates"]["units"]
    momentum = {"bohr": "hbar/bohr", "rad": "hbar"}
    header = [("t", out["time_unit"])]
    header += [(f"q_{n}", u) for n, u in zip(names, units)]
    header += [(f"p_{n}", momentum.get(u, "hbar/" + u)) for n, u in zip(names, units)]
    header += [(f"euler_{a}", "rad") for a in ("phi", "theta", "psi")]
    header += [(f"pe_{a}", "hbar") for a in ("phi", "theta", "psi")]
    header += [("Jx", "hbar"), ("Jy", "hbar"), ("Jz", "hbar"), ("H", "hartree")]
    rows = out["rows"].reshape(-1, len(header))
    columns = {name: rows[:, j].copy() for j, (name, _) in enumerate(header)}
    unit_of = dict(header)
    if out["euler_unwrapped"]:
        for a in ("phi", "psi"):
            columns[f"euler_{a}_unwrapped"] = _unwrapped(columns[f"euler_{a}"])
            unit_of[f"euler_{a}_unwrapped"] = "rad"
    summary = json.loads(out["summary"]) if out["summary"] else {}
    t = Trajectory(out_dir=None, columns=columns, summary=summary, units=unit_of)
    if "lab_positions" in out:
        t.lab_positions = out["lab_positions"] * BOHR_IN_ANGSTROM
        t.lab_velocities = out["lab_velocities"] * (BOHR_IN_ANGSTROM / AU_TIME_IN_FS)
        t.lab_potential = out["lab_potential"]
    if "dipole" in out:
        t.dipole = out["dipole"]
    return t


def positions(name: str, q) -> Tuple[np.ndarray, np.ndarray]:
    """The atoms' positions of molecule ``name`` at ``q`` (bohr, rad) in its definition's frame,
    shape (atoms, 3) in bohr, and their derivatives by each coordinate, shape (coordinates,
    atoms, 3) in bohr per bohr or rad: the generated kinematics' ``positions`` and
    ``positions_jacobian``."""
    return _rovib.positions(name, _vec(q))


def with_initial(scene: Dict[str, Any], q=None, p=None, euler=None, pe=None, j=None) -> Dict[str, Any]:
    """A copy of the dict ``scene`` whose ``[initial]`` table holds the given arrays: ``q`` and
    ``p`` one value per coordinate in the molecule's order (named for the table), ``euler``,
    ``pe`` and ``j`` three values each, all in atomic units (bohr, rad, ħ/bohr, ħ; ``j`` is the
    body-frame angular momentum), as :func:`sample` and :func:`from_lab` return them. A scene
    reads ``[initial]`` in its ``[units]``, else in each coordinate's declared unit, so the
    scene must say ``units = {"length": "bohr", "angle": "rad"}`` (else this raises). Keys not
    given keep the scene's values."""
    if not isinstance(scene, dict):
        raise RovibError("error: with_initial takes a scene as a dict (the keys of a scene file)")
    units = scene.get("units") or {}
    if (q is not None or p is not None or euler is not None) and (
        units.get("length") != "bohr" or units.get("angle") != "rad"
    ):
        raise RovibError(
            "error: with_initial takes atomic units, but the scene reads [initial] in "
            f"{units or 'each coordinate declared unit'}: give it units = {{\"length\": \"bohr\", \"angle\": \"rad\"}}"
        )
    names = molecule_info(scene["molecule"])["coordinates"]["names"]
    initial = dict(scene.get("initial") or {})
    for key, values in (("q", q), ("p", p)):
        if values is not None:
            a = np.asarray(values, dtype=float).ravel()
            if a.shape != (len(names),):
                raise RovibError(
                    f"error: initial `{key}` has {a.size} values, expected one per coordinate: {', '.join(names)}"
                )
            initial[key] = {n: float(v) for n, v in zip(names, a)}
    for key, values in (("euler", euler), ("pe", pe), ("j", j)):
        if values is not None:
            a = np.asarray(values, dtype=float).ravel()
            if a.shape != (3,):
                raise RovibError(f"error: initial `{key}` has {a.size} values, expected 3")
            initial[key] = [float(v) for v in a]
    out = dict(scene)
    out["initial"] = initial
    return out


def run(
    scene: Union[PathLike, str, Dict[str, Any]],
    out_dir: Optional[PathLike] = None,
    potential: Optional[Callable[[np.ndarray], Tuple[float, np.ndarray]]] = None,
) -> Trajectory:
    """Runs a scene as ``rovib run`` does and returns its records as NumPy arrays.

    ``scene`` is a dict with the keys of a scene file, a scene's TOML text (a str with a line
    break), or a scene file's path. Without ``out_dir`` nothing is written: the records come
    back in memory; a scene whose ``run.outputs`` names "restart" is refused there (with the
    line to change), since a continuation needs restart.json in a folder. With ``out_dir`` the
    run writes its files there exactly as
    ``rovib run SCENE --out OUT_DIR`` does (a dict scene is passed as text, and restart.json
    keeps it) and they are read back; :func:`resume` continues it. Ctrl-C stops the run at its next output time and
    raises ``KeyboardInterrupt``.

    ``potential``: a function ``f(q) -> (U, dU/dq)`` over the molecule's internal coordinates
    (a NumPy array in bohr and rad, in the order of ``molecule_info(name)["coordinates"]``; U in
    hartree, dU/dq a sequence of one float per coordinate) that replaces the molecule's
    potential for this run (in memory only). Its gradient is checked against central
    differences of U before the run (a mismatch raises :class:`RovibError` naming the
    coordinate); an exception raised by ``f`` ends the run and is raised from ``run``.
    """
    if out_dir is None:
        return _run_in_memory(scene, potential)
    if potential is not None:
        raise RovibError("error: a Python potential runs in memory only: call run(scene, potential=f) without out_dir")

    out = os.fspath(out_dir)
    path, text = _scene_source(scene)
    files = [os.fspath(f) for f in _rovib.run_scene(path, out, text)]
    if not os.path.exists(os.path.join(out, "trajectory.csv")):
        raise RovibError(
            f"error: the run wrote no trajectory.csv into {out} (add \"trajectory\" to the scene's outputs)"
        )
    trajectory = read_trajectory(out)
    trajectory.files = files
    return trajectory


def resume(out_dir: PathLike, scene: Union[None, PathLike, Dict[str, Any]] = None) -> Trajectory:
    """Continues the run in ``out_dir`` from its ``restart.json`` as ``rovib run --resume OUT_DIR
    [SCENE]`` does, and reads the whole trajectory (both parts).

    Without ``scene`` the run continues to its own scene's end (after an interrupt); a scene (a
    path, a TOML text or a dict, passed as text) may change only ``run.end`` (and
    ``max_energy_error``, ``max_outputs``). With DOP853 every row after the first run's last one
    is bit for bit the row of one uninterrupted run (docs/src/howto/restarts.md).
    """
    out = os.fspath(out_dir)
    path, text = (None, None) if scene is None else _scene_source(scene)
    files = [os.fspath(f) for f in _rovib.resume_scene(out, path, text)]
    trajectory = read_trajectory(out)
    trajectory.files = files
    return trajectory


def run_ensemble(
    scene: Union[PathLike, str, Dict[str, Any]], out_dir: Optional[PathLike] = None, threads: Optional[int] = None
) -> Ensemble:
    """Runs the ensemble of a scene with an ``[ensemble]`` table as ``rovib ensemble`` does.

    ``scene`` is a dict with the keys of a scene file, a scene's TOML text (a str with a line
    break), or a scene file's path. ``threads`` overrides the scene's (default: the scene's, else
    every core); the statistics do not depend on it. Returns the means and standard errors per
    output time, the times in the scene's time unit (``time_unit``), and the correlations and
    spectrum as NumPy arrays (see :class:`Ensemble` for their columns and units).

    Without ``out_dir`` nothing is written (no folder, checkpoint or file): the results come back
    from the library in memory, the same numbers, bit for bit, as the files of a run with the
    same seed; a collision ensemble and ``ensemble.keep_trajectories`` need a folder and are
    refused there. With ``out_dir`` the ensemble writes every file ``rovib ensemble SCENE --out
    OUT_DIR`` writes. Ctrl-C stops the ensemble (no trajectory starts, running ones stop at their
    next output time) and raises ``KeyboardInterrupt``.
    """
    path, text = _scene_source(scene)
    threads = None if threads is None else int(threads)
    if out_dir is None:
        report = _rovib.run_ensemble_scene(path, None, threads, text)
        summary = {
            "status": report["status"],
            "trajectories": {
                "requested": report["requested"],
                "completed": report["completed"],
                "failed": report["failed_count"],
                "interrupted_or_not_run": report["interrupted_or_not_run"],
            },
            "seed": report["seed"],
            "sampler": report["sampler"],
            "threads": report["threads"],
            "wall_time_s": report["wall_time_s"],
            "time_unit": report["time_unit"],
        }
        correlations = dict(report["correlations"])
        spectrum = dict(report["spectrum"])
        out = None
    else:
        out = os.fspath(out_dir)
        os.makedirs(out, exist_ok=True)
        report = _rovib.run_ensemble_scene(path, out, threads, text)
        summary = _read_json(os.path.join(out, "summary.json")) or {}
        correlations = _read_columns(os.path.join(out, "correlations.csv"))
        spectrum = _read_columns(os.path.join(out, "spectrum.csv"))
    return Ensemble(
        out_dir=out,
        times=report["times"],
        quantities=list(report["quantities"]),
        units=list(report["units"]),
        means=report["means"],
        stderr=report["stderr"],
        summary=summary,
        report=report,
        time_unit=report["time_unit"],
        correlations=correlations,
        spectrum=spectrum,
    )


def from_lab(name: str, positions, velocities=None, initial_q=None) -> Dict[str, Any]:
    """rovib's phase state of lab-frame Cartesians of molecule ``name``.

    ``positions`` in Å and ``velocities`` in Å/fs (default zero), shape (atoms, 3) in the
    molecule's atom order. Returns ``q``, ``p``, ``euler``, ``pe`` (atomic units), the
    orientation as a unit quaternion ``orientation`` (w, x, y, z) and the body-frame angular
    momentum ``J`` (ħ), ``com`` (``position`` in bohr, ``velocity`` in bohr per ħ/E_h) and ``fit``
    (residuals of the fit; velocity parts the internal coordinates cannot represent are
    discarded and reported). Every orientation converts, the body z axis along the lab z axis
    included (Euler θ = 0, where the Euler angles are one of equivalent choices and only
    ``orientation`` and ``J`` determine the motion; :func:`to_lab` uses them when present).
    """
    return _rovib.from_lab_frame(name, _rows(positions), _rows(velocities), _vec(initial_q))


def to_lab(name: str, state: Dict[str, Any]) -> Tuple[np.ndarray, np.ndarray]:
    """Lab-frame positions (Å) and velocities (Å/fs), shape (atoms, 3), of a state of molecule
    ``name``: a dict with ``q``, ``p`` and either ``orientation`` (unit quaternion w, x, y, z)
    and ``J`` (body frame, ħ), or ``euler`` and ``pe`` (atomic units), and optionally ``com`` as
    :func:`from_lab` returns it (default at rest at the origin). ``orientation`` and ``J`` take
    precedence: they are defined at every orientation, Euler θ = 0 included."""
    com = state.get("com") or {}
    return _rovib.to_lab_frame(
        name,
        _vec(state.get("q")),
        _vec(state.get("p")),
        _vec(state.get("euler")),
        _vec(state.get("pe")),
        _vec(com.get("position")),
        _vec(com.get("velocity")),
        _vec(state.get("orientation")),
        _vec(state.get("J")),
    )


def sample(
    name: str,
    method: str,
    n: int,
    seed: int = 0,
    temperature: Optional[float] = None,
    energy: Optional[float] = None,
    angular_momentum: Optional[float] = None,
    energy_cap: Optional[float] = None,
) -> Dict[str, np.ndarray]:
    """``n`` initial states of molecule ``name`` drawn as an ensemble with ``seed`` draws its
    trajectories 0 to n − 1: ``method="thermal"`` at ``temperature`` (kelvin), or
    ``"microcanonical"`` at total ``energy`` (hartree, the potential's zero) with optionally a
    fixed ``angular_momentum`` |J| (ħ); ``energy_cap`` (hartree above the reference geometry's
    U) bounds the region as ``[ensemble] region.energy_cap`` does.

    Returns NumPy arrays: ``q``, ``p`` (n × coordinates; bohr or rad, ħ/bohr or ħ),
    ``orientation`` (n × 4, unit quaternions w, x, y, z, body → lab), ``J`` (n × 3, body frame,
    ħ), ``H`` and ``U`` (n, hartree). A row with ``q``, ``p``, ``orientation`` and ``J`` is a
    state :func:`to_lab` takes. The other samplers of a scene's ``[ensemble]`` (normal modes, a
    states file, ...) draw through :func:`ensemble_states`.
    """
    return _rovib.sample(name, method, int(n), int(seed), temperature, energy, angular_momentum, energy_cap)


def ensemble_states(scene: Union[PathLike, str, Dict[str, Any]], n: int) -> Dict[str, Any]:
    """The initial states of trajectories 0 to n − 1 of the ensemble of ``scene`` (a dict, TOML
    text or path with an ``[ensemble]`` table), drawn by its ``method`` exactly as
    :func:`run_ensemble` draws them, without running anything: every sampler a scene offers
    ("thermal", "microcanonical", "normal-modes", "file" with a states file in CSV or XYZ,
    see the ensemble reference), with its ``region``, the scene's ``[potential]``, and the
    ``[pairs] max_energy`` restriction. A collision ensemble (two molecules) is refused.

    Returns NumPy arrays as :func:`sample` does: ``q``, ``p`` (n × coordinates; bohr or rad,
    ħ/bohr or ħ), ``orientation`` (n × 4, unit quaternions w, x, y, z, body → lab), ``J``
    (n × 3, body frame, ħ), ``H`` and ``U`` (n, hartree); and ``molecule`` and ``description``
    (how the states are drawn, as summary.json's ``sampler``).
    """
    if int(n) < 0:
        raise RovibError(f"error: n must be a count of states (0 or more), got {n}")
    path, text = _scene_source(scene)
    return _rovib.sample_scene(path, int(n), text)
