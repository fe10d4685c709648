"""Weakly compressible SPH runs in LAMMPS from our particle sets: a hydrostatic tank and the
elliptic drop (BIPI section 4.2, Figs. 13-22: the downstream evidence for a packing).

Model (LAMMPS SPH package): Tait water ``p = B ((rho/rho0)^7 - 1)``, ``B = c0^2 rho0 / 7``,
with Monaghan's artificial viscosity ``alpha`` (``pair_style sph/taitwater``); densities by
kernel summation every step (``sph/rhosum``, the default ``density="summation"``) or by the
continuity equation that ``fix sph`` integrates (``density="continuity"``); ``fix sph`` moves
the fluid, ``fix sph/stationary`` keeps wall particles in place while their densities follow;
``fix gravity`` on the fluid. LAMMPS' SPH kernel is Lucy's with support ``h``: the same
support-radius convention as ours. Units are whatever the particle set carries (SI for the
paper's cases: m, kg, s).

Particle kinds: ``atoms.arrays["type"]`` holds :data:`FLUID` (1) or :data:`WALL` (2); without it
every particle is fluid. Masses are ``rho0 dx^dim`` per particle (one mass per LAMMPS type).

Checks before LAMMPS starts (a one-line ValueError naming the parameter, issue 31; the bounds are those
of :mod:`ase_sphrelax.flows.scales`): ``dx`` must be the fluid's spacing (the median nearest-neighbour
distance, within a factor ``SPACING_FACTOR``) and ``h`` between ``H_OVER_DX_RANGE`` times it (so swapping
h and dx is caught); the tank needs wall particles and lengths, ``g`` and ``c0`` in one unit system
(:func:`hydrostatic_tank`); the drop must start as a disc (:func:`elliptic_drop`).

Verdict after the run: ``stable`` is False, with a :class:`FlowUnstableWarning`, when the kinetic
energy grew past the stated limit (the tank: ``TANK_KE_LIMIT`` of :mod:`ase_sphrelax.flows.scales` times
``M g H``, its potential
energy scale; the drop: :data:`DROP_KE_GROWTH` times its initial kinetic energy, which the drop
only loses) or when fluid particles were thrown out (the tank: beyond the start's bounding box
grown by ``h``; the drop: outside the analytic ellipse grown by ``2 h``) or became NaN.
``ke_history`` starts with the true kinetic energy at t = 0.
"""
from __future__ import annotations

import ctypes
import math
import os
import tempfile
from pathlib import Path

import numpy as np
from ase_sphrelax.checks import SphrelaxWarning, check_positive
from ase_sphrelax.drivers.bipi_packer import FLUID, WALL, particle_kinds
from ase_sphrelax.flows.scales import TANK_KE_LIMIT, check_spacing, check_unit_scale

from ._library import import_lammps, new_lammps
from .box import infer_dim
from .data_file import write_data

__all__ = ["FLUID", "WALL", "hydrostatic_tank", "elliptic_drop", "elliptic_drop_axes", "tait_pressure",
           "FlowUnstableWarning", "TANK_KE_LIMIT", "DROP_KE_GROWTH"]

DENSITY_MODES = ("summation", "continuity")
#: the drop is unstable when its kinetic energy exceeds this multiple of its initial one (it only loses energy)
DROP_KE_GROWTH = 1.5


class FlowUnstableWarning(SphrelaxWarning):
    """A LAMMPS flow run blew up: its kinetic energy grew past the stated limit, or particles were thrown out."""


def _check_spacing(atoms, kinds, h, dx, who):
    """dx against the fluid's spacing and h against dx, before LAMMPS starts (one-line ValueErrors)."""
    check_positive("h", h)
    check_positive("dx", dx)
    check_spacing(atoms.positions[kinds == FLUID, :infer_dim(atoms)], h, dx, who)


