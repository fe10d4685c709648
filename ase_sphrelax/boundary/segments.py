"""2D boundaries as straight segments with unit inward normals (Boregowda & Liu Sec. 2.1, Fig. 1b).

A :class:`BoundarySegments` is a set of closed loops, each oriented with the domain (the
fluid) on the **left** of every segment: outer boundaries run counter-clockwise, holes
clockwise, as in the files of ``../shared/geometries``. The unit inward normal of a segment
with direction ``t`` is ``n = (-t_y, t_x)``.

BIPI2D's own edge files list *outward* normals; ours carry no normals, the orientation of
the loops is the information. Sources: :meth:`BoundarySegments.from_polygon` (a
:class:`~ase_sphrelax.domains.Polygon`, holes included), :meth:`~BoundarySegments.from_edges`
(``x1 y1 x2 y2`` per line), :meth:`~BoundarySegments.from_vertices` (vertex loops) and
:meth:`~BoundarySegments.from_domain` (polygons, 2D boxes and polygonal CSG results).

Periodic directions: :meth:`BoundarySegments.with_cell` (or ``pbc=``/``cell=`` of
:meth:`~BoundarySegments.from_edges` and :meth:`~BoundarySegments.from_polygon`) drops the edges
on the periodic faces and keeps the images of the others around the cell
(:mod:`ase_sphrelax.boundary.periodic`).

Orientation is checked: a loop whose orientation contradicts its role (an outer loop that
runs clockwise, a hole that runs counter-clockwise; the role follows from nesting, even-odd
rule) is reversed with an :class:`OrientationWarning`. An edge file whose loop mixes segment
directions is ambiguous and an error, as are open polylines, branching end points,
zero-length segments and crossings; the messages name the file and the segment index.
"""
from __future__ import annotations

import warnings

import numpy as np

from ..checks import SphrelaxWarning
from ..domains.loops import signed_area, vertex_array

__all__ = ["BoundarySegments", "OrientationWarning", "EDGE_TO_DX_RATIO"]

# BIPI2D's edge_to_dx_ratio: segments are refined to dx_r / dx_s >= 10 (the paper requires > 1)
EDGE_TO_DX_RATIO = 10.0


class OrientationWarning(SphrelaxWarning):
    """A boundary loop ran the wrong way round and was reversed."""


