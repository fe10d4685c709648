"""gamma_a and grad gamma_a exact (1e-12) everywhere within the support (issue 17 item 1).

Property-based tests (hypothesis) over random polygons: convex and concave, with holes, thin
slivers, 10 degree wedges and rectilinear (grid) polygons; points near vertices, ON the lines
through edges beyond their end vertices (inside and outside the domain) and at offsets of
1e-3 .. 1e-12 h from them, on edges and on vertices. gamma and grad gamma are compared with an
independent polar quadrature written here (no code shared with ase_sphrelax.boundary):

* along each ray from the particle the radial integral is exact: the ray's line crosses the
  boundary at signed distances ``t_c`` (entering ``+1`` / leaving ``-1``, decided by the sides of
  the segment's end points, a half-open rule that counts a ray through a vertex once), and the
  inside part of ``[0, h]`` contributes ``sum_c s_c (M(h) - M(clip(t_c, 0, h)))`` with
  ``M(r) = int_0^r W(s) s ds`` (``N`` with ``W'`` for the gradient): order-free, no inside test;
* the angle is integrated by Gauss-Legendre, graded geometrically towards both ends of every
  interval between the kinks: vertex directions, the directions of every edge's line (where a
  ray's crossing distance ``d / sin`` is singular) and the crossings of the circles ``r = h``
  and ``r = break radii``.

Identities: 0 <= gamma <= 1 (to rounding, 1e-14); gamma of a polygon plus gamma of its complement in
a box = 1; grad gamma equal to the central difference of gamma.

3D (a cube, exact values; an icosphere and a tetrahedron, central differences): the half-space value
near faces and near the diagonal edges that split them, quarter spaces about an edge and octants
about a vertex summing to 1, on, near (1e-12 .. 1e-3 h) and away from the surface, inside and out.
"""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from numpy.polynomial import polynomial as P

from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles, gamma_and_gradient

