"""The rovib Python package against the CLI, closed forms, finite differences and conservation."""

import json
import math
import os
import sys

import numpy as np
import pytest

import rovib
from conftest import ROOT, cli

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    tomllib = None

H2O_SCENE = os.path.join(ROOT, "scenes", "h2o.toml")


def column(trajectory, coordinate, prefix="q_"):
    """A trajectory column by coordinate name: ``q_NAME`` (or ``p_NAME`` with prefix="p_")."""
    return trajectory.columns[prefix + coordinate]


def energy_column(trajectory):
    return trajectory.columns["H"]


EULER = ["euler_phi", "euler_theta", "euler_psi"]
PE = ["pe_phi", "pe_theta", "pe_psi"]


def scene_dict(name, end):
    """The shipped scene `scenes/NAME` as a dict (as `rovib.run` takes it), ending at `end`."""
    with open(os.path.join(ROOT, "scenes", name), "rb") as f:
        scene = tomllib.load(f)
    scene["run"]["end"] = end
    return scene


def state_at(t, k):
    """The phase state (atomic units) of row k of a water trajectory."""
    names = rovib.molecule_info("h2o")["coordinates"]["names"]
    return {
        "q": [column(t, n)[k] for n in names],
        "p": [column(t, n, "p_")[k] for n in names],
        "euler": [t[c][k] for c in EULER],
        "pe": [t[c][k] for c in PE],
    }


def test_molecules_lists_h2o_and_info_matches_definition():
    assert "h2o" in rovib.molecules()
    info = rovib.molecule_info("h2o")
    assert info["atoms"]["elements"] == ["O", "H", "H"]
    assert info["coordinates"]["names"] == ["r1", "r2", "alpha"]
    # The definition writes r in Å and alpha in degrees: 0.95785 Å and 104.5°.
    r1, r2, alpha = info["coordinates"]["reference"]
    assert r1 == pytest.approx(0.95785 / rovib.BOHR_IN_ANGSTROM, rel=1e-12)
    assert alpha == pytest.approx(math.radians(104.5), abs=1e-7)
    assert info["atoms"]["masses_da"][0] == pytest.approx(15.995, abs=0.01)


def test_unknown_molecule_raises_rovib_error():
    with pytest.raises(rovib.RovibError, match="unknown molecule `h3o`"):
        rovib.evaluate("h3o")
    assert issubclass(rovib.RovibError, ValueError)


def test_evaluate_at_rest_at_reference_is_the_potential_minimum():
    e = rovib.evaluate("h2o")
    # At rest: no kinetic energy, H = U; the model potential is zero at its reference.
    assert e["T"] == 0.0
    assert e["H"] == e["U"]
    assert abs(e["U"]) < 1e-12
    # Body-frame positions: centre of mass at the origin (masses in Da are proportional).
    m = np.asarray(rovib.molecule_info("h2o")["atoms"]["masses_da"])
    assert np.allclose(m @ e["positions"], 0.0, atol=1e-12)


STATE = dict(q=[1.9, 1.75, 1.7], p=[0.3, -0.2, 0.4], euler=[0.3, 1.2, -0.4], pe=[2.0, -1.0, 3.0])


def test_evaluate_rhs_is_hamiltons_equations_by_finite_differences():
    e = rovib.evaluate("h2o", **STATE)
    h = 1e-6

    def dH(field, i):
        plus = {k: list(v) for k, v in STATE.items()}
        minus = {k: list(v) for k, v in STATE.items()}
        plus[field][i] += h
        minus[field][i] -= h
        return (rovib.evaluate("h2o", **plus)["H"] - rovib.evaluate("h2o", **minus)["H"]) / (2 * h)

    for i in range(3):
        assert e["rhs"]["q"][i] == pytest.approx(dH("p", i), rel=1e-6, abs=1e-9)
        assert e["rhs"]["p"][i] == pytest.approx(-dH("q", i), rel=1e-6, abs=1e-9)
        assert e["rhs"]["euler"][i] == pytest.approx(dH("pe", i), rel=1e-6, abs=1e-9)
        assert e["rhs"]["pe"][i] == pytest.approx(-dH("euler", i), rel=1e-6, abs=1e-9)


