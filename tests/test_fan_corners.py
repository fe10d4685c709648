"""Fan's boundary term at corners (issue 33 item 3): the exact-gamma default, its gradient, clean corners."""
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ase_sphrelax import FanCalculator
from ase_sphrelax.analysis import quality_summary
from ase_sphrelax.boundary import gamma_and_gradient
from ase_sphrelax.build import fill
from ase_sphrelax.domains import Box, Circle, Polygon, Sphere
from ase_sphrelax.drivers.fan_relaxation import FanRelaxation
from ase_sphrelax.models.fan import CORE_DISTANCE, CORE_STIFFNESS, WALL_OPENING, WALL_WEIGHT, FanModel

CHEVRON_LOOP = [(0.0, 0.0), (1.0, 0.5), (0.0, 1.0), (0.35, 0.5)]
CHEVRON = Polygon([CHEVRON_LOOP])  # 28 and 53 degree tips, a concave corner
CUBE = Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
H = 0.2
FAST = settings(max_examples=30, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def _vertices(domain):
    if domain.dim == 3:
        return np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    return np.column_stack([np.asarray(CHEVRON_LOOP), np.zeros(len(CHEVRON_LOOP))])


def _wall_gap(domain, r):
    """Difference of the two smallest distances to the walls (segments of the domain's loops, or the cube's faces)."""
    if domain.dim == 3:
        d = np.sort(np.concatenate([r, 1.0 - r]))
    else:
        a = np.concatenate(domain.loops)
        b = np.concatenate([np.roll(loop, -1, axis=0) for loop in domain.loops])
        t = np.clip(np.einsum("wc,wc->w", r[:2] - a, b - a) / np.einsum("wc,wc->w", b - a, b - a), 0.0, 1.0)
        d = np.sort(np.linalg.norm(r[:2] - (a + t[:, None] * (b - a)), axis=1))
    return d[1] - d[0]


def _numeric_forces(model, r_pc, v0, eps):
    out = np.zeros_like(r_pc)
    for c in range(model.dim):
        step = np.zeros(3)
        step[c] = eps
        out[:, c] = -(model.boundary(r_pc + step, v0)[0] - model.boundary(r_pc - step, v0)[0]) / (2 * eps)
    return out


@FAST
@given(domain=st.sampled_from([CHEVRON, CUBE]), vertex=st.integers(0, 7),
       log_distance=st.floats(-6.0, 0.1), direction=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3))
def test_gamma_force_is_minus_the_gradient_near_vertices(domain, vertex, log_distance, direction):
    """The term's force is -grad of its energy at points inside, down to 1e-6 h from a vertex (tips, the concave
    corner, cube vertices and edges), on the polygon itself (``wall_opening`` 0: its sharp vertices are the wall's)."""
    dim = domain.dim
    corners = _vertices(domain)
    u = np.zeros(3)
    u[:dim] = np.asarray(direction)[:dim]
    if np.linalg.norm(u) < 1e-3:
        u[0] = 1.0
    r = corners[vertex % len(corners)] + H * 10.0**log_distance * u / np.linalg.norm(u)
    phi = float(domain.phi(r[None])[0])
    distance = -phi
    if not distance > 1e-7 * H:
        return  # outside: the outside slope's kinks (phi = 0, exterior medial axes) are tested elsewhere
    model = FanModel(H, 0.05, domain, dim)
    model.wall_opening = 0.0
    assert model.boundary_term == "gamma"
    r_pc = r[None]
    e_p, f_pc = model.boundary(r_pc, 0.05**dim)
    eps = min(1e-7 * H, 0.1 * distance)
    d0 = CORE_DISTANCE * 0.05
    if distance < d0 and _wall_gap(domain, r) < 10 * eps:
        return  # the contact core's kink: on a convex corner's bisector within d0 (grad phi jumps there)
    numeric = _numeric_forces(model, r_pc, 0.05**dim, eps)
    scale = 2 * 0.05**dim * WALL_WEIGHT / H  # |2 v0 kappa grad gamma| ~ 2 v0 kappa / h
    np.testing.assert_allclose(f_pc, numeric, atol=2e-6 * scale)
    # and the energy is the continuum's, 2 v0 kappa (1 - gamma) (gamma from the unmerged boundary), plus the core
    core = CORE_STIFFNESS / (2 * d0 * H) * max(d0 - distance, 0.0) ** 2
    expected = 2 * 0.05**dim * WALL_WEIGHT * (1 - gamma_and_gradient(r_pc, domain, H)[0][0] + core)
    assert e_p[0] == pytest.approx(expected, abs=1e-13)


@FAST
@given(vertex=st.integers(0, 3), log_distance=st.floats(-6.0, 0.1),
       direction=st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=2), along=st.floats(0.0, 1.0))
