"""BISPH: 2D weakly compressible SPH with boundary-integral walls (BIPI Sec. 4.2, Eqs. 16-21).

The downstream solver of Boregowda & Liu (Comput. Phys. Commun. 310 (2025) 109531) that judges a
particle start: no wall particles, the walls enter through the kernel volume fraction ``gamma_a``
and the per-segment terms ``grad gamma_as = n_s int_s W dS`` (``n_s`` into the fluid) of the same
:class:`~ase_sphrelax.boundary.BoundaryIntegrals` that BIPI packs against (Ferrand et al. 2013,
Int. J. Numer. Meth. Fluids 71:446, the unified semi-analytical walls). With ``V_b = m_b / rho_b``
and ``grad_a W = grad_{x_a} W(|x_a - x_b|)``::

    D rho_a/Dt = -(rho_a/gamma_a) [sum_b V_b (v_b - v_a).grad_a W - sum_s (v_s - v_a).grad gamma_as]
                 + D_a                                                                        (16)
    D v_a/Dt   = -(1/(rho_a gamma_a)) [sum_b V_b (p_a + p_b) grad_a W - sum_s (p_a + p_s) grad gamma_as]
                 + (mu/rho_a) lap v_a + F                                                      (17)
    p = rho0 c0^2/7 ((rho/rho0)^7 - 1) + P_B                                                   (18)
    p_s = p(rho~_a) + rho_a c0 (v_s - v_a).n_s                                                (20)
    rho~_a = rho_a if |x_a - x_s| >= dx/2, else (2 rho_a/dx)(dx - |x_a - x_s|)                 (21)

with static walls (``v_s = 0``). ``|x_a - x_s|`` is read pointwise along the wall (``eq21="pointwise"``):
the wall pressure term is ``int_s (p_a + p_s(y)) W dS`` with ``rho~`` at each wall point's distance, so
only the part of a wall within ``dx/2`` of the particle is compressed. The paper writes ``p_s`` per
segment; BIPI2D cuts the walls into segments of ``dx/10``, and as they shrink the per-segment sum tends to
this integral (``tests/test_bisph.py``). Taken at each segment's nearest point over a whole straight
side instead (``eq21="segment"``), Eq. 21 compresses the whole side: 6.7 times the pointwise force on a
particle 0.3 dx from a wall, and 1.24 times with BIPI2D's ``dx/10`` segments (both measured with one
particle, not stored).

Choices the paper leaves open (stated, each a parameter where it matters):

* **Viscosity, "boundary-layer" form** (Mayrhofer et al. 2013; Leroy et al. 2014): from
  ``gamma lap v = int_Omega grad v . grad_x W dy - sum_s (dv/dn)_s int_s W dS``, the fluid part by
  Morris' sum and the wall shear from a linear profile across the wall's boundary layer,
  ``(dv/dn)_s = (v_a - v_s) / delta_as``::

      lap v_a = (1/gamma_a) [sum_b 2 V_b v_ab (x_ab . grad_a W)/(r^2 + eta^2)
                             - sum_s 2 (v_a - v_s) |grad gamma_as| / max(delta_as, dx/4)]

  The factor 2 of the wall term matches Morris' 2: over a support cut by a wall, Morris' sum of a
  linear shear ``v = G n`` is ``2 G |grad gamma|`` to first order (twice the continuous
  ``int_Omega grad v . grad_x W dy = G |grad gamma|``), so a wall term of factor 1 leaves a
  spurious Laplacian ``G |grad gamma|`` next to the wall (measured: the Poiseuille profile slipped
  by 15 % of u_max at 20 particles across; 0.85 % with the factor 2). ``eta^2 = 0.01 h_B^2``;
  ``delta_as`` is the particle's distance to segment ``s`` (the floor only guards a particle that
  Eq. 21 failed to keep off the wall).
* **Viscosity, particle-consistent-gradient (PCG) form** (``viscosity="pcg"``, the paper's Fig. 14b and
  its cylinder array): the paper cites its refs. [3-5] (Liu & Liu 2006; Boregowda & Liu 2023, two papers)
  without writing the formula out, and those papers are not in our collection, so this is our reading,
  stated in :meth:`BISPH.laplacian`: ``lap v`` as the divergence of the gradient, each by Eq. 2 in
  difference form with Liu & Liu's first-order correction matrix (boundary integrals included, the wall
  values at the kernel-weighted centre of each segment, :meth:`BISPH._feet`), the divergence taking the
  gradient at the midpoint of each pair (and the boundary-layer wall shear at the walls): exact for
  linear velocity fields next to walls, for quadratic ones in the interior. Plane Poiseuille at 20
  particles across: 0.01 % of u_max at steady state (the plain nested form: 2.6 %, with an odd-even
  null mode; ``tests/test_bisph.py``).
* **Density diffusion**: Molteni & Colagrossi (2009), ``D_a = (delta h_B c0 / gamma_a) sum_b V_b
  psi_ab . grad_a W``, ``psi_ab = 2 (rho_b - rho_a - rho_ba^H) (x_b - x_a)/(r^2 + eta^2)``,
  ``delta = 0.1``. With ``hydrostatic=True`` (tanks under gravity) the hydrostatic density difference
  ``rho_ba^H = rho0 F . (x_b - x_a) / c0^2`` is removed first (Fourtakas et al. 2019, Comput. Fluids
  190:209): plain Molteni-Colagrossi diffuses the hydrostatic density gradient itself wherever its
  sum is truncated (walls, free surface), which has no wall flux to balance it (not measured here).
* **Kernel**: Wendland C2 with the paper's ``h_B = 2 dx`` (BIPI2D's ``hsml`` 0.02 at dx 0.01); in this
  package's convention (``h`` is the support, ``h = 2 h_B``) that is ``h = 4 dx``.
* **Time step** (the paper's Eq. 19 did not survive in our copy of the text; the usual WCSPH rule of
  Morris et al. 1997 / Ferrand et al. 2013 is used)::

      dt = min(0.25 h_B / (c0 + |v|_max), 0.125 h_B^2 rho0 / mu, 0.25 sqrt(h_B / |F|))     (19)

* **Time integration: symplectic Euler**, ``v^{n+1} = v^n + dt a(x^n, rho^n, v^n)``, then
  ``rho^{n+1} = rho^n + dt Drho(x^n, rho^n, v^{n+1})`` and ``x^{n+1} = x^n + dt v^{n+1}``. The paper
  says "first order Euler". Forward Euler is unconditionally unstable for the undamped acoustic
  oscillator (amplification ``sqrt(1 + (omega dt)^2) > 1``), and the acoustic pair is (v, rho), not
  only (v, x): with ``rho^{n+1}`` from ``v^n`` (one pair pass per step) the free surface of a
  20 x 40 column at rest oscillated with growing amplitude and blew up within 0.15 s (measured).
  So each step makes two pair passes (Eq. 17, then Eq. 16 with the new velocities).

Periodic axes come with the boundary (``BoundarySegments.with_cell``); positions are wrapped into
the cell ``[0, L)`` each step. Cost per step is O(N): two pair passes (two more with
``viscosity="pcg"``) (:class:`~ase_sphrelax.pairs.
PairInteraction` over a stored Verlet list), the boundary terms of the particles within ``h`` of a
wall, and a per-(particle, segment) loop.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from ..boundary import BoundaryIntegrals, as_boundary
from ..checks import check_positive
from ..kernels import get_kernel, kernel_slope_over_q, profile_value_and_slope
from ..neighbors import NeighborList
from ..pairs import Output, PairInteraction

__all__ = ["BISPH", "RunHistory", "tait_pressure", "tait_density"]

ETA2_FRACTION = 0.01  # eta^2 = 0.01 h_B^2 (Morris' and Molteni-Colagrossi's regulariser)
WALL_BAND = 0.5  # Eq. 21: the compressed density within 0.5 dx of a segment
EQ21_READINGS = ("pointwise", "segment")
SHEAR_FLOOR = 0.25  # the viscous wall term's distance floor, in dx
GAMMA_FLOOR = 1e-3
VISCOSITY_FORMS = ("boundary_layer", "pcg")


def tait_pressure(rho, rho0, c0, p_b=0.0):
    """Eq. 18: ``p = rho0 c0^2/7 ((rho/rho0)^7 - 1) + P_B``."""
    return rho0 * c0 * c0 / 7.0 * ((np.asarray(rho) / rho0) ** 7 - 1.0) + p_b


def tait_density(p, rho0, c0, p_b=0.0):
    """The inverse of Eq. 18: the density of pressure ``p``."""
    return rho0 * (1.0 + 7.0 * (np.asarray(p) - p_b) / (rho0 * c0 * c0)) ** (1.0 / 7.0)


@numba.njit(cache=True, inline="always")
def _continuity_pair(a, b, r2, d, inv_h, grad_scale, eta2, hx, hy, vol_s, rho_s, v_sc):
    """Pair sums of Eq. 16 for both partners: ``sum_b V_b (v_b - v_a).grad_a W`` and the
    Molteni-Colagrossi sum ``sum_b V_b psi_ab . grad_a W`` (without ``delta h_B c0``)."""
    if r2 == 0.0:
        return (0.0, 0.0), (0.0, 0.0), ()
    r = math.sqrt(r2)
    gw = grad_scale * inv_h * kernel_slope_over_q(r * inv_h)[1]  # grad_a W = gw (x_a - x_b) = -gw d; gw <= 0
    dv_g = -gw * ((v_sc[b, 0] - v_sc[a, 0]) * d[0] + (v_sc[b, 1] - v_sc[a, 1]) * d[1])  # the same for b
    k = 2.0 * gw * r2 / (r2 + eta2)  # 2 (x_ab . grad_a W)/(r^2 + eta^2) <= 0, the same for b
    drho = rho_s[b] - rho_s[a] - (hx * d[0] + hy * d[1])  # rho_ba minus its hydrostatic part
    return (vol_s[b] * dv_g, -vol_s[b] * k * drho), (vol_s[a] * dv_g, vol_s[a] * k * drho), ()


@numba.njit(cache=True, inline="always")
def _momentum_diffusion_pair(a, b, r2, d, inv_h, grad_scale, eta2, hx, hy, q_sc):
    """Pair sums of Eq. 17 for both partners, ``sum_b V_b (p_a + p_b) grad_a W`` and Morris'
    ``sum_b 2 V_b v_ab (x_ab . grad_a W)/(r^2 + eta^2)``, with the Molteni-Colagrossi sum of
    :func:`_continuity_pair` in the same pass (both at ``x^n``, ``rho^n``: one kernel evaluation). The
    inputs packed per point, ``q_sc = [V, p, rho, v_x, v_y]`` (one cache line per partner), the
    outputs ``[grad_p (2), lap (2), diff]``."""
    if r2 == 0.0:
        return (0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0), ()
    r = math.sqrt(r2)
    gw = grad_scale * inv_h * kernel_slope_over_q(r * inv_h)[1]
    gax = -gw * d[0]
    gay = -gw * d[1]
    pp = q_sc[a, 1] + q_sc[b, 1]
    k = 2.0 * gw * r2 / (r2 + eta2)
    kvx = k * (q_sc[b, 3] - q_sc[a, 3])
    kvy = k * (q_sc[b, 4] - q_sc[a, 4])
    kr = k * (q_sc[b, 2] - q_sc[a, 2] - (hx * d[0] + hy * d[1]))
    va = q_sc[a, 0]
    vb = q_sc[b, 0]
    return ((pp * vb * gax, pp * vb * gay, -vb * kvx, -vb * kvy, -vb * kr),
            (-pp * va * gax, -pp * va * gay, va * kvx, va * kvy, va * kr), ())


@numba.njit(cache=True, inline="always")
def _divergence_pair(a, b, r2, d, inv_h, grad_scale, q_sc):
    """The velocity sum of Eq. 16 alone, ``sum_b V_b (v_b - v_a).grad_a W``, for both partners
    (``q_sc = [V, v_x, v_y]``)."""
    if r2 == 0.0:
        return (0.0,), (0.0,), ()
    r = math.sqrt(r2)
    gw = grad_scale * inv_h * kernel_slope_over_q(r * inv_h)[1]
    dv_g = -gw * ((q_sc[b, 1] - q_sc[a, 1]) * d[0] + (q_sc[b, 2] - q_sc[a, 2]) * d[1])
    return (q_sc[b, 0] * dv_g,), (q_sc[a, 0] * dv_g,), ()


@numba.njit(cache=True, inline="always")
def _consistent_pair(a, b, r2, d, inv_h, grad_scale, vol_s, f_sc):
    """The particle parts of the particle-consistent gradient (Liu & Liu 2006) of the columns of
    ``f_sc`` (K columns, K <= 4): ``L_a = sum_b V_b grad_a W (x) (x_b - x_a)`` (row-major, 4 terms) and
    ``N_a^k = sum_b V_b (f_b^k - f_a^k) grad_a W`` (2 terms per column; unused columns zero)."""
    if r2 == 0.0:
        z = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        return z, z, ()
    r = math.sqrt(r2)
    gw = grad_scale * inv_h * kernel_slope_over_q(r * inv_h)[1]
    gx = -gw * d[0]
    gy = -gw * d[1]
    f0 = f_sc[b, 0] - f_sc[a, 0]
    f1 = f_sc[b, 1] - f_sc[a, 1]
    f2 = f_sc[b, 2] - f_sc[a, 2]
    f3 = f_sc[b, 3] - f_sc[a, 3]
    # b's terms: grad_b W = -grad_a W and x_a - x_b = -d, f_a - f_b = -f: the same products
    vb = vol_s[b]
    va = vol_s[a]
    t = (gx * d[0], gx * d[1], gy * d[0], gy * d[1], f0 * gx, f0 * gy, f1 * gx, f1 * gy, f2 * gx, f2 * gy,
         f3 * gx, f3 * gy)
    return ((vb * t[0], vb * t[1], vb * t[2], vb * t[3], vb * t[4], vb * t[5], vb * t[6], vb * t[7], vb * t[8],
             vb * t[9], vb * t[10], vb * t[11]),
            (va * t[0], va * t[1], va * t[2], va * t[3], va * t[4], va * t[5], va * t[6], va * t[7], va * t[8],
             va * t[9], va * t[10], va * t[11]), ())


@numba.njit(cache=True, inline="always")
def _midpoint_divergence_pair(a, b, r2, d, inv_h, grad_scale, q_sc):
    """The particle part of :meth:`BISPH.laplacian`'s step 2 for both partners: ``sum_b V_b (G_ab - G_a)
    (x) grad_a W`` (8 terms, ``[2c + i, k]`` row-major) with the pair's midpoint gradient
    ``G_ab = Gbar + ((v_b - v_a)/r - Gbar e) (x) e``, ``Gbar = (G_a + G_b)/2``, ``e = (x_b - x_a)/r``
    (``q_sc = [V, v_x, v_y, G_xx, G_xy, G_yx, G_yy]``, ``G_ci = d_i v_c``). ``G_ba = G_ab``."""
    if r2 == 0.0:
        z = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        return z, z, ()
    r = math.sqrt(r2)
    gw = grad_scale * inv_h * kernel_slope_over_q(r * inv_h)[1]
    gx = -gw * d[0]  # grad_a W; grad_b W = -grad_a W
    gy = -gw * d[1]
    ex = d[0] / r
    ey = d[1] / r
    m00 = 0.5 * (q_sc[a, 3] + q_sc[b, 3])
    m01 = 0.5 * (q_sc[a, 4] + q_sc[b, 4])
    m10 = 0.5 * (q_sc[a, 5] + q_sc[b, 5])
    m11 = 0.5 * (q_sc[a, 6] + q_sc[b, 6])
    j0 = (q_sc[b, 1] - q_sc[a, 1]) / r - (m00 * ex + m01 * ey)
    j1 = (q_sc[b, 2] - q_sc[a, 2]) / r - (m10 * ex + m11 * ey)
    m00 += j0 * ex
    m01 += j0 * ey
    m10 += j1 * ex
    m11 += j1 * ey
    va = q_sc[a, 0]
    vb = q_sc[b, 0]
    a0 = vb * (m00 - q_sc[a, 3])
    a1 = vb * (m01 - q_sc[a, 4])
    a2 = vb * (m10 - q_sc[a, 5])
    a3 = vb * (m11 - q_sc[a, 6])
    b0 = -va * (m00 - q_sc[b, 3])
    b1 = -va * (m01 - q_sc[b, 4])
    b2 = -va * (m10 - q_sc[b, 5])
    b3 = -va * (m11 - q_sc[b, 6])
    return ((a0 * gx, a0 * gy, a1 * gx, a1 * gy, a2 * gx, a2 * gy, a3 * gx, a3 * gy),
            (b0 * gx, b0 * gy, b1 * gx, b1 * gy, b2 * gx, b2 * gy, b3 * gx, b3 * gy), ())


_KERNEL_PARAMS = ("inv_h", "grad_scale", "eta2")
CONTINUITY = PairInteraction(_continuity_pair, dict(div=Output(()), diff=Output(())),
                             params=_KERNEL_PARAMS + ("hx", "hy"), inputs=("vol_s", "rho_s", "v_sc"))
MOMENTUM_DIFFUSION = PairInteraction(_momentum_diffusion_pair, dict(terms=Output((5,))),
                                     params=_KERNEL_PARAMS + ("hx", "hy"), inputs=("q_sc",))
DIVERGENCE = PairInteraction(_divergence_pair, dict(div=Output(())), params=("inv_h", "grad_scale"),
                             inputs=("q_sc",))
CONSISTENT = PairInteraction(_consistent_pair, dict(lmat=Output((4,)), nsum=Output((8,))),
                             params=("inv_h", "grad_scale"), inputs=("vol_s", "f_sc"))
MIDPOINT_DIVERGENCE = PairInteraction(_midpoint_divergence_pair, dict(nsum=Output((8,))),
                                      params=("inv_h", "grad_scale"), inputs=("q_sc",))


GAUSS_NODES, GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(8)  # Eq. 21's chord integral


@numba.njit(cache=True)
def _band_excess(x, y, e, seg, band, dx, ra, rho0, b7, w_scale, inv_h, breaks, coef, nodes, weights):
    """``int_{s, |y - x_a| < band} [p(rho~(|y - x_a|)) - p(rho_a)] W dS`` (Eqs. 18, 21, pointwise): the
    chord of segment ``e`` within ``band`` of the particle at ``(x, y)``, split at the foot of the
    perpendicular, each half by Gauss-Legendre in ``sigma`` with ``t = d sinh(sigma)`` (``dS = r dsigma``:
    smooth however near the wall the particle is; in ``t`` on the wall line itself, ``d = 0``)."""
    ax = seg[e, 0]
    ay = seg[e, 1]
    length = seg[e, 6]
    tx = (seg[e, 2] - ax) / length
    ty = (seg[e, 3] - ay) / length
    along = (x - ax) * tx + (y - ay) * ty
    d = abs((x - ax) * ty - (y - ay) * tx)
    if d >= band:
        return 0.0
    c = math.sqrt(band * band - d * d)
    lo = max(-c, -along)  # t = u - along over the chord, u in [0, length]
    hi = min(c, length - along)
    if hi <= lo:
        return 0.0
    pa = (ra / rho0) ** 7
    flat = d < 1e-9 * band
    total = 0.0
    for half in range(2):
        t0 = max(lo, 0.0) if half == 1 else lo
        t1 = hi if half == 1 else min(hi, 0.0)
        if t1 <= t0:
            continue
        s0 = t0 if flat else math.asinh(t0 / d)
        s1 = t1 if flat else math.asinh(t1 / d)
        mid = 0.5 * (s0 + s1)
        width = 0.5 * (s1 - s0)
        for i in range(len(nodes)):
            sg = mid + width * nodes[i]
            r = abs(sg) if flat else d * math.cosh(sg)
            if r >= band:
                continue
            q = 2.0 * ra / dx * (dx - r) / rho0
            w = profile_value_and_slope(r * inv_h, breaks, coef)[0]
            total += weights[i] * width * b7 * (q ** 7 - pa) * w * (1.0 if flat else r)
    return total * w_scale


@numba.njit(cache=True)
def _wall_terms(start_p, element_k, point_k, x_sc, distance_k, grad_k, seg, rho_p, p_p, v_pc, vs_kc, rho0, c0,
                p_b, dx, band, pointwise, w_scale, inv_h, breaks, coef, nodes, weights, floor, div_p, gp_pc, lap_pc,
                pw_p):
    """Per (particle, segment) pair: ``-sum_s (v_s - v_a).grad gamma_as`` (Eq. 16),
    ``-sum_s (p_a + p_s) grad gamma_as`` with Eqs. 20-21 (Eq. 17) and the viscous wall shear;
    ``pw_p``: the largest wall pressure of each particle (0 without walls).

    Eq. 21 ``pointwise``: ``int_s p_s W dS`` with ``rho~`` at each point's distance (the limit of the
    paper's segments as they shrink); otherwise ``rho~`` at the segment's nearest point over all of it."""
    b7 = rho0 * c0 * c0 / 7.0
    for a in range(len(start_p) - 1):
        div = 0.0
        gx = 0.0
        gy = 0.0
        lx = 0.0
        ly = 0.0
        pmax = 0.0
        ra = rho_p[a]
        for k in range(start_p[a], start_p[a + 1]):
            e = element_k[k]
            nx = seg[e, 4]
            ny = seg[e, 5]
            g = grad_k[k]
            dist = distance_k[k]
            rt = ra if dist >= band else 2.0 * ra / dx * (dx - dist)  # Eq. 21 at the nearest point
            q = rt / rho0
            q2 = q * q
            wx = vs_kc[k, 0] - v_pc[a, 0]
            wy = vs_kc[k, 1] - v_pc[a, 1]
            impact = ra * c0 * (wx * nx + wy * ny)  # Eq. 20's second term
            ps = b7 * (q2 * q2 * q2 * q - 1.0) + p_b + impact  # Eq. 18 at rho~, Eq. 20
            if ps > pmax:
                pmax = ps
            div -= (wx * nx + wy * ny) * g
            if pointwise:
                f = (p_p[a] + b7 * ((ra / rho0) ** 7 - 1.0) + p_b + impact) * g
                if dist < band:
                    img = point_k[k]
                    f += _band_excess(x_sc[img, 0], x_sc[img, 1], e, seg, band, dx, ra, rho0, b7, w_scale, inv_h,
                                      breaks, coef, nodes, weights)
            else:
                f = (p_p[a] + ps) * g
            gx -= f * nx
            gy -= f * ny
            s = 2.0 * g / max(dist, floor)
            lx += wx * s  # -2 (v_a - v_s) |grad gamma_as| / delta_as
            ly += wy * s
        div_p[a] = div
        gp_pc[a, 0] = gx
        gp_pc[a, 1] = gy
        lap_pc[a, 0] = lx
        lap_pc[a, 1] = ly
        pw_p[a] = pmax


def first_moment_table(kernel):
    """Piecewise ascending coefficients of ``A(q) = sigma int_0^q f(s) s ds`` (2D): with ``r = q h``,
    ``A`` is the antiderivative of ``W(r) r``, so along a straight segment at distance ``delta`` from the
    particle (``t`` from the foot of the perpendicular, ``r^2 = delta^2 + t^2``)::

        int W t dt = A(r(t1)) - A(r(t0))      (d/dt A(r) = W(r) r dr/dt = W t)

    exactly, the kernel's tangential first moment over the segment, which :func:`_wall_feet` divides by
    ``int W dt = |grad gamma_as|``. Returns ``(lo, table, offset)``: ``A(q) = polyval(table[s], q) +
    offset[s]`` on piece ``s`` (``lo[s] <= q``), ``A(q >= 1) = A(1)``."""
    from numpy.polynomial import polynomial as P

    lo, rows, offset = [], [], []
    total = 0.0
    for s, piece in enumerate(kernel._pieces):
        a, b = float(kernel.breaks[s]), min(float(kernel.breaks[s + 1]), 1.0)
        if a >= 1.0:
            break
        integral = P.polyint(P.polymul(piece, [0.0, 1.0])) * kernel.sigma
        lo.append(a)
        rows.append(integral)
        offset.append(total - P.polyval(a, integral))
        total = P.polyval(b, integral) + offset[-1]
    table = np.zeros((len(rows), max(len(r) for r in rows)))
    for s, row in enumerate(rows):
        table[s, : len(row)] = row
    return np.array(lo), table, np.array(offset)


@numba.njit(cache=True, inline="always")
def _first_moment(q, lo, table, offset):
    q = min(q, 1.0)
    s = len(lo) - 1
    while s > 0 and q < lo[s]:
        s -= 1
    value = 0.0
    for c in range(table.shape[1] - 1, -1, -1):
        value = value * q + table[s, c]
    return value + offset[s]


@numba.njit(cache=True)
def _wall_feet(element_k, point_k, x_sc, grad_k, seg, inv_h, lo, table, offset, feet_kc):
    """The kernel-weighted centre ``y_as = int_s y W dS / int_s W dS`` of every (particle image, segment)
    pair, in closed form (:func:`first_moment_table`): ``int_s f W dS = f(y_as) |grad gamma_as|`` for
    every linear ``f``. Pairs with ``grad gamma_as = 0`` get the segment's point nearest the particle."""
    for k in range(len(element_k)):
        e = element_k[k]
        s = point_k[k]
        x = x_sc[s, 0]
        y = x_sc[s, 1]
        ax = seg[e, 0]
        ay = seg[e, 1]
        bx = seg[e, 2]
        by = seg[e, 3]
        length = seg[e, 6]
        tx = (bx - ax) / length
        ty = (by - ay) / length
        along = (x - ax) * tx + (y - ay) * ty
        g = grad_k[k]
        if g > 0.0:
            ra = math.sqrt((x - ax) ** 2 + (y - ay) ** 2)
            rb = math.sqrt((x - bx) ** 2 + (y - by) ** 2)
            t = along + (_first_moment(rb * inv_h, lo, table, offset)
                         - _first_moment(ra * inv_h, lo, table, offset)) / g
        else:
            t = min(max(along, 0.0), length)
        feet_kc[k, 0] = ax + t * tx
        feet_kc[k, 1] = ay + t * ty