def test_evaluate_equals_the_cli(tmp_path):
    state = tmp_path / "state.json"
    state.write_text(json.dumps(STATE))
    done = cli("eval", "--molecule", "h2o", "--state", str(state))
    assert done.returncode == 0, done.stderr
    expected = json.loads(done.stdout)
    e = rovib.evaluate("h2o", **STATE)
    assert e["H"] == expected["H"]
    assert e["U"] == expected["U"]
    for key in ("a", "A", "I", "G11", "G12", "G22", "positions"):
        assert np.array_equal(e[key], np.asarray(expected[key])), key
    for key in ("q", "p", "euler", "pe"):
        assert np.array_equal(e["rhs"][key], np.asarray(expected["rhs"][key])), key


def test_evaluate_rejects_a_wrong_length():
    with pytest.raises(rovib.RovibError, match=r"`q` has 2 entries, expected 3"):
        rovib.evaluate("h2o", q=[1.0, 2.0])


def test_run_conserves_energy_to_the_stated_error_and_matches_output_times(tmp_path):
    t = rovib.run(H2O_SCENE, tmp_path / "out")
    s = t.summary
    assert s["status"] == "completed"
    # 0 to 1000 fs every 1 fs.
    assert len(t) == 1001 == s["conservation"]["samples"]
    assert np.allclose(t["t"], np.arange(1001) * 1.0, atol=1e-9)
    h = energy_column(t)
    drift = np.max(np.abs(h - h[0]))
    assert h[0] == s["conservation"]["initial_energy_hartree"]
    assert drift <= s["conservation"]["max_abs_energy_error_hartree"]
    assert drift == pytest.approx(s["conservation"]["max_abs_energy_error_hartree"], rel=1e-6)
    assert drift < 1e-9
    # The CSV's H, recomputed independently from its own state columns by the G-matrix path.
    for k in (0, 500, 1000):
        assert rovib.evaluate("h2o", **state_at(t, k))["H"] == pytest.approx(h[k], rel=1e-11)
    # The units file names every column's unit.
    assert t.units["t"] == "fs" and t.units["q_r1"] == "bohr" and t.units["q_alpha"] == "rad"
    assert t.units["p_r1"] == "hbar/bohr" and t.units["pe_phi"] == "hbar" and t.units["H"] == "hartree"
    assert list(t.units) == t.names


@pytest.mark.skipif(tomllib is None, reason="tomllib needs Python 3.11")
def test_a_dict_scene_runs_exactly_as_its_file(tmp_path):
    scene = scene_dict("h2o.toml", 100.0)
    from_dict = rovib.run(scene, tmp_path / "dict")
    file_scene = tmp_path / "file.toml"
    file_scene.write_text(open(H2O_SCENE).read().replace("end = 1000.0", "end = 100.0"))
    from_file = rovib.run(file_scene, tmp_path / "file")
    assert len(from_dict) == 101
    assert from_dict.names == from_file.names
    for name in from_dict.names:
        assert np.array_equal(from_dict[name], from_file[name]), name


def test_a_bad_scene_raises_the_cli_message_with_file_and_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(open(H2O_SCENE).read().replace("output_interval = 1.0", "output_intervall = 1.0"))
    with pytest.raises(rovib.RovibError) as caught:
        rovib.run(bad, tmp_path / "out")
    message = str(caught.value)
    assert f"{bad}:" in message
    done = cli("run", str(bad), "--out", str(tmp_path / "cli"), "--quiet")
    assert done.returncode != 0
    assert done.stderr.strip() == message.strip()


def test_a_dict_scene_with_an_unknown_value_type_is_rejected(tmp_path):
    with pytest.raises(rovib.RovibError, match="cannot hold"):
        rovib.run({"molecule": "h2o", "initial": {"q": object()}}, tmp_path)


