"""The per-particle arrays every export writes, collected once from an ASE ``Atoms``.

What is read (``sphrelax relax``, ``pack`` and ``density`` write these):

=====================  =====================================================================
``positions``          ``atoms.positions`` (N, 3); 2D at z = 0, 1D on the x axis
``velocities``         momenta / the particles' own masses (zeros without momenta)
``masses``             ``rho0 dx^dim`` for every particle when ``dx`` is given; else
                       ``atoms.arrays["masses"]`` (ALARIC: per particle); else ``rho0 dx^dim``
                       with ``atoms.info["dx"]`` (Fan, BIPI); else none (the box codes refuse),
                       never ASE's default mass of the chemical element
``support``            the kernel **support** radius ``H`` (the package's ``h``):
                       ``atoms.arrays["h"]`` (ALARIC) or ``atoms.info["h"]`` (Fan, BIPI)
``densities``          ``rho0`` where the masses are ``rho0 dx^dim``, else ``atoms.arrays["rho"]``
``internal_energy``    ``atoms.arrays["internal_energy"]``, else the isothermal
                       ``u = c_s^2 / (gamma - 1)`` (ALARIC Eq. 30)
``types``              ``atoms.arrays["type"]`` (1 fluid, 2 wall, ...); default all 1
=====================  =====================================================================

Bad input (NaN or inf, arrays of the wrong shape, non-positive masses or support, a dimension
that disagrees with the geometry) raises a one-line ``ValueError`` before any file is written.

Frame for the box codes (:func:`box_frame`)
--------------------------------------------
SWIFT and GADGET want coordinates in ``[0, L)`` along every axis. The rule:

* ``atoms.info["origin"]`` (``sphrelax density`` runs its 1D target on ``[-1, 1)`` and writes the
  particles in that frame with the cell ``[0, 2)`` and ``origin = [-1]``): the particles are first
  shifted by ``-origin`` back into the cell's frame; the shift is recorded in the file.
* periodic axes: box side = the cell's diagonal entry (a skewed periodic cell is refused);
  positions are wrapped into ``[0, L)`` (the same periodic set).
* bounded axes: the cell is used when it holds every particle strictly inside ``(0, L)``;
  otherwise the box is the particles' bounding box plus ``margin`` on each side (default: the
  largest support radius, else 5% of the extent, else 1) and the particles are shifted by its
  lower corner (recorded in the file, like the origin).
* unused axes (y, z in 1D; z in 2D): coordinates 0, box side ``thickness`` (default 1), as in
  SWIFT's own 1D/2D examples (``BoxSize = [L, 1, 1]`` / ``[Lx, Ly, 1]``, z = 0).
"""
from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..checks import finite_array, resolve_dim

__all__ = ["ParticleArrays", "collect", "box_frame", "BoxFrame", "DEFAULT_GAMMA", "written_atomically", "single_fluid",
           "require", "all_or_none_periodic"]

#: adiabatic index of the isothermal internal energy u = c_s^2 / (gamma - 1) (SWIFT's default 5/3)
DEFAULT_GAMMA = 5.0 / 3.0


@dataclass
class ParticleArrays:
    """Per-particle arrays in the atoms' own frame (N particles, shapes in the names)."""

    dim: int
    r_pc: np.ndarray
    v_pc: np.ndarray
    m_p: np.ndarray | None
    support_p: np.ndarray | None
    rho_p: np.ndarray | None
    u_p: np.ndarray | None
    type_p: np.ndarray
    cell_cc: np.ndarray
    pbc_c: np.ndarray
    origin_c: np.ndarray

    def __len__(self):
        return len(self.r_pc)


@dataclass
class BoxFrame:
    """Positions in ``[0, L)`` for the box codes, and how they were obtained.

    ``r_pc = wrap(atoms positions - shift_c)``; ``box_c`` the box sides (unused axes: thickness).
    """

    r_pc: np.ndarray
    box_c: np.ndarray
    shift_c: np.ndarray


def _per_particle(atoms, key, override, n, name, positive=False):
    if override is not None:
        return finite_array(name, override, n, positive=positive)
    if key in atoms.arrays:
        return finite_array(f"atoms.arrays[{key!r}]", atoms.arrays[key], n, positive=positive)
    return None


