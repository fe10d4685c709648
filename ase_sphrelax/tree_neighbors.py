"""Neighbours of point sets in any dimension D: a k-d tree behind the NeighborList interface.

:class:`~ase_sphrelax.neighbors.NeighborList` bins ASE positions (N, 3) into cells, which is
O(N) but needs 3^D stencil bins and so stops paying beyond three axes. Samplers work in
any dimension (SPH-ParVI on a 10-D Gaussian or a 32-parameter logistic-regression
posterior), so :class:`TreeNeighborList` finds the pairs with scipy's ``cKDTree``
(``query_pairs``, O(M log M) to build plus the number of pairs) and stores them as the same
CSR half list, over *sorted points*:

* the points are sorted in the tree's leaf order (``cKDTree.indices``), so that the pair
  loops read neighbours that lie close in memory;
* each pair is stored once, at its lower sorted index: ``pair_j[pair_start[a]:pair_start[a+1]]``
  are the partners ``b > a`` of sorted point ``a``;
* there are no periodic images (open boundaries, no ghosts): the extended points are the
  particles themselves, in sorted order.

It has the methods the pair mechanism calls (``extend``, ``gather``, ``fold_threads``,
``loop_arrays``, ``max_cutoff``), so ``ase_sphrelax.pairs.PairInteraction(..., dim=D)``
walks it with D-component separations exactly as it walks a NeighborList. Like the
NeighborList it is built with ``cutoff + skin`` and reused while
``2 max|displacement| + max(cutoff - cutoff_build, 0) <= skin``.

Why no dense M x M matrices: Huang's SPH-ParVI (Sec. 3, "Practical implementation",
Step 1) caches the distance matrix, the kernel matrix and the M x M x d kernel-gradient
tensor at every step. With compactly supported kernels all but a few dozen entries per row
are zero, so those caches cost O(M^2 d) time and memory for O(M) useful numbers: at
M = 1e5, d = 2 the gradient tensor alone is 160 GB. The sparse half list holds exactly the
non-zero pairs, and the pair loops compute every kernel value and gradient once per pair in
registers, so nothing needs caching.
"""
from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import cKDTree

from .checks import check_skin
from .neighbors import _check_cutoff, _check_positions, fold_thread_buffers

__all__ = ["TreeNeighborList", "brute_force_pairs_nd"]


def _check_points(positions):
    return _check_positions(positions, columns=None)


@numba.njit(cache=True)
def _csr_half_list(a_p, b_p, n):
    """Counting sort of pairs (a < b) by a: returns (pair_start (n + 1,), pair_j)."""
    pair_start = np.zeros(n + 1, dtype=np.int64)
    for p in range(a_p.shape[0]):
        pair_start[a_p[p] + 1] += 1
    for a in range(n):
        pair_start[a + 1] += pair_start[a]
    fill = pair_start[:-1].copy()
    pair_j = np.empty(a_p.shape[0], dtype=np.int32)
    for p in range(a_p.shape[0]):
        a = a_p[p]
        pair_j[fill[a]] = b_p[p]
        fill[a] += 1
    return pair_start, pair_j


