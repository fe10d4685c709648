"""ALARIC's modified SPH dynamics (Vela Vela et al. Sec. 2) as an ASE MolecularDynamics.

Per step, kick-drift-kick leapfrog (2nd-order symplectic for the conservative part)::

    v <- v + dt/2 a(x, v);  x <- x + dt v;  v <- v + dt/2 a(x, v*)

with ``a = F_calc / m`` (the calculator's force: the ALARIC potential or the paper's Eq. 29 form)
``+ (dv/dt)_visc`` (Eq. 35, switch alpha by Eq. 19-20, ``alpha_min = 0``) ``- chi v`` (Eq. 36, chi = 2);
``v*`` is the half-step velocity (the dissipative terms are evaluated with it). Ingredients, each
on or off: **S** velocity stops, **F** friction, **V** viscosity, and splitting.

* Time step: CFL, ``dt = C min_a H_a / (v_sig + ...)`` with ``v_sig = max(c_s, max |v|)`` and the
  force condition ``dt <= C sqrt(H_a / |a_a|)``; a given ``timestep`` that exceeds the CFL limit
  raises :class:`TimeStepError` naming the step (never silent NaN).
* Velocity stops (Eq. 37-41): the first interval ends at ``tau_cross = L / c_s`` or when the kinetic
  energy first decreases (``tau_NE``, Eq. 38), whichever comes first; that interval is ``tau``; then
  velocities are set to zero every ``tau``, with ``tau <- (1 + theta) tau`` after each stop (Eq. 41).
* At each stop (or interval end when S is off) the mass is reset (Eq. 44), ``epsilon`` (Eq. 45) and
  ``eps_dot`` (its rate since the previous check) are recorded and compared with ``eps_min`` and
  ``eps_dot_min`` (paper: 1e-8). Converged at the coarse level, the particles are split (Fig. 2,
  Eq. 42) if splits remain, else the run stops with ``stop_reason`` "epsilon" or "epsilon_dot";
  "max_steps" when the step cap is reached first.
"""
from __future__ import annotations

import time
import warnings

import numpy as np
from ase.md.md import MolecularDynamics

from .. import sph
from ..checks import NotConvergedWarning, check_positive
from ..models.alaric import convergence_verdict, density_diagnostics, zero_region_mask
from ..splitting import split_particles

__all__ = ["ALARICDynamics", "TimeStepError"]


class TimeStepError(FloatingPointError):
    """The time step is above the CFL limit or the state became non-finite; the message names the step."""


