"""Fused kernel sums over a :class:`~ase_sphrelax.neighbors.NeighborList` half list.

All loops run over sorted extended points (see :mod:`ase_sphrelax.neighbors`)
and touch each physical pair once. Per-point results are folded back onto the
particles with ``fold``. Pair potentials run either over a stored Verlet list or
fused into the bin scan of :class:`~ase_sphrelax.neighbors.BinnedPoints` (one-shot
evaluations, no list stored). Above ``PARALLEL_MIN`` points the loops use numba
threads, each on a static chunk of points with its own output buffers. (The thread
index comes from the loop, not from ``numba.get_thread_id``: after LAMMPS has run
OpenMP threads in the same process that id can exceed numba's thread count.)
"""
from __future__ import annotations

import numba
import numpy as np

from .kernels import profile_by_kind
from .neighbors import PARALLEL_MIN, BinnedPoints, bin_coords, is_canonical_pair, stencil_range

__all__ = ["pair_potential_sums", "kernel_sums", "KernelSums"]


@numba.njit(cache=True, inline="always")
def _pair_terms(r2, inv_h, scale, kind, breaks, coef):
    """(half pair energy, g) of phi = scale f(r/h): the force on a is +g d, d = x_b - x_a."""
    r = np.sqrt(r2)
    value, slope = profile_by_kind(r * inv_h, kind, breaks, coef)
    if r2 == 0.0:
        return 0.5 * scale * value, 0.0  # coincident points: the profile is flat at q = 0
    return 0.5 * scale * value, scale * slope * inv_h / r


@numba.njit(cache=True, inline="always")
def _scatter(b, half, g, d0, d1, d2, e_s, f_sc, vir, want_virial):
    """Partner b's share of a pair, and the pair's virial sum_pairs phi'(r) d d^T / r."""
    e_s[b] += half
    f_sc[b, 0] -= g * d0
    f_sc[b, 1] -= g * d1
    f_sc[b, 2] -= g * d2
    if want_virial:
        vir[0] += g * d0 * d0
        vir[1] += g * d1 * d1
        vir[2] += g * d2 * d2
        vir[3] += g * d1 * d2
        vir[4] += g * d0 * d2
        vir[5] += g * d0 * d1


@numba.njit(cache=True, inline="always")
def _owner_add(a, ea, fa0, fa1, fa2, e_s, f_sc):
    e_s[a] += ea
    f_sc[a, 0] += fa0
    f_sc[a, 1] += fa1
    f_sc[a, 2] += fa2


@numba.njit(cache=True, inline="always")
def _zeroed_thread_chunks(n, e_ts, f_tsc, vir_tv):
    """Zero the per-thread buffers; return (threads, points per thread chunk).

    Called before the prange, not inside it: array expressions in a prange body become
    nested parallel loops, which leave the outer loop sequential.
    """
    e_ts[:] = 0.0
    f_tsc[:] = 0.0
    vir_tv[:] = 0.0
    nthreads = e_ts.shape[0]
    return nthreads, (n + nthreads - 1) // nthreads


def _list_pair_potential_impl(x_sc, pair_start, pair_j, h, scale, kind, breaks, coef, want_virial,
                              e_ts, f_tsc, vir_tv):
    """phi = scale f(r/h) over a stored half list, into the (zeroed) per-thread buffers."""
    n = x_sc.shape[0]
    h2 = h * h
    inv_h = 1.0 / h
    nthreads, chunk = _zeroed_thread_chunks(n, e_ts, f_tsc, vir_tv)
    for t in numba.prange(nthreads):
        e_s, f_sc, vir = e_ts[t], f_tsc[t], vir_tv[t]
        for a in range(t * chunk, min(n, (t + 1) * chunk)):
            xa0, xa1, xa2 = x_sc[a, 0], x_sc[a, 1], x_sc[a, 2]
            ea = fa0 = fa1 = fa2 = 0.0
            for p in range(pair_start[a], pair_start[a + 1]):
                b = pair_j[p]
                d0 = x_sc[b, 0] - xa0
                d1 = x_sc[b, 1] - xa1
                d2 = x_sc[b, 2] - xa2
                r2 = d0 * d0 + d1 * d1 + d2 * d2
                if r2 >= h2:
                    continue
                half, g = _pair_terms(r2, inv_h, scale, kind, breaks, coef)
                ea += half
                fa0 += g * d0
                fa1 += g * d1
                fa2 += g * d2
                _scatter(b, half, g, d0, d1, d2, e_s, f_sc, vir, want_virial)
            _owner_add(a, ea, fa0, fa1, fa2, e_s, f_sc)
    return e_ts, f_tsc, vir_tv


def _scan_pair_potential_impl(x_sc, src_s, img_sc, is_ghost_s, bin_s, nbin_c, bin_start, stencil_kc,
                              h, scale, kind, breaks, coef, want_virial, e_ts, f_tsc, vir_tv):
    """The same sums fused into the half-stencil bin scan (no stored list)."""
    n = x_sc.shape[0]
    h2 = h * h
    inv_h = 1.0 / h
    nthreads, chunk = _zeroed_thread_chunks(n, e_ts, f_tsc, vir_tv)
    for t in numba.prange(nthreads):
        e_s, f_sc, vir = e_ts[t], f_tsc[t], vir_tv[t]
        for a in range(t * chunk, min(n, (t + 1) * chunk)):
            xa0, xa1, xa2 = x_sc[a, 0], x_sc[a, 1], x_sc[a, 2]
            ea = fa0 = fa1 = fa2 = 0.0
            kx, ky, kz = bin_coords(a, bin_s, nbin_c)
            for k in range(-1, stencil_kc.shape[0]):
                lo, hi = stencil_range(a, k, kx, ky, kz, bin_s, nbin_c, bin_start, stencil_kc)
                for b in range(lo, hi):
                    d0 = x_sc[b, 0] - xa0
                    d1 = x_sc[b, 1] - xa1
                    d2 = x_sc[b, 2] - xa2
                    r2 = d0 * d0 + d1 * d1 + d2 * d2
                    if r2 >= h2 or not is_canonical_pair(a, b, src_s, img_sc, is_ghost_s):
                        continue
                    half, g = _pair_terms(r2, inv_h, scale, kind, breaks, coef)
                    ea += half
                    fa0 += g * d0
                    fa1 += g * d1
                    fa2 += g * d2
                    _scatter(b, half, g, d0, d1, d2, e_s, f_sc, vir, want_virial)
            _owner_add(a, ea, fa0, fa1, fa2, e_s, f_sc)
    return e_ts, f_tsc, vir_tv


