"""Fan et al.'s total error (Eq. 3.8) without the pair loop: :class:`FanModel`.

With one particle volume ``v0 = vt`` (Fan's ``v0`` and ``ṽ``, Appendix A)::

    E = sum_{i,j} W(|x_i - x_j|, h) v0 vt  -  V  +  sum_i 2 vt I(-phi(x_i)),      (3.8)
    I(s) = int_s^h W1(max(r, 0), h) dr,                                            (3.5)

where the double sum includes ``i = j``. The model splits ``E`` into

* the **pair part**, each unordered pair once: ``phi(r) = 2 v0 vt W(r, h) = C f(r/h)`` with
  ``C = 2 v0 vt sigma_d / h^d`` (:meth:`FanModel.pair_prefactor`); its negative gradient
  is Eq. 3.17;
* the **self part** ``N v0 vt W(0, h) - V`` (:meth:`FanModel.self_energy`), a constant
  of the positions;
* the **boundary part** per particle (:meth:`FanModel.boundary`), one of two terms
  (``boundary_term``):

  - ``"level_set"``: Fan's ``2 vt I(-phi_i)`` with force ``-2 W1(max(-phi_i, 0), h) vt n_i``,
    ``n = grad phi`` (last term of Eq. 4.4). ``I`` is the flat-wall missing kernel mass: at a
    corner ``grad phi`` jumps and the force follows the nearer wall only (issue 33 item 3:
    ``sphrelax relax --domain box`` drove corner particles to 0.04 dx from the walls).
  - ``"gamma"``: the wall as a continuum of particles of volume ``vt`` beyond the boundary,
    ``2 vt (1 - gamma_i)``, with ``gamma_i = int_{Omega cap B(x_i, h)} W`` the exact kernel volume
    fraction of the boundary's segments or triangles (BIPI Eq. 2-3, :mod:`ase_sphrelax.boundary`):
    the pair energy of particle ``i`` with that continuum (both orders of the double sum). For a
    flat wall ``1 - gamma`` is ``I`` with the exact projected profile; at corners, tips, 3D
    edges and vertices it is the exact missing mass, and the force ``2 vt grad gamma_i`` is its
    exact gradient. Two short terms complete it:

    * a particle outside (``phi > 0``) gets ``2 vt W1(0, h) phi``, the outside slope of Fan's
      term, so that it comes back from beyond ``h``;
    * a contact core ``2 vt (B / (2 d0 h)) max(d0 + phi_i, 0)^2`` with ``d0 = CORE_DISTANCE dp``
      (0.4, ``dp = vt^(1/d)``) and ``B = CORE_STIFFNESS`` (2): zero for particles at least ``d0`` from
      the boundary, at the wall a force ``B`` times the scale ``2 vt / h`` of the continuum's. The
      continuum alone is soft: a relaxed box (576 particles) kept wall-layer particles 0.31 dx from
      a flat wall (Eq. 2.4 and FIRE alike), a cube 0.22 dx; with the core none is nearer than
      0.35 dx (``reproductions/fan-corners``). Its gradient is ``-grad phi`` times a factor that
      vanishes beyond ``d0``, so it jumps only where ``grad phi`` does within ``d0`` of the wall:
      on the bisector of a convex corner, within ``d0 / sin(alpha / 2)`` of its vertex (a set of
      measure zero; there E is continuous and its one-sided gradients are the two walls').

    :attr:`FanModel.wall_weight` (``kappa``, 1) scales the whole ``"gamma"`` term. On a
    :class:`~ase_sphrelax.domains.Polygon` the wall of the continuum and of the core is the polygon's opening at
    ``WALL_OPENING dp`` (0.35; :meth:`FanModel.wall`): the parts narrower than ``0.7 dp``, where no particle can sit
    0.35 dx from both walls, are left out, and convex corners become arcs of that radius.

  ``"auto"`` (the default) takes ``"gamma"`` when the domain has boundary elements (Polygon, Box,
  polygonal CSG, Mesh) and ``"level_set"`` for curved analytic domains (Circle, Sphere), whose
  level set has no corner.

Volumes (:meth:`FanModel.volumes`), one rule for every backend: ``V`` is the domain
volume, else the periodic measure of the cell (length, area or volume spanned by the first
``dim`` cell vectors), else ``N dx^d``; ``v0 = vt = dx^d`` (Eq. 3.3) or, with ``dx`` None,
``V / N`` (Eq. 3.2).

Stress (:meth:`FanModel.stress`; periodic cells without a domain) is ``(1/V_cell) dE/d(strain)``:
the pair virial, ``-V`` times the in-plane identity for the ``-V`` term and, with ``dx`` None,
``+2 (E + V)`` times the in-plane identity, because ``v0 vt = (V/N)^2`` scales with the cell.

The pair sums run elsewhere: :class:`~ase_sphrelax.calculators.fan.FanCalculator` through
:func:`ase_sphrelax.kernel_sums.pair_potential_sums`; ``lammps_io``'s calculator and
relaxation deck through LAMMPS pair styles written from :meth:`FanModel.pair_prefactor`.
"""
from __future__ import annotations

