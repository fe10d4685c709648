"""gamma_a and grad gamma_a (issue 7 item 2) against direct numerical integration of W over
Omega cap B(x_a, h): polar coordinates about x_a with the radial integral exact and the angle
split where the integrand has kinks (2D, to 1e-8 relative); nested Cartesian quadrature (3D,
to 1e-6)."""
import math

import numpy as np
import pytest
from numpy.polynomial import polynomial as P

from ase_sphrelax.boundary import BoundaryIntegrals, BoundarySegments, BoundaryTriangles, boundary_terms
from ase_sphrelax.boundary import gamma_and_gradient
from ase_sphrelax.boundary.radial import _q_powers
from ase_sphrelax.domains import Polygon
from ase_sphrelax.kernels import get_kernel
from ase_sphrelax.neighbors import NeighborList


# ----------------------------------------------------------------- reference integrals
class Radial:
    """M(r) = int_0^r W(s) s^(d-1) ds and N(r) = int_0^r W'(s) s^(d-1) ds, exact piecewise polynomials."""

    def __init__(self, kernel, dim, h):
        k = get_kernel(kernel, dim)
        self.breaks, coef = _q_powers(k)
        q = np.linspace(0, 0.999, 101)
        ref = k.profile(q)
        mine = np.array([P.polyval(x, coef[np.searchsorted(self.breaks, x, side="right") - 1]) for x in q])
        assert np.allclose(mine, ref, atol=1e-13)  # the power form is the kernel
        self.h, self.dim, self.sigma = h, dim, k.sigma
        w = [0.0] * (dim - 1) + [1.0]
        self.m = [P.polyint(P.polymul(c, w)) for c in coef]
        self.n = [P.polyint(P.polymul(P.polyder(c), w)) for c in coef]

    def _cum(self, polys, r):
        q = np.minimum(np.asarray(r, dtype=float) / self.h, 1.0)
        out = np.zeros_like(q)
        for j, poly in enumerate(polys):
            lo, hi = self.breaks[j], self.breaks[j + 1]
            out += P.polyval(np.clip(q, lo, hi), poly) - P.polyval(lo, poly)
        return out

    def M(self, r):
        return self.sigma * self._cum(self.m, r)

    def N(self, r):
        return self.sigma / self.h * self._cum(self.n, r)


def graded_nodes(cuts, levels=20, ratio=0.2, order=16):
    """Gauss-Legendre nodes and weights on [cuts[i], cuts[i+1]], graded geometrically towards both
    ends of every interval (where the near-singularities of the angular integrand sit)."""
    xg, wg = np.polynomial.legendre.leggauss(order)
    frac = ratio ** np.arange(levels, 0, -1)
    unit = np.unique(np.concatenate([[0.0], frac * 0.5, [0.5], 1 - frac * 0.5, [1.0]]))
    th, wt = [], []
    for t0, t1 in zip(cuts[:-1], cuts[1:]):
        if t1 <= t0:
            continue
        b = t0 + (t1 - t0) * unit
        mid, half = 0.5 * (b[1:] + b[:-1]), 0.5 * np.diff(b)
        th.append((mid[:, None] + half[:, None] * xg).ravel())
        wt.append((half[:, None] * wg).ravel())
    return np.concatenate(th), np.concatenate(wt)


