"""Write particle sets as LAMMPS data files (``read_data`` format).

Atoms-section columns (checked against ``write_data`` of LAMMPS 22 Jul 2025):

========  ==========================================
atomic    ``atom-ID atom-type x y z``
sph       ``atom-ID atom-type rho esph cv x y z``
sphere    ``atom-ID atom-type diameter density x y z``
========  ==========================================

Coordinates are written as they are (no unit conversion): SPH particle sets
carry their own length unit, and ``units`` only names the LAMMPS unit system
the file is meant for.  ASE's own ``write_lammps_data`` supports neither
``sph`` nor ``sphere`` and raises ``KeyError`` for ``units lj``.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ase_sphrelax.checks import finite_array

from .box import lammps_box

__all__ = ["write_data", "ATOM_STYLES", "UNIT_STYLES", "check_units_style"]

ATOM_STYLES = ("atomic", "sph", "sphere")
UNIT_STYLES = ("lj", "real", "metal", "si", "cgs", "electron", "micro", "nano")


def check_units_style(units, atom_style):
    """Validate ``units``/``atom_style`` names before LAMMPS sees them.

    LAMMPS itself accepts every unit system with these atom styles (checked:
    ``units electron/real/micro`` with ``atom_style sph`` run ``sph/taitwater``);
    what it rejects are SPH pair styles without ``atom_style sph``, 2D boxes
    with z tilts or off-plane atoms, and atoms outside non-periodic boxes,
    which :func:`lammps_io.box.lammps_box` and :func:`lammps_io.sph_at_rest`
    rule out before LAMMPS starts.

    Raises
    ------
    ValueError
        for unknown names.
    """
    if atom_style not in ATOM_STYLES:
        raise ValueError(f"atom_style must be one of {ATOM_STYLES}, got {atom_style!r}")
    if units not in UNIT_STYLES:
        raise ValueError(f"units must be one of {UNIT_STYLES}, got {units!r}")


def particle_types(atoms):
    """LAMMPS type (1-based) of each particle: ``atoms.arrays['type']`` if
    present, else one type per distinct atomic number (ascending)."""
    if "type" in atoms.arrays:
        t_p = np.asarray(atoms.arrays["type"], dtype=int)
        if t_p.min() < 1:
            raise ValueError("atoms.arrays['type'] must hold LAMMPS types >= 1")
        return t_p
    numbers = atoms.numbers
    _, t_p = np.unique(numbers, return_inverse=True)
    return t_p.astype(int) + 1


def write_data(
    atoms,
    path,
    atom_style="atomic",
    units="lj",
    dim=None,
    masses=None,
    volume=None,
    rho=None,
    esph=0.0,
    cv=1.0,
    diameter=None,
    margin=None,
    thickness=1.0,
    velocities=None,
):
    """Write ``atoms`` as a LAMMPS data file.

    Parameters
    ----------
    atoms : ase.Atoms
        Periodic directions follow ``atoms.pbc``; 2D sets live at z = 0.
    path : str or Path
    atom_style : {"atomic", "sph", "sphere"}
    units : {"lj", "real", "metal", "si", "cgs", "electron", "micro", "nano"}
        Unit system the file is meant for (written in the header comment).
    dim : {1, 2, 3, None}
        Physical dimension, inferred by :func:`lammps_io.box.infer_dim` if None.
    masses : float, sequence or None
        Mass of each LAMMPS type (``Masses`` section, atomic and sph) or of
        each particle (sphere, through its density).  Default: ``rho * volume``
        when ``rho`` is given, else ``atoms.get_masses()`` (1.0 for "X").
    volume : float, array or None
        Particle volume v0 (area in 2D); default cell measure / N for a
        periodic set, else 1.0.
    rho : float, array or None
        SPH density (sph) — default ``mass / volume``.
    esph, cv : float or array
        SPH internal energy and heat capacity (sph).
    diameter : float, array or None
        Sphere diameter (sphere) — default ``volume ** (1/dim)``.
    margin, thickness : float
        See :func:`lammps_io.box.lammps_box`.
    velocities : array (N, 3) or None
        Written as a ``Velocities`` section (rotated to the LAMMPS frame).

    Returns
    -------
    LammpsBox
        The box and the ASE -> LAMMPS rotation used.

    Raises
    ------
    ValueError
        for unknown styles/units, non-positive masses/volumes, particles
        outside a non-periodic box without ``margin``, several masses in one
        type for atomic/sph (one mass per type in LAMMPS).
    """
    check_units_style(units, atom_style)
    box = lammps_box(atoms, dim=dim, margin=margin, thickness=thickness)
    n = len(atoms)
    t_p = particle_types(atoms)
    ntypes = int(t_p.max())
    if volume is None:
        if all(atoms.pbc[: box.dim]):
            volume = abs(float(np.linalg.det(atoms.cell[: box.dim, : box.dim]))) / n
        else:
            volume = 1.0
    v_p = finite_array("volume", volume, n, positive=True)
    # per-particle masses
    if masses is None:
        if rho is not None:
            m_p = finite_array("rho", rho, n, positive=True) * v_p
        else:
            m_p = atoms.get_masses().astype(float)
            m_p[m_p <= 0] = 1.0
    else:
        m = np.asarray(masses, dtype=float)
        if m.ndim == 0:
            m_p = np.full(n, float(m))
        elif m.shape == (ntypes,):
            m_p = m[t_p - 1]
        elif m.shape == (n,):
            m_p = m
        else:
            raise ValueError(f"masses must be a scalar, one value per type ({ntypes}) or per particle ({n})")
    m_p = finite_array("masses", m_p, n, positive=True)
    lines = [f"LAMMPS data file written by lammps_io (units {units}, atom_style {atom_style}, dim {box.dim})", ""]
    lines += [f"{n} atoms", f"{ntypes} atom types", ""]
    lines += box.header_lines()
    lines.append("")
    if atom_style in ("atomic", "sph"):
        type_mass = np.zeros(ntypes)
        for t in range(1, ntypes + 1):
            sel = m_p[t_p == t]
            if len(sel) == 0:
                type_mass[t - 1] = 1.0
                continue
            if np.ptp(sel) > 1e-12 * abs(sel[0]):
                raise ValueError(
                    f"atom_style {atom_style!r} has one mass per type but type {t} has masses "
                    f"from {sel.min():.6g} to {sel.max():.6g}; use atom_style 'sphere' or one type per mass"
                )
            type_mass[t - 1] = sel[0]
        lines += ["Masses", ""] + [f"{t + 1} {mass:.17g}" for t, mass in enumerate(type_mass)] + [""]
    r_pc = box.r_pc
    xyz = [f"{x:.17g} {y:.17g} {z:.17g}" for x, y, z in r_pc]
    if atom_style == "atomic":
        rows = [f"{i + 1} {t_p[i]} {xyz[i]}" for i in range(n)]
    elif atom_style == "sph":
        rho_p = m_p / v_p if rho is None else finite_array("rho", rho, n, positive=True)
        e_p = finite_array("esph", esph, n)
        cv_p = finite_array("cv", cv, n, positive=True)
        rows = [f"{i + 1} {t_p[i]} {rho_p[i]:.17g} {e_p[i]:.17g} {cv_p[i]:.17g} {xyz[i]}" for i in range(n)]
    else:  # sphere: LAMMPS mass = density * 4/3 pi r^3, also in 2D (checked by reading back)
        d_p = v_p ** (1.0 / box.dim) if diameter is None else finite_array("diameter", diameter, n, positive=True)
        radius = 0.5 * d_p
        shape_volume = 4.0 / 3.0 * math.pi * radius**3
        dens_p = m_p / shape_volume
        rows = [f"{i + 1} {t_p[i]} {d_p[i]:.17g} {dens_p[i]:.17g} {xyz[i]}" for i in range(n)]
    lines += [f"Atoms # {atom_style}", ""] + rows + [""]
    if velocities is not None:
        v_pc = np.asarray(velocities, dtype=float)
        if v_pc.shape != (n, 3):
            raise ValueError(f"velocities must have shape ({n}, 3), got {v_pc.shape}")
        v_pc = v_pc @ box.rot_cc
        if atom_style == "sphere":
            vrows = [f"{i + 1} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g} 0 0 0" for i, v in enumerate(v_pc)]
        else:
            vrows = [f"{i + 1} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g}" for i, v in enumerate(v_pc)]
        lines += ["Velocities", ""] + vrows + [""]
    Path(path).write_text("\n".join(lines))
    return box
