"""BoundarySegments / BoundaryTriangles (issue 7 item 1): sources, orientation checks, refinement, errors."""
import math
import warnings

import numpy as np
import pytest

from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles, OrientationWarning
from ase_sphrelax.domains import Box, Circle, Polygon


def write(tmp_path, name, rows):
    path = tmp_path / name
    np.savetxt(path, np.asarray(rows, dtype=float))
    return path


SQUARE = [[0, 0, 1, 0], [1, 0, 1, 1], [1, 1, 0, 1], [0, 1, 0, 0]]


@pytest.mark.parametrize("name", ["TrapezoidalTank", "Standford2DBunny", "AirFoilSolid", "AirFoilFluid",
                                  "EllipticDrop"])
def test_geometry_files_load_without_warnings(geometries, name):
    path = geometries / f"{name}.edges"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        seg = BoundarySegments.from_edges(path)
    raw = np.loadtxt(path)
    assert len(seg) == len(raw)  # every file segment kept (no merging), in file order per loop
    assert sorted(seg.source_s.tolist()) == list(range(len(raw)))
    np.testing.assert_array_equal(seg.start_sc, raw[seg.source_s, :2])
    np.testing.assert_array_equal(seg.end_sc, raw[seg.source_s, 2:])
    poly = Polygon.from_edges(path)
    assert seg.area == pytest.approx(poly.volume, rel=1e-12)
    eps = 1e-7 * float(np.ptp(raw, axis=0).max())
    assert np.all(poly.contains(seg.centroid_sc + eps * seg.normal_sc))


def test_from_polygon_keeps_holes(geometries):
    poly = Polygon.from_edges(geometries / "AirFoilFluid.edges")
    seg = BoundarySegments.from_polygon(poly)
    assert len(seg.loops) == 2
    # the hole's normals point out of the airfoil, into the fluid
    hole = seg.loop_s == np.argmin([abs(BoundarySegments([v]).area) for v in seg.loops])
    solid = Polygon.from_edges(geometries / "AirFoilSolid.edges")
    assert not np.any(solid.contains(seg.centroid_sc[hole] + 1e-6 * seg.normal_sc[hole]))
    assert np.all(solid.contains(seg.centroid_sc[hole] - 1e-6 * seg.normal_sc[hole]))


def test_clockwise_loop_is_reversed_with_warning(tmp_path):
    cw = write(tmp_path, "cw.edges", [[0, 0, 0, 1], [0, 1, 1, 1], [1, 1, 1, 0], [1, 0, 0, 0]])
    with pytest.warns(OrientationWarning, match="clockwise.*outer boundary.*reversed"):
        seg = BoundarySegments.from_edges(cw)
    assert seg.area == pytest.approx(1.0)
    np.testing.assert_allclose(seg.normal_sc @ [0, 1] + seg.normal_sc @ [1, 0] != 0, True)
    assert np.all(Box([0, 0], [1, 1]).contains(seg.centroid_sc + 1e-6 * seg.normal_sc))
    # source indices follow the reversal: segment s of the result is file line source_s[s]
    raw = np.loadtxt(cw)
    np.testing.assert_array_equal(seg.start_sc, raw[seg.source_s, 2:])
    # a hole that runs counter-clockwise
    rows = SQUARE + [[0.2, 0.2, 0.4, 0.2], [0.4, 0.2, 0.4, 0.4], [0.4, 0.4, 0.2, 0.4], [0.2, 0.4, 0.2, 0.2]]
    with pytest.warns(OrientationWarning, match="hole"):
        seg = BoundarySegments.from_edges(write(tmp_path, "hole.edges", rows))
    assert seg.area == pytest.approx(1.0 - 0.04)


def test_edge_file_errors_name_file_and_segment(tmp_path):
    f = write(tmp_path, "open.edges", [[0, 0, 1, 0], [1, 0, 1, 1], [1, 1, 0, 1], [0, 1, 0, 0.5]])
    with pytest.raises(ValueError, match=r"open\.edges.*segment\(s\) (0|3)\b.*|not closed.*open\.edges"):
        BoundarySegments.from_edges(f)
    f = write(tmp_path, "zero.edges", SQUARE[:2] + [[1, 1, 1, 1]] + SQUARE[2:])
    with pytest.raises(ValueError, match=r"zero\.edges: segment 2 .*zero length"):
        BoundarySegments.from_edges(f)
    f = write(tmp_path, "cross.edges", [[0, 0, 1, 1], [1, 1, 1, 0], [1, 0, 0, 1], [0, 1, 0, 0]])
    with pytest.raises(ValueError, match=r"cross\.edges: segments 0 and 2 cross"):
        BoundarySegments.from_edges(f)
    f = write(tmp_path, "mixed.edges", [SQUARE[0], SQUARE[1], [0, 1, 1, 1], SQUARE[3]])
    with pytest.raises(ValueError, match=r"mixed\.edges: segments 0 and 2 .*opposite directions.*ambiguous"):
        BoundarySegments.from_edges(f)
    # Polygon.from_edges orients by nesting and accepts the mixed file
    assert BoundarySegments.from_domain(Polygon.from_edges(f)).area == pytest.approx(1.0)
    f = write(tmp_path, "branch.edges", SQUARE + [[0, 0, 0.5, 0.5], [0.5, 0.5, 1, 1]])
    with pytest.raises(ValueError, match=r"branches.*branch\.edges"):
        BoundarySegments.from_edges(f)
    (tmp_path / "bad.edges").write_text("0 0 1\n1 0 1 1\n")
    with pytest.raises(ValueError, match=r"bad\.edges: line 1: expected 4 numbers 'x1 y1 x2 y2'"):
        BoundarySegments.from_edges(tmp_path / "bad.edges")
    with pytest.raises(ValueError, match="cannot read"):
        BoundarySegments.from_edges(tmp_path / "missing.edges")
    # two loops crossing each other
    rows = SQUARE + [[0.5, 0.5, 1.5, 0.5], [1.5, 0.5, 1.5, 1.5], [1.5, 1.5, 0.5, 1.5], [0.5, 1.5, 0.5, 0.5]]
    with pytest.raises(ValueError, match=r"two\.edges: segments \d and \d cross"):
        BoundarySegments.from_edges(write(tmp_path, "two.edges", rows))


