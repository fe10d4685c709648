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
Each is one :func:`register_kernel` entry at the end of this module: its breaks and
piecewise-polynomial coefficients in ``q`` (per dimension where they differ), Phantom's
``eta`` and the smoothing-length solve's extrapolation step.

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
``q`` would suffer.

From that one definition follow the numpy profile and its derivatives
(:meth:`Kernel.profile`), the normalisation and moments, Fan's ``W1`` and its tail
integral, and the numba closed forms of the hot loops (:meth:`Kernel.closed_forms`):
Python source with the coefficients written in (Horner in ``u``, the lowest power of
``u`` factored out), compiled with ``cache=True`` against this file under a name
holding the kernel, its dimension and a hash of its coefficients. A pair function calls
the placeholders :func:`kernel_profile` and :func:`kernel_derivatives`;
:class:`~ase_sphrelax.pairs.PairInteraction` re-compiles it with them bound to a
kernel's closed forms. :func:`profile_value_and_slope` evaluates the arrays
``Kernel.breaks``/``Kernel.coef`` generically (lattice sums).
"""
from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import numba
import numpy as np
from numpy.polynomial import polynomial as P

from .checks import check_dim

__all__ = ["Kernel", "get_kernel", "KERNEL_NAMES", "register_kernel", "KernelDefinition", "kernel_profile",
           "kernel_derivatives", "kernel_slope_over_q", "KERNEL_FUNCTIONS", "profile_value_and_slope"]

_SPHERE_SURFACE = {1: 2.0, 2: 2.0 * math.pi, 3: 4.0 * math.pi}


def _exact(coefficients):
    """Coefficients as exact fractions (a float is taken at its exact binary value)."""
    return tuple(Fraction(c) for c in coefficients)


def _poly(*factors):
    """Exact product of polynomials given as ascending coefficient lists."""
    out = (Fraction(1),)
    for factor in factors:
        factor = _exact(factor)
        prod = [Fraction(0)] * (len(out) + len(factor) - 1)
        for i, x in enumerate(out):
            for j, y in enumerate(factor):
                prod[i + j] += x * y
        out = tuple(prod)
    return out


def _power(base, n):
    return _poly(*([base] * n))


def _to_u(piece_q, right):
    """Coefficients in u = right - q of a polynomial given in powers of q, composed exactly (so that
    a factor (1 - q)^k gives exact zeros below u^k), then rounded to floats."""
    right = Fraction(right)
    out = [Fraction(0)] * len(piece_q)
    for k, c in enumerate(_exact(piece_q)):
        # c q^k = c (right - u)^k = c sum_j binom(k, j) right^(k-j) (-u)^j
        for j in range(k + 1):
            out[j] += c * math.comb(k, j) * right ** (k - j) * (-1) ** j
    return np.array([float(c) for c in out])


# -- the registry: one entry per kernel --------------------------------------------------------------
@dataclass(frozen=True)
class KernelDefinition:
    """One kernel: its profile ``f(q)`` on [0, 1] as a piecewise polynomial.

    Attributes
    ----------
    name : str
    breaks : tuple of float
        ``0 = b_0 < b_1 < ... < b_n = 1``.
    pieces : tuple of tuple of Fraction
        Ascending coefficients in ``q`` of the ``n`` pieces, exact (floats at their binary value).
    per_dim : dict
        ``{dim: (breaks, pieces)}`` where a dimension has a profile of its own (Wendland C4 in 1D).
    eta : float or None
        ``rho H^d = m eta^d`` for support ``H`` (Phantom's value for support 2h, times 2).
    extrapolation_step : float
        The factor of the smoothing-length solve's extrapolated steps
        (:func:`ase_sphrelax.sph.solve_smoothing_lengths`); 0 unless the profile is C^4 across the
        support edge and inside.
    """

    name: str
    breaks: tuple
    pieces: tuple
    per_dim: dict = field(default_factory=dict)
    eta: float | None = None
    extrapolation_step: float = 0.0

    def profile(self, dim):
        """(breaks, pieces) in ``dim`` dimensions."""
        return self.per_dim.get(dim, (self.breaks, self.pieces))


_REGISTRY: dict = {}
_CACHE: dict = {}


def _checked_profile(name, breaks, pieces):
    breaks = tuple(float(b) for b in breaks)
    if len(breaks) < 2 or breaks[0] != 0.0 or breaks[-1] != 1.0 or any(b <= a for a, b in zip(breaks, breaks[1:])):
        raise ValueError(f"kernel {name!r}: breaks must increase from 0 to 1, got {breaks}")
    try:
        pieces = tuple(_exact(np.atleast_1d(p).tolist() if isinstance(p, np.ndarray) else p) for p in pieces)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"kernel {name!r}: pieces must be lists of finite numbers (ascending powers of q)") from None
    if len(pieces) != len(breaks) - 1:
        raise ValueError(f"kernel {name!r}: breaks {breaks} need {len(breaks) - 1} pieces, got {len(pieces)}")
    if not all(pieces) or not all(any(pieces_k) for pieces_k in pieces):
        raise ValueError(f"kernel {name!r}: every piece needs a non-zero coefficient (ascending powers of q)")
    return breaks, pieces


def register_kernel(name, breaks, pieces, per_dim=None, eta=None, extrapolation_step=0.0, replace=False):
    """Add a kernel: the one place a kernel is defined.

    Parameters
    ----------
    name : str
        An identifier (letters, digits, underscores), e.g. ``"wendland_c2"``.
    breaks : sequence of float
        ``0 = b_0 < ... < b_n = 1``.
    pieces : sequence of sequence of float
        Ascending coefficients in ``q`` of each piece; the normalisation follows (``Kernel.sigma``).
    per_dim : dict or None
        ``{dim: (breaks, pieces)}`` for dimensions with a profile of their own.
    eta : float or None
        Default ``eta`` of the adaptive smoothing lengths (support ``H``); None: callers must pass one.
    extrapolation_step : float
        See :class:`KernelDefinition`.
    replace : bool
        Allow redefining a registered name.

    Returns
    -------
    KernelDefinition
    """
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise ValueError(f"kernel name must be an identifier (letters, digits, underscores), got {name!r}")
    if name in _REGISTRY and not replace:
        raise ValueError(f"kernel {name!r} is already registered (pass replace=True to redefine it)")
    if eta is not None and not (math.isfinite(eta) and eta > 0):
        raise ValueError(f"eta must be a number > 0 or None, got {eta!r}")
    breaks, pieces = _checked_profile(name, breaks, pieces)
    own = {check_dim(d): _checked_profile(name, *bp) for d, bp in (per_dim or {}).items()}
    definition = KernelDefinition(name, breaks, pieces, own, None if eta is None else float(eta),
                                  float(extrapolation_step))
    _REGISTRY[name] = definition
    for key in [k for k in _CACHE if k[0] == name]:
        del _CACHE[key]
    return definition


class _RegisteredNames(Sequence):
    """The registered kernel names, read live (kernels registered later included)."""

    def __getitem__(self, index):
        return tuple(_REGISTRY)[index]

    def __len__(self):
        return len(_REGISTRY)

    def __contains__(self, name):
        return isinstance(name, str) and name in _REGISTRY

    def __repr__(self):
        return repr(tuple(_REGISTRY))


KERNEL_NAMES = _RegisteredNames()


# -- placeholders of the pair functions ---------------------------------------------------------------
def kernel_profile(q):
    """f(q) and df/dq (zero for q >= 1): a placeholder in pair functions, bound to a kernel's closed
    form by :class:`~ase_sphrelax.pairs.PairInteraction` (``compute(..., kernel=k)``)."""
    raise NotImplementedError("kernel_profile is bound by PairInteraction(...).compute(..., kernel=k)")


def kernel_derivatives(q):
    """f(q) and its first four derivatives in q (zero for q >= 1): a placeholder, as :func:`kernel_profile`.

    For the smoothing-length solve of :func:`ase_sphrelax.sph.solve_smoothing_lengths` (Halley steps,
    and the sums carried to the new H by their Taylor series). At a break, where a derivative may
    jump, the piece on the right counts (the cubic spline's f''' at q = 1/2; its f'''' is zero).
    """
    raise NotImplementedError("kernel_derivatives is bound by PairInteraction(...).compute(..., kernel=k)")


def kernel_slope_over_q(q):
    """f(q) and f'(q) / q (zero for q >= 1): a placeholder, as :func:`kernel_profile`.

    A radial pair force ``f'(r/h) d / (h r)`` is ``f'(q)/q d / h^2``: with ``f'(q)/q`` in closed form (a
    polynomial on the segment at q = 0 when ``f'(0) = 0``, as for every smooth kernel) the pair loop needs no
    division by ``r`` and no branch at ``r = 0``. On the other segments (``q >= b_1 > 0``) it is ``f'(q) / q``.
    A profile with ``f'(0) != 0`` gives 0 at ``q = 0`` (no force between coincident points).
    """
    raise NotImplementedError("kernel_slope_over_q is bound by PairInteraction(...).compute(..., kernel=k)")


KERNEL_FUNCTIONS = ("kernel_profile", "kernel_derivatives", "kernel_slope_over_q")
_ORDERS = {"kernel_profile": 1, "kernel_derivatives": 4}


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


# -- closed forms, generated from the coefficients ----------------------------------------------------
def _horner(coef_u):
    """Source of ``sum_k coef_u[k] u^k``: the lowest power ``u^m`` factored out, Horner in u for the rest;
    and ``m``."""
    nonzero = np.nonzero(coef_u)[0]
    if nonzero.size == 0:
        return "0.0", 0
    low, high = int(nonzero[0]), int(nonzero[-1])
    expr = repr(float(coef_u[high]))
    for k in range(high - 1, low - 1, -1):
        expr = f"{float(coef_u[k])!r} + u * ({expr})" if coef_u[k] != 0.0 else f"u * ({expr})"
    if low == 0:
        return expr, 0
    return (f"u * ({expr})" if low == 1 else f"u{low} * ({expr})"), low


def _derivative_in_q(coef_u, order):
    """Coefficients in u of ``d^order f / dq^order`` (``= (-1)^order d^order p / du^order``)."""
    poly = np.asarray(coef_u, dtype=float)
    for _ in range(order):
        poly = -P.polyder(poly) if poly.size > 1 else np.zeros(1)
    return poly


def _piecewise_source(name, breaks, piece_terms):
    """Source of ``name(q)`` -> the terms of its segment, zeros for q >= 1. ``piece_terms[s]``: the segment's
    terms as ``(expression in u, lowest power of u)`` (:func:`_horner`), ``u = b_{s+1} - q``.

    One segment whose every term has a factor ``u`` is written without a branch: ``u = 0`` beyond the support
    gives the zeros. In the pair loops of adaptive smoothing lengths the test ``q >= 1`` goes either way at random
    (listed pairs beyond one partner's ``H``); as a select it costs no mispredicted branch (ALARIC's pressure pass
    1.4x faster).
    """
    def body(pad, terms):
        top = max(low for _, low in terms)
        return [f"{pad}u{k} = {'u' if k == 2 else f'u{k - 1}'} * u" for k in range(2, top + 1)] + \
            [f"{pad}return ({''.join(expr + ', ' for expr, _ in terms)})"]

    if len(piece_terms) == 1 and float(breaks[1]) >= 1.0 and all(low >= 1 for _, low in piece_terms[0]):
        lines = [f"def {name}(q):", "    u = 0.0 if q >= 1.0 else 1.0 - q  # a select: zeros beyond the support"]
        return "\n".join(lines + body("    ", piece_terms[0])) + "\n"
    lines = [f"def {name}(q):", "    if q >= 1.0:", "        return (" + "0.0, " * len(piece_terms[0]) + ")"]
    for s, terms in enumerate(piece_terms):
        right = min(float(breaks[s + 1]), 1.0)
        last = s == len(piece_terms) - 1
        pad = " " * (4 if last else 8)
        if not last:
            lines.append(f"    if q < {right!r}:")
        lines.append(f"{pad}u = {right!r} - q")
        lines += body(pad, terms)
    return "\n".join(lines) + "\n"


def _closed_form_source(name, breaks, pieces_u, orders):
    """Source of ``name(q)`` -> (f, f', ..., f^(orders)) of the piecewise profile (:func:`_piecewise_source`)."""
    return _piecewise_source(name, breaks, [[_horner(_derivative_in_q(coef_u, j)) for j in range(orders + 1)]
                                            for coef_u in pieces_u])


def _slope_over_q_source(name, breaks, pieces_q, pieces_u):
    """Source of ``name(q)`` -> (f, f'/q): on the first segment ``f'/q`` is the polynomial
    ``sum_k k c_k q^(k-2)`` (exact when ``c_1 = 0``), written in ``u`` as the profile is; on the others
    ``f' / q`` (:func:`_piecewise_source`)."""
    first = _exact(pieces_q[0])
    smooth = len(first) < 2 or first[1] == 0
    piece_terms = []
    for s, coef_u in enumerate(pieces_u):
        value = _horner(np.asarray(coef_u, dtype=float))
        if s == 0 and smooth:
            ratio = _horner(_to_u([k * c for k, c in enumerate(first)][2:] or [0], breaks[1]))
        else:
            slope, low = _horner(_derivative_in_q(coef_u, 1))
            ratio = (f"({slope}) / q" + (" if q > 0.0 else 0.0" if s == 0 else ""), low)
        piece_terms.append([value, ratio])
    return _piecewise_source(name, breaks, piece_terms)


def _placeholder_source(kernel, placeholder, name):
    if placeholder == "kernel_slope_over_q":
        return _slope_over_q_source(name, kernel.breaks, kernel._pieces_exact, kernel._pieces_u)
    return _closed_form_source(name, kernel.breaks, kernel._pieces_u, _ORDERS[placeholder])


_CLOSED_FORMS: dict = {}


def _closed_forms(kernel):
    """The numba closed forms of ``kernel`` by placeholder name, compiled against this file (disk cache)."""
    if kernel.key not in _CLOSED_FORMS:
        namespace = {}
        functions = {}
        for placeholder in KERNEL_FUNCTIONS:
            name = f"_{placeholder}__{kernel.key}"
            source = _placeholder_source(kernel, placeholder, name)
            exec(compile(source, __file__, "exec"), namespace)  # noqa: S102 (generated from the coefficients)
            function = namespace[name]
            function.__module__ = __name__
            functions[placeholder] = numba.njit(cache=True, inline="always")(function)
            functions[placeholder].generated_source = source
        _CLOSED_FORMS[kernel.key] = functions
    return _CLOSED_FORMS[kernel.key]


class Kernel:
    """A compactly supported SPH kernel in ``dim`` dimensions.

    Parameters
    ----------
    name : str
        A registered name (:data:`KERNEL_NAMES`, :func:`register_kernel`).
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
    eta, extrapolation_step : float or None
        From the kernel's definition (:class:`KernelDefinition`).
    key : str
        Identifier of the profile (name, dimension, hash of the coefficients): names its closed forms.
    """

    def __init__(self, name: str = "wendland_c2", dim: int = 2):
        dim = check_dim(dim)
        if name not in KERNEL_NAMES:
            raise ValueError(f"kernel must be one of {KERNEL_NAMES}, got {name!r}")
        definition = _REGISTRY[name]
        breaks, pieces = definition.profile(dim)
        self.name = name
        self.dim = dim
        self.eta = definition.eta
        self.extrapolation_step = definition.extrapolation_step
        self.breaks = np.asarray(list(breaks) + [np.inf], dtype=float)
        self._pieces = [np.array([float(c) for c in p]) for p in pieces]
        self._pieces_exact = [_exact(p) for p in pieces]
        self._pieces_u = [_to_u(p, self.breaks[s + 1]) for s, p in enumerate(pieces)]
        deg = max(len(p) for p in self._pieces_u) - 1
        self.coef = np.zeros((len(pieces), deg + 1))
        for s, p in enumerate(self._pieces_u):
            self.coef[s, : len(p)] = p
        # the closed forms' source (coefficients and generator): in the names of everything compiled from them,
        # so that numba's disk cache never serves code inlined from an older kernel or generator
        sources = "".join(_placeholder_source(self, placeholder, "f") for placeholder in KERNEL_FUNCTIONS)
        self._stamp = hashlib.sha1(sources.encode()).hexdigest()[:8]
        # exact moments of the profile: int_0^1 f(q) q^(d-1) dq
        self.sigma = 1.0 / (_SPHERE_SURFACE[dim] * self._moment(dim - 1))
        self.sigma_1d = 1.0 / (2.0 * self._moment(0))
        self.f0 = float(P.polyval(self.breaks[1], self._pieces_u[0]))  # f(0)

    def __repr__(self):
        return f"Kernel({self.name!r}, dim={self.dim})"

    @property
    def key(self):
        return f"{self.name}_{self.dim}d_{self._stamp}"

    def closed_forms(self):
        """``{"kernel_profile": q -> (f, f'), "kernel_derivatives": q -> (f, f', f'', f''', f'''')}``:
        numba functions generated from the coefficients (zeros for q >= 1), bound to the pair
        functions' placeholders by :class:`~ase_sphrelax.pairs.PairInteraction`."""
        return _closed_forms(self)

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
    def profile(self, q, derivative=0):
        """f(q), or its ``derivative``-th derivative in q, for an array of q >= 0 (zero for q >= 1)."""
        q = np.asarray(q, dtype=float)
        out = np.zeros_like(q)
        for mask, u, seg in self._segments(q):
            out[mask] = P.polyval(u, _derivative_in_q(self._pieces_u[seg], derivative))
        return out

    def profile_slope(self, q):
        """df/dq for an array of q >= 0."""
        return self.profile(q, derivative=1)

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
        """``W1(r, h) = A W(|r|, h)`` with A chosen so that W1 integrates to 1 on [-h, h]."""
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


# -- the kernels: one entry each ------------------------------------------------------------------------
_ONE_MINUS_Q = [1.0, -1.0]
# eta: Phantom's default for support 2h (cubic 1.2, Wendland C2 1.3, C4 1.5), times 2 for support H.
register_kernel("wendland_c2", [0.0, 1.0], [_poly(_power(_ONE_MINUS_Q, 4), [1.0, 4.0])], eta=2.6)
# Wendland C4's extrapolation step: a Halley step |d ln H| <= 0.22 tol^(1/4) of the smoothing-length solve may
# be accepted without a further density pass, its sums carried to the new H by their Taylor series. The
# truncation error in t is |s^(5)/t| dl^4 / 24; measured (jittered lattices, 1D-3D, dl = 1e-3 to 1e-2)
# |s^(5)/t| <= 1300 for Wendland C4, so the factor 0.22 keeps it below 0.4 tol with |s^(5)/t| up to 4000. Only
# for kernels whose profile is C^4 across the support edge and inside: the series of Wendland C2 (4th
# derivative jumps at q = 1) and of the cubic spline (3rd derivative jumps at q = 1/2 and 1) converge only like
# dl^3 and dl^2 (measured), so they always take the check pass.
register_kernel("wendland_c4", [0.0, 1.0], [_poly(_power(_ONE_MINUS_Q, 6), [1.0, 6.0, 35.0 / 3.0])],
                per_dim={1: ([0.0, 1.0], [_poly(_power(_ONE_MINUS_Q, 5), [1.0, 5.0, 8.0])])},
                eta=3.0, extrapolation_step=0.22)
register_kernel("cubic_spline", [0.0, 0.5, 1.0], [[1.0, 0.0, -6.0, 6.0], _poly([2.0], _power(_ONE_MINUS_Q, 3))], eta=2.4)
