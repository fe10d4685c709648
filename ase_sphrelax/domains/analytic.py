"""Analytic level-set domains: balls (Circle, Sphere) and axis-aligned boxes.

Exact signed distance functions (Fan Sec. 2) with their exact gradients.
"""
from __future__ import annotations

import math

import numpy as np

from ..checks import check_positive
from .base import Domain, check_vector

# a disc in a 2D CSG area is a regular 4 * _QUAD_SEGS-gon of the disc's exact area (relative error of
# order (2 pi / 4096)^2 of the part that is cut; see csg.py)
_QUAD_SEGS = 1024


def _check_count(name, value, minimum):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


class Ball(Domain):
    """Disc (2D) or ball (3D): ``phi = |r - center| - radius``.

    ``n = (r - center) / |r - center|``; at the centre itself (a kink) the
    normal is taken as ``e_x``.
    """

    def __init__(self, center, radius, dim=None):
        self.center = check_vector(center, "center", dim)
        self.dim = self.center.size
        self.radius = check_positive("radius", radius)

    def _phi_grad(self, r_pd):
        d_pd = r_pd - self.center
        dist_p = np.sqrt(np.einsum("pd,pd->p", d_pd, d_pd))
        safe_p = np.where(dist_p > 0.0, dist_p, 1.0)
        g_pd = d_pd / safe_p[:, None]
        g_pd[dist_p == 0.0, 0] = 1.0
        return dist_p - self.radius, g_pd

    def _phi(self, r_pd):
        return np.linalg.norm(r_pd - self.center, axis=1) - self.radius

    # the public queries in numba, on the given array without a (P, dim) copy (same values)
    def _query_points(self, r_pc):
        r = np.asarray(r_pc, dtype=float)
        if r.ndim == 1:
            r = r[None, :]
        if r.ndim != 2 or r.shape[1] not in (self.dim, 3) or r.shape[1] < self.dim:
            raise ValueError(f"r_pc must have shape (P, 3) or (P, {self.dim}), got {np.shape(r_pc)}")
        return r

    def phi(self, r_pc):
        """Signed distance ``|r - center| - radius`` at positions ``r_pc`` (P, 3) or (P, dim)."""
        from ._ball_loops import ball_phi

        return ball_phi(self._query_points(r_pc), self.center, self.radius)

    def phi_and_normal(self, r_pc):
        """Return ``(phi_p, n_pc)``; ``n_pc = grad phi`` with shape (P, 3)."""
        from ._ball_loops import ball_phi_grad

        return ball_phi_grad(self._query_points(r_pc), self.center, self.radius, 3)

    @property
    def bounds(self):
        return self.center - self.radius, self.center + self.radius

    def to_polygon(self, n_segments):
        """The inscribed regular ``n_segments``-gon as a :class:`~ase_sphrelax.domains.Polygon` (2D only)."""
        from .polygon import Polygon

        if self.dim != 2:
            raise ValueError(f"to_polygon is for 2D discs; this ball is {self.dim}D (use to_mesh)")
        n = _check_count("n_segments", n_segments, 3)
        angle = 2.0 * math.pi * np.arange(n) / n
        return Polygon([self.center + self.radius * np.stack([np.cos(angle), np.sin(angle)], axis=1)])

    def to_mesh(self, subdivisions=3):
        """The inscribed icosphere (trimesh) as a :class:`~ase_sphrelax.domains.Mesh` (3D only)."""
        import trimesh

        from .mesh import Mesh

        if self.dim != 3:
            raise ValueError(f"to_mesh is for 3D balls; this one is {self.dim}D (use to_polygon)")
        n = _check_count("subdivisions", subdivisions, 0)
        ico = trimesh.creation.icosphere(subdivisions=n, radius=self.radius)
        ico.apply_translation(self.center)
        return Mesh(ico)

    def area_geometry(self):
        """2D: a regular polygon of the disc's exact area (area-matched radius), for exact CSG areas."""
        if self.dim != 2:
            return None
        import shapely

        n = 4 * _QUAD_SEGS
        r = self.radius * np.sqrt(2.0 * np.pi / (n * np.sin(2.0 * np.pi / n)))
        return shapely.Point(self.center).buffer(r, quad_segs=_QUAD_SEGS)

    @property
    def volume(self):
        if self.dim == 2:
            return math.pi * self.radius**2
        return 4.0 / 3.0 * math.pi * self.radius**3

    def __repr__(self):
        return f"{type(self).__name__}(center={self.center.tolist()}, radius={self.radius})"


class Circle(Ball):
    """Disc of ``radius`` around the 2D ``center``: ``phi = |r - c| - R``."""

    def __init__(self, center=(0.0, 0.0), radius=1.0):
        super().__init__(center, radius, dim=2)


class Sphere(Ball):
    """Ball of ``radius`` around the 3D ``center``: ``phi = |r - c| - R``."""

    def __init__(self, center=(0.0, 0.0, 0.0), radius=1.0):
        super().__init__(center, radius, dim=3)


class Box(Domain):
    """Axis-aligned box ``[lo, hi]`` (dim = len(lo)) with its exact signed distance.

    With ``q = |r - c| - a`` (``c`` centre, ``a`` half sizes):
    outside ``phi = |max(q, 0)|`` (exact also in the corner regions), inside
    ``phi = max_k q_k`` (distance to the nearest face).
    """

    def __init__(self, lo, hi):
        self.lo = check_vector(lo, "lo")
        self.hi = check_vector(hi, "hi", self.lo.size)
        if np.any(self.hi <= self.lo):
            raise ValueError(f"hi must exceed lo on every axis, got lo={lo!r}, hi={hi!r}")
        self.dim = self.lo.size
        self._c = 0.5 * (self.lo + self.hi)
        self._a = 0.5 * (self.hi - self.lo)

    def _phi_grad(self, r_pd):
        d_pd = r_pd - self._c
        s_pd = np.where(d_pd >= 0.0, 1.0, -1.0)
        q_pd = np.abs(d_pd) - self._a
        qpos_pd = np.maximum(q_pd, 0.0)
        out_p = np.sqrt(np.einsum("pd,pd->p", qpos_pd, qpos_pd))
        k_p = np.argmax(q_pd, axis=1)
        qmax_p = q_pd[np.arange(len(q_pd)), k_p]
        inside_p = qmax_p <= 0.0
        phi_p = np.where(inside_p, qmax_p, out_p)
        g_pd = np.zeros_like(d_pd)
        outside = ~inside_p
        g_pd[outside] = s_pd[outside] * qpos_pd[outside] / out_p[outside, None]
        idx = np.nonzero(inside_p)[0]
        g_pd[idx, k_p[idx]] = s_pd[idx, k_p[idx]]
        return phi_p, g_pd

    @property
    def bounds(self):
        return self.lo.copy(), self.hi.copy()

    def area_geometry(self):
        """2D: the box as a shapely polygon (exact CSG areas)."""
        if self.dim != 2:
            return None
        import shapely

        return shapely.box(*self.lo, *self.hi)

    @property
    def volume(self):
        return float(np.prod(self.hi - self.lo))

    def __repr__(self):
        return f"Box(lo={self.lo.tolist()}, hi={self.hi.tolist()})"
