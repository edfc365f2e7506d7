"""Conversions between ASE ``Atoms`` and rovib's phase state; ASE is imported only when used.

ASE works in Å, u and eV, so its time unit is Å·sqrt(u/eV) ≈ 10.18 fs: velocities from
``Atoms.get_velocities()`` are in Å per ASE time unit and ``ase.units.fs`` is one femtosecond in
that unit. rovib's lab functions use Å/fs, hence the factor ``ase.units.fs`` below.
"""

from __future__ import annotations

from typing import Any, Dict

import numpy as np

from . import BOHR_IN_ANGSTROM, from_lab, molecule_info, positions, to_lab


def to_atoms(name: str, state: Dict[str, Any]):
    """An ``ase.Atoms`` of molecule ``name`` at ``state`` (see :func:`rovib.to_lab`), with the
    molecule's elements and masses (Da) and its velocities."""
    from ase import Atoms, units

    info = molecule_info(name)
    positions, velocities = to_lab(name, state)
    atoms = Atoms(symbols=info["atoms"]["elements"], positions=positions, masses=info["atoms"]["masses_da"])
    # Å/fs → Å per ASE time unit: multiply by the number of fs in one ASE time unit.
    atoms.set_velocities(np.asarray(velocities) / units.fs)
    return atoms


def from_atoms(name: str, atoms, initial_q=None) -> Dict[str, Any]:
    """rovib's phase state (see :func:`rovib.from_lab`) of an ``ase.Atoms`` of molecule ``name``,
    atoms in the molecule's order; velocities are taken from the Atoms (zero if it has none)."""
    from ase import units

    info = molecule_info(name)
    symbols = atoms.get_chemical_symbols()
    if list(symbols) != list(info["atoms"]["elements"]):
        from . import RovibError

        raise RovibError(
            f"error: the atoms are {symbols}, but {name} has {info['atoms']['elements']} in this order "
            "(reorder the Atoms to the molecule's atom order)"
        )
    velocities = atoms.get_velocities()
    if velocities is not None:
        velocities = np.asarray(velocities) * units.fs
    return from_lab(name, atoms.get_positions(), velocities, initial_q)


def calculator_potential(name: str, calculator):
    """A potential ``f(q) -> (U, dU/dq)`` for ``rovib.run(scene, potential=f)`` from an ASE
    calculator: the atoms (the molecule's elements, in its order) stand at the positions the
    definition gives for ``q`` (:func:`rovib.positions`; the energy of an isolated molecule does
    not depend on its orientation or place), ``U`` is the calculator's energy in hartree and
    ``dU/dq = −Σ F · ∂x/∂q`` with the generated Jacobian ``∂x/∂q``, in hartree per bohr or rad."""
    from ase import Atoms, units

    info = molecule_info(name)
    atoms = Atoms(symbols=info["atoms"]["elements"], masses=info["atoms"]["masses_da"])
    atoms.calc = calculator

    def f(q):
        x, dx = positions(name, q)
        atoms.positions = x * BOHR_IN_ANGSTROM
        energy = atoms.get_potential_energy()
        # eV/Å times Å per unit of q.
        forces = atoms.get_forces()
        grad = -np.einsum("ai,kai->k", forces, dx * BOHR_IN_ANGSTROM)
        return energy / units.Hartree, grad / units.Hartree

    f.__name__ = f"ase_{type(calculator).__name__}"
    return f
