"""Has an SPH-ParVI run come to rest? Drift of the ensemble's moments and of its kinetic energy.

A particle sampler returns one ensemble of M particles; the user reads moments off it. A run is
judged converged when, over the last half of the run, nothing the user would read moves by more
than its own Monte-Carlo error:

* **mean and covariance drift.** Each moment of the recorded states is compared with the
  Monte-Carlo standard error of the final ensemble (``sd_c / sqrt(M)`` for a mean,
  ``std((x_i - mu_i)(x_j - mu_j)) / sqrt(M)`` for a covariance entry: the particles' own fourth
  moments, no Gaussian assumption) in three ways: the change of its average from the third to the
  fourth quarter of the run, its range (max - min) within the fourth quarter, and the change still
  to come. The last is projected from the ranges R3, R4 of the last two quarters: in a geometric
  approach (exponential, or a damped oscillation) the range shrinks by ``rho = R4 / R3`` per
  quarter and the moment still moves by ``R4 rho / (1 - rho)``; when ``rho >= 1`` there is no limit
  in sight and the projection is the change over another run as long as this one, ``4 R4``. A change larger than one standard error means the answer
  depends on when the run stopped more than on the sample size. A slow approach (a run shorter
  than the fluid's relaxation time) moves little per quarter but shrinks slowly: the projection
  catches it.
* **damping time.** With a drag ``beta`` velocities are forgotten over ``1 / beta``: a window (the
  last half of the run) shorter than that is shorter than the memory of the dynamics, and its
  slow modes move too little within it to be seen (e.g. the spread of a 1D fluid whose CFL step
  is small: 600 steps are 0.5 time units at M = 500). Such a run is not converged whatever its
  moments do.
* **kinetic energy.** The mean kinetic energy of the fourth quarter must not exceed that of the
  third (a damped fluid at rest loses energy; a rising one is being driven or expelled), unless the
  particles' motion is too slow to move any mean by one standard error within a quarter of the
  run (round-off motion of a fluid at rest).

No number here is fitted to a target: the scale of every comparison is the ensemble's own
standard error.
"""
from __future__ import annotations

import numpy as np

__all__ = ["ensemble_moments", "moment_standard_errors", "assess_convergence", "ROUND_OFF"]

#: a change of a moment below this fraction of its size is floating-point noise of a fluid at rest
ROUND_OFF = 1e-9


def ensemble_moments(x_pc):
    """The mean (d,) and the upper triangle of the covariance (d (d + 1) / 2,) of particles ``x_pc`` (M, d)."""
    mu_c = x_pc.mean(axis=0)
    cov_cc = np.cov(x_pc, rowvar=False, bias=True).reshape(x_pc.shape[1], x_pc.shape[1])
    return mu_c, cov_cc[np.triu_indices(x_pc.shape[1])]


def moment_standard_errors(x_pc):
    """Monte-Carlo standard errors of :func:`ensemble_moments` for M particles: ``sd / sqrt(M)`` for the
    mean, ``std(y_i y_j) / sqrt(M)`` (``y = x - mean``) for each covariance entry."""
    m = x_pc.shape[0]
    y_pc = x_pc - x_pc.mean(axis=0)
    iu, ju = np.triu_indices(x_pc.shape[1])
    return y_pc.std(axis=0) / np.sqrt(m), (y_pc[:, iu] * y_pc[:, ju]).std(axis=0) / np.sqrt(m)


def _moment_names(dim):
    iu, ju = np.triu_indices(dim)
    return [f"mean[{c}]" for c in range(dim)] + [f"cov[{i},{j}]" for i, j in zip(iu, ju)]


