"""SPH-ParVI with the score held over several SPH steps (``sample(..., score_every=K)``, multiple time steps):
the held score, the evaluations counted, the stationary density and the resting states."""
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.sampling.friction import ScoreMemory
from ase_sphrelax.sampling.sampler import ParVISampler as _ParVISampler, variant_options
from ase_sphrelax.sampling.targets import gaussian_target
from parvi_rest import assert_rests_at_the_predicted_variance
from test_parvi_steps import assert_one_line_error_before_work
from ase_sphrelax.sampling import CLASSIC


def ParVISampler(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _ParVISampler(*args, **dict(CLASSIC, **kwargs))


@pytest.mark.parametrize("value", [0, -2, 1.5, True, "4"])
def test_bad_score_every_is_one_line_before_work(value):
    assert_one_line_error_before_work(dict(score_every=value), "score_every must be an integer >= 1 (SPH steps per "
                                                               "score evaluation)")


def test_variant_name_score_every():
    assert variant_options("local+critical+score_every=4") == dict(time_step="local", friction="critical",
                                                                   score_every=4)


@settings(max_examples=60, deadline=None, database=None)
@given(n=st.integers(1, 40), other=st.integers(1, 40), d=st.integers(1, 3), seed=st.integers(0, 2**31))
def test_a_held_score_is_the_last_one_and_costs_nothing(n, other, d, seed):
    """``hold``: the last score of n points again, uncounted; other sizes (and no last score) are evaluated."""
    rng = np.random.default_rng(seed)
    target = ScoreMemory(score=lambda x: -x**3, dim=d, n=n)
    x, y = rng.standard_normal((n, d)), rng.standard_normal((n, d))
    target.hold = True
    np.testing.assert_array_equal(target.score(x), -x**3)  # nothing held yet: evaluated
    assert target.n_score == n
    np.testing.assert_array_equal(target.score(y), -x**3)  # held: x's score, not y's
    assert target.n_score == n
    z = rng.standard_normal((other, d))
    if other != n:
        np.testing.assert_array_equal(target.score(z), -z**3)
        assert target.n_score == n + other
    target.hold = False
    np.testing.assert_array_equal(target.score(y), -y**3)
    assert target.n_score == (2 * n if other == n else 2 * n + other)


@pytest.mark.parametrize("k", [2, 5])
def test_evaluations_are_one_per_k_steps(k):
    target = gaussian_target(np.zeros(2), np.eye(2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = ParVISampler(score=target.score, dim=2, n=100, steps=20 * k, seed=0, score_every=k).run()
    assert res.n_score == 100 * (20 + 1)  # the start and every K-th step


@pytest.mark.parametrize("dim, n, steps", [(1, 300, 3000), (2, 500, 1200)])
def test_held_score_keeps_the_stationary_density(dim, n, steps):
    """The resting states are those of K = 1: the same variance as K = 1 and the predicted one (unit Gaussian: 1),
    with K = 4 at the same number of SPH steps."""
    target = gaussian_target(np.zeros(dim), np.eye(dim))
    out = {}
    for k in (1, 4):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out[k] = ParVISampler(target.log_density, target.score, dim=dim, n=n, steps=steps, seed=1,
                                  score_every=k).run()
    assert_rests_at_the_predicted_variance(out[4], out[1], dim)


@pytest.fixture(scope="module")
def resting_state():
    target = gaussian_target(np.zeros(2), np.eye(2))
    return target, ParVISampler(target.log_density, target.score, dim=2, n=200, steps=2000, seed=2).run().samples


@settings(max_examples=6, deadline=None, database=None)
@given(k=st.integers(1, 12), local=st.booleans())
def test_a_resting_state_stays_at_rest_with_a_held_score(resting_state, k, local):
    """Exact at rest: a state at rest with K = 1 is a fixed point of the map with any K (held score = fresh score
    at unchanged positions), with global or local steps."""
    target, rest = resting_state
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = ParVISampler(target.log_density, target.score, dim=2, n=200, steps=10 * k, seed=2, x0=rest,
                             score_every=k, time_step="local" if local else "global").run().samples
    assert np.max(np.abs(again - rest)) < 0.02 * rest.std()
