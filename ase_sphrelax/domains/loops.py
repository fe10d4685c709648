"""Closed 2D vertex loops: orientation, validity, crossings, and edge files (``x1 y1 x2 y2`` per line).

The loop geometry shared by :class:`~ase_sphrelax.domains.Polygon` (a level set) and
:class:`~ase_sphrelax.boundary.BoundarySegments` (boundary elements): plain arrays in,
plain arrays (or one-line errors naming the loop, file and segment) out.
"""
from __future__ import annotations

import numpy as np

__all__ = ["signed_area", "vertex_array", "validate_loops", "first_crossing", "EdgeLoop", "read_edge_loops",
           "read_edges"]


def signed_area(v):
    """Signed area of the closed vertex loop ``v`` (k, 2) (shoelace): > 0 counter-clockwise."""
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def vertex_array(loop, name):
    """``loop`` as a finite float array of shape (k, 2); errors name ``name``."""
    try:
        v = np.array(loop, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of 2D vertices") from None
    if v.ndim != 2 or v.shape[1] != 2:
        raise ValueError(f"{name} must have shape (k, 2), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} has non-finite vertices")
    return v


def validate_loops(loops, names):
    """Each ring simple, rings pairwise disjoint; return nesting depth per loop."""
    import shapely
    from shapely.validation import explain_validity

    rings = []
    for v, name in zip(loops, names):
        ring = shapely.LinearRing(v)
        if not ring.is_simple:
            raise ValueError(f"{name} crosses itself (not a simple closed loop): "
                             f"{explain_validity(shapely.Polygon(v))}")
        rings.append(ring)
    polys = [shapely.Polygon(v) for v in loops]
    tree = shapely.STRtree(rings)
    left, right = tree.query(rings, predicate="intersects")
    for a, b in zip(left, right):
        if a < b:
            raise ValueError(f"{names[a]} and {names[b]} intersect; loops must be disjoint")
    depth = np.zeros(len(loops), int)
    ptree = shapely.STRtree(polys)
    for i, ring in enumerate(rings):
        inside = ptree.query(shapely.Point(ring.coords[0]), predicate="within")
        depth[i] = sum(1 for j in inside if j != i)
    return depth


class EdgeLoop:
    """One closed loop chained from an edge file.

    Attributes
    ----------
    vertices : ndarray (k, 2)
        Vertices in the order of the walk (the direction of the loop's first segment in the file).
    segment_k : ndarray of int (k,)
        File index (0-based line of data) of the segment from ``vertices[i]`` to ``vertices[i + 1]``.
    forward_k : ndarray of bool (k,)
        Whether that segment is written in the walk's direction in the file.
    """

    def __init__(self, vertices, segment_k, forward_k):
        self.vertices = vertices
        self.segment_k = segment_k
        self.forward_k = forward_k


def _segment_name(path, s, line_s=None):
    line = f"line {line_s[s]}" if line_s is not None else f"data line {s + 1}"
    return f"{path}: segment {s} ({line})"


def _load_edge_file(path):
    """Segments ``x1 y1 x2 y2`` of an edge file, shape (n, 4), and the file line of each (1-based).

    Blank lines and ``#`` comments are skipped. Every error is one line naming the file and,
    for a malformed line, its number and what is accepted.
    """
    from pathlib import Path

    name = str(path)
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise ValueError(f"cannot read the edge file {name!r}: no such file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ValueError(f"cannot read the edge file {name!r}: {err}") from None
    rows, line_s = [], []
    for number, line in enumerate(text.splitlines(), 1):
        content = line.split("#", 1)[0].strip()
        if not content:
            continue
        fields = content.split()
        try:
            values = [float(f) for f in fields]
        except ValueError:
            values = None
        if values is None or len(values) != 4:
            raise ValueError(f"{name}: line {number}: expected 4 numbers 'x1 y1 x2 y2' (one segment per line), "
                             f"got {content[:60]!r}")
        rows.append(values)
        line_s.append(number)
    if len(rows) < 3:
        what = "the file has no segment" if not rows else f"got {len(rows)}"
        raise ValueError(f"{name}: an edge file needs at least 3 lines 'x1 y1 x2 y2' (a closed loop); {what}")
    return np.array(rows, dtype=float), line_s


def read_edge_loops(path, tol, strict=False):
    """Read ``x1 y1 x2 y2`` lines and chain the segments into closed loops (list of :class:`EdgeLoop`).

    Errors name the file, the segment index and its line. Zero-length segments are skipped, or with
    ``strict`` rejected.
    """
    from scipy.spatial import cKDTree

    e, line_s = _load_edge_file(path)
    if not np.all(np.isfinite(e)):
        s = int(np.nonzero(~np.all(np.isfinite(e), axis=1))[0][0])
        raise ValueError(f"{_segment_name(path, s, line_s)} has non-finite coordinates")
    a, b = e[:, :2], e[:, 2:]
    if tol is None:
        tol = 1e-9 * max(1.0, float(np.ptp(e.reshape(-1, 2), axis=0).max()))
    # merge end points into vertices
    pts = np.concatenate([a, b])
    tree = cKDTree(pts)
    vid = -np.ones(len(pts), int)
    n_v = 0
    for i in range(len(pts)):
        if vid[i] < 0:
            near = tree.query_ball_point(pts[i], tol)
            vid[near] = n_v
            n_v += 1
    va, vb = vid[: len(e)], vid[len(e):]
    zero = np.nonzero(va == vb)[0]
    if strict and len(zero):
        s = int(zero[0])
        raise ValueError(f"{_segment_name(path, s, line_s)} has zero length (its end points coincide within "
                         f"{tol:g}); {len(zero)} such segment(s)")
    adj = [[] for _ in range(n_v)]
    for s in range(len(e)):
        if va[s] == vb[s]:
            continue
        adj[va[s]].append(s)
        adj[vb[s]].append(s)
    for v in range(n_v):
        if len(adj[v]) not in (0, 2):
            idx = np.nonzero(vid == v)[0][0]
            x, y = pts[idx]
            what = "is not closed" if len(adj[v]) == 1 else "branches"
            segs = ", ".join(str(s) for s in adj[v])
            lines = ", ".join(str(line_s[s]) for s in adj[v])
            raise ValueError(f"the boundary {what} at ({x:.10g}, {y:.10g}): {len(adj[v])} segment end(s) meet there "
                             f"(tolerance {tol:g}); {path}: segment(s) {segs} (line(s) {lines})")
    used = np.zeros(len(e), bool)
    used[va == vb] = True
    loops = []
    for s0 in range(len(e)):
        if used[s0]:
            continue
        verts, segs, fwd = [], [], []
        s, v = s0, va[s0]  # walk in the direction of the first segment
        while not used[s]:
            used[s] = True
            verts.append(a[s] if va[s] == v else b[s])
            segs.append(s)
            fwd.append(va[s] == v)
            v = vb[s] if va[s] == v else va[s]
            s = adj[v][0] if adj[v][1] == s else adj[v][1]
        loops.append(EdgeLoop(np.array(verts), np.array(segs), np.array(fwd)))
    return loops


def read_edges(path, tol):
    """Vertex loops of an edge file (see :func:`read_edge_loops`)."""
    return [loop.vertices for loop in read_edge_loops(path, tol)]


def first_crossing(loops):
    """First pair of segments that cross or overlap, as ``((loop, k), (loop, k))``, or None.

    ``loops`` are closed vertex loops; segment ``k`` of a loop runs from vertex k to k + 1.
    Segments that only share their common end point (neighbours along a loop) do not count.
    """
    import shapely

    lines, owner = [], []
    for i, v in enumerate(loops):
        w = np.roll(v, -1, axis=0)
        lines += [shapely.LineString([p, q]) for p, q in zip(v, w)]
        owner += [(i, k) for k in range(len(v))]
    tree = shapely.STRtree(lines)
    left, right = tree.query(lines, predicate="intersects")
    hits = []
    for x, y in zip(left, right):
        if x >= y:
            continue
        (li, ki), (lj, kj) = owner[x], owner[y]
        n = len(loops[li])
        if li == lj and (kj - ki) % n in (1, n - 1):
            # neighbours: fine if they meet only at the shared vertex
            shared = loops[li][kj] if (kj - ki) % n == 1 else loops[li][ki]
            inter = lines[x].intersection(lines[y])
            if inter.geom_type == "Point" and np.allclose(inter.coords[0], shared, rtol=0, atol=0):
                continue
            if inter.geom_type == "Point" and inter.equals(shapely.Point(shared)):
                continue
        hits.append((owner[x], owner[y]))
    return min(hits) if hits else None
