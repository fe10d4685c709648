"""reproductions/bipi-gamma-accuracy/run.py: its independent references hit known values and agree with gamma_and_gradient."""

import numpy as np
import pytest
from examples_loader import load_script

pytest.importorskip("shapely")
pytest.importorskip("trimesh")
pytest.importorskip("mpmath")
pytestmark = pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")


@pytest.fixture(scope="module")
def example():
    return load_script("reproductions/bipi-gamma-accuracy/run.py")


def test_references_known_values(example):
    assert example.check_references()["max_error"] < 1e-13


def test_graded_cuts_keep_order_and_ends(example):
    for cuts in ([0.0, 1.0], [0.0, -2.0, -3.0], [0.5, 0.7, 3.0]):
        out = example.graded(cuts)
        assert out[0] == cuts[0] and out[-1] == cuts[-1] and set(cuts) <= set(out)
        assert np.all(np.diff(out) * np.sign(cuts[-1] - cuts[0]) >= 0)


@pytest.mark.parametrize("offset", [1e-9, 1e-3])
def test_near_an_edge_both_references_agree_with_ours(example, offset):
    """A 2D point ``offset`` h outside the L's top edge and a 3D point ``offset`` h from a tetrahedron's edge."""
    import shapely

    from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles, gamma_and_gradient

    h = example.H
    poly = example.shapes_2d()["L (concave)"]
    x = np.array([0.967, 2.5 + offset])
    ref, _ = example.reference_2d(x, poly)
    seg = BoundarySegments.from_shapely(shapely.affinity.scale(poly, h, h, origin=(0, 0)))
    g, d = gamma_and_gradient(np.array([[x[0] * h, x[1] * h, 0.0]]), seg, h)
    assert abs(g[0] - ref[0]) < 1e-12 and np.abs(d[0, :2] * h - ref[1:]).max() < 1e-12

    mesh = example.shapes_3d()["tetrahedron"]
    unit = mesh.copy()
    unit.apply_scale(1.0 / h)
    a, b = unit.vertices[unit.face_adjacency_edges[0]]
    normal_sum = unit.face_normals[unit.face_adjacency[0]].sum(axis=0)
    x3 = a + 0.4 * (b - a) + offset * normal_sum / np.linalg.norm(normal_sum)  # outside, off the edge
    ref3, _ = example.reference_3d(x3, unit)
    g3, d3 = gamma_and_gradient(np.array([x3 * h]), BoundaryTriangles.from_trimesh(mesh), h)
    assert abs(g3[0] - ref3[0]) < 1e-12 and np.abs(d3[0] * h - ref3[1:]).max() < 1e-12
