"""SPHFIRE's two passes (numba, chunked) against numpy's arithmetic: the sums to round-off, the move bit for bit.

The passes are written for speed (two partial sums per product, the components in scalars); these tests hold
them to what ASE's FIRE computes, over odd chunk boundaries, 2D and 3D, every mode and both cuts."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.drivers.sph_optimizers import _fire_dots, _fire_move_norm, _fire_velocity_move


def _chunks(n, cuts):
    edges = sorted({0, n, *[min(c, n) for c in cuts]})
    return list(zip(edges[:-1], edges[1:]))


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 41), d=st.sampled_from([2, 3]), cuts=st.lists(st.integers(0, 41), max_size=3),
       seed=st.integers(0, 2**31))
def test_dots_are_the_sums(n, d, cuts, seed):
    rng = np.random.default_rng(seed)
    v_pc = rng.normal(size=(n, d))
    f_pc = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-8, 3)
    out = np.zeros(3)
    for first, last in _chunks(n, cuts):
        _fire_dots(v_pc, f_pc, d, out, first, last)
    f = f_pc[:, :d]
    expected = [np.sum(v_pc * f), np.sum(f * f), np.sum(v_pc * v_pc)]
    scale = [np.sum(np.abs(v_pc * f)), np.sum(f * f), np.sum(v_pc * v_pc)]
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-13 * max(max(scale), 1e-300))


def _reference(x_pc, v_pc, f_pc, mode, a, dt, maxstep, cap, d):
    """ASE's FIRE step in numpy (the same order of operations), then the cut of each particle's move."""
    f = f_pc[:, :d]
    ff, vv = float(np.sum(f * f)), float(np.sum(v_pc * v_pc))
    if mode == 0:
        v = np.zeros_like(v_pc)
    elif mode == 1:
        v = (1.0 - a) * v_pc + a * f / np.sqrt(ff) * np.sqrt(vv)
    else:
        v = v_pc * 0.0
    v = v + dt * f
    dr = dt * v
    normdr = float(np.sqrt(np.sum(dr * dr)))
    scaled = normdr > maxstep
    if scaled:
        dr = maxstep * dr / normdr
    length2 = dr[:, 0] * dr[:, 0] + dr[:, 1] * dr[:, 1] + (dr[:, 2] * dr[:, 2] if d == 3 else 0.0)
    shrink = np.ones(len(dr))
    if cap > 0.0:
        cut = length2 > cap * cap
        shrink[cut] = cap / np.sqrt(length2[cut])
    new = x_pc.copy()
    new[:, :d] = x_pc[:, :d] + dr * shrink[:, None]
    return v, new, normdr, scaled, float(np.max(length2 * shrink * shrink, initial=0.0))


@settings(max_examples=80, deadline=None)
@given(n=st.integers(1, 33), d=st.sampled_from([2, 3]), mode=st.sampled_from([0, 1, 2]),
       where=st.sampled_from(["buffer", "in_place", "in_place_keep_old", "into_forces"]),
       cap=st.sampled_from([0.0, 0.3, 1e-3]), maxstep=st.sampled_from([0.2, 1e-3]), cuts=st.lists(st.integers(0, 33)),
       seed=st.integers(0, 2**31))
def test_velocity_move_is_ase_fire(n, d, mode, where, cap, maxstep, cuts, seed):
    rng = np.random.default_rng(seed)
    x_pc = rng.random((n, 3))
    v_pc = rng.normal(size=(n, d))
    f_pc = rng.normal(size=(n, 3))
    a, dt = 0.1, 0.3
    v_ref, new_ref, normdr_ref, scaled_ref, longest2_ref = _reference(x_pc, v_pc, f_pc, mode, a, dt, maxstep, cap, d)
    f = f_pc[:, :d]
    vf, ff, vv = float(np.sum(v_pc * f)), float(np.sum(f * f)), float(np.sum(v_pc * v_pc))
    normdr = _fire_move_norm(mode, a, np.sqrt(ff), np.sqrt(vv), vf, ff, vv, dt)
    assert normdr == pytest.approx(normdr_ref, rel=1e-12, abs=1e-300)
    normdr = normdr_ref  # the pass given the same norm: its arithmetic is then ASE's bit for bit
    in_place = where.startswith("in_place")
    keep_old = where == "in_place_keep_old"
    x_old = x_pc.copy()
    v_work = v_pc.copy()
    f_work = f_pc.copy()
    new_pc = f_work if where == "into_forces" else np.full((n, 3), np.nan)
    out = np.zeros(1)
    for first, last in _chunks(n, cuts):
        _fire_velocity_move(x_pc, v_work, f_work, new_pc, mode, a, np.sqrt(ff), np.sqrt(vv), dt, scaled_ref,
                            maxstep, normdr, cap, d, in_place, keep_old, out, first, last)
    np.testing.assert_array_equal(v_work, v_ref)
    if in_place:
        np.testing.assert_array_equal(x_pc, new_ref)
        if keep_old:
            np.testing.assert_array_equal(new_pc, x_old)
        else:
            assert np.isnan(new_pc).all()  # not written
    else:
        np.testing.assert_array_equal(new_pc, new_ref)
        np.testing.assert_array_equal(x_pc, x_old)
    assert out[0] == longest2_ref
