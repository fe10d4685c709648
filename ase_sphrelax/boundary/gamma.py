"""Kernel volume fraction ``gamma_a`` and its gradient from the boundary elements (BIPI Eq. 2-3).

``gamma_a = int_{Omega cap B(x_a, h)} W(|x_a - y|) dy`` and
``grad gamma_a = sum_s grad gamma_as = sum_s int_s W n_s dS`` (``n_s`` inward), with ``h`` the
kernel **support** (BIPI's smoothing length is ``h_B = h / 2``). ``gamma`` comes from the
divergence-theorem identity ``gamma_a = chi_a - sum_s gamma_as``
(:mod:`~ase_sphrelax.boundary.radial`), evaluated per element in closed form in 2D
(:mod:`~ase_sphrelax.boundary.line_integrals`) and in 3D as closed-form integrals along the
triangles' edges (:mod:`~ase_sphrelax.boundary.surface_integrals`).

Only the elements within ``h`` of a particle contribute; they come from the particle-element
query on the neighbour bins (:class:`~ase_sphrelax.boundary.BoundaryQuery`). A particle farther
than ``h`` from every element gets ``gamma = chi`` (1 inside, 0 outside) and zero gradient
without touching any element. ``chi`` of a particle near the boundary follows from its nearest
element (the side of the nearest feature: the element's normal, or the pseudo-normal of a
vertex/edge); on the boundary it is the fraction of the angle inside (1/2 on a segment's
interior or a face, the interior angle over ``2 pi`` at a vertex in 2D). In 3D the side of a
point closer than ``1e-7 h`` to the surface (edges and vertices included) is not resolved by the
closest-point test, so ``gamma`` there is evaluated at a point ``q`` moved ``1e-7 h`` inside and
carried back to first order, ``gamma(q) + grad gamma(q) . (x_a - q)`` (both exact at ``q``; the
remainder is ``|x_a - q|^2 |grad^2 gamma| / 2``, about 1e-14); within ``10 NUDGE h`` of a vertex or an
edge ``q`` starts from that vertex or edge, so that the move stays inside at sharp corners and edges). The triangles' shares of the solid
angle themselves are exact near edge lines and vertices
(:func:`~ase_sphrelax.boundary.surface_integrals.triangle_terms`). For the others it
is the inside test of the enclosed region, made when the neighbour list builds its bins (a
particle that moved less than half the skin since cannot have crossed the boundary band).
"""
from __future__ import annotations

import math
import os
import weakref

import numba
import numpy as np

from ..checks import check_positive
from ..domains.closest import closest_on_triangle
from ..parallel import run_chunks, thread_count
from ..specialise import recompiled
from .line_integrals import at_vertex, line_offset, segment_terms
from .query import BoundaryQuery, _element_dist2, boundary_pairs
from .radial import RadialTables
from .segments import BoundarySegments
from .surface_integrals import EDGE_COLUMNS, edge_frames, edge_ids, row_scratch, triangle_row_terms, triangle_terms
from .triangles import BoundaryTriangles

__all__ = ["BoundaryIntegrals", "BoundaryTerms", "gamma_and_gradient", "boundary_terms", "as_boundary"]

UNKNOWN, NEAR_SURFACE = -1.0, -2.0  # chi codes: use the inside test; 3D point within NUDGE h of the surface
# particles whose boundary rows one call of _row_block computes (a call per particle cost more than its terms;
# BoundaryIntegrals.block_rows)
BLOCK_ROWS = 64
# 3D: points closer than NUDGE h to the surface (whose side the closest-point test cannot resolve) are evaluated
# NUDGE h inside and carried back by the exact gradient there (remainder ~ NUDGE^2, about 1e-14)
NUDGE = 1e-7
BAND_RULES = ("normal", "centroid", "ball")
# the boundary rows' templates (_row_block, _rows, _rows_fused) are compiled for each element kind by _for_kind, which
# binds KIND (0: segments, 1: triangles; None here: the templates are not called as they are)
ELEMENT_KINDS = ("segments", "triangles")
KIND = None


