"""O(N) cell-list neighbour search with periodic images and a Verlet skin.

The search works on an *extended* set of points: the particles themselves
(wrapped into the cell along periodic axes) followed by ghost copies, the
periodic images that lie within ``cutoff + skin`` of the cell. Ghosts make any
ASE cell work the same way: orthogonal or skewed, and cells smaller than the
cut-off (several images of one particle). The extended points are sorted by bin
so that the hot loops read memory in order.

Each physical pair (i, j, image) is stored exactly once, as a half list in CSR
form over the sorted extended points: ``pair_j[pair_start[a]:pair_start[a+1]]``
are the partners ``b`` of point ``a``. A pair with a ghost is kept only in its
canonical orientation (original ``i`` < source ``j``, or for a particle and its
own image, the lexicographically positive image), so energies and forces are
never double counted. Calculators evaluate on :meth:`NeighborList.extend`
positions and fold ghost forces back with :meth:`NeighborList.fold`.

The list is built with ``cutoff + skin`` and reused until some particle moved
more than ``skin / 2`` (or the cell, pbc, particle number or cut-offs change).
Per-particle cut-offs are supported: a pair is listed if
``r < max(cutoff_i, cutoff_j) + skin``.

A (re)build bins the points and leaves the list scan *pending*: the next pair sum of
:mod:`ase_sphrelax.pairs` runs one bin scan that writes the list and evaluates its pairs
(:meth:`NeighborList.fused_build`); reading ``pair_start``/``pair_j`` or moving the
points first completes it alone, from the positions of the build. The scan is one pass
(no count pass): each thread's chunk of points writes into its own region of a pair
buffer kept between builds, the regions are then closed up. Bins have an edge of
``reach / 2`` in 2D and 3D and are scanned as rows of consecutive bins (one contiguous
range of sorted points each), bins beyond reach left out.

With cut-offs spanning orders of magnitude the bins are sized by a typical reach, and the
few points of larger reach scan their own full stencils (:class:`BinnedPoints`,
:func:`bin_reach`): a rebuild stays O(N).
"""
from __future__ import annotations

import ctypes
import inspect
import itertools
import sys

import numba
import numpy as np
from numba.core import types
from numba.extending import overload

from .checks import check_skin
from .parallel import PARALLEL_MIN, chunk_bounds, reduce_chunks, run_chunks, thread_count, thread_pool

__all__ = ["NeighborList", "BinnedPoints", "PARALLEL_MIN", "complete_cell", "is_canonical_pair", "bin_coords",
           "stencil_range", "stencil_rows", "finds_pair", "point_room", "bin_reach", "SCAN_HELPERS"]


def complete_cell(cell, pbc):
    """Return a rank-3 version of ``cell`` and its inverse.

    Zero vectors on non-periodic axes (a 2D sheet with ``c = 0``, or a free
    cluster with no cell) are replaced by unit vectors orthogonal to the others.
    A zero or degenerate vector on a periodic axis raises ``ValueError``.
    """
    cell = np.array(cell, dtype=float).reshape(3, 3)
    pbc = np.asarray(pbc, dtype=bool)
    lengths = np.linalg.norm(cell, axis=1)
    for axis in range(3):
        if lengths[axis] == 0.0:
            if pbc[axis]:
                raise ValueError(f"cell vector {axis} is zero but pbc[{axis}] is True")
            cell[axis] = np.eye(3)[axis]
    if abs(np.linalg.det(cell)) < 1e-12 * max(1.0, np.prod(np.linalg.norm(cell, axis=1))):
        # replace non-periodic vectors by an orthonormal completion
        for axis in np.where(~pbc)[0]:
            others = [cell[k] for k in range(3) if k != axis]
            normal = np.cross(*others)
            if np.linalg.norm(normal) == 0.0:
                normal = np.eye(3)[axis]
            cell[axis] = normal / np.linalg.norm(normal)
        if abs(np.linalg.det(cell)) < 1e-12:
            raise ValueError("cell is degenerate along its periodic axes")
    return cell, np.linalg.inv(cell)


def _check_positions(positions, columns=3, finite=True):
    """Positions as a float array (N, columns), N >= 1 (``columns=None``: any D >= 1); finite unless told not."""
    r_pc = np.asarray(positions, dtype=float)
    if r_pc.ndim != 2 or (r_pc.shape[1] != columns if columns else r_pc.shape[1] < 1):
        raise ValueError(f"positions must have shape (N, {columns or 'D'}), got {r_pc.shape}")
    if r_pc.shape[0] == 0:
        raise ValueError("positions: need at least one particle, got none")
    if finite and not np.all(np.isfinite(r_pc)):
        bad = np.where(~np.all(np.isfinite(r_pc), axis=1))[0]
        raise ValueError(f"positions must be finite; particles {bad[:10].tolist()} are NaN or inf")
    return r_pc


@numba.njit(cache=True, inline="always")
def _image_position(r_pc, p, img0, img1, img2, cell_cc, c):
    """Coordinate c of particle p's image (integer image vector, wrap included)."""
    return r_pc[p, c] + img0 * cell_cc[0, c] + img1 * cell_cc[1, c] + img2 * cell_cc[2, c]


@numba.njit(cache=True, nogil=True)
def _bounds_chunk(r_pc, out, first, last):
    """out[0:3] = min(out[0:3], min of x_c), out[3:6] = min(out[3:6], min of -x_c) over the points [first, last)."""
    for p in range(first, last):
        for c in range(3):
            x = r_pc[p, c]
            out[c] = min(out[c], x)
            out[3 + c] = min(out[3 + c], -x)


def _extended_points(r_pc, cell_cc, inv_cc, pbc_c, pad_c, layers_c):
    """:func:`_extended_points_general`; without a periodic axis (no wrap, no ghost: the particles themselves, their
    bounding box found in chunks on the threads), 0.1x its time at 1e6 particles, a serial pass of every rebuild."""
    if np.any(pbc_c):
        return _extended_points_general(r_pc, cell_cc, inv_cc, pbc_c, pad_c, layers_c)
    n = r_pc.shape[0]
    outs = reduce_chunks(_bounds_chunk, n, (r_pc,), 6, fill=np.inf)
    low = np.min(outs, axis=0)
    return np.arange(n, dtype=np.int32), np.zeros((n, 3), dtype=np.int32), low[:3].copy(), -low[3:]


@numba.njit(cache=True)
def _extended_points_general(r_pc, cell_cc, inv_cc, pbc_c, pad_c, layers_c):
    """Particles wrapped into the cell along periodic axes, followed by ghosts:
    periodic images within ``pad`` (fractional units) of the unit cell.

    Returns (src_e, img_ec, lo_c, hi_c): source particle and integer image vector
    (including the wrap) of every extended point, and the bounding box of their
    positions. Positions are not stored: they follow from the images
    (:func:`_image_position`), as in every later pass.
    """
    n = r_pc.shape[0]
    lx, ly, lz = layers_c[0], layers_c[1], layers_c[2]
    src_e = np.empty(0, dtype=np.int32)
    img_ec = np.empty((0, 3), dtype=np.int32)
    lo_c = np.full(3, np.inf)
    hi_c = np.full(3, -np.inf)
    for sweep in range(2):
        count = n
        for p in range(n):
            f0 = r_pc[p, 0] * inv_cc[0, 0] + r_pc[p, 1] * inv_cc[1, 0] + r_pc[p, 2] * inv_cc[2, 0]
            f1 = r_pc[p, 0] * inv_cc[0, 1] + r_pc[p, 1] * inv_cc[1, 1] + r_pc[p, 2] * inv_cc[2, 1]
            f2 = r_pc[p, 0] * inv_cc[0, 2] + r_pc[p, 1] * inv_cc[1, 2] + r_pc[p, 2] * inv_cc[2, 2]
            w0 = -np.floor(f0) if pbc_c[0] else 0.0
            w1 = -np.floor(f1) if pbc_c[1] else 0.0
            w2 = -np.floor(f2) if pbc_c[2] else 0.0
            f0 += w0
            f1 += w1
            f2 += w2
            if sweep == 1:
                src_e[p] = p
                img_ec[p, 0], img_ec[p, 1], img_ec[p, 2] = int(w0), int(w1), int(w2)
                for c in range(3):
                    x = _image_position(r_pc, p, w0, w1, w2, cell_cc, c)
                    lo_c[c] = min(lo_c[c], x)
                    hi_c[c] = max(hi_c[c], x)
            for sx in range(-lx, lx + 1):
                fx = f0 + sx
                if pbc_c[0] and (fx < -pad_c[0] or fx >= 1.0 + pad_c[0]):
                    continue
                for sy in range(-ly, ly + 1):
                    fy = f1 + sy
                    if pbc_c[1] and (fy < -pad_c[1] or fy >= 1.0 + pad_c[1]):
                        continue
                    for sz in range(-lz, lz + 1):
                        if sx == 0 and sy == 0 and sz == 0:
                            continue
                        fz = f2 + sz
                        if pbc_c[2] and (fz < -pad_c[2] or fz >= 1.0 + pad_c[2]):
                            continue
                        if sweep == 1:
                            src_e[count] = p
                            i0, i1, i2 = w0 + sx, w1 + sy, w2 + sz
                            img_ec[count, 0], img_ec[count, 1], img_ec[count, 2] = int(i0), int(i1), int(i2)
                            for c in range(3):
                                x = _image_position(r_pc, p, i0, i1, i2, cell_cc, c)
                                lo_c[c] = min(lo_c[c], x)
                                hi_c[c] = max(hi_c[c], x)
                        count += 1
        if sweep == 0:
            src_e = np.empty(count, dtype=np.int32)
            img_ec = np.empty((count, 3), dtype=np.int32)
    return src_e, img_ec, lo_c, hi_c


