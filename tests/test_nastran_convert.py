"""reproductions/lib/nastran.py: BIPI2D's GRID/PLOTEL loops become edge files with the inside on the left."""
import warnings

import numpy as np
import pytest
from examples_loader import load_script

from ase_sphrelax.boundary import BoundarySegments

# a 4 x 4 mm box with a 1 x 1 mm hole, both written clockwise (the box's inside on the right)
BOX_WITH_HOLE = """$ comment
BEGIN BULK
GRID,1,0,0.0,0.0,4.0,0
GRID,2,0,4.0,0.0,4.0,0
GRID,3,0,4.0,0.0,0.0,0
GRID,4,0,0.0,0.0,0.0,0
GRID,5,0,1.0,0.0,1.0,0
GRID,6,0,1.0,0.0,2.0,0
GRID,7,0,2.0,0.0,2.0,0
GRID,8,0,2.0,0.0,1.0,0
PLOTEL,1,1,2
PLOTEL,2,2,3
PLOTEL,3,3,4
PLOTEL,4,4,1
PLOTEL,5,5,6
PLOTEL,6,6,7
PLOTEL,7,7,8
PLOTEL,8,8,5
ENDDATA
"""


@pytest.fixture(scope="module")
def nastran():
    return load_script("reproductions/lib/nastran.py")


def test_loops_are_scaled_and_oriented_inside_left(nastran, tmp_path):
    src, out = tmp_path / "b.dat", tmp_path / "b.edges"
    src.write_text(BOX_WITH_HOLE)
    nastran.main([str(src), str(out), "--header", "# test"])
    e = np.loadtxt(out, comments="#")
    assert e.shape == (8, 4) and e.max() == pytest.approx(0.004)
    areas = [np.sum(q[:, 0] * q[:, 3] - q[:, 2] * q[:, 1]) / 2 for q in (e[:4], e[4:])]
    assert areas[0] == pytest.approx(16e-6) and areas[1] == pytest.approx(-1e-6)  # box ccw, hole cw
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an OrientationWarning (a loop reversed on reading) fails the test
        walls = BoundarySegments.from_edges(out)
    assert len(walls.packed_sk) == 8


def test_open_loop_is_refused(nastran):
    text = BOX_WITH_HOLE.replace("PLOTEL,4,4,1\n", "")
    with pytest.raises(ValueError, match="open at grid 4"):
        nastran.loops_of(*nastran.read_nastran(text))