@numba.njit(cache=True)
def _chi_segment(px, py, seg, e, next_s, prev_s, inv_h):
    """Point term of a particle whose nearest segment is e (see the module docstring).

    The query's nearest segment ``e`` is only nearest up to the rounding of its distance, which is
    measured from the segment's start (``eps |b - a|``, not ``eps`` times the distance) and whose square
    underflows below 1e-154. Near a vertex ``v`` of ``e`` that can pick ``e`` over its neighbour at
    ``v`` (e.g. a point 5e-14 above the sharp vertex of a sliver, 2e-6 relatively nearer the other
    edge). So the decision is remade locally at the end ``v`` of ``e`` nearer the particle, between
    ``e``, its neighbour there and ``v`` itself, from ``p - v`` (exact near ``v``) and the signed line
    offsets ``delta`` exactly as :func:`~ase_sphrelax.boundary.line_integrals.segment_terms` computes
    them: ``chi`` must have the sign of the ``delta`` whose subtended angle (about ``+-pi``) it cancels.
    Within ``VERTEX_SNAP`` (1e-200) of an end point the particle is on it, as in ``segment_terms``.
    """
    px, py = at_vertex(px, py, seg, e)  # as segment_terms
    ax, ay, bx, by = seg[e, 0], seg[e, 1], seg[e, 2], seg[e, 3]
    t = ((px - ax) * (bx - ax) + (py - ay) * (by - ay)) * seg[e, 7]
    if px == bx and py == by:
        t = 1.0  # on the end vertex: |b - a|^2 / |b - a|^2 may round below 1
    elif px == ax and py == ay:
        t = 0.0
    if t < 0.5:
        vx, vy, s_in, s_out = ax, ay, prev_s[e], e
    else:
        vx, vy, s_in, s_out = bx, by, e, next_s[e]
    dx = px - vx
    dy = py - vy
    tix, tiy = seg[s_in, 5], -seg[s_in, 4]
    tox, toy = seg[s_out, 5], -seg[s_out, 4]
    # signed offsets to the two lines, the values segment_terms uses (positive on the domain side)
    d_out = line_offset(px, py, seg, s_out) * inv_h
    d_in = line_offset(px, py, seg, s_in) * inv_h
    if (dx == 0.0 and dy == 0.0) or (d_out == 0.0 and d_in == 0.0):
        # on the vertex (or within underflow of both lines): interior angle / 2 pi, the domain on the left
        turn = math.atan2(tix * toy - tiy * tox, tix * tox + tiy * toy)
        return (math.pi - turn) / (2.0 * math.pi)
    # where the feet of p on the two edges lie: beyond v along the edge (0 < along < length) or not
    along_out = tox * dx + toy * dy
    along_in = -(tix * dx + tiy * dy)
    foot_out = 0.0 < along_out < seg[s_out, 6]
    foot_in = 0.0 < along_in < seg[s_in, 6]
    if foot_out and (not foot_in or abs(d_out) < abs(d_in)):
        return 1.0 if d_out > 0.0 else (0.0 if d_out < 0.0 else 0.5)
    if foot_in and (not foot_out or abs(d_in) < abs(d_out)):
        return 1.0 if d_in > 0.0 else (0.0 if d_in < 0.0 else 0.5)
    # the nearest point is the vertex (or a tie between the edges): inside iff p - v points into the
    # interior wedge (from the outgoing edge counter-clockwise to the reversed incoming one), i.e. on the left
    # of both edge lines at a convex vertex, of either at a reflex one
    left_out = d_out > 0.0
    left_in = d_in > 0.0
    if tix * toy - tiy * tox >= 0.0:
        return 1.0 if (left_out and left_in) else 0.0
    return 1.0 if (left_out or left_in) else 0.0


@numba.njit(cache=True)
def _chi_triangle(px, py, pz, tri, pseudo, t, delta, close2):
    """Point term of a particle whose nearest triangle is t (see the module docstring).

    ``delta`` is the particle's offset to the plane of t exactly as
    :func:`~ase_sphrelax.boundary.surface_integrals.triangle_terms` computed it for this pair (from
    the nearest edge line): on the face (``delta == 0``, where that triangle subtends no solid angle)
    ``chi`` is 1/2, and only there. A second offset rounded differently (e.g. from the nearest
    vertex) can be 0 where ``delta`` is -3e-17, whose triangle then subtends -1/2: ``gamma`` 1, not 1/2.
    """
    d2, qx, qy, qz, feature = closest_on_triangle(px, py, pz, tri[t])
    side = delta
    if feature == 6 and side == 0.0:
        return 0.5
    if d2 < close2:
        return -2.0  # closer than NUDGE h: from NUDGE h inside (see BoundaryIntegrals._nudged)
    if feature == 6:
        return 1.0 if side > 0.0 else 0.0
    side = (px - qx) * pseudo[t, feature, 0] + (py - qy) * pseudo[t, feature, 1] + (pz - qz) * pseudo[t, feature, 2]
    return 1.0 if side > 0.0 else (0.0 if side < 0.0 else -1.0)


@numba.njit(cache=True, inline="always")
def _empty_row(p, sum_p, grad_pc, near_pc, chi_p, nearest_p):
    """What :func:`_row_block` gives particle ``p`` with no element within ``h``: the callers test for an empty row
    and leave such particles out of their blocks (most particles are far from the boundary)."""
    sum_p[p] = 0.0
    grad_pc[p, 0] = grad_pc[p, 1] = grad_pc[p, 2] = 0.0
    near_pc[p, 0] = near_pc[p, 1] = near_pc[p, 2] = 0.0
    nearest_p[p] = np.inf
    chi_p[p] = UNKNOWN


