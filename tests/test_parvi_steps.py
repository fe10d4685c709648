"""SPH-ParVI with local time steps (``time_step="local"``; theory.py eqs. L1-L3)."""
import warnings

import numpy as np
import pytest

import ase_sphrelax
from ase_sphrelax.sampling import get_target
from ase_sphrelax.sampling.sampler import ParVISampler as _ParVISampler
from ase_sphrelax.sampling.targets import gaussian_target
from ase_sphrelax.sampling.theory import predicted_gaussian_moments
from ase_sphrelax.sampling import CLASSIC


def ParVISampler(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _ParVISampler(*args, **dict(CLASSIC, **kwargs))


def kurtosis(x):
    x = x - x.mean(axis=0)
    return float(np.mean((x**4).mean(axis=0) / (x**2).mean(axis=0) ** 2))


@pytest.mark.parametrize("kwargs, message", [
    (dict(time_step="block"), "time_step must be 'global' or 'local', got 'block'"),
    (dict(time_step=None), "time_step must be 'global' or 'local', got None"),
    (dict(time_step="local", dt=0.01), "time_step='local' takes each particle's CFL step: give dt=None"),
])
def test_bad_time_step_is_one_line_before_work(kwargs, message):
    assert_one_line_error_before_work(kwargs, message)


def assert_one_line_error_before_work(kwargs, message):
    """``sample(**kwargs)`` raises a one-line ValueError matching ``message`` before any score evaluation."""
    calls = []
    target = gaussian_target(np.zeros(2), np.eye(2))

    def score(x):
        calls.append(len(x))
        return target.score(x)

    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
        ase_sphrelax.sample(score=score, n=50, dim=2, **dict(CLASSIC, steps=5, **kwargs))
    assert "\n" not in str(info.value) and not calls


@pytest.mark.parametrize("dim, n, steps", [(1, 300, 3000), (2, 500, 1200)])
@pytest.mark.parametrize("alpha", [1.0, 2.0])
def test_local_steps_keep_the_stationary_density(dim, n, steps, alpha):
    """L2: the resting states do not depend on the steps: rho ~ p^(alpha/c0^2) (variance c0^2/alpha, kurtosis 3)."""
    target = gaussian_target(np.zeros(dim), np.eye(dim))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # 1D, alpha = 2: the global step's run is not judged converged either
        res = ParVISampler(target.log_density, target.score, dim=dim, n=n, alpha=alpha, c0=1.0, steps=steps, seed=1,
                           time_step="local").run()
    predicted = predicted_gaussian_moments("force", "isothermal", dim, alpha=alpha, c0=1.0)
    assert res.samples.var(axis=0).mean() == pytest.approx(predicted["variance"], rel=0.1)
    assert kurtosis(res.samples) == pytest.approx(3.0, rel=0.15)
    assert res.info["dt_median"] > res.info["dt_min"]  # the steps are per particle


def test_local_steps_rest_where_the_global_step_rests():
    """L2 on the discrete map: a state at rest under the global step is a fixed point of the local one."""
    target = gaussian_target(np.zeros(2), np.eye(2))
    rest = ParVISampler(target.log_density, target.score, dim=2, n=200, steps=1500, seed=2).run().samples
    again = ParVISampler(target.log_density, target.score, dim=2, n=200, steps=200, seed=2, x0=rest,
                         time_step="local").run().samples
    assert np.max(np.abs(again - rest)) < 0.05 * rest.std()


def test_cfl_steps_are_eq9_per_particle_and_never_below_the_global_step():
    target = gaussian_target(np.zeros(2), np.eye(2))
    sampler = ParVISampler(target.log_density, target.score, dim=2, n=200, steps=0)
    x = np.random.default_rng(3).standard_normal((200, 2))
    ev = sampler.model.evaluate(x, np.zeros_like(x))
    dt_p = sampler.model.cfl_steps(ev)
    accel_p = np.linalg.norm(ev.forces, axis=1) / ev.mass
    brute = [min(0.25 * np.sqrt(0.5 * h / a), 0.4 * 0.5 * h / (1.0 * 1.06)) for h, a in zip(ev.h, accel_p)]
    np.testing.assert_allclose(dt_p, brute, rtol=1e-12)
    assert dt_p.min() >= sampler.model.cfl_step(ev) * (1 - 1e-12)


def test_the_funnel_neck_no_longer_sets_the_step_of_all():
    """Item 2: with local steps the median particle's step is >= 10x the global (minimum) rule's."""
    target = get_target("funnel")
    x0 = np.random.default_rng(0).standard_normal((300, 2))
    sampler = ParVISampler(target.log_density, target.score, dim=2, n=300, x0=x0, steps=150, seed=0,
                           time_step="local")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = sampler.run()
    ev = sampler.model.evaluate(res.samples, np.zeros_like(res.samples))
    global_step = sampler.courant * sampler.model.cfl_step(ev)
    assert np.median(sampler.model.cfl_steps(ev, sampler.courant)) >= 10 * global_step
    assert res.info["dt_median"] >= 5 * res.info["dt_min"]
