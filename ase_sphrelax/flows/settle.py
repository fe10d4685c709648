"""``settle``: run a particle start at rest downstream and say how calm it stays (issue 29 item 3).

A start (from ``sphrelax relax``, ``pack``, ``density`` or a user's own) is run at rest: under gravity
in a tank, or periodic without gravity, in one of two solvers:

* ``solver="bisph"``: :class:`~ase_sphrelax.flows.bisph.BISPH` (BIPI Eqs. 16-21, boundary-integral walls,
  the paper's own wall model), through :func:`~ase_sphrelax.flows.scene.tank`: hydrostatic density at
  ``t = 0``, ``c0 = 10 sqrt(2 g H)``, ``mu = 10`` Pa s, Wendland C2 of support ``h = 4 dx`` (the paper's
  ``h_B = 2 dx``). Wall particles in the file are ignored.
* ``solver="lammps"``: :func:`lammps_io.hydrostatic_tank` (wall *particles*: the file's ``type`` 2, on
  the Step-1 grid or packed, ``sphrelax pack --walls [--wall-mode packed]``), Tait water, Monaghan
  viscosity ``alpha`` (0.5), continuity densities, hydrostatic densities at ``t = 0``,
  ``c0 = 10 sqrt(g H)`` (its default).

The tank is the ``boundary`` (an edge file or :class:`~ase_sphrelax.boundary.BoundarySegments`), the
water region the start was packed in: its top edges (horizontal at its highest ``y``, within ``h`` of
the water's surface) are the free surface, so for BISPH they are lifted by the water depth, the side
walls continued along their own direction (the walls above the water are never reached, as in
``reproductions/bipi-wedge-bisph``). A taller tank is used as given. The free surface is at
``min(top, y_max + dx/2)`` (``y_max`` the highest fluid particle).

Periodic input (``atoms.pbc`` along x or y, the cell's lengths as periods, as ``sphrelax pack
--periodic`` writes): no gravity, BISPH only, ``c0`` must be given (there is no velocity scale), and the
background pressure ``P_B`` (Eq. 18) defaults to ``rho0 (c0/10)^2``: without gravity the uniform start
density gives a uniform pressure, and only ``P_B`` makes the pair sums of a disordered start non-zero.

The record (a dict; ``summary.json`` of ``sphrelax settle``):

* ``ke_history``: ``[[t, KE], ...]`` (J per metre of depth: particle mass ``rho0 dx^2``);
* ``ke_mean``: KE averaged over the run (trapezoid rule), ``ke_final``, ``ke_max``;
* ``pressure_error``: at the end, the RMS over the fluid particles of ``p - rho0 g (surface - y)``
  over ``rho0 g H`` (tank); periodic: RMS of ``p - mean(p)`` over ``rho0 (c0/10)^2``;
* ``max_drop``: the largest downward displacement of a fluid particle, in dx (periodic: the largest
  displacement, minimum image); ``max_displacement``: the largest displacement in any direction (dx);
* ``n_fluid``, and the run's parameters (``solver``, ``dx``, ``h``, ``c0``, ``depth``, ``surface``, ...);
* with ``compare="cartesian"``, ``compare``: the same run from the Cartesian start of the same water
  region (BIPI's Step 1: :func:`~ase_sphrelax.drivers.bipi_packer.initial_fill` at the same dx, below the
  same surface; for LAMMPS with the input's wall particles), its ``ke_mean``, ``ke_final``,
  ``ke_history``, ``pressure_error``, ``max_drop``, ``n_fluid``, ``stable``, and ``ke_ratio`` = ``ke_mean`` of
  the input over the Cartesian start's, ``calmer`` and ``verdict`` (a sentence; an unstable run is the noisier
  whatever its ratio);
* ``stable`` (False when a BISPH run diverged or passed Mach 1, when LAMMPS found it unstable, or when the
  KE passed :data:`KE_LIMIT` ``M g H``) and ``stability_reason``.

Bad input is refused before any run with a one-line ValueError naming the parameter: no fluid particle,
no wall particles for ``lammps``, particles not in the boundary's plane or outside it, ``dx`` not the
particles' spacing (``h`` and ``dx`` swapped), ``h`` outside 1.5-6 dx, a water depth that is not
1 mm - 20 m with ``g`` in m/s^2 or a ``c0`` outside 3-1000 ``sqrt(g H)`` (a tank in mm gives an
absurd ``c0``); an ImportError (one line) when LAMMPS is missing.
"""
from __future__ import annotations


