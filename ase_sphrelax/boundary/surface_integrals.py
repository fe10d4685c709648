"""3D boundary integrals over flat triangles (the 3D extension of BIPI's Eq. 2-3).

For a particle ``x_a`` at signed distance ``delta`` (units of the support ``h``) from the plane
of a triangle with inward normal ``n``, let ``p`` be its foot on the plane. The triangle is the
signed sum of the three triangles ``(p, v_i, v_i+1)``; each is integrated in polar coordinates
about ``p``. The radial integrals are the antiderivatives ``P1`` and ``Q`` of
:mod:`~ase_sphrelax.boundary.radial`; what remains is one integral along each edge, in the
coordinate ``x`` from the foot of ``p`` on the edge's line (edge distance ``e``):

``int dx e / (e^2 + x^2) [R(rho(x)) - R(|delta|)]``, ``rho(x)^2 = delta^2 + e^2 + x^2``.

* Beyond the support (``rho >= 1``) ``R`` is constant and the integral is an arctangent.
* The singular part of ``gamma`` (``Q ~ -A3_0 / rho``, the solid angle) is integrated in closed
  form: ``A3_0 sign(delta) [atan(x / e) - atan(|delta| x / (e rho))]``.
* The remainders are divided differences ``(R(rho) - R(|delta|)) / (rho^2 - delta^2)``
  (``rho^2 - delta^2 = e^2 + x^2`` exactly), integrated in closed form per power of ``rho``
  (:func:`triangle_terms`: arctangents, one ``asinh`` and polynomials in ``x`` and ``rho``) on
  intervals split where ``rho`` crosses the kernel's break radii.

Near an edge's line the edge's share of the solid angle, ``atan2`` of the foot's distance ``e`` to
the line against ``delta``, is ill-conditioned (``1e-16 L / sqrt(e^2 + delta^2)``) while the sum over
the triangles around the edge is not: ``e`` and ``delta`` come from the particle's offset to the line
computed identically by every triangle sharing it (:func:`_edge_offset`), so the rounding is that of
one slightly moved particle and cancels in the sum (exact near edges, their lines and vertices).

Exact to rounding (no quadrature; issue 17 items 1 and 6): the closed form agrees with 64-node
Gauss-Legendre on the same intervals to 5e-15 (where the former 8-node rule erred by up to 4e-8),
and ``tests/test_gamma_3d_exact.py`` checks it against an adaptive quadrature over the faces.
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["triangle_terms", "triangle_row_terms", "edge_frames", "edge_ids", "row_scratch", "EDGE_COLUMNS"]

EDGE_COLUMNS = 16  # columns of edge_frames
INV_INT = 1.0 / np.maximum(np.arange(64), 1.0)  # 1 / k: the recursions multiply instead of dividing (kernels below degree 60)


@numba.njit(cache=True, inline="always")
def _laurent(row, r):
    """sum_m row[m] r^(m - 1)."""
    total = row[0] / r if row[0] != 0.0 else 0.0
    rk = 1.0
    for m in range(1, row.shape[0]):
        total += row[m] * rk
        rk *= r
    return total


@numba.njit(cache=True, inline="always")
def _piece(breaks, r):
    j = 0
    while j < breaks.shape[0] - 2 and r >= breaks[j + 1]:
        j += 1
    return j


@numba.njit(cache=True)
def edge_frames(tri):
    """Per-edge geometry of every triangle, computed once: ``(T, 3, EDGE_COLUMNS)`` for edge i (v_i, v_i+1).

    Columns: 0-2 and 3-5 the edge's end points in lexicographic order and 6-8 the unit direction
    from the first to the second (the canonical frame of :func:`_edge_offset`, shared bit for bit by
    the two triangles of an edge); 9-11 the unit vector ``u`` from v_i to v_i+1; 12-14 the in-plane
    normal ``m`` of the edge towards the opposite vertex (not normalised) and 15 its length. The
    arithmetic is that of the former per-pair computation, so the terms are unchanged to the bit.
    """
    out = np.empty((tri.shape[0], 3, EDGE_COLUMNS))
    for t in range(tri.shape[0]):
        for i in range(3):
            k = (i + 1) % 3
            k2 = (i + 2) % 3
            ax, ay, az = tri[t, 3 * i], tri[t, 3 * i + 1], tri[t, 3 * i + 2]
            bx, by, bz = tri[t, 3 * k], tri[t, 3 * k + 1], tri[t, 3 * k + 2]
            sx, sy, sz, ex, ey, ez = ax, ay, az, bx, by, bz
            if (bx, by, bz) < (ax, ay, az):
                sx, sy, sz, ex, ey, ez = bx, by, bz, ax, ay, az
            cx, cy, cz = ex - sx, ey - sy, ez - sz
            inv_len = 1.0 / math.sqrt(cx * cx + cy * cy + cz * cz)
            cx *= inv_len
            cy *= inv_len
            cz *= inv_len
            ux, uy, uz = bx - ax, by - ay, bz - az
            length = math.sqrt(ux * ux + uy * uy + uz * uz)
            ux /= length
            uy /= length
            uz /= length
            wx, wy, wz = tri[t, 3 * k2] - ax, tri[t, 3 * k2 + 1] - ay, tri[t, 3 * k2 + 2] - az
            along = wx * ux + wy * uy + wz * uz
            mx, my, mz = wx - along * ux, wy - along * uy, wz - along * uz
            row = out[t, i]
            row[0], row[1], row[2], row[3], row[4], row[5] = sx, sy, sz, ex, ey, ez
            row[6], row[7], row[8] = cx, cy, cz
            row[9], row[10], row[11] = ux, uy, uz
            row[12], row[13], row[14] = mx, my, mz
            row[15] = math.sqrt(mx * mx + my * my + mz * mz)
    return out


@numba.njit(cache=True, inline="always")
def _edge_offset(px, py, pz, frames, t, i):
    """``w``: the part of ``x_a - x_0`` normal to the line through edge i (v_i, v_i+1) of triangle t.

    Computed the same way, bit for bit, by both triangles that share the edge: the direction runs from
    the lexicographically smaller end point to the larger one and ``x_0`` is the end point nearer to
    the particle (``frames``: :func:`edge_frames`). A point near the edge's line (or a vertex) is then
    seen at the same rounded offset from both sides, so their shares of the solid angle, each
    ill-conditioned there (``1e-16 L / |w|``), add up as for one point: the sum is exact (backward stable).
    """
    f = frames[t, i]
    cx, cy, cz = f[6], f[7], f[8]
    dax, day, daz = px - f[0], py - f[1], pz - f[2]
    dbx, dby, dbz = px - f[3], py - f[4], pz - f[5]
    if dbx * dbx + dby * dby + dbz * dbz < dax * dax + day * day + daz * daz:
        dax, day, daz = dbx, dby, dbz
    along = dax * cx + day * cy + daz * cz
    return dax - along * cx, day - along * cy, daz - along * cz


@numba.njit(cache=True, inline="always")
def _phi_difference(x0, r0, x1, r1, e, e2, ad):
    """``phi(x1) - phi(x0)``, ``phi(x) = atan(x / e) - atan(|delta| x / (e rho))`` (``r = rho(x)``).

    ``tan phi = y / z`` with ``y = x e (e^2 + x^2)``, ``z = (rho + |delta|)(e^2 rho + |delta| x^2) > 0``
    (no cancellation), so ``phi`` lies in (-pi/2, pi/2) and the difference is one ``atan2`` of
    ``(y1 z0 - y0 z1, z1 z0 + y1 y0)``; two where the products could underflow.
    """
    y0 = x0 * e * (e2 + x0 * x0)
    z0 = (r0 + ad) * (e2 * r0 + ad * x0 * x0)
    y1 = x1 * e * (e2 + x1 * x1)
    z1 = (r1 + ad) * (e2 * r1 + ad * x1 * x1)
    zz = z1 * z0
    if zz > 1e-200:
        return math.atan2(y1 * z0 - y0 * z1, zz + y1 * y0)
    return math.atan2(y1, z1) - math.atan2(y0, z0)


@numba.njit(cache=True, inline="always")
def _piece_squared(breaks, r2):
    """The kernel piece holding ``rho`` given ``rho^2`` (as :func:`_piece`, without the root)."""
    j = 0
    while j < breaks.shape[0] - 2 and r2 >= breaks[j + 1] * breaks[j + 1]:
        j += 1
    return j


@numba.njit(cache=True, inline="always")
def _asinh_difference(x0, r0, x1, r1, d, d2):
    """``asinh(x1 / d) - asinh(x0 / d)`` for ``x0 < x1`` (``r = sqrt(d^2 + x^2)``), with no cancellation.

    ``asinh(x / d) = sign(x) log((|x| + r) / d)``: on one side of 0 the ``d`` cancels in a ratio;
    across 0 it is ``log((x1 + r1)(r0 - x0) / d^2)``.
    """
    if x0 >= 0.0:
        return math.log((x1 + r1) / (x0 + r0))
    if x1 <= 0.0:
        return math.log((r0 - x0) / (r1 - x1))
    if d2 > 1e-280:
        return math.log((x1 + r1) * (r0 - x0) / d2)
    return math.log(x1 + r1) + math.log(r0 - x0) - 2.0 * math.log(d)


@numba.njit(cache=True, inline="always")
def _polynomial_part(row, r):
    """``sum_{m >= 1} row[m] r^(m - 1)``: the Laurent polynomial of ``row`` without its ``1 / r`` column."""
    total = 0.0
    for m in range(row.shape[0] - 1, 0, -1):
        total = total * r + row[m]
    return total


@numba.njit(cache=True, inline="always")
def _edge_cuts(xa, xb, d2, breaks, q_max, with_gamma, cuts):
    """The interval end points along an edge, sorted into ``cuts``: ``xa``, where ``rho`` crosses a break
    radius (and ``q_max`` unless ``with_gamma``), ``xb``; returns their number."""
    nb = breaks.shape[0] - 1
    n_cut = 0
    cuts[n_cut] = xa
    n_cut += 1
    for j in range(1, nb + 2):
        radius = breaks[j] if j <= nb else q_max
        if radius > q_max or (j == nb + 1 and with_gamma):
            continue
        b2 = radius * radius - d2
        if b2 > 0.0:
            xc = math.sqrt(b2)
            if xa < xc < xb:
                cuts[n_cut] = xc
                n_cut += 1
            if xa < -xc < xb:
                cuts[n_cut] = -xc
                n_cut += 1
    cuts[n_cut] = xb
    n_cut += 1
    # insertion sort (a handful of points)
    for m in range(1, n_cut):
        v = cuts[m]
        q = m - 1
        while q >= 0 and cuts[q] > v:
            cuts[q + 1] = cuts[q]
            q -= 1
        cuts[q + 1] = v
    return n_cut


@numba.njit(cache=True, inline="always")
def triangle_terms(px, py, pz, tri, nrm, frames, t, inv_h, breaks, lp, lq, a0, p1_one, sigma, q_max, cuts):
    """Boundary terms of particle p and triangle ``t`` (packed vertices ``tri[t]``, inward ``nrm[t]``).

    ``q_max`` is the radius (units of ``h``) the triangle is clipped to: 1, the support, for both
    terms; less for ``int_{t cap B(x_a, q_max h)} W dS`` alone (``gamma_at`` is then returned as 0).
    ``cuts`` is scratch space of at least ``2 (number of kernel pieces) + 5`` entries.

    Every edge integral is in closed form (module docstring): with ``a = |delta|``,
    ``d^2 = a^2 + e^2``, ``rho^2 = d^2 + x^2`` and ``T_k = int e (rho^k - a^k) / (e^2 + x^2) dx``,

    * ``T_1 = e asinh(x / d) - a phi(x)``, ``phi = atan(x / e) - atan(a x / (e rho))``;
    * ``T_2n = e sum_{i<n} a^(2(n-1-i)) E_i``, ``E_i = int rho^(2i) dx``;
    * ``T_(2n+1) = e sum_{i<n} a^(2(n-1-i)) J_i + a^(2n) T_1``, ``J_i = int rho^(2i+1) dx``;
    * ``delta T_(-1) = -sign(delta) phi`` (the ``1 / rho`` column of a kernel with several pieces),

    with ``E_i = (x rho^(2i) + 2i d^2 E_(i-1)) / (2i + 1)``, ``E_0 = x``, and
    ``J_i = (x rho^(2i+1) + (2i + 1) d^2 J_(i-1)) / (2i + 2)``, ``J_(-1) = asinh(x / d)``.

    Returns
    -------
    gamma_at : float
        ``sigma delta int_t G3(rho) dA'``.
    grad_at : float
        ``int_t W dS`` (so that ``grad gamma_at = grad_at * n_t``), in 1 / length.
    delta : float
        Signed distance to the triangle's plane in units of ``h``.
    """
    nx, ny, nz = nrm[t, 0], nrm[t, 1], nrm[t, 2]
    # delta from the edge line nearest to the particle (see _edge_offset): consistent with that edge's e
    w0x, w0y, w0z = _edge_offset(px, py, pz, frames, t, 0)
    w1x, w1y, w1z = _edge_offset(px, py, pz, frames, t, 1)
    w2x, w2y, w2z = _edge_offset(px, py, pz, frames, t, 2)
    wx, wy, wz = w0x, w0y, w0z
    if w1x * w1x + w1y * w1y + w1z * w1z < wx * wx + wy * wy + wz * wz:
        wx, wy, wz = w1x, w1y, w1z
    if w2x * w2x + w2y * w2y + w2z * w2z < wx * wx + wy * wy + wz * wz:
        wx, wy, wz = w2x, w2y, w2z
    delta = (wx * nx + wy * ny + wz * nz) * inv_h
    ad = abs(delta)
    if ad >= q_max:
        return 0.0, 0.0, delta
    with_gamma = q_max >= 1.0
    sgn = 1.0 if delta > 0.0 else (-1.0 if delta < 0.0 else 0.0)
    jd = _piece(breaks, ad)
    p1_d = _laurent(lp[jd], ad)  # piece 0 has no 1 / rho term: fine at ad = 0
    qt_d = _laurent(lq[jd], ad)
    if with_gamma:
        kf_inf = p1_one - p1_d
        kg_inf = sgn * a0 - delta * qt_d
    else:
        kf_inf = _laurent(lp[_piece(breaks, q_max)], q_max) - p1_d
        kg_inf = 0.0
    cols = lp.shape[1]
    a2 = ad * ad
    gam = 0.0
    jf = 0.0
    for i in range(3):
        k1 = (i + 1) % 3
        ax, ay, az = tri[t, 3 * i], tri[t, 3 * i + 1], tri[t, 3 * i + 2]
        bx, by, bz = tri[t, 3 * k1], tri[t, 3 * k1 + 1], tri[t, 3 * k1 + 2]
        f = frames[t, i]
        ux, uy, uz = f[9], f[10], f[11]  # unit edge vector
        mx, my, mz, mlen = f[12], f[13], f[14], f[15]  # in-plane normal of the edge, towards the opposite vertex
        if i == 0:
            wx, wy, wz = w0x, w0y, w0z
        elif i == 1:
            wx, wy, wz = w1x, w1y, w1z
        else:
            wx, wy, wz = w2x, w2y, w2z
        e = (wx * mx + wy * my + wz * mz) / mlen * inv_h  # distance of the foot to the edge line
        if e == 0.0:
            continue
        xa = ((ax - px) * ux + (ay - py) * uy + (az - pz) * uz) * inv_h  # u is normal to n: as from the foot
        xb = ((bx - px) * ux + (by - py) * uy + (bz - pz) * uz) * inv_h
        e2 = e * e
        d2 = a2 + e2
        d = math.sqrt(d2) if d2 > 1e-280 else math.hypot(ad, e)
        n_cut = _edge_cuts(xa, xb, d2, breaks, q_max, with_gamma, cuts)
        for m in range(n_cut - 1):
            x0 = cuts[m]
            x1 = cuts[m + 1]
            if x1 <= x0:
                continue
            xm = 0.5 * (x0 + x1)
            rm2 = d2 + xm * xm
            if rm2 >= q_max * q_max:
                ang = math.atan2(e * (x1 - x0), e2 + x0 * x1)
                jf += kf_inf * ang
                gam += kg_inf * ang
                continue
            j = _piece_squared(breaks, rm2)
            r1 = math.sqrt(d2 + x1 * x1)
            r0 = math.sqrt(d2 + x0 * x0)
            dphi = _phi_difference(x0, r0, x1, r1, e, e2, ad)
            if sgn != 0.0 and with_gamma:
                gam += a0 * sgn * dphi  # the solid angle
            das = _asinh_difference(x0, r0, x1, r1, d, d2)
            t1 = e * das - ad * dphi  # T_1
            sf = lp[j, 2] * t1
            sq = lq[j, 2] * t1
            de = x1 - x0  # E_0
            dj = 0.5 * ((x1 * r1 - x0 * r0) + d2 * das)  # J_0
            u_n = 0.0
            v_n = 0.0
            a2n = 1.0
            xe0, xe1 = x0, x1  # x rho^(2n)
            xo0, xo1 = x0 * r0, x1 * r1  # x rho^(2n + 1)
            s0, s1 = r0 * r0, r1 * r1
            n = 1
            while 2 * n + 1 < cols:
                u_n = a2 * u_n + de
                sf += lp[j, 2 * n + 1] * e * u_n  # T_2n
                sq += lq[j, 2 * n + 1] * e * u_n
                if 2 * n + 2 >= cols:
                    break
                v_n = a2 * v_n + dj
                a2n *= a2
                term = e * v_n + a2n * t1  # T_(2n+1)
                sf += lp[j, 2 * n + 2] * term
                sq += lq[j, 2 * n + 2] * term
                if 2 * n + 3 >= cols:
                    break  # no next power: E_n, J_n are not needed
                xe0 *= s0
                xe1 *= s1
                de = ((xe1 - xe0) + 2 * n * d2 * de) * INV_INT[2 * n + 1]
                xo0 *= s0
                xo1 *= s1
                dj = ((xo1 - xo0) + (2 * n + 1) * d2 * dj) * INV_INT[2 * n + 2]
                n += 1
            if j != jd:  # the difference of the pieces' constants at rho = a: times atan(x / e)
                ang = math.atan2(e * (x1 - x0), e2 + x0 * x1)
                sf += (_polynomial_part(lp[j], ad) - _polynomial_part(lp[jd], ad)) * ang
                sq += (_polynomial_part(lq[j], ad) - _polynomial_part(lq[jd], ad)) * ang
                if with_gamma:
                    gam += sgn * (lq[j, 0] - lq[jd, 0]) * ang
            jf += sf
            if with_gamma:
                gam += delta * sq - sgn * lq[j, 0] * dphi  # the 1 / rho column: delta T_(-1) = -sign phi
    return sigma * gam, sigma * inv_h * jf, delta


# Per-pair constants of triangle_row_terms (columns of ``pair_c``)
PC_DELTA, PC_AD, PC_SGN, PC_JD, PC_KF, PC_KG, PC_GAM, PC_JF, PC_ACTIVE = 0, 1, 2, 3, 4, 5, 6, 7, 8
PAIR_COLUMNS = 9


def edge_ids(frames):
    """``(T, 3)`` id of every triangle edge, the same for the triangles sharing it, and the number of edges.

    Edges are identified by their canonical end points (``frames[..., 0:6]``, :func:`edge_frames`).
    """
    keys = np.ascontiguousarray(frames[:, :, 0:6].reshape(-1, 6))
    if keys.shape[0] == 0:
        return np.zeros((0, 3), dtype=np.int64), 0
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    ids = np.ascontiguousarray(inverse.reshape(frames.shape[0], 3), dtype=np.int64)
    return ids, int(ids.max()) + 1


@numba.njit(cache=True)
def row_scratch(longest, breaks, cols):
    """Scratch arrays of :func:`triangle_row_terms` for rows of at most ``longest`` pairs."""
    n_slots = 3 * max(longest, 1)
    return (np.empty((n_slots, 3)), np.empty((n_slots, 4), dtype=np.int64), np.empty((max(longest, 1), PAIR_COLUMNS)),
            np.empty(2 * breaks.shape[0] + 5), np.empty(2 * max((cols - 2) // 2, 1)))


@numba.njit(cache=True, inline="always")
def _interval_sum(x0, r0, x1, r1, das, mom, n_mom, j, e, pair_c, q, lp, lq, a0):
    """(gamma, flux) of one interval within the support for the triangle of pair ``q`` (edge distance ``e``):
    the per-triangle part of :func:`triangle_terms` (``phi``, ``T_k`` from the edge's ``E_i``, ``J_i`` in ``mom``)."""
    delta, ad, sgn, jd = pair_c[q, PC_DELTA], pair_c[q, PC_AD], pair_c[q, PC_SGN], int(pair_c[q, PC_JD])
    e2 = e * e
    a2 = ad * ad
    cols = lp.shape[1]
    gam = 0.0
    dphi = _phi_difference(x0, r0, x1, r1, e, e2, ad)
    if sgn != 0.0:
        gam += a0 * sgn * dphi  # the solid angle
    t1 = e * das - ad * dphi  # T_1
    sf = lp[j, 2] * t1
    sq = lq[j, 2] * t1
    u_n = 0.0
    v_n = 0.0
    a2n = 1.0
    n = 1
    while 2 * n + 1 < cols:
        u_n = a2 * u_n + mom[n - 1]  # E_(n-1)
        sf += lp[j, 2 * n + 1] * e * u_n  # T_2n
        sq += lq[j, 2 * n + 1] * e * u_n
        if 2 * n + 2 >= cols:
            break
        v_n = a2 * v_n + mom[n_mom + n - 1]  # J_(n-1)
        a2n *= a2
        term = e * v_n + a2n * t1  # T_(2n+1)
        sf += lp[j, 2 * n + 2] * term
        sq += lq[j, 2 * n + 2] * term
        n += 1
    if j != jd:  # the difference of the pieces' constants at rho = a: times atan(x / e)
        ang = math.atan2(e * (x1 - x0), e2 + x0 * x1)
        sf += (_polynomial_part(lp[j], ad) - _polynomial_part(lp[jd], ad)) * ang
        sq += (_polynomial_part(lq[j], ad) - _polynomial_part(lq[jd], ad)) * ang
        gam += sgn * (lq[j, 0] - lq[jd, 0]) * ang
    gam += delta * sq - sgn * lq[j, 0] * dphi  # the 1 / rho column: delta T_(-1) = -sign phi
    return gam, sf


@numba.njit(cache=True)
def triangle_row_terms(px, py, pz, elem_k, k0, k1, tri, nrm, frames, edge_tk, inv_h, breaks, lp, lq, a0, p1_one, sigma,
                       stamp_e, slot_e, visit, slot_w, slot_pair, pair_c, cuts, mom, g_k, gr_k, d_k):
    """:func:`triangle_terms` (``q_max = 1``) of the point ``p`` and the triangles ``elem_k[k0:k1]``, edge by edge.

    The two triangles of an edge need the same ``d`` (the distance to the edge's line), the same
    intervals and ``rho`` at their ends, ``asinh`` difference and ``E_i``, ``J_i``; only ``e``, ``|delta|``
    and ``phi`` are their own. So each edge of the row (``edge_tk``: ids shared by the triangles of an
    edge; ``stamp_e``/``slot_e`` mark the edges seen in this ``visit``) is integrated once, along the
    direction of its first triangle, and both triangles' terms are added from it. The integrands are even
    in ``x`` (``phi`` is odd), so the second triangle, which runs along the edge the other way, has the
    same integrals over the same intervals. The same formulas as :func:`triangle_terms`, summed in another
    order and with ``d`` from the offset ``w`` itself (agreement to rounding: ``tests/test_bipi_edge_sharing.py``).

    Writes ``g_k[q]``, ``gr_k[q]``, ``d_k[q]`` (gamma_at, int W dS, delta) for pair ``k0 + q``.
    """
    n_slots = 0
    n_mom = mom.shape[0] // 2
    # the edges of the row's triangles, once each, with the (up to two) triangles that need them
    for k in range(k0, k1):
        q = k - k0
        t = elem_k[k]
        for i in range(3):
            edge = edge_tk[t, i]
            s = slot_e[edge] if stamp_e[edge] == visit else -1
            if s >= 0 and slot_pair[s, 2] < 0:
                slot_pair[s, 2] = q
                slot_pair[s, 3] = i
            else:  # a new edge (or a third triangle on it: a slot of its own)
                s = n_slots
                n_slots += 1
                if stamp_e[edge] != visit:
                    stamp_e[edge] = visit
                    slot_e[edge] = s
                wx, wy, wz = _edge_offset(px, py, pz, frames, t, i)
                slot_w[s, 0], slot_w[s, 1], slot_w[s, 2] = wx, wy, wz
                slot_pair[s, 0], slot_pair[s, 1], slot_pair[s, 2], slot_pair[s, 3] = q, i, -1, -1
        # delta from the edge line nearest to the particle (see _edge_offset), as triangle_terms
        best = np.inf
        wx = wy = wz = 0.0
        for i in range(3):
            edge = edge_tk[t, i]
            s = slot_e[edge]
            if slot_pair[s, 0] != q and slot_pair[s, 2] != q:  # a third triangle of the edge: its own slot
                for s2 in range(n_slots - 1, -1, -1):
                    if (slot_pair[s2, 0] == q and slot_pair[s2, 1] == i) or (slot_pair[s2, 2] == q and slot_pair[s2, 3] == i):
                        s = s2
                        break
            vx, vy, vz = slot_w[s, 0], slot_w[s, 1], slot_w[s, 2]
            v2 = vx * vx + vy * vy + vz * vz
            if i == 0 or v2 < best:
                best = v2
                wx, wy, wz = vx, vy, vz
        delta = (wx * nrm[t, 0] + wy * nrm[t, 1] + wz * nrm[t, 2]) * inv_h
        ad = abs(delta)
        sgn = 1.0 if delta > 0.0 else (-1.0 if delta < 0.0 else 0.0)
        jd = _piece(breaks, ad)
        pair_c[q, PC_DELTA], pair_c[q, PC_AD], pair_c[q, PC_SGN], pair_c[q, PC_JD] = delta, ad, sgn, jd
        pair_c[q, PC_KF] = p1_one - _laurent(lp[jd], ad)  # piece 0 has no 1 / rho term: fine at ad = 0
        pair_c[q, PC_KG] = sgn * a0 - delta * _laurent(lq[jd], ad)
        pair_c[q, PC_GAM] = 0.0
        pair_c[q, PC_JF] = 0.0
        pair_c[q, PC_ACTIVE] = 1.0 if ad < 1.0 else 0.0
    for s in range(n_slots):
        qa, ia, qb, ib = slot_pair[s, 0], slot_pair[s, 1], slot_pair[s, 2], slot_pair[s, 3]
        ta = elem_k[k0 + qa]
        wx, wy, wz = slot_w[s, 0], slot_w[s, 1], slot_w[s, 2]
        # distance of each triangle's foot to the edge line (in-plane normal m towards the opposite vertex)
        ea = (wx * frames[ta, ia, 12] + wy * frames[ta, ia, 13] + wz * frames[ta, ia, 14]) / frames[ta, ia, 15] * inv_h
        use_a = pair_c[qa, PC_ACTIVE] != 0.0 and ea != 0.0
        use_b = False
        eb = 0.0
        if qb >= 0:
            tb = elem_k[k0 + qb]
            eb = (wx * frames[tb, ib, 12] + wy * frames[tb, ib, 13] + wz * frames[tb, ib, 14]) / frames[tb, ib, 15] * inv_h
            use_b = pair_c[qb, PC_ACTIVE] != 0.0 and eb != 0.0
        if not (use_a or use_b):
            continue
        k1a = (ia + 1) % 3
        ux, uy, uz = frames[ta, ia, 9], frames[ta, ia, 10], frames[ta, ia, 11]  # unit edge vector of the first
        # end points along u from the foot (u is normal to w), in units of h
        xa = ((tri[ta, 3 * ia] - px) * ux + (tri[ta, 3 * ia + 1] - py) * uy + (tri[ta, 3 * ia + 2] - pz) * uz) * inv_h
        xb = ((tri[ta, 3 * k1a] - px) * ux + (tri[ta, 3 * k1a + 1] - py) * uy + (tri[ta, 3 * k1a + 2] - pz) * uz) * inv_h
        whx, why, whz = wx * inv_h, wy * inv_h, wz * inv_h
        d2 = whx * whx + why * why + whz * whz
        d = math.sqrt(d2) if d2 > 1e-280 else math.hypot(math.hypot(whx, why), whz)
        n_cut = _edge_cuts(xa, xb, d2, breaks, 1.0, True, cuts)
        for m in range(n_cut - 1):
            x0 = cuts[m]
            x1 = cuts[m + 1]
            if x1 <= x0:
                continue
            xm = 0.5 * (x0 + x1)
            rm2 = d2 + xm * xm
            if rm2 >= 1.0:  # beyond the support: atan(x / e), the same from -x1 to -x0
                if use_a:
                    ang = math.atan2(ea * (x1 - x0), ea * ea + x0 * x1)
                    pair_c[qa, PC_JF] += pair_c[qa, PC_KF] * ang
                    pair_c[qa, PC_GAM] += pair_c[qa, PC_KG] * ang
                if use_b:
                    ang = math.atan2(eb * (x1 - x0), eb * eb + x0 * x1)
                    pair_c[qb, PC_JF] += pair_c[qb, PC_KF] * ang
                    pair_c[qb, PC_GAM] += pair_c[qb, PC_KG] * ang
                continue
            j = _piece_squared(breaks, rm2)
            r1 = math.sqrt(d2 + x1 * x1)
            r0 = math.sqrt(d2 + x0 * x0)
            das = _asinh_difference(x0, r0, x1, r1, d, d2)
            de = x1 - x0  # E_0
            dj = 0.5 * ((x1 * r1 - x0 * r0) + d2 * das)  # J_0
            xe0, xe1 = x0, x1  # x rho^(2n)
            xo0, xo1 = x0 * r0, x1 * r1  # x rho^(2n + 1)
            s0, s1 = r0 * r0, r1 * r1
            for n in range(n_mom):
                mom[n] = de
                mom[n_mom + n] = dj
                if n + 1 == n_mom:
                    break
                xe0 *= s0
                xe1 *= s1
                de = ((xe1 - xe0) + 2 * (n + 1) * d2 * de) * INV_INT[2 * n + 3]
                xo0 *= s0
                xo1 *= s1
                dj = ((xo1 - xo0) + (2 * n + 3) * d2 * dj) * INV_INT[2 * n + 4]
            if use_a:
                g, f = _interval_sum(x0, r0, x1, r1, das, mom, n_mom, j, ea, pair_c, qa, lp, lq, a0)
                pair_c[qa, PC_GAM] += g
                pair_c[qa, PC_JF] += f
            if use_b:
                g, f = _interval_sum(x0, r0, x1, r1, das, mom, n_mom, j, eb, pair_c, qb, lp, lq, a0)
                pair_c[qb, PC_GAM] += g
                pair_c[qb, PC_JF] += f
    for q in range(k1 - k0):
        d_k[q] = pair_c[q, PC_DELTA]
        if pair_c[q, PC_ACTIVE] != 0.0:
            g_k[q] = sigma * pair_c[q, PC_GAM]
            gr_k[q] = sigma * inv_h * pair_c[q, PC_JF]
        else:
            g_k[q] = 0.0
            gr_k[q] = 0.0
