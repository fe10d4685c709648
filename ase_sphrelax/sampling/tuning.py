"""One tuning rule for the baselines' step sizes: a pilot over a log grid scored by the kernel Stein discrepancy.

SVGD's learning rate (and the factor on its median-heuristic bandwidth), ULA's and MALA's step sizes are all
chosen by the same procedure, which sees the target only through its score (and MALA's log density inside
MALA itself), never through reference samples:

1. **Pilot.** The method runs from the first ``min(M, pilot_particles)`` of the initial points for
   ``pilot_steps`` steps (by default the run's own number of evaluations per particle), once per candidate
   on the log grid ``10^(k/2)`` (half a decade apart) between ``low`` and ``high``
   (:data:`GRIDS`; SVGD: every learning rate with every bandwidth factor in ``{0.5, 1, 2}``).
2. **Score.** Each pilot's final points are scored by the squared kernel Stein discrepancy (Gorham and
   Mackey 2017, eq. 4; Liu, Lee and Jordan 2016, eq. 8) with the inverse multiquadric kernel
   ``k(x, y) = (c^2 + |x - y|^2)^(-1/2)``, a V-statistic that is zero in the limit only for samples
   of p and needs only the score ``s = grad log p``::

       KSD^2 = mean_ij [ s_i . s_j k_ij + s_i . grad_y k_ij + s_j . grad_x k_ij + tr grad_x grad_y k_ij ]

   One kernel serves all candidates of a method: ``c`` is the median over candidates of each pilot's
   median pairwise distance (robust against a diverged candidate; the criterion then scales with the target).
3. **Pick** the candidate of smallest KSD (a non-finite pilot scores ``inf``; ties: the first, smallest).

The pilot counts as tuning, not sampling: its evaluations are not charged to the run (the published
tables state the tuning cost separately). Cost: ``len(grid)`` pilots of ``pilot_particles`` points.
"""
from __future__ import annotations

import numpy as np

from . import baselines

__all__ = ["GRIDS", "log_grid", "kernel_stein_discrepancy", "tune"]

#: (low, high) of each method's log grid 10^(k/2); SVGD's bandwidth factors multiply the median heuristic.
GRIDS = dict(svgd=(1e-3, 10.0), ula=(1e-4, 1.0), mala=(1e-4, 1.0))
SVGD_BANDWIDTH_FACTORS = (0.5, 1.0, 2.0)


def log_grid(low, high):
    """The values ``10^(k/2)`` (k integer) in ``[low, high]``, ascending."""
    if not (0 < low <= high):
        raise ValueError(f"log_grid needs 0 < low <= high, got low={low!r}, high={high!r}")
    ks = np.arange(int(np.ceil(2 * np.log10(low) - 1e-9)), int(np.floor(2 * np.log10(high) + 1e-9)) + 1)
    return [float(10.0 ** (k / 2)) for k in ks]


def _median_distance(x_pc):
    diff = x_pc[:, None, :] - x_pc[None, :, :]
    r = np.sqrt(np.einsum("abc,abc->ab", diff, diff))[np.tril_indices(x_pc.shape[0], k=-1)]
    return float(np.median(r)) if r.size else 1.0


def kernel_stein_discrepancy(x_pc, score_pc, c):
    """Squared KSD (V-statistic) of the points ``x_pc`` (M, d) with scores ``score_pc``; IMQ kernel, beta -1/2.

    With ``q = c^2 + r^2``, ``k = q^(-1/2)``: ``grad_x k = -(x - y) q^(-3/2)``, ``grad_y k = -grad_x k``,
    ``tr grad_x grad_y k = d q^(-3/2) - 3 r^2 q^(-5/2)``. O(M^2 d); for pilots of a few hundred points.
    """
    x_pc = np.asarray(x_pc, dtype=float)
    s_pc = np.asarray(score_pc, dtype=float)
    if not (np.all(np.isfinite(x_pc)) and np.all(np.isfinite(s_pc))):
        return float("inf")
    d = x_pc.shape[1]
    diff = x_pc[:, None, :] - x_pc[None, :, :]  # x_i - x_j
    r2 = np.einsum("ijc,ijc->ij", diff, diff)
    q = c * c + r2
    k = q ** -0.5
    q32 = q ** -1.5
    ss = s_pc @ s_pc.T
    # s_i . grad_{x_j} k(x_i, x_j) + s_j . grad_{x_i} k: grad_{x_i} k = -(x_i - x_j) q^-3/2
    cross = (np.einsum("ic,ijc->ij", s_pc, diff) - np.einsum("jc,ijc->ij", s_pc, diff)) * q32
    trace = d * q32 - 3.0 * r2 * q ** -2.5
    return float(np.mean(ss * k + cross + trace))


