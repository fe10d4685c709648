"""The ``sphrelax`` command line: one module per command, registries for commands, methods and engines.

Layout
------
==================  ==========================================================================================
``main.py``         the entry point (``sphrelax = "ase_sphrelax.cli:main"``): one sub-parser per command
``registry.py``     :data:`~.registry.COMMANDS`, :data:`~.registry.METHODS`, :data:`~.registry.ENGINES` and
                    their entry-point groups
``usage.py``        :class:`UsageError`, :func:`usage_errors` and argparse types (``positive``, ...)
``scene.py``        :func:`~.scene.make_scene`: built-in domains, edge files and STL meshes
``relax.py``, ...   the built-in commands (``relax``, ``pack``, ``density``, ``sample``, ``lattice``,
                    ``table``); ``sphrelax export`` comes from ``lammps_io`` by entry point
==================  ==========================================================================================

Add a command
-------------
1. Write ``ase_sphrelax/cli/NAME.py``. Its docstring's first line is the one-line help of
   ``sphrelax --help``; the rest is the description of ``sphrelax NAME --help``. It defines
   ``add_arguments(parser)`` (argparse options; use the types of ``usage.py`` so that bad
   numbers are rejected while parsing) and ``run(args)`` (returns an exit code or None).
   Import only the standard library and other ``cli`` modules at module level, and everything
   heavy (numpy, numba, scipy, matplotlib, ASE optimisers) inside ``run``: every command
   module is imported to build the parser, and ``sphrelax --help`` must stay under 0.5 s
   (``tests/test_cli.py`` checks that it does not import numba).
2. Add one line to :data:`~.registry.COMMANDS`: ``"NAME": "ase_sphrelax.cli.NAME"``.
   (Another package registers ``NAME = "package.module:Object"`` in the entry-point group
   ``ase_sphrelax.commands`` of its ``pyproject.toml`` instead; the object may be a module or
   a class with static methods.)
3. In ``run``, do the set-up (reading files, building the scene, constructing calculators and
   drivers: where the constructors validate input) inside ``with usage_errors():``, so that
   its ValueError, TypeError and FileNotFoundError print as one line with exit code 2; raise
   :class:`UsageError` for other bad input. Errors of the run itself keep their traceback.

Add a method
------------
A method is what a command minimises or samples, e.g. ``sphrelax relax --method fan``.
Write an object (class or module) whose docstring's first line is its help, and add one line
to :data:`~.registry.METHODS` under the command: ``"NAME": "ase_sphrelax.cli.MODULE:Object"``
(other packages: entry-point group ``ase_sphrelax.methods.<command>``). The command reads
the choices with ``registry.methods(command)``; what the object provides is the command's
contract, e.g. for ``relax`` (:class:`~.relax.FanMethod`): ``calculator(scene, h, args)``,
optionally ``add_arguments(parser)`` (options shown in the group ``--method NAME``) and
``energy_label``. A new command with several methods (``pack --method bipi``) adds its own
key to :data:`~.registry.METHODS` and calls ``registry.methods("pack")`` in ``add_arguments``.

Add a relax engine
------------------
``sphrelax relax --engine NAME``: an object like :class:`~.relax.AseEngine` registered in
:data:`~.registry.ENGINES` or the entry-point group ``ase_sphrelax.engines`` (``lammps_io``
registers ``lammps`` there, so nothing in ``ase_sphrelax`` imports ``lammps_io``).
"""
import time

STARTED = time.perf_counter()  # the command's wall time is measured from here (``relax`` prints both)

from .main import build_parser, main  # noqa: E402
from .usage import UsageError, usage_errors

__all__ = ["main", "build_parser", "UsageError", "usage_errors"]