class ALARICDynamics(MolecularDynamics):
    """ALARIC relaxation: isothermal SPH + friction + viscosity + velocity stops + splitting.

    Parameters
    ----------
    atoms : Atoms
        With an :class:`~ase_sphrelax.ALARICCalculator` attached. Masses are set to the calculator's
        particle mass (and reset with it, Eq. 44).
    timestep : float or None
        Fixed step (checked against the CFL limit at every step), or None for the CFL step.
    friction : float
        chi of Eq. 36 (paper: 2); 0 switches F off.
    viscosity : bool
        Eq. 35 with the alpha switch (V).
    velocity_stop : bool
        Velocity nullification (S, Eq. 37-41).
    splits : int
        Number of splitting stages (each multiplies N by p = 3, 4, 5).
    mass_reset : bool
        Eq. 44 at each check.
    eps_min, eps_dot_min : float
        Convergence thresholds (paper: 1e-8 both).
    cfl : float
        Courant number C.
    length : float or None
        L of Eq. 37 (default: the largest extent of the particles, or the cell length along periodic axes).
    theta : float
        tau growth of Eq. 41 (paper: 0.1).
    alpha0, alpha_max : float
        Initial and largest viscosity switch (alpha_min = 0, Sec. 2.2).
    seed : int
        Seed of the split patterns' orientations.
    stage_steps : int or None
        Split (while splits remain) after this many steps in a stage even if it has not converged.
    max_wall : float or None
        Wall-time cap in seconds, counted from the start of the first :meth:`run`: the run stops after the step
        that passes it, with ``stop_reason = "max_wall"`` (a cap like the step cap: not converged).
    logfile, loginterval, trajectory
        As in ASE; the log prints step, time, epsilon, kinetic energy and N.

    Attributes
    ----------
    trace : list of dict
        One entry per check: step, time, epsilon, eps_dot, kinetic energy, N, stage, wall time.
    stop_reason : str or None
        "epsilon", "epsilon_dot", "max_steps" (after :meth:`run`), "max_wall", None while running.
    force_calls : int
        Calculator force evaluations (one per step, plus the first).
    """

    def __init__(self, atoms, timestep=None, friction=2.0, viscosity=True, velocity_stop=True, splits=0,
                 mass_reset=True, eps_min=1e-8, eps_dot_min=1e-8, cfl=0.25, length=None, theta=0.1, alpha0=1.0,
                 alpha_max=1.0, seed=0, stage_steps=None, logfile=None, loginterval=1, trajectory=None,
                 progress=None, max_wall=None):
        from ..calculators.alaric import ALARICCalculator

        calc = atoms.calc
        if not isinstance(calc, ALARICCalculator):
            raise TypeError("ALARICDynamics needs atoms with an ALARICCalculator attached")
        self.fixed_dt = check_positive("timestep", timestep, allow_none=True)
        if not (np.isfinite(friction) and friction >= 0):
            raise ValueError(f"friction must be a finite number >= 0, got {friction!r}")
        self.friction = float(friction)
        self.viscosity = bool(viscosity)
        self.velocity_stop = bool(velocity_stop)
        if int(splits) != splits or splits < 0:
            raise ValueError(f"splits must be an integer >= 0, got {splits!r}")
        self.splits_left = int(splits)
        self.mass_reset = bool(mass_reset)
        self.eps_min = float(eps_min)
        self.eps_dot_min = float(eps_dot_min)
        self.cfl = check_positive("cfl", cfl)
        self.theta = float(theta)
        self.alpha0 = float(alpha0)
        self.alpha_max = float(alpha_max)
        self.seed = int(seed)
        self.stage_steps = None if stage_steps is None else int(stage_steps)
        self.max_wall = check_positive("max_wall", max_wall, allow_none=True)
        self._stage_start = 0
        self.progress = progress
        self.calc = calc
        calc.silence_scale_hint()  # the CFL step follows the forces: ASE's fmax is not in play
        self.dim = calc.resolve_dim(atoms)
        self.cs = float(np.sqrt(calc.parameters.cs2))
        self.length = check_positive("length", length, allow_none=True)
        self._logfile_arg = logfile
        MolecularDynamics.__init__(self, atoms, timestep=timestep or 0.0, trajectory=trajectory,
                                   logfile=None, loginterval=loginterval)
        self.trace = []
        self.stop_reason = None
        self.stage = 0
        self.force_calls = 0
        self.time = 0.0
        self._log_stream = None
        if logfile is not None:
            self._log_stream = open(logfile, "a") if isinstance(logfile, str) and logfile != "-" else None
            self._log_to_stdout = logfile == "-"
        self._start_stage()

    # -- set-up -----------------------------------------------------------------------------
    def _start_stage(self):
        atoms = self.atoms
        self.calc.reset()
        atoms.get_forces()  # solves H, sets the mass (Eq. 44) at the first call
        self.force_calls += 1
        self._sync_masses()
        self.alpha_p = np.full(len(atoms), self.alpha0)
        if self.length is None:
            d = self.dim
            ext = np.ptp(atoms.positions[:, :d], axis=0)
            for c in range(d):
                if atoms.pbc[c]:
                    ext[c] = np.linalg.norm(atoms.cell[c])
            self.length = float(ext.max())
        self.tau = self.length / self.cs  # tau_cross (Eq. 37, isothermal: c_s^2 = P/rho)
        self.tau_measured = False
        self.since_stop = 0.0
        self.ek_prev = 0.0
        self._last_check = None
        self._accel = self._accelerations(atoms.get_velocities())

    def _sync_masses(self):
        self.atoms.set_masses(np.full(len(self.atoms), self.calc.mass))
        # ASE's (N, 1) masses as a read-only view of the one mass: no second array per particle, the same products
        self.masses = np.broadcast_to(np.float64(self.calc.mass), (len(self.atoms), 1))

    # -- physics ------------------------------------------------------------------------------
    def _accelerations(self, v_pc):
        atoms = self.atoms
        self.div_p = None  # the last step's: not held through the evaluation
        f_pc = atoms.get_forces()
        if not atoms.constraints:  # the calculator's own forces (read only): no copy of them through the viscous sum
            f_pc = None
            f_pc = self.calc.results["forces"]
        m = self.calc.mass
        if self.viscosity:
            v_sig = max(self.cs, float(np.sqrt((v_pc**2).sum(axis=1)).max()))
            a_pc, self.div_p = self.calc.viscous_forces(v_pc, self.alpha_p, v_sig)  # a new array: ours to change
            a_pc += f_pc  # F + F_visc (a sum commutes: the same bits as F += F_visc)
        else:
            a_pc = f_pc if atoms.constraints else f_pc.copy()
        f_pc = None
        a_pc /= m
        if self.friction > 0:
            a_pc -= self.friction * v_pc
        a_pc[:, self.dim:] = 0.0
        return a_pc

    def cfl_timestep(self, v_pc=None, a_pc=None):
        """``C min(H / v_sig, sqrt(H / |a|))`` for the current state."""
        h_p = self.calc.results["smoothing_lengths"]
        v_pc = self.atoms.get_velocities() if v_pc is None else v_pc
        a_pc = self._accel if a_pc is None else a_pc
        speed = float(np.sqrt((v_pc**2).sum(axis=1)).max())
        v_sig = max(self.cs, speed)
        dt = float((h_p / (v_sig + speed)).min())
        acc = np.sqrt((a_pc**2).sum(axis=1))
        moving = acc > 0  # a particle at rest with no force sets no limit
        dt_force = float(np.sqrt(h_p[moving] / acc[moving]).min()) if np.any(moving) else np.inf
        return self.cfl * min(dt, dt_force)

    def step(self, forces=None):
        atoms = self.atoms
        limit = self.cfl_timestep()
        if self.fixed_dt is not None:
            if self.fixed_dt > limit * 1.0000001:
                raise TimeStepError(f"step {self.nsteps}: timestep {self.fixed_dt:.4g} exceeds the CFL limit "
                                    f"{limit:.4g} (C = {self.cfl}); use a smaller timestep or timestep=None")
            dt = self.fixed_dt
        else:
            dt = limit
        h_min = float(self.calc.results["smoothing_lengths"].min())
        if not np.isfinite(dt) or dt <= 1e-9 * h_min / self.cs:
            raise TimeStepError(f"step {self.nsteps}: the CFL step collapsed to {dt:.3g} (accelerations "
                                f"{float(np.abs(self._accel).max()):.3g}); the particle state is degenerate")
        self.dt = dt
        v = atoms.get_velocities() + 0.5 * dt * self._accel
        atoms.set_positions(atoms.positions + dt * v)
        if not np.all(np.isfinite(atoms.positions)):
            raise TimeStepError(f"step {self.nsteps}: positions became non-finite (dt = {dt:.4g})")
        self.force_calls += 1
        # the last accelerations and the Atoms' momenta (v holds the state; set again below) go before the
        # evaluation (its peak of memory) makes the new ones
        self._accel = None
        atoms.arrays.pop("momenta", None)
        try:
            self._accel = self._accelerations(v)  # dissipative terms with the half-step velocity
        except BaseException:
            atoms.set_velocities(v)
            raise
        v += 0.5 * dt * self._accel
        if self.viscosity:
            self.alpha_p = sph.update_alpha(self.alpha_p, self.div_p, self.cs, self.calc.results["smoothing_lengths"],
                                            dt, alpha_min=0.0, alpha_max=self.alpha_max)
        atoms.set_velocities(v)
        self.time += dt
        self.since_stop += dt
        ek = 0.5 * float((self.masses * v * v).sum())
        v = None  # not held through an interval end's evaluation
        decreasing = ek < self.ek_prev
        self.ek_prev = ek
        # end of an interval: tau reached, or (first interval) the kinetic energy peaked (Eq. 38)
        if self.since_stop >= self.tau or (not self.tau_measured and decreasing and self.since_stop > 0):
            if not self.tau_measured:
                self.tau = min(self.tau, self.since_stop)
                self.tau_measured = True
            else:
                self.tau *= 1.0 + self.theta  # Eq. 41
            self._interval_end(ek)
        if (self.splits_left > 0 and self.stage_steps is not None and self.stop_reason is None
                and self.nsteps + 1 - self._stage_start >= self.stage_steps):
            self._split()

    def _interval_end(self, ek):
        atoms = self.atoms
        self.since_stop = 0.0
        if self.velocity_stop:  # at rest: ASE's Atoms without momenta (none held through the evaluation below)
            atoms.arrays.pop("momenta", None)
            self.ek_prev = 0.0
        res = self.calc.results
        if self.mass_reset:
            from ..models.alaric import reset_mass

            self.calc.set_mass(reset_mass(res["target"], res["number_density"]))  # Eq. 44
            res = None  # the last evaluation's results and accelerations: not held through the next evaluation
            self._sync_masses()
            self._accel = None
            self._accel = self._accelerations(atoms.get_velocities())
            res = self.calc.results
        if self.velocity_stop:
            atoms.set_velocities(np.zeros((len(atoms), 3)))
        eps = float(res["epsilon"])
        eps_dot = None
        if self._last_check is not None:
            t0, e0 = self._last_check
            eps_dot = (eps - e0) / (self.time - t0) if self.time > t0 else 0.0
        self._last_check = (self.time, eps)
        self.trace.append(dict(step=self.nsteps + 1, time=self.time, epsilon=eps, eps_dot=eps_dot, ek=ek,
                               n=len(atoms), stage=self.stage, tau=self.tau, wall=time.perf_counter() - self._wall0))
        self._write_log()
        if self.progress is not None:
            self.progress.set_postfix(eps=f"{eps:.2e}", N=len(atoms))
        converged = None
        if eps <= self.eps_min:
            converged = "epsilon"
        elif eps_dot is not None and abs(eps_dot) <= self.eps_dot_min:
            converged = "epsilon_dot"
        if converged is None:
            return
        if self.splits_left > 0:
            self._split()
            return
        self.stop_reason = converged

    def _split(self):
        atoms = self.atoms
        res = self.calc.results
        new_h = split_particles(atoms, res["smoothing_lengths"], res["number_density"], self.dim,
                                seed=self.seed + self.stage)
        self.splits_left -= 1
        self.stage += 1
        self._stage_start = self.nsteps + 1
        self.calc.reset_smoothing_lengths(new_h)  # a new list; Eq. 44 at the first evaluation of the new stage
        length = self.length
        self._start_stage()
        self.length = length

    # -- running ------------------------------------------------------------------------------
    def _write_log(self):
        if self._logfile_arg is None:
            return
        e = self.trace[-1]
        line = (f"{e['step']:8d} t={e['time']:.5g} eps={e['epsilon']:.4e} Ek={e['ek']:.4e} N={e['n']} "
                f"stage={e['stage']}\n")
        if self._log_stream is not None:
            self._log_stream.write(line)
            self._log_stream.flush()
        else:
            print(line, end="")

    def converged(self, gradient=None):
        return self.stop_reason is not None or self.nsteps >= self.max_steps

    def irun(self, steps=100000):
        if self.stop_reason == "max_steps":  # a new run continues where the step cap stopped the last one
            self.stop_reason = None
        self.max_steps = self.nsteps + steps
        self._wall0 = getattr(self, "_wall0", time.perf_counter())
        yield self.converged()
        while not self.converged():
            if self.max_wall is not None and time.perf_counter() - self._wall0 >= self.max_wall:
                self.stop_reason = "max_wall"
                break
            self.step()
            self.nsteps += 1
            if self.progress is not None:
                self.progress.update(1)
            self.call_observers()
            yield self.converged()
        if self.stop_reason is None:
            self.stop_reason = "max_steps"

    def run(self, steps=100000):
        """Run until converged (see the module docstring) or ``steps`` steps; return True if converged."""
        for _ in self.irun(steps):
            pass
        return self.stop_reason in ("epsilon", "epsilon_dot")

    def get_time(self):
        return self.time

    def todict(self):
        return {"type": "molecular-dynamics", "md-type": "ALARICDynamics", "timestep": self.fixed_dt,
                "friction": self.friction, "viscosity": self.viscosity, "velocity_stop": self.velocity_stop}


