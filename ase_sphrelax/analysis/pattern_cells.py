"""Unit cells of the lattice patterns (Fan et al. Sec. 5.1, Fig. 7-8, Eq. B.1).

Every cell is scaled to unit area (2D) or volume (3D) per particle. The
parameter ranges searched for each family, and the two conventions, are in
:mod:`ase_sphrelax.analysis.pattern_prediction`.

2D patterns
-----------
* ``"hexagonal"``, ``"square"``: unique lattices, no parameters.
* ``"rectangular"`` (Eq. B.1): ``a1 = (a, 0)``, ``a2 = (0, k a)``, ``k a**2 = 1``.
* ``"diamond"`` (centred rectangular, Fig. 7 right): conventional rectangle
  ``A x k A`` with a particle at its centre, ``k A**2 / 2 = 1``; primitive
  vectors ``(A, 0)``, ``(A/2, k A/2)``.
* ``"parallelogram"`` (oblique, Fig. 8): base ``s`` along x, height ``H``,
  ``k = H / s``, slant ``r`` = offset / height, ``a1 = (s, 0)``,
  ``a2 = (r H, H)``, ``s H = 1``.

3D patterns
-----------
``"sc"``, ``"bcc"``, ``"fcc"``, ``"hcp"`` (ideal ``c/a = sqrt(8/3)``) and
``"general"`` (any one-atom cell, given as ``params["cell"]``).
"""
from __future__ import annotations

import math

import numpy as np

from ..checks import check_dim

__all__ = ["PATTERNS_2D", "PATTERNS_3D", "pattern_cell"]

PATTERNS_2D = ("hexagonal", "square", "rectangular", "diamond", "parallelogram")
PATTERNS_3D = ("sc", "bcc", "fcc", "hcp", "general")

_SQRT3 = math.sqrt(3.0)


def _check_pattern(pattern, dim):
    names = PATTERNS_2D if dim == 2 else PATTERNS_3D
    if pattern not in names:
        raise ValueError(f"pattern must be one of {names} for dim={dim}, got {pattern!r}")
    return pattern



def _cell_2d(pattern, params):
    """Unit-area primitive cell (rows) of a 2D pattern with the documented parameters."""
    if pattern == "hexagonal":
        s = math.sqrt(2.0 / _SQRT3)
        return np.array([[s, 0.0], [0.5 * s, 0.5 * _SQRT3 * s]])
    if pattern == "square":
        return np.eye(2)
    k = float(params["k"])
    if pattern == "rectangular":
        a = 1.0 / math.sqrt(k)
        return np.array([[a, 0.0], [0.0, k * a]])
    if pattern == "diamond":
        a = math.sqrt(2.0 / k)
        return np.array([[a, 0.0], [0.5 * a, 0.5 * k * a]])
    if pattern == "parallelogram":
        s, height = 1.0 / math.sqrt(k), math.sqrt(k)
        return np.array([[s, 0.0], [params["r"] * height, height]])
    raise ValueError(f"unknown pattern {pattern!r}")


_HCP_C_OVER_A = math.sqrt(8.0 / 3.0)


def _cell_3d(pattern, params=None):
    """(cell rows, basis) of a 3D pattern, any scale."""
    if pattern == "sc":
        return np.eye(3), None
    if pattern == "bcc":
        return 0.5 * np.array([[-1.0, 1, 1], [1, -1, 1], [1, 1, -1]]), None
    if pattern == "fcc":
        return 0.5 * np.array([[0.0, 1, 1], [1, 0, 1], [1, 1, 0]]), None
    if pattern == "hcp":
        c = params.get("c_over_a", _HCP_C_OVER_A) if params else _HCP_C_OVER_A
        cell = np.array([[1.0, 0, 0], [-0.5, 0.5 * _SQRT3, 0], [0, 0, c]])
        basis = np.array([[0.0, 0, 0], [1.0 / 3.0, 2.0 / 3.0, 0.5]]) @ cell
        return cell, basis
    if pattern == "general":
        return np.asarray(params["cell"], dtype=float), None
    raise ValueError(f"unknown pattern {pattern!r}")


def pattern_cell(pattern, params=None, dim=2):
    """Primitive cell (rows, unit volume per particle) and basis of a pattern.

    Parameters
    ----------
    pattern : str
        One of :data:`PATTERNS_2D` or :data:`PATTERNS_3D`.
    params : dict, optional
        The parameters returned by :func:`characteristic_volume` (``k`` and
        ``r`` in 2D, ``cell`` for the 3D ``"general"`` lattice).

    Returns
    -------
    cell_vv : (d, d) ndarray
    basis_bv : (b, d) ndarray
    """
    dim = check_dim(dim, allowed=(2, 3))
    _check_pattern(pattern, dim)
    if dim == 2:
        cell, basis = _cell_2d(pattern, params or {}), np.zeros((1, 2))
    else:
        cell, basis = _cell_3d(pattern, params)
        basis = np.zeros((1, 3)) if basis is None else basis
    scale = (abs(np.linalg.det(cell)) / len(basis)) ** (-1.0 / dim)
    return cell * scale, basis * scale

