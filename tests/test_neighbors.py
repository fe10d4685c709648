"""Cell-list neighbour search against a brute-force minimum-image O(N^2) search."""
import numpy as np
import pytest

from ase_sphrelax.neighbors import NeighborList, complete_cell
from reference import brute_force_pairs


def canonical(i, j, shift):
    shift = tuple(int(round(x)) for x in shift)
    if i > j or (i == j and shift < (0, 0, 0)):
        return (j, i, tuple(-x for x in shift))
    return (i, j, shift)


def listed_pairs(nlist, r_pc, cell, pbc, cutoff):
    i_p, j_p, d_pc = nlist.get_pairs(r_pc)
    keep = np.linalg.norm(d_pc, axis=1) < cutoff
    _, inv = complete_cell(cell, pbc)
    found = [canonical(i, j, (d - (r_pc[j] - r_pc[i])) @ inv) for i, j, d in zip(i_p[keep], j_p[keep], d_pc[keep])]
    assert len(found) == len(set(found)), "a pair is listed twice"
    return set(found)


@pytest.mark.parametrize("seed", range(40))
def test_random_cells_match_brute_force(seed):
    """Skewed cells, mixed pbc, cells smaller than the cut-off, particles outside the cell."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    cell = rng.normal(size=(3, 3)) * 0.3 + np.diag(rng.uniform(0.3, 3, 3))
    pbc = rng.random(3) < 0.6
    flat = seed % 4 == 0
    if flat:  # 2D sheet: zero c vector, non-periodic z
        cell[2] = 0.0
        pbc[2] = False
    cutoff = rng.uniform(0.2, 1.5)
    r_pc = rng.uniform(-0.3, 1.3, size=(n, 3)) @ complete_cell(cell, pbc)[0]
    if flat:
        r_pc[:, 2] = 0.0
    nlist = NeighborList(cutoff)
    nlist.update(r_pc, cell, pbc)
    assert listed_pairs(nlist, r_pc, cell, pbc, cutoff) == set(brute_force_pairs(r_pc, cell, pbc, cutoff))


def test_per_particle_cutoffs_use_the_larger_radius():
    rng = np.random.default_rng(7)
    n = 60
    cell = np.diag([4.0, 4.0, 4.0])
    r_pc = rng.uniform(0, 4, (n, 3))
    cut_p = rng.uniform(0.3, 1.2, n)
    nlist = NeighborList(cut_p)
    nlist.update(r_pc, cell, [True, True, True])
    i_p, j_p, d_pc = nlist.get_pairs(r_pc)
    r_p = np.linalg.norm(d_pc, axis=1)
    assert np.all(r_p < np.maximum(cut_p[i_p], cut_p[j_p]))
    reference = brute_force_pairs(r_pc, cell, [True] * 3, cut_p.max())
    expected = {k for k, r in reference.items() if r < max(cut_p[k[0]], cut_p[k[1]])}
    assert len(r_p) == len(expected)


def test_verlet_skin_reuses_the_list_until_half_skin_is_exceeded():
    rng = np.random.default_rng(3)
    r_pc = rng.uniform(0, 5, (200, 3))
    cell, pbc = np.diag([5.0] * 3), [True] * 3
    nlist = NeighborList(1.0, skin=0.2)
    assert nlist.update(r_pc, cell, pbc)
    moved = r_pc.copy()
    moved[0, 0] += 0.09
    assert not nlist.update(moved, cell, pbc)
    # the reused list still holds every pair within the cut-off
    assert listed_pairs(nlist, moved, cell, pbc, 1.0) == set(brute_force_pairs(moved, cell, pbc, 1.0))
    moved[1, 1] += 0.11
    assert nlist.update(moved, cell, pbc)
    assert nlist.builds == 2


def test_adaptive_skin_grows_for_lists_rebuilt_often_and_shrinks_for_lists_that_last():
    """max_skin: a list rebuilt after each few moves gets a wider skin (2x per build, up to max_skin), one that
    lasts many evaluations a narrower one (down to skin); every pair within the cut-off is listed throughout."""
    from ase_sphrelax.neighbors import SKIN_SHRINK_ABOVE

    rng = np.random.default_rng(5)
    r_pc = rng.uniform(0, 5, (200, 3))
    cell, pbc = np.diag([5.0] * 3), [True] * 3
    nlist = NeighborList(1.0, skin=0.1, max_skin=0.3)
    skins = []
    for step in range(40):
        r_pc = r_pc + rng.uniform(-0.03, 0.03, r_pc.shape)  # about one build per two moves at skin 0.1
        nlist.update(r_pc, cell, pbc)
        skins.append(nlist.skin)
        if step % 5 == 4:  # the brute-force reference is the slow part
            assert listed_pairs(nlist, r_pc, cell, pbc, 1.0) == set(brute_force_pairs(r_pc, cell, pbc, 1.0))
    assert skins[0] == 0.1 and max(skins) == pytest.approx(0.3) and skins == sorted(skins)
    for _ in range(SKIN_SHRINK_ABOVE + 1):  # still: the list lasts
        nlist.update(r_pc, cell, pbc)
    r_pc = r_pc + 0.2  # a rigid shift beyond half the skin: a rebuild, after a list that lasted
    nlist.update(r_pc, cell, pbc)
    assert nlist.skin == pytest.approx(0.15)
    fixed = NeighborList(1.0, skin=0.1)
    assert fixed.max_skin == 0.1
    with pytest.raises(ValueError, match="max_skin"):
        NeighborList(1.0, skin=0.1, max_skin=-1.0)


def test_neighbour_count_is_linear_in_n():
    """O(N): pairs per particle stay constant as the system grows (jittered lattice)."""
    counts = []
    for side in (20, 80):
        g = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2) + 0.5
        r_pc = np.zeros((side * side, 3))
        r_pc[:, :2] = g
        nlist = NeighborList(2.6)
        nlist.update(r_pc, np.diag([side, side, 1.0]), [True, True, False])
        counts.append(len(nlist.pair_j) / side**2)
    assert counts[0] == pytest.approx(counts[1])


@pytest.mark.parametrize("bad", [[[np.nan, 0, 0]], np.zeros((0, 3)), np.zeros((3, 2))])
def test_bad_positions_are_rejected(bad):
    with pytest.raises(ValueError, match="positions"):
        NeighborList(1.0).update(np.asarray(bad, dtype=float), np.eye(3), [True] * 3)


@pytest.mark.parametrize("cutoff", [0.0, -1.0, np.nan])
def test_bad_cutoff_is_rejected(cutoff):
    with pytest.raises(ValueError, match="cutoff"):
        NeighborList(cutoff)


# -- cut-offs spanning orders of magnitude: bins by a typical cut-off, wide points (issue 16) ---------------
import numba  # noqa: E402
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import ase_sphrelax.neighbors as neighbors  # noqa: E402
import ase_sphrelax.pairs as pairs  # noqa: E402
from ase_sphrelax.pairs import Output, PairInteraction  # noqa: E402


@numba.njit(inline="always")
def _bump_pair(a, b, r2, d, cut_s):
    """A pair term within the larger of the two cut-offs: e = (1 - r / c)^2, and e * d."""
    c = max(cut_s[a], cut_s[b])
    if r2 >= c * c:
        return (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0), ()
    e = (1.0 - np.sqrt(r2) / c) ** 2
    return (e, e * d[0], e * d[1], e * d[2]), (e, -e * d[0], -e * d[1], -e * d[2]), ()


@numba.njit(inline="always")
def _gather_pair(a, b, r2, d, cut_s):
    """a gathers (1 - r / c_a)^2 from b within its own cut-off c_a (a density with its own H)."""
    c = cut_s[a]
    if r2 >= c * c:
        return (0.0,), ()
    return ((1.0 - np.sqrt(r2) / c) ** 2,), ()


BUMP = PairInteraction(_bump_pair, dict(e=Output(()), v=Output((3,))), inputs=("cut_s",))
GATHER = PairInteraction(_gather_pair, dict(rho=Output(())), symmetric=False, inputs=("cut_s",))


def _brute_sums(r_pc, cell, pbc, cut_p):
    """(pairs, e_p, v_pc, rho_p) by the O(N^2 * images) reference search."""
    full_cell = complete_cell(cell, pbc)[0]
    found = {k: r for k, r in brute_force_pairs(r_pc, cell, pbc, cut_p.max()).items()
             if r < max(cut_p[k[0]], cut_p[k[1]])}
    e_p, v_pc, rho_p = np.zeros(len(r_pc)), np.zeros((len(r_pc), 3)), np.zeros(len(r_pc))
    for (i, j, shift), r in found.items():
        d = r_pc[j] + np.array(shift) @ full_cell - r_pc[i]
        e = (1.0 - r / max(cut_p[i], cut_p[j])) ** 2
        e_p[i] += e
        e_p[j] += e
        v_pc[i] += e * d
        v_pc[j] -= e * d
        rho_p[i] += (1.0 - r / cut_p[i]) ** 2 if r < cut_p[i] else 0.0
        rho_p[j] += (1.0 - r / cut_p[j]) ** 2 if r < cut_p[j] else 0.0
    return set(found), e_p, v_pc, rho_p


def _check_wide(r_pc, cell, pbc, cut_p, skin=0.05):
    """Stored list (fused rebuild, then walked), one-shot scan: the pairs of the brute-force
    search, each once, and the same sums."""
    pairs_ref, e_ref, v_ref, rho_ref = _brute_sums(r_pc, cell, pbc, cut_p)
    scale = max(np.abs(v_ref).max(), 1.0)
    for store in (True, False):
        nlist = NeighborList(cut_p, skin=skin)
        nlist.update(r_pc, cell, pbc, store=store)
        for _ in range(2 if store else 1):  # fused rebuild, then the stored list walked
            out = BUMP.compute(nlist, r_pc, inputs=dict(cut_s=cut_p))
            rho = GATHER.compute(nlist, r_pc, inputs=dict(cut_s=cut_p)).rho
            np.testing.assert_allclose(out.e, e_ref, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(out.v, v_ref, rtol=1e-12, atol=1e-12 * scale)
            np.testing.assert_allclose(rho, rho_ref, rtol=1e-12, atol=1e-12)
        if store:
            i_p, j_p, d_pc = nlist.get_pairs(r_pc)
            r_p = np.linalg.norm(d_pc, axis=1)
            assert np.all(r_p < np.maximum(cut_p[i_p], cut_p[j_p]) + skin)
            assert listed_pairs(nlist, r_pc, cell, pbc, np.inf) >= pairs_ref  # each once (asserted inside)
            keep = r_p < np.maximum(cut_p[i_p], cut_p[j_p])
            assert np.count_nonzero(keep) == len(pairs_ref)
    return nlist


def _wide_scene(seed, n, dim, periodic, spread=100.0):
    rng = np.random.default_rng(seed)
    box = 4.0
    r_pc = np.zeros((n, 3))
    r_pc[:, :dim] = rng.normal(box / 2, box / 6, (n, dim))  # dense centre, sparse edges
    cell = np.diag([box if c < dim else 0.0 for c in range(3)])
    pbc = np.array([periodic and c < dim for c in range(3)])
    cut_p = 0.02 * box * spread ** rng.uniform(0, 1, n) ** 3  # most small, a few up to 100x
    return r_pc, cell, pbc, cut_p


@pytest.fixture(params=[1, 2], ids=["1 thread", "2 threads"])
def threads(request, monkeypatch):
    """Run every loop on 1 or 2 chunks (threads), whatever the system size."""
    monkeypatch.setattr(neighbors, "thread_count", lambda n: request.param)
    monkeypatch.setattr(pairs, "thread_count", lambda n: request.param)
    return request.param


@pytest.mark.parametrize("periodic", [False, True], ids=["bounded", "periodic"])
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_cutoffs_spanning_100x_match_brute_force(threads, dim, periodic):
    r_pc, cell, pbc, cut_p = _wide_scene(dim, {1: 60, 2: 200, 3: 250}[dim], dim, periodic)
    nlist = _check_wide(r_pc, cell, pbc, cut_p)
    assert nlist.points.n_normal < nlist.n_extended  # the wide path was taken
    assert nlist.points.bin_reach < 0.5 * nlist.points.reach


def test_bins_are_sized_by_a_typical_cutoff():
    """Cut-offs spanning 100x: bins by the typical (quantile) cut-off, the larger ones wide points;
    within WIDE_FACTOR of each other: bins by the largest, no wide points."""
    r_pc, cell, pbc, cut_p = _wide_scene(3, 4000, 2, False)
    wide = neighbors.BinnedPoints(r_pc, cell, pbc, cut_p)
    typical = np.quantile(cut_p, neighbors.TYPICAL_QUANTILE)
    uniform = neighbors.BinnedPoints(r_pc, cell, pbc, np.full(len(r_pc), typical))
    assert wide.bin_reach == pytest.approx(typical)
    assert wide.binsize == pytest.approx(uniform.binsize)
    assert wide.n_extended - wide.n_normal == np.count_nonzero(cut_p > typical)
    close = neighbors.BinnedPoints(r_pc, cell, pbc, np.linspace(1.0, neighbors.WIDE_FACTOR, len(r_pc)))
    assert close.n_normal == len(r_pc) and close.bin_reach == close.reach == neighbors.WIDE_FACTOR


@settings(max_examples=40, deadline=None, database=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 50), dim=st.sampled_from([1, 2, 3]), periodic=st.booleans(),
       decades=st.floats(0.0, 2.0), skin=st.sampled_from([0.0, 0.1]), degenerate=st.sampled_from(["", "same", "line"]))
def test_property_any_cutoff_spread_gives_every_pair_once(seed, n, dim, periodic, decades, skin, degenerate):
    """Random points and per-particle cut-offs spanning up to 2 decades, periodic or not, coincident or
    collinear points: the pairs and sums of the brute-force search."""
    rng = np.random.default_rng(seed)
    box = 2.0
    r_pc = np.zeros((n, 3))
    r_pc[:, :dim] = rng.uniform(0, box, (n, dim))
    if degenerate == "same":
        r_pc[n // 2:] = r_pc[0]
    elif degenerate == "line" and dim > 1:
        r_pc[:, 1:] = 0.0
    cell = np.diag([box if c < dim else 0.0 for c in range(3)])
    pbc = [periodic and c < dim for c in range(3)]
    cut_p = 0.01 * 10.0 ** (decades * rng.uniform(0, 1, n) ** 3)  # most small: wide points above WIDE_FACTOR
    for chunks in (1, 3):
        neighbors_thread_count, pairs_thread_count = neighbors.thread_count, pairs.thread_count
        neighbors.thread_count = pairs.thread_count = lambda m, k=chunks: k
        try:
            _check_wide(r_pc, cell, pbc, cut_p, skin)
        finally:
            neighbors.thread_count, pairs.thread_count = neighbors_thread_count, pairs_thread_count


@pytest.mark.skipif(neighbors._MADVISE is None, reason="madvise: Linux only")
def test_copy_releasing_copies_and_gives_back_the_source_pages(monkeypatch):
    """The list's closing copy: the values arrive, and the source's whole pages already copied read as zeros (given
    back to the system), nothing outside the source is touched, and the lists of a rebuild stay those of before."""
    monkeypatch.setattr(neighbors, "_COPY_CHUNK", 4096)
    outer = np.arange(1, 300_001, dtype=np.int32)
    src = outer[1000:-1000]
    dst = np.empty_like(src)
    neighbors._copy_releasing(dst, src)
    assert np.array_equal(dst, np.arange(1001, 299_001, dtype=np.int32))
    assert np.count_nonzero(src == 0) * src.itemsize >= src.nbytes - 2 * 4096  # all but the two partial pages
    assert np.array_equal(outer[:1000], np.arange(1, 1001))
    assert np.array_equal(outer[-1000:], np.arange(299_001, 300_001))
    rng = np.random.default_rng(1)
    r_pc = np.zeros((20_000, 3))
    r_pc[:, :2] = rng.random((20_000, 2))
    nl = NeighborList(0.02, skin=0.002)
    nl.update(r_pc, np.zeros((3, 3)), [False] * 3)
    start, pairs_j = nl.pair_start.copy(), nl.pair_j.copy()
    nl.update(r_pc + 0.01, np.zeros((3, 3)), [False] * 3)
    nl.update(r_pc, np.zeros((3, 3)), [False] * 3)
    assert np.array_equal(nl.pair_start, start) and np.array_equal(nl.pair_j, pairs_j)


@pytest.mark.skipif(neighbors._MADVISE is None, reason="madvise: Linux only")
def test_copy_releasing_gives_back_a_small_source_in_sixteenths():
    """A list of 1-4 MB (1e4-3e4 particles) is copied in sixteenths, each given back once copied: whole, both
    copies were resident at once (BIPI 2D at 3e4: about 117 B per particle more at each build)."""
    src = np.arange(1, 300_001, dtype=np.int32)  # 1.2 MB, below 4 _COPY_CHUNK
    assert src.nbytes < 4 * neighbors._COPY_CHUNK
    dst = np.empty_like(src)
    neighbors._copy_releasing(dst, src)
    assert np.array_equal(dst, np.arange(1, 300_001, dtype=np.int32))
    assert np.count_nonzero(src == 0) * src.itemsize >= src.nbytes - 2 * 4096


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 60), periodic=st.booleans(),
       fraction=st.floats(0.0, 1.0), approach=st.booleans())
def test_property_a_reused_list_holds_every_pair_within_the_cutoff(seed, n, periodic, fraction, approach):
    """Moves of at most half the skin (``fraction`` of it) keep the list (no rebuild), and it still holds every
    pair within the cut-off (brute force); ``approach``: the worst case, two particles just beyond cut-off +
    skin moving straight at each other by half the skin each, then 2 % of the skin further (a rebuild)."""
    rng = np.random.default_rng(seed)
    cutoff, skin, side = 1.0, 0.3, 4.0
    cell, pbc = np.diag([side] * 3), [periodic] * 3
    r_pc = rng.uniform(0, side, (n, 3))
    if approach:
        r_pc[1] = r_pc[0] + np.array([cutoff + skin + 1e-9, 0.0, 0.0])
    nlist = NeighborList(cutoff, skin=skin)
    nlist.update(r_pc, cell, pbc)
    step_pc = rng.normal(size=(n, 3))
    step_pc /= np.linalg.norm(step_pc, axis=1)[:, None]
    size_p = rng.uniform(0.0, 1.0, n)
    if approach:
        step_pc[0], step_pc[1] = (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)
        size_p[:2] = 1.0
    half = 0.5 * skin * (1 - 1e-12)
    moved = r_pc + step_pc * (size_p * fraction * half / size_p.max())[:, None]
    assert not nlist.update(moved, cell, pbc)  # kept
    assert listed_pairs(nlist, moved, cell, pbc, cutoff) == set(brute_force_pairs(moved, cell, pbc, cutoff))
    if approach:
        moved[:2] += step_pc[:2] * ((1.0 - fraction) * half + 0.01 * skin)
        assert np.linalg.norm(moved[1] - moved[0]) < cutoff
        assert nlist.update(moved, cell, pbc)
        assert listed_pairs(nlist, moved, cell, pbc, cutoff) == set(brute_force_pairs(moved, cell, pbc, cutoff))