def assess_convergence(steps_k, times_k, kinetic_k, moments_k, x_final_pc, friction=0.0):
    """Judge a run from its recorded states (see the module docstring).

    Parameters
    ----------
    steps_k, times_k, kinetic_k : array (K,)
        Step, simulated time and kinetic energy of each recorded state (the last one is the final state).
    moments_k : array (K, d + d (d + 1) / 2)
        :func:`ensemble_moments` of each recorded state, concatenated.
    x_final_pc : array (M, d)
        The final particles (for the standard errors).
    friction : float
        The drag ``beta`` of the run (0: none). A run whose last half is shorter than the drag's
        damping time ``1 / beta`` is not converged: the window judged is shorter than the memory of
        the dynamics, so slow modes are invisible in it.

    Returns
    -------
    dict
        ``converged`` (bool), ``reason`` (one sentence), ``mean_drift_se`` and ``cov_drift_se``
        (largest change over the last half in standard errors), ``kinetic_ratio`` (mean kinetic
        energy of the fourth quarter over the third), ``window`` (first and last step judged).
    """
    steps_k = np.asarray(steps_k, dtype=float)
    total = steps_k[-1]
    q3 = (steps_k > 0.5 * total) & (steps_k <= 0.75 * total)
    q4 = steps_k > 0.75 * total
    out = dict(converged=False, mean_drift_se=None, cov_drift_se=None, kinetic_ratio=None,
               window=[float(0.5 * total), float(total)])
    if q3.sum() < 2 or q4.sum() < 2:
        out["reason"] = (f"too short to judge: {int(total)} steps leave fewer than two recorded states in the third "
                         f"or the fourth quarter (record_every too large or too few steps)")
        return out
    moments_k = np.asarray(moments_k, dtype=float)
    dim = x_final_pc.shape[1]
    se_mean, se_cov = moment_standard_errors(x_final_pc)
    se = np.concatenate([se_mean, se_cov])
    se = np.where(se > 0, se, np.finfo(float).tiny)
    avg3, avg4 = moments_k[q3].mean(axis=0), moments_k[q4].mean(axis=0)
    delta4 = np.abs(avg4 - avg3)
    # what is still to come: the range of a moment within a quarter shrinks by rho = R4 / R3 per quarter
    # in a geometric (exponential or damped oscillating) approach, which continues by R4 rho / (1 - rho);
    # a range that does not shrink has no limit in sight: its change over another run as long as this one
    # (four quarters) is what is to come
    range3, range4 = np.ptp(moments_k[q3], axis=0), np.ptp(moments_k[q4], axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(range3 > 0, range4 / range3, np.where(range4 > 0, np.inf, 0.0))
        to_come = np.where(rho < 1.0, range4 * rho / (1.0 - rho), 4.0 * range4)
    to_come = np.where(range4 <= ROUND_OFF * np.maximum(np.abs(avg4), se), 0.0, to_come)
    drift = np.maximum(np.maximum(delta4, range4), to_come) / se
    out["mean_drift_se"] = float(drift[:dim].max())
    out["cov_drift_se"] = float(drift[dim:].max())
    kinetic_k = np.asarray(kinetic_k, dtype=float)
    ke3, ke4 = float(kinetic_k[q3].mean()), float(kinetic_k[q4].mean())
    out["kinetic_ratio"] = ke4 / ke3 if ke3 > 0 else (np.inf if ke4 > 0 else 1.0)
    # how far the particles can still move within a quarter: rms speed (kinetic = 0.5 * mean v^2 for m = 1/M)
    quarter_time = float(np.asarray(times_k)[-1] - np.asarray(times_k)[q3][0]) / 2.0
    reach = np.sqrt(2.0 * max(ke4, 0.0)) * quarter_time
    reasons = []
    worst = int(np.argmax(drift))
    if drift[worst] > 1.0:
        names = _moment_names(dim)
        still = (f"not slowing down: {to_come[worst]:.3g} over another run as long" if rho[worst] >= 1.0 else
                 f"projected to move {to_come[worst]:.3g} more")
        reasons.append(f"{names[worst]} still moves: {avg3[worst]:.4g} -> {avg4[worst]:.4g} (averages of the third "
                       f"and fourth quarter of the run), by {range4[worst]:.3g} within the last quarter, {still} "
                       f"(standard error {se[worst]:.2g})")
    if ke4 > ke3 and reach > se_mean.min():
        reasons.append(f"kinetic energy rising over the last half ({ke3:.3g} -> {ke4:.3g})")
    times_k = np.asarray(times_k, dtype=float)
    window_time = float(times_k[-1] - times_k[steps_k <= 0.5 * total][-1])
    out["window_time"] = window_time
    if friction > 0 and window_time * friction < 1.0:
        reasons.append(f"the last half of the run lasted {window_time:.3g} time units, less than the damping time "
                       f"of the friction (1 / friction = {1.0 / friction:.3g}): too short to see the fluid settle "
                       f"(more steps)")
    out["converged"] = not reasons
    out["reason"] = ("at rest: every mean and covariance entry moved by less than one standard error over the last "
                     "half, kinetic energy not rising") if not reasons else "; ".join(reasons)
    return out
