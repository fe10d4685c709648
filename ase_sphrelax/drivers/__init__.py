"""Drivers: the papers' own update rules as ASE optimisers, and scale-aware ASE optimisers."""
from .blas import limit_blas_in_steps
from .fan_relaxation import FanRelaxation
from .optimizers import OPTIMIZERS, make_optimizer

__all__ = ["FanRelaxation", "make_optimizer", "OPTIMIZERS", "limit_blas_in_steps"]
