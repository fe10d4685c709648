"""BIPI's staged particle packing as an ASE optimiser (Boregowda & Liu 2025, Sec. 3.2, Fig. 5).

Step 1 (:func:`initial_fill`): one particle per Cartesian cell centre inside the boundary
(:func:`ase_sphrelax.build.fill`, no jitter, the paper's Fig. 2); like BIPI2D's generator, the
centres within ``dx/8`` of the boundary are dropped.

Step 2, :class:`BIPIPacker`, every iteration moves particles by Eq. 14 with the step boundary
pressure, capped by Eq. 15 (:meth:`ase_sphrelax.models.bipi.BIPIModel.shift`):

* **2a** -- *packable* particles: those within ``k_a = kappa h_B = h`` of the boundary (every
  particle whose kernel is truncated); *selected*: the packable ones and their neighbours
  within ``h``, found once at the start. Each iteration evaluates the selected particles only
  (a sub-system with its own neighbour list) and moves the packable ones, so its cost follows
  the selected particles, not N.
* **2b** -- freeze (``ase.constraints.FixAtoms``) the particles within ``k_b = 0.6 dx`` of the
  boundary, found through gamma as the paper does: ``gamma_a`` below the gamma of a point at
  ``k_b`` from a straight wall.
* **2c** -- every unfrozen particle is packable, all are selected.

Stopping rules (defined here; the paper says "when the change is less than 1 %"). With ``X_i``
the monitored average after ``i`` iterations of the stage (``X_0`` at its start) -- Step 2a:
``TPD_avg``, the mean over the packable particles of ``|x_a - x_a0|`` from the start of Step 2;
Step 2c: ``|grad C|_avg`` over the unfrozen particles -- a stage stops after iteration ``i >= w``
when ``|X_i - X_(i-w)| <= tol |X_(i-w)|`` (and ``X_(i-w) > 0``), with the window ``w``
(``window``, default 10) and ``tol`` 0.01; or at the iteration caps (BIPI2D: 5000 for 2a, 1000
for 2c). ``window=1`` is the literal per-iteration reading.

A move that would take a particle out of the domain is not made (the particle keeps its
position for that iteration; ``history`` counts them as ``rejected``): no particle leaves.

``history`` keeps, per iteration: stage, iteration, ``TPD_avg``, ``|grad C|_avg`` (packable),
``n_pack``, ``n_selected``, the iteration's wall time, rejected moves; :meth:`BIPIPacker.save`
writes it as JSON and :func:`ase_sphrelax.plotting.plot_packing_history` draws it (Fig. 7-9);
:func:`ase_sphrelax.analysis.bipi.pack_summary` adds the quality metrics.
"""
from __future__ import annotations

import json
import time
import warnings

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms
from ase.optimize.optimize import Optimizer

from ..checks import NotConvergedWarning, SpacingWarning, check_positive

__all__ = ["BIPIPacker", "initial_fill", "wall_layers", "wall_particles", "add_walls", "pack", "STAGES", "FLUID", "WALL",
           "particle_kinds", "MIN_GAP", "JUST_OUTSIDE"]

STAGES = ("2a", "2b", "2c")
CAP_2A, CAP_2C = 5000, 1000  # BIPI2D's pack_step2a, pack_step2c
DROP_FRACTION = 1.0 / 8.0  # BIPI2D's generator drops cell centres within dx/8 of the boundary
FLUID, WALL = 1, 2  # atoms.arrays["type"] (read by particle_kinds; lammps_io.sph_flows and flows.settle use it)


def _result(calc, name, atoms):
    """The calculator's result ``name`` for ``atoms`` without ASE's copy (``get_property`` copies; read only)."""
    if name not in calc.results or calc.check_state(atoms):
        calc.get_property(name, atoms)
    return calc.results[name]


def particle_kinds(atoms):
    """``atoms.arrays["type"]`` per particle: :data:`FLUID` (1) or :data:`WALL` (2); all fluid without it.

    Raises a one-line ValueError naming the particles of any other type.
    """
    if "type" not in atoms.arrays:
        return np.full(len(atoms), FLUID, dtype=int)
    t_p = np.asarray(atoms.arrays["type"], dtype=int)
    bad = ~np.isin(t_p, (FLUID, WALL))
    if bad.any():
        raise ValueError(f"atoms.arrays['type'] must hold {FLUID} (fluid) or {WALL} (wall); particles "
                         f"{np.where(bad)[0][:10].tolist()} have {sorted(set(t_p[bad].tolist()))[:5]}")
    return t_p


