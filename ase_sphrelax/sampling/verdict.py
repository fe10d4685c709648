"""Is the sample right? The evidence behind SPH-ParVI's ``converged`` (issue 31).

"At rest" (:mod:`.convergence`) is a property of the fluid, not evidence that the particles follow p: a fluid
trapped in one mode of a mixture, or resting at a biased state, is at rest too. The log-density and the score
the user gives make three checks possible; :func:`judge_run` runs them on the final particles, with their own
evaluation counter (``info["n_check_density"]``, ``info["n_check_score"]``; not the run's cost):

1. **An exact short MALA chain** (:func:`mala_check`). Every particle is moved by ``steps`` Metropolis-adjusted
   Langevin steps (:func:`~.finish.mala_finish` in the frame ``x = c + L z`` of the particles' mean and Cholesky
   covariance factor, its step adapted over the first quarter to an acceptance of 0.574, then fixed: a p-invariant
   kernel, theory.py G3). If the particles follow p, so do the moved ones at every step, and for any statistic f
   the paired differences ``D_a = mean_t f(z_a,t) - f(z_a,0)`` (f averaged along particle a's chain over the second
   half of its steps) have mean zero, so ``t = mean(D) / (sd(D) / sqrt(M))`` is close to N(0, 1). The statistics
   are the d means and the d (d + 1) / 2 second moments ``z_i z_j`` of the whitened particles: K of them. The
   check fails when one ``|t|`` exceeds the Bonferroni bound ``z_(1 - alpha / (2 K))`` with ``alpha =``
   :data:`VERDICT_ALPHA` / 2 (a false-alarm rate of at most about alpha on exact samples; measured on
   i.i.d. samples of the built-in targets in ``reproductions/parvi-verdict/``). A sample whose mean or covariance
   is off is moved towards p by the chain: its t statistics grow like ``sqrt(M)`` times the share of the bias the
   chain removes in ``steps`` steps (slow directions, e.g. along the banana's arms, are removed slowly).
2. **A mode search** (:func:`mode_search`). Gradient ascent of log p in the particles' frame, from
   :data:`MODE_STARTS` starts drawn :data:`WIDEN` times wider than the particles, from a few particles and from the
   given extra points (the origin, the automatic start's mode); each end point polished by a Newton step and kept
   as a mode when its Hessian is negative definite (a ridge, e.g. the donut's circle, is not an isolated mode).
   Each isolated mode has a Laplace share ``w_k ∝ p(m_k) det(-H_k)^(-1/2)``; with two or more, every particle is
   assigned to the mode of largest Laplace responsibility, and a mode is **missed** when ``w_k >=``
   :data:`MIN_SHARE` and the particles' share is below :data:`MISSED_FRACTION` of ``w_k``.

3. **An importance-sampling comparison of the tails** (:func:`importance_check`), for what the chain cannot move:
   particles stranded far out along a curved arm, where the chain's step (set by the arm's width in the frame of
   the whole ensemble) is rejected, and which inflate the second moments (the banana of other curvature at rest
   with var(y) 4.3 against 2.25). ``draws`` points from a proposal q built from the particles (:data:`IS_PROPOSAL`:
   Gaussian kernel density estimates of them in their whitened frame at Scott's bandwidth and three times it, and
   a Gaussian twice as wide as them: q covers p's tails, along curved arms too) give self-normalised importance
   estimates of p's mean and covariance (p's frame, z') and of p's share ``s_a`` beyond each whitened radius
   ``|z'| > a``, a in :data:`IS_LEVELS`, with its standard error ``se_a``. The statistics are bounded (a
   heavy-tailed p, e.g. the funnel, has no usable second moments). With ``n_a`` of the M particles beyond a, the
   one-sided p-value is ``P(Binomial(M, s) >= n_a)`` averaged over ``s ~ N(s_a, se_a^2)`` (21 quantiles, floored at
   1 / ESS: a region no weighted draw reached); the check fails when the smallest, times the number of levels
   (Bonferroni), is below ``alpha =`` :data:`VERDICT_ALPHA` / 2. Too few particles in the tails (a collapsed sample)
   is the MALA check's case: the chain spreads them quickly. With an effective sample size below
   :data:`IS_MIN_ESS` (p far from the particles' cloud, high dimension) the check is **inconclusive** and does not
   fail (``conclusive`` False, the reason says so). Cost: ``draws`` log-density evaluations, no score.

The nominal false-alarm rate :data:`VERDICT_ALPHA` is split in half between checks 1 and 3.

:func:`judge_run`: ``converged = at rest and MALA check passed and importance check passed and no mode
missed``. A missed mode restarts the run once from ``x0`` drawn from the Laplace mixture of the isolated modes
found; missed again (or the MALA or importance check failing): ``converged`` False, the reason naming the
evidence. Without a log-density (or with ``check=False``) nothing can be checked and ``converged`` is the fluid
at rest, which ``info["verdict"]["checked"]`` says.
"""
from __future__ import annotations

