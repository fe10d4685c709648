"""SPH-ParVI in whitened coordinates (sampling/whitening.py, theory.py eqs. W1-W3)."""
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.checks import NotConvergedWarning
from ase_sphrelax.sampling import ParVISampler as _ParVISampler, sample as _sample
from ase_sphrelax.sampling.whitening import AffineMap
from ase_sphrelax.sampling import CLASSIC


def ParVISampler(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _ParVISampler(*args, **dict(CLASSIC, **kwargs))


def sample(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _sample(*args, **dict(CLASSIC, **kwargs))

A = np.array([[2.0, 0.0], [1.7, 0.3]])  # correlation 0.985, scales 2 and 1.72


def _gaussian(cov):
    prec = np.linalg.inv(cov)
    return (lambda x: -0.5 * np.einsum("pc,cd,pd->p", x, prec, x)), (lambda x: -x @ prec)


def _run(cov, whiten, x0, steps=120):
    log_density, score = _gaussian(cov)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)
        return ParVISampler(log_density, score, dim=x0.shape[1], n=len(x0), x0=x0, steps=steps, whiten=whiten,
                            seed=0).run()


def test_whitening_is_exact_for_a_linear_change_of_variables():
    """N(0, A A^T) with the map A fixed from the start = A times the samples of N(0, I), up to round-off."""
    z = np.random.default_rng(5).standard_normal((150, 2))
    unit = _run(np.eye(2), np.eye(2), z)
    mapped = _run(A @ A.T, A, z @ A.T)
    assert np.allclose(mapped.samples, unit.samples @ A.T, rtol=0, atol=1e-7)
    assert mapped.info["friction"] == pytest.approx(unit.info["friction"], rel=1e-9)
    assert np.max(np.abs(unit.samples - z)) > 0.01  # the particles moved: the comparison means something


def test_identity_map_changes_nothing():
    z = np.random.default_rng(6).standard_normal((100, 2))
    plain = _run(np.eye(2), None, z, steps=60)
    identity = _run(np.eye(2), np.eye(2), z, steps=60)
    assert np.allclose(plain.samples, identity.samples, rtol=0, atol=1e-12)


@settings(max_examples=25, deadline=None, database=None)
@given(st.integers(1, 4), st.integers(0, 10**6), st.booleans())
def test_pull_back_score_is_the_gradient_of_the_pull_back_log_density(d, seed, degenerate):
    """Eqs. W1, W2 against central differences, including a nearly singular map."""
    rng = np.random.default_rng(seed)
    l_cc = rng.standard_normal((d, d)) + 2.0 * np.eye(d)
    if degenerate:
        l_cc[:, 0] *= 1e-3
    cov = np.eye(d) + 0.5 * np.diag(rng.uniform(0, 1, d))
    log_density, score = _gaussian(cov)
    affine = AffineMap(rng.standard_normal(d), l_cc)
    y = rng.standard_normal((3, d))
    lp, s = affine.log_density_y(log_density), affine.score_y(score)
    step = 1e-5
    fd = np.stack([(lp(y + step * e) - lp(y - step * e)) / (2 * step) for e in np.eye(d)], axis=1)
    assert np.allclose(s(y), fd, rtol=1e-5, atol=1e-6)
    assert np.allclose(affine.to_y(affine.to_x(y)), y, atol=1e-9)


def test_renewal_carries_the_state_over_exactly():
    rng = np.random.default_rng(2)
    affine = AffineMap(np.zeros(2), np.eye(2))
    y = rng.standard_normal((50, 2)) @ A.T + 3.0
    v = rng.standard_normal((50, 2))
    x, vx = affine.to_x(y), v @ affine.l_cc.T
    y2, v2, _ = affine.renew(y, v)
    assert np.allclose(affine.to_x(y2), x, atol=1e-12)
    assert np.allclose(v2 @ affine.l_cc.T, vx, atol=1e-12)  # the same velocity in x
    assert np.allclose(np.cov(y2, rowvar=False), np.eye(2), atol=1e-12)  # whitened


@pytest.mark.parametrize("dim", [1, 2])
def test_covariance_whitening_samples_the_target(dim):
    """The renewed, then frozen, map: mean and covariance of a correlated, shifted Gaussian within 10 %."""
    cov = np.array([[4.0]]) if dim == 1 else A @ A.T
    centre = np.full(dim, 3.0)
    prec = np.linalg.inv(cov)
    res = sample(lambda x: -0.5 * np.einsum("pc,cd,pd->p", x - centre, prec, x - centre),
                 lambda x: -(x - centre) @ prec, n=300 if dim == 2 else 100, dim=dim, seed=1, whiten="covariance",
                 steps=400 if dim == 2 else 1600)  # 1D: the CFL step is short (as without whitening)
    x = res.samples
    scale = np.sqrt(np.diag(cov))
    assert np.all(np.abs(x.mean(axis=0) - centre) < 0.1 * scale)
    assert np.allclose(np.cov(x, rowvar=False), cov, rtol=0.1, atol=0.1 * scale.max() ** 2)


def test_whiten_rejects_bad_input():
    for bad in ("chol", np.ones((2, 2)), np.eye(3)):
        with pytest.raises(ValueError, match="whiten"):
            ParVISampler(score=lambda x: -x, dim=2, n=50, whiten=bad)
    with pytest.raises(ValueError, match="whiten_every"):
        ParVISampler(score=lambda x: -x, dim=2, n=50, whiten="covariance", whiten_every=0)
    with pytest.raises(ValueError, match="whiten_until"):
        ParVISampler(score=lambda x: -x, dim=2, n=50, whiten="covariance", whiten_until=1.5)