def initial_fill(boundary, dx, origin=None, drop=DROP_FRACTION, max_particles=None):
    """Step 1: one particle per Cartesian cell centre inside, none within ``drop * dx`` of the boundary.

    Parameters
    ----------
    boundary : BoundarySegments, BoundaryTriangles, domain or file (:func:`ase_sphrelax.boundary.as_boundary`)
    dx : float
    origin : array_like, optional
        Grid anchor (:func:`ase_sphrelax.build.fill`); default the coordinate origin.
    drop : float
        Fraction of ``dx``.
    max_particles : float or None
        Refuse a fill of more particles (:func:`ase_sphrelax.build.fill`; default its
        :data:`~ase_sphrelax.build.MAX_PARTICLES`).

    Returns
    -------
    ase.Atoms
        Bounded, ``info["dx"] = dx``; 2D particles at z = 0. A periodic boundary
        (``boundary.with_cell``): the cell centres in the cell ``[0, L)`` along the periodic
        axes, with the boundary's periods as cell vectors and ``pbc`` set (a warning when ``L``
        is not a whole number of ``dx``: the spacing across the seam then differs).
    """
    from ..boundary import as_boundary
    from ..build import fill

    dx = check_positive("dx", dx)
    boundary = as_boundary(boundary)
    domain = boundary.domain
    lo, hi = domain.bounds
    if np.any(hi - lo < dx):
        raise ValueError(f"dx={dx!r} is larger than the shape (extent {np.round(hi - lo, 6).tolist()}): no particle "
                         "would be placed; choose a smaller dx")
    atoms = fill(domain, dx, jitter=0.0, origin=origin, **({} if max_particles is None else dict(max_particles=max_particles)))
    keep = domain.phi(atoms.positions) < -drop * dx
    if not keep.any():
        raise ValueError(f"dx={dx!r}: no cell centre lies farther than {drop:g} dx inside the boundary; choose a "
                         "smaller dx")
    if boundary.periodic is not None:
        keep &= in_cell(atoms.positions, boundary)
    del atoms[np.nonzero(~keep)[0]]
    atoms.info["volume"] = float(getattr(domain, "volume", np.nan))
    if boundary.periodic is not None:
        periodic_cell(atoms, boundary, dx)
    return atoms


def in_cell(r_pc, boundary):
    """Mask of the positions inside the cell ``[0, L)`` along the boundary's periodic axes."""
    inside = np.ones(len(r_pc), dtype=bool)
    for i in boundary.periodic.axes:
        inside &= (r_pc[:, i] >= 0.0) & (r_pc[:, i] < boundary.periodic.period_c[i])
    return inside


def periodic_cell(atoms, boundary, dx):
    """Give ``atoms`` the boundary's periods (cell vectors, ``pbc``); warn when a period is not a whole number of dx."""
    cell = atoms.cell.array.copy()
    pbc = np.array(atoms.pbc, dtype=bool)
    disp = np.asarray(atoms.get_celldisp()).reshape(3).copy()
    for i in boundary.periodic.axes:
        cell[i] = boundary.cell[i]
        pbc[i] = True
        disp[i] = 0.0
        ratio = boundary.periodic.period_c[i] / dx
        if abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio):
            warnings.warn(f"the period along {'xyz'[i]} is {ratio:.6g} dx, not a whole number: the Cartesian start's "
                          "spacing across the periodic seam differs from dx", SpacingWarning, stacklevel=3)
    atoms.set_cell(cell)
    atoms.set_celldisp(disp)
    atoms.pbc = pbc


def wall_layers(h, dx):
    """Default number of wall layers: enough for the kernel support, ``ceil(h / dx)``."""
    return int(np.ceil(check_positive("h", h) / check_positive("dx", dx) - 1e-9))


