"""Cheap first looks at a sampling target: its location and scale, and whether score and log-density agree.

Run once before SPH-ParVI starts, on a few points, with their own evaluation counter (the run's
``n_density``/``n_score`` stay the cost of the run itself).

* :func:`locate_target` -- a short diagonal Newton search for a mode: at the current point x and
  per-axis scale s, the score's central difference over ``x +- s_c e_c`` gives the curvature
  ``k_c = -d score_c / d x_c``; where ``k_c > 0`` the scale becomes ``1 / sqrt(k_c)`` and x moves by
  the Newton step ``score_c / k_c`` (at most ten scales per iteration, halved while it lowers log p when the
  log-density is given); where it is not, x stays
  and the scale doubles (the probe looks wider: between the modes of a mixture the secant over a
  wider span measures the spread of the whole target). A Gaussian is found in one step (any centre, any scale). A score
  whose finite values never show positive curvature, on any axis at any probed scale, points away
  from the mass everywhere: no normalisable density has it (a sign error), an error naming ``score``.
* :func:`check_score_matches_log_density` -- when both are given, the score against central
  differences of the log-density at a few points (relative mismatch beyond 1 % and beyond ten times
  the finite differences' own error): an error naming ``score`` (and saying when it is minus the gradient).
"""
from __future__ import annotations

import numpy as np

from .result import CountingTarget

__all__ = ["locate_target", "check_score_matches_log_density", "probe_target"]


def probe_target(target):
    """A second :class:`CountingTarget` on the same callables: the checks count their own evaluations."""
    return CountingTarget(target._log_density, target._score, target.dim, fd_step=target.fd_step)


def _score_or_nan(probe, x_pc):
    """The score at ``x_pc`` with NaN rows where it is not finite (a probe far away may leave the support)."""
    if not probe.has_score:
        return probe.fd_score_or_nan(x_pc)
    out = np.array(probe._score(x_pc), dtype=float)
    probe.n_score += x_pc.shape[0]
    if out.shape != x_pc.shape:
        raise ValueError(f"score must return shape {x_pc.shape} for points of shape {x_pc.shape}, got {out.shape}")
    out[~np.all(np.isfinite(out), axis=1)] = np.nan
    return out


def _backtrack(probe, x_c, step_c, halvings=40):
    """The Newton step halved until log p does not decrease (when the log-density is known): a secant curvature
    that underestimates an exponential (the logistic posterior's log-precision) would send x off to where the
    score overflows."""
    if not probe.has_density or not np.any(step_c):
        return step_c

    def log_p(x):
        with np.errstate(all="ignore"):
            out = float(np.asarray(probe._log_density(x[None, :]), dtype=float).ravel()[0])
        probe.n_density += 1
        return out if np.isfinite(out) else -np.inf

    here = log_p(x_c)
    if not np.isfinite(here):
        return step_c
    for _ in range(halvings):
        if log_p(x_c + step_c) >= here:
            return step_c
        step_c = 0.5 * step_c
    return np.zeros_like(step_c)


def locate_target(probe, dim, iterations=30):
    """A mode and per-axis scale of the target from its score (see the module docstring).

    Returns
    -------
    centre_c, scale_c : ndarray (d,)
        The point reached and the scale ``1 / sqrt(k_c)`` there (NaN where no positive curvature
        was seen: the caller keeps its own scale on that axis).
    """
    x_c = np.zeros(dim)
    s_c = np.ones(dim)
    found_c = np.zeros(dim, dtype=bool)
    informative = False
    eye = np.eye(dim)
    for _ in range(iterations):
        points = np.vstack([x_c[None, :], x_c + s_c[:, None] * eye, x_c - s_c[:, None] * eye])
        g_pc = _score_or_nan(probe, points)
        g0_c = g_pc[0]
        plus, minus = g_pc[1:dim + 1].diagonal(), g_pc[dim + 1:].diagonal()
        k_c = -(plus - minus) / (2.0 * s_c)
        ok_c = np.isfinite(k_c)
        informative |= bool(ok_c.any())
        convex_c = ok_c & (k_c > 0)
        found_c |= convex_c
        new_s_c = np.where(convex_c, 1.0 / np.sqrt(np.where(convex_c, k_c, 1.0)), 2.0 * s_c)
        if np.all(np.isfinite(g0_c)):
            step_c = np.where(convex_c, g0_c / np.where(convex_c, k_c, 1.0), 0.0)
            cap_c = 10.0 * np.maximum(s_c, new_s_c)
            step_c = np.clip(step_c, -cap_c, cap_c)
            step_c = _backtrack(probe, x_c, step_c)
        else:
            step_c = np.zeros(dim)
        settled = np.all(np.abs(step_c) <= 0.1 * new_s_c) and np.all(np.abs(new_s_c - s_c) <= 0.1 * s_c)
        x_c, s_c = x_c + step_c, new_s_c
        if settled or not np.all(np.isfinite(x_c)) or np.any(s_c > 1e150):
            break
    if informative and not found_c.any():
        raise ValueError("score: it points away from the probed points' centre on every axis at every scale probed "
                         "(no positive curvature of log p anywhere): no normalisable density has this score; "
                         "is its sign flipped? (it must be +grad log p)")
    return x_c, np.where(found_c, s_c, np.nan)


def check_score_matches_log_density(probe, x_pc, scale_c):
    """Compare the score with central differences of the log-density at the points ``x_pc`` (a few).

    Steps ``1e-4 scale_c`` and twice that; a point where either is not finite is skipped. Raises
    ValueError naming ``score`` when they disagree (see the module docstring).
    """
    if not (probe.has_score and probe.has_density):
        return
    m, d = x_pc.shape
    g_pc = _score_or_nan(probe, x_pc)
    fd = []
    for factor in (1.0, 2.0):
        step_c = 1e-4 * factor * scale_c
        out = np.empty_like(x_pc)
        for c in range(d):
            shift = np.zeros(d)
            shift[c] = step_c[c]
            out[:, c] = (probe.log_density(x_pc + shift) - probe.log_density(x_pc - shift)) / (2.0 * step_c[c])
        fd.append(out)
    fd_pc, fd2_pc = fd
    with np.errstate(invalid="ignore"):
        ok_p = np.all(np.isfinite(g_pc), axis=1) & np.all(np.isfinite(fd_pc), axis=1) & np.all(np.isfinite(fd2_pc),
                                                                                               axis=1)
    for a in np.nonzero(ok_p)[0]:
        mismatch = np.linalg.norm(g_pc[a] - fd_pc[a])
        size = np.linalg.norm(g_pc[a]) + np.linalg.norm(fd_pc[a])
        fd_error = np.linalg.norm(fd_pc[a] - fd2_pc[a])
        if mismatch > 1e-2 * size and mismatch > 10.0 * fd_error:
            flipped = np.linalg.norm(g_pc[a] + fd_pc[a]) <= 1e-2 * size
            hint = ("it is minus the gradient (a sign error)" if flipped else
                    "they describe different targets")
            raise ValueError(f"score does not match the gradient of log_density: at x = "
                             f"{np.array2string(x_pc[a], precision=4)} score = {np.array2string(g_pc[a], precision=4)}"
                             f" but central differences of log_density give "
                             f"{np.array2string(fd_pc[a], precision=4)}: {hint}")
