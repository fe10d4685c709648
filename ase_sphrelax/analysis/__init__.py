"""Analysis: quality metrics, characteristic volumes and lattice patterns (Fan Sec. 5).

Lattice theory, one module per idea: ``lattice_sums`` (v_c of a periodic
arrangement, Eq. 5.2), ``pattern_cells`` (the cells of the patterns),
``pattern_prediction`` (best member of each family, predicted pattern, Table 2),
``patterns`` (variable-cell relaxation of periodic patterns, the ``lattice`` and
``table`` commands' bodies), ``symmetry`` (spglib classification), ``bounded``
(patterns in bounded domains), ``cell_filter`` (constant-area cell filter), ``shock`` (a blast
front's radius per direction and its spread over angle).

Names are imported on first use, so ``import ase_sphrelax.analysis.quality`` does
not load spglib or the lattice machinery.
"""
from ..lazy import lazy_exports

_WHERE = {
    "Quality": ".quality",
    "quality_summary": ".quality",
    "lattice_kernel_sum": ".lattice_sums",
    "characteristic_volume_of_cell": ".lattice_sums",
    "characteristic_volume_of_atoms": ".lattice_sums",
    "PATTERNS_2D": ".pattern_cells",
    "PATTERNS_3D": ".pattern_cells",
    "pattern_cell": ".pattern_cells",
    "CONVENTIONS": ".pattern_prediction",
    "characteristic_volume": ".pattern_prediction",
    "predict_pattern": ".pattern_prediction",
    "pattern_table": ".pattern_prediction",
    "classify_lattice": ".symmetry",
    "pattern_name_3d": ".symmetry",
    "LatticeNotFoundError": ".symmetry",
    "ConstantMeasureCellFilter": ".cell_filter",
    "relax_lattice": ".patterns",
    "lattice_report": ".patterns",
    "write_table": ".patterns",
    "classify_bounded_pattern": ".bounded",
    "relax_circle": ".bounded",
    "alaric_min_error": ".alaric",
    "pack_summary": ".bipi",
    "shock_radii": ".shock",
    "shock_isotropy": ".shock",
    "angular_modes": ".shock",
}
__all__ = sorted(_WHERE)
_SUBMODULES = ("alaric", "bounded", "cell_filter", "lattice_sums", "pattern_cells", "pattern_prediction", "patterns",
               "quality", "shock", "symmetry")
__getattr__, __dir__ = lazy_exports(globals(), _WHERE, _SUBMODULES)
