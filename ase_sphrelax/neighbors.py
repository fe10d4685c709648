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
"""
from __future__ import annotations

import itertools

import numba
import numpy as np

from .checks import check_skin
from .parallel import PARALLEL_MIN, run_chunks

__all__ = ["NeighborList", "BinnedPoints", "PARALLEL_MIN", "complete_cell", "is_canonical_pair", "bin_coords",
           "stencil_range"]


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


def _check_positions(positions):
    r_pc = np.asarray(positions, dtype=float)
    if r_pc.ndim != 2 or r_pc.shape[1] != 3:
        raise ValueError(f"positions must have shape (N, 3), got {r_pc.shape}")
    if r_pc.shape[0] == 0:
        raise ValueError("positions: need at least one particle, got none")
    if not np.all(np.isfinite(r_pc)):
        bad = np.where(~np.all(np.isfinite(r_pc), axis=1))[0]
        raise ValueError(f"positions must be finite; particles {bad[:10].tolist()} are NaN or inf")
    return r_pc


@numba.njit(cache=True)
def _bin_sort(x_ec, origin_c, binsize, nbin_c):
    """Counting sort of points into bins; returns (order_s, bin_start, bin_s)."""
    n = x_ec.shape[0]
    nbins = nbin_c[0] * nbin_c[1] * nbin_c[2]
    inv_bs = 1.0 / binsize
    bin_e = np.empty(n, dtype=np.int64)
    for e in range(n):
        b = 0
        for c in range(3):
            k = min(max(int((x_ec[e, c] - origin_c[c]) * inv_bs), 0), nbin_c[c] - 1)
            b = b * nbin_c[c] + k
        bin_e[e] = b
    count = np.zeros(nbins + 1, dtype=np.int64)
    for e in range(n):
        count[bin_e[e] + 1] += 1
    for b in range(nbins):
        count[b + 1] += count[b]
    bin_start = count.copy()
    fill = count[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    bin_s = np.empty(n, dtype=np.int64)
    for e in range(n):
        b = bin_e[e]
        order[fill[b]] = e
        bin_s[fill[b]] = b
        fill[b] += 1
    return order, bin_start, bin_s


@numba.njit(cache=True)
def _extended_points(r_pc, cell_cc, inv_cc, pbc_c, pad_c, layers_c):
    """Particles wrapped into the cell along periodic axes, followed by ghosts:
    periodic images within ``pad`` (fractional units) of the unit cell.

    Returns (src_e, img_ec, x_ec): source particle, integer image vector
    (including the wrap) and Cartesian position of every extended point.
    """
    n = r_pc.shape[0]
    frac_pc = np.empty((n, 3))
    wrap_pc = np.zeros((n, 3))
    for p in range(n):
        for c in range(3):
            f = r_pc[p, 0] * inv_cc[0, c] + r_pc[p, 1] * inv_cc[1, c] + r_pc[p, 2] * inv_cc[2, c]
            if pbc_c[c]:
                wrap_pc[p, c] = -np.floor(f)
                f += wrap_pc[p, c]
            frac_pc[p, c] = f
    lx, ly, lz = layers_c[0], layers_c[1], layers_c[2]
    n_ext = n
    src_e = np.empty(0, dtype=np.int64)
    img_ec = np.empty((0, 3))
    for sweep in range(2):
        count = n
        for p in range(n):
            if sweep == 1:
                src_e[p] = p
                for c in range(3):
                    img_ec[p, c] = wrap_pc[p, c]
            for sx in range(-lx, lx + 1):
                fx = frac_pc[p, 0] + sx
                if pbc_c[0] and (fx < -pad_c[0] or fx >= 1.0 + pad_c[0]):
                    continue
                for sy in range(-ly, ly + 1):
                    fy = frac_pc[p, 1] + sy
                    if pbc_c[1] and (fy < -pad_c[1] or fy >= 1.0 + pad_c[1]):
                        continue
                    for sz in range(-lz, lz + 1):
                        if sx == 0 and sy == 0 and sz == 0:
                            continue
                        fz = frac_pc[p, 2] + sz
                        if pbc_c[2] and (fz < -pad_c[2] or fz >= 1.0 + pad_c[2]):
                            continue
                        if sweep == 1:
                            src_e[count] = p
                            img_ec[count, 0] = wrap_pc[p, 0] + sx
                            img_ec[count, 1] = wrap_pc[p, 1] + sy
                            img_ec[count, 2] = wrap_pc[p, 2] + sz
                        count += 1
        if sweep == 0:
            n_ext = count
            src_e = np.empty(n_ext, dtype=np.int64)
            img_ec = np.empty((n_ext, 3))
    x_ec = np.empty((n_ext, 3))
    for e in range(n_ext):
        p = src_e[e]
        for c in range(3):
            x_ec[e, c] = (r_pc[p, c] + img_ec[e, 0] * cell_cc[0, c] + img_ec[e, 1] * cell_cc[1, c]
                          + img_ec[e, 2] * cell_cc[2, c])
    return src_e, img_ec, x_ec


@numba.njit(cache=True)
def _sorted_arrays(order_s, src_e, img_ec, x_ec, r_pc, cut_p):
    """Per sorted extended point: source, image, position, shift, ghost flag and cut-off."""
    n_ext = order_s.shape[0]
    n = r_pc.shape[0]
    src_s = np.empty(n_ext, dtype=np.int64)
    img_sc = np.empty((n_ext, 3))
    x_sc = np.empty((n_ext, 3))
    shift_sc = np.empty((n_ext, 3))
    is_ghost_s = np.empty(n_ext, dtype=np.bool_)
    cut_s = np.empty(n_ext)
    for s in range(n_ext):
        e = order_s[s]
        p = src_e[e]
        src_s[s] = p
        is_ghost_s[s] = e >= n
        cut_s[s] = cut_p[p]
        for c in range(3):
            img_sc[s, c] = img_ec[e, c]
            x_sc[s, c] = x_ec[e, c]
            shift_sc[s, c] = x_ec[e, c] - r_pc[p, c]
    return src_s, img_sc, x_sc, shift_sc, is_ghost_s, cut_s


@numba.njit(cache=True, nogil=True)
def _gather_chunk(r_pc, src_s, shift_sc, x_sc, first, last):
    """x_s = r[src_s] + shift_s for s in [first, last), written into x_sc."""
    for s in range(first, last):
        p = src_s[s]
        for c in range(3):
            x_sc[s, c] = r_pc[p, c] + shift_sc[s, c]


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


def _half_stencil(m, nbin_c):
    """Forward half of the (2m+1)^d bin stencil (own bin excluded) as a (K, 3) array,
    without offsets along axes that have a single bin (2D sheets, 1D chains)."""
    spans = [range(-m, m + 1) if nb > 1 else range(1) for nb in nbin_c]
    return np.array([o for o in itertools.product(*spans) if o > (0, 0, 0)], dtype=np.int64).reshape(-1, 3)


@numba.njit(cache=True, inline="always")
def bin_coords(a, bin_s, nbin_c):
    """Integer bin coordinates (kx, ky, kz) of sorted point a."""
    nby, nbz = nbin_c[1], nbin_c[2]
    return bin_s[a] // (nbz * nby), (bin_s[a] // nbz) % nby, bin_s[a] % nbz


@numba.njit(cache=True, inline="always")
def stencil_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil_kc):
    """Sorted points [lo, hi) of half-stencil entry k of point a in bin (kx, ky, kz).

    k = -1 is the own bin with b > a; an offset outside the bin grid gives an empty range.
    """
    if k < 0:
        return a + 1, bin_start[bin_s[a] + 1]
    bx = kx + stencil_kc[k, 0]
    by = ky + stencil_kc[k, 1]
    bz = kz + stencil_kc[k, 2]
    if bx < 0 or bx >= nbin_c[0] or by < 0 or by >= nbin_c[1] or bz < 0 or bz >= nbin_c[2]:
        return 0, 0
    b_bin = (bx * nbin_c[1] + by) * nbin_c[2] + bz
    return bin_start[b_bin], bin_start[b_bin + 1]


@numba.njit(cache=True, nogil=True)
def _scan_pairs_chunk(x_sc, cut_s, src_s, img_sc, is_ghost_s, skin, bin_s, nbin_c, bin_start, stencil_kc,
                      pair_start, pair_j, fill, first, last):
    """Half-stencil bin scan. With fill=False counts the pairs of each point
    into pair_start[a+1]; with fill=True writes the partners into pair_j.

    A pair is listed if r < max(cut_a, cut_b) + skin, at most one of the two
    is a ghost, and (for original-ghost pairs) it is the canonical orientation.
    ``stencil_kc`` holds the bin offsets (x, y, z) of the forward half stencil;
    the own bin is scanned for b > a.
    """
    for a in range(first, last):
        xa0, xa1, xa2 = x_sc[a, 0], x_sc[a, 1], x_sc[a, 2]
        ca = cut_s[a]
        kx, ky, kz = bin_coords(a, bin_s, nbin_c)
        count = 0
        pos = pair_start[a] if fill else 0
        for k in range(-1, stencil_kc.shape[0]):
            lo, hi = stencil_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil_kc)
            for b in range(lo, hi):
                d0 = x_sc[b, 0] - xa0
                d1 = x_sc[b, 1] - xa1
                d2 = x_sc[b, 2] - xa2
                rc = max(ca, cut_s[b]) + skin
                if d0 * d0 + d1 * d1 + d2 * d2 >= rc * rc:
                    continue
                if not is_canonical_pair(a, b, src_s, img_sc, is_ghost_s):
                    continue
                if fill:
                    pair_j[pos + count] = b
                count += 1
        if not fill:
            pair_start[a + 1] = count


def _gather(r_pc, src_s, shift_sc, x_sc):
    run_chunks(_gather_chunk, src_s.shape[0], (r_pc, src_s, shift_sc, x_sc))
    return x_sc


def _scan_pairs(*args):
    run_chunks(_scan_pairs_chunk, args[0].shape[0], args)


@numba.njit(cache=True)
def _fold(f_sc, order_s, src_e, n):
    """Sum values on sorted extended points back onto their source particles."""
    out = np.zeros((n, f_sc.shape[1]))
    for s in range(f_sc.shape[0]):
        p = src_e[order_s[s]]
        for c in range(f_sc.shape[1]):
            out[p, c] += f_sc[s, c]
    return out


@numba.njit(cache=True, nogil=True)
def _fold_originals(bufs, order_s, n, outs, first, last):
    """outs[i][p] = sum over threads of bufs[i][:, s], for the originals s in [first, last).

    Each original particle appears once among the sorted points, so chunks never write
    the same row.
    """
    for i in range(len(bufs)):
        buf_tsk = bufs[i]
        out_pk = outs[i]
        n_threads, _, k_max = buf_tsk.shape
        for s in range(first, last):
            e = order_s[s]
            if e < n:
                for k in range(k_max):
                    total = buf_tsk[0, s, k]
                    for t in range(1, n_threads):
                        total += buf_tsk[t, s, k]
                    out_pk[e, k] = total


@numba.njit(cache=True)
def _fold_ghosts(bufs, order_s, ghost_s, src_e, outs):
    """Add the (few) ghosts' values to their source particles."""
    for i in range(len(bufs)):
        buf_tsk = bufs[i]
        out_pk = outs[i]
        n_threads, _, k_max = buf_tsk.shape
        for g in range(ghost_s.shape[0]):
            s = ghost_s[g]
            p = src_e[order_s[s]]
            for t in range(n_threads):
                for k in range(k_max):
                    out_pk[p, k] += buf_tsk[t, s, k]


