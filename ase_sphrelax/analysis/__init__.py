"""Analysis: quality metrics, characteristic volumes and lattice patterns (Fan Sec. 5).

Names are imported on first use, so ``import ase_sphrelax.analysis.quality`` does
not load spglib or the lattice machinery.
"""
from .._lazy import lazy_exports

_WHERE = {
    "Quality": ".quality",
    "quality_summary": ".quality",
    "PATTERNS_2D": ".lattice",
    "PATTERNS_3D": ".lattice",
    "characteristic_volume": ".lattice",
    "characteristic_volume_of_cell": ".lattice",
    "characteristic_volume_of_atoms": ".lattice",
    "pattern_cell": ".lattice",
    "predict_pattern": ".lattice",
    "classify_lattice": ".symmetry",
    "pattern_name_3d": ".symmetry",
    "LatticeNotFoundError": ".symmetry",
    "ConstantMeasureCellFilter": ".cell_filter",
    "relax_lattice": ".patterns",
    "lattice_report": ".patterns",
    "write_table": ".patterns",
    "classify_bounded_pattern": ".bounded",
    "relax_circle": ".bounded",
}
__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_exports(globals(), _WHERE)
