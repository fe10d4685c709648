"""Particles against boundary elements: all (particle, segment) pairs in 2D and (particle,
triangle) pairs in 3D within a radius, in O(N + S), on the bins of the neighbour search.

The elements are registered once per bin grid of a
:class:`~ase_sphrelax.neighbors.NeighborList` (``nlist.points``, a
:class:`~ase_sphrelax.neighbors.BinnedPoints`): an element goes into every bin whose centre
lies within ``radius + margin + half the bin diagonal`` of it, where ``margin`` is how far a
particle may have moved since the bins were built (half the skin for a stored list, zero in
the one-shot state). A particle then tests only the elements registered in its own bin, at
its current position: no element within ``radius`` is missed, and the cost is one bin look-up
per particle plus the tests of the particles near the boundary. The registration is reused
until the neighbour list rebuilds its bins. With a stored list, the first query on new bins also
keeps, per particle, the registered elements within ``radius + skin`` (its candidates); later
queries test only those (a particle moves less than half the skin from the build, so every element
within ``radius`` of it is a candidate), in the same order: the pairs of the bin scan at the same positions.

The pairs come in CSR form over particles (:class:`BoundaryPairs`): row ``p`` holds the
elements within ``radius`` of particle ``p`` (of any of its periodic images), with their
distances and the extended point (particle or ghost) that made the pair. A periodic boundary
(``elements.with_cell``) holds the images of its elements around the cell: the particles,
wrapped into the cell by the neighbour list, meet them directly and the ghosts are skipped, so a
particle meets every image within ``radius`` once.
"""
from __future__ import annotations

import math
import weakref

import numba
import numpy as np

from ..domains.closest import closest_on_triangle, segment_distance2
from ..parallel import run_chunks, thread_count

__all__ = ["BoundaryPairs", "BoundaryQuery", "boundary_pairs"]


@numba.njit(cache=True, inline="always")
def _element_dist2(kind, elem, e, x, y, z):
    """Squared distance of (x, y, z) to element e (kind 0: 2D segment packed row, 1: triangle)."""
    if kind == 0:
        d2, _ = segment_distance2(x, y, elem[e, 0], elem[e, 1], elem[e, 2] - elem[e, 0], elem[e, 3] - elem[e, 1],
                           elem[e, 7])
        return d2 + z * z
    return closest_on_triangle(x, y, z, elem[e])[0]


@numba.njit(cache=True)
def _register(kind, elem, origin_c, bin_size, nbin_c, reach, start, out, fill):
    """Bins of every element (count pass with fill=False into start[b+1], then fill pass)."""
    half_diag = 0.5 * bin_size * (math.sqrt(2.0) if kind == 0 else math.sqrt(3.0))
    lim = reach + half_diag
    lim2 = lim * lim
    cursor = np.zeros(start.shape[0], dtype=np.int64)
    n_corner = 2 if kind == 0 else 3
    for e in range(elem.shape[0]):
        lo = np.empty(3)
        hi = np.empty(3)
        for c in range(3):
            lo[c] = np.inf
            hi[c] = -np.inf
        for k in range(n_corner):
            for c in range(3):
                if kind == 0:
                    v = elem[e, 2 * k + c] if c < 2 else 0.0
                else:
                    v = elem[e, 3 * k + c]
                lo[c] = min(lo[c], v)
                hi[c] = max(hi[c], v)
        k_lo = np.empty(3, dtype=np.int64)
        k_hi = np.empty(3, dtype=np.int64)
        empty = False
        for c in range(3):
            a = int(math.floor((lo[c] - reach - origin_c[c]) / bin_size))
            b = int(math.floor((hi[c] + reach - origin_c[c]) / bin_size))
            if b < 0 or a > nbin_c[c] - 1:
                empty = True
            k_lo[c] = max(a, 0)
            k_hi[c] = min(b, nbin_c[c] - 1)
        if empty:
            continue
        for kx in range(k_lo[0], k_hi[0] + 1):
            cx = origin_c[0] + (kx + 0.5) * bin_size
            for ky in range(k_lo[1], k_hi[1] + 1):
                cy = origin_c[1] + (ky + 0.5) * bin_size
                for kz in range(k_lo[2], k_hi[2] + 1):
                    cz = origin_c[2] + (kz + 0.5) * bin_size if kind == 1 else 0.0
                    if _element_dist2(kind, elem, e, cx, cy, cz) > lim2:
                        continue
                    b_bin = (kx * nbin_c[1] + ky) * nbin_c[2] + kz
                    if fill:
                        out[start[b_bin] + cursor[b_bin]] = e
                        cursor[b_bin] += 1
                    else:
                        start[b_bin + 1] += 1


