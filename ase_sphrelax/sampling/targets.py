"""Test targets for samplers: unnormalised log-densities with their scores and reference samples.

Every target is a :class:`Target`: vectorised ``log_density`` (M, d) -> (M,) and ``score``
(M, d) -> (M, d) (the gradient of the log-density, written out analytically), and where the
distribution allows it an exact i.i.d. sampler ``sample(n, rng)``. Conventions (the common
definitions collected in the project's method notes; constants dropped):

``gaussian``
    2D standard normal.
``correlated``
    2D normal, unit variances, correlation 0.9.
``ring8``
    Equal mixture of 8 normals, centres on the circle of radius 2 sqrt(2) (angles k pi / 4),
    standard deviation 0.354 (the "8 Gaussians" of the generative-modelling literature).
``banana``
    Haario's banana, ``log p = -x0^2/200 - (x1 - 0.03 (x0^2 - 100))^2 / 2``: x0 ~ N(0, 100),
    x1 | x0 ~ N(0.03 (x0^2 - 100), 1).
``donut``
    ``log p = -(r - 2)^2 / 0.32`` in 2D (a ring of radius 2, radial width 0.4); i.i.d.
    samples by the inverse CDF of the radius, whose density is ``r p(r)``, tabulated.
``funnel``
    Neal's funnel in 2D, ``log p = -x0^2/18 - x1^2 exp(-x0) / 2 - x0 / 2``: x0 ~ N(0, 9),
    x1 | x0 ~ N(0, exp(x0)).
``gaussian10d``
    10-D normal with covariance ``Q diag(lambda) Q^T``, eigenvalues ``lambda`` log-spaced in
    [0.1, 10] (condition number 100), ``Q`` a fixed random rotation (seed 0).
``logistic``
    Bayesian logistic regression on scikit-learn's bundled breast-cancer data (569 x 30,
    standardised features, labels +-1), the SVGD paper's set-up: w (30 weights + bias) ~ N(0,
    1/alpha), alpha ~ Gamma(1, rate 0.01), sampled in theta = [w, log alpha] (32 parameters,
    Jacobian included). No i.i.d. sampler: its reference is a long NUTS run (benchmarks).
    Needs scikit-learn (the ``sampling`` extra) for the data only.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
from scipy.integrate import trapezoid
from scipy.special import expit, logsumexp

__all__ = ["Target", "get_target", "TARGET_NAMES", "gaussian_target"]


@dataclass
class Target:
    """An unnormalised density with its score.

    Attributes
    ----------
    name : str
    dim : int
    log_density : callable (M, d) -> (M,)
    score : callable (M, d) -> (M, d)
    sample : callable (n, rng) -> (n, d), or None when no exact sampler exists
    mean, cov : ndarray or None
        Exact moments where known (else estimated from reference samples by the metrics).
    modes : ndarray (K, d) or None
        Mode centres of a mixture (for mode weights), with ``mode_weights`` (K,).
    init_scale : float
        Standard deviation of the common initial proposal N(0, init_scale^2 I) used in
        the evaluation.
    """

    name: str
    dim: int
    log_density: Callable
    score: Callable
    sample: Optional[Callable] = None
    mean: Optional[np.ndarray] = None
    cov: Optional[np.ndarray] = None
    modes: Optional[np.ndarray] = None
    mode_weights: Optional[np.ndarray] = None
    init_scale: float = 1.0
    description: str = ""
    extra: dict = field(default_factory=dict)

    def __repr__(self):
        return f"Target({self.name!r}, dim={self.dim})"


def _as_points(x, dim):
    x_pc = np.asarray(x, dtype=float)
    if x_pc.ndim != 2 or x_pc.shape[1] != dim:
        raise ValueError(f"x must have shape (M, {dim}), got {x_pc.shape}")
    return x_pc


def gaussian_target(mean, cov, name="gaussian", init_scale=1.0, description=""):
    """A normal target N(mean, cov) with exact log-density, score and sampler."""
    mean = np.atleast_1d(np.asarray(mean, dtype=float))
    cov = np.atleast_2d(np.asarray(cov, dtype=float))
    dim = mean.shape[0]
    prec = np.linalg.inv(cov)
    chol = np.linalg.cholesky(cov)

    def log_density(x):
        y = _as_points(x, dim) - mean
        return -0.5 * np.einsum("pc,cd,pd->p", y, prec, y)

    def score(x):
        return -(_as_points(x, dim) - mean) @ prec

    def sample(n, rng):
        return mean + rng.standard_normal((n, dim)) @ chol.T

    return Target(name, dim, log_density, score, sample, mean=mean, cov=cov, init_scale=init_scale,
                  description=description or f"N(mean, cov) in {dim}D")


def _ring8():
    angles = np.arange(8) * np.pi / 4
    centres = 2.0 * np.sqrt(2.0) * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    sigma = 0.354

    def parts(x):
        d_pkc = _as_points(x, 2)[:, None, :] - centres[None, :, :]
        return d_pkc, -0.5 * np.einsum("pkc,pkc->pk", d_pkc, d_pkc) / sigma**2

    def log_density(x):
        return logsumexp(parts(x)[1], axis=1)

    def score(x):
        d_pkc, log_pk = parts(x)
        w_pk = np.exp(log_pk - logsumexp(log_pk, axis=1, keepdims=True))
        return -np.einsum("pk,pkc->pc", w_pk, d_pkc) / sigma**2

    def sample(n, rng):
        return centres[rng.integers(0, 8, n)] + sigma * rng.standard_normal((n, 2))

    cov = np.eye(2) * (sigma**2 + 0.5 * (2.0 * np.sqrt(2.0)) ** 2)
    return Target("ring8", 2, log_density, score, sample, mean=np.zeros(2), cov=cov, modes=centres,
                  mode_weights=np.full(8, 1 / 8), init_scale=1.0,
                  description="8 equal normals (sd 0.354) on the circle of radius 2 sqrt 2")


def _banana():
    b = 0.03

    def log_density(x):
        x = _as_points(x, 2)
        return -x[:, 0] ** 2 / 200.0 - 0.5 * (x[:, 1] - b * (x[:, 0] ** 2 - 100.0)) ** 2

    def score(x):
        x = _as_points(x, 2)
        u = x[:, 1] - b * (x[:, 0] ** 2 - 100.0)
        return np.stack([-x[:, 0] / 100.0 + 2.0 * b * x[:, 0] * u, -u], axis=1)

    def sample(n, rng):
        x0 = 10.0 * rng.standard_normal(n)
        return np.stack([x0, b * (x0**2 - 100.0) + rng.standard_normal(n)], axis=1)

    # E[x1] = b (E x0^2 - 100) = 0; Var x1 = 1 + b^2 Var(x0^2) = 1 + b^2 * 2 * 100^2
    cov = np.diag([100.0, 1.0 + b**2 * 2.0 * 1e4])
    return Target("banana", 2, log_density, score, sample, mean=np.zeros(2), cov=cov, init_scale=1.0,
                  description="Haario banana, b = 0.03")


def _donut():
    radius, width2 = 2.0, 0.32  # log p = -(r - 2)^2 / 0.32, i.e. radial sd 0.4
    r_t = np.linspace(0.0, radius + 12 * np.sqrt(width2 / 2), 200001)
    pdf_t = r_t * np.exp(-((r_t - radius) ** 2) / width2)  # radial density in 2D: r p(r)
    cdf_t = np.concatenate([[0.0], np.cumsum(0.5 * (pdf_t[1:] + pdf_t[:-1]) * np.diff(r_t))])
    cdf_t /= cdf_t[-1]
    r2_mean = trapezoid(r_t**2 * pdf_t, r_t) / trapezoid(pdf_t, r_t)

    def log_density(x):
        x = _as_points(x, 2)
        return -((np.hypot(x[:, 0], x[:, 1]) - radius) ** 2) / width2

    def score(x):
        x = _as_points(x, 2)
        r = np.hypot(x[:, 0], x[:, 1])
        safe = np.where(r > 0, r, 1.0)
        g = np.where(r > 0, -2.0 * (r - radius) / width2 / safe, 0.0)  # the cone tip at r = 0: 0
        return g[:, None] * x

    def sample(n, rng):
        r = np.interp(rng.uniform(size=n), cdf_t, r_t)
        phi = rng.uniform(0, 2 * np.pi, n)
        return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)

    return Target("donut", 2, log_density, score, sample, mean=np.zeros(2), cov=np.eye(2) * r2_mean / 2,
                  init_scale=1.0, description="ring of radius 2, log p = -(r - 2)^2 / 0.32")


def _funnel():
    def log_density(x):
        x = _as_points(x, 2)
        return -x[:, 0] ** 2 / 18.0 - 0.5 * x[:, 1] ** 2 * np.exp(-x[:, 0]) - 0.5 * x[:, 0]

    def score(x):
        x = _as_points(x, 2)
        e = np.exp(-x[:, 0])
        return np.stack([-x[:, 0] / 9.0 + 0.5 * x[:, 1] ** 2 * e - 0.5, -x[:, 1] * e], axis=1)

    def sample(n, rng):
        x0 = 3.0 * rng.standard_normal(n)
        return np.stack([x0, np.exp(0.5 * x0) * rng.standard_normal(n)], axis=1)

    # Var x1 = E exp(x0) = exp(9 / 2)
    return Target("funnel", 2, log_density, score, sample, mean=np.zeros(2), cov=np.diag([9.0, np.exp(4.5)]),
                  init_scale=1.0, description="Neal's funnel in 2D, x0 ~ N(0, 9), x1 ~ N(0, exp(x0))")


def _gaussian10d():
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.standard_normal((10, 10)))
    lam = np.logspace(-1, 1, 10)
    cov = (q * lam) @ q.T
    cov = 0.5 * (cov + cov.T)
    return gaussian_target(np.zeros(10), cov, name="gaussian10d", init_scale=1.0,
                           description="10-D normal, eigenvalues log-spaced in [0.1, 10], rotated (seed 0)")


def breast_cancer_data():
    """Standardised breast-cancer features with a bias column (569, 31) and labels +-1 (569,)."""
    try:
        from sklearn.datasets import load_breast_cancer
    except ImportError as exc:  # pragma: no cover - depends on the extra
        raise ImportError("the logistic target needs scikit-learn: pip install 'ase-sphrelax[sampling]'") from exc
    data = load_breast_cancer()
    x = (data.data - data.data.mean(axis=0)) / data.data.std(axis=0)
    x = np.concatenate([x, np.ones((x.shape[0], 1))], axis=1)
    y = np.where(data.target == 1, 1.0, -1.0)
    return x, y


def _logistic():
    x_nf, y_n = breast_cancer_data()
    nw = x_nf.shape[1]  # 31: weights and bias
    a0, b0 = 1.0, 0.01  # Gamma(shape a0, rate b0) on alpha

    def log_density(theta):
        theta = _as_points(theta, nw + 1)
        w, s = theta[:, :nw], theta[:, nw]
        z = (w @ x_nf.T) * y_n  # (M, n)
        loglik = -np.logaddexp(0.0, -z).sum(axis=1)
        alpha = np.exp(s)
        return loglik + 0.5 * nw * s - 0.5 * alpha * np.einsum("pc,pc->p", w, w) + a0 * s - b0 * alpha

    def score(theta):
        theta = _as_points(theta, nw + 1)
        w, s = theta[:, :nw], theta[:, nw]
        z = (w @ x_nf.T) * y_n
        alpha = np.exp(s)
        g_w = (expit(-z) * y_n) @ x_nf - alpha[:, None] * w
        g_s = 0.5 * nw - 0.5 * alpha * np.einsum("pc,pc->p", w, w) + a0 - b0 * alpha
        return np.concatenate([g_w, g_s[:, None]], axis=1)

    return Target("logistic", nw + 1, log_density, score, None, init_scale=1.0,
                  description="Bayesian logistic regression, breast cancer (569 x 30 + bias), theta = [w, log alpha]",
                  extra=dict(x=x_nf, y=y_n))


_FACTORIES = {
    "gaussian": lambda: gaussian_target(np.zeros(2), np.eye(2), name="gaussian", description="2D standard normal"),
    "correlated": lambda: gaussian_target(np.zeros(2), [[1.0, 0.9], [0.9, 1.0]], name="correlated",
                                          description="2D normal, correlation 0.9"),
    "ring8": _ring8,
    "banana": _banana,
    "donut": _donut,
    "funnel": _funnel,
    "gaussian10d": _gaussian10d,
    "logistic": _logistic,
}
TARGET_NAMES = tuple(_FACTORIES)
_CACHE: dict = {}


def get_target(name) -> Target:
    """The (cached) target ``name``, one of :data:`TARGET_NAMES`."""
    if name not in _FACTORIES:
        raise ValueError(f"target must be one of {TARGET_NAMES}, got {name!r}")
    if name not in _CACHE:
        _CACHE[name] = _FACTORIES[name]()
    return _CACHE[name]
