"""Particle-boundary queries (issue 12 item 4): (particle, segment) and (particle, triangle) pairs
within a radius on the neighbour-search bins, against brute force."""
import math

import numpy as np
import pytest

from ase_sphrelax.boundary import BoundaryQuery, BoundarySegments, BoundaryTriangles, boundary_pairs
from ase_sphrelax.domains import Polygon
from ase_sphrelax.neighbors import NeighborList


def brute_segments(r_pc, seg, radius, shifts=((0.0, 0.0),)):
    """{(particle, segment): distance} by testing every pair (and every listed image shift)."""
    a, e = seg.start_sc, seg.end_sc - seg.start_sc
    out = {}
    for shift in shifts:
        p = r_pc[:, None, :2] + np.asarray(shift) - a[None]
        t = np.clip(np.einsum("psc,sc->ps", p, e) / np.einsum("sc,sc->s", e, e), 0.0, 1.0)
        d = np.linalg.norm(p - t[..., None] * e[None], axis=2)
        for i, s in zip(*np.nonzero(d < radius)):
            out[(int(i), int(s), tuple(shift))] = d[i, s]
    return out


def brute_triangles(r_pc, tri, radius):
    """{(particle, triangle): distance}, closest points by dense sampling-free projection (trimesh)."""
    import trimesh

    out = {}
    v = tri.vertices_tkc
    for t in range(len(v)):
        q = trimesh.triangles.closest_point(np.repeat(v[t:t + 1], len(r_pc), axis=0), r_pc)
        d = np.linalg.norm(q - r_pc, axis=1)
        for i in np.nonzero(d < radius)[0]:
            out[(int(i), t)] = d[i]
    return out


def scatter(bounds, n, rng, dim=2, spread=0.2):
    lo, hi = bounds
    ext = hi - lo
    r = np.zeros((n, 3))
    r[:, :dim] = lo - spread * ext + (1 + 2 * spread) * ext * rng.random((n, dim))
    return r


def got_pairs(bp):
    return {(int(p), int(e)): d for p, e, d in zip(bp.particle_k, bp.element_k, bp.distance_k)}


def check_against_brute(bp, ref):
    got = got_pairs(bp)
    ref2 = {(i, s): d for (i, s, *_), d in ref.items()}
    assert got.keys() == ref2.keys()
    np.testing.assert_allclose([got[k] for k in ref2], [ref2[k] for k in ref2], rtol=0, atol=1e-12)
    # CSR rows are per particle
    assert np.all(np.diff(bp.start_p) >= 0) and bp.start_p[-1] == bp.n_pairs
    assert np.all(bp.particle_k[np.argsort(bp.particle_k, kind="stable")] == bp.particle_k)


def wedge(degrees):
    t = math.radians(degrees)
    return BoundarySegments.from_vertices([[0.0, 0.0], [1.0, 0.0], [math.cos(t), math.sin(t)]])


def square_with_holes():
    outer = np.array([[0, 0], [4, 0], [4, 4], [0, 4.0]])
    holes = [np.array([[1, 1], [1.6, 1], [1.6, 1.6], [1, 1.6]]), np.array([[2.5, 2.5], [3.5, 2.5], [3, 3.4]])]
    return BoundarySegments.from_vertices([outer], holes=holes)


@pytest.mark.parametrize("radius", [0.05, 0.3])
def test_segments_against_brute_force_wedge_and_holes(radius):
    rng = np.random.default_rng(1)
    for seg in (wedge(10.0), square_with_holes()):
        r = scatter(seg.bounds, 3000, rng)
        # particles on vertices and on segments too
        r[:len(seg)] = np.column_stack([seg.start_sc, np.zeros(len(seg))])
        r[len(seg):2 * len(seg)] = np.column_stack([seg.centroid_sc, np.zeros(len(seg))])
        check_against_brute(boundary_pairs(r, seg, radius), brute_segments(r, seg, radius))


@pytest.mark.parametrize("name,radius", [("TrapezoidalTank", 0.04), ("Standford2DBunny", 2.0), ("AirFoilFluid", 0.5),
                                         ("AirFoilSolid", 0.2)])
def test_segments_against_brute_force_geometries(geometries, name, radius):
    seg = BoundarySegments.from_domain(Polygon.from_edges(geometries / f"{name}.edges"))
    rng = np.random.default_rng(2)
    r = scatter(seg.bounds, 4000, rng, spread=0.02)
    if name == "AirFoilFluid":  # most of the box is far from the airfoil: sample near it too
        air = BoundarySegments.from_domain(Polygon.from_edges(geometries / "AirFoilSolid.edges"))
        r = np.concatenate([r, scatter(air.bounds, 4000, rng, spread=0.1)])
    check_against_brute(boundary_pairs(r, seg, radius), brute_segments(r, seg, radius))