# derandomize: the same examples every run; too_slow: generation is timed, and the shared 2-core machine is loaded
SETTINGS = dict(deadline=None, database=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
TOL_GAMMA = 1e-12  # absolute
TOL_GRAD = 1e-12  # times 1 / h


# ----------------------------------------------------------------- kernels, written here
def _kernel(name):
    """(break radii in units of the support, profile pieces in powers of q, 2D normalisation)."""
    one = [1.0, -1.0]
    if name == "wendland_c2":
        breaks, pieces = [0.0, 1.0], [P.polymul(P.polypow(one, 4), [1.0, 4.0])]
    elif name == "wendland_c4":
        breaks, pieces = [0.0, 1.0], [P.polymul(P.polypow(one, 6), [1.0, 6.0, 35.0 / 3.0])]
    else:  # cubic spline, support 1
        breaks, pieces = [0.0, 0.5, 1.0], [np.array([1.0, 0.0, -6.0, 6.0]), 2.0 * P.polypow(one, 3)]
    weighted = [P.polymul(c, [0.0, 1.0]) for c in pieces]
    moment = sum(P.polyval(hi, P.polyint(w)) - P.polyval(lo, P.polyint(w))
                 for lo, hi, w in zip(breaks[:-1], breaks[1:], weighted))
    return np.array(breaks), pieces, 1.0 / (2.0 * math.pi * moment)


class Radial2D:
    """M(q) = sigma int_0^q f(s) s ds and N(q) = sigma int_0^q f'(s) s ds (q in units of h), piecewise exact."""

    def __init__(self, name):
        self.breaks, pieces, self.sigma = _kernel(name)
        self.m = [P.polyint(P.polymul(c, [0.0, 1.0])) for c in pieces]
        self.n = [P.polyint(P.polymul(P.polyder(c), [0.0, 1.0])) for c in pieces]

    def _cum(self, polys, q):
        out = np.zeros_like(q)
        for j, poly in enumerate(polys):
            lo, hi = self.breaks[j], self.breaks[j + 1]
            out += P.polyval(np.clip(q, lo, hi), poly) - P.polyval(lo, poly)
        return self.sigma * out


def _graded(t0, t1, xg, wg, levels=20, ratio=0.2):
    frac = ratio ** np.arange(levels, 0, -1)
    unit = np.unique(np.concatenate([[0.0], frac * 0.5, [0.5], 1 - frac * 0.5, [1.0]]))
    b = t0 + (t1 - t0) * unit
    mid, half = 0.5 * (b[1:] + b[:-1]), 0.5 * np.diff(b)
    return (mid[:, None] + half[:, None] * xg).ravel(), (half[:, None] * wg).ravel()


def reference_2d(p, loops, h, radial, order=16):
    """(gamma, grad gamma (2,)) at p for the domain on the left of the vertex loops (see the module docstring)."""
    a = np.concatenate([np.asarray(loop, float) for loop in loops])
    b = np.concatenate([np.roll(np.asarray(loop, float), -1, axis=0) for loop in loops])
    p = np.asarray(p, float)
    e = b - a
    cuts = [np.arctan2(a[:, 1] - p[1], a[:, 0] - p[0]), np.arctan2(e[:, 1], e[:, 0]), np.arctan2(-e[:, 1], -e[:, 0])]
    length2 = np.einsum("sc,sc->s", e, e)
    foot = np.einsum("sc,sc->s", p - a, e) / length2  # parameter of the foot of p on each line
    line2 = np.sum((a + foot[:, None] * e - p) ** 2, axis=1)  # squared distance of p to each line
    for radius in h * radial.breaks[1:]:  # where each segment crosses the circle |y - p| = radius
        half = np.sqrt(np.maximum(radius * radius - line2, 0.0) / length2)
        for where in (foot - half, foot + half):
            on = (radius * radius > line2) & (where > 0) & (where < 1)
            y = a[on] + where[on, None] * e[on]
            cuts.append(np.arctan2(y[:, 1] - p[1], y[:, 0] - p[0]))
    cuts = np.unique(np.concatenate(cuts + [np.array([-np.pi, np.pi])]))
    xg, wg = np.polynomial.legendre.leggauss(order)
    th, wt = zip(*[_graded(t0, t1, xg, wg) for t0, t1 in zip(cuts[:-1], cuts[1:]) if t1 > t0])
    th, wt = np.concatenate(th), np.concatenate(wt)
    c, s = np.cos(th)[:, None], np.sin(th)[:, None]
    ap, bp = a - p, b - p
    crossed = (c * ap[:, 1] - s * ap[:, 0] >= 0) != (c * bp[:, 1] - s * bp[:, 0] >= 0)
    den = c * e[:, 1] - s * e[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ap[:, 0] * e[:, 1] - ap[:, 1] * e[:, 0]) / den
    t = np.where(np.isnan(t), 0.0, t)  # a ray along the edge from a particle on its line (a node on a cut)
    entering = np.where(s * e[:, 0] - c * e[:, 1] > 0, 1.0, -1.0)  # the ray along the inward normal
    q = np.clip(np.where(crossed, t, h), 0.0, h) / h
    one = np.ones(1)
    dm = np.where(crossed, entering * (radial._cum(radial.m, one) - radial._cum(radial.m, q)), 0).sum(axis=1)
    dn = np.where(crossed, entering * (radial._cum(radial.n, one) - radial._cum(radial.n, q)), 0).sum(axis=1)
    gamma = np.sum(wt * dm)
    grad = -np.array([np.sum(wt * dn * c[:, 0]), np.sum(wt * dn * s[:, 0])]) / h
    return gamma, grad


RADIAL = {name: Radial2D(name) for name in ("wendland_c2", "wendland_c4", "cubic_spline")}


def test_reference_known_values():
    """The reference itself: the half plane (1/2 on the wall), a 90 degree vertex (1/4), far inside (1)."""
    square = [np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])]
    for name, radial in RADIAL.items():
        for p, value in (([2.0, 0.0], 0.5), ([0.0, 0.0], 0.25), ([2.0, 2.0], 1.0), ([9.0, 9.0], 0.0)):
            g, d = reference_2d(p, square, 0.7, radial)
            assert abs(g - value) < 1e-14, (name, p, g)
        g, d = reference_2d([2.0, 2.0], square, 0.7, radial)
        assert np.abs(d).max() < 1e-13