import numpy as np
from scipy.special import logsumexp
from scipy.stats import binom, norm

from .finish import ellipsoid_frame, mala_finish
from .result import CountingTarget
from .target_checks import _score_or_nan

__all__ = ["mala_check", "importance_check", "mode_search", "judge_run", "VERDICT_ALPHA", "MALA_CHECK_STEPS",
           "IS_DRAWS", "IS_PROPOSAL", "IS_LEVELS", "IS_MIN_ESS", "MODE_STARTS", "WIDEN", "MIN_SHARE", "MISSED_FRACTION"]

#: The nominal false-alarm rate of the checks on exact samples: half for the MALA check, half for the importance
#: check (each Bonferroni over its statistics).
VERDICT_ALPHA = 0.01
#: The importance check's draws per particle (at least 4000 in all) and the effective sample size below which it is
#: inconclusive.
IS_DRAWS, IS_MIN_ESS = 20, 500
#: The importance check's tail levels (in p's whitened frame).
IS_LEVELS = (2.0, 3.0, 4.0, 5.0)
#: The importance check's proposal: (weight, width) parts; width > 0: a Gaussian kernel density estimate of the
#: particles with ``width`` times Scott's bandwidth, width < 0: a Gaussian of sd ``-width`` around their mean
#: (all in their whitened frame; the wider parts cover p's tails, along curved arms too).
IS_PROPOSAL = ((0.7, 1.0), (0.2, 3.0), (0.1, -2.0))
#: Particles used as the kernel density's centres (a random subset beyond it: the cost stays O(draws x 1000)).
IS_CENTRES = 1000
#: MALA steps per particle of the check.
MALA_CHECK_STEPS = 100
#: Starts of the mode search drawn from N(c, WIDEN^2 Sigma) (c, Sigma: the particles' mean and covariance).
MODE_STARTS, WIDEN = 32, 3.0
#: A mode is missed when its Laplace share is >= MIN_SHARE and the particles hold < MISSED_FRACTION of it.
MIN_SHARE, MISSED_FRACTION = 0.05, 0.25


def _statistics(z_pc):
    """The K = d + d (d + 1) / 2 statistics per particle (M, K): ``z_c`` and ``z_i z_j`` (i <= j), with names."""
    d = z_pc.shape[1]
    iu, ju = np.triu_indices(d)
    names = [f"mean of z[{c}]" for c in range(d)] + [f"second moment z[{i}] z[{j}]" for i, j in zip(iu, ju)]
    return np.hstack([z_pc, z_pc[:, iu] * z_pc[:, ju]]), names


