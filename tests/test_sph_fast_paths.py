"""The cheaper paths of the H solve and the pressure pass (issue 20 item 4, 2D speed) against the general ones.

* the pairs over the first ``dims`` coordinates give the same sums and forces bit for bit (ASE positions of a
  d < 3 system have zeros beyond d);
* the power sums in a window of eight (count, u^low .. u^(low + 6)) give the moments of all nine powers, bit for bit;
* the first pass without activity flags equals the flagged pass with every flag set, bit for bit;
* the Taylor step's series for exp and log1p agree with the library to rounding.
"""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.polynomial import polynomial as P

from ase_sphrelax import sph
from ase_sphrelax.kernels import _derivative_in_q, get_kernel
from ase_sphrelax.neighbors import NeighborList

from test_sph import _system


def _solved(dim, periodic, kernel_name="wendland_c4", seed=3):
    r_pc, cell, pbc = _system(dim, {1: 60, 2: 14, 3: 6}[dim], periodic, seed=seed)
    kernel = get_kernel(kernel_name, dim)
    nlist = NeighborList(1.0, skin=0.3)
    state = sph.solve_smoothing_lengths(nlist, r_pc, cell, pbc, 1.0, kernel, tol=1e-12)
    nlist.update(r_pc, cell, pbc, cutoff=state.h_p)
    return r_pc, cell, pbc, kernel, nlist, state


@pytest.mark.parametrize("dim", [1, 2])
@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("masses", ["equal", "per-particle"])
def test_pressure_pass_over_d_coordinates_is_the_same(dim, periodic, masses):
    r_pc, cell, pbc, kernel, nlist, state = _solved(dim, periodic)
    n = len(r_pc)
    rng = np.random.default_rng(1)
    m_p = 1.0 if masses == "equal" else rng.uniform(0.5, 2.0, n)
    pr_p = rng.uniform(-1.0, 2.0, n)
    want_virial = periodic and masses == "equal"
    f_pc, virial = sph.pressure_forces(nlist, r_pc, m_p, state.h_p, pr_p, kernel, want_virial=want_virial)
    f_pd, virial_d = sph.pressure_forces(nlist, r_pc, m_p, state.h_p, pr_p, kernel, want_virial=want_virial,
                                         dims=dim)
    assert f_pd.shape == (n, dim)
    assert np.array_equal(f_pd, f_pc[:, :dim])
    assert not np.any(f_pc[:, dim:])
    assert np.array_equal(virial, virial_d)
    if want_virial:
        assert np.any(virial != 0.0)


@pytest.mark.parametrize("dims", [0, 4, 2.0, "2"])
def test_bad_dims_is_a_clear_error(dims):
    r_pc, cell, pbc, kernel, nlist, state = _solved(2, True)
    with pytest.raises(ValueError, match="dims must be"):
        sph.pressure_forces(nlist, r_pc, 1.0, state.h_p, np.ones(len(r_pc)), kernel, dims=dims)
    with pytest.raises(ValueError, match="dims must be"):
        sph.solve_smoothing_lengths(nlist, r_pc, cell, pbc, 1.0, kernel, dims=dims)


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("masses", [1.0, "per-particle"])
def test_solve_over_d_coordinates_is_the_same(dim, masses):
    r_pc, cell, pbc = _system(dim, {1: 60, 2: 14, 3: 6}[dim], True, seed=5)
    kernel = get_kernel("wendland_c4", dim)
    m = masses if masses == 1.0 else np.random.default_rng(2).uniform(0.8, 1.2, len(r_pc))
    h0 = sph.solve_smoothing_lengths(NeighborList(1.0, skin=0.3), r_pc, cell, pbc, m, kernel).h_p * 1.01
    full = sph.solve_smoothing_lengths(NeighborList(1.0, skin=0.3), r_pc, cell, pbc, m, kernel, h0=h0)
    part = sph.solve_smoothing_lengths(NeighborList(1.0, skin=0.3), r_pc, cell, pbc, m, kernel, h0=h0, dims=dim)
    for name in ("h_p", "rho_p", "n_p", "omega_p", "neighbours_p"):
        assert np.array_equal(getattr(full, name), getattr(part, name)), name
    assert full.iterations == part.iterations