# ----------------------------------------------------------------- polygons and points
def _star(draw, n, r_min, r_max, centre=(0.0, 0.0), scale=1.0, min_gap=0.2):
    """A simple polygon: n vertices at increasing angles about ``centre`` (counter-clockwise)."""
    gaps = draw(st.lists(st.floats(min_gap, 1.0), min_size=n, max_size=n))
    th = np.cumsum(gaps) / np.sum(gaps) * 2 * np.pi + draw(st.floats(0, 2 * np.pi))
    r = np.array(draw(st.lists(st.floats(r_min, r_max), min_size=n, max_size=n)))
    return np.column_stack([centre[0] + scale * r * np.cos(th), centre[1] + scale * r * np.sin(th)])


@st.composite
def polygons(draw):
    """(outer loop counter-clockwise, holes clockwise) of one of the families in the module docstring."""
    kind = draw(st.sampled_from(["convex", "concave", "holes", "sliver", "wedge10", "rectilinear"]))
    if kind == "convex":
        return kind, _star(draw, draw(st.integers(3, 8)), 1.0, 1.0), []
    if kind == "concave":
        return kind, _star(draw, draw(st.integers(4, 9)), 0.25, 1.0), []
    if kind == "holes":
        outer = _star(draw, draw(st.integers(5, 8)), 0.8, 1.0, min_gap=0.5)  # no edge closer than 0.4 to 0
        hole = _star(draw, draw(st.integers(3, 6)), 0.06, 0.15, centre=(draw(st.floats(-0.2, 0.2)), 0.0))
        return kind, outer, [hole[::-1]]
    if kind == "sliver":
        height = 10.0 ** draw(st.floats(-3, -1))
        return kind, np.array([[0.0, 0.0], [1.0, 0.0], [draw(st.floats(0.1, 0.9)), height]]), []
    if kind == "wedge10":
        t = math.radians(10.0)
        rot = draw(st.floats(0, 2 * np.pi))
        v = np.array([[0.0, 0.0], [1.0, 0.0], [math.cos(t), math.sin(t)]])
        c, s = math.cos(rot), math.sin(rot)
        return kind, v @ np.array([[c, s], [-s, c]]), []
    # rectilinear: an L or a U on a grid of spacing 1/4 (exact binary coordinates: points lie exactly on lines)
    shape = draw(st.sampled_from([[[0, 0], [4, 0], [4, 2], [2, 2], [2, 4], [0, 4]],
                                  [[0, 0], [6, 0], [6, 4], [4, 4], [4, 2], [2, 2], [2, 4], [0, 4]]]))
    return kind, 0.25 * np.array(shape, float), []


@st.composite
def cases(draw):
    kind, outer, holes = draw(polygons())
    loops = [outer] + holes
    size = np.ptp(outer, axis=0).max()
    h = size * draw(st.sampled_from([0.05, 0.2, 0.6, 1.5]))
    verts = np.concatenate(loops)
    ends = np.concatenate([np.roll(loop, -1, axis=0) for loop in loops])
    pts = []
    for _ in range(4):
        i = draw(st.integers(0, len(verts) - 1))
        a, b = verts[i], ends[i]
        u = (b - a) / np.linalg.norm(b - a)
        n = np.array([-u[1], u[0]])
        mode = draw(st.sampled_from(["line", "line", "vertex", "near_vertex", "edge", "near_edge"]))
        offset = draw(st.sampled_from([0.0, 1.0])) * 10.0 ** -draw(st.integers(3, 12)) * draw(st.sampled_from([-1, 1]))
        if mode == "line":  # on / near the line through the edge, beyond one of its end vertices
            along = draw(st.floats(1e-6, 1.0)) * h
            base = b + along * u if draw(st.booleans()) else a - along * u
            if kind == "rectilinear":
                base = np.round(base * 64) / 64  # exactly on the (axis-parallel) line
            pts.append(base + offset * h * n)
        elif mode == "vertex":
            pts.append(a.copy())
        elif mode == "near_vertex":
            angle = draw(st.floats(0, 2 * np.pi))
            pts.append(a + 10.0 ** -draw(st.integers(3, 12)) * h * np.array([math.cos(angle), math.sin(angle)]))
        else:  # on an edge or near it
            pts.append(a + draw(st.floats(0, 1)) * (b - a) + (offset * h * n if mode == "near_edge" else 0.0))
    return kind, loops, h, np.array(pts)


