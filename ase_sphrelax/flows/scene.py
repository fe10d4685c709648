"""Scenes for :class:`~ase_sphrelax.flows.bisph.BISPH`: a tank at rest under gravity, a periodic channel, the
elliptic drop (a free surface and no walls).

A scene is a :class:`~ase_sphrelax.boundary.BoundarySegments`, fluid particles and a body force.
The Cartesian start is BIPI2D's particle generator (METHOD_NOTES): one particle at each cell centre
of a ``dx`` grid inside the walls, dropping those within ``dx/8`` of a wall.
"""
from __future__ import annotations

import math

import numpy as np

from ..boundary import BoundarySegments, as_boundary
from ..checks import check_positive
from .bisph import BISPH, tait_density

__all__ = ["cartesian_fill", "tank", "channel", "poiseuille", "wall_distance", "elliptic_drop"]

DROP_FRACTION = 0.125  # BIPI2D drops grid particles within dx/8 of the boundary


def wall_distance(points, boundary, chunk=4096):
    """Distance of each point (N, 2+) to the nearest segment: O(N S) in chunks (S segments)."""
    seg = as_boundary(boundary).packed_sk
    a, b = seg[:, 0:2], seg[:, 2:4]
    ab = b - a
    x = np.asarray(points, dtype=float)[:, :2]
    out = np.empty(len(x))
    for lo in range(0, len(x), chunk):
        p = x[lo: lo + chunk, None, :] - a[None]
        t = np.clip(np.einsum("psc,sc->ps", p, ab) * seg[:, 7], 0.0, 1.0)
        gap = p - t[..., None] * ab[None]
        out[lo: lo + chunk] = np.sqrt(np.min(np.einsum("psc,psc->ps", gap, gap), axis=1))
    return out


def cartesian_fill(boundary, dx, fill_height=None):
    """BIPI2D's Cartesian start: cell centres of the ``dx`` grid (anchored at the walls' lower-left
    corner) inside ``boundary`` and below ``fill_height``, minus those within ``dx/8`` of a wall.

    Returns (N, 3) positions (z = 0).
    """
    boundary = as_boundary(boundary)
    dx = check_positive("dx", dx)
    (x0, y0), (x1, y1) = np.asarray(boundary.bounds, dtype=float).reshape(2, 2)[:, :2]
    top = y1 if fill_height is None else float(fill_height)
    if top <= y0:
        raise ValueError(f"fill_height must be above the walls' lowest point {y0:g}, got {fill_height!r}")
    xs = x0 + dx * (np.arange(int(math.ceil((x1 - x0) / dx))) + 0.5)
    ys = y0 + dx * (np.arange(int(math.ceil((top - y0) / dx))) + 0.5)
    gx, gy = np.meshgrid(xs, ys, indexing="xy")
    pts = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    pts = pts[(pts[:, 1] < top) & (pts[:, 0] < x1)]
    pts = pts[np.asarray(boundary.contains(pts), dtype=bool)]
    pts = pts[wall_distance(pts, boundary) > DROP_FRACTION * dx]
    if len(pts) == 0:
        raise ValueError("no fluid particles: the fill is empty (check fill_height and dx)")
    return pts


def tank(boundary, positions, dx, fill_height, g=9.81, c0=None, mu=10.0, rho0=1000.0, **kwargs):
    """A tank at rest under gravity: hydrostatic density at ``t = 0`` (Eq. 18 inverted for
    ``p = rho0 g (fill_height - y)``), free surface at ``fill_height``.

    Parameters
    ----------
    boundary : BoundarySegments or polygonal domain
        The tank (taller than ``fill_height``: the walls above the water are never touched).
    positions : array (N, 2|3)
        Fluid particles (e.g. :func:`cartesian_fill` or a BIPI-packed start).
    dx, fill_height, g : float
    c0 : float or None
        Default ``10 sqrt(2 g H)`` with ``H`` the water depth (Mach 0.1 for the fastest free fall).
    **kwargs
        More :class:`BISPH` parameters.
    """
    boundary = as_boundary(boundary)
    r = np.asarray(positions, dtype=float)
    depth = float(fill_height) - float(np.asarray(boundary.bounds).reshape(2, -1)[0, 1])
    check_positive("fill_height above the tank's floor", depth)
    c0 = 10.0 * math.sqrt(2.0 * g * depth) if c0 is None else c0
    p = rho0 * g * (float(fill_height) - r[:, 1])
    rho = tait_density(np.maximum(p, 0.0), rho0, c0, kwargs.get("p_background", 0.0))
    return BISPH(boundary, r, dx, rho0=rho0, c0=c0, mu=mu, body_force=(0.0, -g), density=rho,
                 surface=float(fill_height), hydrostatic=True, **kwargs)


