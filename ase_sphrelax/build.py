"""Initial particle distributions as ``ase.Atoms``.

``fill`` puts one particle at the centre of every background-mesh cell inside
a level-set domain and shifts it by a small random vector (Fan Sec. 3.1:
"the particles are initialized at the cell center with a small random
shift", Eq. 3.3).  ``periodic_box`` builds the periodic interior case of Fan
Sec. 3.4 / 5.1 on a lattice.
"""
from __future__ import annotations

import math
import numbers

import numpy as np
from ase import Atoms

from .checks import check_positive
from .domains.base import Domain

_LATTICES = {2: ("square", "hexagonal"), 3: ("square", "cubic", "sc", "fcc", "bcc")}


def _check_jitter(jitter):
    if isinstance(jitter, bool) or not isinstance(jitter, numbers.Real):
        raise TypeError(f"jitter must be a real number in [0, 0.5), got {jitter!r}")
    jitter = float(jitter)
    if not (0.0 <= jitter < 0.5):
        raise ValueError(f"jitter must be in [0, 0.5) (fraction of dx), got {jitter!r}")
    return jitter


def _jitter(rng, shape, jitter, dx):
    if jitter == 0.0:
        return np.zeros(shape)
    return rng.uniform(-jitter * dx, jitter * dx, size=shape)


#: particles a fill makes without ``max_particles=`` raised (about 10 GB at BYTES_PER_PARTICLE)
MAX_PARTICLES = 20_000_000
#: rough memory of one particle in a relaxation: positions, forces, per-particle arrays and its
#: neighbour pairs at h ~ 3 dx (about 30 in 2D, 110 in 3D, 8 bytes each way)
BYTES_PER_PARTICLE = {1: 200, 2: 500, 3: 1500}


def estimate_fill(domain, dx):
    """The particle count and memory of :func:`fill` before filling: ``(n, bytes)``.

    ``n = V / dx^d`` (the domain's measure ``V``; its bounding box when it has none), the count of
    cell centres inside up to the cells the boundary cuts; ``bytes`` is ``n`` times
    :data:`BYTES_PER_PARTICLE` (an order of magnitude: the run needs about that).
    """
    dx = check_positive("dx", dx)
    try:
        volume = float(domain.volume)
    except Exception:  # a domain without a measure: its bounding box bounds the count
        volume = float("nan")
    if not (np.isfinite(volume) and volume > 0):
        lo, hi = domain.bounds
        volume = float(np.prod(np.asarray(hi, float) - np.asarray(lo, float)))
    n = volume / dx**domain.dim
    return n, n * BYTES_PER_PARTICLE[domain.dim]


def describe_estimate(n, n_bytes):
    """``"about 1.2e+06 particles, about 0.6 GB"``: the words of :func:`estimate_fill`'s numbers."""
    return f"about {n:.3g} particles, about {n_bytes / 1e9:.2g} GB"


def check_particle_count(n, n_bytes, max_particles, name="max_particles"):
    """ValueError (one line, the estimate in it) when ``n > max_particles``."""
    limit = check_positive(name, max_particles)
    if n > limit:
        raise ValueError(f"the fill would make {describe_estimate(n, n_bytes)}, more than {name}={limit:.3g}: "
                         f"choose a larger dx, or raise {name}")


