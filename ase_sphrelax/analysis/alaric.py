"""ALARIC analysis: the lowest attainable error of Eq. 48 (Appendix 1) for the Eq. 46 profile.

With one particle alone at the bottom of the density well (Fig. 8), its contribution bounds the
error from below:

    eps_teo.min = V lambda^d / Q (m / (V lambda^d) - Delta)^2                         (Eq. 48, 55)

in the unit ball ``B^d``, with ``Q = A int_0^1 rho*(r)^2 r^(d-1) dr`` (Eq. 52), the particle mass
``m = A int_0^1 rho* r^(d-1) dr / N`` and ``lambda`` from ``A int_0^lambda rho* r^(d-1) dr = m``
(Eq. 53); ``A = {2, 2 pi, 4 pi}`` and ``V = {2, pi, 4 pi / 3}`` (footnotes 13, 14).

:func:`declared_epsilon` is Eq. 45 as one fixed construction, to compare the particles of any method (ALARIC,
WVT) on one measure (Fig. 13, ``reproductions/alaric-fig13-declared``); :func:`nn_min_over_mean` the pairing
check beside it.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import quad
from scipy.optimize import brentq

from ..checks import check_dim

__all__ = ["alaric_min_error", "declared_epsilon", "nn_min_over_mean", "ANGULAR", "UNIT_BALL_VOLUME"]

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


def declared_epsilon(positions, target_density, domain, dim, boundary="mirror"):
    """Eq. 45 over all particles, the same construction for any method's particles.

    ``n_a`` is the SPH number density of a fresh
    :class:`~ase_sphrelax.calculators.alaric.ALARICCalculator` (default kernel and eta, H solved by it) with the
    edge treatment ``boundary`` (``"mirror"``: the radial mirror ghosts of the particles near ``domain``'s
    boundary count in the density; ``"wall"``: truncated kernels); ``rho_a = m n_a`` with the Eq. 44 mass
    ``m = mean(rho*_a / n_a)`` of this evaluation.

    Parameters
    ----------
    positions : ndarray (N, dim) or (N, 3)
    target_density : callable
        ``(N, dim) -> (N,)``.
    domain : Domain
    dim : {1, 2, 3}
    boundary : {"mirror", "wall"}

    Returns
    -------
    dict
        ``epsilon`` (Eq. 45), ``mass`` (Eq. 44).
    """
    from ase import Atoms

    from ..calculators.alaric import ALARICCalculator
    from ..models.alaric import epsilon, reset_mass

    dim = check_dim(dim)
    if boundary not in ("mirror", "wall"):
        raise ValueError(f"boundary must be 'mirror' or 'wall', got {boundary!r}")
    x = np.asarray(positions, dtype=float)
    if x.ndim != 2 or x.shape[1] not in (dim, 3) or len(x) < 2:
        raise ValueError(f"positions must have shape (N, {dim}) or (N, 3) with N >= 2, got {x.shape}")
    pos = np.zeros((len(x), 3))
    pos[:, :dim] = x[:, :dim]
    atoms = Atoms(numbers=np.zeros(len(x), int), positions=pos, pbc=False)
    calc = ALARICCalculator(target_density=target_density, dim=dim, domain=domain, boundary=boundary)
    atoms.calc = calc
    atoms.get_forces()
    r = calc.results
    mass = reset_mass(r["target"], r["number_density"])
    return dict(epsilon=epsilon(mass * r["number_density"], r["target"], r["number_density"]), mass=float(mass))


def nn_min_over_mean(positions):
    """The smallest nearest-neighbour distance over the mean one (pairing when small; ``positions`` (N, d))."""
    from scipy.spatial import cKDTree

    x = np.asarray(positions, dtype=float)
    if x.ndim != 2 or len(x) < 2:
        raise ValueError(f"positions must have shape (N, d) with N >= 2, got {x.shape}")
    dist, _ = cKDTree(x).query(x, k=2)
    return float(dist[:, 1].min() / dist[:, 1].mean())
