"""Closed forms of the 2D boundary integrals over straight segments (METHOD_NOTES, BIPI section).

For a particle ``x_a`` and a segment with inward normal ``n``, in units of the support ``h``:
``delta`` is the signed distance of ``x_a`` to the segment's line (positive on the domain side),
``tau`` the coordinate along the segment from the foot of ``x_a`` and ``rho^2 = delta^2 + tau^2``.
The integrals of :mod:`~ase_sphrelax.boundary.radial` reduce to ``int rho^k dtau``, with the
reduction ``I_k = (tau rho^k + k delta^2 I_(k-2)) / (k + 1)`` from ``I_0 = tau`` and
``I_-1 = asinh(tau / |delta|)``, and to ``delta int rho^-2 dtau = atan(tau / delta)``, the
subtended angle (stable as ``delta -> 0``). The segment is clipped to the support
(``|tau| <= sqrt(1 - delta^2)``) and split at the kernel's break radii; no quadrature.

``segment_terms`` returns, for one pair, ``gamma_as`` (Eq. 2: its share of ``1 - gamma_a``),
``|grad gamma_as|`` (Eq. 3: ``grad gamma_as = n_s int_s W dS``) and ``delta``.
"""
from __future__ import annotations

import math

import numba

__all__ = ["segment_terms", "line_offset", "at_vertex", "VERTEX_SNAP"]

# A particle closer than this (per coordinate) to a segment's end point is evaluated at the end point: below it
# the products of p - v with the edge directions are subnormal and lose the direction of p - v, on which the
# subtended angles of both edges at v depend. gamma and grad gamma move by |grad gamma| 1e-200, far below an ulp.
VERTEX_SNAP = 1e-200


@numba.njit(cache=True, inline="always")
def _power_sums(tau, d2, fc, gc, j, degree):
    """(sum_k fc[j, k] I_k(tau), sum_k gc[j, k] I_k(tau)) with I_k = int rho^k dtau."""
    r = math.sqrt(d2 + tau * tau)
    # delta^2 I_-1 = delta^2 asinh(tau / |delta|), which vanishes with delta
    jm1 = d2 * math.asinh(tau / math.sqrt(d2)) if d2 > 1e-280 else 0.0
    sf = fc[j, 0] * tau
    sg = gc[j, 0] * tau
    i_even = tau
    i_odd = 0.0
    rk = 1.0
    for k in range(1, degree + 1):
        rk *= r
        if k % 2 == 1:
            i_odd = (tau * rk + (jm1 if k == 1 else k * d2 * i_odd)) / (k + 1)
            sf += fc[j, k] * i_odd
            sg += gc[j, k] * i_odd
        else:
            i_even = (tau * rk + k * d2 * i_even) / (k + 1)
            sf += fc[j, k] * i_even
            sg += gc[j, k] * i_even
    return sf, sg


@numba.njit(cache=True, inline="always")
def _interval(delta, t0, t1, fc, gc, a, j, degree, gam, jw):
    """Add the piece-j integrals over tau in [t0, t1] to (gam, jw)."""
    f1, g1 = _power_sums(t1, delta * delta, fc, gc, j, degree)
    f0, g0 = _power_sums(t0, delta * delta, fc, gc, j, degree)
    jw += f1 - f0
    angle = math.atan2(delta * (t1 - t0), delta * delta + t0 * t1) if delta != 0.0 else 0.0
    gam += a[j] * angle + delta * (g1 - g0)
    return gam, jw


@numba.njit(cache=True, inline="always")
def at_vertex(px, py, seg, e):
    """(px, py), or the end point of segment ``e`` within :data:`VERTEX_SNAP` of it."""
    if abs(px - seg[e, 0]) < VERTEX_SNAP and abs(py - seg[e, 1]) < VERTEX_SNAP:
        return seg[e, 0], seg[e, 1]
    if abs(px - seg[e, 2]) < VERTEX_SNAP and abs(py - seg[e, 3]) < VERTEX_SNAP:
        return seg[e, 2], seg[e, 3]
    return px, py


@numba.njit(cache=True, inline="always")
def line_offset(px, py, seg, e):
    """The offset ``(x_a - x_s)·n_s`` from the end point nearer to the particle (rounding ~ its distance)."""
    ax, ay, bx, by = seg[e, 0], seg[e, 1], seg[e, 2], seg[e, 3]
    if (px - ax) ** 2 + (py - ay) ** 2 <= (px - bx) ** 2 + (py - by) ** 2:
        return (px - ax) * seg[e, 4] + (py - ay) * seg[e, 5]
    return (px - bx) * seg[e, 4] + (py - by) * seg[e, 5]


@numba.njit(cache=True)
def segment_terms(px, py, seg, e, inv_h, breaks, fc, gc, a, sigma, q_max):
    """Boundary terms of particle (px, py) and segment ``e`` of the packed rows ``seg``.

    ``q_max`` is the radius (units of ``h``) the segment is clipped to: 1, the support, for
    ``gamma_as`` and ``grad gamma_as``; less for ``int_{s cap B(x_a, q_max h)} W dS`` alone
    (``gamma_as`` is then meaningless).

    Returns
    -------
    gamma_as : float
        ``sigma delta int G(rho) dtau`` (dimensionless).
    grad_as : float
        ``int_s W dS`` (so that ``grad gamma_as = grad_as * n_s``), in 1 / length.
    delta : float
        Signed distance to the segment's line in units of ``h`` (positive on the domain side).
    """
    px, py = at_vertex(px, py, seg, e)
    ax, ay, bx, by = seg[e, 0], seg[e, 1], seg[e, 2], seg[e, 3]
    nx, ny = seg[e, 4], seg[e, 5]
    tx, ty = ny, -nx  # direction: the inward normal is the direction turned left
    delta = line_offset(px, py, seg, e) * inv_h
    ad = abs(delta)
    if ad >= q_max:
        return 0.0, 0.0, delta
    ta = ((ax - px) * tx + (ay - py) * ty) * inv_h
    tb = ((bx - px) * tx + (by - py) * ty) * inv_h
    degree = fc.shape[1] - 1
    gam = 0.0
    jw = 0.0
    d2 = delta * delta
    for j in range(breaks.shape[0] - 1):
        lo = breaks[j]
        hi = min(breaks[j + 1], q_max)
        if ad >= hi or lo >= hi:
            continue
        t_hi = math.sqrt(hi * hi - d2)
        t_lo = math.sqrt(lo * lo - d2) if lo > ad else 0.0
        if t_lo == 0.0:
            x0 = max(-t_hi, ta)
            x1 = min(t_hi, tb)
            if x1 > x0:
                gam, jw = _interval(delta, x0, x1, fc, gc, a, j, degree, gam, jw)
        else:
            x0 = max(-t_hi, ta)
            x1 = min(-t_lo, tb)
            if x1 > x0:
                gam, jw = _interval(delta, x0, x1, fc, gc, a, j, degree, gam, jw)
            x0 = max(t_lo, ta)
            x1 = min(t_hi, tb)
            if x1 > x0:
                gam, jw = _interval(delta, x0, x1, fc, gc, a, j, degree, gam, jw)
    return sigma * gam, sigma * inv_h * jw, delta
