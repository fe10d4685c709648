"""SPH-ParVI as a sampler: Algorithms 1 and 2 of Huang (2024) with leapfrog, CFL steps and friction.

:class:`ParVISampler` draws M particles from an initial proposal, integrates the SPH fluid of
:class:`~ase_sphrelax.models.parvi.ParVIModel` with kick-drift-kick leapfrog (cc.Eq. 30) and a
step from the CFL condition (Eq. 9, in its dimensionally consistent form) or a fixed step,
and returns the particles of the final state (``rule="final"``) or of the paper's "optimal
state" (Sec. 4: the recorded step of largest mean density, ``rule="optimal"``).

Friction. Viscosity conserves momentum, so it cannot stop the centre of mass oscillating in
the target's potential well (the "expands and contracts cyclically" of Sec. 4); a damped fluid
needs a drag ``-beta v``. It is applied exactly (``v <- v exp(-beta dt / 2)`` around each kick);
``friction=0`` is the paper's undamped fluid. With friction and the score force the dynamics
descends the energy of the model (a Lyapunov function), so it settles at the minimiser whose
density the theory predicts (:mod:`ase_sphrelax.sampling.theory`).
``friction="critical"`` (:mod:`.friction`) is a matrix drag, critical along each principal direction of
the target's curvature seen by the particles; no friction rule moves the resting states (theory.py, F1-F3).

Smoothing length: ``h="adaptive"`` (the default: ``rho_a H_a^d = m eta^d``, about
``n_neighbours`` particles per support), a number (constant), or ``h_schedule="anneal"`` from
``h`` to ``h_end`` geometrically over the run (Sec. 4 "time-varying annealing").

Before any work (:meth:`ParVISampler.look_at_target`, :mod:`.target_checks`) a short diagonal
Newton search on the score finds a mode and per-axis scale of the target: the particles start there
(unless ``x0`` or ``init_scale`` is given) and the friction defaults to 1 / scale, so that a target of
any scale and location runs like the unit Gaussian. A score that points away from the mass
everywhere (a flipped sign) or that disagrees with the log-density's central differences is an
error naming ``score``.

At the end the run is judged (:mod:`.convergence`): the drift of the ensemble's mean and
covariance and of its kinetic energy over the last half of the run against their Monte-Carlo
standard errors: the fluid at rest. Then (:mod:`.verdict`, ``check=True``) the samples are checked against
the target: a short exact MALA chain from them must not move their moments beyond a calibrated bound, and a
mode search must find no mode the particles miss (a missed one restarts the run once from the modes found).
``info["converged"]`` (at rest and the check passed) and ``info["convergence_reason"]`` say the verdict,
``info["verdict"]`` has ``at_rest`` and the check's figures; a run that is not converged warns with
:class:`~ase_sphrelax.checks.NotConvergedWarning`.

Divergence (a step too large, a force that explodes) is detected after every step — non-finite
positions or velocities, or a kinetic energy beyond ``1e6`` times its scale — and raised as
:class:`ParVIDivergence` naming the step and the time step; nothing returns NaN silently.
"""
from __future__ import annotations

import math
import numbers
import time
import warnings

import numpy as np

from ..checks import NotConvergedWarning, check_positive
from ..models.parvi import CountingTarget, ParVIModel
from ..models.parvi_knn import DEFAULT_K, KNNParVIModel, KNNRatioParVIModel, check_k, check_knn_options
from .configurations import (AUTO_NEIGHBOURS_2D, CLASSIC, DEFAULTS, HOLD_MAX, HOLD_TOLERANCE,  # noqa: F401
                             LOCAL_COURANT, LOCAL_GROWTH, VARIANT_INTEGERS, VARIANT_NUMBERS, VARIANT_TOKENS)
from .coarse_to_fine import check_coarse_options, child_counts, coarse_schedule, split_into_children
from .convergence import assess_convergence, ensemble_moments
from .friction import ScoreMemory, check_friction, critical_drag, damp
from .finish import check_finish, ellipsoid_frame, mala_finish, refill_radii
from .hold_rule import resolve_hold_max
from .result import SampleResult
from .target_checks import check_score_matches_log_density, locate_target, probe_target
from .whitening import AffineMap, check_whiten

__all__ = ["ParVISampler", "ParVIDivergence", "sample", "DEFAULTS", "CLASSIC", "variant_options", "VARIANT_TOKENS"]



class ParticleScoreMemory(ScoreMemory):
    """A :class:`~.friction.ScoreMemory` whose ``hold`` may also be a boolean mask (n,): the rows where it is True
    return their last score (uncounted), the others are evaluated on that subset only (the target function is
    called on those rows; counted per row) and kept. ``hold = True / False`` behaves as in ScoreMemory."""

    def _partial(self, x_pc, evaluate):
        if self.last_score is None or x_pc.shape[0] != self.n:
            return None
        fresh_p = ~self.hold
        out_pc = self.last_score.copy()
        if np.any(fresh_p):
            out_pc[fresh_p] = evaluate(self, x_pc[fresh_p])
        self.last_score = out_pc
        return out_pc

    def _masked(self, x_pc, name):
        evaluate = getattr(CountingTarget, name)
        if not isinstance(self.hold, np.ndarray):
            return getattr(super(), name)(x_pc)
        out = self._partial(x_pc, evaluate)
        return self._keep(evaluate(self, x_pc)) if out is None else out

    def score(self, x_pc):
        return self._masked(x_pc, "score")

    def fd_score_or_nan(self, x_pc):
        return self._masked(x_pc, "fd_score_or_nan")


def held_particles(dr_pc, h_p, score_pc, age_p, tolerance, hold_max):
    """``score_every="adaptive"``: the mask (M,) of particles that keep their last score at this step.

    Particle a holds while ``age_a < hold_max`` (steps it has held since its last evaluation), ``|dr_a| <= tolerance
    H_a`` (its displacement since then, in its support) and ``|dr_a| |s_a| <= tolerance`` (the first-order change
    of ``log p`` along the displacement, i.e. the displacement in units of the score's length ``1 / |s_a|``): a
    particle in the neck of a funnel (large ``|s|``) is evaluated at every step, one in a wide, slow region holds
    up to ``hold_max`` steps. Non-finite scores are re-evaluated."""
    dist_p = np.sqrt(np.einsum("pc,pc->p", dr_pc, dr_pc))
    speed_p = np.sqrt(np.einsum("pc,pc->p", score_pc, score_pc))
    return (age_p < hold_max) & (dist_p <= tolerance * h_p) & (dist_p * speed_p <= tolerance) \
        & np.isfinite(speed_p)


