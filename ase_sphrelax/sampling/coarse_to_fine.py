"""Coarse-to-fine SPH-ParVI: settle M / k particles first, split each into k children, finish at M.

Why. The CFL step is ``dt ∝ H ∝ M^(-1/d)``: at a fixed number of steps the physical time a run covers shrinks with
M, and a target with a slow direction (the banana, x0 of standard deviation 10) is not spread at M = 2000 after 1000
steps (reproductions/parvi-banana-m2000/). A fluid of ``M_c = M / k`` particles has supports ``k^(1/d)``
times wider, steps ``k^(1/d)`` times longer and costs ``1/k`` of the evaluations per step of a final particle: for
the same evaluations per final particle it covers ``k^(1 + 1/d)`` times the time (8x in 2D with k = 4). The large
scales settle there; the fine fluid then has only to relax the scale of one parent's cell.

The budget (:func:`coarse_schedule`), in evaluations per final particle ``S`` (the ``steps`` of the sampler): a share
``f`` goes to the coarse level, ``S_c = floor(f S M / M_c)`` steps of ``M_c`` particles, the rest to
``S_f = S - ceil(S_c M_c / M)`` steps of M particles, so that ``M_c S_c + M S_f <= M S``: the coarse level's
evaluations are charged to the run (``SampleResult.n_score`` / ``n_density`` hold both levels').

The split (:func:`split_into_children`): parent a, of volume ``V_a = m / rho_a`` (its share of the fluid, in the
fluid's coordinates), becomes ``c_a`` children (:func:`child_counts`: ``k`` each, one more for the first ``M mod M_c``
parents) at the parent plus the offsets of a pattern of zero mean in the cube of volume ``V_a`` around it: the cell
centres of a ``j^d`` sub-grid when ``c_a = j^d`` (2D, k = 4: a 2 x 2 grid at spacing ``V_a^(1/d) / 2``, the fine
fluid's), else ``c_a`` stratified points of the cube with their mean removed (within the cube of twice the side); each pattern turned by a seeded random
rotation. Every parent's children have the parent's position as their mean (the ensemble mean is kept exactly, to
round-off) and start at rest.

What is exact. The fine level is the unchanged fluid of M particles (the same options, started from the children):
its resting states, hence the stationary density, are those of the one-level run (theory.py; the split only sets
the initial condition, as ``x0`` does). The coarse level samples p at M_c with the discretisation error of M_c.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["check_coarse_options", "coarse_schedule", "child_counts", "child_pattern", "split_into_children"]


def check_coarse_options(coarse_to_fine, coarse_share):
    """``coarse_to_fine`` None or an integer >= 2, ``coarse_share`` in (0, 1); one-line errors otherwise."""
    if coarse_to_fine is not None and (isinstance(coarse_to_fine, bool)
                                       or not isinstance(coarse_to_fine, (int, np.integer)) or coarse_to_fine < 2):
        raise ValueError(f"coarse_to_fine must be None or an integer >= 2 (final particles per coarse particle), "
                         f"got {coarse_to_fine!r}")
    if isinstance(coarse_share, bool) or not isinstance(coarse_share, numbers.Real) \
            or not 0.0 < float(coarse_share) < 1.0:
        raise ValueError(f"coarse_share must be a number in (0, 1) (the share of the evaluations spent on the coarse "
                         f"level), got {coarse_share!r}")
    return (None if coarse_to_fine is None else int(coarse_to_fine)), float(coarse_share)


def coarse_schedule(n, steps, factor, share):
    """``(n_coarse, coarse_steps, fine_steps)`` with ``n_coarse coarse_steps + n fine_steps <= n steps``.

    ``n_coarse = n // factor`` particles run ``floor(share steps n / n_coarse)`` steps, the n final particles
    ``steps - ceil(coarse_steps n_coarse / n)`` (see the module docstring). Errors (one line) when fewer than 2
    coarse particles or no fine step remain.
    """
    n_coarse = int(n) // int(factor)
    if n_coarse < 2:
        raise ValueError(f"coarse_to_fine={factor}: n // coarse_to_fine = {n_coarse} coarse particles; needs >= 2 "
                         f"(use a smaller factor or more particles)")
    coarse_steps = int(math.floor(share * steps * n / n_coarse))
    # the integer form of ceil(coarse_steps n_coarse / n): no round-off in the budget
    fine_steps = int(steps) - (-(-coarse_steps * n_coarse // int(n)))
    if fine_steps < 1:
        raise ValueError(f"coarse_share={share}: no step left for the {n} final particles out of steps={steps}; "
                         f"use a smaller coarse_share or more steps")
    return n_coarse, coarse_steps, fine_steps


def child_counts(n, n_coarse):
    """Children per parent (n_coarse,): ``n // n_coarse`` each, one more for the first ``n mod n_coarse``."""
    counts_p = np.full(int(n_coarse), int(n) // int(n_coarse), dtype=np.int64)
    counts_p[: int(n) % int(n_coarse)] += 1
    return counts_p


def child_pattern(count, dim, rng):
    """Offsets (count, dim) of zero mean in the unit cube centred at 0: a ``j^dim`` grid of cell centres when
    ``count = j^dim``, else ``count`` stratified points (one per slab along a random axis order) minus their mean."""
    j = int(round(count ** (1.0 / dim)))
    if j**dim == count:
        axis = (np.arange(j) + 0.5) / j - 0.5
        grid = np.meshgrid(*([axis] * dim), indexing="ij")
        return np.stack([g.ravel() for g in grid], axis=1)
    offsets = rng.uniform(-0.5, 0.5, size=(count, dim))
    offsets[:, 0] = (rng.permutation(count) + rng.uniform(size=count)) / count - 0.5
    return offsets - offsets.mean(axis=0)


def _random_rotation(rng, dim):
    if dim == 1:
        return np.ones((1, 1))
    q, r = np.linalg.qr(rng.standard_normal((dim, dim)))
    return q * np.sign(np.diag(r))


def split_into_children(r_pc, volume_p, counts_p, seed=0):
    """The children (sum counts, d) of parents ``r_pc`` (P, d) of volumes ``volume_p`` (P,): parent a's ``counts_p[a]``
    children, in order, at ``r_a + V_a^(1/d) R_a u_i`` with u the :func:`child_pattern` and R_a a seeded random
    rotation; their mean is ``r_a`` (to round-off)."""
    r_pc = np.asarray(r_pc, dtype=float)
    volume_p = np.asarray(volume_p, dtype=float)
    counts_p = np.asarray(counts_p)
    if r_pc.ndim != 2 or volume_p.shape != (r_pc.shape[0],) or counts_p.shape != (r_pc.shape[0],):
        raise ValueError(f"r_pc (P, d), volume_p (P,) and counts_p (P,) must agree, got {r_pc.shape}, "
                         f"{volume_p.shape}, {counts_p.shape}")
    if not (np.all(np.isfinite(volume_p)) and np.all(volume_p >= 0)) or np.any(counts_p < 1):
        raise ValueError("volume_p must be finite and >= 0 and counts_p >= 1")
    dim = r_pc.shape[1]
    rng = np.random.default_rng([int(seed) if isinstance(seed, (int, np.integer)) else 0, 4051])
    side_p = volume_p ** (1.0 / dim)
    out = []
    for a in range(r_pc.shape[0]):
        pattern = child_pattern(int(counts_p[a]), dim, rng) @ _random_rotation(rng, dim).T
        out.append(r_pc[a] + side_p[a] * (pattern - pattern.mean(axis=0)))
    return np.concatenate(out, axis=0)