class BoundarySegments:
    """Closed loops of straight segments, the domain on the left of each (inward normals).

    Build one with :meth:`from_polygon`, :meth:`from_edges`, :meth:`from_vertices` or
    :meth:`from_domain`; the constructor takes loops that are already valid and oriented.

    Parameters
    ----------
    loops : list of ndarray (k, 2)
        Vertex loops (implicitly closed), each with the domain on its left.
    source_s : ndarray of int, optional
        For every segment, the index of the input segment it comes from (file line, segment of
        the polygon or vertex list); kept by :meth:`refine`. Default: its own index.
    name : str, optional
        Where the segments come from (a file name), used in messages.

    Attributes
    ----------
    start_sc, end_sc : ndarray (S, 2)
        End points of each segment (``end_sc[s] == start_sc[next_s[s]]`` exactly; modulo the
        periods for periodic segments).
    normal_sc : ndarray (S, 2)
        Unit inward normals (into the domain).
    tangent_sc : ndarray (S, 2)
        Unit directions ``(end - start) / length``.
    length_s : ndarray (S,)
    surface : float
        Total length of the walls (of one period, for periodic segments: images not counted).
    centroid_sc : ndarray (S, 2)
        Mid points.
    periodic : PeriodicCell or None
        The periodic directions (:meth:`with_cell`), None when bounded; the elements are then the
        segments of one period and their images around the cell.
    cell, pbc : ndarray (3, 3), ndarray of bool (3,)
        The periods as an ASE cell (zero rows along bounded axes) and the periodic axes; zeros
        and all False when bounded.
    loop_s, next_s, prev_s : ndarray of int (S,)
        Loop of each segment and its neighbours along the loop.
    packed_sk : ndarray (S, 8)
        ``ax, ay, bx, by, nx, ny, length, 1 / length^2`` for the numba loops.
    """

    dim = 2

    def __init__(self, loops, source_s=None, name=None):
        loops = [np.ascontiguousarray(np.asarray(v, dtype=float)) for v in loops]
        if not loops or any(v.ndim != 2 or v.shape[1] != 2 or len(v) < 3 for v in loops):
            raise ValueError("loops must be a non-empty list of (k >= 3, 2) vertex arrays")
        self.loops = loops
        self.name = name
        start = np.concatenate(loops)
        end = np.concatenate([np.roll(v, -1, axis=0) for v in loops])
        counts = [len(v) for v in loops]
        first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        loop_s = np.repeat(np.arange(len(loops)), counts)
        local = np.arange(len(start)) - first[loop_s]
        size = np.asarray(counts)[loop_s]
        next_s = first[loop_s] + (local + 1) % size
        prev_s = first[loop_s] + (local - 1) % size
        source_s = np.arange(len(start)) if source_s is None else np.asarray(source_s, dtype=np.int64)
        if source_s.shape != (len(start),):
            raise ValueError(f"source_s must have one entry per segment ({len(start)}), got {source_s.shape}")
        self._set_segments(start, end, loop_s, next_s, prev_s, source_s)
        self.periodic = None
        self.cell = np.zeros((3, 3))
        self.pbc = np.zeros(3, dtype=bool)
        self._polygon = None
        self._domain = None
        self.surface = float(np.sum(self.length_s))  # the walls' length (of one period, when periodic)

    def _set_segments(self, start, end, loop_s, next_s, prev_s, source_s):
        """The per-segment arrays (the class docstring's attributes) of segments ``start -> end``."""
        edge = end - start
        length = np.sqrt(np.einsum("sc,sc->s", edge, edge))
        if not np.all(length > 0):
            s = int(np.nonzero(~(length > 0))[0][0])
            raise ValueError(f"segment {s} has zero length")
        self.start_sc = np.ascontiguousarray(start)
        self.end_sc = np.ascontiguousarray(end)
        self.length_s = length
        self.tangent_sc = edge / length[:, None]
        self.normal_sc = np.stack([-self.tangent_sc[:, 1], self.tangent_sc[:, 0]], axis=1)
        self.centroid_sc = 0.5 * (start + end)
        self.loop_s, self.next_s, self.prev_s = loop_s, next_s, prev_s
        self.source_s = source_s
        self.packed_sk = np.ascontiguousarray(np.column_stack(
            [start, end, self.normal_sc, length, 1.0 / length**2]))

    # -- sources ------------------------------------------------------------------
    @classmethod
    def from_polygon(cls, polygon, pbc=None, cell=None):
        """The segments of a :class:`~ase_sphrelax.domains.Polygon` (its loops, holes included).

        The polygon's loops are already validated and oriented (outer counter-clockwise,
        holes clockwise); runs of exactly collinear segments were merged by the polygon.
        ``pbc`` (and ``cell``): periodic directions, as :meth:`with_cell`.
        """
        from ..domains.polygon import Polygon

        if not isinstance(polygon, Polygon):
            raise TypeError(f"polygon must be an ase_sphrelax.domains.Polygon, got {type(polygon).__name__}")
        out = cls(polygon.loops, name=repr(polygon))
        out._polygon = polygon
        return out if pbc is None else out.with_cell(pbc, cell)

    @classmethod
    def from_vertices(cls, loops, holes=None, name="vertices"):
        """Segments of closed vertex loops (a repeated closing vertex is dropped).

        Parameters
        ----------
        loops : (k, 2) array or list of them
            Loops; the role of each (outer boundary or hole) follows from nesting.
        holes : list of (k, 2) arrays, optional
            Loops given explicitly as holes (each must lie inside an outer loop).

        Loops whose orientation contradicts their role are reversed with an
        :class:`OrientationWarning`; repeated consecutive vertices (zero-length segments),
        crossings and loops with fewer than 3 vertices are errors naming the loop and segment.
        """
        try:
            single = np.asarray(loops, dtype=float)
        except (TypeError, ValueError):
            single = None
        if single is not None and single.ndim == 2:
            loops = [single]
        if not isinstance(loops, (list, tuple)) or len(loops) == 0:
            raise TypeError("loops must be a (k, 2) vertex array or a non-empty list of them")
        holes = [] if holes is None else list(holes)
        names = [f"{name} loop {i}" for i in range(len(loops))] + [f"{name} hole {i}" for i in range(len(holes))]
        clean = []
        for v, label in zip(list(loops) + holes, names):
            v = vertex_array(v, label)
            if len(v) > 1 and np.array_equal(v[0], v[-1]):
                v = v[:-1]
            if len(v) < 3:
                raise ValueError(f"{label} needs at least 3 distinct vertices, got {len(v)}")
            w = np.roll(v, -1, axis=0)
            zero = np.nonzero(np.all(v == w, axis=1))[0]
            if len(zero):
                raise ValueError(f"{label}: segment {int(zero[0])} has zero length (vertex {int(zero[0])} is repeated)")
            clean.append(v)
        sources = [np.arange(len(v)) for v in clean]
        return cls._oriented(clean, sources, names, n_outer=len(loops), name=name)

    @classmethod
    def from_edges(cls, path, tol=None, pbc=None, cell=None):
        """Segments of an edge file, ``x1 y1 x2 y2`` per line (one or more closed loops).

        End points are matched within ``tol`` (default ``1e-9`` times the size). Each loop must
        list its segments in one direction (the inside on the left for outer loops, as in
        ``../shared/geometries``); a loop that runs the other way round is reversed with an
        :class:`OrientationWarning`. Errors (naming the file and the 0-based segment index):
        unreadable file, open polyline or branching end point, zero-length segment, a loop whose
        segments run in both directions (ambiguous orientation), crossing segments.

        ``pbc`` (and ``cell``): periodic directions (:meth:`with_cell`); the segments on the
        periodic faces, e.g. the ends of a channel drawn as a closed rectangle, are dropped with
        a warning saying how many.
        """
        from ..domains.loops import read_edge_loops

        edge_loops = read_edge_loops(path, tol, strict=True)
        loops, sources, names = [], [], []
        for i, loop in enumerate(edge_loops):
            seg = loop.segment_k
            if not np.all(loop.forward_k):
                k = int(np.nonzero(~loop.forward_k)[0][0])
                raise ValueError(
                    f"{path}: segments {int(seg[0])} and {int(seg[k])} of loop {i} run in opposite directions "
                    "along the loop, so the file's orientation (inside on the left) is ambiguous; write every loop "
                    "in one direction, or build the domain with Polygon.from_edges (which orients loops by "
                    "nesting) and use BoundarySegments.from_polygon")
            loops.append(loop.vertices)
            sources.append(seg)
            names.append(f"{path}: loop {i} (segments {int(seg.min())}..{int(seg.max())})")
        out = cls._oriented(loops, sources, names, n_outer=len(loops), name=str(path), file_sources=True)
        return out if pbc is None else out.with_cell(pbc, cell)

    @classmethod
    def _oriented(cls, loops, sources, names, n_outer, name, file_sources=False):
        """Check crossings and nesting, orient loops by their role (warning when reversed)."""
        from ..domains.loops import first_crossing, validate_loops

        hit = first_crossing(loops)
        if hit is not None:
            (la, ka), (lb, kb) = hit
            sa, sb = int(sources[la][ka]), int(sources[lb][kb])
            where = f"{name}" if file_sources else f"{names[la]} / {names[lb]}"
            raise ValueError(f"{where}: segments {sa} and {sb} cross or overlap (the boundary must be simple, "
                             "disjoint closed loops)")
        depth = validate_loops(loops, names)
        for i in range(n_outer, len(loops)):
            if depth[i] % 2 == 0:
                raise ValueError(f"{names[i]} is not inside an outer loop")
        out_loops, out_sources = [], []
        for i, (v, src, dep) in enumerate(zip(loops, sources, depth)):
            ccw = signed_area(v) > 0.0
            outer = dep % 2 == 0
            if ccw != outer and i >= n_outer:  # an explicit hole: its role is given, orient it silently
                k = len(v)
                src = np.asarray(src)[(k - 2 - np.arange(k)) % k]
                v = v[::-1]
            elif ccw != outer:
                role = "an outer boundary" if outer else "a hole"
                sense = "clockwise" if outer else "counter-clockwise"
                warnings.warn(f"{names[i]} runs {sense} but is {role} (the domain must be on the left of every "
                              "segment); reversed", OrientationWarning, stacklevel=3)
                k = len(v)
                src = np.asarray(src)[(k - 2 - np.arange(k)) % k]
                v = v[::-1]
            out_loops.append(np.ascontiguousarray(v))
            out_sources.append(np.asarray(src))
        return cls(out_loops, source_s=np.concatenate(out_sources), name=name)

    @classmethod
    def from_domain(cls, domain):
        """Segments of a polygonal 2D domain: Polygon, 2D Box, or a CSG of those.

        Analytic curved domains (Circle) have no segments: sample them as a polygon first
        (``circle.to_polygon(n_segments)``).
        """
        from ..domains.analytic import Ball, Box
        from ..domains.csg import BooleanDomain
        from ..domains.polygon import Polygon

        if isinstance(domain, BoundarySegments):
            return domain
        if isinstance(domain, Polygon):
            return cls.from_polygon(domain)
        if not hasattr(domain, "dim"):
            raise TypeError(f"cannot take boundary segments of {type(domain).__name__}; accepted: Polygon, 2D Box, "
                            "Union/Intersection/Difference of those (or BoundarySegments.from_edges / from_vertices)")
        if domain.dim != 2:
            raise ValueError(f"boundary segments are 2D; {type(domain).__name__} is {getattr(domain, 'dim', '?')}D "
                             "(use ase_sphrelax.boundary.BoundaryTriangles for 3D meshes)")
        if isinstance(domain, Box):
            (x0, y0), (x1, y1) = domain.lo, domain.hi
            return cls([np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])], name=repr(domain))
        if isinstance(domain, Ball):
            raise NoSegmentsError(_no_segments_message(domain))
        if isinstance(domain, BooleanDomain):
            return cls.from_shapely(_polygonal_geometry(domain), name=repr(domain))
        raise TypeError(f"cannot take boundary segments of {type(domain).__name__}; accepted: Polygon, 2D Box, "
                        "Union/Intersection/Difference of those, an edge file or vertex loops")

    @classmethod
    def from_shapely(cls, geometry, name="shapely"):
        """Segments of a shapely Polygon or MultiPolygon (exteriors and interiors)."""
        import shapely
        from shapely.geometry.polygon import orient

        if geometry.is_empty:
            raise ValueError(f"{name}: the geometry is empty (no boundary)")
        parts = getattr(geometry, "geoms", [geometry])
        loops = []
        for part in parts:
            if not isinstance(part, shapely.Polygon):
                raise ValueError(f"{name}: expected polygons, got a {part.geom_type}")
            part = orient(part, 1.0)  # exterior counter-clockwise, interiors clockwise
            for ring in [part.exterior, *part.interiors]:
                v = np.asarray(ring.coords)[:-1]
                keep = np.ones(len(v), bool)
                keep[1:] = np.any(v[1:] != v[:-1], axis=1)
                loops.append(v[keep])
        return cls(loops, name=name)

    # -- derived ------------------------------------------------------------------
    def __len__(self):
        return len(self.start_sc)

    @property
    def n_segments(self):
        return len(self.start_sc)

    @property
    def bounds(self):
        v = np.concatenate(self.loops)
        return v.min(axis=0), v.max(axis=0)

    @property
    def area(self):
        """Enclosed area (shoelace over the oriented loops)."""
        return float(sum(signed_area(v) for v in self.loops))

    # -- periodic directions ---------------------------------------------------------
    def with_cell(self, pbc=True, cell=None, quiet=False, reach=1):
        """These segments periodic along the axes ``pbc`` (ASE ``cell`` + ``pbc``).

        The loops stay one period's closed region. Segments lying on a periodic face (the lines
        ``x = lo`` and ``x = lo + L``, ``lo`` the lower bound of the loops, ``L`` the period:
        e.g. the ends of a channel drawn as a closed rectangle) are dropped, with a
        :class:`~ase_sphrelax.boundary.periodic.PeriodicFacesWarning` saying how many; the others
        are split where they cross a line ``x = k L`` and moved by whole periods into the cell
        ``[0, L)``. A segment's neighbour across the cell face is the segment starting at the
        image of its end (its own start, for a straight wall). The elements are then the images of
        these segments ``-reach..reach`` periods away along every periodic axis, built once, and a
        wall that continues straight across a cell face is one segment through all its images (no
        vertex at the seam, so ``gamma`` is as exact there as along any straight wall). Particles
        are wrapped into the cell (by the neighbour list of the same cell) and meet the images
        directly (:mod:`.periodic`).

        Parameters
        ----------
        pbc : bool or sequence of 2 or 3 bool
            Periodic axes (x, y); ``True`` alone makes both periodic.
        cell : None, float, sequence or (3, 3) array
            Periods: an ASE cell (its periodic vectors along their axes) or lengths; default
            (None, or a zero length) the loops' extent along the axis.
        quiet : bool
            No warning about dropped face segments.
        reach : int
            Periods of images on each side (the kernel support must not exceed ``reach`` periods).

        Returns
        -------
        BoundarySegments
            With ``periodic`` (a :class:`~ase_sphrelax.boundary.periodic.PeriodicCell`), ``cell``
            (3, 3) and ``pbc`` (3,) set; ``domain`` is the
            :class:`~ase_sphrelax.boundary.periodic.PeriodicDomain`.

        Raises
        ------
        ValueError
            Bad ``pbc``/``cell``, a period shorter than the loops' extent, every segment on a
            face, or a wall ending on a face without a continuation at the opposite face.
        """
        from .periodic import PeriodicCell

        base = BoundarySegments(self.loops, name=self.name) if self.periodic is not None else self
        lo, hi = base.bounds
        periodic = PeriodicCell(pbc, cell, lo, hi, 2, name=self.name or "boundary", reach=reach)
        out = BoundarySegments(base.loops, source_s=base.source_s, name=base.name)
        out._polygon = base._polygon
        if not periodic.pbc.any():
            return out
        face = periodic.on_face(np.stack([base.start_sc, base.end_sc], axis=1))
        if face.all():
            raise ValueError(f"{self.name}: every segment lies on a periodic face ({periodic.label}): no wall is left")
        pieces = [(a, b, base.loop_s[s], base.source_s[s]) for s in np.nonzero(~face)[0]
                  for a, b in _split_at_periods(base.start_sc[s], base.end_sc[s], periodic)]
        start = np.array([p[0] for p in pieces])
        end = np.array([p[1] for p in pieces])
        shift = periodic.wrap(0.5 * (start + end)) - 0.5 * (start + end)
        start, end = start + shift, end + shift
        next_s = _match_periodic(end, start, periodic, self.name, "ends")
        prev_s = _match_periodic(start, end, periodic, self.name, "starts")
        loop_s = np.array([p[2] for p in pieces])
        source_s = np.array([p[3] for p in pieces], dtype=np.int64)
        seam_s = periodic.on_seam(end)
        out._set_segments(*_periodic_images(start, end, loop_s, source_s, next_s, prev_s, seam_s, periodic, reach))
        out.surface = float(np.sum(base.length_s[~face]))
        out.periodic, out.cell, out.pbc = periodic, periodic.cell, periodic.pbc
        if not quiet:
            periodic.warn_dropped(int(face.sum()), self.name or "boundary", "segments")
        return out

    def merged(self):
        """The segments of :attr:`polygon` (runs of collinear segments merged), with the same periodicity."""
        out = BoundarySegments.from_polygon(self.polygon)
        return out if self.periodic is None else out.with_cell(self.pbc, self.cell, quiet=True,
                                                                 reach=self.periodic.reach)

    @property
    def polygon(self):
        """The enclosed region as a :class:`~ase_sphrelax.domains.Polygon` (inside tests, fill)."""
        if self._polygon is None:
            from ..domains.polygon import Polygon

            self._polygon = Polygon(self.loops)
        return self._polygon

    @property
    def domain(self):
        """The enclosed region as a level-set domain (the :attr:`polygon`), as for BoundaryTriangles.

        Periodic segments: a :class:`~ase_sphrelax.boundary.periodic.PeriodicDomain` (the images of
        the polygon joined across the periodic faces, evaluated at wrapped positions)."""
        if self.periodic is None:
            return self.polygon
        if self._domain is None:
            from .periodic import PeriodicDomain

            self._domain = PeriodicDomain(self.polygon, _joined_images(self.polygon, self.periodic), self.periodic)
        return self._domain

    def contains(self, r_pc):
        """Boolean mask of the points strictly inside (through :attr:`domain`; periodic: the wrapped position)."""
        return self.domain.contains(r_pc)

    def refine(self, max_length=None, dx=None, ratio=EDGE_TO_DX_RATIO):
        """Split every segment longer than ``max_length`` into equal parts.

        Parameters
        ----------
        max_length : float, optional
            Longest allowed segment.
        dx, ratio : float
            Alternatively ``max_length = dx / ratio``: BIPI's particle spacing ``dx_r`` and the
            ratio ``dx_r / dx_s`` (default BIPI2D's ``edge_to_dx_ratio`` = 10; the paper
            requires > 1).

        Returns
        -------
        BoundarySegments
            New segments on the same loops (``source_s`` kept); the exact boundary integrals
            (:func:`~ase_sphrelax.boundary.gamma_and_gradient`) do not change.
        """
        from ..checks import check_positive

        if max_length is None:
            if dx is None:
                raise ValueError("refine needs max_length or dx (max_length = dx / ratio)")
            max_length = check_positive("dx", dx) / check_positive("ratio", ratio)
        max_length = check_positive("max_length", max_length)
        loops, sources = [], []
        first = 0
        closed = self if self.periodic is None else BoundarySegments(self.loops, name=self.name)
        for v in self.loops:
            w = np.roll(v, -1, axis=0)
            length = closed.length_s[first:first + len(v)]
            parts = np.maximum(1, np.ceil(length / max_length - 1e-12).astype(np.int64))
            pts = []
            for a, b, k in zip(v, w, parts):
                frac = np.arange(k)[:, None] / k
                pts.append(a + frac * (b - a))
            loops.append(np.concatenate(pts))
            sources.append(np.repeat(closed.source_s[first:first + len(v)], parts))
            first += len(v)
        out = BoundarySegments(loops, source_s=np.concatenate(sources), name=self.name)
        out._polygon = self._polygon
        return out if self.periodic is None else out.with_cell(self.pbc, self.cell, quiet=True,
                                                                 reach=self.periodic.reach)

    def __repr__(self):
        periodic = "" if self.periodic is None else f", periodic in {self.periodic.label}"
        return (f"BoundarySegments({len(self.loops)} loops, {self.n_segments} segments, "
                f"length {self.length_s.min():.4g}..{self.length_s.max():.4g}{periodic})")