def fill(domain, dx, jitter=0.1, seed=None, origin=None, padding=4, max_particles=MAX_PARTICLES):
    """One particle per background cell whose centre lies inside ``domain``.

    Parameters
    ----------
    domain : Domain
        Level-set domain (``phi < 0`` inside).
    dx : float
        Background mesh spacing; the particle volume is ``v0 ~ dx^d``
        (Fan Eq. 3.3).
    jitter : float
        Each coordinate is shifted by a uniform random number in
        ``[-jitter dx, jitter dx]``; ``0 <= jitter < 0.5``.
    seed : int or numpy.random.Generator, optional
        Random seed for the shifts.
    origin : array_like, optional
        Mesh anchor: cells are ``[origin + k dx, origin + (k+1) dx)``;
        default the coordinate origin.
    padding : float
        The (informational, non-periodic) cell is the bounding box of the
        domain enlarged by ``padding * dx`` on every side; its corner is
        stored as ``atoms.get_celldisp()`` (not kept by extxyz/traj files).
    max_particles : float
        Refuse (ValueError, with the estimate of :func:`estimate_fill`) a fill of more particles
        than this, before any work (default :data:`MAX_PARTICLES`).

    Returns
    -------
    ase.Atoms
        Bounded (``pbc`` all False) system, z = 0 in 2D with cell
        c-vector (0, 0, 1); ``info["dx"] = dx``, ``info["volume"]`` the
        domain volume.

    Notes
    -----
    Fan Sec. 5.2 (circle of radius 0.2 centred at (0.5, 0.5), 256 x 256
    mesh on [0, 1]^2) quotes 8186 particles; the cell centres strictly inside
    that circle are 8224 (brute force, also with ``<=``).  8186 cannot come
    from a cell-centre test on this mesh: the mesh and the circle share the
    symmetries of the square, so the count is a multiple of 4 (here of 8),
    and 8186 = 2 mod 4.  Shifting the mesh (40 x 40 sub-cell offsets) gives
    8224-8250, never fewer, and inscribed regular N-gons (N = 20..360, as
    SPHinXsys' ``addACircle`` builds circles) give multiples of 4 as well.
    SPHinXsys, which Fan et al. used, decides "inside" by its interpolated,
    re-initialised level set (``LevelSetShape::checkContain`` tests
    ``probeSignedDistance(x) < 0``), whose small asymmetric errors remove
    about 38 boundary cells; that procedure is not reproduced here.
    The particle volume used by the calculator is ``V / N`` or ``dx^d``,
    so the difference (0.46 % in N) only matters for reproducing the count.
    """
    if not isinstance(domain, Domain):
        raise TypeError(f"domain must be an ase_sphrelax Domain, got {type(domain).__name__}")
    dx = check_positive("dx", dx)
    jitter = _check_jitter(jitter)
    check_particle_count(*estimate_fill(domain, dx), max_particles)
    dim = domain.dim
    if origin is None:
        origin = np.zeros(dim)
    else:
        origin = np.asarray(origin, dtype=float).reshape(-1)
        if origin.size == 3 and dim == 2:
            if origin[2] != 0:
                raise ValueError(f"origin: a 2D mesh lies at z = 0 (one dimension rule), got z = {origin[2]!r}")
            origin = origin[:2]
        if origin.size != dim or not np.all(np.isfinite(origin)):
            raise ValueError(f"origin must be {dim} finite numbers, got {origin!r}")
    lo, hi = domain.bounds
    k_lo = np.floor((lo - origin) / dx - 0.5).astype(np.int64)
    k_hi = np.ceil((hi - origin) / dx + 0.5).astype(np.int64)
    n_k = k_hi - k_lo
    if float(np.prod(n_k.astype(float))) > 5e8:
        raise ValueError(f"dx={dx!r} gives {np.prod(n_k.astype(float)):.3g} background "
                         "cells; choose a larger dx")
    axes = [origin[d] + (np.arange(k_lo[d], k_hi[d]) + 0.5) * dx for d in range(dim)]
    inside = []
    # slabs along the first axis keep memory bounded
    for x0 in axes[0]:
        grids = np.meshgrid(np.array([x0]), *axes[1:], indexing="ij")
        r_pd = np.stack([g.ravel() for g in grids], axis=1)
        inside.append(r_pd[domain.phi(r_pd) < 0.0])
    r_pd = np.concatenate(inside)
    if len(r_pd) == 0:
        raise ValueError(f"dx={dx!r}: no background cell centre lies inside the domain "
                         "(domain smaller than a cell); choose a smaller dx")
    rng = np.random.default_rng(seed)
    r_pd = r_pd + _jitter(rng, r_pd.shape, jitter, dx)
    positions = np.zeros((len(r_pd), 3))
    positions[:, :dim] = r_pd
    pad = padding * dx
    ext = hi - lo + 2 * pad
    cell = np.eye(3)
    cell[np.arange(dim), np.arange(dim)] = ext
    disp = np.zeros(3)
    disp[:dim] = lo - pad
    atoms = Atoms(positions=positions, cell=cell, pbc=False, celldisp=disp)
    atoms.info["dx"] = dx
    atoms.info["volume"] = float(domain.volume)
    atoms.info["dim"] = dim
    return atoms