def _verdict(result, ke_over, limit_text, n_out, where, who, failure=None):
    """``stable`` and its reason into ``result``; a FlowUnstableWarning when it is False."""
    import warnings

    reasons = [] if failure is None else [f"LAMMPS stopped at t = {result['t_reached']:.4g}: {failure}"]
    if not np.isfinite(ke_over) or ke_over > 1.0:
        reasons.append(f"the kinetic energy grew past {limit_text}")
    if n_out:
        reasons.append(f"{n_out} fluid particle(s) thrown out ({where}) or lost")
    result.update(stable=not reasons, stability_reason="; ".join(reasons) if reasons else
                  f"kinetic energy within {limit_text}, no particle thrown out")
    if reasons:
        warnings.warn(f"{who}: unstable run: {result['stability_reason']}", FlowUnstableWarning, stacklevel=3)
    return result


def tait_pressure(rho, rho0, c0):
    """Tait's equation of state of ``sph/taitwater``: ``p = c0^2 rho0 / 7 ((rho / rho0)^7 - 1)``."""
    return c0 * c0 * rho0 / 7.0 * ((np.asarray(rho, dtype=float) / rho0) ** 7 - 1.0)


def _run(atoms, h, dx, *, rho0, c0, alpha, gravity, t_end, dt, samples, density, nthreads, workdir, progress,
         desc, observe, velocities=None, rho_p=None):
    """The shared LAMMPS run: write the data file, set up the SPH styles, run in chunks, observe.

    ``observe(lmp, n, time)`` is called at t = 0 and after every chunk and returns a dict that is
    appended to the history. Returns ``(history, (x_pc, rho_p), n_fluid, n_wall, steps, dt, failure)``, with the
    final positions and densities gathered once, after the last chunk; ``failure`` is None, or the first line of
    the LAMMPS error that stopped a blown-up run (e.g. "Too many neighbor bins" when particles fly off), after
    which the history ends and the positions are those LAMMPS still holds (NaN if it cannot give them).
    """
    if len(atoms) == 0:
        raise ValueError("atoms: need at least one particle, got an empty Atoms")
    if not np.all(np.isfinite(atoms.positions)):
        raise ValueError("atoms.positions must be finite")
    for name, value in dict(h=h, dx=dx, rho0=rho0, c0=c0, t_end=t_end).items():
        check_positive(name, value)
    if not (np.isscalar(alpha) and alpha >= 0):
        raise ValueError(f"alpha must be a non-negative number, got {alpha!r}")
    if density not in DENSITY_MODES:
        raise ValueError(f"density must be one of {DENSITY_MODES}, got {density!r}")
    if not (isinstance(samples, (int, np.integer)) and samples >= 1):
        raise ValueError(f"samples must be an integer >= 1, got {samples!r}")
    kinds = particle_kinds(atoms)
    if not (kinds == FLUID).any():
        raise ValueError("atoms: no fluid particle (every atoms.arrays['type'] is WALL)")
    dim = infer_dim(atoms)
    if dim not in (2, 3):
        raise ValueError(f"SPH flows need 2D or 3D particles, got dim={dim}")
    import_lammps()
    dt = 0.1 * h / c0 if dt is None else float(dt)
    if gravity:
        dt = min(dt, 0.25 * math.sqrt(h / abs(gravity)))  # the body-force condition (Monaghan 1992)
    check_positive("dt", dt)
    steps = max(1, int(math.ceil(t_end / dt - 1e-9)))
    chunk = max(1, steps // samples)
    mass = rho0 * dx**dim
    run_atoms = atoms.copy()
    run_atoms.arrays["type"] = kinds
    ntypes = int(kinds.max())
    tmp = tempfile.TemporaryDirectory(prefix="lammps_io_flow_") if workdir is None else None
    folder = Path(tmp.name if tmp else workdir)
    folder.mkdir(parents=True, exist_ok=True)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=steps, desc=desc, unit="step", leave=False, disable=None, mininterval=0.5)
    cwd = os.getcwd()
    try:
        box = write_data(run_atoms, folder / "flow.data", atom_style="sph", dim=dim, masses=[mass] * ntypes,
                         rho=rho0 if rho_p is None else rho_p, esph=0.0, cv=1.0, margin=4.0 * h)
        lmp = new_lammps(nthreads=nthreads)
        os.chdir(folder)
        periodic = ["p" if p else "s" for p in atoms.pbc[:dim]] + (["p"] if dim == 2 else [])
        commands = [
            *box.read_data_commands("flow.data", "sph", " ".join(periodic), units="si"),
            "pair_style hybrid/overlay sph/rhosum 1 sph/taitwater" if density == "summation"
            else "pair_style sph/taitwater",
        ]
        if density == "summation":
            commands.append(f"pair_coeff * * sph/rhosum {h:.17g}")
            commands.append(f"pair_coeff * * sph/taitwater {rho0:.17g} {c0:.17g} {alpha:.17g} {h:.17g}")
        else:
            commands.append(f"pair_coeff * * {rho0:.17g} {c0:.17g} {alpha:.17g} {h:.17g}")
        commands += [
            f"group fluid type {FLUID}",
            f"group wall type {WALL}",
            f"neighbor {0.2 * h:.17g} bin",
            "neigh_modify every 1 delay 0 check yes",
            "compute flowke fluid ke",
            "thermo_style custom step c_flowke",
            "thermo_modify norm no lost error",
            "fix flowsph fluid sph",
        ]
        if (kinds == WALL).any():
            commands.append("fix flowwall wall sph/stationary")
        if gravity:
            down = "0 -1 0" if dim == 2 else "0 0 -1"
            commands.append(f"fix flowgrav fluid gravity {abs(gravity):.17g} vector {down}")
        if box.lammps_dimension == 2:
            commands.append("fix flow2d all enforce2d")
        commands += [f"timestep {dt:.17g}", f"thermo {chunk}"]
        lmp.commands_list(commands)
        n = lmp.get_natoms()
        if velocities is not None:
            v = np.zeros((n, 3))
            v[:, :] = velocities
            lmp.scatter_atoms("v", 1, 3, (3 * n * ctypes.c_double)(*v.ravel()))
        lmp.command("run 0")  # computes the thermo output of step 0: KE(0) is the true initial kinetic energy
        history = [observe(lmp, n, 0.0)]
        done = 0
        failure = None
        while done < steps:
            k = min(chunk, steps - done)
            try:
                lmp.command(f"run {k} pre no post no")
            except Exception as error:  # noqa: BLE001 - LAMMPS raises a bare Exception; a blow-up is a result
                failure = (str(error).strip().splitlines() or ["LAMMPS error"])[0]
                break
            done += k
            history.append(observe(lmp, n, done * dt))
            if bar is not None:
                bar.update(k)
        try:
            final = (_gather(lmp, "x", n, 3), _gather(lmp, "rho", n, 1))
        except Exception:  # noqa: BLE001 - after a LAMMPS error
            final = (np.full((n, 3), np.nan), np.full(n, np.nan))
        lmp.close()
    finally:
        os.chdir(cwd)
        if bar is not None:
            bar.close()
        if tmp is not None:
            tmp.cleanup()
    return history, final, int((kinds == FLUID).sum()), int((kinds == WALL).sum()), steps, dt, failure