def reference_2d(p, seg, h, radial, inside):
    """gamma and grad gamma at p by polar integration over Omega cap B(p, h).

    Along each ray the radial integral is exact (M, N over the inside stretches, decided by the
    inside test at their mid points); the angle is integrated by graded Gauss-Legendre between
    the kinks: vertex directions, feet of the perpendiculars, crossings of r = h.
    """
    a, b = seg.start_sc, seg.end_sc
    e = b - a
    t = np.clip(np.einsum("sc,sc->s", p - a, e) / np.einsum("sc,sc->s", e, e), 0, 1)
    foot = a + t[:, None] * e
    near = np.nonzero(np.linalg.norm(foot - p, axis=1) < h)[0]
    a, b, e, foot = a[near], b[near], e[near], foot[near]
    cuts = [np.arctan2(*(v - p)[:, ::-1].T) for v in (a, b)]
    far = np.linalg.norm(foot - p, axis=1) > 0
    cuts.append(np.arctan2(*(foot[far] - p)[:, ::-1].T))
    aa = np.einsum("sc,sc->s", e, e)
    bb = 2 * np.einsum("sc,sc->s", e, a - p)
    for radius in h * radial.breaks[1:]:  # crossings of the circles r = h and r = break radii
        cc = np.einsum("sc,sc->s", a - p, a - p) - radius**2
        disc = bb * bb - 4 * aa * cc
        for sign in (-1, 1):
            s = (-bb + sign * np.sqrt(np.maximum(disc, 0))) / (2 * aa)
            ok = (disc > 0) & (s > 0) & (s < 1)
            y = a[ok] + s[ok, None] * e[ok]
            cuts.append(np.arctan2(y[:, 1] - p[1], y[:, 0] - p[0]))
    cuts = np.unique(np.concatenate(cuts + [np.array([-np.pi, np.pi])]))
    cuts = cuts[(cuts >= -np.pi) & (cuts <= np.pi)]
    th, wt = graded_nodes(cuts)
    om = np.stack([np.cos(th), np.sin(th)], axis=1)
    den = om[:, None, 0] * e[None, :, 1] - om[:, None, 1] * e[None, :, 0]
    ap = a[None] - p
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (ap[..., 0] * e[None, :, 1] - ap[..., 1] * e[None, :, 0]) / den
        s = (ap[..., 0] * om[:, None, 1] - ap[..., 1] * om[:, None, 0]) / den
    hit = (den != 0) & (s >= 0) & (s <= 1) & (r > 1e-13 * h) & (r < h)
    r = np.sort(np.concatenate([np.zeros((len(th), 1)), np.where(hit, r, h), np.full((len(th), 1), h)], axis=1),
                axis=1)
    mid = 0.5 * (r[:, 1:] + r[:, :-1])
    ins = inside((p + mid[..., None] * om[:, None, :]).reshape(-1, 2)).reshape(mid.shape) & (np.diff(r, axis=1) > 0)
    dm = np.where(ins, radial.M(r[:, 1:]) - radial.M(r[:, :-1]), 0).sum(axis=1)
    dn = np.where(ins, radial.N(r[:, 1:]) - radial.N(r[:, :-1]), 0).sum(axis=1)
    return np.sum(wt * dm), -np.sum((wt * dn)[:, None] * om, axis=0)


def wedge(degrees, size=1.0):
    t = math.radians(degrees)
    return BoundarySegments.from_vertices(size * np.array([[0.0, 0.0], [1.0, 0.0], [math.cos(t), math.sin(t)]]))


def l_shape():
    return BoundarySegments.from_vertices([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]])


def trapezoid_with_hole():
    return BoundarySegments.from_vertices([[0, 1], [0, 0], [1, 0], [1.5, 1]],
                                          holes=[[[0.4, 0.4], [0.42, 0.4], [0.41, 0.43]]])


def probe_points(seg, h, rng, n=40, fractions=(1e-9, 1e-3, 0.1, 0.3, 0.6, 0.9)):
    """Inside, on the boundary (segment interiors and vertices), near edges, near corners."""
    poly = Polygon(seg.loops)
    pts = [seg.start_sc, seg.centroid_sc]
    for frac in fractions:
        pts.append(seg.centroid_sc + frac * h * seg.normal_sc)
        pts.append(seg.start_sc + frac * h * (seg.normal_sc + seg.normal_sc[seg.prev_s]) / 2)
    lo, hi = seg.bounds
    cloud = lo + (hi - lo) * rng.random((4 * n, 2))
    pts.append(cloud[poly.contains(cloud)][:n])
    r = np.concatenate(pts)
    return r[poly.phi(r) <= 0]  # inside or on the boundary


