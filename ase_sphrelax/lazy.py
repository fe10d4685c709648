"""Package attributes imported on first use (SPEC 1, through ``lazy_loader``).

``import ase_sphrelax`` (and so ``sphrelax --help``) must not load numba, scipy or
LAMMPS: a package ``__init__`` lists its public names with the submodule that
defines them, and its submodules, and :func:`lazy_exports` resolves both when first
touched (``ase_sphrelax.domains.Circle`` works after a bare ``import ase_sphrelax``).
Public, so that companion packages (``lammps_io``) use it without another package's private name.
"""
from __future__ import annotations

import lazy_loader

__all__ = ["lazy_exports"]


def lazy_exports(namespace, where, submodules=()):
    """Return ``(__getattr__, __dir__)`` for a package namespace.

    Parameters
    ----------
    namespace : dict
        The package's ``globals()``. A resolved name is cached there by ``lazy_loader``, so it
        wins over a submodule of the same name.
    where : dict
        ``{public name: submodule}``, the submodule relative to the package (``".calculators"``,
        ``".calculators.alaric"``).
    submodules : iterable of str
        Submodules reachable as attributes (``"domains"``, ``"build"``), loaded on first use.

    Raises
    ------
    ValueError
        When an entry of ``where`` is not a relative module path.
    """
    package = namespace["__name__"]
    submod_attrs: dict = {}
    for name, module in where.items():
        if not module.startswith(".") or module.startswith(".."):
            raise ValueError(f"where[{name!r}] must be a submodule relative to {package} ('.name'), got {module!r}")
        submod_attrs.setdefault(module[1:], []).append(name)
    getattr_, dir_, _ = lazy_loader.attach(package, submodules=list(submodules), submod_attrs=submod_attrs)
    known = set(where) | set(submodules)

    def __getattr__(name):
        if name not in known:  # Python's own message (lazy_loader words it otherwise)
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr_(name)

    def __dir__():
        return sorted(set(namespace) | set(dir_()))

    return __getattr__, __dir__
