"""Shock-front radius per direction and its spread over angle: an isotropy measure for blast waves.

A point explosion in a homogeneous medium has a circular (2D) or spherical (3D) front; a particle
arrangement with preferred directions (a lattice) makes it run faster along some of them (ALARIC
paper, Sec. 5.2, Figs. 14-15). Here the front is located per angular bin around the centre, from a
per-particle field (density, or minus the velocity divergence):

- ``method="peak"``: the particles of one angular bin are binned in radius (width ``dr``); the
  front is the radius of the radial bin whose mean field is largest, refined by the vertex of the
  parabola through it and its two neighbours (clipped to the bin);
- ``method="threshold"``: the front (its leading edge) is the largest radius of a particle of the
  bin whose field exceeds ``threshold``;
- ``method="centroid"``: the front is the mean radius of the bin's particles weighted by
  ``max(field - threshold, 0)`` (the middle of the compressed shell; no radial bins, so it moves
  continuously with the particles).

``threshold=None`` takes the level midway between the ambient field (its median over all the
particles: the blast must cover less than half of them) and the median over the direction bins of
the largest field value of each bin.

The isotropy measure is the relative spread over angle, ``std_k R_k / mean_k R_k`` (and the range
``(max_k R_k - min_k R_k) / mean_k R_k``). Everything is O(N) (``numpy.bincount``). In 2D,
:func:`angular_modes` splits the spread into angular harmonics: a lattice's preferred directions
show as the m = 4 (square) or m = 6 (hexagonal) harmonic, noise spreads over all of them.

Directions: 2D, ``n_angles`` equal bins of the polar angle; 3D, ``n_angles`` bins of the azimuth times
``n_angles // 2`` bins of ``cos(theta)`` (equal solid angle).
"""
from __future__ import annotations

import numbers

import numpy as np

from ..checks import check_dim, check_positive

__all__ = ["relative_positions", "shock_radii", "shock_isotropy", "angular_modes", "SHOCK_METHODS"]

SHOCK_METHODS = ("peak", "threshold", "centroid")


def relative_positions(r_pc, centre, cell=None, pbc=None, dim=2):
    """Positions relative to ``centre``, nearest periodic image along the periodic axes.

    Parameters
    ----------
    r_pc : array (N, >= dim)
        Positions (the first ``dim`` columns are used).
    centre : array (>= dim,)
    cell : array (3, 3) or None
        An orthogonal cell (its diagonal are the periods); needed when ``pbc`` has a True entry.
    pbc : sequence of bool or None
        Periodic axes (default none).
    dim : {2, 3}

    Returns
    -------
    ndarray (N, dim)
    """
    dim = check_dim(dim, (2, 3))
    r_pc = np.asarray(r_pc, dtype=float)
    if r_pc.ndim != 2 or r_pc.shape[1] < dim:
        raise ValueError(f"r_pc must have shape (N, >= {dim}), got {r_pc.shape}")
    centre = np.asarray(centre, dtype=float).ravel()
    if centre.shape[0] < dim or not np.all(np.isfinite(centre[:dim])):
        raise ValueError(f"centre must hold {dim} finite coordinates, got {centre!r}")
    d_pd = r_pc[:, :dim] - centre[:dim]
    pbc = np.zeros(3, bool) if pbc is None else np.asarray(pbc, dtype=bool)
    if pbc[:dim].any():
        if cell is None:
            raise ValueError("cell is needed when pbc has a periodic axis")
        cell = np.asarray(cell, dtype=float)
        if cell.shape != (3, 3) or np.any(np.abs(cell[:dim, :dim] - np.diag(np.diag(cell)[:dim])) > 0):
            raise ValueError(f"cell must be an orthogonal (3, 3) cell along the first {dim} axes")
        for c in range(dim):
            if pbc[c]:
                period = cell[c, c]
                d_pd[:, c] -= period * np.round(d_pd[:, c] / period)
    return d_pd