# -- the whole recipe --------------------------------------------------------------------------
def start_atoms(n, dim, domain=None, seed=0, jitter=0.1):
    """Equal particles to start from: ``n`` equispaced on the periodic interval ``[-1, 1)`` in 1D
    (cell ``[0, 2)``, origin -1: the paper's Sec. 4.1 set-up), or a jittered lattice filling
    ``domain`` (default the unit disc / ball, Sec. 4.3-4.4) thinned at random to exactly ``n`` in 2D/3D.
    ``atoms.info["dx"]`` is the mean spacing, ``(V / n)^(1/d)`` (``2 / n`` in 1D); splitting divides it by
    ``p^(1/d)`` (:func:`~ase_sphrelax.splitting.split_particles`).

    Returns ``(atoms, origin, domain)``.
    """
    from ase import Atoms

    from ..build import fill
    from ..domains import Circle, Sphere

    if dim == 1:
        pos = np.zeros((n, 3))
        pos[:, 0] = (np.arange(n) + 0.5) * 2.0 / n
        atoms = Atoms(numbers=np.zeros(n, int), positions=pos, cell=[2.0, 0.0, 0.0], pbc=[True, False, False])
        atoms.info["dx"] = 2.0 / n
        return atoms, np.array([-1.0]), None
    if domain is None:
        domain = Circle((0.0, 0.0), 1.0) if dim == 2 else Sphere((0.0, 0.0, 0.0), 1.0)
    dx = (float(domain.volume) / n) ** (1.0 / dim)
    atoms = fill(domain, dx, jitter=jitter, seed=seed)
    while len(atoms) < n:  # a lattice fill holds about V / dx^d: refine until there are enough
        dx *= 0.98
        atoms = fill(domain, dx, jitter=jitter, seed=seed)
    if len(atoms) > n:  # then drop random ones: exactly n
        keep = np.sort(np.random.default_rng(seed).choice(len(atoms), n, replace=False))
        atoms = atoms[keep]
    atoms.set_cell(np.zeros((3, 3)))
    atoms.pbc = False
    atoms.info["dx"] = (float(domain.volume) / n) ** (1.0 / dim)  # the mean spacing of the n kept particles
    return atoms, np.zeros(dim), domain


