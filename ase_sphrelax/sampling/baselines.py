"""Baseline samplers for the SPH-ParVI evaluation: SVGD, ULA, MALA (numpy) and emcee.

All run M particles or chains in parallel from the same initial points ``x0`` (M, d) and
return the M final states as a :class:`~ase_sphrelax.sampling.result.SampleResult`, so that
every method is compared at the same number of samples and counted in the same units
(score and density evaluations per point).

* :func:`svgd` — Stein variational gradient descent (Liu and Wang 2016, Algorithm 1) with
  the RBF kernel ``k(x, y) = exp(-|x - y|^2 / l)`` and the median heuristic
  ``l = med^2 / log M``, updated after every step, and Adam on ``-phi`` as in blackjax
  (``blackjax.svgd(grad_logp, optax.adam(lr))``, which the tests check it against); the
  learning rate and a factor on the median heuristic are tuned per target by
  :mod:`~ase_sphrelax.sampling.tuning` (a pilot over a log grid scored by the kernel Stein
  discrepancy), the same rule that sets ULA's and MALA's step sizes.
  SVGD is O(M^2) per step by construction (every particle interacts with every other):
  the M x M kernel is computed in row blocks so that memory stays O(block * M). Above
  ``median_points`` particles the median is taken over a fixed random subset.
* :func:`ula` — unadjusted Langevin, ``x <- x + eps s(x) + sqrt(2 eps) xi``.
* :func:`mala` — Metropolis-adjusted Langevin (the same proposal, accepted with the MH ratio).
* :func:`emcee_ensemble` — Goodman-Weare affine-invariant ensemble (``emcee``, an optional
  dependency: the ``sampling`` extra), M walkers.
"""
from __future__ import annotations

import time

import numpy as np
from scipy.spatial.distance import pdist

from .result import CountingTarget, SampleResult

__all__ = ["svgd", "svgd_direction", "median_length_scale", "ula", "mala", "emcee_ensemble", "Adam"]

_BLOCK = 1024


def median_length_scale(x_pc, median_points=2000, seed=0):
    """``med^2 / log M``: the median heuristic of SVGD (``med`` the median pairwise distance).

    The distances of the distinct pairs come from :func:`scipy.spatial.distance.pdist` (the same values, to
    round-off, as the M x M x d difference array with its lower triangle that this used before 2026-12-02,
    which cost 75-90 % of an SVGD step at M = 2000: reproductions/parvi-banana-m2000/results/svgd_cost.json).
    """
    m = x_pc.shape[0]
    sub = x_pc
    if m > median_points:
        sub = x_pc[np.random.default_rng(seed).choice(m, median_points, replace=False)]
    med = np.median(pdist(sub))
    return float(med**2 / np.log(m))


def svgd_direction(x_pc, g_pc, length_scale):
    """The Stein direction ``phi(x_i) = mean_j [k(x_j, x_i) s(x_j) + grad_{x_j} k(x_j, x_i)]`` (M, d).

    With ``k = exp(-|x_j - x_i|^2 / l)``: ``grad_{x_j} k = 2 (x_i - x_j) k / l``.
    """
    m = x_pc.shape[0]
    phi = np.empty_like(x_pc)
    sq_p = np.einsum("pc,pc->p", x_pc, x_pc)
    for start in range(0, m, _BLOCK):
        xi = x_pc[start:start + _BLOCK]
        r2 = np.maximum(sq_p[start:start + _BLOCK, None] + sq_p[None, :] - 2.0 * xi @ x_pc.T, 0.0)
        k = np.exp(-r2 / length_scale)  # (block, M): k[i, j]
        ksum = k.sum(axis=1)
        phi[start:start + _BLOCK] = (k @ g_pc + 2.0 / length_scale * (xi * ksum[:, None] - k @ x_pc)) / m
    return phi


class Adam:
    """Adam as optax.adam (b1 0.9, b2 0.999, eps 1e-8 added after the square root)."""

    def __init__(self, lr, b1=0.9, b2=0.999, eps=1e-8):
        self.lr, self.b1, self.b2, self.eps = lr, b1, b2, eps
        self.t = 0
        self.mu = self.nu = None

    def update(self, grad):
        if self.mu is None:
            self.mu = np.zeros_like(grad)
            self.nu = np.zeros_like(grad)
        self.t += 1
        self.mu = self.b1 * self.mu + (1 - self.b1) * grad
        self.nu = self.b2 * self.nu + (1 - self.b2) * grad * grad
        mu_hat = self.mu / (1 - self.b1**self.t)
        nu_hat = self.nu / (1 - self.b2**self.t)
        return -self.lr * mu_hat / (np.sqrt(nu_hat) + self.eps)


def _check_x0(x0):
    x0 = np.array(x0, dtype=float)
    if x0.ndim != 2 or x0.shape[0] < 2:
        raise ValueError(f"x0 must have shape (M, d) with M >= 2, got {x0.shape}")
    return x0


class _Recorder:
    """Every ``every`` steps: the particles and the wall time since the start (``every`` 0: never)."""

    def __init__(self, every):
        self.every = every
        self.t0 = time.perf_counter()
        self.trace = dict(step=[], samples=[], wall=[])

    def __call__(self, k, x):
        if self.every and (k + 1) % self.every == 0:
            self.trace["step"].append(k + 1)
            self.trace["samples"].append(x.copy())
            self.trace["wall"].append(time.perf_counter() - self.t0)

    def result(self, x, info, **counts):
        return SampleResult(x, wall_time=time.perf_counter() - self.t0, info=info,
                            trace={k: np.array(v) for k, v in self.trace.items()}, **counts)


