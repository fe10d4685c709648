"""Sampling unnormalised densities with SPH (SPH-ParVI) and the tools to judge it.

* :mod:`.targets` — test densities with scores and reference samplers;
* :mod:`.metrics` — energy distance, MMD, sliced Wasserstein, moment and mode errors;
* :mod:`.baselines` — SVGD, ULA, MALA and emcee, run like the SPH sampler;
* :mod:`.result` — :class:`SampleResult` and the evaluation-counting wrapper;
* :mod:`.sampler` — :class:`ParVISampler` and :func:`sample` (the default configuration; :data:`CLASSIC` the old one);
* :mod:`.verdict` — is the sample right: an exact MALA check and a mode search behind ``converged``;
* :mod:`.theory` — the predicted stationary densities;
* :mod:`.convergence` — has a run come to rest (moment and kinetic-energy drift against Monte-Carlo errors);
* :mod:`.target_checks` — the target's mode and scale, a flipped score, a score of another target.
* :mod:`.whitening` — the affine map of the whitened variant (``sample(..., whiten="covariance")``);
* :mod:`.tuning` — the one rule that sets the baselines' step sizes (pilot, kernel Stein discrepancy).
"""
from .result import CountingTarget, SampleResult
from .sampler import CLASSIC, ParVIDivergence, ParVISampler, sample
from .targets import TARGET_NAMES, Target, get_target

__all__ = ["CLASSIC", "SampleResult", "CountingTarget", "ParVISampler", "ParVIDivergence", "sample", "Target", "get_target",
           "TARGET_NAMES"]
