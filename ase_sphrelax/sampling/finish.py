"""Exact finishing moves for SPH-ParVI: p-invariant kernels applied to the fluid's final state (issue 18).

Above a few dimensions the k-NN fluid does not rest at p (theory.py, eqs. K5-K7): on the 32-D logistic posterior
its marginal sds are 1.10-1.24 of NUTS's and a few particles rest far in a tail
(``reproductions/parvi-logistic-goal/``). ``finish=`` runs, after the fluid, a Markov kernel that leaves p
invariant exactly, in the fluid's frame (the frozen whitening map ``x = c + L y``, or the particles' mean and
Cholesky covariance factor without one; theory.py, eqs. G1-G5):

* ``"mala"`` (:func:`mala_finish`, the remedy): ``steps`` Metropolis-adjusted Langevin steps per particle in y,
  ``y' = y + (eps/2) grad log p_y(y) + sqrt(eps) xi``, accepted with the Metropolis-Hastings ratio (one score and
  one log-density per particle and step). The first quarter adapts ``eps`` to an ensemble acceptance of 0.574
  (from ``d^(-1/3)``); the rest draws each step's ``eps`` as ``eps_max * spread^(-U)``, U uniform on (0, 1),
  independent of the state: a mixture of p-invariant kernels (G3), whose small steps free particles stranded
  where the curvature is large (the funnel-like neck of the posterior's log-precision);
* ``"radial"`` (:func:`refill_radii`, the diagnosis): every particle keeps its direction u from the centre and its
  radius is redrawn from the exact conditional ``pi(r | u) ∝ r^(d-1) p(c + L r u)`` by univariate slice sampling
  (Neal 2003: stepping out with width ``width``, at most ``max_out`` steps, then shrinkage), ``steps`` updates:
  the thin shell's radial profile replaced by the exact one (G1-G2); log-densities only.

Both are exact for a linear change of variables (G4): the frame is affine equivariant, the moves are made in y with
the same random numbers, and ``log p`` differs by a constant, which cancels in every acceptance and slice
decision.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["refill_radii", "mala_finish", "check_finish", "ellipsoid_frame", "FINISH_STEP_SPREAD",
           "FINISH_ACCEPTANCE"]

#: ``finish="mala"``: after the adaptation each step's eps is ``eps_max * FINISH_STEP_SPREAD^(-U)``, U ~ U(0, 1).
FINISH_STEP_SPREAD = 16.0
#: ``finish="mala"``: the ensemble acceptance the adaptation aims at (Roberts and Rosenthal 1998).
FINISH_ACCEPTANCE = 0.574


def check_finish(finish, finish_steps, rule):
    """``finish`` None, ``"mala"`` or ``"radial"``; ``finish_steps`` an integer >= 1; ``rule="final"`` with a
    finish; one-line errors naming the parameter."""
    if finish is not None and not (isinstance(finish, str) and finish in ("mala", "radial")):
        raise ValueError(f"finish must be None, 'mala' or 'radial', got {finish!r}")
    if isinstance(finish_steps, bool) or not isinstance(finish_steps, (int, np.integer)) or finish_steps < 1:
        raise ValueError(f"finish_steps must be an integer >= 1, got {finish_steps!r}")
    if finish is not None and rule != "final":
        raise ValueError(f"finish={finish!r} moves the final particles: it needs rule='final', got {rule!r}")
    return finish, int(finish_steps)


def ellipsoid_frame(x_pc):
    """``(c, L)``: the particles' mean and the Cholesky factor of their covariance (equivariant under a linear map
    up to a rotation of the frame, theory.py G4); a one-line error when the covariance is singular."""
    x_pc = np.asarray(x_pc, dtype=float)
    cov_cc = np.atleast_2d(np.cov(x_pc, rowvar=False))
    try:
        return x_pc.mean(axis=0), np.linalg.cholesky(cov_cc)
    except np.linalg.LinAlgError:
        raise ValueError(f"finish: the particles' covariance is singular ({x_pc.shape[0]} particles in "
                         f"{x_pc.shape[1]} dimensions); use whiten='covariance' (the finish then runs in the map's "
                         f"frame) or more particles") from None


def refill_radii(x_pc, log_density, centre_c, l_cc, sweeps, rng, width=1.0, max_out=20):
    """Redraw every particle's radius about ``centre_c`` in the frame ``L`` (module docstring, eq. G1).

    Parameters
    ----------
    x_pc : ndarray (M, d)
    log_density : callable
        ``(n, d) -> (n,)``, vectorised; called on the particles still being updated only.
    centre_c : ndarray (d,)
    l_cc : ndarray (d, d)
        Invertible; ``z = L^-1 (x - c)``, ``r = |z|``, ``u = z / r``.
    sweeps : int
        Slice-sampling updates per particle.
    rng : numpy.random.Generator
    width : float
        Stepping-out width in units of r (the whitened units: the radial sd of a unit Gaussian is about 0.7 in
        any dimension).
    max_out : int
        Most stepping-out steps per update (Neal's m; the stepping-out split is random, as the proof needs).

    Returns
    -------
    x_pc : ndarray (M, d)
        The particles with their radii redrawn.
    info : dict
        ``evaluations`` (log-density calls per particle, all sweeps), ``radius_before``/``radius_after``
        (mean and sd of r).
    """
    x_pc = np.asarray(x_pc, dtype=float)
    m, d = x_pc.shape
    centre_c = np.asarray(centre_c, dtype=float)
    l_cc = np.atleast_2d(np.asarray(l_cc, dtype=float))
    z_pc = np.linalg.solve(l_cc, (x_pc - centre_c).T).T
    r_p = np.sqrt(np.einsum("pc,pc->p", z_pc, z_pc))
    if not np.all(r_p > 0):
        raise ValueError("finish='radial': a particle sits at the centre (its direction is undefined)")
    u_pc = z_pc / r_p[:, None]
    before = (float(r_p.mean()), float(r_p.std()))
    calls = 0

    def log_f(r_n, rows):
        """``(d - 1) log r + log p(c + L r u)`` for the particles ``rows`` at radii ``r_n``; -inf for r <= 0."""
        nonlocal calls
        out = np.full(r_n.shape, -np.inf)
        pos = r_n > 0
        if np.any(pos):
            sel = rows[pos]
            pts = centre_c + (r_n[pos, None] * u_pc[sel]) @ l_cc.T
            out[pos] = (d - 1) * np.log(r_n[pos]) + np.asarray(log_density(pts), dtype=float)
            calls += int(pos.sum())
        return out

    every = np.arange(m)
    f_p = log_f(r_p, every)
    if not np.all(np.isfinite(f_p)):
        raise ValueError("finish='radial': log_density is not finite at a particle")
    for _ in range(int(sweeps)):
        level_p = f_p - rng.exponential(size=m)
        left_p = r_p - width * rng.random(m)
        right_p = left_p + width
        steps_left = np.floor(max_out * rng.random(m)).astype(int)
        steps_right = max_out - 1 - steps_left
        for edge_p, budget_p, sign in ((left_p, steps_left, -1.0), (right_p, steps_right, 1.0)):
            active = np.nonzero(budget_p > 0)[0]
            while active.size:  # step out while the edge is inside the slice
                inside = log_f(edge_p[active], active) > level_p[active]
                active = active[inside]
                edge_p[active] += sign * width
                budget_p[active] -= 1
                active = active[budget_p[active] > 0]
        new_r_p = r_p.copy()
        new_f_p = f_p.copy()
        active = every
        while active.size:  # shrinkage
            trial = left_p[active] + rng.random(active.size) * (right_p[active] - left_p[active])
            f_trial = log_f(trial, active)
            accept = f_trial > level_p[active]
            new_r_p[active[accept]] = trial[accept]
            new_f_p[active[accept]] = f_trial[accept]
            rest, t_rest = active[~accept], trial[~accept]
            below = t_rest < r_p[rest]
            left_p[rest[below]] = t_rest[below]
            right_p[rest[~below]] = t_rest[~below]
            active = rest
        r_p, f_p = new_r_p, new_f_p
    x_new = centre_c + (r_p[:, None] * u_pc) @ l_cc.T
    return x_new, dict(evaluations=calls / m, radius_before=before, radius_after=(float(r_p.mean()),
                                                                                 float(r_p.std())))


def mala_finish(x_pc, log_density, score, centre_c, l_cc, steps, rng, spread=FINISH_STEP_SPREAD,
                acceptance=FINISH_ACCEPTANCE, record=None):
    """Metropolis-adjusted Langevin steps for every particle in the frame ``x = c + L y`` (module docstring; G3).

    Parameters
    ----------
    x_pc : ndarray (M, d)
    log_density, score : callable
        Vectorised ``(n, d) -> (n,)`` and ``(n, d) -> (n, d)`` in x; the score is called only where the proposal's
        log-density is finite.
    centre_c, l_cc : ndarray (d,), (d, d)
        The frame (``L`` invertible); the target in y is ``p_y(y) ∝ p(c + L y)``, its score ``L^T s(x)``.
    steps : int
        MALA steps per particle; the first ``steps // 4`` adapt ``eps`` (from ``d^(-1/3)``, ``log eps += a - 0.574``
        with ``a`` the ensemble's acceptance of the step), the rest draw ``eps = eps_max * spread^(-U)``.
    rng : numpy.random.Generator
    record : callable or None
        Called as ``record(step, x_pc)`` after every step (``step`` from 0; the adaptation's steps are the first
        ``steps // 4``), e.g. to average statistics along the chains (:func:`~.verdict.mala_check`).

    Returns
    -------
    x_pc : ndarray (M, d)
    info : dict
        ``eps_max`` (the adapted step), ``acceptance`` (mean over the ensemble of the non-adapting steps),
        ``adapt_steps``, ``stuck_share`` (particles that accepted none of those steps).
    """
    x_pc = np.asarray(x_pc, dtype=float)
    m, d = x_pc.shape
    centre_c = np.asarray(centre_c, dtype=float)
    l_cc = np.atleast_2d(np.asarray(l_cc, dtype=float))
    to_x = lambda y: centre_c + y @ l_cc.T  # noqa: E731
    y_pc = np.linalg.solve(l_cc, (x_pc - centre_c).T).T
    logp_p = np.asarray(log_density(x_pc), dtype=float)
    if not np.all(np.isfinite(logp_p)):
        raise ValueError("finish='mala': log_density is not finite at a particle")
    g_pc = np.asarray(score(x_pc), dtype=float) @ l_cc
    eps = float(d) ** (-1.0 / 3.0)
    adapt = int(steps) // 4
    accepted_p = np.zeros(m)
    rates = []
    for step in range(int(steps)):
        step_eps = eps if step < adapt else eps * spread ** (-rng.random())
        noise_pc = rng.standard_normal((m, d))
        prop_pc = y_pc + 0.5 * step_eps * g_pc + math.sqrt(step_eps) * noise_pc
        logp_new = np.asarray(log_density(to_x(prop_pc)), dtype=float)
        finite = np.isfinite(logp_new)
        g_new = np.zeros_like(g_pc)
        if np.any(finite):
            g_new[finite] = np.asarray(score(to_x(prop_pc[finite])), dtype=float) @ l_cc
        forward = -0.5 * np.einsum("pc,pc->p", noise_pc, noise_pc)
        back_pc = y_pc - prop_pc - 0.5 * step_eps * g_new
        backward = -np.einsum("pc,pc->p", back_pc, back_pc) / (2.0 * step_eps)
        with np.errstate(invalid="ignore"):
            log_ratio = np.where(finite, logp_new - logp_p + backward - forward, -np.inf)
        accept = np.log(rng.random(m)) < log_ratio
        y_pc[accept], logp_p[accept], g_pc[accept] = prop_pc[accept], logp_new[accept], g_new[accept]
        rate = float(accept.mean())
        if step < adapt:
            eps *= math.exp(rate - acceptance)
        else:
            rates.append(rate)
            accepted_p += accept
        if record is not None:
            record(step, to_x(y_pc))
    return to_x(y_pc), dict(eps_max=eps, acceptance=float(np.mean(rates)) if rates else None, adapt_steps=adapt,
                            stuck_share=float(np.mean(accepted_p == 0)) if rates else None)
