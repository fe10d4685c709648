"""Quality metrics every relaxation method is judged by.

For particles with volume ``V_j`` (the average volume ``v0``, Fan Eq. 3.2; ``dx^d`` or
``V / N`` by :meth:`ase_sphrelax.models.fan.FanModel.volumes`, the rule of the Fan calculators):

* zeroth-order consistency (partition of unity) ``|sum_j V_j W_ij - 1|``,
* first-order consistency ``|sum_j V_j grad_i W_ij|`` (reported times ``h`` to
  be dimensionless),

both summarised (mean and max) over the particles whose kernel support lies
inside the domain (``phi_i <= -h``; every particle in the interior case), and
for bounded domains the distances of the boundary-layer particles
(``-phi_i < 0.75 dp``, ``dp = v0^(1/d)``) to the boundary, which Fan Sec. 4.2
expects at half a layer spacing (``dp/2`` for a square lattice, ``sqrt(3)/4``
times the neighbour distance for a hexagonal one).

Next to walls (the particles whose support the boundary cuts, ``phi_i > -h``) the kernel sums
are judged with the continuum completed beyond the wall (issue 33 item 3): with ``gamma_i`` the
exact kernel volume fraction of the boundary (BIPI Eq. 2-3, :mod:`ase_sphrelax.boundary`),
``|sum_j V_j W_ij + (1 - gamma_i) - 1|`` and ``h |sum_j V_j grad_i W_ij - grad gamma_i|`` should
vanish there as the plain sums do inside. ``gamma`` comes from the domain's boundary elements
(Polygon, Box, polygonal CSG, Mesh), from an inscribed 1024-gon for a Circle; other domains
(Sphere) get None for these metrics.

The dimension follows the package's one rule (:func:`ase_sphrelax.checks.resolve_dim`):
``dim=None`` takes the domain's, else infers it from the atoms; a mismatch is an error.
A metric over an empty set of particles (no interior particle, no boundary layer) is None,
never NaN.
"""
from __future__ import annotations

import numpy as np

from ..calculators.base import periodic_measure
from ..checks import resolve_dim
from ..kernel_sums import kernel_sums
from ..models.fan import FanModel
from ..neighbors import NeighborList

__all__ = ["Quality", "quality_summary"]

BOUNDARY_LAYER = 0.75  # boundary layer: -phi < BOUNDARY_LAYER * dp


