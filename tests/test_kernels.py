"""Kernels: normalisation (quadrature), derivatives (finite differences), published constants."""
import math

import numba
import numpy as np
import pytest
from scipy.integrate import quad

from ase_sphrelax.kernels import KERNEL_NAMES, get_kernel, profile_value_and_slope

BUILT_IN = tuple(KERNEL_NAMES)  # the registry is live: kernels other test files register are not among these


@numba.njit(cache=True)
def _evaluate_generic(q_k, breaks, coef):
    out = np.empty((q_k.shape[0], 2))
    for k in range(q_k.shape[0]):
        out[k, 0], out[k, 1] = profile_value_and_slope(q_k[k], breaks, coef)
    return out


def _evaluate_closed(q_k, kernel, placeholder="kernel_profile"):
    function = kernel.closed_forms()[placeholder]
    return np.array([function(q) for q in q_k])


SURFACE = {1: lambda r: 2.0, 2: lambda r: 2 * math.pi * r, 3: lambda r: 4 * math.pi * r * r}


@pytest.mark.parametrize("name", BUILT_IN)
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_kernel_integrates_to_one(name, dim):
    kernel = get_kernel(name, dim)
    h = 0.37
    total, _ = quad(lambda r: kernel.w(r, h) * SURFACE[dim](r), 0, h, points=[h / 2], epsabs=1e-13)
    assert total == pytest.approx(1.0, abs=1e-10)


def test_published_normalisations():
    """Fan Sec. 2 (7/pi, 21/2pi), ALARIC footnote to Eq. 6 (3/2, 9/pi, 495/32pi), M4 spline (40/7pi, 8/pi)."""
    assert get_kernel("wendland_c2", 2).sigma == pytest.approx(7 / math.pi, rel=1e-13)
    assert get_kernel("wendland_c2", 3).sigma == pytest.approx(21 / (2 * math.pi), rel=1e-13)
    assert get_kernel("wendland_c4", 1).sigma == pytest.approx(3 / 2, rel=1e-13)
    assert get_kernel("wendland_c4", 2).sigma == pytest.approx(9 / math.pi, rel=1e-13)
    assert get_kernel("wendland_c4", 3).sigma == pytest.approx(495 / (32 * math.pi), rel=1e-13)
    assert get_kernel("cubic_spline", 2).sigma == pytest.approx(40 / (7 * math.pi), rel=1e-13)
    assert get_kernel("cubic_spline", 3).sigma == pytest.approx(8 / math.pi, rel=1e-13)