def mala_check(x_pc, log_density, score, rng, steps=MALA_CHECK_STEPS, alpha=VERDICT_ALPHA / 2):
    """Do ``steps`` exact MALA steps move the particles' moments beyond their Monte-Carlo error? (module docstring)

    Parameters
    ----------
    x_pc : ndarray (M, d)
    log_density, score : callable
        Vectorised, in x (counted by the caller's wrapper).
    rng : numpy.random.Generator
    steps : int
    alpha : float
        Nominal false-alarm rate of the whole check (Bonferroni over the K statistics).

    Returns
    -------
    dict
        ``passed``, ``max_t`` (largest ``|t|``), ``bound`` (``z_(1 - alpha / (2K))``), ``worst`` (its statistic),
        ``statistics`` (K), ``steps``, ``alpha``, ``acceptance`` and ``eps`` of the chain, the particles' mean and
        variance before and after (``mean_before``, ``mean_after``, ``var_before``, ``var_after``, in x), ``reason``.
    """
    x_pc = np.asarray(x_pc, dtype=float)
    m, d = x_pc.shape
    centre_c, l_cc = ellipsoid_frame(x_pc)
    z0_pc = np.linalg.solve(l_cc, (x_pc - centre_c).T).T
    f0_pk, names = _statistics(z0_pc)
    f1_pk = np.zeros_like(f0_pk)
    averaged = []

    def record(step, x_now):  # the statistics averaged along each chain over the second half of its steps
        if step >= steps // 2:
            f1_pk[:] += _statistics(np.linalg.solve(l_cc, (x_now - centre_c).T).T)[0]
            averaged.append(step)

    moved_pc, chain = mala_finish(x_pc, log_density, score, centre_c, l_cc, steps, rng, spread=1.0, record=record)
    diff_pk = f1_pk / max(len(averaged), 1) - f0_pk
    se_k = diff_pk.std(axis=0, ddof=1) / np.sqrt(m)
    t_k = np.where(se_k > 0, diff_pk.mean(axis=0) / np.where(se_k > 0, se_k, 1.0), 0.0)
    bound = float(norm.isf(alpha / (2.0 * t_k.size)))
    worst = int(np.argmax(np.abs(t_k)))
    max_t = float(abs(t_k[worst]))
    moved_any = bool(chain["acceptance"] and chain["acceptance"] > 0)
    passed = moved_any and max_t <= bound
    if not moved_any:
        reason = f"the MALA check's chain accepted no move in {steps} steps: no evidence either way"
    else:
        reason = (f"{steps} exact MALA steps from the particles moved the {names[worst]} (whitened by the particles' "
                  f"mean and covariance; averaged over the chains' second half) by {abs(diff_pk[:, worst].mean()):.3g}, "
                  f"{max_t:.2f} standard errors "
                  f"({'within' if passed else 'beyond'} the bound {bound:.2f} of a {alpha:g} false-alarm rate "
                  f"over {t_k.size} statistics)")
    return dict(passed=bool(passed), max_t=max_t, bound=bound, worst=names[worst], statistics=int(t_k.size),
                steps=int(steps), alpha=float(alpha), acceptance=chain["acceptance"], eps=chain["eps_max"],
                mean_before=x_pc.mean(axis=0).tolist(), mean_after=moved_pc.mean(axis=0).tolist(),
                var_before=x_pc.var(axis=0, ddof=1).tolist(), var_after=moved_pc.var(axis=0, ddof=1).tolist(),
                reason=reason)


def _is_statistics(z_pc):
    """The importance check's statistics per point (M, len(IS_LEVELS)): ``1{|z| > a}`` for a in :data:`IS_LEVELS`,
    with names."""
    r_p = np.sqrt(np.sum(z_pc * z_pc, axis=1))
    return np.stack([r_p > a for a in IS_LEVELS], axis=1).astype(float), [f"share of |z| > {a:g}" for a in IS_LEVELS]


