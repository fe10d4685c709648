"""ase_sphrelax: SPH particle relaxation as ASE calculators and optimisers.

Methods: Fan et al. (total error, Eq. 3.8) as :class:`FanCalculator` with the
Eq. 2.4 driver :class:`FanRelaxation`.

The names below are imported on first use, so that ``import ase_sphrelax`` (and
``sphrelax --help``) loads no numba: to export a name, add one line to ``_WHERE``
(name -> defining module), never an eager import (``tests/test_cli.py`` checks).
"""
from ._lazy import lazy_exports

__version__ = "0.1.0"

_WHERE = {
    "FanCalculator": ".calculators",
    "BIPICalculator": ".calculators",
    "ALARICCalculator": ".calculators.alaric",
    "FanRelaxation": ".drivers",
    "BIPIPacker": ".drivers",
    "Kernel": ".kernels",
    "get_kernel": ".kernels",
    "NeighborList": ".neighbors",
    "fill": ".build",
    "periodic_box": ".build",
    "Box": ".domains",
    "Circle": ".domains",
    "Sphere": ".domains",
    "Polygon": ".domains",
    "Mesh": ".domains",
    "Union": ".domains",
    "Intersection": ".domains",
    "Difference": ".domains",
    "ParVICalculator": ".calculators.parvi", "sample": ".sampling.sampler",  # SPH-ParVI
}
__all__ = list(_WHERE) + ["__version__"]
__getattr__, __dir__ = lazy_exports(globals(), _WHERE)
