"""Friction rules for SPH-ParVI: a drag ``-B v`` that sets how fast the fluid comes to rest, not where.

The sampler damps velocities exactly, ``v <- exp(-B dt / 2) v`` around each kick (theory.py, eqs. F1-F3: any
symmetric positive semi-definite B, constant or renewed, leaves the resting states and hence the stationary
density unchanged). Rules:

* a number ``beta`` (or the default 1 / target scale): ``B = beta I``;
* ``"critical"``: ``B = Q diag(2 (alpha k_i)^(1/2)) Q^T`` from the particles' last scores (no extra
  evaluations), renewed every ``friction_every`` steps: Q the principal directions of the Fisher matrix
  ``F = mean_a s_a s_a^T`` and ``k_i`` the curvature of a typical particle along e_i, ``median_a (s_a . e_i)^2 /
  MEDIAN_CHI2_1``. Under p the Fisher matrix is the mean curvature of ``-log p`` (integration by parts:
  ``E_p[s s^T] = E_p[-Hess log p]``); for a Gaussian ``(s . e_i)^2`` is ``lambda_i`` times a chi-square with one
  degree of freedom, so the median over its median (0.4549) is ``lambda_i`` too, but unlike the mean it is not
  set by a stiff minority (the funnel's neck, where the curvature is e^9 times the mouth's, makes the mean 90x
  the typical value). Along e_i the fluid's slowest (centre-of-mass) mode has angular frequency
  ``omega_i = (alpha k_i)^(1/2)`` and the rate ``2 omega_i`` damps it critically: neither overdamped in a
  soft direction (a rate ``beta >> 2 omega`` makes it creep with rate ``omega^2 / beta``) nor underdamped in a
  stiff one. With whitened coordinates the scores are those of p_y, so the curvature is the whitened target's.
* ``friction_ramp`` r < 1 (any rule): the drag is multiplied by ``r^(1 - t / t_ramp)`` up to ``t_ramp``
  (the first half of the run): low friction while the fluid spreads, the rule's own afterwards.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

from ..models.parvi import CountingTarget

__all__ = ["FRICTION_RULES", "check_friction", "ScoreMemory", "critical_drag", "damp"]

#: The named friction rules (a number is a constant friction).
FRICTION_RULES = ("critical",)
#: The median of a chi-square variable with one degree of freedom.
MEDIAN_CHI2_1 = 0.45493642311957283
#: Eigenvalues of the Fisher matrix below this fraction of the largest are raised to it (a direction the scores do
#: not see would get no friction at all and never settle).
FISHER_FLOOR = 1e-6


def check_friction(friction):
    """None, a finite number >= 0, or a name of :data:`FRICTION_RULES`; a one-line error otherwise."""
    if friction is None or (isinstance(friction, str) and friction in FRICTION_RULES):
        return friction
    if isinstance(friction, bool) or not isinstance(friction, numbers.Real) or not math.isfinite(friction) \
            or friction < 0:
        raise ValueError(f"friction must be a finite number >= 0, None (1 / target scale) or one of "
                         f"{', '.join(repr(r) for r in FRICTION_RULES)}, got {friction!r}")
    return float(friction)


class ScoreMemory(CountingTarget):
    """A :class:`CountingTarget` that keeps the last score it computed for ``n`` points (``last_score``, (n, d)):
    the particles' scores of the last evaluation, for :func:`critical_drag`, at no extra evaluation.

    ``hold = True`` returns that last score again for ``n`` points, without evaluating or counting: the sampler's
    ``score_every`` (the score force held over several SPH steps; see :class:`~.sampler.ParVISampler`)."""

    def __init__(self, log_density=None, score=None, dim=None, n=None):
        super().__init__(log_density, score, dim)
        self.n = n
        self.last_score = None
        self.hold = False

    def _held(self, x_pc):
        return self.hold and self.last_score is not None and x_pc.shape[0] == self.n

    def _keep(self, g_pc):
        if g_pc.shape[0] == self.n:
            self.last_score = g_pc
        return g_pc

    def score(self, x_pc):
        return self.last_score if self._held(x_pc) else self._keep(super().score(x_pc))

    def fd_score_or_nan(self, x_pc):
        return self.last_score if self._held(x_pc) else self._keep(super().fd_score_or_nan(x_pc))


def critical_drag(score_pc, alpha):
    """``(q_cc, rate_c)``: the principal directions (columns) of the Fisher matrix ``mean_a s_a s_a^T`` of
    ``score_pc`` (M, d) and the damping rates ``2 (alpha k_i)^(1/2)`` of the critical friction, ``k_i =
    median_a (s_a·e_i)^2 / MEDIAN_CHI2_1`` (see the module docstring; non-finite rows ignored; curvatures
    floored at :data:`FISHER_FLOOR` times the largest). None when no score is finite or all vanish."""
    g_pc = np.asarray(score_pc, dtype=float)
    g_pc = g_pc[np.all(np.isfinite(g_pc), axis=1)]
    if g_pc.shape[0] == 0:
        return None
    fisher_cc = g_pc.T @ g_pc / g_pc.shape[0]
    _, q_cc = np.linalg.eigh(fisher_cc)
    lam_c = np.median((g_pc @ q_cc) ** 2, axis=0) / MEDIAN_CHI2_1
    top = float(lam_c.max())
    if not math.isfinite(top) or top <= 0:
        return None
    lam_c = np.maximum(lam_c, FISHER_FLOOR * top)
    return q_cc, 2.0 * np.sqrt(alpha * lam_c)


def damp(v_pc, dt, friction, drag, out=None):
    """``exp(-B dt / 2) v`` for rows ``v_pc`` (M, d): ``B = friction I`` when ``drag`` is None, else
    ``B = Q diag(rate) Q^T`` with ``drag = (Q, rate)``; ``dt`` a number or per-particle steps (M, 1).
    ``out``: an (M, d) array for the result (it may be ``v_pc`` itself), else a new one."""
    if drag is None:
        return np.multiply(v_pc, math.exp(-0.5 * friction * dt) if np.isscalar(dt) else np.exp(-0.5 * friction * dt),
                           out=out)
    q_cc, rate_c = drag
    return np.matmul((v_pc @ q_cc) * np.exp(-0.5 * dt * rate_c), q_cc.T, out=out)
