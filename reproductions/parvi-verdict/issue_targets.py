"""The user targets of issue 31, item 1, as ``module:function`` pairs for ``sphrelax sample``
(``PYTHONPATH=reproductions/parvi-verdict sphrelax sample --target issue_targets:mixture_logp --score
issue_targets:mixture_score --dim 2``).

* ``mixture``: three isotropic 2D Gaussians (sd 0.5) with weights 0.5 / 0.3 / 0.2 at (-2, 0), (1, 2.5), (1.5, 0):
  mean (-0.4, 0.75), as the issue's (its component centres were not given: these reproduce its weights and mean).
* ``banana``: a banana of another curvature than the built-in: x ~ N(0, 1), y | x ~ N(x^2 - 1, 0.5^2):
  mean (0, 0), var(y) = 0.25 + 2 = 2.25, as the issue's.
"""
import numpy as np
from scipy.special import logsumexp

WEIGHTS = np.array([0.5, 0.3, 0.2])
CENTRES = np.array([[-2.0, 0.0], [1.0, 2.5], [1.5, 0.0]])
SD = 0.5
MIXTURE_MEAN = WEIGHTS @ CENTRES  # (-0.4, 0.75)
MIXTURE_COV = (SD**2 * np.eye(2) + np.einsum("k,ki,kj->ij", WEIGHTS, CENTRES, CENTRES)
               - np.outer(MIXTURE_MEAN, MIXTURE_MEAN))
BANANA_MEAN, BANANA_COV = np.zeros(2), np.diag([1.0, 2.25])


def _parts(x):
    x = np.atleast_2d(x)
    d2 = np.sum((x[:, None, :] - CENTRES[None]) ** 2, axis=2)
    return x, np.log(WEIGHTS)[None] - 0.5 * d2 / SD**2


def mixture_logp(x):
    return logsumexp(_parts(x)[1], axis=1)


def mixture_score(x):
    x, lw = _parts(x)
    r = np.exp(lw - logsumexp(lw, axis=1, keepdims=True))
    return np.einsum("pk,pkc->pc", r, CENTRES[None] - x[:, None, :]) / SD**2


def mixture_sample(n, rng):
    k = rng.choice(3, size=n, p=WEIGHTS)
    return CENTRES[k] + SD * rng.standard_normal((n, 2))


def banana_logp(x):
    x = np.atleast_2d(x)
    return -0.5 * x[:, 0] ** 2 - 0.5 * (x[:, 1] - x[:, 0] ** 2 + 1.0) ** 2 / 0.25


def banana_score(x):
    x = np.atleast_2d(x)
    r = (x[:, 1] - x[:, 0] ** 2 + 1.0) / 0.25
    return np.stack([-x[:, 0] + 2.0 * x[:, 0] * r, -r], axis=1)


def banana_sample(n, rng):
    x = rng.standard_normal(n)
    return np.stack([x, x**2 - 1.0 + 0.5 * rng.standard_normal(n)], axis=1)
