"""SPH-ParVI physics (Huang 2024) on point arrays of any dimension d.

A fluid of M particles of mass m = 1/M is driven by the target density p:

``formulation="force"`` (Algorithm 2, Eq. 3)
    ``dv_a/dt = -sum_b m (P_a/(Omega_a rho_a^2) grad_a W_ab(H_a) + P_b/(Omega_b rho_b^2) grad_a W_ab(H_b))
    + f_vis + alpha grad log p(x_a)``.
``formulation="pressure-log"`` / ``"pressure-inverse"`` (Algorithm 1, Eq. 2)
    no body force; the pressure is ``P_a = P_int(rho_a) + P_ext(x_a)`` with
    ``P_ext = -alpha log(p + eps)`` or ``1 / (alpha (p + eps))`` (Algorithm 1, step 2).

Internal pressure (cc.Eq. 25): ``eos="tait"``, ``P = rho0 c0^2/gamma ((rho/rho0)^gamma - 1)``, or
``eos="isothermal"``, ``P = c0^2 rho``. Densities by summation (Eq. 1, self term included), with
a fixed support ``h``, an annealed one (set by the driver), or adaptive ``H_a`` with
``rho_a H_a^d = m eta^d`` (Sec. 4, "spatially-varying h"; grad-h terms Omega from
:mod:`ase_sphrelax.sph`), or by the continuity equation (cc.Eq. 28) with the density
diffusion of Eq. 29 (Algorithm 1 step 1, second form; the driver integrates it).

Viscosity: ``"linear"`` is Eq. 6 exactly (Monaghan 1992): for approaching pairs
``f_a = sum_b m eta_ab (v_ab . r_ab)/(r^2 + eps h^2) grad_a W``, ``eta_ab = 2 alpha_v h c0/(rho_a + rho_b)``;
``"laplacian"`` is Eq. 5b, ``nu sum_b m/rho_b (v_b - v_a) lap W``, with the Brookshaw/Morris
Laplacian ``lap W ~ 2 W'(r)/r`` (the literal second derivative of a bell-shaped kernel is negative
at r = 0 and would amplify the velocity differences of close pairs); ``"none"``. Both viscosities
are pairwise antisymmetric (they conserve momentum) and dissipative. Eq. 8's regularisation
``f_a = -c_reg sum_b m grad_a W_ab / (rho_a + eps)`` (written with the sign that repels, as the
text intends).

The stationary state (derived in :mod:`ase_sphrelax.sampling.theory`): with the score force and
a barotropic EOS the dynamics is damped motion in the energy

    ``E = sum_a m u(rho_a) - alpha sum_a m log p(x_a)``,  ``u'(rho) = P/rho^2``,

whose continuum minimiser has ``w(rho) = alpha log p + const`` (``w = int dP / rho`` the enthalpy): isothermal
``rho ∝ p^(alpha/c0^2)``, i.e. exactly p when ``alpha = c0^2``: that is the default.
The pressure formulations are not gradient systems (and depend on the unknown normalising
constant of p through P_ext); they are reported as non-conservative.

Neighbours: :class:`~ase_sphrelax.neighbors.NeighborList` cell lists for d <= 3 (positions
padded to three columns), :class:`~ase_sphrelax.tree_neighbors.TreeNeighborList` beyond.
The SPH sums are those of :mod:`ase_sphrelax.sph`; the two viscosities of the paper and the
regularisation, which it does not have, are pair functions of :mod:`ase_sphrelax.pairs` here.
"""
from __future__ import annotations

import copy
import math

import numba
import numpy as np
from numba.extending import overload

from .. import sph
from ..checks import check_positive
from ..kernels import KERNEL_NAMES, get_kernel, kernel_profile
from ..neighbors import NeighborList
from ..pairs import Output, PairInteraction
from ..tree_neighbors import TreeNeighborList

__all__ = ["CountingTarget", "ParVIModel", "ParVIEvaluation", "kernel_in_dim", "FORMULATIONS", "EOS_NAMES",
           "VISCOSITIES", "unit_ball_volume", "eta_for_neighbours"]

FORMULATIONS = ("force", "pressure-log", "pressure-inverse")
EOS_NAMES = ("isothermal", "tait")
VISCOSITIES = ("linear", "laplacian", "none")


def unit_ball_volume(d):
    """Volume of the unit ball in d dimensions, ``pi^(d/2) / Gamma(d/2 + 1)``."""
    return math.pi ** (d / 2) / math.gamma(d / 2 + 1)


