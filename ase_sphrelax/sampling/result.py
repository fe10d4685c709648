"""The result of a sampler run, shared by SPH-ParVI and the baselines."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..models.parvi import CountingTarget

__all__ = ["SampleResult", "CountingTarget"]


@dataclass
class SampleResult:
    """Samples and the cost of producing them.

    Attributes
    ----------
    samples : ndarray (M, d)
    n_density, n_score : int
        Evaluations of the log-density and of the score, counted per point (a batch call
        on M points counts M). Scores obtained by finite differences count their density
        evaluations under ``n_density``.
    wall_time : float
        Seconds spent in the run (set-up included, compilation of numba loops excluded
        when warmed up by the caller).
    trace : dict of str to ndarray
        Per recorded step (``step``, and method-specific columns).
    info : dict
        Method, parameters and anything else worth reporting (e.g. the chosen step).
    alternatives : dict of str to ndarray
        The samples another selection rule would have returned from the same run (SPH-ParVI:
        ``"final"`` and ``"optimal"``).
    """

    samples: np.ndarray
    n_density: int = 0
    n_score: int = 0
    wall_time: float = 0.0
    trace: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    alternatives: dict = field(default_factory=dict)

    @property
    def evaluations(self):
        """Density plus score evaluations."""
        return self.n_density + self.n_score
