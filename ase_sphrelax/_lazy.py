"""Package attributes imported on first use (PEP 562).

``import ase_sphrelax`` (and so ``sphrelax --help``) must not load numba, scipy or
LAMMPS: a package ``__init__`` lists its public names with the submodule that
defines them and lets :func:`lazy_exports` resolve them when first touched.
"""
from __future__ import annotations

import importlib

__all__ = ["lazy_exports"]


def lazy_exports(namespace, where):
    """Return ``(__getattr__, __dir__)`` for a package namespace.

    Parameters
    ----------
    namespace : dict
        The package's ``globals()``; a resolved name is stored there, so it wins
        over a submodule of the same name (``lammps_io.sph_at_rest``).
    where : dict
        ``{public name: submodule}``, the submodule relative (``".calculators"``)
        or absolute.
    """
    package = namespace["__name__"]

    def __getattr__(name):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(where[name], package), name)
        namespace[name] = value
        return value

    def __dir__():
        return sorted(set(namespace) | set(where))

    return __getattr__, __dir__
