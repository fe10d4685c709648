"""Polygonal 2D domains with holes: exact signed distance in numba (Fan Sec. 2).

``phi`` is the signed Euclidean distance to the boundary segments.  The
nearest segment is found among the candidates of a uniform bucket grid (cells
whose candidate list provably contains the nearest segment); the sign comes
from the nearest feature: the outward segment normal if the closest point is
inside a segment, the vertex pseudo-normal (sum of the two adjacent segment
normals, Baerentzen & Aanaes 2005) if it is a vertex.  The normal is
``grad phi = sign * (r - q) / |r - q|`` with ``q`` the closest point, i.e.
the exact gradient of the ``phi`` returned (one-sided on the medial axis).

Runs of exactly collinear segments are merged first (same ``phi``):
AirFoilFluid 5224 -> 686 segments, Standford2DBunny 882 -> 695.

Exact versus tabulated (``grid_spacing``), measured on this machine (2 vCPU,
ranges: quiet machine .. load average 6) with
``python -m ase_sphrelax.domains.benchmark FILE.edges``: time of
``phi_and_normal`` for 1e4 random points in the bounding box, and the
tabulated error within 3 dx of the boundary for dx = size / 256:

=================  ========  ===========  ============  ====================
geometry           segments  exact        tabulated     tabulated max error
=================  ========  ===========  ============  ====================
TrapezoidalTank    4         0.7-1.5 ms   0.7-0.9 ms    0.04 dx (corners)
Standford2DBunny   695       3-6 ms       0.8-2.7 ms    0.09 dx
AirFoilFluid       686       1.6-4.4 ms   0.8-1.6 ms    0.31 dx (trailing edge)
EllipticDrop       3140      14-22 ms     0.8 ms        3e-5 dx
=================  ========  ===========  ============  ====================

For comparison, one SPH energy+forces evaluation with numpy + cKDTree costs
about 16 ms per 1e4 particles here.  The exact distance has no
interpolation error at corners (the tabulated one reaches 0.3 dx at the
airfoil's trailing edge), so it is the default; the tabulated mode, which is
what Fan et al. use (Sec. 2), is faster for boundaries made of thousands of
short segments: deep inside a nearly circular boundary every segment is a
candidate, the worst case of the bucket search (EllipticDrop).
"""
from __future__ import annotations

import math

import numba
import numpy as np

from ..checks import check_positive
from .base import SearchedDomain
from .closest import segment_distance2
from .loops import EdgeLoop, first_crossing, read_edges, signed_area, validate_loops, vertex_array  # noqa: F401


# ----------------------------------------------------------------------------
# numba kernels
# ----------------------------------------------------------------------------
@numba.njit(cache=True)
def _bucket_count(seg, glo, gh, gn, out_count, out_list, out_dist, fill):
    """Candidate segments per bucket cell (two passes: count, then fill).

    For a point p in a cell with centre c and half diagonal rho, the nearest
    segment s* satisfies dist(c, s*) <= dist(c, s_c) + 2 rho, where s_c is
    the segment nearest to c; all such segments are candidates.  The fill
    pass sorts each list by dist(c, s) (stored in ``out_dist``) so that the
    search can stop once dist(c, s) - |p - c| exceeds the best distance.
    """
    n_seg = seg.shape[0]
    rho2 = gh * math.sqrt(2.0)  # 2 * half diagonal = full diagonal
    d2 = np.empty(n_seg)
    for ix in range(gn[0]):
        for iy in range(gn[1]):
            cx = glo[0] + (ix + 0.5) * gh
            cy = glo[1] + (iy + 0.5) * gh
            best = np.inf
            for s in range(n_seg):
                d, t = segment_distance2(cx, cy, seg[s, 0], seg[s, 1], seg[s, 2], seg[s, 3], seg[s, 4])
                d2[s] = d
                if d < best:
                    best = d
            lim = math.sqrt(best) + rho2 + 1e-12 * (1.0 + math.sqrt(best))
            lim2 = lim * lim
            cell = ix * gn[1] + iy
            k = 0
            for s in range(n_seg):
                if d2[s] <= lim2:
                    if fill:
                        out_list[out_count[cell] + k] = s
                        out_dist[out_count[cell] + k] = math.sqrt(d2[s])
                    k += 1
            if fill:
                k0 = out_count[cell]
                order = np.argsort(out_dist[k0:k0 + k])
                list_k = out_list[k0:k0 + k].copy()
                dist_k = out_dist[k0:k0 + k].copy()
                for q in range(k):  # element by element: a slice copy compiles numba's shape-mismatch message
                    out_list[k0 + q] = list_k[order[q]]
                    out_dist[k0 + q] = dist_k[order[q]]
            else:
                out_count[cell + 1] = k


