"""Wall particles are never inside the fluid, and never within 0.5 dx of it (issue 31 item 3).

Before: ``add_walls`` took the cell centres the Step-1 fill dropped within dx/8 of the boundary as wall particles
where they lay, up to 0.12 dx *inside* an ellipse (28 of them; the closest fluid-wall pair 0.39 dx), 16 in a periodic
channel, 55 in a tank with an obstacle. Now those centres are moved to just outside, and ``add_walls`` leaves out
any wall particle inside or within ``MIN_GAP`` (0.5) dx of a fluid particle, periodic images included.

Properties (``hypothesis``): random star-shaped polygons (sharp corners, thin spikes), periodic channels with a
random floor, 3D boxes, and packed walls; the fluid is the Step-1 fill, or the fill shaken by up to 0.35 dx (as a
packing's boundary layer, which can come within 0.4 dx of the boundary) and kept inside.
"""
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from ase_sphrelax.boundary import BoundarySegments
from ase_sphrelax.domains import Polygon
from ase_sphrelax.drivers.bipi_packer import FLUID, MIN_GAP, WALL, add_walls, initial_fill

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


def _check(both, boundary, dx, images=()):
    """No wall inside (phi > 0, the boundary's own signed distance) and every fluid-wall pair >= 0.5 dx apart,
    by brute force over the periodic ``images`` (shift vectors) given."""
    t = both.arrays["type"]
    dim = boundary.domain.dim
    fluid, walls = both.positions[t == FLUID, :dim], both.positions[t == WALL, :dim]
    assert len(walls) > 0
    phi = boundary.domain.phi(walls)
    assert phi.min() > 0.0, f"{int((phi <= 0).sum())} wall particles inside, the deepest {phi.min() / dx:.3g} dx"
    fluid_images = np.concatenate([fluid + np.asarray(s)[:dim] for s in [np.zeros(3), *images]])
    d, _ = cKDTree(fluid_images).query(walls)
    assert d.min() >= MIN_GAP * dx * (1 - 1e-12), f"a fluid-wall pair {d.min() / dx:.4g} dx apart"
    assert both.info["n_wall"] == len(walls) and both.info["n_fluid"] == len(fluid)


def _shaken(fluid, domain, dx, rng, amount=0.35):
    """The fill with every particle moved by up to ``amount`` dx, kept inside (a stand-in for a packed fluid)."""
    out = fluid.copy()
    dim = domain.dim
    step = rng.uniform(-amount, amount, size=(len(out), dim)) * dx
    moved = out.positions[:, :dim] + step
    inside = domain.phi(moved) < 0
    out.positions[inside, :dim] = moved[inside]
    return out


@st.composite
def star_polygons(draw):
    """A star-shaped polygon about the origin (always simple: every edge spans less than half a turn about it, so
    edges lie in sectors that do not overlap): random radii give sharp corners; a spike (two close angles and a long
    radius between them) gives a thin feature."""
    n = draw(st.integers(3, 11))
    angles = np.sort(np.array(draw(st.lists(st.floats(0.0, 2 * np.pi, exclude_max=True), min_size=n, max_size=n,
                                            unique=True))))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2 * np.pi]))
    # a gap of half a turn or more: the closing edge passes the origin's far side and can cross the others (the
    # angles 0, 1, 2 with a spike at 0.5 crossed itself)
    assume(gaps.min() > 0.05 and gaps.max() < np.pi - 0.05)
    radii = np.array(draw(st.lists(st.floats(0.25, 1.0), min_size=n, max_size=n)))
    if draw(st.booleans()):  # a thin spike
        i = draw(st.integers(0, n - 1))
        gap = np.diff(np.concatenate([angles, angles[:1] + 2 * np.pi]))[i]
        spike = angles[i] + 0.5 * gap
        angles = np.insert(angles, i + 1, spike)
        radii = np.insert(radii, i + 1, draw(st.floats(1.2, 1.6)))
    return np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=1)


@settings(max_examples=40, **SETTINGS)
@given(loop=star_polygons(), dx=st.floats(0.04, 0.12), shake=st.booleans(), seed=st.integers(0, 2**16),
       layers=st.integers(1, 4))
def test_random_polygons_grid_walls(loop, dx, shake, seed, layers):
    boundary = BoundarySegments.from_polygon(Polygon([loop.tolist()]))
    try:
        fluid = initial_fill(boundary, dx)
    except ValueError:
        assume(False)
    if shake:
        fluid = _shaken(fluid, boundary.domain, dx, np.random.default_rng(seed))
    _check(add_walls(fluid, boundary, dx, layers=layers), boundary, dx)


@settings(max_examples=25, **SETTINGS)
@given(n_cells=st.integers(12, 30), height=st.floats(0.3, 0.8), bump=st.lists(st.floats(0.0, 0.25), min_size=1,
                                                                              max_size=5),
       shake=st.booleans(), seed=st.integers(0, 2**16))