def wall_particles(boundary, dx, layers=None, h=None, origin=None, keep=None, drop=None):
    """Wall particles: the Step-1 grid's cell centres outside the domain, within ``layers * dx`` of it.

    The solid side of every wall, on the same Cartesian grid as :func:`initial_fill` (same
    ``origin``), so that fluid and wall particles continue one lattice: a cell centre ``r`` is a
    wall particle when ``0 < phi(r) <= layers dx`` (``phi`` the domain's signed distance,
    negative inside). Not packed against the wall (Step 1 only). No wall particle is ever inside
    the domain (issue 31).

    With ``drop`` (the ``drop`` given to :func:`initial_fill`) the band also takes the centres
    that the fill left out as too close to the boundary, ``-drop dx <= phi(r) <= 0``, each moved
    along the normal of its closest boundary point to just outside it (``phi =``
    :data:`JUST_OUTSIDE` ``dx``; at most ``drop dx`` from its cell centre): fluid and walls are
    then one unbroken lattice, every wall about 1 dx from a Step-1 fluid particle, and no wall
    inside. Without it (the default, only ``phi > 0``), a column of centres lying on a wall
    belongs to neither, and that wall is 2 dx from the fluid: the wedge tank of
    ``reproductions/lib/bipi_sph.py`` at ``dx = 0.02`` is 102.5 dx wide, so the centres at ``x = 2.05`` lie
    on its right wall. :func:`add_walls`, which pairs the walls with a fill, passes the fill's
    default.

    Parameters
    ----------
    boundary : BoundarySegments, BoundaryTriangles, domain or file
    dx : float
    layers : int or None
        Thickness of the band in units of ``dx``; default :func:`wall_layers` of ``h``.
    h : float or None
        Kernel support radius, for the default ``layers``.
    origin : array_like, optional
        Grid anchor, as for :func:`initial_fill`.
    keep : callable or None
        ``keep(r_pd) -> bool array``: a further filter (e.g. no wall above a free surface).
    drop : float or None
        Fraction of ``dx``: also take the centres with ``-drop dx <= phi <= 0`` (those
        ``initial_fill(..., drop=drop)`` leaves out), moved to just outside; ``None``: only
        ``phi > 0``.

    Returns
    -------
    ase.Atoms
        The wall particles, ``arrays["type"] = WALL``, 2D ones at z = 0.
    """
    from ..boundary import as_boundary

    dx = check_positive("dx", dx)
    if layers is None:
        if h is None:
            raise ValueError("wall_particles: give layers (an integer >= 1) or h (the kernel support) for the default")
        layers = wall_layers(h, dx)
    layers = _count("layers", layers, minimum=1)
    if drop is not None and not (np.isfinite(drop) and 0.0 <= drop < layers):
        raise ValueError(f"wall_particles: drop must be None or a fraction of dx in [0, layers), got {drop!r}")
    boundary = as_boundary(boundary)
    domain = boundary.domain
    dim = domain.dim
    origin = np.zeros(dim) if origin is None else np.asarray(origin, dtype=float).reshape(-1)[:dim]
    lo, hi = domain.bounds
    pad = (layers + 1) * dx
    k_lo = np.floor((lo - pad - origin) / dx - 0.5).astype(np.int64)
    k_hi = np.ceil((hi + pad - origin) / dx + 0.5).astype(np.int64)
    axes = [origin[d] + (np.arange(k_lo[d], k_hi[d]) + 0.5) * dx for d in range(dim)]
    found = []
    for x0 in axes[0]:  # slabs along the first axis keep memory bounded
        grids = np.meshgrid(np.array([x0]), *axes[1:], indexing="ij")
        r_pd = np.stack([g.ravel() for g in grids], axis=1)
        phi_p = domain.phi(r_pd)
        near = (phi_p > 0.0) if drop is None else (phi_p >= -drop * dx)
        band = near & (phi_p <= layers * dx)
        r_pd, phi_p = r_pd[band], phi_p[band]
        if drop is not None:
            r_pd = _just_outside(domain, r_pd, phi_p, dx)
        if keep is not None and len(r_pd):
            r_pd = r_pd[np.asarray(keep(r_pd), dtype=bool)]
        found.append(r_pd)
    r_pd = np.concatenate(found) if found else np.zeros((0, dim))
    positions = np.zeros((len(r_pd), 3))
    positions[:, :dim] = r_pd
    if boundary.periodic is not None:  # one period of walls: the cell centres in [0, L) along the periodic axes
        positions = positions[in_cell(positions, boundary)]
    walls = Atoms(positions=positions, pbc=False)
    walls.arrays["type"] = np.full(len(walls), WALL, dtype=int)
    walls.info.update(dx=dx, wall_layers=layers)
    return walls


#: where :func:`wall_particles` puts the centres on or just inside the boundary: ``phi`` = this times dx
JUST_OUTSIDE = 1e-6
#: :func:`add_walls`' default: no wall particle closer than this (times dx) to a fluid particle
MIN_GAP = 0.5


def _just_outside(domain, r_pd, phi_p, dx):
    """``r_pd`` with the points at ``phi <= JUST_OUTSIDE dx`` moved along the normal to ``phi = JUST_OUTSIDE dx``;
    a point the move does not take outside (a corner's ambiguous normal) is left out."""
    target = JUST_OUTSIDE * dx
    move = phi_p <= target
    if not move.any():
        return r_pd
    r_pd = r_pd.copy()
    for _ in range(3):
        idx = np.nonzero(move)[0]
        phi_m, n_mc = domain.phi_and_normal(r_pd[idx])
        norm = np.linalg.norm(n_mc[:, : r_pd.shape[1]], axis=1)
        step = np.where(norm > 0, (target - phi_m) / np.where(norm > 0, norm, 1.0) ** 2, 0.0)
        r_pd[idx] += step[:, None] * n_mc[:, : r_pd.shape[1]]
        move[idx] = domain.phi(r_pd[idx]) <= 0.5 * target
        if not move.any():
            return r_pd
    return r_pd[~move]


