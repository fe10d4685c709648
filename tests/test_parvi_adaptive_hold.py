"""SPH-ParVI with a per-particle score hold (``sample(..., score_every="adaptive")``): the mask of held particles,
the subset evaluated and counted, the budget in evaluations, the stationary density and the resting states."""
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.sampling.friction import ScoreMemory
from ase_sphrelax.sampling.sampler import HOLD_MAX, ParticleScoreMemory
from ase_sphrelax.sampling.sampler import ParVISampler as _ParVISampler
from ase_sphrelax.sampling.sampler import held_particles, variant_options
from ase_sphrelax.sampling.targets import gaussian_target
from parvi_rest import assert_rests_at_the_predicted_variance
from test_parvi_score_every import resting_state  # noqa: F401 (the fixture: a state at rest with K = 1)
from test_parvi_steps import assert_one_line_error_before_work
from ase_sphrelax.sampling import CLASSIC


def ParVISampler(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _ParVISampler(*args, **dict(CLASSIC, **kwargs))


@pytest.mark.parametrize("kwargs, message", [
    (dict(score_every="often"), "score_every must be an integer >= 1 (SPH steps per score evaluation) or 'adaptive'"),
    (dict(score_every="adaptive", hold_tolerance=0.0), "hold_tolerance must be a finite number > 0"),
    (dict(score_every="adaptive", hold_tolerance=np.inf), "hold_tolerance must be a finite number > 0"),
    (dict(score_every="adaptive", hold_tolerance="0.1"), "hold_tolerance must be a finite number > 0"),
    (dict(score_every="adaptive", hold_max=0), "hold_max must be an integer >= 1"),
    (dict(score_every="adaptive", hold_max=2.5), "hold_max must be an integer >= 1"),
    (dict(score_every="adaptive", coarse_to_fine=4), "score_every='adaptive' counts steps as evaluations"),
    (dict(score_every="adaptive", max_steps=10), "score_every='adaptive' counts steps as evaluations"),
])
def test_bad_adaptive_options_are_one_line_before_work(kwargs, message):
    assert_one_line_error_before_work(kwargs, message)


def test_variant_name_adaptive_hold():
    assert variant_options("local+critical+score_every=adaptive+hold_tolerance=0.2+hold_max=6") == dict(
        time_step="local", friction="critical", score_every="adaptive", hold_tolerance=0.2, hold_max=6)


def test_the_default_does_not_hold():
    target = gaussian_target(np.zeros(2), np.eye(2))
    sampler = ParVISampler(score=target.score, dim=2, n=50, steps=5)
    assert sampler.score_every == 1 and not sampler.adaptive_hold


@settings(max_examples=60, deadline=None, database=None)
@given(n=st.integers(1, 30), d=st.integers(1, 3), seed=st.integers(0, 2**31), flag=st.booleans())
def test_a_boolean_hold_is_that_of_score_memory(n, d, seed, flag):
    """``hold = True / False``: ParticleScoreMemory returns and counts exactly what ScoreMemory does."""
    rng = np.random.default_rng(seed)
    x, y = rng.standard_normal((n, d)), rng.standard_normal((n, d))
    a, b = (cls(score=lambda z: -z**3, dim=d, n=n) for cls in (ScoreMemory, ParticleScoreMemory))
    for target in (a, b):
        target.score(x)
        target.hold = flag
    np.testing.assert_array_equal(a.score(y), b.score(y))
    assert a.n_score == b.n_score


@settings(max_examples=80, deadline=None, database=None)
@given(n=st.integers(1, 30), d=st.integers(1, 3), seed=st.integers(0, 2**31), share=st.floats(0.0, 1.0),
       fd=st.booleans())
def test_a_held_mask_evaluates_only_the_others(n, d, seed, share, fd):
    """Held rows return their last score, uncounted; the target function is called on the other rows only and
    counted per row; with every row held nothing is called; with a mask the last score is the mixed one."""
    rng = np.random.default_rng(seed)
    calls = []

    def log_density(z):
        calls.append(len(z))
        return -0.25 * np.sum(z**4, axis=1)

    def score(z):
        calls.append(len(z))
        return -z**3

    target = ParticleScoreMemory(log_density=log_density if fd else None, score=None if fd else score, dim=d, n=n)
    evaluate = target.fd_score_or_nan if fd else target.score
    x, y = rng.standard_normal((n, d)), rng.standard_normal((n, d))
    evaluate(x)
    counted = (target.n_density if fd else target.n_score)
    calls.clear()
    held_p = rng.random(n) < share
    target.hold = held_p
    got = evaluate(y)
    fresh = int(np.sum(~held_p))
    np.testing.assert_allclose(got[held_p], -x[held_p]**3, atol=1e-6 if fd else 0)
    np.testing.assert_allclose(got[~held_p], -y[~held_p]**3, atol=1e-6 if fd else 0, rtol=1e-6 if fd else 0)
    np.testing.assert_array_equal(target.last_score, got)
    if fresh == 0:
        assert calls == []
    else:
        assert all(c == fresh for c in calls)  # the subset only (fd: 2 d calls of the subset)
    new = (target.n_density if fd else target.n_score) - counted
    assert new == (2 * d * fresh if fd else fresh)


def test_held_particles_rules():
    """Each condition alone triggers a fresh evaluation: the age, the displacement in H, in 1 / |s|, a NaN."""
    dr = np.array([[0.0, 0.0], [0.05, 0.0], [0.3, 0.0], [0.05, 0.0], [0.0, 0.0], [0.0, 0.0]])
    h = np.ones(6)
    s = np.array([[0.0, 1.0], [1.0, 0.0], [1.0, 0.0], [10.0, 0.0], [0.0, 0.0], [np.nan, 0.0]])
    age = np.array([0, 3, 0, 0, 8, 0])
    held = held_particles(dr, h, s, age, tolerance=0.1, hold_max=8)
    np.testing.assert_array_equal(held, [True, True, False, False, False, False])


@settings(max_examples=60, deadline=None, database=None)
@given(seed=st.integers(0, 2**31), tol=st.floats(1e-3, 10.0), hold_max=st.integers(1, 20))
def test_held_particles_never_hold_a_moved_or_old_particle(seed, tol, hold_max):
    rng = np.random.default_rng(seed)
    dr, s = rng.standard_normal((50, 2)) * rng.exponential(size=(50, 1)), rng.standard_normal((50, 2)) * 10
    h, age = rng.exponential(size=50), rng.integers(0, 2 * hold_max, 50)
    held = held_particles(dr, h, s, age, tol, hold_max)
    dist = np.linalg.norm(dr, axis=1)
    assert not np.any(held & (age >= hold_max))
    assert not np.any(held & (dist > tol * h))
    assert not np.any(held & (dist * np.linalg.norm(s, axis=1) > tol))
    zero = held_particles(np.zeros_like(dr), h, s, np.zeros(50, dtype=int), tol, hold_max)
    assert np.all(zero == (hold_max > 0))  # at rest and fresh: held


@pytest.mark.parametrize("steps", [20, 60])
def test_the_budget_is_the_evaluations(steps):
    """``steps`` evaluations per particle (plus the start), spent to within one step, or fewer when the run
    reaches ``(hold_max + 1) steps`` SPH steps first; more SPH steps than ``steps`` (the hold saves evaluations)."""
    target = gaussian_target(np.zeros(2), np.eye(2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = ParVISampler(score=target.score, dim=2, n=100, steps=steps, seed=0, score_every="adaptive").run()
    assert res.n_score < 100 * (steps + 2)
    assert steps < res.info["steps"] <= (HOLD_MAX + 1) * steps
    assert res.n_score >= 100 * (steps + 1) or res.info["steps"] == (HOLD_MAX + 1) * steps
    assert res.trace["step"][-1] == res.info["steps"]
    assert 0.0 <= res.info["hold_moved_share"] <= 1.0


@pytest.mark.parametrize("dim, n, steps", [(1, 300, 600), (2, 500, 400)])
def test_adaptive_hold_keeps_the_stationary_density(dim, n, steps):
    """The resting states are those of K = 1: the same variance as K = 1 (run for the same SPH steps as the
    adaptive run took) and the predicted one (unit Gaussian)."""
    target = gaussian_target(np.zeros(dim), np.eye(dim))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        held = ParVISampler(target.log_density, target.score, dim=dim, n=n, steps=steps, seed=1,
                            score_every="adaptive").run()
        one = ParVISampler(target.log_density, target.score, dim=dim, n=n, steps=held.info["steps"], seed=1).run()
    assert_rests_at_the_predicted_variance(held, one, dim)


@settings(max_examples=6, deadline=None, database=None)
@given(hold_max=st.integers(1, 12), tol=st.floats(0.01, 2.0), local=st.booleans())
def test_a_resting_state_stays_at_rest_with_an_adaptive_hold(resting_state, hold_max, tol, local):
    """Exact at rest: a state at rest with K = 1 is a fixed point of the map with the per-particle hold (no
    displacement, refreshed scores equal to the held ones), with global or local steps."""
    target, rest = resting_state
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = ParVISampler(target.log_density, target.score, dim=2, n=200, steps=10, seed=2, x0=rest,
                             score_every="adaptive", hold_max=hold_max, hold_tolerance=tol,
                             time_step="local" if local else "global").run().samples
    assert np.max(np.abs(again - rest)) < 0.02 * rest.std()


@pytest.mark.parametrize("k, local", [(2, False), (4, True)])
def test_an_infinite_tolerance_is_score_every(k, local):
    """``hold_max = K - 1`` with a tolerance no displacement reaches holds every particle for K - 1 steps after
    each evaluation: the trajectory of ``score_every=K`` (steps = K x evaluations), the same samples and count."""
    target = gaussian_target(np.zeros(2), np.eye(2))
    options = dict(seed=3, time_step="local" if local else "global")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fixed = ParVISampler(score=target.score, dim=2, n=80, steps=30 * k, score_every=k, **options).run()
        held = ParVISampler(score=target.score, dim=2, n=80, steps=30, score_every="adaptive", hold_max=k - 1,
                            hold_tolerance=1e300, **options).run()
    assert held.info["steps"] == 30 * k and held.n_score == fixed.n_score
    assert held.info["hold_moved_share"] == 0.0
    np.testing.assert_array_equal(held.samples, fixed.samples)