def test_periodic_channels_grid_walls(n_cells, height, bump, shake, seed):
    """A channel periodic along x (period a whole number of dx) with a random floor profile."""
    dx = 1.0 / n_cells
    xs = np.linspace(0.0, 1.0, len(bump) + 2)
    floor = [[0.0, 0.0]] + [[x, b] for x, b in zip(xs[1:-1], bump)] + [[1.0, 0.0]]
    loop = floor + [[1.0, height], [0.0, height]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        boundary = BoundarySegments.from_polygon(Polygon([loop])).with_cell([True, False, False])
    fluid = initial_fill(boundary, dx)
    if shake:
        fluid = _shaken(fluid, boundary.domain, dx, np.random.default_rng(seed))
        fluid.positions[:, :2] = boundary.periodic.wrap(fluid.positions)[:, :2]
    both = add_walls(fluid, boundary, dx, layers=3)
    t = both.arrays["type"]
    walls = both.positions[t == WALL]
    assert walls[:, 0].min() >= 0.0 and walls[:, 0].max() < 1.0  # one period of walls
    _check(both, boundary, dx, images=[(1.0, 0, 0), (-1.0, 0, 0)])


@settings(max_examples=6, **SETTINGS)
@given(size=st.tuples(st.floats(0.3, 0.6), st.floats(0.3, 0.6), st.floats(0.3, 0.6)), dx=st.floats(0.06, 0.1),
       shake=st.booleans(), seed=st.integers(0, 2**16))
def test_3d_boxes_grid_walls(size, dx, shake, seed):
    from ase_sphrelax.boundary import BoundaryTriangles
    from ase_sphrelax.domains import Box

    boundary = BoundaryTriangles.from_domain(Box((0.0, 0.0, 0.0), size))
    fluid = initial_fill(boundary, dx)
    if shake:
        fluid = _shaken(fluid, boundary.domain, dx, np.random.default_rng(seed))
    _check(add_walls(fluid, boundary, dx, layers=2), boundary, dx)


def test_3d_sphere_grid_walls():
    from ase_sphrelax.boundary import BoundaryTriangles
    from ase_sphrelax.domains import Sphere

    boundary, dx = BoundaryTriangles.from_domain(Sphere((0.0, 0.0, 0.0), 0.4).to_mesh(2)), 0.07
    fluid = _shaken(initial_fill(boundary, dx), boundary.domain, dx, np.random.default_rng(3))
    _check(add_walls(fluid, boundary, dx, layers=2), boundary, dx)


@pytest.mark.parametrize("loop", [
    [[0.0, 0.0], [1.0, 0.0], [1.0, 0.5], [0.55, 0.5], [0.5, 0.05], [0.45, 0.5], [0.0, 0.5]],  # a thin sharp notch
    [[0.0, 0.0], [1.0, 0.0], [0.1, 0.08], [1.0, 0.5], [0.0, 0.5]],  # a thin wedge of solid poking in
])
def test_packed_walls(loop):
    """BIPI-packed walls beside a shaken fluid: none inside, none within 0.5 dx."""
    from ase_sphrelax.drivers.bipi_walls import add_packed_walls

    boundary, dx = BoundarySegments.from_polygon(Polygon([loop])), 0.05
    fluid = _shaken(initial_fill(boundary, dx), boundary.domain, dx, np.random.default_rng(0))
    both = add_packed_walls(fluid, boundary, dx, layers=2, h=4 * dx, max_steps_2a=40, max_steps_2c=40)
    _check(both, boundary, dx)


def test_the_ellipse_of_the_issue(tmp_path):
    """The newcomer's case through ``sphrelax pack --walls``: an ellipse 0.5 x 0.3 at dx = 0.04."""
    from ase.io import read

    from ase_sphrelax.cli import main

    t = np.linspace(0.0, 2 * np.pi, 201)[:-1]
    x, y = 0.5 * np.cos(t), 0.3 * np.sin(t)
    edges = tmp_path / "ellipse.edges"
    edges.write_text("".join(f"{x[i]} {y[i]} {x[i - 199]} {y[i - 199]}\n" for i in range(200)))
    out = tmp_path / "out"
    assert main(["pack", "--boundary", str(edges), "--dx", "0.04", "--walls", "--out", str(out), "--no-progress",
                 "--max-steps-2a", "30", "--max-steps-2c", "30"]) == 0
    both = read(out / "packed.extxyz")
    both.info.update(n_wall=int((both.arrays["type"] == WALL).sum()), n_fluid=int((both.arrays["type"] == FLUID).sum()))
    _check(both, BoundarySegments.from_edges(edges), 0.04)
