"""Has an SPH-ParVI run come to rest? Drift of the ensemble's moments and of its kinetic energy.

A particle sampler returns one ensemble of M particles; the user reads moments off it. A run is
judged converged when, over the last half of the run, nothing the user would read moves by more
than its own Monte-Carlo error:

* **mean and covariance drift.** The moments are averaged over the recorded states of the second,
  third and fourth quarter of the run. Three changes are compared with the Monte-Carlo standard
  errors of the final ensemble (``sd_c / sqrt(M)`` for a mean, ``std((x_i - mu_i)(x_j - mu_j)) /
  sqrt(M)`` for a covariance entry: the particles' own fourth moments, no Gaussian assumption):
  the change from the third to the fourth quarter, the spread (max - min) within the fourth
  quarter, and the change still to come if the approach is geometric (Aitken:
  ``delta4 rho / (1 - rho)``, ``rho = delta4 / delta3``; infinite when the change does not shrink).
  A change larger than one standard error means the answer still depends on when the run stopped
  more than on the sample size. A slow approach (a run shorter than the fluid's relaxation
  time) moves little per quarter but shrinks slowly: the projection catches it.
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


def assess_convergence(steps_k, times_k, kinetic_k, moments_k, x_final_pc):
    """Judge a run from its recorded states (see the module docstring).

    Parameters
    ----------
    steps_k, times_k, kinetic_k : array (K,)
        Step, simulated time and kinetic energy of each recorded state (the last one is the final state).
    moments_k : array (K, d + d (d + 1) / 2)
        :func:`ensemble_moments` of each recorded state, concatenated.
    x_final_pc : array (M, d)
        The final particles (for the standard errors).

    Returns
    -------
    dict
        ``converged`` (bool), ``reason`` (one sentence), ``mean_drift_se`` and ``cov_drift_se``
        (largest change over the last half in standard errors), ``kinetic_ratio`` (mean kinetic
        energy of the fourth quarter over the third), ``window`` (first and last step judged).
    """
    steps_k = np.asarray(steps_k, dtype=float)
    total = steps_k[-1]
    q2 = (steps_k > 0.25 * total) & (steps_k <= 0.5 * total)
    q3 = (steps_k > 0.5 * total) & (steps_k <= 0.75 * total)
    q4 = steps_k > 0.75 * total
    out = dict(converged=False, mean_drift_se=None, cov_drift_se=None, kinetic_ratio=None,
               window=[float(0.5 * total), float(total)])
    if not (q2.any() and q3.any() and q4.any()):
        out["reason"] = (f"too short to judge: {int(total)} steps leave no recorded state in the second, third or "
                         f"fourth quarter (record_every too large or too few steps)")
        return out
    moments_k = np.asarray(moments_k, dtype=float)
    dim = x_final_pc.shape[1]
    se_mean, se_cov = moment_standard_errors(x_final_pc)
    se = np.concatenate([se_mean, se_cov])
    se = np.where(se > 0, se, np.finfo(float).tiny)
    avg2, avg3, avg4 = (moments_k[q].mean(axis=0) for q in (q2, q3, q4))
    delta3, delta4 = np.abs(avg3 - avg2), np.abs(avg4 - avg3)
    # what is still to come: a geometric (exponential) approach continues by delta4 rho / (1 - rho),
    # rho = delta4 / delta3; a change that does not shrink has no limit in sight
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(delta3 > 0, delta4 / delta3, np.where(delta4 > 0, np.inf, 0.0))
        to_come = np.where(rho < 1.0, delta4 * rho / (1.0 - rho), np.inf)
    to_come = np.where(delta4 <= ROUND_OFF * np.maximum(np.abs(avg4), se), 0.0, to_come)
    spread = np.ptp(moments_k[q4], axis=0)
    drift = np.maximum(np.maximum(delta4, spread), to_come) / se
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
        still = "without slowing down" if not np.isfinite(to_come[worst]) else (
            f"and is projected to move {to_come[worst] / se[worst]:.3g} more" if to_come[worst] > delta4[worst] else "")
        reasons.append(f"{names[worst]} still moves: {avg2[worst]:.4g} -> {avg3[worst]:.4g} -> {avg4[worst]:.4g} "
                       f"over the last three quarters of the run {still} (standard error {se[worst]:.2g})")
    if ke4 > ke3 and reach > se_mean.min():
        reasons.append(f"kinetic energy rising over the last half ({ke3:.3g} -> {ke4:.3g})")
    out["converged"] = not reasons
    out["reason"] = ("at rest: every mean and covariance entry moved by less than one standard error over the last "
                     "half, kinetic energy not rising") if not reasons else "; ".join(reasons)
    return out