from typing import NamedTuple, Optional

import numba
import numpy as np
from ase.calculators.calculator import PropertyNotImplementedError

from ..checks import SphrelaxWarning, check_dim, check_positive, check_skin
from ..domains.base import Domain
from ..kernels import get_kernel

__all__ = ["FanModel", "FanVolumes", "verlet_skin", "ParticlesOutsideWarning", "BOUNDARY_TERMS", "WALL_WEIGHT",
           "CORE_DISTANCE", "CORE_STIFFNESS", "WALL_OPENING"]

SKIN_FRACTION = 0.1  # default Verlet skin: 0.1 h
BOUNDARY_TERMS = ("auto", "gamma", "level_set")  # FanModel(boundary_term=...)
WALL_WEIGHT = 1.0  # kappa of the "gamma" boundary term (module docstring)
CORE_DISTANCE = 0.4  # d0 / dp of the "gamma" term's contact core
CORE_STIFFNESS = 2.0  # B of the contact core (at the wall: B times the scale 2 vt / h of the continuum's force)
WALL_OPENING = 0.35  # r / dp of the "gamma" term's wall on a Polygon: its opening at r (parts narrower than 2 r left out)
# particles per level-set call of the "level_set" term (FanModel.boundary): Fan's sphere at 1e6 in 3D (132 073
# candidates) spent 6.9 ms a step in it with 8192, 8.9 ms with 65536 (a chunk's arrays on fresh pages)
_BOUNDARY_CHUNK = 1 << 13


class ParticlesOutsideWarning(SphrelaxWarning):
    """Particles far outside the domain at the first evaluation (:meth:`FanModel.warn_far_outside`)."""


def verlet_skin(skin, h):
    """Neighbour-list skin of a Fan run: ``skin`` as a float >= 0, or ``SKIN_FRACTION * h`` when None."""
    return SKIN_FRACTION * h if skin is None else check_skin(skin)


class FanVolumes(NamedTuple):
    """Volumes of one particle set (:meth:`FanModel.volumes`)."""

    volume: float
    """``V`` of Eq. 3.8."""
    v0: float
    """Particle volume ``v0 = vt``."""
    measure: Optional[float]
    """Periodic measure of the cell, or None when it is not periodic along all ``dim`` axes."""


