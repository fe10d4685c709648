"""The baselines' one tuning rule (sampling/tuning.py): pilot over a log grid, scored by the kernel Stein discrepancy."""
import inspect

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.sampling import metrics, tuning
from ase_sphrelax.sampling.targets import Target


def _gaussian(sigma):
    return (lambda x: -0.5 * np.sum(x * x, axis=1) / sigma**2), (lambda x: -x / sigma**2)


def _ksd_brute(x, s, c, h=1e-5):
    """u_p(x_i, x_j) summed with the kernel's derivatives by central differences (Liu et al. 2016, eq. 8)."""
    k = lambda a, b: (c * c + np.sum((a - b) ** 2)) ** -0.5  # noqa: E731
    d = x.shape[1]
    e = np.eye(d) * h
    total = 0.0
    for i in range(len(x)):
        for j in range(len(x)):
            a, b = x[i], x[j]
            gx = np.array([(k(a + e[c_], b) - k(a - e[c_], b)) / (2 * h) for c_ in range(d)])
            gy = np.array([(k(a, b + e[c_]) - k(a, b - e[c_])) / (2 * h) for c_ in range(d)])
            tr = sum((k(a + e[c_], b + e[c_]) - k(a + e[c_], b - e[c_]) - k(a - e[c_], b + e[c_])
                      + k(a - e[c_], b - e[c_])) / (4 * h * h) for c_ in range(d))
            total += s[i] @ s[j] * k(a, b) + s[i] @ gy + s[j] @ gx + tr
    return total / len(x) ** 2


def test_ksd_matches_finite_differences():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((7, 3))
    s = rng.standard_normal((7, 3))
    assert tuning.kernel_stein_discrepancy(x, s, 0.7) == pytest.approx(_ksd_brute(x, s, 0.7), rel=1e-5, abs=1e-8)


def test_ksd_prefers_samples_of_the_target():
    _, score = _gaussian(1.0)
    x = np.random.default_rng(0).standard_normal((300, 2))
    good = tuning.kernel_stein_discrepancy(x, score(x), 1.0)
    shifted = tuning.kernel_stein_discrepancy(x + 0.5, score(x + 0.5), 1.0)
    narrow = tuning.kernel_stein_discrepancy(0.5 * x, score(0.5 * x), 1.0)
    assert good < shifted / 5 and good < narrow / 5


@settings(max_examples=40, deadline=None, database=None)
@given(st.integers(2, 12), st.integers(1, 4), st.floats(0.05, 5.0), st.integers(0, 10**6), st.booleans())
def test_ksd_is_a_nonnegative_quadratic_form(m, d, c, seed, coincide):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((m, d))
    if coincide:
        x[:] = x[0]  # degenerate: every point at one place
    s = rng.standard_normal((m, d))
    assert tuning.kernel_stein_discrepancy(x, s, c) >= -1e-12


def test_log_grid_is_half_decades():
    assert tuning.log_grid(1e-3, 1.0) == pytest.approx([1e-3, 10**-2.5, 1e-2, 10**-1.5, 0.1, 10**-0.5, 1.0])
    with pytest.raises(ValueError, match="low"):
        tuning.log_grid(0.0, 1.0)


@pytest.mark.parametrize("method", ["svgd", "ula", "mala"])
def test_tuning_follows_the_target_scale(method):
    """The same rule on N(c, sigma^2 I), started 3 sigma off the centre: wider targets get larger steps."""
    picked = {}
    for sigma in (0.1, 10.0):
        log_density, score = _gaussian(sigma)
        x0 = sigma * (3.0 + 0.3 * np.random.default_rng(1).standard_normal((40, 2)))
        result = tuning.tune(method, score, x0, 150, log_density=log_density, pilot_particles=40)
        picked[sigma] = result["value"]
        assert np.isfinite(result["ksd"])
        assert len(result["table"]) == len(tuning.log_grid(*tuning.GRIDS[method])) * (3 if method == "svgd" else 1)
    assert picked[10.0] > picked[0.1]


def test_tuning_sees_only_score_and_log_density(monkeypatch):
    """No reference samples: the signature takes none, and every metric against a reference is never called."""
    params = set(inspect.signature(tuning.tune).parameters)
    assert params == {"method", "score", "x0", "steps", "log_density", "pilot_particles", "pilot_steps"}

    def forbidden(*args, **kwargs):
        raise AssertionError("tuning used a reference-sample metric")

    for name in ("energy_distance", "sliced_wasserstein", "mean_error", "cov_error", "mode_weight_error"):
        if hasattr(metrics, name):
            monkeypatch.setattr(metrics, name, forbidden)
    monkeypatch.setattr(Target, "sample", property(lambda self: forbidden()), raising=False)
    calls = dict(score=0, log_density=0)
    log_density, score = _gaussian(1.0)

    def counted_score(x):
        calls["score"] += 1
        return score(x)

    def counted_log_density(x):
        calls["log_density"] += 1
        return log_density(x)

    x0 = np.random.default_rng(0).standard_normal((20, 2)) + 2.0
    for method in ("svgd", "ula", "mala"):
        tuning.tune(method, counted_score, x0, 20, log_density=counted_log_density, pilot_particles=20)
    assert calls["score"] > 0 and calls["log_density"] > 0


def test_tuning_rejects_bad_input():
    _, score = _gaussian(1.0)
    x0 = np.zeros((5, 2))
    with pytest.raises(ValueError, match="method"):
        tuning.tune("hmc", score, x0, 10)
    with pytest.raises(ValueError, match="log_density"):
        tuning.tune("mala", score, x0, 10)
    with pytest.raises(ValueError, match="x0"):
        tuning.tune("ula", score, np.zeros(5), 10)