import numpy as np

from ..drivers.bipi_packer import FLUID, WALL, particle_kinds
from .scales import TANK_KE_LIMIT, check_spacing, check_unit_scale

__all__ = ["settle", "check_settle", "tank_walls", "SOLVERS", "COMPARE"]

SOLVERS = ("bisph", "lammps")
#: entry-point group of the solvers other packages plug in (lammps_io's ``lammps``)
SOLVER_GROUP = "ase_sphrelax.settle_solvers"
COMPARE = (None, "cartesian")
#: the default ``h / dx`` (support; the paper's ``h_B = 2 dx``); the accepted range is ``scales.H_OVER_DX_RANGE``
H_OVER_DX = 4.0
#: a tank run is unstable when its KE exceeds this fraction of ``M g H`` (the same limit as lammps_io's tanks)
KE_LIMIT = TANK_KE_LIMIT
#: a fraction of fluid particles outside the boundary above this is refused (another unit or file)
OUTSIDE_LIMIT = 0.01


def tank_walls(boundary, surface, lift, tol=1e-9):
    """The tank's walls for BISPH: ``boundary`` with its top edges (at its highest ``y``) lifted by ``lift``.

    Each vertex at the top is moved up by ``lift`` along the side wall that reaches it (vertical for a
    vertex between two top edges) and the vertex kept, so the walls below the surface are unchanged and
    the lid ends ``lift`` above it. Loops are kept oriented (the fluid on their left). A boundary whose
    top lies more than ``tol`` above ``surface`` is returned as given.
    """
    from ..boundary import BoundarySegments

    top = float(boundary.bounds[1][1])
    scale = tol * max(1.0, abs(top))
    if top > surface + scale or lift <= 0:
        return boundary
    loops = []
    for v in boundary.loops:
        at_top = np.abs(v[:, 1] - top) <= scale
        out = []
        for i, p in enumerate(v):
            if not at_top[i]:
                out.append(p)
                continue
            prev, nxt = v[i - 1], v[(i + 1) % len(v)]
            before, after = at_top[i - 1], at_top[(i + 1) % len(v)]
            if before and after:  # inside the lid: straight up
                out.append(p + (0.0, lift))
            elif not before and after:  # a side wall arrives here: continue it upwards, then the lid
                d = (p - prev) / (p[1] - prev[1])
                out += [p, p + lift * d]
            elif before and not after:  # the lid ends here: come down along the next side wall
                d = (p - nxt) / (p[1] - nxt[1])
                out += [p + lift * d, p]
            else:  # a lone peak at the top (no lid edge): kept
                out.append(p)
        loops.append(np.array(out))
    return BoundarySegments(loops, name=f"{boundary.name or 'boundary'} (lid lifted by {lift:g})")


