"""Coarse-to-fine SPH-ParVI (sampling/coarse_to_fine.py; ``sample(..., coarse_to_fine=k)``): the budget, the split,
the stationary density."""
import warnings

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from ase_sphrelax.sampling.coarse_to_fine import child_counts, child_pattern, coarse_schedule, split_into_children
from ase_sphrelax.sampling.sampler import ParVISampler as _ParVISampler, variant_options
from ase_sphrelax.sampling.targets import gaussian_target
from parvi_rest import assert_rests_at_the_predicted_variance
from test_parvi_steps import assert_one_line_error_before_work
from ase_sphrelax.sampling import CLASSIC


def ParVISampler(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _ParVISampler(*args, **dict(CLASSIC, **kwargs))


@pytest.mark.parametrize("kwargs, message", [
    (dict(coarse_to_fine=1), "coarse_to_fine must be None or an integer >= 2 (final particles per coarse particle), "
                             "got 1"),
    (dict(coarse_to_fine=2.5), "coarse_to_fine must be None or an integer >= 2"),
    (dict(coarse_to_fine=True), "coarse_to_fine must be None or an integer >= 2"),
    (dict(coarse_to_fine=4, coarse_share=1.0), "coarse_share must be a number in (0, 1)"),
    (dict(coarse_to_fine=4, coarse_share=0), "coarse_share must be a number in (0, 1)"),
    (dict(coarse_to_fine=30), "coarse_to_fine=30: n // coarse_to_fine = 1 coarse particles; needs >= 2"),
    (dict(coarse_to_fine=2, coarse_share=0.99), "coarse_share=0.99: no step left"),
])
def test_bad_coarse_options_are_one_line_before_work(kwargs, message):
    assert_one_line_error_before_work(kwargs, message)


def test_coarse_level_too_small_for_an_adaptive_support_is_named():
    target = gaussian_target(np.zeros(3), np.eye(3))
    with pytest.raises(ValueError, match="coarse_to_fine=10: the coarse level's 5 particles") as info:
        ParVISampler(target.log_density, target.score, dim=3, n=50, coarse_to_fine=10)
    assert "\n" not in str(info.value)


def test_variant_name_coarse():
    assert variant_options("local+critical+coarse") == dict(time_step="local", friction="critical", coarse_to_fine=4,
                                                            score_every=1)  # issue 31: coarse needs a fixed cadence
    assert variant_options("coarse_to_fine=9+coarse_share=0.3") == dict(coarse_to_fine=9, coarse_share=0.3)


@settings(max_examples=300, deadline=None, database=None)
@given(n=st.integers(2, 200_000), steps=st.integers(1, 5000), factor=st.integers(2, 64),
       share=st.floats(0.01, 0.99))
def test_schedule_never_exceeds_the_budget(n, steps, factor, share):
    """``n_c S_c + n S_f <= n steps`` exactly (integers), and less than one step of each level is left unspent."""
    assume(n // factor >= 2)
    try:
        n_c, s_c, s_f = coarse_schedule(n, steps, factor, share)
    except ValueError as error:
        assert "no step left" in str(error)
        return
    assert n_c == n // factor and s_f >= 1 and s_c >= 0
    spent = n_c * s_c + n * s_f
    assert spent <= n * steps
    assert n * steps - spent < n_c + n


@settings(max_examples=200, deadline=None, database=None)
@given(n=st.integers(1, 5000), n_coarse=st.integers(1, 5000))
def test_child_counts_share_out_n(n, n_coarse):
    assume(n_coarse <= n)
    counts = child_counts(n, n_coarse)
    assert counts.sum() == n and counts.max() - counts.min() <= 1 and counts.min() >= 1


@settings(max_examples=200, deadline=None, database=None)
@given(parents=st.integers(1, 30), dim=st.integers(1, 4), seed=st.integers(0, 2**31),
       scale=st.sampled_from([0.0, 1e-8, 1.0, 1e6]), count=st.integers(1, 9), mixed=st.booleans())
def test_split_keeps_each_parent_as_its_childrens_mean(parents, dim, seed, scale, count, mixed):
    """Every parent's children: the right number, their mean the parent (to round-off), within the parent's
    rotated cube of volume V (|offset| <= sqrt(d) / 2 V^(1/d)) for a grid pattern and within twice it otherwise (the
    stratified points' mean removed), distinct when V > 0; V = 0 puts them on it."""
    rng = np.random.default_rng(seed)
    r_pc = 10.0 * rng.standard_normal((parents, dim))
    volume_p = scale * rng.uniform(0.5, 2.0, parents)
    counts_p = rng.integers(1, count + 1, parents) if mixed else np.full(parents, count)
    children = split_into_children(r_pc, volume_p, counts_p, seed=seed)
    assert children.shape == (counts_p.sum(), dim)
    start = 0
    for a in range(parents):
        kids = children[start:start + counts_p[a]]
        start += counts_p[a]
        side = volume_p[a] ** (1.0 / dim)
        np.testing.assert_allclose(kids.mean(axis=0), r_pc[a], rtol=0, atol=1e-12 * (10 + side) * counts_p[a])
        grid = round(counts_p[a] ** (1.0 / dim)) ** dim == counts_p[a]
        reach = (0.5 if grid else 1.0) * np.sqrt(dim) * side
        assert np.all(np.linalg.norm(kids - r_pc[a], axis=1) <= reach * (1 + 1e-9) + 1e-12)
        if volume_p[a] > 0 and counts_p[a] > 1:
            assert len(np.unique(kids, axis=0)) == counts_p[a]


def test_four_children_in_2d_are_the_fine_grid():
    """k = 4 in 2D: a 2 x 2 grid of the cell, spacing half the parent's side (the fine fluid's spacing)."""
    pattern = child_pattern(4, 2, np.random.default_rng(0))
    assert sorted(map(tuple, pattern)) == [(-0.25, -0.25), (-0.25, 0.25), (0.25, -0.25), (0.25, 0.25)]


@pytest.mark.parametrize("dim, n, steps", [(1, 300, 3000), (2, 500, 1200)])
def test_coarse_to_fine_keeps_the_stationary_density(dim, n, steps):
    """The fine level is the one-level fluid: the same resting variance as the one-level run and the predicted one
    (unit Gaussian: 1); both levels' evaluations are counted and stay within the budget of ``steps``."""
    target = gaussian_target(np.zeros(dim), np.eye(dim))
    out = {}
    for factor in (None, 4):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out[factor] = ParVISampler(target.log_density, target.score, dim=dim, n=n, steps=steps, seed=1,
                                       coarse_to_fine=factor).run()
    assert_rests_at_the_predicted_variance(out[4], out[None], dim)
    info = out[4].info["coarse"]
    n_c = n // 4
    assert (info["n"], info["steps"], info["fine_steps"]) == (n_c, 2 * steps, steps // 2)
    assert out[4].n_score == info["n_score"] + n * (steps // 2 + 1)  # fine level: the start and every step
    assert info["n_score"] == n_c * (2 * steps + 1)
    assert out[4].n_score <= out[None].n_score + n_c  # the budget: only the coarse start's evaluations on top