@pytest.mark.parametrize("name,h,kernel", [("wedge10", 0.3, "wendland_c2"), ("wedge10", 2.0, "wendland_c2"),
                                           ("lshape", 0.35, "wendland_c2"), ("trapezoid_hole", 0.08, "wendland_c2"),
                                           ("wedge90", 0.4, "wendland_c2"), ("wedge10", 0.3, "cubic_spline"),
                                           ("lshape", 0.35, "wendland_c4")])
def test_gamma_2d_exact_against_polar_integration(name, h, kernel):
    seg = {"wedge10": wedge(10.0), "lshape": l_shape(), "trapezoid_hole": trapezoid_with_hole(),
           "wedge90": BoundarySegments.from_vertices([[0, 0], [1, 0], [1, 1], [0, 1]])}[name]
    rng = np.random.default_rng(0)
    r = probe_points(seg, h, rng)
    gamma, grad = gamma_and_gradient(r, seg, h, kernel=kernel)
    assert gamma.shape == (len(r),) and grad.shape == (len(r), 3) and np.all(grad[:, 2] == 0)
    radial = Radial(kernel, 2, h)
    poly = Polygon(seg.loops)
    worst_g = worst_d = 0.0
    for x, g, d in zip(r, gamma, grad):
        g_ref, d_ref = reference_2d(x, seg, h, radial, poly.contains)
        worst_g = max(worst_g, abs(g - g_ref) / abs(g_ref))
        # relative to |grad| where it is not tiny, and 1e-12 / h absolute everywhere
        worst_d = max(worst_d, np.linalg.norm(d[:2] - d_ref) / max(np.linalg.norm(d_ref), 1e-4 / h))
    assert worst_g < 1e-8, worst_g
    assert worst_d < 1e-8, worst_d


def test_gamma_known_values():
    """Half plane: 1/2 on the wall; a vertex: the interior angle over 2 pi; far inside: 1."""
    seg = BoundarySegments.from_vertices([[0, 0], [4, 0], [4, 4], [0, 4]])
    t = math.radians(10.0)
    w = wedge(10.0)
    r = np.array([[2.0, 0.0], [2.0, 2.0], [0.0, 0.0], [4.0, 4.0], [2.0, 1e-14]])
    g, _ = gamma_and_gradient(r, seg, 0.5)
    np.testing.assert_allclose(g, [0.5, 1.0, 0.25, 0.25, 0.5], atol=1e-13)
    g, grad = gamma_and_gradient([[0.0, 0.0], [1.0, 0.0], [math.cos(t), math.sin(t)]], w, 0.05)
    apex, base = 10 / 360, (180 - 10) / 2 / 360
    np.testing.assert_allclose(g, [apex, base, base], atol=1e-13)
    # outside, far from everything: 0; outside but within h: small and continuous across the wall
    g, _ = gamma_and_gradient([[10.0, 10.0], [2.0, -0.25]], seg, 0.5)
    assert g[0] == 0.0 and 0 < g[1] < 0.5
    eps = 1e-10
    g, _ = gamma_and_gradient([[2.0, -eps], [2.0, eps]], seg, 0.5)
    assert abs(g[0] - g[1]) < 1e-8