def fold_thread_buffers(bufs, order_s, ghost_s, src_e, n):
    """Per-particle sums (n, k) of per-thread values on sorted extended points (T, n_s, k), for each buffer."""
    bufs = tuple(bufs)
    outs = tuple(np.empty((n, buf.shape[2])) for buf in bufs)
    run_chunks(_fold_originals, bufs[0].shape[1], (bufs, order_s, n, outs), nthreads=bufs[0].shape[0])
    _fold_ghosts(bufs, order_s, ghost_s, src_e, outs)
    return outs


@numba.njit(cache=True)
def _max_displacement2(r_pc, r0_pc):
    best = 0.0
    for p in range(r_pc.shape[0]):
        d2 = 0.0
        for c in range(3):
            d = r_pc[p, c] - r0_pc[p, c]
            d2 += d * d
        if d2 > best:
            best = d2
    return best


BIN_DIVISIONS = 1  # bins of edge reach / BIN_DIVISIONS (2 checks fewer candidates but costs as much here)


class BinnedPoints:
    """Particles and their periodic ghosts, sorted into bins of edge ``reach / m``.

    The building block of :class:`NeighborList` and of the fused one-shot scans
    in :mod:`ase_sphrelax.kernel_sums`. Arrays with suffix ``_s`` are over sorted
    extended points.

    Attributes
    ----------
    x_sc, src_s, img_sc, shift_sc, is_ghost_s, cut_s : ndarray
        Position (at the build, then at the last :meth:`extend`), source particle,
        integer image, Cartesian shift, ghost flag and cut-off of each sorted extended point.
    bin_s, nbin_c, bin_start, stencil_kc : ndarray
        Bin of each point, bins per axis, CSR start of each bin, forward half stencil.
    origin_c, bin_size : ndarray, float
        Corner of bin (0, 0, 0) and the bin edge: point x is in bin ``floor((x - origin_c) / bin_size)``
        (clamped to the grid), at the positions of the build. Other searches on the same bins
        (particle-boundary queries, :mod:`ase_sphrelax.boundary`) use them.
    """

    def __init__(self, r_pc, cell, pbc, cut_p, skin=0.0):
        n = r_pc.shape[0]
        full_cell, inv_cell = complete_cell(cell, pbc)
        reach = float(cut_p.max()) + skin
        # perpendicular widths of the cell; image layers needed per periodic axis
        width_c = 1.0 / np.linalg.norm(inv_cell, axis=0)
        pad_c = np.where(pbc, reach / width_c, 0.0)
        layers_c = np.where(pbc, np.ceil(pad_c), 0).astype(np.int64)
        src_e, img_ec, x_ec = _extended_points(r_pc, full_cell, inv_cell, pbc, pad_c, layers_c)
        n_ext = src_e.shape[0]
        lo_c = x_ec.min(axis=0)
        extent_c = x_ec.max(axis=0) - lo_c
        # bins of edge reach / m scanned with a (2m+1)^d stencil; for sparse sets
        # (bins > 4 per point) fall back to m = 1 and larger bins
        m = BIN_DIVISIONS
        binsize = reach / m
        nbin_c = np.maximum(1, np.floor(extent_c / binsize).astype(np.int64) + 1)
        while np.prod(nbin_c.astype(float)) > 4.0 * n_ext + 64:
            m = 1
            binsize *= 1.5
            nbin_c = np.maximum(1, np.floor(extent_c / binsize).astype(np.int64) + 1)
        order_s, bin_start, bin_s = _bin_sort(x_ec, lo_c, max(binsize, reach / m), nbin_c)
        self.origin_c = lo_c  # bin (0, 0, 0) starts here; bins are cubes of edge bin_size
        self.bin_size = float(max(binsize, reach / m))
        self.n_particles = n
        self.n_extended = n_ext
        self.order_s = order_s
        self.src_e = src_e
        (self.src_s, self.img_sc, self.x_sc, self.shift_sc, self.is_ghost_s,
         self.cut_s) = _sorted_arrays(order_s, src_e, img_ec, x_ec, r_pc, cut_p)
        self._x_buffer = self.x_sc  # extend() writes current positions here
        self.ghost_s = np.nonzero(self.is_ghost_s)[0]
        self.bin_s = bin_s
        self.nbin_c = nbin_c
        self.bin_start = bin_start
        self.stencil_kc = _half_stencil(m, nbin_c)
        self._gather_buffers = {}

    def extend(self, positions):
        """Positions of the sorted extended points for the current ``positions``.

        The array is reused by the next call: copy it to keep it.
        """
        return _gather(np.asarray(positions, dtype=float), self.src_s, self.shift_sc, self._x_buffer)

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

    def fold(self, values_s):
        """Sum per-extended-point values (shape (n_extended,) or (n_extended, k)) onto particles."""
        values_s = np.asarray(values_s, dtype=float)
        flat = values_s.ndim == 1
        out = _fold(values_s.reshape(values_s.shape[0], -1), self.order_s, self.src_e, self.n_particles)
        return out[:, 0] if flat else out

    def fold_threads(self, bufs):
        """Per-particle sums (N, k) of per-thread buffers (T, n_extended, k), ghosts included, for each buffer."""
        return fold_thread_buffers(bufs, self.order_s, self.ghost_s, self.src_e, self.n_particles)

    def loop_arrays(self):
        """("scan", arrays) for the pair loops of :mod:`ase_sphrelax.pairs`: the fused bin scan."""
        return "scan", (self.src_s, self.img_sc, self.is_ghost_s, self.bin_s, self.nbin_c, self.bin_start,
                        self.stencil_kc)


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
    """

    def __init__(self, cutoff, skin=0.0):
        self.cutoff = _check_cutoff(cutoff)
        self.skin = check_skin(skin)
        self.builds = 0
        self.points = None
        self.pair_start = None
        self.pair_j = None
        self._pair_buffer = np.empty(0, dtype=np.int32)
        self._key = None
        self._r0_pc = None
        self._cut_build = None

    # -- public -----------------------------------------------------------------
    @property
    def stored(self):
        """True when a Verlet list is stored (False: one-shot bins, or nothing built)."""
        return self.pair_j is not None

    @property
    def max_cutoff(self):
        """The largest current cut-off."""
        return float(self.cutoff.max())

    def update(self, positions, cell, pbc, cutoff=None, store=True) -> bool:
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
        """
        r_pc = _check_positions(positions)
        pbc = np.array(pbc, dtype=bool).reshape(3) if np.ndim(pbc) else np.array([bool(pbc)] * 3)
        cell = np.array(cell, dtype=float).reshape(3, 3)
        if cutoff is not None:
            self.cutoff = _check_cutoff(cutoff)
        if self.cutoff.ndim == 1 and self.cutoff.shape[0] != r_pc.shape[0]:
            raise ValueError(f"cutoff has {self.cutoff.shape[0]} entries but there are {r_pc.shape[0]} particles")
        key = (r_pc.shape[0], cell.tobytes(), pbc.tobytes())
        if key == self._key and (self.stored or not store) and self._still_valid(r_pc):
            return False
        self._build(r_pc, cell, pbc, store)
        self._key = key
        self._r0_pc = r_pc.copy()
        return True

    def _still_valid(self, r_pc):
        growth = float(np.max(self.cutoff - self._cut_build))
        if not self.stored:  # one-shot bins: only for the positions and cut-offs they were made for
            return growth <= 0.0 and np.array_equal(r_pc, self._r0_pc)
        margin = self.skin - max(growth, 0.0)
        if margin < 0.0:
            return False
        if margin == 0.0:
            return np.array_equal(r_pc, self._r0_pc)
        return _max_displacement2(r_pc, self._r0_pc) <= (0.5 * margin) ** 2

    def extend(self, positions):
        """Positions of the sorted extended points for the current ``positions``."""
        return self.points.extend(positions)

    def gather(self, values_p, slot=0):
        """Per-particle values on the sorted extended points, without image shifts
        (see :meth:`BinnedPoints.gather`)."""
        return self.points.gather(values_p, slot)

    def fold(self, values_s):
        """Sum per-extended-point values onto particles (see :meth:`BinnedPoints.fold`)."""
        return self.points.fold(values_s)

    def fold_threads(self, bufs):
        return self.points.fold_threads(bufs)

    def loop_arrays(self):
        """("list", arrays) when a list is stored, else the one-shot bin scan's ("scan", arrays)."""
        if self.stored:
            return "list", (self.pair_start, self.pair_j)
        return self.points.loop_arrays()

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
        skin = self.skin if store else 0.0
        pts = self.points = BinnedPoints(r_pc, cell, pbc, cut_p, skin)
        if not store:
            self.pair_start = self.pair_j = None
            return
        pair_start = np.zeros(pts.n_extended + 1, dtype=np.int64)
        args = (pts.x_sc, pts.cut_s, pts.src_s, pts.img_sc, pts.is_ghost_s, self.skin, pts.bin_s, pts.nbin_c,
                pts.bin_start, pts.stencil_kc)
        _scan_pairs(*args, pair_start, self._pair_buffer[:0], False)
        np.cumsum(pair_start, out=pair_start)
        if self._pair_buffer.shape[0] < pair_start[-1]:
            # reuse the buffer between builds: fresh pages are expensive to touch
            self._pair_buffer = np.empty(int(1.2 * pair_start[-1]) + 16, dtype=np.int32)
        self.pair_start = pair_start
        self.pair_j = self._pair_buffer[: pair_start[-1]]
        _scan_pairs(*args, pair_start, self.pair_j, True)
        self.builds += 1


def _check_cutoff(cutoff):
    cutoff_arr = np.asarray(cutoff, dtype=float)
    if cutoff_arr.ndim > 1 or cutoff_arr.size == 0 or not np.all(np.isfinite(cutoff_arr)) or np.any(cutoff_arr <= 0):
        raise ValueError(f"cutoff must be a positive finite number or 1D array of them, got {cutoff!r}")
    return cutoff_arr