def importance_check(x_pc, log_density, rng, draws=None, alpha=VERDICT_ALPHA / 2):
    """Do the particles hold more of p's tails than p does, by importance sampling? (module docstring, check 3)

    Parameters
    ----------
    x_pc : ndarray (M, d)
    log_density : callable
        Vectorised, in x (counted by the caller's wrapper); the normalising constant is not needed.
    rng : numpy.random.Generator
    draws : int or None
        Proposal draws (log-density evaluations); None: ``max(4000, IS_DRAWS * M)``.
    alpha : float
        Nominal false-alarm rate of the whole check (Bonferroni over its levels).

    Returns
    -------
    dict
        ``passed``, ``conclusive`` (effective sample size >= :data:`IS_MIN_ESS`), ``p_value`` (Bonferroni-adjusted),
        ``worst`` (its level), ``max_t`` (its excess share in standard errors, for display), ``statistics``,
        ``draws``, ``ess``, ``alpha``, ``particle_value`` and ``target_value`` (the particles' and p's share beyond
        the worst level), ``reason``.
    """
    x_pc = np.asarray(x_pc, dtype=float)
    m, d = x_pc.shape
    draws = int(max(4000, IS_DRAWS * m) if draws is None else draws)
    if draws < 1:
        raise ValueError(f"draws must be >= 1, got {draws}")
    centre_c, l_cc = ellipsoid_frame(x_pc)
    z_pc = np.linalg.solve(l_cc, (x_pc - centre_c).T).T
    kc = z_pc if m <= IS_CENTRES else z_pc[rng.choice(m, size=IS_CENTRES, replace=False)]
    h = len(kc) ** (-1.0 / (d + 4))  # Scott's rule in the whitened frame
    weights = np.array([w for w, _ in IS_PROPOSAL])
    part_n = rng.choice(len(IS_PROPOSAL), size=draws, p=weights / weights.sum())
    u_nc = np.empty((draws, d))
    for j, (_, width) in enumerate(IS_PROPOSAL):
        rows = part_n == j
        n_j = int(rows.sum())
        around = np.zeros((n_j, d)) if width < 0 else kc[rng.integers(len(kc), size=n_j)]
        u_nc[rows] = around + (-width if width < 0 else width * h) * rng.standard_normal((n_j, d))
    log_q = np.full(draws, -np.inf)
    for (weight, width) in IS_PROPOSAL:
        if width < 0:  # the Gaussian around the particles' mean
            log_c = -0.5 * np.sum(u_nc**2, axis=1) / width**2 - d * np.log(-width)
        else:
            s2 = (width * h) ** 2
            log_c = np.empty(draws)
            for start in range(0, draws, 2000):  # in blocks: (2000, len(kc)) at a time
                u = u_nc[start:start + 2000]
                a = (u @ kc.T - 0.5 * np.sum(kc * kc, axis=1)[None]) / s2  # -|u - k|^2 / (2 s2) + |u|^2 / (2 s2)
                log_c[start:start + 2000] = logsumexp(a, axis=1) - 0.5 * np.sum(u * u, axis=1) / s2
            log_c -= np.log(len(kc)) + 0.5 * d * np.log(s2)
        log_q = np.logaddexp(log_q, np.log(weight / weights.sum()) + log_c - 0.5 * d * np.log(2.0 * np.pi))
    with np.errstate(all="ignore"):
        log_p = np.asarray(log_density(centre_c + u_nc @ l_cc.T), dtype=float).reshape(-1)
    log_w = np.where(np.isfinite(log_p), log_p - log_q, -np.inf)
    out = dict(statistics=len(IS_LEVELS), draws=draws, alpha=float(alpha))
    if not np.any(np.isfinite(log_w)):
        return dict(out, passed=True, conclusive=False, ess=0.0, max_t=None, worst=None, p_value=None,
                    reason=f"the importance check is inconclusive: log p is not finite at any of its {draws} draws")
    w_n = np.exp(log_w - log_w.max())
    w_n /= w_n.sum()
    ess = float(1.0 / np.sum(w_n**2))
    # p's frame (importance estimates of its mean and covariance): the particles and p's draws compared in it
    mu_c = w_n @ u_nc
    cov_cc = (u_nc - mu_c).T @ ((u_nc - mu_c) * w_n[:, None]) + 1e-12 * np.eye(d)
    try:
        lp_cc = np.linalg.cholesky(cov_cc)
    except np.linalg.LinAlgError:
        lp_cc = np.eye(d)
    f_pk, names = _is_statistics(np.linalg.solve(lp_cc, (z_pc - mu_c).T).T)
    f_nk = _is_statistics(np.linalg.solve(lp_cc, (u_nc - mu_c).T).T)[0]
    mean_k = w_n @ f_nk  # p's share beyond each level
    se_is_k = np.sqrt(np.sum(w_n[:, None] ** 2 * (f_nk - mean_k) ** 2, axis=0))  # the estimate's standard error
    # p's share, uncertain: N(mean, se^2) at 21 quantiles, floored at 1 / ESS (a region no weighted draw reached)
    share_jk = np.clip(mean_k + se_is_k * norm.ppf((np.arange(21) + 0.5) / 21.0)[:, None], 1.0 / ess, 1.0)
    count_k = f_pk.sum(axis=0)
    p_k = binom.sf(count_k - 1, m, share_jk).mean(axis=0)  # P(at least count_k of M beyond the level)
    upper_k = share_jk[-1]
    worst = int(np.argmin(p_k))
    p_value = float(min(1.0, p_k[worst] * len(p_k)))  # Bonferroni over the statistics
    max_t = float((count_k[worst] / m - mean_k[worst])
                  / np.sqrt(max(upper_k[worst] * (1.0 - upper_k[worst]), 1e-300) / m + se_is_k[worst] ** 2))
    conclusive = ess >= IS_MIN_ESS
    passed = (p_value > alpha) or not conclusive
    where = (f"the particles' {names[worst]} (in p's frame) is {f_pk[:, worst].mean():.3g}, p's by importance "
             f"sampling {mean_k[worst]:.3g} ({draws} draws, effective size {ess:.0f}; to {upper_k[worst]:.3g} at +2 "
             f"standard errors): {int(count_k[worst])} of {m} particles where {m * mean_k[worst]:.3g} are expected, "
             f"p-value {p_value:.3g} (binomial, Bonferroni over {len(p_k)} statistics)")
    if not conclusive:
        reason = (f"the importance check is inconclusive: its effective sample size {ess:.0f} is below {IS_MIN_ESS} "
                  f"(p is far from the particles' cloud); {where}")
    else:
        reason = f"{where} ({'above' if passed else 'below'} {alpha:g})"
    return dict(out, passed=bool(passed), conclusive=bool(conclusive), ess=ess, max_t=max_t, worst=names[worst],
                p_value=p_value, particle_value=float(f_pk[:, worst].mean()), target_value=float(mean_k[worst]),
                reason=reason)


