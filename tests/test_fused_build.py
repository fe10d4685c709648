"""The rebuild path of the neighbour list: one-pass list scan, threads, buffer growth, and the
list scan fused with the first pair sum after a build (issue 9)."""
import weakref

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ase_sphrelax.neighbors as neighbors
import ase_sphrelax.pairs as pairs
from ase_sphrelax.kernel_sums import pair_potential_sums
from ase_sphrelax.kernels import get_kernel
from ase_sphrelax.neighbors import NeighborList, complete_cell
from reference import brute_force_pairs

KERNEL = get_kernel("wendland_c2", 3)


def listed(nlist, r_pc, cell, pbc, cutoff):
    """Set of (i, j, image) of the stored pairs within ``cutoff``, each once, canonical."""
    i_p, j_p, d_pc = nlist.get_pairs(r_pc)
    keep = np.linalg.norm(d_pc, axis=1) < cutoff
    _, inv = complete_cell(cell, pbc)
    out = []
    for i, j, d in zip(i_p[keep], j_p[keep], d_pc[keep]):
        shift = tuple(int(round(x)) for x in (d - (r_pc[j] - r_pc[i])) @ inv)
        if i > j or (i == j and shift < (0, 0, 0)):
            i, j, shift = j, i, tuple(-x for x in shift)
        out.append((int(i), int(j), shift))
    assert len(out) == len(set(out)), "a pair is listed twice"
    return set(out)


def scene(seed, n=300, box=4.0, flat=False):
    rng = np.random.default_rng(seed)
    r_pc = rng.uniform(0, box, (n, 3))
    cell = np.diag([box] * 3)
    pbc = np.array([True, True, not flat])
    if flat:
        r_pc[:, 2] = 0.0
        cell[2, 2] = 0.0
    return r_pc, cell, pbc


@pytest.fixture(params=[1, 3], ids=["1 chunk", "3 chunks"])
def chunks(request, monkeypatch):
    """Run every loop on 1 or 3 chunks (threads), whatever the system size."""
    monkeypatch.setattr(neighbors, "thread_count", lambda n: request.param)
    monkeypatch.setattr(pairs, "thread_count", lambda n: request.param)
    return request.param


@pytest.fixture(params=[False, True], ids=["sized buffer", "buffer grown"])
def tiny_buffer(request, monkeypatch):
    """Optionally start from an almost empty pair buffer, so that every region overflows and grows."""
    if request.param:
        monkeypatch.setattr(neighbors.BinnedPoints, "expected_pairs", lambda self: 1)
    return request.param


@pytest.mark.parametrize("flat", [False, True], ids=["3D", "2D"])
def test_one_pass_list_matches_brute_force(chunks, tiny_buffer, flat):
    r_pc, cell, pbc = scene(1, flat=flat)
    nlist = NeighborList(0.9, skin=0.1)
    nlist.update(r_pc, cell, pbc)
    assert nlist.build_pending
    assert listed(nlist, r_pc, cell, pbc, 1.0) == set(brute_force_pairs(r_pc, cell, pbc, 1.0))
    assert not nlist.build_pending