@numba.njit(cache=True)
def _wall_consistent(start_p, element_k, point_k, x_sc, grad_k, seg, feet_kc, f_kc, f_pc, lmat_p, nsum_p):
    """Subtract the wall parts of the particle-consistent gradient (Eq. 2's boundary integral, exact for
    a linear field through the feet ``feet_kc``): ``L_a -= sum_s grad gamma_as (x) (y_as - x_a)`` and
    ``N_a^c -= sum_s (f_s^c - f_a^c) grad gamma_as`` (``f_kc``: the wall values at the feet)."""
    ncol = f_kc.shape[1]
    for a in range(len(start_p) - 1):
        for k in range(start_p[a], start_p[a + 1]):
            e = element_k[k]
            s = point_k[k]
            gx = grad_k[k] * seg[e, 4]
            gy = grad_k[k] * seg[e, 5]
            ox = feet_kc[k, 0] - x_sc[s, 0]
            oy = feet_kc[k, 1] - x_sc[s, 1]
            lmat_p[a, 0] -= gx * ox
            lmat_p[a, 1] -= gx * oy
            lmat_p[a, 2] -= gy * ox
            lmat_p[a, 3] -= gy * oy
            for c in range(ncol):
                df = f_kc[k, c] - f_pc[a, c]
                nsum_p[a, 2 * c] -= df * gx
                nsum_p[a, 2 * c + 1] -= df * gy