def _gather(lmp, name, n, width):
    values = np.array(lmp.gather_atoms(name, 1, width)[: n * width], dtype=float)
    return values.reshape(n, width) if width > 1 else values


def hydrostatic_tank(atoms, h, dx, rho0=1000.0, g=9.81, c0=None, alpha=0.5, t_end=1.0, dt=None, samples=100,
                     density="continuity", hydrostatic_start=True, depth_bins=10, nthreads=1, workdir=None,
                     progress=True, check_units=True):
    """A tank of water at rest under gravity, run in LAMMPS; return its kinetic energy and pressures.

    Parameters
    ----------
    atoms : ase.Atoms
        2D (z = 0, gravity along -y) or 3D (gravity along -z) particles: fluid, and wall particles
        marked ``atoms.arrays["type"] == WALL`` (several layers, at least ``h`` thick, outside the
        walls). Positions in metres for the defaults.
    h : float
        Kernel support radius (LAMMPS' ``h``).
    dx : float
        Particle spacing: masses ``rho0 dx^dim``.
    rho0, g : float
        Reference density and gravity.
    c0 : float or None
        Sound speed; default ``10 sqrt(g H)`` with ``H`` the water depth (Mach 0.1).
    alpha : float
        Monaghan's artificial viscosity (see ``density`` for what 0.02 and 0.1 did).
    t_end, dt : float
        Physical time and time step (default ``min(0.1 h / c0, 0.25 sqrt(h / g))``).
    samples : int
        Number of kinetic-energy samples.
    density : {"continuity", "summation"}
        Continuity (default): ``fix sph`` integrates the densities. Summation densities are
        deficient at the free surface, whose particles then feel a negative pressure: measured on
        a 0.2 m x 0.1 m tank (dx = 0.01 m, h = 2.6 dx, alpha = 0.1, 0.5 s), the pressure profile
        was off by 27 % of rho0 g H with summation against 2 % with continuity, and surface
        particles sank 5.6 dx against 0.02 dx (0.5 s). With alpha = 0.02 the continuity run of that
        tank did not settle (kinetic energy 1e2 J after 0.5 s, particles through the floor); with
        alpha = 0.1 longer runs did not either (the 2.05 m wedge tank and a flat tank at dx = 0.02 m:
        kinetic energy 570-730 J/m within 1 s, reproductions/bipi-fig13-14/), while alpha = 0.5 settled.
    hydrostatic_start : bool
        Start from the hydrostatic densities ``rho0 (1 + rho0 g d / B)^(1/7)`` at depth ``d`` (walls
        included, at their own depth, zero above the surface), so that only the particle
        arrangement disturbs the equilibrium; else from ``rho0`` everywhere. (With summation
        densities only the walls' matter: the fluid's are recomputed every step.)
    depth_bins : int
        Bins of the final pressure profile against depth.
    nthreads : int
        OpenMP threads of LAMMPS.
    progress : bool
        A tqdm bar over the time steps.
    check_units : bool
        Refuse a depth outside ``DEPTH_RANGE_M`` metres (:mod:`ase_sphrelax.flows.scales`; the lengths
        converted with ``g``: a tank in mm with g in m/s^2 is 1000 times too deep) and a ``c0`` outside
        ``C0_RANGE`` times ``sqrt(g H)``.

    Raises
    ------
    ValueError
        Before LAMMPS starts: no wall particles, lengths/g/c0 of different unit systems (``check_units``),
        ``dx`` not the fluid's spacing or ``h`` outside ``H_OVER_DX_RANGE`` dx (module docstring).

    Returns
    -------
    dict
        ``ke_history`` (list of (time, KE), from the true KE at t = 0), ``ke_final``, ``ke_max``,
        ``pressure_profile`` (list of (depth, mean p of the fluid particles in the bin, hydrostatic
        rho0 g depth)), ``pressure_error`` (mean ``|p - rho0 g depth| / (rho0 g H)`` over the bins),
        ``max_drop`` (largest downward displacement of a fluid particle / dx), ``n_fluid``, ``n_wall``,
        ``steps``, ``dt``, ``c0``, ``depth``, ``h``, ``dx``; ``stable`` (False, with a
        :class:`FlowUnstableWarning`, when ``ke_max`` exceeded ``TANK_KE_LIMIT`` ``M g H`` or fluid
        particles left the start's bounding box grown by ``h``, or LAMMPS stopped), ``stability_reason``,
        ``ke_over_mgh``, ``n_thrown``, ``t_reached``, ``lammps_error``.
    """
    kinds = particle_kinds(atoms)
    dim = infer_dim(atoms)
    up = 1 if dim == 2 else 2
    fluid = kinds == FLUID
    if not fluid.any():
        raise ValueError("atoms: no fluid particle (every atoms.arrays['type'] is WALL)")
    if not (kinds == WALL).any():
        raise ValueError("hydrostatic_tank: atoms has no wall particles (atoms.arrays['type'] == 2): the water would "
                         "fall freely; add them, e.g. ase_sphrelax.drivers.bipi_packer.add_walls")
    check_positive("g", g)
    check_positive("depth_bins", depth_bins)
    _check_spacing(atoms, kinds, h, dx, "hydrostatic_tank")
    surface = float(atoms.positions[fluid, up].max()) + 0.5 * dx
    bottom = float(atoms.positions[fluid, up].min()) - 0.5 * dx
    depth = surface - bottom
    c0 = 10.0 * math.sqrt(g * depth) if c0 is None else check_positive("c0", c0)
    if check_units:
        check_unit_scale(depth, g, c0, "hydrostatic_tank", escape=", or g in mm/s^2; check_units=False for a tank "
                         "this deep")
    start_up = atoms.positions[:, up].copy()
    rho_start = None
    if hydrostatic_start:
        depth_p = np.clip(surface - start_up, 0.0, None)
        rho_start = rho0 * (1.0 + rho0 * g * depth_p / (c0 * c0 * rho0 / 7.0)) ** (1.0 / 7.0)

    def observe(lmp, n, time):
        return dict(time=time, ke=float(lmp.last_thermo()["c_flowke"]))

    history, (x_pc, rho_p), n_fluid, n_wall, steps, dt, failure = _run(
        atoms, h, dx, rho0=rho0, c0=c0, alpha=alpha, gravity=g, t_end=t_end, dt=dt, samples=samples, density=density,
        nthreads=nthreads, workdir=workdir, progress=progress, desc="hydrostatic tank", observe=observe,
        rho_p=rho_start)
    d_p = surface - x_pc[fluid, up]
    p_p = tait_pressure(rho_p[fluid], rho0, c0)
    edges = np.linspace(0.0, depth, int(depth_bins) + 1)
    profile = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        inside = (d_p >= lo) & (d_p < hi)
        if inside.any():
            mid = 0.5 * (lo + hi)
            profile.append((float(mid), float(p_p[inside].mean()), float(rho0 * g * mid)))
    scale = rho0 * g * depth
    ke = [(r["time"], r["ke"]) for r in history]
    ke_max = max(k for _, k in ke)
    energy_scale = rho0 * dx**dim * n_fluid * g * depth  # M g H
    lo_c = atoms.positions[:, :dim].min(axis=0) - h
    hi_c = atoms.positions[:, :dim].max(axis=0) + h
    x_f = x_pc[fluid, :dim]
    thrown = ~np.all(np.isfinite(x_f), axis=1) | np.any((x_f < lo_c) | (x_f > hi_c), axis=1)
    result = dict(ke_history=ke, ke_final=ke[-1][1], ke_max=ke_max, pressure_profile=profile,
                  pressure_error=float(np.mean([abs(p - ph) for _, p, ph in profile]) / scale) if profile else np.nan,
                  max_drop=float((start_up[fluid] - x_pc[fluid, up]).max() / dx), positions=x_pc, density_p=rho_p,
                  n_fluid=n_fluid, n_wall=n_wall, ke_over_mgh=float(ke_max / energy_scale), n_thrown=int(thrown.sum()),
                  t_reached=float(ke[-1][0]), lammps_error=failure,
                  steps=steps, dt=dt, c0=c0, depth=depth, h=float(h), dx=float(dx), density=density)
    return _verdict(result, ke_max / (TANK_KE_LIMIT * energy_scale), f"{TANK_KE_LIMIT:g} M g H",
                    int(thrown.sum()), "beyond the start's bounding box grown by h", "hydrostatic_tank", failure)