def _segments(loops):
    return BoundarySegments.from_vertices([loops[0]], holes=loops[1:] or None)


# ----------------------------------------------------------------- properties
@settings(max_examples=60, **SETTINGS)
@given(cases(), st.sampled_from(["wendland_c2", "wendland_c2", "wendland_c4", "cubic_spline"]))
@example(("sliver", [np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.001]])], 0.05, np.array([[2.16080428e-305, 5e-14]])),
         "wendland_c2")  # test_sliver_point_on_its_sharp_vertex_regression
def test_gamma_and_gradient_exact_near_edge_lines(case, kernel):
    kind, loops, h, r = case
    gamma, grad = gamma_and_gradient(r, _segments(loops), h, kernel=kernel)
    for x, g, d in zip(r, gamma, grad):
        g_ref, d_ref = reference_2d(x, loops, h, RADIAL[kernel])
        assert abs(g - g_ref) < TOL_GAMMA, (kind, x, g, g_ref)
        assert np.abs(d[:2] - d_ref).max() * h < TOL_GRAD, (kind, x, d, d_ref)
        assert -1e-14 <= g <= 1 + 1e-14  # rounding of chi - sum_s gamma_as


@settings(max_examples=40, **SETTINGS)
@given(cases())
def test_gamma_plus_complement_is_one(case):
    """The same loops as holes of a box: gamma inside + gamma of the complement = 1 (the point term included)."""
    kind, loops, h, r = case
    lo = np.concatenate(loops).min(axis=0) - 2 * h - 1.0
    hi = np.concatenate(loops).max(axis=0) + 2 * h + 1.0
    box = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])
    g_in, d_in = gamma_and_gradient(r, _segments(loops), h)
    islands = [hole[::-1] for hole in loops[1:]]  # the holes become islands of the complement
    complement = BoundarySegments.from_vertices([box] + islands, holes=[loops[0][::-1]])
    g_out, d_out = gamma_and_gradient(r, complement, h)
    np.testing.assert_allclose(g_in + g_out, 1.0, rtol=0, atol=TOL_GAMMA)
    np.testing.assert_allclose((d_in + d_out) * h, 0.0, rtol=0, atol=TOL_GRAD)


@settings(max_examples=40, **SETTINGS)
@given(cases())
def test_gradient_is_central_difference(case):
    """grad gamma against (gamma(x + eta) - gamma(x - eta)) / (2 eta), eta = 1e-5 h (error O(eta^2) + rounding)."""
    kind, loops, h, r = case
    seg = _segments(loops)
    _, grad = gamma_and_gradient(r, seg, h)
    eta = 1e-5 * h
    for axis in range(2):
        step = np.zeros(2)
        step[axis] = eta
        g_plus, _ = gamma_and_gradient(r + step, seg, h)
        g_minus, _ = gamma_and_gradient(r - step, seg, h)
        fd = (g_plus - g_minus) / (2 * eta)
        np.testing.assert_allclose(grad[:, axis] * h, fd * h, rtol=0, atol=1e-8)


