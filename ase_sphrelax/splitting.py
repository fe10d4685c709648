"""Particle splitting (ALARIC Sec. 2.4, Fig. 2, Eq. 42).

Each particle ``a`` is replaced by ``p`` particles at ``x_a + q_{a,i}``: in 1D left/centre/right
(``p = 3``), in 2D a triangle with its centre (``p = 4``), in 3D a tetrahedron with its centre
(``p = 5``), with::

    |q_{a,i}| = 2 H_a / (p^(1/d) N_H)                                   (Eq. 42)

for the non-central ones. ``N_H`` is read here as the number of neighbours across a kernel
diameter, ``N_H = 2 H_a / dx_a`` with ``dx_a = n_a^(-1/d)`` the local spacing, so that
``|q| = dx_a / p^(1/d)``, the spacing of the split particles (in 1D exactly the new lattice
spacing, Eq. 42's footnote: the old particle's volume element split into ``p`` fragments). A
different ``N_H`` may be given. The 2D/3D patterns are rotated at random per particle (seeded),
so that no direction is preferred; the 1D pattern is the line.
"""
from __future__ import annotations

import numpy as np

from .checks import check_dim, check_positive

__all__ = ["SPLIT_COUNT", "split_pattern", "split_particles"]

SPLIT_COUNT = {1: 3, 2: 4, 3: 5}


def split_pattern(dim):
    """Unit displacement vectors ``(p, dim)`` of Fig. 2: the centre first, then the outer ones at unit length."""
    dim = check_dim(dim)
    if dim == 1:
        return np.array([[0.0], [-1.0], [1.0]])
    if dim == 2:
        angles = np.pi / 2 + 2 * np.pi * np.arange(3) / 3
        return np.vstack([[0.0, 0.0], np.stack([np.cos(angles), np.sin(angles)], axis=1)])
    tetra = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float) / np.sqrt(3.0)
    return np.vstack([[0.0, 0.0, 0.0], tetra])


def _rotations(rng, n, dim):
    if dim == 1:
        return np.ones((n, 1, 1))
    if dim == 2:
        t = rng.uniform(0, 2 * np.pi, n)
        c, s = np.cos(t), np.sin(t)
        return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    # uniformly random rotations from QR of Gaussian matrices
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q *= np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    det = np.linalg.det(q)
    q[det < 0, :, 0] *= -1
    return q


def split_particles(atoms, h, number_density, dim, n_h=None, seed=0):
    """Split every particle of ``atoms`` in place into the ``p = 3, 4, 5`` pattern of Fig. 2.

    Parameters
    ----------
    atoms : Atoms
        Modified in place: particle ``a`` stays (the centre of its pattern) and ``p - 1`` new
        particles are appended per particle; masses are divided by ``p``; velocities are copied;
        ``info["dx"]`` (the spacing, when there) becomes the spacing after the split, ``dx / p^(1/d)``.
    h, number_density : ndarray (N,)
        Support radius ``H_a`` and number density ``n_a`` of each particle (e.g. the ALARIC
        calculator's ``smoothing_lengths`` and ``number_density``).
    dim : {1, 2, 3}
    n_h : float, ndarray or None
        ``N_H`` of Eq. 42; default ``2 H_a n_a^(1/d)`` (see the module docstring).
    seed : int
        Seed of the random pattern orientations (2D/3D).

    Returns
    -------
    new_h : ndarray (p N,)
        A first guess of the split particles' support radii, ``H_a / p^(1/d)``.
    """
    dim = check_dim(dim)
    n = len(atoms)
    h = np.asarray(h, dtype=float)
    number_density = np.asarray(number_density, dtype=float)
    if h.shape != (n,) or number_density.shape != (n,):
        raise ValueError(f"h and number_density must have shape ({n},), got {h.shape} and {number_density.shape}")
    if not (np.all(np.isfinite(h)) and np.all(h > 0) and np.all(np.isfinite(number_density))
            and np.all(number_density > 0)):
        raise ValueError("h and number_density must be finite and > 0")
    p = SPLIT_COUNT[dim]
    if n_h is None:
        n_h = 2.0 * h * number_density ** (1.0 / dim)
    else:
        n_h = np.broadcast_to(np.asarray(n_h, dtype=float), (n,))
        for value in np.unique(n_h):
            check_positive("n_h", float(value))
    length = 2.0 * h / (p ** (1.0 / dim) * n_h)  # Eq. 42
    rng = np.random.default_rng(seed)
    rot = _rotations(rng, n, dim)
    unit = split_pattern(dim)[1:]  # (p - 1, dim)
    q = np.einsum("nij,kj->nki", rot, unit) * length[:, None, None]  # (n, p-1, dim)
    new_pos = np.repeat(atoms.positions[:, None, :], p - 1, axis=1)
    new_pos[:, :, :dim] += q
    masses = atoms.get_masses() / p
    momenta = atoms.get_momenta() / p  # velocities kept
    atoms.set_masses(masses)
    atoms.set_momenta(momenta)
    extra = atoms[np.repeat(np.arange(n), p - 1)]
    extra.positions = new_pos.reshape(-1, 3)
    atoms.extend(extra)
    if "dx" in atoms.info:  # the spacing after the split: p particles in each old particle's volume
        atoms.info["dx"] = float(atoms.info["dx"]) / p ** (1.0 / dim)
    return np.concatenate([h, np.repeat(h, p - 1)]) / p ** (1.0 / dim)