@numba.njit(cache=True, nogil=True)
def _query_chunk(kind, elem, x_sc, bin_s, reg_start, reg_elem, radius2, skip_s, count_s, row_s, elem_k, d_k, fill,
                 first, last):
    """Elements within the radius of sorted points [first, last): counts, then the pairs (none for the
    points ``skip_s`` marks, if it is not empty)."""
    skip = skip_s.shape[0] > 0
    for s in range(first, last):
        if skip and skip_s[s]:
            if not fill:
                count_s[s] = 0
            continue
        b = bin_s[s]
        n = 0
        pos = row_s[s] if fill else 0
        x, y, z = x_sc[s, 0], x_sc[s, 1], x_sc[s, 2]
        for k in range(reg_start[b], reg_start[b + 1]):
            e = reg_elem[k]
            d2 = _element_dist2(kind, elem, e, x, y, z)
            if d2 < radius2:
                if fill:
                    elem_k[pos + n] = e
                    d_k[pos + n] = math.sqrt(d2)
                n += 1
        if not fill:
            count_s[s] = n


@numba.njit(cache=True, nogil=True)
def _filter_chunk(kind, elem, x_sc, cand_row_s, cand_elem, radius2, skip_s, count_s, elem_s, d_s, first, last):
    """The candidates of sorted points [first, last) closer than the radius, kept in their order at the
    start of each point's candidate row (``count_s`` of them; none for the points ``skip_s`` marks)."""
    skip = skip_s.shape[0] > 0
    for s in range(first, last):
        n = 0
        if not (skip and skip_s[s]):
            pos = cand_row_s[s]
            x, y, z = x_sc[s, 0], x_sc[s, 1], x_sc[s, 2]
            for k in range(cand_row_s[s], cand_row_s[s + 1]):
                e = cand_elem[k]
                d2 = _element_dist2(kind, elem, e, x, y, z)
                if d2 < radius2:
                    elem_s[pos + n] = e
                    d_s[pos + n] = math.sqrt(d2)
                    n += 1
        count_s[s] = n


@numba.njit(cache=True)
def _rows_to_particles(src_s, count_s, row_s, elem_s, d_s, n):
    """Regroup the pairs of the sorted extended points by particle (a particle and its ghosts)."""
    start_p = np.zeros(n + 1, dtype=np.int64)
    for s in range(src_s.shape[0]):
        start_p[src_s[s] + 1] += count_s[s]
    for p in range(n):
        start_p[p + 1] += start_p[p]
    cursor = start_p[:-1].copy()
    m = start_p[n]
    elem_k = np.empty(m, dtype=np.int64)
    d_k = np.empty(m)
    point_k = np.empty(m, dtype=np.int64)
    for s in range(src_s.shape[0]):
        p = src_s[s]
        for i in range(count_s[s]):
            k = cursor[p]
            elem_k[k] = elem_s[row_s[s] + i]
            d_k[k] = d_s[row_s[s] + i]
            point_k[k] = s
            cursor[p] += 1
    return start_p, elem_k, d_k, point_k


class BoundaryPairs:
    """(particle, element) pairs within ``radius``, CSR over particles.

    Attributes
    ----------
    start_p : ndarray of int64 (N + 1,)
        Row ``p`` is ``start_p[p]:start_p[p + 1]``.
    element_k : ndarray of int64
        Segment or triangle index of each pair.
    distance_k : ndarray
        Distance from the particle (image) to the element.
    point_k : ndarray of int64
        Sorted extended point of the pair (index into ``x_sc``, the positions of
        ``nlist.extend``): the particle itself or one of its periodic ghosts.
    x_sc : ndarray (n_extended, 3)
        A copy of the extended positions the pairs were found for.
    radius : float
    """

    def __init__(self, start_p, element_k, distance_k, point_k, x_sc, radius):
        self.start_p = start_p
        self.element_k = element_k
        self.distance_k = distance_k
        self.point_k = point_k
        self.x_sc = x_sc
        self.radius = radius

    @property
    def n_particles(self):
        return len(self.start_p) - 1

    @property
    def n_pairs(self):
        return len(self.element_k)

    @property
    def count_p(self):
        """Number of elements within the radius of each particle."""
        return np.diff(self.start_p)

    @property
    def particle_k(self):
        """Particle of each pair."""
        return np.repeat(np.arange(self.n_particles), self.count_p)

    def nearest_distance(self):
        """Distance of each particle to its nearest element within the radius (inf if none)."""
        out = np.full(self.n_particles, np.inf)
        rows = np.flatnonzero(self.start_p[1:] != self.start_p[:-1])  # a bool temporary, not an int64 diff
        if len(rows):  # CSR rows are contiguous: one reduceat over the non-empty rows
            out[rows] = np.minimum.reduceat(self.distance_k, self.start_p[rows])
        return out


