"""BIPI 3D memory (issue 33 item 4) changes no value: the particle-triangle query fused into the boundary rows
(``keep_pairs=False``, no pair arrays) gives the terms of the pair path bit for bit, on one-shot bins, a stored
list and a periodic boundary; particles far from the walls keep their inside test on one-shot bins; and a
BIPICalculator without a stored list (``store_list=False``) gives the trajectory of the stored one to rounding."""
import warnings

import numpy as np
import pytest

from ase_sphrelax import BIPICalculator, BIPIPacker
from ase_sphrelax.boundary import BoundaryIntegrals, BoundaryTriangles
from ase_sphrelax.domains import Box, Sphere
from ase_sphrelax.drivers.bipi_packer import initial_fill
from ase_sphrelax.neighbors import NeighborList
from bipi_meshes import H, SKIN, cloud, sphere


def same_terms(got, ref):
    for name in ("gamma_p", "grad_gamma_pc", "chi_p", "near_pc"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    np.testing.assert_array_equal(got.nearest_p, ref.pairs.nearest_distance())


@pytest.mark.parametrize("store", [False, True])
def test_fused_query_equals_pair_path(store):
    """keep_pairs=False: no pairs, and gamma, grad gamma, chi, the band sum and the nearest distance of the
    pair path to the bit, over moves that keep a stored list (its candidates) and one that rebuilds it."""
    rng = np.random.default_rng(7)
    tri = sphere()
    r = cloud(500, rng)
    fused, paired = BoundaryIntegrals(tri, H), BoundaryIntegrals(tri, H)
    nl_f, nl_p = NeighborList(H, skin=SKIN), NeighborList(H, skin=SKIN)
    for k in range(4):
        r = r + (0.2 if k < 3 else 2.0) * SKIN * rng.uniform(-1.0, 1.0, size=r.shape) / 3 ** 0.5
        for nl in (nl_f, nl_p):
            nl.update(r, np.zeros((3, 3)), [False] * 3, store=store)
        got = fused.compute(nl_f, r, band=0.025, keep_pairs=False)
        ref = paired.compute(nl_p, r, band=0.025)
        assert got.pairs is None and ref.pairs.n_pairs > 0
        assert np.isfinite(got.nearest_p).any() and np.isinf(got.nearest_p).any()  # near and far particles
        same_terms(got, ref)


def test_fused_query_with_periodic_images():
    """A box periodic along x: the particles meet the triangles' images, their ghosts are skipped, as in the
    pair path."""
    from ase_sphrelax.boundary.periodic import PeriodicFacesWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PeriodicFacesWarning)
        tri = BoundaryTriangles.from_domain(Box((0.0, 0.0, 0.0), (1.0, 0.6, 0.6))).with_cell([True, False, False])
    rng = np.random.default_rng(3)
    r = rng.uniform([0.0, 0.01, 0.01], [1.0, 0.59, 0.59], size=(300, 3))
    for store in (False, True):
        nl_f, nl_p = NeighborList(H, skin=SKIN), NeighborList(H, skin=SKIN)
        for nl in (nl_f, nl_p):
            nl.update(r, tri.cell, tri.pbc, store=store)
        assert nl_f.points.n_extended > len(r)  # ghosts exist
        got = BoundaryIntegrals(tri, H).compute(nl_f, r, band=0.025, keep_pairs=False)
        same_terms(got, BoundaryIntegrals(tri, H).compute(nl_p, r, band=0.025))


def test_one_shot_bins_keep_the_inside_test_of_far_particles():
    """On one-shot bins (a new grid per call), particles farther than h from the surface that moved less than h
    keep their chi: no inside test after the first call, and the chi of a fresh evaluation; a particle moved
    across the surface (more than h) is tested again."""
    rng = np.random.default_rng(11)
    tri = sphere()
    r = cloud(400, rng, scale=0.7)  # inside and outside
    integrals = BoundaryIntegrals(tri, H)
    nl = NeighborList(H)
    nl.update(r, np.zeros((3, 3)), [False] * 3, store=False)
    first = integrals.compute(nl, r, keep_pairs=False)
    assert integrals.inside_tests == 1 and (first.chi_p == 0.0).any() and (first.chi_p == 1.0).any()
    moved = r + 0.3 * H * rng.uniform(-1.0, 1.0, size=r.shape) / 3 ** 0.5
    nl.update(moved, np.zeros((3, 3)), [False] * 3, store=False)
    got = integrals.compute(nl, moved, keep_pairs=False)
    assert integrals.inside_tests == 1
    fresh_nl = NeighborList(H)
    fresh_nl.update(moved, np.zeros((3, 3)), [False] * 3, store=False)
    np.testing.assert_array_equal(got.chi_p, BoundaryIntegrals(tri, H).compute(fresh_nl, moved).chi_p)
    far_in = np.nonzero((got.chi_p == 1.0) & np.isinf(got.nearest_p))[0][0]
    jumped = moved.copy()
    jumped[far_in] = [3.0, 3.0, 3.0]  # far outside: must not keep chi = 1
    nl.update(jumped, np.zeros((3, 3)), [False] * 3, store=False)
    out = integrals.compute(nl, jumped, keep_pairs=False)
    assert integrals.inside_tests == 2 and out.chi_p[far_in] == 0.0 and out.gamma_p[far_in] == 0.0