class FanModel:
    """Parameters and closed-form terms of Fan's total error (Eq. 3.8, 3.17, 4.4).

    Parameters
    ----------
    h : float
        Kernel support radius (Fan's cut-off ``h``, e.g. ``2.6 * dx``).
    dx : float or None
        Background cell size: ``v0 = vt = dx**dim``; None: ``V / N``.
    domain : Domain or None
        Level set ``phi`` (negative inside) with ``phi_and_normal`` and ``volume``;
        None is the interior case (periodic or free).
    dim : {1, 2, 3}
    kernel : str or Kernel
        Kernel name (:data:`ase_sphrelax.kernels.KERNEL_NAMES`); Fan uses ``"wendland_c2"``.
    boundary_term : {"auto", "gamma", "level_set"}
        The boundary part of Eq. 3.8 (module docstring): ``"gamma"`` the exact missing kernel mass
        ``2 vt (1 - gamma)`` of the boundary elements, ``"level_set"`` Fan's ``2 vt I(-phi)``;
        ``"auto"``: ``"gamma"`` when the domain has boundary elements, else ``"level_set"``.

    Raises
    ------
    TypeError, ValueError
        One line naming the parameter and what is accepted, before any work.

    Attributes
    ----------
    h, dx, domain, dim
        The validated parameters (floats, int).
    kernel : Kernel
    boundary_term : str or None
        ``"gamma"`` or ``"level_set"`` as resolved (None without a domain).
    wall_weight, core_stiffness : float
        ``kappa`` and ``B`` of the ``"gamma"`` term (class attributes, :data:`WALL_WEIGHT`,
        :data:`CORE_STIFFNESS`; ``reproductions/fan-corners`` sets them per instance to compare).
    wall_opening : float
        ``r / dp`` of the ``"gamma"`` term's wall on a :class:`~ase_sphrelax.domains.Polygon` (class attribute,
        :data:`WALL_OPENING`): the wall is the polygon's opening at ``r`` (:meth:`wall`); 0 takes the polygon itself.
    """

    wall_weight = WALL_WEIGHT
    core_stiffness = CORE_STIFFNESS
    wall_opening = WALL_OPENING

    def __init__(self, h, dx=None, domain=None, dim=2, kernel="wendland_c2", boundary_term="auto"):
        self.dim = check_dim(dim)
        self.kernel = get_kernel(kernel, self.dim)
        self.h = check_positive("h", h)
        self.dx = check_positive("dx", dx, allow_none=True)
        if domain is not None:
            if not hasattr(domain, "phi_and_normal"):
                raise TypeError(f"domain must be a Domain with phi_and_normal() or None, got {type(domain).__name__}")
            if getattr(domain, "dim", self.dim) != self.dim:
                raise ValueError(f"domain is {domain.dim}D but dim={self.dim}")
        self.domain = domain
        if boundary_term not in BOUNDARY_TERMS:
            raise ValueError(f"boundary_term must be one of {BOUNDARY_TERMS}, got {boundary_term!r}")
        self._boundary_term = boundary_term
        self._integrals = None
        self._wall_key = self._wall_value = None
        self.boundary_term = None if domain is None else self._resolve_boundary_term(boundary_term)

    def _resolve_boundary_term(self, boundary_term):
        """``"gamma"`` or ``"level_set"`` for this domain; builds :attr:`_integrals` for ``"gamma"``."""
        if boundary_term == "level_set":
            return "level_set"
        from ..boundary import BoundaryIntegrals, as_boundary

        try:
            elements = as_boundary(self.domain)
            if elements.dim == 2 and elements.periodic is None:
                elements = elements.merged()  # collinear runs merged: the same integrals over fewer segments
            self._integrals = BoundaryIntegrals(elements, self.h, self.kernel.name)
        except (TypeError, ValueError, KeyError, AttributeError) as error:
            if boundary_term == "gamma":
                raise ValueError(f"boundary_term='gamma' needs a domain with boundary elements (Polygon, Box, "
                                 f"polygonal CSG, Mesh): {error}") from None
            return "level_set"
        return "gamma"

    @classmethod
    def from_parameters(cls, parameters):
        """The model of a calculator's ``parameters`` (h, dx, domain, dim, kernel), which are
        normalised in place (``h``, ``dx`` as floats).

        With ``dim`` None (inferred from the atoms at each evaluation) the model is built for
        the domain's dimension, or 2 without a domain, to check the parameters; the calculator
        then uses :meth:`with_dim` for the dimension of the atoms.
        """
        p = parameters
        dim = p.dim if p.dim is not None else getattr(p.domain, "dim", 2)
        model = cls(p.h, p.dx, p.domain, dim, p.kernel, p.get("boundary_term", "auto"))
        p.h, p.dx = model.h, model.dx
        if p.dim is not None:
            p.dim = model.dim
        return model

    def with_dim(self, dim):
        """The same model in ``dim`` dimensions (self if it already is)."""
        if dim == self.dim:
            return self
        return type(self)(self.h, self.dx, self.domain, dim, self.kernel.name, self._boundary_term)

    def __repr__(self):
        return (f"FanModel(h={self.h!r}, dx={self.dx!r}, domain={self.domain!r}, dim={self.dim}, "
                f"kernel={self.kernel.name!r}, boundary_term={self._boundary_term!r})")

    # -- volumes ---------------------------------------------------------------
    def volumes(self, n, measure=None):
        """``V``, ``v0 = vt`` and the periodic measure of ``n`` particles (one rule, Eq. 3.2-3.3).

        Parameters
        ----------
        n : int
            Number of particles (>= 1).
        measure : float or None
            Periodic measure of the cell, as
            :func:`ase_sphrelax.calculators.base.periodic_measure` returns it
            (None when the cell is not periodic along all ``dim`` axes).

        Returns
        -------
        FanVolumes
        """
        if n < 1:
            raise ValueError("atoms: need at least one particle, got an empty Atoms")
        if self.domain is not None:
            volume = float(self.domain.volume)
            if not (np.isfinite(volume) and volume > 0):
                raise ValueError(f"domain.volume must be a positive finite number, got {volume!r}")
        elif measure is not None:
            volume = float(measure)
            if not volume > 0:
                raise ValueError(f"the periodic cell must have a positive {self.dim}D measure, got {volume!r}")
        elif self.dx is not None:
            volume = n * self.dx**self.dim
        else:
            raise ValueError("dx=None needs a domain or a cell periodic along all dim axes to define v0 = V/N; "
                             "give dx")
        v0 = self.dx**self.dim if self.dx is not None else volume / n
        return FanVolumes(volume, v0, measure)

    # -- the three parts of Eq. 3.8 -------------------------------------------------
    def pair_prefactor(self, v0):
        """``C`` of the pair potential ``phi(r) = 2 v0 vt W(r, h) = C f(r/h)``: ``2 v0^2 sigma_d / h^d``."""
        return 2.0 * v0 * v0 * self.kernel.sigma / self.h**self.dim

    def pair_energy(self, r, v0):
        """``phi(r) = 2 v0 vt W(r, h)`` and ``dphi/dr`` (arrays)."""
        return 2.0 * v0 * v0 * self.kernel.w(r, self.h), 2.0 * v0 * v0 * self.kernel.dw(r, self.h)

    def self_energy(self, n, v0, volume):
        """``N v0 vt W(0, h) - V``: the ``i = j`` terms of Eq. 3.8 and its ``-V``."""
        return float(n * v0 * v0 * self.kernel.w0(self.h) - volume)

    def boundary(self, r_pc, v0, want_forces=True, nlist=None, out=None, candidates=None, phi_out=None):
        """Boundary term of Eq. 3.8 per particle and its force (:attr:`boundary_term`).

        Parameters
        ----------
        r_pc : ndarray (N, 3) or (N, dim)
            Positions in the domain's frame.
        v0 : float
            ``vt = v0``.
        nlist : NeighborList or None
            ``"gamma"``: the neighbour list of ``r_pc`` (N, 3), whose bins find the boundary
            elements within ``h``; None bins the particles once.
        out : (ndarray (N,), ndarray (N, 3) or None) or None
            Arrays to which the term and its force are added in place and which are returned
            (the calculator's energies and forces): ``"level_set"`` then holds no array of N
            (the level set runs on :data:`_BOUNDARY_CHUNK` particles at a time; at 1e6 in 3D the
            full-N level set, mask, energies and forces held 48 bytes per particle). None:
            fresh arrays. The energies None: forces only (the energy terms are not computed).
        candidates : ndarray of int or None
            ``"level_set"``: the only particles that can lie within ``h`` of the wall (e.g. those within
            ``h + skin`` at the neighbour list's build, :meth:`near_wall`); None: all.
        phi_out : ndarray (len(candidates),) or None
            ``"level_set"`` with ``candidates``: receives the level set of each candidate at ``r_pc``.

        Returns
        -------
        e_p : ndarray (N,)
            ``"level_set"``: ``2 vt I(-phi_i)``; ``"gamma"``: ``2 vt kappa (1 - gamma_i + W1(0, h) max(phi_i, 0)
            + B max(d0 + phi_i, 0)^2 / (2 d0 h))`` (module docstring)
            (zeros without a domain).
        f_pc : ndarray (N, 3) or None
            Its negative gradient: ``-2 W1(max(-phi_i, 0), h) vt n_i`` (Eq. 4.4), or
            ``2 vt kappa (grad gamma_i - (W1(0, h) [phi_i > 0] + B max(d0 + phi_i, 0) / (d0 h)) n_i)``
            (None unless ``want_forces``).
        """
        r_pc = np.asarray(r_pc, dtype=float)
        n = len(r_pc)
        if out is None:
            e_p, f_pc = np.zeros(n), (np.zeros((n, 3)) if want_forces else None)
        else:
            e_p, f_pc = out
            f_pc = f_pc if want_forces else None
        if self.domain is None:
            return e_p, f_pc
        if self.boundary_term == "gamma":
            return self._gamma_boundary(r_pc, v0, want_forces, nlist, e_p, f_pc)
        # Fan's term vanishes at and beyond h from the wall (I(s >= h) = 0, W1(s >= h) = 0): only the particles near
        # the wall (the candidates) are looked at, in chunks; one level-set call gives phi and the normal of each, and
        # the terms of those within h are added in place (numba: a fancy-indexed add cost more than the level set)
        if candidates is None:
            candidates = self.near_wall(r_pc, self.h)
        for first in range(0, len(candidates), _BOUNDARY_CHUNK):
            pool = candidates[first:first + _BOUNDARY_CHUNK]
            phi_o, n_oc = self._phi_and_normal(np.take(r_pc, pool, axis=0))
            if phi_out is not None:
                phi_out[first:first + len(pool)] = phi_o
            s_o = -phi_o
            if e_p is not None:
                _add_where_within(e_p, pool, 2.0 * v0 * self.kernel.w1_tail_integral(s_o, self.h), s_o, self.h)
            if want_forces:  # -2 vt W1(max(s, 0), h) n, W1 as Kernel.w1 computes it (the same bits), in one loop
                breaks_s, pieces_su = self._w1_pieces()
                _add_wall_forces(f_pc, pool, s_o, n_oc, self.h, self.kernel.sigma_1d, -2.0 * v0, breaks_s, pieces_su)
        return e_p, f_pc

    def _w1_pieces(self):
        """The kernel profile's pieces as :func:`_add_wall_forces` reads them: ``(breaks_s, pieces_su)``, the right
        end of each piece (at most 1) and its polynomial in ``u = right - q`` (lowest power first, zero-padded)."""
        kernel = self.kernel
        if getattr(self, "_w1_key", None) != kernel.key:
            pieces = kernel._pieces_u
            self._w1_table = (np.array([kernel.breaks[s] for s in range(len(pieces))] + [min(kernel.breaks[len(pieces)],
                                                                                            1.0)]),
                              np.array([np.pad(np.asarray(p, dtype=float), (0, max(len(q) for q in pieces) - len(p)))
                                        for p in pieces]))
            self._w1_key = kernel.key
        return self._w1_table

    def near_wall(self, r_pc, reach):
        """Indices of the particles within ``reach`` of the wall or outside (``phi > -reach``), ``"level_set"``
        only (else None): with ``reach = h + skin`` at a neighbour list's build, the only ones that can come
        within ``h`` while the list is valid (they move less than ``skin / 2``)."""
        if self.domain is None or self.boundary_term != "level_set":
            return None
        parts = [np.flatnonzero(self._phi(r_pc[first:first + _BOUNDARY_CHUNK]) > -reach) + first
                 for first in range(0, len(r_pc), _BOUNDARY_CHUNK)]
        return np.concatenate(parts) if parts else np.zeros(0, dtype=np.intp)

    def _domain_points(self, r_pc):
        """``r_pc`` as the domain takes it: a Domain takes ASE positions (z dropped in 2D), others ``dim`` columns."""
        if isinstance(self.domain, Domain) and r_pc.shape[1] == 3:
            return r_pc
        return np.ascontiguousarray(r_pc[:, : self.dim])

    def _phi(self, r_pc):
        """The level set ``phi`` (N,) at ``r_pc``, (N, 3) or (N, dim)."""
        if not hasattr(self.domain, "phi"):  # a duck-typed domain with phi_and_normal() only
            return self._phi_and_normal(r_pc)[0]
        return np.asarray(self.domain.phi(self._domain_points(r_pc)), dtype=float).reshape(len(r_pc))

    def _phi_and_normal(self, r_pc, domain=None):
        """The level set ``phi`` (N,) and its gradient ``n`` (N, 3) at ``r_pc``, (N, 3) or (N, dim), of ``domain``
        (None: the model's)."""
        n = len(r_pc)
        phi_p, n_pc = (self.domain if domain is None else domain).phi_and_normal(self._domain_points(r_pc))
        n_pc = np.asarray(n_pc, dtype=float)
        if n_pc.shape != (n, 3):  # normals of fewer columns, padded with zeros
            normal_pc = np.zeros((n, 3))
            normal_pc[:, : n_pc.shape[1]] = n_pc[:, :3]
            n_pc = normal_pc
        return np.asarray(phi_p, dtype=float).reshape(n), n_pc

    def wall(self, v0):
        """``(integrals, domain)``: the wall of the ``"gamma"`` term for the particle volume ``v0``.

        On a :class:`~ase_sphrelax.domains.Polygon` the wall is the polygon's opening at ``r = wall_opening dp``
        (``dp = v0^(1/d)``; :meth:`~ase_sphrelax.domains.Polygon.opening`): its convex corners rounded to ``r``,
        and the parts narrower than ``2 r`` left out. No particle can sit ``r`` from both walls there, and the
        continuum's pull into such a sliver (a 15 degree trailing edge) pressed the nearest particle to 0.31 dx
        from the wall; with the opening at 0.35 dp it ends 0.37 dx away, and the near-wall kernel-sum error
        measured against the polygon itself falls from 0.043 to 0.027 (``reproductions/fan-thin-features``).
        Other domains (Box, CSG, Mesh), and ``wall_opening`` 0: the domain and its integrals. ``integrals`` is a
        :class:`~ase_sphrelax.boundary.BoundaryIntegrals`; the opening is computed once per ``r``.
        """
        opening = getattr(self.domain, "opening", None)
        if not self.wall_opening or opening is None:
            return self._integrals, self.domain
        radius = float(self.wall_opening) * float(v0) ** (1.0 / self.dim)
        key = (radius, self.h, self.kernel.key)
        if self._wall_key != key:
            from ..boundary import BoundaryIntegrals, as_boundary

            try:
                opened = opening(radius)
            except ValueError:
                raise ValueError(f"domain: the polygon is nowhere {2 * radius:g} wide (2 * wall_opening * dp), so "
                                 f"Fan's wall, its opening at {radius:g}, is empty; refine dx or set "
                                 f"model.wall_opening = 0 for the polygon itself") from None
            self._wall_value = (BoundaryIntegrals(as_boundary(opened).merged(), self.h, self.kernel.name), opened)
            self._wall_key = key
        return self._wall_value

    def _gamma_boundary(self, r_pc, v0, want_forces, nlist, out_e_p, out_f_pc):
        """``2 vt (1 - gamma)`` (+ the outside slope) and its negative gradient (:meth:`boundary`),
        added to ``out_e_p`` and ``out_f_pc``."""
        from ..neighbors import NeighborList

        n = len(r_pc)
        r3_pc = np.zeros((n, 3))
        r3_pc[:, : min(3, r_pc.shape[1])] = r_pc[:, :3]
        if nlist is None:
            nlist = NeighborList(self.h)
            nlist.update(r3_pc, np.zeros((3, 3)), np.zeros(3, dtype=bool), store=False)
        integrals, wall = self.wall(v0)
        terms = integrals.compute(nlist, r3_pc)
        weight = 2.0 * v0 * self.wall_weight
        e_p = weight * (1.0 - terms.gamma_p) if out_e_p is not None else None
        f_pc = weight * terms.grad_gamma_pc if want_forces else None
        # the contact core (within d0 of the wall, outside included) and the outside slope (phi > 0)
        d0 = CORE_DISTANCE * v0 ** (1.0 / self.dim)
        near = np.nonzero(terms.gamma_p < 1.0)[0]  # within h of the boundary or outside: phi > -d0 only here
        if len(near):
            phi_o, n_oc = self._phi_and_normal(r3_pc[near], wall)
            slope = weight * float(self.kernel.w1(0.0, self.h))
            core = weight * self.core_stiffness / (2.0 * d0 * self.h)
            x_o = np.maximum(d0 + phi_o, 0.0)
            if e_p is not None:
                e_p[near] += slope * np.maximum(phi_o, 0.0) + core * x_o * x_o
            if want_forces:
                g_o = slope * (phi_o > 0.0) + 2.0 * core * x_o
                f_pc[near] -= g_o[:, None] * n_oc
        if out_e_p is not None:
            out_e_p += e_p
        if want_forces:
            out_f_pc += f_pc
        return out_e_p, out_f_pc

    def warn_far_outside(self, r_pc, who="FanModel"):
        """Warn (:class:`ParticlesOutsideWarning`) when particles lie more than ``h`` outside the domain.

        Beyond the boundary the force of Eq. 4.4 is the constant ``-2 W1(0) vt n``: such particles
        come back slowly, one small step at a time, and usually mean positions in another frame
        than the domain's (issue 10 item 5: particles 5 units outside ran silently).
        """
        if self.domain is None:
            return
        phi_p = np.asarray(self.domain.phi(np.ascontiguousarray(np.asarray(r_pc)[:, : self.dim])), dtype=float)
        far = np.nonzero(phi_p > self.h)[0]
        if len(far):
            import warnings

            worst = int(far[np.argmax(phi_p[far])])
            warnings.warn(f"{who}: {len(far)} particle(s) lie more than h outside the domain (up to "
                          f"{phi_p[worst]:.4g} = {phi_p[worst] / self.h:.3g} h, particle {worst}): the boundary "
                          "force is constant out there, so they return only slowly; check that the positions and "
                          "the domain share one frame", ParticlesOutsideWarning, stacklevel=5)

    # -- stress ----------------------------------------------------------------------
    def check_stress(self, volumes, cell_volume):
        """Raise PropertyNotImplementedError unless stress is defined: periodic along all dim axes,
        no domain, a cell of non-zero volume (2D cells need a c vector)."""
        if self.domain is not None or volumes.measure is None:
            raise PropertyNotImplementedError("stress needs a cell periodic along all dim axes and no domain")
        if not abs(cell_volume) > 0:
            raise PropertyNotImplementedError("stress needs a cell of non-zero volume (give a 2D cell a c vector), "
                                              f"got {cell_volume!r}")

    def stress(self, pair_virial_cc, energy, volumes, cell_volume):
        """Voigt stress ``(1/V_cell) dE/d(strain)`` (xx yy zz yz xz xy) of Eq. 3.8 in a periodic cell.

        Parameters
        ----------
        pair_virial_cc : ndarray (3, 3)
            ``dE_pair/d(strain)`` of the pair part (``sum over pairs phi'(r) d d^T / r``).
        energy : float
            The total ``E`` (no domain: pair part + self part).
        volumes : FanVolumes
        cell_volume : float
            ``atoms.cell.volume``.
        """
        self.check_stress(volumes, cell_volume)
        in_plane = np.zeros((3, 3))
        in_plane[: self.dim, : self.dim] = np.eye(self.dim)
        d_e = np.array(pair_virial_cc, dtype=float) - volumes.measure * in_plane  # the -V term
        if self.dx is None:
            # v0 = vt = V/N scales with the measure: d(v0 vt)/d(eps_aa) = 2 v0 vt, on E + V = v0 vt sum W
            d_e += 2.0 * (energy + volumes.volume) * in_plane
        return (d_e / abs(cell_volume)).flat[[0, 4, 8, 5, 2, 1]]


