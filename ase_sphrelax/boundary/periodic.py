"""Boundaries periodic along some axes: the cell, the face elements, and the periodic domain.

A boundary is made periodic along an axis by an orthogonal period ``L`` (an ASE cell vector
along that axis) and ``pbc``. The boundary's elements are then one period's worth of walls:

* elements lying on the two *periodic faces* (the planes ``x = lo`` and ``x = lo + L`` of a
  channel drawn as a closed rectangle, ``lo`` the boundary's lower bound along the axis) are
  dropped (:class:`PeriodicFacesWarning` says how many) when the boundary spans the period; a body
  shorter than the period keeps all its elements;
* the others are moved by whole periods into the cell ``[0, L)`` (2D segments that cross a plane
  ``x = k L`` are split there first), and their images ``-reach..reach`` periods away along every
  periodic axis are built once; a 2D wall that continues straight across a seam becomes one
  segment through its images, so no vertex appears where the long bounded wall has none;
* the closed loops (or mesh) stay the description of the region of one period; the periodic
  region is the union of its images (:class:`PeriodicDomain`).

The particles are wrapped into the cell by the neighbour list
(:class:`~ase_sphrelax.neighbors.NeighborList` with the cell and ``pbc``), whose ghosts serve the
pair sums; the particle-element query (:class:`~ase_sphrelax.boundary.BoundaryQuery`) skips the
ghosts and pairs each particle with the element images directly, so ``gamma`` and its gradient come
from the boundary integrals of bounded domains (:mod:`ase_sphrelax.boundary.gamma`), unchanged.
A point is inside when its wrapped image is.
"""
from __future__ import annotations

import warnings

import numpy as np

from ..checks import SphrelaxWarning
from ..domains.base import Domain

__all__ = ["PeriodicCell", "PeriodicDomain", "PeriodicFacesWarning", "AXES"]

AXES = "xyz"


class PeriodicFacesWarning(SphrelaxWarning):
    """Boundary elements on the periodic faces were dropped."""


class PeriodicCell:
    """An orthogonal cell periodic along some axes, for a boundary of dimension ``dim``.

    Parameters
    ----------
    pbc : bool or sequence of bool
        Periodic axes (``True`` alone: every one of the ``dim`` axes); axes beyond ``dim`` must
        be False.
    cell : None, float, sequence or (3, 3) array
        ASE cell: a (3, 3) matrix, 3 (or ``dim``) lengths, or None. Along a periodic axis the
        cell vector must lie along that axis (orthogonal periods); a zero or missing length
        takes the boundary's extent.
    lo_c, hi_c : ndarray (dim,)
        The boundary's bounds (the periodic faces are ``lo`` and ``lo + L``).
    dim : {2, 3}
    name : str
        For messages.
    reach : int
        Periods of element images on each side of the cell.

    Attributes
    ----------
    pbc : ndarray of bool (3,)
    period_c : ndarray (3,)
        ``L`` along periodic axes, 0 elsewhere.
    cell : ndarray (3, 3)
        ``diag(period_c)``: the ASE cell of the periodic axes (zero rows elsewhere).
    lo_c : ndarray (3,)
        Plane of the lower periodic face along each periodic axis.
    """

    def __init__(self, pbc, cell, lo_c, hi_c, dim, name="boundary", reach=1):
        pbc_c = np.zeros(3, dtype=bool)
        flags = np.atleast_1d(np.asarray(pbc))
        if flags.dtype != bool or flags.size not in (1, dim, 3):
            raise ValueError(f"pbc must be a bool or {dim} or 3 bools, got {pbc!r}")
        if flags.size == 1:
            pbc_c[:dim] = bool(flags[0])
        else:
            pbc_c[: flags.size] = flags
        if np.any(pbc_c[dim:]):
            raise ValueError(f"pbc: a {dim}D boundary is periodic along its {dim} axes only, got {pbc!r}")
        lengths = _cell_lengths(cell, pbc_c, dim)
        extent = np.zeros(3)
        extent[:dim] = np.asarray(hi_c, float) - np.asarray(lo_c, float)
        period = np.where(pbc_c & (lengths > 0), lengths, np.where(pbc_c, extent, 0.0))
        for i in np.nonzero(pbc_c)[0]:
            if not period[i] > 0:
                raise ValueError(f"cell: the period along {AXES[i]} must be > 0, got {period[i]!r}")
            if extent[i] > period[i] * (1 + 1e-9):
                raise ValueError(f"cell: {name} extends over {extent[i]:.12g} along {AXES[i]}, more than the period "
                                 f"{period[i]:.12g}; give a period at least the extent")
        if isinstance(reach, bool) or not isinstance(reach, (int, np.integer)) or reach < 1:
            raise ValueError(f"reach must be an integer >= 1 (periods of images on each side), got {reach!r}")
        self.reach = int(reach)
        self.dim = dim
        self.pbc = pbc_c
        self.period_c = period
        self.cell = np.diag(period)
        self.lo_c = np.zeros(3)
        self.lo_c[:dim] = lo_c
        # the loops span the period along these axes: their edges on the planes lo and lo + L are the cell faces
        self.spanning = pbc_c & (extent >= period * (1 - 1e-9))
        self.tol = 1e-9 * max(1.0, float(np.max(np.abs(np.concatenate([lo_c, hi_c])))))

    @property
    def image_reach(self):
        """Largest kernel support the images cover: ``reach`` times the shortest period."""
        return self.reach * float(self.period_c[self.pbc].min())

    @property
    def axes(self):
        """Indices of the periodic axes."""
        return np.nonzero(self.pbc)[0]

    @property
    def label(self):
        """The periodic axes as letters, e.g. ``"x"`` or ``"x y"``."""
        return " ".join(AXES[i] for i in self.axes)

    def wrap(self, r_pc):
        """Positions moved by whole periods into ``[0, L)`` along the periodic axes (a copy)."""
        r = np.array(r_pc, dtype=float, copy=True)
        for i in self.axes:
            if i < r.shape[1]:
                r[:, i] -= np.floor(r[:, i] / self.period_c[i]) * self.period_c[i]
                r[:, i][r[:, i] >= self.period_c[i]] = 0.0  # -1e-17 wraps to L in floating point
        return r

    def on_face(self, corners_kc):
        """Mask of the elements whose corners ``(E, k, dim)`` all lie on one periodic face plane (along the
        axes the boundary spans: a body shorter than the period has no face elements)."""
        out = np.zeros(len(corners_kc), dtype=bool)
        for i in np.nonzero(self.spanning)[0]:
            for plane in (self.lo_c[i], self.lo_c[i] + self.period_c[i]):
                out |= np.all(np.abs(corners_kc[:, :, i] - plane) <= self.tol, axis=1)
        return out

    def on_seam(self, r_pc):
        """Mask of the points on a plane ``x = lo + k L`` or ``x = k L`` of a periodic axis (cell faces and
        the boundary's periodic faces, modulo the periods)."""
        out = np.zeros(len(r_pc), dtype=bool)
        for i in self.axes:
            for plane in (0.0, self.lo_c[i]):
                u = np.mod(r_pc[:, i] - plane, self.period_c[i])
                out |= (u <= self.tol) | (u >= self.period_c[i] - self.tol)
        return out

    def shifts(self, reach=1, lo_k=None, hi_k=None):
        """Integer image vectors ``(M, 3)``, each periodic component in ``-reach..reach`` (or ``lo_k..hi_k``)."""
        lo_k = np.full(3, -reach) if lo_k is None else lo_k
        hi_k = np.full(3, reach) if hi_k is None else hi_k
        ranges = [np.arange(lo_k[i], hi_k[i] + 1) if p else np.zeros(1, dtype=int) for i, p in enumerate(self.pbc)]
        return np.stack(np.meshgrid(*ranges, indexing="ij"), axis=-1).reshape(-1, 3)

    def warn_dropped(self, n, name, what):
        """The one-line message about elements dropped on the periodic faces."""
        if n:
            warnings.warn(f"{name}: {n} {what} on the periodic faces ({self.label}) dropped", PeriodicFacesWarning,
                          stacklevel=4)

    def __repr__(self):
        return f"PeriodicCell({self.label}, period={self.period_c[self.pbc].tolist()})"


