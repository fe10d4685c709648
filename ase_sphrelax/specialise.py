"""numba functions re-compiled from their own source with some of their globals bound: compile-time constants.

numba reads a module global as a constant when it compiles a function. So a function re-compiled from its source
with a global bound to a value has the branches on that value pruned, and the code behind a pruned branch is
neither typed nor compiled: a 2D evaluation does not compile the 3D code beside it. The re-compiled function is
compiled against the original's own file under a name of its own, so numba's disk cache holds it like any other
jitted function (a function that captures values in a closure, or receives a jitted function as an argument, is
compiled again in every process).

Used by :mod:`ase_sphrelax.pairs` (a pair function's constants and kernel) and
:mod:`ase_sphrelax.boundary.gamma` (the boundary rows of segments and of triangles).
"""
from __future__ import annotations

import ast
import inspect
import textwrap

import numba

__all__ = ["recompiled"]


def recompiled(function, name, bind, drop=(), **njit_options):
    """``function`` re-compiled by numba from its source as ``name``, with the globals ``bind`` bound.

    Parameters
    ----------
    function : function or numba dispatcher
        Its Python source is read (a dispatcher's ``py_func``); it must be a top-level ``def``.
    name : str
        The new function's name: unique within the file for each set of bound values (numba's cache files are named
        by it).
    bind : dict
        Global names and their values, seen by the re-compiled function only (numbers and bools are compile-time
        constants; a jitted function is called as one).
    drop : iterable of str
        Arguments removed from the signature (their names are then globals, bound in ``bind``).
    **njit_options
        Passed to ``numba.njit`` (``cache=True`` always).
    """
    py_func = getattr(function, "py_func", function)
    drop = set(drop)
    missing = drop - set(bind)
    if missing:
        raise ValueError(f"drop: arguments {sorted(missing)} have no value in bind")
    tree = ast.parse(textwrap.dedent(inspect.getsource(py_func)))
    definition = tree.body[0]
    definition.decorator_list = []
    definition.args.args = [arg for arg in definition.args.args if arg.arg not in drop]
    definition.name = name
    ast.increment_lineno(tree, py_func.__code__.co_firstlineno - 1)
    namespace = dict(py_func.__globals__)
    namespace.update(bind)
    # compiled against the function's own file: numba's disk cache keys it by that file and by its name
    exec(compile(tree, inspect.getfile(py_func), "exec"), namespace)  # noqa: S102
    made = namespace[name]
    made.__module__ = py_func.__module__
    return numba.njit(cache=True, **njit_options)(made)