@numba.njit(cache=True, nogil=True)
def _add_where_within(e_p, pool_o, value_o, s_o, h):
    """``e_p[pool_o[k]] += value_o[k]`` for the k with ``s_o[k] < h`` (a particle within h of the wall)."""
    for k in range(pool_o.shape[0]):
        if s_o[k] < h:
            e_p[pool_o[k]] += value_o[k]


@numba.njit(cache=True, nogil=True)
def _add_wall_forces(f_pc, pool_o, s_o, n_oc, h, sigma_1d, scale, breaks_s, pieces_su):
    """``f_pc[pool_o[k]] += scale W1(max(s_o[k], 0), h) n_oc[k]`` for the k with ``s_o[k] < h`` (Eq. 4.4's force with
    ``scale = -2 vt``): ``W1(r, h) = sigma_1d / h f(r / h)`` with the profile ``f`` evaluated as
    :meth:`~ase_sphrelax.kernels.Kernel.profile` does (piece s holds ``breaks_s[s] <= q < breaks_s[s + 1]``, its
    polynomial in ``u = breaks_s[s + 1] - q`` by Horner's rule as numpy's ``polyval``): the bits of
    ``Kernel.w1``, without its temporary arrays."""
    pieces = pieces_su.shape[0]
    degree = pieces_su.shape[1]
    factor = sigma_1d / h
    for k in range(pool_o.shape[0]):
        if not s_o[k] < h:
            continue
        q = max(s_o[k], 0.0) / h
        f = 0.0
        for s in range(pieces):
            if breaks_s[s] <= q < breaks_s[s + 1]:
                u = breaks_s[s + 1] - q
                f = pieces_su[s, degree - 1]
                for i in range(degree - 2, -1, -1):
                    f = pieces_su[s, i] + f * u
                break
        g = factor * f * scale
        p = pool_o[k]
        for c in range(n_oc.shape[1]):
            f_pc[p, c] += g * n_oc[k, c]
