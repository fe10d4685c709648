"""SPH-ParVI says when it has not converged, and checks its target before any work (issue 22: problems 1, 2, 7).

Every run here either reports ``converged`` True and is then right (within its standard errors of the
method's stationary state), or reports False with a reason and a :class:`NotConvergedWarning`.
"""
import json
import sys
import textwrap
import warnings

import numpy as np
import pytest

from ase_sphrelax.checks import NotConvergedWarning
from ase_sphrelax.cli import main
from ase_sphrelax.sampling import CLASSIC
from ase_sphrelax.sampling.convergence import assess_convergence, ensemble_moments
from ase_sphrelax.sampling.sampler import ParVIDivergence, ParVISampler
from ase_sphrelax.sampling.targets import gaussian_target


def _gaussian(mean, sd):
    mean = np.asarray(mean, dtype=float)
    return gaussian_target(mean, np.eye(len(mean)) * sd**2)


def _run(target, **kwargs):
    """Run in the configuration these tests were written for (CLASSIC, issue 31) and return (result, the
    NotConvergedWarnings raised)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = ParVISampler(target.log_density, target.score, dim=target.dim, **dict(CLASSIC, **kwargs)).run()
    return res, [w for w in caught if issubclass(w.category, NotConvergedWarning)]


def _assert_honest(res, caught, mean, sd):
    """Converged: mean and sd within 4 standard errors of the truth; otherwise a warning with the reason."""
    if res.info["converged"]:
        x = res.samples
        se = sd / np.sqrt(len(x))
        assert np.all(np.abs(x.mean(axis=0) - mean) < 4 * se)
        assert np.all(np.abs(x.std(axis=0) - sd) < 4 * se / np.sqrt(2) + 0.03 * sd)  # SPH's own O(1/M) bias aside
        assert not caught
    else:
        assert len(caught) == 1 and res.info["convergence_reason"] in str(caught[0].message)


# -- the diagnostics themselves --------------------------------------------------------------------
def _synthetic(path):
    """Recorded states of a 1D ensemble whose particles are ``path(t) * z`` (z fixed): its sd follows path."""
    z = np.random.default_rng(0).standard_normal((400, 1))
    z = (z - z.mean()) / z.std()
    steps = np.arange(0, 401, 10)
    moments = [np.concatenate(ensemble_moments(path(s / 400) * z)) for s in steps]
    return steps, steps / 100.0, np.zeros(len(steps)), moments, path(1.0) * z


def test_diagnostics_pass_a_state_at_rest_and_flag_a_slow_approach():
    at_rest = assess_convergence(*_synthetic(lambda t: 1.0 + 0.5 * np.exp(-40 * t)))
    assert at_rest["converged"], at_rest["reason"]
    # sd 1.06 -> 1: each quarter moves it by well under a standard error (0.035 in variance), but the
    # exponential approach has most of its way still to go: the projection sees it
    slow = assess_convergence(*_synthetic(lambda t: 1.0 + 0.1 * np.exp(-0.5 * t)))
    assert not slow["converged"] and "projected" in slow["reason"]
    rising = assess_convergence(*_synthetic(lambda t: 1.0 + t))
    assert not rising["converged"] and "not slowing down" in rising["reason"]
    short = assess_convergence(np.array([0, 10]), np.array([0.0, 1.0]), np.zeros(2),
                               [np.zeros(2), np.zeros(2)], np.zeros((10, 1)))
    assert not short["converged"] and "too short" in short["reason"]


# -- problem 1: the "optimal state" rule returned the untouched start silently --------------------------
def test_optimal_rule_returning_the_start_is_not_converged():
    target = _gaussian([3.0, 3.0], 1.0)
    res, caught = _run(target, n=100, steps=80, rule="optimal", seed=0)
    if res.info["chosen_step"] == 0:  # the paper's rule: the clumped random start has the largest mean density
        assert not res.info["converged"]
        assert "initial particles, untouched" in res.info["convergence_reason"]
    _assert_honest(res, caught, target.mean, 1.0)


def test_cli_optimal_rule_exits_non_zero_and_says_which_step(tmp_path, capsys, monkeypatch):
    from ase_sphrelax.cli import sample as sample_cli

    out = tmp_path / "banana"  # the stopping rule (classic), short for the test
    code = main(["sample", "--target", "banana", "--n", "200", "--rule", "optimal", "--variant", "classic", "--steps",
                 "80", "--max-steps", "160", "--out", str(out), "--no-progress"])
    summary = json.loads((out / "summary.json").read_text())
    captured = capsys.readouterr()
    if summary["chosen_step"] == 0:
        assert "the state of step 0" in captured.out
    assert code == (0 if summary["converged"] else sample_cli.EXIT_NOT_CONVERGED)
    assert not summary["converged"] and summary["convergence_reason"] in captured.err
    assert summary["seed"] == 0 and summary["target"] == "banana" and summary["parameters"]["rule"] == "optimal"
    # a fixed number of steps asked for: exit 0, the verdict still recorded
    code = main(["sample", "--target", "banana", "--n", "200", "--rule", "optimal", "--steps", "80", "--variant",
                 "classic", "--out", str(tmp_path / "fixed"), "--no-progress"])
    assert code == 0
    assert json.loads((tmp_path / "fixed" / "summary.json").read_text())["converged"] is False


# -- problem 2: unconverged runs said nothing -----------------------------------------------------------
@pytest.mark.parametrize("mean, sd", [([0.0, 0.0], 1e6), ([100.0, 100.0], 1.0)])
def test_far_or_wide_targets_start_at_their_scale_or_say_so(mean, sd):
    target = _gaussian(mean, sd)
    res, caught = _run(target, n=150, steps=300, seed=1)  # the start from the target's score: converges
    assert res.info["converged"], res.info["convergence_reason"]
    _assert_honest(res, caught, target.mean, sd)
    old, caught = _run(target, n=150, steps=300, seed=1, init_scale=1.0)  # the old N(0, I) start
    _assert_honest(old, caught, target.mean, sd)
    assert not old.info["converged"]


def test_one_dimensional_default_length_is_honest():
    """1D, M = 300: 600 CFL steps are one time unit and the sd ends 5 % high; 3000 steps relax it."""
    target = _gaussian([0.0], 1.0)
    res, caught = _run(target, n=300, seed=0)
    _assert_honest(res, caught, target.mean, 1.0)
    assert not res.info["converged"] and "damping time" in res.info["convergence_reason"]
    ruled, caught = _run(target, n=300, seed=0, max_steps=9600)  # the stopping rule: 600, 1200, ... steps
    assert ruled.info["converged"], ruled.info["convergence_reason"]
    assert 600 < ruled.info["steps"] <= 9600 and ruled.info["steps"] == ruled.trace["step"][-1]
    _assert_honest(ruled, caught, target.mean, 1.0)


@pytest.mark.parametrize("kwargs, words", [(dict(formulation="pressure-log"), ("kinetic energy rising", "still moves")),
                                           (dict(eos="tait"), ("still moves",))])
def test_paper_variants_that_do_not_settle_say_so(kwargs, words):
    target = _gaussian([0.0, 0.0], 1.0)
    res, caught = _run(target, n=150, steps=300, seed=0, **kwargs)
    assert not res.info["converged"]
    assert any(w in res.info["convergence_reason"] for w in words)
    assert len(caught) == 1


# -- problem 7: inconsistent derivatives and a wrong initial scale ---------------------------------------
def test_score_of_another_target_is_an_error_naming_score():
    p, q = _gaussian([0.0, 0.0], 1.0), _gaussian([2.0, -1.0], 0.5)
    with pytest.raises(ValueError, match="score does not match the gradient of log_density.*different targets"):
        ParVISampler(p.log_density, q.score, n=50, steps=5).run()


@pytest.mark.parametrize("with_density", [False, True])
def test_wrong_sign_score_is_an_error_naming_score(with_density):
    p = _gaussian([0.0, 0.0], 1.0)
    with pytest.raises(ValueError, match="^score: .*sign"):
        ParVISampler(p.log_density if with_density else None, lambda x: -p.score(x), n=50, steps=5).run()


def test_tiny_target_starts_at_its_scale_and_a_forced_wide_start_names_the_scale():
    target = _gaussian([0.0, 0.0], 1e-6)
    res, caught = _run(target, n=150, steps=300, seed=2)
    _assert_honest(res, caught, target.mean, 1e-6)
    unit, _ = _run(_gaussian([0.0, 0.0], 1.0), n=150, steps=300, seed=2)
    # start, friction and CFL step all scale with the target: the run is the unit run shrunk by 1e-6
    np.testing.assert_allclose(res.samples, 1e-6 * unit.samples, rtol=1e-5, atol=1e-12)
    assert res.info["converged"] == unit.info["converged"]
    with pytest.raises(ParVIDivergence, match=r"target's scale.*1\.e-06.*leave init_scale and x0 unset"):
        ParVISampler(target.log_density, target.score, n=150, init_scale=1.0, **dict(CLASSIC, steps=300)).run()


def test_tiny_target_with_only_a_log_density_differences_at_its_scale():
    """Central differences of log p with a step of 1e-5 see nothing of a target of sd 1e-6."""
    target = _gaussian([3e-6, 0.0], 1e-6)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = ParVISampler(log_density=target.log_density, n=150, seed=2, **dict(CLASSIC, steps=300)).run()
    _assert_honest(res, [w for w in caught if issubclass(w.category, NotConvergedWarning)], target.mean, 1e-6)
    assert res.info["converged"], res.info["convergence_reason"]


@pytest.fixture
def mismatched_module(tmp_path, monkeypatch):
    (tmp_path / "mismatched_target.py").write_text(textwrap.dedent("""
        import numpy as np
        def log_density(x):
            return -0.5 * np.sum(x ** 2, axis=1)
        def score(x):
            return -(x - 3.0)
        def minus_score(x):
            return x
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "mismatched_target"
    sys.modules.pop("mismatched_target", None)


