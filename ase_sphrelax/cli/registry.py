"""Registries of ``sphrelax`` commands, methods and relax engines.

Each registry is a dict of built-ins, ``name -> "module"`` or ``"module:attribute"``
(imported only when the parser is built), extended by an entry-point group that other
installed packages fill from their ``pyproject.toml``::

    [project.entry-points."ase_sphrelax.commands"]
    export = "lammps_io.cli:ExportCommand"

=================  ===============================  ===========================================
registry           built-ins                        entry-point group
=================  ===============================  ===========================================
commands           :data:`COMMANDS`                 ``ase_sphrelax.commands``
methods of a       :data:`METHODS` ``[command]``    ``ase_sphrelax.methods.<command>``
command
relax engines      :data:`ENGINES`                  ``ase_sphrelax.engines``
=================  ===============================  ===========================================

Built-ins win over entry points of the same name. An entry point that cannot be
loaded is skipped with a warning, so one broken plug-in does not take ``sphrelax``
down. What the registered objects provide is described in
:mod:`ase_sphrelax.cli` (commands, methods) and :mod:`ase_sphrelax.cli.relax` (engines).
"""
from __future__ import annotations

import importlib
import inspect
import sys
import warnings
from functools import lru_cache
from importlib.metadata import entry_points

__all__ = ["COMMANDS", "METHODS", "ENGINES", "COMMAND_GROUP", "ENGINE_GROUP", "method_group", "load",
           "commands", "methods", "engines", "help_texts"]

#: built-in commands, in the order ``sphrelax --help`` lists them
COMMANDS = {
    "relax": "ase_sphrelax.cli.relax",
    "lattice": "ase_sphrelax.cli.lattice",
    "table": "ase_sphrelax.cli.table",
    "sample": "ase_sphrelax.cli.sample",
    "density": "ase_sphrelax.cli.density",
    "pack": "ase_sphrelax.cli.pack",
    "settle": "ase_sphrelax.cli.settle",
    "reproduce": "ase_sphrelax.cli.reproduce",
    "data": "ase_sphrelax.cli.data",
}

#: built-in methods per command (``sphrelax COMMAND --method NAME``)
METHODS = {
    "relax": {
        "fan": "ase_sphrelax.cli.relax:FanMethod",
    },
    "pack": {
        "bipi": "ase_sphrelax.cli.pack:BIPIMethod",
    },
}

#: built-in engines of ``sphrelax relax --engine NAME``
ENGINES = {
    "ase": "ase_sphrelax.cli.relax:AseEngine",
}

COMMAND_GROUP = "ase_sphrelax.commands"
ENGINE_GROUP = "ase_sphrelax.engines"


def method_group(command):
    """Entry-point group of the methods of ``command``: ``ase_sphrelax.methods.<command>``."""
    return f"ase_sphrelax.methods.{command}"


def load(spec):
    """Import ``"module"`` or ``"module:attribute"`` and return the module or the attribute."""
    module_name, _, attribute = spec.partition(":")
    obj = importlib.import_module(module_name)
    for part in filter(None, attribute.split(".")):
        obj = getattr(obj, part)
    return obj


@lru_cache(maxsize=8)
def _entry_points(path):
    """All entry points visible on ``path`` (``sys.path`` as a tuple: the cache follows it)."""
    return entry_points()


def _collect(builtins, group):
    """``{name: object}``: the built-ins (imported), then the loadable entry points of ``group`` by name."""
    found = {name: load(spec) for name, spec in builtins.items()}
    source = dict(builtins)
    for ep in sorted(_entry_points(tuple(sys.path)).select(group=group), key=lambda ep: ep.name):
        if ep.name in source:
            if source[ep.name] != ep.value:  # the same plug-in seen twice on sys.path is no conflict
                from ..checks import PluginWarning  # here, not at the top: building the parser stays light

                warnings.warn(f"{group} entry point {ep.name!r} ({ep.value}) ignored: {ep.name!r} is "
                              f"already {source[ep.name]}", PluginWarning, stacklevel=2)
            continue
        source[ep.name] = ep.value
        try:
            found[ep.name] = ep.load()
        except Exception as error:  # noqa: BLE001 - a broken plug-in must not break the other commands
            from ..checks import PluginWarning

            warnings.warn(f"{group} entry point {ep.name!r} ({ep.value}) skipped: "
                          f"{type(error).__name__}: {error}", PluginWarning, stacklevel=2)
    return found


def commands():
    """Command objects by name: :data:`COMMANDS` and the ``ase_sphrelax.commands`` entry points."""
    return _collect(COMMANDS, COMMAND_GROUP)


def methods(command):
    """Method objects of ``command`` by name: ``METHODS[command]`` and its entry-point group."""
    return _collect(METHODS.get(command, {}), method_group(command))


def engines():
    """Relax engines by name: :data:`ENGINES` and the ``ase_sphrelax.engines`` entry points."""
    return _collect(ENGINES, ENGINE_GROUP)


def help_texts(obj):
    """``(short, long)`` help of a registered object: its docstring's first line, and the whole docstring.

    ``short`` is ready for argparse's ``help=`` (a literal ``%`` is doubled).
    """
    doc = inspect.getdoc(obj) or ""
    return doc.split("\n", 1)[0].strip().replace("%", "%%"), doc