@pytest.mark.parametrize("kernel_name", ["wendland_c2", "wendland_c4"])
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_power_window_gives_the_moments_of_all_powers(kernel_name, dim):
    """The window's moments against the combination of all nine power sums u^0..u^8 (gathered here directly):
    equal bit for bit (the left-out powers have zero coefficients in every moment)."""
    r_pc, cell, pbc, kernel, nlist, state = _solved(dim, True, kernel_name)
    table, low = sph._power_moments(kernel)
    assert low == (2 if (kernel_name == "wendland_c4" and dim > 1) else 1)
    full = np.zeros((5, sph.POWER_DEGREE + 1))
    for k in range(5):
        poly = P.polymul(P.polypow([1.0, -1.0], k), _derivative_in_q(kernel.coef[0], k))
        full[k, : len(poly)] = poly
    # every power the window leaves out has zero coefficients
    kept = [0] + list(range(low, low + sph.POWER_WINDOW))
    assert not np.any(np.delete(full, [j for j in kept if j <= sph.POWER_DEGREE], axis=1))
    # all nine power sums by brute force over the listed pairs (both orientations, the partner's own H)
    h_p = state.h_p
    x_sc = nlist.extend(r_pc).copy()
    src_s = nlist.src_s
    a_s = np.repeat(np.arange(len(nlist.pair_start) - 1), np.diff(nlist.pair_start))
    b_s = nlist.pair_j[: len(a_s)]
    r = np.linalg.norm(x_sc[b_s] - x_sc[a_s], axis=1)
    powers = np.zeros((len(r_pc), sph.POWER_DEGREE + 1))
    for one, other in ((a_s, b_s), (b_s, a_s)):
        q = r / h_p[src_s[one]]
        inside = q < 1.0
        u = np.where(inside, 1.0 - q, 0.0)
        np.add.at(powers, src_s[one][inside], u[inside, None] ** np.arange(sph.POWER_DEGREE + 1))
    moments = powers @ full.T  # (N, 5): sum_b q^k f^(k)
    rows = sph._solve_sums(nlist, r_pc, h_p, np.ones(len(r_pc)), True, np.ones(len(r_pc), dtype=bool), kernel)
    np.testing.assert_allclose(rows[0], moments[:, 0] + kernel.f0, rtol=1e-12)
    for k in range(1, 5):
        np.testing.assert_allclose(rows[k], moments[:, k], rtol=1e-10, atol=1e-10 * np.abs(moments[:, k]).max())
    np.testing.assert_array_equal(rows[6], powers[:, 0])


@pytest.mark.parametrize("dim", [2, 3])
def test_first_pass_without_flags_equals_the_flagged_pass(dim):
    r_pc, cell, pbc, kernel, nlist, state = _solved(dim, True)
    table, low = sph._power_moments(kernel)
    ih = 1.0 / state.h_p
    flagged = sph._interaction(f"solve_powers{low}", dim).compute(
        nlist, r_pc, inputs=dict(ih_s=ih, active_s=np.ones(len(r_pc), dtype=np.bool_)), reach=state.h_p.max()).sums
    flagged = flagged.copy()
    every = sph._interaction(f"solve_powers{low}_all", dim).compute(
        nlist, r_pc, inputs=dict(ih_s=ih), reach=state.h_p.max()).sums
    assert np.array_equal(flagged, every)


@settings(max_examples=300, deadline=None, database=None)
@given(st.one_of(st.floats(-0.05, 0.05), st.sampled_from([0.0, -0.0, 0.03, -0.03, 5e-324, 1e-300, 0.5, -0.5, 3.0])))
def test_exp_series_is_exp_to_rounding(x):
    assert math.isclose(sph._exp_small(x), math.exp(x), rel_tol=4e-16, abs_tol=0.0)


@settings(max_examples=300, deadline=None, database=None)
@given(st.one_of(st.floats(-0.02, 0.02), st.sampled_from([0.0, -0.0, 0.01, -0.01, 5e-324, 1e-300, 0.5, -0.5])))
def test_log1p_series_is_log1p_to_rounding(e):
    want = math.log1p(e)
    assert math.isclose(sph._log1p_small(e), want, rel_tol=4e-16, abs_tol=1e-320)