@numba.njit(cache=True)
def _wall_midpoint(start_p, element_k, point_k, x_sc, distance_k, grad_k, seg, feet_kc, vs_kc, v_pc, g_pc, floor,
                   nsum_p):
    """The wall part of :meth:`BISPH.laplacian`'s step 2: ``nsum_a -= sum_s (G_as - G_a) (x) grad gamma_as``
    with the wall's midpoint gradient ``G_as = G_a + j_as (x) n_s``, ``j_as = (v_a - v_s + G_a (y_as -
    x_a)) / delta_as`` (the boundary-layer wall shear ``(v_a - v_s)/delta_as`` in place of ``G_a``'s
    normal derivative; ``j_as = 0`` for a linear field)."""
    for a in range(len(start_p) - 1):
        for k in range(start_p[a], start_p[a + 1]):
            e = element_k[k]
            s = point_k[k]
            nx = seg[e, 4]
            ny = seg[e, 5]
            ox = feet_kc[k, 0] - x_sc[s, 0]
            oy = feet_kc[k, 1] - x_sc[s, 1]
            inv = 1.0 / max(distance_k[k], floor)
            j0 = (v_pc[a, 0] - vs_kc[k, 0] + g_pc[a, 0] * ox + g_pc[a, 1] * oy) * inv
            j1 = (v_pc[a, 1] - vs_kc[k, 1] + g_pc[a, 2] * ox + g_pc[a, 3] * oy) * inv
            gx = grad_k[k] * nx
            gy = grad_k[k] * ny
            t = (j0 * nx, j0 * ny, j1 * nx, j1 * ny)
            for c in range(4):
                nsum_p[a, 2 * c] -= t[c] * gx
                nsum_p[a, 2 * c + 1] -= t[c] * gy