def _check(atoms, boundary, dx, h, solver, g, c0, compare):
    """Every check before a run; returns ``(kinds, fluid positions (N, 2), pbc (2,))``."""
    from ..checks import check_positive

    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    if compare not in COMPARE:
        raise ValueError(f"compare must be None or 'cartesian', got {compare!r}")
    check_positive("dx", dx)
    check_positive("h", h)
    check_positive("g", g)
    check_positive("c0", c0, allow_none=True)
    if boundary.dim != 2:
        raise ValueError(f"boundary: settle runs 2D tanks (an edge file), got a {boundary.dim}D boundary")
    if len(atoms) == 0:
        raise ValueError("atoms: no fluid particles (the file is empty)")
    kinds = particle_kinds(atoms)
    fluid = kinds == FLUID
    if not fluid.any():
        raise ValueError("atoms: no fluid particles (every 'type' is 2, wall); settle needs type 1 (fluid)")
    r = atoms.positions
    if not np.all(np.isfinite(r)):
        raise ValueError("atoms: positions must be finite")
    extent = float(np.ptp(r[fluid, :2], axis=0).max()) if fluid.sum() > 1 else 1.0
    if np.ptp(r[:, 2]) > 1e-9 * max(extent, 1.0) or bool(atoms.pbc[2]):
        raise ValueError(f"atoms: 3D particles (z spread {np.ptp(r[:, 2]):.3g}, pbc {atoms.pbc.tolist()}) against "
                         "the 2D boundary: dimension mismatch (settle runs 2D tanks; give particles with z = 0)")
    x = r[fluid, :2]
    pbc = np.asarray(atoms.pbc[:2], dtype=bool)
    check_spacing(x[:0] if pbc.any() else x, h, dx)  # periodic: h against dx only (no images in the spacing)
    if pbc.any():
        if solver != "bisph":
            raise ValueError("solver: periodic particles (atoms.pbc) run without gravity in 'bisph' only "
                             "(lammps_io.hydrostatic_tank is a tank under gravity)")
        if c0 is None:
            raise ValueError("c0: a periodic start without gravity has no velocity scale; give c0 (m/s)")
        if compare is not None:
            raise ValueError("compare: 'cartesian' needs a tank (the periodic case has no Step-1 fill here)")
    inside = np.asarray(boundary.contains(np.column_stack([x, np.zeros(len(x))])), dtype=bool)
    if (~inside).mean() > OUTSIDE_LIMIT:
        raise ValueError(f"boundary: {int((~inside).sum())} of {len(x)} fluid particles lie outside it (particles "
                         f"span {x.min(axis=0).round(6).tolist()}-{x.max(axis=0).round(6).tolist()}, the boundary "
                         f"{np.asarray(boundary.bounds[0]).round(6).tolist()}-"
                         f"{np.asarray(boundary.bounds[1]).round(6).tolist()}): another file or unit?")
    if solver == "lammps" and not (kinds == WALL).any():
        raise ValueError("atoms: no wall particles ('type' 2) for solver 'lammps' (its walls are particles): "
                         "pack with `sphrelax pack --walls` (grid) or `--walls --wall-mode packed`")
    return kinds, x, pbc


def _mean(ke_history):
    t, ke = np.asarray(ke_history, dtype=float).T
    return float(np.trapezoid(ke, t) / (t[-1] - t[0])) if len(t) > 1 and t[-1] > t[0] else float(ke.mean())


def displacements(start, end, dx, pbc, cell):
    d = end[:, :2] - start[:, :2]
    for i in np.nonzero(pbc)[0]:
        length = cell[i, i]
        d[:, i] -= length * np.round(d[:, i] / length)
    moved = float(np.sqrt(np.einsum("pc,pc->p", d, d)).max()) / dx
    drop = moved if pbc.any() else float(max(0.0, (-d[:, 1]).max())) / dx
    return drop, moved