def _split_at_periods(a, b, periodic):
    """Pieces of the segment a -> b split where it crosses a line ``x = k L`` of a periodic axis."""
    cuts = [0.0, 1.0]
    for i in periodic.axes:
        L = periodic.period_c[i]
        lo, hi = sorted((a[i], b[i]))
        for k in range(int(np.floor(lo / L)) + 1, int(np.ceil(hi / L))):
            t = (k * L - a[i]) / (b[i] - a[i])
            if periodic.tol < t * abs(b[i] - a[i]) < abs(b[i] - a[i]) - periodic.tol:
                cuts.append(t)
    cuts = np.unique(cuts)
    points = a + cuts[:, None] * (b - a)
    points[0], points[-1] = a, b
    return list(zip(points[:-1], points[1:]))


def _match_periodic(point_sc, target_sc, periodic, name, what):
    """For every point, the index of the target point at the same place modulo the periods."""
    from scipy.spatial import cKDTree

    def folded(r):
        w = periodic.wrap(r)
        for i in periodic.axes:
            w[:, i][w[:, i] > periodic.period_c[i] - periodic.tol] -= periodic.period_c[i]
        return w

    d, k = cKDTree(folded(target_sc)).query(folded(point_sc), distance_upper_bound=10 * periodic.tol)
    missing = np.nonzero(~np.isfinite(d))[0]
    if len(missing):
        s = int(missing[0])
        raise ValueError(f"{name}: a wall {what} at {np.round(point_sc[s], 12).tolist()} on a periodic face "
                         f"({periodic.label}) and does not continue at the opposite face; the walls of one period "
                         "must meet their images")
    return k.astype(np.int64)