@numba.njit(cache=True, nogil=True)
def _bin_count_chunk(r_pc, cell_cc, src_e, img_ec, origin_c, binsize, nbin_c, wide_p, groups, bin_e, count_k,
                     first, last):
    """The bin of each extended point e in [first, last) into bin_e; count_k[key + 1] += 1 per point (key: the
    bin, after all the normal bins for a wide point when ``groups == 2``)."""
    nbins = nbin_c[0] * nbin_c[1] * nbin_c[2]
    inv_bs = 1.0 / binsize
    for e in range(first, last):
        p = src_e[e]
        b = 0
        for c in range(3):
            x = _image_position(r_pc, p, img_ec[e, 0], img_ec[e, 1], img_ec[e, 2], cell_cc, c)
            k = min(max(int((x - origin_c[c]) * inv_bs), 0), nbin_c[c] - 1)
            b = b * nbin_c[c] + k
        bin_e[e] = b
        count_k[b + (nbins if groups == 2 and wide_p[p] else 0) + 1] += 1


@numba.njit(cache=True)
def _bin_cursors(count_tk):
    """From each thread's counts (``count_tk[t, key + 1]``): where each key starts (returned) and, in place, where
    thread t writes its first point of each key (``count_tk[t, key]``): key by key, thread by thread, the order of a
    one-thread counting sort."""
    nthreads, size = count_tk.shape
    start_k = np.empty(size, dtype=np.int64)
    start_k[0] = 0
    run = 0
    for key in range(size - 1):
        for t in range(nthreads):
            c = count_tk[t, key + 1]  # read before the cursor of key + 1 is written (next key)
            count_tk[t, key] = run
            run += c
        start_k[key + 1] = run
    return start_k


@numba.njit(cache=True, nogil=True)
def _bin_place_chunk(src_e, bin_e, wide_p, groups, nbins, cursor_k, order, bin_s, first, last):
    for e in range(first, last):
        b = bin_e[e]
        key = b + (nbins if groups == 2 and wide_p[src_e[e]] else 0)
        pos = cursor_k[key]
        order[pos] = e
        bin_s[pos] = b
        cursor_k[key] = pos + 1


def _bin_sort(r_pc, cell_cc, src_e, img_ec, origin_c, binsize, nbin_c, wide_p, groups):
    """Counting sort of the extended points into bins; returns (order_s, bin_start, bin_s).

    With ``groups == 2`` the points of wide particles (``wide_p``) come after all the others,
    sorted by the same bins: ``bin_start[nbins + b]`` starts wide bin b. ``bin_s`` is the bin.
    Stable (each bin's points in the order of the extended points), counted and placed in
    :func:`thread_count` chunks (each thread its own counts and cursors).
    """
    n = src_e.shape[0]
    nbins = int(np.prod(nbin_c))
    nthreads = thread_count(n)
    bin_e = np.empty(n, dtype=np.int32)
    count_tk = np.zeros((nthreads, groups * nbins + 1), dtype=np.int64)
    run_chunks(_bin_count_chunk, n, (r_pc, cell_cc, src_e, img_ec, origin_c, float(binsize), nbin_c, wide_p, groups,
                                     bin_e), per_thread=[(count_tk[t],) for t in range(nthreads)])
    bin_start = _bin_cursors(count_tk)
    order = np.empty(n, dtype=np.int32)
    bin_s = np.empty(n, dtype=np.int32)
    run_chunks(_bin_place_chunk, n, (src_e, bin_e, wide_p, groups, nbins), per_thread=[
        (count_tk[t], order, bin_s) for t in range(nthreads)])
    return order, bin_start, bin_s


@numba.njit(cache=True, nogil=True)
def _sorted_arrays_chunk(order_s, src_e, img_ec, r_pc, cell_cc, cut_p, src_s, img_sc, x_sc, is_ghost_s, cut_s,
                         first, last):
    """Per sorted extended point s in [first, last): source, image, position, ghost flag and cut-off."""
    n = r_pc.shape[0]
    for s in range(first, last):
        e = order_s[s]
        p = src_e[e]
        src_s[s] = p
        is_ghost_s[s] = e >= n
        cut_s[s] = cut_p[p]
        for c in range(3):
            img_sc[s, c] = img_ec[e, c]
        for c in range(3):
            x_sc[s, c] = _image_position(r_pc, p, img_sc[s, 0], img_sc[s, 1], img_sc[s, 2], cell_cc, c)


def _sorted_arrays(order_s, src_e, img_ec, r_pc, cell_cc, cut_p):
    """(src_s, img_sc, x_sc, is_ghost_s, cut_s) of the sorted extended points."""
    n_ext = order_s.shape[0]
    out = (np.empty(n_ext, dtype=np.int32), np.empty((n_ext, 3), dtype=np.int32), np.empty((n_ext, 3)),
           np.empty(n_ext, dtype=np.bool_), np.empty(n_ext))
    run_chunks(_sorted_arrays_chunk, n_ext, (order_s, src_e, img_ec, r_pc, cell_cc, cut_p) + out)
    return out


@numba.njit(cache=True, nogil=True)
def _gather_chunk(r_pc, src_s, img_sc, cell_cc, x_sc, first, last):
    """x_s = position of image img_s of particle src_s, for s in [first, last), written into x_sc."""
    for s in range(first, last):
        p = src_s[s]
        for c in range(3):
            x_sc[s, c] = _image_position(r_pc, p, img_sc[s, 0], img_sc[s, 1], img_sc[s, 2], cell_cc, c)


@numba.njit(cache=True, inline="always")
def is_canonical_pair(a, b, src_s, img_sc, is_ghost_s):
    """True if extended points a, b represent their physical pair in canonical form.

    Two originals: always. Two ghosts: never (the pair appears with an original).
    An original o and a ghost g: only if src_o < src_g, or for a particle and its own
    image, if the image shift img_g - img_o is lexicographically positive.
    """
    ga = is_ghost_s[a]
    gb = is_ghost_s[b]
    if not (ga or gb):
        return True
    if ga and gb:
        return False
    sign = -1.0 if ga else 1.0
    i = src_s[b] if ga else src_s[a]  # the original
    j = src_s[a] if ga else src_s[b]  # the ghost's source
    if i != j:
        return i < j
    for c in range(3):
        shift = sign * (img_sc[b, c] - img_sc[a, c])
        if shift != 0.0:
            return shift > 0.0
    return False


def _half_stencil(m, nbin_c, binsize, reach):
    """Forward half of the bin stencil as rows of bins, a (K, 6) array.

    Bins of edge ``binsize >= reach / m`` are scanned within ``m`` bins of the own bin.
    Bins that are consecutive along the *row axis* (the last axis with more than one bin)
    are consecutive in the sorted order, so each entry is one row of bins, one contiguous
    range of points: columns 0-2 are the bin offset (x, y, z) of the row's first bin,
    columns 3-5 that of its last. The rows cover every bin offset that is lexicographically
    positive (the own bin itself, with b > a, is the scan's entry -1), without offsets
    along axes that have a single bin, and without the bins that lie entirely beyond
    ``reach`` of the own bin.
    """
    spread = [c for c in range(3) if nbin_c[c] > 1]
    if not spread:
        return np.zeros((0, 6), dtype=np.int64)
    row = spread[-1]
    others = [range(-m, m + 1) if c in spread and c != row else range(1) for c in range(3)]
    rows = []
    for o in itertools.product(*others):
        across = sum(max(abs(k) - 1, 0) ** 2 for k in o) * binsize**2
        if across >= reach**2:
            continue
        # longest span along the row whose end bins are still within reach
        span = max(s for s in range(m + 1) if across + max(s - 1, 0) ** 2 * binsize**2 < reach**2)
        lo, hi = list(o), list(o)
        lo[row], hi[row] = -span, span
        if tuple(o) == (0, 0, 0):  # own row: only the bins after the own bin
            if span == 0:
                continue
            lo[row] = 1
        elif tuple(o) < (0, 0, 0):
            continue
        rows.append(lo + hi)
    return np.array(sorted(rows), dtype=np.int64).reshape(-1, 6)


@numba.njit(cache=True, inline="always")
def bin_coords(a, bin_s, nbin_c):
    """Integer bin coordinates (kx, ky, kz) of sorted point a."""
    nby, nbz = nbin_c[1], nbin_c[2]
    return bin_s[a] // (nbz * nby), (bin_s[a] // nbz) % nby, bin_s[a] % nbz