def _run_bisph(x, boundary, dx, h, t_end, rho0, g, c0, mu, p_b, surface, depth, pbc, cell, samples, progress):
    from .bisph import BISPH
    from .scene import tank

    if pbc.any():
        walls = boundary.with_cell([bool(pbc[0]), bool(pbc[1])], [cell[0, 0], cell[1, 1]], quiet=True)
        sim = BISPH(walls, x, dx, rho0=rho0, c0=c0, mu=mu, body_force=(0.0, 0.0), h_over_dx=h / dx,
                    hydrostatic=False, p_background=p_b, density=np.full(len(x), rho0))
    else:
        walls = tank_walls(boundary, surface, lift=depth)
        sim = tank(walls, x, dx, surface, g=g, c0=c0, mu=mu, rho0=rho0, h_over_dx=h / dx)
    start = sim.r.copy()
    ke_history, error, diverged = _integrate(sim, t_end, samples, progress)
    if pbc.any():
        p = sim.pressure()
        error = float(np.sqrt(np.mean((p - p.mean()) ** 2)) / (rho0 * (sim.c0 / 10.0) ** 2)) if np.all(np.isfinite(p)) \
            else float("nan")
    else:
        error = error / (rho0 * g * depth)
    drop, moved = displacements(start, sim.r, dx, pbc, cell)
    error = float(error) if np.isfinite(error) else None  # None: the run ended early (JSON has no NaN)
    return dict(ke_history=ke_history, pressure_error=error, max_drop=drop, max_displacement=moved,
                n_fluid=len(x), steps=int(sim.steps), c0=float(sim.c0), wall_model="boundary integrals (BISPH)",
                stable=diverged is None, stability_reason=diverged or "finite to the end")


def _integrate(sim, t_end, samples, progress):
    """``sim.step`` to ``t_end`` with the KE every ``t_end / samples`` (a tqdm bar over simulated time).

    A run whose velocities or densities stop being finite, or in which a particle moves faster than ``c0``
    (Mach 1), ends there:
    returns ``(ke_history, pressure error (Pa) at the end, reason or None)``; the last state is the last
    finite one's successor (the displacements then say how far it went)."""
    from tqdm.auto import tqdm

    every = t_end / samples
    history = [[float(sim.t), sim.kinetic_energy()]]
    next_record, reason = sim.t + every, None
    with np.errstate(all="ignore"), tqdm(total=t_end, disable=not progress, unit="s", desc="settle (BISPH)") as bar:
        while sim.t < t_end * (1 - 1e-12):
            dt = sim.step(min(sim.time_step(), t_end - sim.t))
            bar.update(dt)
            v2 = np.einsum("pc,pc->p", sim.v, sim.v)
            if not (np.all(np.isfinite(v2)) and np.all(np.isfinite(sim.rho)) and np.all(sim.rho > 0)):
                reason = f"diverged at t = {sim.t:.4g} s after {sim.steps} steps (non-finite velocity or density)"
                break
            if v2.max() > sim.c0**2:
                reason = (f"stopped at t = {sim.t:.4g} s after {sim.steps} steps: a particle moved faster than c0 "
                          f"= {sim.c0:.4g} m/s (Mach 1: the weakly compressible model no longer holds)")
            if reason is not None or sim.t >= next_record - 1e-12 * t_end or sim.t >= t_end * (1 - 1e-12):
                history.append([float(sim.t), sim.kinetic_energy()])
                next_record += every
            if reason is not None:
                break
    error = sim.pressure_error() if reason is None else float("nan")
    return history, error, reason


def _lammps_solver():
    """The ``lammps`` solver: the module of the ``ase_sphrelax.settle_solvers`` entry point ``lammps``.

    lammps_io depends on ase_sphrelax, never the reverse: it plugs its solver in (``run_tank``, ``check``),
    as it plugs in its commands and engine.
    """
    from importlib.metadata import entry_points

    found = [ep for ep in entry_points().select(group=SOLVER_GROUP) if ep.name == "lammps"]
    if not found:
        raise ImportError("solver='lammps' needs the lammps_io plug-in (installed with ase_sphrelax: pip install "
                          "-e .); no 'lammps' entry point in the group " + SOLVER_GROUP)
    return found[0].load()


def _summarise(run, scale):
    """KE mean, final and largest; ``stable`` False also when the KE passed ``KE_LIMIT`` ``scale`` (``M g H``)."""
    ke = [k for _, k in run["ke_history"]]
    run.update(ke_mean=_mean(run["ke_history"]), ke_final=float(ke[-1]), ke_max=float(max(ke)))
    if scale and run["stable"] and not run["ke_max"] <= KE_LIMIT * scale:
        run.update(stable=False, stability_reason=f"the kinetic energy grew past {KE_LIMIT:g} M g H")
    return run