@pytest.mark.parametrize("flat", [False, True], ids=["3D", "2D"])
def test_fused_build_gives_the_sums_and_the_list_of_the_separate_passes(chunks, tiny_buffer, flat):
    r_pc, cell, pbc = scene(2, flat=flat)
    h, skin = 0.9, 0.15
    one_shot = NeighborList(h)
    one_shot.update(r_pc, cell, pbc, store=False)
    e_ref, f_ref, v_ref = pair_potential_sums(one_shot, r_pc, h, 1.0, KERNEL, want_virial=True)
    fused = NeighborList(h, skin=skin)
    fused.update(r_pc, cell, pbc)
    e, f, v = pair_potential_sums(fused, r_pc, h, 1.0, KERNEL, want_virial=True)  # scan + list + sums
    assert not fused.build_pending
    np.testing.assert_allclose(e, e_ref, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(f, f_ref, rtol=1e-12, atol=1e-12 * np.abs(f_ref).max())
    np.testing.assert_allclose(v, v_ref, rtol=1e-12, atol=1e-12 * np.abs(v_ref).max())
    separate = NeighborList(h, skin=skin)
    separate.update(r_pc, cell, pbc)
    assert listed(fused, r_pc, cell, pbc, h + skin) == listed(separate, r_pc, cell, pbc, h + skin)
    np.testing.assert_array_equal(fused.pair_start, separate.pair_start)
    e2, f2, _ = pair_potential_sums(fused, r_pc, h, 1.0, KERNEL)  # the stored list is walked now
    np.testing.assert_allclose(f2, f_ref, rtol=1e-12, atol=1e-12 * np.abs(f_ref).max())
    assert fused.builds == 1


def test_pending_list_is_made_from_the_build_positions(chunks):
    """A sum asked at moved positions before the pending scan ran must not list pairs from
    the moved positions: later positions within skin/2 of the build would miss pairs."""
    r_pc, cell, pbc = scene(3)
    h, skin = 0.8, 0.4
    rng = np.random.default_rng(4)
    nlist = NeighborList(h, skin=skin)
    nlist.update(r_pc, cell, pbc)
    u_pc = rng.normal(size=r_pc.shape)
    u_pc *= 0.19 / np.linalg.norm(u_pc, axis=1)[:, None]
    first = r_pc + u_pc  # within skin/2 of the build: no rebuild
    assert not nlist.update(first, cell, pbc)
    assert nlist.build_pending
    pair_potential_sums(nlist, first, h, 1.0, KERNEL)
    second = r_pc - u_pc  # within skin/2 of the build, 0.38 from `first`
    assert not nlist.update(second, cell, pbc)
    _, f, _ = pair_potential_sums(nlist, second, h, 1.0, KERNEL)
    reference = NeighborList(h)
    reference.update(second, cell, pbc, store=False)
    _, f_ref, _ = pair_potential_sums(reference, second, h, 1.0, KERNEL)
    np.testing.assert_allclose(f, f_ref, rtol=1e-12, atol=1e-12 * np.abs(f_ref).max())
    assert listed(nlist, second, cell, pbc, h) == set(brute_force_pairs(second, cell, pbc, h))


def test_rebuilds_keep_one_compact_pair_buffer():
    """Each build gathers its list into a buffer sized to it (5 % and 1024 entries to spare) and the
    previous buffer is released: after a rebuild no second list stays alive (the memory change of
    ``reproductions/speed-scale-memory``; the list in fresh pages also walks faster than in the scan's)."""
    r_pc, cell, pbc = scene(5)
    nlist = NeighborList(0.9, skin=0.1)
    nlist.update(r_pc, cell, pbc)
    nlist.pair_j  # complete the scan
    last = weakref.ref(nlist._pair_buffer)
    for k in range(3):
        nlist.update(r_pc + 0.3 * (k + 1), cell, pbc)
        pair_potential_sums(nlist, r_pc + 0.3 * (k + 1), 0.9, 1.0, KERNEL)
        assert last() is None
        buffer = nlist._pair_buffer
        assert buffer.shape[0] == int(1.05 * len(nlist.pair_j)) + 1024
        last = weakref.ref(buffer)
        del buffer
    assert nlist.builds == 4


@pytest.mark.parametrize("store", [True, False])
def test_nan_positions_are_rejected_on_the_reuse_path_too(store):
    """update() checks finiteness only when it rebuilds; a NaN forces that rebuild."""
    r_pc, cell, pbc = scene(6)
    nlist = NeighborList(0.9, skin=0.1)
    nlist.update(r_pc, cell, pbc, store=store)
    for bad in (np.nan, np.inf):
        moved = r_pc.copy()
        moved[7, 1] = bad
        with pytest.raises(ValueError, match=r"finite.*\[7\]"):
            nlist.update(moved, cell, pbc, store=store)


def _edge_scenes():
    rng = np.random.default_rng(0)
    chain_x = np.zeros((50, 3))
    chain_x[:, 0] = rng.uniform(0, 10, 50)
    chain_y = np.zeros((50, 3))
    chain_y[:, 1] = rng.uniform(0, 10, 50)
    skewed = np.array([[1.0, 0, 0], [0.4, 0.9, 0], [0.1, 0.2, 1.1]])
    sheet = np.zeros((60, 3))
    sheet[:, :2] = rng.uniform(-1, 4, (60, 2))
    return {
        "periodic chain along x (row axis x)": (chain_x, np.diag([10.0, 0, 0]), [True, False, False], 0.7),
        "open chain along y": (chain_y, np.zeros((3, 3)), [False] * 3, 0.9),
        "every point in one bin": (rng.uniform(0, 0.3, (20, 3)), np.zeros((3, 3)), [False] * 3, 1.0),
        "skewed cell smaller than the cut-off": (rng.uniform(0, 1, (7, 3)) @ skewed, skewed, [True] * 3, 1.6),
        "2D sheet, points outside the cell": (sheet, np.diag([3.0, 2.0, 0.0]), [True, True, False], 0.8),
    }


@pytest.mark.parametrize("name", list(_edge_scenes()))
def test_row_stencil_on_degenerate_bin_grids(name, chunks):
    r_pc, cell, pbc, cut = _edge_scenes()[name]
    nlist = NeighborList(cut, skin=0.1)
    nlist.update(r_pc, cell, pbc)
    e, f, _ = pair_potential_sums(nlist, r_pc, cut, 1.0, KERNEL)  # fused build
    assert listed(nlist, r_pc, cell, pbc, cut) == set(brute_force_pairs(r_pc, cell, pbc, cut))
    one_shot = NeighborList(cut)
    one_shot.update(r_pc, cell, pbc, store=False)
    e_ref, f_ref, _ = pair_potential_sums(one_shot, r_pc, cut, 1.0, KERNEL)
    np.testing.assert_allclose(e, e_ref, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(f, f_ref, rtol=1e-12, atol=1e-12 * max(np.abs(f_ref).max(), 1e-300))


@pytest.mark.parametrize("name", list(_edge_scenes()) + ["3D random", "2D random"])
@pytest.mark.parametrize("n_chunks", [2, 3, 5])
def test_partner_ends_bound_every_pair_of_a_chunk(name, n_chunks):
    """The threads' buffers end at partner_ends: no listed partner of a chunk's points lies beyond."""
    if name.endswith("random"):
        r_pc, cell, pbc = scene(5, flat=name.startswith("2D"))
        cut = 0.9
    else:
        r_pc, cell, pbc, cut = _edge_scenes()[name]
    nlist = NeighborList(cut, skin=0.1)
    nlist.update(r_pc, cell, pbc)
    assert nlist.partner_ends(n_chunks) is None  # the build is pending: no list yet
    start, partner = nlist.pair_start, nlist.pair_j
    bounds = neighbors.chunk_bounds(nlist.n_extended, n_chunks)
    ends = nlist.partner_ends(n_chunks)
    for (first, last), end in zip(bounds, ends):
        assert last <= end <= nlist.n_extended
        if start[last] > start[first]:
            assert partner[start[first]:start[last]].max() == end - 1 or end == last


def _bounded_scene(seed, n=300, box=4.0, flat=False):
    r_pc, cell, _ = scene(seed, n, box, flat)
    return r_pc, cell, np.zeros(3, dtype=bool)


@pytest.mark.parametrize("flat", [False, True], ids=["3D", "2D"])
def test_plain_build_of_a_bounded_set_gives_the_general_builds_list_and_sums(chunks, tiny_buffer, flat, monkeypatch):
    """A set without periodic images and of one cut-off is built by the "build_plain" loop (distance test alone):
    the same list, in the same order, and the same sums bit for bit as the general loop, and the pairs of brute
    force."""
    r_pc, cell, pbc = _bounded_scene(6, flat=flat)
    h, skin = 0.9, 0.15
    runs = {}
    for plain in (True, False):
        if not plain:
            monkeypatch.setattr(NeighborList, "plain", property(lambda self: False))
        nlist = NeighborList(h, skin=skin)
        nlist.update(r_pc, cell, pbc)
        assert nlist.plain is plain
        e, f, _ = pair_potential_sums(nlist, r_pc, h, 1.0, KERNEL)
        runs[plain] = (nlist.pair_start.copy(), nlist.pair_j.copy(), e, f)
        assert listed(nlist, r_pc, cell, pbc, h + skin) == set(brute_force_pairs(r_pc, cell, pbc, h + skin))
    for got, want in zip(runs[True], runs[False]):
        np.testing.assert_array_equal(got, want)


def test_plain_applies_to_bounded_sets_of_one_cutoff_only():
    r_pc, cell, pbc = scene(7)
    periodic = NeighborList(0.9, skin=0.1)
    periodic.update(r_pc, cell, pbc)
    bounded = NeighborList(0.9, skin=0.1)
    bounded.update(r_pc, cell, np.zeros(3, dtype=bool))
    per_point = NeighborList(np.full(len(r_pc), 0.9), skin=0.1)
    per_point.update(r_pc, cell, np.zeros(3, dtype=bool))
    assert (periodic.plain, bounded.plain, per_point.plain, NeighborList(0.9).plain) == (False, True, False, False)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(2, 40), st.booleans())
def test_plain_build_on_grid_points_with_coincident_pairs_and_pairs_at_the_reach(seed, n, flat):
    """Points on a grid of spacing 0.25 (pairs at exactly h + skin = 1.0 and 0.75, beyond and within; points on
    bin edges) with coincident copies: the plain build (distance test alone) lists what brute force lists
    (distance < h + skin), the general loop's list in its order, and its forces are the one-shot scan's and, bit
    for bit, the general loop's."""
    rng = np.random.default_rng(seed)
    r_pc = rng.integers(0, 8, (n, 3)) * 0.25
    r_pc = np.concatenate([r_pc, r_pc[: n // 3]])  # coincident copies
    if flat:
        r_pc[:, 2] = 0.0
    cell, pbc = np.diag([2.0, 2.0, 2.0 if not flat else 0.0]), np.zeros(3, dtype=bool)
    h, skin = 0.8, 0.2  # bins of edge 0.5 (3D) or 1/3 (2D): many points on bin edges
    nlist = NeighborList(h, skin=skin)
    nlist.update(r_pc, cell, pbc)
    assert nlist.plain
    _, f, _ = pair_potential_sums(nlist, r_pc, h, 1.0, KERNEL)
    assert listed(nlist, r_pc, cell, pbc, h + skin) == set(brute_force_pairs(r_pc, cell, pbc, h + skin))
    with pytest.MonkeyPatch.context() as patch:  # the general loop (every test): the same list
        patch.setattr(NeighborList, "plain", property(lambda self: False))
        general = NeighborList(h, skin=skin)
        general.update(r_pc, cell, pbc)
        _, f_general, _ = pair_potential_sums(general, r_pc, h, 1.0, KERNEL)
    np.testing.assert_array_equal(nlist.pair_j, general.pair_j)
    np.testing.assert_array_equal(f, f_general)
    one_shot = NeighborList(h)
    one_shot.update(r_pc, cell, pbc, store=False)
    _, f_ref, _ = pair_potential_sums(one_shot, r_pc, h, 1.0, KERNEL)
    np.testing.assert_allclose(f, f_ref, rtol=1e-12, atol=1e-12 * max(np.abs(f_ref).max(), 1.0))


@pytest.fixture(params=[False, True], ids=["one call", "region written over"])
def small_region(request, monkeypatch):
    """Optionally let a one-shot plain scan's region hold a few bins only, so that every chunk is scanned in many
    calls, each writing over the partners of the last."""
    if request.param:
        monkeypatch.setattr(neighbors, "ONE_SHOT_REGION", 1)
    return request.param


@pytest.mark.parametrize("flat", [False, True], ids=["3D", "2D"])
def test_one_shot_plain_scan_gives_the_sums_of_the_general_scan_and_of_a_fused_build(chunks, small_region, flat,
                                                                                      monkeypatch):
    """One-shot bins of a set without images and of one cut-off are summed by the plain build's loop with no list
    kept: the energies and forces of the general one-shot scan (to round-off: another order of the terms) and, bit
    for bit, those of a fused build that lists the same pairs (skin 1e-9: no pair lies between h and h + skin)."""
    r_pc, cell, pbc = _bounded_scene(8, n=400, flat=flat)
    r_pc = np.concatenate([r_pc, r_pc[:20]])  # coincident pairs
    h = 0.9
    calls = []
    one_shot = NeighborList(h)
    one_shot.update(r_pc, cell, pbc, store=False)
    assert one_shot.plain
    scan = one_shot.one_shot_scan
    monkeypatch.setattr(one_shot, "one_shot_scan", lambda *a: calls.append(1) or scan(*a))
    e, f, _ = pair_potential_sums(one_shot, r_pc, h, 1.0, KERNEL)
    assert calls and not one_shot.stored  # the plain path ran, and kept no list
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(NeighborList, "plain", property(lambda self: False))
        general = NeighborList(h)
        general.update(r_pc, cell, pbc, store=False)
        e_general, f_general, _ = pair_potential_sums(general, r_pc, h, 1.0, KERNEL)
    np.testing.assert_allclose(e, e_general, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(f, f_general, rtol=1e-12, atol=1e-12 * np.abs(f_general).max())
    fused = NeighborList(h, skin=1e-9)
    fused.update(r_pc, cell, pbc)
    e_fused, f_fused, _ = pair_potential_sums(fused, r_pc, h, 1.0, KERNEL)
    assert fused.stored
    np.testing.assert_array_equal(e, e_fused)
    np.testing.assert_array_equal(f, f_fused)


def test_one_shot_scan_refuses_a_stored_list_and_bins_with_images():
    r_pc, cell, pbc = scene(9)
    stored = NeighborList(0.9, skin=0.1)
    stored.update(r_pc, cell, np.zeros(3, dtype=bool))
    periodic = NeighborList(0.9)
    periodic.update(r_pc, cell, pbc, store=False)
    for nlist in (stored, periodic):
        with pytest.raises(ValueError, match="one_shot_scan"):
            nlist.one_shot_scan(lambda *a: None, 1)
