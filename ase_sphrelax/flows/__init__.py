"""Downstream flows: a weakly compressible SPH solver with boundary-integral walls (BISPH, BIPI Sec. 4.2).

A judge of particle starts, not a general CFD code: :class:`BISPH` (the equations, BIPI Eqs. 16-21)
and the scenes of :mod:`.scene` (a :class:`~ase_sphrelax.boundary.BoundarySegments`, fluid particles
and a body force); :meth:`BISPH.run` returns KE(t) and pressure histories.

Names are imported on first use (numba): add one line to ``_WHERE``.
"""
from ..lazy import lazy_exports

_WHERE = {
    "BISPH": ".bisph",
    "RunHistory": ".bisph",
    "tank": ".scene",
    "channel": ".scene",
    "cartesian_fill": ".scene",
    "poiseuille": ".scene",
    "wall_distance": ".scene",
    "elliptic_drop": ".scene",
}
__all__ = list(_WHERE)
__getattr__, __dir__ = lazy_exports(globals(), _WHERE)