@numba.njit(cache=True)
def _polygon_phi_grad(r_pd, seg, nrm, vna, vnb, glo, gh, gn, start, cand, cdist, phi_p, g_pd):
    """Signed distance and its gradient for every point (see module doc)."""
    n_seg = seg.shape[0]
    for p in range(r_pd.shape[0]):
        px = r_pd[p, 0]
        py = r_pd[p, 1]
        if not (math.isfinite(px) and math.isfinite(py)):
            phi_p[p] = np.nan
            g_pd[p, 0] = np.nan
            g_pd[p, 1] = np.nan
            continue
        ix = int(math.floor((px - glo[0]) / gh))
        iy = int(math.floor((py - glo[1]) / gh))
        best = np.inf
        bs = 0
        bt = 0.0
        if 0 <= ix < gn[0] and 0 <= iy < gn[1]:
            cell = ix * gn[1] + iy
            off = math.sqrt((px - glo[0] - (ix + 0.5) * gh) ** 2 + (py - glo[1] - (iy + 0.5) * gh) ** 2)
            for k in range(start[cell], start[cell + 1]):
                # lower bound of dist(p, s): dist(c, s) - |p - c|
                lb = cdist[k] - off
                if lb > 0.0 and lb * lb > best * (1.0 + 1e-12):
                    break
                s = cand[k]
                d, t = segment_distance2(px, py, seg[s, 0], seg[s, 1], seg[s, 2], seg[s, 3], seg[s, 4])
                if d < best:
                    best = d
                    bs = s
                    bt = t
        else:
            for s in range(n_seg):
                d, t = segment_distance2(px, py, seg[s, 0], seg[s, 1], seg[s, 2], seg[s, 3], seg[s, 4])
                if d < best:
                    best = d
                    bs = s
                    bt = t
        qx = seg[bs, 0] + bt * seg[bs, 2]
        qy = seg[bs, 1] + bt * seg[bs, 3]
        dx = px - qx
        dy = py - qy
        if bt <= 0.0:
            nx = vna[bs, 0]
            ny = vna[bs, 1]
        elif bt >= 1.0:
            nx = vnb[bs, 0]
            ny = vnb[bs, 1]
        else:
            nx = nrm[bs, 0]
            ny = nrm[bs, 1]
        dist = math.sqrt(best)
        side = dx * nx + dy * ny
        if dist == 0.0 or side == 0.0:
            phi_p[p] = 0.0 if dist == 0.0 else dist
            g_pd[p, 0] = nrm[bs, 0]
            g_pd[p, 1] = nrm[bs, 1]
            continue
        sgn = 1.0 if side > 0.0 else -1.0
        phi_p[p] = sgn * dist
        g_pd[p, 0] = sgn * dx / dist
        g_pd[p, 1] = sgn * dy / dist


# ----------------------------------------------------------------------------
# loop handling
# ----------------------------------------------------------------------------
def _clean_loop(loop, name, tol):
    v = vertex_array(loop, name)
    # drop repeated consecutive vertices and an explicit closing vertex
    keep = np.ones(len(v), bool)
    if len(v) > 1:
        keep[1:] = np.linalg.norm(np.diff(v, axis=0), axis=1) > tol
    v = v[keep]
    if len(v) > 1 and np.linalg.norm(v[0] - v[-1]) <= tol:
        v = v[:-1]
    if len(v) < 3:
        raise ValueError(f"{name} needs at least 3 distinct vertices, got {len(v)}")
    # merge runs of exactly collinear segments (same distance function, far
    # fewer candidates: the 80 x 30 box of AirFoilFluid has 4400 segments)
    e_prev = v - np.roll(v, 1, axis=0)
    e_next = np.roll(v, -1, axis=0) - v
    cross = e_prev[:, 0] * e_next[:, 1] - e_prev[:, 1] * e_next[:, 0]
    dot = np.einsum("vd,vd->v", e_prev, e_next)
    scale = np.linalg.norm(e_prev, axis=1) * np.linalg.norm(e_next, axis=1)
    straight = (np.abs(cross) <= 1e-12 * scale) & (dot > 0.0)
    if np.count_nonzero(~straight) >= 3:
        v = v[~straight]
    return v