def add_walls(atoms, boundary, dx, layers=None, h=None, origin=None, keep=None, walls=None, drop=DROP_FRACTION,
              min_gap=MIN_GAP):
    """``atoms`` (fluid, ``type`` FLUID) followed by :func:`wall_particles` (``type`` WALL).

    Returns a new Atoms with ``atoms``' cell, pbc and info, without constraints or calculator;
    ``info["n_fluid"]`` and ``info["n_wall"]`` count the kinds. ``walls``: wall particles made
    elsewhere (:mod:`~ase_sphrelax.drivers.bipi_walls`), used instead of the grid ones.
    ``drop``: passed to :func:`wall_particles`; the default, :func:`initial_fill`'s, makes the
    grid walls also take the cell centres the fill dropped within ``dx/8`` of the boundary, moved
    to just outside it, so every wall is about 1 dx from a Step-1 fluid (``None``: walls strictly
    outside, ``phi > 0``).

    Whatever made them, the walls kept are never inside the domain (``phi > 0``) and none is
    closer than ``min_gap dx`` (default :data:`MIN_GAP`, 0.5) to a fluid particle of ``atoms``
    (periodic images included): the others are left out, counted in ``info["n_wall_dropped"]``
    (a packed fluid's boundary layer can sit within 0.5 dx of the boundary, closer than a grid
    wall just outside it).
    """
    from ..boundary import as_boundary

    boundary = as_boundary(boundary)
    if not (np.isfinite(min_gap) and min_gap >= 0):
        raise ValueError(f"min_gap must be a fraction of dx >= 0, got {min_gap!r}")
    if walls is None:
        walls = wall_particles(boundary, dx, layers=layers, h=h, origin=origin, keep=keep, drop=drop)
    dim = boundary.domain.dim
    bad = ~(boundary.domain.phi(walls.positions[:, :dim]) > 0.0)
    if len(atoms) and len(walls) and min_gap > 0:
        bad |= _nearest_distance(walls.positions, atoms.positions, atoms, dim) < min_gap * dx
    walls = walls[~bad] if bad.any() else walls
    out = atoms.copy()
    out.set_constraint()
    out.calc = None
    for name in list(out.arrays):
        if name not in ("numbers", "positions"):
            del out.arrays[name]
    out.arrays["type"] = np.full(len(out), FLUID, dtype=int)
    walls.cell, walls.pbc = out.cell, out.pbc
    walls.set_atomic_numbers(np.full(len(walls), out.numbers[0] if len(out) else 1))
    out += walls
    out.info.update(n_fluid=len(atoms), n_wall=len(walls), wall_layers=walls.info["wall_layers"],
                    n_wall_dropped=int(bad.sum()))
    return out


def _nearest_distance(r_pc, fluid_qc, atoms, dim):
    """Distance from each ``r_pc`` to the nearest of ``fluid_qc`` and their periodic images (``atoms``' cell)."""
    from scipy.spatial import cKDTree

    points = [np.asarray(fluid_qc, dtype=float)[:, :dim]]
    for i in range(dim):
        if atoms.pbc[i]:
            shift = np.asarray(atoms.cell[i], dtype=float)[:dim]
            points = [p + k * shift for p in points for k in (-1, 0, 1)]
    d, _ = cKDTree(np.concatenate(points)).query(np.asarray(r_pc, dtype=float)[:, :dim])
    return d


