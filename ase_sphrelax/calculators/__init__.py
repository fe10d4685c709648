"""ASE calculators, one module per method."""
from .bipi import BIPICalculator
from .fan import FanCalculator
from .alaric import ALARICCalculator

__all__ = ["FanCalculator", "ALARICCalculator", "BIPICalculator"]