def test_refined_segments_against_brute_force(geometries):
    seg = BoundarySegments.from_domain(Polygon.from_edges(geometries / "TrapezoidalTank.edges")).refine(dx=0.02)
    assert seg.length_s.max() <= 0.002 + 1e-15 and len(seg) > 2000
    rng = np.random.default_rng(3)
    r = scatter(seg.bounds, 3000, rng, spread=0.05)
    check_against_brute(boundary_pairs(r, seg, 0.04), brute_segments(r, seg, 0.04))


def test_periodic_images():
    seg = BoundarySegments.from_vertices([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]])
    rng = np.random.default_rng(4)
    r = np.zeros((2000, 3))
    r[:, :2] = rng.random((2000, 2))
    bp = boundary_pairs(r, seg, 0.3, cell=np.eye(3), pbc=(True, True, False))
    shifts = [(sx, sy) for sx in (-1, 0, 1) for sy in (-1, 0, 1)]
    ref = brute_segments(r, seg, 0.3, shifts)
    assert bp.n_pairs == len(ref)
    # the pair's extended point is the image that is close
    x_k = bp.x_sc[bp.point_k, :2]
    d = [min(np.linalg.norm(x - q) for q in (seg.start_sc[e], seg.end_sc[e])) for x, e in zip(x_k, bp.element_k)]
    assert np.all(bp.distance_k <= np.array(d) + 1e-12)
    got = sorted(bp.distance_k)
    np.testing.assert_allclose(got, sorted(ref.values()), atol=1e-12)


def test_stored_list_reuse_and_rebuild(geometries):
    """Particles moving within half the skin reuse the registration and stay exact; larger moves rebuild."""
    seg = BoundarySegments.from_domain(Polygon.from_edges(geometries / "Standford2DBunny.edges"))
    rng = np.random.default_rng(5)
    r = scatter(seg.bounds, 3000, rng, spread=0.02)
    nlist = NeighborList(2.0, skin=1.0)
    query = BoundaryQuery(seg)
    cell, pbc = np.zeros((3, 3)), False
    for it in range(3):
        nlist.update(r, cell, pbc, store=True)
        bp = query.pairs(nlist, r, 2.0)
        check_against_brute(bp, brute_segments(r, seg, 2.0))
        step = rng.normal(size=r.shape)
        step[:, 2] = 0
        step *= 0.45 * 0.5 / np.linalg.norm(step, axis=1).max()  # < skin / 2
        r = r + step
    assert nlist.builds == 1 and query.registrations == 1
    r = r + np.array([0.8, 0.0, 0.0])  # beyond the skin: new bins, new registration
    nlist.update(r, cell, pbc, store=True)
    bp = query.pairs(nlist, r, 2.0)
    check_against_brute(bp, brute_segments(r, seg, 2.0))
    assert nlist.builds == 2 and query.registrations == 2


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    trimesh = pytest.importorskip("trimesh")
    d = tmp_path_factory.mktemp("stl")
    trimesh.creation.box(extents=(1.0, 2.0, 3.0)).export(d / "box.stl")
    trimesh.creation.icosphere(subdivisions=3, radius=1.0).export(d / "ico.stl")
    return d


@pytest.mark.parametrize("name,radius", [("box.stl", 0.3), ("ico.stl", 0.15)])
def test_triangles_against_brute_force(meshes, name, radius):
    tri = BoundaryTriangles.from_file(meshes / name)
    rng = np.random.default_rng(6)
    r = scatter(tri.bounds, 1500, rng, dim=3, spread=0.1)
    r[:len(tri)][:300] = tri.centroid_tc[:300]
    got = boundary_pairs(r, tri, radius)
    check_against_brute(got, brute_triangles(r, tri, radius))


def test_query_cost_is_local(geometries):
    """Particles far from the boundary test no element: the work grows with the boundary layer only."""
    seg = BoundarySegments.from_domain(Polygon.from_edges(geometries / "TrapezoidalTank.edges")).refine(dx=0.01)
    rng = np.random.default_rng(7)
    r = np.zeros((20000, 3))
    r[:, :2] = [0.2, 0.2] + 0.6 * rng.random((20000, 2))  # all at least 0.2 from the walls
    bp = boundary_pairs(r, seg, 0.04)
    assert bp.n_pairs == 0
    query = BoundaryQuery(seg)
    nlist = NeighborList(0.04)
    nlist.update(r, np.zeros((3, 3)), False, store=False)
    query.pairs(nlist, r, 0.04)
    start, _ = query._reg
    # the bins of interior particles hold no element
    assert np.all(start[nlist.points.bin_s + 1] - start[nlist.points.bin_s] == 0)
