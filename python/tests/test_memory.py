"""Runs in memory (nothing written, records as NumPy arrays) and Python-callable potentials."""

import json
import os
import re
import time

import numpy as np
import pytest

import rovib
from conftest import ROOT
from test_library import water

ARN2_SCENE = """molecule = "arn2"
[units]
angle = "deg"
[initial]
q = { R = 6.9, theta = 80 }
p = { R = 0, theta = 1.5 }
j = [0.5, -1.0, 4.0]
[integrator]
method = "dop853"
rtol = 1e-12
atol = 1e-12
[run]
end = 20000
output_interval = 500
outputs = ["trajectory", "summary"]
"""


def arn2_spline_tables():
    """The clamped cubic splines V0(R), V2(R) of molecules/arn2.toml: per interval its left knot
    and the four coefficients, read from the definition's text."""
    text = open(os.path.join(ROOT, "molecules", "arn2.toml"), encoding="utf-8").read()
    tables = []
    for name in ("v0", "v2"):
        body = text.split(f"{name} = \"\"\"", 1)[1].split("\"\"\"", 1)[0]
        rows = re.findall(r"cubic\(R - ([0-9.]+), ([-0-9.e]+), ([-0-9.e]+), ([-0-9.e]+), ([-0-9.e]+)\)", body)
        tail = float(re.search(r"([-0-9.]+) / pow\(R, 6\)\)+\s*$", body.strip()).group(1))
        tables.append(([tuple(float(x) for x in r) for r in rows], tail))
    return tables


def spline(table, r):
    """V(R) and dV/dR of one spline table (the knots' right ends are the next row's left knot, the
    last interval ends at 12 bohr, beyond which the -C6/R^6 tail holds)."""
    rows, c6 = table
    ends = [row[0] for row in rows[1:]] + [12.0]
    for (x0, a, b, c, d), end in zip(rows, ends):
        if r < end:
            x = r - x0
            return a + x * (b + x * (c + x * d)), b + x * (2.0 * c + x * 3.0 * d)
    return c6 / r**6, -6.0 * c6 / r**7


def arn2_python():
    """U(R, θ) = 30 exp(-1.6 R) (1 + 0.4 P2) + V0(R) + V2(R) P2 and its gradient, in NumPy."""
    v0, v2 = arn2_spline_tables()

    def arn2(q):
        r, theta = q
        c, s = np.cos(theta), np.sin(theta)
        p2, dp2 = 0.5 * (3.0 * c * c - 1.0), -3.0 * c * s
        e = 30.0 * np.exp(-1.6 * r)
        (a, da), (b, db) = spline(v0, r), spline(v2, r)
        u = e * (1.0 + 0.4 * p2) + a + b * p2
        return u, np.array([-1.6 * e * (1.0 + 0.4 * p2) + da + db * p2, e * 0.4 * dp2 + b * dp2])

    return arn2


def test_a_run_in_memory_writes_nothing_and_equals_the_run_into_a_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    def temporary():
        return {n for n in os.listdir(os.environ.get("TMPDIR", "/tmp")) if n.startswith("rovib")}

    before = temporary()
    scene = water(20.0, outputs=("trajectory", "lab", "summary"))
    t = rovib.run(scene)
    assert os.listdir(tmp_path) == []
    assert temporary() <= before
    assert t.out_dir is None and t.files == [] and t.time_unit == "fs"
    on_disk = rovib.run(scene, tmp_path / "out")
    assert t.names == on_disk.names and len(t) == len(on_disk) == 21
    for name in t.names:
        # The CSV holds every number to round-trip precision: the same bits.
        assert np.array_equal(t[name], on_disk[name]), name
    assert t.units == on_disk.units
    assert t.summary["rhs_evaluations"] == on_disk.summary["rhs_evaluations"] > 0
    # The lab frame in memory is lab.xyz's: positions in Å, one frame per record.
    xyz = (tmp_path / "out" / "lab.xyz").read_text().splitlines()
    first = np.array([[float(v) for v in line.split()[1:4]] for line in xyz[2:5]])
    assert t.lab_positions.shape == (21, 3, 3)
    assert np.allclose(t.lab_positions[0], first, atol=1e-12, rtol=1e-12)