def _solve2(lmat_p, nsum_p, ncol, fallback_p):
    """``L_a^{-1} N_a^c`` for each column ``c``, (N, ncol, 2); where ``L_a`` is near singular
    (``|det| < 1e-6 (tr/2)^2``, e.g. a lone particle) the gamma normalisation ``N_a / fallback_a``."""
    a, b, c, d = lmat_p[:, 0], lmat_p[:, 1], lmat_p[:, 2], lmat_p[:, 3]
    det = a * d - b * c
    ok = np.abs(det) > 1e-6 * (0.5 * (a + d)) ** 2
    det = np.where(ok, det, 1.0)
    out = np.empty((len(lmat_p), ncol, 2))
    for col in range(ncol):
        nx, ny = nsum_p[:, 2 * col], nsum_p[:, 2 * col + 1]
        out[:, col, 0] = np.where(ok, (d * nx - b * ny) / det, nx / fallback_p)
        out[:, col, 1] = np.where(ok, (a * ny - c * nx) / det, ny / fallback_p)
    return out


class RunHistory(dict):
    """What :meth:`BISPH.run` records, by name (also as attributes).

    ``t`` (s), ``ke`` (``sum m |v|^2 / 2``, J/m: per unit depth), ``v_max`` (m/s), ``p_mean``,
    ``p_min``, ``p_max`` (Pa, over the fluid particles), ``pressure_error`` (Pa; the RMS deviation
    from the hydrostatic profile when the solver has one, else NaN), ``steps``, ``dt`` (the last).
    """

    def __getattr__(self, name):
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    def mean_ke(self, t_from=0.0):
        """KE averaged over the recorded times ``t >= t_from`` (trapezoid rule)."""
        t = np.asarray(self["t"])
        ke = np.asarray(self["ke"])
        keep = t >= t_from
        t, ke = t[keep], ke[keep]
        if len(t) < 2:
            return float(ke.mean())
        return float(np.trapezoid(ke, t) / (t[-1] - t[0]))