def _pack(store_list, steps=4):
    tri = BoundaryTriangles.from_domain(Sphere((0.0, 0.0, 0.0), 0.3).to_mesh(2))
    dx = 0.05
    atoms = initial_fill(tri, dx)
    calc = BIPICalculator.from_paper(2.0, dx, tri, store_list=store_list)
    packer = BIPIPacker(atoms, calc, stages=("2b", "2c"), max_steps_2c=steps, window=10**9)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in packer.irun():
            pass
    return atoms.positions, calc


def test_calculator_without_stored_list_gives_the_same_trajectory():
    """store_list=False: no list is ever stored, and Step 2c moves the particles as with the list (the pair sums
    in another order: rounding only)."""
    ref, calc_ref = _pack(True)
    got, calc = _pack(False)
    assert calc_ref.nlist.stored and not calc.nlist.stored
    assert calc.boundary_distances().shape == (len(got),)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="store_list must be True, False or None"):
        BIPICalculator.from_paper(2.0, 0.05, calc.boundary, store_list="no")


def test_the_default_keeps_no_list_in_3d():
    """store_list=None (the default): one-shot bins in 3D (the list alone is about 630 B per particle at
    h = 4 dx, issue 33's goal 900 B), the trajectory of store_list=False bit for bit."""
    got, calc = _pack(None)
    ref, _ = _pack(False)
    assert calc.parameters.store_list is None and not calc.nlist.stored
    np.testing.assert_array_equal(got, ref)


def _star_segments():
    """A star polygon: sharp convex tips and concave corners, segments of unequal length."""
    from ase_sphrelax.boundary import BoundarySegments

    angle = np.linspace(0.0, 2.0 * np.pi, 14, endpoint=False)
    radius = np.where(np.arange(14) % 2 == 0, 0.5, 0.22)
    loop = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)
    return BoundarySegments.from_vertices([loop])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("store", [False, True])
def test_row_blocks_change_no_value(dim, store):
    """The boundary rows are computed a block of particles per call (``block_rows``, BLOCK_ROWS by default): one row
    per call, a few, and blocks cut by the scratch's room instead of the row count give every output bit for bit,
    in the fused query and in the pair path (with the per-pair terms)."""
    rng = np.random.default_rng(5)
    if dim == 3:
        boundary, r = sphere(), cloud(700, rng)
    else:
        boundary = _star_segments()
        r = np.zeros((900, 3))
        r[:, :2] = rng.uniform(-0.55, 0.55, size=(900, 2))
    nl = NeighborList(H, skin=SKIN)
    nl.update(r, np.zeros((3, 3)), [False] * 3, store=store)

    def outputs(block_rows, keep_pairs):
        integrals = BoundaryIntegrals(boundary, H)
        integrals.block_rows = block_rows
        got = integrals.compute(nl, r, band=0.025, terms=keep_pairs, keep_pairs=keep_pairs)
        names = ["gamma_p", "grad_gamma_pc", "chi_p", "near_pc", "nearest_p"]
        names += ["gamma_k", "grad_k", "delta_k"] if keep_pairs else []
        return {name: getattr(got, name) for name in names}

    for keep_pairs in (False, True):
        ref = outputs(64, keep_pairs)
        assert np.isfinite(ref["nearest_p"]).sum() > 200  # many non-empty rows: several blocks of 64
        for block_rows in (1, 2, 3, 7):  # 1-3: the scratch's room (longest * (block_rows // 4) + longest) cuts blocks
            got = outputs(block_rows, keep_pairs)
            for name, value in ref.items():
                np.testing.assert_array_equal(got[name], value, err_msg=f"{name}, block_rows={block_rows}")
