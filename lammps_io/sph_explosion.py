"""A point explosion (Sedov-type blast) in LAMMPS' SPH package, from our particle sets.

ALARIC paper (Vela Vela et al.), Sec. 5.2, Figs. 14-15: a periodic box of gas at rest with uniform
density, a total energy ``E0`` of which a fraction (the paper: half) is spread evenly over the
particles and the rest placed at the centre; the blast front should stay circular, and a particle
arrangement with preferred directions (a lattice) shows through as an anisotropic front.

Model (LAMMPS SPH package, ``pair_style sph/idealgas``, read in ``src/SPH/pair_sph_idealgas.cpp``
and ``fix_sph.cpp`` of LAMMPS 22 Jul 2025):

- ideal gas ``p = (gamma - 1) rho e`` with ``gamma = 1.4`` fixed in the source (``0.4`` written in),
  ``e = esph / m``: LAMMPS' ``esph`` is the particle's internal energy (extensive), not per mass;
- Lucy's kernel with support ``h`` (our support-radius convention);
- Monaghan's artificial viscosity, the ``alpha`` term only (no ``beta``), with LAMMPS' signal
  speed ``sqrt(0.4 e)`` per particle;
- the energy equation ``d esph_a / dt = -1/2 sum_b f_ab . v_ab`` (pressure and viscosity), the
  symmetric form: each pair's work is billed half to each particle, so ``KE + sum esph`` is
  conserved by the semi-discrete equations (up to the time integration, which ``fix sph`` does as
  velocity Verlet with half-step ``esph`` and ``rho`` updates);
- densities by summation every step (``pair_style hybrid/overlay sph/rhosum 1 sph/idealgas``,
  default) or by the continuity equation ``fix sph`` integrates (``density="continuity"``).

The symmetric energy equation has one trap measured here: a single hot particle cools its cold
neighbours by the work of its own pressure until their energies go negative (40 x 40 lattice, half
of E0 = 1 in one particle: the neighbours' ``esph`` fell from 3.1e-4 to below zero in 70 steps at
dt = 1e-5, about 1/60 of the CFL step, and the run turned to NaN). The paper's recipe (half the
energy in the one particle closest to the centre) is therefore available as ``deposit="particle"``
but fails in LAMMPS; the default ``deposit="kernel"`` spreads the central share with Lucy's kernel
weights over the particles within ``deposit_radius`` (default ``2 h``) of that particle. The same trap
sets that default: on a 100 x 100 square lattice (h = 2.6 dx) a deposit over ``h`` (21 particles)
failed at t = 0.0025 with cfl = 0.1 and with cfl = 0.025 alike, while ``2 h`` (89 particles) and
``3 h`` ran to t = 0.09.

Time step: ``fix sph`` takes a fixed step; it is reset every ``chunk`` steps from the CFL
condition ``dt = cfl h / max_a (c_a + |v_a|)``, ``c_a = sqrt(gamma (gamma - 1) e_a)``, and shortened
to land on the snapshot times. Units: LAMMPS ``lj`` (the paper's are dimensionless: rho = 1 in
the unit box, t = 0.09).
"""
from __future__ import annotations

import math
import numbers
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from ase_sphrelax.checks import check_positive

from ._library import check_threads, import_lammps, new_lammps
from .box import infer_dim, lammps_box
from .data_file import write_data

__all__ = ["point_explosion", "deposit_energies", "GAMMA", "DEPOSITS"]

GAMMA = 1.4  # written into pair_sph_idealgas.cpp as 0.4 = gamma - 1
DEPOSITS = ("kernel", "particle")
DENSITY_MODES = ("summation", "continuity")
DEFAULT_H_FACTOR = {2: 2.6, 3: 2.0}
_TRAP_HINT = ("sph/idealgas's symmetric energy equation cools the cold neighbours of hot particles below zero: "
              "spread the deposit (deposit='kernel', a larger deposit_radius) or raise background")  # h / spacing: about 21 (2D) and 34 (3D) neighbours


