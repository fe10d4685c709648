"""Level-set domains (Fan et al. Sec. 2): signed distance ``phi`` < 0 inside,
outward normal ``n = grad phi``."""
from .analytic import Ball, Box, Circle, Sphere
from .base import BooleanDomain, Difference, Domain, Intersection, Tabulated, Union
from .mesh import Mesh
from .polygon import Polygon

__all__ = ["Domain", "Ball", "Circle", "Sphere", "Box", "Polygon", "Mesh",
           "Union", "Intersection", "Difference", "BooleanDomain", "Tabulated"]