class BISPH:
    """The state and the right-hand side of BIPI's Eqs. 16-21 (see the module docstring).

    Parameters
    ----------
    boundary : BoundarySegments, polygonal domain or edge file
        The walls (2D). Periodic axes with ``boundary.with_cell(pbc, cell)``.
    positions : array (N, 2) or (N, 3)
        Fluid particles (z = 0).
    dx : float
        Particle spacing ``dx_r``; masses ``rho0 dx^2`` (per unit depth).
    rho0, c0, mu : float
        Reference density (kg/m^3), speed of sound (m/s), dynamic viscosity (Pa s).
    body_force : sequence of 2 floats
        ``F`` (m/s^2), e.g. ``(0, -9.81)``.
    h_over_dx : float
        Support ``h / dx`` in this package's convention (4: the paper's ``h_B = 2 dx``).
    p_background : float
        ``P_B`` of Eq. 18.
    delta : float
        Molteni-Colagrossi coefficient (0 switches the diffusion off).
    hydrostatic : bool
        Remove the hydrostatic density difference from the diffusion (tanks under gravity).
    density : array (N,) or None
        Initial densities (default ``rho0``).
    velocities : array (N, 2) or None
    surface : float or None
        Height of the free surface: enables the hydrostatic pressure error,
        ``p_ref = rho0 |F| (surface - y)``.
    kernel : str
    wall_band : float
        Eq. 21's band in dx (the paper's 0.5); 0 switches the compressed density off
        (``p_s = p(rho_a) + rho_a c0 (v_s - v_a).n_s``), for controlled experiments.
    eq21 : {"pointwise", "segment"}
        How Eq. 21's ``|x_a - x_s|`` is read. ``"pointwise"`` (default): at every point of the wall,
        ``int_s p(rho~(|y - x_a|)) W dS``, so only the part of a wall within ``dx/2`` of the particle
        is compressed; this is the limit of the paper's segments as they shrink (BIPI2D refines them to
        ``dx/10``) and does not depend on how the wall is cut. ``"segment"``: ``rho~`` at the
        segment's nearest point over the whole segment, which with one segment per straight side
        compresses the whole side (the earlier behaviour; with ``segment_ratio=10``, BIPI2D's
        discretisation).
    segment_ratio : float or None
        The walls are split into segments no longer than ``dx / segment_ratio`` (BIPI2D's
        ``edge_to_dx_ratio`` is 10). The integrals of Eqs. 16-17 do not depend on it; ``eq21="segment"``
        and the viscous wall shear (at the particle's distance to each segment) do. ``None`` merges
        collinear runs (one segment per straight side; cheapest).
    viscosity : {"boundary_layer", "pcg"}
        The viscous term's form (BIPI Fig. 14a / 14b; see the module docstring): Morris' sum with
        the boundary-layer wall shear (default), or the Laplacian as the particle-consistent
        divergence of the particle-consistent gradient (:meth:`laplacian`).
    """

    def __init__(self, boundary, positions, dx, rho0=1000.0, c0=None, mu=10.0, body_force=(0.0, -9.81),
                 h_over_dx=4.0, p_background=0.0, delta=0.1, hydrostatic=True, density=None, velocities=None,
                 surface=None, kernel="wendland_c2", wall_band=WALL_BAND, viscosity="boundary_layer",
                 eq21="pointwise", segment_ratio=None):
        self.boundary = as_boundary(boundary)
        if self.boundary.dim != 2:
            raise ValueError(f"boundary must be 2D (BISPH is a 2D solver), got a {self.boundary.dim}D boundary")
        r = np.asarray(positions, dtype=float)
        if r.ndim != 2 or r.shape[1] not in (2, 3) or len(r) == 0:
            raise ValueError(f"positions must have shape (N, 2) or (N, 3) with N >= 1, got {r.shape}")
        self.dx = check_positive("dx", dx)
        self.rho0 = check_positive("rho0", rho0)
        if c0 is None:
            raise ValueError("c0 must be given: the speed of sound, about 10x the largest expected speed (Mach 0.1)")
        self.c0 = check_positive("c0", c0)
        if mu < 0:
            raise ValueError(f"mu must be >= 0, got {mu!r}")
        self.mu = float(mu)
        self.force = np.zeros(3)
        self.force[:2] = np.asarray(body_force, dtype=float).reshape(2)
        self.h = check_positive("h_over_dx", h_over_dx) * self.dx
        self.h_b = self.h / 2.0
        self.p_background = float(p_background)
        if delta < 0:
            raise ValueError(f"delta must be >= 0, got {delta!r}")
        self.delta = float(delta)
        self.hydrostatic = bool(hydrostatic)
        if not 0.0 <= wall_band <= 1.0:
            raise ValueError(f"wall_band must be in [0, 1] (Eq. 21's band in dx; the paper's 0.5), got {wall_band!r}")
        self.wall_band = float(wall_band)
        if eq21 not in EQ21_READINGS:
            raise ValueError(f"eq21 must be one of {EQ21_READINGS}, got {eq21!r}")
        self.eq21 = eq21
        if viscosity not in VISCOSITY_FORMS:
            raise ValueError(f"viscosity must be one of {VISCOSITY_FORMS}, got {viscosity!r}")
        self.viscosity = viscosity
        self.surface = None if surface is None else float(surface)
        self.kernel = get_kernel(kernel, 2)
        self._moment = first_moment_table(self.kernel)
        n = len(r)
        self.r = np.zeros((n, 3))
        self.r[:, : r.shape[1]] = r
        self._planar = not self.r[:, 2].any()  # the pair loops read x and y only (PairInteraction planar)
        self.v = np.zeros((n, 3))
        if velocities is not None:
            self.v[:, :2] = np.asarray(velocities, dtype=float).reshape(n, 2)
        self.rho = np.full(n, self.rho0) if density is None else np.array(density, dtype=float).reshape(n)
        self.mass = self.rho0 * self.dx**2
        self.t = 0.0
        self.steps = 0
        elements = self.boundary.merged()  # collinear runs merged: the same integrals over fewer segments
        if segment_ratio is not None:
            elements = elements.refine(dx=self.dx, ratio=check_positive("segment_ratio", segment_ratio))
        self.segment_ratio = None if segment_ratio is None else float(segment_ratio)
        self.integrals = BoundaryIntegrals(elements, self.h, self.kernel.name)
        self._seg = elements.packed_sk
        self.cell = np.array(self.boundary.cell, dtype=float)
        self.pbc = np.array(self.boundary.pbc, dtype=bool)
        self.nlist = NeighborList(self.h, skin=0.5 * self.dx)
        self._wrap()

    def __repr__(self):
        return (f"BISPH(N={len(self.r)}, dx={self.dx!r}, h={self.h!r} (h_B={self.h_b!r}), c0={self.c0!r}, "
                f"mu={self.mu!r}, F={self.force[:2].tolist()}, delta={self.delta!r}, t={self.t:.4g})")

    # -- helpers ------------------------------------------------------------------------
    def _wrap(self):
        for i in np.nonzero(self.pbc[:2])[0]:
            length = self.cell[i, i]
            self.r[:, i] = np.mod(self.r[:, i], length)
            self.r[self.r[:, i] >= length, i] = 0.0

    def pressure(self, rho=None):
        """Eq. 18 at the particles' densities (or ``rho``)."""
        return tait_pressure(self.rho if rho is None else rho, self.rho0, self.c0, self.p_background)

    def time_step(self):
        """Eq. 19 (see the module docstring)."""
        vmax = float(np.sqrt(np.max(np.einsum("pc,pc->p", self.v, self.v))))
        dt = 0.25 * self.h_b / (self.c0 + vmax)
        if self.mu > 0:
            dt = min(dt, 0.125 * self.h_b**2 * self.rho0 / self.mu)
        f = float(np.linalg.norm(self.force))
        if f > 0:
            dt = min(dt, 0.25 * math.sqrt(self.h_b / f))
        return dt

    def kinetic_energy(self):
        """``sum_a m |v_a|^2 / 2`` (J per metre of depth)."""
        return 0.5 * self.mass * float(np.einsum("pc,pc->", self.v, self.v))

    def pressure_error(self, p=None):
        """RMS of ``p_a - rho0 |F| (surface - y_a)`` over the particles (Pa); NaN without a surface."""
        if self.surface is None:
            return float("nan")
        p = self.pressure() if p is None else p
        ref = self.rho0 * float(np.linalg.norm(self.force)) * (self.surface - self.r[:, 1]) + self.p_background
        return float(np.sqrt(np.mean((p - ref) ** 2)))

    # -- the right-hand side --------------------------------------------------------------
    def walls(self):
        """Neighbours and boundary terms at the current positions: ``(BoundaryTerms, gamma_p)``
        (``gamma_p`` floored at 1e-3 for the divisions)."""
        self.nlist.update(self.r, self.cell, self.pbc)
        bt = self.integrals.compute(self.nlist, self.r, terms=True)
        return bt, np.maximum(bt.gamma_p, GAMMA_FLOOR)

    def _kernel_params(self):
        return dict(inv_h=1.0 / self.h, grad_scale=self.kernel.sigma / self.h**3, eta2=ETA2_FRACTION * self.h_b**2)

    def _wall_sums(self, bt, v_pc, rho, p, wall_velocity=None):
        """Per-particle wall sums of Eqs. 16-17 (``wall_velocity``: a function of the pairs' foot
        points, (M, 2) -> (M, 2), for the operator checks; default 0, static walls)."""
        pairs = bt.pairs
        vs = np.zeros((pairs.n_pairs, 2))
        if wall_velocity is not None and pairs.n_pairs:
            vs[:] = wall_velocity(self._feet(bt))
        n = len(self.r)
        div_w, gp_w, lap_w, pw = np.empty(n), np.empty((n, 2)), np.empty((n, 2)), np.empty(n)
        _wall_terms(pairs.start_p, pairs.element_k, pairs.point_k, pairs.x_sc, pairs.distance_k, bt.grad_k,
                    self._seg, rho, p, v_pc, vs, self.rho0, self.c0, self.p_background, self.dx,
                    self.wall_band * self.dx, self.eq21 == "pointwise", self.kernel.sigma / self.h**2, 1.0 / self.h,
                    self.kernel.breaks, self.kernel.coef, GAUSS_NODES, GAUSS_WEIGHTS, SHEAR_FLOOR * self.dx,
                    div_w, gp_w, lap_w, pw)
        return div_w, gp_w, lap_w

    def _feet(self, bt):
        """The kernel-weighted centre ``y_as = int_s y W dS / int_s W dS`` of each (particle image,
        segment) pair, (M, 2), in closed form (:func:`first_moment_table`): for a linear field
        ``int_s f W dS = f(y_as) int_s W dS`` exactly, so the wall term of :meth:`gradient` is exact
        for linear fields (the boundary term's discretisation adds no error)."""
        pairs = bt.pairs
        feet = np.empty((pairs.n_pairs, 2))
        _wall_feet(pairs.element_k, pairs.point_k, pairs.x_sc, bt.grad_k, self._seg, 1.0 / self.h, *self._moment,
                   feet)
        return feet

    def _consistent(self, bt, gamma, f_pc, wall_f=None, walls=True):
        """Particle-consistent gradient of the columns of ``f_pc`` (N, K <= 4): (N, K, 2), and its
        correction matrix ``L_a`` (N, 4), walls included (see :meth:`gradient`). ``wall_f``: the wall values
        at the feet, (M, K) (default 0: static no-slip walls); ``walls=False`` leaves the wall terms out."""
        n, ncol = f_pc.shape
        f_sc = np.zeros((n, 4))
        f_sc[:, :ncol] = f_pc
        out = CONSISTENT.compute(self.nlist, self.r, dict(inv_h=1.0 / self.h, grad_scale=self.kernel.sigma / self.h**3),
                                 dict(vol_s=self.mass / self.rho, f_sc=f_sc), reach=self.h, kernel=self.kernel,
                                 planar=self._planar)
        lmat, nsum = out.lmat, out.nsum
        if walls and bt.pairs.n_pairs:
            pairs = bt.pairs
            feet = self._feet(bt)
            f_kc = np.zeros((pairs.n_pairs, 4)) if wall_f is None else np.asarray(wall_f, dtype=float).reshape(
                pairs.n_pairs, ncol)
            _wall_consistent(pairs.start_p, pairs.element_k, pairs.point_k, pairs.x_sc, bt.grad_k, self._seg, feet,
                             np.ascontiguousarray(f_kc[:, :ncol]), np.ascontiguousarray(f_pc), lmat, nsum)
        return _solve2(lmat, nsum, ncol, gamma), lmat

    def laplacian(self, v_pc=None, bt=None, gamma=None, wall_velocity=None):
        """``lap v`` in the particle-consistent-gradient (PCG) form of BIPI Fig. 14b, (N, 2).

        The divergence of the gradient, each particle-consistent (the paper names the PCG formulation
        of its refs. [3-5], Liu & Liu 2006 and Boregowda & Liu 2023, without writing it out; this is our
        reading, stated):

        1. ``G_a = grad v_a = L_a^{-1} [sum_b V_b (v_b - v_a) (x) grad_a W - sum_s (v_s - v_a) (x) grad gamma_as]``
           with ``L_a = sum_b V_b grad_a W (x) (x_b - x_a) - sum_s grad gamma_as (x) (y_as - x_a)``
           (Eq. 2 in difference form with Liu & Liu's first-order correction; ``v_s = 0`` at the
           kernel-weighted centres ``y_as`` of the static walls): exact for a linear ``v``, to rounding,
           next to walls and corners;
        2. ``lap v_a = tr(grad G_a)``, ``grad G_a = 2 L_a^{-1} [sum_b V_b (G_ab - G_a) (x) grad_a W
           - sum_s (G_as - G_a) (x) grad gamma_as]`` with the same ``L_a`` and the gradient at the
           midpoint of each pair, ``G_ab = Gbar + ((v_b - v_a)/r_ab - Gbar e_ab) (x) e_ab``, ``Gbar =
           (G_a + G_b)/2``, and of each (particle, wall) pair, ``G_as = G_a + j_as (x) n_s``, ``j_as = (v_a
           - v_s + G_a (y_as - x_a))/delta_as`` (the boundary-layer form's wall shear ``(v_a - v_s)/delta_as``
           in place of ``G_a``'s normal derivative; ``delta_as`` floored at ``dx/4``). For a quadratic
           ``v`` with exact ``G_a``, ``G_ab`` is the gradient at the midpoint, so ``G_ab - G_a = (grad G)
           (x_b - x_a)/2`` and ``grad G_a`` is exact (hence the 2); at a wall ``G_as`` gets the normal
           derivative's part of it only, so a corner particle, next to two walls, is off (measured in
           ``tests/test_bisph.py``).

        The nested form with ``G_b`` in place of ``G_ab`` (and no wall term) is blind to the odd-even
        mode across the channel (a null eigenvalue of the Poiseuille operator, and one of rate -0.05
        against the physical -24.5 1/s) and its wall slip left the profile 2.6 % off at steady state; the
        difference quotient along the pair is the finite-volume cure of that checkerboard (Rhie & Chow
        1983). Exact (to rounding) for linear velocity fields everywhere, walls and corners included
        (``G_ab = G_as - G_a + G_a = G``). Two pair passes more than Morris' form.
        ``wall_velocity``: a function of the feet, (M, 2) -> (M, 2), for operator checks (default 0).
        """
        if bt is None:
            bt, gamma = self.walls()
        v_pc = np.ascontiguousarray((self.v if v_pc is None else v_pc)[:, :2])
        pairs = bt.pairs
        feet = self._feet(bt)
        vs = np.zeros((pairs.n_pairs, 2)) if wall_velocity is None else np.asarray(wall_velocity(feet), float)
        grad_v, lmat = self._consistent(bt, gamma, v_pc, vs)  # [a, c, i] = d_i v_c
        q_pc = np.empty((len(v_pc), 7))
        q_pc[:, 0] = self.mass / self.rho
        q_pc[:, 1:3] = v_pc
        q_pc[:, 3:] = grad_v.reshape(-1, 4)
        nsum = MIDPOINT_DIVERGENCE.compute(self.nlist, self.r, dict(inv_h=1.0 / self.h,
                                                                    grad_scale=self.kernel.sigma / self.h**3),
                                           dict(q_sc=q_pc), reach=self.h, kernel=self.kernel,
                                           planar=self._planar).nsum
        if pairs.n_pairs:
            _wall_midpoint(pairs.start_p, pairs.element_k, pairs.point_k, pairs.x_sc, pairs.distance_k, bt.grad_k,
                           self._seg, feet, np.ascontiguousarray(vs), v_pc, np.ascontiguousarray(q_pc[:, 3:]),
                           SHEAR_FLOOR * self.dx, nsum)
        grad_g = _solve2(lmat, 2.0 * nsum, 4, gamma)  # [a, 2c + i, k]
        lap = np.empty((len(v_pc), 2))
        lap[:, 0] = grad_g[:, 0, 0] + grad_g[:, 1, 1]
        lap[:, 1] = grad_g[:, 2, 0] + grad_g[:, 3, 1]
        return lap

    def acceleration(self, bt=None, gamma=None):
        """``D v/Dt`` of Eq. 17 at the current state, (N, 3)."""
        if bt is None:
            bt, gamma = self.walls()
        return self._momentum(bt, gamma, self.pressure())[0]

    def _momentum(self, bt, gamma, p):
        """Eq. 17's acceleration (N, 3) and the Molteni-Colagrossi sum of Eq. 16 at the current state
        (one pair pass for both)."""
        hx, hy = (self.rho0 * self.force[:2] / self.c0**2) if self.hydrostatic else (0.0, 0.0)
        params = dict(self._kernel_params(), hx=float(hx), hy=float(hy))
        q_pc = np.empty((len(self.r), 5))
        q_pc[:, 0] = self.mass / self.rho
        q_pc[:, 1] = p
        q_pc[:, 2] = self.rho
        q_pc[:, 3:] = self.v[:, :2]
        terms = MOMENTUM_DIFFUSION.compute(self.nlist, self.r, params, dict(q_sc=q_pc), reach=self.h,
                                           kernel=self.kernel, planar=self._planar).terms
        div_w, gp_w, lap_w = self._wall_sums(bt, self.v, self.rho, p)
        acc = np.zeros_like(self.v)
        if self.viscosity == "pcg":
            acc[:, :2] = (self.mu / self.rho)[:, None] * self.laplacian(self.v, bt, gamma) \
                - (terms[:, 0:2] + gp_w) / (self.rho * gamma)[:, None]
        else:
            acc[:, :2] = (self.mu * (terms[:, 2:4] + lap_w) - (terms[:, 0:2] + gp_w)) * \
                (1.0 / (self.rho * gamma))[:, None]
        acc += self.force
        return acc, terms[:, 4]

    def density_rate(self, bt=None, gamma=None, v_pc=None, wall_velocity=None, diffusion=True):
        """``D rho/Dt`` of Eq. 16 at the current positions and densities with velocities ``v_pc``
        (default the state's), (N,)."""
        if bt is None:
            bt, gamma = self.walls()
        v_pc = self.v if v_pc is None else v_pc
        hx, hy = (self.rho0 * self.force[:2] / self.c0**2) if self.hydrostatic else (0.0, 0.0)
        params = dict(self._kernel_params(), hx=float(hx), hy=float(hy))
        out = CONTINUITY.compute(self.nlist, self.r, params, dict(vol_s=self.mass / self.rho, rho_s=self.rho,
                                                                  v_sc=v_pc), reach=self.h, kernel=self.kernel,
                                planar=self._planar)
        div_w, _, _ = self._wall_sums(bt, v_pc, self.rho, self.pressure(), wall_velocity)
        rate = -self.rho / gamma * (out.div + div_w)
        if diffusion and self.delta > 0:
            rate += self.delta * self.h_b * self.c0 * out.diff / gamma
        return rate

    def gradient(self, f_p, wall_value=None, consistent=False):
        """The gamma-renormalised gradient of Eq. 16 applied to a scalar field (an operator check)::

            grad f_a = (1/gamma_a) [sum_b V_b (f_b - f_a) grad_a W - sum_s (f_s - f_a) grad gamma_as]

        ``f_s`` is ``wall_value`` (a function of points (M, 2) -> (M,)) at the kernel-weighted centre
        of segment ``s`` seen from the particle (:meth:`_feet`: exact for a linear field), or ``f_a``
        (no wall term) when None. Returns (N, 2).

        With exact gamma, grad gamma and wall integrals, the error is the particle sum's alone: the
        lattice quadrature of a kernel cut by the wall, whose first moment ``sum_b V_b grad_a W (x)
        (x_b - x_a)`` is not ``gamma_a I`` there (h = 4 dx: 2.9 % next to the walls of a box, 19.5 %
        next to a re-entrant vertex; the controlled experiment of ``tests/test_bisph.py`` replaces the
        particle sum by a finer quadrature and the error falls with it). ``consistent=True`` divides
        by that first moment instead of ``gamma_a`` (the particle-consistent gradient, :meth:`laplacian`
        step 1): exact to rounding for a linear field, with the wall term (``wall_value``) or without it
        (``wall_value=None``: the particle-only correction matrix, exact for linear fields too, one-sided;
        the wall term brings the wall's values in, which matters for the other fields).
        """
        f_p = np.asarray(f_p, dtype=float)
        bt, gamma = self.walls()
        if consistent:
            wall = None if wall_value is None else wall_value(self._feet(bt))[:, None]
            return self._consistent(bt, gamma, f_p[:, None], wall, walls=wall_value is not None)[0][:, 0, :]
        out = np.zeros((len(self.r), 2))
        for c in range(2):
            v = np.zeros_like(self.v)
            v[:, c] = f_p
            wall = None
            if wall_value is not None:
                def wall(feet, c=c):
                    vs = np.zeros((len(feet), 2))
                    vs[:, c] = wall_value(feet)
                    return vs
            # density_rate = -rho/gamma (sum_b V_b (f_b - f_a).grad W - sum_s (f_s - f_a).grad gamma_as)
            out[:, c] = -self.density_rate(bt, gamma, v, wall, diffusion=False) / self.rho
        return out

    # -- time stepping ------------------------------------------------------------------
    def step(self, dt=None):
        """One symplectic Euler step: ``v^{n+1}`` from Eq. 17 at step n, then ``rho^{n+1}`` from
        Eq. 16 with ``v^{n+1}`` and ``x^{n+1} = x^n + dt v^{n+1}``; returns ``dt``.

        Two pair passes: Eq. 17 with the density diffusion of Eq. 16 (both at ``x^n``, ``rho^n``),
        then the velocity divergence of Eq. 16 with ``v^{n+1}`` (the same terms as
        :meth:`acceleration` and :meth:`density_rate`)."""
        dt = self.time_step() if dt is None else float(dt)
        bt, gamma = self.walls()
        p = self.pressure()
        acc, diff = self._momentum(bt, gamma, p)
        self.v += dt * acc
        q_pc = np.empty((len(self.r), 3))
        q_pc[:, 0] = self.mass / self.rho
        q_pc[:, 1:] = self.v[:, :2]
        out = DIVERGENCE.compute(self.nlist, self.r, dict(inv_h=1.0 / self.h, grad_scale=self.kernel.sigma / self.h**3),
                                 dict(q_sc=q_pc), reach=self.h, kernel=self.kernel, planar=self._planar)
        div_w, _, _ = self._wall_sums(bt, self.v, self.rho, p)
        rate = -self.rho / gamma * (out.div + div_w)
        if self.delta > 0:
            rate += self.delta * self.h_b * self.c0 * diff / gamma
        self.rho += dt * rate
        self.r += dt * self.v
        self._wrap()
        self.t += dt
        self.steps += 1
        return dt

    def run(self, t_end, record_every=None, progress=True, max_steps=None):
        """Integrate to ``t_end`` (s); return a :class:`RunHistory`.

        Parameters
        ----------
        t_end : float
            End time (absolute, from the state's ``t``).
        record_every : float or None
            Recording interval (s); default ``t_end / 200``.
        progress : bool
            A tqdm bar over simulated time.
        max_steps : int or None
            Stop after this many steps (a guard).
        """
        from tqdm.auto import tqdm

        t_end = check_positive("t_end", t_end)
        every = t_end / 200.0 if record_every is None else check_positive("record_every", record_every)
        hist = RunHistory(t=[], ke=[], v_max=[], p_mean=[], p_min=[], p_max=[], pressure_error=[])

        def record():
            p = self.pressure()
            hist["t"].append(self.t)
            hist["ke"].append(self.kinetic_energy())
            hist["v_max"].append(float(np.sqrt(np.max(np.einsum("pc,pc->p", self.v, self.v)))))
            hist["p_mean"].append(float(p.mean()))
            hist["p_min"].append(float(p.min()))
            hist["p_max"].append(float(p.max()))
            hist["pressure_error"].append(self.pressure_error(p))

        record()
        next_record = self.t + every
        dt = 0.0
        with tqdm(total=t_end, disable=not progress, unit="s", desc="BISPH") as bar:
            while self.t < t_end - 1e-12 * t_end:
                dt = min(self.time_step(), t_end - self.t)
                self.step(dt)
                bar.update(dt)
                if not np.all(np.isfinite(self.v)):
                    raise FloatingPointError(f"BISPH diverged at t={self.t:.4g} s after {self.steps} steps")
                if self.t >= next_record - 1e-12:
                    record()
                    next_record += every
                if max_steps is not None and self.steps >= max_steps:
                    break
        if hist["t"][-1] != self.t:
            record()
        hist["steps"] = self.steps
        hist["dt"] = dt
        return hist
