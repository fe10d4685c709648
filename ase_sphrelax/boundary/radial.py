"""Radial antiderivatives of a kernel profile for the boundary integrals (METHOD_NOTES, BIPI section).

Lengths are in units of the support ``h`` (our convention; BIPI's ``h_B`` is ``h / 2``). The
profile ``f(q)`` of :class:`~ase_sphrelax.kernels.Kernel` is a polynomial on each piece
``[b_j, b_{j+1})`` (Wendland C2: one piece), ``f = sum_k c_jk q^k``, and ``W(r) = sigma/h^d f(r/h)``.

Divergence theorem with the radial field ``u g(|u|)`` (``u = y - x_a``): for ``x_a`` not on the
boundary, ``gamma_a = chi_a - sum_s gamma_as`` with ``chi_a`` 1 inside, 0 outside (the fraction
of the angle inside for points on the boundary) and, for an element ``s`` with inward normal
``n_s``, signed distance ``delta h = (x_a - x_s) . n_s``:

* 2D: ``gamma_as = sigma delta int_s G(rho) dtau``, ``G(q) = q^-2 int_q^1 f(t) t dt``;
* 3D: ``gamma_as = sigma delta int_s G3(rho) dA'``, ``G3(q) = q^-3 int_q^1 f(t) t^2 dt``;
* ``grad gamma_as = n_s int_s W dS = n_s sigma / h int_s f(rho) dS'``,

with ``rho = |y - x_a| / h`` and ``dtau``, ``dA'`` in units of ``h``, ``h^2``. On piece ``j``:
``G = A_j q^-2 - sum_k c_jk q^k / (k + 2)`` and ``G3 = A3_j q^-3 - sum_k c_jk q^k / (k + 3)``.
``sigma A_0 = 1 / (2 pi)`` (2D) and ``1 / (4 pi)`` (3D): the leading terms are the subtended
angle over ``2 pi`` and the solid angle over ``4 pi``.

3D integrals run in polar coordinates about the foot of ``x_a`` on the triangle's plane, where
the radial integrals are antiderivatives in ``rho``: ``P1(rho) = int_0^rho f t dt`` (for
``grad gamma``) and ``Q(rho) = -int_rho^1 G3(t) t dt`` (for ``gamma``), both constant beyond
``rho = 1``. ``Q = -A3_0 / rho + Qt`` with ``Qt`` smooth; both ``P1`` and ``Qt`` are stored as
Laurent polynomials per piece: column ``m`` multiplies ``rho^(m - 1)``.
"""
from __future__ import annotations

import numpy as np
from numpy.polynomial import polynomial as P

from ..kernels import get_kernel

__all__ = ["RadialTables"]


def _q_powers(kernel):
    """Pieces of the profile in powers of q: (breaks (nb + 1,) ending at 1, coef (nb, K + 1))."""
    nb = kernel.coef.shape[0]
    breaks = np.minimum(np.asarray(kernel.breaks[: nb + 1], dtype=float), 1.0)
    rows = []
    for j in range(nb):
        # f_j(q) = sum_k coef[j, k] (b - q)^k
        poly = P.Polynomial(kernel.coef[j])(P.Polynomial([breaks[j + 1], -1.0]))
        rows.append(poly.coef)
    width = max(len(r) for r in rows)
    coef = np.zeros((nb, width))
    for j, r in enumerate(rows):
        coef[j, : len(r)] = r
    return breaks, coef