def _row_block(n_rows, p_r, k0_r, k1_r, x_sc, elem_k, dist_k, point_k, elem, nrm, frames, edge_tk, centroid,
               next_s, prev_s, pseudo, inv_h, breaks, fc, gc, a, lp, lq, p1_one, sigma, close2, band, rule, want_terms,
               gamma_k, grad_k, delta_k, sum_p, grad_pc, near_pc, chi_p, nearest_p, cuts, scratch, row_g, row_gr, row_d,
               stamp_e, slot_e, visit):
    """The terms of particles ``p_r[:n_rows]``, each from its pairs ``k0_r[i]:k1_r[i]`` (see :func:`_rows`); returns
    the last edge visit. A block of rows per call, not one: a call per row cost about 0.8 us (its ~50 arguments),
    more than the terms of a row of a few segments (BIPI's trapezoid at 1e5 particles in 2D: the boundary rows
    took 8.7 ms with a call per row, 3.8 ms with the row inlined). A template: ``KIND`` is bound by
    :func:`_for_kind`."""
    slot_w, slot_pair, pair_c, row_cuts, mom = scratch
    h = 1.0 / inv_h
    for i in range(n_rows):
        p = p_r[i]
        k0 = k0_r[i]
        k1 = k1_r[i]
        run = k0
        if KIND == 1:  # per point: every pair of a particle's row has the same (see BoundaryPairs)
            while run < k1:
                s = point_k[run]
                end = run + 1
                while end < k1 and point_k[end] == s:
                    end += 1
                visit += 1
                triangle_row_terms(x_sc[s, 0], x_sc[s, 1], x_sc[s, 2], elem_k, run, end, elem, nrm, frames, edge_tk,
                                   inv_h, breaks, lp, lq, a[0], p1_one, sigma, stamp_e, slot_e, visit, slot_w,
                                   slot_pair, pair_c, row_cuts, mom, row_g[run - k0:], row_gr[run - k0:],
                                   row_d[run - k0:])
                run = end
        total = 0.0
        g0 = g1 = g2 = 0.0
        w0 = w1 = w2 = 0.0
        best = np.inf
        k_best = -1
        delta_best = 0.0
        for k in range(k0, k1):
            s = point_k[k]
            e = elem_k[k]
            x, y, z = x_sc[s, 0], x_sc[s, 1], x_sc[s, 2]
            if KIND == 1:
                g, gr, d = row_g[k - k0], row_gr[k - k0], row_d[k - k0]
            else:
                g, gr, d = segment_terms(x, y, elem, e, inv_h, breaks, fc, gc, a, sigma, 1.0)
            total += g
            g0 += gr * nrm[e, 0]
            g1 += gr * nrm[e, 1]
            g2 += gr * nrm[e, 2]
            gb = 0.0
            if rule == 2:
                if dist_k[k] < band:
                    if KIND == 0:
                        gb = segment_terms(x, y, elem, e, inv_h, breaks, fc, gc, a, sigma, band * inv_h)[1]
                    else:
                        gb = triangle_terms(x, y, z, elem, nrm, frames, e, inv_h, breaks, lp, lq, a[0], p1_one, sigma,
                                            band * inv_h, cuts)[1]
            elif rule == 1:
                cx, cy, cz = centroid[e, 0] - x, centroid[e, 1] - y, centroid[e, 2] - z
                gb = gr if cx * cx + cy * cy + cz * cz < band * band else 0.0
            elif abs(d) * h < band:
                gb = gr
            w0 += gb * nrm[e, 0]
            w1 += gb * nrm[e, 1]
            w2 += gb * nrm[e, 2]
            if want_terms:
                gamma_k[k] = g
                grad_k[k] = gr
                delta_k[k] = d * h
            if dist_k[k] < best:
                best = dist_k[k]
                k_best = k
                delta_best = d
        sum_p[p] = total
        grad_pc[p, 0], grad_pc[p, 1], grad_pc[p, 2] = g0, g1, g2
        near_pc[p, 0], near_pc[p, 1], near_pc[p, 2] = w0, w1, w2
        nearest_p[p] = best
        if k_best < 0:
            chi_p[p] = UNKNOWN
        elif KIND == 0:
            s = point_k[k_best]
            chi_p[p] = _chi_segment(x_sc[s, 0], x_sc[s, 1], elem, elem_k[k_best], next_s, prev_s, inv_h)
        else:
            s = point_k[k_best]
            chi_p[p] = _chi_triangle(x_sc[s, 0], x_sc[s, 1], x_sc[s, 2], elem, pseudo, elem_k[k_best], delta_best,
                                     close2)
    return visit


@numba.njit(cache=True, nogil=True)
def _row_buffers(kind, longest, breaks, cols, n_edges):
    """One thread's buffers for rows of at most ``longest`` elements: the integrals' scratch, the row's gamma,
    grad-gamma and distance, and the edge stamps/slots of triangles (``kind == 1``; edge e is integrated once per
    visit)."""
    scratch = row_scratch(longest if kind == 1 else 1, breaks, cols)
    stamp_e = np.full(n_edges if kind == 1 else 1, -1, dtype=np.int64)  # the visit whose slot holds edge e
    return (scratch, np.empty(longest), np.empty(longest), np.empty(longest), stamp_e,
            np.empty(stamp_e.shape[0], dtype=np.int64))


