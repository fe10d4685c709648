"""ase_sphrelax: SPH particle relaxation as ASE calculators and optimisers.

Methods: Fan et al. (total error, Eq. 3.8) as :class:`FanCalculator` with the
Eq. 2.4 driver :class:`FanRelaxation`.
"""
from .calculators import FanCalculator
from .drivers import FanRelaxation
from .kernels import Kernel, get_kernel
from .neighbors import NeighborList

__version__ = "0.1.0"
__all__ = ["FanCalculator", "FanRelaxation", "Kernel", "get_kernel", "NeighborList", "__version__"]