def test_wendland_c2_formula_as_fan_writes_it():
    kernel = get_kernel("wendland_c2", 2)
    h = 2.6
    r = np.linspace(0, 3.0, 31)
    q = r / h
    expected = np.where(q < 1, 7 / (math.pi * h**2) * (1 - q) ** 4 * (1 + 4 * q), 0.0)
    np.testing.assert_allclose(kernel.w(r, h), expected, rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("name", BUILT_IN)
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_derivative_matches_finite_differences(name, dim):
    kernel = get_kernel(name, dim)
    h, eps = 1.3, 1e-6
    r = np.linspace(0.01, 1.29, 57)
    numeric = (kernel.w(r + eps, h) - kernel.w(r - eps, h)) / (2 * eps)
    np.testing.assert_allclose(kernel.dw(r, h), numeric, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("name", BUILT_IN)
def test_w1_is_normalised_on_minus_h_to_h(name):
    kernel = get_kernel(name, 2)
    h = 0.8
    total, _ = quad(lambda r: kernel.w1(r, h), -h, h, points=[0, -h / 2, h / 2])
    assert total == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("name", BUILT_IN)
def test_w1_tail_integral_by_quadrature_and_derivative(name):
    """I(s) = int_s^h W1(max(r,0)) dr (Fan Eq. 3.5); dI/ds = -W1(max(s,0))."""
    kernel = get_kernel(name, 3)
    h = 1.7
    s = np.array([-2.0, -0.3, 0.0, 0.2, 0.85, 1.5, 1.7, 2.5])
    def reference_integral(x):
        kinks = [k for k in (0.0, h / 2) if x < k < h]  # kernel breakpoints inside (x, h)
        return quad(lambda r: kernel.w1(max(r, 0.0), h), x, h, points=kinks or None, epsabs=1e-14)[0]

    reference = [reference_integral(x) if x < h else 0.0 for x in s]
    np.testing.assert_allclose(kernel.w1_tail_integral(s, h), reference, rtol=1e-12, atol=1e-14)
    eps = 1e-6
    s_in = np.array([-0.5, 0.3, 1.0, 1.6])
    numeric = (kernel.w1_tail_integral(s_in + eps, h) - kernel.w1_tail_integral(s_in - eps, h)) / (2 * eps)
    np.testing.assert_allclose(numeric, -kernel.w1(np.maximum(s_in, 0), h), rtol=1e-6)


def test_bad_kernel_arguments():
    with pytest.raises(ValueError, match="dim"):
        get_kernel("wendland_c2", 4)
    with pytest.raises(ValueError, match="kernel"):
        get_kernel("gaussian", 2)


@pytest.mark.parametrize("name", BUILT_IN)
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_closed_forms_of_the_hot_loops_equal_the_exact_polynomials(name, dim):
    kernel = get_kernel(name, dim)
    q = np.linspace(0.0, 1.2, 241)
    closed = _evaluate_closed(q, kernel)
    generic = _evaluate_generic(q, kernel.breaks, kernel.coef)
    # profiles and slopes are O(1): compare at 1e-13 absolute (coefficient rounding)
    np.testing.assert_allclose(closed, generic, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(closed[:, 0], kernel.profile(q), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(closed[:, 1], kernel.profile_slope(q), rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("name", BUILT_IN)
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_higher_derivatives_match_finite_differences(name, dim):
    """kernel_derivatives' closed form: value and slope as kernel_profile's, f'', f''' and f'''' as central
    differences of f', f'' and f''' (f'''' away from the cubic spline's knot at q = 1/2, where f''' jumps)."""
    k = get_kernel(name, dim)
    e = 1e-6
    derivatives = k.closed_forms()["kernel_derivatives"]
    profile = k.closed_forms()["kernel_profile"]
    for q in np.linspace(0.013, 0.987, 60):
        value, slope, curv, third, fourth = derivatives(q)
        v0, s0 = profile(q)
        up = derivatives(q + e)
        down = derivatives(q - e)
        assert value == pytest.approx(v0, rel=1e-12, abs=1e-12)
        assert slope == pytest.approx(s0, rel=1e-12, abs=1e-12)
        assert curv == pytest.approx((up[1] - down[1]) / (2 * e), rel=1e-6, abs=1e-7)
        assert third == pytest.approx((up[2] - down[2]) / (2 * e), rel=1e-6, abs=1e-6)
        if abs(q - 0.5) > 2 * e:
            assert fourth == pytest.approx((up[3] - down[3]) / (2 * e), rel=1e-6, abs=1e-5)
    assert derivatives(1.0) == (0.0, 0.0, 0.0, 0.0, 0.0)


@pytest.mark.parametrize("name", BUILT_IN)
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_slope_over_q_is_the_slope_divided_by_q_and_its_limit_at_zero(name, dim):
    """kernel_slope_over_q (the pair forces' f'(q)/q, no division in the loops): equal to f'(q)/q away from
    0, to f''(0) at q = 0 (f'(0) = 0 for these smooth profiles), zero beyond the support."""
    k = get_kernel(name, dim)
    over_q = k.closed_forms()["kernel_slope_over_q"]
    derivatives = k.closed_forms()["kernel_derivatives"]
    for q in np.linspace(0.01, 1.2, 239):
        value, slope = k.closed_forms()["kernel_profile"](q)
        v, ratio = over_q(q)
        assert v == pytest.approx(value, rel=1e-13, abs=1e-14)
        assert ratio == pytest.approx(slope / q, rel=1e-11, abs=1e-12)
    assert over_q(0.0)[1] == pytest.approx(derivatives(0.0)[2], rel=1e-12)
    assert over_q(1e-9)[1] == pytest.approx(derivatives(0.0)[2], rel=1e-6)
    assert over_q(1.0) == (0.0, 0.0) and over_q(3.0) == (0.0, 0.0)