def _rows(x_sc, start_p, elem_k, dist_k, point_k, elem, nrm, frames, edge_tk, n_edges, centroid, next_s, prev_s,
          pseudo, inv_h, breaks, fc, gc, a, lp, lq, p1_one, sigma, close2, band, rule, want_terms, skip_p, gamma_k,
          grad_k, delta_k, sum_p, grad_pc, near_pc, chi_p, nearest_p, block_rows, first, last):
    """Per particle: sum_s gamma_as, grad gamma_a, the band sum, the point term and the nearest element's distance
    (see the module docstring).

    ``rule``: 0 normal, 1 centroid, 2 ball (:data:`BAND_RULES`). The kernel tables are those of
    :class:`~ase_sphrelax.boundary.radial.RadialTables` (segments use fc, gc, a; triangles lp, lq,
    a[0], p1_one). Particles with ``skip_p[p]`` (when ``skip_p`` is not empty) are left untouched:
    their values come from the cache of unmoved particles (:meth:`BoundaryIntegrals.compute`).

    Triangles: a particle's terms come edge by edge
    (:func:`~ase_sphrelax.boundary.surface_integrals.triangle_row_terms`): each edge near it is integrated
    once for both its triangles (``edge_tk``: edge ids shared by the triangles of an edge).

    A template, as :func:`_row_block` (``KIND``, and the ``_row_block`` it calls, bound by :func:`_for_kind`).
    """
    cuts = np.empty(2 * breaks.shape[0] + 5)
    use_skip = skip_p.shape[0] > 0
    longest = 1
    for p in range(first, last):
        longest = max(longest, start_p[p + 1] - start_p[p])
    scratch, row_g, row_gr, row_d, stamp_e, slot_e = _row_buffers(KIND, longest, breaks, lp.shape[1], n_edges)
    p_r = np.empty(block_rows, dtype=np.int64)
    k0_r = np.empty(block_rows, dtype=np.int64)
    k1_r = np.empty(block_rows, dtype=np.int64)
    n_rows = np.int64(0)  # typed int64 from the start: a literal 0 would compile _row_block a second time
    visit = -1
    for p in range(first, last):
        if use_skip and skip_p[p]:
            continue
        if start_p[p] == start_p[p + 1]:
            _empty_row(p, sum_p, grad_pc, near_pc, chi_p, nearest_p)
            continue
        p_r[n_rows], k0_r[n_rows], k1_r[n_rows] = p, start_p[p], start_p[p + 1]
        n_rows += 1
        if n_rows == block_rows:
            visit = _row_block(n_rows, p_r, k0_r, k1_r, x_sc, elem_k, dist_k, point_k, elem, nrm, frames,
                               edge_tk, centroid, next_s, prev_s, pseudo, inv_h, breaks, fc, gc, a, lp, lq, p1_one,
                               sigma, close2, band, rule, want_terms, gamma_k, grad_k, delta_k, sum_p, grad_pc, near_pc,
                               chi_p, nearest_p, cuts, scratch, row_g, row_gr, row_d, stamp_e, slot_e, visit)
            n_rows = np.int64(0)
    if n_rows:
        _row_block(n_rows, p_r, k0_r, k1_r, x_sc, elem_k, dist_k, point_k, elem, nrm, frames, edge_tk, centroid,
                   next_s, prev_s, pseudo, inv_h, breaks, fc, gc, a, lp, lq, p1_one, sigma, close2, band, rule,
                   want_terms, gamma_k, grad_k, delta_k, sum_p, grad_pc, near_pc, chi_p, nearest_p, cuts, scratch,
                   row_g, row_gr, row_d, stamp_e, slot_e, visit)


