"""TreeNeighborList: pairs in any dimension against brute force, and the pair mechanism over it."""
import numba
import numpy as np
import pytest

from ase_sphrelax.kernel_sums import KERNEL_SUMS
from ase_sphrelax.kernels import get_kernel
from ase_sphrelax.neighbors import NeighborList
from ase_sphrelax.pairs import Output, PairInteraction
from ase_sphrelax.tree_neighbors import TreeNeighborList, brute_force_pairs_nd


def listed_pairs(nlist, r_pc, reach):
    i_p, j_p, d_pc = nlist.get_pairs(r_pc)
    r_p = np.linalg.norm(d_pc, axis=1)
    return {(min(i, j), max(i, j)) for i, j, r in zip(i_p, j_p, r_p) if r < reach}


@pytest.mark.parametrize("dim", [1, 2, 3, 5, 10])
def test_pairs_match_brute_force(dim):
    rng = np.random.default_rng(dim)
    r_pc = rng.normal(size=(300, dim))
    cutoff = {1: 0.02, 2: 0.2, 3: 0.4, 5: 1.0, 10: 2.6}[dim]
    nlist = TreeNeighborList(cutoff)
    assert nlist.update(r_pc)
    reference = brute_force_pairs_nd(r_pc, cutoff)
    assert len(reference) > 100
    i_p, j_p, d_pc = nlist.get_pairs(r_pc)
    assert len(i_p) == len(reference)  # each pair exactly once
    assert listed_pairs(nlist, r_pc, cutoff) == set(reference)
    np.testing.assert_allclose(d_pc, r_pc[j_p] - r_pc[i_p])
    # half list over sorted points: partners have higher sorted index
    a_p = np.repeat(np.arange(300), np.diff(nlist.pair_start))
    assert np.all(nlist.pair_j > a_p)


def test_per_point_cutoffs_use_the_larger_of_the_two():
    rng = np.random.default_rng(1)
    r_pc = rng.uniform(0, 3, (250, 4))
    cut_p = rng.uniform(0.3, 0.9, 250)
    nlist = TreeNeighborList(cut_p)
    nlist.update(r_pc)
    assert listed_pairs(nlist, r_pc, np.inf) == set(brute_force_pairs_nd(r_pc, cut_p))


def test_skin_reuse_and_rebuild():
    rng = np.random.default_rng(2)
    r_pc = rng.normal(size=(200, 6))
    nlist = TreeNeighborList(1.0, skin=0.2)
    assert nlist.update(r_pc) and nlist.builds == 1
    moved = r_pc + rng.uniform(-0.05, 0.05, r_pc.shape) / np.sqrt(6)  # |dx| <= 0.05 < skin / 2
    assert not nlist.update(moved)
    assert listed_pairs(nlist, moved, 1.0) == set(brute_force_pairs_nd(moved, 1.0))
    assert not nlist.update(moved, cutoff=1.1)  # growth 0.1 + 2 * 0.05 <= skin
    assert listed_pairs(nlist, moved, 1.1) == set(brute_force_pairs_nd(moved, 1.1))
    assert nlist.update(moved, cutoff=1.3)  # beyond the skin
    assert nlist.builds == 2
    far = moved + 0.3
    far[0] += 1.0
    assert nlist.update(far)
    assert listed_pairs(nlist, far, 1.3) == set(brute_force_pairs_nd(far, 1.3))


def test_one_shot_build_has_no_skin():
    r_pc = np.random.default_rng(3).normal(size=(50, 5))
    nlist = TreeNeighborList(1.0, skin=0.5)
    nlist.update(r_pc, store=False)
    assert not nlist.update(r_pc, store=False)  # same points: still valid
    assert nlist.update(r_pc + 1e-9)  # any move rebuilds a list without skin


def test_kernel_sums_over_the_tree_equal_the_cell_list_in_3d():
    """The same PairInteraction over TreeNeighborList and NeighborList (open 3D cell)."""
    rng = np.random.default_rng(4)
    r_pc = rng.normal(size=(800, 3))
    h = 0.6
    kernel = get_kernel("wendland_c2", 3)
    params = dict(inv_h=1.0 / h)
    cells = NeighborList(h)
    cells.update(r_pc, np.zeros((3, 3)), [False] * 3)
    tree = TreeNeighborList(h)
    tree.update(r_pc)
    ref = KERNEL_SUMS.compute(cells, r_pc, params, reach=h, kernel=kernel)
    out = KERNEL_SUMS.compute(tree, r_pc, params, reach=h, kernel=kernel)
    np.testing.assert_allclose(out.w, ref.w, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(out.grad, ref.grad, rtol=1e-10, atol=1e-13)
    assert len(tree.get_pairs(r_pc)[0]) > 5 * len(r_pc)  # many neighbours: a real test


@numba.njit(cache=True, inline="always")
def _weighted_separation(a, b, r2, d, w_s):
    """Per point: sum_b w_b (x_b - x_a) within reach, in D = 7 components, and the count."""
    return ((1.0, w_s[b] * d[0], w_s[b] * d[1], w_s[b] * d[2], w_s[b] * d[3], w_s[b] * d[4], w_s[b] * d[5],
             w_s[b] * d[6]),
            (1.0, -w_s[a] * d[0], -w_s[a] * d[1], -w_s[a] * d[2], -w_s[a] * d[3], -w_s[a] * d[4], -w_s[a] * d[5],
             -w_s[a] * d[6]), ())


def test_pair_interaction_in_7d_against_brute_force():
    rng = np.random.default_rng(5)
    m, dim, reach = 400, 7, 2.2
    r_pc = rng.normal(size=(m, dim))
    w_p = rng.uniform(0.5, 2.0, m)
    interaction = PairInteraction(_weighted_separation, dict(count=Output(()), s=Output((dim,))), inputs=("w_s",),
                                  dim=dim)
    nlist = TreeNeighborList(reach)
    nlist.update(r_pc)
    out = interaction.compute(nlist, r_pc, inputs=dict(w_s=w_p), reach=reach)
    d_ppc = r_pc[None, :, :] - r_pc[:, None, :]  # x_b - x_a at [a, b]
    near_pp = np.linalg.norm(d_ppc, axis=2) < reach
    np.fill_diagonal(near_pp, False)
    np.testing.assert_array_equal(out.count, near_pp.sum(axis=1))
    np.testing.assert_allclose(out.s, np.einsum("ab,b,abc->ac", near_pp, w_p, d_ppc), atol=1e-11)
    assert out.count.mean() > 10


def test_bad_input_is_named():
    nlist = TreeNeighborList(1.0)
    with pytest.raises(ValueError, match="shape"):
        nlist.update(np.zeros(5))
    with pytest.raises(ValueError, match="at least one"):
        nlist.update(np.zeros((0, 4)))
    with pytest.raises(ValueError, match="finite"):
        nlist.update(np.array([[0.0, np.nan, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="pbc"):
        nlist.update(np.zeros((3, 3)), np.eye(3), [True, False, False])
    with pytest.raises(ValueError, match="cutoff"):
        TreeNeighborList(-1.0)
    with pytest.raises(ValueError, match="entries"):
        TreeNeighborList(np.ones(3)).update(np.zeros((4, 5)))


def test_coincident_points_are_pairs():
    r_pc = np.zeros((5, 4))
    nlist = TreeNeighborList(0.1)
    nlist.update(r_pc)
    assert len(nlist.get_pairs(r_pc)[0]) == 10
