"""The shared SPH core: density sums with adaptive smoothing lengths, grad-h pressure forces,
artificial viscosity with a per-particle switch, the velocity divergence and the continuity
equation with density diffusion.

Conventions
-----------
``H`` is the kernel **support** radius (ALARIC Eq. 5, Fan): ``W(r, H) = sigma / H^d f(r/H)``,
``f(q) = 0`` for ``q >= 1``. Phantom (Price 2012) writes a smoothing length with support ``2h``;
its ``eta`` is converted here: ``eta_H = 2 eta_h`` (each kernel's ``eta``). Positions are
``(N, D)`` arrays: ``D = 3`` for ASE Atoms (zeros beyond the dimension ``d`` of the kernel) or
any ``D`` for point sets walked over a stored list (SPH-ParVI's k-d tree); ``d`` (the kernel's
dimension) sets the normalisation and the grad-h terms.

Pieces (each a :class:`~ase_sphrelax.pairs.PairInteraction`; no pair loop of its own)
-------------------------------------------------------------------------------------
:func:`density_sums`
    Gather with each particle's own ``H_a``: ``rho_a = sum_b m_b W_ab(H_a)`` (Eq. 8, self term
    included), the number density ``n_a = sum_b W_ab(H_a)`` (Eq. 32) and Omega_a (Eq. 13).
    A fixed (global) ``h`` is the special case ``H_a = h``.
:func:`solve_smoothing_lengths`
    ``H_a`` and ``rho_a`` solved together (Eq. 31-32 in the equal-mass case, Phantom's
    ``rho_a = m_a (eta / H_a)^d`` in general): safeguarded Halley iteration in ``ln H`` with a
    bisection bracket, tolerance ``|dH|/H < tol`` (one density pass from the previous step's H with
    Wendland C4 and equal masses, two otherwise), and :class:`SmoothingLengthError` naming the particle
    when it does not converge or when no root exists (fewer particles than one kernel's
    neighbours in an open system).
:func:`pressure_forces`
    The symmetric grad-h force (Eq. 9/34 with ``S = -p I``)
    ``F_a = -m_a sum_b m_b [P_a/(Omega_a rho_a^2) grad_a W_ab(H_a) + P_b/(Omega_b rho_b^2) grad_a W_ab(H_b)]``
    from per-particle ``P/(Omega rho^2)``, with the pair virial for stresses. It is the exact
    negative gradient of ``sum_a m_a u(rho_a)`` with ``du/drho = P/rho^2`` when the ``H_a`` are
    solved from the constraint (Price 2012, Sec. 2.3).
:func:`viscosity_forces`
    Artificial viscosity (Eq. 15/35): ``dv_a/dt = -sum_b m_b Pi_ab grad_a Wbar_ab`` with
    ``Pi_ab = (-alpha_ab v_sig w_ab + beta w_ab^2) / rhobar_ab``, ``w_ab = v_ab . rhat_ab``,
    ``Wbar`` the mean of the kernels with ``H_a`` and ``H_b`` (Eq. 18), ``alpha_ab`` the mean of
    the two particles' switches; with ``beta = 0`` and every pair this is Eq. 35, with
    ``approaching_only`` it is Monaghan's (1997) signal-velocity form. The same pass returns the
    velocity divergence of Eq. 21.
:func:`velocity_divergence`
    Eq. 21 alone: ``(div v)_a = sum_b m_b/rho_b v_ab . r_ab F_ab(H_a)``, ``grad W = -r F`` (Eq. 11).
:func:`continuity_rate`
    ``drho_a/dt = sum_b m_b v_ab . grad_a W_ab(H_a)`` plus the density diffusion of Molteni &
    Colagrossi (2009) with coefficient ``a_d H c0`` (SPH-ParVI Eq. 29, written here with the
    diffusive sign).
:func:`update_alpha`
    The viscosity switch (Eq. 19-20, Morris & Monaghan): ``dalpha/dt = max(-div v, 0) -
    (alpha - alpha_min)/tau``, ``1/tau = 0.1 c_s / H``, integrated implicitly, capped at alpha_max.

Equations of state: :func:`isothermal_pressure` (``P = c_s^2 rho``) and :func:`tait_pressure`.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from numba.extending import overload

from numpy.polynomial import polynomial as P

from .kernels import _derivative_in_q, get_kernel, kernel_derivatives, kernel_profile
from .neighbors import set_mmap_threshold
from .pairs import Output, PairInteraction, release_scratch
from .parallel import run_chunks, thread_count

__all__ = ["default_eta", "DensitySums", "density_sums", "solve_smoothing_lengths",
           "SmoothingLengthError", "initial_smoothing_length", "pressure_forces", "viscosity_forces",
           "velocity_divergence", "continuity_rate", "update_alpha", "isothermal_pressure", "tait_pressure",
           "scaled", "fix_mmap_threshold", "fix_mmap_threshold_once", "release_pair_buffers"]


def release_pair_buffers(nlist):
    """Give back the pair sums' kept buffers at the end of a method's evaluation (ALARIC: and of its viscous sum):
    the pages of the loops' scratch (:func:`ase_sphrelax.neighbors.release_pages`; they read as zeros and are
    written again by the next sum) and ``nlist``'s gathered inputs (None: the scratch only). The driver's own arrays
    (time step, velocity update) are then made without them resident: ALARIC 2D at 1e4 particles held about 130 B
    per particle (the H solve's 8 power sums per point and the viscous sum's inputs, particles and mirror ghosts)
    through its dynamics' step, the peak of memory there (issue 33 item 4, ``reproductions/speed-scale-memory-2d``).
    Once per evaluation, not per sum: below :data:`ase_sphrelax.pairs.RELEASE_MIN_POINTS` the sums of one
    evaluation share them."""
    release_scratch()
    if nlist is not None:
        nlist.release_gathered()


def default_eta(kernel):
    """``eta`` for support radius ``H``: ``rho H^d = m eta^d`` (the kernel's registered value: Phantom's value
    for support 2h, times 2)."""
    kernel = get_kernel(kernel, 1) if isinstance(kernel, str) else kernel
    if kernel.eta is None:
        raise ValueError(f"eta: kernel {kernel.name!r} registers no default eta; pass eta explicitly")
    return kernel.eta


MMAP_THRESHOLD = 64 * 1024
"""glibc's mmap threshold in bytes, fixed (``mallopt(M_MMAP_THRESHOLD)``, process-wide) at the first
:func:`solve_smoothing_lengths` (ALARIC, SPH-ParVI) or 3D :class:`~ase_sphrelax.BIPICalculator` evaluation
(:func:`fix_mmap_threshold_once`); None leaves glibc's own. glibc raises the threshold to the size of each large
block freed (up to 32 MB), after which per-particle arrays come from the heap, whose freed pages it keeps: in ALARIC
2D's and SPH-ParVI 2D's steps at 1e4-1e5 particles such kept pages were 60-140 bytes per particle of the peak
resident set, in BIPI 2D's at 1e4 about 60 (``reproductions/speed-scale-memory-2d``). Fixed, every array above it is
its own mapping, given back when freed, and written to fresh pages when made: page faults cost about 3 % of an ALARIC
2D step at 1e5 against a threshold fixed at 32 MiB (``reproductions/speed-scale-memory-alaric``), more against
glibc's own rule, which also trims the heap less: a BIPI 2D Step-2c iteration at 1e5 was about 1.3x slower with it,
so a 2D BIPI evaluation leaves it alone (BIPI 2D keeps within 600 B per particle without it). The setting stays for
the rest of the process, so a Fan relaxation run after ALARIC or SPH-ParVI in the same process costs 1.15-1.2x the
CPU time a step (2D, 1e5 particles). Set it to None before the first solve to keep glibc's rule (faster, about
60-140 B per particle more)."""
_mmap_fixed = False


def fix_mmap_threshold(threshold=None):
    """Fix glibc's mmap threshold at ``threshold`` bytes (default :data:`MMAP_THRESHOLD`; its dynamic growth
    ends with it; :func:`ase_sphrelax.neighbors.set_mmap_threshold`). Elsewhere than glibc, or with a threshold
    None, nothing. True when set."""
    threshold = MMAP_THRESHOLD if threshold is None else threshold
    if threshold is not None and (isinstance(threshold, bool) or not isinstance(threshold, int) or threshold <= 0):
        raise ValueError(f"threshold must be a positive int (bytes) or None, got {threshold!r}")
    return threshold is not None and set_mmap_threshold(threshold)


def fix_mmap_threshold_once():
    """:func:`fix_mmap_threshold` at :data:`MMAP_THRESHOLD` on the first call of a process (the first H solve
    or 3D BIPI evaluation); later calls do nothing. True when this call set it."""
    global _mmap_fixed
    if _mmap_fixed:
        return False
    _mmap_fixed = True
    return fix_mmap_threshold()


class SmoothingLengthError(ValueError):
    """The smoothing-length iteration failed for (at least) one particle; the message names it."""


def _coincidence_note(r_pc, a, h_a):
    """``"; it coincides with particles [..]"`` (or lies within ``H`` of them) for particle ``a``, else ``""``.

    Only on the error path (an O(N) scan). ``k`` particles at one point hold ``k sigma f(0)`` kernel
    neighbours for every H: with ``k sigma f(0) >= eta^d`` the constraint ``n H^d = eta^d`` has no
    solution with ``Omega > 0``, which is the usual reason for a failed solve.
    """
    dist_p = np.sqrt(((r_pc - r_pc[a]) ** 2).sum(axis=1))
    dist_p[a] = np.inf
    same = np.nonzero(dist_p == 0.0)[0]
    if len(same):
        return (f"; it coincides with particle(s) {same[:10].tolist()} (coincident particles hold sigma f(0) kernel "
                f"neighbours each for every H: move them apart)")
    close = np.nonzero(dist_p <= max(float(h_a), 0.0))[0] if np.isfinite(h_a) else np.array([], int)
    if len(close) and h_a < 1e-6 * max(float(np.ptp(r_pc, axis=0).max()), 1e-300):
        return (f"; it (nearly) coincides with particle(s) {close[:10].tolist()} at distance "
                f"{float(dist_p[close].min()):.3g} (move them apart)")
    return ""


# -- a D-component tuple scaled by a number, for the vector terms of the pair functions ------------
def scaled(g, d):
    """``(g * d[0], ..., g * d[D-1])`` inside numba code, for a tuple ``d`` of any length."""
    return tuple(g * x for x in d)


@overload(scaled, inline="always")
def _scaled_overload(g, d):
    n = len(d)
    source = "def impl(g, d):\n    return (" + "".join(f"g * d[{i}], " for i in range(n)) + ")\n"
    namespace = {}
    exec(source, namespace)  # noqa: S102 (a fixed template unrolled over the tuple length)
    return namespace["impl"]


# -- pair physics -------------------------------------------------------------------------------
# Each pair function calls the kernel placeholders of ase_sphrelax.kernels, bound per kernel by PairInteraction;
# flags bound as constants (equal_masses, with_virial) give each variant's flat form from one source.
# The density and solve pairs are symmetric (one call per pair: one square root, a's and b's kernels at
# their own H) and write their sums as one vector per point (one cache line per partner); beyond a partner's
# H, or for an inactive one, q = 1 gives the kernel's zeros (a select, not a branch, for the kernels whose
# closed form has no branch: ase_sphrelax.kernels._closed_form_source).
@numba.njit(cache=True, inline="always")
def _density_pair(a, b, r2, d, ih_s, m_s, active_s):
    """Each partner gathers from the other with its own H: sum m f(q), sum m q f'(q), sum f(q), neighbour count.

    The inputs carry 1/H, so that q is a product rather than a division per pair.
    """
    r = math.sqrt(r2)
    qa = r * ih_s[a] if active_s[a] else 1.0
    qb = r * ih_s[b] if active_s[b] else 1.0
    fa, sa = kernel_profile(qa)
    fb, sb = kernel_profile(qb)
    ma = m_s[a]
    mb = m_s[b]
    return ((mb * fa, mb * qa * sa, fa, 1.0 if qa < 1.0 else 0.0),
            (ma * fb, ma * qb * sb, fb, 1.0 if qb < 1.0 else 0.0), ())


@numba.njit(cache=True, inline="always")
def _solve_pair(a, b, r2, d, ih_s, m_s, active_s, equal_masses):
    """The smoothing-length solve's sums of both partners, each with its own H. Equal masses (``m_s``
    unused): the moments sum q^k f^(k)(q), k = 0..4, and the neighbour count; per-particle masses:
    sum m f, sum m q f', sum m q^2 f'', sum f, count."""
    r = math.sqrt(r2)
    qa = r * ih_s[a] if active_s[a] else 1.0
    qb = r * ih_s[b] if active_s[b] else 1.0
    fa, sa, ca, ta, ua = kernel_derivatives(qa)
    fb, sb, cb, tb, ub = kernel_derivatives(qb)
    qa2 = qa * qa
    qb2 = qb * qb
    na = 1.0 if qa < 1.0 else 0.0
    nb = 1.0 if qb < 1.0 else 0.0
    if equal_masses:
        return ((fa, qa * sa, qa2 * ca, qa2 * qa * ta, qa2 * qa2 * ua, na),
                (fb, qb * sb, qb2 * cb, qb2 * qb * tb, qb2 * qb2 * ub, nb), ())
    ma = m_s[a]
    mb = m_s[b]
    return ((mb * fa, mb * qa * sa, mb * qa2 * ca, fa, na), (ma * fb, ma * qb * sb, ma * qb2 * cb, fb, nb), ())