def eta_for_neighbours(n_neighbours, d):
    """``eta`` of ``rho H^d = m eta^d`` for about ``n_neighbours`` particles inside the support H."""
    return (n_neighbours / unit_ball_volume(d)) ** (1.0 / d)


def kernel_in_dim(name, d):
    """The kernel ``name`` normalised in d dimensions (any d >= 1).

    For d <= 3 it is :func:`ase_sphrelax.kernels.get_kernel`; beyond, the 3D profile with
    ``sigma = 1 / (S_(d-1) int_0^1 f(q) q^(d-1) dq)``, ``S_(d-1) = 2 pi^(d/2) / Gamma(d/2)``.
    """
    if name not in KERNEL_NAMES:
        raise ValueError(f"kernel must be one of {KERNEL_NAMES}, got {name!r}")
    if d <= 3:
        return get_kernel(name, d)
    kernel = copy.copy(get_kernel(name, 3))
    kernel.dim = d
    surface = 2.0 * math.pi ** (d / 2) / math.gamma(d / 2)
    kernel.sigma = 1.0 / (surface * kernel._moment(d - 1))
    return kernel


# -- pair physics the shared SPH module does not have ---------------------------------------------
def scaled_row_difference(k, v_sc, a, b, d):
    """``k (v_b - v_a)`` as a tuple of ``len(d)`` components, inside numba code."""
    raise NotImplementedError  # numba only (see the overload)


@overload(scaled_row_difference, inline="always")
def _scaled_row_difference_overload(k, v_sc, a, b, d):
    n = len(d)
    source = ("def impl(k, v_sc, a, b, d):\n    return ("
              + "".join(f"k * (v_sc[b, {i}] - v_sc[a, {i}]), " for i in range(n)) + ")\n")
    namespace = {}
    exec(source, namespace)  # noqa: S102 (a fixed template unrolled over the tuple length)
    return namespace["impl"]


@numba.njit(cache=True, inline="always")
def _mean_support(a, b, h_s):
    """The pair's mean support ``H_ab``."""
    return 0.5 * (h_s[a] + h_s[b])


# The pair functions evaluate dW/dr <= 0 with H_ab as ``kernel_profile(r / hab)[1] sigma / hab^(kdim + 1)``
# (zero for r >= H_ab), the kernel bound per kernel by PairInteraction.
@numba.njit(cache=True, inline="always")
def _linear_viscosity_pair(a, b, r2, d, sigma, kdim, coeff, eps, m, h_s, rho_s, v_sc):
    """Eq. 6 for approaching pairs: F_a = m^2 eta_ab (v_ab . r_ab)/(r^2 + eps H^2) grad_a W,
    eta_ab = 2 alpha_v H_ab c0 / (rho_a + rho_b) (``coeff = alpha_v c0``; equal masses m)."""
    vr = 0.0  # v_ab . r_ab with r_ab = x_a - x_b = -d
    for c in range(len(d)):
        vr -= (v_sc[a, c] - v_sc[b, c]) * d[c]
    if r2 == 0.0 or vr >= 0.0:
        z = sph.scaled(0.0, d)
        return z, z, ()
    r = math.sqrt(r2)
    hab = _mean_support(a, b, h_s)
    slope = kernel_profile(r / hab)[1] * sigma / hab ** (kdim + 1)
    # grad_a W = slope (x_a - x_b)/r = -slope d / r
    k = -m * m * 2.0 * coeff * hab / (rho_s[a] + rho_s[b]) * vr / (r2 + eps * hab * hab) * slope / r
    return sph.scaled(k, d), sph.scaled(-k, d), ()


@numba.njit(cache=True, inline="always")
def _laplacian_viscosity_pair(a, b, r2, d, sigma, kdim, nu, eps, m, h_s, rho_s, v_sc):
    """Eq. 5b with the Brookshaw/Morris Laplacian 2 W'(r) r / (r^2 + eps H^2):
    F_a = m^2 nu 2/(rho_a + rho_b) (v_b - v_a) (-lap W), antisymmetric (mean density; equal masses m)."""
    if r2 == 0.0:
        z = sph.scaled(0.0, d)
        return z, z, ()
    r = math.sqrt(r2)
    hab = _mean_support(a, b, h_s)
    slope = kernel_profile(r / hab)[1] * sigma / hab ** (kdim + 1)
    k = -nu * m * m * 2.0 / (rho_s[a] + rho_s[b]) * 2.0 * slope * r / (r2 + eps * hab * hab)  # >= 0
    fa = scaled_row_difference(k, v_sc, a, b, d)
    return fa, sph.scaled(-1.0, fa), ()