def _deref(ref):
    """The object of a weak reference, None for none or a dead one."""
    return None if ref is None else ref()


def _kind(elements):
    from .segments import BoundarySegments
    from .triangles import BoundaryTriangles

    if isinstance(elements, BoundarySegments):
        return 0, elements.packed_sk
    if isinstance(elements, BoundaryTriangles):
        return 1, elements.packed_tk
    raise TypeError(f"elements must be BoundarySegments or BoundaryTriangles, got {type(elements).__name__}")


class BoundaryQuery:
    """Pairs of particles and boundary elements within a radius, on a neighbour list's bins.

    Parameters
    ----------
    elements : BoundarySegments or BoundaryTriangles

    The registration of the elements in the bins is kept until the neighbour list builds new
    bins (or the radius grows).
    """

    def __init__(self, elements):
        self.elements = elements
        self.kind, self._elem = _kind(elements)
        self.periodic = getattr(elements, "periodic", None)
        self._points = None
        self._reach = -1.0
        self._reg = None
        self.registrations = 0
        self._cand_key = None
        self._cand = None
        self.candidate_builds = 0

    def _registered(self, pts, reach):
        if _deref(self._points) is pts and reach <= self._reach:
            return self._reg
        nbins = int(np.prod(pts.nbin_c))
        start = np.zeros(nbins + 1, dtype=np.int64)
        args = (self.kind, self._elem, np.asarray(pts.origin_c, dtype=float), float(pts.bin_size),
                np.asarray(pts.nbin_c, dtype=np.int64), float(reach))
        _register(*args, start, np.empty(0, dtype=np.int64), False)
        np.cumsum(start, out=start)
        out = np.empty(start[-1], dtype=np.int64)
        _register(*args, start, out, True)
        # weak references to the bins: the old bins go when the neighbour list rebuilds (not kept alive here)
        self._points, self._reach, self._reg = weakref.ref(pts), reach, (start, out)
        self.registrations += 1
        return self._reg

    def _within(self, x_sc, pts, reg_start, reg_elem, radius2, skip_s, count_s):
        """Rows ``(row_s, elem_s, d_s)`` of the registered elements closer than ``sqrt(radius2)`` to each point."""
        n_ext = x_sc.shape[0]
        row_s = np.zeros(n_ext + 1, dtype=np.int64)
        common = (self.kind, self._elem, x_sc, pts.bin_s, reg_start, reg_elem, radius2, skip_s, count_s)
        run_chunks(_query_chunk, n_ext, common + (row_s, np.empty(0, dtype=np.int64), np.empty(0), False))
        np.cumsum(count_s, out=row_s[1:])
        elem_s = np.empty(row_s[-1], dtype=np.int64)
        d_s = np.empty(row_s[-1])
        run_chunks(_query_chunk, n_ext, common + (row_s, elem_s, d_s, True))
        return row_s, elem_s, d_s

    def _candidates(self, pts, x_sc, reg_start, reg_elem, radius, margin, skip_s, scratch=True):
        """Per sorted point, the registered elements within ``radius + 2 margin`` (``row_s``, ``cand_elem``), kept
        while the bins stay, and (``scratch``) scratch rows of the same size for the kept pairs (made on first
        use: :meth:`sources` needs none)."""
        if self._cand_key is None or _deref(self._cand_key[0]) is not pts or self._cand_key[1:] != (radius, margin):
            self._cand = None  # the old candidates go before the new ones are made
            count_s = np.zeros(x_sc.shape[0], dtype=np.int64)
            row_s, cand_elem, _ = self._within(x_sc, pts, reg_start, reg_elem, (radius + 2.0 * margin) ** 2, skip_s,
                                               count_s)
            self._cand_key = (weakref.ref(pts), radius, margin)
            self._cand = (row_s, cand_elem, None, None)
            self.candidate_builds += 1
        if scratch and self._cand[2] is None:  # scratch for the kept pairs, reused by every call on these bins
            row_s, cand_elem = self._cand[:2]
            self._cand = (row_s, cand_elem, np.empty(len(cand_elem), dtype=np.int64), np.empty(len(cand_elem)))
        return self._cand

    def sources(self, nlist, r_pc, radius):
        """What a fused query needs (:func:`~ase_sphrelax.boundary.gamma._rows_fused`): ``(x_sc, points, by_bin,
        src_start, src_elem, work)``, the rows of elements each sorted point tests, by bin (the registration,
        one-shot bins) or by point (the candidates of a stored list), as :meth:`pairs` tests them; None when a
        ghost can meet an element (bounded elements with periodic particles: use :meth:`pairs`)."""
        radius = self._check_radius(radius)
        pts = nlist.points
        if self.periodic is None and pts.n_extended != pts.n_particles:
            return None
        margin = 0.5 * nlist.skin if nlist.stored else 0.0
        reg_start, reg_elem = self._registered(pts, radius + margin)
        x_sc = nlist.extend(r_pc)
        if margin > 0.0:
            skip_s = pts.is_ghost_s if self.periodic is not None else np.zeros(0, dtype=np.bool_)
            row_s, cand_elem = self._candidates(pts, x_sc, reg_start, reg_elem, radius, margin, skip_s,
                                                scratch=False)[:2]
            return x_sc, pts, False, row_s, cand_elem, len(cand_elem)
        return x_sc, pts, True, reg_start, reg_elem, x_sc.shape[0]

    def _check_radius(self, radius):
        radius = float(radius)
        if not radius > 0:
            raise ValueError(f"radius must be > 0, got {radius!r}")
        if self.periodic is not None and radius > self.periodic.image_reach:
            raise ValueError(f"radius (the kernel support h) {radius!r} exceeds the periodic images' reach "
                             f"{self.periodic.image_reach!r}; build the boundary with with_cell(..., reach=k) for "
                             "k periods of images")
        return radius

    def pairs(self, nlist, r_pc, radius):
        """All (particle, element) pairs closer than ``radius``.

        Parameters
        ----------
        nlist : NeighborList
            Updated for ``r_pc`` (stored list or one-shot bins).
        r_pc : ndarray (N, 3)
            Current positions (2D: z = 0).
        radius : float

        Returns
        -------
        BoundaryPairs
        """
        radius = self._check_radius(radius)
        pts = nlist.points
        margin = 0.5 * nlist.skin if nlist.stored else 0.0
        reg_start, reg_elem = self._registered(pts, radius + margin)
        x_sc = nlist.extend(r_pc)
        n_ext = x_sc.shape[0]
        # periodic elements are images around the cell: the particles (wrapped into it) meet them, not their ghosts
        skip_s = pts.is_ghost_s if self.periodic is not None else np.zeros(0, dtype=np.bool_)
        count_s = np.zeros(n_ext, dtype=np.int64)
        if margin > 0.0:
            # a stored list: the candidates within radius + 2 margin of the positions of the first call on these
            # bins hold every pair until the bins change (each point moves less than the margin from the build)
            row_s, cand_elem, elem_s, d_s = self._candidates(pts, x_sc, reg_start, reg_elem, radius, margin, skip_s)
            run_chunks(_filter_chunk, n_ext, (self.kind, self._elem, x_sc, row_s, cand_elem, radius * radius, skip_s,
                                              count_s, elem_s, d_s), nthreads=thread_count(len(cand_elem)))
        else:
            row_s, elem_s, d_s = self._within(x_sc, pts, reg_start, reg_elem, radius * radius, skip_s, count_s)
        start_p, elem_k, d_k, point_k = _rows_to_particles(pts.src_s, count_s, row_s, elem_s, d_s, nlist.n_particles)
        return BoundaryPairs(start_p, elem_k, d_k, point_k, x_sc.copy(), radius)


def boundary_pairs(r_pc, elements, radius, cell=None, pbc=None):
    """One-shot query: (particle, element) pairs within ``radius`` of positions ``r_pc`` (N, 3).

    Bins the particles with a one-shot :class:`~ase_sphrelax.neighbors.NeighborList` of cut-off
    ``radius``. ``cell``/``pbc`` default to the elements' own (bounded, or the periods of a
    periodic boundary, ``elements.with_cell``): the pairs then include those of the periodic images.
    """
    from ..neighbors import NeighborList

    r_pc = np.asarray(r_pc, dtype=float)
    nlist = NeighborList(radius)
    if pbc is None:
        pbc = getattr(elements, "pbc", False)
        cell = getattr(elements, "cell", None) if cell is None else cell
    nlist.update(r_pc, np.zeros((3, 3)) if cell is None else cell, pbc, store=False)
    return BoundaryQuery(elements).pairs(nlist, r_pc, radius)