def test_default_wall_force_is_minus_the_gradient_near_the_opening(vertex, log_distance, direction, along):
    """With the default wall (the chevron's opening at WALL_OPENING dp, FanModel.wall) the force is -grad of the
    energy near the chevron's tips and concave corner and near the vertices of the opening's arcs, and the energy
    is the continuum's of that wall (gamma from the unmerged segments of Polygon.opening) plus the core."""
    dp = 0.05
    model = FanModel(H, dp, CHEVRON, 2)
    wall = model.wall(dp**2)[1]
    radius = WALL_OPENING * dp
    assert wall.volume < CHEVRON.volume and len(np.concatenate(wall.loops)) > len(CHEVRON_LOOP)
    arcs = np.concatenate(wall.loops)
    centres = np.concatenate([np.asarray(CHEVRON_LOOP, float), arcs])
    u = np.asarray(direction, float)
    if np.linalg.norm(u) < 1e-3:
        u = np.array([1.0, 0.0])
    base = centres[int(along * (len(centres) - 1))] if vertex == 3 else centres[vertex]
    r = np.zeros(3)
    r[:2] = base + H * 10.0**log_distance * u / np.linalg.norm(u)
    distance = -float(wall.phi(r[None])[0])
    if not distance > 1e-7 * H:
        return  # outside the wall: the outside slope's kinks are tested elsewhere
    r_pc = r[None]
    e_p, f_pc = model.boundary(r_pc, dp**2)
    eps = min(1e-7 * H, 0.1 * distance)
    d0 = CORE_DISTANCE * dp
    if distance < d0 and _wall_gap(wall, r) < 10 * eps:
        return  # the contact core's kink on a convex vertex's bisector within d0
    numeric = _numeric_forces(model, r_pc, dp**2, eps)
    scale = 2 * dp**2 * WALL_WEIGHT / H
    np.testing.assert_allclose(f_pc, numeric, atol=2e-6 * scale)
    core = CORE_STIFFNESS / (2 * d0 * H) * max(d0 - distance, 0.0) ** 2
    expected = 2 * dp**2 * WALL_WEIGHT * (1 - gamma_and_gradient(r_pc, wall, H)[0][0] + core)
    assert e_p[0] == pytest.approx(expected, abs=1e-13)
    assert radius > 0


@FAST
@given(x=st.floats(1.02, 1.4), y=st.floats(0.1, 0.9))
def test_gamma_force_outside_includes_the_outside_slope(x, y):
    """Beyond the chevron's tip: 2 v0 kappa (1 - gamma + W1(0) phi + core), force its exact negative gradient."""
    model = FanModel(H, 0.05, CHEVRON, 2)
    r_pc = np.array([[x, y, 0.0]])
    if not CHEVRON.phi(r_pc)[0] > 1e-3:
        return
    e_p, f_pc = model.boundary(r_pc, 0.05**2)
    np.testing.assert_allclose(f_pc, _numeric_forces(model, r_pc, 0.05**2, 1e-8), atol=1e-9)
    assert np.linalg.norm(f_pc) > 0.0  # also beyond h, where gamma = 0


def test_auto_picks_gamma_for_elements_and_the_level_set_for_curves():
    assert FanModel(0.1, 0.05, Box((0, 0), (1, 1)), 2).boundary_term == "gamma"
    assert FanModel(0.1, 0.05, CUBE, 3).boundary_term == "gamma"
    assert FanModel(0.1, 0.05, Circle((0, 0), 1.0), 2).boundary_term == "level_set"
    assert FanModel(0.1, 0.05, Sphere((0, 0, 0), 1.0), 3).boundary_term == "level_set"
    assert FanModel(0.1, 0.05, CHEVRON, 2, boundary_term="level_set").boundary_term == "level_set"
    assert FanModel(0.1, 0.05).boundary_term is None
    with pytest.raises(ValueError, match="boundary_term='gamma' needs a domain with boundary elements"):
        FanModel(0.1, 0.05, Circle((0, 0), 1.0), 2, boundary_term="gamma")
    with pytest.raises(ValueError, match="boundary_term must be one of"):
        FanModel(0.1, 0.05, CHEVRON, 2, boundary_term="exact")
    with pytest.raises(ValueError, match="boundary_term must be one of"):
        FanCalculator(h=0.1, dx=0.05, domain=CHEVRON, boundary_term="smooth")


def test_quality_reports_the_completed_sums_next_to_walls():
    """Aligned grid in a box: plain sums lose up to 3/4 of the kernel at corners, the completed ones do not."""
    dx = 1 / 24
    box = Box((0.0, 0.0), (1.0, 1.0))
    atoms = fill(box, dx, jitter=0.0, origin=(0.0, 0.0))
    q = quality_summary(atoms, 2.6 * dx, dx, box)
    assert q["n_near_wall"] == len(atoms) - q["n_interior"] > 0
    assert q["near_wall_kernel_sum_error_max"] < 0.05  # 0.043 at the corners of the square grid
    assert q["near_wall_gradient_error_max"] < 0.1  # 0.080: the grid is not relaxed
    assert q["boundary_distance_min"] == pytest.approx(0.5) and q["boundary_distance_std"] < 1e-12
    assert quality_summary(fill(Sphere((0, 0, 0), 0.3), 0.1), 0.26, 0.1, Sphere((0, 0, 0), 0.3))[
        "near_wall_kernel_sum_error_max"] is None


def _star(seed, k):
    rng = np.random.default_rng(seed)
    angle = np.linspace(0.0, 2 * np.pi, k, endpoint=False) + rng.uniform(-0.3, 0.3, k) * 2 * np.pi / k
    radius = rng.uniform(0.35, 1.0, k)
    return Polygon([np.column_stack([0.5 + 0.4 * radius * np.cos(angle), 0.5 + 0.4 * radius * np.sin(angle)])])


@settings(max_examples=4, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**16), k=st.integers(4, 7))
def test_default_relaxation_keeps_particles_off_corners_of_random_polygons(seed, k):
    """Random star polygons (sharp tips, concave corners), ~80 particles, 300 Eq. 2.4 steps with the
    default term: none nearer than 0.35 dx to the boundary, none outside."""
    domain = _star(seed, k)
    dx = float(np.sqrt(domain.volume / 80))
    atoms = fill(domain, dx, jitter=0.1, seed=0)
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # particles of the fill outside the polygon, the scale hint
        FanRelaxation(atoms, c=0.01, logfile=None).run(fmax=0.0, steps=300)
    distance = -domain.phi(atoms.positions) / dx
    assert distance.min() >= 0.35, (seed, k, distance.min())
