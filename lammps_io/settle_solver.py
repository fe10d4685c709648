"""The ``lammps`` solver of :func:`ase_sphrelax.settle` (entry point ``ase_sphrelax.settle_solvers``).

A start run at rest in :func:`lammps_io.sph_flows.hydrostatic_tank` with the file's wall particles
(``type`` 2); the record's keys are those of :func:`ase_sphrelax.flows.settle.settle`.
"""
from __future__ import annotations

import warnings

import numpy as np

from ase_sphrelax.flows.settle import FLUID, WALL, displacements

from . import _library
from .sph_flows import hydrostatic_tank, tait_pressure

__all__ = ["run_tank", "check"]


def check():
    """Raise the one-line ImportError of a missing LAMMPS before any work."""
    _library.import_lammps()


def run_tank(atoms, kinds, dx, h, t_end, rho0, g, c0, alpha, surface, depth, samples, progress):
    """Run ``atoms`` (fluid ``kinds`` 1, wall 2) at rest in LAMMPS; the run's part of settle's record.

    ``surface`` and ``depth`` (m) set the hydrostatic reference of ``pressure_error`` (RMS of
    ``p - rho0 g (surface - y)`` over ``rho0 g depth``); ``max_drop`` is in ``dx``.
    """
    fluid = kinds == FLUID
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its instability verdict is recorded in 'stable'
        out = hydrostatic_tank(atoms, h, dx, rho0=rho0, g=g, c0=c0, alpha=alpha, t_end=t_end, samples=samples,
                               progress=progress, check_units=False)
    x_end = out["positions"][fluid]
    p = tait_pressure(out["density_p"][fluid], rho0, out["c0"])
    error = float(np.sqrt(np.mean((p - rho0 * g * (surface - x_end[:, 1])) ** 2)) / (rho0 * g * depth))
    drop, moved = displacements(atoms.positions[fluid], x_end, dx, np.zeros(2, bool), None)
    n_wall = int((kinds == WALL).sum())
    return dict(ke_history=[[float(t), float(k)] for t, k in out["ke_history"]], pressure_error=error,
                max_drop=drop, max_displacement=moved, n_fluid=int(fluid.sum()), n_wall=n_wall,
                steps=int(out["steps"]), c0=float(out["c0"]), alpha=float(alpha), stable=bool(out["stable"]),
                stability_reason=out["stability_reason"], wall_model=f"wall particles ({n_wall}, LAMMPS)")
