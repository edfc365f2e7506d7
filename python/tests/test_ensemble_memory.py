"""Ensembles in memory, scenes passed as text, and every sampler of a scene, checked against the
files the same scene and seed write and against the samplers' own definitions."""

import os

import numpy as np
import pytest

import rovib

ENSEMBLE = {
    "molecule": "h2o",
    "ensemble": {
        "trajectories": 12,
        "seed": 4,
        "method": "thermal",
        "temperature": 300.0,
        "region": {"energy_cap": 0.1},
    },
    "statistics": {"means": ["r1", "H"], "correlations": ["r1", "mu_x", "mu_y", "mu_z"]},
    "integrator": {"method": "dop853", "rtol": 1e-8, "atol": 1e-8},
    "run": {"end": 2000.0, "output_interval": 20.0},
}


def same_bits(a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def test_an_ensemble_in_memory_equals_the_files_of_the_same_seed_bit_for_bit(tmp_path):
    memory = rovib.run_ensemble(ENSEMBLE, threads=1)
    files = rovib.run_ensemble(ENSEMBLE, tmp_path / "ens", threads=2)
    assert memory.out_dir is None and memory.report["files"] == []
    assert memory.summary["status"] == "completed" and memory.summary["trajectories"]["completed"] == 12
    assert files.summary["trajectories"]["completed"] == 12
    assert same_bits(memory.times, files.times) and memory.time_unit == files.time_unit == "au"
    assert same_bits(memory.means, files.means) and same_bits(memory.stderr, files.stderr)
    # The columns of correlations.csv and spectrum.csv (read back from the files), in order.
    for found, written in ((memory.correlations, files.correlations), (memory.spectrum, files.spectrum)):
        assert list(found) == list(written) and len(found) > 3
        for name in written:
            assert same_bits(found[name], written[name]), name
    assert "mu_x_C_(e*bohr)^2" in memory.correlations and "sigma_harmonic_cm2" in memory.spectrum
    # ensemble.csv's means (read independently of the report).
    data = np.genfromtxt(tmp_path / "ens" / "ensemble.csv", delimiter=",", names=True)
    assert same_bits(memory.mean("H")[0], data["H_mean_hartree"])


def test_a_scene_given_as_a_dict_or_text_with_out_dir_writes_no_scene_file(tmp_path):
    rovib.run_ensemble(ENSEMBLE, tmp_path / "ens", threads=1)
    assert not (tmp_path / "ens" / "scene.toml").exists()
    scene = {
        "molecule": "h2o",
        "initial": {"q": {"r1": 1.9, "r2": 1.75, "alpha": 1.8}},
        "units": {"length": "bohr", "angle": "rad"},
        "run": {"end": 200.0, "output_interval": 20.0, "outputs": ["trajectory", "summary", "restart"]},
    }
    t = rovib.run(scene, tmp_path / "run")
    assert len(t) == 11 and not (tmp_path / "run" / "scene.toml").exists()
    longer = dict(scene, run=dict(scene["run"], end=400.0))
    t = rovib.resume(tmp_path / "run", longer)
    assert len(t) == 21 and sorted(os.listdir(tmp_path / "run")) == sorted(
        ["trajectory.csv", "trajectory.units.json", "summary.json", "restart.json"]
    )
    # The text of a scene file, named as its text: the same rows as the file itself.
    text = rovib._rovib.scene_toml(scene)
    a = rovib.run(text, tmp_path / "text")
    (tmp_path / "scene.toml").write_text(text)
    b = rovib.run(tmp_path / "scene.toml", tmp_path / "file")
    assert same_bits(a["H"], b["H"])


def test_ensemble_states_of_the_thermal_and_microcanonical_methods_are_the_samplers(tmp_path):
    drawn = rovib.ensemble_states(ENSEMBLE, 20)
    direct = rovib.sample("h2o", "thermal", 20, seed=4, temperature=300.0, energy_cap=0.1)
    for key in ("q", "p", "orientation", "J", "H", "U"):
        assert same_bits(drawn[key], direct[key]), key
    assert drawn["molecule"] == "h2o" and "300" in drawn["description"]
    energy = rovib.evaluate("h2o")["U"] + 0.02
    micro = dict(ENSEMBLE, ensemble={"trajectories": 8, "seed": 2, "method": "microcanonical", "energy": energy})
    m = rovib.ensemble_states(micro, 8)
    assert np.allclose(m["H"], energy, rtol=0, atol=1e-9)
    direct = rovib.sample("h2o", "microcanonical", 8, seed=2, energy=energy)
    assert same_bits(m["q"], direct["q"]) and same_bits(m["J"], direct["J"])


def test_ensemble_states_reads_a_states_file_and_draws_normal_modes(tmp_path):
    states = tmp_path / "states.csv"
    states.write_text("q_r1,q_r2,q_alpha,p_alpha,Jx,Jy,Jz\n1.8,1.9,1.8,0.1,1.0,2.0,3.0\n1.85,1.75,1.9,-0.2,0,0,0\n")
    scene = dict(ENSEMBLE, ensemble={"trajectories": 2, "method": "file", "file": str(states)})
    s = rovib.ensemble_states(scene, 2)
    assert same_bits(s["q"], [[1.8, 1.9, 1.8], [1.85, 1.75, 1.9]])
    assert same_bits(s["p"], [[0.0, 0.0, 0.1], [0.0, 0.0, -0.2]])
    assert np.allclose(s["J"], [[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]], rtol=0, atol=1e-12)
    # H of each row is the molecule's Hamiltonian there.
    for i in range(2):
        x, v = rovib.to_lab("h2o", {k: s[k][i] for k in ("q", "p", "orientation", "J")})
        back = rovib.from_lab("h2o", x, v)
        e = rovib.evaluate("h2o", q=back["q"], p=back["p"], euler=back["euler"], pe=back["pe"])
        assert abs(e["H"] - s["H"][i]) < 1e-10
    with pytest.raises(rovib.RovibError, match="state 2"):
        rovib.ensemble_states(scene, 3)
    modes = dict(ENSEMBLE, ensemble={"trajectories": 4, "seed": 1, "method": "normal-modes", "quanta": [0, 0, 0],
                                       "temperature": 300.0})
    n = rovib.ensemble_states(modes, 4)
    assert n["q"].shape == (4, 3) and np.all(np.isfinite(n["H"]))


def test_what_an_ensemble_in_memory_cannot_do_is_a_clear_error():
    kept = dict(ENSEMBLE, ensemble=dict(ENSEMBLE["ensemble"], keep_trajectories=2))
    with pytest.raises(rovib.RovibError, match="keep_trajectories.*output folder"):
        rovib.run_ensemble(kept)
    with pytest.raises(rovib.RovibError, match="error: .*unknown ensemble method"):
        rovib.ensemble_states(dict(ENSEMBLE, ensemble={"trajectories": 2, "method": "thermall"}), 2)
    with pytest.raises(rovib.RovibError, match="at most"):
        rovib.ensemble_states(ENSEMBLE, 10**9)
    with pytest.raises(rovib.RovibError, match="n must be"):
        rovib.ensemble_states(ENSEMBLE, -1)
