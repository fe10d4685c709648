"""Bounded renewals of the whitening map (sampling/whitening.py, theory.py eq. W4; issue 18, items 1 and 3).

The renewal is a linear change of variables with the state carried over exactly (property test, including a
collapsed direction); only the map changes, shrinking by at most ``max_shrink`` per direction after the first renewal.
The stationary density in 1D and 2D with renewals is checked by ``test_parvi_whitening.py``
(``test_covariance_whitening_samples_the_target``); here the 10-D case that failed before at M = 100.
"""
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.checks import NotConvergedWarning
from ase_sphrelax.sampling import whitening
from ase_sphrelax.sampling.sampler import ParVISampler as _ParVISampler
from ase_sphrelax.sampling.targets import get_target
from ase_sphrelax.sampling.whitening import AffineMap
from ase_sphrelax.sampling import CLASSIC


def ParVISampler(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _ParVISampler(*args, **dict(CLASSIC, **kwargs))


def _cloud(rng, m, d, collapse):
    """m points in d dimensions with a random covariance; ``collapse`` shrinks one direction by that factor."""
    x = rng.standard_normal((m, d)) @ (rng.standard_normal((d, d)) + 2.0 * np.eye(d)).T
    x[:, 0] *= collapse
    return x + rng.standard_normal(d)


@settings(max_examples=40, deadline=None, database=None)
@given(d=st.integers(1, 6), seed=st.integers(0, 10**6), collapse=st.sampled_from([1.0, 1e-3, 1e-8, 30.0]),
       max_shrink=st.sampled_from([None, 1.0, 2.0, 10.0]))
def test_bounded_renewal_is_an_exact_change_of_variables(d, seed, collapse, max_shrink):
    rng = np.random.default_rng(seed)
    m = 3 * d + 5
    affine = AffineMap(np.zeros(d), np.eye(d), max_shrink=max_shrink)
    y, v = affine.renew(_cloud(rng, m, d, 1.0), rng.standard_normal((m, d)))[:2]  # the first renewal
    assert np.allclose(np.cov(y, rowvar=False), np.eye(d), atol=1e-9)  # not bounded
    y = _cloud(rng, m, d, collapse)  # the fluid moved in y
    x, v_x = affine.to_x(y), v @ affine.l_cc.T
    w_c = np.linalg.eigvalsh(np.atleast_2d(np.cov(y, rowvar=False)))
    rho = rng.uniform(0.5, 2.0, m)
    old_log_det = affine.log_det
    y2, v2, rho2 = affine.renew(y, v, rho)
    assert affine.renewals == 2
    # the same particles and velocities, up to the round-off of a (possibly ill-conditioned) map
    l_norm = np.abs(affine.l_cc).max()
    assert np.allclose(affine.to_x(y2), x, rtol=0, atol=1e-9 * (1 + np.abs(x).max() + l_norm * np.abs(y2).max()))
    assert np.allclose(v2 @ affine.l_cc.T, v_x, rtol=0, atol=1e-9 * (1 + np.abs(v_x).max() + l_norm * np.abs(v2).max()))
    assert np.allclose(rho2, rho * np.exp(affine.log_det - old_log_det), rtol=1e-12)
    # the covariance in the new y: 1 where the shrinking was within the bound (or it grew), the rest beyond it
    clipped = w_c if max_shrink is None else np.maximum(w_c, 1 / max_shrink)
    expected = np.sort(w_c / clipped)
    got = np.linalg.eigvalsh(np.atleast_2d(np.cov(y2, rowvar=False)))
    # the sample covariance of a whitened near-collinear cloud carries round-off growing as the square of the whitened
    # covariance's condition number kappa: a fixed 1e-6 failed 2 in 4000 random cases of this test (d = 6, collapse 30,
    # kappa 1.3e5: 1.1e-6); 1e-6 + 1e6 kappa^2 eps held with a 58x margin over 12000
    kappa = clipped.max() / clipped.min()
    assert np.allclose(got, expected, rtol=0, atol=1e-6 + 1e6 * kappa**2 * np.finfo(float).eps)


def test_bounded_renewal_within_the_bound_is_the_plain_renewal():
    rng = np.random.default_rng(3)
    bounded, plain = AffineMap(np.zeros(3), np.eye(3)), AffineMap(np.zeros(3), np.eye(3), max_shrink=None)
    y0 = _cloud(rng, 40, 3, 1.0)
    y1 = [affine.renew(y0, np.zeros_like(y0))[0] for affine in (bounded, plain)][0]
    assert np.allclose(bounded.l_cc, plain.l_cc, atol=0)
    y = y1 * np.array([3.0, 0.8, 1.1])  # the fluid moved (whitened: covariance I before): grew 9x, shrank 1.6x
    yb, yp = bounded.renew(y, np.zeros_like(y))[0], plain.renew(y, np.zeros_like(y))[0]
    assert np.allclose(bounded.l_cc, plain.l_cc, atol=1e-12) and np.allclose(yb, yp, atol=1e-12)
    assert np.allclose(np.cov(yb, rowvar=False), np.eye(3), atol=1e-12)


def test_max_shrink_rejects_bad_values():
    with pytest.raises(ValueError, match="max_shrink"):
        AffineMap(np.zeros(2), np.eye(2), max_shrink=0.5)


def _gaussian10d_run(m, max_shrink):
    target = get_target("gaussian10d")
    saved = whitening.RENEWAL_MAX_SHRINK
    whitening.RENEWAL_MAX_SHRINK = max_shrink
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotConvergedWarning)
            res = ParVISampler(target.log_density, target.score, dim=10, n=m, seed=0, steps=1000,
                               neighbours="knn", whiten="covariance").run()
    finally:
        whitening.RENEWAL_MAX_SHRINK = saved
    return np.diag(np.cov(res.samples, rowvar=False)) / np.diag(target.cov)


def test_knn_with_whitening_runs_at_100_particles_in_10d():
    """The 10-D Gaussian (condition number 100) at M = 100: every variance within 15 % with bounded renewals;
    with the map of the moment (unbounded) a renewal during the expansion collapsed it (0.07-0.78 measured)."""
    var_ratio = _gaussian10d_run(100, whitening.RENEWAL_MAX_SHRINK)
    assert np.all(np.abs(var_ratio - 1) < 0.15), var_ratio
    assert np.min(_gaussian10d_run(100, None)) < 0.5  # the failure the bound removes