@numba.njit(cache=True, inline="always")
def _wide_frame(a, kx, ky, kz, nbin_c, stencil):
    """The rows of wide point a's full stencil: (reach, m, x0, x1, y0, y1, z0, z1, rows per grid).

    Its bins lie within ``m = int(reach / binsize) + 1`` bins of the own bin (clipped to the grid);
    one row per bin offset across the row axis (the last axis with several bins, which has
    the single offset 0 here), for each of the two groups of points (normal, wide).
    """
    row, binsize, reach_w = stencil[2], stencil[3], stencil[4]
    reach = reach_w[a - stencil[1]]
    m = int(reach / binsize) + 1
    x0, x1 = (0, 0) if row == 0 else (max(kx - m, 0) - kx, min(kx + m, nbin_c[0] - 1) - kx)
    y0, y1 = (0, 0) if row == 1 else (max(ky - m, 0) - ky, min(ky + m, nbin_c[1] - 1) - ky)
    z0, z1 = (0, 0) if row == 2 else (max(kz - m, 0) - kz, min(kz + m, nbin_c[2] - 1) - kz)
    return reach, m, x0, x1, y0, y1, z0, z1, (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1)


@numba.njit(cache=True, inline="always")
def _wide_range(a, k, kx, ky, kz, nbin_c, bin_start, stencil):
    """Sorted points [lo, hi) of full-stencil row k >= 0 of wide point a (see :func:`_wide_frame`)."""
    reach, m, x0, x1, y0, y1, z0, z1, per_group = _wide_frame(a, kx, ky, kz, nbin_c, stencil)
    row, binsize = stencil[2], stencil[3]
    group = k // per_group
    r = k - group * per_group
    ny, nz = y1 - y0 + 1, z1 - z0 + 1
    ox = x0 + r // (ny * nz)
    oy = y0 + (r // nz) % ny
    oz = z0 + r % nz
    gx, gy, gz = max(abs(ox) - 1, 0), max(abs(oy) - 1, 0), max(abs(oz) - 1, 0)  # whole bins between
    across = float(gx * gx + gy * gy + gz * gz) * binsize * binsize
    if across >= reach * reach:
        return 0, 0
    span = min(m, int(np.sqrt(reach * reach - across) / binsize) + 1)  # bins along the row within reach
    lx, hx, ly, hy, lz, hz = kx + ox, kx + ox, ky + oy, ky + oy, kz + oz, kz + oz
    if row == 0:
        lx, hx = max(kx - span, 0), min(kx + span, nbin_c[0] - 1)
    elif row == 1:
        ly, hy = max(ky - span, 0), min(ky + span, nbin_c[1] - 1)
    else:
        lz, hz = max(kz - span, 0), min(kz + span, nbin_c[2] - 1)
    offset = group * nbin_c[0] * nbin_c[1] * nbin_c[2]
    return (bin_start[offset + (lx * nbin_c[1] + ly) * nbin_c[2] + lz],
            bin_start[offset + (hx * nbin_c[1] + hy) * nbin_c[2] + hz + 1])


@numba.njit(cache=True, inline="always")
def _half_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil_kc):
    """Sorted points [lo, hi) of half-stencil row k of normal point a in bin (kx, ky, kz).

    k = -1 is the own bin with b > a; a row is clipped to the bin grid (an empty range
    when it lies outside).
    """
    if k < 0:
        return a + 1, bin_start[bin_s[a] + 1]
    x0 = max(kx + stencil_kc[k, 0], 0)
    x1 = min(kx + stencil_kc[k, 3], nbin_c[0] - 1)
    y0 = max(ky + stencil_kc[k, 1], 0)
    y1 = min(ky + stencil_kc[k, 4], nbin_c[1] - 1)
    z0 = max(kz + stencil_kc[k, 2], 0)
    z1 = min(kz + stencil_kc[k, 5], nbin_c[2] - 1)
    if x0 > x1 or y0 > y1 or z0 > z1:
        return 0, 0
    return bin_start[(x0 * nbin_c[1] + y0) * nbin_c[2] + z0], bin_start[(x1 * nbin_c[1] + y1) * nbin_c[2] + z1 + 1]


# The scans' stencil helpers below take ``stencil`` = :attr:`BinnedPoints.stencil`: the half
# stencil array alone when the bins are sized by the largest cut-off (no wide points), else the
# tuple of the wide path. numba compiles a scan for each of the two types: with the array, the
# helpers are those of a uniform cut-off (the wide path costs nothing there).


def stencil_rows(a, kx, ky, kz, nbin_c, stencil):
    """Number of stencil rows k = 0, 1, ... of point a in bin (kx, ky, kz) (row -1 is the own bin):
    the half stencil's for a normal point, the full stencil's of its own reach for a wide one.
    (numba only.)"""
    raise NotImplementedError("stencil_rows is called from numba code only")


@overload(stencil_rows, inline="always")
def _stencil_rows(a, kx, ky, kz, nbin_c, stencil):
    if isinstance(stencil, types.Array):
        return lambda a, kx, ky, kz, nbin_c, stencil: stencil.shape[0]

    def wide(a, kx, ky, kz, nbin_c, stencil):
        if a < stencil[1]:
            return stencil[0].shape[0]
        return 2 * _wide_frame(a, kx, ky, kz, nbin_c, stencil)[8]
    return wide


def stencil_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil):
    """Sorted points [lo, hi) of stencil row k of point a in bin (kx, ky, kz).

    For a normal point, row k of the forward half stencil (:func:`_half_range`; k = -1 is
    the own bin with b > a). For a wide point (``a >= stencil[1]``), row k of its full stencil
    (:func:`_wide_range`), row -1 empty. (numba only.)
    """
    raise NotImplementedError("stencil_range is called from numba code only")


@overload(stencil_range, inline="always")
def _stencil_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil):
    if isinstance(stencil, types.Array):
        return lambda a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil: _half_range(
            a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil)

    def wide(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil):
        if a >= stencil[1]:
            if k < 0:
                return 0, 0
            return _wide_range(a, k, kx, ky, kz, nbin_c, bin_start, stencil)
        return _half_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil[0])
    return wide


def finds_pair(a, b, stencil):
    """True if the scan of a keeps the pair (a, b) that its stencil reached: each pair is found once,
    by the point of the larger reach (of two wide points of equal reach, the later one).
    A normal point's stencil reaches only normal points b > a. (numba only.)"""
    raise NotImplementedError("finds_pair is called from numba code only")


@overload(finds_pair, inline="always")
def _finds_pair(a, b, stencil):
    if isinstance(stencil, types.Array):
        return lambda a, b, stencil: True

    def wide(a, b, stencil):
        n_norm = stencil[1]
        if b < n_norm:
            return True
        reach_w = stencil[4]
        ra, rb = reach_w[a - n_norm], reach_w[b - n_norm]
        return rb < ra or (rb == ra and b < a)
    return wide


def point_room(a, room, stencil):
    """Most candidates of point a: ``room`` for a normal point, every point for a wide one. (numba only.)"""
    raise NotImplementedError("point_room is called from numba code only")


@overload(point_room, inline="always")
def _point_room(a, room, stencil):
    if isinstance(stencil, types.Array):
        return lambda a, room, stencil: room
    return lambda a, room, stencil: room if a < stencil[1] else stencil[5]


# what the scans generated by :mod:`ase_sphrelax.pairs` call and inline, and the source they inline
SCAN_HELPERS = {f.__name__: f for f in (bin_coords, stencil_rows, stencil_range, finds_pair, point_room,
                                        is_canonical_pair, _half_range)}
SCAN_SOURCE = "".join(inspect.getsource(getattr(f, "py_func", f)) for f in (
    bin_coords, is_canonical_pair, _wide_frame, _wide_range, _half_range, _stencil_rows, _stencil_range,
    _finds_pair, _point_room))


@numba.njit(cache=True, nogil=True)
def _partner_end(partners, count, last):
    """1 + the largest of ``partners[:count]`` (the partners of a chunk of points ending at
    ``last``), at least ``last``."""
    end = last
    for p in range(count):
        if partners[p] >= end:
            end = partners[p] + 1
    return end


@numba.njit(cache=True, nogil=True)
def _partner_end_chunk(pair_start, pair_j, out, t, first, last):
    """out[t] = 1 + the largest listed partner of the points [first, last) (at least ``last``)."""
    out[t] = _partner_end(pair_j[pair_start[first]:pair_start[last]], pair_start[last] - pair_start[first], last)


