"""ASE calculators, one module per method."""
from .bipi import BIPICalculator
from .fan import FanCalculator

__all__ = ["FanCalculator", "BIPICalculator"]