def _lucy(q):
    """Lucy's kernel shape ``(1 + 3q)(1 - q)^3`` for ``q < 1`` (unnormalised)."""
    q = np.asarray(q, dtype=float)
    return np.where(q < 1.0, (1.0 + 3.0 * q) * (1.0 - q) ** 3, 0.0)


def _minimum_image(d_pd, length_d):
    return d_pd - length_d * np.round(d_pd / length_d)


def deposit_energies(r_pd, length_d, central, energy, background, deposit, radius):
    """Per-particle internal energies ``esph_a`` of the blast; they sum to ``energy``.

    Parameters
    ----------
    r_pd : array (N, dim)
        Positions in a periodic orthogonal box of side lengths ``length_d``.
    central : int
        Index of the central particle.
    energy : float
        Total energy ``E0``.
    background : float
        Fraction of ``E0`` spread evenly: over every particle (``"kernel"``) or over every particle
        but the central one (``"particle"``, the paper's recipe).
    deposit : {"kernel", "particle"}
        ``"kernel"``: the rest with weights ``W(|r_a - r_c|, radius)`` (Lucy's kernel) about the
        central particle ``c``; ``"particle"``: the rest in the central particle.
    radius : float
        Support of the deposit kernel (``"kernel"``).

    Returns
    -------
    ndarray (N,)
    """
    n = len(r_pd)
    e_p = np.zeros(n)
    if deposit == "particle":
        if n > 1:
            e_p[:] = background * energy / (n - 1)
        e_p[central] = (1.0 - background) * energy if n > 1 else energy
        return e_p
    d_pd = _minimum_image(r_pd - r_pd[central], length_d)
    w_p = _lucy(np.sqrt((d_pd**2).sum(axis=1)) / radius)
    return background * energy / n + (1.0 - background) * energy * w_p / w_p.sum()


def _snapshot_times(snapshots, t_end):
    if isinstance(snapshots, numbers.Integral) and not isinstance(snapshots, bool):
        if snapshots < 1:
            raise ValueError(f"snapshots must be an integer >= 1 or a sequence of times in (0, t_end], got {snapshots!r}")
        return [t_end * (k + 1) / int(snapshots) for k in range(int(snapshots))]
    try:
        times = sorted(float(t) for t in snapshots)
    except (TypeError, ValueError):
        raise ValueError(f"snapshots must be an integer >= 1 or a sequence of times in (0, t_end], got {snapshots!r}") from None
    if not times or times[0] <= 0 or times[-1] > t_end * (1 + 1e-12) or not all(map(math.isfinite, times)):
        raise ValueError(f"snapshots must be an integer >= 1 or a sequence of times in (0, t_end], got {snapshots!r}")
    return times


def _check_inputs(atoms, energy, rho0, h, background, deposit, deposit_radius, t_end, cfl, alpha, density, chunk,
                  nthreads):
    if len(atoms) < 2:
        raise ValueError(f"atoms: need at least 2 particles, got {len(atoms)}")
    if not np.all(np.isfinite(atoms.positions)):
        raise ValueError("atoms.positions must be finite")
    for name, value in dict(energy=energy, rho0=rho0, t_end=t_end, cfl=cfl).items():
        check_positive(name, value)
    check_positive("h", h, allow_none=True)
    check_positive("deposit_radius", deposit_radius, allow_none=True)
    if isinstance(background, bool) or not isinstance(background, numbers.Real) or not 0.0 <= background < 1.0:
        raise ValueError(f"background must be a number in [0, 1), got {background!r}")
    if deposit not in DEPOSITS:
        raise ValueError(f"deposit must be one of {DEPOSITS}, got {deposit!r}")
    if cfl > 1.0:
        raise ValueError(f"cfl must be in (0, 1], got {cfl!r}")
    if isinstance(alpha, bool) or not isinstance(alpha, numbers.Real) or not (math.isfinite(alpha) and alpha >= 0):
        raise ValueError(f"alpha must be a finite number >= 0, got {alpha!r}")
    if density not in DENSITY_MODES:
        raise ValueError(f"density must be one of {DENSITY_MODES}, got {density!r}")
    if isinstance(chunk, bool) or not isinstance(chunk, numbers.Integral) or chunk < 1:
        raise ValueError(f"chunk must be an integer >= 1, got {chunk!r}")
    check_threads(nthreads)
    dim = infer_dim(atoms)
    if dim not in (2, 3):
        raise ValueError(f"point_explosion needs 2D or 3D particles, got dim={dim}")
    if not all(atoms.pbc[:dim]):
        raise ValueError(f"point_explosion needs a box periodic along all {dim} axes, got atoms.pbc={atoms.pbc.tolist()}")
    cell = atoms.cell.array[:dim, :dim]
    if np.any(np.abs(cell - np.diag(np.diag(cell))) > 1e-12 * np.abs(cell).max()) or np.any(np.diag(cell) <= 0):
        raise ValueError("point_explosion needs an orthogonal cell (a diagonal, positive atoms.cell along the used axes)")
    return dim