def _periodic_images(start, end, loop_s, source_s, next_s, prev_s, seam_s, periodic, reach):
    """The segments of one period (in the cell, joined by next/prev modulo the periods) and their images
    ``-reach..reach`` periods away, with the straight joints at the seams merged (``seam_s``: the segment
    ends on a plane ``x = k L`` or ``x = lo + k L``, a cell face, a periodic face or a split).

    Returns the arguments of :meth:`BoundarySegments._set_segments`.
    """
    shifts = periodic.shifts(reach)
    n, m = len(start), len(shifts)
    index = {tuple(k): i for i, k in enumerate(shifts)}
    period = periodic.period_c[:2]
    offset = shifts[:, :2] * period
    start_ms = start[None] + offset[:, None]
    end_ms = end[None] + offset[:, None]

    def neighbour(link_s, sign):
        """Image index of the next (sign +1) or previous (-1) segment of every image; itself at an open end."""
        out = np.arange(n * m).reshape(m, n)
        jump = np.zeros((n, 3), dtype=np.int64)
        gap = (start[link_s] - end) if sign > 0 else (end[link_s] - start)  # in periods, along each axis
        jump[:, :2] = np.rint(-gap / np.where(period > 0, period, 1.0)).astype(np.int64)
        for i, k in enumerate(shifts):
            for s_ in range(n):
                j = index.get(tuple(k + jump[s_]))
                if j is not None:
                    out[i, s_] = j * n + link_s[s_]
        return out.ravel()

    next_k, prev_k = neighbour(next_s, 1), neighbour(prev_s, -1)
    start_k, end_k = start_ms.reshape(-1, 2), end_ms.reshape(-1, 2)
    tangent = (end - start) / np.linalg.norm(end - start, axis=1)[:, None]
    tangent_k = np.tile(tangent, (m, 1))
    # a joint between images of one straight wall is no vertex: merge across it
    seam = np.tile(seam_s, m)  # ends on a cell face, a periodic face or a split at a plane x = k L
    straight = seam & (next_k != np.arange(n * m)) & (np.abs(tangent_k[next_k] - tangent_k).max(axis=1) <= 1e-12)
    into = np.zeros(n * m, dtype=bool)
    into[next_k[straight]] = True
    first_k = np.nonzero(~into)[0]
    chain_of = np.full(n * m, -1, dtype=np.int64)
    last_k = np.empty(len(first_k), dtype=np.int64)
    for c, k in enumerate(first_k):
        chain_of[k] = c
        while straight[k] and chain_of[next_k[k]] < 0:
            k = next_k[k]
            chain_of[k] = c
        last_k[c] = k
    if np.any(chain_of < 0):  # a closed straight ring cannot occur in finitely many images
        raise RuntimeError("periodic images: a straight chain without an end")
    return (start_k[first_k], end_k[last_k], np.tile(loop_s, m)[first_k], chain_of[next_k[last_k]],
            chain_of[prev_k[first_k]], np.tile(source_s, m)[first_k])


