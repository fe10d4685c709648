"""ALARIC analysis: the lowest attainable error of Eq. 48 (Appendix 1) for the Eq. 46 profile.

With one particle alone at the bottom of the density well (Fig. 8), its contribution bounds the
error from below:

    eps_teo.min = V lambda^d / Q (m / (V lambda^d) - Delta)^2                         (Eq. 48, 55)

in the unit ball ``B^d``, with ``Q = A int_0^1 rho*(r)^2 r^(d-1) dr`` (Eq. 52), the particle mass
``m = A int_0^1 rho* r^(d-1) dr / N`` and ``lambda`` from ``A int_0^lambda rho* r^(d-1) dr = m``
(Eq. 53); ``A = {2, 2 pi, 4 pi}`` and ``V = {2, pi, 4 pi / 3}`` (footnotes 13, 14).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import quad
from scipy.optimize import brentq

from ..checks import check_dim

__all__ = ["alaric_min_error", "ANGULAR", "UNIT_BALL_VOLUME"]

ANGULAR = {1: 2.0, 2: 2.0 * math.pi, 3: 4.0 * math.pi}
UNIT_BALL_VOLUME = {1: 2.0, 2: math.pi, 3: 4.0 * math.pi / 3.0}


def _eq46(r, delta):
    return (1.0 + delta) - math.cos(5.0 * r) * math.exp(-5.0 * r * r)


def alaric_min_error(n, delta, dim):
    """Eq. 48: the theoretical lowest epsilon for ``n`` particles, the Eq. 46 profile with ``delta``, in the unit ball.

    Parameters
    ----------
    n : int
        Number of particles (e.g. 303 on [-1, 1]).
    delta : float
        ``rho*(0) = delta`` (Eq. 46), >= 0.
    dim : {1, 2, 3}

    Returns
    -------
    float
    """
    dim = check_dim(dim)
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    delta = float(delta)
    if not math.isfinite(delta) or delta < 0:
        raise ValueError(f"delta must be a finite number >= 0, got {delta!r}")
    a, v = ANGULAR[dim], UNIT_BALL_VOLUME[dim]
    opts = dict(epsabs=0.0, epsrel=1e-11, limit=200)
    mass = a * quad(lambda r: _eq46(r, delta) * r ** (dim - 1), 0.0, 1.0, **opts)[0] / int(n)
    q = a * quad(lambda r: _eq46(r, delta) ** 2 * r ** (dim - 1), 0.0, 1.0, **opts)[0]

    def enclosed(lam):
        return a * quad(lambda r: _eq46(r, delta) * r ** (dim - 1), 0.0, lam, **opts)[0] - mass

    lam = brentq(enclosed, 0.0, 1.0, xtol=1e-15, rtol=1e-14)
    vol = v * lam**dim
    return float(vol / q * (mass / vol - delta) ** 2)
