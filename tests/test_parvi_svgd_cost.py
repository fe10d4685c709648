"""SVGD's median heuristic by scipy's pdist (issue 18, item 5): the same number as the M x M x d form it replaced."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.sampling import baselines


def median_length_scale_dense(x_pc):
    """The form before 2026-12-02: every pair's distance from the difference array, its lower triangle."""
    diff = x_pc[:, None, :] - x_pc[None, :, :]
    r = np.sqrt(np.einsum("abc,abc->ab", diff, diff))[np.tril_indices(x_pc.shape[0], k=-1)]
    return float(np.median(r) ** 2 / np.log(x_pc.shape[0]))


@settings(max_examples=60, deadline=None, database=None)
@given(m=st.integers(2, 60), d=st.integers(1, 4), seed=st.integers(0, 2**31), repeated=st.booleans(),
       scale=st.sampled_from([1e-6, 1.0, 1e4]))
def test_median_heuristic_is_the_dense_one_to_round_off(m, d, seed, repeated, scale):
    x_pc = scale * np.random.default_rng(seed).standard_normal((m, d))
    if repeated:  # coincident points (zero distances), the degenerate case
        x_pc[m // 2:] = x_pc[0]
    # the same distances summed in another order (d >= 3): equal to a few units in the last place
    assert baselines.median_length_scale(x_pc) == pytest.approx(median_length_scale_dense(x_pc), rel=1e-14, abs=0)


def test_median_heuristic_subset_above_median_points():
    x_pc = np.random.default_rng(3).standard_normal((300, 2))
    sub = x_pc[np.random.default_rng(0).choice(300, 100, replace=False)]
    expected = float(np.median(np.sqrt(((sub[:, None] - sub[None]) ** 2).sum(-1))[np.tril_indices(100, -1)]) ** 2
                     / np.log(300))
    assert baselines.median_length_scale(x_pc, median_points=100) == expected