def _log_p_or_minus_inf(probe, x_pc):
    """log p at the points, -inf where it is not finite (a start far out may overflow); counted."""
    with np.errstate(all="ignore"):
        out = np.asarray(probe._log_density(x_pc), dtype=float).reshape(-1)
    probe.n_density += x_pc.shape[0]
    return np.where(np.isfinite(out), out, -np.inf)


def _hessians(probe, z_nc, centre_c, l_cc, step=1e-4):
    """``-H`` in z (n, d, d) at the points z by central differences of the score along the frame's columns."""
    n, d = z_nc.shape
    a_ndd = np.empty((n, d, d))
    for j in range(d):
        e = np.zeros(d)
        e[j] = step
        gp = _score_or_nan(probe, centre_c + (z_nc + e) @ l_cc.T) @ l_cc
        gm = _score_or_nan(probe, centre_c + (z_nc - e) @ l_cc.T) @ l_cc
        a_ndd[:, :, j] = -(gp - gm) / (2.0 * step)
    return 0.5 * (a_ndd + np.transpose(a_ndd, (0, 2, 1)))


def mode_search(x_pc, probe, rng, extra=(), starts=MODE_STARTS, widen=WIDEN, iterations=300, particles=16):
    """Modes of p near and around the particles, their Laplace shares and the particles' shares (module docstring).

    Parameters
    ----------
    x_pc : ndarray (M, d)
        The particles (frame, starts, shares).
    probe : CountingTarget
        The target (needs the log-density), counting the search's evaluations.
    rng : numpy.random.Generator
    extra : sequence of (d,) points
        More starts (the origin, the automatic start's mode).

    Returns
    -------
    dict
        ``modes`` (isolated modes, each ``position``, ``log_p``, ``laplace_share``, ``particle_share``, ``missed``),
        ``ridges`` (stationary points whose Hessian is not definite: not used for shares), ``missed`` (the
        missed modes' indices), ``reason``; ``laplace`` (the frame and each mode's z and ``-H``, for
        :func:`laplace_draw`; not for JSON).
    """
    x_pc = np.asarray(x_pc, dtype=float)
    m, d = x_pc.shape
    centre_c, l_cc = ellipsoid_frame(x_pc)
    to_x = lambda z: centre_c + z @ l_cc.T  # noqa: E731
    pick = rng.choice(m, size=min(particles, m), replace=False)
    z_nc = np.vstack([widen * rng.standard_normal((starts, d)), np.linalg.solve(l_cc, (x_pc[pick] - centre_c).T).T]
                     + [np.linalg.solve(l_cc, np.asarray(p, dtype=float) - centre_c)[None, :] for p in extra
                        if p is not None and np.all(np.isfinite(p))])
    lp_n = _log_p_or_minus_inf(probe, to_x(z_nc))
    g_nc = _score_or_nan(probe, to_x(z_nc)) @ l_cc
    eta_n = np.full(len(z_nc), 0.5)
    active = np.isfinite(lp_n) & np.all(np.isfinite(g_nc), axis=1)
    for _ in range(iterations):  # ascent with a step per point: grown by 1.5 when log p rose, halved otherwise
        idx = np.nonzero(active)[0]
        if not idx.size:
            break
        trial = z_nc[idx] + eta_n[idx, None] * g_nc[idx]
        lp_t = _log_p_or_minus_inf(probe, to_x(trial))
        up = lp_t >= lp_n[idx]
        if np.any(up):
            g_t = _score_or_nan(probe, to_x(trial[up])) @ l_cc
            ok = np.all(np.isfinite(g_t), axis=1)
            rows = idx[up][ok]
            z_nc[rows], lp_n[rows], g_nc[rows] = trial[up][ok], lp_t[up][ok], g_t[ok]
            up[np.nonzero(up)[0][~ok]] = False
        eta_n[idx] = np.where(up, 1.5 * eta_n[idx], 0.5 * eta_n[idx])
        moved = eta_n[idx] * np.linalg.norm(g_nc[idx], axis=1)
        active[idx] = (moved > 1e-6) & (eta_n[idx] > 1e-12)
    ok_n = np.isfinite(lp_n) & np.all(np.isfinite(g_nc), axis=1)
    z_nc, lp_n, g_nc = z_nc[ok_n], lp_n[ok_n], g_nc[ok_n]
    a_ndd = _hessians(probe, z_nc, centre_c, l_cc) if len(z_nc) else np.zeros((0, d, d))
    modes, ridges = [], []
    for i in np.argsort(-lp_n):
        a_dd = a_ndd[i]
        if not np.all(np.isfinite(a_dd)):
            continue
        eig = np.linalg.eigvalsh(a_dd)
        isolated = eig.min() > 1e-3 * max(eig.max(), 0.0) and eig.max() > 0
        if isolated:  # one Newton step: where the ascent stopped short in a stiff direction
            z_i = z_nc[i] + np.linalg.solve(a_dd, g_nc[i])
            if np.linalg.norm(z_i - z_nc[i]) > 0.05:
                continue  # not at a stationary point
        else:
            z_i = z_nc[i]
            if np.linalg.norm(g_nc[i]) > 1e-3:
                continue
        near = [k for k in modes + ridges if np.linalg.norm(k["z"] - z_i) < 0.25]
        if near:
            continue
        entry = dict(z=z_i, a=a_dd, log_p=float(lp_n[i]))
        (modes if isolated else ridges).append(entry)
    out = dict(missed=[], ridges=[to_x(r["z"]).tolist() for r in ridges], modes=[],
               laplace=dict(centre=centre_c, l=l_cc, z=[k["z"] for k in modes], a=[k["a"] for k in modes]))
    if not modes:
        out["reason"] = "the mode search found no isolated mode (nothing to compare the particles' shares with)"
        return out
    logw = np.array([k["log_p"] - 0.5 * np.linalg.slogdet(k["a"])[1] for k in modes])
    w_k = np.exp(logw - logw.max())
    w_k /= w_k.sum()
    out["laplace"]["w"] = w_k
    z_pc = np.linalg.solve(l_cc, (x_pc - centre_c).T).T
    resp_pk = np.stack([k["log_p"] - 0.5 * np.einsum("pc,cd,pd->p", z_pc - k["z"], k["a"], z_pc - k["z"])
                        for k in modes], axis=1)
    share_k = np.bincount(np.argmax(resp_pk, axis=1), minlength=len(modes)) / m
    for k, mode in enumerate(modes):
        missed = len(modes) > 1 and w_k[k] >= MIN_SHARE and share_k[k] < MISSED_FRACTION * w_k[k]
        out["modes"].append(dict(position=to_x(mode["z"]).tolist(), log_p=mode["log_p"],
                                 laplace_share=float(w_k[k]), particle_share=float(share_k[k]), missed=bool(missed)))
        if missed:
            out["missed"].append(k)
    if out["missed"]:
        out["reason"] = "; ".join(f"a mode at {np.array2string(to_x(modes[k]['z']), precision=3)} holds "
                                  f"{share_k[k]:.1%} of the particles against its Laplace share {w_k[k]:.1%}"
                                  for k in out["missed"])
    else:
        out["reason"] = (f"{len(modes)} isolated mode(s) found, none short of its Laplace share" if len(modes) > 1
                         else "one isolated mode found: no other mode to miss")
    return out


