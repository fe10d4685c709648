"""The stationary density of SPH-ParVI: hydrostatic balance of a damped fluid in the target's field.

Derivation (continuum limit, the fluid at rest, total mass ``M_tot``)
----------------------------------------------------------------------
At rest viscosity and friction vanish and the momentum equation (Eq. 2/3) reduces to
hydrostatic balance.

Score force (Algorithm 2): ``grad P / rho = alpha grad log p``. For a barotropic EOS write the
enthalpy ``w(rho) = int dP / rho``; then ``w(rho) = alpha log p + C``. Equivalently the flow is
damped motion in the energy ``E[rho] = int rho u(rho) dx - alpha int rho log p dx`` with
``u' = P / rho^2`` (the discrete :class:`~ase_sphrelax.models.parvi.ParVIModel` energy), whose
Euler-Lagrange equation is ``(rho u)' = w = alpha log p + lambda``.

* isothermal, ``P = c0^2 rho``: ``w = c0^2 log rho``, so ``rho ∝ p^(alpha / c0^2)``: the target
  exactly when ``alpha = c0^2`` (a Gaussian of variance ``sigma^2`` becomes one of variance
  ``sigma^2 c0^2 / alpha``).
* Tait, ``P = rho0 c0^2 / gamma ((rho/rho0)^gamma - 1)``: ``w = c0^2/(gamma - 1) (rho/rho0)^(gamma-1)``, so
  ``rho = rho0 [C' + (gamma - 1) alpha log p / c0^2]^(1/(gamma-1))`` on a compact support. The
  constant ``-1`` of the EOS makes ``rho u(rho)`` jump from 0 (no fluid) to ``rho0 c0^2/gamma``:
  the convex envelope of ``rho u`` touches the curve at ``rho = rho0``, so densities below
  ``rho0`` are unstable (vacuum and fluid at ``rho0`` cost less) and the free surface sits where
  ``rho = rho0`` (``P = 0``). For gamma = 7 and ``alpha / c0^2`` of order one the profile is
  nearly flat: a weakly compressible fluid fills a blob of volume ``~ M_tot / rho0`` whatever p is.

External pressure (Algorithm 1): ``grad (P_int + P_ext) = 0``, so ``P_int(rho) = C - P_ext(x)``:
isothermal ``rho = (C + alpha log(p + eps)) / c0^2`` (linear in log p; for a Gaussian an
inverted paraboloid) or ``rho = (C - 1 / (alpha (p + eps))) / c0^2``, cut where it reaches zero.
These depend on the additive constant of log p (the unknown normalisation) through the free
surface, and are not gradient systems.

Whitened coordinates (``whiten=``, :mod:`~ase_sphrelax.sampling.whitening`). For a fixed invertible
affine map ``x = c + L y`` the fluid moves in y pushed by the score of the pull-back

* (W1) ``p_y(y) = p(c + L y) |det L|``, the density of ``y = L^-1 (x - c)`` when x ~ p;
* (W2) ``grad_y log p_y(y) = L^T grad_x log p(c + L y)`` (chain rule);

so the result above, applied to ``p_y``, gives the resting density ``rho_y ∝ p_y^(alpha / c0^2)``, i.e. p_y
itself in the default configuration, and the particles mapped back by ``x = c + L y`` have density
``rho_y(L^-1 (x - c)) / |det L| = p(x)``:

* (W3) **exact** for a fixed map, with the same continuum-limit and discretisation errors as the
  unwhitened fluid has for ``p_y`` (whose covariance is the identity when L is the Cholesky factor
  of p's covariance: the errors of the unit Gaussian, whatever p's correlations and scales);
* the whitened fluid is affine equivariant: for a target ``q(x) = p(A^-1 x) / |det A|`` and the map
  ``A L`` (started from ``A`` times the initial points) it sees the same ``p_y`` and moves the
  same y (up to round-off): its samples are A times those for p (tested);
* a **renewed** map (``whiten="covariance"``) carries the state over exactly (``y' = L'^-1 (c + L y - c')``,
  ``v' = L'^-1 L v``), but a fluid at rest under L is not at rest under L' (its arrangement is isotropic in
  the old y, the kernels in the new): renewals perturb the fluid, and nothing here says what a
  continually renewed map would converge to. The sampler renews only up to ``whiten_until * steps`` and
  then holds the map fixed, so the final state is that of the fixed-map fluid (W3); the convergence
  verdict covers the last half of the run, which lies after the last renewal for ``whiten_until <= 0.5``.

Local time steps (``time_step="local"``). Every particle a is kicked, drifted and damped with its own
CFL step ``dt_a`` (:meth:`~ase_sphrelax.models.parvi.ParVIModel.cfl_steps`), the local time stepping of
steady-state CFD. With a common fictitious step ``dtau`` and ``s_a = dt_a / dtau > 0`` it is the
kick-drift-kick leapfrog of

* (L1) ``dr_a/dtau = s_a v_a``, ``dv_a/dtau = s_a (F_a / m - beta v_a)``;

* (L2) its resting states are ``v_a = 0`` and ``F_a = 0`` for every a, whatever the positive ``s_a``: the
  same states as with one global step (the fixed points of the discrete map too: a kick by ``F_a = 0``
  and a drift by ``v_a = 0`` change nothing, and a state the map leaves unchanged needs a zero
  half-step velocity, hence ``F_a = 0``). So the stationary density is exactly the one derived above
  (``rho ∝ p^(alpha / c0^2)``, p itself by default), with the same discretisation errors;
* (L3) the flow still descends ``H = E + K``, ``K = sum_a m |v_a|^2 / 2``:
  ``dH/dtau = sum_a (-F_a) . s_a v_a + sum_a m v_a . s_a (F_a / m - beta v_a) = -beta sum_a s_a m |v_a|^2 <= 0``
  for any ``s_a(tau) > 0`` (no derivative of s appears, so steps renewed at every step are allowed).
  The pairwise viscosity adds ``sum_a s_a v_a . f_vis,a``, dissipative where ``s`` is equal across a pair
  (the supports vary smoothly, so do the steps) and zero at rest: it does not move the resting states.

L3 is a statement about the flow; the discrete map (leapfrog with steps that change per particle and per step)
is not guaranteed to descend H: on the banana the kinetic energy of a local-step run stops decaying and bursts
(``examples/results/parvi/steps/README.md``), a growth limit on the steps removes the bursts. L2, the resting
states, holds for the discrete map whatever the steps.

The path to rest differs from the fluid's (a particle with a large step moves further per step), which
is what is wanted: a stiff particle (a small H or a large acceleration, the funnel's neck) no longer sets
the step of all. Friction is applied per particle in its own time (``exp(-beta dt_a / 2)``), so the
number of steps a particle needs to be damped scales with its own step, not the smallest one.

The functions here solve these relations for isotropic targets ``log p = -r^2 / (2 sigma^2)``
in d dimensions (radial quadrature, the constant from the mass) and return the profile's
moments, to compare with the particles.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import trapezoid
from scipy.optimize import brentq

__all__ = ["stationary_profile", "predicted_gaussian_moments"]


def _shell(d, r):
    """Surface of the sphere of radius r in d dimensions (d = 1: the two points +-r)."""
    return 2.0 * math.pi ** (d / 2) / math.gamma(d / 2) * r ** (d - 1)


def stationary_profile(formulation, eos, dim, alpha=1.0, c0=1.0, rho0=1.0, gamma=7.0, sigma=1.0, total_mass=1.0,
                       eps=1e-10, r_max=None, n_grid=20001):
    """Radial stationary density rho(r) for the target ``log p = -r^2/(2 sigma^2)`` (see the module docstring).

    Returns
    -------
    r_g, rho_g : ndarray
        Radius grid and density (zero outside the support).
    """
    if r_max is None:
        r_max = 12.0 * sigma * max(1.0, math.sqrt(c0**2 / alpha))
    r_g = np.linspace(0.0, r_max, n_grid)
    log_p = -(r_g**2) / (2.0 * sigma**2)

    if formulation == "force" and eos == "isothermal":
        rho = np.exp(alpha / c0**2 * log_p)
        rho *= total_mass / trapezoid(rho * _shell(dim, r_g), r_g)
        return r_g, rho

    def profile(c):
        if formulation == "force":  # Tait: w(rho) = c0^2/(g-1) (rho/rho0)^(g-1) = alpha log p + C, rho >= rho0
            base = c + (gamma - 1.0) * alpha * log_p / c0**2
            rho = rho0 * np.clip(base, 0.0, None) ** (1.0 / (gamma - 1.0))
            return np.where(rho >= rho0, rho, 0.0)
        p_ext = (-alpha * np.logaddexp(log_p, math.log(eps)) if formulation == "pressure-log"
                 else 1.0 / (alpha * (np.exp(log_p) + eps)))
        if eos == "isothermal":
            return np.clip((c - p_ext) / c0**2, 0.0, None)
        b = rho0 * c0**2 / gamma  # Tait: P_int = b ((rho/rho0)^g - 1) = C - P_ext, free surface at P_int = 0 -> rho0
        arg = 1.0 + (c - p_ext) / b
        return np.where(arg >= 1.0, rho0 * np.clip(arg, 0.0, None) ** (1.0 / gamma), 0.0)

    def excess(c):
        return trapezoid(profile(c) * _shell(dim, r_g), r_g) - total_mass

    lo, hi = (1.0, 2.0) if formulation == "force" else (0.0, 1.0)
    if formulation == "pressure-inverse":
        lo = 1.0 / (alpha * (1.0 + eps))  # P_ext at the centre: no fluid below it
        hi = lo + 1.0
    while excess(hi) < 0:
        hi = lo + 2.0 * (hi - lo)
    c = brentq(excess, lo, hi, xtol=1e-14, rtol=1e-13)
    return r_g, profile(c)


def predicted_gaussian_moments(formulation, eos, dim, **kwargs):
    """Per-component variance and kurtosis (of one coordinate) of the stationary profile.

    Keyword arguments as in :func:`stationary_profile`. The kurtosis is ``E x1^4 / (E x1^2)^2``
    (3 for a Gaussian, 1.8 for a uniform segment).
    """
    r_g, rho = stationary_profile(formulation, eos, dim, **kwargs)
    w = rho * _shell(dim, r_g)
    mass = trapezoid(w, r_g)
    r2 = trapezoid(w * r_g**2, r_g) / mass
    r4 = trapezoid(w * r_g**4, r_g) / mass
    # isotropic: E x1^2 = E r^2 / d, E x1^4 = 3 E r^4 / (d (d + 2))
    var = r2 / dim
    x4 = 3.0 * r4 / (dim * (dim + 2))
    return dict(variance=float(var), kurtosis=float(x4 / var**2),
                support=float(r_g[np.nonzero(rho)[0][-1]]) if np.any(rho) else 0.0)


# -- Friction rules (issue 18, item 1): appended to the module docstring ------------------------------------------
__doc__ += """
Friction rules (``friction=``, :mod:`~ase_sphrelax.sampling.friction`; issue 18, item 1). The drag is
``-m B_a(t) v_a`` with ``B_a`` symmetric positive semi-definite, constant (``beta I``, the default
``beta = 1 / scale``) or renewed during the run (``"critical"``: ``B = 2 (alpha F)^(1/2)`` from the Fisher
matrix ``F`` of the particles' scores, the same for all particles), applied exactly as
``v_a <- exp(-B_a dt_a / 2) v_a`` around each kick. Friction does not change the resting state of a fluid:

* (F1) at rest ``v_a = 0``, so the drag ``-m B_a v_a`` vanishes whatever ``B_a`` is: the resting states are the
  solutions of ``F_a = 0`` (hydrostatic balance, the derivation above), which contain no friction. So the
  stationary density is ``rho ∝ p^(alpha / c0^2)``, p itself by default, for every rule; on the discrete map
  too: ``exp(-B dt / 2)`` leaves ``v = 0`` in place, and a state the map leaves unchanged has a zero
  half-step velocity, hence ``F_a = 0`` (as in L2);
* (F2) the flow descends ``H = E + K`` for any such ``B_a(t)``, also when renewed:
  ``dH/dt = -sum_a m v_a^T B_a v_a <= 0`` (no derivative of B appears); with local steps the factor ``s_a``
  of L3 multiplies each term. ``exp(-B dt / 2)`` has eigenvalues in (0, 1]: it never adds kinetic energy;
* (F3) what friction changes is the path and its speed. A mode of angular frequency ``omega`` under a
  drag rate ``b`` decays like ``exp(-b t / 2)`` when underdamped (``b < 2 omega``) and like
  ``exp(-omega^2 t / b)`` when overdamped: the fastest decay is at ``b = 2 omega`` (critical). A scalar
  friction fitted to the stiffest direction is overdamped in the soft ones (the banana's x0, scale 10:
  creep with rate ``omega^2 / beta``). The critical rule damps each principal direction of ``F`` at
  ``2 omega_i``, ``omega_i^2 = alpha lambda_i(F)``: the frequency of the fluid's centre of mass in the
  quadratic fit ``-log p ≈ x^T F x / 2`` (under p, ``F = E_p[-Hess log p]`` exactly, by integration by
  parts), the slowest collective mode (the breathing and higher modes are faster and decay at least
  at ``b / 2``). It is taken from the scores the step computes anyway (no extra evaluation), renewed
  every ``friction_every`` steps, and in whitened coordinates from the whitened target's scores.
"""
