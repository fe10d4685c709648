"""Distances between a sample and a reference sample, and moment and mode errors.

* :func:`energy_distance`: ``2 E|X - Y| - E|X - X'| - E|Y - Y'|`` (Szekely-Rizzo), the
  V-statistic (self-pairs included, as ``dcor.energy_distance``). It is zero only for equal
  distributions and needs no bandwidth.
* :func:`mmd`: the squared maximum mean discrepancy with the RBF kernel
  ``exp(-|x - y|^2 / (2 l^2))``; the bandwidth ``l`` is stated by the caller (the evaluation
  uses the median distance of the reference sample, reported with the numbers).
* :func:`sliced_wasserstein`: ``(mean_k W_p^p(theta_k . X, theta_k . Y))^(1/p)`` over random
  unit directions, with the exact one-dimensional W_p between empirical distributions of
  any sizes (POT's ``sliced_wasserstein_distance`` with the same directions gives the same
  number).
* :func:`mean_error`, :func:`cov_error`, :func:`mode_weights`.

The two-sample distances are O(n m) by definition (every cross pair); they are evaluation
tools, computed in blocks so that memory stays O(block * m), never in a sampler's step.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.distance import cdist

__all__ = ["energy_distance", "mmd", "median_distance", "sliced_wasserstein", "wasserstein_1d", "mean_error",
           "cov_error", "mode_weights", "mode_weight_error", "random_directions"]

_BLOCK = 2048


def _points(x, name):
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] < 1:
        raise ValueError(f"{name} must have shape (n, d) with n >= 1, got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} must be finite")
    return x


def _pair_mean(x, y, fn):
    """Mean of fn(cdist block) over all pairs of x and y, in blocks of x."""
    total = 0.0
    for start in range(0, x.shape[0], _BLOCK):
        total += fn(cdist(x[start:start + _BLOCK], y)).sum()
    return total / (x.shape[0] * y.shape[0])


def energy_distance(x, y):
    """Energy distance ``2 E|X-Y| - E|X-X'| - E|Y-Y'|`` between samples x (n, d) and y (m, d)."""
    x, y = _points(x, "x"), _points(y, "y")
    ident = lambda r: r  # noqa: E731
    return 2.0 * _pair_mean(x, y, ident) - _pair_mean(x, x, ident) - _pair_mean(y, y, ident)


def median_distance(y, max_points=2000, seed=0):
    """Median pairwise distance of (at most ``max_points`` of) y: the RBF bandwidth of :func:`mmd`."""
    y = _points(y, "y")
    if y.shape[0] > max_points:
        y = y[np.random.default_rng(seed).choice(y.shape[0], max_points, replace=False)]
    r = cdist(y, y)
    return float(np.median(r[np.triu_indices(y.shape[0], k=1)]))


def mmd(x, y, bandwidth):
    """Squared MMD (V-statistic) with the kernel ``exp(-|x - y|^2 / (2 bandwidth^2))``."""
    x, y = _points(x, "x"), _points(y, "y")
    if not bandwidth > 0:
        raise ValueError(f"bandwidth must be > 0, got {bandwidth!r}")
    k = lambda r: np.exp(-0.5 * (r / bandwidth) ** 2)  # noqa: E731
    return _pair_mean(x, x, k) + _pair_mean(y, y, k) - 2.0 * _pair_mean(x, y, k)


def random_directions(dim, n_projections, seed=0):
    """``n_projections`` uniform random unit vectors in ``dim`` dimensions, (n_projections, dim)."""
    theta = np.random.default_rng(seed).standard_normal((n_projections, dim))
    return theta / np.linalg.norm(theta, axis=1, keepdims=True)


def wasserstein_1d(u, v, p=2):
    """Exact W_p^p between the empirical distributions of 1D samples u and v (any sizes).

    ``W_p^p = int_0^1 |F^-1(t) - G^-1(t)|^p dt``, piecewise constant between the merged
    quantile levels of the two samples.
    """
    u, v = np.sort(np.asarray(u, dtype=float)), np.sort(np.asarray(v, dtype=float))
    cu = np.arange(1, u.size + 1) / u.size
    cv = np.arange(1, v.size + 1) / v.size
    levels = np.union1d(cu, cv)
    widths = np.diff(np.concatenate([[0.0], levels]))
    # quantile at the middle of each level interval (right-continuous inverse CDF)
    mid = levels - 0.5 * widths
    qu = u[np.minimum(np.searchsorted(cu, mid), u.size - 1)]
    qv = v[np.minimum(np.searchsorted(cv, mid), v.size - 1)]
    return float(np.sum(widths * np.abs(qu - qv) ** p))


def sliced_wasserstein(x, y, n_projections=200, p=2, seed=0, directions=None):
    """Sliced Wasserstein distance ``(mean_k W_p^p(theta_k·x, theta_k·y))^(1/p)``."""
    x, y = _points(x, "x"), _points(y, "y")
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"x and y must have the same dimension, got {x.shape[1]} and {y.shape[1]}")
    theta = random_directions(x.shape[1], n_projections, seed) if directions is None else np.asarray(directions)
    xp, yp = x @ theta.T, y @ theta.T
    return float(np.mean([wasserstein_1d(xp[:, k], yp[:, k], p) for k in range(theta.shape[0])]) ** (1.0 / p))


def mean_error(x, mean):
    """Euclidean norm of the sample mean's error, ``|mean(x) - mean|``."""
    return float(np.linalg.norm(_points(x, "x").mean(axis=0) - np.asarray(mean, dtype=float)))


def cov_error(x, cov):
    """Relative Frobenius error of the sample covariance, ``|C(x) - cov|_F / |cov|_F``."""
    x = _points(x, "x")
    cov = np.atleast_2d(np.asarray(cov, dtype=float))
    c = np.atleast_2d(np.cov(x, rowvar=False))
    return float(np.linalg.norm(c - cov) / np.linalg.norm(cov))


def mode_weights(x, centres):
    """Fraction of the points of x nearest to each centre (K,)."""
    x = _points(x, "x")
    nearest = np.argmin(cdist(x, np.asarray(centres, dtype=float)), axis=1)
    return np.bincount(nearest, minlength=len(centres)) / x.shape[0]


def mode_weight_error(x, centres, weights):
    """Total-variation distance between the mode weights of x and the true ``weights``."""
    return float(0.5 * np.abs(mode_weights(x, centres) - np.asarray(weights)).sum())
