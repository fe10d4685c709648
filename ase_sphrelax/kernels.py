"""SPH smoothing kernels with compact support radius ``h``.

Convention (Fan et al., ALARIC Eq. 5): ``h`` is the *support* (cut-off) radius,

    W(r, h) = sigma_d / h**d * f(q),   q = r / h,   f(q) = 0 for q >= 1,

where the profile ``f`` is a piecewise polynomial on [0, 1] and ``sigma_d`` makes
``W`` integrate to one in ``d`` dimensions. Every kernel here is stored as exact
piecewise-polynomial coefficients, so values, derivatives, normalisation and
Fan's one-dimensional boundary profile ``W1`` and its tail integral
(Fan Eq. 3.5) all follow from one representation without quadrature.

Kernels
-------
``wendland_c2``
    Fan et al. Sec. 2: f = (1 - q)^4 (1 + 4q); sigma_2 = 7/pi, sigma_3 = 21/(2 pi).
``wendland_c4``
    ALARIC Eq. 6: f = (1 - q)^6 (35 q^2 / 3 + 6 q + 1) in 2D/3D and
    (1 - q)^5 (8 q^2 + 5 q + 1) in 1D; C = {3/2, 9/pi, 495/(32 pi)}.
``cubic_spline``
    Monaghan's M4 B-spline written with support h: f = 1 - 6q^2 + 6q^3 for
    q < 1/2, 2 (1 - q)^3 for 1/2 <= q < 1.

Each segment ``[b_s, b_{s+1})`` is stored in powers of ``u = b_{s+1} - q``,
the distance to the segment's right end: near the cut-off the profile is a
small power of ``u`` and is evaluated without the cancellation that powers of
``q`` would suffer. The numba hot loops evaluate the profile through
:func:`profile_by_kind` (closed forms) or :func:`profile_value_and_slope` with the arrays ``Kernel.breaks`` and ``Kernel.coef``.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from numpy.polynomial import polynomial as P

from .checks import check_dim

__all__ = ["Kernel", "get_kernel", "KERNEL_NAMES", "profile_value_and_slope", "profile_by_kind",
           "profile_derivatives_by_kind", "PIECEWISE"]

_SPHERE_SURFACE = {1: 2.0, 2: 2.0 * math.pi, 3: 4.0 * math.pi}


def _poly(*factors):
    """Product of polynomials given as ascending coefficient lists."""
    out = np.array([1.0])
    for factor in factors:
        out = P.polymul(out, np.asarray(factor, dtype=float))
    return out


def _power(base, n):
    return _poly(*([base] * n))


def _profiles(name, dim):
    """(breaks, list of ascending coefficient arrays) of the profile f(q)."""
    one_minus_q = [1.0, -1.0]
    if name == "wendland_c2":
        return [0.0, 1.0], [_poly(_power(one_minus_q, 4), [1.0, 4.0])]
    if name == "wendland_c4":
        if dim == 1:
            return [0.0, 1.0], [_poly(_power(one_minus_q, 5), [1.0, 5.0, 8.0])]
        return [0.0, 1.0], [_poly(_power(one_minus_q, 6), [1.0, 6.0, 35.0 / 3.0])]
    if name == "cubic_spline":
        inner = np.array([1.0, 0.0, -6.0, 6.0])
        outer = 2.0 * _power(one_minus_q, 3)
        return [0.0, 0.5, 1.0], [inner, outer]
    raise ValueError(f"kernel must be one of {KERNEL_NAMES}, got {name!r}")


KERNEL_NAMES = ("wendland_c2", "wendland_c4", "cubic_spline")


@numba.njit(cache=True, inline="always")
def _piece(q, breaks):
    """Segment ``s`` of a piecewise profile holding ``q < 1`` and ``u = breaks[s+1] - q``."""
    s = 0
    while q >= breaks[s + 1]:
        s += 1
    return s, breaks[s + 1] - q


@numba.njit(cache=True, inline="always")
def profile_value_and_slope(q, breaks, coef):
    """Profile f(q) and df/dq of a piecewise polynomial (zero for q >= 1).

    ``coef[s, k]`` multiplies ``u**k``, ``u = breaks[s+1] - q``, on segment
    ``breaks[s] <= q < breaks[s+1]``; ``coef`` is padded with zeros to a common degree.
    """
    if q >= 1.0:
        return 0.0, 0.0
    s, u = _piece(q, breaks)
    deg = coef.shape[1] - 1
    value = coef[s, deg]
    slope = 0.0
    for k in range(deg - 1, -1, -1):
        slope = slope * u + value
        value = value * u + coef[s, k]
    return value, -slope


# closed forms (in u = 1 - q) for the hot loops; ids index Kernel.kind
WENDLAND_C2, WENDLAND_C4, WENDLAND_C4_1D, CUBIC_SPLINE, PIECEWISE = 0, 1, 2, 3, 4


@numba.njit(cache=True, inline="always")
def profile_by_kind(q, kind, breaks, coef):
    """Profile f(q) and df/dq (zero for q >= 1) for the hot loops.

    ``kind`` (``Kernel.kind``) selects a closed form, a loop-invariant branch that
    costs less than the generic evaluation; ``PIECEWISE`` falls back to
    :func:`profile_value_and_slope` with ``breaks``/``coef``.
    """
    if q >= 1.0:
        return 0.0, 0.0
    u = 1.0 - q
    if kind == WENDLAND_C2:  # u^4 (5 - 4u)
        u3 = u * u * u
        return u3 * u * (5.0 - 4.0 * u), -20.0 * u3 * (1.0 - u)
    if kind == WENDLAND_C4:  # u^6 (35 q^2 / 3 + 6 q + 1)
        u5 = u * u * u * u * u
        poly = (35.0 / 3.0) * q * q + 6.0 * q + 1.0
        return u5 * u * poly, u5 * (u * ((70.0 / 3.0) * q + 6.0) - 6.0 * poly)
    if kind == WENDLAND_C4_1D:  # u^5 (8 q^2 + 5 q + 1)
        u4 = u * u * u * u
        poly = 8.0 * q * q + 5.0 * q + 1.0
        return u4 * u * poly, u4 * (u * (16.0 * q + 5.0) - 5.0 * poly)
    if kind == CUBIC_SPLINE:
        if q < 0.5:
            return 1.0 - 6.0 * q * q + 6.0 * q * q * q, q * (18.0 * q - 12.0)
        return 2.0 * u * u * u, -6.0 * u * u
    return profile_value_and_slope(q, breaks, coef)


@numba.njit(cache=True, inline="always")
def profile_derivatives_by_kind(q, kind, breaks, coef):
    """Profile f(q) and its first four derivatives in q (zero for q >= 1).

    :func:`profile_by_kind` plus f'', f''' and f'''', for the smoothing-length solve of
    :func:`ase_sphrelax.sph.solve_smoothing_lengths` (Halley steps, and the sums carried to the
    new H by their Taylor series). The cubic spline's f'''' is zero between its knots (its f'''
    jumps at q = 1/2; the jump is left out).
    """
    if q >= 1.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    u = 1.0 - q
    if kind == WENDLAND_C2:  # f' = -20 q u^3, f'' = 20 u^2 (4 q - 1), f''' = 120 u (1 - 2 q), f'''' = 120 (4 q - 3)
        u2 = u * u
        return (u2 * u2 * (5.0 - 4.0 * u), -20.0 * q * u2 * u, 20.0 * u2 * (4.0 * q - 1.0), 120.0 * u * (1.0 - 2.0 * q),
                120.0 * (4.0 * q - 3.0))
    if kind == WENDLAND_C4:
        # f' = -(56/3) q (1 + 5 q) u^5, f'' = -(56/3) u^4 (1 + 4 q - 35 q^2), f''' = 560 q u^3 (3 - 7 q),
        # f'''' = 560 u^2 (3 - 26 q + 35 q^2)
        u2 = u * u
        u3 = u2 * u
        u4 = u3 * u
        poly = (35.0 / 3.0) * q * q + 6.0 * q + 1.0
        return (u4 * u2 * poly, (-56.0 / 3.0) * q * (1.0 + 5.0 * q) * u4 * u,
                (-56.0 / 3.0) * u4 * (1.0 + 4.0 * q - 35.0 * q * q), 560.0 * q * u3 * (3.0 - 7.0 * q),
                560.0 * u2 * (3.0 - 26.0 * q + 35.0 * q * q))
    if kind == WENDLAND_C4_1D:
        # f' = -14 q (1 + 4 q) u^4, f'' = -14 u^3 (1 + 3 q - 24 q^2), f''' = 840 q u^2 (1 - 2 q),
        # f'''' = 840 u (1 - 7 q + 8 q^2)
        u2 = u * u
        u3 = u2 * u
        poly = 8.0 * q * q + 5.0 * q + 1.0
        return (u3 * u2 * poly, -14.0 * q * (1.0 + 4.0 * q) * u3 * u, -14.0 * u3 * (1.0 + 3.0 * q - 24.0 * q * q),
                840.0 * q * u2 * (1.0 - 2.0 * q), 840.0 * u * (1.0 - 7.0 * q + 8.0 * q * q))
    if kind == CUBIC_SPLINE:
        if q < 0.5:
            return 1.0 - 6.0 * q * q + 6.0 * q * q * q, q * (18.0 * q - 12.0), 36.0 * q - 12.0, 36.0, 0.0
        return 2.0 * u * u * u, -6.0 * u * u, 12.0 * u, -12.0, 0.0
    s, u = _piece(q, breaks)
    deg = coef.shape[1] - 1
    value = coef[s, deg]
    d1 = 0.0
    d2 = 0.0
    d3 = 0.0
    d4 = 0.0
    for k in range(deg - 1, -1, -1):  # Horner with derivatives in u = breaks[s+1] - q
        d4 = d4 * u + d3
        d3 = d3 * u + d2
        d2 = d2 * u + d1
        d1 = d1 * u + value
        value = value * u + coef[s, k]
    return value, -d1, 2.0 * d2, -6.0 * d3, 24.0 * d4


def _to_u(piece_q, right):
    """Coefficients in u = right - q of a polynomial given in powers of q."""
    composed = P.Polynomial(piece_q)(P.Polynomial([right, -1.0]))
    return composed.coef


class Kernel:
    """A compactly supported SPH kernel in ``dim`` dimensions.

    Parameters
    ----------
    name : {"wendland_c2", "wendland_c4", "cubic_spline"}
    dim : {1, 2, 3}

    Attributes
    ----------
    sigma : float
        Normalisation for unit support: ``W(r, h) = sigma / h**dim * f(r / h)``.
    sigma_1d : float
        Normalisation of the same profile on [-h, h]: Fan's ``A`` in
        ``W1 = A W`` (Eq. 3.5), times ``h**dim / h``.
    breaks, coef : ndarray
        Piecewise-polynomial profile for :func:`profile_value_and_slope`.
    kind : int
        Closed form used by the hot loops (``PIECEWISE`` evaluates ``breaks``/``coef``).
    """

    def __init__(self, name: str = "wendland_c2", dim: int = 2):
        dim = check_dim(dim)
        breaks, pieces = _profiles(name, dim)
        self.name = name
        self.dim = dim
        self.breaks = np.asarray(breaks + [np.inf], dtype=float)
        self._pieces = pieces
        self._pieces_u = [_to_u(p, self.breaks[s + 1]) for s, p in enumerate(pieces)]
        deg = max(len(p) for p in self._pieces_u) - 1
        self.coef = np.zeros((len(pieces), deg + 1))
        for s, p in enumerate(self._pieces_u):
            self.coef[s, : len(p)] = p
        # exact moments of the profile: int_0^1 f(q) q^(d-1) dq
        self.sigma = 1.0 / (_SPHERE_SURFACE[dim] * self._moment(dim - 1))
        self.sigma_1d = 1.0 / (2.0 * self._moment(0))
        self.f0 = float(P.polyval(self.breaks[1], self._pieces_u[0]))  # f(0)
        self.kind = {"wendland_c2": WENDLAND_C2, "cubic_spline": CUBIC_SPLINE,
                     "wendland_c4": WENDLAND_C4_1D if dim == 1 else WENDLAND_C4}.get(name, PIECEWISE)

    def __repr__(self):
        return f"Kernel({self.name!r}, dim={self.dim})"

    def _moment(self, power):
        total = 0.0
        for s, p in enumerate(self._pieces):
            integrand = P.polyint(P.polymul(p, [0.0] * power + [1.0]))
            a, b = self.breaks[s], self.breaks[s + 1]
            total += P.polyval(b, integrand) - P.polyval(a, integrand)
        return total

    def _segments(self, q):
        """Yield (mask, u, segment) over the segments holding the entries of q."""
        for seg, _ in enumerate(self._pieces_u):
            right = min(self.breaks[seg + 1], 1.0)
            mask = (q >= self.breaks[seg]) & (q < right)
            yield mask, right - q[mask], seg

    # -- dimensionless profile -------------------------------------------------
    def profile(self, q):
        """f(q) for an array of q >= 0."""
        q = np.asarray(q, dtype=float)
        out = np.zeros_like(q)
        for mask, u, seg in self._segments(q):
            out[mask] = P.polyval(u, self._pieces_u[seg])
        return out

    def profile_slope(self, q):
        """df/dq for an array of q >= 0."""
        q = np.asarray(q, dtype=float)
        out = np.zeros_like(q)
        for mask, u, seg in self._segments(q):
            out[mask] = -P.polyval(u, P.polyder(self._pieces_u[seg]))
        return out

    # -- dimensional kernel ------------------------------------------------------
    def w(self, r, h):
        """W(r, h) = sigma / h^d f(r/h)."""
        h = np.asarray(h, dtype=float)
        return self.sigma / h**self.dim * self.profile(np.asarray(r) / h)

    def dw(self, r, h):
        """dW/dr (r, h) = sigma / h^(d+1) f'(r/h)."""
        h = np.asarray(h, dtype=float)
        return self.sigma / h ** (self.dim + 1) * self.profile_slope(np.asarray(r) / h)

    def w0(self, h):
        """W(0, h), the self contribution."""
        return self.sigma / np.asarray(h, dtype=float) ** self.dim * self.f0

    # -- Fan's one-dimensional boundary profile (Eq. 3.5) ------------------------
    def w1(self, r, h):
        """W1(r, h) = A W(|r|, h) with A chosen so that W1 integrates to 1 on [-h, h]."""
        h = np.asarray(h, dtype=float)
        return self.sigma_1d / h * self.profile(np.abs(np.asarray(r)) / h)

    def w1_tail_integral(self, s, h):
        """I(s) = int_s^h W1(max(r, 0), h) dr (Fan Eq. 3.5, 3.8).

        I(s) = 1/2 + (-s) W1(0) for s < 0, decreasing to 0 at s = h; dI/ds = -W1(max(s, 0)).
        """
        s = np.asarray(s, dtype=float)
        h = np.asarray(h, dtype=float)
        s, h = np.broadcast_arrays(s, h)
        q = s / h
        out = np.zeros(q.shape)
        # int_q^1 f = int over the rest of q's segment (a polynomial in u) + whole later segments
        later = 0.0
        for seg in range(len(self._pieces_u) - 1, -1, -1):
            right = min(self.breaks[seg + 1], 1.0)
            antider = P.polyint(self._pieces_u[seg])
            mask = (q >= self.breaks[seg]) & (q < right)
            out[mask] = P.polyval(right - q[mask], antider) + later
            later += P.polyval(right - self.breaks[seg], antider)
        out = self.sigma_1d * out
        # below zero W1(max(r, 0)) = W1(0): I(s) = 1/2 - s W1(0)
        negative = q < 0
        out[negative] = 0.5 - q[negative] * self.sigma_1d * self.f0
        return out[()] if out.ndim == 0 else out


_CACHE: dict = {}


def get_kernel(name="wendland_c2", dim=2) -> Kernel:
    """Return the (cached) :class:`Kernel` ``name`` in ``dim`` dimensions.

    ``name`` may also be a :class:`Kernel`, which is returned after checking its dimension.
    """
    if isinstance(name, Kernel):
        if name.dim != dim:
            raise ValueError(f"kernel {name!r} is {name.dim}D but dim={dim}")
        return name
    if name not in KERNEL_NAMES:
        raise ValueError(f"kernel must be one of {KERNEL_NAMES}, got {name!r}")
    key = (name, check_dim(dim))
    if key not in _CACHE:
        _CACHE[key] = Kernel(name, dim)
    return _CACHE[key]
