"""Exact finishing kernels after the SPH-ParVI fluid (sampling/finish.py; theory.py eqs. G1-G5)."""
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from ase_sphrelax.checks import NotConvergedWarning
from ase_sphrelax.sampling import ParVISampler as _ParVISampler, sample as _sample
from ase_sphrelax.sampling.finish import check_finish, ellipsoid_frame, mala_finish, refill_radii
from ase_sphrelax.sampling.sampler import variant_options
from ase_sphrelax.sampling import CLASSIC


def ParVISampler(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _ParVISampler(*args, **dict(CLASSIC, **kwargs))


def sample(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _sample(*args, **dict(CLASSIC, **kwargs))


def _gaussian(cov):
    prec = np.linalg.inv(np.atleast_2d(cov))
    return (lambda x: -0.5 * np.einsum("pc,cd,pd->p", x, prec, x)), (lambda x: -x @ prec)


def _skewed_1d():
    """log p(x) = 3 x - e^x (x = log of a Gamma(3, 1) variable): skewed, log-density linear on one side."""
    return (lambda x: 3.0 * x[:, 0] - np.exp(x[:, 0])), (lambda x: 3.0 - np.exp(x)), \
        stats.loggamma(3.0)  # scipy's loggamma(c) is log of Gamma(c, 1)


def test_mala_finish_keeps_exact_samples_exact_in_1d():
    """G3: p-invariance. Exact draws of a skewed 1D target stay distributed as p (KS test)."""
    log_p, score, law = _skewed_1d()
    x = law.rvs(size=(4000, 1), random_state=np.random.default_rng(1))
    out, info = mala_finish(x, log_p, score, np.zeros(1), np.eye(1), 60, np.random.default_rng(2))
    assert np.mean(np.abs(out - x) > 0) > 0.5  # most particles moved
    assert stats.kstest(out[:, 0], law.cdf).pvalue > 1e-3
    assert 0.3 < info["acceptance"] < 1.0


def test_mala_finish_removes_a_known_bias_in_1d():
    """From a start of the wrong scale (twice p's sd, shifted), 200 steps reach p: the fluid's bias is removed."""
    log_p, score, law = _skewed_1d()
    start = law.rvs(size=(3000, 1), random_state=np.random.default_rng(3))
    start = 2.0 * (start - start.mean()) + start.mean() + 0.5
    assert stats.kstest(start[:, 0], law.cdf).pvalue < 1e-10
    out, _ = mala_finish(start, log_p, score, *ellipsoid_frame(start), 200, np.random.default_rng(4))
    assert stats.kstest(out[:, 0], law.cdf).pvalue > 1e-3


def test_sample_with_mala_finish_samples_p_in_1d_and_2d():
    """From particles of twice p's sd and shifted (``x0`` with ``steps=0``: the fluid returns them untouched), the
    finish of ``sample`` reaches p in 1D (no map: the particles' own frame) and 2D (correlated, the whitening map)."""
    for cov, whiten in ((np.eye(1), None), (np.array([[1.0, 0.8], [0.8, 1.0]]), "covariance")):
        log_p, score = _gaussian(cov)
        d = cov.shape[0]
        x0 = 2.0 * np.random.default_rng(10).standard_normal((800, d)) @ np.linalg.cholesky(cov).T + 0.5
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotConvergedWarning)
            res = sample(log_p, score, n=800, dim=d, seed=0, steps=0, x0=x0, whiten=whiten, finish="mala",
                         finish_steps=200)
        assert np.allclose(res.alternatives["fluid"], x0)
        var = np.diag(np.atleast_2d(np.cov(res.samples, rowvar=False)))
        assert np.allclose(var, np.diag(cov), rtol=0.15)
        assert np.all(np.abs(res.samples.mean(axis=0)) < 0.12)
        assert abs(np.corrcoef(res.samples, rowvar=False)[0, 1] - 0.8) < 0.05 if d == 2 else True
        assert stats.kstest(res.samples[:, 0], stats.norm.cdf).pvalue > 1e-3
        assert res.info["finish_info"]["n_score"] == res.info["finish_info"]["n_density"] == 800 * 201
        assert res.n_score == 800 * 202  # the fluid's one evaluation at the start, the finish's


def test_radial_refill_keeps_exact_samples_and_restores_a_shell_in_2d():
    """G1-G2: exact draws stay exact; particles on a ring of radius 1.4 with uniform angles get the exact radial law
    of the 2D unit Gaussian (Rayleigh) whatever their radius was."""
    log_p, _ = _gaussian(np.eye(2))
    rng = np.random.default_rng(5)
    x = rng.standard_normal((3000, 2))
    out, info = refill_radii(x, log_p, np.zeros(2), np.eye(2), 3, np.random.default_rng(6))
    assert stats.kstest(np.linalg.norm(out, axis=1), stats.rayleigh.cdf).pvalue > 1e-3
    assert np.allclose(out / np.linalg.norm(out, axis=1)[:, None], x / np.linalg.norm(x, axis=1)[:, None])
    angle = rng.uniform(0, 2 * np.pi, 3000)
    ring = 1.4 * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    out, info = refill_radii(ring, log_p, np.zeros(2), np.eye(2), 3, np.random.default_rng(7))
    assert info["radius_before"][1] < 1e-12
    assert stats.kstest(np.linalg.norm(out, axis=1), stats.rayleigh.cdf).pvalue > 1e-3
    assert 3 < info["evaluations"] < 40


def test_radial_refill_in_1d_is_exact_given_the_signs():
    """1D: the direction is the sign; with the signs in p's proportions the refill gives p (a skewed target)."""
    log_p, _, law = _skewed_1d()
    centre = 1.0
    share_above = law.sf(centre)
    n = 4000
    signs = np.where(np.arange(n) < round(share_above * n), 1.0, -1.0)
    x = (centre + 0.3 * signs)[:, None]
    out, _ = refill_radii(x, log_p, np.array([centre]), np.eye(1), 4, np.random.default_rng(8))
    assert stats.kstest(out[:, 0], law.cdf).pvalue > 1e-3


@settings(max_examples=20, deadline=None, database=None)
@given(st.integers(1, 4), st.integers(0, 10**6), st.sampled_from(["mala", "radial"]), st.booleans())
def test_finish_kernels_are_exact_for_a_linear_change_of_variables(d, seed, kind, degenerate):
    """G4: the kernel on ``A x + b`` for the target ``p(A^-1 (x - b))`` in the frame ``(A c + b, A L)`` is ``A`` times
    its result on x in ``(c, L)`` plus b, with the same random numbers (the log-densities differ by a constant)."""
    rng = np.random.default_rng(seed)
    a_cc = rng.standard_normal((d, d)) + 2.0 * np.eye(d)
    if degenerate:
        a_cc[:, 0] *= 1e-3
    b_c = 10.0 * rng.standard_normal(d)
    cov = np.eye(d) + 0.5 * np.diag(rng.uniform(0, 1, d))
    log_p, score = _gaussian(cov)
    a_inv = np.linalg.inv(a_cc)
    log_q = lambda x: log_p((x - b_c) @ a_inv.T) - math.log(abs(np.linalg.det(a_cc)))  # noqa: E731
    score_q = lambda x: score((x - b_c) @ a_inv.T) @ a_inv  # noqa: E731
    x = rng.standard_normal((40, d))
    c_c, l_cc = 0.1 * rng.standard_normal(d), np.linalg.cholesky(cov)
    if kind == "mala":
        out, _ = mala_finish(x, log_p, score, c_c, l_cc, 12, np.random.default_rng(seed + 1))
        out_q, _ = mala_finish(x @ a_cc.T + b_c, log_q, score_q, a_cc @ c_c + b_c, a_cc @ l_cc, 12,
                               np.random.default_rng(seed + 1))
    else:
        out, _ = refill_radii(x, log_p, c_c, l_cc, 2, np.random.default_rng(seed + 1))
        out_q, _ = refill_radii(x @ a_cc.T + b_c, log_q, a_cc @ c_c + b_c, a_cc @ l_cc, 2,
                                np.random.default_rng(seed + 1))
    back = (out_q - b_c) @ a_inv.T
    assert np.allclose(back, out, rtol=0, atol=1e-6 * (1 + np.abs(out).max()))
    assert np.max(np.abs(out - x)) > 1e-3  # something moved


def test_sample_with_a_fixed_map_and_finish_is_exact_for_a_linear_change_of_variables():
    """N(0, A A^T) with the map A fixed from the start and the finish = A times the samples of N(0, I)."""
    a_cc = np.array([[2.0, 0.0], [1.7, 0.3]])
    z = np.random.default_rng(9).standard_normal((120, 2))
    runs = []
    for cov, whiten, x0 in ((np.eye(2), np.eye(2), z), (a_cc @ a_cc.T, a_cc, z @ a_cc.T)):
        log_p, score = _gaussian(cov)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotConvergedWarning)
            runs.append(ParVISampler(log_p, score, dim=2, n=120, x0=x0, steps=60, whiten=whiten, seed=0,
                                     finish="mala", finish_steps=20).run())
    assert np.allclose(runs[1].samples, runs[0].samples @ a_cc.T, rtol=0, atol=1e-7)
    assert np.max(np.abs(runs[0].samples - runs[0].alternatives["fluid"])) > 1e-3


