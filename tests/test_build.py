"""fill() and periodic_box(): particle counts, shapes, cells, pbc, bad input."""
import math

import numpy as np
import pytest

from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.domains import Box, Circle, Polygon, Sphere


def brute_force_count(center, radius, n):
    """Cell centres of an n x n mesh on [0, 1]^2 strictly inside the circle."""
    c = (np.arange(n) + 0.5) / n
    x, y = np.meshgrid(c, c)
    return int(np.count_nonzero(np.hypot(x - center[0], y - center[1]) < radius))


def test_fill_fan_circle_count():
    """Fan Sec. 5.2: circle (0.5, 0.5), r = 0.2, 256 x 256 mesh on [0, 1]^2.

    The paper quotes 8186 particles.  The cell centres strictly inside the
    circle are 8224 (brute force below).  8186 is not a multiple of 4, while
    any mesh symmetric about the circle centre gives a multiple of 4 (8 here),
    so the paper's number cannot come from a cell-centre test on this mesh;
    see ase_sphrelax.build.fill Notes.
    """
    atoms = fill(Circle((0.5, 0.5), 0.2), 1 / 256, jitter=0.0)
    assert len(atoms) == brute_force_count((0.5, 0.5), 0.2, 256) == 8224
    assert len(atoms) % 8 == 0 and 8186 % 4 != 0
    # same count with jitter: the inside test is done at the cell centres
    jittered = fill(Circle((0.5, 0.5), 0.2), 1 / 256, jitter=0.25, seed=1)
    assert len(jittered) == 8224
    shift = jittered.positions - atoms.positions
    assert np.abs(shift[:, :2]).max() <= 0.25 / 256 and np.abs(shift[:, :2]).max() > 0.2 / 256
    assert np.all(shift[:, 2] == 0.0)


def test_fill_positions_are_cell_centres_and_atoms_metadata():
    dom = Box([0.0, 0.0], [1.0, 0.5])
    atoms = fill(dom, 0.1, jitter=0.0)
    assert len(atoms) == 50
    frac = atoms.positions[:, :2] / 0.1 - 0.5
    np.testing.assert_allclose(frac, np.round(frac), atol=1e-12)
    assert not atoms.pbc.any()
    assert np.all(atoms.positions[:, 2] == 0.0)
    np.testing.assert_allclose(atoms.cell[2], [0, 0, 1])
    assert atoms.info["dx"] == 0.1
    assert atoms.info["volume"] == pytest.approx(0.5)
    # padded bounding box: cell corner at bounds.lo - pad, cell contains all particles
    lo = atoms.get_celldisp().ravel()
    assert np.all(atoms.positions[:, :2] > lo[:2])
    assert np.all(atoms.positions[:, :2] < lo[:2] + np.diag(atoms.cell)[:2])
    assert np.all(np.diag(atoms.cell)[:2] > [1.0, 0.5])


def test_fill_origin_shifts_mesh():
    atoms = fill(Box([0.0, 0.0], [1.0, 1.0]), 0.25, jitter=0.0, origin=(0.1, 0.0))
    xs = np.unique(np.round(atoms.positions[:, 0], 12))
    ys = np.unique(np.round(atoms.positions[:, 1], 12))
    # cells [0.1 + k/4, 0.1 + (k+1)/4): centres 0.225 .. 0.975 inside [0, 1]
    np.testing.assert_allclose(xs, [0.225, 0.475, 0.725, 0.975])
    np.testing.assert_allclose(ys, [0.125, 0.375, 0.625, 0.875])
    assert len(atoms) == 16


def test_fill_3d_sphere_and_polygon_volume_ratio():
    s = Sphere((0.0, 0.0, 0.0), 1.0)
    atoms = fill(s, 0.1, jitter=0.1, seed=0)
    assert atoms.pbc.tolist() == [False, False, False]
    assert len(atoms) * 0.1**3 == pytest.approx(s.volume, rel=0.01)  # Fan Eq. 3.3
    wedge = Polygon([[[0, 0], [1, 0], [0.5, 0.8]]])
    a = fill(wedge, 0.01, seed=0)
    assert len(a) * 1e-4 == pytest.approx(wedge.volume, rel=0.02)