def _cell_lengths(cell, pbc_c, dim):
    """Lengths of an ASE cell along the axes, checking periodic vectors are axis-aligned."""
    if cell is None:
        return np.zeros(3)
    c = np.asarray(cell, dtype=float)
    if c.ndim == 0:
        c = np.full(dim, float(c))
    if c.shape in ((dim,), (3,)):
        out = np.zeros(3)
        out[: c.size] = c
    elif c.shape == (3, 3):
        out = np.zeros(3)
        for i in np.nonzero(pbc_c)[0]:
            off = np.delete(c[i], i)
            if np.any(off != 0.0) or not c[i, i] > 0:
                raise ValueError(f"cell: the periodic vector {i} must lie along {AXES[i]} with a positive length "
                                 f"(orthogonal periods), got {c[i].tolist()}")
            out[i] = c[i, i]
    else:
        raise ValueError(f"cell must be None, {dim} or 3 lengths or a (3, 3) matrix, got shape {c.shape}")
    if not np.all(np.isfinite(out)) or np.any(out < 0):
        raise ValueError(f"cell lengths must be finite and >= 0, got {out.tolist()}")
    return out


class PeriodicDomain(Domain):
    """The periodic region: the images of one period's closed region, joined across the faces.

    ``phi`` and ``contains`` take positions wrapped into the cell and evaluate a domain made of
    the images ``-2..2`` (2D) or ``-1..1`` (3D) periods along every periodic axis joined into one
    (their shared face boundaries removed), so distances are exact up to one period.

    Parameters
    ----------
    closed : Domain
        One period's region (the closed loops or mesh, face edges included).
    extended : Domain
        The joined images.
    periodic : PeriodicCell
    """

    def __init__(self, closed, extended, periodic):
        self.closed = closed
        self.extended = extended
        self.periodic = periodic
        self.dim = closed.dim

    def _phi_grad(self, r_pd):
        return self.extended._phi_grad(self.periodic.wrap(r_pd))

    def phi(self, r_pc):
        return self.extended.phi(self.periodic.wrap(self.points(r_pc)))

    def phi_and_normal(self, r_pc):
        return self.extended.phi_and_normal(self.periodic.wrap(self.points(r_pc)))

    def contains(self, r_pc):
        """Strictly inside: the wrapped position inside the joined images."""
        return self.extended.contains(self.periodic.wrap(self.points(r_pc)))

    @property
    def bounds(self):
        """The closed region's bounds, the cell ``[0, L]`` along periodic axes."""
        lo, hi = (np.array(b, dtype=float) for b in self.closed.bounds)
        for i in self.periodic.axes:
            lo[i], hi[i] = 0.0, self.periodic.period_c[i]
        return lo, hi

    @property
    def volume(self):
        """Area (2D) or volume (3D) of one period."""
        return float(self.closed.volume)

    def __repr__(self):
        return f"PeriodicDomain({self.closed!r}, periodic in {self.periodic.label})"
