"""ASE calculators, one module per method."""
from .fan import FanCalculator

__all__ = ["FanCalculator"]
