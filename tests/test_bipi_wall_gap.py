"""Grid walls 1 dx from the fluid (reproductions/bipi-fig13-14/README.md, "A defect of these grid walls").

The wedge tank is 102.5 dx wide at dx = 0.02: the cell centres at x = 2.05 lie on its right wall,
``initial_fill`` drops them (within dx/8 of the boundary) and walls strictly outside skipped them too,
leaving a 2 dx gap there. ``add_walls`` now takes the centres the fill dropped, moved to just outside the
boundary (``JUST_OUTSIDE`` dx: no wall particle inside the fluid, issue 31).
"""

import numpy as np
import pytest
from examples_loader import load_script

from ase_sphrelax.boundary import BoundarySegments
from ase_sphrelax.domains import Polygon
from ase_sphrelax.drivers.bipi_packer import (DROP_FRACTION, FLUID, JUST_OUTSIDE, WALL, add_walls, initial_fill,
                                              wall_particles)


def _example():
    return load_script("reproductions/lib/bipi_sph.py")


def _side_gaps(both, dx):
    """(left, right) gaps in dx between the fluid's outer columns and the side walls, above the floor."""
    t, r = both.arrays["type"], both.positions
    up = r[:, 1] > 0.05
    right = up & (r[:, 0] > 1.5)
    left = up & (r[:, 0] < 0.5)
    gap_right = (r[(t == WALL) & right, 0].min() - r[(t == FLUID) & right, 0].max()) / dx
    gap_left = (r[(t == FLUID) & left, 0].min() - r[(t == WALL) & left, 0].max()) / dx
    return gap_left, gap_right


@pytest.mark.parametrize("dx", [0.02, 0.01])
def test_wedge_tank_walls_one_dx_from_the_fluid(dx):
    example = _example()
    boundary = example.wedge_tank()
    both = example.with_walls(initial_fill(boundary, dx), boundary, dx, example.H_OVER_DX * dx, example.DEPTH)
    gap_left, gap_right = _side_gaps(both, dx)
    assert gap_left == pytest.approx(1.0, abs=1e-9)
    assert gap_right == pytest.approx(1.0, abs=2 * JUST_OUTSIDE)  # at 0.02 the column on the wall, moved just outside
    from scipy.spatial import cKDTree

    d, _ = cKDTree(both.positions[:, :2]).query(both.positions[:, :2], k=2)
    assert d[:, 1].min() == pytest.approx(dx, rel=2 * JUST_OUTSIDE)  # one lattice: no two particles closer than dx
    assert np.all(boundary.domain.phi(both.positions[both.arrays["type"] == WALL, :2]) > 0)


def test_strict_walls_keep_the_old_gap():
    """drop=None is the old rule (phi > 0): the 2 dx gap the README's first grid-wall runs had."""
    example = _example()
    boundary, dx = example.wedge_tank(), 0.02
    both = add_walls(initial_fill(boundary, dx), boundary, dx, h=4 * dx, keep=lambda r: r[:, 1] < example.DEPTH,
                     drop=None)
    assert _side_gaps(both, dx) == pytest.approx((1.0, 2.0), abs=1e-9)


@pytest.mark.parametrize("drop", [0.0, DROP_FRACTION, 0.3])
def test_fill_and_walls_are_one_lattice(drop):
    """Brute force: the fill with ``drop`` and the walls with the same ``drop`` partition the grid's centres
    with phi <= layers dx, on a tank whose edges pass through centres (phi = 0 up to rounding); the walls among
    them that are not outside are moved just outside, by at most ``drop dx``."""
    loop = [[0.0, 0.0], [0.4, 0.0], [0.5, 0.1], [0.6, 0.0], [1.0, 0.0], [1.0, 0.5], [0.0, 0.5]]
    boundary, dx, k = BoundarySegments.from_polygon(Polygon([loop])), 0.05, 3
    fluid = initial_fill(boundary, dx, drop=drop)
    walls = wall_particles(boundary, dx, layers=k, drop=drop)
    axes = [(np.arange(-20, 40) + 0.5) * dx] * 2
    gx, gy = np.meshgrid(*axes, indexing="ij")
    r_pd = np.stack([gx.ravel(), gy.ravel()], axis=1)
    expected = r_pd[boundary.domain.phi(r_pd) <= k * dx]
    key = lambda r: list(map(tuple, np.round(r[:, :2] / dx - 0.5).astype(int)))  # noqa: E731
    got = key(fluid.positions) + key(walls.positions)
    assert len(got) == len(set(got)) and set(got) == set(key(expected))
    phi = boundary.domain.phi(walls.positions[:, :2])
    assert phi.min() > 0 and phi.max() <= k * dx * (1 + 1e-12)
    grid = (np.round(walls.positions[:, :2] / dx - 0.5) + 0.5) * dx
    assert np.abs(walls.positions[:, :2] - grid).max() <= drop * dx + 2 * JUST_OUTSIDE * dx


def test_drop_is_checked():
    boundary = BoundarySegments.from_polygon(Polygon([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]]))
    for bad in (-0.1, np.nan, 3.0):
        with pytest.raises(ValueError, match="drop"):
            wall_particles(boundary, 0.1, layers=3, drop=bad)
