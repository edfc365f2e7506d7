"""The package on the library: Ctrl-C, temporary folders, one time unit, from_lab along z."""

import glob
import os
import signal
import sys
import tempfile
import threading
import time

import numpy as np
import pytest

import rovib
from conftest import ROOT

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    tomllib = None


# What a run in memory can give back (restart.json needs a folder).
IN_MEMORY = ("trajectory", "summary")


def water(end_fs, interval_fs=1.0, outputs=("trajectory", "summary", "restart")):
    """scenes/h2o.toml as a dict, ending at ``end_fs`` with an output every ``interval_fs``."""
    return {
        "molecule": "h2o",
        "units": {"length": "angstrom", "angle": "deg", "time": "fs"},
        "initial": {
            "q": {"r1": 1.0078, "r2": 0.95785, "alpha": 104.5},
            "p": {"r1": 0.0, "r2": 0.0, "alpha": 0.0},
            "euler": [0.0, 90.0, 0.0],
            "j": [3.0, 8.0, 2.0],
        },
        "integrator": {"method": "dop853", "rtol": 1e-10, "atol": 1e-10},
        "run": {"end": end_fs, "output_interval": interval_fs, "outputs": list(outputs)},
    }


def water_ensemble(n, end_fs):
    """A thermal water ensemble of ``n`` trajectories to ``end_fs``, time in fs."""
    scene = water(end_fs, end_fs / 10.0, outputs=())
    del scene["initial"]
    scene["run"].pop("outputs")
    scene["ensemble"] = {
        "trajectories": n,
        "seed": 5,
        "method": "thermal",
        "temperature": 300.0,
        "region": {"energy_cap": 0.1},
    }
    scene["statistics"] = {"means": ["r1", "H"]}
    return scene


