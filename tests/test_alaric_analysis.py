"""Eq. 48 (ALARIC Appendix 1) against the paper's Table 2 column."""
import numpy as np
import pytest

from ase_sphrelax.analysis import alaric_min_error


def test_eq48_reproduces_table2_column():
    """N = 303 on [-1, 1]: the paper prints 1e-4, 7e-5, 9e-6, 8e-7, 1e-9, 8e-11 (one digit)."""
    deltas = [0.0, 0.01, 0.05, 0.1, 0.5, 1.0]
    paper = [1e-4, 7e-5, 9e-6, 8e-7, 1e-9, 8e-11]
    ours = [alaric_min_error(303, d, 1) for d in deltas]
    for value, printed in zip(ours, paper):
        assert 0.8 < value / printed < 1.25, (value, printed)
    np.testing.assert_allclose(ours, [1.2e-4, 7.2e-5, 8.9e-6, 8.5e-7, 1.1e-9, 8.6e-11], rtol=0.06)


def test_eq48_decreases_with_n_and_delta_in_every_dimension():
    for dim in (1, 2, 3):
        n0 = 77 * 7**dim
        assert alaric_min_error(10 * n0, 0.01, dim) < alaric_min_error(n0, 0.01, dim)
        assert alaric_min_error(n0, 0.1, dim) < alaric_min_error(n0, 0.01, dim)


@pytest.mark.parametrize("args", [(0, 0.1, 1), (10, -0.1, 1), (10, 0.1, 4), (2.5, 0.1, 1)])
def test_bad_input(args):
    with pytest.raises(ValueError):
        alaric_min_error(*args)
