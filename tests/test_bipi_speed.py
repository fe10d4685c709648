"""BIPI 3D speed-ups (issue 17 item 6) change no value: the particle-triangle query that keeps its
candidates while the bins stay gives the pairs of a fresh query bit for bit, the per-edge frames are
shared by the two triangles of every edge, and the packer's momentum is off by default."""
import numpy as np
import pytest

from ase_sphrelax.boundary import BoundaryIntegrals, BoundaryQuery, BoundaryTriangles, boundary_pairs
from ase_sphrelax.boundary.surface_integrals import edge_frames
from ase_sphrelax.domains import Box
from ase_sphrelax.neighbors import NeighborList
from bipi_meshes import H, SKIN, cloud, sphere


def same_pairs(got, ref):
    """Identical CSR rows: elements in the same order, distances to the bit."""
    np.testing.assert_array_equal(got.start_p, ref.start_p)
    np.testing.assert_array_equal(got.element_k, ref.element_k)
    np.testing.assert_array_equal(got.distance_k, ref.distance_k)


@pytest.mark.parametrize("seed", [0, 1])
def test_stored_query_equals_fresh_query(seed):
    """Moves below half the skin reuse the candidates (one candidate build) and give the pairs of a fresh
    one-shot query at the new positions; a larger move rebuilds the bins and the candidates."""
    rng = np.random.default_rng(seed)
    tri = sphere()
    r = cloud(400, rng)
    nlist = NeighborList(H, skin=SKIN)
    query = BoundaryQuery(tri)
    nlist.update(r, np.zeros((3, 3)), [False] * 3, store=True)
    for _ in range(6):
        step = rng.normal(size=r.shape)
        step *= 0.49 * 0.5 * SKIN / np.linalg.norm(step, axis=1).max()  # < skin / 2 from the build
        moved = r + step
        assert not nlist.update(moved, np.zeros((3, 3)), [False] * 3, store=True)
        same_pairs(query.pairs(nlist, moved, H), boundary_pairs(moved, tri, H))
    assert query.candidate_builds == 1
    far = r + np.array([0.6 * SKIN, 0.0, 0.0])
    assert nlist.update(far, np.zeros((3, 3)), [False] * 3, store=True)
    same_pairs(query.pairs(nlist, far, H), boundary_pairs(far, tri, H))
    assert query.candidate_builds == 2


def test_stored_query_with_periodic_images():
    """A box periodic along x: the stored query finds the pairs (triangle or image) a fresh one finds."""
    import warnings

    from ase_sphrelax.boundary.periodic import PeriodicFacesWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PeriodicFacesWarning)
        tri = BoundaryTriangles.from_domain(Box((0.0, 0.0, 0.0), (1.0, 0.6, 0.6))).with_cell([True, False, False])
    rng = np.random.default_rng(3)
    r = rng.uniform([0.0, 0.01, 0.01], [1.0, 0.59, 0.59], size=(300, 3))
    nlist = NeighborList(H, skin=SKIN)
    query = BoundaryQuery(tri)
    nlist.update(r, tri.cell, tri.pbc, store=True)
    for _ in range(3):
        moved = r + rng.uniform(-0.2 * SKIN, 0.2 * SKIN, size=r.shape)
        nlist.update(moved, tri.cell, tri.pbc, store=True)
        got, ref = query.pairs(nlist, moved, H), boundary_pairs(moved, tri, H)
        # a particle that left the cell since the build meets the images of the triangles the fresh query (which
        # wraps it) meets: the same distances, up to the rounding of the translated triangles
        np.testing.assert_array_equal(got.start_p, ref.start_p)
        for p in range(len(moved)):
            rows = slice(got.start_p[p], got.start_p[p + 1])
            np.testing.assert_allclose(np.sort(got.distance_k[rows]), np.sort(ref.distance_k[rows]), rtol=0, atol=1e-14)
    assert query.candidate_builds == 1


