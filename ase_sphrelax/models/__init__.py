"""Method physics, one module per method (``fan.py``, ...).

A model owns a method's parameters, their validation and its closed-form terms
(volumes, prefactors, self and boundary terms, stress corrections). It runs no
pair loop: calculators sum its pair terms with :mod:`ase_sphrelax.pairs` (or
LAMMPS). This package imports nothing on purpose: import ``ase_sphrelax.models.NAME``.
"""
