"""SPH-ParVI with k-nearest-neighbour densities: a variant that runs in any dimension (issue 18, item 3).

The kernel-sum densities of :class:`~ase_sphrelax.models.parvi.ParVIModel` need a support that holds more
mass than the particle's own kernel weight, ``eta^d > sigma f(0)``: about 330 neighbours in 10-D and 1e4 in
32-D for Wendland C2 (a compact kernel puts its weight near the centre of a ball whose volume sits near the
rim). Here the density of particle a comes from the distances to its k nearest neighbours
``r_a(1) <= ... <= r_a(k)`` (k fixed, independent of d):

* (K1) ``log rho_a = C_k - log(M V_d) - (d / 2k) sum_{j<=k} log(r_a(j)^2 + delta^2 Hbar_a^2)``, with
  ``Hbar_a^2 = (1/k) sum_{j<=k} r_a(j)^2`` and particle mass ``m = 1/M``. For ``delta = 0`` it is the mean of the
  k Kozachenko-Leonenko log-density estimators ``psi(j) - log(M V_d r_a(j)^d)``, each unbiased for ``log rho``
  when the neighbours of a are a Poisson process of locally constant intensity ``M rho``
  (``M rho V_d r_a(j)^d ~ Gamma(j, 1)``, ``E log Gamma(j, 1) = psi(j)``): ``C_k = (1/k) sum_j psi(j)``. The
  softening ``delta`` (default 0.5) bounds the pair stiffness of close neighbours by ``1 / (delta Hbar)^2``;
  :func:`poisson_log_constant` gives ``C_k`` for it (Monte Carlo, fixed seed).

With the isothermal EOS (``u = c0^2 log rho``) and the score force, the energy of the default model,

* (K2) ``E = sum_a m c0^2 log rho_a - alpha sum_a m log p(x_a)
  = -(c0^2 m d / 2k) sum_a sum_{b in N_k(a)} log(r_ab^2 + delta^2 Hbar_a^2) - alpha m sum_a log p(x_a) + const``,

is a sum over the directed k-nearest-neighbour graph. The set ``N_k(a)`` changes when neighbours swap order,
but the sums over the k nearest (of continuous functions, equal at a swap) are continuous: E is continuous and
piecewise smooth, and the forces

* (K3) ``F_a = sum_{edges (a,b), (b,a)} w_ab (x_a - x_b) + alpha m grad log p(x_a)``,
  ``w_ab = (c0^2 m d / k) [1 / s_ab + (delta^2 / k) sum_{c in N_k(a)} 1 / s_ac]``, ``s_ab = r_ab^2 + delta^2 Hbar_a^2``

are its exact gradient wherever no particle's k-th and (k+1)-th neighbours are at equal distance (almost
everywhere; at such a swap the force jumps by one edge's weight, 1/k of the total). The internal forces are
pairwise antisymmetric (momentum is conserved). There is no kernel, no support to solve for and no self
weight: any ``1 <= k < M`` works in any d. The resting state is derived in :mod:`ase_sphrelax.sampling.theory`
(eqs. K4-K7). ``h`` reported is ``r_a(k)``; viscosity is not used (the sampler's friction damps the fluid).

:class:`KNNRatioParVIModel` (``neighbours="knn-ratio"``, eqs. R1-R5) estimates ``rho / p^beta`` instead of rho.

Neighbour search (:class:`KNNSearch`): a :class:`scipy.spatial.cKDTree` query of ``2k + 1`` points per particle
builds a candidate list; later evaluations measure the distances to the candidates only and keep the k nearest,
exact by a displacement bound, and rebuild where the bound fails. In 32-D at M = 2000 a kd-tree query is no
faster than brute force (``reproductions/parvi-highdim/README.md`` has the timing): the reuse is what keeps a
step O(M k d).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import digamma

from .parvi import ParVIEvaluation, unit_ball_volume

__all__ = ["KNNParVIModel", "KNNRatioParVIModel", "KNNSearch", "check_k", "check_knn_options", "knn_graph",
           "poisson_log_constant", "DEFAULT_K", "DEFAULT_SOFTENING", "DEFAULT_SHAPE"]

#: Default number of neighbours of ``neighbours="knn"``.
DEFAULT_K = 20
#: Weight lambda of the scale-free shape term of ``neighbours="knn-ratio"`` (eq. R5).
DEFAULT_SHAPE = 0.2
#: Default softening delta of eq. K1.
DEFAULT_SOFTENING = 0.5


def check_k(k, n):
    """``k`` as an int with ``1 <= k < n``; a one-line error naming ``k`` otherwise."""
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k must be an integer >= 1 (neighbours per particle), got {k!r}")
    if k >= n:
        raise ValueError(f"k must be smaller than the number of particles n = {n}, got k = {k}")
    return int(k)


def knn_graph(x_pc, k):
    """The k nearest neighbours of every point, itself excluded: ``(idx_pk, dist_pk)``, sorted by distance.

    One :class:`~scipy.spatial.cKDTree` query of ``k + 1`` points. A point that has exact copies may not be
    listed first among its own neighbours: the row's last column is then dropped instead.
    """
    m = x_pc.shape[0]
    dist_pk, idx_pk = cKDTree(x_pc).query(x_pc, k=k + 1)
    self_pk = idx_pk == np.arange(m)[:, None]
    self_pk[~self_pk.any(axis=1), -1] = True
    keep_pk = ~self_pk
    return idx_pk[keep_pk].reshape(m, k), dist_pk[keep_pk].reshape(m, k)


class KNNSearch:
    """The k nearest neighbours of moving points, exact at every call, with a candidate list reused between calls.

    A rebuild queries a :class:`~scipy.spatial.cKDTree` for ``k + extra`` candidates per point (``extra``
    defaults to k). Later calls compute the distances to the candidates only (O(M (k + extra) d)) and keep the k
    nearest; that is the true k-NN set as long as, for every point a, its k-th candidate distance now is at most
    ``r_a(k + extra)`` at the rebuild minus ``delta_a + max_b delta_b`` (``delta`` the displacements since the
    rebuild): every point outside the list was at least ``r_a(k + extra)`` away then and moved closer by at most
    that. Where this fails (or the number of points changes) the list is rebuilt. Ties may be ordered either way.
    """

    def __init__(self, k, extra=None):
        self.k = int(k)
        self.extra = self.k if extra is None else int(extra)
        self.x_build = None
        self.rebuilds = 0
        self.calls = 0

    def _rebuild(self, x_pc):
        m = x_pc.shape[0]
        width = min(self.k + self.extra, m - 1)
        self.cand_pk, self.reach_p = knn_graph(x_pc, width)
        # every other point a candidate: nothing outside the list can come closer
        self.reach_p = self.reach_p[:, -1] if width < m - 1 else np.full(m, np.inf)
        self.x_build = x_pc.copy()
        self.rebuilds += 1

    def query(self, x_pc):
        """``(idx_pk, dist_pk)``: the k nearest neighbours of every point (itself excluded), sorted by distance."""
        self.calls += 1
        if self.x_build is None or self.x_build.shape != x_pc.shape:
            self._rebuild(x_pc)
        moved_p = np.sqrt(np.einsum("pc,pc->p", x_pc - self.x_build, x_pc - self.x_build))
        idx_pk, dist_pk = self._nearest_candidates(x_pc)
        if np.any(dist_pk[:, -1] > self.reach_p - moved_p - moved_p.max()):
            self._rebuild(x_pc)
            idx_pk, dist_pk = self._nearest_candidates(x_pc)
        return idx_pk, dist_pk

    def _nearest_candidates(self, x_pc):
        diff_pkc = x_pc[:, None, :] - x_pc[self.cand_pk]
        d_pk = np.sqrt(np.einsum("pkc,pkc->pk", diff_pkc, diff_pkc))
        if d_pk.shape[1] > self.k:
            part_pk = np.argpartition(d_pk, self.k - 1, axis=1)[:, : self.k]
            d_pk = np.take_along_axis(d_pk, part_pk, axis=1)
            cand_pk = np.take_along_axis(self.cand_pk, part_pk, axis=1)
        else:
            cand_pk = self.cand_pk
        order_pk = np.argsort(d_pk, axis=1, kind="stable")
        return np.take_along_axis(cand_pk, order_pk, axis=1), np.take_along_axis(d_pk, order_pk, axis=1)


class KNNParVIModel:
    """SPH-ParVI forces with k-nearest-neighbour densities (the module docstring, eqs. K1-K3).

    Same interface as :class:`~ase_sphrelax.models.parvi.ParVIModel` for
    :class:`~ase_sphrelax.sampling.sampler.ParVISampler`: :meth:`evaluate`, :meth:`cfl_step`,
    :meth:`cfl_steps`.

    Parameters
    ----------
    target : CountingTarget
    dim : int
    k : int
        Neighbours per particle, ``1 <= k < M`` (checked by :meth:`evaluate` and by the sampler).
    alpha, c0 : float
        Score-force amplification and isothermal sound speed (stationary density ``p^(alpha/c0^2)``).
    softening : float or None
        delta >= 0 of eq. K1 (None: :data:`DEFAULT_SOFTENING`): the distances enter as
        ``sqrt(r^2 + delta^2 Hbar_a^2)``, ``Hbar_a^2`` the mean square of the k neighbour distances.
    """

    #: the sampler's switches: no adaptive support to solve, summation densities, a gradient system
    adaptive = False
    density = "summation"
    conservative = True
    formulation = "force"
    eos = "isothermal"
    viscosity = "none"
    viscosity_alpha = 0.0

    def __init__(self, target, dim, k=DEFAULT_K, alpha=1.0, c0=1.0, softening=None):
        self.target = target
        self.dim = int(dim)
        self.k = check_k(k, k + 1)  # the particle number is checked at evaluate (and by the sampler)
        self.alpha = float(alpha)
        self.c0 = float(c0)
        self.softening = float(DEFAULT_SOFTENING if softening is None else softening)
        if not math.isfinite(self.softening) or self.softening < 0:
            raise ValueError(f"softening must be a finite number >= 0, got {softening!r}")
        self.n_neighbours = float(self.k)
        self.search = KNNSearch(self.k)
        self.log_bias = poisson_log_constant(self.k, self.dim, self.softening)

    def _checked_positions(self, r_pc):
        """``r_pc`` as a float (M, d) array; one-line errors for a wrong shape, ``k >= M`` or non-finite rows."""
        r_pc = np.asarray(r_pc, dtype=float)
        if r_pc.ndim != 2 or r_pc.shape[1] != self.dim:
            raise ValueError(f"positions must have shape (M, {self.dim}), got {r_pc.shape}")
        check_k(self.k, r_pc.shape[0])
        if not np.all(np.isfinite(r_pc)):
            bad = np.nonzero(~np.all(np.isfinite(r_pc), axis=1))[0]
            raise ValueError(f"positions must be finite; particles {bad[:10].tolist()} are not")
        return r_pc

    def log_density_estimate(self, dist_pk, m):
        """Eq. K1: ``log rho_a`` from the k sorted neighbour distances (M, k) of M particles."""
        r2_pk = dist_pk**2
        s_pk = r2_pk + self.softening**2 * r2_pk.mean(axis=1, keepdims=True)
        return self.log_bias - math.log(m * unit_ball_volume(self.dim)) - 0.5 * self.dim * np.mean(np.log(s_pk), axis=1)

    def internal_forces(self, r_pc, idx_pk):
        """Eq. K3 without the score, and each particle's pair stiffness per unit mass (the sum of its in- and
        out-edges' weights, for the step). ``idx_pk`` sorted by distance: its last column is the k-th neighbour."""
        m_particles, k = idx_pk.shape
        diff_pkc = r_pc[:, None, :] - r_pc[idx_pk]
        r2_pk = np.einsum("pkc,pkc->pk", diff_pkc, diff_pkc)
        s_pk = r2_pk + self.softening**2 * r2_pk.mean(axis=1, keepdims=True)
        if not np.all(s_pk > 0):
            raise ValueError("positions: a particle coincides with its k nearest neighbours (infinite pair energy)")
        coeff = self.c0**2 * self.dim / (k * m_particles)  # c0^2 m d / k with m = 1 / M
        w_pk = coeff / s_pk
        w_pk += (self.softening**2 / k) * w_pk.sum(axis=1, keepdims=True)  # through the mean square distance (K3)
        f_pkc = w_pk[:, :, None] * diff_pkc
        f_pc = f_pkc.sum(axis=1)
        flat = idx_pk.ravel()
        for c in range(self.dim):
            f_pc[:, c] -= np.bincount(flat, weights=f_pkc[:, :, c].ravel(), minlength=m_particles)
        stiff_p = (w_pk.sum(axis=1) + np.bincount(flat, weights=w_pk.ravel(), minlength=m_particles)) * m_particles
        return f_pc, stiff_p

    def evaluate(self, r_pc, v_pc=None, rho_p=None, want_energy=False):
        """Forces (eq. K3), densities (eq. K1) and, with ``want_energy`` and a log-density, the energy (eq. K2)
        at positions ``r_pc`` (M, d). ``v_pc`` and ``rho_p`` are accepted for the sampler's interface and unused."""
        r_pc = self._checked_positions(r_pc)
        m_particles = r_pc.shape[0]
        mass = 1.0 / m_particles
        idx_pk, dist_pk = self.search.query(r_pc)
        f_pc, stiff_p = self.internal_forces(r_pc, idx_pk)
        g_pc = self.target.score(r_pc)
        f_pc += self.alpha * mass * g_pc
        log_rho_p = self.log_density_estimate(dist_pk, m_particles)
        rho_p = np.exp(log_rho_p)
        log_p, energy = None, None
        if want_energy and self.target.has_density:
            log_p = self.target.log_density(r_pc)
            energy = float(mass * (self.c0**2 * log_rho_p.sum() - self.alpha * log_p.sum()))
        accel_p = np.sqrt(np.einsum("pc,pc->p", f_pc, f_pc)) / mass
        return ParVIEvaluation(forces=f_pc, rho=rho_p, rho_summation=rho_p, h=dist_pk[:, -1].copy(),
                               pressure=self.c0**2 * rho_p, log_p=log_p, energy=energy,
                               accel_max=float(accel_p.max()), sound_speed=self.c0,
                               sound_speed_p=np.full(m_particles, self.c0), fallback=0, mass=mass,
                               stiffness_p=stiff_p,
                               nearest_p=np.sqrt(dist_pk[:, 0] ** 2 + self.softening**2 * np.mean(dist_pk**2, axis=1)))

    def cfl_steps(self, evaluation, courant=1.0):
        """Each particle's step (M,): ``min(0.25 sqrt(l_a / a_a), 1 / omega_a)``, ``l_a`` the softened nearest
        distance ``sqrt(r_a(1)^2 + delta^2 H_a^2)``, ``a_a`` the acceleration and ``omega_a^2`` the sum of the pair
        weights of eq. K3 per unit mass (a bound on the fastest pair frequency: leapfrog is stable below
        ``2 / omega``)."""
        accel_p = np.maximum(np.sqrt(np.einsum("pc,pc->p", evaluation.forces, evaluation.forces)) / evaluation.mass,
                             1e-300)
        return courant * np.minimum(0.25 * np.sqrt(evaluation.nearest_p / accel_p),
                                    1.0 / np.sqrt(evaluation.stiffness_p))

    def cfl_step(self, evaluation, courant=1.0):
        """One step for all particles: :meth:`cfl_steps` with the smallest length, largest acceleration and
        largest stiffness."""
        a = max(evaluation.accel_max, 1e-300)
        return courant * min(0.25 * math.sqrt(float(evaluation.nearest_p.min()) / a),
                             1.0 / math.sqrt(float(evaluation.stiffness_p.max())))