def _joined_images(polygon, periodic, reach=2):
    """The images of ``polygon`` within ``reach`` periods, joined into one Polygon (face edges removed)."""
    import shapely
    from shapely.affinity import translate

    from ..domains.polygon import Polygon

    geometry = polygon.to_shapely()
    copies = [translate(geometry, *(k[:2] * periodic.period_c[:2])) for k in periodic.shifts(reach)]
    joined = shapely.union_all(copies, grid_size=periodic.tol)
    return Polygon(BoundarySegments.from_shapely(joined, name="periodic images").loops)


class NoSegmentsError(ValueError, AttributeError):
    """An analytic (curved) domain has no boundary segments."""


def _no_segments_message(domain):
    return (f"{type(domain).__name__} is an analytic curved domain and has no boundary segments; sample it as a "
            "polygon, e.g. domain.to_polygon(n_segments) (a Polygon of a regular n-gon), and use its segments")


def _polygonal_geometry(domain):
    """Exact shapely geometry of a polygonal 2D domain (Polygon, Box, CSG of those)."""
    import shapely

    from ..domains.analytic import Ball, Box
    from ..domains.csg import BooleanDomain
    from ..domains.polygon import Polygon

    if isinstance(domain, Polygon):
        return domain.to_shapely()
    if isinstance(domain, Box):
        return shapely.box(*domain.lo, *domain.hi)
    if isinstance(domain, Ball):
        raise NoSegmentsError(_no_segments_message(domain) + " (it appears in a CSG expression)")
    if isinstance(domain, BooleanDomain):
        return domain.shapely_operation(_polygonal_geometry(domain.a), _polygonal_geometry(domain.b))
    raise TypeError(f"cannot take boundary segments of {type(domain).__name__}")