_list_serial = numba.njit(cache=True)(_list_pair_potential_impl)
_list_parallel = numba.njit(cache=True, parallel=True)(_list_pair_potential_impl)
_scan_serial = numba.njit(cache=True)(_scan_pair_potential_impl)
_scan_parallel = numba.njit(cache=True, parallel=True)(_scan_pair_potential_impl)


def _threads(n):
    return numba.get_num_threads() if n >= PARALLEL_MIN else 1


_BUFFERS: dict = {}


def _thread_buffers(nthreads, n):
    """Per-thread output buffers, kept between calls: touching fresh pages costs more
    than the pair loop on some machines (measured: 8 MB in 2.4 ms fresh, 0.4 ms reused)."""
    key = (nthreads, n)
    if key not in _BUFFERS:
        _BUFFERS.clear()
        _BUFFERS[key] = (np.empty((nthreads, n)), np.empty((nthreads, n, 3)), np.empty((nthreads, 6)))
    return _BUFFERS[key]


def _fold_threads_impl(e_ts, f_tsc, order_s, ghost_s, src_e, n):
    """Energies (n,) and forces (n, 3) on particles: thread buffers summed and ghosts folded.

    Each original particle appears once among the sorted points, so those are summed in
    parallel without races; the (few) ghosts are added afterwards.
    """
    e_p = np.zeros(n)
    f_pc = np.zeros((n, 3))
    n_threads = e_ts.shape[0]
    for s in numba.prange(e_ts.shape[1]):
        e = order_s[s]
        if e < n:
            for t in range(n_threads):
                e_p[e] += e_ts[t, s]
                f_pc[e, 0] += f_tsc[t, s, 0]
                f_pc[e, 1] += f_tsc[t, s, 1]
                f_pc[e, 2] += f_tsc[t, s, 2]
    for g in range(ghost_s.shape[0]):
        s = ghost_s[g]
        p = src_e[order_s[s]]
        for t in range(n_threads):
            e_p[p] += e_ts[t, s]
            f_pc[p, 0] += f_tsc[t, s, 0]
            f_pc[p, 1] += f_tsc[t, s, 1]
            f_pc[p, 2] += f_tsc[t, s, 2]
    return e_p, f_pc


_fold_threads_serial = numba.njit(cache=True)(_fold_threads_impl)
_fold_threads_parallel = numba.njit(cache=True, parallel=True)(_fold_threads_impl)


def _reduce(points, e_ts, f_tsc, vir_tv):
    v = vir_tv.sum(axis=0)  # xx yy zz yz xz xy
    virial = np.array([[v[0], v[5], v[4]], [v[5], v[1], v[3]], [v[4], v[3], v[2]]])
    fold = _fold_threads_parallel if e_ts.shape[0] > 1 else _fold_threads_serial
    e_p, f_pc = fold(e_ts, f_tsc, points.order_s, points.ghost_s, points.src_e, points.n_particles)
    return e_p, f_pc, virial


def pair_potential_sums(pairs, r_pc, h, scale, kernel, want_virial=False):
    """Energy, forces and virial of ``phi(r) = scale * f(r / h)`` summed over pairs.

    Parameters
    ----------
    pairs : NeighborList or BinnedPoints
        A Verlet list updated for ``r_pc``, or binned points for a one-shot
        evaluation fused into the bin scan (no list is stored).
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
    x_sc = pairs.extend(r_pc)
    nthreads = _threads(x_sc.shape[0])
    args = (float(h), float(scale), kernel.kind, kernel.breaks, kernel.coef, bool(want_virial),
            *_thread_buffers(nthreads, x_sc.shape[0]))
    if isinstance(pairs, BinnedPoints):
        run = _scan_parallel if nthreads > 1 else _scan_serial
        out = run(x_sc, pairs.src_s, pairs.img_sc, pairs.is_ghost_s, pairs.bin_s, pairs.nbin_c, pairs.bin_start,
                  pairs.stencil_kc, *args)
        return _reduce(pairs, *out)
    run = _list_parallel if nthreads > 1 else _list_serial
    out = run(x_sc, pairs.pair_start, pairs.pair_j, *args)
    return _reduce(pairs.points, *out)


@numba.njit(cache=True)
def _kernel_sums(x_sc, pair_start, pair_j, h, kind, breaks, coef):
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
            value, slope = profile_by_kind(r * inv_h, kind, breaks, coef)
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
    w_s, g_sc = _kernel_sums(x_sc, nlist.pair_start, nlist.pair_j, float(h), kernel.kind, kernel.breaks, kernel.coef)
    norm = kernel.sigma / h**kernel.dim
    w_p = norm * (nlist.fold(w_s) + kernel.f0)
    grad_pc = norm / h * nlist.fold(g_sc)
    return KernelSums(w_p, grad_pc)
