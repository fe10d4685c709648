"""Scale-aware construction of ASE optimisers for SPH relaxation.

ASE's defaults are set for atoms in eV and Angstrom (FIRE ``dt = 0.1``,
``maxstep = 0.2``; BFGS/LBFGS ``alpha = 70``). Fan's forces scale like
``dx^(2d) / h^(d+1)``, so those defaults are off by orders of magnitude for
``dx = 1/256``. :func:`make_optimizer` sets them from the initial forces so
that the first step moves the fastest particle by ``c h``, the step of Eq. 2.4.

``"fire"``, ``"fire2"`` and ``"lbfgs"`` are by default
:class:`~ase_sphrelax.drivers.sph_optimizers.SPHFIRE`,
:class:`~ase_sphrelax.drivers.sph_optimizers.SPHFIRE2` and
:class:`~ase_sphrelax.drivers.sph_optimizers.SPHLBFGS`: ASE's algorithms step for step
(the same trajectories to round-off), with numba vector work on the coordinates that move and
buffers reused between steps (issue 33, item 1); ``backend="ase"`` gives ASE's own classes.
"""
from __future__ import annotations

import numpy as np

from ..checks import ASE_DEFAULT_FMAX, SPHScaleWarning  # noqa: F401 (SPHScaleWarning re-exported)
from .blas import limit_blas_in_steps, resolve_blas_threads
from .keep_inside import attach_keep_inside
# re-exported: NothingRelaxedWarning and check_c have been public names of this module
from .step_scale import NothingRelaxedWarning, calculator_h, check_c, mark_scaled, warn_if_nothing_relaxed

__all__ = ["OPTIMIZERS", "BACKENDS", "DEFAULT_C", "DEFAULT_MEMORY", "FIRE_DYNAMICS", "FIRE_PARTICLE_STEP",
           "make_optimizer", "check_c", "NothingRelaxedWarning", "SPHScaleWarning", "warn_if_nothing_relaxed",
           "ASE_DEFAULT_FMAX"]


_CHECKED = {}


def _checked(cls):
    """``cls`` with a ``run`` that warns when it converged at step 0 (:func:`warn_if_nothing_relaxed`)."""
    if cls not in _CHECKED:
        def run(self, fmax=ASE_DEFAULT_FMAX, steps=None, **kwargs):
            converged = cls.run(self, fmax=fmax, **({} if steps is None else {"steps": steps}), **kwargs)
            warn_if_nothing_relaxed(self, fmax, converged)
            return converged

        _CHECKED[cls] = type(cls.__name__, (cls,), {"run": run, "__doc__": cls.__doc__,
                                                    "__module__": cls.__module__})
    return _CHECKED[cls]

# the one list of optimiser names (CLI choices, relax_lattice); importing it loads no ASE optimiser
OPTIMIZERS = ("fan", "fire", "fire2", "bfgs", "lbfgs")

# default step scale c per optimiser (first step c h, largest step 10 c h); measured in
# benchmarks/bench_speed_vs_error.py: LBFGS with c = 0.05 (and memory 20) reaches the error of
# 2000 Eq. 2.4 steps with 0.14-0.17 of its force evaluations, with c = 0.01 only 0.29-0.38
DEFAULT_C = {"fan": 0.01, "fire": 0.01, "fire2": 0.01, "bfgs": 0.05, "lbfgs": 0.05}

# who does the FIRE / LBFGS vector work: "sph" (numba, drivers/sph_optimizers.py) or "ase" (numpy)
BACKENDS = ("sph", "ase")

# FIRE's dynamics for SPH, set relative to the scaled first dt (issue 33, item 2;
# benchmarks/bench_optimizer_steps.py, Fan's circle, steps to the interior mean h|sum V grad W| of 6e-4):
# dt grows up to dtmax = 2.5 dt (with ASE's 10 dt the steps went unstable beyond about 3-6 dt, and
# every restart then cost tens of steps) and the velocity mixing keeps a = 0.15 (fa = 1; ASE's a
# starts at 0.1 and shrinks by 0.99 per step, which left the velocities to swing for a hundred steps
# between restarts): half the steps of ASE's values in 2D at 1e4-1e6, 0.7 of them on the sphere at 1e4
# (the entry speed-optimizer-steps)
FIRE_DYNAMICS = dict(dtmax_over_dt=2.5, astart=0.15, a=0.15, fa=1.0)