@numba.njit(cache=True, inline="always")
def _regularisation_pair(a, b, r2, d, sigma, kdim, c_reg, eps, m, h_s, rho_s):
    """a gathers Eq. 8 with the repulsive sign: F_a = -c m sum_b m grad_a W_ab / (rho_a + eps) (equal masses m)."""
    if r2 == 0.0:
        return sph.scaled(0.0, d), ()
    r = math.sqrt(r2)
    hab = _mean_support(a, b, h_s)
    slope = kernel_profile(r / hab)[1] * sigma / hab ** (kdim + 1)
    # grad_a W = -slope d / r, so F_a = c m_a m_b slope d / (r (rho_a + eps)) (points away from b)
    k = c_reg * m * m * slope / (r * (rho_s[a] + eps))
    return sph.scaled(k, d), ()


# name: (pair function, its coefficient's name, symmetric). The particles' common mass m is a parameter, not a
# per-particle input: one gathered array fewer per pair sum (the products are the same, m_a m_b = m m).
_PAIRS = {"linear": (_linear_viscosity_pair, "coeff", True), "laplacian": (_laplacian_viscosity_pair, "nu", True),
          "regularisation": (_regularisation_pair, "c_reg", False)}
_INTERACTIONS: dict = {}


def _interaction(name, dim_points):
    key = (name, dim_points)
    if key not in _INTERACTIONS:
        pair, coefficient, symmetric = _PAIRS[name]
        inputs = ("h_s", "rho_s") + (("v_sc",) if symmetric else ())
        _INTERACTIONS[key] = PairInteraction(pair, dict(forces=Output((dim_points,))),
                                             params=("sigma", "kdim", coefficient, "eps", "m"), inputs=inputs,
                                             symmetric=symmetric, dim=dim_points)
    return _INTERACTIONS[key]


# -- the target, counted ------------------------------------------------------------------------
class CountingTarget:
    """Wraps vectorised ``log_density`` / ``score`` callables, checks their output and counts calls per point.

    Parameters
    ----------
    log_density, score : callable or None
        (M, d) -> (M,) and (M, d) -> (M, d). At least one must be given.
    dim : int
    fd_step : float
        Relative step of the central differences used for the score when only the
        log-density is given (2 d density evaluations per point, counted).
    """

    def __init__(self, log_density=None, score=None, dim=None, fd_step=1e-5):
        if log_density is None and score is None:
            raise ValueError("log_density, score: give at least one (vectorised callables)")
        for name, fn in (("log_density", log_density), ("score", score)):
            if fn is not None and not callable(fn):
                raise TypeError(f"{name} must be a callable (M, d) -> ..., got {type(fn).__name__}")
        self._log_density = log_density
        self._score = score
        self.dim = dim
        self.fd_step = fd_step
        self.n_density = 0
        self.n_score = 0

    @property
    def has_density(self):
        return self._log_density is not None

    @property
    def has_score(self):
        return self._score is not None

    def log_density(self, x_pc):
        """log p at the points (M,); -inf allowed (zero density), NaN and +inf are errors."""
        if self._log_density is None:
            raise ValueError("log_density: this formulation needs the log-density, but only a score was given")
        out = np.asarray(self._log_density(x_pc), dtype=float)
        self.n_density += x_pc.shape[0]
        if out.shape != (x_pc.shape[0],):
            raise ValueError(f"log_density must return shape ({x_pc.shape[0]},) for {x_pc.shape[0]} points, "
                             f"got {out.shape}")
        bad = np.isnan(out) | (out == np.inf)
        if np.any(bad):
            raise ValueError(f"log_density returned NaN or +inf at {int(bad.sum())} points, e.g. x = "
                             f"{x_pc[np.argmax(bad)].tolist()}")
        return out

    def score(self, x_pc):
        """grad log p at the points (M, d); must be finite."""
        if self._score is None:
            return self._fd_score(x_pc)
        out = np.asarray(self._score(x_pc), dtype=float)
        self.n_score += x_pc.shape[0]
        if out.shape != x_pc.shape:
            raise ValueError(f"score must return shape {x_pc.shape} for points of shape {x_pc.shape}, got {out.shape}")
        bad = ~np.all(np.isfinite(out), axis=1)
        if np.any(bad):
            raise ValueError(f"score returned NaN or inf at {int(bad.sum())} points, e.g. x = "
                             f"{x_pc[np.argmax(bad)].tolist()}")
        return out

    def fd_score_or_nan(self, x_pc):
        """Central differences of the log-density (2 d evaluations per point); NaN rows where
        log p is -inf at a stencil point (zero density)."""
        m, d = x_pc.shape
        step_pc = self.fd_step * np.maximum(1.0, np.abs(x_pc))
        g_pc = np.empty_like(x_pc)
        for c in range(d):
            xp, xm = x_pc.copy(), x_pc.copy()
            xp[:, c] += step_pc[:, c]
            xm[:, c] -= step_pc[:, c]
            lp, lm = self.log_density(xp), self.log_density(xm)
            with np.errstate(invalid="ignore"):
                g_pc[:, c] = (lp - lm) / (2.0 * step_pc[:, c])
        g_pc[~np.all(np.isfinite(g_pc), axis=1)] = np.nan
        return g_pc

    def _fd_score(self, x_pc):
        g_pc = self.fd_score_or_nan(x_pc)
        bad = ~np.all(np.isfinite(g_pc), axis=1)
        if np.any(bad):
            raise ValueError(f"score by finite differences of log_density is not finite at {int(bad.sum())} points "
                             f"(log_density -inf nearby), e.g. x = {x_pc[np.argmax(bad)].tolist()}")
        return g_pc


