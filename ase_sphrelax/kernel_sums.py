"""Fused kernel sums over a :class:`~ase_sphrelax.neighbors.NeighborList` half list.

All loops run over sorted extended points (see :mod:`ase_sphrelax.neighbors`)
and touch each physical pair once. Per-point results are folded back onto the
particles by the caller with ``NeighborList.fold``.
"""
from __future__ import annotations

import numba
import numpy as np

from .kernels import profile_value_and_slope

__all__ = ["pair_potential_sums", "kernel_sums", "KernelSums"]


@numba.njit(cache=True)
def _pair_potential(x_sc, pair_start, pair_j, h, scale, breaks, coef, want_virial):
    """Sum of phi(r) = scale * f(r/h) over pairs, with forces and virial.

    Returns (energy_s, f_sc, virial_cc): the pair energy split evenly onto the
    two points, the force -d/dx of the total, and sum_pairs phi'(r) d d^T / r.
    """
    n = x_sc.shape[0]
    e_s = np.zeros(n)
    f_sc = np.zeros((n, 3))
    virial = np.zeros((3, 3))
    h2 = h * h
    inv_h = 1.0 / h
    for a in range(n):
        xa0, xa1, xa2 = x_sc[a, 0], x_sc[a, 1], x_sc[a, 2]
        fa0 = 0.0
        fa1 = 0.0
        fa2 = 0.0
        ea = 0.0
        for p in range(pair_start[a], pair_start[a + 1]):
            b = pair_j[p]
            d0 = x_sc[b, 0] - xa0
            d1 = x_sc[b, 1] - xa1
            d2 = x_sc[b, 2] - xa2
            r2 = d0 * d0 + d1 * d1 + d2 * d2
            if r2 >= h2:
                continue
            r = np.sqrt(r2)
            value, slope = profile_value_and_slope(r * inv_h, breaks, coef)
            half = 0.5 * scale * value
            ea += half
            e_s[b] += half
            if r2 == 0.0:
                continue  # coincident points: the profile is flat at q = 0, force 0
            # dphi/dr / r; force on a is +dphi/dr * d / r (repulsive for slope < 0)
            g = scale * slope * inv_h / r
            fa0 += g * d0
            fa1 += g * d1
            fa2 += g * d2
            f_sc[b, 0] -= g * d0
            f_sc[b, 1] -= g * d1
            f_sc[b, 2] -= g * d2
            if want_virial:
                virial[0, 0] += g * d0 * d0
                virial[1, 1] += g * d1 * d1
                virial[2, 2] += g * d2 * d2
                virial[0, 1] += g * d0 * d1
                virial[0, 2] += g * d0 * d2
                virial[1, 2] += g * d1 * d2
        e_s[a] += ea
        f_sc[a, 0] += fa0
        f_sc[a, 1] += fa1
        f_sc[a, 2] += fa2
    virial[1, 0] = virial[0, 1]
    virial[2, 0] = virial[0, 2]
    virial[2, 1] = virial[1, 2]
    return e_s, f_sc, virial


def pair_potential_sums(nlist, r_pc, h, scale, kernel, want_virial=False):
    """Energy, forces and virial of ``phi(r) = scale * f(r / h)`` summed over pairs.

    Parameters
    ----------
    nlist : NeighborList
        Already updated for ``r_pc``.
    r_pc : ndarray (N, 3)
    h : float
        Kernel support radius.
    scale : float
        ``phi(r) = scale * f(r/h)``; for a kernel-valued potential ``c W(r, h)``
        use ``scale = c * kernel.sigma / h**dim``.
    kernel : Kernel

    Returns
    -------
    energies_p : ndarray (N,)
        Pair energy, half of each pair to each partner.
    f_pc : ndarray (N, 3)
        ``-dE/dx``.
    virial_cc : ndarray (3, 3)
        ``dE/d(strain)`` = sum over pairs of ``phi'(r) d d^T / r``.
    """
    x_sc = nlist.extend(r_pc)
    e_s, f_sc, virial = _pair_potential(x_sc, nlist.pair_start, nlist.pair_j, float(h), float(scale),
                                        kernel.breaks, kernel.coef, bool(want_virial))
    return nlist.fold(e_s), nlist.fold(f_sc), virial


@numba.njit(cache=True)
def _kernel_sums(x_sc, pair_start, pair_j, h, breaks, coef):
    """Per point: sum_j f(r/h) (j != i) and sum_j f'(r/h) (x_i - x_j)/r."""
    n = x_sc.shape[0]
    w_s = np.zeros(n)
    g_sc = np.zeros((n, 3))
    h2 = h * h
    inv_h = 1.0 / h
    for a in range(n):
        for p in range(pair_start[a], pair_start[a + 1]):
            b = pair_j[p]
            d0 = x_sc[b, 0] - x_sc[a, 0]
            d1 = x_sc[b, 1] - x_sc[a, 1]
            d2 = x_sc[b, 2] - x_sc[a, 2]
            r2 = d0 * d0 + d1 * d1 + d2 * d2
            if r2 >= h2:
                continue
            r = np.sqrt(r2)
            value, slope = profile_value_and_slope(r * inv_h, breaks, coef)
            w_s[a] += value
            w_s[b] += value
            if r2 == 0.0:
                continue
            g = slope / r
            # grad_i W(|x_i - x_j|) = W' (x_i - x_j) / r, with d = x_b - x_a
            g_sc[a, 0] -= g * d0
            g_sc[a, 1] -= g * d1
            g_sc[a, 2] -= g * d2
            g_sc[b, 0] += g * d0
            g_sc[b, 1] += g * d1
            g_sc[b, 2] += g * d2
    return w_s, g_sc


class KernelSums:
    """Per-particle kernel sums ``sum_j W_ij`` (incl. j = i) and ``sum_j grad_i W_ij``."""

    def __init__(self, w_p, grad_pc):
        self.w_p = w_p
        self.grad_pc = grad_pc


def kernel_sums(nlist, r_pc, h, kernel):
    """Return :class:`KernelSums` for particles at ``r_pc`` (list already updated)."""
    x_sc = nlist.extend(r_pc)
    w_s, g_sc = _kernel_sums(x_sc, nlist.pair_start, nlist.pair_j, float(h), kernel.breaks, kernel.coef)
    norm = kernel.sigma / h**kernel.dim
    w_p = norm * (nlist.fold(w_s) + kernel.f0)
    grad_pc = norm / h * nlist.fold(g_sc)
    return KernelSums(w_p, grad_pc)