class KNNRatioParVIModel(KNNParVIModel):
    """SPH-ParVI with a k-nearest-neighbour estimate of the ratio ``rho / p^beta`` (``neighbours="knn-ratio"``,
    theory.py eqs. R1-R4), ``beta = alpha / c0^2``.

    * (R1) ``g_a = sum_{b in {a} + N_k(a)} f(s_ab) q_b / (M V_d H_a^d (k + 1) / 2)``, ``q_b = p(x_b)^(-beta)``,
      ``s_ab = (r_ab / H_a)^d`` (the volume fraction of a's ball inside r_ab), ``f(s) = 1 - s``, ``H_a = r_a(k)``
      (the particle itself, ``s = 0``, included: every particle then feels its own score);
    * (R2) ``E = c0^2 m sum_a log g_a`` (the fluid's free energy ``int rho log(rho / p^beta)``, estimated);
    * (R3) the forces are its exact gradient: pair terms through ``s_ab`` and ``H_a`` and, on every neighbour b,
      the score force ``alpha m W_b grad log p(x_b)``, ``W_b = sum_a pi_ab f(s_ab)`` the weight b carries in its
      neighbours' estimates (``pi_ab = q_b / sum_c f(s_ac) q_c``).

    Where the kernel estimate of rho is smoothed over a's ball (a bias of order ``(H / L)^2``, large above
    3 dimensions), ``rho / p^beta`` is constant at the resting state ``rho ∝ p^beta``, so smoothing it is exact
    there: the continuum minimiser has no smoothing bias (theory.py eq. R4). Needs the log-density (one evaluation
    per particle per step besides the score) and ``k >= 2``.
    """

    def __init__(self, target, dim, k=DEFAULT_K, alpha=1.0, c0=1.0):
        super().__init__(target, dim, k=k, alpha=alpha, c0=c0, softening=0.0)
        if self.k < 2:
            raise ValueError(f"k must be >= 2 for neighbours='knn-ratio' (the k-th neighbour has weight 0), got {k!r}")
        if not target.has_density:
            raise ValueError("log_density: neighbours='knn-ratio' weighs the neighbours by p^(-alpha/c0^2); give it")
        self.beta = self.alpha / self.c0**2
        self.shape = DEFAULT_SHAPE

    def evaluate(self, r_pc, v_pc=None, rho_p=None, want_energy=False):
        """Forces (eq. R3), the k-NN densities (eq. K1, reported) and the energy (eq. R2) at ``r_pc`` (M, d)."""
        r_pc = self._checked_positions(r_pc)
        m_particles, d, k = r_pc.shape[0], self.dim, self.k
        mass = 1.0 / m_particles
        idx_pk, dist_pk = self.search.query(r_pc)
        h_p = dist_pk[:, -1]
        if not np.all(h_p > 0):
            raise ValueError("positions: a particle coincides with its k nearest neighbours (its ball is empty)")
        log_p = self.target.log_density(r_pc)
        if not np.all(np.isfinite(log_p)):
            raise ValueError("log_density is -inf at a particle: neighbours='knn-ratio' needs p > 0 at every particle")
        g_pc = self.target.score(r_pc)
        diff_pkc = r_pc[:, None, :] - r_pc[idx_pk]
        r2_pk = np.einsum("pkc,pkc->pk", diff_pkc, diff_pkc)
        h2_p1 = (h_p**2)[:, None]
        s_pk = np.minimum((r2_pk / h2_p1) ** (0.5 * d), 1.0)
        f_pk = 1.0 - s_pk
        # s / r^2 = r^(d-2) / H^d, finite at r = 0 for d >= 2
        with np.errstate(divide="ignore", invalid="ignore"):
            s_r2_pk = np.where(r2_pk > 0, s_pk / r2_pk, 0.0)
        lq_pk = -self.beta * log_p[idx_pk]  # log q_b
        lq_self_p = -self.beta * log_p
        shift_p = np.maximum(lq_pk[:, :-1].max(axis=1, initial=-np.inf), lq_self_p)  # f = 0 at the k-th neighbour
        # the k-th neighbour has f = 0 exactly: q = 0 there (its exp, not in the shift, may overflow: inf * 0)
        q_pk = np.exp(np.minimum(lq_pk - shift_p[:, None], 0.0))
        q_pk[:, -1] = 0.0
        q_self_p = np.exp(lq_self_p - shift_p)
        sum_p = np.einsum("pk,pk->p", f_pk, q_pk) + q_self_p  # the particle itself: s = 0, f = 1
        pi_pk = q_pk / sum_p[:, None]
        # s_ak = 1 identically for the k-th neighbour: its explicit and H_a terms cancel (and f = 0): drop both
        pi_pk[:, -1] = 0.0
        coeff = self.c0**2 * mass
        # explicit r-dependence of s (f' = -1): e = C pi d s / r^2 on (x_a - x_b)
        e_pk = coeff * d * pi_pk * s_r2_pk
        # H_a terms: G_a = -dE/dH_a = C d / H_a (1 - sum_j pi_aj s_aj), on the k-th neighbour's edge
        g_h_p = coeff * d / h_p * (1.0 - np.einsum("pk,pk->p", pi_pk, s_pk))
        e_pk[:, -1] += g_h_p / h_p
        if self.shape > 0.0:  # eq. R5: -lambda C (d/k) sum_{j<k} log(r_aj / H_a), scale-free
            if not np.all(r2_pk > 0):
                raise ValueError("positions: two particles coincide (the shape term's -log r is infinite)")
            e_pk[:, :-1] += self.shape * coeff * d / k / r2_pk[:, :-1]
            e_pk[:, -1] -= self.shape * coeff * d * (k - 1) / k / h_p**2
        f_pkc = e_pk[:, :, None] * diff_pkc
        f_pc = f_pkc.sum(axis=1)
        flat = idx_pk.ravel()
        for c in range(d):
            f_pc[:, c] -= np.bincount(flat, weights=f_pkc[:, :, c].ravel(), minlength=m_particles)
        weight_p = np.bincount(flat, weights=(pi_pk * f_pk).ravel(), minlength=m_particles) + q_self_p / sum_p
        f_pc += self.alpha * mass * weight_p[:, None] * g_pc
        log_g_p = (shift_p + np.log(sum_p) - d * np.log(h_p)
                   - math.log(m_particles * unit_ball_volume(d) * 0.5 * (k + 1)))
        shape_p = -(d / k) * np.log(np.maximum(r2_pk[:, :-1], 1e-300) / h2_p1).sum(axis=1) * 0.5
        energy = float(coeff * (log_g_p.sum() + self.shape * shape_p.sum())) if want_energy else None
        abs_e = np.abs(e_pk)
        stiff_p = (abs_e.sum(axis=1) + np.bincount(flat, weights=abs_e.ravel(), minlength=m_particles)) / mass
        rho_p = np.exp(self.log_density_estimate(dist_pk, m_particles))
        accel_p = np.sqrt(np.einsum("pc,pc->p", f_pc, f_pc)) / mass
        return ParVIEvaluation(forces=f_pc, rho=rho_p, rho_summation=rho_p, h=h_p.copy(), pressure=self.c0**2 * rho_p,
                               log_p=log_p, energy=energy, accel_max=float(accel_p.max()), sound_speed=self.c0,
                               sound_speed_p=np.full(m_particles, self.c0), fallback=0, mass=mass,
                               stiffness_p=np.maximum(stiff_p, 1e-300), nearest_p=np.maximum(dist_pk[:, 0], 1e-3 * h_p),
                               log_ratio=log_g_p, weight=weight_p)