# -- the model ------------------------------------------------------------------------------------
class ParVIEvaluation:
    """One evaluation of the SPH-ParVI forces at positions (and velocities).

    Attributes
    ----------
    forces : ndarray (M, d)
        ``m dv/dt`` from pressure, body force, viscosity and regularisation (friction, a
        driver's term, is not included).
    rho, h, pressure : ndarray (M,)
        Densities, supports and total pressures (internal plus external).
    log_p : ndarray (M,) or None
        log-density at the particles, where it was evaluated.
    energy : float or None
        ``sum m u(rho) - alpha sum m log p`` when the configuration is conservative and
        the log-density is known.
    accel_max : float
        Largest acceleration, for the CFL step.
    sound_speed : float
        Largest sound speed ``sqrt(dP/drho)``.
    sound_speed_p : ndarray (M,)
        Each particle's sound speed (for the per-particle steps of :meth:`ParVIModel.cfl_steps`).
    fallback : int
        Particles whose score was replaced by the zero-density pull (see ParVIModel).
    """

    def __init__(self, **kwargs):
        self.__dict__.update(kwargs)


class ParVIModel:
    """SPH-ParVI forces for M particles in d dimensions (see the module docstring).

    Parameters
    ----------
    target : CountingTarget
        The log-density and/or score (counted per point).
    dim : int
        Dimension d >= 1.
    formulation : {"force", "pressure-log", "pressure-inverse"}
    eos : {"isothermal", "tait"}
    alpha : float
        Amplification of the target (score force ``alpha grad log p``, or ``P_ext``).
    c0 : float
        Sound speed of the EOS (and of the linear viscosity).
    rho0 : float or None
        Tait reference density (default: the mean summation density of the first evaluation).
    gamma : float
        Tait exponent.
    kernel : str
        A kernel of :mod:`ase_sphrelax.kernels` (normalised in d dimensions).
    h : float or "adaptive"
        Kernel support: a fixed number (also for annealing: the driver calls :meth:`set_h`),
        or "adaptive" for ``rho_a H_a^d = m eta^d`` with grad-h terms.
    n_neighbours : float
        Adaptive H: about this many particles inside each support (sets ``eta``).
    viscosity : {"linear", "laplacian", "none"}
        Eq. 6 with ``viscosity_alpha`` (0.08-0.5 in the paper) or Eq. 5b with ``nu``.
    regularisation : float
        Coefficient of Eq. 8 (0: off).
    density : {"summation", "continuity"}
        Summation (Eq. 1) or the driver's continuity integration (cc.Eq. 28 with Eq. 29
        diffusion ``diffusion``); continuity needs a fixed h.
    eps : float
        The ``epsilon`` of ``log(p + eps)``, ``1/(alpha (p + eps))`` and Eq. 8.
    mass : float or None
        Particle mass (default 1/M: the densities then estimate the normalised p).
    """

    def __init__(self, target, dim, formulation="force", eos="isothermal", alpha=1.0, c0=1.0, rho0=None, gamma=7.0,
                 kernel="wendland_c2", h="adaptive", n_neighbours=None, viscosity="linear", viscosity_alpha=0.1,
                 nu=0.05, regularisation=0.0, density="summation", diffusion=0.1, eps=1e-10, mass=None):
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 1:
            raise ValueError(f"dim must be an integer >= 1, got {dim!r}")
        if formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {FORMULATIONS}, got {formulation!r}")
        if eos not in EOS_NAMES:
            raise ValueError(f"eos must be one of {EOS_NAMES}, got {eos!r}")
        if viscosity not in VISCOSITIES:
            raise ValueError(f"viscosity must be one of {VISCOSITIES}, got {viscosity!r}")
        if density not in ("summation", "continuity"):
            raise ValueError(f"density must be 'summation' or 'continuity', got {density!r}")
        if not (isinstance(h, str) and h == "adaptive"):
            check_positive("h", h)
        elif density == "continuity":
            raise ValueError("density='continuity' needs a fixed h (a number), got h='adaptive'")
        if formulation != "force" and not target.has_density:
            raise ValueError(f"formulation={formulation!r} needs log_density (the external pressure is made of p)")
        self.target = target
        self.dim = int(dim)
        self.formulation = formulation
        self.eos = eos
        self.alpha = check_positive("alpha", alpha)
        self.c0 = check_positive("c0", c0)
        self.rho0 = check_positive("rho0", rho0, allow_none=True)
        self.gamma = check_positive("gamma", gamma)
        self.kernel = kernel_in_dim(kernel, self.dim)
        self.adaptive = isinstance(h, str)
        self.h = None if self.adaptive else float(h)
        self.n_neighbours_given = check_positive("n_neighbours", n_neighbours, allow_none=True)
        self.n_neighbours = self.n_neighbours_given or self.default_neighbours()
        self.eta = eta_for_neighbours(self.n_neighbours, self.dim)
        self.viscosity = viscosity
        self.viscosity_alpha = float(viscosity_alpha)
        self.nu = float(nu)
        if self.viscosity_alpha < 0 or self.nu < 0:
            raise ValueError(f"viscosity_alpha and nu must be >= 0, got {viscosity_alpha!r}, {nu!r}")
        self.regularisation = float(regularisation)
        if not math.isfinite(self.regularisation) or self.regularisation < 0:
            raise ValueError(f"regularisation must be a finite number >= 0, got {regularisation!r}")
        self.density = density
        self.diffusion = float(diffusion)
        self.eps = check_positive("eps", eps)
        self.mass = check_positive("mass", mass, allow_none=True)
        self.nlist = None
        self.h_tol = 1e-8  # relative tolerance of the adaptive H solve
        self._h_p = None
        self._x_pc = None  # the padded positions (_positions)
        self._cell = np.zeros((3, 3))
        self._pbc = np.zeros(3, dtype=bool)

    # -- properties ---------------------------------------------------------------------
    @property
    def conservative(self):
        """True when the forces are minus the gradient of :attr:`ParVIEvaluation.energy`
        (score force, barotropic EOS, summation density, no viscosity at rest, no Eq. 8)."""
        return self.formulation == "force" and self.density == "summation" and self.regularisation == 0.0

    def minimum_neighbours(self):
        """The fewest neighbours an adaptive support can hold: ``eta^d > sigma f(0)`` (the particle's own
        kernel weight), with a 20 % margin. In d dimensions a compact kernel puts its weight near the
        centre of a ball whose volume sits near the rim: the bound grows fast (Wendland C2: 1.5 in 2D,
        about 330 in 10-D, about 1e4 in 32-D)."""
        return 1.2 * self.kernel.sigma * self.kernel.f0 * unit_ball_volume(self.dim)

    def default_neighbours(self):
        """Default ``n_neighbours``: 8 (1D), 32 (2D), 44 (3D); beyond, 8 d + 20 or twice the self-weight bound."""
        if self.dim <= 3:
            return {1: 8.0, 2: 32.0, 3: 44.0}[self.dim]
        return max(8.0 * self.dim + 20.0, 2.0 * self.minimum_neighbours() / 1.2)

    def _eta_for(self, m):
        """eta for M particles: the default neighbour number is capped at M / 2 (small M); a number of
        neighbours that M cannot hold, or below the self-weight bound, is an error."""
        need = self.minimum_neighbours()
        n = self.n_neighbours_given if self.n_neighbours_given is not None else min(self.n_neighbours, 0.5 * m)
        if n > m - 1 or n < need:
            raise ValueError(
                f"n: adaptive h in {self.dim}-D with {m} particles cannot hold {n:.4g} neighbours per support "
                f"(needs at least {need:.4g}, the kernel's self weight, and at most M - 1); use at least "
                f"{int(2 * need) + 1} particles, a fixed h, or another n_neighbours")
        return eta_for_neighbours(n, self.dim)

    def set_h(self, h):
        """Change the fixed support (annealing)."""
        if self.adaptive:
            raise ValueError("set_h: this model has adaptive smoothing lengths")
        self.h = check_positive("h", h)

    def _points(self, r_pc):
        """Positions in the layout of the neighbour object: (M, 3) padded for d <= 3, (M, d) beyond."""
        if self.dim > 3:
            return np.ascontiguousarray(r_pc, dtype=float)
        out = np.zeros((r_pc.shape[0], 3))
        out[:, : self.dim] = r_pc
        return out

    def _positions(self, r_pc):
        """:meth:`_points` of the positions, written into one buffer kept between calls for d <= 3 (the neighbour
        list copies what it keeps): not a fresh (M, 3) array twice per evaluation."""
        if self.dim > 3:
            return self._points(r_pc)
        if self._x_pc is None or self._x_pc.shape[0] != r_pc.shape[0]:
            self._x_pc = None
            self._x_pc = np.zeros((r_pc.shape[0], 3))
        self._x_pc[:, : self.dim] = r_pc
        return self._x_pc

    def _neighbours(self, reach):
        if self.nlist is None:
            skin = 0.2 * reach
            self.nlist = NeighborList(reach, skin=skin) if self.dim <= 3 else TreeNeighborList(reach, skin=skin)
        return self.nlist

    def particle_mass(self, m):
        return self.mass if self.mass is not None else 1.0 / m

    # -- pieces ---------------------------------------------------------------------------
    def densities(self, r_pc):
        """(rho (M,), h (M,), omega (M,)) by summation, with fixed or adaptive support."""
        m = r_pc.shape[0]
        x = self._positions(r_pc)
        mass = self.particle_mass(m)
        if self.adaptive:
            guess = self._h_p is None or self._h_p.shape[0] != m
            if guess:
                spread = np.sqrt(np.mean(np.var(r_pc, axis=0))) or 1.0
                # twice the spacing of a uniform ball of radius 2 spread: a guess from above, where the
                # Newton steps on H are safe (below, a first particle just outside H gives dg ~ 0 and a huge step)
                self._h_p = np.full(m, 2.0 * self._eta_for(m) * spread
                                    * (unit_ball_volume(self.dim) * 2.0 ** self.dim / m) ** (1.0 / self.dim))
            nlist = self._neighbours(float(np.median(self._h_p)))
            try:
                eta = self._eta_for(m)
                # from the guess (H well above the root) the sums scan the bins without a Verlet list: a list of
                # the guess's pairs (about 3.5 times the converged one's) set the run's peak memory and was walked
                # until the particles left its skin; the next update builds the list at the converged H. The sums
                # are the same but taken in the bins' order: this evaluation's H, rho and forces change in the
                # last bit (1e-15 relative), far below the H solve's own tolerance (h_tol)
                sums = sph.solve_smoothing_lengths(nlist, x, self._cell, self._pbc, mass, self.kernel, eta=eta,
                                                   h0=self._h_p, tol=self.h_tol, store=not guess)
            except sph.SmoothingLengthError as exc:
                raise ValueError(f"n_neighbours: {exc}") from None
            self._h_p = sums.h_p
            return sums.rho_p, sums.h_p, sums.omega_p
        nlist = self._neighbours(self.h)
        nlist.update(x, self._cell, self._pbc, cutoff=self.h)
        sums = sph.density_sums(nlist, x, mass, self.h, self.kernel)
        return sums.rho_p, sums.h_p, np.ones(m)

    def internal_pressure(self, rho_p):
        """P_int and the squared sound speed dP/drho (cc.Eq. 25 or isothermal)."""
        if self.eos == "isothermal":
            return sph.isothermal_pressure(rho_p, self.c0**2), np.full_like(rho_p, self.c0**2)
        pressure = sph.tait_pressure(rho_p, self.rho0, self.c0, self.gamma)
        return pressure, self.c0**2 * (rho_p / self.rho0) ** (self.gamma - 1.0)

    def internal_energy(self, rho_p):
        """u(rho) with u' = P/rho^2: ``c0^2 log rho`` or ``B (rho^(g-1)/((g-1) rho0^g) + 1/rho)``."""
        if self.eos == "isothermal":
            return self.c0**2 * np.log(rho_p)
        b = self.rho0 * self.c0**2 / self.gamma
        g = self.gamma
        return b * ((rho_p / self.rho0) ** (g - 1.0) / ((g - 1.0) * self.rho0) + 1.0 / rho_p)

    def external_pressure(self, log_p):
        """P_ext of Algorithm 1: ``-alpha log(p + eps)`` or ``1/(alpha (p + eps))``; finite for log p = -inf."""
        if self.formulation == "pressure-log":
            return -self.alpha * np.logaddexp(log_p, math.log(self.eps))
        return 1.0 / (self.alpha * (np.exp(np.minimum(log_p, 700.0)) + self.eps))

    def body_score(self, r_pc):
        """grad log p at the particles (M, d) and the number of zero-density fallbacks.

        With only a log-density, the score is a central difference; where it is not finite
        (log p = -inf at or next to the particle: zero density far from the mass) the particle
        is pulled towards the centroid of the particles that see a finite score, with the
        largest finite score's magnitude, so that it returns into the support and stays finite.
        """
        if self.target.has_score:
            return self.target.score(r_pc), 0
        g_pc = self.target.fd_score_or_nan(r_pc)
        if np.all(np.isfinite(g_pc)):
            return g_pc, 0
        bad = ~np.all(np.isfinite(g_pc), axis=1)
        if bad.all():
            raise ValueError("log_density is -inf (zero density) at and around every particle: no score to follow; "
                             "start the particles where p > 0")
        centre = r_pc[~bad].mean(axis=0)
        magnitude = np.linalg.norm(g_pc[~bad], axis=1).max()
        pull = centre - r_pc[bad]
        norm = np.linalg.norm(pull, axis=1, keepdims=True)
        g_pc[bad] = magnitude * pull / np.where(norm > 0, norm, 1.0)
        return g_pc, int(bad.sum())

    # -- evaluation -------------------------------------------------------------------------
    def evaluate(self, r_pc, v_pc=None, rho_p=None, want_energy=False):
        """Forces at positions ``r_pc`` (M, d), velocities ``v_pc`` (for viscosity) and, with
        continuity densities, the integrated ``rho_p``."""
        r_pc = np.asarray(r_pc, dtype=float)
        if r_pc.ndim != 2 or r_pc.shape[1] != self.dim:
            raise ValueError(f"positions must have shape (M, {self.dim}), got {r_pc.shape}")
        m = r_pc.shape[0]
        if m < 2:
            raise ValueError(f"n: SPH-ParVI needs at least 2 particles, got {m}")
        if not np.all(np.isfinite(r_pc)):
            bad = np.nonzero(~np.all(np.isfinite(r_pc), axis=1))[0]
            raise ValueError(f"positions must be finite; particles {bad[:10].tolist()} are not")
        mass = self.particle_mass(m)
        rho_sum, h_p, omega_p = self.densities(r_pc)
        if self.density == "continuity" and rho_p is not None:
            rho = np.asarray(rho_p, dtype=float)
        else:
            rho = rho_sum
        if self.eos == "tait" and self.rho0 is None:
            self.rho0 = float(np.mean(rho))
        p_int, cs2 = self.internal_pressure(rho)
        pressure = p_int
        log_p = None
        if self.formulation != "force" or (want_energy and self.target.has_density):
            log_p = self.target.log_density(r_pc)
        if self.formulation != "force":
            pressure = p_int + self.external_pressure(log_p)
        x = self._positions(r_pc)
        # dims: the pairs see the d coordinates (the padding's zeros add nothing), and the forces come as (M, d)
        f_pc, _ = sph.pressure_forces(self.nlist, x, mass, h_p, pressure / (omega_p * rho * rho), self.kernel,
                                      dims=self.dim)
        f_pc = np.ascontiguousarray(f_pc[:, : self.dim])  # a fresh array (the pair sum's output): no copy
        fallback = 0
        if self.formulation == "force":
            g_pc, fallback = self.body_score(r_pc)
            f_pc += self.alpha * mass * g_pc
        if v_pc is not None and self.viscosity != "none":
            f_pc += self._viscosity(x, np.ascontiguousarray(v_pc, dtype=float), mass, h_p, rho)
        if self.regularisation > 0.0:
            out = _interaction("regularisation", self.dim).compute(
                self.nlist, x, params=self._pair_params("regularisation", self.regularisation, mass),
                inputs=dict(h_s=h_p, rho_s=rho), reach=float(h_p.max()), kernel=self.kernel)
            f_pc += out.forces
        if hasattr(self.nlist, "release_gathered"):
            self.nlist.release_gathered()  # the pair sums' gathered inputs: not held through the next step's H solve
        energy = None
        if want_energy and self.conservative and log_p is not None:
            energy = float(mass * self.internal_energy(rho).sum() - self.alpha * mass * log_p.sum())
        accel = np.sqrt(np.einsum("pc,pc->p", f_pc, f_pc)).max() / mass
        # isothermal: one sound speed for all, a read-only view rather than M copies
        sound_p = np.broadcast_to(np.sqrt(cs2[:1]), cs2.shape) if self.eos == "isothermal" else np.sqrt(cs2)
        return ParVIEvaluation(forces=f_pc, rho=rho, rho_summation=rho_sum, h=h_p, pressure=pressure, log_p=log_p,
                               energy=energy, accel_max=float(accel), sound_speed=float(np.sqrt(cs2.max())),
                               sound_speed_p=sound_p, fallback=fallback, mass=mass)

    def _pair_params(self, name, coefficient, mass):
        """The parameters of the pair function ``name`` (:data:`_PAIRS`) by name; ``mass`` the particles' mass."""
        return {"sigma": float(self.kernel.sigma), "kdim": float(self.kernel.dim), _PAIRS[name][1]: float(coefficient),
                "eps": 0.01, "m": float(mass)}

    def _viscosity(self, x, v, mass, h_p, rho):
        """The viscous forces (M, d) at the padded positions ``x`` and the velocities ``v`` (M, d)."""
        coefficient = self.viscosity_alpha * self.c0 if self.viscosity == "linear" else self.nu
        out = _interaction(self.viscosity, self.dim).compute(
            self.nlist, x, params=self._pair_params(self.viscosity, coefficient, mass),
            inputs=dict(h_s=h_p, rho_s=rho, v_sc=v), reach=float(h_p.max()), kernel=self.kernel)
        return out.forces

    def density_rate(self, r_pc, v_pc, rho_p):
        """drho/dt of the continuity equation with Eq. 29 diffusion (fixed h; call after :meth:`evaluate`)."""
        x = self._points(r_pc)
        return sph.continuity_rate(self.nlist, x, self._points(v_pc), self.particle_mass(r_pc.shape[0]), self.h,
                                   rho_p, self.kernel, diffusion=self.diffusion, c0=self.c0)

    def cfl_step(self, evaluation, courant=1.0):
        """Eq. 9 in its dimensionally consistent form (Becker and Teschner 2007, Monaghan 1992):
        ``min(0.25 sqrt(h_s / a_max), 0.4 h_s / (c_s (1 + 0.6 alpha_v)))`` with the smoothing
        length ``h_s = H/2`` (the paper's h; our H is the support) and ``a_max`` the largest
        acceleration (the paper writes ``h/|f_min|``: not a time, and the smallest force would
        give the largest step)."""
        h_s = 0.5 * float(evaluation.h.min())
        a = max(evaluation.accel_max, 1e-300)
        alpha_v = self.viscosity_alpha if self.viscosity == "linear" else 0.0
        return courant * min(0.25 * math.sqrt(h_s / a), 0.4 * h_s / (evaluation.sound_speed * (1.0 + 0.6 * alpha_v)))

    def cfl_steps(self, evaluation, courant=1.0):
        """Each particle's own step (M,): :meth:`cfl_step`'s Eq. 9 with the particle's smoothing length
        ``h_s = H_a/2``, acceleration ``|f_a| / m`` and sound speed instead of the ensemble's extremes
        (the local time steps of ``time_step="local"``; theory.py, eqs. L1-L3). Never below
        :meth:`cfl_step` (which combines the smallest H with the largest acceleration)."""
        h_s_p = 0.5 * np.asarray(evaluation.h, dtype=float)
        accel_p = np.maximum(np.sqrt(np.einsum("pc,pc->p", evaluation.forces, evaluation.forces)) / evaluation.mass,
                             1e-300)
        alpha_v = self.viscosity_alpha if self.viscosity == "linear" else 0.0
        sound_p = np.broadcast_to(evaluation.sound_speed_p, h_s_p.shape)
        return courant * np.minimum(0.25 * np.sqrt(h_s_p / accel_p), 0.4 * h_s_p / (sound_p * (1.0 + 0.6 * alpha_v)))
