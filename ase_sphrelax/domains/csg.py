"""Constructive solid geometry on level sets: union, intersection, difference.

``phi_{A|B} = min(phi_A, phi_B)``, ``phi_{A&B} = max(phi_A, phi_B)``,
``phi_{A-B} = max(phi_A, -phi_B)``; the normal is that of the operand that
attains the min/max (exact gradient of the returned ``phi``, one-sided where
the two are equal).  The results are exact signed distances inside/outside
only away from the seams, but ``{phi < 0}`` is exactly the set operation and
``|grad phi| = 1`` almost everywhere, which is all the boundary term of Fan
Eq. 3.8 / 4.4 uses near the boundary.

Volume: in 2D, when every operand is a :class:`Polygon`, :class:`Box` or
:class:`Circle` (or CSG of those), the shapely boolean area, with circles as
4096-gons of the exact disc area (exact for polygons; relative error of
order (2 pi / 4096)^2 ~ 2e-6 of the part of a disc that is cut; measured:
annulus Circle(0.3) - Circle(0.2) of Fan Appendix C and trapezoid minus a
disc exact to 4e-15, box cutting a disc in half exact).  Otherwise (3D, tabulated or meshes) the
extrapolated smoothed-Heaviside grid integral of
:func:`~.base.smoothed_volume` (relative error ~1e-6 for smooth boundaries).
"""
from __future__ import annotations

# defined in base.py, next to Domain whose ``|``, ``&`` and ``-`` build them (no import cycle)
from .base import BooleanDomain, Difference, Intersection, Union

__all__ = ["BooleanDomain", "Union", "Intersection", "Difference"]