# Powers of u = 1 - q whose sums can enter the moments: u^0 (the neighbour count) to u^POWER_DEGREE.
POWER_DEGREE = 8
# The power-sum pass gathers the count and a window of POWER_WINDOW consecutive powers u^low .. u^(low + 6): eight
# sums per point (one 64-byte row), the powers whose coefficients are zero for every moment left out (Wendland C4
# in 2D and 3D: u^0 and u^1 enter no moment, low = 2; in 1D low = 1; C2: low = 1).
POWER_WINDOW = 7


@numba.njit(cache=True, inline="always")
def _power_pair(a, b, r2, d, ih_s, active_s, low, all_active):
    """Both partners' neighbour counts and sums of ``u^j``, ``u = 1 - q`` (``q = r / H`` with the partner's own H),
    ``j = low .. low + 6`` (``low`` 1 or 2, a constant); zeros beyond H and for an inactive particle. With a
    one-piece polynomial kernel every moment ``sum_b q^k f^(k)(q)`` is a fixed combination of these sums
    (:func:`_power_moments`): no kernel evaluation per pair. ``all_active`` (a constant; ``active_s`` then None):
    every particle active, as in the first pass of each solve (no flags gathered or read)."""
    r = math.sqrt(r2)
    if all_active:
        qa = r * ih_s[a]
        qb = r * ih_s[b]
    else:
        qa = r * ih_s[a] if active_s[a] else 1.0
        qb = r * ih_s[b] if active_s[b] else 1.0
    ua = 0.0 if qa >= 1.0 else 1.0 - qa
    ub = 0.0 if qb >= 1.0 else 1.0 - qb
    ca = 1.0 if qa < 1.0 else 0.0
    cb = 1.0 if qb < 1.0 else 0.0
    a2 = ua * ua
    a3 = a2 * ua
    a4 = a2 * a2
    b2 = ub * ub
    b3 = b2 * ub
    b4 = b2 * b2
    if low == 1:
        return ((ca, ua, a2, a3, a4, a4 * ua, a4 * a2, a4 * a3),
                (cb, ub, b2, b3, b4, b4 * ub, b4 * b2, b4 * b3), ())
    return ((ca, a2, a3, a4, a4 * ua, a4 * a2, a4 * a3, a4 * a4),
            (cb, b2, b3, b4, b4 * ub, b4 * b2, b4 * b3, b4 * b4), ())


def _voigt(k, d):
    """k d d^T (Voigt xx yy zz yz xz xy of the first three components of d; zeros for missing components)."""
    d0, d1, d2 = (tuple(d) + (0.0, 0.0))[:3]
    return (k * d0 * d0, k * d1 * d1, k * d2 * d2, k * d1 * d2, k * d0 * d2, k * d0 * d1)


