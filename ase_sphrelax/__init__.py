"""ase_sphrelax: SPH particle relaxation as ASE calculators and optimisers.

Methods: Fan et al. (total error, Eq. 3.8) as :class:`FanCalculator` with the
Eq. 2.4 driver :class:`FanRelaxation`.
"""
from .calculators import FanCalculator
from .drivers import FanRelaxation
from .build import fill, periodic_box
from .domains import Box, Circle, Difference, Intersection, Mesh, Polygon, Sphere, Union
from .kernels import Kernel, get_kernel
from .neighbors import NeighborList
from .calculators.parvi import ParVICalculator; from .sampling.sampler import sample  # noqa: E702

__version__ = "0.1.0"
__all__ = ["FanCalculator", "FanRelaxation", "Kernel", "get_kernel", "NeighborList", "fill", "periodic_box",
           "ParVICalculator", "sample", "Box", "Circle", "Sphere", "Polygon", "Mesh", "Union", "Intersection", "Difference", "__version__"]
