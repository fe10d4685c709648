"""Polygon.opening (the union of the discs of radius r inside the polygon) and FanModel.wall, which takes it for Fan's
"gamma" term on a polygon (issue 33 item 3: a part narrower than 0.7 dx can hold no particle 0.35 dx from both walls)."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ase_sphrelax.domains import Box, Polygon
from ase_sphrelax.models.fan import WALL_OPENING, FanModel

FAST = settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def _star(seed, k):
    """A random star polygon of ``k`` spikes: sharp convex tips and concave notches (as test_fan_corners')."""
    rng = np.random.default_rng(seed)
    angle = (np.arange(2 * k) + rng.uniform(-0.3, 0.3, 2 * k)) * np.pi / k
    radius = np.where(np.arange(2 * k) % 2 == 0, rng.uniform(0.6, 1.0, 2 * k), rng.uniform(0.15, 0.45, 2 * k))
    return Polygon([np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])])


@FAST
@given(seed=st.integers(0, 2**31), k=st.integers(3, 9), r=st.floats(0.005, 0.05))
def test_opening_holds_every_disc_centre_and_lies_inside(seed, k, r):
    """Every point at least r from the wall is inside the opening (its disc is in the polygon); every point of the
    opening is inside the polygon (the chords of the arcs cut inward); the tips' vertices are left out when the tip is
    narrower than 2 r there, and the concave vertices stay on the wall (to the chords' error)."""
    poly = _star(seed, k)
    opened = poly.opening(r)
    rng = np.random.default_rng(seed + 1)
    p = np.zeros((4000, 3))
    p[:, :2] = rng.uniform(-1.0, 1.0, (4000, 2))
    phi, phi_open = poly.phi(p), opened.phi(p)
    assert np.all(phi_open[phi < -r * (1 + 1e-9)] < 0.0)  # disc centres are inside
    assert np.all(phi[phi_open < 0.0] < 1e-12)  # the opening lies inside the polygon
    assert opened.volume <= poly.volume
    loop = poly.loops[0]
    vertices = np.zeros((len(loop), 3))
    vertices[:, :2] = loop
    at_vertex = opened.phi(vertices)
    prev, nxt = np.roll(loop, 1, axis=0), np.roll(loop, -1, axis=0)
    cross = (loop - prev)[:, 0] * (nxt - loop)[:, 1] - (loop - prev)[:, 1] * (nxt - loop)[:, 0]
    u, w = prev - loop, nxt - loop
    half = 0.5 * np.arccos(np.clip(np.einsum("vc,vc->v", u, w) / np.linalg.norm(u, axis=1) / np.linalg.norm(w, axis=1),
                                   -1.0, 1.0))
    # concave vertices stay (ccw loop: cross < 0), to two chords' errors (0.5 % of r each: the erosion's arc around
    # the vertex, then the dilation's) over the sine of the notch's half angle (the offset walls meet at that angle)
    concave = cross < 0
    assert np.all(np.abs(at_vertex[concave]) < 0.01 * r / np.sin(half[concave]))
    convex = cross > 0
    # a convex vertex of interior angle 2 half is left out: the opening's nearest point is where the disc of radius r
    # touches both edges, r / sin(half) - r from the vertex along the bisector (within the chords' 0.5 % of r); only
    # where the disc fits beside the vertex's own edges
    fits = (np.minimum(np.linalg.norm(u, axis=1), np.linalg.norm(w, axis=1)) > 2 * r / np.tan(half)) & convex
    expected = r / np.sin(half) - r
    assert np.all(at_vertex[fits] >= expected[fits] - 0.006 * r)


def test_a_rectangle_loses_its_corners_to_quarter_discs():
    r = 0.05
    opened = Polygon([[(0, 0), (1, 0), (1, 0.5), (0, 0.5)]]).opening(r)
    # four corners of (1 - pi/4) r^2, the arcs as 8 chords a quarter turn (32-gon: 8 sin(pi/16) cos(pi/16) r^2 each)
    chord_area = 4 * 0.25 * 32 * 0.5 * np.sin(2 * np.pi / 32) * r**2
    assert opened.volume == pytest.approx(0.5 - (4 * r**2 - chord_area), rel=1e-9)


def test_a_thin_sliver_is_left_out_and_a_neck_splits_the_domain():
    r = 0.05
    # two squares joined by a neck 0.06 wide (< 2 r): the opening is two parts
    dumbbell = Polygon([[(0, 0), (1, 0), (1, 0.47), (1.5, 0.47), (1.5, 0), (2.5, 0), (2.5, 1), (1.5, 1), (1.5, 0.53),
                         (1, 0.53), (1, 1), (0, 1)]])
    opened = dumbbell.opening(r)
    assert len(opened.loops) == 2
    neck = np.array([[1.25, 0.5, 0.0]])
    assert dumbbell.phi(neck)[0] < 0 < opened.phi(neck)[0]


@pytest.mark.parametrize("radius", [0.0, -1.0, np.nan, np.inf])
def test_opening_refuses_a_radius_that_is_not_positive_and_finite(radius):
    with pytest.raises(ValueError, match="radius"):
        Polygon([[(0, 0), (1, 0), (0, 1)]]).opening(radius)


def test_opening_of_a_domain_thinner_than_2_r_everywhere_is_refused():
    with pytest.raises(ValueError, match="nowhere"):
        Polygon([[(0, 0), (1, 0), (1, 0.01), (0, 0.01)]]).opening(0.05)


def test_fan_wall_is_the_opening_on_a_polygon_only():
    dx = 0.02
    chevron = Polygon([[(0.0, 0.0), (0.5, 0.25), (0.0, 0.5), (0.175, 0.25)]])
    model = FanModel(2.6 * dx, dx, chevron, 2)
    integrals, wall = model.wall(dx**2)
    assert wall is not chevron and wall.volume < chevron.volume
    assert model.wall(dx**2)[1] is wall  # computed once per radius
    reference = chevron.opening(WALL_OPENING * dx)
    assert wall.volume == pytest.approx(reference.volume, rel=1e-12)
    assert model.wall((2 * dx) ** 2)[1].volume < wall.volume  # the radius follows dp
    model.wall_opening = 0.0
    assert model.wall(dx**2)[1] is chevron
    box = FanModel(2.6 * dx, dx, Box((0.0, 0.0), (0.4, 0.3)), 2)
    assert box.boundary_term == "gamma" and box.wall(dx**2)[1] is box.domain


def test_fan_on_a_polygon_thinner_than_its_opening_says_what_to_change():
    from ase import Atoms

    from ase_sphrelax import FanCalculator

    dx = 0.02
    strip = Polygon([[(0, 0), (1, 0), (1, 0.5 * dx), (0, 0.5 * dx)]])  # 0.5 dx wide: nowhere 0.7 dx
    atoms = Atoms(numbers=[0, 0], positions=[(0.3, 0.2 * dx, 0), (0.31, 0.2 * dx, 0)], pbc=False)
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=strip)
    with pytest.raises(ValueError, match="domain: the polygon is nowhere .*wall_opening = 0"):
        atoms.get_forces()
    atoms.calc.model.wall_opening = 0.0
    assert np.all(np.isfinite(atoms.get_forces()))