@pytest.mark.parametrize("score, message", [("score", "does not match"), ("minus_score", "sign")])
def test_cli_inconsistent_target_is_one_line_exit_2(tmp_path, capsys, mismatched_module, score, message):
    code = main(["sample", "--target", f"{mismatched_module}:log_density", "--score", f"{mismatched_module}:{score}",
                 "--dim", "2", "--n", "50", "--steps", "5", "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1


@pytest.fixture
def truncated_module(tmp_path, monkeypatch):
    (tmp_path / "truncated_target.py").write_text(textwrap.dedent("""
        import numpy as np
        def log_density(x):  # zero density beyond |x| = 3
            lp = -0.5 * np.einsum("pc,pc->p", x, x)
            return np.where(np.linalg.norm(x, axis=1) < 3.0, lp, -np.inf)
        def nan_far(x):  # a bug: NaN beyond |x| = 2.5
            lp = -0.5 * np.einsum("pc,pc->p", x, x)
            return np.where(np.linalg.norm(x, axis=1) < 2.5, lp, np.nan)
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "truncated_target"
    sys.modules.pop("truncated_target", None)


def test_cli_divergence_and_a_nan_target_are_one_line(tmp_path, capsys, truncated_module):
    from ase_sphrelax.cli import sample as sample_cli

    # 1/(alpha (p + eps)) jumps to 1/(alpha eps) where p = 0: the paper's pressure diverges at once
    out = tmp_path / "div"
    code = main(["sample", "--target", f"{truncated_module}:log_density", "--dim", "2", "--n", "200", "--formulation",
                 "pressure-inverse", "--steps", "80", "--variant", "classic", "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert code == sample_cli.EXIT_NOT_CONVERGED and "diverged at step" in err and len(err.strip().splitlines()) == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["converged"] is False and "diverged" in summary["convergence_reason"]
    code = main(["sample", "--target", f"{truncated_module}:nan_far", "--dim", "2", "--n", "200", "--steps", "80",
                 "--out", str(tmp_path / "nan"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and "log_density returned NaN" in err and len(err.strip().splitlines()) == 1
