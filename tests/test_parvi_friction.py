"""SPH-ParVI friction rules (sampling/friction.py; theory.py eqs. F1-F3) and the variant names."""
import warnings

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.sampling.friction import critical_drag, damp
from ase_sphrelax.sampling.sampler import ParVISampler as _ParVISampler, variant_options
from ase_sphrelax.sampling.targets import gaussian_target
from parvi_rest import assert_rests_at_the_predicted_variance
from test_parvi_steps import assert_one_line_error_before_work
from ase_sphrelax.sampling import CLASSIC


def ParVISampler(*args, **kwargs):
    """The classic configuration these tests were written for (issue 31 changed the default); keywords win."""
    return _ParVISampler(*args, **dict(CLASSIC, **kwargs))


@pytest.mark.parametrize("kwargs, message", [
    (dict(friction="fast"), "friction must be a finite number >= 0, None (1 / target scale) or one of 'critical', "
                            "got 'fast'"),
    (dict(friction=-1.0), "friction must be a finite number >= 0"),
    (dict(friction=float("nan")), "friction must be a finite number >= 0"),
    (dict(friction=True), "friction must be a finite number >= 0"),
    (dict(friction="critical", friction_every=0), "friction_every must be an integer >= 1, got 0"),
])
def test_bad_friction_is_one_line_before_work(kwargs, message):
    assert_one_line_error_before_work(kwargs, message)


@pytest.mark.parametrize("spec, message", [
    ("whiten+fast", "unknown token 'fast'"), ("friction=abc", "friction needs a number, got 'abc'"),
    ("", "variant must be a non-empty string"), ("whiten+", "unknown token ''"), ("steps=3", "unknown token"),
])
def test_bad_variant_names_are_one_line(spec, message):
    with pytest.raises(ValueError, match=message) as info:
        variant_options(spec)
    assert "\n" not in str(info.value)


def test_variant_names_are_the_sampler_options():
    assert variant_options("default") == {}
    assert variant_options("whiten+local+critical") == dict(whiten="covariance", time_step="local",
                                                            friction="critical")
    assert variant_options("local+friction=0.3+friction_every=20") == dict(time_step="local", friction=0.3,
                                                                           friction_every=20)


@pytest.mark.parametrize("dim, n, steps", [(1, 300, 3000), (2, 500, 1200)])
def test_critical_friction_keeps_the_stationary_density(dim, n, steps):
    """F1: the resting density does not depend on the friction: the same variance (and kurtosis) as the default's,
    and the predicted one (the unit Gaussian: 1)."""
    target = gaussian_target(np.zeros(dim), np.eye(dim))
    out = {}
    for friction in (None, "critical"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out[friction] = ParVISampler(target.log_density, target.score, dim=dim, n=n, steps=steps, seed=1,
                                         friction=friction).run()
    assert_rests_at_the_predicted_variance(out["critical"], out[None], dim)
    rates = out["critical"].info["friction_rates"]
    assert len(rates) == dim and all(1.0 < r < 3.0 for r in rates)  # 2 sqrt(curvature 1), from the particles


def test_critical_friction_rests_where_the_default_rests():
    """F1 on the discrete map: a state at rest under the default friction is a fixed point with the critical one."""
    target = gaussian_target(np.zeros(2), np.eye(2))
    rest = ParVISampler(target.log_density, target.score, dim=2, n=200, steps=1500, seed=2).run().samples
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = ParVISampler(target.log_density, target.score, dim=2, n=200, steps=200, seed=2, x0=rest,
                             friction="critical").run().samples
    assert np.max(np.abs(again - rest)) < 0.05 * rest.std()


def test_critical_rates_are_twice_the_root_curvature_of_a_gaussian():
    """Under p the Fisher matrix is the precision: rates 2 sqrt(eigenvalues of the precision) (alpha = 1), and
    scale with sqrt(alpha)."""
    cov = np.array([[1.0, 0.9], [0.9, 1.0]])
    target = gaussian_target(np.zeros(2), cov)
    x = target.sample(200000, np.random.default_rng(0))
    q_cc, rate_c = critical_drag(target.score(x), alpha=1.0)
    expected = 2.0 * np.sqrt(np.linalg.eigvalsh(np.linalg.inv(cov)))
    np.testing.assert_allclose(np.sort(rate_c), expected, rtol=0.02)
    np.testing.assert_allclose(np.sort(critical_drag(target.score(x), alpha=4.0)[1]), 2.0 * expected, rtol=0.02)
    assert critical_drag(np.zeros((5, 2)), 1.0) is None
    assert critical_drag(np.full((5, 2), np.nan), 1.0) is None


@settings(max_examples=40, deadline=None, database=None)
@given(d=st.integers(1, 4), seed=st.integers(0, 10**6), local=st.booleans(), zero=st.booleans())
def test_damping_is_the_exact_matrix_exponential_and_never_adds_energy(d, seed, local, zero):
    """``damp`` = exp(-B dt / 2) v with B = Q diag(rate) Q^T (F2: a contraction; v = 0 stays 0), per-particle
    steps included; degenerate inputs: zero rates, zero velocities, one dimension."""
    rng = np.random.default_rng(seed)
    g_pc = rng.standard_normal((7, d)) * rng.uniform(0.01, 10.0, d)
    drag = critical_drag(g_pc, alpha=rng.uniform(0.1, 3.0))
    v_pc = np.zeros((5, d)) if zero else rng.standard_normal((5, d))
    dt = rng.uniform(0.001, 2.0, (5, 1)) if local else float(rng.uniform(0.001, 2.0))
    out = damp(v_pc, dt, None, drag)
    q_cc, rate_c = drag
    b_cc = q_cc @ np.diag(rate_c) @ q_cc.T
    for a in range(5):
        step = dt[a, 0] if local else dt
        np.testing.assert_allclose(out[a], scipy.linalg.expm(-0.5 * step * b_cc) @ v_pc[a], rtol=1e-10, atol=1e-12)
    assert np.all(np.linalg.norm(out, axis=1) <= np.linalg.norm(v_pc, axis=1) * (1 + 1e-12))
    np.testing.assert_allclose(damp(v_pc, dt, 0.0, None), v_pc)  # friction 0: the paper's fluid
    for friction, rule in ((None, drag), (0.7, None)):  # out= (the sampler's in-place kicks): the same bits
        expected = damp(v_pc, dt, friction, rule)
        in_place = v_pc.copy()
        assert damp(in_place, dt, friction, rule, out=in_place) is in_place
        np.testing.assert_array_equal(in_place, expected)


def test_sphrelax_sample_runs_a_variant(tmp_path, capsys):
    from ase_sphrelax.cli import main

    out = tmp_path / "run"
    assert main(["sample", "--target", "correlated", "--n", "150", "--steps", "60", "--variant",
                 "whiten+local+critical", "--out", str(out), "--no-progress"]) == 0
    info = __import__("json").loads((out / "trace.json").read_text())["info"]
    assert info["whiten"] == "covariance" and info["time_step"] == "local" and info["friction"] == "critical"
    assert len(info["friction_rates"]) == 2


@pytest.mark.parametrize("args, message", [
    (["--variant", "whiten+fast"], "--variant: variant 'whiten+fast': unknown token 'fast'"),
    (["--variant", "critical", "--friction", "2"], "both set the friction"),
])
def test_sphrelax_sample_bad_variant_is_one_line(tmp_path, capsys, args, message):
    from ase_sphrelax.cli import main

    assert main(["sample", "--target", "gaussian", "--out", str(tmp_path), "--steps", "1", "--no-progress"]
                + args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