def channel(width, length, dx, force, mu, rho0=1000.0, c0=None, **kwargs):
    """Plane Poiseuille flow: plates at ``y = 0`` and ``y = width``, periodic in x with period
    ``length``, the body force ``force`` (m/s^2) along x, starting at rest.

    The steady profile is ``u(y) = force rho0 / (2 mu) y (width - y)``
    (:meth:`poiseuille`). ``c0`` defaults to ``10 u_max``.
    """
    width = check_positive("width", width)
    length = check_positive("length", length)
    dx = check_positive("dx", dx)
    u_max = force * rho0 * width**2 / (8.0 * mu)
    c0 = 10.0 * u_max if c0 is None else c0
    walls = BoundarySegments.from_vertices([[0.0, 0.0], [length, 0.0], [length, width], [0.0, width]])
    walls = walls.with_cell(pbc=(True, False), cell=(length, 0.0), quiet=True)
    nx, ny = int(round(length / dx)), int(round(width / dx))
    gx, gy = np.meshgrid(dx * (np.arange(nx) + 0.5), dx * (np.arange(ny) + 0.5), indexing="xy")
    r = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    return BISPH(walls, r, dx, rho0=rho0, c0=c0, mu=mu, body_force=(force, 0.0), hydrostatic=False, **kwargs)


def poiseuille(y, width, force, mu, rho0=1000.0):
    """The steady plane Poiseuille profile ``u(y) = force rho0 y (width - y) / (2 mu)``."""
    y = np.asarray(y, dtype=float)
    return force * rho0 * y * (width - y) / (2.0 * mu)


def elliptic_drop(positions, dx, a0=100.0, radius=None, rho0=1000.0, c0=None, mu=10.0, box=5.0, **kwargs):
    """The elliptic drop (Monaghan 1994; BIPI Sec. 4.2.2, Eq. 22): a disc of fluid, free surface all round,
    no gravity, starting from BIPI's Eq. 22::

        v = (A0 x, -A0 y),   p = rho0 A0^2 (R^2 - |x|^2) / 2      (x from the particles' mean)

    (the density from Eq. 18 inverted; ``p`` floored at 0). BISPH needs a boundary: the walls are a square of
    half-width ``box R`` about the centre, so far that no particle comes within the support ``h`` of it while
    the drop's long axis stays below ``box R - h`` (the analytic axis reaches 3.67 R at A0 t = 2): every
    ``gamma_a`` is then 1 and Eqs. 16-17 have no wall terms, the free surface is left to the truncated
    particle sums.

    Parameters
    ----------
    positions : array (N, 2|3)
        The disc's particles (all fluid).
    dx, a0 : float
        Particle spacing (m) and initial strain rate ``A0`` (1/s).
    radius : float or None
        ``R`` of Eq. 22; default the uniform disc's of the particles' second moment, ``sqrt(2 <|x|^2>)``.
    rho0, mu : float
    c0 : float or None
        Default ``14 A0 R`` (Mach 0.07 at the fastest initial particle).
    box : float
        The walls' half-width in units of ``R``.
    **kwargs
        More :class:`BISPH` parameters.
    """
    r = np.asarray(positions, dtype=float)
    if r.ndim != 2 or r.shape[1] not in (2, 3) or len(r) == 0:
        raise ValueError(f"positions must have shape (N, 2) or (N, 3) with N >= 1, got {r.shape}")
    a0 = check_positive("a0", a0)
    centre = r[:, :2].mean(axis=0)
    rel = r[:, :2] - centre
    r2 = np.einsum("pc,pc->p", rel, rel)
    radius = math.sqrt(2.0 * float(r2.mean())) if radius is None else check_positive("radius", radius)
    c0 = 14.0 * a0 * radius if c0 is None else c0
    half = check_positive("box", box) * radius
    if half <= math.sqrt(float(r2.max())) + kwargs.get("h_over_dx", 4.0) * dx:
        raise ValueError(f"box must put the walls beyond the drop plus a support; {box!r} R is too close")
    walls = BoundarySegments.from_vertices([centre + [-half, -half], centre + [half, -half], centre + [half, half],
                                            centre + [-half, half]])
    p = 0.5 * rho0 * a0**2 * (radius**2 - r2)
    rho = tait_density(np.maximum(p, 0.0), rho0, c0, kwargs.get("p_background", 0.0))
    v = np.column_stack([a0 * rel[:, 0], -a0 * rel[:, 1]])
    return BISPH(walls, r, dx, rho0=rho0, c0=c0, mu=mu, body_force=(0.0, 0.0), hydrostatic=False, density=rho,
                 velocities=v, **kwargs)
