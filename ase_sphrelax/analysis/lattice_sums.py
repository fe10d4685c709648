"""Lattice sums: characteristic volumes of periodic arrangements (Fan et al. Sec. 5.1, Eq. 5.2).

For a periodic distribution every particle has the same volume
``v_c = 1 / sum_j W(|r_j|, h)`` (the sum over the whole lattice, including
``j = 0``), and the interior error is ``E_P = V vt / v_c`` (Eq. 5.2): the
relaxed pattern is the lattice with the largest ``v_c`` at fixed particle
volume. At unit particle volume (``dx = 1``) ``h`` is Fan's ``h / dx``. The
sums are exact finite sums (the kernel has compact support).
"""
from __future__ import annotations

import numba
import numpy as np

from ..checks import check_dim, check_positive
from ..kernels import get_kernel, profile_value_and_slope

__all__ = ["lattice_kernel_sum", "characteristic_volume_of_cell", "characteristic_volume_of_atoms"]


@numba.njit(cache=True)
def _profile_lattice_sum(cell_vv, h, breaks, coef, m_max):
    """sum over m in the box |m_i| <= m_max[i] of f(|m @ cell| / h) for a one-site lattice (2D or 3D)."""
    dim = cell_vv.shape[0]
    total = 0.0
    inv_h = 1.0 / h
    m2_max = m_max[2] if dim == 3 else 0
    for m0 in range(-m_max[0], m_max[0] + 1):
        for m1 in range(-m_max[1], m_max[1] + 1):
            for m2 in range(-m2_max, m2_max + 1):
                r2 = 0.0
                for c in range(dim):
                    x = m0 * cell_vv[0, c] + m1 * cell_vv[1, c]
                    if dim == 3:
                        x += m2 * cell_vv[2, c]
                    r2 += x * x
                q = np.sqrt(r2) * inv_h
                if q < 1.0:
                    total += profile_value_and_slope(q, breaks, coef)[0]
    return total


def lattice_kernel_sum(cell_vv, h, kernel="wendland_c2", basis_bv=None):
    """Mean over basis sites of ``sum_j W(|r_j - r_i|, h)`` over the whole crystal (j = i included).

    Parameters
    ----------
    cell_vv : (d, d) array_like
        Lattice vectors as rows, ``d`` = 2 or 3, in the units of ``h``.
    h : float
        Kernel support radius.
    kernel : str or Kernel
    basis_bv : (b, d) array_like, optional
        Cartesian positions of the sites in the cell (default: one site at 0).

    Returns
    -------
    float
        ``mean_i sum_j W_ij``; ``1 / (v sum)`` is Fan's ``v_c`` (Eq. 5.2) when the
        cell holds ``b`` particles of volume ``v = |det cell| / b``.
    """
    cell_vv = np.asarray(cell_vv, dtype=float)
    dim = cell_vv.shape[0]
    if cell_vv.shape != (dim, dim) or dim not in (2, 3):
        raise ValueError(f"cell_vv must be a (2, 2) or (3, 3) array, got shape {cell_vv.shape}")
    kern = get_kernel(kernel, dim)
    inv_vv = np.linalg.inv(cell_vv)
    if basis_bv is None:
        m_max = np.ceil(h * np.linalg.norm(inv_vv, axis=0)).astype(np.int64) + 1
        m_max = np.concatenate([m_max, np.zeros(3 - dim, dtype=np.int64)])
        total = _profile_lattice_sum(cell_vv, float(h), kern.breaks, kern.coef, m_max)
        return float(kern.sigma / h**dim * total)
    basis_bv = np.asarray(basis_bv, dtype=float).reshape(-1, dim)
    # integer coefficients of r = m @ cell: |m_i| <= (h + basis extent) * |column i of inv|
    extent = h + 2.0 * np.max(np.linalg.norm(basis_bv - basis_bv[0], axis=1)) if len(basis_bv) > 1 else h
    m_max = np.ceil(extent * np.linalg.norm(inv_vv, axis=0)).astype(int) + 1
    axes = [np.arange(-m, m + 1) for m in m_max]
    m_tv = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    t_tv = m_tv @ cell_vv
    d_bbv = basis_bv[None, :, :] - basis_bv[:, None, :]  # r_j - r_i
    r = np.linalg.norm(t_tv[:, None, None, :] + d_bbv[None], axis=-1)
    return float(kern.w(r, h).sum() / len(basis_bv))


def characteristic_volume_of_cell(cell_vv, h_over_dx, kernel="wendland_c2", basis_bv=None):
    """``v_c`` of a periodic arrangement rescaled to unit particle volume (Eq. 5.2).

    The cell (rows) and basis are scaled so that ``|det cell| / n_basis = 1``;
    ``v_c = 1 / mean_i sum_j W(|r_ij|, h)``.
    """
    h = check_positive("h_over_dx", h_over_dx)
    cell_vv = np.asarray(cell_vv, dtype=float)
    dim = cell_vv.shape[0]
    nb = 1 if basis_bv is None else len(np.asarray(basis_bv).reshape(-1, dim))
    vol = abs(np.linalg.det(cell_vv)) / nb
    if not vol > 0:
        raise ValueError("cell_vv is singular")
    scale = vol ** (-1.0 / dim)
    basis = None if basis_bv is None else np.asarray(basis_bv, dtype=float) * scale
    return 1.0 / lattice_kernel_sum(cell_vv * scale, h, kernel, basis)


def characteristic_volume_of_atoms(atoms, h_over_dx, dim=None, kernel="wendland_c2"):
    """``v_c = 1 / mean_i sum_j W(|r_ij|, h)`` of a periodic ``Atoms`` at unit particle volume.

    ``h_over_dx`` is in units of ``dx = (V / N)**(1/d)``; 2D atoms use the
    first two cell vectors and coordinates (Fan Eq. 5.1-5.2: ``E_P = V vt / v_c``).
    """
    dim = check_dim(dim if dim is not None else (2 if not atoms.pbc[2] else 3), allowed=(2, 3))
    if not all(atoms.pbc[:dim]):
        raise ValueError(f"atoms must be periodic along the first {dim} axes, got pbc={atoms.pbc}")
    cell = atoms.cell.array[:dim, :dim]
    pos = atoms.positions[:, :dim] - atoms.positions[0, :dim]
    return characteristic_volume_of_cell(cell, h_over_dx, kernel, pos)