class BIPIPacker(Optimizer):
    """The paper's Step 2 (2a, 2b, 2c) on an Atoms with a :class:`~ase_sphrelax.BIPICalculator`.

    Parameters
    ----------
    atoms : ase.Atoms
        Particles (e.g. :func:`initial_fill`), all strictly inside the boundary. Bounded, or
        periodic with a periodic boundary (``boundary.with_cell``: the same ``pbc`` and periods):
        the pair sums and ``gamma`` then see the periodic images, displacements are taken as
        minimum images, and the particles are wrapped into the cell at the end of each stage.
    calculator : BIPICalculator, optional
        Default ``atoms.calc``; attached to ``atoms``.
    max_steps_2a, max_steps_2c : int
        Iteration caps (BIPI2D: 5000 and 1000).
    tol, window : float, int
        Stopping rule (module docstring): relative change ``tol`` over ``window`` iterations.
    k_a, k_b : float or None
        Packable band of Step 2a (default ``h``) and freezing distance of Step 2b (default
        ``0.6 dx``).
    pressure : bool
        The step boundary pressure of Eq. 14 (False: Eq. 12).
    momentum : float
        0 (default): the paper's Eq. 14-15. ``beta`` in [0, 1): Step 2c moves by the heavy-ball step
        ``s_i = Eq. 14 + beta s_(i-1)``, capped by Eq. 15, with ``s_(i-1)`` the previous move (0 where it
        was rejected). Not the paper's rule: it reaches a lower ``|grad C|_avg`` in fewer iterations
        (``reproductions/speed-bipi-sphere/README.md``; the sphere: 352 iterations to 4.1e-5 by the 1 % rule
        against 1000, the cap, to 3.4e-4 at 0). Opt-in: at 0.95 the oscillating ``|grad C|_avg``
        satisfied the 1 % rule after 36 iterations, far from converged.
    momentum_stages : tuple of str
        The stages ``momentum`` applies to: default Step 2c only. In Step 2a it moved the boundary
        layer (the sphere: TPD's rule stopped after 30 iterations with the layer's minimum at 0.41 dx
        against 0.44).
    stages : tuple of str
        Which of "2a", "2b", "2c" to run, in order.
    outside : {"raise", "move"}
        Particles that start outside (or on) the boundary: refuse with an error naming them, or
        move them to ``0.5 dx`` inside along the normal of their closest boundary point.
    progress : bool
        A tqdm bar per stage.
    logfile, trajectory, loginterval
        As for ASE optimisers (a log line per iteration of the current stage).

    Attributes
    ----------
    stage : str
        "2a", "2b", "2c" or "done".
    history : list of dict
    frozen : ndarray of int
        Particles frozen in Step 2b.
    """

    def __init__(self, atoms, calculator=None, max_steps_2a=CAP_2A, max_steps_2c=CAP_2C, tol=0.01, window=10,
                 k_a=None, k_b=None, pressure=True, stages=STAGES, outside="raise", progress=False, logfile=None,
                 trajectory=None, momentum=0.0, momentum_stages=("2c",), **kwargs):
        from ..calculators.bipi import BIPICalculator

        calc = calculator if calculator is not None else atoms.calc
        if not isinstance(calc, BIPICalculator):
            raise TypeError(f"calculator must be a BIPICalculator, got {type(calc).__name__}")
        atoms.calc = calc
        self.calc = calc
        self.model = calc.model
        self.max_steps_2a = _count("max_steps_2a", max_steps_2a)
        self.max_steps_2c = _count("max_steps_2c", max_steps_2c)
        self.tol = check_positive("tol", tol)
        self.window = _count("window", window, minimum=1)
        self.k_a = self.model.h if k_a is None else check_positive("k_a", k_a)
        self.k_b = self.model.k_b if k_b is None else check_positive("k_b", k_b)
        self.pressure = bool(pressure)
        momentum = float(momentum)
        if not 0.0 <= momentum < 1.0:
            raise ValueError(f"momentum must be in [0, 1) (0: the paper's Eq. 14-15), got {momentum!r}")
        self.momentum = momentum
        momentum_stages = tuple(momentum_stages)
        if any(s not in ("2a", "2c") for s in momentum_stages):
            raise ValueError(f"momentum_stages must be a subset of ('2a', '2c'), got {momentum_stages!r}")
        self.momentum_stages = momentum_stages
        stages = tuple(stages)
        if not stages or any(s not in STAGES for s in stages) or list(stages) != sorted(stages):
            raise ValueError(f"stages must be an ordered subset of {STAGES}, got {stages!r}")
        self.stages = stages
        if outside not in ("raise", "move"):
            raise ValueError(f"outside must be 'raise' or 'move', got {outside!r}")
        self.progress = bool(progress)
        calc.validate_atoms(atoms)
        calc.check_spacing(len(atoms), final=True)  # Step 2a evaluates subsets: check the whole set once
        self.moved_in = self._bring_inside(atoms, outside)
        Optimizer.__init__(self, atoms, logfile=logfile, trajectory=trajectory, **kwargs)

    # -- set-up ------------------------------------------------------------------------
    def _bring_inside(self, atoms, outside):
        domain = self.calc.boundary.domain
        phi = domain.phi(atoms.positions)
        bad = np.nonzero(~(phi < 0.0))[0]
        if len(bad) == 0:
            return np.zeros(0, dtype=int)
        if outside == "raise":
            raise ValueError(f"atoms: particles {bad[:10].tolist()} ({len(bad)} in all) are outside or on the boundary; "
                             "move them inside or pass outside='move'")
        phi_b, n_bc = domain.phi_and_normal(atoms.positions[bad])
        pos = atoms.positions.copy()
        pos[bad] -= (phi_b + 0.5 * self.model.dx)[:, None] * n_bc
        still = np.nonzero(~(domain.phi(pos[bad]) < 0.0))[0]
        if len(still):
            raise ValueError(f"atoms: particles {bad[still][:10].tolist()} could not be moved inside")
        atoms.positions = pos
        return bad

    def initialize(self):
        self.stage = self.stages[0]
        self.history = []
        self.frozen = np.zeros(0, dtype=int)
        self.x0 = self.atoms.positions.copy()
        self.iteration = 0
        self._metric = []
        self._sub = None
        self._velocity = None
        self._t0 = time.perf_counter()
        self.stage_iterations = {s: 0 for s in ("2a", "2c")}
        self.gamma_wall = None
        self._done = False
        self._final = None
        self._movable_all = None
        self.stopped_by = {}  # stage -> "rule", "cap" or "nothing to move"
        self.degenerate = False

    def read(self):
        raise NotImplementedError("BIPIPacker has no restart file")

    def todict(self):
        d = Optimizer.todict(self)
        d.update(max_steps_2a=self.max_steps_2a, max_steps_2c=self.max_steps_2c, tol=self.tol, window=self.window,
                 k_a=self.k_a, k_b=self.k_b, pressure=self.pressure, stages=list(self.stages), h=self.model.h,
                 dx=self.model.dx, h_over_dx_paper=self.model.h_over_dx_paper, J=self.model.J,
                 momentum=self.momentum, momentum_stages=list(self.momentum_stages))
        return d

    def _user_fixed(self, n):
        fixed = np.zeros(n, dtype=bool)
        for c in self.atoms.constraints:
            if isinstance(c, FixAtoms):
                fixed[c.index] = True
        return fixed

    def _start_2a(self):
        from ..boundary import boundary_pairs
        from ..neighbors import NeighborList

        atoms = self.atoms
        r = atoms.positions
        near = boundary_pairs(r, self.calc.boundary, self.k_a).nearest_distance()
        packable = near < self.k_a
        nlist = NeighborList(self.model.h)
        nlist.update(r, atoms.cell.array, self._pbc(), store=True)
        i, j, d = nlist.get_pairs(r)
        close = np.einsum("kc,kc->k", d, d) < self.model.h**2
        selected = packable.copy()
        selected[j[close & packable[i]]] = True
        selected[i[close & packable[j]]] = True
        self._sel = np.nonzero(selected)[0]
        sub = Atoms(positions=r[self._sel], cell=atoms.cell, pbc=atoms.pbc)
        sub.calc = self.calc.clone()
        sub.calc.skip_spacing_check()  # a subset: the whole set was checked
        self._sub = sub
        self._movable = packable[self._sel] & ~self._user_fixed(len(atoms))[self._sel]
        self._x0_sub = self.x0[self._sel]

    def _pbc(self):
        """The atoms' pbc along the boundary's axes (False beyond its dimension)."""
        pbc = np.array(self.atoms.pbc, dtype=bool)
        pbc[self.model.dim:] = False
        return pbc

    def _displacement(self, r_pc, r0_pc, out=None):
        """``r - r0``, the minimum image along periodic axes (into ``out`` if given)."""
        d = np.subtract(r_pc, r0_pc, out=out)
        periodic = self.calc.boundary.periodic
        if periodic is not None:
            for i in periodic.axes:
                d[:, i] -= np.round(d[:, i] / periodic.period_c[i]) * periodic.period_c[i]
        return d

    def wrap(self):
        """Wrap the particles into the cell along the boundary's periodic axes (no-op when bounded)."""
        periodic = self.calc.boundary.periodic
        if periodic is not None:
            self.atoms.positions = periodic.wrap(self.atoms.positions)

    def _freeze(self):
        """Step 2b: FixAtoms on the particles whose gamma is below gamma at k_b from a straight wall."""
        atoms = self.atoms
        self.gamma_wall = self.model.wall_gamma(self.k_b)
        gamma = self.calc.get_property("gamma", atoms)
        self.frozen = np.nonzero(gamma < self.gamma_wall)[0]
        fixed = self._user_fixed(len(atoms))
        fixed[self.frozen] = True
        atoms.set_constraint([c for c in atoms.constraints if not isinstance(c, FixAtoms)] +
                             [FixAtoms(indices=np.nonzero(fixed)[0])])
        self._movable_all = ~fixed

    # -- iteration ---------------------------------------------------------------------
    def _evaluate(self, atoms, movable):
        """grad C of ``atoms`` and its average over the movable particles."""
        grad_c = _result(atoms.calc, "concentration_gradient", atoms)  # read only
        if not movable.any():
            return grad_c, 0.0
        every = movable.all()  # the usual case in 2c: no masked copy
        gradc_avg = float(np.mean(np.linalg.norm(grad_c if every else grad_c[movable], axis=1)))
        return grad_c, gradc_avg

    def _move(self, atoms, grad_c, x0, movable):
        """One Eq. 14-15 move of the movable particles; returns (TPD_avg after it, rejected moves)."""
        calc = atoms.calc
        step = self.model.shift(grad_c, _result(calc, "wall_gradient", atoms), _result(calc, "gamma", atoms),
                                self.pressure)
        step[~movable] = 0.0
        heavy = self.momentum > 0.0 and self.stage in self.momentum_stages
        if heavy and self._velocity is not None and self._velocity.shape == step.shape:
            step += self.momentum * self._velocity  # heavy ball, capped as Eq. 15
            norm = np.sqrt(np.einsum("pc,pc->p", step, step))
            over = norm > self.model.cap
            step[over] *= (self.model.cap / norm[over])[:, None]
        # a move can leave the domain only from closer than the cap: test those particles
        near = calc.boundary_distances() <= self.model.cap * (1 + 1e-12)
        check = np.nonzero(near & movable)[0]
        rejected = 0
        if len(check):
            out = ~self.calc.boundary.contains(atoms.positions[check] + step[check])
            step[check[out]] = 0.0
            rejected = int(out.sum())
        if heavy:
            self._velocity = step
            pos = atoms.positions + step
        else:
            pos = np.add(atoms.positions, step, out=step)
        del step
        atoms.positions = pos  # a copy into the atoms' array: pos is free below
        if movable.all():  # the usual case in 2c: the displacements in pos, no masked copies
            d = self._displacement(pos, x0, out=pos)
            tpd = np.sqrt(np.add.reduce(np.multiply(d, d, out=d), axis=1))  # np.linalg.norm(d, axis=1), in place
        else:
            tpd = np.linalg.norm(self._displacement(pos[movable], x0[movable]), axis=1)
        return (float(tpd.mean()) if len(tpd) else 0.0), rejected

    def _stop(self, values):
        """The stopping rule on X_0 .. X_i (module docstring)."""
        i = len(values) - 1
        w = self.window
        if i < w:
            return False
        prev = values[i - w]
        return prev > 0 and abs(values[i] - prev) <= self.tol * abs(prev)

    def step(self, f=None):
        """One iteration of the current stage (2b takes none: it runs on leaving 2a).

        2a: evaluate the selected particles, move the packable ones, then TPD_avg (X_i).
        2c: evaluate all, ``|grad C|_avg`` (X_i); stop here if the rule holds, else move.
        """
        t = time.perf_counter()
        if self.stage == "2a":
            if self._sub is None:
                self._start_2a()
                self._metric = [0.0]  # X_0: TPD at the start of Step 2
            grad_c, gradc = self._evaluate(self._sub, self._movable)
            tpd, rejected = self._move(self._sub, grad_c, self._x0_sub, self._movable)
            self.atoms.positions[self._sel] = self._sub.positions
            n_pack, n_sel = int(self._movable.sum()), len(self._sel)
            self._metric.append(tpd)
            if self._stop(self._metric):
                self._done, self.stopped_by["2a"] = True, "rule"
            elif self.stage_iterations["2a"] + 1 >= self.max_steps_2a:
                self._done, self.stopped_by["2a"] = True, "cap"
        elif self.stage == "2c":
            if self._movable_all is None:
                self._movable_all = ~self._user_fixed(len(self.atoms))
            movable = self._movable_all
            if not movable.any():  # every particle frozen or fixed: iterations would move nothing
                self._done, self.stopped_by["2c"], self.degenerate = True, "nothing to move", True
                return
            grad_c, gradc = self._evaluate(self.atoms, movable)
            self._metric.append(gradc)
            if self._stop(self._metric):
                self._done, self.stopped_by["2c"] = True, "rule"
                self._final = dict(gradc_avg=gradc)
                return
            tpd, rejected = self._move(self.atoms, grad_c, self.x0, movable)
            n_pack, n_sel = int(movable.sum()), len(self.atoms)
            if self.stage_iterations["2c"] + 1 >= self.max_steps_2c:
                self._done, self.stopped_by["2c"] = True, "cap"
        else:
            raise RuntimeError(f"no iteration in stage {self.stage!r}")
        self.stage_iterations[self.stage] += 1
        self.iteration += 1
        row = dict(stage=self.stage, iteration=self.stage_iterations[self.stage], tpd_avg=tpd, gradc_avg=gradc,
                   n_pack=n_pack, n_selected=n_sel, rejected=rejected, time=time.perf_counter() - t)
        self.history.append(row)

    def _next_stage(self):
        self.wrap()
        order = list(self.stages)
        k = order.index(self.stage) + 1 if self.stage in order else len(order)
        self.stage = order[k] if k < len(order) else "done"
        self._metric = []
        self._done = False
        self._sub = None
        self._velocity = None
        if self.stage == "2b":
            self._freeze()
            self._next_stage()

    def converged(self, *args, **kwargs):
        return self.stage == "done"

    def log(self, *args, **kwargs):
        if self.logfile is None or not self.history:
            return
        r = self.history[-1]
        if r["iteration"] == 1:
            self.logfile.write(f"{'stage':>5} {'iter':>6} {'TPD_avg':>12} {'|gradC|_avg':>12} {'n_pack':>7} "
                               f"{'time':>9}\n")
        self.logfile.write(f"{r['stage']:>5} {r['iteration']:6d} {r['tpd_avg']:12.5e} {r['gradc_avg']:12.5e} "
                           f"{r['n_pack']:7d} {r['time']:9.2e}\n")

    def irun(self, steps=None):
        """Run the stages as a generator (yields after each iteration); ``steps`` caps the total."""
        bars = {}
        if self.stage == "2b":
            self._freeze()
            self._next_stage()
        total = 0
        while self.stage != "done" and (steps is None or total < steps):
            if self.progress and self.stage not in bars:
                from tqdm.auto import tqdm

                for bar in bars.values():
                    bar.close()
                cap = self.max_steps_2a if self.stage == "2a" else self.max_steps_2c
                bars[self.stage] = tqdm(total=cap, desc=f"BIPI step {self.stage}", leave=True)
            before = len(self.history)
            self.step()
            if len(self.history) > before:
                self.nsteps += 1
                total += 1
                self.log()
                self.call_observers()
                if self.stage in bars:
                    row = self.history[-1]
                    bars[self.stage].update(1)
                    bars[self.stage].set_postfix(tpd=f"{row['tpd_avg']:.3g}", gradC=f"{row['gradc_avg']:.3g}")
            if self._done:
                self._next_stage()
            yield self.stage == "done"
        self.wrap()
        for bar in bars.values():
            bar.close()

    def run(self, steps=None, fmax=None):
        """Run every stage to its stopping rule or cap; ``steps`` caps the total. Returns True when done.

        A run that finished its stages without converging (:meth:`verdict`) warns
        (:class:`~ase_sphrelax.checks.NotConvergedWarning`)."""
        for _ in self.irun(steps):
            pass
        if self.stage == "done":
            converged, reason = self.verdict()
            if not converged:
                warnings.warn(f"BIPIPacker: not converged: {reason}", NotConvergedWarning, stacklevel=2)
        return self.stage == "done"

    # -- results -----------------------------------------------------------------------
    def summary(self):
        """Iterations per stage, final averages, frozen particles, wall time."""
        out = dict(iterations_2a=self.stage_iterations["2a"], iterations_2c=self.stage_iterations["2c"],
                   h=self.model.h, dx=self.model.dx, h_over_dx_paper=self.model.h_over_dx_paper,
                   n_frozen=int(len(self.frozen)), gamma_wall=self.gamma_wall, moved_in=int(len(self.moved_in)),
                   rejected_moves=int(sum(r["rejected"] for r in self.history)),
                   wall_time=float(sum(r["time"] for r in self.history)), stage=self.stage)
        for s in ("2a", "2c"):
            rows = [r for r in self.history if r["stage"] == s]
            if rows:
                out[f"tpd_avg_{s}"] = rows[-1]["tpd_avg"]
                out[f"gradc_avg_{s}_first"] = rows[0]["gradc_avg"]
                out[f"gradc_avg_{s}_last"] = rows[-1]["gradc_avg"]
        return out

    def verdict(self):
        """``(converged, reason)``: did every stage that ran stop by its own 1 % rule, and improve?

        Not converged: a stage reached its iteration cap first; Step 2c had no particle to move
        (every one frozen in Step 2b or fixed: degenerate, ``self.degenerate``); or ``|grad C|_avg``
        of Step 2c ended above where it started (the packing is worse than the fill). A run stopped
        before its last stage (``run(steps=...)``) is not converged either.
        """
        if self.degenerate:
            return False, (f"degenerate: all {len(self.atoms)} particles are frozen in Step 2b or fixed, so Step 2c "
                           "had nothing to move (choose a smaller dx)")
        if self.stage != "done":
            return False, f"stopped in Step {self.stage} before the stages finished"
        caps = {"2a": self.max_steps_2a, "2c": self.max_steps_2c}
        capped = [s for s, how in self.stopped_by.items() if how == "cap"]
        if capped:
            return False, "; ".join(f"Step {s} reached its cap of {caps.get(s)} iterations before its "
                                    f"{100 * self.tol:g} % rule" for s in capped)
        rows = [r["gradc_avg"] for r in self.history if r["stage"] == "2c"]
        if rows and self._final is not None and self._final["gradc_avg"] > rows[0]:
            return False, (f"|grad C|_avg of Step 2c rose from {rows[0]:.4g} to {self._final['gradc_avg']:.4g}: "
                           "the packing ended worse than it started")
        ran = ", ".join(f"{s} by its {100 * self.tol:g} % rule" for s in self.stopped_by) or "no stage ran"
        return True, f"Step {ran}"

    def final_gradc_avg(self):
        """``|grad C|_avg`` over the movable (unfrozen) particles at the current positions."""
        movable = self._movable_all if self._movable_all is not None else ~self._user_fixed(len(self.atoms))
        return self._evaluate(self.atoms, movable)[1]

    def save(self, path):
        """Write the history and the summary as JSON."""
        with open(path, "w") as fh:
            json.dump(dict(parameters=self.todict(), summary=self.summary(), history=self.history), fh, indent=1)