def _check_centre(centre, dim):
    try:
        target = np.asarray(centre, dtype=float).ravel()
    except (TypeError, ValueError):
        target = np.zeros(0)
    if target.shape[0] < dim or not np.all(np.isfinite(target[:dim])):
        raise ValueError(f"centre must hold {dim} finite coordinates, got {centre!r}")
    return target[:dim]


def _gather(lmp, name, n, width):
    values = np.ctypeslib.as_array(lmp.gather_atoms(name, 1, width)).astype(float)[: n * width]
    return values.reshape(n, width) if width > 1 else values


def point_explosion(atoms, energy=1.0, *, rho0=1.0, h=None, background=0.5, deposit="kernel", deposit_radius=None,
                    centre=None, t_end=0.09, snapshots=9, cfl=0.1, alpha=1.0, density="summation", chunk=10,
                    nthreads=1, workdir=None, progress=True):
    """Run a point explosion in LAMMPS (``pair_style sph/idealgas``) from ``atoms``.

    Parameters
    ----------
    atoms : ase.Atoms
        2D (z = 0, pbc (True, True, False)) or 3D particles in a periodic orthogonal box; every
        particle has the mass ``rho0 V / N`` (``V`` the box measure).
    energy : float
        Total energy ``E0`` (kinetic + internal, conserved).
    rho0 : float
        The gas density.
    h : float or None
        Kernel support (LAMMPS' ``h``); default 2.6 (2D) or 2.0 (3D) times the spacing ``(V/N)^(1/d)``.
    background : float in [0, 1)
        Fraction of ``E0`` spread evenly (the paper: 0.5), so that the gas ahead of the blast has a
        pressure and a sound speed.
    deposit : {"kernel", "particle"}
        How the rest is placed about the particle closest to ``centre``: Lucy-kernel weights over
        ``deposit_radius`` (default), or all in that particle (the paper's; fails in LAMMPS, see
        the module docstring: a RuntimeError names it).
    deposit_radius : float or None
        Support of the deposit kernel (default ``2 h``; see the module docstring).
    centre : array-like or None
        Where the explosion starts (the particle closest to it); default the box centre.
    t_end : float
        End time (the paper's Fig. 14: 0.09).
    snapshots : int or sequence of float
        Times in ``(0, t_end]`` of the per-particle snapshots (an int: that many, evenly spaced);
        one at t = 0 is always added.
    cfl : float in (0, 1]
        Courant factor of ``dt = cfl h / max_a (c_a + |v_a|)``.
    alpha : float
        Monaghan's artificial viscosity (LAMMPS' ``alpha``; no ``beta`` term in sph/idealgas).
    density : {"summation", "continuity"}
        Kernel summation every step (default) or the continuity equation.
    chunk : int
        Steps between time-step updates and history records.
    nthreads : int
        OpenMP threads of LAMMPS.
    workdir : str or Path or None
        Where the data file goes (default a temporary folder).
    progress : bool
        A tqdm bar over the simulated time.

    Returns
    -------
    dict
        ``history`` (list of dicts per chunk: ``time``, ``steps``, ``dt``, ``kinetic``, ``internal``,
        ``total``, ``energy_error`` = (total - E0) / E0, ``min_esph``, ``max_signal``);
        ``snapshots`` (list of dicts: ``time``, ``positions`` (N, dim), ``density`` (N,),
        ``esph`` (N, the particles' internal energies), ``velocities`` (N, dim), ``div_v`` (N,
        ``-drho/rho`` of the continuity equation at the last step)); positions and velocities are in
        LAMMPS' frame, which for these orthogonal boxes is the ASE cell with positions wrapped into
        ``[0, L)``; ``centre`` (the central particle's start position in that frame), ``cell``
        (side lengths), ``central_index``, ``energy_error_max`` (max over the history of
        ``|energy_error|``), ``deposit_count`` (particles given more than the background share),
        ``n``, ``dim``, ``mass``, ``h``, ``steps``, ``dt_min``, ``dt_max``, ``wall_time``, and the
        parameters.

    Raises
    ------
    ValueError
        for bad input (one line naming the parameter), before LAMMPS starts.
    RuntimeError
        when a particle's internal energy turns negative or non-finite (the run is then meaningless).
    """
    dim = _check_inputs(atoms, energy, rho0, h, background, deposit, deposit_radius, t_end, cfl, alpha, density,
                        chunk, nthreads)
    times = _snapshot_times(snapshots, t_end)
    if centre is not None:
        _check_centre(centre, dim)
    import_lammps()
    t_start = time.perf_counter()
    n = len(atoms)
    box = lammps_box(atoms, dim=dim)
    length_d = (box.hi_c - box.lo_c)[:dim]
    volume = float(np.prod(length_d))
    spacing = (volume / n) ** (1.0 / dim)
    h = DEFAULT_H_FACTOR[dim] * spacing if h is None else float(h)
    radius = 2.0 * h if deposit_radius is None else float(deposit_radius)
    mass = rho0 * volume / n
    r_pd = box.r_pc[:, :dim]
    target = 0.5 * length_d if centre is None else _check_centre(centre, dim) @ box.rot_cc[:dim, :dim]
    central = int(np.argmin((_minimum_image(r_pd - target, length_d) ** 2).sum(axis=1)))
    e_p = deposit_energies(r_pd, length_d, central, float(energy), float(background), deposit, radius)
    background_share = background * energy / n
    tmp = tempfile.TemporaryDirectory(prefix="lammps_io_blast_") if workdir is None else None
    folder = Path(tmp.name if tmp else workdir)
    folder.mkdir(parents=True, exist_ok=True)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=float(t_end), desc="point explosion", unit="t", leave=False, disable=None, mininterval=0.5,
                   bar_format="{l_bar}{bar}| {n:.4g}/{total:.4g} [{elapsed}<{remaining}]")
    cwd = os.getcwd()
    snaps, history = [], []
    steps, t_now, dt_seen = 0, 0.0, []
    lmp = None
    try:
        write_data(atoms, folder / "blast.data", atom_style="sph", dim=dim, masses=mass, rho=rho0, esph=e_p, cv=1.0)
        lmp = new_lammps(nthreads=nthreads)
        os.chdir(folder)
        summation = density == "summation"
        lmp.commands_list([
            *box.read_data_commands("blast.data", "sph", "p p p"),
            "pair_style hybrid/overlay sph/rhosum 1 sph/idealgas" if summation else "pair_style sph/idealgas",
            *([f"pair_coeff * * sph/rhosum {h:.17g}", f"pair_coeff * * sph/idealgas {alpha:.17g} {h:.17g}"]
              if summation else [f"pair_coeff * * {alpha:.17g} {h:.17g}"]),
            f"neighbor {0.2 * h:.17g} bin",
            "neigh_modify every 1 delay 0 check yes",
            "compute blastke all ke",
            "compute blaste all sph/e/atom",
            "compute blasteint all reduce sum c_blaste",
            "compute blastemin all reduce min c_blaste",
            f"variable blastsig atom sqrt({GAMMA * (GAMMA - 1.0):.17g}*abs(c_blaste)/mass)+sqrt(vx*vx+vy*vy+vz*vz)",
            "compute blastsig all reduce max v_blastsig",
            "thermo_style custom step c_blastke c_blasteint c_blastemin c_blastsig",
            "thermo_modify norm no lost error",
            "fix blastsph all sph",
            *(["fix blast2d all enforce2d"] if box.lammps_dimension == 2 else []),
            f"timestep {1e-6 * h:.17g}",
            "run 0",
        ])

        def record():
            th = lmp.last_thermo()
            kinetic, internal = float(th["c_blastke"]), float(th["c_blasteint"])
            rec = dict(time=t_now, steps=steps, dt=dt_seen[-1] if dt_seen else 0.0, kinetic=kinetic,
                       internal=internal, total=kinetic + internal, energy_error=(kinetic + internal - energy) / energy,
                       min_esph=float(th["c_blastemin"]), max_signal=float(th["c_blastsig"]))
            history.append(rec)
            if not (math.isfinite(rec["min_esph"]) and rec["min_esph"] >= 0 and math.isfinite(rec["total"])):
                raise RuntimeError(
                    f"point_explosion: a particle's internal energy went negative or non-finite at t = {t_now:.4g} "
                    f"(min esph {rec['min_esph']:.3g}, total energy {rec['total']:.6g}, step {steps}); {_TRAP_HINT}")
            return rec

        def snapshot():
            x_pc = _gather(lmp, "x", n, 3)[:, :dim]
            v_pc = _gather(lmp, "v", n, 3)[:, :dim]
            rho_p = _gather(lmp, "rho", n, 1)
            drho_p = _gather(lmp, "drho", n, 1)
            snaps.append(dict(time=t_now, positions=x_pc, density=rho_p, esph=_gather(lmp, "esph", n, 1),
                              velocities=v_pc, div_v=-drho_p / rho_p))

        rec = record()
        snapshot()
        for target_time in times:
            while t_now < target_time * (1 - 1e-12):
                dt = cfl * h / rec["max_signal"]
                k = int(chunk)
                if t_now + k * dt >= target_time:
                    k = max(1, int(math.ceil((target_time - t_now) / dt - 1e-9)))
                    dt = (target_time - t_now) / k
                try:
                    lmp.commands_list([f"timestep {dt:.17g}", f"run {k} pre no post no"])
                except Exception as err:  # the lammps module raises a bare Exception
                    raise RuntimeError(f"point_explosion: LAMMPS stopped between t = {t_now:.4g} and "
                                       f"{t_now + k * dt:.4g} ({err}); {_TRAP_HINT}") from None
                steps += k
                t_now = target_time if t_now + k * dt >= target_time * (1 - 1e-12) else t_now + k * dt
                dt_seen.append(dt)
                rec = record()
                if bar is not None:
                    bar.update(k * dt)
            snapshot()
    finally:
        if lmp is not None:
            lmp.close()
        os.chdir(cwd)
        if bar is not None:
            bar.close()
        if tmp is not None:
            tmp.cleanup()
    return dict(history=history, snapshots=snaps, centre=r_pd[central].tolist(), cell=length_d.tolist(),
                central_index=central, energy_error_max=float(max(abs(r["energy_error"]) for r in history)),
                deposit_count=int(np.sum(e_p > background_share * (1 + 1e-9))), n=n, dim=dim, mass=mass, h=h,
                steps=steps, dt_min=float(min(dt_seen)) if dt_seen else 0.0,
                dt_max=float(max(dt_seen)) if dt_seen else 0.0, wall_time=time.perf_counter() - t_start,
                energy=float(energy), rho0=float(rho0), background=float(background), deposit=deposit,
                deposit_radius=radius, t_end=float(t_end), cfl=float(cfl), alpha=float(alpha), density=density,
                gamma=GAMMA)