def test_a_scene_given_as_text_or_path_runs_in_memory(tmp_path):
    path = tmp_path / "arn2.toml"
    path.write_text(ARN2_SCENE)
    a, b = rovib.run(ARN2_SCENE), rovib.run(path)
    assert np.array_equal(a["q_R"], b["q_R"]) and len(a) == 41
    assert sorted(os.listdir(tmp_path)) == ["arn2.toml"]


def test_a_run_in_memory_refuses_restart_with_the_line():
    scene = ARN2_SCENE.replace('outputs = ["trajectory", "summary"]', 'outputs = ["trajectory", "restart"]')
    with pytest.raises(rovib.RovibError, match=r"(?s)writes no restart.json.*<scene text>:15.*out_dir"):
        rovib.run(scene)


def test_a_python_potential_gives_the_definitions_trajectory_to_1e_12_bohr():
    f = arn2_python()
    # Pointwise first: the Python surface is the definition's.
    for r in (4.5, 5.5, 6.54, 7.5, 9.7, 11.9, 14.0):
        for theta in (0.2, 1.0, np.pi / 2, 2.9):
            e = rovib.evaluate("arn2", q=[r, theta])
            u, g = f(np.array([r, theta]))
            assert abs(u - e["U"]) <= 1e-13 * abs(e["U"])
            # At p = 0 and p_e = 0, dp/dt = -dU/dq.
            assert np.allclose(g, -e["rhs"]["p"], rtol=1e-11, atol=1e-16)
    reference = rovib.run(ARN2_SCENE)
    begin = time.perf_counter()
    python = rovib.run(ARN2_SCENE, potential=f)
    wall = time.perf_counter() - begin
    assert len(python) == len(reference) == 41
    # The trajectory goes somewhere, and the same way.
    assert abs(reference["q_R"][-1] - reference["q_R"][0]) > 0.05
    assert np.max(np.abs(python["q_R"] - reference["q_R"])) <= 1e-12
    assert np.max(np.abs(python["q_theta"] - reference["q_theta"])) <= 1e-12
    rhs = python.summary["rhs_evaluations"]
    print(
        f"Python potential: {rhs} right-hand sides in {wall:.3f} s, {1e6 * wall / rhs:.1f} us per RHS "
        f"(generated: {1e6 * reference.summary['wall_time_s'] / reference.summary['rhs_evaluations']:.2f} us)"
    )


def test_a_wrong_gradient_raises_with_the_coordinate_before_the_run():
    f = arn2_python()
    calls = []

    def wrong(q):
        calls.append(1)
        u, g = f(q)
        return u, g * np.array([1.0, 1.01])

    with pytest.raises(rovib.RovibError, match=r"gradient of the Python potential `wrong`.*fix ∂U/∂theta"):
        rovib.run(ARN2_SCENE, potential=wrong)
    # The check stopped it: 17 points, two coordinates, a handful of calls each.
    assert 0 < len(calls) < 200


class Boom(Exception):
    pass


def test_an_exception_in_the_potential_is_raised_from_run():
    f = arn2_python()
    calls = []

    def failing(q):
        calls.append(1)
        if len(calls) > 500:
            raise Boom(f"no energy at {q}")
        return f(q)

    with pytest.raises(Boom, match="no energy at"):
        rovib.run(ARN2_SCENE, potential=failing)
    assert len(calls) == 501
    # A potential returning the wrong shape is a TypeError naming what it must return.
    with pytest.raises(TypeError, match=r"must return \(U, dU/dq\)"):
        rovib.run(ARN2_SCENE, potential=lambda q: (0.0, np.zeros(3)))
    # Another run works.
    assert len(rovib.run(ARN2_SCENE)) == 41


# Boltzmann's constant in hartree per kelvin (CODATA 2018).
K_B = 3.166811563e-6


def test_thermal_draws_have_the_equipartition_kinetic_energy():
    # (J, p) Gaussian with covariance kT M(q): <T> = (3 + N) kT / 2 at every q, N = 3 for water.
    n, temperature = 4000, 300.0
    d = rovib.sample("h2o", "thermal", n, seed=11, temperature=temperature, energy_cap=0.1)
    assert d["q"].shape == (n, 3) and d["orientation"].shape == (n, 4) and d["J"].shape == (n, 3)
    kinetic = d["H"] - d["U"]
    mean, se = kinetic.mean(), kinetic.std(ddof=1) / np.sqrt(n)
    expected = 3.0 * K_B * temperature
    assert abs(mean - expected) < 4.0 * se, (mean, expected, se)
    assert np.allclose(np.linalg.norm(d["orientation"], axis=1), 1.0, atol=1e-12)
    # The same seed draws the same states.
    again = rovib.sample("h2o", "thermal", 3, seed=11, temperature=temperature, energy_cap=0.1)
    assert np.array_equal(again["q"], d["q"][:3])