def laplace_draw(laplace, n, rng):
    """``n`` points of the Laplace mixture of the modes found (``mode_search(...)["laplace"]``), in x."""
    w_k = np.asarray(laplace["w"])
    k_p = rng.choice(len(w_k), size=n, p=w_k)
    d = len(laplace["centre"])
    z_pc = np.empty((n, d))
    for k in range(len(w_k)):
        rows = k_p == k
        cov_dd = np.linalg.inv(laplace["a"][k])
        z_pc[rows] = laplace["z"][k] + rng.standard_normal((int(rows.sum()), d)) @ np.linalg.cholesky(cov_dd).T
    return laplace["centre"] + z_pc @ laplace["l"].T


def _evidence(x_pc, probe, rng, extra):
    """The MALA check, the importance check and the mode search on the particles: ``(mala, importance, modes)``; a
    failure to run a check is a failed check with its reason."""
    try:
        mala = mala_check(x_pc, probe.log_density, probe.score, rng)
    except ValueError as error:
        mala = dict(passed=False, reason=f"the MALA check could not run: {error}")
    try:
        importance = importance_check(x_pc, probe.log_density, rng)
    except ValueError as error:
        importance = dict(passed=False, conclusive=False, reason=f"the importance check could not run: {error}")
    try:
        modes = mode_search(x_pc, probe, rng, extra=extra)
    except (ValueError, np.linalg.LinAlgError) as error:
        modes = dict(missed=[], modes=[], ridges=[], reason=f"the mode search could not run: {error}")
    return mala, importance, modes