def test_fill_seed_reproducible():
    c = Circle((0, 0), 1.0)
    a, b = fill(c, 0.1, seed=3), fill(c, 0.1, seed=3)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert not np.array_equal(a.positions, fill(c, 0.1, seed=4).positions)


@pytest.mark.parametrize("kwargs,match", [
    (dict(dx=0.0), "dx"), (dict(dx=-1.0), "dx"), (dict(dx=float("nan")), "dx"),
    (dict(dx=0.1, jitter=0.5), "jitter"), (dict(dx=0.1, jitter=-0.1), "jitter"),
    (dict(dx=10.0), "dx"),  # domain smaller than a cell: nothing inside
    (dict(dx=0.1, origin=(0, 0, 0, 0)), "origin"),
])
def test_fill_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        fill(Circle((0.3, 0.3), 0.2), **kwargs)


def test_fill_rejects_non_domain():
    with pytest.raises(TypeError, match="domain"):
        fill("circle", 0.1)


@pytest.mark.parametrize("lattice,n,expected", [("square", 5, 25), ("square", (3, 4), 12),
                                                ("hexagonal", (4, 6), 24)])
def test_periodic_box_2d(lattice, n, expected):
    atoms = periodic_box(n, dx=0.5, dim=2, lattice=lattice)
    assert len(atoms) == expected
    assert atoms.pbc.tolist() == [True, True, False]
    np.testing.assert_allclose(atoms.cell[2], [0, 0, 1])
    assert np.all(atoms.positions[:, 2] == 0.0)
    area = abs(np.linalg.det(atoms.cell[:2, :2]))
    assert area / len(atoms) == pytest.approx(0.25)  # particle area dx^2
    assert atoms.info["dx"] == 0.5
    # nearest-neighbour distance under periodic images
    d = atoms.get_all_distances(mic=True)[0, 1:]
    nn = dict(square=0.5, hexagonal=0.5 * math.sqrt(2 / math.sqrt(3)))[lattice]
    assert d.min() == pytest.approx(nn)
    assert np.count_nonzero(np.isclose(d, nn)) == (4 if lattice == "square" else 6)


@pytest.mark.parametrize("lattice,per_cell,coordination", [("cubic", 1, 6), ("fcc", 4, 12), ("bcc", 2, 8)])
def test_periodic_box_3d(lattice, per_cell, coordination):
    atoms = periodic_box(3, dx=2.0, dim=3, lattice=lattice)
    assert len(atoms) == 27 * per_cell
    assert atoms.pbc.all()
    assert atoms.get_volume() / len(atoms) == pytest.approx(8.0)
    d = atoms.get_all_distances(mic=True)[0, 1:]
    assert np.count_nonzero(np.isclose(d, d.min())) == coordination


def test_periodic_box_jitter_wraps_and_is_bounded():
    ref = periodic_box(4, dx=1.0)
    atoms = periodic_box(4, dx=1.0, jitter=0.3, seed=0)
    frac = atoms.get_scaled_positions(wrap=False)[:, :2]
    assert np.all((frac >= 0) & (frac < 1))
    d = atoms.positions - ref.positions
    d -= np.round(d / 4.0) * 4.0
    assert np.abs(d).max() <= 0.3 and np.abs(d).max() > 0.1


@pytest.mark.parametrize("kwargs,match", [
    (dict(n=0), "n"), (dict(n=(2, 2, 2)), "n"), (dict(n=4, dx=0), "dx"),
    (dict(n=4, jitter=0.6), "jitter"), (dict(n=4, dim=1), "dim"),
    (dict(n=4, lattice="fcc"), "lattice"), (dict(n=(4, 3), lattice="hexagonal"), "n"),
])
def test_periodic_box_bad_input(kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        periodic_box(**kwargs)
