"""``hold_max="scaled"``: a per-particle score hold whose length grows with M so that the physical time one score
evaluation covers does not shrink with M.

With adaptive supports (about ``n_neighbours`` particles per support) H scales like ``M^(-1/d)``, and so does the
CFL step: at a fixed ``hold_max`` a budget of score evaluations covers ``M^(-1/d)`` times less physical time at
larger M (issue 18: "at a fixed number of steps it gets worse with M"). The rule

    hold_max(M, d) = max(1, round(HOLD_MAX * (M / SCALED_HOLD_REFERENCE_N)^(1/d)))      (S1)

keeps the time per evaluation about that of ``hold_max = HOLD_MAX`` at ``M = SCALED_HOLD_REFERENCE_N``: 4 at
M = 500 and 8 at M = 2000 in 2D. The held score then also has a fixed age in physical time (the support, and the
displacement the hold tolerates, ``hold_tolerance min(H, 1/|s|)``, shrink like the step). Any ``hold_max`` keeps the
resting states of ``score_every=1`` (:class:`~.sampler.ParVISampler`, ``score_every="adaptive"``), so the rule
leaves the stationary density unchanged. The reference M and the base were chosen on the funnel and the banana
(reproductions/parvi-rest-vs-time/).
"""
from __future__ import annotations

import numbers

__all__ = ["SCALED_HOLD_REFERENCE_N", "resolve_hold_max"]

#: The M at which ``hold_max="scaled"`` is the option's default ``HOLD_MAX``.
SCALED_HOLD_REFERENCE_N = 500


def resolve_hold_max(hold_max, n, dim, base):
    """``hold_max`` itself, or for ``"scaled"`` eq. S1 with ``base`` (the sampler's ``HOLD_MAX``) for ``n`` particles
    in ``dim`` dimensions. An ``n`` or ``dim`` that is not a positive integer returns ``base`` (the sampler's own
    checks name them)."""
    if not (isinstance(hold_max, str) and hold_max == "scaled"):
        return hold_max
    valid = all(isinstance(k, numbers.Integral) and not isinstance(k, bool) and k >= 1 for k in (n, dim))
    if not valid:
        return base
    return max(1, int(round(base * (n / SCALED_HOLD_REFERENCE_N) ** (1.0 / dim))))
