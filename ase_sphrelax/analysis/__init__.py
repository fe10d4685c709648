"""Analysis: quality metrics, characteristic volumes and lattice patterns (Fan Sec. 5)."""
from .lattice import characteristic_volume, predict_pattern
from .patterns import relax_lattice
from .quality import Quality, quality
from .symmetry import classify_lattice

__all__ = ["Quality", "quality", "characteristic_volume", "predict_pattern", "classify_lattice", "relax_lattice"]
