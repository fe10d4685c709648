"""Level set tabulated on a Cartesian background mesh (Fan Sec. 2).

``phi`` is sampled exactly at the nodes of a grid of spacing ``dx`` that
covers the domain bounds plus ``margin`` cells, and interpolated with the
tensor-product Catmull-Rom cubic (bicubic in 2D, tricubic in 3D).  The
interpolant is C1, so the normal ``grad phi`` is continuous, and the normal
returned is the exact gradient of the interpolated ``phi``.  Catmull-Rom
reproduces quadratics, so the error is O(dx^3) where ``phi`` is smooth
(O(dx) within a cell of a kink).  Outside the grid,
``phi(r) = phi(c(r)) + |r - c(r)|`` with ``c`` the clamp onto the grid, which
is continuous and whose gradient is again exact.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from ..checks import check_positive


@numba.njit(cache=True, inline="always")
def _cr_weights(t, w, dw):
    """Catmull-Rom weights for nodes -1, 0, 1, 2 and their d/dt."""
    t2 = t * t
    t3 = t2 * t
    w[0] = 0.5 * (-t3 + 2.0 * t2 - t)
    w[1] = 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0)
    w[2] = 0.5 * (-3.0 * t3 + 4.0 * t2 + t)
    w[3] = 0.5 * (t3 - t2)
    dw[0] = 0.5 * (-3.0 * t2 + 4.0 * t - 1.0)
    dw[1] = 0.5 * (9.0 * t2 - 10.0 * t)
    dw[2] = 0.5 * (-9.0 * t2 + 8.0 * t + 1.0)
    dw[3] = 0.5 * (3.0 * t2 - 2.0 * t)


@numba.njit(cache=True, inline="always")
def _locate(x, lo, h, n, c_out):
    """Cell index and local coordinate of x; c_out[0] = x - clamp(x).

    Valid interpolation range is nodes 1 .. n-2 (stencil needs i-1, i+2).
    """
    u = (x - lo) / h
    if not math.isfinite(u):  # NaN/inf positions: any valid cell, NaN offset
        c_out[0] = np.nan
        return 1, 0.0
    uc = min(max(u, 1.0), n - 2.0)
    i = min(int(np.floor(uc)), n - 3)
    # distance beyond the valid range (exactly 0 inside it)
    c_out[0] = x - (lo + uc * h) if uc != u else 0.0
    return i, uc - i


@numba.njit(cache=True)
def _interp2(r_pd, table, lo, h, phi_p, g_pd):
    nx, ny = table.shape
    wx = np.empty(4)
    dwx = np.empty(4)
    wy = np.empty(4)
    dwy = np.empty(4)
    cx = np.empty(1)
    cy = np.empty(1)
    for p in range(r_pd.shape[0]):
        i, tx = _locate(r_pd[p, 0], lo[0], h, nx, cx)
        j, ty = _locate(r_pd[p, 1], lo[1], h, ny, cy)
        _cr_weights(tx, wx, dwx)
        _cr_weights(ty, wy, dwy)
        f = 0.0
        fx = 0.0
        fy = 0.0
        for a in range(4):
            for b in range(4):
                v = table[i - 1 + a, j - 1 + b]
                f += wx[a] * wy[b] * v
                fx += dwx[a] * wy[b] * v
                fy += wx[a] * dwy[b] * v
        gx = fx / h
        gy = fy / h
        ex = cx[0]
        ey = cy[0]
        e = np.sqrt(ex * ex + ey * ey)
        if e > 0.0:
            f += e
            if ex != 0.0:
                gx = ex / e
            if ey != 0.0:
                gy = ey / e
        if e != e:
            f = gx = gy = np.nan
        phi_p[p] = f
        g_pd[p, 0] = gx
        g_pd[p, 1] = gy


@numba.njit(cache=True)
def _interp3(r_pd, table, lo, h, phi_p, g_pd):
    nx, ny, nz = table.shape
    wx = np.empty(4)
    dwx = np.empty(4)
    wy = np.empty(4)
    dwy = np.empty(4)
    wz = np.empty(4)
    dwz = np.empty(4)
    cx = np.empty(1)
    cy = np.empty(1)
    cz = np.empty(1)
    for p in range(r_pd.shape[0]):
        i, tx = _locate(r_pd[p, 0], lo[0], h, nx, cx)
        j, ty = _locate(r_pd[p, 1], lo[1], h, ny, cy)
        k, tz = _locate(r_pd[p, 2], lo[2], h, nz, cz)
        _cr_weights(tx, wx, dwx)
        _cr_weights(ty, wy, dwy)
        _cr_weights(tz, wz, dwz)
        f = 0.0
        fx = 0.0
        fy = 0.0
        fz = 0.0
        for a in range(4):
            for b in range(4):
                for c in range(4):
                    v = table[i - 1 + a, j - 1 + b, k - 1 + c]
                    f += wx[a] * wy[b] * wz[c] * v
                    fx += dwx[a] * wy[b] * wz[c] * v
                    fy += wx[a] * dwy[b] * wz[c] * v
                    fz += wx[a] * wy[b] * dwz[c] * v
        gx = fx / h
        gy = fy / h
        gz = fz / h
        ex = cx[0]
        ey = cy[0]
        ez = cz[0]
        e = np.sqrt(ex * ex + ey * ey + ez * ez)
        if e > 0.0:
            f += e
            if ex != 0.0:
                gx = ex / e
            if ey != 0.0:
                gy = ey / e
            if ez != 0.0:
                gz = ez / e
        if e != e:
            f = gx = gy = gz = np.nan
        phi_p[p] = f
        g_pd[p, 0] = gx
        g_pd[p, 1] = gy
        g_pd[p, 2] = gz


class CubicTable:
    """``phi`` sampled on nodes ``lo + i dx`` and its Catmull-Rom interpolant.

    Parameters
    ----------
    phi_function : callable
        Exact ``phi`` on points (P, dim).
    bounds : (lo_d, hi_d)
        Box to cover; the grid extends ``margin`` cells (plus one stencil node)
        beyond it on every side.
    dx : float
        Node spacing (Fan's background mesh spacing).
    """

    def __init__(self, phi_function, bounds, dx, margin=4):
        self.dx = check_positive("dx", dx)
        if int(margin) != margin or margin < 1:
            raise ValueError(f"margin must be an integer >= 1, got {margin!r}")
        lo, hi = (np.asarray(b, dtype=float) for b in bounds)
        self.dim = lo.size
        pad = (int(margin) + 1) * self.dx
        n_d = np.ceil((hi - lo + 2 * pad) / self.dx).astype(int) + 1
        n_nodes = int(np.prod(n_d.astype(float)))
        if n_nodes > 2e8:
            raise ValueError(
                f"dx={dx!r} gives a table of {n_nodes:.3g} nodes; choose a larger dx")
        self.lo = lo - pad
        axes = [self.lo[d] + np.arange(n_d[d]) * self.dx for d in range(self.dim)]
        grids = np.meshgrid(*axes, indexing="ij")
        nodes = np.stack([g.ravel() for g in grids], axis=1)
        self.values = np.ascontiguousarray(phi_function(nodes).reshape(tuple(n_d)))

    def phi_grad(self, r_pd):
        r_pd = np.ascontiguousarray(r_pd, dtype=float)
        phi_p = np.empty(len(r_pd))
        g_pd = np.empty_like(r_pd)
        if self.dim == 2:
            _interp2(r_pd, self.values, self.lo, self.dx, phi_p, g_pd)
        else:
            _interp3(r_pd, self.values, self.lo, self.dx, phi_p, g_pd)
        return phi_p, g_pd