@numba.njit(cache=True, nogil=True)
def _scan_pairs_chunk(x_sc, cut_s, src_s, img_sc, is_ghost_s, skin, bin_s, nbin_c, bin_start, stencil,
                      count_s, pair_j, pos, first, last):
    """Half-stencil bin scan in one pass: the partners of the points [first, last) are appended
    to ``pair_j`` from ``pos`` on, and ``count_s[a + 1]`` is set to the number of partners of a.

    A pair is listed if r < max(cut_a, cut_b) + skin, at most one of the two is a ghost, and
    (for original-ghost pairs) it is the canonical orientation. ``stencil`` is
    :attr:`BinnedPoints.stencil`: a normal point scans the forward half stencil (the own bin
    for b > a), a wide point its full stencil, keeping the pairs it finds (:func:`finds_pair`).

    Returns ``(a_next, pos)``: ``a_next == last`` when done; otherwise ``pair_j`` was full and
    the scan stopped before point ``a_next`` (``pos`` is where its partners go): the caller
    grows the buffer and calls again from ``a_next``.
    """
    cap = pair_j.shape[0]
    for a in range(first, last):
        xa0, xa1, xa2 = x_sc[a, 0], x_sc[a, 1], x_sc[a, 2]
        ca = cut_s[a]
        kx, ky, kz = bin_coords(a, bin_s, nbin_c)
        start = pos
        for k in range(-1, stencil_rows(a, kx, ky, kz, nbin_c, stencil)):
            lo, hi = stencil_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil)
            for b in range(lo, hi):
                d0 = x_sc[b, 0] - xa0
                d1 = x_sc[b, 1] - xa1
                d2 = x_sc[b, 2] - xa2
                rc = max(ca, cut_s[b]) + skin
                if d0 * d0 + d1 * d1 + d2 * d2 >= rc * rc:
                    continue
                if not is_canonical_pair(a, b, src_s, img_sc, is_ghost_s) or not finds_pair(a, b, stencil):
                    continue
                if pos >= cap:
                    return a, start
                pair_j[pos] = b
                pos += 1
        count_s[a + 1] = pos - start
    return last, pos


def _gather(r_pc, src_s, img_sc, cell_cc, x_sc):
    run_chunks(_gather_chunk, src_s.shape[0], (r_pc, src_s, img_sc, cell_cc, x_sc))
    return x_sc


def _scan_chunk_growing(scan, t, count_s, region, first, last):
    """Chunk ``t`` of a one-pass list scan into ``region``, continued in a grown copy
    whenever it fills up. ``scan(t, count_s, region, pos, first, last) -> (a_next, pos)``.
    Returns (array holding the chunk's partners, number written, grown?, 1 + the largest
    partner: see :meth:`NeighborList.partner_ends`, found here while the partners are in cache)."""
    a, pos = scan(t, count_s, region, 0, first, last)
    grown = False
    while a < last:
        bigger = np.empty(int(1.5 * region.shape[0]) + 1024, dtype=region.dtype)
        bigger[:pos] = region[:pos]
        region, grown = bigger, True
        a, pos = scan(t, count_s, region, pos, a, last)
    return region, pos, grown, int(_partner_end(region, pos, last))


_COPY_CHUNK = 1 << 20  # bytes copied between two releases
# partners a thread of a one-shot plain scan lists before it writes over them (int32: 1 MiB, in cache)
ONE_SHOT_REGION = 1 << 18
_MADV_DONTNEED = 4  # Linux


def _libc_function(name, argtypes, use_errno=False):
    """libc's function ``name`` returning int, with its ctypes argument types (Linux), or None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = getattr(ctypes.CDLL(None, use_errno=use_errno), name)
    except (OSError, AttributeError):
        return None
    fn.argtypes = argtypes
    fn.restype = ctypes.c_int
    return fn


_MADVISE = _libc_function("madvise", (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int), use_errno=True)
_PAGE = 4096
_MALLOC_TRIM = _libc_function("malloc_trim", (ctypes.c_size_t,))  # glibc's
_MALLOPT = _libc_function("mallopt", (ctypes.c_int, ctypes.c_int))  # glibc's
_M_MMAP_THRESHOLD = -3


def set_mmap_threshold(nbytes):
    """Fix glibc's mmap threshold at ``nbytes`` (``mallopt(M_MMAP_THRESHOLD)``, process-wide; it also ends glibc's
    dynamic threshold): True when set, False elsewhere than glibc."""
    return _MALLOPT is not None and bool(_MALLOPT(_M_MMAP_THRESHOLD, nbytes))


def release_free_memory():
    """Give the heap's free pages back to the system (glibc ``malloc_trim(0)``; elsewhere a no-op). Arrays of a
    few MB that numpy frees go back to the heap, whose free pages glibc keeps: measured in the ALARIC 2D step at
    1e5, 200-330 bytes per particle of the resident set between two steps were such pages."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