def elliptic_drop_axes(a0, t, radius=1.0):
    """Analytic semi-axes of the elliptic drop (Monaghan 1994): ``u = A x``, ``v = -A y`` with
    ``a' = A a``, ``b' = -A b``, ``A' = A^2 (b^2 - a^2) / (a^2 + b^2)``, from a circle of ``radius``.

    Returns ``(a, b, A)`` at the times ``t`` (increasing, from 0), integrated with scipy's RK45
    to 1e-12 relative.
    """
    from scipy.integrate import solve_ivp

    t = np.atleast_1d(np.asarray(t, dtype=float))

    def rhs(_, y):
        a, b, A = y
        return [A * a, -A * b, A * A * (b * b - a * a) / (a * a + b * b)]

    sol = solve_ivp(rhs, (0.0, float(t.max()) if t.max() > 0 else 1e-12), [radius, radius, a0], t_eval=t,
                    rtol=1e-12, atol=1e-14)
    return sol.y[0], sol.y[1], sol.y[2]


def elliptic_drop(atoms, h, dx, a0=100.0, rho0=1000.0, c0=None, alpha=0.02, t_end=0.008, dt=None, samples=40,
                  density="continuity", center=None, nthreads=1, workdir=None, progress=True):
    """The elliptic drop (Monaghan 1994; BIPI Fig. 22), run in LAMMPS: a circle of fluid with
    ``v = (A0 x, -A0 y)`` about its centre and a free surface, against the analytic semi-axes.

    Parameters
    ----------
    atoms : ase.Atoms
        2D particles (z = 0) filling a circle of radius R (all fluid).
    h, dx : float
        Kernel support and particle spacing.
    a0 : float
        Initial strain rate A0 (1/s).
    rho0, c0, alpha : float
        Tait water (default ``c0 = 14 A0 R``, Mach 0.07 at the largest initial speed).
    t_end, dt, samples :
        Physical time, time step (default ``0.1 h / c0``) and the number of samples.
    density : {"continuity", "summation"}
        Continuity (default) keeps the free surface at rho0; summation density is deficient there.
    center : array-like or None
        The drop's centre (default the particles' mean).

    Raises
    ------
    ValueError
        Before LAMMPS starts: wall particles, a start that is not a disc (second moments in a ratio
        above 1.05, or an extent other than ``R``), ``dx`` not the spacing or ``h`` outside
        :data:`~ase_sphrelax.flows.scales.H_OVER_DX_RANGE` dx.

    Returns
    -------
    dict
        ``history`` (list of dicts: time, a and b from the particles' second moments ``a = 2
        sqrt(<x^2>)``, a and b from their extents, KE (at t = 0 the true initial KE), the analytic
        a and b), ``axis_error`` (max over samples of ``|a - a_exact| / R`` from the moments), ``n``,
        ``steps``, ``dt``, ``c0``, ``radius``; ``stable`` (False, with a :class:`FlowUnstableWarning`,
        when the KE exceeded :data:`DROP_KE_GROWTH` times ``ke0`` or particles ended outside the
        analytic ellipse grown by ``2 h``, or LAMMPS stopped), ``stability_reason``, ``ke0``,
        ``ke_growth``, ``n_thrown``, ``t_reached``, ``lammps_error``.
    """
    kinds = particle_kinds(atoms)
    if (kinds == WALL).any():
        raise ValueError("elliptic_drop: the drop is all fluid; remove the wall particles (atoms.arrays['type'])")
    if infer_dim(atoms) != 2:
        raise ValueError("elliptic_drop: needs 2D particles at z = 0")
    check_positive("a0", a0)
    _check_spacing(atoms, kinds, h, dx, "elliptic_drop")
    centre = atoms.positions[:, :2].mean(axis=0) if center is None else np.asarray(center, dtype=float)[:2]
    rel = atoms.positions[:, :2] - centre
    radius = float(np.sqrt(2.0 * np.mean((rel**2).sum(axis=1)))) * 1.0  # a uniform disc: <r^2> = R^2 / 2
    _check_disc(rel, radius, dx)
    c0 = 14.0 * a0 * radius if c0 is None else float(c0)
    v_pc = np.zeros((len(atoms), 3))
    v_pc[:, 0] = a0 * rel[:, 0]
    v_pc[:, 1] = -a0 * rel[:, 1]

    final = {}

    def observe(lmp, n, time):
        x = _gather(lmp, "x", n, 3)[:, :2]
        final["x"] = x
        r = x - x.mean(axis=0)
        return dict(time=time, ke=float(lmp.last_thermo()["c_flowke"]),
                    a_moment=float(2.0 * np.sqrt(np.mean(r[:, 0] ** 2))),
                    b_moment=float(2.0 * np.sqrt(np.mean(r[:, 1] ** 2))),
                    a_extent=float(np.abs(r[:, 0]).max() + 0.5 * dx), b_extent=float(np.abs(r[:, 1]).max() + 0.5 * dx))

    history, _, n_fluid, _, steps, dt, failure = _run(atoms, h, dx, rho0=rho0, c0=c0, alpha=alpha, gravity=0.0,
                                          t_end=t_end, dt=dt, samples=samples, density=density, nthreads=nthreads,
                                          workdir=workdir, progress=progress, desc="elliptic drop", observe=observe,
                                          velocities=v_pc)
    times = np.array([r["time"] for r in history])
    a_exact, b_exact, _ = elliptic_drop_axes(a0, times, radius)
    for record, a, b in zip(history, a_exact, b_exact):
        record.update(a_exact=float(a), b_exact=float(b))
    error = max(abs(r["a_moment"] - r["a_exact"]) for r in history) / radius
    ke0 = history[0]["ke"]
    ke_max = max(r["ke"] for r in history)
    x = final["x"] - final["x"].mean(axis=0)
    a, b = history[-1]["a_exact"] + 2.0 * h, history[-1]["b_exact"] + 2.0 * h
    thrown = ~np.all(np.isfinite(x), axis=1) | ((x[:, 0] / a) ** 2 + (x[:, 1] / b) ** 2 > 1.0)
    result = dict(history=history, axis_error=float(error), n=n_fluid, steps=steps, dt=dt, c0=c0, radius=radius,
                  a0=float(a0), h=float(h), dx=float(dx), density=density, ke0=float(ke0),
                  ke_growth=float(ke_max / ke0) if ke0 > 0 else np.inf, n_thrown=int(thrown.sum()),
                  t_reached=float(history[-1]["time"]), lammps_error=failure)
    return _verdict(result, ke_max / (DROP_KE_GROWTH * ke0) if ke0 > 0 else np.inf,
                    f"{DROP_KE_GROWTH:g} KE(0)", int(thrown.sum()), "outside the analytic ellipse grown by 2 h",
                    "elliptic_drop", failure)


def _check_disc(rel_pc, radius, dx, tol=0.05):
    """The drop's start must be a disc: equal second moments along every direction (an ellipse is refused) and
    an extent of R (``R = sqrt(2 <r^2>)``; a square or a ring is refused), within ``tol`` R (plus dx for the
    extent)."""
    cov = rel_pc.T @ rel_pc / len(rel_pc)
    lam = np.linalg.eigvalsh(cov)
    aspect = float(np.sqrt(lam[-1] / lam[0])) if lam[0] > 0 else np.inf
    if aspect > 1.0 + tol:
        raise ValueError(f"elliptic_drop: atoms must start as a disc; their second moments give axes in the ratio "
                         f"{aspect:.3g} (an ellipse; at most {1 + tol:g} allowed)")
    extent = float(np.sqrt((rel_pc**2).sum(axis=1)).max()) + 0.5 * dx
    if abs(extent / radius - 1.0) > tol + dx / radius:
        raise ValueError(f"elliptic_drop: atoms must start as a disc; they reach {extent:.4g} from the centre while "
                         f"a uniform disc of their second moment has radius {radius:.4g} (not a filled disc)")