class TreeNeighborList:
    """Half list of the pairs within a cut-off, for points in any dimension (open boundaries).

    Parameters
    ----------
    cutoff : float or array_like of shape (M,)
        Interaction radius, or one per point (a pair is listed within the larger of the two,
        as in :class:`~ase_sphrelax.neighbors.NeighborList`). It may change at every :meth:`update`.
    skin : float
        Extra radius of the stored list (reuse while points move less than skin / 2).

    Attributes
    ----------
    order_s : ndarray of int64 (M,)
        The point stored at each sorted position (``x_s = r[order_s]``); also ``src_s``.
    pair_start : ndarray of int64 (M + 1,), pair_j : ndarray of int32
        The CSR half list over sorted points (partners ``b > a``).
    builds : int
        Number of tree builds.
    """

    def __init__(self, cutoff, skin=0.0):
        self.cutoff = _check_cutoff(cutoff)
        self.skin = check_skin(skin)
        self.builds = 0
        self.order_s = None
        self.pair_start = None
        self.pair_j = None
        self._x_buffer = None
        self._gather_buffers = {}
        self._r0_pc = None
        self._cut_build = None
        self._skin_build = 0.0

    # -- state --------------------------------------------------------------------
    @property
    def stored(self):
        """True once a list is built (a tree list is always stored)."""
        return self.pair_j is not None

    @property
    def max_cutoff(self):
        """The largest current cut-off."""
        return float(self.cutoff.max())

    @property
    def n_particles(self):
        return self.order_s.shape[0]

    n_extended = n_particles  # no ghosts

    @property
    def src_s(self):
        return self.order_s

    @property
    def dim(self):
        return None if self._r0_pc is None else self._r0_pc.shape[1]

    def update(self, positions, cell=None, pbc=None, cutoff=None, store=True) -> bool:
        """Make the list valid for ``positions`` (M, D); return True if it was (re)built.

        ``cell`` is ignored and ``pbc`` must be false on every axis (open boundaries): the
        arguments exist so that callers of :class:`~ase_sphrelax.neighbors.NeighborList`
        can pass theirs. ``store=False`` builds without the skin (one evaluation).
        """
        r_pc = _check_points(positions)
        if pbc is not None and np.any(pbc):
            raise ValueError(f"pbc: TreeNeighborList has open boundaries only, got pbc={pbc!r}; "
                             "use NeighborList for periodic cells (D <= 3)")
        if cutoff is not None:
            self.cutoff = _check_cutoff(cutoff)
        if self.cutoff.ndim == 1 and self.cutoff.shape[0] != r_pc.shape[0]:
            raise ValueError(f"cutoff has {self.cutoff.shape[0]} entries but there are {r_pc.shape[0]} points")
        if self._still_valid(r_pc):
            return False
        self._build(r_pc, self.skin if store else 0.0)
        return True

    def _still_valid(self, r_pc):
        if self._r0_pc is None or r_pc.shape != self._r0_pc.shape:
            return False
        growth = float(np.max(self.cutoff - self._cut_build))
        margin = self._skin_build - max(growth, 0.0)
        if margin < 0.0:
            return False
        if margin == 0.0:
            return np.array_equal(r_pc, self._r0_pc)
        disp2 = np.einsum("pc,pc->p", r_pc - self._r0_pc, r_pc - self._r0_pc).max()
        return disp2 <= (0.5 * margin) ** 2

    def _build(self, r_pc, skin):
        n = r_pc.shape[0]
        cut_p = np.broadcast_to(self.cutoff, (n,)).astype(float)
        tree = cKDTree(r_pc)
        order_s = np.asarray(tree.indices, dtype=np.int64)
        rank_p = np.empty(n, dtype=np.int64)
        rank_p[order_s] = np.arange(n)
        pairs = tree.query_pairs(float(cut_p.max()) + skin, output_type="ndarray")
        i_p, j_p = pairs[:, 0], pairs[:, 1]
        if self.cutoff.ndim == 1:  # per-point cut-offs: keep r < max(cut_i, cut_j) + skin
            d_pc = r_pc[j_p] - r_pc[i_p]
            reach_p = np.maximum(cut_p[i_p], cut_p[j_p]) + skin
            keep = np.einsum("pc,pc->p", d_pc, d_pc) < reach_p * reach_p
            i_p, j_p = i_p[keep], j_p[keep]
        a_p, b_p = rank_p[i_p], rank_p[j_p]
        lo_p, hi_p = np.minimum(a_p, b_p), np.maximum(a_p, b_p)
        self.pair_start, self.pair_j = _csr_half_list(lo_p, hi_p, n)
        self.order_s = order_s
        self._x_buffer = np.empty_like(r_pc)
        self._gather_buffers = {}
        self._is_ghost_s = np.zeros(n, dtype=np.bool_)
        self._no_ghosts = np.empty(0, dtype=np.int64)
        self._r0_pc = r_pc.copy()
        self._cut_build = cut_p
        self._skin_build = skin
        self.builds += 1

    # -- the pair-mechanism interface -----------------------------------------------
    def extend(self, positions):
        """Positions of the sorted points (M, D); the array is reused by the next call."""
        r_pc = np.asarray(positions, dtype=float)
        if r_pc.shape != self._x_buffer.shape:
            raise ValueError(f"positions must have shape {self._x_buffer.shape}, got {r_pc.shape}")
        np.take(r_pc, self.order_s, axis=0, out=self._x_buffer)
        return self._x_buffer

    def gather(self, values_p, slot=0):
        """Per-point values (M, ...) in sorted order; the array is reused by the next call with ``slot``."""
        values_p = np.asarray(values_p)
        if values_p.ndim == 0 or values_p.shape[0] != self.n_particles:
            raise ValueError(f"values_p must have one row per point ({self.n_particles}), got shape {values_p.shape}")
        buf = self._gather_buffers.get(slot)
        if buf is None or buf.shape != values_p.shape or buf.dtype != values_p.dtype:
            buf = self._gather_buffers[slot] = np.empty(values_p.shape, dtype=values_p.dtype)
        np.take(values_p, self.order_s, axis=0, out=buf)
        return buf

    def fold(self, values_s):
        """Values on sorted points (M,) or (M, k) back in the points' own order."""
        values_s = np.asarray(values_s, dtype=float)
        out = np.empty_like(values_s)
        out[self.order_s] = values_s
        return out

    def fold_threads(self, bufs, outs=None):
        """Per-point sums (M, k) of per-thread buffers (T, M, k) on sorted points, for each buffer (into ``outs``'
        arrays where given)."""
        # order_s[s] is the point at sorted position s; every point is an original (no ghosts)
        return fold_thread_buffers(bufs, self.order_s, self._is_ghost_s, self._no_ghosts, self.n_particles, outs)

    def loop_arrays(self):
        """("list", (pair_start, pair_j)) for :class:`~ase_sphrelax.pairs.PairInteraction`."""
        return "list", (self.pair_start, self.pair_j)

    def get_pairs(self, positions):
        """Every listed pair once as point indices and separations: (i_p, j_p, d_pc = x_j - x_i)."""
        x_sc = self.extend(positions)
        a_p = np.repeat(np.arange(self.n_particles), np.diff(self.pair_start))
        b_p = self.pair_j
        return self.order_s[a_p], self.order_s[b_p], x_sc[b_p] - x_sc[a_p]


def brute_force_pairs_nd(positions, cutoff):
    """Reference O(M^2) search for tests: dict {(i, j): r} of the pairs i < j with r < cutoff
    (``cutoff`` a number, or one per point combined as the larger of the two)."""
    r_pc = _check_points(positions)
    cut_p = np.broadcast_to(np.asarray(cutoff, dtype=float), (r_pc.shape[0],))
    r_pp = np.linalg.norm(r_pc[None, :, :] - r_pc[:, None, :], axis=2)
    reach_pp = np.maximum(cut_p[:, None], cut_p[None, :])
    i_p, j_p = np.nonzero(np.triu(r_pp < reach_pp, k=1))
    return {(int(i), int(j)): float(r_pp[i, j]) for i, j in zip(i_p, j_p)}