def _check_steps(steps):
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
        raise ValueError(f"steps must be an integer >= 0, got {steps!r}")
    return int(steps)


def svgd(score, x0, steps, lr=0.1, length_scale=None, median_points=2000, record_every=0, seed=0,
         bandwidth_factor=1.0):
    """Stein variational gradient descent with Adam; see the module docstring.

    Parameters
    ----------
    score : callable (M, d) -> (M, d)
    x0 : ndarray (M, d)
    steps : int
    lr : float
        Adam learning rate.
    length_scale : float or None
        Initial ``l`` (default: the median heuristic of ``x0``); later steps use the median
        heuristic of the previous step's particles, as blackjax does.
    bandwidth_factor : float
        Multiplies the median heuristic (1: blackjax's rule). ``lr`` and this factor are tuned per
        target by :func:`ase_sphrelax.sampling.tuning.tune`, the rule that also sets ULA's and MALA's steps.
    record_every : int
        Record the particles every this many steps into ``trace["samples"]`` (0: never).
    """
    target = CountingTarget(score=score)
    x = _check_x0(x0)
    steps = _check_steps(steps)
    record = _Recorder(record_every)
    if not (np.isfinite(bandwidth_factor) and bandwidth_factor > 0):
        raise ValueError(f"bandwidth_factor must be a finite number > 0, got {bandwidth_factor!r}")
    ell = bandwidth_factor * median_length_scale(x, median_points, seed) if length_scale is None \
        else float(length_scale)
    opt = Adam(lr)
    for k in range(steps):
        phi = svgd_direction(x, target.score(x), ell)
        x = x + opt.update(-phi)
        ell = bandwidth_factor * median_length_scale(x, median_points, seed)
        record(k, x)
    return record.result(x, dict(method="svgd", lr=lr, steps=steps, length_scale=ell,
                                 bandwidth_factor=bandwidth_factor), n_score=target.n_score)


def ula(score, x0, steps, step_size, seed=0, record_every=0):
    """Unadjusted Langevin algorithm, M chains: ``x <- x + eps s(x) + sqrt(2 eps) xi``."""
    target = CountingTarget(score=score)
    x = _check_x0(x0)
    steps = _check_steps(steps)
    rng = np.random.default_rng(seed)
    record = _Recorder(record_every)
    for k in range(steps):
        x = x + step_size * target.score(x) + np.sqrt(2.0 * step_size) * rng.standard_normal(x.shape)
        record(k, x)
    return record.result(x, dict(method="ula", step_size=step_size, steps=steps), n_score=target.n_score)


def mala(log_density, score, x0, steps, step_size, seed=0, record_every=0):
    """Metropolis-adjusted Langevin, M independent chains; ``info["acceptance"]`` is the mean rate."""
    target = CountingTarget(log_density=log_density, score=score)
    x = _check_x0(x0)
    steps = _check_steps(steps)
    rng = np.random.default_rng(seed)
    record = _Recorder(record_every)
    lp, g = target.log_density(x), target.score(x)
    accepted = 0
    for k in range(steps):
        y = x + step_size * g + np.sqrt(2.0 * step_size) * rng.standard_normal(x.shape)
        lp_y, g_y = target.log_density(y), target.score(y)
        fwd = np.einsum("pc,pc->p", y - x - step_size * g, y - x - step_size * g)
        bwd = np.einsum("pc,pc->p", x - y - step_size * g_y, x - y - step_size * g_y)
        with np.errstate(invalid="ignore"):
            log_ratio = lp_y - lp - (bwd - fwd) / (4.0 * step_size)
        accept = np.log(rng.uniform(size=x.shape[0])) < np.nan_to_num(log_ratio, nan=-np.inf)
        x = np.where(accept[:, None], y, x)
        lp = np.where(accept, lp_y, lp)
        g = np.where(accept[:, None], g_y, g)
        accepted += int(accept.sum())
        record(k, x)
    rate = accepted / max(steps * x.shape[0], 1)
    return record.result(x, dict(method="mala", step_size=step_size, steps=steps, acceptance=rate),
                         n_density=target.n_density, n_score=target.n_score)


def emcee_ensemble(log_density, x0, steps, seed=0):
    """emcee's affine-invariant ensemble with M = len(x0) walkers; returns the walkers' final states.

    Needs ``emcee`` (the ``sampling`` extra). emcee needs M >= 2 d walkers.
    """
    try:
        import emcee
    except ImportError as exc:  # pragma: no cover - depends on the extra
        raise ImportError("emcee_ensemble needs emcee: pip install 'ase-sphrelax[sampling]'") from exc
    target = CountingTarget(log_density=log_density)
    x = _check_x0(x0)
    steps = _check_steps(steps)
    t0 = time.perf_counter()
    sampler = emcee.EnsembleSampler(x.shape[0], x.shape[1], target.log_density, vectorize=True)
    sampler.random_state = np.random.RandomState(seed).get_state()
    state = sampler.run_mcmc(x, steps, progress=False) if steps else None
    final = state.coords if state is not None else x
    return SampleResult(np.array(final), n_density=target.n_density, wall_time=time.perf_counter() - t0,
                        info=dict(method="emcee", steps=steps, acceptance=float(np.mean(sampler.acceptance_fraction))
                                  if steps else 0.0))