def _rows_fused(x_sc, src_s, is_ghost_s, bin_s, by_bin, src_start, src_elem, radius2, elem, nrm, frames,
                edge_tk, n_edges, centroid, next_s, prev_s, pseudo, inv_h, breaks, fc, gc, a, lp, lq, p1_one, sigma,
                close2, band, rule, skip_p, sum_p, grad_pc, near_pc, chi_p, nearest_p, block_rows, first, last):
    """:func:`_rows` with the query fused in: no pair arrays. Each sorted point ``s`` (ghosts skipped: every
    particle's pairs are those of its own point) finds its elements closer than ``sqrt(radius2)`` among its
    source row (``by_bin``: the elements registered in its bin, ``src_start[bin_s[s]]:``; else its candidate
    row ``src_start[s]:``) in their order, as :class:`~ase_sphrelax.boundary.query.BoundaryQuery` does, into a
    row of scratch, and gets the terms of :func:`_rows` from that row (the same values). A template, as
    :func:`_rows`."""
    cuts = np.empty(2 * breaks.shape[0] + 5)
    use_skip = skip_p.shape[0] > 0
    longest = 1
    if by_bin:
        for b in range(src_start.shape[0] - 1):
            longest = max(longest, src_start[b + 1] - src_start[b])
    else:
        for s in range(first, last):
            longest = max(longest, src_start[s + 1] - src_start[s])
    scratch, row_g, row_gr, row_d, stamp_e, slot_e = _row_buffers(KIND, longest, breaks, lp.shape[1], n_edges)
    # the rows of a block of particles one after another: room for a quarter of block_rows rows of the longest's
    # length and one more (rows within h are shorter than their candidate rows)
    cap = longest * (block_rows // 4) + longest
    elem_r = np.empty(cap, dtype=np.int64)
    dist_r = np.empty(cap)
    point_r = np.empty(cap, dtype=np.int64)
    p_r = np.empty(block_rows, dtype=np.int64)
    k0_r = np.empty(block_rows, dtype=np.int64)
    k1_r = np.empty(block_rows, dtype=np.int64)
    no_terms = np.empty(0)
    no_flag = np.bool_(False)  # typed bool, as _rows passes want_terms: a literal False compiles _row_block again
    n_rows = np.int64(0)  # typed int64 from the start: a literal 0 would compile _row_block a second time
    pos = 0
    visit = -1
    for s in range(first, last):
        if is_ghost_s[s]:
            continue
        p = src_s[s]
        if use_skip and skip_p[p]:
            continue
        row = bin_s[s] if by_bin else s
        if n_rows == block_rows or pos + src_start[row + 1] - src_start[row] > cap:  # the block is full
            visit = _row_block(n_rows, p_r, k0_r, k1_r, x_sc, elem_r, dist_r, point_r, elem, nrm, frames,
                               edge_tk, centroid, next_s, prev_s, pseudo, inv_h, breaks, fc, gc, a, lp, lq, p1_one,
                               sigma, close2, band, rule, no_flag, no_terms, no_terms, no_terms, sum_p, grad_pc,
                               near_pc, chi_p, nearest_p, cuts, scratch, row_g, row_gr, row_d, stamp_e, slot_e, visit)
            n_rows = np.int64(0)
            pos = 0
        x, y, z = x_sc[s, 0], x_sc[s, 1], x_sc[s, 2]
        k0 = pos
        for k in range(src_start[row], src_start[row + 1]):
            e = src_elem[k]
            d2 = _element_dist2(KIND, elem, e, x, y, z)
            if d2 < radius2:
                elem_r[pos] = e
                dist_r[pos] = math.sqrt(d2)
                point_r[pos] = s
                pos += 1
        if pos == k0:
            _empty_row(p, sum_p, grad_pc, near_pc, chi_p, nearest_p)
            continue
        p_r[n_rows], k0_r[n_rows], k1_r[n_rows] = p, k0, pos
        n_rows += 1
    if n_rows:
        _row_block(n_rows, p_r, k0_r, k1_r, x_sc, elem_r, dist_r, point_r, elem, nrm, frames, edge_tk, centroid,
                   next_s, prev_s, pseudo, inv_h, breaks, fc, gc, a, lp, lq, p1_one, sigma, close2, band, rule, no_flag,
                   no_terms, no_terms, no_terms, sum_p, grad_pc, near_pc, chi_p, nearest_p, cuts, scratch, row_g,
                   row_gr, row_d, stamp_e, slot_e, visit)


def _for_kind(template, kind, **calls):
    """``template`` (:func:`_row_block`, :func:`_rows`, :func:`_rows_fused`) compiled for one element kind,
    ``KIND`` = 0 (segments, 2D) or 1 (triangles, 3D), with the jitted functions ``calls`` it calls by name: the
    branches of the other kind are pruned, so a 2D run never compiles the triangles' terms (the one function for both
    kinds took 35 s of the 51 s of a cold ``sphrelax relax`` in 2D: ``benchmarks/bench_cold_start.py``)."""
    return recompiled(template, f"{template.__name__}__{ELEMENT_KINDS[kind]}", dict(KIND=kind, **calls), nogil=True)


_ROW_BLOCK = {kind: _for_kind(_row_block, kind) for kind in (0, 1)}
_ROWS = {kind: _for_kind(_rows, kind, _row_block=_ROW_BLOCK[kind]) for kind in (0, 1)}
_ROWS_FUSED = {kind: _for_kind(_rows_fused, kind, _row_block=_ROW_BLOCK[kind]) for kind in (0, 1)}


@numba.njit(cache=True)
def _inherit_chi(chi_p, r_pc, r0_pc, chi0_p, reach2):
    """``chi_p[p] = chi0_p[p]`` for the particles still UNKNOWN whose last ``chi`` was 0 or 1 and that moved less
    than ``sqrt(reach2)`` since (:meth:`BoundaryIntegrals._resolve_unknown`); returns how many are left."""
    left = 0
    for p in range(chi_p.shape[0]):
        if chi_p[p] != UNKNOWN:
            continue
        c = chi0_p[p]
        if c == 0.0 or c == 1.0:
            d0 = r_pc[p, 0] - r0_pc[p, 0]
            d1 = r_pc[p, 1] - r0_pc[p, 1]
            d2 = r_pc[p, 2] - r0_pc[p, 2]
            if d0 * d0 + d1 * d1 + d2 * d2 < reach2:
                chi_p[p] = c
                continue
        left += 1
    return left


class BoundaryTerms:
    """Result of :meth:`BoundaryIntegrals.compute`. Its arrays are also the integrals' cache of the
    unmoved particles: read them, copy before writing.

    Attributes
    ----------
    gamma_p : ndarray (N,)
        Kernel volume fraction ``gamma_a`` (Eq. 2).
    grad_gamma_pc : ndarray (N, 3)
        ``grad gamma_a = sum_s grad gamma_as`` (Eq. 3); zero z in 2D.
    chi_p : ndarray (N,)
        Point term: 1 inside, 0 outside, the angle fraction on the boundary.
    near_pc : ndarray (N, 3) or None
        ``sum_s grad gamma_as`` over the elements whose line/plane is closer than ``band``
        (the step boundary pressure of BIPI Eq. 14), when a band was given.
    pairs : BoundaryPairs
        The (particle, element) pairs within ``h``.
    gamma_k, grad_k, delta_k : ndarray or None
        Per pair (with ``terms=True``): ``gamma_as``, ``|grad gamma_as|`` (along ``n_s``) and the
        signed distance ``(x_a - x_s) . n_s``.
    nearest_p : ndarray (N,) or None
        Distance of each particle to its nearest element within ``h`` (inf if none), as
        :meth:`~ase_sphrelax.boundary.query.BoundaryPairs.nearest_distance`.
    """

    def __init__(self, gamma_p, grad_gamma_pc, chi_p, near_pc, pairs, gamma_k=None, grad_k=None, delta_k=None,
                 nearest_p=None):
        self.gamma_p = gamma_p
        self.grad_gamma_pc = grad_gamma_pc
        self.chi_p = chi_p
        self.near_pc = near_pc
        self.pairs = pairs
        self.gamma_k = gamma_k
        self.grad_k = grad_k
        self.delta_k = delta_k
        self.nearest_p = nearest_p

    @property
    def inside_p(self):
        """Particles strictly inside (``chi = 1``)."""
        return self.chi_p == 1.0


def as_boundary(boundary):
    """``boundary`` as BoundarySegments / BoundaryTriangles.

    Accepts either, a domain with segments or triangles (Polygon, Box, polygonal CSG, Mesh) or a
    file: ``.edges``/``.txt``/``.dat`` (``x1 y1 x2 y2`` lines) or a mesh file trimesh reads.
    """
    if isinstance(boundary, (BoundarySegments, BoundaryTriangles)):
        return boundary
    if isinstance(boundary, (str, os.PathLike)):
        suffix = os.fspath(boundary).lower().rsplit(".", 1)[-1]
        if suffix in ("edges", "txt", "dat"):
            return BoundarySegments.from_edges(boundary)
        return BoundaryTriangles.from_file(boundary)
    dim = getattr(boundary, "dim", None)
    if dim == 2:
        return BoundarySegments.from_domain(boundary)
    if dim == 3:
        return BoundaryTriangles.from_domain(boundary)
    raise TypeError(f"boundary must be BoundarySegments, BoundaryTriangles, a polygonal domain, a Mesh or a file "
                    f"name, got {type(boundary).__name__}")


class BoundaryIntegrals:
    """``gamma_a``, ``grad gamma_a`` and per-element terms for particles near a boundary.

    Parameters
    ----------
    boundary : BoundarySegments, BoundaryTriangles, domain or file (see :func:`as_boundary`)
    h : float
        Kernel support radius (BIPI: ``h = 2 h_B``).
    kernel : str
        Kernel name (BIPI: ``"wendland_c2"``, the paper's Wendland "quintic").
    """

    def __init__(self, boundary, h, kernel="wendland_c2"):
        self.boundary = as_boundary(boundary)
        self.dim = self.boundary.dim
        self.h = check_positive("h", h)
        self.tables = RadialTables(kernel, self.dim)
        self.query = BoundaryQuery(self.boundary)
        b = self.boundary
        self._empty2 = np.zeros((1, 1))
        if self.dim == 2:  # normals and centroids with a zero z, connectivity for the point term
            self._nrm = np.ascontiguousarray(np.column_stack([b.normal_sc, np.zeros(len(b))]))
            self._centroid = np.ascontiguousarray(np.column_stack([b.centroid_sc, np.zeros(len(b))]))
            self._next, self._prev = b.next_s, b.prev_s
            self._pseudo = np.zeros((1, 7, 3))
            self._frames = np.zeros((1, 3, EDGE_COLUMNS))
            self._edge_tk, self._n_edges = np.zeros((1, 3), dtype=np.int64), 1
        else:
            self._next = self._prev = np.zeros(1, dtype=np.int64)
            self._pseudo = b.pseudo_normal_tfc
            self._frames = edge_frames(b.packed_tk)  # per-edge geometry, once (not per pair)
            self._edge_tk, self._n_edges = edge_ids(self._frames)  # edges shared by two triangles: integrated once
        self._inside_points = None
        self._inside_p = None
        self.inside_tests = 0
        self._cache = None
        self.reused = 0  # particles whose terms came from the cache in the last compute
        self.block_rows = BLOCK_ROWS  # particles per call of the rows' terms (the values do not depend on it)

    def _inside(self, nlist, r_pc):
        """Inside test of every particle, redone when the neighbour list builds new bins."""
        pts = nlist.points
        reuse = nlist.stored and 0.5 * nlist.skin < self.h
        if not (reuse and self._inside_points is not None and self._inside_points() is pts
                and len(self._inside_p) == len(r_pc)):
            self._inside_p = np.asarray(self.boundary.contains(r_pc), dtype=bool)
            self._inside_points = weakref.ref(pts)  # not keeping old bins alive past a rebuild
            self.inside_tests += 1
        return self._inside_p

    def _unmoved(self, r_pc, band, band_rule):
        """Particles at exactly the position of the last call (same band and rule), or None."""
        c = self._cache
        if c is None or c["r_pc"].shape != r_pc.shape or c["band"] != band or c["rule"] != band_rule:
            return None
        same_p = np.all(c["r_pc"] == r_pc, axis=1)
        return same_p if same_p.any() else None

    def compute(self, nlist, r_pc, terms=False, band=0.0, band_rule="ball", keep_pairs=True, _nudge=True):
        """Boundary terms for particles at ``r_pc`` (N, 3); ``nlist`` updated for them.

        Parameters
        ----------
        nlist : NeighborList
            Its bins are reused for the particle-element query (stored list or one-shot bins).
        terms : bool
            Also return the per-pair terms (``gamma_k``, ``grad_k``, ``delta_k``).
        band : float
            If > 0, also sum ``grad gamma_as`` over the elements within ``band`` (``near_pc``;
            BIPI Eq. 14 with ``band = 0.5 dx_r``).
        band_rule : {"ball", "normal", "centroid"}
            Which parts of the boundary enter ``near_pc``. "ball" (default): the part within
            ``band`` of the particle, ``sum_s n_s int_{s cap B(x_a, band)} W dS``, exact, the limit of
            "centroid" for fine elements; "normal": whole elements with ``|(x_a - x_s) . n_s| < band``
            (the distance to the element's line or plane, as BIPI's Eq. 14 is written);
            "centroid": whole elements with ``|x_a - c_s| < band``, ``c_s`` the centroid (as Eq. 21
            is written; depends on the element size, hence BIPI2D's refinement to ``dx / 10``).
        keep_pairs : bool
            False: the particle-element query runs inside the per-particle loop and no pair arrays are made
            (``pairs`` of the result is None; ``nearest_p`` holds what is kept of them). The same values;
            per particle a row of scratch instead of 24 B per pair (and 24 B per candidate of a stored list).

        Notes
        -----
        A particle at exactly (bit for bit) the position it had in the previous call, with the same
        ``band`` and ``band_rule``, keeps its ``gamma``, ``grad gamma``, band sum and point term
        from that call (issue 17 item 6: BIPI's frozen particles in Step 2c, the unselected ones
        in 2a): the same computation at the same position, so the same value (the boundary and
        ``h`` are fixed per instance). ``terms=True`` always recomputes every particle.
        """
        if band_rule not in BAND_RULES:
            raise ValueError(f"band_rule must be one of {BAND_RULES}, got {band_rule!r}")
        r_pc = np.asarray(r_pc, dtype=float)
        n = len(r_pc)
        # no pair arrays (the query fused into the rows) when none are asked for and every particle's pairs are
        # those of its own sorted point
        source = None if keep_pairs or terms else self.query.sources(nlist, r_pc, self.h)
        pairs = self.query.pairs(nlist, r_pc, self.h) if source is None else None
        m = pairs.n_pairs if pairs is not None else 0
        gamma_k = np.empty(m) if terms else np.empty(0)
        grad_k = np.empty(m) if terms else np.empty(0)
        delta_k = np.empty(m) if terms else np.empty(0)
        sum_p = np.empty(n)
        grad_pc = np.empty((n, 3))
        near_pc = np.empty((n, 3))
        chi_p = np.empty(n)
        nearest_p = np.empty(n)
        t = self.tables
        b = self.boundary
        if self.dim == 2:
            kind, elem, nrm, centroid = 0, b.packed_sk, self._nrm, self._centroid
            tables = (t.breaks, t.fc, t.gc, t.a, self._empty2, self._empty2, 0.0)
            close2 = 0.0
        else:
            kind, elem, nrm, centroid = 1, b.packed_tk, b.normal_tc, b.centroid_tc
            tables = (t.breaks, self._empty2, self._empty2, t.a, t.lp, t.lq, t.p1_one)
            close2 = (NUDGE * self.h) ** 2 if _nudge else 0.0
        same_p = None if terms or not _nudge else self._unmoved(r_pc, float(band), band_rule)
        skip_p = np.zeros(0, dtype=np.bool_) if same_p is None else same_p
        if same_p is not None:
            c = self._cache
            chi_p[same_p] = c["chi_p"][same_p]  # final values: never UNKNOWN or NEAR_SURFACE
            sum_p[same_p] = 0.0
            nearest_p[same_p] = c["nearest_p"][same_p]
        geometry = (elem, nrm, self._frames, self._edge_tk, self._n_edges, centroid, self._next, self._prev,
                    self._pseudo, 1.0 / self.h, *tables, t.sigma, close2, float(band), BAND_RULES.index(band_rule))
        outputs = (sum_p, grad_pc, near_pc, chi_p, nearest_p)
        if pairs is not None:
            # threads by the number of pairs (the work), not of particles: 4000 particles near a mesh are 2e5 pairs
            run_chunks(_ROWS[kind], n, (pairs.x_sc, pairs.start_p, pairs.element_k, pairs.distance_k, pairs.point_k,
                                  *geometry, bool(terms), skip_p, gamma_k, grad_k, delta_k, *outputs,
                                  self.block_rows),
                       nthreads=thread_count(m))
        else:
            x_sc, pts, by_bin, src_start, src_elem, work = source
            run_chunks(_ROWS_FUSED[kind], x_sc.shape[0], (x_sc, pts.src_s, pts.is_ghost_s, pts.bin_s, by_bin,
                                                    src_start, src_elem, self.h * self.h, *geometry, skip_p, *outputs,
                                                    self.block_rows),
                       nthreads=thread_count(work))
            del source, x_sc, src_start, src_elem
        unknown = chi_p == UNKNOWN
        if unknown.any():
            self._resolve_unknown(nlist, r_pc, chi_p, unknown)
        gamma_p = chi_p - sum_p
        close = chi_p == NEAR_SURFACE
        if close.any():
            rows = np.nonzero(close)[0]
            if pairs is None:  # the pairs of these few particles, from a query of their own
                pairs = boundary_pairs(r_pc[close], self.boundary, self.h)
                rows = np.arange(len(rows))
            gamma_p[close] = self._nudged(r_pc[close], pairs, rows)
            chi_p[close] = 1.0 if self.dim == 3 else chi_p[close]
        self.reused = 0 if same_p is None else int(same_p.sum())
        if same_p is not None:
            c = self._cache
            gamma_p[same_p] = c["gamma_p"][same_p]
            grad_pc[same_p] = c["grad_pc"][same_p]
            near_pc[same_p] = c["near_pc"][same_p]
        if _nudge:
            # the outputs themselves, not copies (64 B per particle): they are new arrays of this call, and
            # BoundaryTerms' users read them (a caller that writes into them must copy first); the positions
            # into the last call's copy when it fits (no second copy at once)
            old = self._cache
            self._cache = None
            if old is not None and old["r_pc"].shape == r_pc.shape:
                np.copyto(old["r_pc"], r_pc)
                r_copy = old["r_pc"]
            else:
                r_copy = r_pc.copy()
            del old
            self._cache = dict(r_pc=r_copy, band=float(band), rule=band_rule, gamma_p=gamma_p,
                               grad_pc=grad_pc, near_pc=near_pc, chi_p=chi_p, nearest_p=nearest_p)
        return BoundaryTerms(gamma_p, grad_pc, chi_p, near_pc if band > 0 else None, pairs,
                             gamma_k if terms else None, grad_k if terms else None, delta_k if terms else None,
                             nearest_p=nearest_p)

    def _resolve_unknown(self, nlist, r_pc, chi_p, unknown):
        """``chi`` of the particles with no element within ``h`` (``unknown``), in place.

        With a stored list: the inside test of every particle, made once per bins (:meth:`_inside`). Without
        one (one-shot bins, a new grid at every call): a particle that moved less than ``h`` since the last
        call, where it was inside (or outside), still is (the straight path from there would have met the
        surface, which is farther than ``h`` from it now), and keeps that ``chi``; only the others are tested.
        """
        c = self._cache
        if nlist.stored or c is None or c["r_pc"].shape != r_pc.shape:
            chi_p[unknown] = self._inside(nlist, r_pc)[unknown]
            return
        left = _inherit_chi(chi_p, r_pc, c["r_pc"], c["chi_p"], self.h * self.h)
        if left:
            rest = np.nonzero(chi_p == UNKNOWN)[0]
            chi_p[rest] = np.asarray(self.boundary.contains(r_pc[rest]), dtype=bool)
            self.inside_tests += 1

    def _nudged(self, r_pc, pairs, rows):
        """3D gamma of points within NUDGE h of the surface, from a point NUDGE h inside it.

        The point moves to ``y = q + NUDGE h m``, with ``q`` its closest surface point and ``m`` the
        inward pseudo-normal of the closest feature (face, edge or vertex), and
        ``gamma(x) = gamma(y) + grad gamma(y) . (x - y) + O(|x - y|^2)`` (gamma is C^1 with a
        Lipschitz gradient across the surface).
        """
        from ..neighbors import NeighborList

        b = self.boundary
        moved = r_pc.copy()
        for i, p in enumerate(rows):
            best = (np.inf, None)
            for k in range(pairs.start_p[p], pairs.start_p[p + 1]):
                t = pairs.element_k[k]
                d2, qx, qy, qz, f = closest_on_triangle(*r_pc[i], b.packed_tk[t])
                if d2 < best[0]:
                    best = (d2, (np.array([qx, qy, qz]), t, f))
            q, t, f = best[1]
            # within a few moves of a vertex, move from the vertex (along an edge's or the face's normal the
            # move could leave through a neighbouring face of a sharp vertex, e.g. a tetrahedron's)
            gap_c = b.vertices_tkc[t] - q
            corner = int(np.argmin(np.einsum("kc,kc->k", gap_c, gap_c)))
            if f > 2 and np.linalg.norm(gap_c[corner]) < 10.0 * NUDGE * self.h:
                q, f = b.vertices_tkc[t, corner], corner
            elif f == 6:
                # near an edge, move from the edge along its pseudo-normal: along the face's normal the move
                # leaves through the other face of an edge sharper than 90 degrees (a tetrahedron's: 70.5)
                q, f = _edge_start(q, b.vertices_tkc[t], 10.0 * NUDGE * self.h)
            m = b.pseudo_normal_tfc[t, f]
            moved[i] = q + NUDGE * self.h * m / np.linalg.norm(m)
        nlist = NeighborList(self.h)
        nlist.update(moved, b.cell, b.pbc, store=False)
        out = self.compute(nlist, moved, _nudge=False)
        if np.any(out.chi_p != 1.0):
            raise FloatingPointError("a point moved inside the surface is not inside (degenerate mesh?)")
        return out.gamma_p + np.einsum("pc,pc->p", out.grad_gamma_pc, r_pc - moved)


def _edge_start(q_c, v_kc, reach):
    """``(q, 6)``, or the foot of ``q`` on the triangle's nearest edge and that edge's feature (3 ab, 4 ac,
    5 bc, as :func:`~ase_sphrelax.domains.closest.closest_on_triangle`) when it is closer than ``reach``."""
    best, out = reach, (q_c, 6)
    for feature, (i, k) in zip((3, 4, 5), ((0, 1), (0, 2), (1, 2))):
        edge_c = v_kc[k] - v_kc[i]
        foot_c = v_kc[i] + np.clip((q_c - v_kc[i]) @ edge_c / (edge_c @ edge_c), 0.0, 1.0) * edge_c
        gap = np.linalg.norm(q_c - foot_c)
        if gap < best:
            best, out = gap, (foot_c, feature)
    return out


def _positions(r_pc, dim):
    r = np.asarray(r_pc, dtype=float)
    if r.ndim != 2 or r.shape[1] not in (dim, 3) or r.shape[0] == 0:
        raise ValueError(f"r_pc must have shape (N, 3) or (N, {dim}) with N >= 1, got {np.shape(r_pc)}")
    if not np.all(np.isfinite(r)):
        raise ValueError("r_pc must be finite")
    out = np.zeros((len(r), 3))
    out[:, : r.shape[1]] = r
    if dim == 2 and r.shape[1] == 3 and np.any(r[:, 2] != 0.0):
        raise ValueError("r_pc: a 2D boundary needs particles at z = 0 (dimension mismatch; got z != 0)")
    return out


def boundary_terms(r_pc, boundary, h, kernel="wendland_c2", band=0.0, band_rule="ball"):
    """One-shot :class:`BoundaryTerms` (per-pair terms included) for particles at ``r_pc``."""
    from ..neighbors import NeighborList

    integrals = BoundaryIntegrals(boundary, h, kernel)
    r = _positions(r_pc, integrals.dim)
    nlist = NeighborList(integrals.h)
    nlist.update(r, integrals.boundary.cell, integrals.boundary.pbc, store=False)  # periodic images of the boundary
    return integrals.compute(nlist, r, terms=True, band=band, band_rule=band_rule)


def gamma_and_gradient(r_pc, segments, h, kernel="wendland_c2"):
    """Kernel volume fraction and its gradient at particles ``r_pc`` (BIPI Eq. 2-3).

    Parameters
    ----------
    r_pc : array (N, 3) or (N, dim)
        Positions (2D: z = 0).
    segments : BoundarySegments, BoundaryTriangles, domain or file (see :func:`as_boundary`)
    h : float
        Kernel **support** radius (BIPI's ``h_B = h / 2``).
    kernel : str

    Returns
    -------
    gamma_p : ndarray (N,)
        ``gamma_a = int_{Omega cap B(x_a, h)} W(|x_a - y|, h) dy``.
    grad_gamma_pc : ndarray (N, 3)
        ``grad gamma_a = sum_s int_s W n_s dS`` with inward normals ``n_s``.
    """
    out = boundary_terms(r_pc, segments, h, kernel)
    return out.gamma_p, out.grad_gamma_pc