# FIRE's cut of each particle's move in one step, in units of h, by dimension (None: no cut), for the "sph"
# backend, on an Atoms whose calculator keeps a Verlet list (``skin``; SPHFIRE's ``max_particle_step``; ASE's
# FIRE has none). Uncut, the list's rebuilds are set off by a few fast particles; cut, they come less often, for a
# few more steps (and then by the bulk, every particle that moves far moving at the cut). On Fan's sphere (skin
# 0.1 h) 0.005 h, a tenth of half the skin, leaves 16 rebuilds instead of 46 for 170 steps instead of 155 at 1e6
# (40 s instead of 47 s to the bench's target); on the circle (its skin adapts up to 0.3 h) 0.01 h leaves 16
# instead of 21 for 165 steps instead of 155 (17 s instead of 18 s) (reproductions/speed-fan-1e6/particle_step_scan.py,
# the entry speed-fan-1e6)
FIRE_PARTICLE_STEP = {2: 0.01, 3: 0.005}

# LBFGS history length per backend: ASE's LBFGS keeps 20 pairs (its own 100 cost more than a force call);
# SPHLBFGS 5, each pair 16 dim bytes per particle: on Fan's circle and sphere it converges per step as
# ASE's with 20 (energy and mean gradient error after 300 steps, reproductions/speed-optimizers)
DEFAULT_MEMORY = {"sph": 5, "ase": 20}


