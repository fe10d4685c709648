"""SPHLBFGS's passes over its history (numba, in blocks of ``_BLOCK`` particles, chunked) against numpy.

The trajectory tests of ``test_sph_optimizers`` run on fewer particles than one block; these cover several blocks
per chunk, odd chunk boundaries and block ends, 2D and 3D."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.drivers.sph_optimizers import _BLOCK, _lbfgs_combine, _lbfgs_pair_dots


def _chunks(n, cuts):
    edges = sorted({0, n, *[min(c, n) for c in cuts]})
    return list(zip(edges[:-1], edges[1:]))


def _history(rng, m, n, d):
    return rng.normal(size=(m, n, d)), rng.normal(size=(m, n, d))


SIZES = st.sampled_from([1, 7, _BLOCK - 1, _BLOCK, _BLOCK + 1, 2 * _BLOCK + 13])
CUTS = st.lists(st.integers(0, 2 * _BLOCK + 13), max_size=3)


@settings(max_examples=25, deadline=None)
@given(n=SIZES, d=st.sampled_from([2, 3]), m=st.integers(1, 5), cuts=CUTS, seed=st.integers(0, 2**31))
def test_pair_dots_completes_the_pair_and_takes_every_dot(n, d, m, cuts, seed):
    rng = np.random.default_rng(seed)
    s_mpc, y_mpc = _history(rng, m, n, d)
    x_pc, f_pc = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    slot = int(rng.integers(m))
    s_ref, y_ref = s_mpc.copy(), y_mpc.copy()
    s_ref[slot] += x_pc[:, :d]
    y_ref[slot] -= f_pc[:, :d]
    g = -f_pc[:, :d]
    expected = np.array([[np.sum(s_ref[slot] * s_ref[j]), np.sum(s_ref[slot] * y_ref[j]),
                          np.sum(y_ref[slot] * s_ref[j]), np.sum(y_ref[slot] * y_ref[j]),
                          np.sum(g * s_ref[j]), np.sum(g * y_ref[j])] for j in range(m)]).ravel()
    out = np.zeros(6 * m)
    for first, last in _chunks(n, cuts):
        _lbfgs_pair_dots(s_mpc, y_mpc, slot, x_pc, f_pc, d, out, first, last)
    np.testing.assert_array_equal(s_mpc, s_ref)
    np.testing.assert_array_equal(y_mpc, y_ref)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12 * max(n * d, 1) * 10.0)


@settings(max_examples=25, deadline=None)
@given(n=SIZES, d=st.sampled_from([2, 3]), m=st.integers(1, 5), cuts=CUTS, seed=st.integers(0, 2**31),
       zero=st.booleans())
def test_combine_forms_the_step_in_the_oldest_slot(n, d, m, cuts, seed, zero):
    rng = np.random.default_rng(seed)
    s_mpc, y_mpc = _history(rng, m, n, d)
    f_pc = rng.normal(size=(n, 3))
    slot = int(rng.integers(m))
    cs, cy, cg = rng.normal(size=m), rng.normal(size=m), float(rng.normal())
    if zero:  # a pair with both coefficients zero (an empty slot before the history is full) is skipped
        cs[0] = cy[0] = 0.0
    z = cg * -f_pc[:, :d]
    for j in range(m):
        if cs[j] != 0.0 or cy[j] != 0.0:
            z = z + (cs[j] * s_mpc[j] + cy[j] * y_mpc[j])
    y_before = y_mpc.copy()
    others = [j for j in range(m) if j != slot]
    s_others = s_mpc[others].copy()
    out = np.zeros(1)
    for first, last in _chunks(n, cuts):
        _lbfgs_combine(f_pc, s_mpc, y_mpc, slot, cs, cy, cg, d, out, first, last)
    np.testing.assert_allclose(s_mpc[slot], z, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(s_mpc[others], s_others)
    np.testing.assert_array_equal(y_mpc, y_before)
    assert out[0] == pytest.approx(float(np.max(np.sum(s_mpc[slot] ** 2, axis=1))), rel=1e-15)