def _pilot(method, target, x0, steps, value, factor):
    if method == "svgd":
        return baselines.svgd(target["score"], x0, steps, lr=value, bandwidth_factor=factor).samples
    if method == "ula":
        return baselines.ula(target["score"], x0, steps, value, seed=0).samples
    return baselines.mala(target["log_density"], target["score"], x0, max(steps // 2, 1), value, seed=0).samples


def tune(method, score, x0, steps, log_density=None, pilot_particles=100, pilot_steps=None):
    """The step size (SVGD: learning rate and bandwidth factor) of smallest pilot KSD; see the module docstring.

    Parameters
    ----------
    method : {"svgd", "ula", "mala"}
    score : callable (M, d) -> (M, d)
    x0 : ndarray (M, d)
        The run's initial points; the pilot uses the first ``pilot_particles``.
    steps : int
        The run's evaluations per particle (MALA's pilot takes ``steps // 2`` steps, as its run does).
    log_density : callable or None
        Needed for MALA only.
    pilot_steps : int or None
        Default ``steps``.

    Returns
    -------
    dict
        ``value`` (the step size or learning rate), ``bandwidth_factor`` (SVGD; 1 otherwise), ``ksd``
        (the winner's), ``table`` (every candidate: value, factor, KSD), ``c`` (the IMQ constant),
        ``at_edge`` (the value is the grid's smallest or largest: widen :data:`GRIDS`).
    """
    if method not in GRIDS:
        raise ValueError(f"method must be one of {sorted(GRIDS)}, got {method!r}")
    if method == "mala" and log_density is None:
        raise ValueError("log_density is needed to tune MALA")
    x0 = np.asarray(x0, dtype=float)
    if x0.ndim != 2 or x0.shape[0] < 2:
        raise ValueError(f"x0 must have shape (M, d) with M >= 2, got {x0.shape}")
    pilot_steps = int(steps if pilot_steps is None else pilot_steps)
    if pilot_steps < 1:
        raise ValueError(f"pilot_steps must be >= 1, got {pilot_steps}")
    x_pilot = x0[: max(2, min(len(x0), int(pilot_particles)))]
    target = dict(score=score, log_density=log_density)
    factors = SVGD_BANDWIDTH_FACTORS if method == "svgd" else (1.0,)
    grid = log_grid(*GRIDS[method])
    candidates = [(v, f) for v in grid for f in factors]
    finals = []
    with np.errstate(all="ignore"):
        for value, factor in candidates:
            try:
                finals.append(_pilot(method, target, x_pilot, pilot_steps, value, factor))
            except (FloatingPointError, ValueError, OverflowError):
                finals.append(None)
        finite = [x for x in finals if x is not None and np.all(np.isfinite(x))]
        c = float(np.median([_median_distance(x) for x in finite])) if finite else 1.0
        c = c if np.isfinite(c) and c > 0 else 1.0
        table = []
        for (value, factor), x in zip(candidates, finals):
            ksd = float("inf") if x is None or not np.all(np.isfinite(x)) else \
                kernel_stein_discrepancy(x, score(x), c)
            table.append(dict(value=value, bandwidth_factor=factor, ksd=ksd if np.isfinite(ksd) else float("inf")))
    best = min(range(len(table)), key=lambda i: table[i]["ksd"])
    return dict(value=table[best]["value"], bandwidth_factor=table[best]["bandwidth_factor"],
                ksd=table[best]["ksd"], table=table, at_edge=table[best]["value"] in (grid[0], grid[-1]), c=c, pilot_steps=pilot_steps, pilot_particles=len(x_pilot))
