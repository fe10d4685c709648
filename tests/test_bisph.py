"""BISPH (BIPI Eqs. 16-21): the boundary-integral WCSPH solver of ``ase_sphrelax.flows`` on small cases."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.boundary import BoundarySegments, boundary_terms
from ase_sphrelax.flows.bisph import BISPH
from ase_sphrelax.flows.scene import cartesian_fill, channel, poiseuille, tank


def test_hydrostatic_column_pressure():
    """A 20 x 40 column started hydrostatic keeps p within 1 % of rho0 g H (RMS over particles).

    Measured at 0.1 s (about 560 steps): 0.54 % (0.42 % at 0.5 s); the RMS deviation is largest at
    the first records (0.77 % at 0.025 s) and then settles."""
    dx = 0.01
    width, depth = 20 * dx, 40 * dx
    walls = BoundarySegments.from_vertices([[0, 0], [width, 0], [width, 1.5 * depth], [0, 1.5 * depth]])
    r = cartesian_fill(walls, dx, depth)
    assert len(r) == 800
    sim = tank(walls, r, dx, depth)
    hist = sim.run(0.1, record_every=0.025, progress=False)
    scale = sim.rho0 * 9.81 * depth
    assert hist.pressure_error[-1] / scale <= 0.01
    assert max(hist.pressure_error) / scale <= 0.01
    assert np.all(walls.contains(sim.r))
    assert hist.v_max[-1] < 0.01 * np.sqrt(9.81 * depth)


def test_poiseuille_profile():
    """Plane Poiseuille between periodic plates: u(y) within 2 % of u_max of the analytic profile.

    20 particles across, nu = 1e-3 m^2/s, F = 1 m/s^2 (u_max = 0.05 m/s, Re = 1); 0.6 W^2/nu is
    six e-folds of the slowest mode. Measured: 0.85 % at 0.8 W^2/nu (the wall term's factor 2,
    see ``flows/bisph.py``; with factor 1 the profile slipped by 15 %)."""
    width = 0.02
    dx = width / 20
    force, mu = 1.0, 1.0
    sim = channel(width, 10 * dx, dx, force=force, mu=mu)
    sim.run(0.6 * width**2 * sim.rho0 / mu, progress=False)
    u_exact = poiseuille(sim.r[:, 1], width, force, mu)
    u_max = u_exact.max()
    assert np.max(np.abs(sim.v[:, 0] - u_exact)) <= 0.02 * u_max
    assert np.max(np.abs(sim.v[:, 1])) <= 1e-4 * u_max  # no cross flow (5e-6 measured: acoustic transients)


def test_mass_conserved():
    """Masses are per particle and constant; the Molteni-Colagrossi diffusion moves density between
    particles without creating any: sum_a V_a gamma_a D_a = 0 to rounding (its pair terms are
    antisymmetric), here with random densities next to the walls of a periodic channel."""
    width = 0.02
    dx = width / 10
    sim = channel(width, 10 * dx, dx, force=1.0, mu=1.0)
    rng = np.random.default_rng(3)
    sim.rho = sim.rho0 * (1.0 + 0.01 * rng.standard_normal(len(sim.r)))
    bt, gamma = sim.walls()
    rate = sim.density_rate(bt, gamma, v_pc=np.zeros_like(sim.v))  # diffusion only
    volume = sim.mass / sim.rho
    scale = np.sum(volume * gamma * np.abs(rate))
    assert scale > 0
    assert abs(np.sum(volume * gamma * rate)) <= 1e-12 * scale
    n0, m0 = len(sim.r), sim.mass * len(sim.r)
    sim.run(0.05, progress=False)
    assert len(sim.r) == n0 and sim.mass * len(sim.r) == m0
    assert np.all(sim.integrals.boundary.contains(sim.r))


@st.composite
def polygons(draw):
    """Star-shaped simple polygons with 3-8 vertices, sharp corners included (radii 0.15-1)."""
    n = draw(st.integers(3, 8))
    angles = np.sort(draw(st.lists(st.floats(0.0, 2 * np.pi, exclude_max=True), min_size=n, max_size=n,
                                   unique=True)))
    gaps = np.diff(np.append(angles, angles[0] + 2 * np.pi))
    if gaps.min() < 0.05 or gaps.max() > np.pi - 0.05:
        angles = np.linspace(0.0, 2 * np.pi, n, endpoint=False) + 0.3 * np.asarray(
            draw(st.lists(st.floats(-1.0, 1.0), min_size=n, max_size=n))) * (np.pi / n)
    radii = np.asarray(draw(st.lists(st.floats(0.15, 1.0), min_size=n, max_size=n)))
    return np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])


@settings(max_examples=12, deadline=None)
@given(polygons())
def test_wall_force_of_uniform_pressure_vanishes(vertices):
    """The wall terms of Eq. 17 under a uniform pressure p add up to no net force on a closed wall.

    The force of segment s on particle a is ``V p grad gamma_as``; summed over a lattice of
    particles covering the plane near the wall, ``sum_a V grad gamma_as -> n_s int_s (sum_a V W) dS
    = n_s L_s`` (a partition of unity), so the net force is ``p sum_s n_s L_s = 0`` up to the
    lattice's partition-of-unity error at h = 4 dx: about 1e-5 p perimeter for oblique segments,
    where it averages out along the segment, and up to 5e-4 p L_s for a segment along a lattice
    axis (measured: an equilateral triangle with a vertical side, +4.9e-4 or -3.9e-4 of that side's
    n_s L_s depending on the lattice offset). A wrong normal, a missing or doubled segment or a
    wrong ``grad gamma_as`` at a corner gives O(p L_s)."""
    walls = BoundarySegments.from_vertices(vertices)
    dx = 0.03
    h = 4 * dx
    lo, hi = vertices.min(axis=0) - h - dx, vertices.max(axis=0) + h + dx  # every point within h of a wall
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], dx), np.arange(lo[1], hi[1], dx))
    r = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    terms = boundary_terms(r, walls, h)
    force = dx * dx * np.sum(terms.grad_k[:, None] * walls.normal_sc[terms.pairs.element_k], axis=0)
    perimeter = walls.packed_sk[:, 6].sum()
    assert np.abs(force).max() <= 2e-3 * perimeter
    # each segment's own share is its n_s L_s (not zero): the cancellation is between segments
    share = dx * dx * np.bincount(terms.pairs.element_k, weights=terms.grad_k, minlength=len(walls))
    np.testing.assert_allclose(share, walls.packed_sk[:, 6], rtol=2e-3)


def test_gradient_of_linear_field_next_to_a_wall():
    """The gamma-renormalised gradient (Eq. 16's operator) of f = 2x + 3y on a Cartesian lattice.

    Not exact (the issue asked for exact): with the wall value taken at the kernel-weighted centre
    of each segment (exact for a linear f), the remaining error is the particle sum's, the lattice
    quadrature of a kernel cut by the wall: ``sum_b V_b (x_b - x_a) grad_a W`` is not the identity
    there. Measured (dx = 0.05, h = 4 dx, unit box): 0.08 % in the interior, 0.76 % mean and 2.9 %
    max over the particles within h of a wall (the worst at the corners); in a tank with a
    re-entrant wedge vertex 19.5 % max next to the vertex (1.9 % mean). Without the wall term the
    error next to a wall is O(1) (18.6x the gradient)."""
    dx = 0.05
    walls = BoundarySegments.from_vertices([[0, 0], [1, 0], [1, 1], [0, 1]])
    sim = BISPH(walls, cartesian_fill(walls, dx), dx, c0=10.0, mu=0.0, body_force=(0.0, 0.0))

    def f(x):
        return 2.0 * x[:, 0] + 3.0 * x[:, 1]

    exact = np.array([2.0, 3.0])
    err = np.linalg.norm(sim.gradient(f(sim.r), wall_value=f) - exact, axis=1) / np.linalg.norm(exact)
    _, gamma = sim.walls()
    near = gamma < 1.0 - 1e-12
    assert near.sum() > 100 and (~near).sum() > 100
    assert err[~near].max() <= 1e-3
    assert err[near].max() <= 0.035
    assert err[near].mean() <= 0.01
    bare = np.linalg.norm(sim.gradient(f(sim.r)) - exact, axis=1) / np.linalg.norm(exact)
    assert bare[near].max() > 1.0  # the wall term is what makes it first-order accurate


def test_bad_input_is_one_line():
    walls = BoundarySegments.from_vertices([[0, 0], [1, 0], [1, 1], [0, 1]])
    with pytest.raises(ValueError, match="c0"):
        BISPH(walls, [[0.5, 0.5]], 0.1, c0=-1.0)
    with pytest.raises(ValueError, match="positions"):
        BISPH(walls, np.zeros((0, 2)), 0.1, c0=1.0)
    with pytest.raises(ValueError, match="wall_band"):
        BISPH(walls, [[0.5, 0.5]], 0.1, c0=1.0, wall_band=2.0)
    with pytest.raises(ValueError, match="c0 must be given"):
        BISPH(walls, [[0.5, 0.5]], 0.1)
    with pytest.raises(ValueError, match="fill"):
        cartesian_fill(walls, 0.1, fill_height=-1.0)