class Quality:
    """Kernel-sum quality of a particle distribution, freud-style.

    Parameters
    ----------
    h : float
        Kernel cut-off radius.
    dx : float or None
        ``V_j = dx**dim``; None uses ``V / N`` (domain volume, or periodic cell measure).
        Parameters are checked as by :class:`~ase_sphrelax.FanCalculator` (one model,
        :class:`~ase_sphrelax.models.fan.FanModel`).
    domain : Domain or None
    dim : {1, 2, 3} or None
        None: the domain's dimension, else that of the atoms (:func:`ase_sphrelax.checks.resolve_dim`).
    kernel : str

    Attributes (after :meth:`compute`)
    ----------------------------------
    dim : int
        The dimension of the atoms computed.
    kernel_sum_p : ndarray
        ``sum_j V_j W_ij`` per particle (including j = i).
    kernel_sum_error_p : ndarray
        ``|sum_j V_j W_ij - 1|`` per particle.
    gradient_error_p : ndarray
        ``h |sum_j V_j grad_i W_ij|`` per particle.
    volume_p : ndarray
        Particle volume ``1 / sum_j W_ij`` (Fan Eq. 3.10).
    interior_p : ndarray of bool
        Particles whose support lies inside the domain.
    phi_p : ndarray or None
        Level set at the particles.
    boundary_distance_b : ndarray
        ``-phi / dp`` of the boundary-layer particles (empty without a domain).
    completed_sum_p, completed_error_p, completed_gradient_p : ndarray or None
        ``sum_j V_j W_ij + 1 - gamma_i``, its distance to 1 and ``h |sum_j V_j grad W_ij - grad gamma_i|`` (None
        without a domain or without boundary elements for it).
    """

    def __init__(self, h, dx=None, domain=None, dim=None, kernel="wendland_c2"):
        self._dim = dim
        self.model = FanModel(h, dx, domain, getattr(domain, "dim", 2) if dim is None else dim, kernel)
        self.h, self.dx, self.domain, self.dim = self.model.h, self.model.dx, self.model.domain, self.model.dim
        self.kernel = self.model.kernel

    def compute(self, atoms):
        """Compute the metrics for ``atoms``; returns self."""
        n = len(atoms)
        if n == 0:
            raise ValueError("atoms: need at least one particle, got an empty Atoms")
        self.model = self.model.with_dim(resolve_dim(atoms, self._dim, self.domain))
        self.dim, self.kernel = self.model.dim, self.model.kernel
        v0 = self.model.volumes(n, periodic_measure(atoms.cell.array, atoms.pbc, self.dim)).v0
        r_pc = np.array(atoms.positions, dtype=float)
        r_pc[:, self.dim:] = 0.0  # round-off only: resolve_dim refused anything else
        pbc = np.array(atoms.pbc, dtype=bool)
        pbc[self.dim:] = False
        nlist = NeighborList(self.h)
        nlist.update(r_pc, atoms.cell.array, pbc)
        sums = kernel_sums(nlist, r_pc, self.h, self.kernel, planar=self.dim < 3)
        self.v0 = v0
        self.dp = v0 ** (1.0 / self.dim)
        self.volume_p = 1.0 / sums.w_p
        self.kernel_sum_p = v0 * sums.w_p
        self.kernel_sum_error_p = np.abs(self.kernel_sum_p - 1.0)
        self.gradient_error_p = self.h * v0 * np.linalg.norm(sums.grad_pc, axis=1)
        self.completed_sum_p = self.completed_error_p = self.completed_gradient_p = None
        if self.domain is None:
            self.phi_p = None
            self.interior_p = np.ones(n, dtype=bool)
            self.boundary_distance_b = np.zeros(0)
        else:
            integrals = self._integrals()
            if integrals is not None:
                terms = integrals.compute(nlist, r_pc)
                self.completed_sum_p = self.kernel_sum_p + (1.0 - terms.gamma_p)
                self.completed_error_p = np.abs(self.completed_sum_p - 1.0)
                self.completed_gradient_p = self.h * np.linalg.norm(v0 * sums.grad_pc - terms.grad_gamma_pc, axis=1)
            self.phi_p = np.asarray(self.domain.phi(r_pc), dtype=float)
            self.interior_p = self.phi_p <= -self.h
            layer = -self.phi_p < BOUNDARY_LAYER * self.dp
            self.boundary_distance_b = -self.phi_p[layer] / self.dp
        return self

    def _integrals(self):
        """Exact gamma of the domain's boundary (the model's, or of a Circle's 1024-gon), or None."""
        if getattr(self, "_gamma_integrals", False) is not False:
            return self._gamma_integrals
        integrals = getattr(self.model, "_integrals", None)
        if integrals is None and self.dim == 2 and hasattr(self.domain, "to_polygon"):
            from ..boundary import BoundaryIntegrals

            integrals = BoundaryIntegrals(self.domain.to_polygon(1024), self.h, self.kernel.name)
        self._gamma_integrals = integrals
        return integrals

    def summary(self):
        """Dictionary of the headline numbers (means and maxima over interior particles).

        A statistic of an empty set (no interior particle, no boundary-layer particle) is None.
        ``kernel_sum_mean`` is the mean ``sum_j V_j W_ij``, which a relaxed lattice puts at
        ``1 / v_c`` (Fan Sec. 5), not at 1.
        """
        inside = self.interior_p
        out = {
            "n_particles": int(len(self.kernel_sum_error_p)),
            "n_interior": int(inside.sum()),
            "kernel_sum_mean": _mean(self.kernel_sum_p[inside]),
            "kernel_sum_error_mean": _mean(self.kernel_sum_error_p[inside]),
            "kernel_sum_error_max": _max(self.kernel_sum_error_p[inside]),
            # spread of sum_j V_j W_ij: uniformity, independent of a global density offset
            "kernel_sum_std": _std(self.kernel_sum_p[inside]),
            "gradient_error_mean": _mean(self.gradient_error_p[inside]),
            "gradient_error_max": _max(self.gradient_error_p[inside]),
            "gradient_error_std": _std(self.gradient_error_p[inside]),
        }
        if self.phi_p is not None:
            out.update(
                n_boundary_layer=int(len(self.boundary_distance_b)),
                boundary_distance_mean=_mean(self.boundary_distance_b),
                boundary_distance_min=_min(self.boundary_distance_b),
                boundary_distance_max=_max(self.boundary_distance_b),
                boundary_distance_std=_std(self.boundary_distance_b),
                max_phi_over_dp=float(self.phi_p.max() / self.dp),
                n_outside=int((self.phi_p > 0).sum()),
                n_near_wall=int((~inside).sum()),
            )
            # next to walls, with the continuum completed beyond them (module docstring); None without gamma
            near = ~inside
            done = self.completed_error_p is not None
            out.update(
                near_wall_kernel_sum_error_max=_max(self.completed_error_p[near]) if done else None,
                near_wall_kernel_sum_error_mean=_mean(self.completed_error_p[near]) if done else None,
                near_wall_kernel_sum_std=_std(self.completed_sum_p[near]) if done else None,
                near_wall_gradient_error_max=_max(self.completed_gradient_p[near]) if done else None,
            )
        return out


def _mean(x):
    return float(np.mean(x)) if len(x) else None


def _max(x):
    return float(np.max(x)) if len(x) else None


def _min(x):
    return float(np.min(x)) if len(x) else None


def _std(x):
    return float(np.std(x)) if len(x) else None


def quality_summary(atoms, h, dx=None, domain=None, dim=None, kernel="wendland_c2"):
    """Shortcut: ``Quality(h, dx, domain, dim, kernel).compute(atoms).summary()``."""
    return Quality(h, dx=dx, domain=domain, dim=dim, kernel=kernel).compute(atoms).summary()