def test_a_dict_scene_nested_deeply_or_containing_itself_is_rejected_not_a_crash(tmp_path):
    # Without a depth bound the conversion recursed once per level and overflowed the stack
    # (SIGSEGV) at 10 000 levels; a dict containing itself recursed without end.
    deep = {}
    inner = deep
    for _ in range(10_000):
        inner["a"] = {}
        inner = inner["a"]
    with pytest.raises(rovib.RovibError, match="nested more than 32"):
        rovib.run({"molecule": "h2o", "initial": deep}, tmp_path / "deep")
    looped = {"molecule": "h2o"}
    looped["initial"] = looped
    with pytest.raises(rovib.RovibError, match="contain itself"):
        rovib.run(looped, tmp_path / "looped")
    listed = []
    listed.append(listed)
    with pytest.raises(rovib.RovibError, match="nested more than 32"):
        rovib.run({"molecule": "h2o", "initial": {"q": listed}}, tmp_path / "listed")


def _moving_state():
    state = dict(STATE)
    state["com"] = {"position": np.array([0.5, -1.0, 2.0]), "velocity": np.array([1e-4, 2e-4, -3e-4])}
    return state


def test_from_lab_inverts_to_lab():
    state = _moving_state()
    x, v = rovib.to_lab("h2o", state)
    assert x.shape == (3, 3) and v.shape == (3, 3)
    back = rovib.from_lab("h2o", x, v)
    for key in ("q", "p", "euler", "pe"):
        assert np.allclose(back[key], state[key], rtol=0, atol=1e-10), key
    assert np.allclose(back["com"]["position"], state["com"]["position"], atol=1e-10)
    assert np.allclose(back["com"]["velocity"], state["com"]["velocity"], atol=1e-12)
    assert back["fit"]["discarded_kinetic_energy_hartree"] < 1e-20


def test_lab_kinetic_energy_is_the_hamiltonians():
    # Independent of the conversion code: ½ Σ m v² from the lab velocities (Å/fs, Da) equals T.
    x, v = rovib.to_lab("h2o", STATE)
    m = np.asarray(rovib.molecule_info("h2o")["atoms"]["masses_da"]) * 1822.888486209
    v_au = np.asarray(v) * rovib.AU_TIME_IN_FS / rovib.BOHR_IN_ANGSTROM
    t = 0.5 * np.sum(m[:, None] * v_au**2)
    assert t == pytest.approx(rovib.evaluate("h2o", **STATE)["T"], rel=1e-12)


def test_from_lab_names_a_wrong_atom_count():
    with pytest.raises(rovib.RovibError, match="positions have 2 rows, expected one per atom of h2o"):
        rovib.from_lab("h2o", np.zeros((2, 3)))


def test_ase_round_trip_with_velocities():
    import ase
    from ase import units

    from rovib.ase import from_atoms, to_atoms

    state = _moving_state()
    atoms = to_atoms("h2o", state)
    assert atoms.get_chemical_symbols() == ["O", "H", "H"]
    # ASE's kinetic energy (eV), from its masses (u) and velocities (Å per ASE time unit), is the
    # Hamiltonian's T plus the centre of mass's ½ M V², in hartree × 27.211386 eV.
    m = np.asarray(rovib.molecule_info("h2o")["atoms"]["masses_da"]) * 1822.888486209
    com_ke = 0.5 * m.sum() * np.sum(state["com"]["velocity"] ** 2)
    expected_ev = (rovib.evaluate("h2o", **STATE)["T"] + com_ke) * units.Hartree
    assert atoms.get_kinetic_energy() == pytest.approx(expected_ev, rel=1e-9)
    back = from_atoms("h2o", atoms)
    for key in ("q", "p", "euler", "pe"):
        assert np.allclose(back[key], state[key], rtol=0, atol=1e-10), key
    assert ase.__version__