def test_vertex_loops_errors_and_orientation():
    with pytest.raises(ValueError, match="loop 0.*3 distinct"):
        BoundarySegments.from_vertices([[0, 0], [1, 0]])
    with pytest.raises(ValueError, match="loop 0: segment 1 has zero length"):
        BoundarySegments.from_vertices([[0, 0], [1, 0], [1, 0], [0, 1]])
    with pytest.raises(ValueError, match="segments 0 and 2 cross"):
        BoundarySegments.from_vertices([[0, 0], [1, 1], [1, 0], [0, 1]])
    with pytest.raises(ValueError, match="non-finite"):
        BoundarySegments.from_vertices([[0, 0], [1, np.nan], [0, 1]])
    with pytest.warns(OrientationWarning):
        seg = BoundarySegments.from_vertices([[0, 0], [0, 1], [1, 0]])
    assert seg.area == pytest.approx(0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # explicit holes are oriented silently
        seg = BoundarySegments.from_vertices([[0, 0], [4, 0], [4, 4], [0, 4]], holes=[[[1, 1], [2, 1], [2, 2]]])
    assert seg.area == pytest.approx(16 - 0.5)
    with pytest.raises(ValueError, match="not inside an outer loop"):
        BoundarySegments.from_vertices([[0, 0], [1, 0], [0, 1]], holes=[[[5, 5], [6, 5], [5, 6]]])


def test_from_domain_dispatch_and_errors():
    assert len(BoundarySegments.from_domain(Box([0, 0], [1, 1]))) == 4
    with pytest.raises(ValueError, match="to_polygon"):
        BoundarySegments.from_domain(Circle((0, 0), 1))
    with pytest.raises(ValueError, match="3D"):
        BoundarySegments.from_domain(Box([0, 0, 0], [1, 1, 1]))
    with pytest.raises(TypeError, match="accepted"):
        BoundarySegments.from_domain("trapezoid")
    with pytest.raises(ValueError, match="2D"):
        BoundaryTriangles.from_domain(Box([0, 0], [1, 1]))


def test_refine_splits_to_ratio(geometries):
    seg = BoundarySegments.from_edges(geometries / "TrapezoidalTank.edges")
    fine = seg.refine(dx=0.02)  # BIPI2D's edge_to_dx_ratio = 10: dx_s <= 0.002
    assert fine.length_s.max() <= 0.002 * (1 + 1e-12)
    assert fine.length_s.sum() == pytest.approx(seg.length_s.sum(), rel=1e-14)
    assert fine.area == pytest.approx(seg.area, rel=1e-13)
    np.testing.assert_array_equal(np.unique(fine.source_s), np.arange(4))
    assert np.array_equal(fine.end_sc, fine.start_sc[fine.next_s])
    coarse = seg.refine(dx=0.02, ratio=1.5)
    assert 0.02 / coarse.length_s.max() >= 1.5 * (1 - 1e-12)
    with pytest.raises(ValueError, match="max_length or dx"):
        seg.refine()
    with pytest.raises(ValueError, match="ratio"):
        seg.refine(dx=0.1, ratio=0)


def test_triangles_sources_and_refine(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    ico = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    ico.export(tmp_path / "ico.stl")
    tri = BoundaryTriangles.from_file(tmp_path / "ico.stl")
    assert len(tri) == 80
    fine = tri.refine(max_edge=0.2)
    edges = np.linalg.norm(fine.vertices_tkc - np.roll(fine.vertices_tkc, 1, axis=1), axis=2)
    assert edges.max() <= 0.2 and fine.volume == pytest.approx(tri.volume, rel=1e-12)
    assert np.all(fine.contains(fine.centroid_tc + 1e-7 * fine.normal_tc))
    inverted = ico.copy()
    inverted.invert()
    assert BoundaryTriangles.from_trimesh(inverted).volume == pytest.approx(ico.volume)
    open_mesh = trimesh.Trimesh(ico.vertices, ico.faces[:-1])
    with pytest.raises(ValueError, match="watertight"):
        BoundaryTriangles.from_trimesh(open_mesh)
    with pytest.raises(ValueError, match="cannot read"):
        BoundaryTriangles.from_file(tmp_path / "missing.stl")
    assert math.isclose(tri.area_t.sum(), ico.area, rel_tol=1e-6)  # STL stores float32
