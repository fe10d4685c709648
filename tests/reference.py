"""Brute-force references for the tests (not part of the package)."""
import itertools

import numpy as np

from ase_sphrelax.neighbors import complete_cell


def brute_force_pairs(positions, cell, pbc, cutoff):
    """Reference O(N^2 * images) search: dict (i, j, image) -> r for every pair with r < cutoff.

    Each unordered physical pair appears once, oriented so that i < j, or for
    i == j with a lexicographically positive image.
    """
    r_pc = np.asarray(positions, dtype=float)
    assert r_pc.ndim == 2 and r_pc.shape[1] == 3, r_pc.shape
    full_cell, inv_cell = complete_cell(cell, pbc)
    pbc = np.asarray(pbc, dtype=bool)
    width_c = 1.0 / np.linalg.norm(inv_cell, axis=0)
    span = np.ptp(r_pc @ inv_cell, axis=0)
    layers = [int(np.ceil(cutoff / width_c[c] + span[c])) + 1 if pbc[c] else 0 for c in range(3)]
    pairs = {}
    for shift in itertools.product(*[range(-l, l + 1) for l in layers]):
        t_c = np.array(shift) @ full_cell
        d_ppc = r_pc[None, :, :] + t_c - r_pc[:, None, :]
        r_pp = np.linalg.norm(d_ppc, axis=2)
        for i, j in zip(*np.nonzero(r_pp < cutoff)):
            if i < j or (i == j and tuple(shift) > (0, 0, 0)):
                pairs[(int(i), int(j), tuple(shift))] = r_pp[i, j]
    return pairs