def _copy_releasing(dst, src):
    """``dst[:] = src`` for 1D contiguous arrays, chunk by chunk, giving the whole pages of ``src`` already copied
    back to the system (``madvise(MADV_DONTNEED)``; they read as zeros afterwards): for a source that is dropped
    after the copy, the peak holds one copy and a chunk, not two. Elsewhere than Linux, a plain copy."""
    # a small source (a list of 1-4 MB at 1e4-3e4 particles) in sixteenths: whole, both copies were resident at once
    # (BIPI 2D at 3e4: about 117 B per particle more at each build, reproductions/speed-scale-memory-2d)
    chunk = min(_COPY_CHUNK, max(src.nbytes // 16, 16 * _PAGE))
    if _MADVISE is None or src.nbytes < 4 * chunk or not src.flags.c_contiguous:
        dst[:] = src
        return
    step = chunk // src.itemsize
    base = src.ctypes.data
    released = -(-base // _PAGE) * _PAGE  # the first whole page of src
    for lo in range(0, src.shape[0], step):
        hi = min(lo + step, src.shape[0])
        dst[lo:hi] = src[lo:hi]
        done = (base + hi * src.itemsize) // _PAGE * _PAGE  # the end of the last whole page copied
        if done > released:
            _MADVISE(released, done - released, _MADV_DONTNEED)
            released = done


def release_pages(arr):
    """Give the whole pages inside a contiguous array back to the system (``madvise(MADV_DONTNEED)``, Linux; they
    read as zeros afterwards, and take memory again when written): for a kept buffer whose contents are no longer
    needed. Elsewhere a no-op."""
    if _MADVISE is None or not arr.flags.c_contiguous or arr.nbytes < 2 * _PAGE:
        return
    lo = -(-arr.ctypes.data // _PAGE) * _PAGE
    hi = (arr.ctypes.data + arr.nbytes) // _PAGE * _PAGE
    if hi > lo:
        _MADVISE(lo, hi - lo, _MADV_DONTNEED)


def _one_pass_list(scan, n_ext, buffer, nthreads):
    """The half list in CSR form, built by one scan over the bins (no separate count pass).

    ``scan(t, count_s, pair_j, pos, first, last) -> (a_next, pos)`` appends the partners of
    the points [first, last) to ``pair_j`` from ``pos`` on, sets ``count_s[a + 1]``, and stops
    early (``a_next < last``) when ``pair_j`` is full. Each of the ``nthreads`` chunks of
    points writes into its own region of ``buffer``; the regions are then moved together.
    A region that fills up continues in a grown copy of its own. Returns ``(pair_start,
    pair_j, buffer, ends)``: ``pair_j`` is a view of the returned buffer (a new, larger one when
    the old was too small); ``ends[t]`` is 1 + the largest partner of chunk t (at least its end).
    """
    count_s = np.empty(n_ext + 1, dtype=np.int64)
    count_s[0] = 0
    bounds = chunk_bounds(n_ext, nthreads)
    cap_t = buffer.shape[0] // nthreads
    regions = [buffer[t * cap_t:(t + 1) * cap_t] for t in range(nthreads)]
    pool = thread_pool(nthreads) if nthreads > 1 else None
    jobs = [pool.submit(_scan_chunk_growing, scan, t, count_s, regions[t], *bounds[t]) for t in range(nthreads - 1)]
    last = _scan_chunk_growing(scan, nthreads - 1, count_s, regions[-1], *bounds[-1])  # on the calling thread
    results = [job.result() for job in jobs] + [last]
    total = sum(r[1] for r in results)
    # the list gathered into a new, compact buffer (with a margin for the next build), always: a list walked in the
    # pages the scan wrote was 1.25x slower to walk (Fan 2D at 1e5 on one thread: 48 vs 38 ms per step) than the
    # same list copied into fresh pages; the scan's buffer is freed when this returns
    # the scan's pages are released as they are copied (the scan's buffer is dropped on return): one list at the
    # peak, not two
    buffer = np.empty(int(1.05 * total) + 1024, dtype=buffer.dtype)
    starts = np.cumsum([0] + [r[1] for r in results])
    copies = [(buffer[starts[t]:starts[t + 1]], results[t][0][:results[t][1]]) for t in range(len(results))]
    # each region copied on its own thread (numpy's copy and madvise run without the GIL)
    jobs = [pool.submit(_copy_releasing, *copy) for copy in copies[:-1]] if pool is not None else []
    for copy in copies[len(jobs):]:
        _copy_releasing(*copy)
    for job in jobs:
        job.result()
    np.cumsum(count_s, out=count_s)
    return count_s, buffer[:total], buffer, [r[3] for r in results]


@numba.njit(cache=True)
def _fold(f_sc, src_s, n):
    """Sum values on sorted extended points back onto their source particles."""
    out = np.zeros((n, f_sc.shape[1]))
    for s in range(f_sc.shape[0]):
        p = src_s[s]
        for c in range(f_sc.shape[1]):
            out[p, c] += f_sc[s, c]
    return out


@numba.njit(cache=True, nogil=True)
def _fold_originals(bufs, src_s, is_ghost_s, outs, first, last):
    """outs[i][p] = sum over threads of bufs[i][:, s], for the originals s in [first, last).

    Each original particle appears once among the sorted points, so chunks never write
    the same row.
    """
    for i in range(len(bufs)):
        buf_tsk = bufs[i]
        out_pk = outs[i]
        n_threads, _, k_max = buf_tsk.shape
        for s in range(first, last):
            if not is_ghost_s[s]:
                p = src_s[s]
                for k in range(k_max):
                    total = buf_tsk[0, s, k]
                    for t in range(1, n_threads):
                        total += buf_tsk[t, s, k]
                    out_pk[p, k] = total


@numba.njit(cache=True)
def _fold_ghosts(bufs, ghost_s, src_s, outs):
    """Add the (few) ghosts' values to their source particles."""
    for i in range(len(bufs)):
        buf_tsk = bufs[i]
        out_pk = outs[i]
        n_threads, _, k_max = buf_tsk.shape
        for g in range(ghost_s.shape[0]):
            s = ghost_s[g]
            p = src_s[s]
            for t in range(n_threads):
                for k in range(k_max):
                    out_pk[p, k] += buf_tsk[t, s, k]


@numba.njit(cache=True, nogil=True)
def _fold_part_originals(parts, bases, src_s, is_ghost_s, outs, first, last):
    """outs[i][p] = sum over threads t of parts[i][t][s - bases[t]] (the rows s that thread t's
    part holds, ``bases[t] <= s < bases[t] + len(part)``), for the originals s in [first, last).

    The points are taken in segments over which the same threads hold rows (on 2 threads: the first thread's
    rows alone, both, the second's alone), so the sum over threads needs no test per point (0.7x the CPU time
    of a test per point and thread at 1e6); threads are added in order, from 0.0, as before."""
    nt = bases.shape[0]
    held = np.empty(nt, dtype=np.int64)
    for i in range(len(parts)):
        part_i = parts[i]
        out_pk = outs[i]
        k_max = out_pk.shape[1]
        s = first
        while s < last:
            stop = last
            m = 0
            for t in range(nt):
                lo = bases[t]
                hi = lo + part_i[t].shape[0]
                if s < lo:
                    stop = min(stop, lo)
                elif s < hi:
                    stop = min(stop, hi)
                    held[m] = t
                    m += 1
            if m == 1 or m == 2:  # the test of m is the same for the whole segment (taken out of the loop)
                pa = part_i[held[0]]
                pb = part_i[held[m - 1]]
                la = bases[held[0]]
                lb = bases[held[m - 1]]
                for q in range(s, stop):
                    if not is_ghost_s[q]:
                        p = src_s[q]
                        for k in range(k_max):
                            value = 0.0 + pa[q - la, k]
                            if m == 2:
                                value += pb[q - lb, k]
                            out_pk[p, k] = value
            else:
                for q in range(s, stop):
                    if not is_ghost_s[q]:
                        p = src_s[q]
                        for k in range(k_max):
                            total = 0.0
                            for j in range(m):
                                total += part_i[held[j]][q - bases[held[j]], k]
                            out_pk[p, k] = total
            s = stop


@numba.njit(cache=True)
def _fold_part_ghosts(parts, bases, ghost_s, src_s, outs):
    for i in range(len(parts)):
        part_i = parts[i]
        out_pk = outs[i]
        k_max = out_pk.shape[1]
        for g in range(ghost_s.shape[0]):
            s = ghost_s[g]
            p = src_s[s]
            for t in range(len(part_i)):
                row = s - bases[t]
                if row >= 0 and row < part_i[t].shape[0]:
                    for k in range(k_max):
                        out_pk[p, k] += part_i[t][row, k]


def check_fold_output(out, shape, name="outs"):
    """``out`` itself if it can take a fold's sums in place: a writeable C-contiguous float64 array of ``shape``
    (then a reshape of it is a view); else ValueError naming ``name``."""
    if not (isinstance(out, np.ndarray) and out.dtype == np.float64 and out.shape == tuple(shape)
            and out.flags.c_contiguous and out.flags.writeable):
        raise ValueError(f"{name}: a writeable C-contiguous float64 array of shape {tuple(shape)} expected, got "
                         f"{getattr(out, 'dtype', type(out).__name__)} {getattr(out, 'shape', '')}")
    return out


def _fold_outputs(widths, n, outs):
    """The arrays (n, k) a fold writes, one per width k: ``outs[i]`` where given (not None; overwritten,
    :func:`check_fold_output`), else fresh."""
    if outs is None:
        return tuple(np.empty((n, k)) for k in widths)
    if len(outs) != len(widths):
        raise ValueError(f"outs: {len(widths)} arrays or None expected, got {len(outs)}")
    return tuple(np.empty((n, k)) if out is None else check_fold_output(out, (n, k)) for k, out in zip(widths, outs))


def fold_thread_parts(parts, bases, src_s, is_ghost_s, ghost_s, n, outs=None):
    """Per-particle sums (n, k) of per-thread buffers that start at their thread's first
    point: ``parts[i][t]`` has shape (m_t, k), row 0 being point ``bases[t]``, rows beyond
    ``bases[t] + m_t`` zero (see :meth:`NeighborList.partner_ends`); written into ``outs[i]`` where given
    (:func:`_fold_outputs`), else into fresh arrays."""
    parts = tuple(tuple(p) for p in parts)
    outs = _fold_outputs([part[0].shape[1] for part in parts], n, outs)
    run_chunks(_fold_part_originals, src_s.shape[0], (parts, bases, src_s, is_ghost_s, outs),
               nthreads=len(parts[0]))
    _fold_part_ghosts(parts, bases, ghost_s, src_s, outs)
    return outs


def fold_thread_buffers(bufs, src_s, is_ghost_s, ghost_s, n, outs=None):
    """Per-particle sums (n, k) of per-thread values on sorted extended points (T, n_s, k), for each buffer;
    written into ``outs[i]`` where given (:func:`_fold_outputs`), else into fresh arrays."""
    bufs = tuple(bufs)
    outs = _fold_outputs([buf.shape[2] for buf in bufs], n, outs)
    run_chunks(_fold_originals, bufs[0].shape[1], (bufs, src_s, is_ghost_s, outs), nthreads=bufs[0].shape[0])
    _fold_ghosts(bufs, ghost_s, src_s, outs)
    return outs


@numba.njit(cache=True, nogil=True)
def _max_displacement2_chunk(r_pc, r0_pc, out, first, last):
    best = out[0]
    for p in range(first, last):
        d2 = 0.0
        for c in range(3):
            d = r_pc[p, c] - r0_pc[p, c]
            d2 += d * d
        if not d2 <= best:  # also true for NaN
            best = d2 if d2 == d2 else np.inf
    out[0] = best


def _max_displacement2(r_pc, r0_pc):
    """Largest squared displacement; inf if a position is NaN or inf (the rebuild then rejects it). In
    :func:`thread_count` chunks: at 1e6 particles one thread took 3 ms, a step's largest serial pass."""
    return max(float(out[0]) for out in reduce_chunks(_max_displacement2_chunk, r_pc.shape[0], (r_pc, r0_pc), 1))


# the adaptive skin (NeighborList's max_skin): lists rebuilt after fewer evaluations than this grow the next skin
# (Fan's FIRE at 1e5 in 2D rebuilt every 3-4 evaluations with 0.1 h, every 10 with 0.3 h: calculators.fan's
# MAX_SKIN_FACTOR), lists that last longer than SKIN_SHRINK_ABOVE shrink it (the walk of a wider list costs more)
SKIN_GROW_BELOW = 8
SKIN_SHRINK_ABOVE = 24

# bins of edge reach / m, by the number of axes the points spread along (measured in
# benchmarks/profile_fan.py: m = 2 in 3D checks 0.58x the candidates of m = 1)
BIN_DIVISIONS = {1: 1, 2: 2, 3: 2}

# Wide cut-offs (reproductions/speed-wide-cutoffs/README.md): when the largest
# reach (cut-off + skin) exceeds WIDE_FACTOR times the TYPICAL_QUANTILE of the reaches, the bins
# are sized by that typical reach and the points of larger reach ("wide" points) scan their own
# full stencils; otherwise the bins are sized by the largest reach, as for a uniform cut-off.
TYPICAL_QUANTILE = 0.85
WIDE_FACTOR = 2.0


def bin_reach(cut_p, skin):
    """(reach, typical): the largest reach ``max(cut_p) + skin``, and the reach the bins are sized
    by: ``reach`` itself unless it exceeds ``WIDE_FACTOR`` times the ``TYPICAL_QUANTILE`` of the
    particles' reaches (then that quantile)."""
    reach = float(cut_p.max()) + skin
    if reach <= WIDE_FACTOR * (float(cut_p.min()) + skin):  # the common case, without a quantile
        return reach, reach
    typical = float(np.quantile(cut_p, TYPICAL_QUANTILE)) + skin
    return reach, (reach if reach <= WIDE_FACTOR * typical else typical)


class BinnedPoints:
    """Particles and their periodic ghosts, sorted into bins of edge ``reach / m``.

    The building block of :class:`NeighborList` and of the fused one-shot scans
    in :mod:`ase_sphrelax.kernel_sums`. Arrays with suffix ``_s`` are over sorted
    extended points.

    The bins are sized by a typical reach (:func:`bin_reach`): by the largest when the
    cut-offs are within ``WIDE_FACTOR`` of each other. Otherwise the points of larger reach
    than the bins' ("wide" points, ``n_normal`` on in sorted order, after all others and
    sorted by the same bins) scan the bins within their own reach, both directions, and keep
    the pairs with the normal points and with the wide points of smaller reach
    (:func:`finds_pair`): each pair is found once, and a rebuild stays O(N) when the cut-offs
    span orders of magnitude.

    Attributes
    ----------
    x_sc, src_s, img_sc, is_ghost_s, cut_s : ndarray
        Position (at the build, then at the last :meth:`extend`), source particle (int32),
        integer image (int32, the wrap into the cell included), ghost flag and cut-off of each
        sorted extended point; ``shift_sc`` (computed) is the Cartesian image shift.
    cell_cc : ndarray (3, 3)
        The cell completed to rank 3 (:func:`complete_cell`).
    bin_s, nbin_c, bin_start, stencil_kc : ndarray
        Bin of each point, bins per axis, CSR start of each bin (normal points, then the
        wide points' bins from ``bin_start[prod(nbin_c)]`` on), forward half stencil.
    stencil : ndarray or tuple
        What the scans take (:func:`stencil_rows`, :func:`stencil_range`): ``stencil_kc`` without
        wide points, else ``(stencil_kc, n_normal, row axis, bin edge, reach of each wide point,
        n_extended)``.
    reach, bin_reach : float
        The largest reach (cut-off + skin) and the one the bins are sized by.
    origin_c, bin_size : ndarray, float
        Corner of bin (0, 0, 0) and the bin edge: point x is in bin ``floor((x - origin_c) / bin_size)``
        (clamped to the grid), at the positions of the build. Other searches on the same bins
        (particle-boundary queries, :mod:`ase_sphrelax.boundary`) use them.
    forward_pairs : bool
        True: the pairs of a scan or list that a chunk of points finds lie at or after
        :meth:`partner_starts` (the chunk's first point, lower only for wide points): the pair
        loops give each thread buffers that start there.
    """

    forward_pairs = True

    def __init__(self, r_pc, cell, pbc, cut_p, skin=0.0):
        n = r_pc.shape[0]
        full_cell, inv_cell = complete_cell(cell, pbc)
        reach, typical = bin_reach(cut_p, skin)
        # perpendicular widths of the cell; image layers needed per periodic axis
        width_c = 1.0 / np.linalg.norm(inv_cell, axis=0)
        pad_c = np.where(pbc, reach / width_c, 0.0)
        layers_c = np.where(pbc, np.ceil(pad_c), 0).astype(np.int64)
        src_e, img_ec, lo_c, hi_c = _extended_points(r_pc, full_cell, inv_cell, pbc, pad_c, layers_c)
        self.cell_cc = full_cell
        n_ext = src_e.shape[0]
        extent_c = hi_c - lo_c
        # bins of edge typical / m scanned with a (2m+1)^d stencil (m by the number of axes the
        # points spread along); for sparse sets (bins > 4 per point) fall back to m = 1 and
        # larger bins
        spread = int(np.count_nonzero(extent_c >= typical))
        m = BIN_DIVISIONS.get(spread, 1)
        binsize = typical / m
        nbin_c = np.maximum(1, np.floor(extent_c / binsize).astype(np.int64) + 1)
        while np.prod(nbin_c.astype(float)) > 4.0 * n_ext + 64:
            m = 1
            binsize *= 1.5
            nbin_c = np.maximum(1, np.floor(extent_c / binsize).astype(np.int64) + 1)
        binsize = max(binsize, typical / m)
        wide_p = cut_p + skin > typical
        groups = 2 if typical < reach else 1
        order_s, bin_start, bin_s = _bin_sort(r_pc, full_cell, src_e, img_ec, lo_c, binsize, nbin_c, wide_p, groups)
        self.origin_c = lo_c  # bin (0, 0, 0) starts here; bins are cubes of edge bin_size
        self.bin_size = float(binsize)
        self.n_particles = n
        self.n_extended = n_ext
        self.src_s, self.img_sc, self.x_sc, self.is_ghost_s, self.cut_s = _sorted_arrays(order_s, src_e, img_ec, r_pc,
                                                                                     full_cell, cut_p)
        del img_ec, src_e, order_s  # the sorted arrays say it all
        self._x_buffer = self.x_sc  # extend() writes current positions here
        self.ghost_s = np.nonzero(self.is_ghost_s)[0]
        self.bin_s = bin_s
        self.nbin_c = nbin_c
        self.bin_start = bin_start
        self.stencil_kc = _half_stencil(m, nbin_c, binsize, typical)
        self.binsize = binsize
        self.reach = reach
        self.bin_reach = typical
        nbins = int(np.prod(nbin_c))
        self.n_normal = int(bin_start[nbins])
        spread_c = [c for c in range(3) if nbin_c[c] > 1]
        reach_w = self.cut_s[self.n_normal:] + skin
        # most candidates of one point: for a normal one, the fullest bin times the bins of the own bin and the
        # stencil; a wide one can have them all
        span_k = self.stencil_kc[:, 3:] - self.stencil_kc[:, :3] + 1
        self.fullest_bin = int(np.diff(bin_start[:nbins + 1]).max())  # the most points of one bin
        self.max_candidates = self.fullest_bin * int(1 + np.prod(span_k, axis=1).sum())
        self.stencil = self.stencil_kc if self.n_normal == n_ext else (
            self.stencil_kc, self.n_normal, spread_c[-1] if spread_c else 2, float(binsize), reach_w, n_ext)
        # the lowest point a wide point's stencil can reach: the start of its lowest bin (the corner of its frame)
        k_wc = np.stack([bin_s[self.n_normal:] // (nbin_c[2] * nbin_c[1]), (bin_s[self.n_normal:] // nbin_c[2])
                         % nbin_c[1], bin_s[self.n_normal:] % nbin_c[2]], axis=1)
        corner_wc = np.maximum(k_wc - (reach_w / binsize).astype(np.int64)[:, None] - 1, 0)
        self._low_w = bin_start[(corner_wc[:, 0] * nbin_c[1] + corner_wc[:, 1]) * nbin_c[2] + corner_wc[:, 2]]
        self._gather_buffers = {}

    def partner_starts(self, nthreads):
        """For the ``nthreads`` chunks of points of the pair loops (:func:`chunk_bounds`), the
        lowest point a pair found by the chunk's points can have: the chunk's first point, or
        lower when the chunk holds wide points (whose full stencils reach back)."""
        starts = []
        for first, last in chunk_bounds(self.n_extended, nthreads):
            lo = max(first, self.n_normal)
            starts.append(min(first, int(self._low_w[lo - self.n_normal:last - self.n_normal].min()))
                          if last > lo else first)
        return starts

    def expected_pairs(self):
        """Estimated size of the half list (uniform density within the occupied bins)."""
        spread = self.nbin_c > 1
        dim = int(np.count_nonzero(spread))
        if dim == 0:
            return self.n_extended * (self.n_extended - 1) // 2
        # the occupied bins' volume, not the grid's: a disc fills pi/4 of its box, and a list buffer
        # sized from the box has to grow (a copy, 2.5 lists at once) on the first build
        occupied = int(np.count_nonzero(np.diff(self.bin_start)))
        volume = occupied * self.binsize**dim
        ball = {1: 2.0, 2: np.pi, 3: 4.0 * np.pi / 3.0}[dim] * self.bin_reach**dim
        return int(0.5 * self.n_extended * min(self.n_extended, self.n_extended / volume * ball))

    def extend(self, positions):
        """Positions of the sorted extended points for the current ``positions``.

        The array is reused by the next call: copy it to keep it.
        """
        return _gather(np.asarray(positions, dtype=float), self.src_s, self.img_sc, self.cell_cc, self._x_buffer)

    @property
    def shift_sc(self):
        """Cartesian image shift of each sorted extended point (x_s = r[src_s] + shift_s)."""
        return self.img_sc @ self.cell_cc

    def gather(self, values_p, slot=0):
        """Per-particle values (N, ...) on the sorted extended points, without image shifts.

        For quantities that do not move with a periodic image (velocities, masses,
        smoothing lengths, densities). The array is reused by the next call with the same
        ``slot``: copy it to keep it.
        """
        values_p = np.asarray(values_p)
        if values_p.ndim == 0 or values_p.shape[0] != self.n_particles:
            raise ValueError(f"values_p must have one row per particle ({self.n_particles}), "
                             f"got shape {values_p.shape}")
        shape = (self.n_extended,) + values_p.shape[1:]
        buf = self._gather_buffers.get(slot)
        if buf is None or buf.shape != shape or buf.dtype != values_p.dtype:
            buf = self._gather_buffers[slot] = np.empty(shape, dtype=values_p.dtype)
        np.take(values_p, self.src_s, axis=0, out=buf)
        return buf

    def release_gathered(self):
        """Drop the arrays of :meth:`gather` (a pair sum's inputs, not needed after it: not held through the next
        one's peak)."""
        self._gather_buffers = {}

    def fold(self, values_s):
        """Sum per-extended-point values (shape (n_extended,) or (n_extended, k)) onto particles."""
        values_s = np.asarray(values_s, dtype=float)
        flat = values_s.ndim == 1
        out = _fold(values_s.reshape(values_s.shape[0], -1), self.src_s, self.n_particles)
        return out[:, 0] if flat else out

    def fold_threads(self, bufs, outs=None):
        """Per-particle sums (N, k) of per-thread buffers (T, n_extended, k), ghosts included, for each buffer
        (into ``outs``' arrays where given, see :func:`fold_thread_buffers`)."""
        return fold_thread_buffers(bufs, self.src_s, self.is_ghost_s, self.ghost_s, self.n_particles, outs)

    def fold_thread_parts(self, parts, bases, outs=None):
        """Per-particle sums (N, k) of per-thread buffers starting at each thread's first
        point (see :func:`fold_thread_parts`), ghosts included, for each output (into ``outs``' arrays where
        given)."""
        return fold_thread_parts(parts, bases, self.src_s, self.is_ghost_s, self.ghost_s, self.n_particles, outs)

    def loop_arrays(self):
        """("scan", arrays) for the pair loops of :mod:`ase_sphrelax.pairs`: the fused bin scan."""
        return "scan", (self.src_s, self.img_sc, self.is_ghost_s, self.bin_s, self.nbin_c, self.bin_start,
                        self.stencil)


class NeighborList:
    """Verlet half list built from a cell list; O(N) in time and memory.

    The one neighbour interface of the package: every pair sum of
    :mod:`ase_sphrelax.pairs` takes a NeighborList, whichever state it is in:

    * *stored*: the half list ``pair_start``/``pair_j`` over sorted extended points,
      built with ``cutoff + skin`` and reused while it stays valid;
    * *one-shot* (``update(..., store=False)``): the points are binned but no list is
      stored; the pair sums are fused into the bin scan. A calculator's first
      evaluation works this way, since a list pays off only when it is reused.

    Parameters
    ----------
    cutoff : float or array_like of shape (N,)
        Interaction radius, or one per particle (a pair interacts within the
        larger of the two). It may be changed at every :meth:`update`.
    skin : float
        Extra radius of the stored list.
    max_skin : float or None
        With ``max_skin > skin`` the skin adapts to how the points move: a list rebuilt after
        fewer than :data:`SKIN_GROW_BELOW` evaluations gives the next build a skin twice as large
        (up to ``max_skin``), one that lasted more than :data:`SKIN_SHRINK_ABOVE` a skin half as
        large (down to ``skin``). Which pairs are listed changes, not which interact: sums
        differ by rounding only. None (default): the skin stays ``skin``.

    The stored list is reused as long as ``2 max|displacement| + max(cutoff - cutoff_build, 0)
    <= skin`` since the build (and the cell, pbc and particle number are unchanged): then
    every pair within the current cut-offs is listed. Per-particle cut-offs may therefore
    grow by less than the skin without a rebuild (adaptive smoothing lengths).

    Attributes
    ----------
    n_particles, n_extended : int
        Number of particles and of extended points (particles + ghosts).
    pair_start : ndarray of int64, shape (n_extended + 1,)
    pair_j : ndarray of int32
        Half list over *sorted extended* points (see module docstring); None in the
        one-shot state.
    builds : int
        How many times the stored list was (re)built.
    skin : float
        The skin of the current list (of the next build before any).
    forward_pairs : bool
        True: the pairs of a chunk of points lie at or after :meth:`partner_starts` (the chunk's
        first point unless wide points reach back; see :class:`BinnedPoints`).
    """

    forward_pairs = True

    def __init__(self, cutoff, skin=0.0, max_skin=None):
        self.cutoff = _check_cutoff(cutoff)
        self.skin = self.min_skin = check_skin(skin)
        self.max_skin = self.skin if max_skin is None else max(check_skin(max_skin, "max_skin"), self.skin)
        self._reuses = 0  # evaluations the current list served after its build
        self.builds = 0
        self.points = None
        self._pair_start = None
        self._pair_j = None
        self._pending = False
        self._pair_buffer = np.empty(0, dtype=np.int32)
        self._pair_count = 0
        self._key = None
        self._r0_pc = None
        self._drift = None  # a bound on every displacement since the build (update's moved_at_most), or None
        self._cut_build = None
        self._cut_build_uniform = None
        self._ends = None

    # -- public -----------------------------------------------------------------
    @property
    def stored(self):
        """True when a Verlet list is stored (False: one-shot bins, or nothing built)."""
        return self._pending or self._pair_j is not None

    @property
    def pair_start(self):
        """CSR start of each sorted extended point's partners (None in the one-shot state)."""
        self._complete_pending()
        return self._pair_start

    @property
    def pair_j(self):
        """Partners (sorted extended points) of the half list (None in the one-shot state)."""
        self._complete_pending()
        return self._pair_j

    @property
    def positions_at_build(self):
        """The positions (N, 3) the current list (or bins) was built for, read only; None before any build."""
        return self._r0_pc

    @property
    def build_pending(self):
        """True after a (re)build whose list scan waits for the next pair sum to fuse with
        (:meth:`fused_build`); reading the list or moving the points completes it first."""
        return self._pending

    @property
    def plain(self):
        """True when the current bins hold originals only (no periodic images), all of one cut-off: a pair is then
        listed by its distance alone, and the points of one bin share their stencil rows' candidates (the fused
        build's ``"build_plain"`` loop; with two points of a bin scanning the rows together it took 0.59x the general
        one's time on Fan's sphere at 1e6 on one thread, ``reproductions/speed-fan-1e6/build_loops.py``; the rows'
        candidates gathered once per bin, 0.85x that)."""
        pts = self.points
        return (pts is not None and self._cut_build_uniform is not None and pts.n_extended == pts.n_particles
                and pts.n_normal == pts.n_extended)

    @property
    def max_cutoff(self):
        """The largest current cut-off."""
        return float(self.cutoff.max())

    def update(self, positions, cell, pbc, cutoff=None, store=True, moved_at_most=None) -> bool:
        """Make the neighbours valid for ``positions``; return True if anything was (re)built.

        Parameters
        ----------
        positions : ndarray (N, 3)
        cell, pbc
            As in ASE.
        cutoff : float, array_like (N,) or None
            New cut-off(s); None keeps the current ones.
        store : bool
            False asks for a one-shot evaluation: if no valid stored list exists, the points
            are binned (skin 0) and the pair sums scan the bins; no list is built.
        moved_at_most : float or None
            No position moved further than this since the last call (the caller's promise, e.g. an
            optimiser's longest move of a step): while the sum of these bounds since the build
            stays under half the skin, the list is kept without measuring the displacements (a
            pass over 2 N positions). None: measured.
        """
        r_pc = _check_positions(positions, finite=False)  # NaN/inf: see _still_valid and _build
        pbc = np.array(pbc, dtype=bool).reshape(3) if np.ndim(pbc) else np.array([bool(pbc)] * 3)
        cell = np.array(cell, dtype=float).reshape(3, 3)
        if cutoff is not None:
            self.cutoff = _check_cutoff(cutoff)
        if self.cutoff.ndim == 1 and self.cutoff.shape[0] != r_pc.shape[0]:
            raise ValueError(f"cutoff has {self.cutoff.shape[0]} entries but there are {r_pc.shape[0]} particles")
        key = (r_pc.shape[0], cell.tobytes(), pbc.tobytes())
        if key == self._key and (self.stored or not store) and self._still_valid(r_pc, moved_at_most):
            self._reuses += 1
            return False
        _check_positions(r_pc)
        if store and self.stored and key == self._key:
            self._adapt_skin()
        self._build(r_pc, cell, pbc, store)
        self._reuses = 0
        self._key = key
        self._drift = 0.0 if store else None
        if self._r0_pc is not None and self._r0_pc.shape == r_pc.shape and self._r0_pc is not r_pc:
            np.copyto(self._r0_pc, r_pc)  # in place: not a second copy of the positions at a rebuild's peak
        else:
            self._r0_pc = r_pc.copy()
        return True

    def _adapt_skin(self):
        """The next build's skin from how many evaluations the current list lasted (``max_skin``)."""
        lasted = self._reuses + 1
        self._reuses = 0
        if self.max_skin <= self.min_skin:
            return
        if lasted < SKIN_GROW_BELOW:
            self.skin = min(2.0 * self.skin, self.max_skin)
        elif lasted > SKIN_SHRINK_ABOVE:
            self.skin = max(0.5 * self.skin, self.min_skin)

    def _still_valid(self, r_pc, moved_at_most=None):
        if self.cutoff.ndim == 0 and self._cut_build_uniform is not None:
            growth = float(self.cutoff) - self._cut_build_uniform
        else:
            growth = float(np.max(self.cutoff - self._cut_build))
        drift, self._drift = self._drift, None  # a bound on the displacements since the build, while it holds
        if not self.stored:  # one-shot bins: only for the positions and cut-offs they were made for
            return growth <= 0.0 and np.array_equal(r_pc, self._r0_pc)
        margin = self.skin - max(growth, 0.0)
        if margin < 0.0:
            return False
        if margin == 0.0:
            return np.array_equal(r_pc, self._r0_pc)
        if drift is not None and moved_at_most is not None:
            # the bounds add up (with a little to spare for the round-off of the moves themselves)
            bound = drift + float(moved_at_most) * (1.0 + 1e-9) + 1e-12 * margin
            if bound <= 0.5 * margin:
                self._drift = bound
                return True
        d2 = _max_displacement2(r_pc, self._r0_pc)
        if d2 <= (0.5 * margin) ** 2:
            self._drift = float(np.sqrt(d2))
            return True
        return False

    def extend(self, positions):
        """Positions of the sorted extended points for the current ``positions``."""
        if self._pending and not np.array_equal(positions, self._r0_pc):
            self._complete_pending()  # the list is made from the positions of the build
        return self.points.extend(positions)

    def gather(self, values_p, slot=0):
        """Per-particle values on the sorted extended points, without image shifts
        (see :meth:`BinnedPoints.gather`)."""
        return self.points.gather(values_p, slot)

    def release_gathered(self):
        """Drop the arrays of :meth:`gather` (see :meth:`BinnedPoints.release_gathered`)."""
        if self.points is not None:
            self.points.release_gathered()

    def fold(self, values_s):
        """Sum per-extended-point values onto particles (see :meth:`BinnedPoints.fold`)."""
        return self.points.fold(values_s)

    def fold_threads(self, bufs, outs=None):
        return self.points.fold_threads(bufs, outs)

    def fold_thread_parts(self, parts, bases, outs=None):
        return self.points.fold_thread_parts(parts, bases, outs)

    def partner_ends(self, nthreads):
        """For the ``nthreads`` chunks of points of the pair loops (:func:`chunk_bounds`), 1 + the
        last listed partner of each chunk's points, or None without a complete stored list.

        A thread walking chunk ``(first, last)`` of the list writes rows ``[first, end)`` only:
        its buffers need no more (on 2 threads the first thread's end is about n/2, not n).
        Found by the list scan's threads (for its number of threads), else by one pass of
        the threads over the list.
        """
        if self._pair_j is None or self._pending:
            return None
        if self._ends is None or len(self._ends) != nthreads:
            out = np.empty(nthreads, dtype=np.int64)
            run_chunks(_partner_end_chunk, self.points.n_extended, (self._pair_start, self._pair_j, out),
                       per_thread=[(t,) for t in range(nthreads)])
            self._ends = [int(x) for x in out]
        return self._ends

    def partner_starts(self, nthreads):
        """The lowest point each of the ``nthreads`` chunks of the pair loops can reach
        (:meth:`BinnedPoints.partner_starts`; a stored list holds a subset of the scans' pairs)."""
        return self.points.partner_starts(nthreads)

    def loop_arrays(self):
        """("list", arrays) when a list is stored, else the one-shot bin scan's ("scan", arrays)."""
        if self.stored:
            return "list", (self.pair_start, self.pair_j)
        return self.points.loop_arrays()

    def fused_build(self, scan, nthreads):
        """Complete a pending build with a scan that also does other work (a pair sum).

        ``scan(t, count_s, pair_j, pos, first, last) -> (a_next, pos)`` is the one-pass list
        scan of :func:`_scan_pairs_chunk` over chunk ``t`` of ``nthreads``, on the bins of
        :meth:`build_arrays`; see :func:`_one_pass_list`. Used by
        :meth:`ase_sphrelax.pairs.PairInteraction.compute`: a rebuild then costs one bin
        scan that lists the pairs and evaluates the interaction, and no list walk.
        """
        if not self._pending:
            raise ValueError("fused_build: no build is pending")
        self._store_list(scan, nthreads)

    def build_arrays(self):
        """Arrays of the list scan, after the positions: (src_s, img_sc, is_ghost_s, cut_s,
        skin, bin_s, nbin_c, bin_start, stencil, room), ``room`` the most candidates a
        normal point can have (:attr:`BinnedPoints.max_candidates`; a wide point's own is in
        ``stencil``, see :func:`point_room`). In the one-shot state ``skin`` is 0 (the bins' own)."""
        pts = self.points
        return (pts.src_s, pts.img_sc, pts.is_ghost_s, pts.cut_s, self.skin if self.stored or self._pending else 0.0,
                pts.bin_s, pts.nbin_c, pts.bin_start, pts.stencil, pts.max_candidates)

    def one_shot_scan(self, scan, nthreads):
        """A one-shot pair sum on :attr:`plain` bins by the plain build's loop, with no list kept.

        ``scan`` as :meth:`fused_build`'s, on the bins of :meth:`build_arrays` (skin 0). Each of the ``nthreads``
        chunks lists its points' partners into a small region of its own, which every call fills anew: a point's
        terms are summed from its partners as soon as they are listed (the loop's order), and the region is
        overwritten by the next bins'. The same pairs as the general one-shot scan (``"scan"``), each point's in the
        list's order (the general scan branches on each candidate's test)."""
        if self.stored or self._pending or not self.plain:
            raise ValueError("one_shot_scan: needs one-shot plain bins (update(..., store=False), no images)")
        pts = self.points
        room = int(pts.max_candidates)
        cap = max(ONE_SHOT_REGION, 1 + pts.fullest_bin * room)  # at least the fullest bin's points and their candidates
        count_s = np.empty(pts.n_extended + 1, dtype=np.int64)

        def run(t, first, last):
            region = np.empty(cap, dtype=np.int32)
            a, _ = scan(t, count_s, region, 0, first, last)
            while a < last:  # the region is full: on from ``a``, written over (pos 1: the thread's sums are kept)
                before, (a, _) = a, scan(t, count_s, region, 1, a, last)
                if a <= before:  # cannot happen: the region holds any bin's points and their candidates
                    raise RuntimeError("one_shot_scan: a call listed no point")

        run_chunks(run, pts.n_extended, (), per_thread=[(t,) for t in range(nthreads)])

    @property
    def n_particles(self):
        return self.points.n_particles

    @property
    def n_extended(self):
        return self.points.n_extended

    @property
    def src_s(self):
        return self.points.src_s

    def get_pairs(self, positions):
        """Every listed pair once: (i_p, j_p, d_pc) with d = x_j + image - x_i.

        Pairs within ``cutoff + skin`` are returned; filter by distance as needed.
        """
        if not self.stored:
            raise ValueError("get_pairs needs a stored list: call update(..., store=True)")
        x_sc = self.extend(positions)
        a_p = np.repeat(np.arange(self.n_extended), np.diff(self.pair_start))
        b_p = self.pair_j
        return self.src_s[a_p], self.src_s[b_p], x_sc[b_p] - x_sc[a_p]

    # -- build ------------------------------------------------------------------
    def _build(self, r_pc, cell, pbc, store):
        cut_p = np.broadcast_to(self.cutoff, (r_pc.shape[0],)).astype(float)
        self._cut_build = cut_p
        self._cut_build_uniform = float(self.cutoff) if self.cutoff.ndim == 0 else None
        skin = self.skin if store else 0.0
        self._pair_start = self._pair_j = None
        self._pending = False
        self._ends = None
        self.points = None  # free the old bins before the new ones are made
        self.points = BinnedPoints(r_pc, cell, pbc, cut_p, skin)
        if store:
            # the list scan waits for the next pair sum, which can fuse with it (fused_build)
            self._pending = True
            self.builds += 1

    def _complete_pending(self):
        if self._pending:
            x_sc = self.points.x_sc  # the positions of the build (extend() completes the list before moving them)
            arrays = self.build_arrays()
            self._store_list(lambda t, count_s, pair_j, pos, first, last: _scan_pairs_chunk(
                x_sc, arrays[3], *arrays[:3], *arrays[4:9], count_s, pair_j, pos, first, last),
                thread_count(self.points.n_extended))

    def _store_list(self, scan, nthreads):
        # one scan, no count pass: the buffer is sized from the last build (or the density)
        # and kept between builds (fresh pages are expensive to touch)
        expected = self._pair_count if self._pair_count else self.points.expected_pairs()
        want = int(1.05 * expected) + 1024
        if self.points.n_normal < self.points.n_extended:  # room for a wide point's candidates in every region
            want += nthreads * self.points.n_extended
        if self._pair_buffer.shape[0] < want:
            # the old buffer goes first; the new one has room to spare: its untouched pages take no memory,
            # and a list that outgrows its buffer costs a grown copy of it (the buffer and 1.5 times it at once)
            self._pair_buffer = None
            self._pair_buffer = np.empty(int(1.5 * want), dtype=np.int32)
        self._pair_start, self._pair_j, self._pair_buffer, self._ends = _one_pass_list(
            scan, self.points.n_extended, self._pair_buffer, nthreads)
        self._pair_count = self._pair_j.shape[0]
        self._pending = False


def _check_cutoff(cutoff):
    cutoff_arr = np.asarray(cutoff, dtype=float)
    if cutoff_arr.ndim > 1 or cutoff_arr.size == 0 or not np.all(np.isfinite(cutoff_arr)) or np.any(cutoff_arr <= 0):
        raise ValueError(f"cutoff must be a positive finite number or 1D array of them, got {cutoff!r}")
    return cutoff_arr
