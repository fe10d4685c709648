"""The result of a sampler run, shared by SPH-ParVI and the baselines."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

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
    """

    samples: np.ndarray
    n_density: int = 0
    n_score: int = 0
    wall_time: float = 0.0
    trace: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    @property
    def evaluations(self):
        """Density plus score evaluations."""
        return self.n_density + self.n_score


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
