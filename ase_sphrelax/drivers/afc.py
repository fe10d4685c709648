"""Away-From-Closest (AFC), the naive inertia-free baseline of ALARIC Sec. 5.1 (Fig. 12), as an ASE Optimizer.

The paper's description: "The AFC method simply displaces each particle an amount dr away from its
closest neighbour. The strength of the displacement is also regulated by a free parameter mu which is
linearly brought down to zero in the course of the run." All particles move at once::

    dx_a = mu s_a (x_a - x_c(a)) / |x_a - x_c(a)|,        s_a = (m / rho*(x_a))^(1/d),

with ``c(a)`` the closest neighbour of ``a`` (minimum image along periodic axes), ``s_a`` the local
target spacing (``m = V mean(rho*) / N``, as in :class:`~ase_sphrelax.drivers.wvt.WVTRelaxation`), and
``mu = mu0 (1 - k / steps)`` at iteration ``k``. The paper gives neither the length scale of ``dr`` nor
``mu0``: the local spacing and ``mu0 = 0.1`` are our choices. Two particles at the same place move
apart along a seeded random direction. A step that would leave ``domain`` is cut by
:class:`~ase_sphrelax.drivers.keep_inside.KeepInDomain`; positions are wrapped into periodic cells.

The schedule, the target spacing and the run loop are WVT's (the two differ only in the move); the
closest neighbours come from scipy's k-d tree (O(N log N) per step).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..checks import check_positive
from .keep_inside import KeepInDomain
from .wvt import WVTRelaxation

__all__ = ["AFCRelaxation", "away_from_closest"]

DEFAULT_MU0 = 0.1


def away_from_closest(x_pd, box_d=None, rng=None):
    """Unit vectors from each point's closest neighbour to the point, and the distances.

    Parameters
    ----------
    x_pd : ndarray (P, d)
        Points, ``P >= 2``.
    box_d : ndarray (d,) or None
        Periodic lengths of an orthogonal box ``[0, L)`` (points are wrapped into it), or None.
    rng : numpy Generator or None
        Directions for points that coincide with their closest neighbour (default seed 0).

    Returns
    -------
    away_pd : ndarray (P, d)
        ``(x_a - x_c) / |x_a - x_c|`` (minimum image); a random unit vector where the distance is 0.
    distance_p : ndarray (P,)
    """
    x_pd = np.asarray(x_pd, dtype=float)
    n, d = x_pd.shape
    if n < 2:
        raise ValueError(f"away_from_closest needs at least 2 points, got {n}")
    if box_d is not None:
        box_d = np.asarray(box_d, dtype=float)
        x_pd = np.mod(x_pd, box_d)
        x_pd[x_pd >= box_d] = 0.0  # np.mod can round up to L
    tree = cKDTree(x_pd, boxsize=box_d)
    k = min(3, n)  # self and up to two others: with coincident points the first hit need not be self
    _, idx = tree.query(x_pd, k=k)
    own = np.arange(n)
    closest_p = np.where(idx[:, 0] != own, idx[:, 0], idx[:, 1])
    d_pd = x_pd - x_pd[closest_p]
    if box_d is not None:
        d_pd -= box_d * np.round(d_pd / box_d)
    distance_p = np.sqrt(np.einsum("pd,pd->p", d_pd, d_pd))
    away_pd = np.empty_like(d_pd)
    apart = distance_p > 0
    away_pd[apart] = d_pd[apart] / distance_p[apart, None]
    if not apart.all():
        rng = np.random.default_rng(0) if rng is None else rng
        u = rng.normal(size=(int((~apart).sum()), d))
        away_pd[~apart] = u / np.linalg.norm(u, axis=1, keepdims=True)
    return away_pd, distance_p


class AFCRelaxation(WVTRelaxation):
    """AFC: each particle steps ``mu s_a`` away from its closest neighbour, ``mu`` falling linearly to zero.

    Parameters
    ----------
    atoms : Atoms
        At least 2 particles; periodic axes (within ``dim``) all periodic or none, with an orthogonal cell.
    target_density : callable
        ``(N, dim) -> (N,)``, ``> 0`` where particles are; sets the local spacing ``s_a``.
    dim : {1, 2, 3} or None
        None: the domain's, else inferred from the Atoms (a mismatch is an error).
    steps : int
        Length of the ``mu`` schedule (and the natural ``run()``).
    mu0 : float
        Initial ``mu`` in ``(0, 1]``: the first move is ``mu0`` local spacings (default 0.1).
    domain : Domain or None
        No step leaves it (:class:`~ase_sphrelax.drivers.keep_inside.KeepInDomain`).
    seed : int
        Seed of the directions of coincident particles.
    """

    def __init__(self, atoms, target_density, dim=None, steps=1000, mu0=DEFAULT_MU0, domain=None, seed=0,
                 logfile=None, **kwargs):
        mu0 = check_positive("mu0", mu0)
        if mu0 > 1.0:
            raise ValueError(f"mu0 must be in (0, 1] (the first move in local spacings), got {mu0!r}")
        if len(atoms) < 2:
            raise ValueError(f"atoms must hold at least 2 particles (AFC moves away from the closest), got {len(atoms)}")
        super().__init__(atoms, target_density, dim=dim, steps=steps, mu0=mu0, domain=domain, logfile=logfile,
                         **kwargs)
        self.box_d = self._periodic_box(atoms)
        self.keep = None if domain is None else KeepInDomain(domain)
        self.rng = np.random.default_rng(seed)

    def _periodic_box(self, atoms):
        d = self.dim
        pbc = np.asarray(atoms.pbc[:d], dtype=bool)
        if not pbc.any():
            return None
        cell = atoms.cell.array[:d, :d]
        if not pbc.all() or np.any(cell[~np.eye(d, dtype=bool)] != 0) or np.any(np.diag(cell) <= 0):
            raise ValueError(f"atoms must be periodic along all {d} axes with an orthogonal cell, or along none "
                             f"(AFC), got pbc {atoms.pbc.tolist()} and cell {cell.tolist()}")
        return np.diag(cell).copy()

    def step(self, f=None):
        atoms = self.atoms
        d = self.dim
        spacing_p = self.smoothing_lengths(atoms) / self.eta
        r_pc = atoms.positions.copy()
        away_pd, _ = away_from_closest(r_pc[:, :d], self.box_d, self.rng)
        mu = self.mu0 * max(0.0, 1.0 - self.iteration / self.schedule)
        new = r_pc.copy()
        new[:, :d] += (mu * spacing_p)[:, None] * away_pd
        if self.keep is not None:
            self.keep.adjust_positions(atoms, new)
        self.last_max_move = float(np.sqrt(((new - r_pc) ** 2).sum(axis=1)).max())
        if self.box_d is not None:
            new[:, :d] = np.mod(new[:, :d], self.box_d)
        atoms.set_positions(new)
        self.iteration += 1

    def log(self, gradient=None):
        if self.logfile is not None:
            self.logfile.write(f"AFC {self.iteration:6d} max move {self.last_max_move:.4e}\n")
