"""Plain numpy + scipy ``cKDTree`` implementation of Fan's total error (reference).

The same formula as :class:`ase_sphrelax.FanCalculator` (Fan Eq. 3.8 energy,
Eq. 3.17 / 4.4 forces), written the way a careful numpy user would:

* ``cKDTree(boxsize=L)`` over the wrapped positions (periodic axes must be
  orthogonal and at least ``2 (h + skin)`` long: minimum image only),
* ``query_pairs(h + skin, output_type="ndarray")`` for each pair once,
* minimum-image displacements, the kernel profile by vectorised Horner on the
  kernel's own piecewise-polynomial coefficients (no kernel formula copied),
* force accumulation with ``np.bincount``,
* an optional Verlet skin: the pair array is reused until a particle moved
  more than ``skin / 2``, so warm evaluations skip the tree, as FanCalculator's
  neighbour list does.

Used by ``benchmarks/bench_fan_forces.py`` (speed) and
``tests/test_reference_implementation.py`` (agreement with FanCalculator).
It is deliberately independent of :mod:`ase_sphrelax.neighbors` and
:mod:`ase_sphrelax.kernel_sums`; only the kernel coefficients and the
one-dimensional boundary profile ``W1`` come from :mod:`ase_sphrelax.kernels`.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ase_sphrelax.kernels import get_kernel

__all__ = ["ReferenceFan", "profile_and_slope"]


def profile_and_slope(q, kernel):
    """Kernel profile f(q) and df/dq for an array ``q`` (zero for q >= 1), vectorised Horner.

    Uses ``kernel.breaks`` / ``kernel.coef`` (powers of ``u = b_{s+1} - q`` per
    segment), the representation of :func:`ase_sphrelax.kernels.profile_value_and_slope`.
    """
    q = np.asarray(q, dtype=float)
    coef = kernel.coef
    if coef.shape[0] == 1:
        u = kernel.breaks[1] - q
        c = coef[0]
        value = np.full(q.shape, c[-1])
        slope = np.zeros(q.shape)
        for k in range(c.shape[0] - 2, -1, -1):
            slope *= u
            slope += value
            value *= u
            value += c[k]
    else:
        seg = np.searchsorted(kernel.breaks, q, side="right") - 1
        seg = np.minimum(seg, coef.shape[0] - 1)
        u = kernel.breaks[seg + 1] - q
        c = coef[seg]
        value = c[:, -1].copy()
        slope = np.zeros(q.shape)
        for k in range(coef.shape[1] - 2, -1, -1):
            slope = slope * u + value
            value = value * u + c[:, k]
    outside = q >= 1.0
    value[outside] = 0.0
    slope[outside] = 0.0
    return value, -slope


class ReferenceFan:
    """Fan's total error E (Eq. 3.8) and forces -dE/dx (Eq. 3.17, 4.4) with numpy + cKDTree.

    Parameters
    ----------
    h : float
        Kernel support radius.
    dx : float or None
        ``v0 = vt = dx**dim``; with None ``v0 = V / N`` (``V`` the domain volume
        or the periodic cell's area/volume).
    domain : Domain or None
        Level-set domain for the boundary term (Eq. 3.8 last term, Eq. 4.4).
    dim : {2, 3}
    kernel : str
    skin : float
        Verlet skin; 0 rebuilds the tree on every call.

    Notes
    -----
    Periodic axes must be the first ``dim`` axes of an orthogonal cell, each
    longer than ``2 (h + skin)``; otherwise ``ValueError``.
    """

    def __init__(self, h, dx=None, domain=None, dim=2, kernel="wendland_c2", skin=0.0):
        if not (np.isfinite(h) and h > 0):
            raise ValueError(f"h must be a positive finite number, got {h!r}")
        if dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {dim!r}")
        if not (np.isfinite(skin) and skin >= 0):
            raise ValueError(f"skin must be a finite number >= 0, got {skin!r}")
        self.h = float(h)
        self.dx = dx
        self.domain = domain
        self.dim = dim
        self.kernel = get_kernel(kernel, dim)
        self.skin = float(skin)
        self.builds = 0
        self._r0 = None
        self._pairs = None
        self._box = None

    # -- geometry ----------------------------------------------------------------
    def _box_of(self, atoms):
        """Periodic box lengths (dim,) or None for an open system."""
        pbc = np.asarray(atoms.pbc[: self.dim], dtype=bool)
        if not pbc.any():
            return None
        if not pbc.all():
            raise ValueError("ReferenceFan supports periodic along all dim axes or none, got pbc "
                             f"{atoms.pbc.tolist()}")
        full = atoms.cell.array
        cell = full[: self.dim, : self.dim]
        if np.any(cell != np.diag(np.diag(cell))) or np.any(full[: self.dim, self.dim:] != 0):
            raise ValueError("ReferenceFan needs an orthogonal cell")
        box = np.diag(cell).copy()
        if np.any(box <= 2.0 * (self.h + self.skin)):
            raise ValueError(f"cell lengths {box} must exceed 2 (h + skin) for the minimum image")
        return box

    def _minimum_image(self, d_pc, box):
        if box is not None:
            d_pc -= box * np.rint(d_pc / box)
        return d_pc

    def pairs(self, r_pc, box):
        """Pair array (P, 2), i < j, within h + skin; rebuilt when a particle moved > skin / 2."""
        if self._pairs is not None and self._r0.shape == r_pc.shape and (
                box is None and self._box is None or box is not None and self._box is not None
                and np.array_equal(box, self._box)):
            d = self._minimum_image(r_pc - self._r0, box)
            if self.skin > 0 and np.einsum("ij,ij->i", d, d).max() <= (0.5 * self.skin) ** 2:
                return self._pairs
            if self.skin == 0 and not d.any():
                return self._pairs
        data = np.mod(r_pc, box) if box is not None else r_pc
        if box is not None:
            data[data >= box] = 0.0  # np.mod may round up to box
        tree = cKDTree(data, boxsize=box, balanced_tree=False, compact_nodes=False)
        self._pairs = tree.query_pairs(self.h + self.skin, output_type="ndarray")
        self._r0 = r_pc.copy()
        self._box = None if box is None else box.copy()
        self.builds += 1
        return self._pairs

    # -- the formula -----------------------------------------------------------------
    def compute(self, atoms):
        """Return (energy, energies_p (N,), forces_pc (N, 3)) for ``atoms``."""
        dim = self.dim
        n = len(atoms)
        r_pc = np.ascontiguousarray(atoms.positions[:, :dim], dtype=float)
        box = self._box_of(atoms)
        if self.domain is not None:
            volume = float(self.domain.volume)
        elif box is not None:
            volume = float(np.prod(box))
        elif self.dx is not None:
            volume = n * self.dx**dim
        else:
            raise ValueError("dx=None needs a domain or a periodic cell")
        v0 = self.dx**dim if self.dx is not None else volume / n

        ij = self.pairs(r_pc, box)
        i, j = ij[:, 0], ij[:, 1]
        d_pc = self._minimum_image(r_pc[j] - r_pc[i], box)
        r_p = np.sqrt(np.einsum("ij,ij->i", d_pc, d_pc))
        inside = r_p < self.h
        if not inside.all():
            i, j, d_pc, r_p = i[inside], j[inside], d_pc[inside], r_p[inside]
        f_p, df_p = profile_and_slope(r_p / self.h, self.kernel)

        norm = self.kernel.sigma / self.h**dim  # W = norm f(r/h)
        scale = 2.0 * v0 * v0 * norm  # sum_{i != j} = 2 sum_pairs
        half_e = 0.5 * scale * f_p
        energies = np.bincount(i, half_e, minlength=n) + np.bincount(j, half_e, minlength=n)
        energies += v0 * v0 * self.kernel.w0(self.h) - volume / n
        # F_i = 2 v0 vt sum_j W'(r) (x_j - x_i) / r  (Eq. 3.17); W' = norm f'/h
        with np.errstate(invalid="ignore", divide="ignore"):
            g_p = np.where(r_p > 0, scale * df_p / (self.h * r_p), 0.0)
        forces = np.zeros((n, 3))
        for c in range(dim):
            gd = g_p * d_pc[:, c]
            forces[:, c] = np.bincount(i, gd, minlength=n) - np.bincount(j, gd, minlength=n)
        if self.domain is not None:
            r3_pc = np.array(atoms.positions, dtype=float)
            r3_pc[:, dim:] = 0.0
            phi_p, n_pc = self.domain.phi_and_normal(r3_pc)
            phi_p = np.asarray(phi_p, dtype=float)
            energies += 2.0 * v0 * self.kernel.w1_tail_integral(-phi_p, self.h)
            forces[:, :dim] -= (2.0 * v0 * self.kernel.w1(np.maximum(-phi_p, 0.0), self.h))[:, None] * \
                np.asarray(n_pc)[:, :dim]
        return float(energies.sum()), energies, forces
