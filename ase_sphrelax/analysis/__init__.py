"""Analysis: quality metrics, characteristic volumes and lattice patterns (Fan Sec. 5).

Names are imported on first use, so ``import ase_sphrelax.analysis.quality`` does
not load spglib or the lattice machinery.
"""
import importlib

_WHERE = {
    "Quality": "quality",
    "quality_summary": "quality",
    "characteristic_volume": "lattice",
    "predict_pattern": "lattice",
    "classify_lattice": "symmetry",
    "relax_lattice": "patterns",
}
__all__ = sorted(_WHERE)


def __getattr__(name):
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