@pytest.mark.skipif(tomllib is None, reason="tomllib needs Python 3.11")
def test_run_ensemble_means_conserve_energy(tmp_path):
    scene = scene_dict("h2o_thermal.toml", 500.0)
    scene["ensemble"]["trajectories"] = 1024
    scene["statistics"].pop("histograms", None)
    scene["statistics"].pop("correlations", None)
    e = rovib.run_ensemble(scene, tmp_path / "ens", threads=1)
    assert e.report["completed"] == 1024
    assert e.times[0] == 0.0 and e.times[-1] == 500.0
    assert e.means.shape == (len(e.times), len(e.quantities))
    h, h_err = e.mean("H")
    # Every trajectory conserves H (rtol 1e-8): the mean is the same at every time.
    assert np.allclose(h, h[0], rtol=1e-6)
    assert h_err[0] > 0
    # Canonical at 300 K: T is quadratic in 6 momenta (3 vibrations, 3 rotations), so its mean is
    # exactly 3 kT (kT = 9.5e-4 hartree) whatever the potential; 4σ of the sample mean.
    t, t_err = e.mean("T")
    kt = 300.0 * 3.166811563e-6
    assert abs(t[0] - 3 * kt) < 4 * t_err[0]


def test_lab_xyz_reads_in_ase_with_masses_velocities_and_energies(tmp_path):
    import ase.io
    from ase import units

    t = rovib.run(H2O_SCENE, tmp_path / "out")
    frames = ase.io.read(os.path.join(t.out_dir, "lab.xyz"), index=":")
    assert len(frames) == len(t)
    info = rovib.molecule_info("h2o")
    masses = np.asarray(info["atoms"]["masses_da"])
    hartree_in_ev = 27.211386245988  # CODATA 2018, as rovib writes it
    for k in (0, 400, 1000):
        atoms = frames[k]
        state = state_at(t, k)
        x, v = rovib.to_lab("h2o", state)
        assert atoms.get_chemical_symbols() == ["O", "H", "H"]
        # Full round-trip precision: the positions are the library's to round-off.
        assert np.allclose(atoms.get_positions(), x, rtol=0, atol=1e-13), k
        assert np.array_equal(atoms.get_masses(), masses), k
        # ASE's velocities (Å per ASE time unit) in Å/fs.
        assert np.allclose(atoms.get_velocities() * units.fs, v, rtol=1e-12, atol=1e-15), k
        # ASE's potential energy (eV) is U(q) of the same row, by the G-matrix path.
        u = rovib.evaluate("h2o", q=state["q"])["U"]
        assert atoms.get_potential_energy() == pytest.approx(u * hartree_in_ev, rel=1e-12, abs=1e-15), k
        assert atoms.info["H_hartree"] == t["H"][k]
        # ASE's kinetic energy from its masses and momenta is the Hamiltonian's T (this scene has
        # no centre-of-mass motion): T + U = H, in ASE's own eV (CODATA 2014), to 1e-8.
        total_ev = atoms.get_kinetic_energy() + atoms.get_potential_energy()
        assert total_ev / units.Hartree == pytest.approx(t["H"][k], rel=1e-7), k


@pytest.mark.skipif(tomllib is None, reason="tomllib needs Python 3.11")
def test_resume_continues_a_run_bit_for_bit(tmp_path):
    scene = scene_dict("h2o.toml", 100.0)
    whole = rovib.run(scene, tmp_path / "whole")
    scene["run"]["end"] = 50.0
    first = rovib.run(scene, tmp_path / "split")
    assert len(first) == 51 and os.path.exists(os.path.join(first.out_dir, "restart.json"))
    scene["run"]["end"] = 100.0
    split = rovib.resume(first.out_dir, scene)
    assert len(split) == len(whole) == 101
    assert split.summary["resumed_from"] == pytest.approx(50.0)
    for name in whole.names:
        # After t = 50 fs the continuation is the uninterrupted run, bit for bit.
        assert np.array_equal(split[name][51:], whole[name][51:]), name
        assert np.allclose(split[name][:51], whole[name][:51], rtol=1e-8, atol=1e-10), name
    # A scene that changes the integrator is another run.
    scene["integrator"]["rtol"] = 1e-9
    scene["run"]["end"] = 150.0
    with pytest.raises(rovib.RovibError, match=r"differs from the run being continued.*\[integrator\]"):
        rovib.resume(first.out_dir, scene)