def _setup(atoms, boundary, dx, solver, t_end, h, compare, g, c0, samples, p_background=None):
    """The checks of :func:`settle` and what its runs need (nothing is run)."""
    from ..boundary import as_boundary
    from ..checks import check_positive

    boundary = as_boundary(boundary)
    dx = check_positive("dx", dx)
    h = H_OVER_DX * dx if h is None else h
    t_end = check_positive("t_end", t_end)
    if not (isinstance(samples, (int, np.integer)) and samples >= 1):
        raise ValueError(f"samples must be an integer >= 1, got {samples!r}")
    kinds, x, pbc = _check(atoms, boundary, dx, h, solver, g, c0, compare)
    if not pbc.any() and p_background not in (None, 0, 0.0):
        raise ValueError(f"p_background = {p_background!r}: only for periodic input (the tank starts hydrostatic "
                         "with P_B = 0, as reproductions/bipi-wedge-bisph)")
    cell = np.asarray(atoms.cell.array, dtype=float)
    top = float(boundary.bounds[1][1])
    surface = min(top, float(x[:, 1].max()) + 0.5 * dx)
    depth = surface - float(boundary.bounds[0][1])
    if not pbc.any():
        check_positive("depth of the water (surface above the tank's floor)", depth)
        check_unit_scale(depth, g, c0)
    if solver == "lammps":
        _lammps_solver().check()  # an ImportError (one line) before any work
    return boundary, dx, h, t_end, kinds, x, pbc, cell, surface, depth


def check_settle(atoms, boundary, dx, solver="bisph", t_end=1.0, h=None, compare=None, g=9.81, c0=None, samples=200,
                 p_background=None, **_):
    """Every check of :func:`settle` (same arguments), without running: raises what it would raise."""
    _setup(atoms, boundary, dx, solver, t_end, h, compare, g, c0, samples, p_background)


def settle(atoms, boundary, dx, solver="bisph", t_end=1.0, h=None, compare=None, rho0=1000.0, g=9.81, c0=None,
           mu=10.0, alpha=0.5, p_background=None, samples=200, progress=True):
    """Run ``atoms`` at rest in the tank ``boundary`` and return the record (module docstring).

    Parameters
    ----------
    atoms : ase.Atoms
        2D particles (z = 0): fluid, and for ``solver="lammps"`` wall particles (``arrays["type"]``
        1 fluid, 2 wall; without it every particle is fluid). Periodic along x or y when ``atoms.pbc``
        says so (no gravity; the cell's diagonal gives the periods).
    boundary : str, Path or BoundarySegments
        The water region (an edge file), e.g. the ``--boundary`` of ``sphrelax pack``.
    dx : float
        The particles' spacing (masses ``rho0 dx^2``).
    solver : {"bisph", "lammps"}
    t_end : float
        Physical time (s).
    h : float or None
        Kernel support radius (length); default ``4 dx`` (the paper's ``h_B = 2 dx``).
    compare : None or "cartesian"
        Also run the Cartesian start of the same water region and compare (``record["compare"]``).
    rho0, g, c0, mu, alpha : float
        Density, gravity, sound speed (default per solver, module docstring), BISPH's viscosity (Pa s),
        LAMMPS' artificial viscosity.
    p_background : float or None
        BISPH's ``P_B`` (Eq. 18, Pa), periodic input only: default ``rho0 (c0/10)^2`` (without gravity a
        uniform density has uniform pressure, so only ``P_B`` lets a disordered start move); a tank has 0.
    samples : int
        KE samples over the run.
    progress : bool
        tqdm bars over the runs.

    Returns
    -------
    dict
        ``ke_history``, ``ke_mean``, ``ke_final``, ``ke_max``, ``pressure_error``, ``max_drop``,
        ``max_displacement``, ``n_fluid``, the parameters, and ``compare`` with ``compare="cartesian"``.

    Raises
    ------
    ValueError
        Before any run, one line naming the parameter (module docstring).
    ImportError
        ``solver="lammps"`` without a usable LAMMPS.
    """
    boundary, dx, h, t_end, kinds, x, pbc, cell, surface, depth = _setup(atoms, boundary, dx, solver, t_end, h,
                                                                          compare, g, c0, samples, p_background)
    record = dict(solver=solver, dx=float(dx), h=float(h), h_over_dx=float(h / dx), t_end=float(t_end),
                  rho0=float(rho0), g=0.0 if pbc.any() else float(g), periodic=pbc.tolist(),
                  surface=None if pbc.any() else surface, depth=None if pbc.any() else depth)

    def run(positions, kinds_run, atoms_run):
        if solver == "bisph":
            return _run_bisph(positions, boundary, dx, h, t_end, rho0, g, c0, mu, p_background, surface, depth, pbc,
                              cell, samples, progress)
        return _lammps_solver().run_tank(atoms_run, kinds_run, dx, h, t_end, rho0, g, c0, alpha, surface, depth,
                                         samples, progress)

    if solver == "bisph":
        if pbc.any():
            p_background = rho0 * (c0 / 10.0) ** 2 if p_background is None else float(p_background)
        record.update(mu=float(mu), p_background=float(p_background or 0.0))
    def scale(n):  # M g H of n fluid particles (0: periodic, no limit)
        return 0.0 if pbc.any() else rho0 * dx * dx * n * g * depth

    record.update(_summarise(run(x, kinds, atoms), scale(len(x))))
    if compare == "cartesian":
        record["compare"] = _compare(atoms, kinds, boundary, dx, surface, record, run, scale)
    return record


