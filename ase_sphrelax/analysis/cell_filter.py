"""Variable-cell filter at constant area (2D) or constant volume (3D).

ASE's ``FrechetCellFilter(constant_volume=True)`` removes ``trace / 3`` over
all three axes, so a 2D sheet (z = 0, c = (0, 0, 1)) loses in-plane area.
:class:`ConstantMeasureCellFilter` instead deforms only the first ``dim``
axes by ``F = expm(X)`` with ``X`` symmetric and traceless in the
``dim x dim`` block: ``det F = exp(tr X) = 1`` exactly, so the area (2D) or
volume (3D) is conserved to round-off, while all shape changes (rotations
excepted) are reachable.

Generalised coordinates: the positions ``u_i = F^-1 x_i`` in the reference
cell, then ``cell_factor * c`` where ``c`` are the coordinates of ``X`` in an
orthonormal basis of symmetric traceless matrices (2 in 2D, 5 in 3D), packed
in one (2D) or two (3D) extra rows. The generalised forces are the exact
negative gradient: ``F^T f_i`` for the positions and
``-V sigma : (L(X, B_a) F^-1) / cell_factor`` for the cell, with ``L`` the
Frechet derivative of the matrix exponential (by eigendecomposition, X is symmetric) and ``sigma`` the calculator's
stress (``(1/V) dE/d strain``).
"""
from __future__ import annotations

import numpy as np
from ase.filters import Filter
from ase.stress import voigt_6_to_full_3x3_stress

from ..checks import resolve_dim

__all__ = ["ConstantMeasureCellFilter", "traceless_symmetric_basis", "sym_expm", "sym_expm_frechet"]


def sym_expm(x):
    """Matrix exponential of a symmetric matrix by eigendecomposition."""
    w, q = np.linalg.eigh(x)
    return (q * np.exp(w)) @ q.T


def sym_expm_frechet(x, e):
    """Frechet derivative L(x, e) of expm at a symmetric ``x`` in direction ``e`` (Daleckii-Krein)."""
    w, q = np.linalg.eigh(x)
    dw = w[:, None] - w[None, :]
    ew = np.exp(w)
    small = np.abs(dw) < 1e-12
    safe = np.where(small, 1.0, dw)
    g = np.where(small, ew[:, None], ew[None, :] * np.expm1(dw) / safe)
    return q @ (g * (q.T @ e @ q)) @ q.T


def traceless_symmetric_basis(dim):
    """Orthonormal (Frobenius) basis of symmetric traceless ``dim x dim`` matrices, as 3x3 arrays."""
    basis = []
    if dim == 2:
        basis.append(np.diag([1.0, -1.0, 0.0]) / np.sqrt(2.0))
        off = np.zeros((3, 3))
        off[0, 1] = off[1, 0] = 1.0 / np.sqrt(2.0)
        basis.append(off)
    elif dim == 3:
        basis.append(np.diag([1.0, -1.0, 0.0]) / np.sqrt(2.0))
        basis.append(np.diag([1.0, 1.0, -2.0]) / np.sqrt(6.0))
        for i, j in ((0, 1), (0, 2), (1, 2)):
            off = np.zeros((3, 3))
            off[i, j] = off[j, i] = 1.0 / np.sqrt(2.0)
            basis.append(off)
    else:
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    return basis


class ConstantMeasureCellFilter(Filter):
    """Relax positions and cell shape at constant area (``dim=2``) or volume (``dim=3``).

    Parameters
    ----------
    atoms : ase.Atoms
        With a calculator that gives ``stress``; periodic along the first ``dim`` axes.
    dim : {2, 3} or None
        None: inferred from the atoms (:func:`ase_sphrelax.checks.resolve_dim`).
        2D systems live at z = 0 with c-vector ``(0, 0, c)``; only the in-plane
        block of the cell is deformed.
    cell_factor : float, optional
        Scale of the cell coordinates (default ``len(atoms)``, as ASE's filters).

    Notes
    -----
    ``get_potential_energy`` is the calculator's energy (no ``pV`` term: the
    measure is fixed). Use with any ASE optimiser.
    """

    def __init__(self, atoms, dim=None, cell_factor=None):
        if dim is not None and (dim not in (2, 3) or isinstance(dim, bool)):
            raise ValueError(f"dim must be 2, 3 or None, got {dim!r}")
        dim = resolve_dim(atoms, dim)  # the package's one rule (None: inferred from the atoms)
        if dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got atoms that are {dim}D")
        if not all(atoms.pbc[:dim]):
            raise ValueError(f"atoms must be periodic along the first {dim} axes, got pbc={atoms.pbc}")
        if dim == 2 and (np.any(np.abs(atoms.cell.array[:2, 2]) > 0) or np.any(np.abs(atoms.cell.array[2, :2]) > 0)):
            raise ValueError("a 2D cell must have in-plane a, b (z = 0) and c along z")
        self.atoms = atoms  # Filter.__init__ insists on an index subset; all atoms move here
        self.dim = dim
        self.basis = traceless_symmetric_basis(dim)
        self.n_rows = 1 if dim == 2 else 2
        self.cell_factor = float(len(atoms)) if cell_factor is None else float(cell_factor)
        self.orig_cell = atoms.cell.array.copy()
        self.coords = np.zeros(len(self.basis))
        self._cache = None

    # -- deformation -------------------------------------------------------------
    def _x_matrix(self, coords):
        return sum(c * b for c, b in zip(coords, self.basis))

    def deform_grad(self):
        """Current deformation gradient F (3x3) relative to the reference cell."""
        return sym_expm(self._x_matrix(self.coords))

    def _pack(self, coords):
        rows = np.zeros((self.n_rows, 3))
        rows.flat[: len(coords)] = self.cell_factor * coords
        return rows

    def _unpack(self, rows):
        return np.asarray(rows, dtype=float).ravel()[: len(self.basis)] / self.cell_factor

    # -- Filter interface --------------------------------------------------------------
    def get_positions(self):
        f_inv = np.linalg.inv(self.deform_grad())
        u = self.atoms.get_positions() @ f_inv.T
        return np.vstack([u, self._pack(self.coords)])

    def set_positions(self, new, **kwargs):
        new = np.asarray(new, dtype=float)
        n = len(self.atoms)
        self.coords = self._unpack(new[n:])
        f = self.deform_grad()
        self.atoms.set_cell(self.orig_cell @ f.T, scale_atoms=False)
        self.atoms.set_positions(new[:n] @ f.T, **kwargs)

    def get_potential_energy(self, force_consistent=True):
        return self.atoms.get_potential_energy(force_consistent=force_consistent)

    def get_forces(self, **kwargs):
        key = (self.atoms.positions.tobytes(), self.atoms.cell.array.tobytes())
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1].copy()
        f = self.deform_grad()
        # stress first: a calculator computing forces along with the stress then serves both at once
        stress = voigt_6_to_full_3x3_stress(self.atoms.get_stress(**kwargs))
        forces = self.atoms.get_forces(**kwargs) @ f  # rows: F^T f_i
        volume = self.atoms.get_volume()
        x = self._x_matrix(self.coords)
        f_inv = np.linalg.inv(f)
        grad = np.array([volume * np.sum(stress * (sym_expm_frechet(x, b) @ f_inv))
                         for b in self.basis])
        out = np.vstack([forces, self._pack(-grad / self.cell_factor**2)])
        self._cache = (key, out)
        return out.copy()

    def get_stress(self, *args, **kwargs):
        return self.atoms.get_stress(*args, **kwargs)

    def has(self, x):
        return self.atoms.has(x)

    def __len__(self):
        return len(self.atoms) + self.n_rows