@pytest.mark.parametrize("p,offset", [((2.0 + 0.3, 0.0), 1.2e-3), ((2.0 + 0.1, 0.0), 1e-4), ((2.0 + 0.1, 0.0), 1.7e-4)])
def test_issue_points(p, offset):
    """The issue's three configurations (h = 1): outside a convex 90 degree corner near the line past it, and
    inside a domain 0.1 h past a convex wedge tip (a 10 degree wedge as a hole), both sides of the line."""
    h = 1.0
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    t = math.radians(10.0)
    wedge = np.array([[2.0, 0.0], [2.0 - math.cos(t), -math.sin(t)], [1.0, 0.0]])  # tip at (2, 0), clockwise
    box = np.array([[-2.0, -3.0], [5.0, -3.0], [5.0, 3.0], [-2.0, 3.0]])
    for loops in ([square], [box, wedge]):
        r = np.array([[p[0], p[1] + sign * offset * h] for sign in (-1, 0, 1)])
        gamma, grad = gamma_and_gradient(r, _segments(loops), h)
        for x, g, d in zip(r, gamma, grad):
            g_ref, d_ref = reference_2d(x, loops, h, RADIAL["wendland_c2"])
            assert abs(g - g_ref) < TOL_GAMMA and np.abs(d[:2] - d_ref).max() < TOL_GRAD


# ----------------------------------------------------------------- 3D: exact values of a cube
# A cube [-1, 1]^3 with h = 0.3: near a face (farther than h from its edges) gamma is the half-space value
# 1/2 + sign(delta) int_0^|delta| W1 (W1 the kernel's marginal along the normal, a polynomial); the faces are
# split into two triangles along a diagonal, so points near the diagonals test two coplanar triangles near
# their shared edge line. Near an edge (farther than h from the vertices) the four quarter spaces around it
# sum to 1: sum_k gamma(R^k x) = 1 with R the rotation by 90 degrees about the edge; near a vertex the eight
# octants: sum over the reflections of x through the vertex's three planes = 1.
F3 = P.polymul(P.polypow([1.0, -1.0], 4), [1.0, 4.0])  # Wendland C2 profile, support 1
SIGMA3 = 1.0 / (4.0 * math.pi * (P.polyval(1.0, P.polyint(P.polymul(F3, [0.0, 0.0, 1.0])))))
# W1(s h) h = 2 pi sigma3 int_s^1 f(q) q dq  (s = |z| / h); its antiderivative from 0
_TAIL = P.polyint(P.polymul(F3, [0.0, 1.0]))
_W1 = 2 * math.pi * SIGMA3 * P.polysub([P.polyval(1.0, _TAIL)], _TAIL)  # a polynomial in s
_W1_INT = P.polyint(_W1)


def half_space_gamma(delta, h):
    """gamma at signed distance delta (positive inside) from a plane, |delta| < h."""
    return 0.5 + math.copysign(P.polyval(abs(delta) / h, _W1_INT), delta)


CUBE_H = 0.3
OFFSETS_3D = st.sampled_from([0.0, 1e-12, 1e-9, 1e-7, 1e-5, 1e-3, 0.1, 0.5])


@pytest.fixture(scope="module")
def cube():
    trimesh = pytest.importorskip("trimesh")
    return BoundaryTriangles.from_trimesh(trimesh.creation.box(extents=(2.0, 2.0, 2.0)))


def test_half_space_formula():
    """The marginal integrates to 1/2 over a half line, and the formula is odd about the plane."""
    assert abs(half_space_gamma(CUBE_H * (1 - 1e-15), CUBE_H) - 1.0) < 1e-13
    assert abs(half_space_gamma(-0.1, CUBE_H) + half_space_gamma(0.1, CUBE_H) - 1.0) < 1e-15


@settings(max_examples=40, **SETTINGS)
@given(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6), st.sampled_from(["free", "diagonal", "antidiagonal"]),
       OFFSETS_3D, st.sampled_from([-1, 1]), st.integers(0, 5))
def test_gamma_3d_exact_near_faces_and_their_diagonals(cube, x, y, line, offset, sign, face):
    u, v = {"free": (x, y), "diagonal": (x, x + offset * y * CUBE_H),
            "antidiagonal": (x, -x + offset * y * CUBE_H)}[line]
    delta = sign * offset * CUBE_H
    axis, side = face % 3, (1.0 if face < 3 else -1.0)
    p = np.zeros(3)
    p[axis] = side * (1.0 - delta)
    p[(axis + 1) % 3], p[(axis + 2) % 3] = u, v
    gamma, grad = gamma_and_gradient(p[None], cube, CUBE_H)
    assert abs(gamma[0] - half_space_gamma(delta, CUBE_H)) < TOL_GAMMA, (p, gamma[0] - half_space_gamma(delta, CUBE_H))
    assert np.abs(np.delete(grad[0], axis)).max() * CUBE_H < TOL_GRAD


