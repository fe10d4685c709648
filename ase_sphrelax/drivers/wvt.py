"""Weighted Voronoi Tessellation relaxation (Diehl et al. 2015) as an inertia-free ASE Optimizer.

All particles move at once (ALARIC Eq. 28, WVTICs' form of the pair weight):

    dx_i = mu H_i sum_j w(r_ij / H_ij) rhat_ij,     H_ij = (H_i + H_j) / 2,  r_ij < H_ij,

with ``rhat_ij`` pointing from j to i (repulsive), ``H_i`` the support radius that holds ``eta^d``
neighbours at the target density, ``H_i = eta (m / rho*(x_i))^(1/d)`` with ``m`` the mean mass
``V mean(rho*) / N`` (``V`` the domain's volume or the periodic cell's measure), and the weight

* ``"r2"``: Diehl's r^-2 force, ``w(q) = 1/(q + 0.01)^2 - 1/1.01^2`` (zero at the support);
* ``"kernel"``: the SPH kernel profile ``w(q) = sigma f(q)`` (``h^d W``), the variant the ALARIC
  authors suggest (Sec. 1.4.4).

The step factor ``mu`` follows one of two schedules:

* ``"linear"`` (default): ``mu`` decreases linearly from ``mu0`` to ``0`` over ``steps`` iterations (ALARIC
  Sec. 5.1);
* ``"diehl"``: Diehl et al.'s adaptive schedule as WVTICs runs it (Arth et al. 2019): ``mu`` starts at ``mu0`` and
  is multiplied by ``0.95`` whenever the number of particles that moved more than a tenth of their local mean
  spacing ``H_i / eta`` grew from the previous iteration; the run stops when fewer than 1 % of the particles
  moved more than a thousandth of it, or after ``steps`` iterations.

Edges (``boundary``): particles that leave the domain are put back on its inside (``x - (phi + 1e-9 H) n``)
in both treatments; ``"mirror"`` also adds, for every particle within the largest ``H`` of the boundary, its
radial mirror image (:func:`ase_sphrelax.models.alaric.mirror_map`, the ghosts of ALARIC's
``boundary="mirror"``), whose H is its owner's and which pushes the real particles by the same pair weight
(the ghosts themselves do not move). The pair sum is a :class:`~ase_sphrelax.pairs.PairInteraction`;
positions only, no forces, no energy: a driver.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from ase.optimize.optimize import Optimizer
from scipy.spatial import cKDTree

from ..checks import check_positive, resolve_dim
from ..kernels import get_kernel, kernel_profile
from ..neighbors import NeighborList
from ..pairs import Output, PairInteraction
from ..sph import default_eta, scaled

__all__ = ["WVTRelaxation", "WEIGHTS", "SCHEDULES", "BOUNDARIES"]

WEIGHTS = ("r2", "kernel")
SCHEDULES = ("linear", "diehl")
BOUNDARIES = ("project", "mirror")
# Diehl's schedule as WVTICs runs it (ics.par: StepReduction 0.95, LimitMps1000 1): the reduction factor, the
# move (in local mean spacings) whose count must not grow, and the (move, fraction) of the stop
DIEHL_REDUCTION = 0.95
DIEHL_COUNT_MOVE = 0.1
DIEHL_STOP_MOVE = 1e-3
DIEHL_STOP_FRACTION = 0.01
# the r^-2 weight sums to about 20x the kernel weight over a neighbourhood: first moves of ~H/40 for both
DEFAULT_MU0 = {"r2": 0.002, "kernel": 0.05}


@numba.njit(cache=True, inline="always")
def _wvt_pair(a, b, r2, d, use_kernel, sigma, h_s):
    hab = 0.5 * (h_s[a] + h_s[b])
    if r2 == 0.0 or r2 >= hab * hab:
        z = scaled(0.0, d)
        return z, z, ()
    r = math.sqrt(r2)
    q = r / hab
    if use_kernel:
        w = sigma * kernel_profile(q)[0]
    else:
        w = 1.0 / ((q + 0.01) * (q + 0.01)) - 1.0 / (1.01 * 1.01)
    g = w / r  # rhat_ab = -d / r pushes a away from b
    return scaled(-g, d), scaled(g, d), ()


_WVT = PairInteraction(_wvt_pair, dict(dx=Output((3,))), params=("use_kernel", "sigma"), inputs=("h_s",))


class WVTRelaxation(Optimizer):
    """Diehl et al.'s WVT update (Eq. 28) with ``mu`` decreasing linearly to zero, or by Diehl's schedule.

    Parameters
    ----------
    atoms : Atoms
    target_density : callable
        ``(N, dim) -> (N,)``, ``> 0`` where particles are.
    dim : {1, 2, 3} or None
        None (default): the domain's, else inferred from the Atoms by
        :func:`ase_sphrelax.checks.resolve_dim` (a mismatch is an error, never a projection).
    steps : int
        Length of the ``mu`` schedule (and the natural ``run(steps=...)``); ``schedule="diehl"``: the most
        iterations.
    mu0 : float or None
        Initial ``mu`` (default :data:`DEFAULT_MU0` of the weight).
    weight : {"r2", "kernel"}
    domain : Domain or None
        Particles outside are put back inside after each step.
    schedule : {"linear", "diehl"}
        ``mu`` to zero linearly over ``steps``, or Diehl's adaptive reduction and stop (module docstring).
    boundary : {"project", "mirror"}
        ``"project"`` (default): particles that leave are put back only; ``"mirror"``: also the mirror ghosts
        of the particles near the boundary push them (needs a ``domain`` that
        :func:`~ase_sphrelax.models.alaric.mirror_supported` accepts: a ball or a convex polygon).
    kernel : str
        Kernel of the ``"kernel"`` weight and of ``eta``.
    eta : float or None
        Neighbours: ``H = eta (m / rho*)^(1/d)`` (default :func:`ase_sphrelax.sph.default_eta`).
    """

    def __init__(self, atoms, target_density, dim=None, steps=1000, mu0=None, weight="r2", domain=None,
                 kernel="wendland_c4", eta=None, schedule="linear", boundary="project", logfile=None, **kwargs):
        if not callable(target_density):
            raise TypeError(f"target_density must be callable, got {type(target_density).__name__}")
        if weight not in WEIGHTS:
            raise ValueError(f"weight must be one of {WEIGHTS}, got {weight!r}")
        if schedule not in SCHEDULES:
            raise ValueError(f"schedule must be one of {SCHEDULES}, got {schedule!r}")
        if boundary not in BOUNDARIES:
            raise ValueError(f"boundary must be one of {BOUNDARIES}, got {boundary!r}")
        if boundary == "mirror":
            from ..models.alaric import mirror_supported

            if domain is None or not mirror_supported(domain):
                raise ValueError(f"boundary='mirror' needs a ball or a convex polygon as domain, got {domain!r}")
        self.target_density = target_density
        self.dim = resolve_dim(atoms, dim, domain)
        self.schedule = int(steps)
        if self.schedule < 1:
            raise ValueError(f"steps must be a positive integer, got {steps!r}")
        self.mu0 = DEFAULT_MU0[weight] if mu0 is None else check_positive("mu0", mu0)
        self.weight = weight
        self.schedule_kind = schedule
        self.boundary = boundary
        self.domain = domain
        self.kernel = get_kernel(kernel, self.dim)
        self.eta = default_eta(self.kernel) if eta is None else check_positive("eta", eta)
        self.nlist = None
        self.iteration = 0
        self.last_max_move = 0.0
        self.n_ghosts = 0
        Optimizer.__init__(self, atoms, logfile=logfile, **kwargs)  # calls initialize()

    def initialize(self):
        self.iteration = 0
        self.mu = self.mu0
        self.stopped = False  # Diehl's stop criterion met
        self._last_count = None

    def read(self):
        self.initialize()  # a restart file holds nothing of WVT's: start the schedule afresh

    def _volume(self, atoms):
        if self.domain is not None:
            return float(self.domain.volume)
        d = self.dim
        if np.all(atoms.pbc[:d]):
            vec = atoms.cell.array[:d, :d]
            return float(abs(np.linalg.det(vec)))
        return float(np.prod(np.ptp(atoms.positions[:, :d], axis=0)))

    def smoothing_lengths(self, atoms):
        """``H_i = eta (V mean(rho*) / (N rho*(x_i)))^(1/d)``."""
        x = np.ascontiguousarray(atoms.positions[:, : self.dim])
        rho = np.asarray(self.target_density(x), dtype=float)
        if rho.shape != (len(atoms),) or not np.all(np.isfinite(rho)) or np.any(rho <= 0):
            raise ValueError("target_density must return finite values > 0 of shape (N,) at the particles")
        mass = self._volume(atoms) * rho.mean() / len(atoms)
        return self.eta * (mass / rho) ** (1.0 / self.dim)

    def step(self, f=None):
        atoms = self.atoms
        h_p = self.smoothing_lengths(atoms)
        r_pc = atoms.positions.copy()
        r_pc[:, self.dim:] = 0.0
        pbc = np.array(atoms.pbc, dtype=bool)
        pbc[self.dim:] = False
        if self.nlist is None:
            self.nlist = NeighborList(h_p, skin=0.2 * float(h_p.mean()))
        self.nlist.update(r_pc, atoms.cell.array, pbc, cutoff=h_p)
        k = self.kernel
        params = dict(use_kernel=self.weight == "kernel", sigma=k.sigma)
        dx = _WVT.compute(self.nlist, r_pc, params=params, inputs=dict(h_s=h_p), reach=float(h_p.max()), kernel=k).dx
        if self.boundary == "mirror":
            dx[:, : self.dim] += self._ghost_push(r_pc[:, : self.dim], h_p)
        if self.schedule_kind == "linear":
            self.mu = self.mu0 * max(0.0, 1.0 - self.iteration / self.schedule)
        move = self.mu * h_p[:, None] * dx
        # cap a single move at a quarter of H (close pairs under the r^-2 weight)
        length = np.sqrt((move**2).sum(axis=1))
        cap = 0.25 * h_p
        move *= np.minimum(1.0, cap / np.where(length > 0, length, 1.0))[:, None]
        if self.schedule_kind == "diehl":
            self._diehl_update(np.minimum(length, cap) / (h_p / self.eta))
        new = r_pc + move
        if self.domain is not None:
            phi, normal = self.domain.phi_and_normal(new)
            out = np.asarray(phi) > 0
            new[out] -= (np.asarray(phi)[out] + 1e-9 * h_p[out])[:, None] * np.asarray(normal)[out]
        new[:, self.dim:] = atoms.positions[:, self.dim:]
        self.last_max_move = float(np.sqrt(((new - r_pc) ** 2).sum(axis=1)).max())
        atoms.set_positions(new)
        self.iteration += 1

    def _ghost_push(self, x_pd, h_p):
        """``sum_g w(r_ig / H_ig) rhat_ig`` over the mirror ghosts ``g`` within ``H_ig = (H_i + H_owner(g)) / 2``."""
        from ..models.alaric import mirror_map

        band = float(h_p.max())
        owner_g, g_gd, _, _ = mirror_map(self.domain, x_pd, band)
        self.n_ghosts = len(owner_g)
        out = np.zeros_like(x_pd)
        if not len(owner_g):
            return out
        pairs = cKDTree(x_pd).sparse_distance_matrix(cKDTree(g_gd), band, output_type="coo_matrix")
        i, g, r = pairs.row, pairs.col, pairs.data
        hab = 0.5 * (h_p[i] + h_p[owner_g[g]])
        keep = (r > 0.0) & (r < hab)
        i, g, r, hab = i[keep], g[keep], r[keep], hab[keep]
        q = r / hab
        if self.weight == "kernel":
            w = self.kernel.sigma * self.kernel.profile(q)
        else:
            w = 1.0 / (q + 0.01) ** 2 - 1.0 / 1.01**2
        push = (w / r)[:, None] * (x_pd[i] - g_gd[g])
        for c in range(x_pd.shape[1]):
            out[:, c] = np.bincount(i, weights=push[:, c], minlength=len(x_pd))
        return out

    def _diehl_update(self, move_over_spacing):
        """Diehl's schedule after a step's moves (in local mean spacings): stop, or reduce ``mu`` when the count of
        moves above :data:`DIEHL_COUNT_MOVE` grew."""
        n = len(move_over_spacing)
        if np.count_nonzero(move_over_spacing > DIEHL_STOP_MOVE) < DIEHL_STOP_FRACTION * n:
            self.stopped = True
        count = int(np.count_nonzero(move_over_spacing > DIEHL_COUNT_MOVE))
        if self._last_count is not None and count > self._last_count:
            self.mu *= DIEHL_REDUCTION
        self._last_count = count

    def converged(self, *args, **kwargs):
        return self.iteration >= self.schedule or self.stopped

    def irun(self, steps=None):
        """Iterate the update (no forces are needed); ``steps`` defaults to the schedule's length."""
        steps = self.schedule if steps is None else int(steps)
        self.max_steps = self.nsteps + steps
        if self.nsteps == 0:
            self.call_observers()
        yield self.converged()
        while not self.converged() and self.nsteps < self.max_steps:
            self.step()
            self.nsteps += 1
            self.log()
            self.call_observers()
            yield self.converged()

    def run(self, steps=None):
        """Run the schedule (or ``steps`` iterations); True when the schedule is complete."""
        for converged in self.irun(steps):
            pass
        return converged

    def log(self, gradient=None):
        if self.logfile is not None:
            self.logfile.write(f"WVT {self.iteration:6d} mu {self.mu:.4e} max move {self.last_max_move:.4e}\n")
