"""ASE cell -> LAMMPS simulation box (orthogonal or lower-triangular prism).

LAMMPS wants the box as ``xlo xhi ylo yhi zlo zhi`` plus tilts ``xy xz yz``
(a lower-triangular cell, rows a = (lx, 0, 0), b = (xy, ly, 0), c = (xz, yz, lz)).
An ASE cell is rotated into that form with :class:`ase.calculators.lammps.Prism`
(a QR decomposition); positions, forces and stresses are rotated with the same
matrix.

Dimensions
----------
* 3D: LAMMPS ``dimension 3``; periodic where ``atoms.pbc``.
* 2D (atoms at z = 0): ``dimension 2``; LAMMPS needs z periodic, so the box
  gets a thin z slab ``-thickness/2 .. thickness/2``; xz = yz = 0.
* 1D (atoms on the x axis): LAMMPS has no 1D mode; a pair potential only sees
  distances, so the line is put in a ``dimension 3`` box with thin fixed
  (non-periodic) y and z slabs.

Non-periodic directions need room around the particles: either ``margin``
(box = particle bounds +- margin) or a cell vector that contains every
particle strictly inside; otherwise :class:`ValueError` is raised before
LAMMPS is started.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from ase.calculators.lammps import Prism

from ase_sphrelax.checks import resolve_dim

__all__ = ["LammpsBox", "lammps_box", "infer_dim"]

_TOL = 1e-10


def infer_dim(atoms) -> int:
    """Dimension of a particle set by the package's one rule, :func:`ase_sphrelax.checks.resolve_dim`.

    3 if z is periodic or varies; 2 if every z = 0 (not periodic in z) and y is used (periodic
    or non-zero); 1 if every particle lies on the x axis. Every z equal but not 0 is ambiguous:
    a ValueError names the remedies.
    """
    return resolve_dim(atoms)


@dataclass
class LammpsBox:
    """A LAMMPS box and the ASE <-> LAMMPS mapping of one particle set.

    Attributes
    ----------
    dim : int
        Physical dimension (1, 2 or 3).
    lammps_dimension : int
        Value for the LAMMPS ``dimension`` command (2 or 3).
    lo_c, hi_c : ndarray (3,)
        Box bounds.
    tilt_t : ndarray (3,)
        ``xy xz yz`` (zeros for an orthogonal box).
    boundary : str
        Three LAMMPS boundary letters (``p`` or ``f``) joined by spaces.
    r_pc : ndarray (N, 3)
        Positions in the LAMMPS frame.
    rot_cc : ndarray (3, 3)
        ``r_lammps = r_ase @ rot_cc`` (identity for orthogonal boxes).
    pbc : ndarray (3,) of bool
        Periodicity in LAMMPS.
    """

    dim: int
    lammps_dimension: int
    lo_c: np.ndarray
    hi_c: np.ndarray
    tilt_t: np.ndarray
    boundary: str
    r_pc: np.ndarray
    rot_cc: np.ndarray
    pbc: np.ndarray

    @property
    def triclinic(self) -> bool:
        return bool(np.any(self.tilt_t != 0.0))

    @property
    def lammps_volume(self) -> float:
        """Box area (2D) or volume (3D) as LAMMPS measures it."""
        lengths = self.hi_c - self.lo_c
        return float(np.prod(lengths[: self.lammps_dimension]))

    def to_ase(self, v_pc):
        """Rotate vectors from the LAMMPS frame back to the ASE frame."""
        if np.array_equal(self.rot_cc, np.eye(3)):
            return np.array(v_pc, dtype=float)
        return np.asarray(v_pc) @ np.ascontiguousarray(self.rot_cc.T)

    def tensor_to_ase(self, t_cc):
        """Rotate a 3x3 tensor from the LAMMPS frame back to the ASE frame."""
        return self.rot_cc @ t_cc @ self.rot_cc.T

    def region_command(self, region_id="box"):
        """``region`` command describing this box."""
        bounds = " ".join(f"{lo:.17g} {hi:.17g}" for lo, hi in zip(self.lo_c, self.hi_c))
        if self.triclinic:
            tilts = " ".join(f"{t:.17g}" for t in self.tilt_t)
            return f"region {region_id} prism {bounds} {tilts} units box"
        return f"region {region_id} block {bounds} units box"

    def read_data_commands(self, data_name, atom_style, boundary, units="lj"):
        """The input lines that set up a run from the data file ``data_name`` written for this box.

        ``units``, ``dimension``, ``boundary`` (a LAMMPS boundary string such as ``"p p p"``),
        ``atom_style``, ``atom_modify map array`` (the scatter/gather calls need the map) and ``read_data``.
        """
        return [f"units {units}", f"dimension {self.lammps_dimension}", f"boundary {boundary}",
                f"atom_style {atom_style}", "atom_modify map array", f"read_data {data_name}"]

    def header_lines(self):
        """Box lines of a LAMMPS data file."""
        lines = [f"{lo:.17g} {hi:.17g} {a}lo {a}hi" for lo, hi, a in zip(self.lo_c, self.hi_c, "xyz")]
        if self.triclinic:
            lines.append(" ".join(f"{t:.17g}" for t in self.tilt_t) + " xy xz yz")
        return lines


def _check_dim_arg(dim, atoms):
    if dim is not None and (isinstance(dim, (bool, np.bool_)) or not isinstance(dim, (int, np.integer))
                            or dim not in (1, 2, 3)):
        raise ValueError(f"dim must be 1, 2, 3 or None (infer from atoms), got {dim!r}")
    return resolve_dim(atoms, dim)


def lammps_box(atoms, dim=None, margin=None, thickness=1.0, wrap=True) -> LammpsBox:
    """Map ``atoms`` to a LAMMPS box.

    Parameters
    ----------
    atoms : ase.Atoms
    dim : {1, 2, 3, None}
        Physical dimension; ``None`` infers it with :func:`infer_dim`.
    margin : float or None
        Non-periodic directions: box = particle bounds -/+ margin.  With
        ``None`` the cell must contain every particle strictly inside.
    thickness : float
        Extent of the unused directions (z in 2D; y and z in 1D).
    wrap : bool
        Wrap positions into the periodic box.

    Raises
    ------
    ValueError
        for an empty system, particles off the line/plane of a 1D/2D system,
        a skewed cell with non-periodic directions, a tilted z axis in 2D, or
        particles on or outside a non-periodic box without ``margin``.
    """
    if len(atoms) == 0:
        raise ValueError("atoms must contain at least one particle")
    dim = _check_dim_arg(dim, atoms)
    if margin is not None and (not np.isscalar(margin) or not margin >= 0):
        raise ValueError(f"margin must be a non-negative float or None, got {margin!r}")
    if not (np.isscalar(thickness) and thickness > 0):
        raise ValueError(f"thickness must be a positive float, got {thickness!r}")
    r_pc = np.array(atoms.positions, dtype=float)
    cell = np.array(atoms.cell[:], dtype=float)
    pbc = np.array(atoms.pbc, bool)
    if not np.all(np.isfinite(r_pc)):
        raise ValueError("atoms.positions contain NaN or inf")
    unused = list(range(dim, 3))
    for k in unused:
        if np.any(np.abs(r_pc[:, k]) > _TOL * max(1.0, np.abs(r_pc).max())):
            raise ValueError(f"a {dim}D system needs all particles at {'xyz'[k]} = 0 (ASE convention)")
        r_pc[:, k] = 0.0
        if pbc[k]:
            raise ValueError(f"a {dim}D system cannot be periodic along {'xyz'[k]} (atoms.pbc={atoms.pbc.tolist()})")
    active = list(range(dim))
    lammps_dimension = 2 if dim == 2 else 3
    lo_c = np.zeros(3)
    hi_c = np.zeros(3)
    tilt_t = np.zeros(3)
    rot_cc = np.eye(3)
    lmp_pbc = pbc.copy()
    for k in active:
        if pbc[k] and np.linalg.norm(cell[k]) == 0:
            raise ValueError(f"atoms.pbc[{k}] is True but cell vector {k} is zero")
    offdiag = cell[np.ix_(active, active)] - np.diag(np.diag(cell)[active])
    cross = cell[np.ix_(active, unused)] if unused else np.zeros((0, 0))
    skewed = np.any(np.abs(offdiag) > _TOL * max(1.0, np.abs(cell).max())) or np.any(
        np.abs(cross) > _TOL * max(1.0, np.abs(cell).max())
    )
    if all(pbc[k] for k in active) and skewed:
        # rotate the active block into lower-triangular form
        if dim == 1:
            raise ValueError("a 1D periodic cell vector must point along x")
        full = cell.copy()
        if dim == 2:
            if np.any(np.abs(cell[:2, 2]) > _TOL * np.abs(cell).max()):
                raise ValueError("a 2D periodic cell must have in-plane a and b vectors (zero z components)")
            full[2] = (0.0, 0.0, 1.0)
        prism = Prism(full, pbc=(True,) * 3, reduce_cell=False)
        rot_cc = prism.rot_mat
        tri = prism.lammps_tilt
        lx, ly, lz, xy, xz, yz = prism.get_lammps_prism()
        hi_c[:dim] = [lx, ly, lz][:dim]
        tilt_t[:] = [xy, xz, yz]
        if dim == 2:
            tilt_t[1:] = 0.0
        r_pc = r_pc @ rot_cc
        for k in unused:
            r_pc[:, k] = 0.0
        if wrap:
            frac = np.linalg.solve(tri[:dim, :dim].T, r_pc[:, :dim].T).T
            frac -= np.floor(frac)
            frac[frac >= 1.0] = 0.0
            r_pc[:, :dim] = frac @ tri[:dim, :dim]
    else:
        if skewed:
            raise ValueError(
                "a skewed (triclinic) cell is only supported when every direction is periodic; "
                f"atoms.pbc={atoms.pbc.tolist()}"
            )
        for k in active:
            if pbc[k]:
                hi_c[k] = cell[k, k]
                if hi_c[k] < 0:
                    raise ValueError(f"cell vector {k} points in the negative {'xyz'[k]} direction")
                if wrap:
                    r_pc[:, k] = np.mod(r_pc[:, k], hi_c[k])
                    r_pc[r_pc[:, k] >= hi_c[k], k] = 0.0
            elif margin is not None:
                lo_c[k] = r_pc[:, k].min() - margin
                hi_c[k] = r_pc[:, k].max() + margin
                if hi_c[k] <= lo_c[k]:
                    pad = 0.5 * thickness
                    lo_c[k] -= pad
                    hi_c[k] += pad
            else:
                hi_c[k] = cell[k, k]
                x = r_pc[:, k]
                if hi_c[k] <= 0 or x.min() <= 0.0 or x.max() >= hi_c[k]:
                    raise ValueError(
                        f"non-periodic direction {'xyz'[k]}: particles span [{x.min():.6g}, {x.max():.6g}] "
                        f"but the cell gives [0, {hi_c[k]:.6g}]; particles must lie strictly inside a "
                        "non-periodic box: pass margin=... (box = particle bounds +- margin) or enlarge the cell"
                    )
    for k in unused:
        lo_c[k] = -0.5 * thickness
        hi_c[k] = 0.5 * thickness
        lmp_pbc[k] = dim == 2  # LAMMPS 2D needs periodic z
    boundary = " ".join("p" if p else "f" for p in lmp_pbc)
    return LammpsBox(dim, lammps_dimension, lo_c, hi_c, tilt_t, boundary, r_pc, rot_cc, lmp_pbc)