def variant_options(spec):
    """Keyword options of :class:`ParVISampler` for a variant name such as ``"whiten+local+critical"``.

    ``spec`` joins tokens with ``+``: the names of :data:`VARIANT_TOKENS` (``default``, ``whiten``,
    ``local``, ``critical``, ``coarse``, ``knn``, ``knn-ratio``, ``mala``, ``radial``) and ``name=value`` for a
    number of :data:`VARIANT_NUMBERS` (``friction=0.3``, ``k=20``, ``finish_steps=200``), e.g. ``"knn+whiten"`` for
    the 10-D Gaussian and ``"knn+whiten+mala"`` (the exact finish) for the logistic posterior.
    A token of neither kind is a one-line error naming it.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"variant must be a non-empty string like 'whiten+local+critical', got {spec!r}")
    options = {}
    for token in spec.strip().split("+"):
        if token in VARIANT_TOKENS:
            options.update(VARIANT_TOKENS[token])
            continue
        name, _, value = token.partition("=")
        if name not in VARIANT_NUMBERS or not value:
            raise ValueError(f"variant {spec!r}: unknown token {token!r}; use {', '.join(VARIANT_TOKENS)} or "
                             f"name=number for {', '.join(VARIANT_NUMBERS)}, joined by '+'")
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"variant {spec!r}: {name} needs a number, got {value!r}") from None
        options[name] = int(number) if name in VARIANT_INTEGERS and number.is_integer() else number
    return options


class ParVIDivergence(FloatingPointError):
    """The integration blew up; the message names the step and the time step."""


def _progress(total, enabled, desc):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, leave=False)


class ParVISampler:
    """SPH-ParVI sampler (see the module docstring).

    The defaults are :data:`DEFAULTS` (issue 31: local steps, critical friction, the scaled per-particle score hold,
    12 neighbours in 2D, 1000 evaluations per particle); ``**CLASSIC`` (:data:`CLASSIC`) restores the configuration
    that was the default before (global step, friction ``1 / s``, a score at every step, 600 steps).

    Parameters
    ----------
    log_density, score : callable or None
        Vectorised ``(M, d) -> (M,)`` and ``(M, d) -> (M, d)``; at least one. The force
        formulation without a score uses central differences of ``log_density`` (counted).
    dim : int
        Dimension d >= 1.
    n : int
        Number of particles M >= 2.
    formulation, eos, alpha, c0, rho0, gamma, kernel, viscosity, viscosity_alpha, nu,
    regularisation, density, diffusion, eps, n_neighbours
        Passed to :class:`~ase_sphrelax.models.parvi.ParVIModel`; ``c0`` defaults to
        ``sqrt(alpha)`` (isothermal: stationary density exactly p). ``n_neighbours="auto"`` (default):
        :data:`AUTO_NEIGHBOURS_2D` (12) in 2D, the model's own default in other dimensions; None: the model's.
    h : "adaptive" or float
    h_schedule : {"constant", "anneal"}
    h_end : float or None
        Final support of the annealing (default ``h / 3``).
    steps : int
        SPH steps, or with ``score_every="adaptive"`` (the default) score evaluations per particle (default 1000).
    dt : float or None
        Fixed time step; None: the CFL step (times ``courant``) at every step.
    courant : float or None
        Factor on the CFL step; None: 0.5 (``DEFAULTS``), or :data:`LOCAL_COURANT` with ``time_step="local"``.
    friction : float, None or "critical"
        Default ``"critical"``. Drag coefficient beta >= 0; None (CLASSIC's): ``1 / s``, s the geometric mean of
        the target's per-axis scale found by :meth:`look_at_target` (1 for a unit target, or when no scale is
        found). The drag sets the time the fluid takes to settle, ``~ beta s^2``, while the CFL
        step scales with s: ``beta = 1 / s`` makes the number of steps to rest the same at any scale.
        ``"critical"``: a matrix drag, critical along each principal direction of the particles'
        Fisher matrix (rates ``2 (alpha k_i)^(1/2)``, k_i a typical particle's curvature of
        ``-log p`` along it, from the scores the steps compute; :mod:`.friction`), renewed every
        ``friction_every`` steps; in whitened coordinates the whitened target's. No friction rule
        changes the stationary density (theory.py, eqs. F1-F3); ``info["friction_rates"]`` has the
        last rates.
    friction_every : int
        Steps between renewals of the ``"critical"`` drag (default 50).
    friction_ramp : float
        In (0, 1]; below 1 the drag (any rule) is multiplied by ``friction_ramp^(1 - step / (steps / 2))``
        over the first half of the run, rising to the rule's own: little friction while the fluid spreads
        (default 1: no ramp).
    rule : {"final", "optimal"}
    x0 : ndarray (M, d) or None
        Initial particles; default drawn with ``seed`` from N(0, init_scale^2 I) or, without
        ``init_scale``, from N(c, diag(s^2)) with the centre c and per-axis scale s found from the
        target by :func:`~ase_sphrelax.sampling.target_checks.locate_target` (scale 1 on an axis
        where the score shows no positive curvature).
    init_scale : float or None
    seed : int
    record_every : int
        Trace (and optimal-state candidate) every this many steps.
    progress : bool
        tqdm progress bar.
    max_steps : int or None
        The stopping rule: None runs exactly ``steps``; a number runs ``steps``, then, while the run
        is not converged (:mod:`.convergence`, judged on the last half of the run so far), doubles
        its length, up to ``max_steps`` (annealed supports stay at ``h_end`` after ``steps``).
    whiten : None, "covariance" or ndarray (d, d)
        Run the fluid in whitened coordinates ``y = L^-1 (x - c)`` (:mod:`.whitening`; theory.py eqs.
        W1-W3): None (default) does not. ``"covariance"``: ``c`` and ``L`` are the particles' mean and
        Cholesky factor of their covariance, set from the initial particles and renewed every
        ``whiten_every`` steps up to step ``whiten_until * steps`` (each renewal shrinking the covariance the
        fluid sees by at most 2x per direction, eq. W4), then held fixed, so that the last
        part of the run, where the convergence is judged, samples p exactly (for a fixed map the
        resting density is the pull-back of p); affine invariant. A matrix: the map ``x = L y``
        (``c = 0``) fixed from the start (exactly affine invariant: sampling N(0, A A^T) with
        ``whiten=A`` and ``x0 = z A^T`` gives, up to round-off, ``A`` times the samples of N(0, I) with
        ``whiten=I`` and ``x0 = z``). Checks, start and default friction are those of p_y; ``x0`` is in x;
        ``trace["mean_density"]`` and ``info["final_h_median"]`` are in y.
    whiten_every : int
        Steps between renewals of the ``"covariance"`` map (default 50).
    whiten_until : float
        Fraction of ``steps`` after which the ``"covariance"`` map is frozen (default 0.5).
    time_step : {"global", "local"}
        ``"global"`` (CLASSIC's): one step for all particles, ``courant`` times the CFL step of the
        smallest support and the largest acceleration (:meth:`ParVIModel.cfl_step`). ``"local"``:
        local time stepping (steady-state CFD): every particle is kicked, drifted and damped with its
        own CFL step (:meth:`ParVIModel.cfl_steps`, from its own H, acceleration and sound speed), all
        evaluated together at every step. The trajectory is no longer the fluid's, but the resting
        states are the same (``F_a = 0``, ``v = 0`` for every step field) and the damped flow still
        descends the model's energy (theory.py, eqs. L1-L3; the discrete map need not: bursts of kinetic
        energy were measured on the banana, reproductions/parvi-steps/): a stiff particle (the funnel's neck, a
        tail with a small H or a large score) no longer sets the step of the whole ensemble.
        ``trace["dt"]`` and ``trace["time"]`` are then the median particle's; ``info`` has
        ``dt_median`` and ``dt_min`` of the last step. Needs ``dt=None``; ``courant`` defaults to
        :data:`LOCAL_COURANT` (0.25) there, 0.5 for the global step.
    neighbours : {"kernel", "knn", "knn-ratio"}
        ``"kernel"`` (default): the SPH kernel sums of :class:`~ase_sphrelax.models.parvi.ParVIModel`.
        ``"knn"``: densities from each particle's k nearest neighbours
        (:class:`~ase_sphrelax.models.parvi_knn.KNNParVIModel`, a softened Kozachenko-Leonenko estimate; forces the
        exact gradient of the energy), any ``1 <= k < n`` in any dimension, where the kernel sums need hundreds of
        neighbours above 3-D (M >= 656 in 10-D). At rest the particles satisfy the Stein identities
        ``sum grad log p = 0`` and ``mean (x . grad log p) = -d`` exactly (theory.py, eqs. K4-K6); the density is p
        in the continuum limit (K7), which above a few dimensions the neighbour balls are too wide to reach: the
        particles rest on the typical-set shell (second moments of Gaussians right, radial spread not). Use
        ``whiten="covariance"`` on anisotropic targets. ``"knn-ratio"`` (experimental): a k-NN estimate of
        ``rho / p`` (theory.py, eqs. R1-R5; needs ``log_density``), free of that bias in the continuum but stiff and
        slow to settle (reproductions/parvi-highdim/). Both need the score force with the isothermal EOS and
        ``h="adaptive"``; viscosity options are not used (the friction damps the fluid).
    k : int or None
        Neighbours per particle of ``neighbours="knn"``/``"knn-ratio"`` (None: 20, at most n - 1); an error with
        the kernel.
    coarse_to_fine : None or int
        None (default): one level. An integer k >= 2: coarse to fine (:mod:`.coarse_to_fine`): ``n // k``
        particles run first with the same options (supports ``k^(1/d)`` times wider, so steps that long), then
        each is split into k children (a ``2 x 2`` grid in its cell in 2D with k = 4; their mean is the parent)
        and the n particles finish the run at rest. ``steps`` stays the budget in evaluations per final
        particle: ``coarse_share`` of it goes to the coarse level (``floor(share steps n / (n // k))`` steps),
        the rest to the fine one; ``n_score``/``n_density`` count both levels and ``info["coarse"]`` has the
        coarse level's size, steps, evaluations and verdict. The fine level is the one-level fluid started
        from the children: the stationary density is unchanged (the split only sets the initial condition).
        The trace and the convergence verdict are the fine level's; ``max_steps`` applies to it.
    coarse_share : float
        In (0, 1): the share of the evaluations spent on the coarse level (default 0.5).
    score_every : int
        1 (CLASSIC's): the score is evaluated at every step. K > 1: multiple time steps: the score force is
        evaluated at every K-th step and held (the positions of that step's score) over the K - 1 SPH steps in
        between, while pressure, viscosity and drag are recomputed at every step; ``steps`` counts the SPH steps,
        so a run costs ``steps / K`` score evaluations per particle (counted). The step stays the CFL step of the
        pressure (stability), and the held score covers K of them: K times the physical time per evaluation,
        at the price of the score's change over the held interval (accuracy in the score field, not H, sets K).
        Exact at rest: at a resting state (``v = 0``, positions unchanged) the held score is the score at those
        positions, so the resting states are those of ``score_every=1`` (force balance ``F_pressure + m alpha
        s = 0``, theory.py) and the stationary density is unchanged; with friction the damped steps between
        fresh scores have a constant score force (a potential), so a fixed point of the map is at rest. Energy
        records (``trace["energy"]``) are taken every ``record_every * K`` steps; a renewal of the whitening map
        evaluates the score afresh (counted). ``"adaptive"``: a per-particle hold (:func:`held_particles`): a
        particle re-evaluates its score only when it has moved more than ``hold_tolerance`` of its support H or
        of its score's length ``1 / |s|`` since its last evaluation, or after ``hold_max`` held steps; the target
        function is called on those particles only (counted per particle). ``steps`` is then the budget in score
        evaluations per particle: the run stops at the first SPH step at which ``n_score >= (steps + 1) n`` (the
        start included, as ``score_every=K`` with ``K steps`` SPH steps), or after ``(hold_max + 1) steps`` SPH steps.
        ``hold_max = K - 1`` with a tolerance no displacement reaches is ``score_every=K`` (tested).
        Exact at rest: a particle at rest re-evaluates at least every ``hold_max + 1`` steps at its unchanged
        position, so in a state the map leaves unchanged every held score is the score at the particle's
        position, and the resting states are those of ``score_every=1``; conversely a resting state of K = 1 (with
        its fresh scores) does not move under the hold (no displacement, so only the ``hold_max`` refreshes, which
        return the same scores). Not with ``coarse_to_fine`` or ``max_steps``. ``info["hold_moved_share"]``: the
        share of the evaluations triggered by a displacement.
    hold_tolerance : float
        ``score_every="adaptive"``: the displacement, in units of ``min(H, 1 / |s|)``, that triggers a particle's
        re-evaluation (default :data:`HOLD_TOLERANCE`).
    hold_max : int or "scaled"
        ``score_every="adaptive"``: the most SPH steps a particle holds its score after the step that evaluated it,
        so it is evaluated at least every ``hold_max + 1`` steps (CLASSIC's: :data:`HOLD_MAX`). ``"scaled"``
        (default):
        ``round(HOLD_MAX (n / 500)^(1/dim))`` (:mod:`.hold_rule`, eq. S1; 4 at n = 500, 8 at n = 2000 in 2D), so that
        the physical time per evaluation does not shrink with n as the CFL step does; ``parameters["hold_max"]``
        is the number used.
    finish : None, "mala" or "radial"
        None (default): the particles are the fluid's. Otherwise, after the run, an exact p-invariant kernel
        (:mod:`.finish`; theory.py, eqs. G1-G5) moves the final particles in the frozen whitening map's coordinates
        (or the frame of the particles' mean and covariance without a map), ``finish_steps`` times.
        ``"mala"``: Metropolis-adjusted Langevin steps (one score and one log-density per particle and step, the
        step adapted in the first quarter, then drawn from a fixed spread): the fluid is the start and the
        preconditioner, the Metropolis test removes its bias (the k-NN fluid's shell above a few dimensions,
        K5-K7, and particles stranded in a tail). ``"radial"``: each particle's radius from the centre redrawn
        from ``r^(d-1) p(c + L r u)`` given its direction u (slice sampling; log-densities only): the shell's radial
        profile made exact, the directions left as the fluid's. Needs ``log_density`` (and ``score`` for
        ``"mala"``) and ``rule="final"``; the evaluations are counted in ``n_score``/``n_density`` (``steps`` counts
        the fluid's steps only); ``info["finish_info"]`` has the finish's own counts, step and acceptance;
        ``alternatives["fluid"]`` the particles before it. The convergence verdict is the fluid's.
    finish_steps : int
        Steps (``"mala"``) or slice updates (``"radial"``) per particle of the finish (default 200).
    check : bool
        True (default): ``converged`` also needs the samples to pass the check against the target
        (:mod:`.verdict`: an exact MALA chain, an importance-sampling comparison of the tails and a mode search,
        their evaluations in ``n_check_density`` / ``n_check_score``; a missed mode restarts the run once).
        False: ``converged`` is the fluid at rest only.
    """

    def __init__(self, log_density=None, score=None, dim=2, n=500, formulation=DEFAULTS["formulation"],
                 eos=DEFAULTS["eos"], alpha=DEFAULTS["alpha"], c0=None, rho0=None, gamma=7.0, kernel="wendland_c2",
                 h=DEFAULTS["h"], h_schedule="constant", h_end=None, n_neighbours=DEFAULTS["n_neighbours"],
                 viscosity=DEFAULTS["viscosity"], viscosity_alpha=DEFAULTS["viscosity_alpha"], nu=0.05,
                 regularisation=0.0, density="summation", diffusion=0.1, eps=1e-10, steps=DEFAULTS["steps"], dt=None,
                 courant=None, friction=DEFAULTS["friction"], rule=DEFAULTS["rule"], x0=None,
                 init_scale=None, seed=0, record_every=10, progress=False, max_steps=None, whiten=None,
                 whiten_every=50, whiten_until=0.5, time_step=DEFAULTS["time_step"], friction_every=50,
                 friction_ramp=1.0, neighbours="kernel", k=None, coarse_to_fine=None, coarse_share=0.5,
                 score_every=DEFAULTS["score_every"], hold_tolerance=HOLD_TOLERANCE, hold_max=DEFAULTS["hold_max"],
                 finish=None, finish_steps=200, check=True):
        self._options = {name: value for name, value in locals().items() if name != "self"}  # for the levels
        self.coarse_to_fine, self.coarse_share = check_coarse_options(coarse_to_fine, coarse_share)
        self.finish, self.finish_steps = check_finish(finish, finish_steps, rule)
        if self.finish is not None and (log_density is None or (finish == "mala" and score is None)):
            raise ValueError(f"log_density, score: finish={finish!r} needs the log-density"
                             f"{' and the score' if finish == 'mala' else ''}; give them")
        if score_every != "adaptive" and (isinstance(score_every, bool) or not isinstance(score_every, (int, np.integer))
                                          or score_every < 1):
            raise ValueError(f"score_every must be an integer >= 1 (SPH steps per score evaluation) or 'adaptive', "
                             f"got {score_every!r}")
        if isinstance(hold_tolerance, bool) or not isinstance(hold_tolerance, numbers.Real) \
                or not 0.0 < hold_tolerance < math.inf:
            raise ValueError(f"hold_tolerance must be a finite number > 0, got {hold_tolerance!r}")
        hold_max = resolve_hold_max(hold_max, n, dim, HOLD_MAX)  # "scaled": hold_rule.py, eq. S1
        if isinstance(hold_max, bool) or not isinstance(hold_max, (int, np.integer)) or hold_max < 1:
            raise ValueError(f"hold_max must be an integer >= 1 or 'scaled', got {hold_max!r}")
        self.adaptive_hold = score_every == "adaptive"
        if self.adaptive_hold and (coarse_to_fine is not None or max_steps is not None):
            name = "coarse_to_fine" if coarse_to_fine is not None else "max_steps"
            raise ValueError(f"{name}: score_every='adaptive' counts steps as evaluations (the default since issue "
                             f"31): give score_every=1 (or **CLASSIC) with {name}")
        self.score_every = "adaptive" if self.adaptive_hold else int(score_every)
        self.hold_tolerance, self.hold_max = float(hold_tolerance), int(hold_max)
        self._record_period = self.hold_max if self.adaptive_hold else self.score_every
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 1:
            raise ValueError(f"dim must be an integer >= 1, got {dim!r}")
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
            raise ValueError(f"n must be an integer >= 2 (particles), got {n!r}")
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
            raise ValueError(f"steps must be an integer >= 0, got {steps!r}")
        if rule not in ("final", "optimal"):
            raise ValueError(f"rule must be 'final' or 'optimal', got {rule!r}")
        if h_schedule not in ("constant", "anneal"):
            raise ValueError(f"h_schedule must be 'constant' or 'anneal', got {h_schedule!r}")
        if h_schedule == "anneal" and isinstance(h, str):
            raise ValueError("h_schedule='anneal' needs a number h (the starting support), got h='adaptive'")
        friction = check_friction(friction)
        if isinstance(friction_every, bool) or not isinstance(friction_every, (int, np.integer)) or friction_every < 1:
            raise ValueError(f"friction_every must be an integer >= 1, got {friction_every!r}")
        if isinstance(friction_ramp, bool) or not isinstance(friction_ramp, numbers.Real) \
                or not 0.0 < friction_ramp <= 1.0:
            raise ValueError(f"friction_ramp must be a number in (0, 1], got {friction_ramp!r}")
        if time_step not in ("global", "local"):
            raise ValueError(f"time_step must be 'global' or 'local', got {time_step!r}")
        if time_step == "local" and dt is not None:
            raise ValueError(f"dt: time_step='local' takes each particle's CFL step: give dt=None (or "
                             f"time_step='global', the default's only other choice), got dt={dt!r}")
        if max_steps is not None and (isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer))
                                      or max_steps < steps):
            raise ValueError(f"max_steps must be None or an integer >= steps ({steps}), got {max_steps!r}")
        if isinstance(record_every, bool) or not isinstance(record_every, (int, np.integer)) or record_every < 1:
            raise ValueError(f"record_every must be an integer >= 1, got {record_every!r}")
        alpha = check_positive("alpha", alpha)
        c0 = math.sqrt(alpha) if c0 is None else check_positive("c0", c0)
        self.whiten = check_whiten(whiten, int(dim))
        if isinstance(whiten_every, bool) or not isinstance(whiten_every, (int, np.integer)) or whiten_every < 1:
            raise ValueError(f"whiten_every must be an integer >= 1, got {whiten_every!r}")
        if isinstance(whiten_until, bool) or not isinstance(whiten_until, numbers.Real) \
                or not 0.0 <= whiten_until <= 1.0:
            raise ValueError(f"whiten_until must be a number in [0, 1], got {whiten_until!r}")
        self.whiten_every, self.whiten_until = int(whiten_every), float(whiten_until)
        self.map = None
        self._callables_x = (log_density, score)  # the user's target in x (the verdict's check runs there)
        if self.whiten is not None:  # the fluid sees the pull-back p_y (whitening.py, eqs. W1, W2)
            self.map = AffineMap(np.zeros(int(dim)), np.eye(int(dim)) if isinstance(self.whiten, str) else self.whiten)
            log_density = None if log_density is None else self.map.log_density_y(log_density)
            score = None if score is None else self.map.score_y(score)
        if not isinstance(check, bool):
            raise ValueError(f"check must be True or False, got {check!r}")
        self.check = check
        self._may_restart = True  # verdict.py: one restart from the modes found, not more
        self._friction_from_target = friction is None
        self.target = ParticleScoreMemory(log_density, score, dim, n=int(n))
        if neighbours not in ("kernel", "knn", "knn-ratio"):
            raise ValueError(f"neighbours must be 'kernel', 'knn' or 'knn-ratio', got {neighbours!r}")
        if neighbours != "kernel":  # k-nearest-neighbour densities (models/parvi_knn.py; theory.py, eqs. K1-K7, R1-R4)
            check_knn_options(formulation, eos, h, density, regularisation, kernel)
            model_class = KNNParVIModel if neighbours == "knn" else KNNRatioParVIModel
            self.model = model_class(self.target, int(dim), k=check_k(min(DEFAULT_K, n - 1) if k is None else k, n),
                                     alpha=alpha, c0=c0)
        elif k is not None:
            raise ValueError(f"k: the number of neighbours of neighbours='knn' or 'knn-ratio'; give one of those or "
                             f"k=None, got k={k!r}")
        else:
            if isinstance(n_neighbours, str) and n_neighbours == "auto":  # 12 in 2D (AUTO_NEIGHBOURS_2D)
                n_neighbours = AUTO_NEIGHBOURS_2D if dim == 2 else None
            self.model = ParVIModel(self.target, int(dim), formulation=formulation, eos=eos, alpha=alpha, c0=c0,
                                    rho0=rho0, gamma=gamma, kernel=kernel, h=h, n_neighbours=n_neighbours,
                                    viscosity=viscosity, viscosity_alpha=viscosity_alpha, nu=nu,
                                    regularisation=regularisation, density=density, diffusion=diffusion, eps=eps)
        self.dim, self.n, self.steps = int(dim), int(n), int(steps)
        if self.model.adaptive:
            self.model._eta_for(self.n)  # M too small for an adaptive support: an error before any work
        if self.coarse_to_fine is not None:
            self.schedule = coarse_schedule(self.n, self.steps, self.coarse_to_fine, self.coarse_share)
            if self.model.adaptive:
                try:
                    self.model._eta_for(self.schedule[0])
                except ValueError as error:
                    raise ValueError(f"coarse_to_fine={self.coarse_to_fine}: the coarse level's "
                                     f"{self.schedule[0]} particles: {error}") from None
        self.h_schedule = h_schedule
        self.h_start = None if isinstance(h, str) else float(h)
        self.h_end = check_positive("h_end", h_end, allow_none=True)
        if h_schedule == "anneal" and self.h_end is None:
            self.h_end = self.h_start / 3.0
        self.dt = check_positive("dt", dt, allow_none=True)
        courant = check_positive("courant", courant, allow_none=True)
        self.courant = courant if courant is not None else LOCAL_COURANT if time_step == "local" else DEFAULTS["courant"]
        self.friction = friction
        self.friction_every = int(friction_every)
        self.friction_ramp = float(friction_ramp)
        self._drag = None  # (Q, rates) of a matrix friction (friction="critical"), renewed in run()
        self.time_step = time_step
        self.rule = rule
        self.init_scale = check_positive("init_scale", init_scale, allow_none=True)
        self.start = None  # (centre (d,), scale (d,)) of the initial proposal, from look_at_target()
        self.target_scale = None
        self._probe = None
        self.seed = seed
        self.record_every = int(record_every)
        self.max_steps = None if max_steps is None else int(max_steps)
        self.progress = progress
        self.x0 = None
        if x0 is not None:
            x0 = np.array(x0, dtype=float)
            if x0.shape != (self.n, self.dim):
                raise ValueError(f"x0 must have shape (n, dim) = ({self.n}, {self.dim}), got {x0.shape}")
            if not np.all(np.isfinite(x0)):
                raise ValueError("x0 must be finite")
            self.x0 = x0
        self.parameters = dict(dim=self.dim, n=self.n, formulation=formulation, eos=eos, alpha=alpha, c0=c0,
                               rho0=rho0, gamma=gamma, kernel=kernel, h=h, h_schedule=h_schedule, h_end=self.h_end,
                               n_neighbours=self.model.n_neighbours, viscosity=viscosity,
                               viscosity_alpha=viscosity_alpha, nu=nu, regularisation=regularisation, density=density,
                               diffusion=diffusion, eps=eps, steps=self.steps, dt=dt, courant=self.courant,
                               friction=self.friction, rule=rule, init_scale=init_scale, seed=seed,
                               max_steps=self.max_steps, whiten=None if self.whiten is None else
                               (self.whiten if isinstance(self.whiten, str) else self.whiten.tolist()),
                               whiten_every=self.whiten_every, whiten_until=self.whiten_until, time_step=time_step,
                               friction_every=self.friction_every, friction_ramp=self.friction_ramp,
                               neighbours=neighbours, k=getattr(self.model, "k", None),
                               coarse_to_fine=self.coarse_to_fine, coarse_share=self.coarse_share,
                               score_every=self.score_every, hold_tolerance=self.hold_tolerance,
                               hold_max=self.hold_max, finish=self.finish, finish_steps=self.finish_steps,
                               check=self.check)

    def look_at_target(self):
        """The checks before any work (:mod:`~ase_sphrelax.sampling.target_checks`), on their own counter:
        locate the target (its scale, and the initial proposal unless ``x0`` or ``init_scale`` is given),
        reject a score that points away from the mass everywhere, and compare the score with the
        log-density's central differences at a few initial particles when both are given."""
        probe = self._probe = probe_target(self.target)
        centre_c, scale_c = locate_target(probe, self.dim)
        self.target_scale = scale_c
        if not self.target.has_score and np.any(np.isfinite(scale_c)):
            # central differences of log p with steps of 1e-5 max(1, |x|) see nothing of a target narrower
            # than that: scale the step down with the target (never up: unit targets keep theirs)
            self.target.fd_step = min(self.target.fd_step, self.target.fd_step * float(np.nanmin(scale_c)))
        if self.init_scale is not None or not np.all(np.isfinite(centre_c)):
            self.start = (np.zeros(self.dim), np.full(self.dim, self.init_scale or 1.0))
        else:
            self.start = (centre_c, np.where(np.isfinite(scale_c), scale_c, 1.0))
        if self.friction is None:  # from the target, also when the start is the user's
            known_c = scale_c[np.isfinite(scale_c)]
            self.friction = float(1.0 / np.exp(np.mean(np.log(known_c)))) if known_c.size else 1.0
        self.parameters["friction"] = self.friction
        points = self.initial_particles()[:4]
        known_c = np.where(np.isfinite(scale_c), scale_c, np.std(points, axis=0) if len(points) > 1 else 1.0)
        check_score_matches_log_density(probe, points, np.where(known_c > 0, known_c, 1.0))
        return probe

    def initial_particles(self):
        """The initial proposal: ``x0``, or N(centre, diag(scale^2)) drawn with ``seed`` (see ``x0``)."""
        if self.x0 is not None:
            return self.x0.copy() if self.map is None else self.map.to_y(self.x0)
        if self.start is None:
            self.look_at_target()
        centre_c, scale_c = self.start
        return centre_c + scale_c * np.random.default_rng(self.seed).standard_normal((self.n, self.dim))

    def _separate_coincident(self, r):
        """Coincident particles feel no pressure from each other (the kernel is flat at r = 0) and an
        adaptive support has no solution for them: every copy after the first of a repeated position
        is moved by a seeded N(0, (1e-3 s)^2) jitter, s the spread of the distinct points (or
        ``init_scale``). Returns the particles and the number moved."""
        _, first, inverse = np.unique(r, axis=0, return_index=True, return_inverse=True)
        duplicate = np.ones(r.shape[0], dtype=bool)
        duplicate[first] = False
        if not duplicate.any():
            return r, 0
        distinct = r[first]
        scale = float(np.sqrt(np.mean(np.var(distinct, axis=0)))) if len(distinct) > 1 else 0.0
        scale = scale if scale > 0 else float(np.mean(self.start[1])) if self.start is not None else 1.0
        rng = np.random.default_rng([int(self.seed) if isinstance(self.seed, (int, np.integer)) else 0, 7919])
        r = r.copy()
        r[duplicate] += 1e-3 * scale * rng.standard_normal((int(duplicate.sum()), r.shape[1]))
        return r, int(duplicate.sum())

    def _divergence_hint(self, spread_c):
        """What to change after a divergence: the initial spread ``spread_c`` (the initial particles' sd per axis)
        against the target's scale, then the step."""
        hint = ""
        scale_c = self.target_scale
        if scale_c is not None and np.any(np.isfinite(scale_c)):
            ratio = float(np.nanmax(np.maximum(spread_c / scale_c, scale_c / spread_c)))
            hint = (f"the initial particles (sd {np.array2string(spread_c, precision=3)}) against the target's scale "
                    f"from its score's curvature ({np.array2string(scale_c, precision=3)}): a factor {ratio:.3g}"
                    + ("; start at the target's scale (leave init_scale and x0 unset) or" if ratio > 10 else ";")
                    + " ")
        return hint + "use a smaller dt or courant, or more friction"

    def _step(self, ev):
        """The next time step: ``dt``, or the CFL step (a number), or each particle's (``time_step="local"``, (M,))."""
        if self.dt is not None:
            return self.dt
        if self.time_step == "local":
            dt_p = self.model.cfl_steps(ev, self.courant)
            previous = getattr(self, "_dt_p", None)
            if LOCAL_GROWTH is not None and previous is not None and previous.shape == dt_p.shape:
                dt_p = np.minimum(dt_p, LOCAL_GROWTH * previous)
            self._dt_p = dt_p
            return dt_p
        return self.courant * self.model.cfl_step(ev)

    def _renew_drag(self):
        """``friction="critical"``: the drag from the Fisher matrix of the particles' last scores (friction.py)."""
        if self.friction != "critical":
            return
        drag = critical_drag(self.target.last_score, self.model.alpha)
        if drag is not None:  # no finite, non-zero score: keep the previous drag (or, at the start, rate 1)
            self._drag = drag
        elif self._drag is None:
            self._drag = (np.eye(self.dim), np.ones(self.dim))

    def _drag_at(self, step):
        """``(friction, drag)`` of ``step``: the rule's, times ``friction_ramp^(1 - step / ramp)`` over the first
        half of the run (``ramp = steps / 2``; friction.py)."""
        ramp_steps = 0.5 * self.steps
        if self.friction_ramp == 1.0 or step >= ramp_steps:
            return self.friction, self._drag
        factor = self.friction_ramp ** (1.0 - step / ramp_steps)
        if self._drag is not None:
            return self.friction, (self._drag[0], factor * self._drag[1])
        return factor * self.friction, None

    def damping_rate(self):
        """The slowest damping rate of the drag: the friction, or the smallest rate of the critical drag."""
        return float(np.min(self._drag[1])) if self._drag is not None else float(self.friction)

    def _finish(self, r):
        """``finish=`` (:mod:`.finish`): the final particles moved by the exact kernel in the frozen whitening map's
        coordinates (centre 0, unit frame: ``r`` is y), or without a map in the frame of the particles' mean and
        covariance; returns ``(r, info)``, r in the fluid's coordinates (y when whitened). Counted evaluations."""
        self.target.hold = False
        rng = np.random.default_rng([int(self.seed) if isinstance(self.seed, (int, np.integer)) else 0, 4242])
        centre_c, l_cc = (np.zeros(self.dim), np.eye(self.dim)) if self.map is not None else ellipsoid_frame(r)
        n_score, n_density = self.target.n_score, self.target.n_density
        if self.finish == "mala":
            r, info = mala_finish(r, self.target.log_density, self.target.score, centre_c, l_cc, self.finish_steps,
                                  rng)
        else:
            r, info = refill_radii(r, self.target.log_density, centre_c, l_cc, self.finish_steps, rng)
        info.update(kind=self.finish, steps=self.finish_steps, n_score=self.target.n_score - n_score,
                    n_density=self.target.n_density - n_density)
        return r, info

    def _scores_evaluated(self):
        """Scores evaluated so far, per point: ``n_score``, or without a score function the central differences'
        density evaluations over their 2 d per point (the budget of ``score_every="adaptive"``)."""
        if self.target.has_score:
            return self.target.n_score
        return self.target.n_density // (2 * self.dim)

    def _h_at(self, step):
        if self.h_schedule == "constant" or self.steps == 0:
            return self.h_start
        return self.h_start * (self.h_end / self.h_start) ** (min(step, self.steps) / self.steps)

    def run(self):
        """Integrate (:meth:`run_fluid`), then judge the samples (:mod:`.verdict`); returns the SampleResult.

        ``info["converged"]`` is True only when the fluid is at rest and (with ``check=True`` and a log-density) the
        samples pass the verdict's evidence against the target: a short exact MALA chain started from them moves
        no mean or second moment beyond its Bonferroni-corrected Monte-Carlo bound, and no mode found by a mode
        search is short of its Laplace share. A missed mode restarts the run once from the modes found.
        ``info["verdict"]`` has ``at_rest`` and the check's figures; ``info["convergence_reason"]`` says why.
        Warns :class:`NotConvergedWarning` when not converged.
        """
        from .verdict import judge_run

        result = self._run_coarse_to_fine() if self.coarse_to_fine is not None else self.run_fluid()
        result = judge_run(self, result)
        if not result.info["converged"]:
            warnings.warn(f"SPH-ParVI did not converge after {result.info['steps']} steps: "
                          f"{result.info['convergence_reason']}", NotConvergedWarning, stacklevel=2)
        return result

    def run_fluid(self):
        """Integrate and return a :class:`~ase_sphrelax.sampling.result.SampleResult`.

        ``trace`` columns: ``step, time, dt, mean_density, kinetic, energy`` (NaN where the
        configuration is not conservative or p is not known), ``n_density, n_score, wall``.
        ``info``: the parameters, ``rule``, ``chosen_step``, ``fallback`` (zero-density pulls),
        ``jittered`` (coincident starting particles moved apart, see :meth:`_separate_coincident`),
        ``converged``, ``convergence_reason`` and ``convergence`` (the numbers of
        :func:`~ase_sphrelax.sampling.convergence.assess_convergence`), ``start_centre``,
        ``start_scale``, ``target_scale``, ``n_check_density``, ``n_check_score`` (the checks'
        own evaluations, not in ``n_density``/``n_score``). ``converged`` here is the fluid at rest only;
        :meth:`run` adds the verdict's evidence (and the warning).
        """
        t0 = time.perf_counter()
        model = self.model
        self._dt_p = None  # the local steps of the previous step (LOCAL_GROWTH)
        probe = self._probe if self._probe is not None else self.look_at_target()
        r = self.initial_particles()
        r, jittered = self._separate_coincident(r)
        v = np.zeros_like(r)
        renewing = isinstance(self.whiten, str)
        to_x = (lambda y: y) if self.map is None else self.map.to_x
        if renewing:  # the first map, from the initial particles; the default friction follows the scale
            old_log_det = self.map.log_det
            r, v, _ = self.map.renew(r, v)
            if self._friction_from_target and not isinstance(self.friction, str):
                self.friction *= math.exp((self.map.log_det - old_log_det) / self.dim)
                self.parameters["friction"] = self.friction
        spread0_c = np.std(r, axis=0)  # for the divergence hint (not a copy of the particles)
        if self.h_schedule == "anneal":
            model.set_h(self._h_at(0))
        want_energy = model.conservative and self.target.has_density
        ev = model.evaluate(r, v, want_energy=want_energy)
        self._renew_drag()
        m = ev.mass
        rho = ev.rho.copy() if model.density == "continuity" else None
        scale = max(model.alpha, model.c0**2)  # energy per unit mass of the problem
        trace = {k: [] for k in ("step", "time", "dt", "mean_density", "kinetic", "energy", "n_density", "n_score",
                                 "wall")}
        best = dict(step=0, density=-np.inf, samples=to_x(r).copy())
        moments = []  # ensemble mean and covariance of every recorded state (the convergence diagnostics)
        fallback = 0
        sim_time = 0.0
        dt = self._step(ev)
        bar = _progress(self.steps, self.progress, "SPH-ParVI")

        def record(step, dt_now):
            kinetic = 0.5 * m * float(np.einsum("pc,pc->", v, v))
            trace["step"].append(step)
            trace["time"].append(sim_time)
            trace["dt"].append(float(np.median(dt_now)))
            trace["mean_density"].append(float(np.mean(ev.rho)))
            trace["kinetic"].append(kinetic)
            trace["energy"].append(np.nan if ev.energy is None else ev.energy + kinetic)
            trace["n_density"].append(self.target.n_density)
            trace["n_score"].append(self.target.n_score)
            trace["wall"].append(time.perf_counter() - t0)
            moments.append(np.concatenate(ensemble_moments(to_x(r))))
            if trace["mean_density"][-1] > best["density"]:
                best.update(step=step, density=trace["mean_density"][-1], samples=to_x(r).copy())

        record(0, dt)
        limit = self.steps  # the stopping rule may double it (max_steps)
        if self.adaptive_hold:  # steps: evaluations per particle; the SPH steps stop when they are spent
            limit = (self.hold_max + 1) * self.steps  # every particle holding as long as it may
            budget = (self.steps + 1) * self.n
            r_last, age_p = r.copy(), np.zeros(self.n, dtype=np.min_scalar_type(self.hold_max))
            moved = 0  # evaluations triggered by a displacement (the others: the start and hold_max)
        step = 0
        verdict = None
        while step < limit:
            step += 1
            dt_p1 = dt if np.isscalar(dt) else dt[:, None]  # (M, 1) local steps or one number
            friction, drag = self._drag_at(step)
            # r and v are updated in place (the same operations as ``v = damp(v) + ...``, ``r = r + dt v``): their
            # arrays stay where they are, the step's temporaries do not leave holes of their size in the heap
            np.add(damp(v, dt_p1, friction, drag), (0.5 * dt_p1 / m) * ev.forces, out=v)
            if rho is not None:
                rho = rho + np.ravel(dt_p1) * model.density_rate(r, v, rho)
            r += dt_p1 * v
            if self.h_schedule == "anneal":
                model.set_h(self._h_at(step))
            if self.adaptive_hold:  # per particle (held_particles); the held ones keep the score of r_last
                held_p = held_particles(r - r_last, ev.h, self.target.last_score, age_p, self.hold_tolerance,
                                        self.hold_max)
                self.target.hold = held_p
                moved += int(np.sum(~held_p & (age_p < self.hold_max)))
                r_last[~held_p] = r[~held_p]
                age_p += held_p  # in place: a held particle's age is < hold_max before, <= hold_max after
                age_p[~held_p] = 0
            else:
                self.target.hold = step % self.score_every != 0  # score_every: the score of the last K-th step
            ev = None  # the last evaluation's arrays: not held through this one's H solve
            ev = model.evaluate(r, v, rho_p=rho, want_energy=want_energy and step % (self.record_every *
                                                                                   self._record_period) == 0)
            if self.adaptive_hold and self._scores_evaluated() >= budget:
                limit = step  # the evaluation budget is spent
            v += (0.5 * dt_p1 / m) * ev.forces
            damp(v, dt_p1, friction, drag, out=v)
            fallback += ev.fallback
            sim_time += float(np.median(dt))
            kinetic = 0.5 * m * float(np.einsum("pc,pc->", v, v))
            if not (np.all(np.isfinite(r)) and np.all(np.isfinite(v))) or kinetic > 1e6 * scale:
                raise ParVIDivergence(f"SPH-ParVI diverged at step {step} (dt = {np.min(dt):.3g}, kinetic energy "
                                      f"{kinetic:.3g}): {self._divergence_hint(spread0_c)}")
            if rho is not None and not np.all(rho > 0):
                raise ParVIDivergence(f"SPH-ParVI: the continuity density became <= 0 at step {step} "
                                      f"(dt = {np.min(dt):.3g}); use a smaller dt or summation densities")
            if renewing and step % self.whiten_every == 0 and step <= self.whiten_until * self.steps \
                    and step < limit:  # renew the map; the state is carried over exactly (whitening.py)
                r, v, rho = self.map.renew(r, v, rho)
                self.target.hold = False  # the held score is in the old coordinates
                ev = None
                ev = model.evaluate(r, v, rho_p=rho, want_energy=want_energy and step % self.record_every == 0)
                if self.adaptive_hold:
                    r_last, age_p = r.copy(), np.zeros_like(age_p)
                self._renew_drag()
            elif step % self.friction_every == 0:
                self._renew_drag()
            if step % self.record_every == 0 or step == limit:
                record(step, dt)
            dt = self._step(ev)
            if bar is not None:
                bar.update(1)
            if step == limit:
                verdict = assess_convergence(trace["step"], trace["time"], trace["kinetic"], moments, to_x(r),
                                             friction=self.damping_rate())
                if not verdict["converged"] and self.max_steps is not None and limit < self.max_steps:
                    limit = min(2 * limit, self.max_steps)  # a new last half, judged afresh
                    if bar is not None:
                        bar.total = limit
                        bar.refresh()
        self.target.hold = False
        if bar is not None:
            bar.close()
        if verdict is None:  # steps = 0
            verdict = assess_convergence(trace["step"], trace["time"], trace["kinetic"], moments, to_x(r),
                                         friction=self.damping_rate())
        self.final_state = (r, ev)  # in the fluid's coordinates (y when whitened): the coarse level's split
        finished = None if self.finish is None else self._finish(r)  # finish.py (theory.py, G1-G5)
        if finished is not None:
            r, finish_info = finished
        r = to_x(r)
        samples = r if self.rule == "final" else best["samples"]
        chosen = step if self.rule == "final" else best["step"]
        returned = (f"rule={self.rule!r} returned the state of step {chosen}"
                    + (" (the initial particles, untouched)" if chosen == 0 else ""))
        if verdict["converged"] and chosen < verdict["window"][0]:
            verdict.update(converged=False, reason=f"{returned}, before the last half of the run where the fluid was "
                                                   f"found at rest")
        elif not verdict["converged"] and self.rule != "final":
            verdict["reason"] += f"; {returned}"
        info = dict(self.parameters, steps=step, method="sph-parvi", chosen_step=chosen, fallback=fallback, jittered=jittered,
                    optimal_step=best["step"], friction_rates=None if self._drag is None else self._drag[1].tolist(),
                    final_h_median=float(np.median(ev.h)),
                    dt_median=float(np.median(dt)), dt_min=float(np.min(dt)),
                    converged=verdict["converged"], convergence_reason=verdict["reason"],
                    convergence=verdict, start_centre=self.start[0].tolist() if self.x0 is None else None,
                    start_scale=self.start[1].tolist() if self.x0 is None else None,
                    target_scale=self.target_scale.tolist(), n_check_density=probe.n_density,
                    n_check_score=probe.n_score)
        if self.adaptive_hold:
            info["hold_moved_share"] = moved / max(self._scores_evaluated(), 1)
        if finished is not None:
            info["finish_info"] = finish_info
        return SampleResult(np.array(samples), n_density=self.target.n_density, n_score=self.target.n_score,
                            wall_time=time.perf_counter() - t0, trace={k: np.array(val) for k, val in trace.items()},
                            info=info, alternatives=dict(final=np.array(r), optimal=np.array(best["samples"]),
                                                         **({} if finished is None else  # the fluid before the finish
                                                            dict(fluid=np.array(to_x(self.final_state[0]))))))

    def _run_coarse_to_fine(self):
        """``coarse_to_fine=k`` (:mod:`.coarse_to_fine`): the coarse level, its split, the fine level; both levels'
        evaluations counted."""
        t0 = time.perf_counter()
        n_coarse, coarse_steps, fine_steps = self.schedule
        options = dict(self._options, coarse_to_fine=None)
        x0 = None if self.x0 is None else self.x0[:n_coarse]
        coarse = ParVISampler(**dict(options, n=n_coarse, steps=coarse_steps, x0=x0, max_steps=None, rule="final",
                                     finish=None, check=False))
        coarse_result = coarse.run_fluid()  # its verdict (at rest) goes to info["coarse"]
        r_pc, ev = coarse.final_state
        volume_p = np.broadcast_to(np.asarray(ev.mass, dtype=float) / ev.rho, (n_coarse,))
        children = split_into_children(r_pc, volume_p, child_counts(self.n, n_coarse), seed=self.seed)
        if coarse.map is not None:
            children = coarse.map.to_x(children)
        fine = ParVISampler(**dict(options, steps=fine_steps, x0=children, check=False))
        result = fine.run_fluid()  # judged by run()
        result.n_score += coarse_result.n_score
        result.n_density += coarse_result.n_density
        result.wall_time = time.perf_counter() - t0
        result.info["coarse"] = dict(factor=self.coarse_to_fine, share=self.coarse_share, n=n_coarse,
                                     steps=coarse_steps, fine_steps=fine_steps, n_score=coarse_result.n_score,
                                     n_density=coarse_result.n_density, wall=coarse_result.wall_time,
                                     converged=coarse_result.info["converged"],
                                     convergence_reason=coarse_result.info["convergence_reason"],
                                     time=float(coarse_result.trace["time"][-1]),
                                     final_h_median=coarse_result.info["final_h_median"])
        result.info.update(coarse_to_fine=self.coarse_to_fine, coarse_share=self.coarse_share)
        return result


def sample(log_density=None, score=None, n=500, dim=2, seed=0, **kwargs):
    """Sample with SPH-ParVI in its default configuration (:data:`DEFAULTS`); returns a SampleResult.

    ``result.samples`` has shape (n, dim). Keyword arguments override the defaults (see
    :class:`ParVISampler`); the variants of issue 18 are keyword options:

    * ``whiten="covariance"`` — the fluid in coordinates whitened by the particles' mean and
      covariance, renewed every ``whiten_every`` steps until ``whiten_until * steps``, then fixed
      (exact for the fixed map: theory.py, eqs. W1-W3); ``whiten=L`` fixes ``x = L y`` from the start.
    * ``time_step="local"`` — every particle advanced with its own CFL step (local time stepping), so
      that a stiff particle does not set the step of all; the resting states, hence the stationary
      density, are those of the default ``"global"`` step (theory.py, eqs. L1-L3).
    * ``neighbours="knn"`` (with ``k``, default 20) — densities from each particle's k nearest neighbours, for
      any ``k < n`` in any dimension (the kernel default needs M >= 656 in 10-D and cannot run in 32-D); exact
      Stein identities at rest, density p in the continuum limit, a typical-set shell above a few dimensions
      (theory.py, eqs. K1-K7). Combine with ``whiten="covariance"`` on anisotropic targets (the 10-D Gaussian of
      condition number 100: 0.4-1.1x the energy distance of i.i.d. samples at M = 100 and 500,
      reproductions/parvi-highdim/). ``neighbours="knn-ratio"``: experimental, see :class:`ParVISampler`.
    * ``friction="critical"`` — a drag critical along each principal direction of the target's curvature
      seen by the particles, renewed every ``friction_every`` steps; ``friction_ramp < 1`` starts any
      friction lower; friction never changes the stationary density (theory.py, eqs. F1-F3).
    * ``coarse_to_fine=k`` (with ``coarse_share``, default 0.5) — a step that does not shrink with M beyond
      what accuracy needs: ``n // k`` particles (``k^(1/d)`` times longer CFL steps, ``1/k`` of the evaluations
      per step of a final particle) settle the large scales first, each is split into k children that finish at
      n; ``steps`` remains the evaluations per final particle, both levels counted (:mod:`.coarse_to_fine`).
      The fine level is the one-level fluid started from the children: the same stationary density.
      Measured at M = 2000 (reproductions/parvi-banana-m2000/): better than one level on the banana,
      worse on the funnel, short of 2x i.i.d. on both (the coarse level's error relaxes slowly too).
    * ``score_every=K`` — multiple time steps: the score evaluated every K-th SPH step and held in between
      (pressure and drag at every step); ``steps`` counts SPH steps (``steps / K`` evaluations per particle),
      so an evaluation covers K CFL steps of time; the resting states, hence the stationary density, are
      those of K = 1 (see :class:`ParVISampler`). Measured at M = 2000 with 1000 evaluations and
      ``time_step="local", friction="critical"`` (reproductions/parvi-banana-m2000/): K = 4 takes the
      banana below i.i.d. (0.1-0.35x) at ~5x the wall time, and loses the funnel (its neck's score changes
      within the hold). ``score_every="adaptive"`` (with ``hold_tolerance``, ``hold_max``) holds per particle: a
      particle re-evaluates only when it has moved ``hold_tolerance`` of ``min(H, 1 / |s|)`` or after ``hold_max`` held
      steps, the target called on those particles only; ``steps`` is then the evaluations per particle; the
      same resting states as K = 1 (see :class:`ParVISampler`). Measured with ``time_step="local",
      friction="critical"`` at M = 2000, 1000 evaluations (reproductions/parvi-adaptive-hold/): banana
      0.14-0.50x and funnel 0.90-1.97x i.i.d. (3 seeds), the other 2D targets as K = 1. ``hold_max="scaled"``
      (:mod:`.hold_rule`) lengthens the hold like ``n^(1/dim)`` (4 at n = 500, 8 at n = 2000 in 2D) so that an
      evaluation covers the same physical time at any n; any hold keeps the resting states.
    * ``n_neighbours=N`` — about N particles per support instead of the default (32 in 2D): a smaller H resolves
      structures narrower than the default support (the banana's arms, the funnel's neck), whose resting state at
      M = 500 is biased with 32 (reproductions/parvi-rest-vs-time/); exact in the continuum like any N, at the
      price of a CFL step smaller by ``(N / 32)^(1/2)`` in 2D. Measured with ``time_step="local",
      friction="critical", score_every="adaptive", hold_max="scaled"`` and N = 12, 1000 evaluations, six 2D targets,
      3 seeds (reproductions/parvi-rest-vs-time/): <= 0.94x i.i.d. at M = 500 and <= 1.18x at M = 2000 on every
      target and seed; the funnel's M = 500 figure (0.85-0.87x) is a transient (2.4x with 2000 evaluations).
    * ``finish="mala"`` (with ``finish_steps``, default 200) — after the fluid, Metropolis-adjusted Langevin steps
      for every particle in the whitening map's coordinates (p-invariant exactly; theory.py, eqs. G3-G5): removes
      the k-NN fluid's bias above a few dimensions (K5-K7) at one score and one log-density per particle and step
      (counted); ``finish="radial"`` redraws only the radii from the centre (the diagnosis of that bias). Measured
      on the 32-D logistic posterior with ``neighbours="knn", whiten="covariance", steps=540, finish_steps=200``
      (1008 evaluations per particle): means within 0.093 posterior sd and sds within 9 % of NUTS's at M = 500
      (3 seeds), against 0.43 sd and 25 % for the fluid alone (reproductions/parvi-logistic-goal/).

    :func:`variant_options` turns a variant name such as ``"whiten+local+critical"`` into these options.
    """
    return ParVISampler(log_density=log_density, score=score, dim=dim, n=n, seed=seed, **kwargs).run()