def collect(atoms, dim=None, *, masses=None, dx=None, rho0=None, support=None, internal_energy=None,
            cs2=None, gamma=DEFAULT_GAMMA):
    """Collect the arrays of ``atoms`` for an export (see the module docstring for the sources).

    Parameters
    ----------
    atoms : ase.Atoms
    dim : {1, 2, 3, None}
        None: :func:`ase_sphrelax.checks.resolve_dim` (the package's one rule).
    masses : float, (N,) array or None
        Overrides ``atoms.arrays["masses"]``.
    dx, rho0 : float or None
        Masses ``rho0 dx^dim`` and densities ``rho0`` (``rho0`` defaults to 1): with ``dx`` given,
        for every particle (as ``sphrelax export --dx`` does for LAMMPS); without it, for particles
        without masses, from ``atoms.info["dx"]``. Velocities always use the particles' own masses.
    support : float, (N,) array or None
        Kernel support radius ``H``; overrides ``atoms.arrays["h"]`` / ``atoms.info["h"]``.
    internal_energy : float, (N,) array or None
        Specific internal energy; overrides ``atoms.arrays["internal_energy"]`` and ``cs2``.
    cs2 : float or None
        Isothermal sound speed squared: ``u = cs2 / (gamma - 1)``. Default ``atoms.info["cs2"]``;
        with neither (nor an internal energy) ``u_p`` is None.
    gamma : float
        Adiabatic index (> 1) of that relation.

    Returns
    -------
    ParticleArrays
        Missing quantities are None (the writers that need them refuse).
    """
    n = len(atoms)
    if n == 0:
        raise ValueError("atoms: need at least one particle, got an empty Atoms")
    r_pc = finite_array("atoms.positions", atoms.positions, n, (3,))
    dim = resolve_dim(atoms, dim)
    cell_cc = finite_array("atoms.cell", atoms.cell.array, 3, (3,))
    pbc_c = np.array(atoms.pbc, dtype=bool)
    if not (np.isscalar(gamma) and np.isfinite(gamma) and gamma > 1):
        raise ValueError(f"gamma must be a finite number > 1 (adiabatic index), got {gamma!r}")
    own_m_p = _per_particle(atoms, "masses", None, n, "masses", positive=True)
    rho_p = _per_particle(atoms, "rho", None, n, "densities", positive=True)
    m_p = finite_array("masses", masses, n, positive=True) if masses is not None else None
    if m_p is None and (dx is not None or own_m_p is None):
        dx = atoms.info.get("dx") if dx is None else dx  # an explicit dx wins over the particles' masses
        if dx is not None:
            dx = finite_array("dx", dx, 1, positive=True)[0]
            rho = finite_array("rho0", 1.0 if rho0 is None else rho0, 1, positive=True)[0]
            m_p = np.full(n, rho * dx**dim)
            rho_p = np.full(n, rho)
    if m_p is None:
        m_p = own_m_p
    v_pc = np.zeros((n, 3))
    if atoms.has("momenta"):
        p_pc = finite_array("atoms momenta", atoms.get_momenta(), n, (3,))
        if np.any(p_pc):
            if own_m_p is None:
                raise ValueError("atoms carry momenta but no masses (atoms.arrays['masses']): their velocities "
                                 "are unknown")
            v_pc = p_pc / own_m_p[:, None]
    if np.any(v_pc[:, dim:]):
        raise ValueError(f"{dim}D particles move along {'y or z' if dim == 1 else 'z'}: velocities of a {dim}D "
                         f"set must be 0 along the unused axes (a {dim}D set with 3D motion is a dimension mismatch)")
    support_p = _per_particle(atoms, "h", support, n, "support radius h", positive=True)
    if support_p is None and atoms.info.get("h") is not None:
        support_p = finite_array("atoms.info['h']", atoms.info["h"], n, positive=True)
    u_p = _per_particle(atoms, "internal_energy", internal_energy, n, "internal energy")
    if u_p is None:
        cs2 = atoms.info.get("cs2") if cs2 is None else cs2
        if cs2 is not None:
            u_p = np.full(n, finite_array("cs2", cs2, 1, positive=True)[0] / (gamma - 1.0))
    if "type" in atoms.arrays:
        type_p = np.asarray(atoms.arrays["type"])
        if type_p.shape != (n,) or type_p.dtype.kind not in "iu" or type_p.min() < 1:
            raise ValueError("atoms.arrays['type'] must hold one integer >= 1 per particle (1 fluid, 2 wall, ...)")
        type_p = type_p.astype(int)
    else:
        type_p = np.ones(n, dtype=int)
    origin_c = np.zeros(3)
    if atoms.info.get("origin") is not None:
        origin = finite_array("atoms.info['origin']", np.ravel(atoms.info["origin"]), len(np.ravel(atoms.info["origin"])))
        if len(origin) not in (dim, 3):
            raise ValueError(f"atoms.info['origin'] must have {dim} (or 3) entries, got {len(origin)}")
        origin_c[: len(origin)] = origin
    return ParticleArrays(dim, r_pc, v_pc, m_p, support_p, rho_p, u_p, type_p, cell_cc, pbc_c, origin_c)


