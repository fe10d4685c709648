"""Kernel-valued pair sums: two users of :mod:`ase_sphrelax.pairs`.

* :func:`pair_potential_sums`: energy, forces and virial of the pair potential
  ``phi(r) = scale f(r/h)`` (each pair once), e.g. Fan's ``2 v0 vt W(r, h)``;
* :func:`kernel_sums`: the per-particle sums ``sum_j W_ij`` (including ``j = i``) and
  ``sum_j grad_i W_ij`` of the quality metrics.

Each defines its per-pair physics once; the list walk, the fused bin scan, the threads and
the folding onto particles come from :class:`~ase_sphrelax.pairs.PairInteraction`.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .kernels import kernel_slope_over_q
from .pairs import Output, PairInteraction

__all__ = ["pair_potential_sums", "kernel_sums", "KernelSums", "PAIR_POTENTIAL", "PAIR_POTENTIAL_VIRIAL", "PAIR_FORCES",
           "KERNEL_SUMS"]


# Written flat (no nested helper for the shared terms): Fan's hot path, where a nested inline helper was
# measured 2.5x slower. The virial and forces-only variants are the same source with ``with_virial`` /
# ``with_energy`` bound (PairInteraction constants): the branches are pruned at compile time.
@numba.njit(cache=True, inline="always")
def _radial_potential(a, b, r2, d, inv_h, scale, with_virial, with_energy):
    """phi = scale f(r/h): half the pair energy to each partner (``with_energy``), the force +g d on a, and
    (``with_virial``) the virial phi'(r) d d^T / r (Voigt order xx yy zz yz xz xy)."""
    # g = scale f'(q) / (h r) = scale (f'(q) / q) / h^2: no division (coincident points: d = 0, no force)
    value, slope_over_q = kernel_slope_over_q(math.sqrt(r2) * inv_h)
    g = (scale * inv_h * inv_h) * slope_over_q  # the constant factor first: computed once per loop, not per pair
    f0, f1, f2 = g * d[0], g * d[1], g * d[2]
    if not with_energy:
        return (f0, f1, f2), (-f0, -f1, -f2), ()
    half = 0.5 * scale * value
    if with_virial:
        return (half, f0, f1, f2), (half, -f0, -f1, -f2), (f0 * d[0], f1 * d[1], f2 * d[2], f1 * d[2], f0 * d[2],
                                                            f0 * d[1])
    return (half, f0, f1, f2), (half, -f0, -f1, -f2), ()


_PER_POINT = dict(energies=Output(()), forces=Output((3,), spatial=True))
_POTENTIAL_DATA = dict(params=("inv_h", "scale"), support="inv_h")  # f(q) and f'(q)/q vanish for q >= 1
PAIR_POTENTIAL = PairInteraction(_radial_potential, _PER_POINT, constants=dict(with_virial=False, with_energy=True),
                                 **_POTENTIAL_DATA)
PAIR_POTENTIAL_VIRIAL = PairInteraction(_radial_potential, dict(_PER_POINT, virial=Output((6,), per_point=False)),
                                        constants=dict(with_virial=True, with_energy=True), **_POTENTIAL_DATA)
PAIR_FORCES = PairInteraction(_radial_potential, dict(forces=_PER_POINT["forces"]),
                              constants=dict(with_virial=False, with_energy=False), **_POTENTIAL_DATA)


def pair_potential_sums(pairs, r_pc, h, scale, kernel, want_virial=False, planar=False, want_energy=True,
                        keep_scratch=False, forces_out=None):
    """Energy, forces and virial of ``phi(r) = scale * f(r / h)`` summed over pairs.

    Parameters
    ----------
    pairs : NeighborList
        Updated for ``r_pc``, stored list or one-shot bins.
    r_pc : ndarray (N, 3)
    h : float
        Kernel support radius.
    scale : float
        ``phi(r) = scale * f(r/h)``; for a kernel-valued potential ``c W(r, h)``
        use ``scale = c * kernel.sigma / h**dim``.
    kernel : Kernel
    want_virial : bool
        Also the virial (periodic stress).
    planar : bool
        Every ``r_pc`` has z = 0 (1D/2D): the loops read x and y only (:meth:`PairInteraction.compute`).
    want_energy : bool
        False (and no virial): forces only, ``energies_p`` None (a step of an optimiser that reads forces).
    keep_scratch : bool
        As :meth:`~ase_sphrelax.pairs.PairInteraction.compute`'s.
    forces_out : ndarray (N, 3) or None
        An array to write the forces into (:meth:`~ase_sphrelax.pairs.PairInteraction.compute`'s ``out``);
        None: a fresh one.

    Returns
    -------
    energies_p : ndarray (N,) or None
        Pair energy, half of each pair to each partner.
    f_pc : ndarray (N, 3)
        ``-dE/dx``.
    virial_cc : ndarray (3, 3)
        ``dE/d(strain)`` = sum over pairs of ``phi'(r) d d^T / r``.
    """
    h = float(h)
    params = dict(inv_h=1.0 / h, scale=float(scale))
    into = None if forces_out is None else dict(forces=forces_out)
    if not want_virial and not want_energy:
        return None, PAIR_FORCES.compute(pairs, r_pc, params, reach=h, kernel=kernel, planar=planar,
                                           keep_scratch=keep_scratch, out=into).forces, None
    if not want_virial:
        out = PAIR_POTENTIAL.compute(pairs, r_pc, params, reach=h, kernel=kernel, planar=planar,
                                     keep_scratch=keep_scratch, out=into)
        return out.energies, out.forces, np.zeros((3, 3))
    out = PAIR_POTENTIAL_VIRIAL.compute(pairs, r_pc, params, reach=h, kernel=kernel, planar=planar,
                                        keep_scratch=keep_scratch, out=into)
    v = out.virial
    virial = np.array([[v[0], v[5], v[4]], [v[5], v[1], v[3]], [v[4], v[3], v[2]]])
    return out.energies, out.forces, virial


@numba.njit(cache=True, inline="always")
def _kernel_sum_pair(a, b, r2, d, inv_h):
    """Per point: sum_j f(r/h) (j != i) and sum_j f'(r/h) (x_i - x_j)/r."""
    value, slope_over_q = kernel_slope_over_q(math.sqrt(r2) * inv_h)
    g = slope_over_q * inv_h  # f'(q) / r
    # grad_i W(|x_i - x_j|) = W' (x_i - x_j) / r, with d = x_b - x_a
    g0, g1, g2 = g * d[0], g * d[1], g * d[2]
    return (value, -g0, -g1, -g2), (value, g0, g1, g2), ()


KERNEL_SUMS = PairInteraction(_kernel_sum_pair, dict(w=Output(()), grad=Output((3,), spatial=True)), params=("inv_h",),
                              support="inv_h")


class KernelSums:
    """Per-particle kernel sums ``sum_j W_ij`` (incl. j = i) and ``sum_j grad_i W_ij``."""

    def __init__(self, w_p, grad_pc):
        self.w_p = w_p
        self.grad_pc = grad_pc


def kernel_sums(nlist, r_pc, h, kernel, planar=False):
    """Return :class:`KernelSums` for particles at ``r_pc`` (neighbours already updated); ``planar``: every
    ``r_pc`` has z = 0 (see :func:`pair_potential_sums`)."""
    h = float(h)
    out = KERNEL_SUMS.compute(nlist, r_pc, dict(inv_h=1.0 / h), reach=h, kernel=kernel, planar=planar)
    norm = kernel.sigma / h**kernel.dim
    return KernelSums(norm * (out.w + kernel.f0), norm / h * out.grad)