def make_optimizer(name, atoms, c=None, h=None, logfile=None, keep_inside=True, blas_threads=None, backend="sph",
                   **kwargs):
    """Return an optimiser for ``atoms`` whose first step moves at most ``c h``.

    ASE's own defaults (FIRE ``dt = 0.1``, ``maxstep = 0.2``; ``run(fmax=0.05)``) are set for
    eV and Angstrom: with Fan's forces (about 4e-3 on the default circle) ``run(fmax=0.05)``
    stops at step 0. This optimiser scales the steps; choose ``fmax`` relative to the forces
    (e.g. ``1e-3 * max |F|``): a run that stops at step 0 with ``fmax > 0`` warns
    (:class:`ase_sphrelax.drivers.optimizers.NothingRelaxedWarning`).

    Parameters
    ----------
    name : {"fan", "fire", "fire2", "bfgs", "lbfgs"}
        ``"fan"`` is :class:`FanRelaxation` (Eq. 2.4); ``"fire"``, ``"fire2"`` (Guénolé et al.
        2020) and ``"lbfgs"`` ASE's algorithms (see ``backend``), ``"bfgs"`` ASE's.
    atoms : Atoms or Filter
        With a calculator attached.
    c : float or None
        Step scale: Eq. 2.4 coefficient for ``"fan"``; for the ASE optimisers the
        first step length is ``c h`` and the largest allowed step ``10 c h``.
        None: :data:`DEFAULT_C` of the optimiser.
    h : float or None
        Kernel cut-off radius (default: the calculator's ``h``).
    keep_inside : bool
        With a calculator that has a ``domain``, attach
        :class:`~ase_sphrelax.drivers.keep_inside.KeepInDomain` to the atoms: no step takes a
        particle out of the domain (issue 10 item 9). False: the optimiser's steps as they are.
    blas_threads : None, False or int
        BLAS threads inside the ASE optimisers' steps (:mod:`~ase_sphrelax.drivers.blas`):
        None limits them to 1 unless the user set ``OPENBLAS_NUM_THREADS`` (or another BLAS
        thread variable), False leaves BLAS alone, an integer sets that limit. Multi-threaded
        BLAS on these short vectors collapses under a competing load (12x slower LBFGS).
    backend : {"sph", "ase"}
        For ``"fire"``, ``"fire2"`` and ``"lbfgs"``: ``"sph"`` (default) returns
        :class:`~ase_sphrelax.drivers.sph_optimizers.SPHFIRE` /
        :class:`~ase_sphrelax.drivers.sph_optimizers.SPHFIRE2` /
        :class:`~ase_sphrelax.drivers.sph_optimizers.SPHLBFGS` (ASE's algorithms with numba
        vector work, the same trajectories with the same parameters), ``"ase"`` ASE's own classes.
    **kwargs
        Override the optimiser's own parameters. ``"fire"`` sets ``dtmax``, ``a``, ``astart`` and
        ``fa`` from :data:`FIRE_DYNAMICS` (``dtmax`` 2.5 times the first ``dt``, a constant mixing
        ``a = 0.15``; ASE's are ``dtmax`` 10 dt, ``a`` 0.1 shrinking by 0.99 a step) and, with the
        ``"sph"`` backend, an Atoms (not a Filter) and a calculator that keeps a Verlet list (a ``skin``: Fan's,
        BIPI's), cuts each particle's move at ``max_particle_step`` = 0.01 h in 2D, 0.005 h in 3D
        (:data:`FIRE_PARTICLE_STEP`; ``max_particle_step=None`` gives ASE's step).
    """
    from ase import Atoms
    from ase.optimize import BFGS, FIRE, LBFGS

    from .fan_relaxation import FanRelaxation  # numba: loaded only for Eq. 2.4
    from .sph_optimizers import SPHFIRE, SPHFIRE2, SPHLBFGS, moving_dim

    if name not in OPTIMIZERS:
        raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {name!r}")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    sph = backend == "sph" and name != "bfgs"  # "fire", "lbfgs": ours (and "fan" returns before it is read)
    if not (sph and name == "fire"):  # SPHFIRE alone cuts each particle's move
        if kwargs.pop("max_particle_step", None) is not None:
            raise ValueError(f"max_particle_step: only 'fire' with backend='sph' cuts each particle's move, got "
                             f"{name!r} with backend={backend!r}")
    resolve_blas_threads(blas_threads)  # bad values fail before any work
    c = DEFAULT_C[name] if c is None else c
    h = calculator_h(atoms) if h is None else h
    if name == "fan":  # Eq. 2.4 does no BLAS work
        return FanRelaxation(atoms, c=c, h=h, logfile=logfile, keep_inside=keep_inside, **kwargs)
    if h is None:
        raise ValueError("h must be given, or the calculator must have a parameter 'h'")
    c = check_c(c)
    if keep_inside:
        attach_keep_inside(atoms)
    mark_scaled(atoms)
    forces = atoms.get_forces()
    f_max = float(np.sqrt((forces**2).sum(axis=1)).max())
    step = c * h
    f_max = f_max if f_max > 0 else 1.0
    if name in ("fire", "fire2"):
        # FIRE's first move is dt^2 F: pick dt so that it is c h for the largest force. ASE's FIRE caps
        # the norm of the whole 3N step, not each particle's move: scaled by sqrt(N), the cap is an RMS
        # particle move of 10 c h (unscaled, 1e5 particles needed 1522 steps where LAMMPS FIRE took 200)
        dt = np.sqrt(step / f_max)
        params = dict(dt=dt, dtmax=10 * dt, maxstep=10 * step * np.sqrt(max(len(forces), 1)))
        if name == "fire":  # FIRE_DYNAMICS: about half the steps of ASE's values on Fan's circle
            dynamics = dict(FIRE_DYNAMICS)
            params.update(dtmax=dynamics.pop("dtmax_over_dt") * dt, **dynamics)
            # fewer rebuilds of a Verlet list (FIRE_PARTICLE_STEP): for the particles of an Atoms (a Filter's rows
            # may be a cell's too) whose calculator keeps one
            cut = FIRE_PARTICLE_STEP[moving_dim(atoms, kwargs.get("dim"))]
            if sph and cut is not None and isinstance(atoms, Atoms) and getattr(atoms.calc, "skin", None) is not None:
                params["max_particle_step"] = cut * h
        else:  # FIRE2's floor on dt, in ASE's ratio to its dt (2e-3 / 0.1)
            params["dtmin"] = 0.02 * dt
        params.update(kwargs)
        if name == "fire2":
            from ase.optimize.fire2 import FIRE2

            cls = SPHFIRE2 if sph else _checked(FIRE2)
        else:
            cls = SPHFIRE if sph else _checked(FIRE)  # SPHFIRE's (SPHFIRE2's) run warns itself
        return limit_blas_in_steps(cls(atoms, logfile=logfile, **params), blas_threads)
    # quasi-Newton: the first step is F / alpha
    params = dict(alpha=f_max / step, maxstep=10 * step)
    if name == "lbfgs":
        params["memory"] = DEFAULT_MEMORY[backend]  # ASE's 100 pairs cost more than a force call
    params.update(kwargs)
    if sph:
        return limit_blas_in_steps(SPHLBFGS(atoms, logfile=logfile, **params), blas_threads)
    maxstep = params.pop("maxstep")
    cls = _checked(BFGS if name == "bfgs" else LBFGS)
    # ASE's LBFGS refuses maxstep > 1 (a sanity check in Angstrom); SPH lengths have no such scale
    opt = cls(atoms, logfile=logfile, maxstep=min(maxstep, 1.0), **params)
    opt.maxstep = maxstep
    return limit_blas_in_steps(opt, blas_threads)
