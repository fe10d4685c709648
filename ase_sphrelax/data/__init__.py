"""Small data files shipped with the package: the 2D boundaries that the documentation's examples name.

=================  ========  =====  ==============================================================
file               segments  units  what it is
=================  ========  =====  ==============================================================
``tank.edges``     4         m      the BIPI paper's trapezoidal tank, vertices (0,1) (0,0) (1,0) (1.5,1)
``bunny.edges``    882       mm     outline of the Stanford bunny, about 108 x 108
``airfoil.edges``  824       inch   NACA 6412 airfoil (the solid), chord 20
=================  ========  =====  ==============================================================

Edge files hold one boundary segment per line, ``x1 y1 x2 y2``, in closed counter-clockwise loops
(:meth:`ase_sphrelax.boundary.BoundarySegments.from_edges`). Source: the example boundaries of the
BIPI2D repository (RealTimeSimLab/BIPI2D, MIT licence, Copyright (c) 2024 Parikshit Boregowda),
converted from Nastran bulk format to this plain format (``TrapezoidalTank``, ``Standford2DBunny``
and ``AirFoilSolid`` there).

``sphrelax data --list`` lists them and ``sphrelax data NAME [--out PATH]`` copies one out; in Python,
:func:`path` gives a file's location and :func:`copy` copies it.
"""
from __future__ import annotations

import shutil
from pathlib import Path

__all__ = ["names", "path", "copy"]

_HERE = Path(__file__).resolve().parent


def names():
    """The names of the data files, sorted (``["airfoil.edges", "bunny.edges", "tank.edges"]``)."""
    return sorted(p.name for p in _HERE.iterdir() if p.is_file() and not p.name.endswith((".py", ".pyc")))


def path(name):
    """The path of the data file ``name`` inside the installed package.

    Raises
    ------
    ValueError
        ``name`` is not one of :func:`names`.
    """
    if name not in names():
        raise ValueError(f"name must be one of {', '.join(names())}, got {name!r}")
    return _HERE / name


def copy(name, out=None, overwrite=False):
    """Copy the data file ``name`` to ``out`` (a file or an existing folder; default ``./name``); return the path.

    Raises
    ------
    ValueError
        ``name`` is unknown.
    FileExistsError
        ``out`` exists and ``overwrite`` is False.
    """
    source = path(name)
    target = Path(name) if out is None else Path(out)
    if target.is_dir():
        target = target / name
    if target.exists() and not overwrite:
        raise FileExistsError(f"out {str(target)!r} exists (pass overwrite=True)")
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(source, target)
    return target
