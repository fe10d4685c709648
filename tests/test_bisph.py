"""BISPH (BIPI Eqs. 16-21): the boundary-integral WCSPH solver of ``ase_sphrelax.flows`` on small cases."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.boundary import BoundarySegments, boundary_terms
from ase_sphrelax.flows.bisph import BISPH
from ase_sphrelax.flows.scene import cartesian_fill, channel, poiseuille, tank


def test_hydrostatic_column_pressure():
    """A 20 x 40 column started hydrostatic keeps p within 1 % of rho0 g H (RMS over particles) after settling.

    The first 0.25 s are an acoustic transient (up to 1.6 % at 0.1-0.15 s with Eq. 21 pointwise, the default;
    0.57 % with Eq. 21 over whole sides). Measured from 0.3 s to 0.6 s: at most 0.60 % (0.35 % at 0.6 s)."""
    dx = 0.01
    width, depth = 20 * dx, 40 * dx
    walls = BoundarySegments.from_vertices([[0, 0], [width, 0], [width, 1.5 * depth], [0, 1.5 * depth]])
    r = cartesian_fill(walls, dx, depth)
    assert len(r) == 800
    sim = tank(walls, r, dx, depth)
    hist = sim.run(0.5, record_every=0.05, progress=False)
    scale = sim.rho0 * 9.81 * depth
    settled = np.asarray(hist.pressure_error)[np.asarray(hist.t) >= 0.3 - 1e-9] / scale
    assert len(settled) == 5 and settled.max() <= 0.01
    assert max(hist.pressure_error) / scale <= 0.02
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


def test_poiseuille_profile_pcg():
    """The same channel with the PCG viscous form (``viscosity="pcg"``, BIPI Fig. 14b): within 2 %.

    Measured: 0.27 % of u_max at 0.6 W^2/nu (the slowest mode's tail: 0.01 % at 1.2 W^2/nu). The plain
    nested form (``G_b`` in the divergence, no wall term; commit 92a5089) gave 2.7 % (2.6 % at steady
    state; the boundary-layer form 0.89 % at 1.2 W^2/nu against the same ``poiseuille``). Controlled
    experiment on the steady state of the layer-averaged operator (the time runs match it to 1e-4):
    a wall term alone on the nested form, the wall shear as the wall value of ``G`` 5.7 %, the wall
    slope of a parabola through v_a with slope G_a 2.9 % (the odd-even modes stay); the midpoint difference quotient alone 2.3 %
    (a uniform slip; the odd-even modes gone), plus the wall term with the wall shear as the wall
    value of ``G`` (half weight) 1.1 %, as the wall's midpoint gradient 0.01 % (the study
    ``reproductions/bipi-pcg-poiseuille``, which has 40 across too)."""
    width = 0.02
    dx = width / 20
    force, mu = 1.0, 1.0
    sim = channel(width, 10 * dx, dx, force=force, mu=mu, viscosity="pcg")
    sim.run(0.6 * width**2 * sim.rho0 / mu, progress=False)
    u_exact = poiseuille(sim.r[:, 1], width, force, mu)
    assert np.max(np.abs(sim.v[:, 0] - u_exact)) <= 0.02 * u_exact.max()
    assert np.max(np.abs(sim.v[:, 1])) <= 1e-4 * u_exact.max()


def test_pcg_operator_has_no_odd_even_mode():
    """The PCG Laplacian on the channel's layers (u uniform along x): its slowest decay rate is the
    physical ``nu pi^2 / W^2`` (24.67 1/s; measured 24.54, the boundary-layer form 24.34) and the
    steady profile of ``nu lap u = -F`` is the parabola (measured 9.8e-5 of u_max). The nested form
    (``G_b`` in place of the midpoint gradient) had an exact null mode alternating across the channel and
    a second of rate 0.053 1/s: the odd-even checkerboard of nested first derivatives."""
    width = 0.02
    n = 20
    sim = channel(width, 10 * width / n, width / n, force=1.0, mu=1.0, viscosity="pcg")
    layer = np.round(sim.r[:, 1] / sim.dx - 0.5).astype(int)
    bt, gamma = sim.walls()
    op = np.zeros((n, n))
    for j in range(n):
        u = np.zeros((len(sim.r), 2))
        u[layer == j, 0] = 1.0
        lap = sim.laplacian(u, bt, gamma)[:, 0] * sim.mu / sim.rho0
        op[:, j] = np.bincount(layer, weights=lap, minlength=n) / np.bincount(layer, minlength=n)
    rates = np.sort(-np.linalg.eigvals(op).real)
    physical = sim.mu / sim.rho0 * np.pi**2 / width**2
    assert abs(rates[0] / physical - 1.0) <= 0.02
    u = np.linalg.solve(op, -np.ones(n))
    u_exact = poiseuille(sim.dx * (np.arange(n) + 0.5), width, 1.0, 1.0)
    assert np.abs(u - u_exact).max() <= 1e-3 * u_exact.max()


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


BOX = [[0, 0], [1, 0], [1, 1], [0, 1]]
# a tank with a wedge on its left wall: the vertex (0.5, 0.25) is re-entrant (the fluid wraps around it)
WEDGE = [[0, 0], [2.05, 0], [2.05, 1.2], [0, 1.2], [0, 0.6], [0.5, 0.25], [0, 0.25]]


def _linear(x):
    return 2.0 * x[:, 0] + 3.0 * x[:, 1]


def _fine_gradient(sim, f, k):
    """The gamma-renormalised gradient of ``f`` at ``sim``'s particles with the particle sum taken
    over the k-times finer Cartesian fill of the same walls (volumes ``(dx/k)^2``), and the same exact
    gamma, grad gamma_as and wall term: the controlled experiment of the gradient test."""
    from scipy.spatial import cKDTree

    fine = cartesian_fill(sim.boundary, sim.dx / k)[:, :2]
    x = sim.r[:, :2]
    rows = cKDTree(fine).query_ball_point(x, sim.h)
    bt, gamma = sim.walls()
    out = np.zeros((len(x), 2))
    for a, row in enumerate(rows):
        d = x[a] - fine[row]  # x_a - x_b
        r = np.linalg.norm(d, axis=1)
        keep = r > 0
        grad_w = (sim.kernel.dw(r[keep], sim.h) / r[keep])[:, None] * d[keep]
        out[a] = (sim.dx / k) ** 2 * np.sum((f(fine[row][keep]) - f(x[a:a + 1]))[:, None] * grad_w, axis=0)
    pairs = bt.pairs
    owner = np.repeat(np.arange(len(x)), np.diff(pairs.start_p))
    wall = (f(sim._feet(bt)) - f(x[owner]))[:, None] * bt.grad_k[:, None] * sim._seg[pairs.element_k, 4:6]
    np.add.at(out, owner, -wall)
    return out / gamma[:, None]


def test_gradient_of_linear_field_next_to_a_wall():
    """Eq. 2's gradient of f = 2x + 3y next to walls: where its error comes from, and the exact form.

    With exact gamma, grad gamma_as and wall integrals (the wall value at the kernel-weighted centre
    of each segment, in closed form: exact for a linear f), the continuous operator is exact for a
    linear field; the discrete one is not: its particle sum is a lattice quadrature of a kernel cut by
    the wall, ``sum_b V_b grad_a W (x) (x_b - x_a) != gamma_a I``. Measured (dx = 0.05, h = 4 dx):
    box: 0.08 % interior, 2.9 % max next to the walls (the corners), 0.76 % mean; the wedge tank: 8.8 %
    max (its re-entrant vertex), 1.0 % mean. Without the wall term: O(1) (18.6x the gradient).

    Controlled experiment (``_fine_gradient``): the same operator with the particle sum over a 2x, 4x
    (8x) finer fill, same h, same boundary terms: box 0.59 %, 0.15 % (0.036 %) max, second order (cells
    aligned with the walls); wedge tank 3.5 %, 1.4 % (0.73 %) max, first order at the re-entrant
    vertex, whose cut cells carry a whole particle volume. So gamma, grad gamma and the boundary term
    are exact and the error is the particle quadrature alone, O((dx/h)^2) along lattice-aligned walls
    and O(dx/h) at oblique ones: at the fixed h = 4 dx it does not fall with dx (scale invariant).
    Dividing by that first moment instead of gamma (the particle-consistent gradient,
    ``consistent=True``) makes the gradient exact to rounding: 1.7e-15 max."""
    exact = np.array([2.0, 3.0])
    dx = 0.05
    measured = {}
    cases = (("box", BOX, 0.03, (0.007, 0.0018)), ("wedge", WEDGE, 0.09, (0.04, 0.016)))
    for name, vertices, bound, fine_bounds in cases:
        walls = BoundarySegments.from_vertices(vertices)
        sim = BISPH(walls, cartesian_fill(walls, dx), dx, c0=10.0, mu=0.0, body_force=(0.0, 0.0))
        _, gamma = sim.walls()
        near = gamma < 1.0 - 1e-12
        assert near.sum() > 100 and (~near).sum() > 100

        def error(grad):
            return np.linalg.norm(grad - exact, axis=1) / np.linalg.norm(exact)
        err = error(sim.gradient(_linear(sim.r), wall_value=_linear))
        assert err[~near].max() <= 1e-3
        assert err[near].max() <= bound
        assert err[near].mean() <= 0.011
        measured[name] = err[near].max()
        previous = err[near].max()
        for k, fine_bound in zip((2, 4), fine_bounds):
            fine = error(_fine_gradient(sim, _linear, k))[near].max()
            assert fine <= fine_bound and fine < 0.6 * previous  # the error is the particle quadrature's
            previous = fine
        consistent = error(sim.gradient(_linear(sim.r), wall_value=_linear, consistent=True))
        assert consistent.max() <= 1e-12
        assert error(sim.gradient(_linear(sim.r), consistent=True)).max() <= 1e-12  # particle-only matrix
        bare = error(sim.gradient(_linear(sim.r)))
        assert bare[near].max() > 1.0  # the wall term is what makes it first-order accurate
    assert measured["wedge"] > 2 * measured["box"]  # the re-entrant vertex is the worst place


def test_wall_feet_in_closed_form():
    """The kernel-weighted centre of each (particle, segment) pair (closed form of the tangential first
    moment) against a 400-point quadrature of ``int_s y W dS / int_s W dS`` along the segment."""
    walls = BoundarySegments.from_vertices(WEDGE)
    dx = 0.05
    sim = BISPH(walls, cartesian_fill(walls, dx), dx, c0=10.0, mu=0.0, body_force=(0.0, 0.0))
    bt, _ = sim.walls()
    feet = sim._feet(bt)
    pairs = bt.pairs
    rng = np.random.default_rng(0)
    for k in rng.choice(pairs.n_pairs, 40, replace=False):
        seg = sim._seg[pairs.element_k[k]]
        t = np.linspace(0.0, 1.0, 4001)
        y = seg[0:2] + t[:, None] * (seg[2:4] - seg[0:2])
        w = sim.kernel.w(np.linalg.norm(y - pairs.x_sc[pairs.point_k[k], :2], axis=1), sim.h)
        total = np.trapezoid(w, t) * seg[6]
        np.testing.assert_allclose(total, bt.grad_k[k], rtol=1e-5)
        centre = np.trapezoid(w[:, None] * y, t, axis=0) * seg[6] / total
        np.testing.assert_allclose(feet[k], centre, atol=1e-6 * sim.h)


def test_pcg_laplacian():
    """The viscous term's particle-consistent-gradient form (BIPI Fig. 14b, ``viscosity="pcg"``).

    A linear velocity field (wall values through the feet): Laplacian 0 to rounding next to walls and
    the re-entrant vertex (measured 6.8e-13 and 1.2e-12 against terms of size |grad v| / h ~ 10). A
    parabola u = y (W - y) in the periodic channel: exact to rounding farther than 2h from the walls;
    next to them the first gradient is exact only to first order (the cut kernel's first moment),
    which the midpoint difference quotient and the wall shear mostly absorb: measured 1.2 % max and
    0.34 % mean of |lap u| over the particles within h of a wall (20 across, h = 4 dx; the nested form
    of commit 92a5089: 32 % and 16.7 %). In the box, u = y^2 is off by 1.2 % away from the corners and
    by 50 % at the corner particles (the wall's midpoint gradient takes only the normal derivative)."""
    dx = 0.05
    for vertices in (BOX, WEDGE):
        walls = BoundarySegments.from_vertices(vertices)
        sim = BISPH(walls, cartesian_fill(walls, dx), dx, c0=10.0, mu=0.0, body_force=(0.0, 0.0),
                    viscosity="pcg")

        def velocity(x):
            return np.column_stack([2.0 * x[:, 0] - x[:, 1] + 1.0, 0.5 * x[:, 0] + 3.0 * x[:, 1]])
        assert np.abs(sim.laplacian(velocity(sim.r), wall_velocity=velocity)).max() <= 1e-11
        if vertices is BOX:
            def parabola(x):
                return np.column_stack([x[:, 1] ** 2, np.zeros(len(x))])
            err = np.abs(sim.laplacian(parabola(sim.r), wall_velocity=parabola)[:, 0] - 2.0) / 2.0
            corner = np.all(np.minimum(sim.r[:, :2], 1.0 - sim.r[:, :2]) < sim.h, axis=1)
            assert err[~corner].max() <= 0.02 and 0.3 <= err[corner].max() <= 0.7
    width = 0.02
    sim = channel(width, 10 * width / 20, width / 20, force=1.0, mu=1.0, viscosity="pcg")
    u = np.zeros((len(sim.r), 2))
    u[:, 0] = sim.r[:, 1] * (width - sim.r[:, 1]) / width**2
    lap = sim.laplacian(u)
    err = np.abs(lap[:, 0] + 2.0 / width**2) / (2.0 / width**2)
    wall_gap = np.minimum(sim.r[:, 1], width - sim.r[:, 1])
    assert err[wall_gap > 2 * sim.h].max() <= 1e-9
    near = wall_gap < sim.h
    assert err[near].max() <= 0.02 and err[near].mean() <= 0.005
    assert np.abs(lap[:, 1]).max() <= 1e-9 / width**2


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
    with pytest.raises(ValueError, match="viscosity"):
        BISPH(walls, [[0.5, 0.5]], 0.1, c0=1.0, viscosity="morris")
    with pytest.raises(ValueError, match="fill"):
        cartesian_fill(walls, 0.1, fill_height=-1.0)


def _wall_pressure_force(r_pc, dx, **kwargs):
    walls = BoundarySegments.from_vertices([[0, 0], [1, 0], [1, 1], [0, 1]])
    sim = BISPH(walls, r_pc, dx, c0=10.0, mu=0.0, body_force=(0.0, 0.0), **kwargs)
    rho = sim.rho * 1.001
    bt, _ = sim.walls()
    _, gp_pc, _ = sim._wall_sums(bt, np.zeros((len(r_pc), 3)), rho, sim.pressure(rho))
    return gp_pc


@settings(max_examples=12, deadline=None)
@given(st.floats(0.02, 0.98), st.floats(0.0, 0.49), st.booleans())
def test_eq21_pointwise_is_the_limit_of_short_segments(along, gap, corner):
    """Eq. 21 pointwise (the default) equals the per-segment reading on segments of dx/2000 to 0.2 %, and it
    does not depend on how the walls are cut; the per-segment reading on one segment per side does (it
    compresses the whole side: 6.7x the force at 0.3 dx in ``/tmp`` probes, not stored). Particles from
    0.01 dx to 0.5 dx from the floor, mid-side or in a corner (both walls inside the band)."""
    dx = 0.1
    x = (0.01 + gap) * dx if corner else along
    r_pc = np.array([[x, (0.01 + gap) * dx]])
    exact = _wall_pressure_force(r_pc, dx)
    cut = _wall_pressure_force(r_pc, dx, segment_ratio=7)
    fine = _wall_pressure_force(r_pc, dx, eq21="segment", segment_ratio=2000)
    scale = np.abs(exact).max()
    assert np.abs(cut - exact).max() <= 1e-5 * scale
    assert np.abs(fine - exact).max() <= 2e-3 * scale