def test_gamma_does_not_depend_on_refinement(geometries):
    seg = BoundarySegments.from_edges(geometries / "TrapezoidalTank.edges")
    fine = seg.refine(dx=0.02)
    rng = np.random.default_rng(1)
    r = probe_points(seg, 0.08, rng, n=200, fractions=(1e-9, 1e-3, 0.1, 0.3, 0.6, 0.9))
    g0, d0 = gamma_and_gradient(r, seg, 0.08)
    g1, d1 = gamma_and_gradient(r, fine, 0.08)
    np.testing.assert_allclose(g1, g0, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(d1, d0, rtol=1e-10, atol=1e-10)


def test_far_particles_touch_no_segment_and_thin_features(geometries):
    seg = BoundarySegments.from_edges(geometries / "AirFoilSolid.edges")
    h = 0.2
    rng = np.random.default_rng(2)
    r = probe_points(seg, h, rng, n=400, fractions=(1e-9, 1e-3, 0.1, 0.3, 0.6, 0.9))
    out = boundary_terms(r, seg, h)
    far = out.pairs.count_p == 0
    assert far.any() and np.all(out.gamma_p[far] == 1.0) and np.all(out.grad_gamma_pc[far] == 0.0)
    assert np.all(np.isfinite(out.gamma_p)) and np.all(out.gamma_p > 0) and np.all(out.gamma_p <= 1 + 1e-12)
    # near the thin trailing edge (thickness 0.05 < h), compared with direct integration
    te = seg.start_sc[np.argmax(seg.start_sc[:, 0])]
    probe = te + np.array([[-0.02, 0.0], [-0.1, 0.01], [-0.3, 0.02], [-0.005, 0.0]])
    poly = Polygon(seg.loops)
    probe = probe[poly.contains(probe)]
    g, d = gamma_and_gradient(probe, seg, h)
    radial = Radial("wendland_c2", 2, h)
    for x, gx, dx in zip(probe, g, d):
        g_ref, d_ref = reference_2d(x, seg, h, radial, poly.contains)
        assert abs(gx - g_ref) < 1e-8 * g_ref
        assert np.linalg.norm(dx[:2] - d_ref) < 1e-8 * np.linalg.norm(d_ref)


def test_stored_list_caches_inside_test(geometries):
    """gamma over a stored list equals the one-shot values; the inside test runs once per build."""
    seg = BoundarySegments.from_edges(geometries / "TrapezoidalTank.edges")
    rng = np.random.default_rng(3)
    poly = Polygon(seg.loops)
    r2 = rng.random((4000, 2)) * [1.5, 1]
    r = np.zeros((4000, 3))
    r[:, :2] = r2[poly.contains(r2)][:4000] if poly.contains(r2).sum() >= 4000 else r2
    r = r[poly.contains(r)]
    h = 0.08
    integrals = BoundaryIntegrals(seg, h)
    nlist = NeighborList(h, skin=0.02)
    for _ in range(3):
        nlist.update(r, np.zeros((3, 3)), False, store=True)
        out = integrals.compute(nlist, r)
        g_ref, d_ref = gamma_and_gradient(r, seg, h)
        np.testing.assert_array_equal(out.gamma_p, g_ref)
        np.testing.assert_array_equal(out.grad_gamma_pc, d_ref)
        r = r + rng.normal(scale=1e-3, size=r.shape) * [1, 1, 0]
        r = r[poly.contains(r)]
    assert integrals.inside_tests <= 3


def test_bad_input():
    seg = BoundarySegments.from_vertices([[0, 0], [1, 0], [0, 1]])
    with pytest.raises(ValueError, match="z = 0"):
        gamma_and_gradient([[0.1, 0.1, 0.5]], seg, 0.1)
    with pytest.raises(ValueError, match="h must be"):
        gamma_and_gradient([[0.1, 0.1]], seg, -1)
    with pytest.raises(ValueError, match="r_pc"):
        gamma_and_gradient(np.zeros((0, 3)), seg, 0.1)
    with pytest.raises(TypeError, match="boundary must be"):
        gamma_and_gradient([[0.1, 0.1]], 3.0, 0.1)
    with pytest.raises(ValueError, match="to_polygon"):
        from ase_sphrelax.domains import Circle

        gamma_and_gradient([[0.1, 0.1]], Circle((0, 0), 1), 0.1)


# ----------------------------------------------------------------- 3D
def reference_3d(p, tri, h, radial):
    """gamma and grad gamma at an interior point p of a closed mesh, in spherical coordinates about p.

    The directions through face f form its cone, ``d omega = d / r^3 dA`` on the face, and along a ray
    the radial integral is exact up to ``min(h, r)`` (a convex mesh: one exit). The full sphere gives 1
    and zero gradient, so gamma = 1 + sum over the faces within h of
    ``int_f (M(min(h, r)) - M(h)) d / r^3 dA`` and grad = -sum ``int_f omega (N(min(h, r)) - N(h)) d / r^3 dA``,
    integrated by adaptive cubature (scipy) over each triangle (Duffy map from the unit square).
    """
    from scipy.integrate import cubature

    from ase_sphrelax.domains.closest import closest_on_triangle

    total = np.zeros(4)
    m_h, n_h = radial.M(h), radial.N(h)
    for t, (v0, v1, v2) in enumerate(tri.vertices_tkc):
        if closest_on_triangle(*p, tri.packed_tk[t])[0] >= h * h:
            continue
        d = (p - v0) @ tri.normal_tc[t]
        area2 = np.linalg.norm(np.cross(v1 - v0, v2 - v0))

        def f(x, v0=v0, v1=v1, v2=v2, d=d, area2=area2):
            u, v = x[:, :1], x[:, 1:2]
            y = v0 + u * (v1 - v0) + u * v * (v2 - v1)
            rv = y - p
            r = np.linalg.norm(rv, axis=1)
            jac = area2 * u[:, 0] * d / r**3
            dm = (radial.M(np.minimum(r, h)) - m_h) * jac
            dn = (radial.N(np.minimum(r, h)) - n_h) * jac
            return np.column_stack([dm, -dn[:, None] * rv / r[:, None]])

        total += cubature(f, [0, 0], [1, 1], rtol=1e-12, atol=1e-14, max_subdivisions=20000).estimate
    return 1.0 + total[0], total[1:]


@pytest.mark.parametrize("shape", ["box", "icosphere"])
def test_gamma_3d_against_direct_integration(shape):
    trimesh = pytest.importorskip("trimesh")
    if shape == "box":
        tri = BoundaryTriangles.from_trimesh(trimesh.creation.box(extents=(1.0, 0.8, 1.2)))
        h = 0.3
        # interior, near a face, an edge, a corner; near a face's diagonal edge; 1e-3 h from a face
        probes = [[0.0, 0.0, 0.0], [0.45, 0.0, 0.1], [0.4, 0.3, 0.5], [0.49, 0.39, 0.59], [0.3, 0.2, 0.55],
                  [0.1, 0.08, 0.6 - 3e-4], [0.0, 0.0, 0.6 - 3e-3]]
    else:
        tri = BoundaryTriangles.from_trimesh(trimesh.creation.icosphere(subdivisions=2, radius=1.0))
        h = 0.25
        v = tri.vertices_tkc
        probes = [0.9 * v[0, 0], 0.95 * tri.centroid_tc[3], 0.85 * v[5, 1], [0.6, 0.5, 0.3],
                  0.99 * (v[7, 0] + v[7, 1]) / 2]
    radial = Radial("wendland_c2", 3, h)
    r = np.array(probes, dtype=float)
    gamma, grad = gamma_and_gradient(r, tri, h)
    for x, g, d in zip(r, gamma, grad):
        g_ref, d_ref = reference_3d(x, tri, h, radial)
        assert abs(g - g_ref) < 1e-6 * g_ref, (x, g, g_ref)
        assert np.linalg.norm(d - d_ref) < 1e-6 * max(np.linalg.norm(d_ref), 1 / h), (x, d, d_ref)


def test_gamma_3d_known_values():
    trimesh = pytest.importorskip("trimesh")
    box = BoundaryTriangles.from_trimesh(trimesh.creation.box(extents=(2.0, 2.0, 2.0)))
    r = np.array([[0, 0, 0], [1.0, 0.2, 0.1], [0.0, 0.0, -1.0], [1 - 1e-12, 0.3, 0.0], [1.0, 1.0, 0.0],
                  [1.0, 1.0, 1.0], [0.3, 1.0, 0.0]])
    g, grad = gamma_and_gradient(r, box, 0.4)
    # inside, on a face, on a face (and on a diagonal edge), just inside a face, on an edge (1/4), on a vertex
    # (1/8), on a face; points within 1e-7 h of the surface are evaluated 1e-7 h inside: gamma + O(2e-7)
    np.testing.assert_allclose(g, [1.0, 0.5, 0.5, 0.5, 0.25, 0.125, 0.5], atol=3e-7)
    assert np.all(np.isfinite(grad))
    np.testing.assert_allclose(grad[2, :2], 0.0, atol=1e-12)
    assert grad[2, 2] > 0  # the bottom face's inward normal is +z
