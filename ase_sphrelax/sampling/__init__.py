"""Sampling unnormalised densities with SPH (SPH-ParVI) and the tools to judge it.

* :mod:`.targets` — test densities with scores and reference samplers;
* :mod:`.metrics` — energy distance, MMD, sliced Wasserstein, moment and mode errors;
* :mod:`.baselines` — SVGD, ULA, MALA and emcee, run like the SPH sampler;
* :mod:`.result` — :class:`SampleResult` and the evaluation-counting wrapper;
* :mod:`.sampler` — :class:`ParVISampler` and :func:`sample`;
* :mod:`.configurations` — the default configuration, :data:`CLASSIC` (the old one) and the ``--variant`` tokens;
* :mod:`.verdict` — is the sample right: an exact MALA check and a mode search behind ``converged``;
* :mod:`.theory` — the predicted stationary densities;
* :mod:`.convergence` — has a run come to rest (moment and kinetic-energy drift against Monte-Carlo errors);
* :mod:`.target_checks` — the target's mode and scale, a flipped score, a score of another target.
* :mod:`.whitening` — the affine map of the whitened variant (``sample(..., whiten="covariance")``);
* :mod:`.tuning` — the one rule that sets the baselines' step sizes (pilot, kernel Stein discrepancy).
"""
from ..lazy import lazy_exports

# names are imported on first use (the sampler loads numba; ``sphrelax sample --help`` reads only
# :mod:`.configurations`): add one line here
_WHERE = {
    "CLASSIC": ".configurations",
    "DEFAULTS": ".configurations",
    "SampleResult": ".result",
    "CountingTarget": ".result",
    "ParVISampler": ".sampler",
    "ParVIDivergence": ".sampler",
    "sample": ".sampler",
    "Target": ".targets",
    "get_target": ".targets",
    "TARGET_NAMES": ".targets",
}
__all__ = list(_WHERE)
__getattr__, __dir__ = lazy_exports(globals(), _WHERE)