class Polygon(SearchedDomain):
    """2D domain bounded by closed polygonal loops (outer boundaries and holes).

    Parameters
    ----------
    loops : list of (k, 2) arrays
        Vertex loops (implicitly closed; a repeated first vertex is dropped).
        The role of each loop follows from nesting (even-odd rule): a loop
        inside an odd number of other loops is a hole.  For valid input this
        agrees with the orientation convention of the geometry files (outer
        counter-clockwise, holes clockwise); orientations are normalised.
    holes : list of (k, 2) arrays, optional
        Extra loops given explicitly as holes; each must lie inside a loop of
        ``loops``.
    grid_spacing : float, optional
        If given, ``phi`` is tabulated on a background mesh of this spacing
        and interpolated (C1 Catmull-Rom, Fan Sec. 2); see
        :class:`~ase_sphrelax.domains.table.CubicTable`.  Default: exact
        distance (bucketed numba); timings and errors of both in the module
        docstring.
    tol : float, optional
        Vertex coincidence tolerance (default ``1e-9 * size``).

    Raises
    ------
    ValueError
        Loops with fewer than 3 vertices, self-crossing loops, loops crossing
        each other, holes outside every outer loop.
    """

    dim = 2

    def __init__(self, loops, holes=None, grid_spacing=None, tol=None):
        if isinstance(loops, np.ndarray) and loops.ndim == 2:
            loops = [loops]
        if isinstance(loops, (str, bytes)) or hasattr(loops, "__fspath__"):
            raise TypeError(f"loops must be vertex arrays, got the path {str(loops)!r}: read an edge file with "
                            f"Polygon.from_edges({str(loops)!r})")
        if not isinstance(loops, (list, tuple)) or len(loops) == 0:
            raise TypeError("loops must be a non-empty list of (k, 2) vertex arrays")
        holes = [] if holes is None else list(holes)
        raw = list(loops) + holes
        names = [f"loops[{i}]" for i in range(len(loops))] + [f"holes[{i}]" for i in range(len(holes))]
        if tol is None:
            try:
                allv = np.concatenate([np.asarray(v, float).reshape(-1, 2) for v in raw])
                tol = 1e-9 * max(1.0, float(np.ptp(allv, axis=0).max()))
            except ValueError:
                tol = 1e-9
        vloops = [_clean_loop(v, n, tol) for v, n in zip(raw, names)]
        depth = validate_loops(vloops, names)
        for i in range(len(loops), len(raw)):
            if depth[i] % 2 == 0:
                raise ValueError(f"{names[i]} is not inside an outer loop of loops")
        self.loops = []
        for v, dep in zip(vloops, depth):
            ccw = signed_area(v) > 0.0
            if ccw != (dep % 2 == 0):
                v = v[::-1].copy()
            self.loops.append(np.ascontiguousarray(v))
        self._area = float(sum(signed_area(v) for v in self.loops))
        self._build_segments()
        self._table = None
        if grid_spacing is not None:
            from .table import CubicTable

            grid_spacing = check_positive("grid_spacing", grid_spacing)
            self._table = CubicTable(self._exact_phi, self.bounds, grid_spacing)

    @classmethod
    def from_edges(cls, path, grid_spacing=None, tol=None):
        """Read a ``x1 y1 x2 y2`` per line edge file (several loops allowed).

        Segments are chained into loops by matching end points within ``tol``
        (default ``1e-9 * size``); a dangling or branching end point raises
        ValueError naming its position.
        """
        return cls(read_edges(path, tol), grid_spacing=grid_spacing, tol=tol)

    # ------------------------------------------------------------------
    def _build_segments(self):
        a_l, b_l, n_l, vna_l, vnb_l = [], [], [], [], []
        for v in self.loops:
            w = np.roll(v, -1, axis=0)
            e = w - v
            length = np.linalg.norm(e, axis=1)
            n = np.stack([e[:, 1], -e[:, 0]], axis=1) / length[:, None]
            n_prev = np.roll(n, 1, axis=0)
            n_next = np.roll(n, -1, axis=0)
            a_l.append(v)
            b_l.append(e)
            n_l.append(n)
            vna_l.append(n_prev + n)
            vnb_l.append(n + n_next)
        a = np.concatenate(a_l)
        e = np.concatenate(b_l)
        self._seg = np.ascontiguousarray(
            np.column_stack([a, e, 1.0 / np.einsum("sd,sd->s", e, e)]))
        self._nrm = np.ascontiguousarray(np.concatenate(n_l))
        self._vna = np.ascontiguousarray(np.concatenate(vna_l))
        self._vnb = np.ascontiguousarray(np.concatenate(vnb_l))
        # bucket grid: about 2 segments per cell, at most 256^2 cells
        lo, hi = self.bounds
        ext = hi - lo
        n_cells = min(max(2 * len(a), 16), 256 * 256)
        gh = math.sqrt(ext[0] * ext[1] / n_cells) if ext.min() > 0 else ext.max() / 16
        self._glo = lo - gh
        self._gh = float(gh)
        self._gn = (np.ceil((ext + 2 * gh) / gh).astype(np.int64) + 1)
        n_cell = int(self._gn[0] * self._gn[1])
        start = np.zeros(n_cell + 1, np.int64)
        _bucket_count(self._seg, self._glo, self._gh, self._gn, start,
                      np.empty(0, np.int64), np.empty(0), False)
        start = np.cumsum(start)
        cand = np.empty(start[-1], np.int64)
        cdist = np.empty(start[-1])
        _bucket_count(self._seg, self._glo, self._gh, self._gn, start, cand, cdist, True)
        self._start, self._cand, self._cdist = start, cand, cdist

    def _exact_phi_grad(self, r_pd):
        r_pd = np.ascontiguousarray(r_pd, dtype=float)
        phi_p = np.empty(len(r_pd))
        g_pd = np.empty_like(r_pd)
        _polygon_phi_grad(r_pd, self._seg, self._nrm, self._vna, self._vnb, self._glo,
                          self._gh, self._gn, self._start, self._cand, self._cdist, phi_p, g_pd)
        return phi_p, g_pd

    @property
    def n_segments(self):
        return len(self._seg)

    @property
    def bounds(self):
        v = np.concatenate(self.loops)
        return v.min(axis=0), v.max(axis=0)

    @property
    def volume(self):
        """Exact enclosed area (shoelace over oriented loops, = shapely area)."""
        return self._area

    def area_geometry(self):
        """The polygon as shapely geometry (exact CSG areas)."""
        return self.to_shapely()

    def to_shapely(self):
        """The domain as a shapely (Multi)Polygon."""
        import shapely

        # containers are larger than what they contain: add outer loops (ccw),
        # cut holes (cw), from the largest loop down (islands in holes work)
        geom = shapely.Polygon()
        for v in sorted(self.loops, key=lambda v: -abs(signed_area(v))):
            p = shapely.Polygon(v)
            geom = geom.union(p) if signed_area(v) > 0 else geom.difference(p)
        return geom

    def opening(self, radius, quad_segs=8):
        """The domain's morphological opening at ``radius``: the union of the discs of that radius that lie inside it.

        Every point at least ``radius`` from the wall is inside the opening, with the disc around it. Convex corners
        become arcs of that radius, and concave corners and straight walls stay as they are. Parts narrower than
        ``2 radius`` (the last stretch of a sharp tip, a thin sliver) are left out: no point there is ``radius``
        from both walls. Computed by shapely (``buffer(-radius).buffer(radius)``), each quarter turn of an arc as
        ``quad_segs`` segments, whose vertices lie on the arc (with 8, the chords cut it by at most 0.5 % of ``radius``).

        Parameters
        ----------
        radius : float
            > 0, in the domain's length unit.
        quad_segs : int
            Segments per quarter circle of the arcs (shapely's ``quad_segs``), at least 1.

        Returns
        -------
        Polygon
            The opening, its loops ordered as shapely gives them (parts that a narrow neck separates stay apart).

        Raises
        ------
        ValueError
            When nothing is left: the domain is nowhere ``2 radius`` wide.
        """
        radius = check_positive("radius", radius)
        if int(quad_segs) != quad_segs or quad_segs < 1:
            raise ValueError(f"quad_segs must be an integer >= 1, got {quad_segs!r}")
        opened = self.to_shapely().buffer(-radius, quad_segs=int(quad_segs)).buffer(radius, quad_segs=int(quad_segs))
        parts = [g for g in getattr(opened, "geoms", [opened]) if not g.is_empty and g.area > 0.0]
        if not parts:
            raise ValueError(f"radius: the domain is nowhere 2 * {radius:g} wide, its opening at that radius is "
                             f"empty")
        loops = []
        for part in parts:
            loops.append(np.asarray(part.exterior.coords)[:-1])
            loops += [np.asarray(ring.coords)[:-1] for ring in part.interiors]
        return Polygon(loops)

    def __repr__(self):
        return (f"Polygon({len(self.loops)} loops, {self.n_segments} segments, "
                f"area={self._area:.6g}"
                + (f", grid_spacing={self._table.dx:g})" if self._table is not None else ")"))