def box_frame(particles, margin=None, thickness=1.0):
    """Positions in ``[0, L)`` and the box (the rule of the module docstring).

    Raises
    ------
    ValueError
        For a skewed cell along a periodic axis, a periodic axis with a zero cell vector, or a
        non-positive ``margin``/``thickness``.
    """
    if margin is not None and not (np.isscalar(margin) and np.isfinite(margin) and margin > 0):
        raise ValueError(f"margin must be a positive number or None, got {margin!r}")
    if not (np.isscalar(thickness) and np.isfinite(thickness) and thickness > 0):
        raise ValueError(f"thickness must be a positive number, got {thickness!r}")
    dim, cell_cc = particles.dim, particles.cell_cc
    r_pc = particles.r_pc - particles.origin_c
    shift_c = particles.origin_c.copy()
    box_c = np.full(3, float(thickness))
    for k in range(dim):
        x_p = r_pc[:, k]
        if particles.pbc_c[k]:
            off_diagonal = np.delete(cell_cc[k], k)
            side = cell_cc[k, k]
            if side <= 0 or np.any(np.abs(off_diagonal) > 1e-12 * side):
                raise ValueError(f"periodic axis {'xyz'[k]}: the box codes need an orthogonal cell with a positive "
                                 f"side, got cell vector {k} = {cell_cc[k].tolist()}")
            box_c[k] = side
            r_pc[:, k] = np.mod(x_p, side)
            r_pc[r_pc[:, k] >= side, k] = 0.0  # mod of -tiny gives side exactly
            continue
        side = float(np.linalg.norm(cell_cc[k]))
        if side > 0 and cell_cc[k, k] == side and x_p.min() > 0 and x_p.max() < side:
            box_c[k] = side
            continue
        extent = float(np.ptp(x_p))
        pad = margin
        if pad is None:
            pad = float(particles.support_p.max()) if particles.support_p is not None else 0.05 * extent
            pad = pad if pad > 0 else 1.0
        lo = float(x_p.min()) - pad
        r_pc[:, k] = x_p - lo
        shift_c[k] += lo
        box_c[k] = extent + 2.0 * pad
    r_pc[:, dim:] = 0.0
    return BoxFrame(r_pc, box_c, shift_c)


@contextmanager
def written_atomically(path):
    """Yield a temporary path next to ``path``; move it to ``path`` only when the block succeeds.

    A writer that fails half way (a library error, a full disk) leaves no file behind.
    """
    path = Path(path)
    partial = path.with_name(path.name + ".partial")
    try:
        yield partial
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)


def single_fluid(particles, code):
    """Refuse particle types other than 1 (fluid) for ``code``, which stores one gas type."""
    kinds = np.unique(particles.type_p)
    if kinds.tolist() != [1]:
        raise ValueError(f"{code} export writes fluid particles (type 1) only, but atoms.arrays['type'] holds types "
                         f"{kinds.tolist()}: export the fluid with atoms[atoms.arrays['type'] == 1], or use vtu")


def require(particles, code, **needed):
    """One-line error naming what ``code`` needs and how to give it, for each None in ``needed``."""
    remedies = dict(
        m_p="masses: atoms.arrays['masses'] (sphrelax density writes them), or dx (atoms.info['dx']) and rho0 "
            "(mass = rho0 dx^dim; --dx/--rho0)",
        support_p="smoothing lengths: atoms.arrays['h'] or atoms.info['h'] (the kernel support radius), or --h",
        u_p="internal energies: atoms.arrays['internal_energy'], --internal-energy U, or --cs2 (isothermal "
            "u = cs2/(gamma-1))",
    )
    for name in needed:
        if getattr(particles, name) is None:
            raise ValueError(f"{code} needs {remedies[name]}")


def all_or_none_periodic(particles, code):
    """True when every used axis is periodic, False when none is; the box codes know no mixture."""
    used_c = particles.pbc_c[: particles.dim]
    if used_c.all():
        return True
    if not used_c.any():
        return False
    raise ValueError(f"{code} is periodic along every axis or none, but atoms.pbc = {particles.pbc_c.tolist()} in "
                     f"{particles.dim}D: make the cell periodic along every used axis, or along none")
