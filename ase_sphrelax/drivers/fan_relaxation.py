"""Fan et al.'s relaxation update (Eq. 2.4) as an ASE optimiser::

    r_i^{n+1} = r_i^n + U_i^n dT,   U_i^n = -dE/dx_i (Eq. A.1),   dT = c h / max_i |U_i^n|,

so the particle that moves most moves exactly ``c h`` per step (Eq. 2.5);
Appendix A uses ``c = 0.01``. In continuous time E decreases along the
trajectories (Eq. 3.18). With the fixed step length ``c h`` the discrete
iteration cannot settle: near the minimum it overshoots and E oscillates at a
floor set by ``c`` (measured in ``tests/test_fan_relaxation.py``). ASE's FIRE,
BFGS and LBFGS adapt their step and reach lower E with fewer force calls.
"""
from __future__ import annotations

import numba
import numpy as np
from ase.optimize.optimize import DEFAULT_MAX_STEPS, Optimizer

from ..checks import ASE_DEFAULT_FMAX, check_positive
from .keep_inside import attach_keep_inside
from .step_scale import calculator_h, check_c, mark_scaled, warn_if_nothing_relaxed

__all__ = ["FanRelaxation"]


@numba.njit(cache=True)
def _max_norm2(u_pc):
    """max_p |u_p|^2, NaN if any component is NaN (inf if one is infinite), without temporaries."""
    best = 0.0
    for p in range(u_pc.shape[0]):
        u2 = 0.0
        for c in range(u_pc.shape[1]):
            u2 += u_pc[p, c] * u_pc[p, c]
        if u2 != u2:
            return u2
        best = max(best, u2)
    return best


class FanRelaxation(Optimizer):
    """Particle relaxation with the fixed maximum step ``c h`` (Fan Eq. 2.4, A.1).

    Parameters
    ----------
    atoms : Atoms or Filter
        With a calculator whose forces are ``-dE/dx`` (e.g. :class:`~ase_sphrelax.FanCalculator`).
    c : float
        Step coefficient of Eq. 2.4/2.5, ``0 < c < 1``; the largest displacement per step is ``c h``.
    h : float or None
        Kernel cut-off radius; by default the calculator's parameter ``h``.
    keep_inside : bool
        With a calculator that has a ``domain``, attach
        :class:`~ase_sphrelax.drivers.keep_inside.KeepInDomain`: no step leaves the domain.
    **kwargs
        Passed to :class:`ase.optimize.optimize.Optimizer` (logfile, trajectory, ...).

    Attributes
    ----------
    last_step : float
        The displacement of the fastest particle in the last step (``c h``,
        or 0 when all forces vanish).
    """

    def __init__(self, atoms, c=0.01, h=None, logfile="-", keep_inside=True, **kwargs):
        self.c = check_c(c)  # Eq. 2.4 step coefficient
        h = calculator_h(atoms) if h is None else h
        if h is None:
            raise ValueError("h must be given, or the calculator must have a parameter 'h'")
        self.h = check_positive("h", h)
        self.last_step = 0.0
        self.keep_inside = attach_keep_inside(atoms) if keep_inside else None
        mark_scaled(atoms)  # Eq. 2.4 scales its own step: the ASE-defaults hint is not for it
        # ASE turns logfile=None into a Log that writes nothing, after computing E and |F| for it
        self._silent = logfile is None
        Optimizer.__init__(self, atoms, logfile=logfile, **kwargs)

    def initialize(self):
        self.last_step = 0.0

    def read(self):
        pass

    # -- the run loop, lean for small systems ------------------------------------
    # ASE's loop asks for the forces three times per step and computes the energy and the
    # force norm for its log even without a log file (logfile=None): for 8224 particles that
    # was a third of a step on top of the force evaluation (issue 9, item 3). Here run() hands
    # a step the gradient of the evaluation before it (unless an observer could have moved the
    # atoms), and a silent log costs nothing.
    def run(self, fmax=ASE_DEFAULT_FMAX, steps=DEFAULT_MAX_STEPS):
        """Run until ``max |F| < fmax`` or ``steps`` steps (as :meth:`ase.optimize.optimize.Optimizer.run`).

        Warns (:class:`~ase_sphrelax.drivers.step_scale.NothingRelaxedWarning`) when ``fmax > 0``
        stopped it at step 0: SPH forces are small, pass ``fmax=0`` to run all ``steps`` or an
        fmax relative to the forces.
        """
        converged = False
        self.fmax = fmax
        for converged in self._irun(steps, reuse_gradient=True):  # no code of the caller between the steps
            pass
        warn_if_nothing_relaxed(self, fmax, converged)
        return converged

    def irun(self, fmax=0.05, steps=DEFAULT_MAX_STEPS):
        """Generator of :meth:`run`, yielding ``converged`` after each step (as ASE's).

        One force request per step (ASE's loop makes two more, for its log and its
        convergence test, on unchanged atoms); the log, observers and trajectory are as
        ASE's. The caller may change the atoms between two yields, so each step asks for
        the forces again (the calculator's cache serves them if nothing changed); :meth:`run`,
        which runs no code between the steps, hands the step the gradient it has.
        """
        self.fmax = fmax
        return self._irun(steps)

    def _irun(self, steps, reuse_gradient=False):
        self.max_steps = self.nsteps + steps
        gradient = self.optimizable.get_gradient()
        if self.nsteps == 0:
            self.log(gradient)
            if self.trajectory is None or self._traj_is_empty():
                self.call_observers()
        is_converged = self.gradient_converged(gradient)
        yield is_converged
        while not is_converged and self.nsteps < self.max_steps:
            # an observer may have moved the atoms: then the step asks anew (from the calculator's cache);
            # no gradient is held through the step's own request or the next evaluation (1e6: 24 MB each)
            step_gradient, gradient = (gradient if reuse_gradient and not self.observers else None), None
            self._step(step_gradient)  # consumed in place
            step_gradient = None
            self.nsteps += 1
            gradient = self.optimizable.get_gradient()
            self.log(gradient)
            self.call_observers()
            is_converged = self.gradient_converged(gradient)
            yield is_converged

    def gradient_converged(self, gradient):
        if self.fmax <= 0.0:  # |F| < fmax <= 0 never holds: skip the norm (runs of a fixed step count)
            return False
        return Optimizer.gradient_converged(self, gradient)

    def log(self, gradient):
        if not self._silent:  # ASE computes the energy and |F| even without a log file
            Optimizer.log(self, gradient)

    def todict(self):
        description = Optimizer.todict(self)
        description.update(c=self.c, h=self.h)
        return description

    def step(self, f=None):
        self._step(None if f is None else self._get_gradient(f))  # ASE's warning for f

    def _step(self, gradient=None):
        """One Eq. 2.4 step from ``gradient`` (dE/dx, flat; None: asked for), which it overwrites."""
        # in place on ASE's fresh arrays: no temporaries of size N beyond them (1e6 particles)
        u = np.asarray(self.optimizable.get_gradient() if gradient is None else gradient, dtype=float)
        np.negative(u, out=u)  # U = -dE/dx (Eq. A.1), in ASE's fresh gradient array
        u_max = float(np.sqrt(_max_norm2(u.reshape(-1, 3))))
        if not np.isfinite(u_max):
            raise FloatingPointError("forces are not finite; cannot take an Eq. 2.4 step")
        if u_max == 0.0:
            self.last_step = 0.0
            return
        u *= self.c * self.h / u_max  # Eq. 2.4: dT = c h / max |U|
        x = self.optimizable.get_x()
        x += u
        self.optimizable.set_x(x)
        self.last_step = self.c * self.h