def _counts(n, dim):
    if isinstance(n, numbers.Integral) and not isinstance(n, bool):
        n = (int(n),) * dim
    try:
        n = tuple(int(v) for v in n)
    except (TypeError, ValueError):
        raise TypeError(f"n must be an int or a tuple of {dim} ints, got {n!r}") from None
    if len(n) != dim or min(n) < 1:
        raise ValueError(f"n must be an int >= 1 or {dim} such ints, got {n!r}")
    return n


def periodic_box(n, dx=1.0, dim=2, lattice="square", jitter=0.0, seed=None):
    """Periodic box of particles with volume ``dx^d`` each (Fan Sec. 3.4, 5.1).

    Parameters
    ----------
    n : int or tuple of int
        Repetitions per axis: particles per axis for ``square``/``cubic``,
        ``(columns, rows)`` for ``hexagonal`` (rows must be even), conventional
        cubic cells per axis for ``fcc`` (4 particles each) and ``bcc`` (2).
    dx : float
        Particle spacing of the square/cubic lattice; every lattice has the
        same volume per particle ``dx^d``.
    dim : {2, 3}
    lattice : str
        ``"square"`` or ``"hexagonal"`` in 2D; ``"square"`` (simple cubic,
        aliases ``"cubic"``, ``"sc"``), ``"fcc"`` or ``"bcc"`` in 3D.
    jitter : float
        Uniform random shift of each coordinate in ``[-jitter dx, jitter dx]``,
        ``0 <= jitter < 0.5``; positions are wrapped into the cell.
    seed : int or numpy.random.Generator, optional

    Returns
    -------
    ase.Atoms
        2D: z = 0, pbc (True, True, False), cell c-vector (0, 0, 1);
        3D: pbc True.  ``info["dx"] = dx``.
    """
    if dim not in (2, 3) or isinstance(dim, bool):
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    if not isinstance(lattice, str) or lattice not in _LATTICES[dim]:
        raise ValueError(f"lattice must be one of {_LATTICES[dim]} for dim={dim}, got {lattice!r}")
    dx = check_positive("dx", dx)
    jitter = _check_jitter(jitter)
    n = _counts(n, dim)
    if lattice in ("square", "cubic", "sc"):
        basis = np.zeros((1, dim))
        a_d = np.full(dim, dx)
        basis += 0.5
    elif lattice == "hexagonal":
        if n[1] % 2:
            raise ValueError(f"n: a periodic hexagonal lattice needs an even number of rows, got {n!r}")
        a = dx * math.sqrt(2.0 / math.sqrt(3.0))  # sqrt(3)/2 a^2 = dx^2
        a_d = np.array([a, math.sqrt(3.0) * a])  # rectangular cell with 2 particles
        basis = np.array([[0.25, 0.25], [0.75, 0.75]])
        n = (n[0], n[1] // 2)
    elif lattice == "fcc":
        a_d = np.full(3, dx * 4.0 ** (1.0 / 3.0))
        basis = np.array([[0, 0, 0], [0, 0.5, 0.5], [0.5, 0, 0.5], [0.5, 0.5, 0]]) + 0.25
    else:  # bcc
        a_d = np.full(3, dx * 2.0 ** (1.0 / 3.0))
        basis = np.array([[0, 0, 0], [0.5, 0.5, 0.5]]) + 0.25
    idx = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1).reshape(-1, dim)
    frac = (idx[:, None, :] + basis[None, :, :]).reshape(-1, dim)
    r_pd = frac * a_d
    rng = np.random.default_rng(seed)
    r_pd = r_pd + _jitter(rng, r_pd.shape, jitter, dx)
    length_d = np.array(n) * a_d
    r_pd = np.mod(r_pd, length_d)
    positions = np.zeros((len(r_pd), 3))
    positions[:, :dim] = r_pd
    cell = np.eye(3)
    cell[np.arange(dim), np.arange(dim)] = length_d
    pbc = (True, True, dim == 3)
    atoms = Atoms(positions=positions, cell=cell, pbc=pbc)
    atoms.info["dx"] = dx
    atoms.info["dim"] = dim
    return atoms
