"""Weakly compressible SPH of a fluid at rest in LAMMPS (SPH package).

A periodic box of fluid with zero velocity should stay at rest; with an
irregular particle set the SPH density summation and pressure gradient are not
uniform (no zeroth-order consistency, Fan Sec. 1), so spurious currents grow.
The kinetic energy after a fixed number of steps measures how good the
particle distribution is (Fan's motivation for relaxation).

Model: ``pair_style hybrid/overlay sph/rhosum 1 sph/taitwater`` (density by
kernel summation every step, Tait equation of state
``p = c0^2 rho0 / 7 ((rho/rho0)^7 - 1)``, Monaghan artificial viscosity
``alpha``), integrated by ``fix sph``.  LAMMPS' SPH kernel is Lucy's with
support ``h`` (the same support-radius convention as Fan's W).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from ._library import import_lammps, new_lammps
from .box import infer_dim
from .data_file import write_data

__all__ = ["sph_at_rest"]


def sph_at_rest(atoms, h, dx, steps=400, rho0=1.0, c0=10.0, alpha=0.1, dt=None, sample_every=50, workdir=None,
                nthreads=1):
    """Run fluid at rest from ``atoms`` and return the spurious kinetic energy.

    Parameters
    ----------
    atoms : ase.Atoms
        Periodic 2D or 3D particle set (each particle of volume dx^dim).
    h : float
        SPH kernel support radius (LAMMPS' ``h``).
    dx : float
        Particle spacing; mass = rho0 dx^dim.
    steps : int
        Number of time steps.
    rho0, c0, alpha : float
        Reference density, sound speed, artificial viscosity.
    dt : float or None
        Time step (default 0.1 h / c0).
    sample_every : int
        Kinetic energy sampling interval.

    Returns
    -------
    dict
        ``ke`` (final kinetic energy, 0.5 sum m v^2), ``ke_per_particle``,
        ``ke_max`` (largest sampled), ``ke_history`` (list of (step, ke)), ``vmax_over_c0``, ``rho_std``
        (relative spread of the summation density at the start), ``n``, ``dt``.
    """
    if not all(atoms.pbc[: infer_dim(atoms)]):
        raise ValueError("sph_at_rest needs a periodic particle set (atoms.pbc True along every dimension)")
    for name, value in dict(h=h, dx=dx, rho0=rho0, c0=c0).items():
        if not (np.isscalar(value) and value > 0):
            raise ValueError(f"{name} must be a positive float, got {value!r}")
    if not (isinstance(steps, (int, np.integer)) and steps >= 1):
        raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
    import_lammps()
    dim = infer_dim(atoms)
    dt = 0.1 * h / c0 if dt is None else float(dt)
    mass = rho0 * dx**dim
    tmp = tempfile.TemporaryDirectory(prefix="lammps_io_sph_") if workdir is None else None
    folder = Path(tmp.name if tmp else workdir)
    folder.mkdir(parents=True, exist_ok=True)
    try:
        box = write_data(atoms, folder / "sph.data", atom_style="sph", dim=dim, masses=mass, rho=rho0, esph=0.0,
                         cv=1.0)
        lmp = new_lammps(nthreads=nthreads)
        cwd = os.getcwd()
        os.chdir(folder)
        try:
            lmp.commands_list([
                *box.read_data_commands("sph.data", "sph", "p p p"),
                "pair_style hybrid/overlay sph/rhosum 1 sph/taitwater",
                f"pair_coeff * * sph/rhosum {h:.17g}",
                f"pair_coeff * * sph/taitwater {rho0:.17g} {c0:.17g} {alpha:.17g} {h:.17g}",
                f"neighbor {0.2 * h:.17g} bin",
                "neigh_modify every 1 delay 0 check yes",
                "compute fanke all ke",
                "variable vmag atom sqrt(vx*vx+vy*vy+vz*vz)",
                "compute vmax all reduce max v_vmag",
                "thermo_style custom step c_fanke c_vmax",
                "thermo_modify norm no",
                f"thermo {int(sample_every)}",
                "fix fansph all sph",
            ] + (["fix fan2d all enforce2d"] if box.lammps_dimension == 2 else []) + [
                f"timestep {dt:.17g}",
                "run 0",
            ])
            n = lmp.get_natoms()
            rho_p = np.array(lmp.gather_atoms("rho", 1, 1)[:n])
            history = []
            done = 0
            while done < steps:
                chunk = min(int(sample_every), steps - done)
                lmp.command(f"run {chunk} pre no post no" if done else f"run {chunk}")
                done += chunk
                history.append((done, float(lmp.last_thermo()["c_fanke"])))
            vmax = float(lmp.last_thermo()["c_vmax"])
            lmp.close()
        finally:
            os.chdir(cwd)
    finally:
        if tmp is not None:
            tmp.cleanup()
    ke = history[-1][1]
    return dict(ke=ke, ke_per_particle=ke / n, ke_max=max(k for _, k in history), ke_history=history, vmax_over_c0=vmax / c0,
                rho_std=float(np.std(rho_p) / np.mean(rho_p)), rho_mean=float(np.mean(rho_p)), n=int(n), dt=dt,
                steps=int(steps), h=float(h), c0=float(c0), alpha=float(alpha))
