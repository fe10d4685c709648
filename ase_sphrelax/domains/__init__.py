"""Level-set domains (Fan et al. Sec. 2): signed distance ``phi`` < 0 inside,
outward normal ``n = grad phi``."""
from .analytic import Ball, Box, Circle, Sphere
from .base import Domain
from .csg import Difference, Intersection, Union
from .mesh import Mesh
from .polygon import Polygon
from .table import Tabulated

__all__ = ["Domain", "Ball", "Circle", "Sphere", "Box", "Polygon", "Mesh",
           "Union", "Intersection", "Difference", "Tabulated"]