def poisson_log_constant(k, dim, softening, draws=20000):
    """The constant ``C_k`` of eq. K1 that makes ``log rho_a`` unbiased for a Poisson process of locally
    constant intensity: ``psi(k) + (d / 2k) E sum_{j<=k} log(t_j + delta^2 mean_i t_i)``, ``t_j = (r_a(j) / r_a(k))^2``.
    Given ``r_a(k)``, the k - 1 inner neighbours are uniform in the ball: ``t_j = u_j^(2/d)``, u uniform on
    (0, 1), ``t_k = 1``. ``delta = 0``: ``E log t_j = -2/d`` and ``C_k = psi(k) - (k - 1)/k = (1/k) sum_{j<=k} psi(j)``
    (Kozachenko-Leonenko), exact; ``delta > 0``: the expectation by Monte Carlo with ``draws`` fixed-seed samples
    (standard error below 1e-3 for k >= 2)."""
    if softening == 0.0:
        return float(digamma(k) - (k - 1) / k)
    t_nk = np.ones((draws, k))
    t_nk[:, :-1] = np.random.default_rng(20261202).random((draws, k - 1)) ** (2.0 / dim)
    s_nk = t_nk + softening**2 * t_nk.mean(axis=1, keepdims=True)
    return float(digamma(k) + 0.5 * dim / k * np.log(s_nk).sum(axis=1).mean())


def check_knn_options(formulation, eos, h, density, regularisation, kernel):
    """``neighbours="knn"`` is the score force with the isothermal EOS and no kernel: a one-line error naming the
    first option given another value."""
    given = dict(formulation=(formulation, "force"), eos=(eos, "isothermal"), h=(h, "adaptive"),
                 density=(density, "summation"), regularisation=(regularisation, 0.0), kernel=(kernel, "wendland_c2"))
    for name, (value, allowed) in given.items():
        if value != allowed:
            raise ValueError(f"{name}: neighbours='knn' runs the score force with the isothermal EOS and k-nearest-"
                             f"neighbour densities (no kernel, no support); it needs {name}={allowed!r}, got {value!r}")