@overload(_voigt, inline="always")
def _voigt_overload(k, d):
    n = len(d)  # the tuple's length is known at compile time: missing components are zeros, not indexed
    pick = [f"d[{i}]" if i < n else "0.0" for i in range(3)]
    source = (f"def impl(k, d):\n    d0 = {pick[0]}\n    d1 = {pick[1]}\n    d2 = {pick[2]}\n"
              "    return (k * d0 * d0, k * d1 * d1, k * d2 * d2, k * d1 * d2, k * d0 * d2, k * d0 * d1)\n")
    namespace = {}
    exec(source, namespace)  # noqa: S102 (a fixed template over the tuple length)
    return namespace["impl"]


# The pressure pair is written out flat (no helper for the shared slope sum): in these loops a nested inline
# helper, or one per-point array more per pair, cost 2-4x (measured on 1e5 points in 2D). Two sources (per-particle
# masses, equal masses), each with and without the virial (``with_virial`` bound).
@numba.njit(cache=True, inline="always")
def _pressure_pair(a, b, r2, d, ih_s, m_s, c_s, with_virial):
    """The symmetric grad-h force (see :func:`pressure_forces`): F_a = k d, F_b = -k d with
    k = m_a m_b (c_a f'(r/H_a) + c_b f'(r/H_b)) / r, c = P/(Omega rho^2) sigma/H^(d+1); with the pair
    virial k d d^T."""
    r = math.sqrt(r2)
    g = c_s[a] * kernel_profile(r * ih_s[a])[1] + c_s[b] * kernel_profile(r * ih_s[b])[1]
    k = m_s[a] * m_s[b] * g / r if r2 > 0.0 else 0.0
    if with_virial:
        return scaled(k, d), scaled(-k, d), _voigt(k, d)
    return scaled(k, d), scaled(-k, d), ()


@numba.njit(cache=True, inline="always")
def _pressure_pair_equal(a, b, r2, d, m2, hc_s, with_virial):
    """:func:`_pressure_pair` with equal masses (``m_a m_b = m2``) and each point's ``1/H`` and ``c`` in one row of
    ``hc_s`` (N, 2): one cache line per partner (2D, 1e5 points: 3-9 % less time than two arrays)."""
    r = math.sqrt(r2)
    g = hc_s[a, 1] * kernel_profile(r * hc_s[a, 0])[1] + hc_s[b, 1] * kernel_profile(r * hc_s[b, 0])[1]
    k = m2 * g / r if r2 > 0.0 else 0.0
    if with_virial:
        return scaled(k, d), scaled(-k, d), _voigt(k, d)
    return scaled(k, d), scaled(-k, d), ()


@numba.njit(cache=True, inline="always")
def _viscosity_pair(a, b, r2, d, v_sig, beta, approaching_only, m, ih_s, g_s, m_s, rho_s, alpha_s, v_sc,
                    equal_masses):
    """Pi_ab grad Wbar_ab forces and the Eq. 21 divergence of both partners (equal masses: ``m``, no ``m_s``)."""
    if r2 == 0.0:
        z = scaled(0.0, d)
        return (0.0,) + z, (0.0,) + z, ()
    r = math.sqrt(r2)
    # w = v_ab . rhat_ab with rhat_ab = (x_a - x_b)/r = -d/r
    vd = 0.0
    for c in range(len(d)):
        vd += (v_sc[a, c] - v_sc[b, c]) * d[c]
    w = -vd / r
    ga = g_s[a] * kernel_profile(r * ih_s[a])[1]  # dW/dr (H_a) <= 0, zero beyond H_a
    gb = g_s[b] * kernel_profile(r * ih_s[b])[1]
    if equal_masses:
        ma = mb = m
    else:
        ma = m_s[a]
        mb = m_s[b]
    # Eq. 21: div_a = sum_b m_b/rho_b (v_ab . r_ab) F_ab(H_a), F = -(dW/dr)/r
    div_a = -mb / rho_s[b] * w * ga
    div_b = -ma / rho_s[a] * w * gb
    if approaching_only and w >= 0.0:
        z = scaled(0.0, d)
        return (div_a,) + z, (div_b,) + z, ()
    pi = (-0.5 * (alpha_s[a] + alpha_s[b]) * v_sig * w + beta * w * w) / (0.5 * (rho_s[a] + rho_s[b]))
    # F_a = -m_a m_b Pi grad_a Wbar, grad_a Wbar = 0.5 (ga + gb) (-d / r)
    k = ma * mb * pi * 0.5 * (ga + gb) / r
    return (div_a,) + scaled(k, d), (div_b,) + scaled(-k, d), ()


@numba.njit(cache=True, inline="always")
def _continuity_pair(a, b, r2, d, diffusion, c0, ih_s, g_s, m_s, rho_s, v_sc, divergence):
    """a gathers drho/dt = sum_b m_b v_ab . grad_a W_ab(H_a) + a_d H_a c0 sum_b V_b psi_ab . grad_a W_ab, or
    (``divergence``) Eq. 21, div_a = sum_b m_b/rho_b v_ab . r_ab F_ab(H_a), from the same terms."""
    if r2 == 0.0:
        return (0.0,), ()
    r = math.sqrt(r2)
    vd = 0.0
    for c in range(len(d)):
        vd += (v_sc[a, c] - v_sc[b, c]) * d[c]
    ga = g_s[a] * kernel_profile(r * ih_s[a])[1]  # dW/dr <= 0, zero beyond H_a
    if divergence:
        return (m_s[b] / rho_s[b] * vd / r * ga,), ()
    # grad_a W = ga (x_a - x_b)/r = -ga d / r
    rate = -m_s[b] * ga * vd / r
    if diffusion != 0.0:
        # psi_ab = 2 (rho_b - rho_a) (x_b - x_a)/(r^2 + 0.1 H^2); psi . grad_a W = -2 (rho_b - rho_a) ga r / (...)
        ha = 1.0 / ih_s[a]
        psi_grad = -2.0 * (rho_s[b] - rho_s[a]) * ga * r / (r2 + 0.1 * ha * ha)
        rate += diffusion * ha * c0 * m_s[b] / rho_s[b] * psi_grad
    return (rate,), ()


_GRADIENT_INPUTS = ("ih_s", "g_s", "m_s", "rho_s", "v_sc")


def _pressure_interaction(dim_points, equal_masses, with_virial):
    outputs = dict(forces=Output((dim_points,)))
    if with_virial:
        outputs["virial"] = Output((6,), per_point=False)
    if equal_masses:
        return PairInteraction(_pressure_pair_equal, outputs, symmetric=True, dim=dim_points, params=("m2",),
                               inputs=("hc_s",), constants=dict(with_virial=with_virial))
    return PairInteraction(_pressure_pair, outputs, symmetric=True, dim=dim_points, inputs=("ih_s", "m_s", "c_s"),
                           constants=dict(with_virial=with_virial))


def _build_interaction(name, dim_points):
    scalar = Output(())
    if name == "density":  # sums: s, t, n, count
        return PairInteraction(_density_pair, dict(sums=Output((4,))), inputs=("ih_s", "m_s", "active_s"),
                               dim=dim_points)
    if name == "solve":  # equal masses; sums: M_0 .. M_4, count
        return PairInteraction(_solve_pair, dict(sums=Output((6,))), inputs=("ih_s", "active_s"),
                               constants=dict(equal_masses=True, m_s=None), dim=dim_points)
    if name.startswith("solve_powers"):  # equal masses, a one-piece kernel; count, u^low .. u^(low + 6)
        low, every = int(name[len("solve_powers")]), name.endswith("_all")
        constants = dict(low=low, all_active=every) | (dict(active_s=None) if every else {})
        return PairInteraction(_power_pair, dict(sums=Output((POWER_WINDOW + 1,))),
                               inputs=("ih_s",) if every else ("ih_s", "active_s"), constants=constants,
                               dim=dim_points)
    if name == "solve_masses":  # sums: s, t, M_2, n, count
        return PairInteraction(_solve_pair, dict(sums=Output((5,))), inputs=("ih_s", "m_s", "active_s"),
                               constants=dict(equal_masses=False), dim=dim_points)
    if name.startswith("pressure"):
        return _pressure_interaction(dim_points, name.endswith("_equal"), "virial" in name)
    if name == "viscosity":
        return PairInteraction(_viscosity_pair, dict(div_v=scalar, forces=Output((dim_points,))),
                               params=("v_sig", "beta", "approaching_only"), inputs=_GRADIENT_INPUTS[:4] + (
                                   "alpha_s", "v_sc"), constants=dict(equal_masses=False, m=0.0), symmetric=True,
                               dim=dim_points)
    if name == "viscosity_equal":  # the mass a parameter: no per-particle array of it, nor its gathered copy
        return PairInteraction(_viscosity_pair, dict(div_v=scalar, forces=Output((dim_points,))),
                               params=("v_sig", "beta", "approaching_only", "m"), inputs=("ih_s", "g_s", "rho_s",
                                                                                         "alpha_s", "v_sc"),
                               constants=dict(equal_masses=True, m_s=None), symmetric=True, dim=dim_points)
    if name == "divergence":
        return PairInteraction(_continuity_pair, dict(div_v=scalar), inputs=_GRADIENT_INPUTS, symmetric=False,
                               constants=dict(divergence=True, diffusion=0.0, c0=0.0), dim=dim_points)
    if name == "continuity":
        return PairInteraction(_continuity_pair, dict(rate=scalar), params=("diffusion", "c0"),
                               inputs=_GRADIENT_INPUTS, constants=dict(divergence=False), symmetric=False,
                               dim=dim_points)
    raise KeyError(name)  # pragma: no cover