@settings(max_examples=40, **SETTINGS)
@given(st.floats(-0.6, 0.6), st.floats(0, 2 * np.pi), OFFSETS_3D, st.integers(0, 2))
def test_gamma_3d_quarter_spaces_sum_to_one(cube, z, angle, offset, axis):
    a, b = offset * CUBE_H * math.cos(angle), offset * CUBE_H * math.sin(angle)
    offsets = [(a, b), (-b, a), (-a, -b), (b, -a)]  # rotations by 90 degrees: exact in floating point
    r = np.zeros((4, 3))
    for k, (da, db) in enumerate(offsets):
        r[k, axis] = z
        r[k, (axis + 1) % 3], r[k, (axis + 2) % 3] = 1.0 + da, 1.0 + db
    gamma, _ = gamma_and_gradient(r, cube, CUBE_H)
    assert abs(gamma.sum() - 1.0) < TOL_GAMMA, (r, gamma)
    if offset == 0.0:
        np.testing.assert_allclose(gamma, 0.25, rtol=0, atol=TOL_GAMMA)


@settings(max_examples=30, **SETTINGS)
@given(st.floats(0, 2 * np.pi), st.floats(0, np.pi), OFFSETS_3D)
def test_gamma_3d_octants_sum_to_one(cube, azimuth, polar, offset):
    d = offset * CUBE_H * np.array([math.sin(polar) * math.cos(azimuth), math.sin(polar) * math.sin(azimuth),
                                    math.cos(polar)])
    signs = np.array([[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)])
    r = 1.0 + signs * d
    gamma, _ = gamma_and_gradient(r, cube, CUBE_H)
    assert abs(gamma.sum() - 1.0) < TOL_GAMMA, (r, gamma)
    if offset == 0.0:
        np.testing.assert_allclose(gamma, 0.125, rtol=0, atol=TOL_GAMMA)


@pytest.mark.parametrize("shape", ["cube", "icosphere", "tetrahedron"])
def test_gamma_3d_gradient_is_central_difference(shape):
    """Near faces, edges (and the lines through them) and vertices, inside and outside."""
    trimesh = pytest.importorskip("trimesh")
    mesh = {"cube": lambda: trimesh.creation.box(extents=(2.0, 2.0, 2.0)),
            "icosphere": lambda: trimesh.creation.icosphere(subdivisions=1, radius=1.0),
            "tetrahedron": lambda: trimesh.convex.convex_hull([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]])
            }[shape]()
    tri = BoundaryTriangles.from_trimesh(mesh)
    h = 0.4
    v = tri.vertices_tkc
    rng = np.random.default_rng(5)
    base = np.concatenate([v[:6, 0], 0.5 * (v[:6, 0] + v[:6, 1]), tri.centroid_tc[:6],
                           v[:6, 1] + 0.3 * (v[:6, 1] - v[:6, 0])])  # vertices, edge mid points, faces, edge lines
    r = np.concatenate([base + 10.0 ** -rng.integers(3, 12, size=(len(base), 1)) * h * rng.normal(size=base.shape),
                        base + 0.01 * h * rng.normal(size=base.shape)])
    _, grad = gamma_and_gradient(r, tri, h)
    eta = 1e-5 * h
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = eta
        fd = (gamma_and_gradient(r + step, tri, h)[0] - gamma_and_gradient(r - step, tri, h)[0]) / (2 * eta)
        np.testing.assert_allclose(grad[:, axis] * h, fd * h, rtol=0, atol=1e-7)