def judge_run(sampler, result):
    """``converged`` of a finished run (:class:`~.sampler.ParVISampler`'s ``run``) from the fluid's rest and the
    evidence (module docstring); a missed mode restarts the run once. Returns the (possibly new) result, with
    ``info["verdict"] = {at_rest, at_rest_reason, checked, check_passed, mala_check, importance_check, modes,
    restarted}`` (``check_passed``: every check against the target passed, whatever the fluid's rest)."""
    import warnings

    from ..checks import NotConvergedWarning

    info = result.info
    at_rest, rest_reason = bool(info["converged"]), info["convergence_reason"]
    log_density, score = sampler._callables_x
    verdict = dict(at_rest=at_rest, at_rest_reason=rest_reason, checked=False, check_passed=None, mala_check=None,
                   importance_check=None, modes=None, restarted=None)
    if not sampler.check or log_density is None:
        verdict["note"] = ("check=False" if not sampler.check else "no log_density (the MALA check needs it)") + \
            ": converged means the fluid at rest only"
        info["verdict"] = verdict
        return result
    probe = CountingTarget(log_density, score, sampler.dim, fd_step=sampler.target.fd_step)
    seed = int(sampler.seed) if isinstance(sampler.seed, (int, np.integer)) else 0
    rng = np.random.default_rng([seed, 31])
    extra = [np.zeros(sampler.dim)] + ([np.asarray(info["start_centre"])] if info.get("start_centre") else [])
    mala, importance, modes = _evidence(result.samples, probe, rng, extra)
    info["n_check_density"] = info.get("n_check_density", 0) + probe.n_density
    info["n_check_score"] = info.get("n_check_score", 0) + probe.n_score
    laplace = modes.pop("laplace", None)
    verdict.update(checked=True, mala_check=mala, importance_check=importance, modes=modes,
                   check_passed=bool(mala["passed"] and importance["passed"] and not modes["missed"]))
    if modes["missed"] and sampler._may_restart and laplace is not None:
        # the sampler's own class (no import of sampler.py here: it imports this module)
        again = type(sampler)(**dict(sampler._options, x0=laplace_draw(laplace, sampler.n, rng)))
        again._may_restart = False
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotConvergedWarning)  # said once, by the caller
            second = again.run()
        second.n_score += result.n_score
        second.n_density += result.n_density
        second.wall_time += result.wall_time
        for key in ("n_check_density", "n_check_score"):
            second.info[key] += info[key]
        second.info["verdict"]["restarted"] = dict(first=verdict, reason=f"restarted once from the "
                                                                         f"{len(modes['modes'])} modes found")
        return second
    problems = []
    if not mala["passed"]:
        problems.append(mala["reason"])
    if not importance["passed"]:
        problems.append(importance["reason"])
    if modes["missed"]:
        problems.append("missed mode(s): " + modes["reason"]
                        + ("" if sampler._may_restart else " (after a restart from the modes found)"))
    converged = at_rest and not problems
    if converged:
        reason = (f"{rest_reason}; and the samples pass the check against the target: {mala['reason']}; "
                  f"{importance['reason']}; {modes['reason']}")
    elif at_rest:
        reason = "the fluid is at rest, but the samples fail the check against the target: " + "; ".join(problems)
    else:
        reason = rest_reason + ("; and the samples fail the check against the target: " + "; ".join(problems)
                                if problems else "")
    info.update(converged=converged, convergence_reason=reason, verdict=verdict)
    return result