def _cartesian(atoms, kinds, boundary, dx, surface):
    """The Cartesian start of the same water region (BIPI's Step 1 below ``surface``), with the input's walls."""
    from ase import Atoms

    from ..drivers.bipi_packer import initial_fill

    fill = initial_fill(boundary, dx).positions
    fill = fill[fill[:, 1] < surface]
    walls = atoms.positions[kinds == WALL]
    r = np.concatenate([fill, walls])
    out = Atoms(positions=r, cell=atoms.cell, pbc=atoms.pbc)
    out.arrays["type"] = np.concatenate([np.full(len(fill), FLUID), np.full(len(walls), WALL)]).astype(int)
    return out


def _compare(atoms, kinds, boundary, dx, surface, record, run, scale):
    cart = _cartesian(atoms, kinds, boundary, dx, surface)
    kinds_c = cart.arrays["type"]
    fluid = kinds_c == FLUID
    other = _summarise(run(cart.positions[fluid, :2], kinds_c, cart), scale(int(fluid.sum())))
    ratio = record["ke_mean"] / other["ke_mean"] if other["ke_mean"] > 0 else float("inf")
    mine, theirs = record["stable"], other["stable"]
    if mine != theirs:  # a run that blew up is the noisier, whatever its KE before it stopped
        calmer = "input" if mine else "cartesian"
        verdict = (f"the {'input' if mine else 'Cartesian start'} is calmer: the "
                   f"{'Cartesian start' if mine else 'input'} was unstable "
                   f"({(other if mine else record)['stability_reason']}; KE ratio {ratio:.3g})")
    elif ratio < 1:
        calmer = "input"
        verdict = f"the input is calmer: its run-averaged KE is {1 / ratio:.3g}x below the Cartesian start's"
    elif ratio > 1:
        calmer = "cartesian"
        verdict = f"the Cartesian start is calmer: its run-averaged KE is {ratio:.3g}x below the input's"
    else:
        calmer, verdict = "equal", "the two starts have the same run-averaged KE"
    if not (mine or theirs):
        verdict += " (both runs were unstable)"
    keep = ("ke_history", "ke_mean", "ke_final", "ke_max", "pressure_error", "max_drop", "max_displacement",
            "n_fluid", "steps", "stable", "stability_reason")
    return dict({k: other[k] for k in keep if k in other}, start="cartesian", ke_ratio=float(ratio), calmer=calmer,
                verdict=verdict)