@pytest.fixture
def sigint():
    """SIGINT handled as in an interactive Python (``default_int_handler``, Ctrl-C raising
    ``KeyboardInterrupt``) for the test, the earlier handler restored after it. A process whose
    parent ignored SIGINT (a background job of a non-interactive shell, ``nohup``, some CI
    runners) inherits SIG_IGN, Python keeps it, and the kernel then discards the signal: no
    KeyboardInterrupt can arise, whatever the module does."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def interrupt_after(seconds):
    """SIGINT to this process after ``seconds``, from a timer thread (as Ctrl-C would)."""
    timer = threading.Timer(seconds, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    return timer


def test_ctrl_c_during_a_run_raises_keyboard_interrupt_and_the_next_run_works(tmp_path, sigint):
    # 900 ps in 9e5 outputs: seconds of work, unless the interrupt ends it first.
    timer = interrupt_after(0.5)
    begin = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        rovib.run(water(9e5), tmp_path / "long")
    timer.cancel()
    assert time.monotonic() - begin < 30.0
    # Python's own handler is still the one installed: no handler of rovib replaced it.
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    # The interrupted run stopped cleanly: its rows so far, and a restart file to continue from.
    assert (tmp_path / "long" / "restart.json").exists()
    rows = (tmp_path / "long" / "trajectory.csv").read_text().splitlines()
    assert len(rows) > 2
    # A second call runs normally.
    t = rovib.run(water(5.0), tmp_path / "short")
    assert len(t) == 6


def test_ctrl_c_during_an_ensemble_raises_keyboard_interrupt_and_the_next_works(tmp_path, sigint):
    timer = interrupt_after(0.5)
    begin = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        rovib.run_ensemble(water_ensemble(200000, 100.0), tmp_path / "long", threads=1)
    timer.cancel()
    assert time.monotonic() - begin < 30.0
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    e = rovib.run_ensemble(water_ensemble(16, 10.0), tmp_path / "short", threads=1)
    assert e.report["completed"] == 16


def test_ctrl_c_during_an_ensemble_in_memory_raises_keyboard_interrupt(sigint):
    timer = interrupt_after(0.5)
    begin = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        rovib.run_ensemble(water_ensemble(200000, 100.0), threads=1)
    timer.cancel()
    assert time.monotonic() - begin < 30.0
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def rovib_temporary_folders():
    return set(glob.glob(os.path.join(tempfile.gettempdir(), "rovib-*")))


def test_runs_without_out_dir_leave_no_temporary_folder(sigint):
    before = rovib_temporary_folders()
    t = rovib.run(water(5.0, outputs=IN_MEMORY))
    assert len(t) == 6 and t.out_dir is None
    e = rovib.run_ensemble(water_ensemble(16, 10.0), threads=1)
    assert e.report["completed"] == 16 and e.out_dir is None
    with pytest.raises(rovib.RovibError):
        rovib.run({"molecule": "h2o", "initial": {"q": {"nonsense": 1.0}}})
    timer = interrupt_after(0.5)
    with pytest.raises(KeyboardInterrupt):
        rovib.run(water(9e5, outputs=IN_MEMORY))
    timer.cancel()
    assert rovib_temporary_folders() == before


def test_trajectory_and_ensemble_times_are_in_the_scenes_time_unit(tmp_path):
    t = rovib.run(water(10.0, 0.5, outputs=IN_MEMORY))
    assert t.time_unit == "fs"
    assert np.allclose(t["t"], np.arange(21) * 0.5, rtol=0, atol=1e-12)
    e = rovib.run_ensemble(water_ensemble(16, 10.0), threads=1)
    assert e.time_unit == "fs"
    assert np.allclose(e.times, np.arange(11) * 1.0, rtol=0, atol=1e-12)
    # An atomic-unit scene: both in au.
    scene = water(10.0, 0.5, outputs=IN_MEMORY)
    del scene["units"]["time"]
    scene["run"]["end"] = 400.0
    scene["run"]["output_interval"] = 100.0
    assert rovib.run(scene).time_unit == "au"
    ens = water_ensemble(16, 400.0)
    del ens["units"]["time"]
    assert rovib.run_ensemble(ens, threads=1).time_unit == "au"


def test_from_lab_of_a_molecule_along_z_inverts_to_lab():
    # Water in its body frame and lab axes (Euler θ = 0): the body z axis along the lab z axis.
    state = {
        "q": [1.85, 1.80, 1.82],
        "p": [0.3, -0.2, 0.1],
        "orientation": [1.0, 0.0, 0.0, 0.0],
        "J": [1.0, -2.0, 3.0],
    }
    x, v = rovib.to_lab("h2o", state)
    back = rovib.from_lab("h2o", x, v)
    assert np.allclose(back["q"], state["q"], rtol=0, atol=1e-10)
    assert np.allclose(back["p"], state["p"], rtol=0, atol=1e-10)
    assert np.allclose(back["J"], state["J"], rtol=0, atol=1e-10)
    assert abs(back["euler"][1]) < 1e-6
    x2, v2 = rovib.to_lab("h2o", back)
    assert np.allclose(x2, x, rtol=0, atol=1e-10) and np.allclose(v2, v, rtol=0, atol=1e-12)


@pytest.mark.skipif(tomllib is None, reason="tomllib needs Python 3.11")
def test_an_ensembles_correlations_and_spectrum_are_arrays():
    with open(os.path.join(ROOT, "scenes", "h2o_ir.toml"), "rb") as f:
        scene = tomllib.load(f)
    scene["ensemble"]["trajectories"] = 16
    scene["run"]["end"] = 4000.0
    e = rovib.run_ensemble(scene, threads=1)
    c = e.correlations
    assert c["tau_au"][0] == 0.0 and len(c["tau_au"]) > 10
    names = [n for n in c if n.startswith("mu_x_C_") and n.endswith("^2") and "stderr" not in n]
    assert len(names) == 1, list(c)
    # C(0) = <mu_x(0)^2> > 0, and the normalised column is C(tau)/C(0).
    assert c[names[0]][0] > 0.0
    assert np.allclose(c["mu_x_C_normalised"], c[names[0]] / c[names[0]][0], rtol=1e-12, atol=0)
    assert np.all(c["n"] == 16)
    s = e.spectrum
    assert len(s["wavenumber_cm-1"]) > 10 and np.all(np.diff(s["wavenumber_cm-1"]) > 0)
    assert any(name.startswith("sigma_") for name in s)
