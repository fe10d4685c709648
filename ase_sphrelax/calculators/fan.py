"""Fan et al.'s total error as an ASE calculator.

Energy (Fan Eq. 3.8), with ``v0 = vt`` (Appendix A):

    E = sum_{i,j} W(|x_i - x_j|, h) v0 vt  -  V  +  sum_i 2 vt I(-phi(x_i)),
    I(s) = int_s^h W1(max(r, 0), h) dr,

where the double sum includes ``i = j``, ``V`` is the domain volume and
``W1`` is the kernel profile normalised on ``[-h, h]`` (Eq. 3.5). Its negative
gradient is exactly Eq. 3.17 inside and Eq. 4.4 with the boundary term:

    F_i = 2 v0 vt sum_{j != i} W'(r_ij) e_ij  -  2 W1(max(-phi_i, 0), h) vt n_i,

with ``e_ij = (x_j - x_i) / r_ij``. Stress (periodic cells, no domain) is the
exact strain derivative of ``E`` divided by the cell volume, including the
``-V`` term and, when ``dx`` is None, the dependence of ``v0 = V / N`` on the cell.
"""
from __future__ import annotations

import numpy as np
from ase.calculators.calculator import PropertyNotImplementedError, all_changes

from ..kernel_sums import pair_potential_sums
from ..kernels import get_kernel
from ..checks import check_positive
from .base import SPHCalculator, periodic_measure

__all__ = ["FanCalculator"]


class FanCalculator(SPHCalculator):
    """Total error E of Fan et al. (Eq. 3.8) with forces -dE/dx (Eq. 3.17, 4.4).

    Parameters
    ----------
    h : float
        Kernel cut-off (support) radius, in length units (Fan's ``h``, e.g. ``2.6 * dx``).
    dx : float or None
        Background cell size: ``v0 = vt = dx**dim`` (Appendix A). With None,
        ``v0 = vt = V / N`` (Eq. 3.2), with ``V`` the domain volume or, for a
        periodic cell, its area (2D) or volume (3D).
    domain : Domain or None
        Level set ``phi`` (negative inside) with ``phi_and_normal``; adds the
        boundary term of Eq. 3.8 / 4.4. None is the interior case (periodic or free).
    dim : {1, 2, 3}
        Coordinates beyond ``dim`` are ignored; 2D particles live at z = 0.
    kernel : str
        Kernel name (:data:`ase_sphrelax.kernels.KERNEL_NAMES`); Fan uses ``"wendland_c2"``.
    skin : float or None
        Verlet skin of the neighbour list (default ``0.1 * h``).

    Notes
    -----
    ``free_energy`` equals ``energy``; ``energies`` splits ``E`` per particle:
    ``v0 vt sum_j W_ij - V/N + 2 vt I(-phi_i)``. Two coincident particles give
    zero mutual force (the kernel is flat at r = 0), never NaN.
    """

    implemented_properties = ["energy", "free_energy", "energies", "forces", "stress"]
    default_parameters = dict(h=None, dx=None, domain=None, dim=2, kernel="wendland_c2", skin=None)

    def __init__(self, h=None, dx=None, domain=None, dim=2, kernel="wendland_c2", skin=None, **kwargs):
        super().__init__(h=h, dx=dx, domain=domain, dim=dim, kernel=kernel, skin=skin, **kwargs)

    def _validate_parameters(self):
        super()._validate_parameters()
        p = self.parameters
        p.h = check_positive("h", p.h)
        p.dx = check_positive("dx", p.dx, allow_none=True)
        if p.skin is None:
            p.skin = 0.1 * p.h
        elif not np.isfinite(p.skin) or p.skin < 0:
            raise ValueError(f"skin must be a finite number >= 0 or None, got {p.skin!r}")
        if p.domain is not None:
            if not hasattr(p.domain, "phi_and_normal"):
                raise TypeError(f"domain must be a Domain with phi_and_normal() or None, got {type(p.domain).__name__}")
            if getattr(p.domain, "dim", p.dim) != p.dim:
                raise ValueError(f"domain is {p.domain.dim}D but dim={p.dim}")
        self.kernel = get_kernel(p.kernel, p.dim)

    # -- volumes ---------------------------------------------------------------
    def volumes(self, atoms):
        """(V, v0, measure): domain volume, particle volume v0 = vt, periodic cell measure or None."""
        p = self.parameters
        measure = periodic_measure(atoms.cell.array, atoms.pbc, p.dim)
        n = len(atoms)
        if p.domain is not None:
            volume = float(p.domain.volume)
        elif measure is not None:
            volume = measure
        elif p.dx is not None:
            volume = n * p.dx**p.dim
        else:
            raise ValueError("dx=None needs a domain or a cell periodic along all dim axes to define v0 = V/N; "
                             "give dx")
        v0 = p.dx**p.dim if p.dx is not None else volume / n
        return volume, v0, measure

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        p = self.parameters
        atoms = self.atoms
        want_stress = "stress" in properties
        volume, v0, measure = self.volumes(atoms)
        if want_stress and (p.domain is not None or measure is None):
            raise PropertyNotImplementedError("stress needs a cell periodic along all dim axes and no domain")
        r_pc, _ = self.prepare(atoms, p.h, p.skin)
        n = len(atoms)
        kernel = self.kernel
        w_norm = kernel.sigma / p.h**p.dim  # W = w_norm * f(q)
        # interior: sum_{i != j} = 2 sum_pairs, plus N self terms
        pair_e_p, f_pc, virial = pair_potential_sums(self.pairs, r_pc, p.h, 2.0 * v0 * v0 * w_norm, kernel,
                                                     want_virial=want_stress)
        self_term = v0 * v0 * kernel.w0(p.h)
        energies_p = pair_e_p + self_term - volume / n
        if p.domain is not None:
            phi_p, n_pc = p.domain.phi_and_normal(r_pc)
            phi_p = np.asarray(phi_p, dtype=float)
            energies_p += 2.0 * v0 * kernel.w1_tail_integral(-phi_p, p.h)
            f_pc -= (2.0 * v0 * kernel.w1(np.maximum(-phi_p, 0.0), p.h))[:, None] * np.asarray(n_pc)[:, :3]
        f_pc[:, p.dim:] = 0.0
        energy = float(energies_p.sum())
        self.results["energy"] = energy
        self.results["free_energy"] = energy
        self.results["energies"] = energies_p
        self.results["forces"] = f_pc
        if want_stress:
            self.results["stress"] = self._stress(atoms, virial, energy + volume, v0, measure)

    def _stress(self, atoms, virial, sum_term, v0, measure):
        """Voigt stress (1/V_cell) dE/d(strain); ``sum_term = v0^2 sum_{i,j} W_ij``."""
        p = self.parameters
        d_e = virial.copy()
        in_plane = np.zeros((3, 3))
        in_plane[: p.dim, : p.dim] = np.eye(p.dim)
        d_e -= measure * in_plane  # the -V term
        if p.dx is None:
            # v0 = vt = V/N scales with the cell measure: d(v0^2)/d eps = 2 v0^2 delta
            d_e += 2.0 * sum_term * in_plane
        stress_cc = d_e / atoms.get_volume()
        return stress_cc.flat[[0, 4, 8, 5, 2, 1]]