def test_gamma_at_vertices_of_rotated_wedges():
    """On a vertex gamma is its interior angle over 2 pi, however |b - a|^2 / |b - a|^2 rounds (200 rotations)."""
    t = math.radians(10.0)
    base = np.array([[0.0, 0.0], [1.0, 0.0], [math.cos(t), math.sin(t)]])
    expected = np.array([10.0, 85.0, 85.0]) / 360.0
    for rot in np.linspace(0.0, 2 * np.pi, 200, endpoint=False):
        c, s = math.cos(rot), math.sin(rot)
        v = base @ np.array([[c, s], [-s, c]])
        gamma, _ = gamma_and_gradient(v, BoundarySegments.from_vertices(v), 0.05)
        np.testing.assert_allclose(gamma, expected, rtol=0, atol=TOL_GAMMA)


def test_sliver_point_on_its_sharp_vertex_regression():
    """A hypothesis find: 5e-14 above the 0.1 degree vertex of a sliver, just outside it (the upper edge is at
    4e-308 there), was classified inside (gamma = 1 + 3.18e-4). The query's nearest segment was the lower
    edge: its distance rounds with eps |b - a| (measured from the far end), here 1e3 times the 1e-19 by which
    the upper edge is nearer."""
    loops = [np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.001]])]
    r = np.array([[2.16080428e-305, 5.0e-14]])
    gamma, grad = gamma_and_gradient(r, _segments(loops), 0.05)
    g_ref, d_ref = reference_2d(r[0], loops, 0.05, RADIAL["wendland_c2"])
    assert abs(gamma[0] - g_ref) < TOL_GAMMA, (gamma[0], g_ref)
    assert abs(g_ref - 0.0003183094617716302) < 1e-15
    assert np.abs(grad[0, :2] - d_ref).max() * 0.05 < TOL_GRAD


@pytest.mark.parametrize("shape", ["sliver", "wedge10"])
@pytest.mark.parametrize("offset", [5e-324, 1e-310, 1e-300, 1e-14])
def test_gamma_next_to_sharp_vertices(shape, offset):
    """Points at subnormal, 1e-300 and 1e-14 distances from each vertex of a sliver and a 10 degree wedge, in
    48 directions and along both edges' normals (inside and outside, above the edges of the sharp vertex as in
    the regression above). Each vertex in turn sits at the origin so that the offsets are representable.
    Below 1e-300 gamma is the reference's value on the vertex (they differ by |grad gamma| 1e-300)."""
    h = 0.05
    t = math.radians(10.0)
    base = (np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.001]]) if shape == "sliver"
            else np.array([[0.0, 0.0], [1.0, 0.0], [math.cos(t), math.sin(t)]]))
    angles = list(np.linspace(0.0, 2 * np.pi, 48, endpoint=False)) + [0.5 * np.pi, 0.5 * np.pi + 1e-6]
    for i in range(3):
        loop = base - base[i]
        for k in (i, i - 1):  # the normals of both edges at the vertex, both ways, and slightly tilted
            e = loop[(k + 1) % 3] - loop[k]
            angles += [math.atan2(e[0], -e[1]) + s * np.pi + tilt for s in (0, 1) for tilt in (0.0, 1e-7, -1e-7)]
        r = offset * np.column_stack([np.cos(angles), np.sin(angles)])
        r = r[np.any(r != 0.0, axis=1)] if offset < 1e-300 else r  # a subnormal times cos may round to 0
        gamma, grad = gamma_and_gradient(r, _segments([loop]), h)
        expected, _ = reference_2d(np.zeros(2), [loop], h, RADIAL["wendland_c2"])
        if offset <= 1e-300:
            for x, g in zip(r, gamma):
                assert abs(g - expected) < TOL_GAMMA, (shape, i, x, g, expected)
        else:
            for x, g, d in zip(r, gamma, grad):
                g_ref, d_ref = reference_2d(x, [loop], h, RADIAL["wendland_c2"])
                assert abs(g - g_ref) < TOL_GAMMA, (shape, i, x, g, g_ref)
                assert np.abs(d[:2] - d_ref).max() * h < TOL_GRAD, (shape, i, x, d, d_ref)
