"""``specialise.recompiled``: a function re-compiled from its source with globals bound. A branch on a bound constant
is pruned before typing, so code numba cannot type behind it does not stop the compilation."""
import numba
import pytest

from ase_sphrelax.boundary import gamma
from ase_sphrelax.specialise import recompiled

FLAG = None  # bound by recompiled
UNTYPABLE = object()  # numba cannot type a call of it: compiling the branch that calls it fails


def _template(x, scale):
    if FLAG:
        return scale * x + 1.0
    return UNTYPABLE(x)


def test_a_bound_constant_prunes_the_other_branch():
    on = recompiled(_template, "_template__on", dict(FLAG=True))
    assert on(2.0, 3.0) == 7.0
    off = recompiled(_template, "_template__off", dict(FLAG=False))
    with pytest.raises(numba.core.errors.TypingError):
        off(2.0, 3.0)  # the branch kept calls what numba cannot type: it was compiled


def test_dropped_arguments_become_bound_globals():
    half = recompiled(_template, "_template__half", dict(FLAG=True, scale=0.5), drop=("scale",))
    assert half(4.0) == 3.0
    with pytest.raises(ValueError, match="drop"):
        recompiled(_template, "_template__bad", dict(FLAG=True), drop=("scale",))


def test_the_boundary_rows_are_compiled_per_element_kind():
    """Each kind's rows call the row block of their own kind, and neither is the unbound template."""
    for kind, name in enumerate(gamma.ELEMENT_KINDS):
        tables = ((gamma._ROW_BLOCK, "_row_block"), (gamma._ROWS, "_rows"), (gamma._ROWS_FUSED, "_rows_fused"))
        for table, base in tables:
            assert table[kind].py_func.__name__ == f"{base}__{name}"
            assert table[kind].py_func.__globals__ is not gamma.__dict__
            assert table[kind].py_func.__globals__["KIND"] == kind
        assert gamma._ROWS[kind].py_func.__globals__["_row_block"] is gamma._ROW_BLOCK[kind]
    assert gamma.KIND is None


ONE_ROW_BLOCK = """
import numpy as np
from ase_sphrelax.boundary import gamma
from ase_sphrelax.boundary.gamma import BoundaryIntegrals
from ase_sphrelax.boundary.segments import BoundarySegments
from ase_sphrelax.neighbors import NeighborList
t = np.linspace(0.0, 2.0 * np.pi, 41)[:-1]
vertices = np.stack([0.5 + 0.3 * np.cos(t), 0.5 + 0.3 * np.sin(t)], axis=1)
boundary = BoundarySegments.from_vertices([vertices])
r = np.zeros((600, 3))
r[:, :2] = np.random.default_rng(0).uniform(0.15, 0.85, size=(600, 2))
nl = NeighborList(0.05, skin=0.005)
nl.update(r, np.zeros((3, 3)), [False] * 3, store=True)
integrals = BoundaryIntegrals(boundary, 0.05)
integrals.compute(nl, r, band=0.01, terms=False, keep_pairs=False)  # the fused rows
integrals.compute(nl, r, band=0.01, terms=True, keep_pairs=True)  # the rows of stored pairs
print(len(gamma._ROW_BLOCK[0].overloads), len(gamma._ROWS_FUSED[0].overloads), len(gamma._ROWS[0].overloads))
"""


def test_both_row_paths_compile_one_row_block(tmp_path):
    """With numba's cache empty, the fused rows and the rows of stored pairs compile the segments' row block once:
    the same argument types from both (a literal 0 or False at one call site compiled it again, 4 times in all)."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    done = subprocess.run([sys.executable, "-c", ONE_ROW_BLOCK], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["1", "1", "1"]
