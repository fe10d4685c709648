"""BIPI 3D (issue 17 item 6): the boundary integrals integrate each (particle, edge) once for both triangles of
the edge (``surface_integrals.triangle_row_terms``). Checked against the per-pair closed form
``triangle_terms`` (each triangle on its own, no sharing), pair by pair, near faces, edges and vertices, for
kernels of one and of several pieces, with periodic images; the exactness against an independent quadrature
is ``tests/test_gamma_3d_exact.py``."""
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.boundary import BoundaryTriangles, boundary_terms
from ase_sphrelax.boundary.radial import RadialTables
from ase_sphrelax.boundary.surface_integrals import edge_frames, edge_ids, triangle_terms
from ase_sphrelax.domains import Box, Sphere

H = 0.2
SPHERE = BoundaryTriangles.from_domain(Sphere((0.0, 0.0, 0.0), 0.5).to_mesh(2))


def per_pair(r_pc, tri, kernel):
    """gamma_k, grad_k of boundary_terms' pairs from triangle_terms, one triangle at a time."""
    out = boundary_terms(r_pc, tri, H, kernel=kernel)
    t = RadialTables(kernel, 3)
    frames = edge_frames(tri.packed_tk)
    cuts = np.empty(2 * t.breaks.shape[0] + 5)
    p = out.pairs
    gamma_k, grad_k = np.empty(p.n_pairs), np.empty(p.n_pairs)
    for k in range(p.n_pairs):
        x = p.x_sc[p.point_k[k]]
        gamma_k[k], grad_k[k], _ = triangle_terms(x[0], x[1], x[2], tri.packed_tk, tri.normal_tc, frames, p.element_k[k],
                                                  1.0 / H, t.breaks, t.lp, t.lq, t.a[0], t.p1_one, t.sigma, 1.0, cuts)
    return out, gamma_k, grad_k


def assert_same_terms(out, gamma_k, grad_k):
    # the same formulas summed in another order, d from |w| instead of delta^2 + e^2: rounding only
    np.testing.assert_allclose(out.gamma_k, gamma_k, rtol=0, atol=1e-14)
    np.testing.assert_allclose(out.grad_k * H, grad_k * H, rtol=0, atol=1e-13)


@pytest.mark.parametrize("kernel", ["wendland_c2", "cubic_spline", "wendland_c4"])
def test_shared_edges_equal_per_triangle_terms(kernel):
    rng = np.random.default_rng(7)
    r = rng.uniform(-0.55, 0.55, size=(400, 3))
    assert_same_terms(*per_pair(r, SPHERE, kernel))


@settings(max_examples=25, deadline=None, database=None, derandomize=True)
@given(vertex=st.integers(0, len(SPHERE.packed_tk) - 1), corner=st.integers(0, 2),
       scale=st.sampled_from([0.0, 1e-12, 1e-8, 1e-4, 1e-2, 0.3]), seed=st.integers(0, 2**16),
       on_edge=st.booleans())
def test_shared_edges_near_vertices_and_edges(vertex, corner, scale, seed, on_edge):
    """Points on and near a vertex, or on and near the middle of an edge (the other triangle of the edge reads it
    backwards), from 0 to 0.3 h away."""
    v_kc = SPHERE.packed_tk[vertex].reshape(3, 3)
    base = 0.5 * (v_kc[corner] + v_kc[(corner + 1) % 3]) if on_edge else v_kc[corner]
    offset = np.random.default_rng(seed).normal(size=(3, 3))
    r = base + scale * H * offset / np.linalg.norm(offset, axis=1)[:, None]
    assert_same_terms(*per_pair(r, SPHERE, "wendland_c2"))


def test_shared_edges_with_periodic_images():
    """A box periodic along x: the images of the triangles are edges of their own."""
    from ase_sphrelax.boundary.periodic import PeriodicFacesWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PeriodicFacesWarning)
        tri = BoundaryTriangles.from_domain(Box((0.0, 0.0, 0.0), (1.0, 0.6, 0.6))).with_cell([True, False, False])
    r = np.random.default_rng(3).uniform([0.0, 0.01, 0.01], [1.0, 0.59, 0.59], size=(300, 3))
    assert_same_terms(*per_pair(r, tri, "wendland_c2"))


def test_edge_ids_pair_the_triangles_of_every_edge():
    ids, n_edges = edge_ids(edge_frames(SPHERE.packed_tk))
    assert ids.shape == (len(SPHERE.packed_tk), 3)
    assert n_edges == 3 * len(SPHERE.packed_tk) // 2  # a closed mesh: every edge has two triangles
    np.testing.assert_array_equal(np.bincount(ids.ravel()), 2)