def test_no_finish_leaves_the_run_unchanged():
    """finish=None is the default: the same particles as before the option existed (no extra random numbers)."""
    log_p, score = _gaussian(np.eye(2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)
        plain = sample(log_p, score, n=80, dim=2, seed=3, steps=40)
        explicit = sample(log_p, score, n=80, dim=2, seed=3, steps=40, finish=None, finish_steps=7)
        finished = sample(log_p, score, n=80, dim=2, seed=3, steps=40, finish="radial", finish_steps=1)
    assert np.array_equal(plain.samples, explicit.samples)
    assert np.array_equal(plain.samples, finished.alternatives["fluid"])
    assert plain.info["finish"] is None and "finish_info" not in plain.info and "fluid" not in plain.alternatives


def test_finish_rejects_bad_input():
    log_p, score = _gaussian(np.eye(2))
    for kwargs, name in ((dict(finish="hmc"), "finish"), (dict(finish="mala", finish_steps=0), "finish_steps"),
                         (dict(finish="mala", finish_steps=2.5), "finish_steps"),
                         (dict(finish="mala", rule="optimal"), "rule")):
        with pytest.raises(ValueError, match=name):
            ParVISampler(log_p, score, dim=2, n=20, **kwargs)
    with pytest.raises(ValueError, match="log_density"):
        ParVISampler(None, score, dim=2, n=20, finish="mala")
    with pytest.raises(ValueError, match="score"):
        ParVISampler(log_p, None, dim=2, n=20, finish="mala")
    with pytest.raises(ValueError, match="centre"):
        refill_radii(np.zeros((3, 2)), log_p, np.zeros(2), np.eye(2), 1, np.random.default_rng(0))
    with pytest.raises(ValueError, match="singular"):
        ellipsoid_frame(np.ones((5, 3)))
    assert check_finish(None, 5, "optimal") == (None, 5)
    assert variant_options("knn+whiten+mala+finish_steps=50") == dict(neighbours="knn", whiten="covariance",
                                                                      finish="mala", finish_steps=50)
    assert variant_options("radial")["finish"] == "radial"