_INTERACTIONS: dict = {}


def _interaction(name, dim_points):
    """The PairInteraction ``name`` for points with ``dim_points`` stored coordinates (cached; each
    specialises its loops per kernel, ``compute(..., kernel=k)``)."""
    key = (name, dim_points)
    if key not in _INTERACTIONS:
        _INTERACTIONS[key] = _build_interaction(name, dim_points)
    return _INTERACTIONS[key]


def _per_particle(name, value, n, positive=True):
    """``value`` (scalar or (n,)) as a float array of shape (n,), finite (and > 0)."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} must be a number or an array of shape ({n},), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or (positive and np.any(arr <= 0.0)):
        bad = np.nonzero(~np.isfinite(arr) | ((arr <= 0.0) if positive else False))[0]
        raise ValueError(f"{name} must be finite{' and > 0' if positive else ''}; particles {bad[:10].tolist()} are not")
    return arr


def _check_dims(dims, r_pc):
    """The coordinates the pairs see: ``dims`` (1 .. r_pc's columns) or, None, all of them."""
    if dims is None:
        return r_pc.shape[1]
    if not (isinstance(dims, (int, np.integer)) and 1 <= dims <= r_pc.shape[1]):
        raise ValueError(f"dims must be an integer 1 .. {r_pc.shape[1]} (the columns of r_pc) or None, got {dims!r}")
    return int(dims)


# -- density --------------------------------------------------------------------------------------
class DensitySums:
    """Per-particle results of a density pass with smoothing lengths ``h_p``.

    Attributes
    ----------
    h_p : ndarray (N,)
        Support radii used.
    rho_p : ndarray (N,)
        ``sum_b m_b W_ab(H_a)``, self term included (Eq. 8).
    n_p : ndarray (N,)
        Number density ``sum_b W_ab(H_a)`` (Eq. 32), self term included.
    omega_p : ndarray (N,)
        ``1 + H_a/(d rho_a) sum_b m_b dW_ab/dH`` (Eq. 13); equals
        ``-sum_b m_b q f'(q) / (d sum_b m_b f(q))``.
    neighbours_p : ndarray (N,)
        Number of other particles within ``H_a``.
    iterations : int
        Density passes of the H solve (0 for a plain density pass).
    """

    def __init__(self, h_p, rho_p, n_p, omega_p, neighbours_p, iterations=0):
        self.h_p = h_p
        self.rho_p = rho_p
        self.n_p = n_p
        self.omega_p = omega_p
        self.neighbours_p = neighbours_p
        self.iterations = iterations


def _raw_sums(nlist, r_pc, h_p, m_p, active_p, kernel):
    sums = _interaction("density", r_pc.shape[1]).compute(
        nlist, r_pc, inputs=dict(ih_s=1.0 / h_p, m_s=m_p, active_s=active_p), reach=float(h_p.max()),
        kernel=kernel).sums
    # self terms: f(0) = f0, q f'(q) = 0 at q = 0
    return sums[:, 0] + m_p * kernel.f0, sums[:, 1], sums[:, 2] + kernel.f0, sums[:, 3]


_POWER_MOMENTS: dict = {}


def _power_moments(kernel):
    """``(E, low)``: ``sum_b q^k f^(k)(q) = E[k, 0] count + sum_(j >= 1) E[k, j] sum_b u^(low + j - 1)``
    (``u = 1 - q``, the sums over the partners within H, the count = ``sum_b u^0``), ``E`` of shape
    (5, POWER_WINDOW + 1), the window's start ``low`` 1 or 2; None when the kernel is not one polynomial of
    degree <= POWER_DEGREE on [0, 1), or its moments need powers outside one window.

    ``q^k f^(k)(q) = (1 - u)^k d^k f/dq^k`` is a polynomial in u of the kernel's degree, with the
    coefficients of the kernel's definition in powers of u (:attr:`Kernel.coef`): near the cut-off the
    terms are small powers of u, as in the kernel's closed forms. The powers whose coefficient is zero in
    every moment are not gathered (their terms added zeros: the moments are the same bit for bit).
    """
    if kernel.key not in _POWER_MOMENTS:
        result = None
        if len(kernel.breaks) == 3 and kernel.breaks[1] == 1.0 and kernel.coef.shape[1] <= POWER_DEGREE + 1:
            full = np.zeros((5, POWER_DEGREE + 1))
            for k in range(5):
                poly = P.polymul(P.polypow([1.0, -1.0], k), _derivative_in_q(kernel.coef[0], k))
                full[k, : len(poly)] = poly
            used = np.nonzero(np.any(full[:, 1:] != 0.0, axis=0))[0] + 1
            low = int(used.min()) if used.size else 1
            if low in (1, 2) and (not used.size or used.max() < low + POWER_WINDOW):
                table = np.zeros((5, POWER_WINDOW + 1))
                table[:, 0] = full[:, 0]
                top = min(low + POWER_WINDOW, POWER_DEGREE + 1)
                table[:, 1: 1 + top - low] = full[:, low:top]
                result = (table, low)
        _POWER_MOMENTS[kernel.key] = result
    return _POWER_MOMENTS[kernel.key]


@numba.njit(cache=True, inline="always")
def _table_dot(table_kj, k, v0, v1, v2, v3, v4, v5, v6, v7):
    """``sum_j table[k, j] v_j`` over the window (POWER_WINDOW + 1 = 8 sums), added in the order of j."""
    total = 0.0
    total += table_kj[k, 0] * v0
    total += table_kj[k, 1] * v1
    total += table_kj[k, 2] * v2
    total += table_kj[k, 3] * v3
    total += table_kj[k, 4] * v4
    total += table_kj[k, 5] * v5
    total += table_kj[k, 6] * v6
    total += table_kj[k, 7] * v7
    return total


@numba.njit(cache=True, inline="always")
def _power_row(sums_pj, table_kj, m, f0, p):
    """``s, t, M_2, M_3, M_4, n, count`` of point p with the self terms, for equal masses ``m``, from its power
    sums (a row of :func:`_power_pair`'s, POWER_WINDOW + 1 = 8 of them; written out: a loop over the window
    inside the H update cost 2.7 ms at 1e5 in 2D, more than the whole update)."""
    v0, v1, v2, v3 = sums_pj[p, 0], sums_pj[p, 1], sums_pj[p, 2], sums_pj[p, 3]
    v4, v5, v6, v7 = sums_pj[p, 4], sums_pj[p, 5], sums_pj[p, 6], sums_pj[p, 7]
    nn = _table_dot(table_kj, 0, v0, v1, v2, v3, v4, v5, v6, v7) + f0  # the self term: f(0) = f0, q^k f^(k) = 0
    t = m * _table_dot(table_kj, 1, v0, v1, v2, v3, v4, v5, v6, v7)
    w = m * _table_dot(table_kj, 2, v0, v1, v2, v3, v4, v5, v6, v7)
    x = m * _table_dot(table_kj, 3, v0, v1, v2, v3, v4, v5, v6, v7)
    y = m * _table_dot(table_kj, 4, v0, v1, v2, v3, v4, v5, v6, v7)
    return m * nn, t, w, x, y, nn, v0


@numba.njit(cache=True)
def _moments_from_powers(sums_pj, table_kj, m, f0):
    """Rows ``s, t, M_2, M_3, M_4, n, count`` (7, N) with the self terms, for equal masses ``m``, from the power
    sums (N, POWER_WINDOW + 1): one pass, no temporaries, no BLAS (slow under load on these machines)."""
    n = sums_pj.shape[0]
    out_kp = np.empty((7, n))
    for p in range(n):
        row = _power_row(sums_pj, table_kj, m, f0, p)
        for k in range(7):
            out_kp[k, p] = row[k]
    return out_kp


_NO_ROWS = np.empty(0)
_NO_SUMS = np.empty((0, POWER_WINDOW + 1))
_NO_TABLE = np.zeros((5, POWER_WINDOW + 1))


def _solve_pass(nlist, r_pc, h_p, m_p, equal, active_p, kernel, dims=None):
    """One density pass of the H solve: ``(sums_pj, table_kj, rows)``.

    Equal masses and a one-piece kernel (Wendland): the power sums (N, POWER_WINDOW + 1) of :func:`_power_pair`
    and their table (:func:`_power_moments`), ``rows`` None (the update forms each particle's moments,
    :func:`_power_row`); otherwise ``(None, None, rows)``, the kernel's derivatives per pair
    (:func:`_solve_pair`), ``rows`` as :func:`_solve_sums` returns them. The pairs see the first ``dims``
    coordinates (default all).
    """
    reach = float(h_p.max())
    dims = r_pc.shape[1] if dims is None else dims
    found = _power_moments(kernel) if equal else None
    if found is not None:
        table, low = found
        if active_p.all():  # the first pass: no flags to gather and read
            sums = _interaction(f"solve_powers{low}_all", dims).compute(
                nlist, r_pc, inputs=dict(ih_s=1.0 / h_p), reach=reach).sums
        else:
            sums = _interaction(f"solve_powers{low}", dims).compute(
                nlist, r_pc, inputs=dict(ih_s=1.0 / h_p, active_s=active_p), reach=reach).sums
        return sums, table, None
    if equal:  # m_p constant: s = m sum f, n = sum f
        sums = _interaction("solve", dims).compute(
            nlist, r_pc, inputs=dict(ih_s=1.0 / h_p, active_s=active_p), reach=reach, kernel=kernel).sums
        n_p = sums[:, 0] + kernel.f0
        m = m_p[0]
        return None, None, (m * n_p, m * sums[:, 1], m * sums[:, 2], m * sums[:, 3], m * sums[:, 4], n_p, sums[:, 5])
    sums = _interaction("solve_masses", dims).compute(
        nlist, r_pc, inputs=dict(ih_s=1.0 / h_p, m_s=m_p, active_s=active_p), reach=reach, kernel=kernel).sums
    return None, None, (sums[:, 0] + m_p * kernel.f0, sums[:, 1], sums[:, 2], None, None, sums[:, 3] + kernel.f0,
                        sums[:, 4])


def _solve_sums(nlist, r_pc, h_p, m_p, equal, active_p, kernel):
    """(s, t, M_2, M_3, M_4, n, count) with the self terms, ``M_k = sum_b m_b q^k f^(k)``, ``s = M_0``,
    ``t = M_1``, ``n = sum_b f``; ``M_3``, ``M_4`` only with equal masses (else None).

    Equal masses and a one-piece kernel (Wendland): one pass of power sums (:func:`_power_pair`,
    :func:`_power_moments`); otherwise the kernel's derivatives per pair (:func:`_solve_pair`).
    """
    sums, table, rows = _solve_pass(nlist, r_pc, h_p, m_p, equal, active_p, kernel)
    if rows is None:
        return tuple(_moments_from_powers(sums, table, float(m_p[0]), kernel.f0))
    return rows


def density_sums(nlist, r_pc, masses, h, kernel):
    """Density, number density and Omega for given smoothing lengths (fixed or per particle).

    Parameters
    ----------
    nlist : NeighborList (or an object of the same interface)
        Updated for ``r_pc`` with cut-offs >= ``h`` (per particle or the largest).
    r_pc : ndarray (N, D)
    masses : float or ndarray (N,)
    h : float or ndarray (N,)
        Kernel support radius per particle (a number for a global h).
    kernel : Kernel

    Returns
    -------
    DensitySums
    """
    r_pc = np.asarray(r_pc, dtype=float)
    n = r_pc.shape[0]
    m_p = _per_particle("masses", masses, n)
    h_p = _per_particle("h", h, n)
    s_p, t_p, w_p, count_p = _raw_sums(nlist, r_pc, h_p, m_p, np.ones(n, dtype=np.bool_), kernel)
    norm_p = kernel.sigma / h_p**kernel.dim
    omega_p = -t_p / (kernel.dim * s_p)
    return DensitySums(h_p, norm_p * s_p, norm_p * w_p, omega_p, count_p)


def initial_smoothing_length(r_pc, cell, pbc, dim, eta):
    """A first guess ``H = eta (V/N)^(1/d)`` from the periodic cell or the particles' bounding box."""
    r_pc = np.asarray(r_pc, dtype=float)
    n = r_pc.shape[0]
    pbc = np.asarray(pbc, dtype=bool)
    cell = np.asarray(cell, dtype=float).reshape(3, 3)
    extent_c = np.ptp(r_pc[:, :dim], axis=0) if n > 1 else np.zeros(dim)
    for c in range(min(dim, 3)):
        if pbc[c]:
            extent_c[c] = np.linalg.norm(cell[c])
    scale = float(extent_c.max()) if extent_c.size else 0.0
    extent_c = np.where(extent_c > 0.0, extent_c, max(scale, 1.0) / max(n, 1))
    volume = float(np.prod(extent_c))
    return eta * (volume / n) ** (1.0 / dim)


NEWTON_ITERATIONS = 12  # then bisection only


# reciprocals: a multiplication instead of a division in the H update (rounding differs from x / 3 in the last bit)
_THIRD = 1.0 / 3.0
_SIXTH = 1.0 / 6.0
_SEVENTH = 1.0 / 7.0
_TWENTYFOURTH = 1.0 / 24.0


# The accepted Taylor step of the H update (_smoothing_length_chunk) is small (|dl| <= step_max, 2e-3 for C4 and
# tol 1e-8): its exp and log1p by series, exact to rounding, cost a fraction of the library calls; larger
# arguments take the library's. One logarithm per particle is left (G).
@numba.njit(cache=True, inline="always")
def _exp_small(x):
    """``exp(x)``: Horner series to ``x^8`` for ``|x| <= 0.03`` (truncation below 1e-19 relative), else math.exp."""
    if abs(x) > 0.03:
        return math.exp(x)
    return 1.0 + x * (1.0 + x * 0.5 * (1.0 + x * _THIRD * (1.0 + x * 0.25 * (1.0 + x * 0.2 * (
        1.0 + x * _SIXTH * (1.0 + x * _SEVENTH * (1.0 + x * 0.125)))))))


@numba.njit(cache=True, inline="always")
def _log1p_small(e):
    """``ln(1 + e)``: series to ``e^8`` for ``|e| <= 0.01`` (truncation below 1e-18 relative), else math.log1p."""
    if abs(e) > 0.01:
        return math.log1p(e)
    return e * (1.0 - e * (1.0 / 2.0 - e * (1.0 / 3.0 - e * (1.0 / 4.0 - e * (1.0 / 5.0 - e * (
        1.0 / 6.0 - e * (1.0 / 7.0 - e / 8.0)))))))
# A Halley step |d ln H| <= kernel.extrapolation_step tol^(1/4) may be accepted without a further density pass
# (_smoothing_length_step); the factor is part of each kernel's definition (ase_sphrelax.kernels, Wendland C4:
# 0.22, with the measurement behind it; 0 for kernels whose profile is not C^4).


def solve_smoothing_lengths(nlist, r_pc, cell, pbc, masses, kernel, eta=None, h0=None, tol=1e-8, max_iter=100,
                            store=True, solve=None, dims=None):
    """Solve ``rho_a(H_a) H_a^d = m_a eta^d`` with ``rho_a = sum_b m_b W_ab(H_a)`` for every particle.

    With equal masses this is ALARIC's Eq. 31-32 (``n_a H_a^d = eta^d``). ``sigma s(H) / m_a`` with
    ``s = sum_b m_b f(r_ab / H)`` increases monotonically in ``H``, so each particle has at most one
    root; it is found by Halley steps on ``G = ln(sigma s / m_a) - d ln eta`` in ``ln H`` (one density
    pass gives ``s``, ``sum m q f'`` and ``sum m q^2 f''``; see :func:`_smoothing_length_step`), limited
    to a factor 2 per iteration and kept inside a bisection bracket (a step that leaves the bracket is
    replaced by bisection, or by doubling/halving while one side is open); after
    :data:`NEWTON_ITERATIONS` iterations only bisection. Converged when the step is below ``tol``
    relative; H is then kept, so the returned sums are those of the returned H. From the previous
    step's H (a change of H up to ~1e-3) this takes two density passes.

    Parameters
    ----------
    nlist : NeighborList
        Updated here with the per-particle cut-offs ``H`` (``nlist.update(r_pc, cell, pbc, cutoff=H)``).
    r_pc : ndarray (N, 3)
    cell, pbc
        As in ASE (only the first ``kernel.dim`` axes should be periodic).
    masses : float or ndarray (N,)
    kernel : Kernel
    eta : float or None
        ``rho H^d = m eta^d`` for support ``H`` (:func:`default_eta` when None).
    h0 : float, ndarray (N,) or None
        Starting guess (e.g. the previous step's ``H``); default :func:`initial_smoothing_length`.
    tol : float
        Relative tolerance on ``H``.
    max_iter : int
        Iterations before :class:`SmoothingLengthError`.
    store : bool
        Passed to ``nlist.update`` (False for one-shot bins).
    solve : int or None
        Solve only the first ``solve`` points; the others keep ``h0`` and only count as neighbours (e.g. mirror
        ghosts, whose H is their owner's), their sums in the result are NaN. None: all.
    dims : int or None
        The pairs see the first ``dims`` coordinates of ``r_pc`` (default all): the kernel's dimension for ASE
        positions of a d < 3 system (zeros beyond d), the same sums with fewer operations per pair.

    Returns
    -------
    DensitySums
        At the converged ``H`` (``rho``, ``n`` and ``Omega`` consistent with it).

    Raises
    ------
    SmoothingLengthError
        Naming the first particle that did not converge, or that has no root because the
        whole system holds fewer than ``eta^d / (sigma f(0))`` particles' worth of neighbours.

    Notes
    -----
    The first call in a process fixes glibc's mmap threshold (:data:`MMAP_THRESHOLD`, :func:`fix_mmap_threshold`).
    """
    fix_mmap_threshold_once()  # freed per-particle arrays are not kept by the heap (MMAP_THRESHOLD)
    r_pc = np.asarray(r_pc, dtype=float)
    n = r_pc.shape[0]
    d = kernel.dim
    dims = _check_dims(dims, r_pc)
    eta = default_eta(kernel) if eta is None else float(eta)
    one_mass = np.ndim(masses) == 0
    # one mass: read-only views of it (and of sigma / m), not two arrays per point through the solve (the same values)
    m_p = np.broadcast_to(_per_particle("masses", masses, 1), (n,)) if one_mass else _per_particle("masses", masses, n)
    target = eta**d
    sigma = kernel.sigma
    if target <= sigma * kernel.f0:
        raise SmoothingLengthError(f"eta = {eta:.4g} is too small for {kernel!r}: eta^d must exceed sigma f(0) = "
                                   f"{sigma * kernel.f0:.4g} (the particle's own contribution)")
    # no root in an open system if even all particles inside H give too few neighbours
    if not np.any(np.asarray(pbc, dtype=bool)[:d]):
        most = sigma * kernel.f0 * m_p.sum() / m_p
        if np.any(most <= target):
            a = int(np.argmax(most <= target))
            raise SmoothingLengthError(
                f"particle {a}: {n} particles cannot give eta^d = {target:.4g} kernel neighbours (at most "
                f"{most[a]:.4g} with every particle inside H); use more particles or a smaller eta")
    if h0 is None:
        h_p = np.full(n, initial_smoothing_length(r_pc, cell, pbc, d, eta))
    else:
        h_p = _per_particle("h0", h0, n).copy()
    lo_p = np.zeros(n)
    hi_p = np.full(n, np.inf)
    active_p = np.ones(n, dtype=np.bool_)
    s_p = np.empty(n)
    t_p = np.empty(n)
    n_p = np.empty(n)
    count_p = np.empty(n)
    if solve is not None:  # the rest keep h0: inactive from the start, NaN sums
        active_p[solve:] = False
        for arr in (s_p, t_p, n_p, count_p):
            arr[solve:] = np.nan
    equal = bool(np.all(m_p == m_p[0]))
    step_max = kernel.extrapolation_step * tol**0.25 if equal else 0.0
    sigma_over_m_p = np.broadcast_to(sigma / m_p[:1], (n,)) if one_mass else sigma / m_p
    h_cap = None  # 1e3 times the larger of the extent and the first H, computed when H has grown that far
    h_first = float(h_p.max())
    for iteration in range(1, max_iter + 1):
        nlist.update(r_pc, cell, pbc, cutoff=h_p, store=store)
        sums_pj = rows = moments = None  # the last pass's sums go before the next pass makes its own
        sums_pj, table_kj, rows = _solve_pass(nlist, r_pc, h_p, m_p, equal, active_p, kernel, dims)
        if rows is None:  # power sums: each particle's moments are formed in the update (no (7, N) rows)
            moments = (sums_pj, table_kj, float(m_p[0]), float(kernel.f0)) + (_NO_ROWS,) * 7
        else:
            s_a, t_a, w_a, x_a, y_a, n_a, c_a = rows
            if x_a is None:
                x_a = y_a = t_a  # not read: no extrapolation with unequal masses
            moments = (_NO_SUMS, _NO_TABLE, 0.0, 0.0, s_a, t_a, w_a, x_a, y_a, n_a, c_a)
        bad = _smoothing_length_step(moments, s_p, t_p, n_p, count_p, h_p, lo_p, hi_p, active_p, sigma_over_m_p,
                                     target, tol, iteration > NEWTON_ITERATIONS, step_max)
        if bad >= 0:
            raise SmoothingLengthError(f"particle {bad} at {r_pc[bad].tolist()}: the kernel sum is not finite at H = "
                                       f"{h_p[bad]:.6g} (non-finite positions or masses?)")
        if not active_p.any():
            break
        if h_cap is None and h_p.max() > 1e3 * h_first:
            h_cap = 1e3 * max(float(np.ptp(r_pc, axis=0).max()) if n > 1 else 1.0, h_first)
        if h_cap is not None and np.any(h_p > h_cap):
            a = int(np.argmax(h_p > h_cap))
            raise SmoothingLengthError(
                f"particle {a} at {r_pc[a].tolist()}: H grew beyond {h_cap:.4g} without reaching eta^d = "
                f"{target:.4g} neighbours (too few particles within reach)")
    else:
        a = int(np.argmax(active_p))
        raise SmoothingLengthError(
            f"particle {a} at {r_pc[a].tolist()}: smoothing length did not converge in {max_iter} iterations "
            f"(H = {h_p[a]:.6g}, bracket [{lo_p[a]:.6g}, {hi_p[a]:.6g}], {int(active_p.sum())} particles left)"
            + _coincidence_note(r_pc, a, h_p[a]))
    sums_pj = rows = moments = lo_p = hi_p = None  # done with: freed before the outputs are made
    norm_p = sigma / h_p**d
    omega_p = -t_p / (d * s_p)
    if not np.all(omega_p[:solve] > 0.0):  # NaN included: H is not a differentiable function of the positions there
        a = int(np.argmax(~(omega_p > 0.0)))
        raise SmoothingLengthError(
            f"particle {a} at {r_pc[a].tolist()}: Omega (Eq. 13) = {omega_p[a]:.3g} at H = {h_p[a]:.6g}: n H^d = "
            f"eta^d does not fix H (no energy gradient)" + _coincidence_note(r_pc, a, h_p[a]))
    return DensitySums(h_p.copy(), norm_p * s_p, norm_p * n_p, omega_p, count_p.copy(), iterations=iteration)


def _smoothing_length_step(moments, s_p, t_p, n_p, count_p, h_p, lo_p, hi_p, active_p, sigma_over_m_p, target, tol,
                           bisect_only, step_max):
    """One update of every active particle's H from its sums (in place; the particles in chunks on the
    threads, :func:`_smoothing_length_chunk`); the first particle with a non-finite sum, or -1. ``moments``:
    ``(sums_pj, table_kj, m, f0)`` and seven empty rows (power sums), or an empty ``sums_pj``, a table, two
    zeros and the rows ``s, t, M_2, M_3, M_4, n, count``."""
    nthreads = thread_count(h_p.shape[0])
    bad_t = np.full(nthreads, -1, dtype=np.int64)
    run_chunks(_smoothing_length_chunk, h_p.shape[0], moments + (s_p, t_p, n_p, count_p, h_p, lo_p, hi_p, active_p,
                                                                 sigma_over_m_p, float(target), float(tol),
                                                                 bool(bisect_only), float(step_max), bad_t),
               per_thread=[(t,) for t in range(nthreads)])
    bad = bad_t[bad_t >= 0]
    return int(bad.min()) if bad.size else -1


@numba.njit(cache=True, nogil=True)
def _smoothing_length_chunk(sums_pj, table_kj, m, f0, s_a, t_a, w_a, x_a, y_a, n_a, c_a, s_p, t_p, n_p, count_p,
                            h_p, lo_p, hi_p, active_p, sigma_over_m_p, target, tol, bisect_only, step_max, bad_t,
                            thread, first, last):
    """:func:`_smoothing_length_step` for the particles ``[first, last)``: ``bad_t[thread]`` = the first
    particle with a non-finite sum, else left at -1. Particle a's sums: :func:`_power_row` of ``sums_pj``
    when it has rows (power sums, the pass of :func:`_solve_pass` fused with the update), else
    ``s_a[a], t_a[a], ...``.

    The root of ``G(l) = ln(sigma s / m) - ln(eta^d)``, ``l = ln H``, is found by Halley steps, with the
    moments ``M_k = sum_b m_b q^k f^(k)(q)`` of one density pass (``s = M_0``, ``t = M_1``):
    ``dM_k/dl = -k M_k - M_(k+1)``, so ``G' = -t/s`` (``= d Omega``) and ``G'' = (t + M_2)/s - G'^2``.
    ``G`` is nearly linear in ``ln H`` (``s`` grows like ``H^d``) and Halley's steps converge cubically
    (Newton on ``eta^d - sigma s / m`` left a 1e-6 residual after a 1e-3 change of H).

    Converged when the step or the bracket is below ``tol`` relative: H is kept, with its sums. With
    ``step_max > 0`` (equal masses, moments up to ``M_4``) a step ``|dl| <= step_max`` is also
    accepted without a further density pass when the sums carried to the new H by their Taylor
    series, ``s(l + dl) = sum_j s^(j) dl^j / j!`` to ``j = 4`` and ``t = -s'`` to ``j = 3``
    (``s' = -M_1``, ``s'' = M_1 + M_2``, ``s''' = -(M_1 + 3 M_2 + M_3)``,
    ``s'''' = M_1 + 7 M_2 + 6 M_3 + M_4``), satisfy the constraint to ``tol``; the truncation error,
    ``|s^(5)| dl^4 / 24`` relative in ``t``, is then below ``tol`` (``Kernel.extrapolation_step``: Wendland C4
    only).
    A step outside the bracket, by more than a factor 2, or not finite is replaced by bisection
    (doubling/halving while one side is open); ``bisect_only`` after :data:`NEWTON_ITERATIONS`.
    """
    powers = sums_pj.shape[0] > 0
    log_target = math.log(target)
    for a in range(first, last):
        if not active_p[a]:
            continue
        if powers:
            s, t, w, x, y, nn, c = _power_row(sums_pj, table_kj, m, f0, a)
        else:
            s, t, w, x, y, nn, c = s_a[a], t_a[a], w_a[a], x_a[a], y_a[a], n_a[a], c_a[a]
        s_p[a], t_p[a], n_p[a], count_p[a] = s, t, nn, c
        h = h_p[a]
        g = target - sigma_over_m_p[a] * s
        if not math.isfinite(g) or not math.isfinite(t) or not math.isfinite(w):
            bad_t[thread] = a
            return
        lo = h if g > 0.0 else lo_p[a]
        hi = h if g < 0.0 else hi_p[a]
        lo_p[a], hi_p[a] = lo, hi
        if g == 0.0 or hi - lo <= tol * h:
            active_p[a] = False
            continue
        ok = t < 0.0 and s > 0.0
        step = 0.0
        if ok:
            big_g = math.log(sigma_over_m_p[a] * s) - log_target
            inv_s = 1.0 / s  # one division: they cost more than the logarithm here (2D, 1e5: 6 ms an update)
            g1 = -t * inv_s
            g2 = (t + w) * inv_s - g1 * g1
            den = 2.0 * g1 * g1 - big_g * g2
            step = -2.0 * big_g * g1 / den if den > 0.0 else -big_g / g1
            if abs(step) <= tol:
                active_p[a] = False
                continue
            if abs(step) <= step_max:
                d1 = -t
                d2 = t + w
                d3 = -(t + 3.0 * w + x)
                d4 = t + 7.0 * w + 6.0 * x + y
                grow = step * (d1 + step * (0.5 * d2 + step * (d3 * _SIXTH + step * d4 * _TWENTYFOURTH)))
                s_new = s + grow
                t_new = -(d1 + step * (d2 + step * (0.5 * d3 + step * d4 * _SIXTH)))
                if s_new > 0.0 and t_new < 0.0 and math.isfinite(s_new) and math.isfinite(t_new):
                    # ln(sigma s_new / m) - ln eta^d = G + ln(1 + grow / s): no second logarithm
                    residual = (big_g + _log1p_small(grow * inv_s)) * s_new / t_new
                    if abs(residual) <= tol:
                        h_p[a] = h * _exp_small(step)
                        s_p[a], t_p[a], n_p[a] = s_new, t_new, nn * (s_new * inv_s)
                        active_p[a] = False
                        continue
            ok = abs(step) < 0.6931471805599453  # at most a factor 2
        h_new = h * math.exp(step) if ok else 0.0
        if not ok or bisect_only or h_new <= lo or h_new >= hi:
            if hi == math.inf:
                h_new = 2.0 * h
            elif lo <= 0.0:
                h_new = 0.5 * h
            else:
                h_new = 0.5 * (lo + hi)
        h_p[a] = h_new


# -- forces ----------------------------------------------------------------------------------------
def pressure_forces(nlist, r_pc, masses, h, pr, kernel, want_virial=False, dims=None):
    """Symmetric grad-h pressure forces (Eq. 9/34) from per-particle ``pr = P / (Omega rho^2)``.

    Parameters
    ----------
    nlist : NeighborList
        Updated for ``r_pc`` with cut-offs >= ``h``.
    r_pc : ndarray (N, D)
    masses, h : float or ndarray (N,)
    pr : ndarray (N,)
        ``P_a / (Omega_a rho_a^2)`` (with a fixed h and no grad-h terms, ``Omega = 1``).
    kernel : Kernel
    want_virial : bool
    dims : int or None
        The pairs see the first ``dims`` coordinates of ``r_pc`` (default all ``D``): ``dims = d`` for ASE
        positions of a d < 3 system (zeros beyond d) gives the same forces without their zero columns, and a
        cheaper pass (2D, 1e5 particles: 2 instead of 3 force components written per pair).

    Returns
    -------
    f_pc : ndarray (N, D), or (N, dims)
        ``m_a dv_a/dt`` (forces, not accelerations).
    virial_cc : ndarray (3, 3)
        ``sum_pairs r_ab (x) F_ab`` as ``dE/d(strain)`` for ``E = sum m u(rho)`` (zeros unless asked).
    """
    r_pc = np.asarray(r_pc, dtype=float)
    n = r_pc.shape[0]
    m_p = _per_particle("masses", masses, n)
    h_p = _per_particle("h", h, n)
    pr_p = _per_particle("pr", pr, n, positive=False)
    c_p = pr_p * kernel.sigma / h_p ** (kernel.dim + 1)
    name = "pressure_virial" if want_virial else "pressure"
    if np.all(m_p == m_p[0]):  # equal masses: m^2 as a parameter, one array fewer per pair
        hc_p = np.empty((n, 2))
        hc_p[:, 0] = 1.0 / h_p
        hc_p[:, 1] = c_p
        params, inputs, name = dict(m2=float(m_p[0]) ** 2), dict(hc_s=hc_p), name + "_equal"
    else:
        params, inputs = {}, dict(ih_s=1.0 / h_p, m_s=m_p, c_s=c_p)
    dims = _check_dims(dims, r_pc)
    out = _interaction(name, dims).compute(nlist, r_pc, params=params, inputs=inputs, kernel=kernel,
                                           reach=float(h_p.max()))
    virial = np.zeros((3, 3))
    if want_virial:
        v = out.virial
        virial = np.array([[v[0], v[5], v[4]], [v[5], v[1], v[3]], [v[4], v[3], v[2]]])
    return out.forces, virial


def viscosity_forces(nlist, r_pc, v_pc, masses, h, rho, alpha, v_sig, kernel, beta=0.0, approaching_only=False,
                     dims=None):
    """Artificial viscosity forces (Eq. 15/35) and the velocity divergence (Eq. 21) in one pass.

    Parameters
    ----------
    nlist : NeighborList
        Updated for ``r_pc`` with cut-offs >= ``h``.
    r_pc, v_pc : ndarray (N, D)
        Positions and velocities.
    masses, h, rho, alpha : float or ndarray (N,)
        Masses, support radii, densities and viscosity switches (``alpha_ab`` is the pair mean).
    v_sig : float
        Signal speed (ALARIC: the fastest speed in the system, at least ``c_s``).
    kernel : Kernel
    beta : float
        Quadratic (von Neumann-Richtmyer) coefficient; 0 in Eq. 35.
    approaching_only : bool
        Apply the viscosity only to approaching pairs (``v_ab . r_ab < 0``, Monaghan 1997); False in Eq. 35.
    dims : int or None
        The pairs see the first ``dims`` coordinates of ``r_pc`` and ``v_pc`` (default all ``D``; ``v_pc`` may then
        have ``dims`` columns): as in :func:`pressure_forces`, ``dims = d`` for a d < 3 system gives the same
        forces without their zero columns, and gathers ``dims`` velocity components per point, not ``D``.

    Returns
    -------
    f_pc : ndarray (N, D), or (N, dims)
        ``m_a (dv_a/dt)_visc``; pairwise antisymmetric (momentum conserving).
    div_p : ndarray (N,)
        ``(div v)_a`` of Eq. 21.
    """
    r_pc = np.asarray(r_pc, dtype=float)
    n = r_pc.shape[0]
    m_p = _per_particle("masses", masses, n)
    h_p = _per_particle("h", h, n)
    rho_p = _per_particle("rho", rho, n)
    alpha_p = _per_particle("alpha", alpha, n, positive=False)
    dims = _check_dims(dims, r_pc)
    v_pc = np.ascontiguousarray(v_pc, dtype=float)
    if v_pc.shape != r_pc.shape and v_pc.shape != (n, dims):
        raise ValueError(f"velocities must have the shape of the positions {r_pc.shape} (or {(n, dims)} with dims="
                         f"{dims}), got {v_pc.shape}")
    params = dict(v_sig=float(v_sig), beta=float(beta), approaching_only=bool(approaching_only))
    # 1/H and the gradient factor live in the inputs dict only: compute frees them once gathered (consume_inputs)
    inputs = dict(ih_s=1.0 / h_p, g_s=kernel.sigma / h_p ** (kernel.dim + 1), m_s=m_p, rho_s=rho_p, alpha_s=alpha_p,
                  v_sc=v_pc)
    name = "viscosity"
    if np.all(m_p == m_p[0]):  # equal masses: m a parameter (the same forces bit for bit)
        params["m"], name = float(m_p[0]), "viscosity_equal"
        del inputs["m_s"]
    reach = float(h_p.max())
    # the arrays live in the inputs dict only: those made for this call (by the caller in its arguments, or here)
    # are freed once gathered, not held through the pair loop
    m_p = h_p = rho_p = alpha_p = v_pc = rho = alpha = h = masses = None
    out = _interaction(name, dims).compute(nlist, r_pc, params=params, inputs=inputs, reach=reach, kernel=kernel,
                                           consume_inputs=True)
    return out.forces, out.div_v


def _gradient_inputs(r_pc, v_pc, masses, h, rho, kernel):
    """``h_p`` and the inputs ``ih_s, g_s, m_s, rho_s, v_sc`` of the gathers of a kernel gradient with H_a."""
    n = r_pc.shape[0]
    h_p = _per_particle("h", h, n)
    return h_p, dict(ih_s=1.0 / h_p, g_s=kernel.sigma / h_p ** (kernel.dim + 1), m_s=_per_particle("masses", masses, n),
                     rho_s=_per_particle("rho", rho, n), v_sc=np.ascontiguousarray(v_pc, dtype=float))


def velocity_divergence(nlist, r_pc, v_pc, masses, h, rho, kernel):
    """The velocity divergence (Eq. 21), shape (N,): ``(div v)_a = sum_b m_b / rho_b v_ab . r_ab F_ab(H_a)``."""
    r_pc = np.asarray(r_pc, dtype=float)
    h_p, inputs = _gradient_inputs(r_pc, v_pc, masses, h, rho, kernel)
    out = _interaction("divergence", r_pc.shape[1]).compute(nlist, r_pc, inputs=inputs, reach=float(h_p.max()),
                                                            kernel=kernel)
    return out.div_v


def continuity_rate(nlist, r_pc, v_pc, masses, h, rho, kernel, diffusion=0.0, c0=0.0):
    """``drho_a/dt`` of the continuity equation with density diffusion, shape (N,).

    ``sum_b m_b v_ab . grad_a W_ab(H_a) + a_d H_a c0 sum_b (m_b/rho_b) psi_ab . grad_a W_ab(H_a)``,
    ``psi_ab = 2 (rho_b - rho_a) (x_b - x_a) / (r^2 + 0.1 H_a^2)`` (Molteni & Colagrossi 2009;
    SPH-ParVI Eq. 29 with ``a_d = diffusion``, written with the sign that smooths density differences).
    """
    r_pc = np.asarray(r_pc, dtype=float)
    h_p, inputs = _gradient_inputs(r_pc, v_pc, masses, h, rho, kernel)
    params = dict(diffusion=float(diffusion), c0=float(c0))
    out = _interaction("continuity", r_pc.shape[1]).compute(nlist, r_pc, params=params, inputs=inputs,
                                                            reach=float(h_p.max()), kernel=kernel)
    return out.rate


def update_alpha(alpha, div_v, c_s, h, dt, alpha_min=0.0, alpha_max=1.0, decay=0.1):
    """One implicit step of the viscosity switch (Eq. 19-20, Morris & Monaghan 1997).

    ``dalpha/dt = S - (alpha - alpha_min)/tau``, ``S = max(-div v, 0)``, ``1/tau = decay c_s / H``:
    ``alpha <- (alpha + dt (S + alpha_min / tau)) / (1 + dt / tau)``, capped at ``alpha_max``.
    """
    alpha = np.asarray(alpha, dtype=float)
    source = np.maximum(-np.asarray(div_v, dtype=float), 0.0)
    inv_tau = decay * c_s / np.asarray(h, dtype=float)
    new = (alpha + dt * (source + alpha_min * inv_tau)) / (1.0 + dt * inv_tau)
    return np.minimum(new, alpha_max)


def isothermal_pressure(rho, cs2):
    """``P = c_s^2 rho``."""
    return cs2 * np.asarray(rho, dtype=float)


def tait_pressure(rho, rho0, c0, gamma=7.0):
    """Tait: ``P = rho0 c0^2 / gamma ((rho / rho0)^gamma - 1)``."""
    return rho0 * c0 * c0 / gamma * ((np.asarray(rho, dtype=float) / rho0) ** gamma - 1.0)
