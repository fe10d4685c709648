"""Fan's level-set boundary term (Eq. 3.8 last term, Eq. 4.3-4.4) in numpy.

Energy of particle i:  2 vt I(-phi_i),  I(s) = int_s^h W1(max(r, 0), h) dr;
force on particle i:   -2 W1(max(-phi_i, 0), h) vt n_i,
with phi the signed distance (negative inside) and n = grad phi the outward normal.
O(N), used by the LAMMPS ``fix external`` callback and the LAMMPS calculator.
"""
from __future__ import annotations

import numpy as np

from ase_sphrelax.kernels import get_kernel

__all__ = ["boundary_energy_forces"]


def _phi_and_normal(domain, r_pc, dim):
    phi_p, n_pc = domain.phi_and_normal(np.ascontiguousarray(r_pc[:, :dim]))
    phi_p = np.asarray(phi_p, dtype=float).reshape(len(r_pc))
    n_pc = np.asarray(n_pc, dtype=float)
    out = np.zeros((len(r_pc), 3))
    out[:, : n_pc.shape[1]] = n_pc
    return phi_p, out


def boundary_energy_forces(domain, r_pc, h, vt, dim, kernel="wendland_c2"):
    """Boundary energy sum_i 2 vt I(-phi_i) and forces -2 W1(max(-phi_i, 0)) vt n_i.

    Parameters
    ----------
    domain : object with ``phi_and_normal(r_pc) -> (phi_p, n_pc)``
    r_pc : ndarray (N, 3)
    h, vt : float
    dim : {1, 2, 3}

    Returns
    -------
    (float, ndarray (N, 3))
    """
    k = get_kernel(kernel, dim)
    phi_p, n_pc = _phi_and_normal(domain, np.asarray(r_pc, dtype=float), dim)
    s_p = -phi_p
    energy = float(2.0 * vt * np.sum(k.w1_tail_integral(s_p, h)))
    f_pc = -2.0 * vt * k.w1(np.maximum(s_p, 0.0), h)[:, None] * n_pc
    return energy, f_pc
