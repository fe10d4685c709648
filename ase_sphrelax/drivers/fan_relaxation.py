"""Fan et al.'s relaxation update (Eq. 2.4) as an ASE optimiser.

    r_i^{n+1} = r_i^n + U_i^n dT,   U_i^n = -dE/dx_i (Eq. A.1),   dT = c h / max_i |U_i^n|,

so the particle that moves most moves exactly ``c h`` per step (Eq. 2.5);
Appendix A uses ``c = 0.01``. In continuous time E decreases along the
trajectories (Eq. 3.18). With the fixed step length ``c h`` the discrete
iteration cannot settle: near the minimum it overshoots and E oscillates at a
floor set by ``c`` (measured in ``tests/test_fan_relaxation.py``). ASE's FIRE,
BFGS and LBFGS adapt their step and reach lower E with fewer force calls.
"""
from __future__ import annotations

import numpy as np
from ase.optimize.optimize import Optimizer

from ..checks import check_positive
from .keep_inside import attach_keep_inside
from .optimizers import ASE_DEFAULT_FMAX, check_c, mark_scaled, warn_if_nothing_relaxed

__all__ = ["FanRelaxation"]


def _calculator_h(atoms):
    calc = getattr(atoms, "calc", None)
    if calc is None and hasattr(atoms, "atoms"):  # a Filter
        calc = getattr(atoms.atoms, "calc", None)
    params = getattr(calc, "parameters", {}) or {}
    return params.get("h")


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
        h = _calculator_h(atoms) if h is None else h
        if h is None:
            raise ValueError("h must be given, or the calculator must have a parameter 'h'")
        self.h = check_positive("h", h)
        self.last_step = 0.0
        self.keep_inside = attach_keep_inside(atoms) if keep_inside else None
        mark_scaled(atoms)  # Eq. 2.4 scales its own step: the ASE-defaults hint is not for it
        Optimizer.__init__(self, atoms, logfile=logfile, **kwargs)

    def run(self, fmax=ASE_DEFAULT_FMAX, steps=None, **kwargs):
        """ASE's ``run``; warns when ``fmax > 0`` stopped it at step 0 (SPH forces are small: pass
        ``fmax=0`` to run all ``steps``, or an fmax relative to the forces)."""
        converged = Optimizer.run(self, fmax=fmax, **({} if steps is None else {"steps": steps}), **kwargs)
        warn_if_nothing_relaxed(self, fmax, converged)
        return converged

    def initialize(self):
        self.last_step = 0.0

    def read(self):
        pass

    def todict(self):
        description = Optimizer.todict(self)
        description.update(c=self.c, h=self.h)
        return description

    def step(self, f=None):
        u_pc = -self._get_gradient(f).reshape(-1, 3)  # U = -dE/dx (Eq. A.1)
        u_max = float(np.sqrt((u_pc * u_pc).sum(axis=1)).max())
        if not np.isfinite(u_max):
            raise FloatingPointError("forces are not finite; cannot take an Eq. 2.4 step")
        if u_max == 0.0:
            self.last_step = 0.0
            return
        dt = self.c * self.h / u_max  # Eq. 2.4: dT = c h / max |U|
        self.optimizable.set_x(self.optimizable.get_x() + dt * u_pc.ravel())
        self.last_step = self.c * self.h
