"""Analysis: quality metrics, characteristic volumes and lattice patterns (Fan Sec. 5).

Names are imported on first use, so ``import ase_sphrelax.analysis.quality`` does
not load spglib or the lattice machinery.
"""
import importlib

_WHERE = {
    "Quality": "quality",
    "quality_summary": "quality",
    "PATTERNS_2D": "lattice",
    "PATTERNS_3D": "lattice",
    "characteristic_volume": "lattice",
    "characteristic_volume_of_cell": "lattice",
    "characteristic_volume_of_atoms": "lattice",
    "pattern_cell": "lattice",
    "predict_pattern": "lattice",
    "classify_lattice": "symmetry",
    "pattern_name_3d": "symmetry",
    "LatticeNotFoundError": "symmetry",
    "ConstantMeasureCellFilter": "cell_filter",
    "relax_lattice": "patterns",
    "lattice_report": "patterns",
    "write_table": "patterns",
    "classify_bounded_pattern": "bounded",
    "relax_circle": "bounded",
    "alaric_min_error": "alaric",
}
__all__ = sorted(_WHERE)


def __getattr__(name):
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
