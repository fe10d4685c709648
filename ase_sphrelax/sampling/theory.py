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
* (W4) **bounded renewals**: after the first renewal (which sets the map from the initial particles) a renewal
  may shrink the covariance the fluid sees by at most a factor g (``RENEWAL_MAX_SHRINK = 2``) along any
  direction, and grow it freely: with ``C_y = U diag(w) U^T`` the particles' covariance in the current y,
  ``L' L'^T = L U diag(max(w, 1/g)) U^T L^T``; the particles' covariance in the new y has eigenvalues
  ``w / max(w, 1/g)`` (1 within the bound). Each renewed map is still an invertible linear change of variables
  with the state carried over exactly, so W3 holds for the final, frozen map whatever g: the bound chooses the
  map, not the stationary density. Why it is needed (measured, ``reproductions/parvi-highdim/``, part
  ``renewals``): the k-NN fluid expanding from a narrow start flattens in some directions (covariance
  eigenvalues 4e-5 against 25 of the y covariance at step 50 in 10-D, M = 100). The map of the moment then
  shrinks 1e3-1e5-fold in those directions, the fluid must expand again by that factor in y, the next renewal
  catches the next transient, and at step 500 the frozen map is wrong (variances 0.07-2.5 of the target's).
  Bounded, the map shrinks at most 2x per renewal and the fluid's covariance in y settles near 1 by the last
  renewals. Growth is left free: bounding it too (the factor in both directions) cost the 2D banana (part
  ``renewals2d``), and an expanding fluid is not the failure measured.

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
(``reproductions/parvi-steps/README.md``), a growth limit on the steps removes the bursts. L2, the resting
states, holds for the discrete map whatever the steps.

The path to rest differs from the fluid's (a particle with a large step moves further per step), which
is what is wanted: a stiff particle (a small H or a large acceleration, the funnel's neck) no longer sets
the step of all. Friction is applied per particle in its own time (``exp(-beta dt_a / 2)``), so the
number of steps a particle needs to be damped scales with its own step, not the smallest one.

k-nearest-neighbour densities (``neighbours="knn"``, :mod:`ase_sphrelax.models.parvi_knn`, eqs. K1-K3 there).
The density of particle a comes from its k nearest neighbours (a Kozachenko-Leonenko estimate, softened), the
EOS is isothermal and the body force the score, so the flow descends (K2)
``E = -(c0^2 m d / 2k) sum_a sum_{b in N_k(a)} log s_ab - alpha m sum_a log p(x_a)``,
``s_ab = r_ab^2 + delta^2 Hbar_a^2``. Its resting states (``F_a = 0`` for all a) obey three exact identities,
for any M, k, delta and d, because ``E_int`` (the first sum) is invariant under translations and rotations and
changes by a constant under a scaling (``log s_ab`` gains ``2 log lambda`` when all x are multiplied by lambda):

* (K4) translation: ``sum_a F_int,a = 0``, so at rest ``sum_a grad log p(x_a) = 0``;
* (K5) scaling (Euler's relation, ``sum_a x_a . grad_a E_int = -c0^2 m d M``): ``sum_a x_a . F_int,a = c0^2 d``
  for every configuration (m M = 1), so at rest ``(1/M) sum_a (x_a - c) . grad log p(x_a) = -d c0^2 / alpha``
  for any c (with K4);
* (K6) rotation: ``sum_a (x_a grad log p(x_a)^T - grad log p(x_a) x_a^T) = 0`` at rest.

These are the Stein identities ``E_p[grad log p] = 0`` and ``E_p[x . grad log p] = -d`` (integration by parts)
that an exact sample satisfies on average: the resting fluid satisfies them exactly (with ``alpha = c0^2``).
For a Gaussian ``N(mu, Sigma)`` K4 makes the particles' mean exactly mu, and K5 makes their mean squared
Mahalanobis radius exactly ``d c0^2 / alpha``: for an isotropic target and an isotropic arrangement the variance
per axis is ``c0^2 / alpha`` (1 by default) on average over the axes, in any dimension, exactly at rest. With
motion left, the time-averaged virial adds ``2 <K> / alpha``: the measured mean square exceeds d by that.
K4-K6 hold for the kernel default too (``rho_a H_a^d = m eta^d`` scales the same way), but say nothing about
the per-axis split of an anisotropic target, nor about the shape of the radial distribution.

* (K7) continuum limit. Write ``log rho_a = log rho(x_a) + b_a``: ``b_a`` is the estimator's error, a function
  of the arrangement of a's neighbours measured in units of their spacing (the estimator is scale-free). Where
  the neighbours are a Poisson process ``E b_a = 0`` (the constant ``C_k``: exact for ``delta = 0``, by Monte
  Carlo otherwise); where the resting arrangement is the same (statistically) everywhere, ``b`` is a constant
  and drops out of the isothermal EOS. Then ``c0^2 log rho = alpha log p + const``: ``rho ∝ p^(alpha / c0^2)``,
  p itself by default, as for the kernel fluid. This needs the ball holding the k neighbours,
  ``H ~ (k / (M p V_d))^(1/d)``, to be small against the scale on which log p varies (``H |grad log p| << 1``).

  Above a few dimensions it is not: in 10-D at M = 500 the ball of k = 20 around a typical point of a unit Gaussian
  has radius about 2.7 (the estimate above at ``|x| = sqrt(10)``), comparable to the whole distribution (the median
  i.i.d. nearest-neighbour distance is already 1.92), and it shrinks only like ``M^(-1/d)``. The estimate is then a
  heavy smoothing of rho across the distribution, and the resting state is not p: on the unit Gaussian it
  concentrates on the typical-set shell (measured radius standard deviations 0.14 in 10-D and 0.037 in 32-D at M =
  500, against 0.70 for i.i.d. points, ``reproductions/parvi-highdim/``; a coordinate's kurtosis then is ``3 d /
  (d + 2)``, that of a uniform sphere). By K5 the shell has the right mean square radius, so second moments of
  Gaussians stay right (and the energy distance, which mostly sees location and scale, stays close to i.i.d.); on a
  target whose log-density is not quadratic the virial places the shell wrongly (the logistic posterior's
  log-likelihood grows linearly in the tails: its marginal standard deviations come out 1.10-1.25 times the NUTS
  reference's, while the particles satisfy K5: ``mean (x - mean x) . grad log p = -32.02``, the reference -32.11).
  On an anisotropic target the isotropic neighbour balls mix directions: the 10-D Gaussian of condition number 100
  needs ``whiten="covariance"`` (item 1), under which the fluid sees a unit covariance.

  In 1D and 2D the ball is small except in the tails, where it spans the tail: the tails are thinned
  (kurtosis below 3, measured in ``reproductions/parvi-highdim/``); the variance stays exact by K5.

k-NN estimate of the ratio (``neighbours="knn-ratio"``, :class:`~ase_sphrelax.models.parvi_knn.KNNRatioParVIModel`).
The smoothing of K7 is harmless for a quantity that is constant at the solution. With ``q_b = p(x_b)^(-beta)``,
``beta = alpha / c0^2``, the flow descends

* (R2) ``E = c0^2 m sum_a log g_a``, (R1) ``g_a = sum_{b in {a} + N_k(a)} f(s_ab) q_b / (M V_d H_a^d (k + 1) / 2)``,
  ``s_ab = (r_ab / H_a)^d``, ``f(s) = 1 - s``, ``H_a = r_a(k)`` (f vanishes at the k-th neighbour, so E is
  continuous when neighbours swap), an estimate of the free energy ``int rho log(rho / p^beta)``;
* (R3) its exact gradient (FD-tested) has, on each particle b, the score force ``alpha m W_b grad log p(x_b)``
  with ``W_b`` the weight b carries in its own and its neighbours' estimates;
* (R4) in the continuum ``g = K[rho / p^beta]``, K the smoothing over the ball (a positive operator with
  eigenvalues in [0, 1]); with ``rho = C p^beta (1 + eps phi)`` and ``int rho phi = 0`` the energy is
  ``const + eps^2 C^2 (<phi, K phi> - <K phi, K phi> / 2) + O(eps^3)`` (inner products weighted by p^beta), which is
  ``>= eps^2 C^2 <K phi, K phi> / 2 >= 0``: ``rho ∝ p^beta`` is a minimiser whatever the size of the ball, with
  no smoothing bias (modes that K annihilates are flat: the continuum does not fix the arrangement below H);
* (R5) a scale-free shape term ``-lambda c0^2 m (d/k) sum_a sum_{j<k} log(r_a(j) / H_a)`` (lambda = 0.2) repels
  close pairs: f is flat at s = 0 in high d, and without it particles pair up (measured in 10-D at M = 500: a tenth
  of the particles had a neighbour within 0.22, with the term within 0.59, i.i.d. points 1.48). It depends only on
  the arrangement in units of the spacing: a constant per particle in the continuum, so it does not move R4's
  minimiser at leading order.

What R4 does not cover: the importance weights ``q_b`` vary over a ball by ``exp(beta |grad log p| H)``, a
factor of hundreds in 10-D, so that one neighbour dominates each estimate, the forces are stiff (small steps)
and noisy. Measured: in 10-D the radial spread is restored (radius sd 0.55 against 0.13 for ``"knn"``), but
the fluid had not come to rest in 1000 steps; on the 32-D logistic posterior it does not settle.

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


# -- Exact finishing kernels (issue 18, the logistic goal): appended to the module docstring ----------------------
__doc__ += """
Exact finishing kernels (``finish=``, :mod:`~ase_sphrelax.sampling.finish`; issue 18, the logistic goal). The
resting k-NN fluid above a few dimensions is not p (K7): K4-K5 fix its mean and its mean ``(x - c) . grad log p``,
not its radial profile nor, on a non-Gaussian target, its directions. A finish applies, after the fluid, a Markov
kernel T with ``p T = p`` to every particle, in the fluid's frame ``x = c + L y`` (the frozen whitening map, or the
particles' mean and Cholesky covariance factor); the output density is ``q T^n``, q the fluid's, which tends to p
as n grows for an ergodic T, and equals p at every n if q = p: a finish can only remove the fluid's error, never
add a bias of its own.

* (G1) polar coordinates about c in the frame L: ``x = c + L r u``, ``r > 0``, ``|u| = 1``,
  ``dx = |det L| r^(d-1) dr dsigma(u)``, so under p the pair (r, u) has density ``∝ r^(d-1) p(c + L r u)`` and
  the radius given the direction has the conditional ``pi(r | u) ∝ r^(d-1) p(c + L r u)`` on (0, inf); the
  directions have the marginal ``p_u(u) = |det L| int_0^inf r^(d-1) p(c + L r u) dr``.
* (G2) ``finish="radial"``: each slice-sampling update (Neal 2003: level ``log pi(r) - Exp(1)``, an interval of
  width w placed uniformly at random around r, stepped out at most m times with a random split between the two
  sides, then shrunk towards r) leaves ``pi(r | u)`` invariant; with u untouched, the joint update leaves p invariant
  (a Gibbs step in the coordinates of G1) for any fixed c, L. After the updates the output is
  ``q_u(u) pi(r | u)``: the radial conditional exact whatever the fluid left, the directions the fluid's ``q_u``.
  It is a diagnosis: if the fluid's error were its thin shell (K7), the refill would remove it; measured on the
  32-D logistic posterior it does not (``reproductions/parvi-logistic-goal/``): the fluid's directions are
  biased (they lie where p reaches farther, and a share of the particles is stranded in a far tail).
* (G3) ``finish="mala"``: in y the target is ``p_y(y) ∝ p(c + L y)``, score ``L^T grad log p``; the proposal
  ``y' = y + (eps/2) grad log p_y(y) + sqrt(eps) xi``, ``xi ~ N(0, I)``, accepted with probability
  ``min(1, p_y(y') Q(y | y') / (p_y(y) Q(y' | y)))``, ``Q(b | a) = N(b; a + (eps/2) grad log p_y(a), eps I)``, is
  reversible with respect to p_y for every eps > 0 (Metropolis-Hastings). A step size drawn independently of the
  state, ``eps = eps_max * s^(-U)``, U ~ U(0, 1), makes the step a mixture ``int T_eps dmu(eps)`` of kernels each
  reversible with respect to p: the mixture is too. So after the adaptation (the first quarter of the steps, where
  ``log eps_max`` follows the ensemble's acceptance towards 0.574 and the kernel depends on the other particles'
  acceptances, as in adaptive MCMC) every particle runs a time-homogeneous chain with stationary density exactly p,
  independent of the other particles. The spread s (16) is for particles stranded where the curvature is large:
  the acceptance of a step eps at a point of curvature kappa falls roughly like ``exp(-c eps^2 kappa^2 ...)`` once
  ``eps kappa`` exceeds one, so with one eps fitted to the bulk such a particle never moves (measured: 1.2 % of
  the fluid's particles at the posterior's log-precision 2.97-2.98, beyond the largest of 4000 NUTS draws, 1.33,
  not moved by 1000 fixed-eps MALA steps; with the spread all are back in the bulk after 200-400 steps,
  ``reproductions/parvi-logistic-goal/``, part ``spread``); the small steps of the mixture move them.
* (G4) linear change of variables: for ``x~ = A x + b`` (A invertible), the target ``p~(x~) = p(A^-1 (x~ - b)) / |det A|``
  and the frame ``(A c + b, A L)``, the y of every particle is the same, ``p~_y`` differs from ``p_y`` by the constant
  ``-log |det A|`` and the score in y is the same (``(A L)^T grad log p~ = L^T grad log p``): with the same random
  numbers both kernels make the same moves and decisions in y (constants cancel in the acceptance ratio and in the
  slice comparisons), so the output for ``p~`` is ``A`` times the output for p plus b, up to round-off
  (hypothesis-tested, including a nearly singular A). The fixed whitening map ``whiten=A`` transforms so; the
  renewed map and the particles' own frame use Cholesky factors, equivariant for lower-triangular A and, for other
  A, up to a rotation of y, under which both kernels are equivariant in distribution (isotropic noise, radii).
* (G5) cost and budget: ``"mala"`` one score and one log-density per particle and step (the logistic runs: 540
  fluid steps + 200 MALA steps, about 1000 evaluations per particle in all); ``"radial"`` log-densities only,
  about 5-7 per particle and update.

The stationary density of the finished sampler is therefore p exactly in the limit of many finishing steps, for any
fluid; with finitely many, the output is ``q T^n``: the measured question is how far the fluid's q is from p in the
directions T mixes slowly, and the fluid is what makes a few hundred steps enough (its particles are the start,
its covariance the preconditioner L).
"""