def _direction_bins(d_pd, n_angles):
    dim = d_pd.shape[1]
    phi = np.mod(np.arctan2(d_pd[:, 1], d_pd[:, 0]), 2.0 * np.pi)
    k_phi = np.minimum((phi / (2.0 * np.pi) * n_angles).astype(np.int64), n_angles - 1)
    if dim == 2:
        centres = (np.arange(n_angles) + 0.5) * 2.0 * np.pi / n_angles
        return k_phi, n_angles, centres[:, None]
    n_theta = max(1, n_angles // 2)
    r = np.sqrt((d_pd**2).sum(axis=1))
    cos_t = np.divide(d_pd[:, 2], r, out=np.zeros_like(r), where=r > 0)
    k_t = np.minimum(((cos_t + 1.0) * 0.5 * n_theta).astype(np.int64), n_theta - 1)
    phi_c = (np.arange(n_angles) + 0.5) * 2.0 * np.pi / n_angles
    cos_c = -1.0 + (np.arange(n_theta) + 0.5) * 2.0 / n_theta
    grid = np.stack(np.meshgrid(cos_c, phi_c, indexing="ij"), -1).reshape(-1, 2)
    return k_t * n_angles + k_phi, n_theta * n_angles, grid  # (cos theta, phi) per bin


def shock_radii(r_pc, value_p, centre, *, cell=None, pbc=None, dim=2, n_angles=32, method="peak", dr=None,
                r_max=None, threshold=None):
    """Front radius per direction bin.

    Parameters
    ----------
    r_pc : array (N, >= dim)
        Particle positions.
    value_p : array (N,)
        The field whose front is sought (density, or ``-div v``).
    centre, cell, pbc, dim :
        See :func:`relative_positions`.
    n_angles : int
        Direction bins: 2D, bins of the polar angle (>= 4); 3D, azimuth bins (times ``n_angles // 2``
        bins of ``cos(theta)``).
    method : {"peak", "threshold", "centroid"}
        See the module docstring.
    dr : float
        Radial bin width of ``"peak"`` (about one or two particle spacings; required there).
    r_max : float or None
        Particles beyond are ignored (default: all).
    threshold : float or None
        The field level of ``"threshold"`` and ``"centroid"`` (None: see the module docstring).

    Returns
    -------
    (ndarray, ndarray)
        ``directions`` (2D: ``(K, 1)`` polar angles; 3D: ``(K, 2)`` of ``(cos theta, phi)``) and
        ``radius_k`` (K,), NaN where a bin holds no particle (or, for ``"threshold"`` and
        ``"centroid"``, none above the level).
    """
    if method not in SHOCK_METHODS:
        raise ValueError(f"method must be one of {SHOCK_METHODS}, got {method!r}")
    if isinstance(n_angles, bool) or not isinstance(n_angles, numbers.Integral) or n_angles < 4:
        raise ValueError(f"n_angles must be an integer >= 4, got {n_angles!r}")
    if method == "peak":
        dr = check_positive("dr", dr)
    elif threshold is not None and (isinstance(threshold, bool) or not isinstance(threshold, numbers.Real)
                                    or not np.isfinite(threshold)):
        raise ValueError(f"threshold must be a finite number or None for method={method!r}, got {threshold!r}")
    r_max = check_positive("r_max", r_max, allow_none=True)
    d_pd = relative_positions(r_pc, centre, cell, pbc, dim)
    value_p = np.asarray(value_p, dtype=float)
    if value_p.shape != (len(d_pd),):
        raise ValueError(f"value_p must have shape ({len(d_pd)},), got {value_p.shape}")
    r_p = np.sqrt((d_pd**2).sum(axis=1))
    keep = np.isfinite(value_p) if r_max is None else np.isfinite(value_p) & (r_p <= r_max)
    k_p, n_bins, directions = _direction_bins(d_pd[keep], int(n_angles))
    r_p, v_p = r_p[keep], value_p[keep]
    radius_k = np.full(n_bins, np.nan)
    if method != "peak":
        if threshold is None:
            top = np.full(n_bins, -np.inf)
            np.maximum.at(top, k_p, v_p)
            ambient = float(np.median(v_p)) if len(v_p) else 0.0
            threshold = 0.5 * (ambient + float(np.median(top[np.isfinite(top)]))) if np.isfinite(top).any() else ambient
        above = v_p > threshold
        if method == "threshold":
            best = np.full(n_bins, -np.inf)
            np.maximum.at(best, k_p[above], r_p[above])
            radius_k[np.isfinite(best)] = best[np.isfinite(best)]
        else:
            w_p = v_p[above] - threshold
            weight = np.bincount(k_p[above], weights=w_p, minlength=n_bins)
            moment = np.bincount(k_p[above], weights=w_p * r_p[above], minlength=n_bins)
            radius_k[weight > 0] = moment[weight > 0] / weight[weight > 0]
        return directions, radius_k
    n_r = int(np.floor((r_p.max() if len(r_p) else 0.0) / dr)) + 1
    j_p = np.minimum((r_p / dr).astype(np.int64), n_r - 1)
    flat = k_p * n_r + j_p
    count = np.bincount(flat, minlength=n_bins * n_r).reshape(n_bins, n_r)
    total = np.bincount(flat, weights=v_p, minlength=n_bins * n_r).reshape(n_bins, n_r)
    mean_kj = np.where(count > 0, total / np.maximum(count, 1), -np.inf)
    for k in np.nonzero(count.sum(axis=1))[0]:
        row = mean_kj[k]
        j = int(np.argmax(row))
        shift = 0.0
        if 0 < j < n_r - 1 and np.isfinite(row[j - 1]) and np.isfinite(row[j + 1]):
            curvature = row[j - 1] - 2.0 * row[j] + row[j + 1]
            if curvature < 0:
                shift = float(np.clip(0.5 * (row[j - 1] - row[j + 1]) / curvature, -0.5, 0.5))
        radius_k[k] = (j + 0.5 + shift) * dr
    return directions, radius_k


def shock_isotropy(r_pc, value_p, centre, **kwargs):
    """The front's mean radius and its relative spread over direction bins.

    Parameters
    ----------
    r_pc, value_p, centre, **kwargs :
        As :func:`shock_radii`.

    Returns
    -------
    dict
        ``mean_radius``, ``spread`` (``std_k R_k / mean_k R_k``, the isotropy measure),
        ``range`` (``(max_k R_k - min_k R_k) / mean_k R_k``), ``radius_k`` (list, NaN for empty bins),
        ``directions`` (list), ``empty_bins`` (bins without a front, left out of the statistics).
    """
    directions, radius_k = shock_radii(r_pc, value_p, centre, **kwargs)
    found = radius_k[np.isfinite(radius_k)]
    mean = float(found.mean()) if len(found) else float("nan")
    ok = len(found) > 1 and mean > 0
    return dict(mean_radius=mean, spread=float(found.std() / mean) if ok else float("nan"),
                range=float(np.ptp(found) / mean) if ok else float("nan"), radius_k=radius_k.tolist(),
                directions=directions.tolist(), empty_bins=int(np.sum(~np.isfinite(radius_k))))


def angular_modes(angles_k, radius_k, modes=(1, 2, 3, 4, 5, 6, 8, 12)):
    """Relative amplitudes of the angular harmonics of a 2D front ``R(theta)``.

    ``a_m = 2 |mean_k R_k exp(-i m theta_k)| / mean_k R_k`` over the bins with a front, so that
    ``R = R0 (1 + eps cos(m theta))`` sampled at bin centres gives ``a_m = eps`` (a bin-mean front
    gives ``eps sin(m w/2) / (m w/2)``, ``w`` the bin width).

    Parameters
    ----------
    angles_k : array (K,) or (K, 1)
        Polar angles of the bins (:func:`shock_radii`'s 2D ``directions``).
    radius_k : array (K,)
        Front radii (NaN bins are left out).
    modes : sequence of int
        Harmonics ``m >= 1``.

    Returns
    -------
    dict
        ``{m: a_m}``.
    """
    theta = np.asarray(angles_k, dtype=float).reshape(-1)
    radius_k = np.asarray(radius_k, dtype=float)
    if theta.shape != radius_k.shape:
        raise ValueError(f"angles_k and radius_k must have one entry per bin, got {theta.shape} and {radius_k.shape}")
    bad = [m for m in modes if isinstance(m, bool) or not isinstance(m, numbers.Integral) or m < 1]
    if bad:
        raise ValueError(f"modes must be integers >= 1, got {bad!r}")
    ok = np.isfinite(radius_k)
    theta, r = theta[ok], radius_k[ok]
    mean = r.mean() if len(r) else float("nan")
    return {int(m): float(2.0 * abs(np.mean(r * np.exp(-1j * m * theta))) / mean) for m in modes}