def test_microcanonical_draws_lie_on_the_energy_shell():
    u_min = rovib.evaluate("h2o")["U"]
    energy = u_min + 0.01
    d = rovib.sample("h2o", "microcanonical", 200, seed=3, energy=energy, angular_momentum=5.0)
    assert np.allclose(d["H"], energy, rtol=0, atol=1e-10)
    assert np.allclose(np.linalg.norm(d["J"], axis=1), 5.0, rtol=1e-12)
    with pytest.raises(rovib.RovibError, match="needs `energy`"):
        rovib.sample("h2o", "microcanonical", 1)


def test_an_ase_calculator_wrapped_as_a_potential_runs_and_matches_its_pair_sum():
    pytest.importorskip("ase")
    from ase.calculators.lj import LennardJones
    from ase.units import Hartree

    from rovib.ase import calculator_potential

    # Å, eV: small enough a sigma that the frozen N-N pair (1.1 Å) is not deep in the wall, where
    # its constant 1e3-hartree energy would swamp the central differences of the gradient check.
    sigma, epsilon = 1.0, 1.0
    rc = 50.0
    f = calculator_potential("arn2", LennardJones(sigma=sigma, epsilon=epsilon, rc=rc, smooth=False))

    def lj(q, pairs=((0, 1), (0, 2), (1, 2))):
        """The same Lennard-Jones sum over the pairs, from the body-frame positions."""
        x = np.asarray(rovib.evaluate("arn2", q=q)["positions"]) * rovib.BOHR_IN_ANGSTROM
        u = 0.0
        for i, j in pairs:
            r = np.linalg.norm(x[i] - x[j])
            # ASE shifts each pair by its value at the cutoff rc.
            u += 4.0 * epsilon * ((sigma / r) ** 12 - (sigma / r) ** 6 - (sigma / rc) ** 12 + (sigma / rc) ** 6)
        return u / Hartree

    for q in ([6.9, 1.4], [8.0, 0.6], [7.2, 2.5]):
        u, g = f(np.array(q))
        assert abs(u - lj(q)) <= 1e-12 * abs(u)
        for k in range(2):
            h = 1e-5
            up, down = list(q), list(q)
            up[k] += h
            down[k] -= h
            # The N-N pair (frozen) is constant: the Ar-N pairs' central difference is the reference.
            ar = ((0, 2), (1, 2))
            assert abs(g[k] - (lj(up, ar) - lj(down, ar)) / (2 * h)) <= 1e-6 * abs(g[k])
    scene = {
        "molecule": "arn2",
        "initial": {"q": {"R": 6.9, "theta": 1.4}, "j": [0.0, 0.0, 4.0]},
        "run": {"end": 4000.0, "output_interval": 500.0},
    }
    t = rovib.run(scene, potential=f)
    assert len(t) == 9
    assert abs(t["H"][-1] - t["H"][0]) <= 1e-6 * abs(t["H"][0])


def test_a_sampled_state_runs_from_arrays_with_its_energy():
    s = rovib.sample("h2o", "thermal", 5, seed=2, temperature=500.0, energy_cap=0.1)
    scene = {"molecule": "h2o", "run": {"end": 100.0, "output_interval": 50.0}}
    with pytest.raises(rovib.RovibError, match="takes atomic units"):
        rovib.with_initial(scene, q=s["q"][0])
    scene["units"] = {"length": "bohr", "angle": "rad"}
    for i in range(5):
        t = rovib.run(rovib.with_initial(scene, q=s["q"][i], p=s["p"][i], j=s["J"][i]))
        # H does not depend on the orientation: the run starts at the drawn state's H.
        assert abs(t["H"][0] - s["H"][i]) <= 1e-12 * abs(s["H"][i])
        assert np.allclose([t["q_r1"][0], t["q_r2"][0], t["q_alpha"][0]], s["q"][i], rtol=1e-14, atol=0)
    with pytest.raises(rovib.RovibError, match="one per coordinate: r1, r2, alpha"):
        rovib.with_initial(scene, q=[1.0, 2.0])