def test_integrals_with_stored_query_equal_one_shot():
    """gamma, grad gamma and the band sum through a stored list equal the one-shot evaluation to the bit."""
    rng = np.random.default_rng(5)
    tri = sphere()
    r = cloud(300, rng, scale=0.5)
    integrals = BoundaryIntegrals(tri, H)
    nlist = NeighborList(H, skin=SKIN)
    nlist.update(r, np.zeros((3, 3)), [False] * 3, store=True)
    integrals.compute(nlist, r, band=0.025)
    moved = r + 0.1 * SKIN * rng.normal(size=r.shape) / 3
    nlist.update(moved, np.zeros((3, 3)), [False] * 3, store=True)
    got = integrals.compute(nlist, moved, band=0.025)
    fresh = BoundaryIntegrals(tri, H)
    one = NeighborList(H)
    one.update(moved, np.zeros((3, 3)), [False] * 3, store=False)
    ref = fresh.compute(one, moved, band=0.025)
    np.testing.assert_array_equal(got.gamma_p, ref.gamma_p)
    np.testing.assert_array_equal(got.grad_gamma_pc, ref.grad_gamma_pc)
    np.testing.assert_array_equal(got.near_pc, ref.near_pc)


def test_edge_frames_shared_by_both_triangles_of_an_edge():
    """The canonical frame of an edge (end points, unit direction) is the same bits from both triangles,
    which the exactness near edge lines rests on; ``u`` and ``m`` are unit along the edge and normal to it."""
    tri = sphere()
    frames = edge_frames(tri.packed_tk)
    seen = {}
    for t in range(len(tri.packed_tk)):
        for i in range(3):
            f = frames[t, i]
            key = (tuple(f[0:3]), tuple(f[3:6]))
            if key in seen:
                np.testing.assert_array_equal(seen[key], f[6:9])
            else:
                seen[key] = f[6:9].copy()
            assert abs(np.linalg.norm(f[9:12]) - 1.0) < 1e-15
            assert abs(np.dot(f[9:12], f[12:15])) < 1e-15 * f[15] + 1e-17
            assert f[15] > 0.0
    assert len(seen) == 3 * len(tri.packed_tk) // 2  # every edge met from both sides


def test_packer_momentum_checked_and_off_by_default():
    from ase_sphrelax import BIPICalculator
    from ase_sphrelax.drivers.bipi_packer import BIPIPacker, initial_fill

    tri = sphere()
    atoms = initial_fill(tri, 0.1)
    calc = BIPICalculator(h=4 * 0.1, dx=0.1, boundary=tri)
    assert BIPIPacker(atoms, calc).momentum == 0.0
    with pytest.raises(ValueError, match="momentum"):
        BIPIPacker(atoms, calc, momentum=1.0)
    with pytest.raises(ValueError, match="momentum_stages"):
        BIPIPacker(atoms, calc, momentum=0.5, momentum_stages=("2b",))


def test_momentum_zero_is_the_paper_rule_and_momentum_moves_only_its_stages():
    """momentum=0 gives the default trajectory to the bit; with momentum in Step 2c only, Step 2a (and the
    frozen layer) is the paper's to the bit and 2c differs."""
    from ase_sphrelax.drivers.bipi_packer import pack

    tri = sphere()
    kw = dict(h_over_dx_paper=2.0, max_steps_2a=6, max_steps_2c=6)
    ref, p_ref, _ = pack(tri, 0.1, **kw)
    zero, _, _ = pack(tri, 0.1, momentum=0.0, **kw)
    np.testing.assert_array_equal(zero.positions, ref.positions)
    heavy, p_heavy, _ = pack(tri, 0.1, momentum=0.9, **kw)
    np.testing.assert_array_equal(p_heavy.frozen, p_ref.frozen)
    np.testing.assert_array_equal(heavy.positions[p_ref.frozen], ref.positions[p_ref.frozen])
    rows = [r["gradc_avg"] for r in p_ref.history if r["stage"] == "2a"]
    assert rows == [r["gradc_avg"] for r in p_heavy.history if r["stage"] == "2a"]
    assert not np.array_equal(heavy.positions, ref.positions)