def relax_density(atoms, target_density, dim, target_gradient=None, splits=0, domain=None, origin=None,
                  form="log", polish=None, polish_steps=4000, max_steps=50000, eps_min=1e-8, eps_dot_min=1e-8,
                  progress=False, seed=0, epsilon_min=None, boundary="auto", finish="none", wall_form="linear",
                  split_at_cap=False, calculator_options=None, **dynamics):
    """ALARIC's recipe: S+F+V dynamics with ``splits`` splitting stages, then (``polish``) LBFGS on the
    least-squares potential (``form="squares"``, whose minimum is ``rho_a = rho*(x_a)``).

    The dynamics runs the conservative log potential by default (its pressure ``c_s^2 rho`` stays
    positive; the paper's Eq. 29 form and the least-squares form, whose pressures change sign, were
    measured noisy in the dynamics here); the polish removes the log potential's smoothing bias.
    ``polish=None`` polishes in 1D only: in 2D/3D the least-squares fit (N equations, d N unknowns)
    lowers epsilon by pairing particles (measured on the uniform circle: nearest-neighbour distance
    down to 0.017 of the mean, epsilon 1e-5 to 1e-12), so there it is opt-in.

    ``epsilon_min``: the lowest attainable epsilon when known (Eq. 48 for Eq. 46's profile); a result
    below it is reported as degenerate.

    ``finish``: ``"squares"`` continues the dynamics (the same friction, viscosity, velocity stops and Eq. 44 mass
    reset) on the least-squares potential once the log potential has stopped by its epsilon_dot criterion: its
    minimum is the paper's fixed point ``rho_a = rho*(x_a)`` (Eq. 29, 43). On a uniform target in a disc with
    mirror ghosts it lowers epsilon from about 1e-5 to about 1e-8 without pairing; on Eq. 46's well it lowers
    Eq. 45 below Eq. 48 by moving the particles off the bottom of the well, while the integral error grows
    (``reproductions/alaric-table2-two-stage``): so it is opt-in. ``"none"`` (default): the log potential alone.

    ``boundary``: the calculator's edge treatment; ``"auto"`` (default) mirrors through a ball's or a convex
    polygon's boundary (:func:`~ase_sphrelax.models.alaric.resolve_boundary`): with truncated kernels the
    edge particles' density is about half the target and dominates epsilon (Fig. 13:
    ``reproductions/alaric-fig13``).

    ``form="paper"`` (Eq. 29) runs the calculator's stable recipe by default: the background pressure
    ``P_B = c_s^2 max_a (rho*_a - rho_a)_+`` and ``eta = 2.5``
    (:class:`~ase_sphrelax.calculators.alaric.ALARICCalculator`, study ``reproductions/alaric-eq29-stability``);
    it is a driver (no energy), not a gradient descent.
    ``calculator_options``: further :class:`~ase_sphrelax.calculators.alaric.ALARICCalculator` keywords (e.g.
    ``eta``, ``kernel``, ``background_pressure``, ``omega_floor``).

    ``wall_form``: the calculator's domain wall, ``"linear"`` (default) or ``"quadratic"`` (no force jump at the
    boundary; :class:`~ase_sphrelax.calculators.alaric.ALARICCalculator`), also in the polish.

    ``split_at_cap``: when the dynamics stops at its cap (``max_steps`` or ``max_wall``) with splitting stages left,
    split the particles anyway, so that the result has the final N (unrelaxed after the last split; the verdict
    stays "not converged"). False (default): the result keeps the particles of the stage the cap interrupted.
    The pre-split stages last ``stage_steps`` steps (a keyword of :class:`ALARICDynamics`; default
    ``max_steps // (splits + 1)``: pass it to keep the stages when changing the cap, as ``sphrelax density`` does).

    Returns
    -------
    dict
        ``atoms`` (relaxed, masses = the Eq. 44 mass), ``calculator``, ``dynamics``, ``epsilon``
        (final), ``epsilon_dynamics`` (before the polish), ``trace`` (list of dicts: step, epsilon,
        N, stage, phase), ``steps``, ``force_calls``, ``stop_reason``, ``wall_time``, ``converged`` and
        ``convergence_reason`` (:func:`~ase_sphrelax.models.alaric.convergence_verdict`; a
        :class:`~ase_sphrelax.checks.NotConvergedWarning` when False), ``diagnostics``
        (:func:`~ase_sphrelax.models.alaric.density_diagnostics`: max ``|rho/rho* - 1|`` and epsilon per region),
        ``n_outside``: the particles outside ``domain`` at the end (``phi > 0``; 0 without a domain); any makes
        ``converged`` False, the reason saying how many (a soft ``wall_form="quadratic"`` wall can leave some
        outside).
    """
    from ..calculators.alaric import ALARICCalculator
    from ..models.alaric import reset_mass, resolve_boundary

    t0 = time.perf_counter()
    if polish is None:
        polish = dim == 1
    boundary = resolve_boundary(boundary, domain)
    finish = _resolve_finish(finish, dim)
    calc = ALARICCalculator(target_density=target_density, target_gradient=target_gradient, dim=dim, form=form,
                            domain=domain, origin=origin, boundary=boundary, wall_form=wall_form,
                            **(calculator_options or {}))
    atoms.calc = calc
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=max_steps, desc="ALARIC", unit="step", leave=False, disable=None, mininterval=0.5)
    dynamics.setdefault("stage_steps", max_steps // (splits + 1) if splits else None)
    dyn = ALARICDynamics(atoms, splits=splits, eps_min=eps_min, eps_dot_min=eps_dot_min, seed=seed, progress=bar,
                         **dynamics)
    dyn.run(max_steps)
    trace = [dict(e, phase="dynamics") for e in dyn.trace]
    if split_at_cap and dyn.splits_left > 0 and dyn.stop_reason in ("max_steps", "max_wall"):
        while dyn.splits_left > 0:
            dyn._split()
        trace.append(dict(trace[-1] if trace else {}, step=dyn.nsteps, epsilon=float(calc.results["epsilon"]),
                          n=len(atoms), stage=dyn.stage, phase="split at the cap"))
    if finish == "squares" and dyn.stop_reason == "epsilon_dot" and dyn.nsteps < max_steps:
        first = dyn
        calc.set(form="squares")  # a fresh state: H solved again, the Eq. 44 mass at the first evaluation
        atoms.calc = calc
        dynamics.pop("stage_steps", None)
        dyn = ALARICDynamics(atoms, eps_min=eps_min, eps_dot_min=eps_dot_min, seed=seed, progress=bar, **dynamics)
        dyn.run(max_steps - first.nsteps)
        trace += [dict(e, step=first.nsteps + e["step"], phase="finish (squares)") for e in dyn.trace]
        dyn.nsteps += first.nsteps
        dyn.force_calls += first.force_calls
    res = calc.results
    eps_dyn = float(res["epsilon"])
    force_calls = dyn.force_calls
    eps_final = eps_dyn
    if polish and eps_dyn > eps_min:
        eps_final, polish_trace, calls = polish_least_squares(
            atoms, target_density, dim, reset_mass(res["target"], res["number_density"]), target_gradient,
            domain=domain, origin=origin, steps=polish_steps, eps_min=eps_min, spacing=float(np.mean(
                res["smoothing_lengths"])) / calc.eta, bar=bar, boundary=boundary,
                wall_form=wall_form)
        force_calls += calls
        trace += [dict(e, step=dyn.nsteps + e["step"], stage=dyn.stage, wall=time.perf_counter() - t0)
                  for e in polish_trace]
        atoms.calc = calc
        calc.set_mass(reset_mass(*_target_and_n(calc, atoms)))
        atoms.get_forces()
        eps_final = float(calc.results["epsilon"])
    if bar is not None:
        bar.close()
    atoms.set_masses(np.full(len(atoms), calc.mass))
    res = calc.results
    zero_region_p = zero_region_mask(calc.target, calc.points(atoms.positions, atoms), res["smoothing_lengths"],
                                     res["target"])
    diagnostics = density_diagnostics(res["density"], res["target"], res["number_density"], zero_region_p)
    periods = [float(np.linalg.norm(atoms.cell[c])) for c in range(dim) if atoms.pbc[c]]
    converged, reason = convergence_verdict(dyn.stop_reason, diagnostics, res["smoothing_lengths"], periods,
                                            epsilon_min)
    n_outside = 0
    if domain is not None:  # a soft wall (wall_form="quadratic") may leave particles outside: count and say so
        n_outside = int(np.count_nonzero(np.asarray(domain.phi(calc.points(atoms.positions, atoms))) > 0.0))
        if n_outside:  # not the answer asked for, whatever epsilon says
            outside = (f"{n_outside} of {len(atoms)} particles ended outside the domain (wall_form="
                       f"{calc.parameters.wall_form!r}; a stiffer wall, a smaller wall_length, keeps them in)")
            reason = outside if converged else f"{outside}; {reason}"
            converged = False
    if not converged:
        warnings.warn(f"ALARIC did not converge: {reason} (epsilon {eps_final:.3g}, max |rho/rho* - 1| "
                      f"{diagnostics['max_relative_error']})", NotConvergedWarning, stacklevel=2)
    return dict(atoms=atoms, calculator=calc, dynamics=dyn, epsilon=eps_final, epsilon_dynamics=eps_dyn, trace=trace,
                steps=dyn.nsteps, force_calls=force_calls, stop_reason=dyn.stop_reason,
                wall_time=time.perf_counter() - t0, converged=converged, convergence_reason=reason,
                diagnostics=diagnostics, n_outside=n_outside)


def _resolve_finish(finish, dim):
    if finish not in ("squares", "none"):
        raise ValueError(f"finish must be 'squares' or 'none', got {finish!r}")
    return finish


def _target_and_n(calc, atoms):
    atoms.get_forces()
    return calc.results["target"], calc.results["number_density"]


def polish_least_squares(atoms, target_density, dim, mass, target_gradient=None, domain=None, origin=None, steps=4000,
                         eps_min=0.0, spacing=None, bar=None, chunk=250, boundary="wall",
                         wall_form="linear"):
    """LBFGS on the least-squares potential (``form="squares"``) from the current positions; keeps the best.

    Returns ``(epsilon, trace, force_calls)``; ``epsilon`` (Eq. 45 with the Eq. 44 mass) of the best
    positions, which ``atoms`` ends with (the calculator attached is the least-squares one).
    """
    from ase.optimize import LBFGS

    from ..calculators.alaric import ALARICCalculator
    from ..models.alaric import epsilon as eq45, reset_mass

    squares = ALARICCalculator(target_density=target_density, target_gradient=target_gradient, dim=dim,
                               form="squares", domain=domain, origin=origin, mass=mass, boundary=boundary,
                               wall_form=wall_form)
    squares.silence_scale_hint()  # LBFGS below is scaled to the potential (alpha, maxstep)
    atoms.calc = squares
    atoms.set_velocities(np.zeros((len(atoms), 3)))
    atoms.get_forces()
    r = squares.results
    if spacing is None:
        spacing = float(np.mean(r["smoothing_lengths"])) / squares.eta
    rho_ref = float(np.mean(r["target"]))
    # diagonal Hessian scale of the least-squares potential: 10 m c_s^2 rho_ref / dx^2
    alpha = 10.0 * mass * squares.parameters.cs2 * rho_ref / spacing**2
    opt = LBFGS(atoms, logfile=None, maxstep=min(0.15 * spacing, 1.0), alpha=alpha, memory=20)
    opt.maxstep = 0.15 * spacing

    def current():
        r = squares.results
        m = reset_mass(r["target"], r["number_density"])
        return eq45(m * r["number_density"], r["target"], r["number_density"])

    best_eps = current()
    best = atoms.positions.copy()
    trace = []
    done = 0
    while done < steps:
        opt.run(fmax=1e-14, steps=min(chunk, steps - done))
        done += min(chunk, steps - done)
        eps = current()
        trace.append(dict(step=done, epsilon=eps, n=len(atoms), phase="polish"))
        if bar is not None:
            bar.set_postfix(eps=f"{eps:.2e}", phase="polish")
        if eps < best_eps:
            best_eps, best = eps, atoms.positions.copy()
        if eps <= eps_min:
            break
    atoms.positions = best
    return best_eps, trace, done
