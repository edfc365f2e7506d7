"""Notebook-style example: run water's shipped scene from Python and plot its bond lengths.

Run from the repository root after `pip install ./python` (and `pip install matplotlib`):

    python python/examples/h2o_trajectory.py [OUT.png]

It runs scenes/h2o.toml (1 ps, the same code as `rovib run`), plots the two O-H bond lengths in
Å against time in fs, prints the energy conservation the run reports, and writes a PNG.
"""

# %% Imports and the run
import os
import sys

import matplotlib

matplotlib.use("Agg")  # no display needed
import matplotlib.pyplot as plt
import numpy as np

import rovib

here = os.path.dirname(os.path.abspath(__file__))
scene = os.path.join(here, "..", "..", "scenes", "h2o.toml")
# Without out_dir the outputs would go to a temporary folder, removed once read.
trajectory = rovib.run(scene, out_dir=os.path.join("out", "h2o_python"))
print(f"{len(trajectory)} output times in {trajectory.out_dir}; columns: {', '.join(trajectory.names)}")


# %% Columns by coordinate name (header `q_NAME`; units in trajectory.units.json), from bohr to Å
def coordinate(name):
    return trajectory.columns["q_" + name]


t = trajectory["t"]  # in the scene's time unit
unit = trajectory.time_unit
r1 = coordinate("r1") * rovib.BOHR_IN_ANGSTROM
r2 = coordinate("r2") * rovib.BOHR_IN_ANGSTROM
c = trajectory.summary["conservation"]
print(f"max |H(t) - H(0)| = {c['max_abs_energy_error_hartree']:.3e} hartree (relative {c['max_relative_energy_error']:.1e})")

# %% Plot
fig, ax = plt.subplots(figsize=(8, 3.5))
ax.plot(t, r1, label="r1 (O-H1)")
ax.plot(t, r2, label="r2 (O-H2)")
ax.set_xlabel(f"t / {unit}")
ax.set_ylabel("bond length / Å")
ax.set_title("H2O, one O-H bond stretched by 0.05 Å, |J| ≈ 9 ħ")
ax.legend(loc="upper right")
fig.tight_layout()
out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(trajectory.out_dir, "bond_lengths.png")
fig.savefig(out, dpi=120)
print(f"wrote {out}; mean r1 = {np.mean(r1):.4f} Å")
