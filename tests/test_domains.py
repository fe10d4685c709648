"""Level-set domains: analytic values, normal = exact gradient of phi, volumes, CSG, validation."""
import math
from pathlib import Path

import numpy as np
import pytest

from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles
from ase_sphrelax.domains import (Box, Circle, Difference, Intersection, Mesh, Polygon, Sphere,
                                  Tabulated, Union)

GEOM = Path(__file__).resolve().parents[2] / "shared" / "geometries"


def edges(name):
    path = GEOM / f"{name}.edges"
    if not path.exists():
        pytest.skip(f"{path} not available")
    return path


def fd_gradient(domain, r_pc, eps=1e-6):
    g = np.zeros((len(r_pc), 3))
    for d in range(domain.dim):
        e = np.zeros(3)
        e[d] = eps
        g[:, d] = (domain.phi(r_pc + e) - domain.phi(r_pc - e)) / (2 * eps)
    return g


def sample(domain, n=400, seed=0, spread=0.3):
    """Points inside, outside and near the boundary of ``domain``."""
    rng = np.random.default_rng(seed)
    lo, hi = domain.bounds
    ext = hi - lo
    r = np.zeros((n, 3))
    r[:, : domain.dim] = lo - spread * ext + (1 + 2 * spread) * ext * rng.random((n, domain.dim))
    # move half of them close to the boundary along the normal
    phi, nrm = domain.phi_and_normal(r[: n // 2])
    r[: n // 2] -= (phi - 1e-3 * ext.max() * rng.standard_normal(n // 2))[:, None] * nrm
    return r


def assert_normal_is_gradient(domain, r, tol=1e-6, max_kink_fraction=0.05):
    """normal == central finite difference of phi (eps = 1e-6).

    The central difference differs from the normal by at most the change of
    the normal across the stencil, ``jump`` (curvature times 2 eps where phi
    is smooth, the kink angle where the stencil straddles a shallow kink such
    as the vertex bisectors of a finely polygonised circle); a wrong normal
    gives an O(1) error.  Points whose stencil straddles a sharp kink
    (``jump`` > 0.01) are skipped and must be rare.
    """
    eps = 1e-6
    phi, n = domain.phi_and_normal(r)
    assert n.shape == (len(r), 3) and phi.shape == (len(r),)
    if domain.dim == 2:
        assert np.all(n[:, 2] == 0.0)
    g = fd_gradient(domain, r, eps)
    jump = np.zeros(len(r))
    for d in range(domain.dim):
        e = np.zeros(3)
        e[d] = eps
        jump = np.maximum(jump, np.linalg.norm(
            domain.phi_and_normal(r + e)[1] - domain.phi_and_normal(r - e)[1], axis=1))
    smooth = jump < 1e-2
    assert (~smooth).mean() <= max_kink_fraction, (~smooth).mean()
    err = np.linalg.norm(g - n, axis=1)
    excess = (err - tol - jump)[smooth]
    assert excess.max() < 0, (err[smooth].max(), r[smooth][np.argmax(excess)])


# ---------------------------------------------------------------- analytic
def test_circle_values():
    c = Circle((0.5, 0.5), 0.2)
    phi, n = c.phi_and_normal([[0.5, 0.5, 0.0], [0.8, 0.5, 0.0], [0.5, 0.4, 7.0], [0.6, 0.6, 0.0]])
    np.testing.assert_allclose(phi, [-0.2, 0.1, -0.1, math.hypot(0.1, 0.1) - 0.2])
    np.testing.assert_allclose(n[1], [1, 0, 0])
    np.testing.assert_allclose(n[2], [0, -1, 0])
    np.testing.assert_allclose(n[3], [2**-0.5, 2**-0.5, 0])
    assert c.volume == pytest.approx(math.pi * 0.04)
    np.testing.assert_allclose(c.bounds[0], [0.3, 0.3])
    np.testing.assert_allclose(c.bounds[1], [0.7, 0.7])


def test_sphere_values():
    s = Sphere((1, 2, 3), 2.0)
    phi, n = s.phi_and_normal([[1, 2, 3], [1, 2, 6], [4, 6, 3]])
    np.testing.assert_allclose(phi, [-2, 1, 3])
    np.testing.assert_allclose(n[1:], [[0, 0, 1], [0.6, 0.8, 0]])
    assert s.volume == pytest.approx(4 / 3 * math.pi * 8)


def test_box_values_inside_outside_corner():
    b = Box([0, 0], [1, 2])
    r = [[0.5, 0.1], [0.9, 1.0], [2.0, 1.0], [4.0, 6.0], [-3.0, -4.0], [0.5, -0.5]]
    phi, n = b.phi_and_normal(r)
    np.testing.assert_allclose(phi, [-0.1, -0.1, 1.0, 5.0, 5.0, 0.5])
    np.testing.assert_allclose(n[:, :2], [[0, -1], [1, 0], [1, 0], [0.6, 0.8], [-0.6, -0.8], [0, -1]])
    assert b.volume == 2.0
    b3 = Box([0, 0, 0], [1, 1, 1])
    assert b3.phi([[2, 3, 3]])[0] == pytest.approx(3.0)  # corner region: |(1, 2, 2)|
    assert b3.phi([[0.5, 0.5, 0.5]])[0] == pytest.approx(-0.5)
    assert b3.dim == 3 and b3.volume == 1.0


@pytest.mark.parametrize("domain", [Circle((0.5, 0.5), 0.2), Sphere((0, 0, 0), 1.0),
                                    Box([0, 0], [1, 2]), Box([-1, 0, 0], [1, 2, 0.5])],
                         ids=["circle", "sphere", "box2", "box3"])
def test_analytic_normal_is_gradient_and_unit(domain):
    r = sample(domain)
    assert_normal_is_gradient(domain, r)
    _, n = domain.phi_and_normal(r)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)


def test_bad_input_names_parameter():
    with pytest.raises(ValueError, match="radius"):
        Circle((0, 0), -1.0)
    with pytest.raises(ValueError, match="radius"):
        Sphere((0, 0, 0), float("nan"))
    with pytest.raises(ValueError, match="center"):
        Circle((0, 0, 0), 1.0)
    with pytest.raises(ValueError, match="hi"):
        Box([0, 0], [1, 0])
    with pytest.raises(ValueError, match="r_pc"):
        Sphere((0, 0, 0), 1.0).phi(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="grid_spacing"):
        Polygon([[[0, 0], [1, 0], [0, 1]]], grid_spacing=-0.1)
    with pytest.raises(ValueError, match="dx"):
        Circle((0, 0), 1.0).tabulated(0.0)


# ---------------------------------------------------------------- polygons
def test_trapezoid_from_edges():
    p = Polygon.from_edges(edges("TrapezoidalTank"))
    assert p.volume == pytest.approx(1.25, rel=1e-14)
    np.testing.assert_allclose(p.bounds[0], [0, 0])
    np.testing.assert_allclose(p.bounds[1], [1.5, 1])
    phi, n = p.phi_and_normal([[0.2, 0.5], [-1.0, -1.0], [0.5, -0.25], [0.5, 1.5]])
    np.testing.assert_allclose(phi, [-0.2, math.sqrt(2), 0.25, 0.5])
    np.testing.assert_allclose(n[:, :2], [[-1, 0], [-2**-0.5, -2**-0.5], [0, -1], [0, 1]])
    # slanted side from (1, 0) to (1.5, 1): outward normal (2, -1)/sqrt(5)
    x = np.array([1.25, 0.5]) + 0.1 * np.array([2, -1]) / math.sqrt(5)
    phi, n = p.phi_and_normal([x])
    assert phi[0] == pytest.approx(0.1)
    np.testing.assert_allclose(n[0, :2], np.array([2, -1]) / math.sqrt(5))


@pytest.mark.parametrize("name", ["AirFoilFluid", "Standford2DBunny"])
def test_polygon_matches_shapely_distance(name):
    """Signed distance equals shapely's, with the geometry built from the raw segments."""
    shapely = pytest.importorskip("shapely")
    from functools import reduce

    from shapely.ops import polygonize

    e = np.loadtxt(edges(name))
    loops = list(polygonize([((x1, y1), (x2, y2)) for x1, y1, x2, y2 in e]))
    loops = [shapely.Polygon(poly.exterior) for poly in loops]
    g = reduce(lambda a, b: a.symmetric_difference(b), loops)  # even-odd rule
    p = Polygon.from_edges(edges(name))
    assert p.volume == pytest.approx(g.area, rel=1e-12)
    r = sample(p, n=2000, seed=3)
    d = shapely.distance(g.boundary, shapely.points(r[:, :2]))
    inside = shapely.contains_xy(g, r[:, 0], r[:, 1])
    np.testing.assert_allclose(p.phi(r), np.where(inside, -d, d), atol=1e-12)


@pytest.mark.parametrize("name", ["TrapezoidalTank", "Standford2DBunny", "AirFoilFluid", "EllipticDrop"])
def test_polygon_normal_is_gradient(name):
    p = Polygon.from_edges(edges(name))
    r = sample(p, n=600, seed=1)
    assert_normal_is_gradient(p, r)
    _, n = p.phi_and_normal(r)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)


def test_polygon_volumes():
    assert Polygon.from_edges(edges("EllipticDrop")).volume == pytest.approx(math.pi / 4, rel=1e-5)
    air = Polygon.from_edges(edges("AirFoilFluid"))
    solid = Polygon.from_edges(edges("AirFoilSolid"))
    assert len(air.loops) == 2
    assert air.volume == pytest.approx(80 * 30 - solid.volume, rel=1e-12)
    assert 0 < solid.volume < 20 * 3


def test_airfoil_hole_is_outside():
    air = Polygon.from_edges(edges("AirFoilFluid"))
    solid = Polygon.from_edges(edges("AirFoilSolid"))
    r = sample(solid, n=500, seed=2, spread=0.05)
    r = r[np.abs(solid.phi(r)) > 1e-6]
    np.testing.assert_allclose(air.phi(r), -solid.phi(r), atol=1e-12)


def test_polygon_hole_orientation_and_explicit_holes():
    outer = np.array([[0, 0], [4, 0], [4, 4], [0, 4.0]])
    hole = np.array([[1, 1], [3, 1], [3, 3], [1, 3.0]])
    a = Polygon([outer, hole])  # nesting makes the inner loop a hole
    b = Polygon([outer[::-1]], holes=[hole])  # orientation normalised
    assert a.volume == pytest.approx(12.0) and b.volume == pytest.approx(12.0)
    r = np.array([[2.0, 2.0], [0.5, 2.0], [5.0, 2.0]])
    np.testing.assert_allclose(a.phi(r), [1.0, -0.5, 1.0])
    np.testing.assert_allclose(b.phi(r), [1.0, -0.5, 1.0])
    # the hole normal points into the hole (out of the domain)
    _, n = a.phi_and_normal([[1.5, 2.0]])
    np.testing.assert_allclose(n[0], [1, 0, 0])
    with pytest.raises(ValueError, match="holes"):
        Polygon([hole], holes=[outer])


def test_sharp_wedge_gives_finite_phi_and_normal():
    t = math.radians(10.0)
    wedge = Polygon([[[0, 0], [1, 0], [math.cos(t), math.sin(t)]]])
    rng = np.random.default_rng(0)
    r = np.concatenate([rng.uniform(-0.5, 1.5, (500, 2)), rng.uniform(-1e-3, 1e-3, (100, 2)),
                        [[0.0, 0.0], [1e-12, 1e-13], [-1.0, 0.0]]])
    phi, n = wedge.phi_and_normal(r)
    assert np.all(np.isfinite(phi)) and np.all(np.isfinite(n))
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    assert wedge.phi([[-1.0, 0.0]])[0] == pytest.approx(1.0)
    assert wedge.phi([[0.5, 0.01]])[0] < 0
    assert_normal_is_gradient(wedge, np.concatenate([r[:500], np.zeros((500, 1))], axis=1))
    assert wedge.volume == pytest.approx(0.5 * math.sin(t))


def test_polygon_validation(tmp_path):
    with pytest.raises(ValueError, match=r"loops\[0\].*3"):
        Polygon([[[0, 0], [1, 0]]])
    with pytest.raises(ValueError, match=r"loops\[0\].*crosses itself"):
        Polygon([[[0, 0], [1, 1], [1, 0], [0, 1]]])  # bow tie
    with pytest.raises(ValueError, match="intersect"):
        Polygon([[[0, 0], [2, 0], [2, 2], [0, 2]], [[1, 1], [3, 1], [3, 3], [1, 3]]])
    open_file = tmp_path / "open.edges"
    open_file.write_text("0 0 1 0\n1 0 1 1\n1 1 0 1\n0 1 0 0.5\n")
    with pytest.raises(ValueError, match=r"^the boundary is not closed .*open\.edges: segment\(s\) \d+ \(line"):
        Polygon.from_edges(open_file)
    cross = tmp_path / "cross.edges"
    cross.write_text("0 0 1 1\n1 1 1 0\n1 0 0 1\n0 1 0 0\n")
    with pytest.raises(ValueError, match="crosses itself"):
        Polygon.from_edges(cross)


def test_from_edges_shuffled_and_reversed_segments(tmp_path):
    e = np.loadtxt(edges("Standford2DBunny"))
    rng = np.random.default_rng(0)
    e = e[rng.permutation(len(e))]
    flip = rng.random(len(e)) < 0.3
    e[flip] = e[flip][:, [2, 3, 0, 1]]
    path = tmp_path / "bunny.edges"
    np.savetxt(path, e)
    ref = Polygon.from_edges(edges("Standford2DBunny"))
    shuffled = Polygon.from_edges(path)
    assert shuffled.volume == pytest.approx(ref.volume, rel=1e-12)
    r = sample(ref, n=300)
    np.testing.assert_allclose(shuffled.phi(r), ref.phi(r), atol=1e-12)


# ---------------------------------------------------------------- tabulated
@pytest.mark.parametrize("name,dx", [("Standford2DBunny", 0.5), ("AirFoilFluid", 0.1)])
def test_tabulated_polygon_gradient_and_accuracy(name, dx):
    exact = Polygon.from_edges(edges(name))
    tab = Polygon.from_edges(edges(name), grid_spacing=dx)
    assert isinstance(exact.tabulated(dx), Tabulated)
    r = sample(exact, n=600, seed=4, spread=0.5)  # includes points beyond the grid
    assert_normal_is_gradient(tab, r)
    p_ex = exact.phi(r)
    p_tab = tab.phi(r)
    near = np.abs(p_ex) < 3 * dx
    # C1 cubic interpolation: sub-cell error near the boundary (kinks included)
    assert np.abs(p_tab - p_ex)[near].max() < 0.35 * dx
    assert np.median(np.abs(p_tab - p_ex)[near]) < 0.02 * dx
    # the sign (inside/outside) only differs within a fraction of a cell of the boundary
    assert np.all(np.abs(p_ex[np.sign(p_tab) != np.sign(p_ex)]) < 0.35 * dx)


def test_tabulated_circle_third_order():
    c = Circle((0.5, 0.5), 0.2)
    r = sample(c, n=500, seed=5)
    errs = [np.abs(c.tabulated(dx).phi(r) - c.phi(r))[np.abs(c.phi(r)) < 0.04].max()
            for dx in (0.02, 0.01)]
    assert errs[1] < errs[0] / 6  # O(dx^3) away from the centre kink


def test_tabulated_3d_sphere_gradient():
    s = Sphere((0, 0, 0), 1.0).tabulated(0.1)
    assert_normal_is_gradient(s, sample(s, n=300, spread=0.6))


# ---------------------------------------------------------------- CSG
def test_csg_annulus_phi_and_volume():
    ring = Circle((0, 0), 0.3) - Circle((0, 0), 0.2)  # Fan Appendix C
    assert isinstance(ring, Difference) and ring.dim == 2
    phi, n = ring.phi_and_normal([[0.27, 0.0], [0.0, 0.1], [0.0, -0.4], [0.0, 0.0]])
    np.testing.assert_allclose(phi, [-0.03, 0.1, 0.1, 0.2])
    np.testing.assert_allclose(n[:2, :2], [[1, 0], [0, -1]])
    assert ring.volume == pytest.approx(math.pi * (0.09 - 0.04), rel=1e-12)
    # the generic grid integral (used in 3D) agrees too
    from ase_sphrelax.domains.base import smoothed_volume

    assert smoothed_volume(ring, 1024) == pytest.approx(math.pi * 0.05, rel=1e-6)
    assert_normal_is_gradient(ring, sample(ring))


def test_csg_union_intersection():
    a, b = Box([0, 0], [2, 1]), Box([1, 0], [3, 1])
    u, i = a | b, a & b
    assert isinstance(u, Union) and isinstance(i, Intersection)
    assert u.volume == pytest.approx(3.0, rel=1e-12)  # exact (shapely) for polygonal operands
    assert i.volume == pytest.approx(1.0, rel=1e-12)
    r = np.array([[0.5, 0.5], [2.5, 0.5], [1.5, 0.5], [5, 0.5]])
    np.testing.assert_allclose(u.phi(r), np.minimum(a.phi(r), b.phi(r)))
    np.testing.assert_allclose(i.phi(r), np.maximum(a.phi(r), b.phi(r)))
    np.testing.assert_allclose(u.bounds[1], [3, 1])
    np.testing.assert_allclose(i.bounds[0], [1, 0])
    disc = Circle((1, 0.5), 0.4)
    assert (a & disc).volume == pytest.approx(disc.volume, rel=1e-5)  # grid integral
    assert_normal_is_gradient(u | disc, sample(u | disc))
    with pytest.raises(ValueError, match="dimensions"):
        a | Sphere((0, 0, 0), 1.0)


def test_csg_polygon_with_circle_hole_volume():
    tank = Polygon.from_edges(edges("TrapezoidalTank"))
    d = tank - Circle((0.5, 0.5), 0.25)
    assert d.volume == pytest.approx(1.25 - math.pi / 16, rel=1e-12)
    half = Box([0, 0], [1, 1]) & Circle((0.5, 0.0), 0.3)
    assert half.volume == pytest.approx(math.pi * 0.09 / 2, rel=1e-6)
    s = Sphere((0, 0, 0), 0.5) - Box([0, 0, 0], [1, 1, 1])  # sphere minus an octant
    assert s.volume == pytest.approx(7 / 8 * s.a.volume, rel=1e-5)


# ---------------------------------------------------------------- meshes
@pytest.fixture(scope="module")
def stl_files(tmp_path_factory):
    trimesh = pytest.importorskip("trimesh")
    d = tmp_path_factory.mktemp("stl")
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    box.export(d / "box.stl")
    ico.export(d / "ico.stl")
    open_mesh = trimesh.Trimesh(box.vertices, box.faces[:-1])
    open_mesh.export(d / "open.stl")
    return d, ico


def test_mesh_box_matches_box(stl_files):
    d, _ = stl_files
    m = Mesh(d / "box.stl")
    ref = Box([-0.5, -1, -1.5], [0.5, 1, 1.5])
    assert m.volume == pytest.approx(6.0)
    r = sample(ref, n=300)
    np.testing.assert_allclose(m.phi(r), ref.phi(r), atol=1e-12)
    assert_normal_is_gradient(m, r)


def test_mesh_icosphere(stl_files):
    d, ico = stl_files
    m = Mesh(d / "ico.stl")
    assert m.volume == pytest.approx(ico.volume)
    r = sample(m, n=200)
    assert_normal_is_gradient(m, r)
    phi = m.phi(r)
    # inscribed polyhedron: between the sphere and its inscribed radius
    s = Sphere((0, 0, 0), 1.0).phi(r)
    assert np.all(phi >= s - 1e-12)
    t = Mesh(ico, grid_spacing=0.1)
    assert_normal_is_gradient(t, r)


def test_mesh_rejects_open(stl_files):
    d, _ = stl_files
    with pytest.raises(ValueError, match="watertight"):
        Mesh(d / "open.stl")


def test_non_finite_positions_give_nan(stl_files):
    d, _ = stl_files
    doms = [Polygon.from_edges(edges("TrapezoidalTank")), Circle((0, 0), 1).tabulated(0.1),
            Mesh(d / "box.stl"), Sphere((0, 0, 0), 1.0).tabulated(0.2)]
    for dom in doms:
        phi, n = dom.phi_and_normal([[np.nan, 0.0, 0.0], [0.1, 0.1, 0.1]])
        assert np.isnan(phi[0]) and np.all(np.isnan(n[0, : dom.dim]))
        assert np.all(np.isfinite(phi[1:])) and np.all(np.isfinite(n[1:]))


# ---------------------------------------------------------------- public boundary elements
def check_segments(seg, domain, dim_scale=1.0):
    """Inward unit normals, closed loops, lengths and centroids consistent."""
    assert np.allclose(np.linalg.norm(seg.normal_sc, axis=1), 1.0)
    assert np.array_equal(seg.end_sc, seg.start_sc[seg.next_s])
    np.testing.assert_allclose(seg.length_s, np.linalg.norm(seg.end_sc - seg.start_sc, axis=1))
    np.testing.assert_allclose(seg.centroid_sc, 0.5 * (seg.start_sc + seg.end_sc))
    eps = 1e-6 * dim_scale
    assert np.all(domain.contains(seg.centroid_sc + eps * seg.normal_sc))
    assert not np.any(domain.contains(seg.centroid_sc - eps * seg.normal_sc))
    assert seg.area == pytest.approx(domain.volume, rel=1e-9)


@pytest.mark.parametrize("name", ["TrapezoidalTank", "Standford2DBunny", "AirFoilFluid"])
def test_polygon_segments_public(name):
    p = Polygon.from_edges(edges(name))
    seg = BoundarySegments.from_domain(p)
    assert len(seg) == p.n_segments
    check_segments(seg, p, dim_scale=float(np.ptp(np.concatenate(p.loops), axis=0).max()))


def test_box_and_csg_segments():
    box = Box([0, 0], [2, 1])
    check_segments(BoundarySegments.from_domain(box), box)
    wedge_hole = Polygon([np.array([[0.5, 0.2], [1.5, 0.2], [1.0, 0.8]])])
    d = box - wedge_hole
    seg = BoundarySegments.from_domain(d)
    assert len(seg.loops) == 2 and len(seg) == 7
    check_segments(seg, d)
    u = Box([0, 0], [1, 1]) | Box([0.5, 0.5], [2, 2])
    check_segments(BoundarySegments.from_domain(u), u)


def test_circle_has_no_segments_and_says_how():
    c = Circle((0, 0), 1.0)
    with pytest.raises(ValueError, match="to_polygon"):
        BoundarySegments.from_domain(c)
    assert not hasattr(c, "segments")
    with pytest.raises(ValueError, match="to_polygon"):
        BoundarySegments.from_domain(Box([-2, -2], [2, 2]) - c)
    p = c.to_polygon(64)
    assert p.volume == pytest.approx(0.5 * 64 * math.sin(2 * math.pi / 64))
    check_segments(BoundarySegments.from_domain(p), p)
    with pytest.raises(ValueError, match="icosphere|to_mesh"):
        BoundaryTriangles.from_domain(Sphere((0, 0, 0), 1.0))


def test_mesh_triangles_public(stl_files):
    d, ico = stl_files
    for path in (d / "box.stl", d / "ico.stl"):
        m = Mesh(path)
        tri = BoundaryTriangles.from_domain(m)
        assert tri.area_t.sum() == pytest.approx(m.trimesh.area)
        np.testing.assert_allclose(np.linalg.norm(tri.normal_tc, axis=1), 1.0)
        eps = 1e-7
        assert np.all(m.contains(tri.centroid_tc + eps * tri.normal_tc))
        assert not np.any(m.contains(tri.centroid_tc - eps * tri.normal_tc))
    box3 = BoundaryTriangles.from_domain(Box([0, 0, 0], [1, 2, 3]))
    assert len(box3) == 12 and box3.volume == pytest.approx(6.0)
    s = Sphere((1, 0, 0), 0.5).to_mesh(2)
    assert BoundaryTriangles.from_domain(s).volume == pytest.approx(s.volume) and len(BoundaryTriangles.from_domain(s)) == 320