class RadialTables:
    """Coefficient tables of the boundary integrals for one kernel and dimension.

    Attributes
    ----------
    sigma : float
        Normalisation: ``W(r, h) = sigma / h^d f(r / h)``.
    breaks : ndarray (nb + 1,)
        Piece boundaries in ``q``, the last one 1.
    fc : ndarray (nb, K + 1)
        ``f`` on piece j in powers of q.
    a : ndarray (nb,)
        ``A_j`` (2D) or ``A3_j`` (3D), the coefficient of the singular power of ``G``/``G3``.
    gc : ndarray (nb, K + 1)
        2D: ``G`` on piece j is ``a[j] q^-2 + sum_k gc[j, k] q^k``.
    lp, lq : ndarray (nb, K + 4)
        3D: Laurent coefficients (column m for ``rho^(m - 1)``) of ``P1`` and ``Qt`` per piece.
    p1_one : float
        3D: ``P1(1) = int_0^1 f t dt``.
    """

    def __init__(self, kernel="wendland_c2", dim=2):
        kernel = get_kernel(kernel, dim)
        if dim not in (2, 3):
            raise ValueError(f"boundary integrals are for dim 2 or 3, got {dim}")
        self.kernel = kernel
        self.dim = dim
        self.sigma = float(kernel.sigma)
        self.breaks, self.fc = _q_powers(kernel)
        nb, width = self.fc.shape
        powers = np.arange(width)
        w = dim - 1  # weight t^(d - 1)
        # tail_j = int_{b_{j+1}}^1 f t^w dt
        tail = np.zeros(nb)
        for j in range(nb - 2, -1, -1):
            lo, hi = self.breaks[j + 1], self.breaks[j + 2]
            c = self.fc[j + 1]
            tail[j] = tail[j + 1] + np.sum(c * (hi ** (powers + w + 1) - lo ** (powers + w + 1)) / (powers + w + 1))
        b = self.breaks[1:]
        self.a = tail + np.array([np.sum(self.fc[j] * b[j] ** (powers + w + 1) / (powers + w + 1))
                                  for j in range(nb)])
        self.gc = -self.fc / (powers + w + 1)
        if dim == 3:
            self._laurent_3d()

    def _laurent_3d(self):
        nb, width = self.fc.shape
        powers = np.arange(width)
        cols = width + 3  # rho^-1 ... rho^(K + 2)
        lp = np.zeros((nb, cols))
        lq = np.zeros((nb, cols))
        # P1 = const_j + sum_k c_k rho^(k+2) / (k+2); continuous from P1(0) = 0
        p1_left = 0.0
        for j in range(nb):
            lo = self.breaks[j]
            c = self.fc[j]
            lp[j, powers + 3] = c / (powers + 2)
            lp[j, 1] = p1_left - np.sum(c * lo ** (powers + 2) / (powers + 2))
            hi = self.breaks[j + 1]
            p1_left = lp[j, 1] + np.sum(c * hi ** (powers + 2) / (powers + 2))
        self.p1_one = float(p1_left)
        # Q = -a_j / rho - sum_k c_k rho^(k+2) / ((k+2)(k+3)) + K_j, Q(1) = 0, continuous
        a0 = self.a[0]
        q_right = 0.0
        for j in range(nb - 1, -1, -1):
            hi = self.breaks[j + 1]
            c = self.fc[j]
            poly = -c / ((powers + 2) * (powers + 3))
            phi_hi = -self.a[j] / hi + np.sum(poly * hi ** (powers + 2))
            const = q_right - phi_hi
            lq[j, 0] = -self.a[j] + a0  # Qt = Q + a0 / rho
            lq[j, 1] = const
            lq[j, powers + 3] = poly
            lo = self.breaks[j]
            q_right = (-self.a[j] / lo + np.sum(poly * lo ** (powers + 2)) + const) if lo > 0 else np.nan
        self.lp, self.lq = lp, lq

    # -- reference evaluations (tests, docs) -----------------------------------------
    def G(self, q):
        """``G`` (2D) or ``G3`` (3D) at q in (0, 1), zero beyond."""
        q = np.atleast_1d(np.asarray(q, dtype=float))
        out = np.zeros_like(q)
        j_q = np.searchsorted(self.breaks, q, side="right") - 1
        for j in range(len(self.a)):
            m = (j_q == j) & (q < 1.0)
            out[m] = self.a[j] * q[m] ** (-self.dim) + P.polyval(q[m], self.gc[j])
        return out
