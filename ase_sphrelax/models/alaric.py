"""ALARIC's physics (Vela Vela et al.): isothermal SPH with adaptive H in an external potential.

The **ALARIC potential** of equal-mass particles (mass ``m``, isothermal sound speed
``c_s^2 = (gamma - 1) u``) with target density ``rho*``:

    U = sum_a m c_s^2 ln(rho_a / rho*(x_a))  [+ sum_a m c_s^2 max(phi_D(x_a), 0) / l  with a domain],

``rho_a = m n_a``, ``n_a = sum_b W_ab(H_a)`` and ``H_a`` solved from ``n_a H_a^d = eta^d`` (Eq. 31-32).
Its exact negative gradient (grad-h terms included, Price 2012) is the isothermal SPH pressure
force (Eq. 34 with ``P = c_s^2 rho``) plus the body force ``m c_s^2 grad ln rho*``:

    F_a = -m sum_b m [c_s^2/(Omega_a rho_a) grad_a W_ab(H_a) + c_s^2/(Omega_b rho_b) grad_a W_ab(H_b)]
          + m c_s^2 grad ln rho*(x_a).

Its minimum has ``rho_a / rho*(x_a)`` the same for every particle (a Lagrange condition for the
fixed number of particles); to first order in ``rho - rho*`` it is the paper's effective pressure
``p_eff = c_s^2 (rho - rho*)`` (Eq. 29-30). The paper's own form, ``P_a = c_s^2 (rho_a - rho*(x_a))``
inside the pressure term, is :data:`FORMS` ``"paper"``: not the gradient of any energy
(non-conservative); its equilibrium is ``rho - rho* = const`` (Eq. 43), which the mass reset of
Eq. 44 drives to zero. Bare, it pairs particles where ``P_eff < 0`` (Eq. 46's well, Delta <= 0.1: a tensile
instability); the calculator adds by default the constant background pressure
``P_B = c_s^2 max_a (rho*_a - rho_a)_+`` (so ``P_eff + P_B >= 0``; zero at the fixed point, which it keeps) with
``eta = 2.5`` (``reproductions/alaric-eq29-stability``).

Where ``rho* = 0``
------------------
``ln rho*`` is replaced by ``ln max(rho*, floor)`` (``floor`` 1e-4 of the largest target value by
default: near a zero of ``rho*`` the force ``m c_s^2 grad ln rho*`` grows like ``2/r``, and a smaller
floor let the CFL step collapse at Eq. 46's well with Delta = 0): flat at the floor, so a particle there feels
no pull from the target, only the pressure of its neighbours (no NaN, no infinite force). Give a
:class:`~ase_sphrelax.domains.Domain` (e.g. the target's support) to confine the particles:
outside it (``phi > 0``) the potential rises linearly, ``m c_s^2 phi / l`` (a constant inward force
``m c_s^2 / l``, with ``l`` a tenth of the mean particle spacing by default), so no particle escapes and those
that start outside are pulled in.

Errors and built-in profiles
----------------------------
:func:`epsilon` is Eq. 45, :func:`reset_mass` Eq. 44 (with ``rho*`` in place of the printed
``rho``, which would make it an identity), :func:`eq46`, :func:`eq49` and :func:`uniform` the
paper's targets (vectorised, with gradients).
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["FORMS", "BOUNDARIES", "mirror_map", "mirror_images", "mirror_centre", "mirror_supported", "resolve_boundary", "Target", "eq46", "eq49",
           "uniform", "PROFILES", "epsilon", "reset_mass", "density_diagnostics", "convergence_verdict",
           "zero_region_mask"]

FORMS = ("log", "squares", "paper")
BOUNDARIES = ("wall", "mirror")


def mirror_supported(domain):
    """True when :func:`mirror_map` can mirror through ``domain``'s boundary with a continuous energy: a Ball
    (Circle, Sphere) or a 2D Polygon of one convex loop (a star around its centroid)."""
    from ..domains.analytic import Ball
    from ..domains.polygon import Polygon

    if isinstance(domain, Ball):
        return True
    if not isinstance(domain, Polygon) or len(domain.loops) != 1:
        return False
    v = domain.loops[0]
    e = np.roll(v, -1, axis=0) - v
    e_next = np.roll(e, -1, axis=0)
    turn = e[:, 0] * e_next[:, 1] - e[:, 1] * e_next[:, 0]
    return bool(np.all(turn >= -1e-12 * float(np.abs(e).max()) ** 2))  # counter-clockwise loop: no right turn


def resolve_boundary(boundary, domain):
    """``"auto"``: ``"mirror"`` when the domain supports it (:func:`mirror_supported`), else ``"wall"``."""
    if boundary == "auto":
        return "mirror" if domain is not None and mirror_supported(domain) else "wall"
    if boundary not in BOUNDARIES:
        raise ValueError(f"boundary must be 'auto' or one of {BOUNDARIES}, got {boundary!r}")
    return boundary


def _radial_hits(domain, s_gd):
    """Where the ray from the mirror's centre through ``centre + s`` leaves the domain: ``c = centre + t s``,
    as ``(t_g, n_gd)`` with ``n`` the outward normal of the face hit (Ball: ``t = R / |s|``, ``n = s / |s|``;
    convex polygon, the half-planes ``n_k . y <= p_k``: the smallest ``p_k / (n_k . s)`` with ``n_k . s > 0``)."""
    from ..domains.analytic import Ball

    if isinstance(domain, Ball):
        r_g = np.sqrt(np.einsum("gd,gd->g", s_gd, s_gd))  # > 0: mirror_map leaves out the centre
        return domain.radius / r_g, s_gd / r_g[:, None]
    v = domain.loops[0]
    e = np.roll(v, -1, axis=0) - v
    n_kd = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.linalg.norm(e, axis=1)[:, None]  # outward (ccw loop)
    p_k = np.einsum("kd,kd->k", n_kd, v - mirror_centre(domain))
    ns_gk = s_gd @ n_kd.T
    with np.errstate(divide="ignore"):
        t_gk = np.where(ns_gk > 0.0, p_k[None, :] / np.where(ns_gk > 0.0, ns_gk, 1.0), np.inf)
    k_g = np.argmin(t_gk, axis=1)
    return t_gk[np.arange(len(k_g)), k_g], n_kd[k_g]


def mirror_centre(domain):
    """The centre ``o`` of the radial mirror (:func:`mirror_map`): a ball's centre, a convex polygon's area centroid."""
    from ..domains.analytic import Ball

    if isinstance(domain, Ball):
        return domain.center
    v = domain.loops[0]
    w = np.roll(v, -1, axis=0)
    cross = v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]
    return ((v + w) * cross[:, None]).sum(axis=0) / (3.0 * cross.sum())  # the area centroid


def mirror_map(domain, x_pd, band):
    """Mirror images of the particles within ``band`` of the domain's boundary (ghosts that complete the kernel).

    The mirror is radial, from the domain's centre ``o`` (a ball's centre, a convex polygon's centroid): with
    ``s = x - o`` and ``c = o + t s`` where that ray leaves the domain, the ghost is ``g = 2 c - x = o + (2 t - 1) s``,
    as far outside along the ray as ``x`` is inside. For a ball this is the reflection through the closest boundary
    point. It is continuous in ``x`` (a closest-point reflection is not inside a polygon: it jumps on the bisectors
    of the corners), with Jacobian ``J = dg/dx = 2 dc/dx - I``, ``dc/dx = t (I - s n^T / (n . s))`` (``n`` the
    outward normal of the face hit; ball: ``t (I - n n^T)``).

    The ghosts are those of the particles with ``|phi| < band`` (particles just outside too: the ghost passes
    through the particle as it crosses the boundary, and the density stays continuous). With ``band`` above the
    largest support ``H``, the ghosts left out lie beyond any particle's reach (for a ball: a ghost of a particle
    at depth ``|phi|`` lies ``|phi|`` outside), so the energy does not depend on ``band`` and is continuous;
    ``next_gap`` lets the caller check that for a polygon.

    Parameters
    ----------
    domain : Ball or convex Polygon (:func:`mirror_supported`)
    x_pd : ndarray (N, d)
    band : float

    Returns
    -------
    owner_g : ndarray (G,) int, the particle each ghost mirrors
    g_gd : ndarray (G, d), ghost positions
    jac_gdd : ndarray (G, d, d), ``dg/dx`` of each ghost (``J^T`` maps a ghost's force back to its owner)
    next_gap : float, the smallest distance to the domain of the ghosts of the particles with
        ``band <= |phi| < 2 band`` (those left out); ``inf`` when there are none
    """
    if not mirror_supported(domain):
        raise ValueError(f"boundary='mirror' needs a Ball (Circle, Sphere) or a 2D Polygon of one convex loop, got "
                         f"{domain!r}")
    depth_p = np.abs(np.asarray(domain.phi(x_pd), dtype=float))
    centre = mirror_centre(domain)
    at_centre_p = np.all(x_pd == centre, axis=1)  # no ray: its mirror is undefined
    if np.any(at_centre_p & (depth_p < band)):
        raise ValueError(f"boundary='mirror': a particle at the mirror's centre {centre.tolist()} is within the ghost "
                         f"band {band:.3g} of the boundary (the domain is too small for the smoothing lengths: too "
                         f"few particles)")
    near_q = np.nonzero((depth_p < 2.0 * band) & ~at_centre_p)[0]
    g_qd, jac_qdd = mirror_images(domain, x_pd[near_q])
    inside_band = depth_p[near_q] < band
    rest = g_qd[~inside_band]
    next_gap = float(np.min(np.asarray(domain.phi(rest), dtype=float))) if len(rest) else np.inf
    return near_q[inside_band], g_qd[inside_band], jac_qdd[inside_band], next_gap


def mirror_images(domain, x_gd):
    """The radial mirror images ``g = o + (2 t - 1) s`` of the points ``x_gd`` (none at the mirror's centre ``o``)
    and their Jacobians ``J = dg/dx = 2 dc/dx - I`` (:func:`mirror_map`), as ``(g_gd, jac_gdd)``.

    A ball's images take one compiled pass; a convex polygon's the vectorised ray hits of :func:`_radial_hits`."""
    from ..domains.analytic import Ball

    x_gd = np.ascontiguousarray(x_gd, dtype=float)
    if isinstance(domain, Ball):
        return _ball_images(x_gd, np.asarray(domain.center, dtype=float), float(domain.radius))
    d = x_gd.shape[1]
    centre = mirror_centre(domain)
    s_gd = x_gd - centre
    t_g, n_gd = _radial_hits(domain, s_gd)
    g_gd = centre + (2.0 * t_g - 1.0)[:, None] * s_gd
    ns_g = np.einsum("gd,gd->g", n_gd, s_gd)
    eye = np.eye(d)
    dc_gdd = t_g[:, None, None] * (eye - s_gd[:, :, None] * n_gd[:, None, :] / ns_g[:, None, None])
    return g_gd, 2.0 * dc_gdd - eye


@numba.njit(cache=True)
def _ball_images(x_gd, centre_d, radius):
    """:func:`mirror_images` for a ball: ``t = R / |s|``, ``n = s / |s|``, ``J = 2 t (I - n n^T) - I``."""
    n, d = x_gd.shape
    g_gd = np.empty((n, d))
    jac_gdd = np.empty((n, d, d))
    for a in range(n):
        r2 = 0.0
        for c in range(d):
            r2 += (x_gd[a, c] - centre_d[c]) ** 2
        r = np.sqrt(r2)
        t = radius / r
        for c in range(d):
            s = x_gd[a, c] - centre_d[c]
            g_gd[a, c] = centre_d[c] + (2.0 * t - 1.0) * s
            nc = s / r
            for k in range(d):
                jac_gdd[a, c, k] = 2.0 * t * ((1.0 if c == k else 0.0) - nc * (x_gd[a, k] - centre_d[k]) / r) - (
                    1.0 if c == k else 0.0)
    return g_gd, jac_gdd


class Target:
    """A target density ``rho*`` with its (optional) gradient, checked on every call.

    Parameters
    ----------
    density : callable
        ``(N, d) -> (N,)``, vectorised, finite and ``>= 0``.
    gradient : callable or None
        ``(N, d) -> (N, d)``, the gradient of ``density``; None: central differences with step
        ``fd_step`` (``2 d`` extra calls per evaluation).
    dim : int
    fd_step : float
        Finite-difference step (length units) when no gradient is given.
    """

    def __init__(self, density, dim, gradient=None, fd_step=1e-6):
        if not callable(density):
            raise TypeError(f"target_density must be a callable (N, {dim}) -> (N,), got {type(density).__name__}")
        if gradient is not None and not callable(gradient):
            raise TypeError(f"target_gradient must be a callable (N, {dim}) -> (N, {dim}) or None, "
                            f"got {type(gradient).__name__}")
        self.density = density
        self.gradient = gradient
        self.dim = dim
        self.fd_step = fd_step
        self.calls = 0
        self.gradient_checked = gradient is None

    def values(self, x_pd):
        """rho*(x) at points (N, d), validated: shape (N,), finite, >= 0."""
        self.calls += 1
        try:
            out = np.asarray(self.density(x_pd), dtype=float)
        except Exception as exc:  # noqa: BLE001 - report any failure of the user's function with its input
            raise ValueError(f"target_density failed on an array of shape {x_pd.shape}: {exc}") from exc
        n = x_pd.shape[0]
        if out.shape != (n,):
            raise ValueError(f"target_density must return shape ({n},) for input ({n}, {self.dim}), got {out.shape}")
        if not np.all(np.isfinite(out)):
            bad = np.nonzero(~np.isfinite(out))[0]
            raise ValueError(f"target_density returned NaN or inf at points {bad[:10].tolist()}")
        if np.any(out < 0.0):
            bad = np.nonzero(out < 0.0)[0]
            raise ValueError(f"target_density must be >= 0; negative at points {bad[:10].tolist()} "
                             f"(e.g. {out[bad[0]]:.4g} at {x_pd[bad[0]].tolist()})")
        return out

    def gradients(self, x_pd, values=None):
        """grad rho*(x), shape (N, d): the given gradient or central differences."""
        n = x_pd.shape[0]
        if self.gradient is not None:
            out = np.asarray(self.gradient(x_pd), dtype=float)
            if out.shape != (n, self.dim) and not (self.dim == 1 and out.shape == (n,)):
                raise ValueError(f"target_gradient must return shape ({n}, {self.dim}), got {out.shape}")
            out = out.reshape(n, self.dim)
            if not np.all(np.isfinite(out)):
                raise ValueError("target_gradient returned NaN or inf")
            if not self.gradient_checked:
                self.check_gradient(x_pd, out)
            return out
        return self._central_differences(x_pd)

    def check_gradient(self, x_pd, given_pd, points=8):
        """Compare the given gradient with central differences of the density at a few points (once).

        The points are the ``points`` of ``x_pd`` with the largest difference estimate. Raises ValueError
        naming ``target_gradient`` when they disagree by more than 1e-3 of the larger gradient there
        (plus the rounding error of the difference): a wrong sign or a gradient of another function.
        """
        self.gradient_checked = True
        n = x_pd.shape[0]
        pick = np.unique(np.linspace(0, n - 1, min(n, 64)).astype(int))
        fd_pd = self._central_differences(x_pd[pick])
        top = np.argsort(-np.abs(fd_pd).sum(axis=1))[:points]
        fd_pd, given_pd, pick = fd_pd[top], given_pd[pick][top], pick[top]
        rho_max = float(np.abs(self.values(x_pd[pick])).max())
        scale = max(float(np.abs(fd_pd).max()), float(np.abs(given_pd).max()))
        tol = 1e-3 * scale + 1e3 * np.finfo(float).eps * rho_max / self.fd_step  # plus the differences' rounding
        err_p = np.abs(given_pd - fd_pd).max(axis=1)
        if np.any(err_p > tol):
            k = int(np.argmax(err_p))
            a = int(pick[k])
            opposite = float((given_pd[k] * fd_pd[k]).sum()) < 0
            raise ValueError(f"target_gradient is not the gradient of target_density: at point {a} "
                             f"{x_pd[a].tolist()} it gives {given_pd[k].tolist()}, central differences give "
                             f"{fd_pd[k].tolist()}{' (wrong sign?)' if opposite else ''}")

    def _central_differences(self, x_pd):
        n = x_pd.shape[0]
        out = np.empty((n, self.dim))
        step = self.fd_step
        for c in range(self.dim):
            plus = x_pd.copy()
            plus[:, c] += step
            minus = x_pd.copy()
            minus[:, c] -= step
            out[:, c] = (self.values(plus) - self.values(minus)) / (2.0 * step)
        return out


def _radius(x_pd):
    return np.sqrt(np.einsum("pd,pd->p", x_pd, x_pd))


def eq46(delta=0.0):
    """Eq. 46: ``rho*(r) = (1 + Delta) - cos(5 r) exp(-5 r^2)``, as (density, gradient)."""
    delta = float(delta)
    if not np.isfinite(delta) or delta < 0.0:
        raise ValueError(f"delta must be a finite number >= 0 (rho*(0) = delta), got {delta!r}")

    def density(x_pd):
        r = _radius(x_pd)
        return (1.0 + delta) - np.cos(5.0 * r) * np.exp(-5.0 * r * r)

    def gradient(x_pd):
        r = _radius(x_pd)
        # d/dr = 5 sin(5r) e^{-5r^2} + 10 r cos(5r) e^{-5r^2}; grad = d/dr * x / r (smooth at 0: ~ (25 + 10) x)
        e = np.exp(-5.0 * r * r)
        with np.errstate(invalid="ignore", divide="ignore"):
            over_r = np.where(r > 1e-8, (5.0 * np.sin(5.0 * r) * e) / np.where(r > 0, r, 1.0), 25.0)
        return (over_r + 10.0 * np.cos(5.0 * r) * e)[:, None] * x_pd

    return density, gradient


def eq49(p=1):
    """Eq. 49: ``rho*(r, theta | p) = 1/2 + 2 r^2 exp(-4 (r - 1/5)^2) sin(p (theta + log r))`` (2D), (density, gradient)."""
    p = float(p)

    def parts(x_pd):
        x, y = x_pd[:, 0], x_pd[:, 1]
        r2 = x * x + y * y
        r = np.sqrt(r2)
        safe_r = np.where(r > 0, r, 1.0)
        theta = np.arctan2(y, x)
        phase = p * (theta + np.log(safe_r))
        amp = 2.0 * r2 * np.exp(-4.0 * (r - 0.2) ** 2)
        return x, y, r, safe_r, phase, amp

    def density(x_pd):
        x, y, r, safe_r, phase, amp = parts(x_pd)
        return 0.5 + np.where(r > 0, amp * np.sin(phase), 0.0)

    def gradient(x_pd):
        x, y, r, safe_r, phase, amp = parts(x_pd)
        damp_dr = amp * (2.0 / safe_r - 8.0 * (r - 0.2))
        # phase = p (theta + ln r): d/dr = p / r, d/dtheta = p
        d_dr = damp_dr * np.sin(phase) + amp * np.cos(phase) * p / safe_r
        d_dtheta = amp * np.cos(phase) * p
        er = np.stack([x / safe_r, y / safe_r], axis=1)
        et = np.stack([-y / safe_r, x / safe_r], axis=1)
        g = d_dr[:, None] * er + (d_dtheta / safe_r)[:, None] * et
        g[r == 0] = 0.0
        return g

    return density, gradient


def uniform(value=1.0):
    """A constant target (confine it with a domain), as (density, gradient)."""
    value = float(value)

    def density(x_pd):
        return np.full(x_pd.shape[0], value)

    def gradient(x_pd):
        return np.zeros_like(x_pd)

    return density, gradient


PROFILES = {"eq46": eq46, "eq49": eq49, "uniform": uniform}


def epsilon(rho_p, target_p, n_p):
    """Eq. 45: ``sum (rho_a - rho*_a)^2 / n_a  /  sum rho*_a^2 / n_a``."""
    rho_p = np.asarray(rho_p, dtype=float)
    target_p = np.asarray(target_p, dtype=float)
    n_p = np.asarray(n_p, dtype=float)
    denominator = float(np.sum(target_p**2 / n_p))
    if denominator <= 0.0:
        raise ValueError("epsilon: the target density is zero at every particle")
    return float(np.sum((rho_p - target_p) ** 2 / n_p)) / denominator


def reset_mass(target_p, n_p):
    """Eq. 44 with the target: ``m = (1/N) sum_a rho*(x_a) / n_a`` (equal masses)."""
    return float(np.mean(np.asarray(target_p, dtype=float) / np.asarray(n_p, dtype=float)))


def zero_region_mask(target, x_pd, h_p, target_p):
    """Particles where ``rho* = 0`` on a stretch of their own size: ``rho*(x_a) = 0`` and ``rho*`` also vanishes at
    ``x_a +- H_a/2`` along some axis (a particle at an isolated zero, e.g. the bottom of Eq. 46's well with
    Delta = 0, Fig. 8, is not counted). ``target`` a :class:`Target`."""
    zero_p = np.asarray(target_p) == 0.0
    if not np.any(zero_p):
        return zero_p
    idx = np.nonzero(zero_p)[0]
    x_zd = x_pd[idx]
    region = np.zeros(len(idx), dtype=bool)
    for c in range(x_pd.shape[1]):
        for sign in (-0.5, 0.5):
            shifted = x_zd.copy()
            shifted[:, c] += sign * np.asarray(h_p)[idx]
            region |= target.values(shifted) == 0.0
    out = np.zeros(len(zero_p), dtype=bool)
    out[idx[region]] = True
    return out


def density_diagnostics(rho_p, target_p, n_p, zero_region_p=None):
    """Where the density error sits, beside Eq. 45's single number.

    ``epsilon`` (Eq. 45) weighs each particle by ``rho*^2 / n``, so a low-density region (a 1e-6 contrast,
    or ``rho* = 0``) can be wrong by orders of magnitude while ``epsilon`` stays small. Reported:

    * ``max_relative_error``: ``max |rho_a / rho*_a - 1|`` over the particles with ``rho* > 0``, and
      ``off_by_more_than_target``: how many of them have ``|rho_a / rho*_a - 1| > 1``;
    * ``zero_target_particles``: how many particles sit where ``rho* = 0`` (their density is infinitely
      wrong relative to the target); ``zero_region_particles``: those of them in a region where ``rho* = 0``
      (``zero_region_p``, from :func:`zero_region_mask`; None: all of them);
    * ``regions``: per decade of ``rho* / max rho*`` (``[0.1, 1]``, ``[0.01, 0.1)``, ...), the particle count,
      Eq. 45 restricted to the region, and the RMS and largest ``|rho / rho* - 1|``.

    Returns
    -------
    dict
    """
    rho_p = np.asarray(rho_p, dtype=float)
    target_p = np.asarray(target_p, dtype=float)
    n_p = np.asarray(n_p, dtype=float)
    positive = target_p > 0.0
    zero_region = int((~positive).sum()) if zero_region_p is None else int(np.count_nonzero(zero_region_p))
    out = dict(epsilon=epsilon(rho_p, target_p, n_p), zero_target_particles=int((~positive).sum()),
               zero_region_particles=zero_region, max_relative_error=None, regions=[])
    if not np.any(positive):
        return out
    rel_p = np.abs(rho_p[positive] / target_p[positive] - 1.0)
    out["max_relative_error"] = float(rel_p.max())
    out["off_by_more_than_target"] = int(np.count_nonzero(rel_p > 1.0))
    level_p = target_p[positive] / target_p.max()
    decade_p = np.minimum(np.floor(-np.log10(level_p)).astype(int), 300)
    for k in np.unique(decade_p):
        sel = decade_p == k
        idx = np.nonzero(positive)[0][sel]
        out["regions"].append(dict(target_range=[float(10.0 ** (-k - 1)), float(10.0 ** (-k)) if k else 1.0],
                                   n=int(sel.sum()),
                                   epsilon=epsilon(rho_p[idx], target_p[idx], n_p[idx]),
                                   rms_relative_error=float(np.sqrt(np.mean(rel_p[sel] ** 2))),
                                   max_relative_error=float(rel_p[sel].max())))
    return out


def convergence_verdict(stop_reason, diagnostics, smoothing_lengths=None, periods=None, epsilon_min=None):
    """``(converged, reason)`` of an ALARIC run from its stopping rule and where its error sits.

    Not converged when: the step cap ended the run (``stop_reason == "max_steps"``); particles sit where
    ``rho* = 0`` over a stretch of their own size (``zero_region_particles``); more than one particle has
    ``|rho / rho* - 1| > 1`` (one may sit alone in a dip of the target: Eq. 48's particle at the bottom of the
    well) and a region of :func:`density_diagnostics` has an RMS ``|rho / rho* - 1|`` above 1 (the density
    there is off by more than the target itself, whatever ``epsilon`` says); the run is degenerate: a
    smoothing length reaches half a periodic cell length (``periods``: the cell lengths along periodic axes),
    so every particle sees the whole cell and the density is not resolved, or ``epsilon`` is below
    ``epsilon_min`` (Eq. 48's lowest attainable error, when known).
    """
    reasons = []
    if stop_reason not in ("epsilon", "epsilon_dot"):
        reasons.append(f"stopped by {stop_reason}, not by its epsilon or epsilon_dot criterion")
    if diagnostics["zero_region_particles"]:
        reasons.append(f"{diagnostics['zero_region_particles']} particles sit where rho* = 0 (give a domain that "
                       f"excludes that region)")
    # one particle may sit alone in a dip of rho* (Eq. 48's particle at the bottom of the well, Appendix 1): more
    # than one particle whose density is off by more than the target itself is a region the run did not resolve
    for region in diagnostics["regions"] if diagnostics.get("off_by_more_than_target", 0) > 1 else ():
        if region["rms_relative_error"] > 1.0:
            lo, hi = region["target_range"]
            reasons.append(f"rho / rho* - 1 has RMS {region['rms_relative_error']:.3g} (max "
                           f"{region['max_relative_error']:.3g}) over the {region['n']} particles with rho* in "
                           f"[{lo:.0e}, {hi:.0e}] max rho*")
    if smoothing_lengths is not None and periods:
        h_max = float(np.max(smoothing_lengths))
        if h_max >= 0.5 * min(periods):
            reasons.append(f"degenerate: a smoothing length ({h_max:.3g}) reaches half the periodic cell "
                           f"({min(periods):.3g}): every particle sees the whole cell, too few particles")
    if epsilon_min is not None and diagnostics["epsilon"] < epsilon_min:
        reasons.append(f"degenerate: epsilon {diagnostics['epsilon']:.3g} is below Eq. 48's lowest attainable "
                       f"{epsilon_min:.3g} for this profile and N")
    return (not reasons), "; ".join(reasons) if reasons else f"stopped by {stop_reason}"