def pack(boundary, dx, h=None, h_over_dx_paper=None, kernel="wendland_c2", J=None, band_rule="ball", skin=None,
         pbc=None, cell=None, **packer_kwargs):
    """Step 1 and Step 2 in one call: :func:`initial_fill`, a BIPICalculator and :class:`BIPIPacker`.

    Parameters
    ----------
    boundary : BoundarySegments, BoundaryTriangles, domain or file
    dx : float
    h, h_over_dx_paper : float
        The support ``h`` (our convention), or the paper's ``h_B / dx_r`` (``h = 2 h_B``); default
        BIPI2D's ``h_B / dx_r = 2`` (``h = 4 dx``).
    pbc, cell : optional
        Periodic directions and periods of the boundary (``boundary.with_cell(pbc, cell)``;
        default: the boundary's own).
    **packer_kwargs
        Passed to :class:`BIPIPacker` (caps, ``window``, ``stages``, ``progress``, ...).

    Returns
    -------
    (ase.Atoms, BIPIPacker, ase.Atoms)
        The packed particles, the packer (history, summary) and a copy of the start (Step 1).
    """
    from ..boundary import as_boundary
    from ..calculators.bipi import BIPICalculator
    from ..models.bipi import J_DEFAULT, support_from_paper

    if h is not None and h_over_dx_paper is not None:
        raise ValueError("give h (support) or h_over_dx_paper (h_B / dx_r), not both")
    boundary = as_boundary(boundary)
    if pbc is not None:
        boundary = boundary.with_cell(pbc, cell)
    if h is None:
        h = support_from_paper(2.0 if h_over_dx_paper is None else h_over_dx_paper, dx)
    calc = BIPICalculator(h=h, dx=dx, boundary=boundary, kernel=kernel, J=J_DEFAULT if J is None else J,
                          band_rule=band_rule, skin=skin)
    atoms = initial_fill(boundary, dx)
    start = atoms.copy()
    packer = BIPIPacker(atoms, calc, **packer_kwargs)
    packer.run()
    return atoms, packer, start


def _count(name, value, minimum=0):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)
