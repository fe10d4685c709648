"""Method physics, one module per method (``fan.py``, ...).

A model owns a method's parameters, their validation and its closed-form terms
(volumes, prefactors, self and boundary terms, stress corrections). It runs no
pair loop: calculators sum its pair terms with :mod:`ase_sphrelax.pairs` (or
LAMMPS). Its submodules load on first use (``ase_sphrelax.models.fan``), so importing the
package loads nothing.
"""
from ..lazy import lazy_exports

__all__ = ["alaric", "bipi", "fan", "parvi"]
__getattr__, __dir__ = lazy_exports(globals(), {}, __all__)
