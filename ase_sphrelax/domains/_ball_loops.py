"""Numba loops of :class:`~ase_sphrelax.domains.analytic.Ball` (imported on first use, so that
importing the domains loads no numba).

At 8224 points numpy's ``norm(r - c, axis=1)`` with its temporaries took 0.15-0.25 ms per call,
a level set that a relaxation step asks for twice (the step's :class:`KeepInDomain` and the
boundary force), as much as a quarter of one Fan evaluation. Same arithmetic, same order:
``sqrt(d0^2 + d1^2 (+ d2^2))``.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def ball_phi(r_pd, center_d, radius):
    """``|r_p - center| - radius`` per point, from the first ``len(center_d)`` columns of ``r_pd``."""
    n, dim = r_pd.shape[0], center_d.shape[0]
    phi_p = np.empty(n)
    for p in range(n):
        dist2 = 0.0
        for c in range(dim):
            d = r_pd[p, c] - center_d[c]
            dist2 += d * d
        phi_p[p] = np.sqrt(dist2) - radius
    return phi_p


@numba.njit(cache=True)
def ball_phi_grad(r_pd, center_d, radius, columns):
    """``phi_p`` and its gradient ``(r - center) / |r - center|`` in ``columns >= dim`` columns
    (zeros beyond ``dim = len(center_d)``); ``e_x`` at the centre itself (the kink)."""
    n, dim = r_pd.shape[0], center_d.shape[0]
    phi_p = np.empty(n)
    g_pc = np.zeros((n, columns))
    for p in range(n):
        dist2 = 0.0
        for c in range(dim):
            d = r_pd[p, c] - center_d[c]
            dist2 += d * d
        dist = np.sqrt(dist2)
        phi_p[p] = dist - radius
        if dist > 0.0:
            for c in range(dim):
                g_pc[p, c] = (r_pd[p, c] - center_d[c]) / dist
        else:
            g_pc[p, 0] = 1.0
    return phi_p, g_pc
