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
